"""The ``eosp`` command: generate, import, export, inspect, solve, validate, plot, report.

Every command reads user files through the checked readers and prints one clear
line (exit code 2) on bad input instead of a traceback.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from eosp.args import Parser, add_config_args, add_memory_arg, config_from_args
from eosp.config import InstanceConfig, family_config
from eosp.errors import InputError
from eosp.models.pretrained import PREFIX, pretrained_dir


OVERWRITE_HELP = "replace an existing output that eosp wrote (a file or directory eosp did not write is never replaced)"


def _load_instance(path: str):
    """An instance from an interchange directory, or `SHARD.parquet#INDEX` from a shard."""
    from eosp.instances.interchange import read_instance

    if "#" in path:
        from eosp.shards.io import ShardReader

        file, _, idx = path.rpartition("#")
        if not idx.isdigit():
            raise InputError(path, f"expected SHARD.parquet#INDEX with INDEX a number >= 0, got {idx!r}")
        return ShardReader(file).read(int(idx))
    return read_instance(path)


def cmd_generate(ns: argparse.Namespace) -> int:
    from eosp.instances.generator import generate
    from eosp.instances.interchange import check_instance_out, write_instance

    check_instance_out(ns.out, overwrite=ns.overwrite)
    # the family's settings first, then every flag given
    base = family_config(getattr(ns, "family", "uniform"), 100, 0)
    cfg = config_from_args(InstanceConfig, ns, base=base)
    from eosp.instances.generator import require_generate_memory

    require_generate_memory(cfg, "--n-acquisitions")  # from the request, before minutes of generation
    t0 = time.perf_counter()
    inst = generate(cfg)
    write_instance(inst, ns.out, overwrite=ns.overwrite)
    print(f"{ns.out}: {inst.n_acq} acquisitions, {inst.n_nodes} nodes, {inst.unpruned().n_arcs} arcs "
          f"({time.perf_counter() - t0:.2f} s)")
    return 0


def cmd_import(ns: argparse.Namespace) -> int:
    from eosp.instances.interchange import read_instance
    from eosp.shards.io import check_shard_out, write_shard

    check_shard_out(ns.out, ns.overwrite)
    insts, first = [], {}
    for d in ns.instance_dirs:
        inst = read_instance(d)
        if inst.name in first:  # a shard's instances are told apart by their names
            raise InputError(d, f"instance name {inst.name!r} already given by {first[inst.name]}: a shard holds "
                                "distinct instances (rename one in its meta.json)")
        first[inst.name] = d
        insts.append(inst)
    write_shard(ns.out, insts, include_unpruned=not ns.pruned_only, overwrite=ns.overwrite)
    print(f"{ns.out}: {len(insts)} instance(s)")
    return 0


def cmd_export(ns: argparse.Namespace) -> int:
    from eosp.instances.interchange import check_instance_out, write_instance
    from eosp.shards.io import ShardReader

    check_instance_out(ns.out, overwrite=ns.overwrite)
    reader = ShardReader(ns.shard)
    inst = reader.read(ns.index)
    if inst.unpruned_graph is None:
        raise InputError(ns.shard, "this shard holds only pruned arcs; the interchange format needs the unpruned "
                                   "graph", row=ns.index)
    inst.meta.pop("source", None)
    write_instance(inst, ns.out, overwrite=ns.overwrite)
    print(f"{ns.out}: exported {inst.name}")
    return 0


def cmd_info(ns: argparse.Namespace) -> int:
    from eosp.graphs.continuous import continuous_graph

    inst = _load_instance(ns.instance)
    pg = inst.pruned()
    cs, _ = continuous_graph(pg)
    out = {"name": inst.name, "acquisitions": inst.n_acq, "nodes": inst.n_nodes,
           "arcs_unpruned": None if inst.unpruned_graph is None else inst.unpruned_graph.n_arcs, "arcs_pruned": pg.n_arcs, "continuous_arcs_pruned": int(cs.size),
           "family": inst.meta.get("family")}
    print(json.dumps(out, indent=1))
    return 0


def cmd_validate(ns: argparse.Namespace) -> int:
    from eosp.instances.interchange import read_instance
    from eosp.instances.schedule import check, read_schedule

    inst = read_instance(ns.instance_dir)
    verdict = check(inst, read_schedule(ns.schedule))
    if verdict.feasible:
        print(f"feasible: {verdict.n} acquisitions, value {verdict.value:.6f}")
        return 0
    print(f"infeasible: {verdict.reason}")
    return 1


def solve_options(ns: argparse.Namespace) -> dict:
    """The solver options given on the command line (flags of the solver's config, see build_parser);
    0 for --time-limit or --budget means unset, as it always has."""
    from dataclasses import fields

    from eosp.solvers.base import solver_config_class

    options = {f.name: getattr(ns, f.name) for f in fields(solver_config_class(ns.solver)) if hasattr(ns, f.name)}
    for name in ("time_limit", "budget"):
        if options.get(name) == 0:
            options[name] = None
    return options


def cmd_solve(ns: argparse.Namespace) -> int:
    from eosp.instances.schedule import check, check_schedule_out, from_internal_nodes, write_schedule
    from eosp.solvers.base import make_config, run_solver

    options = solve_options(ns)
    make_config(ns.solver, **options)  # bad options are refused before any file is read
    check_schedule_out(ns.out, ns.overwrite)
    ck = options.get("checkpoint") or ""
    if ck.startswith(PREFIX):
        pretrained_dir(ck[len(PREFIX):])  # a shipped model by name: refused in one line if there is none
    elif ck and not Path(ck).exists():
        raise InputError(ck, "checkpoint not found")
    inst = _load_instance(ns.instance_dir)  # the readers check their own memory from the files' headers
    require_solve_memory(inst, ns.instance_dir)
    t0 = time.perf_counter()
    try:
        sol = run_solver(ns.solver, inst, **options)
    except KeyboardInterrupt:
        return interrupted_solve(ns, inst)
    except Exception:
        if SIGINT_SEEN:  # Ctrl-C that a library turned into another error (numba compiling its kernels)
            return interrupted_solve(ns, inst)
        raise
    elapsed = time.perf_counter() - t0
    sched = from_internal_nodes(inst, sol.nodes)
    verdict = check(inst, sched)
    if not verdict.feasible:  # never write a schedule that the checker refuses
        print(f"solver {ns.solver} produced an infeasible schedule: {verdict.reason}", file=sys.stderr)
        return 3
    write_schedule(sched, ns.out, overwrite=ns.overwrite)
    extra = "".join(f", {k} {v}" for k, v in sol.info.items() if k in ("bound", "gap", "status"))
    if options.get("mode") == "unitary":  # the objective is the count; the utility sum is shown for reference
        value = f"value {len(sched)} (acquisitions, unitary), utility sum {verdict.value:.6f}"
    else:
        value = f"{len(sched)} acquisitions, value {verdict.value:.6f}"
    print(f"{ns.out}: {ns.solver}, {value}{extra} ({elapsed:.2f} s)")
    return 0


SOLVE_BYTES_PER_ARC = 24  # the solvers' copies of the graph (pruning, the polisher's and the environment's arrays)
SOLVE_BYTES_PER_NODE = 512


def require_solve_memory(inst, where: str) -> None:
    """A one-line InputError when solving `inst` cannot fit (estimated from its arcs and nodes)."""
    from eosp.memory import require_memory

    arcs = inst.unpruned_graph.n_arcs if inst.unpruned_graph is not None else inst.pruned().n_arcs
    require_memory(where, SOLVE_BYTES_PER_ARC * arcs + SOLVE_BYTES_PER_NODE * inst.n_nodes,
                   f"solving {inst.n_acq:,} acquisitions ({inst.n_nodes:,} nodes, {arcs:,} arcs)")


def interrupted_solve(ns: argparse.Namespace, inst) -> int:
    """Ctrl-C during a solve: the search's best feasible schedule so far (:mod:`eosp.solvers.base`'s incumbent),
    checked by the independent checker, written atomically; one line saying where, or that nothing was written."""
    import signal

    from eosp.instances.schedule import check, from_internal_nodes, write_schedule
    from eosp.solvers.base import INCUMBENT

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not leave a half-written file
    prog = f"eosp {ns.command}"
    nodes = INCUMBENT.take(inst)
    if nodes is None:
        print(f"{prog}: interrupted: no feasible schedule found yet, nothing written", file=sys.stderr)
        return 130
    sched = from_internal_nodes(inst, nodes)
    verdict = check(inst, sched)
    if not verdict.feasible:  # never write what the checker refuses
        print(f"{prog}: interrupted: the best schedule so far is refused by the checker ({verdict.reason}), "
              "nothing written", file=sys.stderr)
        return 130
    write_schedule(sched, ns.out, overwrite=ns.overwrite)
    print(f"{prog}: interrupted: wrote the best feasible schedule so far to {ns.out} ({len(sched)} acquisitions, "
          f"value {verdict.value:.6f})", file=sys.stderr)
    return 130


def cmd_build_shards(ns: argparse.Namespace, rest: list[str]) -> int:
    from eosp.jobs.build_shards import main as build_main

    return build_main(rest, prog="eosp build-shards")


def cmd_plot(ns: argparse.Namespace) -> int:
    from eosp.evaluation.plots import check_plot_out, plot_trajectories
    from eosp.instances.schedule import check, read_schedule

    check_plot_out(ns.out, ns.overwrite)
    inst = _load_instance(ns.instance_dir)
    schedules = {Path(s).stem: read_schedule(s) for s in ns.schedules}
    for name, sched in zip(ns.schedules, schedules.values()):
        verdict = check(inst, sched)  # plot only schedules that make sense for this instance
        if not verdict.feasible:
            raise InputError(name, f"not a feasible schedule of this instance: {verdict.reason}")
    written = plot_trajectories(inst, schedules, ns.out, overwrite=ns.overwrite)
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


def cmd_report(ns: argparse.Namespace) -> int:
    from eosp.evaluation.html_report import check_report_out, write_report
    from eosp.instances.schedule import read_schedule

    check_report_out(ns.out, ns.overwrite)
    inst = _load_instance(ns.instance_dir)
    schedules = {}
    for path in ns.schedules:
        label = Path(path).stem
        if label in schedules:  # same file name in two folders: tell them apart by the folder
            label = f"{Path(path).parent.name}/{label}"
        while label in schedules:
            label += "'"
        schedules[label] = read_schedule(path)
    try:
        out = write_report(inst, schedules, ns.out, title=ns.title or None, overwrite=ns.overwrite,
                           reference=ns.reference or None)
    except InputError as exc:  # the label is the file's stem: name the file the user gave
        path = next((p for p, lab in zip(ns.schedules, schedules) if lab == exc.file), exc.file)
        raise InputError(path, exc.message) from None
    print(f"{out}: {len(schedules)} schedule(s) of {inst.name} ({out.stat().st_size / 1e6:.1f} MB)")
    return 0


def solver_of(argv: list[str]) -> str | None:
    """The --solver of an ``eosp solve`` command line ("" when missing), None for other commands."""
    if not argv or argv[0] != "solve":
        return None
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--solver", default="")
    return pre.parse_known_args(argv[1:])[0].solver


def build_parser(solver: str | None = None) -> argparse.ArgumentParser:
    """The ``eosp`` parser.  `solver`: the --solver of a solve command (:func:`solver_of`), whose config
    (:mod:`eosp.solvers.base`) gives ``eosp solve`` its flags; "" or an unknown name: the shared ones."""
    p = Parser(prog="eosp", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    g = sub.add_parser("generate", help="generate an instance directory (interchange format)")
    g.add_argument("out", help="instance directory to create")
    g.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(g)
    add_config_args(g, InstanceConfig)
    g.set_defaults(func=cmd_generate)

    i = sub.add_parser("import", help="import instance directories into a Parquet shard")
    i.add_argument("instance_dirs", nargs="+")
    i.add_argument("--out", required=True, help="shard file to write")
    i.add_argument("--pruned-only", action="store_true", help="do not store the unpruned arcs")
    i.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(i)
    i.set_defaults(func=cmd_import)

    e = sub.add_parser("export", help="export one instance of a shard as an interchange directory")
    e.add_argument("shard")
    e.add_argument("--index", type=int, default=0)
    e.add_argument("--out", required=True)
    e.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(e)
    e.set_defaults(func=cmd_export)

    n = sub.add_parser("info", help="sizes of an instance (directory, or SHARD#INDEX)")
    n.add_argument("instance")
    add_memory_arg(n)
    n.set_defaults(func=cmd_info)

    v = sub.add_parser("validate", help="check a schedule against an instance; exit 0 when feasible")
    v.add_argument("instance_dir")
    v.add_argument("schedule")
    add_memory_arg(v)
    v.set_defaults(func=cmd_validate)

    s = sub.add_parser("solve", help="solve an instance and write a schedule file",
                       epilog="Each solver has its own options: eosp solve --solver NAME --help lists them.")
    s.add_argument("instance_dir", help="instance directory (or SHARD#INDEX)")
    s.add_argument("--solver", required=True, help="random, greedy, ramp, exact, lns, policy, sample, beam, mcts")
    s.add_argument("--out", required=True, help="schedule file (.parquet, or .jsonl)")
    s.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(s)
    if solver is not None:
        from eosp.solvers.base import REGISTRY, SolverConfig, solver_config_class

        add_config_args(s, solver_config_class(solver) if solver in REGISTRY else SolverConfig)
    s.set_defaults(func=cmd_solve)

    b = sub.add_parser("build-shards", help="generate a data set of Parquet shards with Ray (jobs/build_shards.py)",
                       add_help=False)
    b.set_defaults(func=None, passthrough=cmd_build_shards)

    pl = sub.add_parser("plot", help="trajectory plot (roll against time) of schedules of one instance")
    pl.add_argument("instance_dir")
    pl.add_argument("schedules", nargs="+")
    pl.add_argument("--out", required=True, help="output path without extension (PNG and SVG are written)")
    pl.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(pl)
    pl.set_defaults(func=cmd_plot)

    x = sub.add_parser("export-schedule", help="write a fleet schedule as an aeossp solution.json or a CSV "
                                               "(fleets: import, info, solve, validate take a fleet directory too)")
    x.add_argument("fleet_dir")
    x.add_argument("schedule")
    x.add_argument("--format", choices=("aeossp", "csv"), required=True)
    x.add_argument("--out", required=True)

    r = sub.add_parser("report", help="one self-contained HTML page: map, timeline, roll/pitch and a summary "
                                      "table of schedules of one instance")
    r.add_argument("instance_dir", help="instance directory (or SHARD#INDEX)")
    r.add_argument("schedules", nargs="+", help="schedule files (.parquet or .jsonl); infeasible ones are drawn too")
    r.add_argument("--out", required=True, help="HTML file to write")
    r.add_argument("--title", default="", help="page title (default: the instance name)")
    r.add_argument("--reference", default="", help="the schedule (its label: the file name without suffix) the "
                                                   "others are compared with and whose missed acquisitions are "
                                                   "explained (default: the best feasible one)")
    r.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(r)
    r.set_defaults(func=cmd_report)
    return p


SIGINT_SEEN: list[bool] = []  # set by Ctrl-C during main: an error that follows it is the interrupt's


def _on_sigint(signum, frame) -> None:  # noqa: ARG001 - Python's own handler, remembering that it ran
    SIGINT_SEEN.append(True)
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    """The ``eosp`` command.  Ctrl-C anywhere (loading torch for a learned solver's flags, reading, solving) is one
    line and exit 130; a search's incumbent is written by :func:`cmd_solve` itself."""
    import signal

    argv = sys.argv[1:] if argv is None else argv
    SIGINT_SEEN.clear()
    previous, unraisable = None, sys.unraisablehook

    def swallowed(u) -> None:
        """A Ctrl-C that lands in a C callback (numba compiling) is dropped there by Python ('Exception ignored'):
        deliver it again, to land in ordinary code, instead of printing it and going on."""
        if u.exc_type is KeyboardInterrupt:
            signal.raise_signal(signal.SIGINT)
        else:
            unraisable(u)

    sys.unraisablehook = swallowed
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # an ignored SIGINT stays ignored
        try:
            previous = signal.signal(signal.SIGINT, _on_sigint)
        except ValueError:  # not the main thread (embedded): Python's handler stays
            previous = None
    try:
        return run(argv)
    except Exception:
        if not SIGINT_SEEN:
            raise
        # Ctrl-C inside a library that turns it into another error (numba compiling its kernels): still Ctrl-C
    except KeyboardInterrupt:
        pass
    finally:
        sys.unraisablehook = unraisable
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
    name = argv[0] if argv and not argv[0].startswith("-") else ""
    print(f"eosp{' ' + name if name else ''}: interrupted: nothing written", file=sys.stderr)
    return 130


def run(argv: list[str]) -> int:
    """:func:`main` without its Ctrl-C line."""
    from eosp.cli.fleet_main import is_fleet_command, route

    if is_fleet_command(argv):  # a fleet (aeossp case, fleet directory) where a single pass would be
        return route(argv)
    solver = solver_of(argv)
    parser = build_parser(solver)
    if not argv:  # the usage only here and for --help; every other error is one line
        parser.print_help(sys.stderr)
        return 2
    if argv and argv[0] == "build-shards":
        return cmd_build_shards(argparse.Namespace(), argv[1:])
    ns, extra = parser.parse_known_args(argv)
    if extra and ns.command == "solve" and extra[0].startswith("--"):
        from dataclasses import fields

        from eosp.solvers.base import REGISTRY, solver_config_class

        if solver in REGISTRY:  # a misspelled or foreign option: name it and the valid ones
            valid = ", ".join("--" + f.name.replace("_", "-") for f in fields(solver_config_class(solver)))
            flag = extra[0].partition("=")[0]
            print(f"eosp solve: error: solver {solver!r} has no option {flag}; its options: {valid}", file=sys.stderr)
            return 2
    if extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    from eosp.memory import set_max_memory_gb

    set_max_memory_gb(getattr(ns, "max_memory_gb", None))
    try:
        return ns.func(ns)
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


if __name__ == "__main__":
    sys.exit(main())
