"""``eosp solve INSTANCE --solver NAME --out SCHEDULE``: run a single-pass solver, check its schedule, write it.

Owns the solver's options on the command line (:func:`solver_of`, :func:`solve_options`, :func:`unknown_option`),
the memory check before solving, and what Ctrl-C writes (:func:`interrupted_solve`).  Fleets: :mod:`eosp.cli.fleet`.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from eosp.cli.load import load_instance
from eosp.errors import InputError
from eosp.models.pretrained import PREFIX, pretrained_dir

SIGINT_SEEN: list[bool] = []  # set by Ctrl-C during main (eosp.cli): an error that follows it is the interrupt's

SOLVE_BYTES_PER_ARC = 24  # the solvers' copies of the graph (pruning, the polisher's and the environment's arrays)
SOLVE_BYTES_PER_NODE = 512


def solver_of(argv: list[str]) -> str | None:
    """The --solver of an ``eosp solve`` command line ("" when missing), None for other commands."""
    if not argv or argv[0] != "solve":
        return None
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--solver", default="")
    return pre.parse_known_args(argv[1:])[0].solver


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


def unknown_option(solver: str | None, flag: str) -> str | None:
    """The error line for `flag` (``--name`` or ``--name=value``), which `solver`'s config lacks, naming the
    valid ones; None when `solver` is no known solver (the parser's own error then)."""
    from dataclasses import fields

    from eosp.solvers.base import REGISTRY, solver_config_class

    if solver not in REGISTRY:
        return None
    valid = ", ".join("--" + f.name.replace("_", "-") for f in fields(solver_config_class(solver)))
    return f"eosp solve: error: solver {solver!r} has no option {flag.partition('=')[0]}; its options: {valid}"


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
    inst = load_instance(ns.instance_dir)  # the readers check their own memory from the files' headers
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
