"""The paper's "single problem" experiment: overfit one instance, compare with Greedy and RAMP.

    python experiments/single_problem.py --family uniform --seed 500 --mode unitary --iterations 40
    python experiments/single_problem.py --family conflict --seed 502 --mode utility --iterations 40

Generates the instance (100 acquisitions by default), trains on it alone with
validation on the same instance (greedy decoding), and prints the learning curve
of the policy's score against Greedy's and RAMP's.  Extra arguments go to
jobs/train.py.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--family", default="uniform")
    p.add_argument("--seed", type=int, default=500)
    p.add_argument("--n", type=int, default=100)
    p.add_argument("--mode", default="unitary", choices=["unitary", "utility"])
    p.add_argument("--iterations", type=int, default=40)
    p.add_argument("--data", default="data/single")
    a, extra = p.parse_known_args()

    from eosp.config import family_config
    from eosp.instances.generator import generate
    from eosp.shards.io import write_shard

    name = f"{a.family}-n{a.n}-s{a.seed}"
    shard = ROOT / a.data / name / "shard-00000.parquet"
    if not shard.exists():
        write_shard(shard, [generate(family_config(a.family, a.n, a.seed))])
    run = f"single-{name}-{a.mode}"
    cmd = [sys.executable, str(ROOT / "jobs" / "train.py"), "--train.train-data", str(shard.parent),
           "--train.val-data", str(shard.parent), "--train.iterations", str(a.iterations),
           "--train.run-name", run, "--env.reward", "unitary" if a.mode == "unitary" else "normalized",
           "--env.max-acquisitions", str(a.n), "--train.validate-every", "2", "--train.checkpoint-every", "2",
           "--train.experiment", "single-problem", "--train.overwrite", "true", *extra]  # a rerun replaces its run
    print(" ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, cwd=ROOT)
    hist = json.loads((ROOT / "runs" / run / "run.json").read_text())["history"]
    val = [h for h in hist if "val/policy_mean" in h]
    print(f"\n{name}, {a.mode} mode: greedy {val[-1]['val/greedy_mean']:.6g}, ramp {val[-1]['val/ramp_mean']:.6g}")
    print("| iteration | policy | policy / greedy | policy / ramp |\n|---|---|---|---|")
    for h in val:
        print(f"| {h['iteration']} | {h['val/policy_mean']:.6g} | {h['val/ratio_to_greedy']:.4f} | "
              f"{h['val/ratio_to_ramp']:.4f} |")
    best = max(h["val/policy_mean"] for h in val)
    print(f"best policy {best:.6g}: {best / val[-1]['val/greedy_mean']:.4f} x greedy, "
          f"{best / val[-1]['val/ramp_mean']:.4f} x ramp")


if __name__ == "__main__":
    main()
