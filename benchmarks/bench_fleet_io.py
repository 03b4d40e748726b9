"""Fleets: time and peak memory of importing an aeossp case (or generating a fleet), solving it greedily and validating.

    nice python benchmarks/bench_fleet_io.py CASE_DIR --work /tmp/bench_fleet
    nice python benchmarks/bench_fleet_io.py --generate 200 20000 24 --work /tmp/bench_fleet_200

CASE_DIR is an aeossp_standard case directory (e.g. an astro-reason checkout's
benchmarks/aeossp_standard/dataset/cases/test_hard/case_0001: 40 satellites, ~4,000 tasks).
Each step runs in its own child process, which reports its phase times and its peak RSS
(``resource.getrusage`` maxrss):

* ``import``: read the three YAML files, propagate every satellite over the horizon, compute
  opportunities and passes, write the fleet directory;
* ``generate`` (instead of ``import``): draw the fleet, compute opportunities and passes, write the fleet
  directory, build every pass graph (what the fleet solver builds first);
* ``solve``: read the fleet directory, greedy, check, write the schedule;
* ``validate``: read the fleet directory and the schedule, check (``validate`` alone timed too).

Prints a Markdown table; ``--json FILE`` also writes the rows.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

IMPORT = """
import json, resource, sys, time
t0 = time.perf_counter()
from eosp.fleet.aeossp import read_case
from eosp.fleet.geometry import Geometry
from eosp.fleet.io import write_fleet
from eosp.fleet.opportunities import compute
t1 = time.perf_counter(); fleet = read_case(sys.argv[1])
t2 = time.perf_counter(); geo = Geometry(fleet); opps = compute(fleet, geo)
t3 = time.perf_counter(); write_fleet(fleet, opps, sys.argv[2], overwrite=True)
t4 = time.perf_counter()
print(json.dumps({"step": "import", "total_s": t4 - t0, "read_yaml_s": t2 - t1, "opportunities_s": t3 - t2,
                  "write_s": t4 - t3, "satellites": len(fleet.satellites), "tasks": len(fleet.tasks),
                  "opportunities": len(opps), "passes": opps.n_passes,
                  "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""

GENERATE = """
import json, resource, sys, time
t0 = time.perf_counter()
from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.geometry import Geometry
from eosp.fleet.io import write_fleet
from eosp.fleet.opportunities import compute
from eosp.fleet.passgraph import build_passes
from eosp.fleet.slew import LineOfSight
sats, tasks, hours = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
t1 = time.perf_counter(); fleet = generate(FleetGenConfig(satellites=sats, tasks=tasks, hours=hours))
t2 = time.perf_counter(); geo = Geometry(fleet); opps = compute(fleet, geo)
t3 = time.perf_counter(); write_fleet(fleet, opps, sys.argv[4], overwrite=True)
t4 = time.perf_counter(); passes = build_passes(fleet, opps, LineOfSight(fleet, geo))
t5 = time.perf_counter()
print(json.dumps({"step": "generate", "total_s": t5 - t0, "generate_s": t2 - t1, "opportunities_s": t3 - t2,
                  "write_s": t4 - t3, "pass_graphs_s": t5 - t4, "satellites": len(fleet.satellites),
                  "tasks": len(fleet.tasks), "opportunities": len(opps), "passes": opps.n_passes,
                  "pass_graph_nodes": int(sum(pg.graph.n_nodes for pg in passes)),
                  "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""

SOLVE = """
import json, resource, sys, time
t0 = time.perf_counter()
from eosp.fleet.check import validate
from eosp.fleet.geometry import Geometry
from eosp.fleet.greedy import solve
from eosp.fleet.io import read_fleet, write_schedule
fleet, opps = read_fleet(sys.argv[1]); geo = Geometry(fleet)
t1 = time.perf_counter(); sched = solve(fleet, opps, geo)
t2 = time.perf_counter(); res = validate(fleet, sched, geo)
write_schedule(sched, fleet, sys.argv[2], overwrite=True, info={"value": res.metrics["WCR"], "solver": "greedy"})
t3 = time.perf_counter()
print(json.dumps({"step": "solve", "total_s": t3 - t0, "greedy_s": t2 - t1, "actions": len(sched),
                  "valid": res.valid, "WCR": res.metrics["WCR"], "CR": res.metrics["CR"],
                  "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""

VALIDATE = """
import json, resource, sys, time
t0 = time.perf_counter()
from eosp.fleet.check import validate
from eosp.fleet.io import read_fleet, read_schedule
fleet, _ = read_fleet(sys.argv[1], with_opportunities=False)
sched, _ = read_schedule(sys.argv[2], fleet)
t1 = time.perf_counter(); res = validate(fleet, sched)
t2 = time.perf_counter()
print(json.dumps({"step": "validate", "total_s": t2 - t0, "validate_s": t2 - t1, "actions": len(sched),
                  "valid": res.valid, "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def run(snippet: str, *args: str) -> dict:
    out = subprocess.run([sys.executable, "-c", snippet, *args], check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", type=Path, nargs="?", help="an aeossp case directory (or use --generate)")
    ap.add_argument("--generate", nargs=3, metavar=("SATELLITES", "TASKS", "HOURS"), default=None,
                    help="instead of a case: generate a fleet (eosp generate --fleet, seed 0) and build its pass graphs")
    ap.add_argument("--work", type=Path, default=Path("/tmp/bench_fleet"))
    ap.add_argument("--json", type=Path, default=None)
    ns = ap.parse_args(argv)
    ns.work.mkdir(parents=True, exist_ok=True)
    fleet_dir, schedule = ns.work / "fleet", ns.work / "greedy.parquet"
    if (ns.case is None) == (ns.generate is None):
        ap.error("give a case directory or --generate SATELLITES TASKS HOURS")
    first = run(IMPORT, str(ns.case), str(fleet_dir)) if ns.case else run(GENERATE, *ns.generate, str(fleet_dir))
    rows = [first, run(SOLVE, str(fleet_dir), str(schedule)),
            run(VALIDATE, str(fleet_dir), str(schedule))]
    print(f"case: {ns.case or 'generated ' + ' x '.join(ns.generate)}")
    print("| step | wall s | peak RSS MB | details |")
    print("|---|---|---|---|")
    for r in rows:
        details = ", ".join(f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()
                            if k not in ("step", "total_s", "maxrss_mb"))
        print(f"| {r['step']} | {r['total_s']:.1f} | {r['maxrss_mb']:.0f} | {details} |")
    if ns.json:
        ns.json.write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
