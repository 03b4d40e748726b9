"""The learned fleet scheduler against its ablation, the fleet greedy, the fleet solver at equal wall time and the
bound, on the aeossp evaluation cases and on held-out generated fleets.

For each fleet (an aeossp case of ``--astro`` ``--splits``, read and its opportunities computed; or a fleet directory
of ``--fleets``), the clock starting when reading starts:

* ``greedy``: the fleet greedy (``eosp solve --solver greedy``);
* ``features``: the features-only decoder (``--solver fleet-features``: the fleet policy's decoder with the best
  hand rule over the same features, no network), raw decode and after the ``fill`` polish;
* ``policy``: the fleet policy's greedy decode (``--solver fleet-policy``), raw and after ``fill``; decisions a
  second; wall and CPU seconds end to end (reading included);
* ``sample T``: ``--solver fleet-sample --time-limit`` so that reading plus solving take T seconds (``--sample``);
* ``fleet T``: the fleet solver (``--solver fleet``) given the same end-to-end T (the largest of ``--sample``), with
  its bound;
* the fleet solver's 120 s WCR and bound of docs/results.md (the aeossp cases), else of a run of ``--bound-time``
  seconds here, and the reference solvers' WCR (benchmarks/bench_fleet.py's REFERENCE), where known;
* ``bound``: the lower of the two bounds, and ``policy / bound`` (``--table`` recomputes both from the bounds
  recorded now);
* with ``--verify``, the astro-reason verifier on the fleet-policy and the longest fleet-sample schedules.

Every schedule is checked by the fleet checker.  Writes ``OUT/results.csv`` and ``OUT/results.md``; wall times
are upper bounds on a shared machine (the CPU seconds of the fleet policy are printed beside them).

    python benchmarks/bench_fleet_policy.py --astro ASTRO --splits test test_easy test_hard test_horizon_2022 \\
        --fleets data/fleets/gen-test/s20 data/fleets/gen-test/s200 --sample 10 30 --verify --out runs/bench-fp
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import time
from pathlib import Path

# the fleet solver at 120 s (docs/results.md, "Fleets: the astro-reason aeossp_standard benchmark"): the better WCR
# and the lowest bound (rounded up) of its 120 s tables (2026-12-03, prices from 0; 2026-12-05, the anytime curves
# with the ceiling prices, with the uniform and the weighted price step, with the small-pass sweep; 2026-12-05, the
# prices by column generation, two runs): every one is valid, so is the lowest
FLEET_120S = {
    "test/case_0001": (0.7120, 0.7121), "test/case_0002": (0.7879, 0.7889), "test/case_0003": (0.7946, 0.7953),
    "test/case_0004": (0.7446, 0.7453), "test/case_0005": (0.7967, 0.7981), "test_easy/case_0001": (0.8831, 0.8855),
    "test_easy/case_0002": (0.8477, 0.8508), "test_easy/case_0003": (0.8234, 0.8251),
    "test_easy/case_0004": (0.8336, 0.8345), "test_easy/case_0005": (0.8028, 0.8050),
    "test_hard/case_0001": (0.8499, 0.8624), "test_hard/case_0002": (0.8277, 0.8387),
    "test_hard/case_0003": (0.8786, 0.8844), "test_hard/case_0004": (0.8830, 0.8876),
    "test_hard/case_0005": (0.8474, 0.8642), "test_horizon_2022/case_0001": (0.7274, 0.7275),
    "test_horizon_2022/case_0002": (0.7719, 0.7748), "test_horizon_2022/case_0003": (0.7842, 0.7848),
    "test_horizon_2022/case_0004": (0.7853, 0.7862), "test_horizon_2022/case_0005": (0.8052, 0.8061),
}


def read(path: Path):
    """(fleet data as the kind reads it, seconds): an aeossp case (opportunities computed) or a fleet directory."""
    from eosp.envs.constellation import read_fleet_dir
    from eosp.kinds.fleet.kind import FleetData

    t0 = time.perf_counter()
    fleet, opps = read_fleet_dir(path)
    return FleetData(fleet, opps, Path(path) / "meta.json"), time.perf_counter() - t0


def verify(astro: str, case: Path, schedule, fleet, out: Path) -> tuple[bool, float | None]:
    """The astro-reason verifier's verdict on `schedule` (written as OUT, an aeossp solution.json)."""
    from eosp.fleet.aeossp import write_solution

    write_solution(schedule, fleet.horizon, out, overwrite=True)
    r = subprocess.run([sys.executable, "-m", "benchmarks.aeossp_standard.verifier.run", str(case.resolve()),
                        str(out.resolve())], cwd=astro, capture_output=True, text=True)
    v = json.loads(r.stdout) if r.stdout.strip().startswith("{") else {"valid": False, "metrics": {}}
    return bool(v.get("valid")), v.get("metrics", {}).get("WCR")


