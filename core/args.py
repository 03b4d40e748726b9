"""Command-line flags generated from the config dataclasses.

``add_config_args(parser, InstanceConfig)`` adds one flag per field, nested
configs with dotted names (``--satellite.roll-max-deg 40``), with the field's
docstring-comment as help; ``config_from_args`` builds the dataclass back.  The
same dataclass is thus the CLI's ``--help``, the job's parameters and Tune's
search space keys.
"""

from __future__ import annotations

import argparse
import ast
import functools
import inspect
import re
import sys
import typing
from dataclasses import MISSING, fields, is_dataclass
from pathlib import Path
from typing import Any


class Parser(argparse.ArgumentParser):
    """The parser of the CLI and of every job: a bad option is one line ``PROG: error: --option: reason``
    (exit 2), without argparse's usage block, which only ``--help`` shows (and ``eosp`` with no arguments).
    Sub-commands get the same class (``eosp solve`` is their PROG).  No abbreviations: ``--moves`` is not taken
    for ``--moves-per-round`` (an option a solver lacks is an error, never another option's prefix)."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> typing.NoReturn:
        message = re.sub(r"^argument ([^:]*?)(?:/[^:]*)?: ", r"\1: ", message)  # 'argument --x/-y: ...' -> '--x: ...'
        print(f"{self.prog}: error: {message}", file=sys.stderr, flush=True)
        sys.exit(2)

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        from eosp import errors

        errors.PROG = self.prog  # a sub-command's parser names itself in the errors that follow
        return super().parse_known_args(args, namespace)


def memory_gb(text: str) -> float:
    """The argparse type of --max-memory-gb: a finite number > 0 (GiB)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of GiB, got {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


def add_memory_arg(parser: argparse.ArgumentParser) -> None:
    """--max-memory-gb: the user's ceiling, on top of the memory available (eosp.memory.require_memory)."""
    parser.add_argument("--max-memory-gb", type=memory_gb, default=None, metavar="GB",
                        help="refuse (one line, with the estimate) work estimated to need more memory than this; "
                             "what the machine has available is always checked")


def run_job(main: Any, argv: list[str] | None, prog: str) -> int:
    """Run a job's `main(argv)` with the one error path of the jobs: a user error (:class:`eosp.errors.InputError`:
    a bad file, option, data set, checkpoint or config) is one line ``PROG: error: ...`` and exit 2; Ctrl-C is one
    line and exit 130 (what was completed before it is kept, e.g. checkpoints and finished shards), also when a
    library turned it into another error (:class:`eosp.interrupt.ProgramInterrupt`), the job's MLflow run ended as
    KILLED.  A job that is a process of its own (`argv` None) shuts Ray down here with Ctrl-C ignored, so that a
    Ctrl-C in the teardown cannot become a traceback of Ray's exit handler."""
    from eosp import errors
    from eosp.interrupt import ProgramInterrupt

    errors.PROG = prog
    interrupted = False
    try:
        with ProgramInterrupt() as ctrl_c:
            try:
                return main(argv)
            except errors.InputError as exc:
                print(errors.error_line(exc), file=sys.stderr, flush=True)
                return 2
            except OSError as exc:
                if ctrl_c.seen:
                    interrupted = True
                elif not exc.filename:
                    raise
                else:  # the system refused a path of the user's (not found, permission): one line naming it
                    print(errors.error_line(f"{exc.filename}: {(exc.strerror or str(exc)).lower()}"),
                          file=sys.stderr, flush=True)
                    return 2
            except KeyboardInterrupt:
                interrupted = True
            except Exception:
                if not ctrl_c.seen:
                    raise
                interrupted = True
    finally:
        _teardown(own_process=argv is None, interrupted=interrupted)
    print(f"{prog}: interrupted: stopped (files completed before the interrupt are kept)", file=sys.stderr,
          flush=True)
    return 130


def _teardown(own_process: bool, interrupted: bool) -> None:
    """What a job leaves: its MLflow run ended as KILLED after Ctrl-C; Ray shut down in a process of its own, with
    a second Ctrl-C ignored meanwhile (the job's outcome is decided)."""
    import signal

    mlflow, ray = sys.modules.get("mlflow"), sys.modules.get("ray")
    if not (own_process or interrupted):
        return
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread
        previous = None
    try:
        if interrupted and mlflow is not None and mlflow.active_run() is not None:
            try:
                mlflow.end_run("KILLED")
            except Exception:  # noqa: BLE001 - a tracking server gone: the job's outcome stays the interrupt
                pass
        if own_process and ray is not None and ray.is_initialized():
            ray.shutdown()
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _field_docs(cls: type) -> dict[str, str]:
    """The string literal that follows each field in the class body (its doc), also for the fields a
    dataclass inherits (the subclass's doc wins)."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if is_dataclass(klass):
            docs.update(_own_field_docs(klass))
    return docs


@functools.lru_cache(maxsize=None)
def _class_defs(path: str) -> dict[str, ast.ClassDef]:
    """The top-level classes of a source file, parsed once (``inspect.getsource`` parses the whole module
    again for every class it is asked for: most of ``eosp --help``)."""
    try:
        tree = ast.parse(Path(path).read_text(encoding="utf-8"))
    except (OSError, SyntaxError, ValueError):
        return {}
    return {node.name: node for node in tree.body if isinstance(node, ast.ClassDef)}


def _own_field_docs(cls: type) -> dict[str, str]:
    try:
        node = _class_defs(inspect.getsourcefile(cls)).get(cls.__qualname__)
    except TypeError:
        node = None
    body = node.body if node is not None else []
    docs: dict[str, str] = {}
    for prev, node in zip(body, body[1:]):
        if (isinstance(prev, ast.AnnAssign) and isinstance(prev.target, ast.Name) and isinstance(node, ast.Expr)
                and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)):
            docs[prev.target.id] = " ".join(node.value.value.split())
    return docs


def _parse_bool(text: str) -> bool:
    t = text.lower()
    if t in ("1", "true", "yes", "on"):
        return True
    if t in ("0", "false", "no", "off"):
        return False
    raise argparse.ArgumentTypeError(f"expected true/false, got {text!r}")


def _checked(cls: type, name: str, conv: Any) -> Any:
    """An argparse type: `conv`, then the field's own checks (finite, range, choices: config.check_value)."""
    from eosp.config import check_value, field_of

    def parse(text: str) -> Any:
        value = conv(text)
        if value == 0 and field_of(cls, name).metadata.get("zero_unsets"):
            return None  # an optional limit: 0 on a command line means unset
        try:
            check_value(cls, name, value)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc).partition(": ")[2]) from None
        return value

    parse.__name__ = getattr(conv, "__name__", "value")  # argparse names the type in its messages
    return parse


