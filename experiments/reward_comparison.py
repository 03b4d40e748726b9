"""Compare the reward variants (normalized, lexicographic, unitary) on the same data and seeds.

    python experiments/reward_comparison.py --iterations 30

Trains one agent per variant with jobs/train.py (same data, seed, iterations and
PPO settings), decodes the validation instances with each best checkpoint, and
compares them class by class with Greedy and RAMP (utility mode) on the same
instances: acquisitions scheduled per priority class and utility per class.  Writes
a Markdown report and plots (PNG, SVG) to runs/reward-comparison/ and logs them to
MLflow (experiment "reward-comparison").  Extra arguments go to jobs/train.py.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

VARIANTS = ("normalized", "lexicographic", "unitary")


def per_class(inst, nodes) -> tuple:
    import numpy as np

    from eosp.config import N_CLASSES

    acq = inst.node_acq[nodes] if len(nodes) else np.zeros(0, dtype=int)
    prio = np.clip(inst.priorities()[acq], 0, N_CLASSES - 1)
    counts = np.bincount(prio, minlength=N_CLASSES)
    util = np.bincount(prio, weights=inst.acqs.utility[acq], minlength=N_CLASSES)
    return counts, util


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--iterations", type=int, default=30)
    p.add_argument("--train", default="data/cmp/train100")
    p.add_argument("--val", default="data/cmp/val100")
    p.add_argument("--family", default="conflict")
    p.add_argument("--out", default="runs/reward-comparison")
    p.add_argument("--skip-train", action="store_true")
    a, extra = p.parse_known_args()
    py = sys.executable
    for path, count, seed in ((a.train, 64, 60000), (a.val, 16, 65000)):
        if not (ROOT / path / "manifest.json").exists():
            subprocess.run([py, str(ROOT / "jobs/build_shards.py"), "--out", str(ROOT / path), "--family", a.family,
                            "--n-acquisitions", "100", "--n-instances", str(count), "--seed", str(seed),
                            "--per-shard", "8"], check=True, cwd=ROOT)
    if not a.skip_train:
        for v in VARIANTS:
            subprocess.run([py, str(ROOT / "jobs/train.py"), "--train.train-data", str(ROOT / a.train),
                            "--train.val-data", str(ROOT / a.val), "--train.iterations", str(a.iterations),
                            "--train.run-name", f"reward-{v}", "--env.reward", v, "--env.max-acquisitions", "128",
                            "--train.experiment", "reward-comparison", "--train.seed", "0", *extra],
                           check=True, cwd=ROOT)
    report(a)


def report(a) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import mlflow
    import numpy as np
    import torch

    from eosp.envs.sources import expand_shards, prepare_instance
    from eosp.config import CLASS_UTILITIES, N_CLASSES
    from eosp.models.checkpoint import load_agent
    from eosp.shards.io import read_instances
    from eosp.solvers.base import run_solver
    from eosp.solvers.policy import rollout

    torch.set_num_threads(1)
    insts = read_instances(expand_shards([str(ROOT / a.val)]))
    methods: dict[str, list] = {}
    for s in ("greedy", "ramp"):
        methods[s] = [per_class(i, run_solver(s, i, mode="utility").nodes) for i in insts]
    for v in VARIANTS:
        agent, env_cfg, _ = load_agent(ROOT / "runs" / f"reward-{v}" / "checkpoints" / "best")
        methods[v] = [per_class(i, rollout(agent, prepare_instance(i, env_cfg.prune), env_cfg)[0]) for i in insts]
    out = ROOT / a.out
    out.mkdir(parents=True, exist_ok=True)
    names = list(methods)
    counts = {m: np.mean([c for c, _ in methods[m]], axis=0) for m in names}
    utils = {m: np.mean([u for _, u in methods[m]], axis=0) for m in names}
    total_u = {m: float(np.mean([u.sum() for _, u in methods[m]])) for m in names}
    total_n = {m: float(np.mean([c.sum() for c, _ in methods[m]])) for m in names}
    lex = {m: np.array([tuple(c) for c, _ in methods[m]]) for m in names}
    wins = {}
    for m in VARIANTS:
        w = t = l = 0
        for x, y in zip(lex[m], lex["greedy"]):
            d = np.flatnonzero(x != y)
            if d.size == 0:
                t += 1
            elif x[d[0]] > y[d[0]]:
                w += 1
            else:
                l += 1
        wins[m] = (w, t, l)
    lines = [f"# Reward variants on {len(insts)} validation instances ({a.family} family, 100 acquisitions)", "",
             "Mean over the instances.  Class 0 is the highest (utility 1e8).", "",
             "| method | utility | acquisitions | " + " | ".join(f"class {c} ({CLASS_UTILITIES[c]:g})"
                                                         for c in range(N_CLASSES)) + " |",
             "|" + "---|" * (3 + N_CLASSES)]
    for m in names:
        lines.append(f"| {m} | {total_u[m]:,.0f} | {total_n[m]:.2f} | "
                     + " | ".join(f"{counts[m][c]:.2f}" for c in range(N_CLASSES)) + " |")
    lines += ["", "Lexicographic comparison with Greedy (class counts compared from the highest class down): "
                  "wins / ties / losses", "", "| variant | W/T/L vs Greedy |", "|---|---|"]
    for m in VARIANTS:
        lines.append(f"| {m} | {wins[m][0]}/{wins[m][1]}/{wins[m][2]} |")
    best_u = max(VARIANTS, key=lambda m: total_u[m])
    best_n = max(VARIANTS, key=lambda m: total_n[m])
    lines += ["", f"Highest mean utility among the learned variants: **{best_u}**; most acquisitions: **{best_n}**."]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    fig, ax = plt.subplots(1, 2, figsize=(12, 4))
    w = 0.8 / len(names)
    for k, m in enumerate(names):
        ax[0].bar(np.arange(N_CLASSES) + k * w, counts[m], w, label=m)
        ax[1].bar(np.arange(N_CLASSES) + k * w, np.log10(np.maximum(utils[m], 1)), w, label=m)
    for axis, label in ((ax[0], "acquisitions per class"), (ax[1], "log10 utility per class")):
        axis.set_xticks(np.arange(N_CLASSES) + 0.4 - w / 2)
        axis.set_xticklabels([f"{c}\n{CLASS_UTILITIES[c]:g}" for c in range(N_CLASSES)])
        axis.set_xlabel("priority class")
        axis.set_ylabel(label)
    ax[0].legend()
    fig.tight_layout()
    for ext in ("png", "svg"):
        fig.savefig(out / f"per_class.{ext}", dpi=120)
    mlflow.set_tracking_uri(f"sqlite:///{(ROOT / 'mlflow.db').resolve()}")
    mlflow.set_experiment("reward-comparison")
    with mlflow.start_run(run_name="comparison"):
        for m in names:
            mlflow.log_metric(f"{m}/utility_mean", total_u[m])
            mlflow.log_metric(f"{m}/acquisitions_mean", total_n[m])
            for c in range(N_CLASSES):
                mlflow.log_metric(f"{m}/class_{c}_count", float(counts[m][c]))
                mlflow.log_metric(f"{m}/class_{c}_utility", float(utils[m][c]))
        for f in ("report.md", "per_class.png", "per_class.svg"):
            mlflow.log_artifact(str(out / f))
    print((out / "report.md").read_text())


if __name__ == "__main__":
    main()