def run_fleet(name: str, path: Path, agent: tuple, a: argparse.Namespace) -> dict:
    from bench_fleet import REFERENCE  # the sibling script: a script's folder is on sys.path
    from eosp.kinds.fleet.config import (FleetConfig, FleetFeaturesConfig, FleetPolicyConfig, FleetSampleConfig,
                                         GreedyConfig)
    from eosp.kinds.fleet.policy import solve_features, solve_policy, solve_sample
    from eosp.kinds.fleet.solve import solve_fleet, solve_greedy

    row: dict = {"fleet": name}
    c0, t0 = time.process_time(), time.perf_counter()
    data, t_read = read(path)
    res = solve_policy(data, FleetPolicyConfig(), agent=agent)
    row |= {"policy_wall_s": time.perf_counter() - t0, "policy_cpu_s": time.process_time() - c0}
    assert res.verdict.valid
    policy_schedule = res.schedule
    row |= {"satellites": len(data.fleet.satellites), "tasks": len(data.fleet.tasks), "read_s": t_read,
            "raw": res.info["raw_wcr"], "policy": res.value, "decisions": res.info["decisions"],
            "decisions_per_s": res.info["decisions_per_s"]}
    t1 = time.perf_counter()
    res = solve_features(data, FleetFeaturesConfig())
    assert res.verdict.valid
    row |= {"features_raw": res.info["raw_wcr"], "features": res.value, "features_s": t_read + time.perf_counter() - t1}
    t1 = time.perf_counter()
    res = solve_greedy(data, GreedyConfig())
    assert res.verdict.valid
    row |= {"greedy": res.value, "greedy_s": t_read + time.perf_counter() - t1}
    sample_schedule = None
    for limit in a.sample:
        t1 = time.perf_counter()
        res = solve_sample(data, FleetSampleConfig(time_limit=max(1.0, limit - t_read)), agent=agent)
        assert res.verdict.valid
        row |= {f"sample{limit:g}": res.value, f"sample{limit:g}_raw": res.info["raw_wcr"],
                f"sample{limit:g}_episodes": res.info["episodes"],
                f"sample{limit:g}_s": t_read + time.perf_counter() - t1}
        sample_schedule = res.schedule
    t_eq = max(a.sample)
    t1 = time.perf_counter()
    res = solve_fleet(data, FleetConfig(time_limit=max(1.0, t_eq - t_read)))
    row |= {f"fleet{t_eq:g}": res.value, f"fleet{t_eq:g}_bound": res.bound, f"fleet{t_eq:g}_s":
            t_read + time.perf_counter() - t1}
    known = FLEET_120S.get(name)
    if known is None and a.bound_time > 0:  # no recorded run: the fleet solver for --bound-time seconds
        long = solve_fleet(data, FleetConfig(time_limit=a.bound_time))
        known = (long.value, long.bound)
    row |= {"fleet120": known[0] if known else None, "bound120": known[1] if known else None}
    with_bound(row, t_eq)
    ref = REFERENCE.get(name, {})
    row |= {"greedy_lns": ref.get("greedy_lns", (None,))[0], "mwis": ref.get("mwis_conflict_graph", (None,))[0]}
    if a.verify and a.astro and "/" in name and (path / "tasks.yaml").exists():
        out = Path(a.out) / name
        out.mkdir(parents=True, exist_ok=True)
        row["policy_verifier_valid"], row["policy_verifier_wcr"] = verify(a.astro, path, policy_schedule, data.fleet,
                                                                          out / "policy.json")
        row["sample_verifier_valid"], row["sample_verifier_wcr"] = verify(a.astro, path, sample_schedule, data.fleet,
                                                                          out / "sample.json")
    return row


