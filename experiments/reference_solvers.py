"""Run astro-reason's reference solvers on aeossp cases and score them with the benchmark's verifier.

The fleet benchmark (benchmarks/bench_fleet.py) compares against reference figures; this script re-measures
them on this machine: each solver with its shipped configuration except an end-to-end budget
(``total_time_budget_s``, default 60 s) and one worker (``candidate_workers``, ``local_search_workers``,
``graph_workers`` all 1).  Wall time is end to end (the solvers' candidate generation included), verifier
excluded.  Needs a checkout of astro-reason (``--astro``, with benchmarks/ and solvers/) and brahe, numpy and
PyYAML in this interpreter.

    python experiments/reference_solvers.py --astro /path/to/astro-reason --cases test/case_0001 test/case_0002 \
        --out runs/reference
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

SOLVERS = {
    "greedy_lns": {"candidate_workers": 1, "local_search_workers": 1},
    "mwis_conflict_graph": {"candidate_workers": 1, "graph_workers": 1},
}


def run(astro: Path, case: str, solver: str, budget: float, out: Path) -> dict:
    case_dir = (astro / "benchmarks/aeossp_standard/dataset/cases" / case).resolve()
    work = out / solver / case.replace("/", "_")
    config_dir = work / "config"
    sol_dir = work / "solution"
    config_dir.mkdir(parents=True, exist_ok=True)
    sol_dir.mkdir(parents=True, exist_ok=True)
    config = dict(SOLVERS[solver], total_time_budget_s=budget)
    (config_dir / "config.json").write_text(json.dumps(config, indent=1))
    solver_dir = astro / "solvers/aeossp_standard" / solver
    env = dict(os.environ, PYTHONPATH=str(solver_dir), MPLCONFIGDIR="/tmp/astroreason-matplotlib")
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "src.solve", "--case-dir", str(case_dir), "--config-dir",
                        str(config_dir.resolve()), "--solution-dir", str(sol_dir.resolve())],
                       cwd=solver_dir, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    (work / "solve.log").write_text(r.stdout + r.stderr)
    sol = sol_dir / "solution.json"
    if r.returncode != 0 or not sol.exists():
        return {"case": case, "solver": solver, "valid": False, "wall_s": round(wall, 1),
                "error": (r.stderr.strip().splitlines() or ["no output"])[-1]}
    v = subprocess.run([sys.executable, "-m", "benchmarks.aeossp_standard.verifier.run", str(case_dir),
                        str(sol.resolve())], cwd=astro, capture_output=True, text=True)
    verdict = json.loads(v.stdout) if v.stdout.strip().startswith("{") else {"valid": False, "metrics": {}}
    (work / "verifier.json").write_text(json.dumps(verdict, indent=1))
    m = verdict.get("metrics", {})
    return {"case": case, "solver": solver, "valid": verdict.get("valid"), "WCR": m.get("WCR"), "CR": m.get("CR"),
            "wall_s": round(wall, 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--astro", required=True, type=Path, help="astro-reason checkout (benchmarks/ and solvers/)")
    ap.add_argument("--cases", nargs="+", default=["test/case_0001", "test/case_0002"], help="split/case names")
    ap.add_argument("--solvers", nargs="+", default=list(SOLVERS), choices=list(SOLVERS))
    ap.add_argument("--budget", type=float, default=60.0, help="total_time_budget_s given to each solver")
    ap.add_argument("--out", type=Path, default=Path("runs/reference"))
    args = ap.parse_args()
    rows = []
    for case in args.cases:
        for solver in args.solvers:
            row = run(args.astro, case, solver, args.budget, args.out)
            rows.append(row)
            print(json.dumps(row), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "reference.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
