"""Compile the kernels a planner's first commands need, so that they answer in seconds.

    python jobs/warmup.py                     # make demo runs it; a container image can run it at build time

The project's hot loops are numba kernels compiled on first use and cached beside the package
(``__pycache__``); on a fresh install the first `eosp solve --solver policy` spends most of a
minute compiling.  This job runs what `eosp generate`, `eosp info`, `eosp solve` (greedy, RAMP,
exact, the shipped policy) and `eosp validate` run, on a small instance written to and read back
from a temporary interchange directory, and prints how long it took.  A second run finds the
cache and takes seconds.
"""

from __future__ import annotations

import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from eosp.args import Parser, add_config_args, config_from_args, run_job


@dataclass
class WarmupConfig:
    """What to compile."""

    solvers: tuple[str, ...] = ("greedy", "ramp", "exact", "policy")
    """Solvers to run once each (their default settings, the shipped model for learned ones)."""


def run(cfg: WarmupConfig) -> dict[str, float]:
    """Seconds per step of the warm-up."""
    from eosp.config import family_config
    from eosp.errors import InputError
    from eosp.instances.generator import generate
    from eosp.instances.interchange import read_instance, write_instance
    from eosp.instances.schedule import check, from_internal_nodes
    from eosp.solvers.base import REGISTRY, run_solver

    unknown = [s for s in cfg.solvers if s not in REGISTRY]
    if unknown:
        raise InputError("--solvers", f"unknown solver {unknown[0]!r}; one of {', '.join(sorted(REGISTRY))}")
    times = {}
    t0 = time.perf_counter()
    inst = generate(family_config("uniform", 30, 0))
    times["generate"] = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        write_instance(inst, Path(tmp) / "inst")
        inst = read_instance(Path(tmp) / "inst")
        inst.pruned()
        times["write, read, prune"] = time.perf_counter() - t0
    for name in cfg.solvers:
        t0 = time.perf_counter()
        sol = run_solver(name, inst)
        check(inst, from_internal_nodes(inst, sol.nodes))
        times[name] = time.perf_counter() - t0
    return times


def main(argv: list[str] | None = None) -> int:
    return run_job(_main, argv, "warmup.py")


def _main(argv: list[str] | None) -> int:
    p = Parser(prog="warmup.py", description=__doc__.splitlines()[0])
    add_config_args(p, WarmupConfig)
    cfg = config_from_args(WarmupConfig, p.parse_args(argv))
    t0 = time.perf_counter()
    times = run(cfg)
    steps = ", ".join(f"{k} {v:.1f} s" for k, v in times.items())
    print(f"[warmup] kernels compiled and cached in {time.perf_counter() - t0:.0f} s ({steps})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