def with_bound(row: dict, t_eq: float) -> dict:
    """`row` with ``bound``, the lower of its fleet solver's bound at `t_eq` and the recorded 120 s one (FLEET_120S
    where it has the fleet, which the rows of an earlier results.csv get too), and ``policy / bound``."""
    if row["fleet"] in FLEET_120S:
        row["fleet120"], row["bound120"] = FLEET_120S[row["fleet"]]
    bounds = [float(b) for b in (row[f"fleet{t_eq:g}_bound"], row["bound120"]) if b not in (None, "")]
    row["bound"] = min(bounds) if bounds else None
    row["policy_over_bound"] = float(row["policy"]) / row["bound"] if row["bound"] else None
    return row


def markdown(rows: list[dict], samples: list[float]) -> str:
    """The table of docs/results.md ("The learned fleet scheduler")."""
    f = (lambda x: "-" if x in (None, "") else f"{float(x):.4f}")
    t_eq = f"{max(samples):g}"
    head = ["fleet", "sat / tasks", "raw decode", "fleet-policy (wall s)", "decisions/s"] + \
        [f"fleet-sample {s:g} s (episodes)" for s in samples] + \
        ["features-only raw", "features-only", "fleet greedy", f"fleet solver {t_eq} s", f"its bound {t_eq} s",
         "fleet solver 120 s", "bound", "fleet-policy / bound", "mwis"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["fleet"], f"{int(r['satellites'])} / {int(r['tasks']):,}", f(r["raw"]),
                 f"{f(r['policy'])} ({float(r['policy_wall_s']):.0f})", f"{float(r['decisions_per_s']):.0f}"] + \
            [f"{f(r[f'sample{s:g}'])} ({int(r[f'sample{s:g}_episodes'])})" for s in samples] + \
            [f(r["features_raw"]), f(r["features"]), f(r["greedy"]), f(r[f"fleet{t_eq}"]),
             f(r[f"fleet{t_eq}_bound"]), f(r["fleet120"]), f(r["bound"]), f(r["policy_over_bound"]), f(r["mwis"])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--astro", default="", help="a checkout of astro-reason (commit ffd1e89)")
    p.add_argument("--splits", nargs="*", default=["test", "test_easy", "test_hard", "test_horizon_2022"])
    p.add_argument("--cases", nargs="*", default=[], help="only these case names (e.g. case_0001)")
    p.add_argument("--fleets", nargs="*", default=[], help="fleet directories, or directories of them")
    p.add_argument("--checkpoint", default="", help="a fleet policy checkpoint; empty: the shipped one")
    p.add_argument("--sample", type=float, nargs="+", default=[10.0, 30.0], help="end-to-end seconds of fleet-sample")
    p.add_argument("--bound-time", type=float, default=120.0,
                   help="seconds of the fleet solver for the WCR and bound of fleets without a recorded run (0: none)")
    p.add_argument("--verify", action="store_true", help="run the astro-reason verifier on the policy's schedules")
    p.add_argument("--out", default="runs/bench-fleet-policy")
    p.add_argument("--table", default="", help="only print the table of this results.csv of an earlier run")
    a = p.parse_args()
    if a.table:
        print(markdown([with_bound(r, max(a.sample)) for r in csv.DictReader(open(a.table))], a.sample))
        return
    import torch

    from eosp.envs.constellation import expand_fleets
    from eosp.models.pretrained import load_fleet_pretrained

    torch.set_num_threads(1)
    agent = load_fleet_pretrained(a.checkpoint)
    todo = []
    if a.astro:
        root = Path(a.astro) / "benchmarks" / "aeossp_standard" / "dataset" / "cases"
        todo += [(f"{s}/{c.name}", c) for s in a.splits for c in sorted((root / s).glob("case_*"))
                 if not a.cases or c.name in a.cases]
    todo += [(f"{p.parent.name}/{p.name}", p) for p in expand_fleets(a.fleets)] if a.fleets else []
    Path(a.out).mkdir(parents=True, exist_ok=True)
    rows = []
    for name, path in todo:
        rows.append(run_fleet(name, path, agent, a))
        print(json.dumps(rows[-1]), flush=True)
        keys = list(dict.fromkeys(k for r in rows for k in r))
        with open(Path(a.out) / "results.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=keys)
            w.writeheader()
            w.writerows(rows)
    (Path(a.out) / "results.md").write_text(markdown(rows, a.sample))
    print(markdown(rows, a.sample))


if __name__ == "__main__":
    main()
