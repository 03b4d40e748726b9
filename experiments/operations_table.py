"""The planners of the operations world side by side (docs/results.md, "A constellation in operation"): for each
fleet, a scenario made with the given options, then every planner through the same realizations through
``eosp simulate`` (one process per planner, one after the other), and the paired differences between planners
with 95% intervals (Student t over the realizations; the same clouds, forecasts and arrivals for every planner).

    python experiments/operations_table.py --fleets FLEET_DIR ... --work DIR --realizations 8 --time-limit 10

Prints one markdown table of means and one of paired differences; every run's summary stays under ``--work``.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

PLANNERS = ("plan-once", "replan", "ev-replan")
PAIRS = (("replan", "plan-once"), ("ev-replan", "replan"), ("ev-replan", "plan-once"))


def eosp(*args: str) -> str:
    r = subprocess.run([sys.executable, "-m", "eosp.cli", *args], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"eosp {' '.join(args)} exited {r.returncode}: {r.stderr.strip()[-400:]}")
    return r.stdout.strip()


def interval(diffs: list[float]) -> tuple[float, float]:
    """The mean of paired differences and the half-width of its 95% Student t interval."""
    from scipy.stats import t as student

    n = len(diffs)
    mean = sum(diffs) / n
    if n < 2:
        return mean, math.inf
    sd = math.sqrt(sum((d - mean) ** 2 for d in diffs) / (n - 1))
    return mean, float(student.ppf(0.975, n - 1)) * sd / math.sqrt(n)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fleets", nargs="+", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--realizations", type=int, default=8)
    ap.add_argument("--time-limit", type=float, default=10.0)
    ap.add_argument("--scenario-args", default="", help="extra options of eosp scenario, e.g. '--cadence-h 2'")
    ap.add_argument("--simulate-args", default="", help="extra options of eosp simulate, e.g. '--bound-time-limit 15'")
    args = ap.parse_args()
    work = Path(args.work)
    rows, pairs = [], []
    for fleet in args.fleets:
        name = Path(fleet).name
        scen = work / f"{name}.scen"
        if not scen.exists():
            print(eosp("scenario", fleet, "--out", str(scen), *args.scenario_args.split()), flush=True)
        got = {}
        for planner in PLANNERS:
            run = work / f"{name}.{planner}"
            print(eosp("simulate", str(scen), "--planner", planner, "--realizations", str(args.realizations),
                       "--time-limit", str(args.time_limit), "--out", str(run), "--resume",
                       *args.simulate_args.split()), flush=True)
            got[planner] = json.loads((run / "summary.json").read_text())
            m = got[planner]["means"]
            rows.append(f"| {name} | {planner} | {m['served']:.4f} | {m['served_catalogue']:.4f} | "
                        f"{m['served_urgent'] if m['served_urgent'] is None else round(m['served_urgent'], 4)} | "
                        f"{m['bound']:.4f} | {m['regret']:.4f} | {m['cloud_lost']:.4f} | "
                        f"{'-' if m['urgent_latency_h'] is None else round(m['urgent_latency_h'], 2)} | "
                        f"{m['churn']:.0f} | {m['compute_s_per_call']:.1f} | {m['valid']}/{m['realizations']} |")
        for a, b in PAIRS:
            ra = {r["realization"]: r["served"] for r in got[a]["realizations"]}
            rb = {r["realization"]: r["served"] for r in got[b]["realizations"]}
            mean, half = interval([ra[i] - rb[i] for i in sorted(ra) if i in rb])
            pairs.append(f"| {name} | {a} - {b} | {mean:+.4f} | [{mean - half:+.4f}, {mean + half:+.4f}] |")
    print("\n| fleet | planner | served | catalogue | urgent | clairvoyant bound | regret | cloud-lost | urgent "
          "latency h | churn | s a call | valid |\n|---|---|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    print("\n| fleet | pair | served, mean difference | 95% interval |\n|---|---|---|---|")
    print("\n".join(pairs))


if __name__ == "__main__":
    main()
