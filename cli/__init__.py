"""The ``eosp`` command: generate, import, export, inspect, solve, validate, plot, report.

Every command reads user files through the checked readers and prints one clear
line (exit code 2) on bad input instead of a traceback.

This module only wires the commands: it asks the registry of problem kinds (:mod:`eosp.kinds`) once which kind
the command line's problem is, :mod:`eosp.cli.parser` builds the parser with that kind's arguments, and the
command's module runs it on any kind (:mod:`eosp.cli.commands` lists them: :mod:`~eosp.cli.generate`,
:mod:`~eosp.cli.import_export`, :mod:`~eosp.cli.info`, :mod:`~eosp.cli.validate`, :mod:`~eosp.cli.solve`,
:mod:`~eosp.cli.report`, :mod:`~eosp.cli.export_schedule`; a single pass's :mod:`~eosp.cli.build_shards` and
:mod:`~eosp.cli.plot`).
"""

from __future__ import annotations

import argparse
import os
import sys

from eosp.cli.build_shards import cmd_build_shards
from eosp.cli.parser import COMMANDS, build_parser
from eosp.cli.solve import solve_options, solver_of, unknown_option
from eosp.errors import InputError

__all__ = ["build_parser", "main", "run", "solve_options"]  # build_parser, solve_options: for tests


def main(argv: list[str] | None = None) -> int:
    """The ``eosp`` command.  Ctrl-C anywhere (loading torch for a learned solver's flags, reading, solving) is one
    line and exit 130; a search's incumbent is written by :func:`eosp.cli.solve.cmd_solve` itself."""
    from eosp.interrupt import ProgramInterrupt

    argv = sys.argv[1:] if argv is None else argv
    with ProgramInterrupt() as ctrl_c:
        try:
            return run(argv)
        except Exception:
            if not ctrl_c.seen:
                raise
            # Ctrl-C inside a library that turns it into another error (numba compiling its kernels): still Ctrl-C
        except KeyboardInterrupt:
            pass
    name = argv[0] if argv and not argv[0].startswith("-") else ""
    print(f"eosp{' ' + name if name else ''}: interrupted: nothing written", file=sys.stderr)
    return 130


def run(argv: list[str]) -> int:
    """:func:`main` without its Ctrl-C line."""
    from eosp.kinds import get

    if argv and argv[0] == "build-shards":
        return cmd_build_shards(argparse.Namespace(), argv[1:])
    kind, refusal = kind_of(argv)  # the kind of the problem the command line names, detected once
    solver = solver_of(argv)
    parser = build_parser(solver, argv[0] if argv and argv[0] in COMMANDS else None, kind)
    if not argv:  # the usage only here and for --help; every other error is one line
        parser.print_help(sys.stderr)
        return 2
    ns, extra = parser.parse_known_args(argv)  # bad option values are refused first, as for any kind
    if refusal is not None:  # a problem no kind reads: its options are no kind's either
        print(f"eosp {argv[0]}: error: {refusal}", file=sys.stderr)
        return 2
    if extra and ns.command == "solve" and extra[0].startswith("--"):
        message = unknown_option(get(ns.kind), solver, extra[0])  # a misspelled or foreign option: name it
        if message:
            print(message, file=sys.stderr)
            return 2
    if extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    from eosp.memory import memory_ceiling

    try:
        with memory_ceiling(getattr(ns, "max_memory_gb", None)):
            return ns.func(get(ns.kind), ns)
    except (InputError, FileExistsError, ValueError, IndexError) as exc:
        print(f"eosp {ns.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # the searches' incumbent is written by cmd_solve; here nothing was
        print(f"eosp {ns.command}: interrupted: nothing written", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `eosp info X | head`: the reader left; stop quietly, as other tools do
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):  # no real file descriptor (captured output)
            pass
        return 141
    except OSError as exc:  # the system refused a path of the user's (permission, disk full, not found, ...)
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"eosp {ns.command}: error: {where}{(exc.strerror or str(exc)).lower()}", file=sys.stderr)
        return 2


def kind_of(argv: list[str]) -> tuple:
    """The problem kind of a command line (None: no command), and the refusal to report when its problem is no
    kind's (an InputError naming every kind tried and why it refused; the first kind offering the command parses
    its options then).  ``generate`` goes by the generator flag it gives (a fleet's --fleet), ``import`` by its
    source, the others by the first argument that a kind recognizes as its problem; a command line that names
    none (``eosp solve --help``) goes to the first kind offering the command."""
    from eosp.kinds import detect, detect_source, generator_kind, kinds, offering

    if not argv or argv[0] not in COMMANDS:
        return None, None
    command, rest = argv[0], argv[1:]
    if command == "generate":
        found = generator_kind(rest)
        return (found[0] if found else offering(command)), None
    offered_by = [k for k in kinds() if command in k.commands]
    if len(offered_by) == 1:  # a command of one kind alone (a single pass's export, plot)
        return offered_by[0], None
    refusal = None
    for path in (a for a in rest if not a.startswith("-")):  # an option's value may come before the problem
        try:
            kind = detect_source(path)[0] if command == "import" else detect(path)
        except InputError as exc:
            refusal = refusal or exc  # the first positional's refusal is the one to report
            continue
        if command not in kind.commands:
            return offered_by[0], InputError(path, f"{kind.title}: its kind ({kind.name}) has no {command} (the "
                                                   f"kinds that have: {', '.join(k.name for k in offered_by)})")
        return kind, None
    return offering(command), refusal


if __name__ == "__main__":
    sys.exit(main())
