"""The features-only decoder's rule: the best linear score over the fleet observation's node features.

    python experiments/fleet_rules.py --demos data/demos/train --out runs/fleet-rules.csv

Every rule of :data:`eosp.solvers.fleet_policy.FEATURE_RULES`, and a grid around the soonest-start rule (weights
of ``weight``, ``other_passes_rel`` and ``weight_share``, or of ``weight``, ``other_passes_rel`` and the battery's
``headroom_after``, added to ``-earliest_start``), decodes every training fleet of the demo sets greedily (no
network); prints the mean WCR of each (and its ratio to the fleet solver's schedules of the demo set), best first,
and writes the table (90 grid rules and 5 named ones on 25 fleets: about 6 minutes on a quiet machine).  The best
rule on the first training fleets is the features-only decoder's default (``DEFAULT_RULE``): the ablation the
network must beat (docs/results.md compares it with the best on later training sets).
"""

from __future__ import annotations

import argparse
import csv
import itertools
import time
from pathlib import Path

import numpy as np


def grid() -> dict[str, dict[str, float]]:
    from eosp.solvers.fleet_policy import FEATURE_RULES, SKIP_LAST

    rules = dict(FEATURE_RULES)
    for w, p, s in itertools.product((0.0, 0.05, 0.1, 0.2, 0.4, 1.0), (0.0, 0.05, 0.1, 0.2, 0.4, 0.8), (0.0, 1.0)):
        rules[f"grid_w{w:g}_p{p:g}_s{s:g}"] = {"earliest_start": -1.0, "weight": w, "other_passes_rel": -p,
                                               "weight_share": s, **SKIP_LAST}
    for w, p, h in itertools.product((0.2, 0.4, 1.0), (0.1, 0.2, 0.4), (0.3, 1.0)):  # the battery left after the task
        rules[f"grid_w{w:g}_p{p:g}_h{h:g}"] = {"earliest_start": -1.0, "weight": w, "other_passes_rel": -p,
                                               "headroom_after": h, **SKIP_LAST}
    return rules


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--demos", nargs="+", required=True, help="demo sets (jobs/build_fleet_demos.py) of training fleets")
    p.add_argument("--out", default="runs/fleet-rules.csv")
    a = p.parse_args()
    from eosp.config import FleetEnvConfig
    from eosp.envs.constellation import load_fleet
    from eosp.solvers.fleet_policy import decode, rule_scorer
    from eosp.training.fleet_demos import read_demo_set

    records = [r for d in a.demos for r in read_demo_set(d)]
    fleets = [load_fleet(r["fleet"]) for r in records]
    expert = np.array([r["wcr"] for r in records])
    rows = []
    t0 = time.perf_counter()
    for name, rule in grid().items():
        wcr = np.array([decode(rule_scorer(rule), f, FleetEnvConfig()).value for f in fleets])
        rows.append({"rule": name, "mean_wcr": wcr.mean(), "mean_ratio_to_fleet_solver": float(np.mean(wcr / expert)),
                     "min_ratio": float(np.min(wcr / expert)), **{k: v for k, v in rule.items()}})
        print(f"{name:32s} WCR {wcr.mean():.4f}  / fleet solver {rows[-1]['mean_ratio_to_fleet_solver']:.4f} "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
    rows.sort(key=lambda r: -r["mean_ratio_to_fleet_solver"])
    keys = sorted({k for r in rows for k in r}, key=lambda k: (k not in ("rule", "mean_wcr"), k))
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    with open(a.out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    print(f"best: {rows[0]['rule']} (mean ratio to the fleet solver {rows[0]['mean_ratio_to_fleet_solver']:.4f}); "
          f"{len(fleets)} fleets, {len(rows)} rules -> {a.out}")


if __name__ == "__main__":
    main()