def add_config_args(parser: argparse.ArgumentParser, cls: type, prefix: str = "",
                    defaults: Any | None = None) -> None:
    hints = typing.get_type_hints(cls)
    docs = _field_docs(cls)
    inst = defaults if defaults is not None else cls()
    for f in fields(cls):
        value = getattr(inst, f.name)
        name = f"{prefix}{f.name}"
        if is_dataclass(value):
            add_config_args(parser, type(value), prefix=name + ".", defaults=value)
            continue
        hint = hints[f.name]
        options = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(options) == 1 and len(typing.get_args(hint)) == 2:  # `X | None`: the flag gives an X
            hint = options[0]
        flag = "--" + name.replace("_", "-")
        # argparse %-formats help strings: a docstring's '%' must reach the user as written
        help_text = (docs.get(f.name, "") + f" (default: {value!r})").strip().replace("%", "%%")
        origin = typing.get_origin(hint)
        if hint is bool:  # `--flag` alone means true
            parser.add_argument(flag, dest=name, type=_parse_bool, nargs="?", const=True, default=argparse.SUPPRESS,
                                metavar="BOOL", help=help_text)
        elif origin is tuple:
            elem = typing.get_args(hint)[0]
            parser.add_argument(flag, dest=name, type=_checked(cls, f.name, elem), nargs="+",
                                default=argparse.SUPPRESS, help=help_text, metavar=elem.__name__.upper())
        elif hint in (int, float, str):
            parser.add_argument(flag, dest=name, type=_checked(cls, f.name, hint), default=argparse.SUPPRESS,
                                help=help_text, metavar=hint.__name__.upper())
        else:
            parser.add_argument(flag, dest=name, type=str, default=argparse.SUPPRESS, help=help_text)


def config_from_args(cls: type, ns: argparse.Namespace, base: Any | None = None) -> Any:
    """The dataclass `cls` (or `base`) with every flag given on the command line applied."""
    from eosp.config import apply_overrides

    cfg = base if base is not None else cls()
    given = {k: tuple(v) if isinstance(v, list) else v for k, v in vars(ns).items() if _belongs(cls, k)}
    return apply_overrides(cfg, given)


def _belongs(cls: type, dotted: str) -> bool:
    head, _, rest = dotted.partition(".")
    for f in fields(cls):
        if f.name == head:
            if not rest:
                return True
            sub = f.default_factory() if f.default_factory is not MISSING else f.default  # type: ignore[misc]
            return is_dataclass(sub) and _belongs(type(sub), rest)
    return False


def prefixed_config(cls: type, ns: argparse.Namespace, prefix: str) -> Any:
    """A flat config added with ``add_config_args(..., prefix=prefix)`` (e.g. RayConfig under 'ray.')."""
    from eosp.config import apply_overrides

    return apply_overrides(cls(), {k[len(prefix):]: tuple(v) if isinstance(v, list) else v
                                   for k, v in vars(ns).items() if k.startswith(prefix)})
