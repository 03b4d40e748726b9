"""Where the prices start, at equal wall time: the fleet solver with --warm-start none, heuristic and learned.

For each case (aeossp case or fleet directory) and start: one solve with ``--time-limit T`` counted after the
pass graphs are built, the same for every start (the features and the network's prediction are inside it);
from the solve's history (value and bound after every event) the WCR and the gap (bound - value, as fractions of
the total weight) at each checkpoint second; and L(start), the bound the start's prices give (one price round,
outside the clock).  One process, one worker: runs are sequential.

    python benchmarks/bench_warm_start.py CASE ... --time-limit 30 --at 5 10 30 --out runs/warm-start
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

STARTS = ("none", "heuristic", "learned")


def at(history: list, t: float) -> tuple[float, float]:
    """(value, bound) known at second t of a solve's history (nan before the first event)."""
    v = b = float("nan")
    for s, value, bound in history:
        if s > t:
            break
        v, b = value, bound
    return v, b


def run(case: str, start: str, args: argparse.Namespace) -> dict:
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import solve
    from eosp.kinds.fleet.warmstart import dual_value, start_prices
    from eosp.jobs.train_prices import read_problem

    prob = read_problem(case)  # outside the clock: reading and opportunities are the same for every start
    t0 = time.perf_counter()
    prob.build_s = 0.0
    cfg = FleetConfig(time_limit=args.time_limit, warm_start=start, seed=args.seed, price_model=args.price_model)
    sol = solve(prob.fleet, prob.opps, cfg, problem=prob, t0=t0)
    wall = time.perf_counter() - t0
    row = {"case": case_name(case), "start": start, "rounds": sol.info["rounds"], "wall_s": round(wall, 1),
           "final_wcr": round(sol.value, 4), "final_bound": round(sol.bound, 4)}
    # L(start), outside the clock
    row["start_bound"] = round(dual_value(prob, start_prices(prob, start, args.price_model or None)), 4)
    for t in args.at:
        v, b = at(sol.history, t)
        row[f"wcr@{t:g}"], row[f"gap@{t:g}"] = round(v, 4), round(b - v, 4)
    return row


def case_name(case: str) -> str:
    p = Path(case).resolve()
    return f"{p.parent.name}/{p.name}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--time-limit", type=float, default=30.0)
    ap.add_argument("--at", type=float, nargs="+", default=[5.0, 10.0, 30.0])
    ap.add_argument("--starts", nargs="+", default=list(STARTS), choices=STARTS)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--price-model", default="", help="price model directory of --warm-start learned (default: the "
                    "shipped one)")
    ap.add_argument("--out", default="runs/warm-start")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for case in args.cases:
        for start in args.starts:
            row = run(case, start, args)
            rows.append(row)
            print("  ".join(f"{k} {v}" for k, v in row.items()), flush=True)
    with open(out / "warm_start.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    for start in args.starts:
        mine = [r for r in rows if r["start"] == start]
        cols = [f"wcr@{t:g}" for t in args.at] + [f"gap@{t:g}" for t in args.at] + ["start_bound"]
        print(f"mean {start}: " + "  ".join(f"{c} {sum(r[c] for r in mine) / len(mine):.4f}" for c in cols))
    return 0


if __name__ == "__main__":
    sys.exit(main())
