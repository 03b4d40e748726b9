"""The planners of the operations world side by side (docs/results.md, "A constellation in operation"): for each
fleet, a scenario made with the given options (and its twin with perfect forecasts: the same seed, so the same
requests and clouds), then every variant through the same realizations through ``eosp simulate`` (one process
each, one after the other), and the paired differences between variants with 95% intervals (Student t over the
realizations; the same clouds, forecasts and arrivals for every variant).

    python experiments/operations_table.py --fleets FLEET_DIR ... --work DIR --realizations 6 --time-limit 10 \\
        --simulate-args "--bound-time-limit 15"

Variants: plan-once, replan, ev-replan, each also with the onboard rule, ev-replan started cold at every call,
ev-replan with perfect forecasts, ev-replan with the onboard rule that looks ahead.  Prints one markdown table of means and one of paired differences; every run's
summary stays under ``--work`` (a rerun resumes them).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

VARIANTS = {  # name: (scenario twin, eosp simulate options)
    "plan-once": ("", ["--planner", "plan-once"]),
    "replan": ("", ["--planner", "replan"]),
    "ev-replan": ("", ["--planner", "ev-replan"]),
    "ev-replan + onboard rule": ("", ["--planner", "ev-replan", "--onboard", "rule"]),
    "plan-once + onboard rule": ("", ["--planner", "plan-once", "--onboard", "rule"]),
    "replan + onboard rule": ("", ["--planner", "replan", "--onboard", "rule"]),
    "ev-replan, cold calls": ("", ["--planner", "ev-replan", "--warm", "false"]),
    "ev-replan, perfect forecasts": ("perfect", ["--planner", "ev-replan"]),
    "ev-replan + lookahead": ("", ["--planner", "ev-replan", "--onboard", "lookahead"]),
}
PAIRS = (("replan", "plan-once"), ("ev-replan", "replan"), ("ev-replan + onboard rule", "ev-replan"),
         ("plan-once + onboard rule", "plan-once"), ("replan + onboard rule", "replan"),
         ("ev-replan", "ev-replan, cold calls"), ("ev-replan, perfect forecasts", "ev-replan"),
         ("ev-replan + lookahead", "ev-replan"))


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


def fmt(v, digits: int = 4) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fleets", nargs="+", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--realizations", type=int, default=8)
    ap.add_argument("--time-limit", type=float, default=10.0)
    ap.add_argument("--scenario-args", default="", help="extra options of eosp scenario, e.g. '--cadence-h 2'")
    ap.add_argument("--simulate-args", default="", help="extra options of eosp simulate, e.g. '--bound-time-limit 15'")
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--report-only", action="store_true", help="tables of the runs --work holds; nothing run")
    args = ap.parse_args()
    work = Path(args.work)
    rows, pairs = [], []
    for fleet in args.fleets:
        name = Path(fleet).name
        got = {}
        for variant in args.variants:
            twin, opts = VARIANTS[variant]
            scen = work / f"{name}{'.' + twin if twin else ''}.scen"
            run = work / f"{name}.{variant.replace(' ', '').replace(',', '.').replace('+', '.')}"
            if args.report_only and not (run / "summary.json").exists():
                continue
            if not scen.exists():
                extra = ["--forecast-sigma-day", "0"] if twin == "perfect" else []
                print(eosp("scenario", fleet, "--out", str(scen), *args.scenario_args.split(), *extra), flush=True)
            if not args.report_only:
                print(eosp("simulate", str(scen), *opts, "--realizations", str(args.realizations), "--time-limit",
                           str(args.time_limit), "--out", str(run), "--resume", *args.simulate_args.split()),
                      flush=True)
            got[variant] = json.loads((run / "summary.json").read_text())
            m = got[variant]["means"]
            rows.append(f"| {name} | {variant} | {fmt(m['served'])} | {fmt(m['served_catalogue'])} | "
                        f"{fmt(m['served_urgent'])} | {fmt(m['bound'])} | {fmt(m['regret'])} | "
                        f"{fmt(m['cloud_lost'])} | {fmt(m['urgent_latency_h'], 2)} | {fmt(m['churn'], 0)} | "
                        f"{fmt(m['compute_s_per_call'], 1)} | {m['valid']}/{m['realizations']} |")
        for a, b in PAIRS:
            if a not in got or b not in got:
                continue
            ra = {r["realization"]: r["served"] for r in got[a]["realizations"]}
            rb = {r["realization"]: r["served"] for r in got[b]["realizations"]}
            mean, half = interval([ra[i] - rb[i] for i in sorted(ra) if i in rb])
            n = len([i for i in ra if i in rb])
            pairs.append(f"| {name} | {a} - {b} | {n} | {mean:+.4f} | [{mean - half:+.4f}, {mean + half:+.4f}] |")
    print("\n| fleet | variant | served | catalogue | urgent | clairvoyant bound | regret | cloud-lost | urgent "
          "latency h | churn | s a call | valid |\n|---|---|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    print("\n| fleet | pair | realizations | served, mean difference | 95% interval |\n|---|---|---|---|---|")
    print("\n".join(pairs))


if __name__ == "__main__":
    main()
