"""The paper's generalization experiments: train on many instances, test on unseen ones and on larger ones.

    python experiments/generalization.py --mode unitary --iterations 120

Data (built with jobs/build_shards.py if missing, family "uniform"):
data/gen/train100 (128 instances), val100 (16, checkpoint selection), test100 (32),
test300 (12), test1000 (4): all distinct seeds.  Trains with jobs/train.py, then
evaluates the best checkpoint with jobs/evaluate.py against Greedy and RAMP on every
test set (per-instance results, report, MLflow), and prints the reports.  Extra
arguments go to jobs/train.py.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SETS = {"train100": (100, 128, 10000), "val100": (100, 16, 25000), "test100": (100, 32, 20000),
        "test300": (300, 12, 30000), "test1000": (1000, 4, 40000)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mode", default="unitary", choices=["unitary", "utility"])
    p.add_argument("--iterations", type=int, default=120)
    p.add_argument("--family", default="uniform")
    p.add_argument("--data", default="data/gen")
    p.add_argument("--skip-train", action="store_true")
    p.add_argument("--tests", nargs="+", default=["test100", "test300", "test1000"])
    a, extra = p.parse_known_args()
    py = sys.executable
    for name, (n, count, seed) in SETS.items():
        out = ROOT / a.data / name
        if not (out / "manifest.json").exists():
            subprocess.run([py, str(ROOT / "jobs/build_shards.py"), "--out", str(out), "--n-acquisitions", str(n),
                            "--n-instances", str(count), "--seed", str(seed), "--family", a.family,
                            "--per-shard", str(max(1, min(16, count // 4)))], check=True, cwd=ROOT)
    run = f"gen-{a.family}-{a.mode}"
    if not a.skip_train:
        subprocess.run([py, str(ROOT / "jobs/train.py"), "--train.train-data", str(ROOT / a.data / "train100"),
                        "--train.val-data", str(ROOT / a.data / "val100"), "--train.iterations", str(a.iterations),
                        "--train.run-name", run, "--env.reward", "unitary" if a.mode == "unitary" else "normalized",
                        "--env.max-acquisitions", "128", "--train.experiment", "generalization", *extra],
                       check=True, cwd=ROOT)
    ck = ROOT / "runs" / run / "checkpoints" / "best"
    for test in a.tests:
        subprocess.run([py, str(ROOT / "jobs/evaluate.py"), "--data", str(ROOT / a.data / test), "--solvers",
                        "greedy", "ramp", "policy", "--checkpoint", str(ck), "--mode", a.mode, "--time-limit", "120",
                        "--out", str(ROOT / "runs" / run / f"eval-{test}"), "--experiment", "generalization"],
                       check=True, cwd=ROOT)


if __name__ == "__main__":
    main()
