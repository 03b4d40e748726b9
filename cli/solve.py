"""``eosp solve PROBLEM --solver NAME --out SCHEDULE``: run a solver of the problem's kind, check its schedule, write
it.

Owns the solver's options on the command line (:func:`solver_of`, :func:`solve_options`, :func:`unknown_option`)
and what Ctrl-C writes (:func:`interrupted_solve`, or a search's own best schedule when it returns with status
"interrupted": checked, written, one line, exit 130); the kind (:mod:`eosp.kinds`) reads, solves, checks and
words the result.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import fields

from eosp.interrupt import sigint_seen
from eosp.problem import load



def solver_of(argv: list[str]) -> str | None:
    """The --solver of an ``eosp solve`` command line ("" when missing), None for other commands."""
    if not argv or argv[0] != "solve":
        return None
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--solver", default="")
    return pre.parse_known_args(argv[1:])[0].solver


def config_class(ns: argparse.Namespace) -> type:
    """The config class of the solve command line `ns` (its kind's solver, see :func:`eosp.cli.parser.build_parser`)."""
    from eosp.kinds import get

    return get(ns.kind).solver_config(ns.solver)


def solve_options(ns: argparse.Namespace) -> dict:
    """The solver options given on the command line (flags of the solver's config, see build_parser); 0 for
    --budget means unset, as it always has (and for --time-limit: eosp.config.ranged's zero_unsets)."""
    options = {f.name: getattr(ns, f.name) for f in fields(config_class(ns)) if hasattr(ns, f.name)}
    for name in ("time_limit", "budget"):
        if options.get(name) == 0:
            options[name] = None
    return options


def unknown_option(kind, solver: str | None, flag: str) -> str | None:
    """The error line for `flag` (``--name`` or ``--name=value``), which `solver`'s config lacks, naming the
    valid ones; None when `solver` is no solver of `kind` (the parser's own error then)."""
    if solver not in kind.solvers:
        return None
    valid = ", ".join("--" + f.name.replace("_", "-") for f in fields(kind.solver_config(solver)))
    return f"eosp solve: error: solver {solver!r} has no option {flag.partition('=')[0]}; its options: {valid}"


def make_config(kind, ns: argparse.Namespace):
    """The solver's config from the command line; an unknown solver or option is a one-line ValueError."""
    if ns.solver not in kind.solvers:
        raise ValueError(f"unknown solver {ns.solver!r}; available: {', '.join(sorted(kind.solvers))}")
    cls = kind.solver_config(ns.solver)
    return cls(**solve_options(ns))


class CompileClock:
    """Seconds numba spends compiling kernels (those not in its cache) while the block runs, in this process: what
    a solve's line names when its first schedule comes after its time limit (``Result.timings["compile"]``)."""

    def __enter__(self) -> CompileClock:
        from numba.core import event

        self.seconds, self._listener = 0.0, event.TimingListener()
        event.register("numba:compile", self._listener)
        return self

    def __exit__(self, *exc) -> None:
        from numba.core import event

        event.unregister("numba:compile", self._listener)
        self.seconds = self._listener.duration if self._listener.done else 0.0


def cmd_solve(kind, ns: argparse.Namespace) -> int:
    cfg = make_config(kind, ns)  # bad options are refused before any file is read
    out = kind.schedule_out(ns.out, ns.overwrite)
    kind.before_read(ns.solver, cfg)
    t_read = time.perf_counter()
    problem = kind.read(ns.problem)  # the readers check their own memory from the files' headers
    kind.before_solve(problem, ns.problem)
    inputs = kind.solve_inputs(ns, problem)
    t0 = time.perf_counter()
    try:
        with CompileClock() as compiling:
            res = load(kind.solvers[ns.solver].solve)(problem, cfg, **inputs)
    except KeyboardInterrupt:
        return interrupted_solve(kind, ns, problem)
    except Exception:
        if sigint_seen():  # Ctrl-C that a library turned into another error (numba compiling its kernels)
            return interrupted_solve(kind, ns, problem)
        raise
    elapsed = time.perf_counter() - t0
    res.timings.setdefault("read", t0 - t_read)
    res.timings.setdefault("compile", compiling.seconds)
    stopped = res.status == "interrupted"  # a search that kept its best schedule when Ctrl-C stopped it
    if stopped:
        import signal

        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not leave a half-written file
    if res.verdict is None:
        res.verdict = kind.check(problem, res.schedule)
    if not res.verdict.valid:  # never write a schedule that the checker refuses
        if stopped:
            print(f"eosp {ns.command}: interrupted: the best schedule so far is refused by the checker "
                  f"({res.verdict.first}), nothing written", file=sys.stderr)
            return 130
        print(f"solver {ns.solver} produced an invalid schedule: {res.verdict.first}", file=sys.stderr)
        return 3
    info, line = kind.solved(ns.out, ns.solver, cfg, res, elapsed)
    kind.write_schedule(res.schedule, problem, out, overwrite=ns.overwrite, info=info)
    print(line)
    if stopped:
        print(f"eosp {ns.command}: interrupted: wrote the best valid schedule so far to {out} (value "
              f"{res.value:.6f})", file=sys.stderr)
        return 130
    return 0


def interrupted_solve(kind, ns: argparse.Namespace, problem) -> int:
    """Ctrl-C during a solve: the search's best feasible schedule so far (the kind's incumbent), checked by the
    checker, written atomically; one line saying where, or that nothing was written."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not leave a half-written file
    prog = f"eosp {ns.command}"
    sched = kind.incumbent(problem)
    if sched is None:
        print(f"{prog}: interrupted: no feasible schedule found yet, nothing written", file=sys.stderr)
        return 130
    verdict = kind.check(problem, sched)
    if not verdict.valid:  # never write what the checker refuses
        print(f"{prog}: interrupted: the best schedule so far is refused by the checker ({verdict.first}), "
              "nothing written", file=sys.stderr)
        return 130
    kind.write_schedule(sched, problem, ns.out, overwrite=ns.overwrite)
    print(f"{prog}: interrupted: wrote the best feasible schedule so far to {ns.out} ({len(sched)} acquisitions, "
          f"value {verdict.metrics['value']:.6f})", file=sys.stderr)
    return 130
