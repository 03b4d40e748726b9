"""Fleets: the exact pass solves alone, every pass of a fleet directory under seeded utilities.

    python benchmarks/bench_pass_solves.py --fleet-dir fleet-200
    python benchmarks/bench_pass_solves.py --fleet-dir fleet-200 --open 0.5 --repeat 3 --sizes

Each pass is solved as the fleet solver's sweeps solve it (``solve_pass_graph``, the exact pass solver, the pass
time limit) with each of its tasks open at its weight with probability ``--open`` (seeded), else worth 0.  A
first pass over 300 passes warms the JIT.  Prints the best wall time of ``--repeat`` passes over the fleet, the
time per pass, and a hash of the paths with the sum of the values: two versions of the code that print the same
hash found the same paths.  ``--sizes`` adds the time by pass size (opportunities) from a last pass, one
solve timed at a time.  One process, one thread.
"""

from __future__ import annotations

import argparse
import hashlib
import time
from pathlib import Path

import numpy as np

SIZES = ((1, 10), (11, 30), (31, 100), (101, 300), (301, 10**9))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fleet-dir", type=Path, required=True, help="a fleet directory (eosp generate --fleet)")
    ap.add_argument("--open", type=float, default=0.5, help="share of each pass's tasks open (at their weight)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the open tasks")
    ap.add_argument("--repeat", type=int, default=3, help="timed passes over the fleet (the best is printed)")
    ap.add_argument("--sizes", action="store_true", help="also the time by pass size, one solve timed at a time")
    args = ap.parse_args()

    from eosp.fleet.io import read_fleet
    from eosp.kinds.fleet.problem import PassSpec, Problem, solve_pass_graph

    fleet, opps = read_fleet(args.fleet_dir)
    prob = Problem.build(fleet, opps)
    cfg = PassSpec()
    rng = np.random.default_rng(args.seed)
    utils = [np.where(rng.random(len(pg.tasks)) < args.open, prob.weight[pg.tasks], 0.0) for pg in prob.passes]
    for pg, u in zip(prob.passes[:300], utils):
        solve_pass_graph(pg, u, cfg)
    best = np.inf
    for _ in range(args.repeat):
        t = time.perf_counter()
        res = [solve_pass_graph(pg, u, cfg) for pg, u in zip(prob.passes, utils)]
        best = min(best, time.perf_counter() - t)
    digest = hashlib.sha256(b"".join(r.nodes.tobytes() for r in res)).hexdigest()[:12]
    n = len(prob.passes)
    print(f"{n} passes, {len(opps)} opportunities: best of {args.repeat} {best:.3f} s ({best / n * 1e6:.0f} us a "
          f"pass); paths {digest}, value {sum(r.value for r in res):.6f}")
    if args.sizes:
        size = np.array([len(pg.rows) for pg in prob.passes])
        spent = np.zeros(n)
        for p, (pg, u) in enumerate(zip(prob.passes, utils)):
            t = time.perf_counter()
            solve_pass_graph(pg, u, cfg)
            spent[p] = time.perf_counter() - t
        print("\n| opportunities | passes | mean (us) | total (s) |\n|---|---|---|---|")
        for lo, hi in SIZES:
            sel = (size >= lo) & (size <= hi)
            if sel.any():
                label = f"{lo}-{hi}" if hi < 10**9 else f">{lo - 1}"
                print(f"| {label} | {int(sel.sum())} | {spent[sel].mean() * 1e6:.0f} | {spent[sel].sum():.3f} |")


if __name__ == "__main__":
    main()
