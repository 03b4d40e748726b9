"""The regional_coverage table: the greedy, the MIP and the coverage search on every case, judged by the
benchmark's own verifier.

Each solve is ``eosp solve CASE --solver S [--time-limit T] --out F`` in its own process, timed from the
process's start to its exit (reading the case and building the candidates included).  Each solution is then
judged twice: by the benchmark's verifier (``verifier.py`` of a copy of astro-reason, run by this Python: it
needs brahe, numpy, PyYAML and shapely, which eosp installs) and by eosp's checker; the row records both
verdicts and every ranking metric, and whether they agree to 1e-9.

    python experiments/regional_table.py --astro-reason PATH_OR_GIT_DIR --work WORK \\
        [--limits 10 60 300] [--cases case_0001 ...] > table.md

Cases of their generator under other seeds (it runs offline: vendored TLEs and regions):
    python -m benchmarks.regional_coverage.generator.run SPLITS.yaml --output-dir OUT   (in their folder; the
    splits file with another seed), then --case-dirs OUT/cases/test/case_000*.

PATH_OR_GIT_DIR: a checkout of github.com/Mtrya/astro-reason, or a bare git directory of it (its
benchmarks/regional_coverage is then exported into WORK; nothing of it is copied into this repository).
Rows go to WORK/regional.jsonl (a run resumes: a row already there is not solved again).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

HERE = "benchmarks/regional_coverage"


def prepare(source: Path, work: Path) -> Path:
    """The benchmark's folder: in a checkout, or exported from a bare git directory into `work`."""
    if (source / HERE / "verifier.py").is_file():
        return source / HERE
    out = work / "astro-reason"
    if not (out / HERE / "verifier.py").is_file():
        out.mkdir(parents=True, exist_ok=True)
        tar = subprocess.run(["git", "--git-dir", str(source), "archive", "HEAD", HERE], check=True,
                             capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(out)], input=tar, check=True)
    return out / HERE


def theirs(bench: Path, case: Path, sol: Path) -> dict:
    import os

    code = "import json, sys, verifier; print(json.dumps(verifier.verify_solution(sys.argv[1], sys.argv[2])))"
    t = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code, str(case), str(sol)], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(bench)}).stdout
    rep = json.loads(out.strip().splitlines()[-1])
    rep["seconds"] = time.perf_counter() - t
    return rep


def mine(case: Path, sol: Path) -> dict:
    from eosp.regional.check import check
    from eosp.regional.read import read_case, read_solution

    rep = check(read_case(str(case)), read_solution(str(sol)))
    return {"valid": rep.valid, "metrics": rep.metrics, "violations": rep.violations}


METRICS = ("coverage_ratio", "weighted_coverage_ratio", "num_actions", "min_battery_wh")


def run(case: Path, solver: str, limit: float | None, work: Path, bench: Path) -> dict:
    sol = work / f"{case.parent.parent.name}-{case.name}-{solver}-{limit or 0:g}.json"
    cmd = ["eosp", "solve", str(case), "--solver", solver, "--out", str(sol), "--overwrite"]
    if limit:
        cmd += ["--time-limit", str(limit)]
    t = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if p.returncode != 0:
        return {"case": str(case), "solver": solver, "limit": limit, "error": p.stderr.strip()}
    info = json.loads(sol.read_text()).get("eosp_info", {})
    a, b = theirs(bench, case, sol), mine(case, sol)
    agree = a["valid"] == b["valid"] and all(abs(float(a["metrics"][k]) - float(b["metrics"][k])) <= 1e-9
                                             for k in METRICS)
    return {"case": str(case), "solver": solver, "limit": limit, "wall_s": round(wall, 2), "line": p.stdout.strip(),
            "bound": info.get("bound"), "valid_theirs": a["valid"], "valid_eosp": b["valid"],
            **{k: a["metrics"][k] for k in METRICS}, "agree_1e-9": agree, "their_verifier_s": round(a["seconds"], 1),
            "violations": a["violations"][:3]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--astro-reason", required=True, type=Path)
    ap.add_argument("--work", required=True, type=Path)
    ap.add_argument("--limits", nargs="+", type=float, default=[10.0, 60.0, 300.0])
    ap.add_argument("--cases", nargs="*", default=None, help="names of the public cases to run (default: all)")
    ap.add_argument("--case-dirs", nargs="*", type=Path, default=None,
                    help="case directories to run instead of the public ones (their generator's output)")
    ap.add_argument("--solvers", nargs="+", default=["greedy", "mip", "coverage"])
    a = ap.parse_args(argv)
    a.work.mkdir(parents=True, exist_ok=True)
    bench = prepare(a.astro_reason, a.work)
    cases = a.case_dirs or sorted((bench / "dataset/cases/test").iterdir())
    if a.cases:
        cases = [c for c in cases if c.name in a.cases]
    rows_path = a.work / "regional.jsonl"
    done = {(r["case"], r["solver"], r["limit"]) for r in map(json.loads, rows_path.read_text().splitlines())} \
        if rows_path.exists() else set()
    for case in cases:
        for solver in a.solvers:
            for limit in ([None] if solver == "greedy" else a.limits):
                if (str(case), solver, limit) in done:
                    continue
                row = run(case, solver, limit, a.work, bench)
                with rows_path.open("a") as fh:
                    fh.write(json.dumps(row) + "\n")
                print(json.dumps(row), file=sys.stderr, flush=True)
    rows = [json.loads(x) for x in rows_path.read_text().splitlines()]
    print("| case | solver | time limit s | wall s | valid (their verifier) | coverage_ratio | weighted | actions | "
          "bound | gap | agree |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "error" in r:
            print(f"| {r['case']} | {r['solver']} | {r['limit']} | error: {r['error']} |")
            continue
        b = r.get("bound")
        gap = "" if b is None else f"{(b - r['coverage_ratio']) / b:.2%}"
        print(f"| {r['case']} | {r['solver']} | {r['limit'] or ''} | {r['wall_s']:.1f} | "
              f"{'yes' if r['valid_theirs'] else 'no'} | {r['coverage_ratio']:.6f} | {r['weighted_coverage_ratio']:.6f} "
              f"| {r['num_actions']} | {'' if b is None else f'{b:.6f}'} | {gap} | {'yes' if r['agree_1e-9'] else 'NO'} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
