"""Anytime quality of the fleet solver before and after a change of its code: the same cases at the same time
limit, the two versions run one after the other (interleaved, A B A B ...) so that the machine's drift falls on
both alike, each run a fresh process through the command line.

    python experiments/anytime_pairs.py --fleets FLEET_DIR ... --before /tmp/old --time-limit 10 --repeats 3

``--before`` is a folder on the import path that holds the earlier code as a package ``eosp`` (e.g. ``git archive
REV`` laid out as eosp/<folder>, as tests/test_architecture.py's wheel build lays it out); the "after" runs import
the installed package.  Each version solves every case once before the measured runs (its numba kernels compiled
and cached).  Prints one row per case (mean WCR of each version, the difference) and the mean difference over
the cases; writes every run as JSON lines to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path


def solve(fleet: str, before: str | None, time_limit: float, out: Path) -> dict:
    """`eosp solve FLEET --solver fleet --time-limit T` in a fresh process (the earlier code first on the import
    path when `before`): its WCR, bound and rounds from the schedule file's metadata."""
    env = dict(os.environ)
    if before:
        env["PYTHONPATH"] = before + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, "-m", "eosp.cli", "solve", fleet, "--solver", "fleet", "--time-limit", str(time_limit),
           "--out", str(out), "--overwrite"]
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited {r.returncode}: {r.stderr.strip()[-400:]}")
    import pyarrow.parquet as pq

    md = pq.read_schema(out).metadata or {}
    return {k: json.loads(md[k.encode()]) if k.encode() in md else None for k in ("value", "bound", "rounds")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fleets", nargs="+", required=True, help="fleet directories (eosp import of aeossp cases)")
    ap.add_argument("--before", required=True, help="folder holding the earlier code as package eosp")
    ap.add_argument("--time-limit", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="runs/anytime-pairs.jsonl")
    args = ap.parse_args(argv)
    versions = {"before": args.before, "after": None}
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in versions.items():  # compile and cache each version's kernels
            solve(args.fleets[0], path, args.time_limit, Path(tmp) / f"warm-{name}.parquet")
        for rep in range(args.repeats):
            for fleet in args.fleets:
                order = list(versions) if rep % 2 == 0 else list(versions)[::-1]
                for name in order:
                    got = solve(fleet, versions[name], args.time_limit, Path(tmp) / "s.parquet")
                    runs.append({"fleet": fleet, "version": name, "repeat": rep, **got})
                    print(json.dumps(runs[-1]), flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("".join(json.dumps(r) + "\n" for r in runs))
    diffs = []
    print("\n| case | before | after | after - before |\n|---|---|---|---|")
    for fleet in args.fleets:
        mean = {v: sum(r["value"] for r in runs if r["fleet"] == fleet and r["version"] == v) / args.repeats
                for v in versions}
        diffs.append(mean["after"] - mean["before"])
        print(f"| {Path(fleet).name} | {mean['before']:.4f} | {mean['after']:.4f} | {diffs[-1]:+.4f} |")
    print(f"\nmean over {len(diffs)} cases: after - before = {sum(diffs) / len(diffs):+.5f} "
          f"({args.repeats} repeats each, {args.time_limit:g} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
