"""Expert-guided training: PPO only, imitation only, imitation + PPO, at equal wall time.

    python experiments/expert_guided.py data                 # the mixed data sets and their demos
    python experiments/expert_guided.py data --more --modes unitary   # a second, larger mix (train2/)
    python experiments/expert_guided.py data --dense --modes utility  # a third mix, dense targets (train3/)
    python experiments/expert_guided.py data --large --modes utility  # a fourth, dense at 200-300 (train4/)
    python experiments/expert_guided.py data --scale        # unseen test sets at 300 and 1000 acquisitions
    python experiments/expert_guided.py run --minutes 10     # the comparison (unitary and utility)
    python experiments/expert_guided.py report               # table of every finished run

Data (``data/expert/``, every set from its own seeds, built by jobs/build_shards.py and
jobs/build_demos.py): a training mix of families (uniform, clusters, conflict), sizes
(50-300), time steps (1 s, 2 s) and slew models (piecewise, bang-coast-bang), so that
nothing learned depends on one generator setting; a validation mix for checkpoint
choice; unseen test sets per family at 100 acquisitions.  The parts are built in
``data/expert/parts/NAME/`` and linked into ``train/``, ``val/`` (a data set is a
directory of shards).

Runs (each given the same wall-time budget on this machine, one at a time):
``ppo`` (jobs/train.py from scratch), ``imitation`` (jobs/pretrain.py: behaviour
cloning + DAgger), ``imitation+ppo`` (half the budget each, PPO from the imitation
checkpoint).  Modes: unitary (reward unitary) and utility (reward normalized).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable

# name: (family, acquisitions, instances, seed, extra generator flags)
TRAIN = {
    "u100-s1-pw": ("uniform", 100, 48, 100_000, []),
    "u100-s2-bcb": ("uniform", 100, 48, 110_000, ["--instance.graph.step-s", "2", "--instance.satellite.slew-model",
                                                  "bang_coast_bang"]),
    "u50-s2-pw": ("uniform", 50, 32, 120_000, ["--instance.graph.step-s", "2"]),
    "c100-s1-pw": ("clusters", 100, 32, 130_000, []),
    "c200-s2-bcb": ("clusters", 200, 12, 140_000, ["--instance.graph.step-s", "2", "--instance.satellite.slew-model",
                                                   "bang_coast_bang"]),
    "x100-s2-pw": ("conflict", 100, 32, 150_000, ["--instance.graph.step-s", "2"]),
    "x100-s1-bcb": ("conflict", 100, 32, 160_000, ["--instance.satellite.slew-model", "bang_coast_bang"]),
    "u300-s2-pw": ("uniform", 300, 8, 170_000, ["--instance.graph.step-s", "2"]),
}
# A second training mix (``data --more``, linked into ``train2/``): more instances, and generator settings the
# first mix never varies (altitude, roll limit, slew rate and acceleration, a 3 s step, shorter acquisitions),
# so that a policy trained on both cannot lean on one orbit or one agility.  Used as
# ``--imitation.train-data data/expert/train data/expert/train2``.
A = "--instance.orbit.altitude-km"
ROLL = "--instance.satellite.roll-max-deg"
STEP = "--instance.graph.step-s"
BCB = ["--instance.satellite.slew-model", "bang_coast_bang"]
TRAIN2 = {
    "u100-s1-bcb-a500": ("uniform", 100, 80, 400_000, [A, "500", *BCB]),
    "u100-s3-pw-r30": ("uniform", 100, 80, 410_000, [STEP, "3", ROLL, "30"]),
    "u80-s2-pw-a800": ("uniform", 80, 64, 420_000, [STEP, "2", A, "800"]),
    "c100-s2-pw": ("clusters", 100, 80, 430_000, [STEP, "2"]),
    "c150-s1-bcb-fast": ("clusters", 150, 40, 440_000, [*BCB, "--instance.satellite.max-rate-deg-s", "2.5",
                                                         "--instance.satellite.max-accel-deg-s2", "1.0"]),
    "x100-s1-pw-a600": ("conflict", 100, 80, 450_000, [A, "600"]),
    "x100-s2-bcb-short": ("conflict", 100, 64, 460_000, [STEP, "2", *BCB, "--instance.targets.duration-min-s", "5",
                                                          "--instance.targets.duration-max-s", "20"]),
    "u200-s2-bcb": ("uniform", 200, 24, 470_000, [STEP, "2", *BCB]),
    "x150-s3-pw-r35": ("conflict", 150, 32, 480_000, [STEP, "3", ROLL, "35"]),
}
# A third mix (``data --dense``, linked into ``train3/``): the dense families only (clusters, conflict), where the
# policies are furthest from the optimum, with what the first two mixes never vary:
# the number of clusters (2-8), their radius (120-450 km), high-priority targets clustered or not.
K = "--instance.targets.n-clusters"
RADIUS = "--instance.targets.cluster-radius-km"
TRAIN3 = {
    "c100-s1-bcb-k2": ("clusters", 100, 64, 500_000, [*BCB, K, "2"]),
    "c120-s2-pw-k6-r150": ("clusters", 120, 48, 510_000, [STEP, "2", K, "6", RADIUS, "150"]),
    "c80-s3-pw-a700-k3": ("clusters", 80, 64, 520_000, [STEP, "3", A, "700", K, "3"]),
    "c100-s2-bcb-r450-r35": ("clusters", 100, 48, 530_000, [STEP, "2", *BCB, RADIUS, "450", ROLL, "35"]),
    "x120-s1-pw-k3": ("conflict", 120, 48, 540_000, [K, "3"]),
    "c140-s1-pw-k8-r120": ("clusters", 140, 32, 550_000, [K, "8", RADIUS, "120"]),
}
# A fourth mix (``data --large``, linked into ``train4/``): the dense families at 200-300 acquisitions, where a
# Greedy-plan model can give up top-class acquisitions that Greedy's rollout also misses; the first three mixes
# have conflict only up to 150 acquisitions.
TRAIN4 = {
    "x250-s2-pw": ("conflict", 250, 24, 600_000, [STEP, "2"]),
    "x300-s1-bcb-a650": ("conflict", 300, 16, 610_000, [*BCB, A, "650"]),
    "c250-s2-pw-k4": ("clusters", 250, 16, 620_000, [STEP, "2", K, "4"]),
    "x200-s3-pw-r40": ("conflict", 200, 24, 630_000, [STEP, "3", ROLL, "40"]),
}
VAL = {
    "val-u100": ("uniform", 100, 8, 200_000, ["--instance.graph.step-s", "2"]),
    "val-c100": ("clusters", 100, 4, 210_000, ["--instance.satellite.slew-model", "bang_coast_bang"]),
    "val-x100": ("conflict", 100, 8, 220_000, []),
}
TEST = {
    "test-u100": ("uniform", 100, 16, 300_000, []),
    "test-c100": ("clusters", 100, 16, 310_000, ["--instance.graph.step-s", "2"]),
    "test-x100": ("conflict", 100, 16, 320_000, ["--instance.satellite.slew-model", "bang_coast_bang"]),
}
# Unseen sets at scale (``data --scale``; x RAMP, which proves nothing but met the optimum wherever it was known)
SCALE = {
    "test-u300": ("uniform", 300, 8, 330_000, []),
    "test-x300": ("conflict", 300, 8, 340_000, [STEP, "2"]),
    "test-u1000": ("uniform", 1000, 4, 350_000, [STEP, "2"]),
}
MODES = {"unitary": "unitary", "utility": "normalized"}


def sh(args: list[str]) -> None:
    print("+", " ".join(args), flush=True)
    subprocess.run(args, check=True, cwd=ROOT)


def build(base: Path, sets: dict, link_into: str | None) -> list[Path]:
    out = []
    for name, (family, n, count, seed, extra) in sets.items():
        d = base / "parts" / name
        if not (d / "manifest.json").exists():
            sh([PY, "jobs/build_shards.py", "--out", str(d), "--family", family, "--n-acquisitions", str(n),
                "--n-instances", str(count), "--seed", str(seed), "--per-shard", str(min(8, count)), *extra])
        out.append(d)
        if link_into:
            target = base / link_into
            target.mkdir(parents=True, exist_ok=True)
            for shard in sorted(d.glob("shard-*.parquet")):
                link = target / f"{name}-{shard.name}"
                if not link.exists():
                    os.symlink(os.path.relpath(shard, target), link)
    return out


def cmd_data(a) -> None:
    base = ROOT / a.data
    if a.scale:
        build(base, SCALE, None)
        return
    if a.more or a.dense or a.large:
        name, sets = ("train2", TRAIN2) if a.more else ("train3", TRAIN3) if a.dense else ("train4", TRAIN4)
        build(base, sets, name)
        sh([PY, "jobs/build_demos.py", "--data", str(base / name), "--modes", *a.modes, "--action-sets", "true",
            "--beam", "1", "--time-limit", "30", "--sets-max-acquisitions", "150"])
        return
    build(base, TRAIN, "train")
    build(base, VAL, "val")
    build(base, TEST, None)
    sets = ["--action-sets", "true", "--beam", "1", "--time-limit", "30"]
    sh([PY, "jobs/build_demos.py", "--data", str(base / "train"), str(base / "val"), "--modes", "unitary", *sets])
    sh([PY, "jobs/build_demos.py", "--data", str(base / "train"), str(base / "val"), "--modes", "utility", *sets,
        "--sets-max-acquisitions", "150"])


def budget_args(kind: str, mode: str, seconds: float, run: str, a) -> list[list[str]]:
    base = ROOT / a.data
    reward = MODES[mode]
    common_env = ["--env.reward", reward, "--env.max-acquisitions", "320"]
    pre = [PY, "jobs/pretrain.py", "--imitation.train-data", str(base / "train"), "--imitation.val-data",
           str(base / "val"), "--imitation.epochs", "1000", "--imitation.dagger-every", "2",
           "--imitation.run-name", run if kind == "imitation" else run + "-bc", "--imitation.experiment",
           "expert-guided", "--imitation.dagger-beam", "1", *common_env]
    if mode == "utility":  # decisions weighed by what they cost (see docs/training.md)
        pre += ["--imitation.regret-coeff", "100", "--imitation.set-tolerance", "1e-6"]
    ppo = [PY, "jobs/train.py", "--train.train-data", str(base / "train"), "--train.val-data", str(base / "val"),
           "--train.iterations", "100000", "--train.run-name", run, "--train.experiment", "expert-guided",
           "--train.validate-every", "2", "--train.checkpoint-every", "2", "--train.time-budget", None, *common_env]
    if kind == "ppo":
        ppo[ppo.index(None)] = str(seconds)
        return [ppo]
    if kind == "imitation":
        return [pre + ["--imitation.time-budget", str(seconds)]]
    half = seconds / 2
    ppo[ppo.index(None)] = str(half)
    init = str(ROOT / "runs" / (run + "-bc") / "checkpoints" / "best")
    return [pre + ["--imitation.time-budget", str(half)], ppo + ["--train.init-checkpoint", init]]


def cmd_run(a) -> None:
    for mode in a.modes:
        for kind in a.kinds:
            run = f"eg-{mode}-{kind.replace('+', '-')}"
            if (ROOT / "runs" / run / "done.json").exists():
                print(f"[expert_guided] {run} already done", flush=True)
                continue
            t0 = time.time()
            for cmd in budget_args(kind, mode, a.minutes * 60, run, a):
                sh(cmd)
            (ROOT / "runs" / run).mkdir(parents=True, exist_ok=True)
            (ROOT / "runs" / run / "done.json").write_text(json.dumps({"wall_s": time.time() - t0}))
            for test in a.tests:
                sh([PY, "jobs/evaluate.py", "--data", str(ROOT / a.data / "parts" / test), "--solvers", "greedy",
                    "ramp", "exact", "policy", "--checkpoint", str(ROOT / "runs" / run / "checkpoints" / "best"),
                    "--mode", mode, "--time-limit", "60", "--out", str(ROOT / "runs" / run / f"eval-{test}"),
                    "--experiment", "expert-guided"])


def cmd_report(a) -> None:
    import pandas as pd

    rows = []
    for d in sorted((ROOT / "runs").glob("eg-*")):
        for ev in sorted(d.glob("eval-*/results.parquet")):
            df = pd.read_parquet(ev)
            piv = df.pivot_table(index="instance", columns="solver", values="value")
            if "policy" not in piv or "exact" not in piv:
                continue
            rows.append({"run": d.name, "test": ev.parent.name.removeprefix("eval-"),
                         "policy/exact": (piv["policy"] / piv["exact"]).mean(),
                         "policy/ramp": (piv["policy"] / piv["ramp"]).mean(),
                         "policy/greedy": (piv["policy"] / piv["greedy"]).mean(),
                         "below greedy": int((piv["policy"] < piv["greedy"] * (1 - 1e-9)).sum()),
                         "at optimum": int((piv["policy"] >= piv["exact"] * (1 - 1e-9)).sum()),
                         "instances": len(piv)})
    print(pd.DataFrame(rows).to_markdown(index=False, floatfmt=".4f") if rows else "no finished evaluation")
    plots = []
    for mode in MODES:
        curves = learning_curves(mode)
        if curves:
            plots.append(plot_curves(curves, mode, ROOT / "docs" / "figures" / f"expert-guided-{mode}.png"))
            print(f"learning curves: {plots[-1]}")
    if rows or plots:
        import mlflow

        from eosp.config import default_mlflow_uri

        mlflow.set_tracking_uri(default_mlflow_uri(""))
        mlflow.set_experiment("expert-guided")
        with mlflow.start_run(run_name="comparison"):
            if rows:
                mlflow.log_text(pd.DataFrame(rows).to_markdown(index=False, floatfmt=".4f"), "comparison.md")
            for f in plots:
                mlflow.log_artifact(str(f))


def learning_curves(mode: str) -> dict[str, list[tuple[float, float]]]:
    """Validation ratio to the optimum (RAMP proved equal on the validation set) against wall time, per run."""
    out = {}
    for kind in ("ppo", "imitation", "imitation+ppo"):
        run = ROOT / "runs" / f"eg-{mode}-{kind.replace('+', '-')}"
        pts, offset = [], 0.0
        bc = ROOT / "runs" / (run.name + "-bc") / "history.json"
        for f in ([bc] if kind == "imitation+ppo" else []) + [run / "history.json", run / "run.json"]:
            if not f.exists():
                continue
            hist = json.loads(f.read_text())["history"]
            for h in hist:
                if "val/ratio_to_exact" in h:
                    pts.append((offset + h["wall_s"], h["val/ratio_to_exact"]))
                elif "val/ratio_to_ramp" in h:
                    pts.append((offset + h["perf/wall_s"], h["val/ratio_to_ramp"]))
            if pts:
                offset = pts[-1][0]
        if pts:
            out[kind] = pts
    return out


def plot_curves(curves: dict, mode: str, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.6))
    for kind, pts in curves.items():
        ax.plot([t / 60 for t, _ in pts], [v for _, v in pts], marker="o", ms=3, label=kind)
    ax.axhline(1.0, color="gray", lw=0.8, ls="--")
    ax.set_xlabel("wall time (min)")
    ax.set_ylabel("validation: policy / optimum")
    ax.set_title(f"{mode} mode, greedy decoding")
    ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("stage", choices=["data", "run", "report"])
    p.add_argument("--data", default="data/expert")
    p.add_argument("--minutes", type=float, default=10.0, help="wall-time budget of each run")
    p.add_argument("--modes", nargs="+", default=["unitary", "utility"], choices=list(MODES))
    p.add_argument("--kinds", nargs="+", default=["ppo", "imitation", "imitation+ppo"])
    p.add_argument("--tests", nargs="+", default=list(TEST))
    p.add_argument("--more", action="store_true", help="data: build the second training mix (train2/) instead")
    p.add_argument("--dense", action="store_true", help="data: build the third mix, dense targets (train3/) instead")
    p.add_argument("--large", action="store_true", help="data: build the fourth mix, dense at 200-300 (train4/)")
    p.add_argument("--scale", action="store_true", help="data: build the test sets at 300 and 1000 acquisitions")
    a = p.parse_args()
    {"data": cmd_data, "run": cmd_run, "report": cmd_report}[a.stage](a)


if __name__ == "__main__":
    main()
