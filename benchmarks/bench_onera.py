"""The ONERA constellation benchmark over its 32 instances: score, proven bound, gap, wall time.

For each ``.pb`` file under ``--dir`` (concentrated_instances/ and spread_instances/ of
ssquilla/Earth_Observing_Satellites_benchmarks): read it, run the greedy baseline and the ONERA solver
(greedy + large-neighbourhood search for ``--time-limit`` s), check both plans with the project's checker,
compute the LP bound (``--bound-time`` s of cutting planes) and the conflict-free bound, and report the
time the search took to reach 99 % of its final score and the requests served by kind.  One JSON line per
instance goes to ``--out`` as it completes, and a Markdown table is printed at the end.

    python benchmarks/bench_onera.py --dir /work/onera --time-limit 15 --bound-time 20 \\
        --out /work/runs/onera/results.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def run_one(path: Path, time_limit: float, bound_time: float, seed: int) -> dict:
    from eosp.onera.model import read_pb
    from eosp.onera.check import best_values, validate
    from eosp.kinds.onera.search import GreedyConfig, OneraConfig, solve
    from eosp.kinds.onera.bound import lp_bound

    t0 = time.perf_counter()
    f = read_pb(path)
    t_read = time.perf_counter() - t0
    greedy = solve(f, GreedyConfig(bound="none", seed=seed))
    g_check = validate(f, greedy.schedule)
    t1 = time.perf_counter()
    sol = solve(f, OneraConfig(time_limit=time_limit, bound="none", seed=seed))
    t_solve = time.perf_counter() - t1
    check = validate(f, sol.schedule)
    cf = float(best_values(f).sum())
    info: dict = {}
    t2 = time.perf_counter()
    # a plan at the conflict-free bound needs no LP
    lp = cf if check.value >= cf - 1e-9 else lp_bound(f, time_limit=bound_time, info=info, finish_first=True)
    t_bound = time.perf_counter() - t2
    bound = min(lp, cf)
    value = check.value if check.valid else float("nan")
    return {
        "instance": f"{path.parent.name.split('_')[0]}/{path.name.split('_seed')[0]}",
        "requests": len(f.requests), "observations": len(f.observations),
        "greedy": g_check.value if g_check.valid else None, "greedy_valid": g_check.valid,
        "value": value, "valid": check.valid, "first_violation": check.first,
        "bound": bound, "gap": max(0.0, (bound - value) / bound) if bound > 0 else 0.0,
        "conflict_free": cf, "lp_rounds": info.get("rounds"), "lp_cuts": info.get("cuts"),
        "seconds_read": t_read, "seconds_solve": t_solve, "seconds_bound": t_bound,
        "seconds_total": time.perf_counter() - t0, "time_to_99": sol.info["time_to_99"],
        "moves": sol.info["moves"], "served": check.served, "requests_by_kind": {
            k: int(v) for k, v in zip(("one-shot", "video", "stereo", "periodic"),
                                      np.bincount(f.requests.kind, minlength=4))},
    }


def table(rows: list[dict]) -> str:
    head = ("| instance | requests (os-v-s-p) | greedy | score | bound | gap | conflict-free | wall s (search + bound) "
            "| t99 s | served os/v/s/p |\n|---|---|---|---|---|---|---|---|---|---|")
    out = [head]
    for r in rows:
        k = r["requests_by_kind"]
        sv = r["served"]
        out.append(f"| {r['instance']} | {r['requests']} ({k['one-shot']}-{k['video']}-{k['stereo']}-{k['periodic']}) "
                   f"| {r['greedy']:.2f} | {r['value']:.2f} | {r['bound']:.2f} | {100 * r['gap']:.2f} % "
                   f"| {r['conflict_free']:.2f} | {r['seconds_solve']:.0f} + {r['seconds_bound']:.0f} "
                   f"| {r['time_to_99']:.1f} | {sv['one-shot']}/{sv['video']}/{sv['stereo']}/{sv['periodic']} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dir", default="/work/onera", help="folder holding the instances' .pb files (searched below)")
    p.add_argument("--time-limit", type=float, default=15.0, help="seconds of search per instance")
    p.add_argument("--bound-time", type=float, default=20.0, help="seconds of LP cutting planes per instance")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--only", default="", help="run the instances whose path contains this text")
    p.add_argument("--out", default="", help="JSON lines, one per instance")
    a = p.parse_args(argv)
    files = sorted(Path(a.dir).rglob("*.pb"))
    files = [f for f in files if a.only in str(f)]
    if not files:
        print(f"no .pb file under {a.dir}", file=sys.stderr)
        return 2
    rows = []
    out = Path(a.out) if a.out else None
    if out:
        out.parent.mkdir(parents=True, exist_ok=True)
    for path in files:
        r = run_one(path, a.time_limit, a.bound_time, a.seed)
        rows.append(r)
        print(f"{r['instance']}: greedy {r['greedy']:.3f} score {r['value']:.3f} bound {r['bound']:.3f} "
              f"gap {100 * r['gap']:.2f}% cf {r['conflict_free']:.3f} valid {r['valid']} "
              f"({r['seconds_total']:.0f} s)", flush=True)
        if out:
            with out.open("a") as fh:
                fh.write(json.dumps(r) + "\n")
    print(table(rows))
    one_shot = [r["gap"] for r in rows if r["requests_by_kind"]["one-shot"] == r["requests"]]
    print(f"median gap: all {100 * np.median([r['gap'] for r in rows]):.2f} %, one-shot "
          f"{100 * np.median(one_shot) if one_shot else float('nan'):.2f} %; all valid: {all(r['valid'] for r in rows)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
