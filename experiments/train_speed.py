"""Learning against env steps and against wall time: PPO with and without overlapped sampling.

    python experiments/train_speed.py --iterations 40 --seeds 0 1 2

Each variant runs ``jobs/train.py`` (unitary reward, cpu preset, PPO defaults:
batch 512, minibatch 128, 4 epochs) on the same 100-acquisition training set with
greedy-decoding validation every ``--val-every`` iterations, one after the other
(never two at once: they would share the 2 cores).  Variants:

* ``plain``: ``--train.overlap-sampling false`` (RLlib's PPO: sample, then learn);
* ``overlap``: ``--train.overlap-sampling true`` (the default: sample the next batch while learning).

Prints, per run: env steps/s, the validation ratio to Greedy at the end, and
the wall time and env steps at which the ratio first reached ``--target``
(1.05 x Greedy); then, over every run in ``--out`` (all seeds of all
invocations), a table, the mean curve of each variant, the curves (ratio against
env steps and against wall time) in ``--plot`` and the figures in
``--out``/summary.json (``--report-only``: just that).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TRAIN = "import sys; from eosp.jobs.train import main; sys.exit(main(sys.argv[1:]))"


@dataclass
class Args:
    variants: tuple[str, ...] = ("plain", "overlap")
    seeds: tuple[int, ...] = (0,)
    iterations: int = 40
    val_every: int = 2
    target: float = 1.05
    """Ratio to Greedy on the validation set whose first crossing is timed."""
    out: str = "runs/train-speed"
    plot: str = "runs/train-speed/curves"


def parse(argv: list[str] | None) -> Args:
    from eosp.args import add_config_args, config_from_args

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--report-only", action="store_true", help="only the table and plot of the runs already done")
    add_config_args(p, Args)
    ns = p.parse_args(argv)
    a = config_from_args(Args, ns)
    a.report_only = ns.report_only
    return a


def data_sets() -> tuple[Path, Path]:
    import ray

    from eosp.config import DatasetConfig, RayConfig
    from eosp.jobs.build_shards import run as build

    train = ROOT / "data" / "bench" / "train-100-32"
    val = ROOT / "data" / "bench" / "val-100-16"
    for path, n, seed in ((train, 32, 770_000), (val, 16, 780_000)):
        if not (path / "manifest.json").exists():
            build(DatasetConfig(out=str(path), family="uniform", n_acquisitions=100, n_instances=n, per_shard=8,
                                seed=seed), RayConfig())
    if ray.is_initialized():
        ray.shutdown()
    return train, val


def run(variant: str, seed: int, a: Args, train: Path, val: Path) -> dict:
    name = f"{variant}-s{seed}"
    out = (ROOT / a.out).resolve()
    flags = ["--train.train-data", str(train), "--train.val-data", str(val), "--env.reward", "unitary",
             "--train.iterations", str(a.iterations), "--train.validate-every", str(a.val_every),
             "--train.checkpoint-every", str(a.iterations), "--train.seed", str(seed),
             "--train.run-dir", str(out), "--train.run-name", name, "--train.experiment", "train-speed"]
    flags += ["--train.overlap-sampling", "true" if variant == "overlap" else "false"]
    log = out / f"{name}.log"
    out.mkdir(parents=True, exist_ok=True)
    print(f"[train_speed] {name}: log in {log}", flush=True)
    with open(log, "w") as f:
        subprocess.run([sys.executable, "-c", TRAIN, *flags], stdout=f, stderr=subprocess.STDOUT,
                       check=True, cwd=ROOT)
    history = json.loads((out / name / "run.json").read_text())["history"]
    return summarize(name, history, a.target)


def summarize(name: str, history: list[dict], target: float) -> dict:
    vals = [h for h in history if "val/ratio_to_greedy" in h]
    reached = next((h for h in vals if h["val/ratio_to_greedy"] >= target), None)
    rates = [h["perf/env_steps_per_s"] for h in history if "perf/env_steps_per_s" in h]
    return {
        "run": name, "env_steps_per_s": sum(rates) / len(rates), "final_ratio": vals[-1]["val/ratio_to_greedy"],
        "best_ratio": max(h["val/ratio_to_greedy"] for h in vals),
        "reached_wall_s": reached["perf/wall_s"] if reached else None,
        "reached_env_steps": reached["perf/env_steps_lifetime"] if reached else None,
        "curve": [(h["perf/env_steps_lifetime"], h["perf/wall_s"], h["val/ratio_to_greedy"]) for h in vals],
    }


def plot(results: list[dict], target: float, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    colors: dict[str, str] = {}
    for r in results:
        variant = r["run"].rsplit("-s", 1)[0]
        first = variant not in colors
        colors.setdefault(variant, f"C{len(colors)}")
        steps, wall, ratio = zip(*r["curve"])
        for ax, x in zip(axes, (steps, wall)):
            ax.plot(x, ratio, marker=".", color=colors[variant], alpha=0.8, label=variant if first else None)
    for ax, xl in zip(axes, ("env steps", "wall time (s), validation included")):
        ax.axhline(target, color="grey", ls="--", lw=0.8)
        ax.set_xlabel(xl)
        ax.set_ylabel("validation: policy / Greedy (unitary)")
        ax.grid(alpha=0.3)
    axes[1].legend()
    fig.suptitle("PPO, 100 acquisitions, cpu preset, batch 512 / minibatch 128 / 4 epochs")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path.with_suffix(".png"), dpi=110)
    fig.savefig(path.with_suffix(".svg"))


def report(a: Args) -> None:
    """Table and curves over every run in the output directory (all seeds of all invocations)."""
    out = ROOT / a.out
    results = []
    for run_file in sorted(out.glob("*-s*/run.json")):
        state = json.loads(run_file.read_text())
        if state["iteration"] >= a.iterations:
            results.append(summarize(run_file.parent.name, state["history"], a.target))
    (out / "summary.json").write_text(json.dumps(results, indent=1))
    plot(results, a.target, ROOT / a.plot)
    print(f"\n| run | env steps/s | final / Greedy | best / Greedy | wall to {a.target} (s) | env steps to {a.target} |")
    print("|---|---|---|---|---|---|")
    for r in results:
        wall = f"{r['reached_wall_s']:.0f}" if r["reached_wall_s"] is not None else "not reached"
        steps = f"{r['reached_env_steps']:.0f}" if r["reached_env_steps"] is not None else "-"
        print(f"| {r['run']} | {r['env_steps_per_s']:.0f} | {r['final_ratio']:.4f} | {r['best_ratio']:.4f} | "
              f"{wall} | {steps} |")
    by_variant: dict[str, list[dict]] = {}
    for r in results:
        by_variant.setdefault(r["run"].rsplit("-s", 1)[0], []).append(r)
    print("\nper variant (mean over seeds; ratio at each validation point averaged over seeds):")
    for v, rs in by_variant.items():
        n = min(len(r["curve"]) for r in rs)
        mean_curve = [sum(r["curve"][i][2] for r in rs) / len(rs) for i in range(n)]
        reached = [r["reached_wall_s"] for r in rs if r["reached_wall_s"] is not None]
        print(f"  {v}: {len(rs)} seeds, {sum(r['env_steps_per_s'] for r in rs) / len(rs):.0f} env steps/s, "
              f"reached {a.target} in {len(reached)}/{len(rs)} (wall {', '.join(f'{x:.0f}' for x in reached)} s); "
              f"mean ratio at validations: {' '.join(f'{x:.3f}' for x in mean_curve)}")


def main(argv: list[str] | None = None) -> int:
    a = parse(argv)
    if a.report_only:
        report(a)
        return 0
    train, val = data_sets()
    for seed in a.seeds:
        for v in a.variants:
            r = run(v, seed, a, train, val)
            print(f"[train_speed] {r['run']}: {r['env_steps_per_s']:.0f} env steps/s, final ratio "
                  f"{r['final_ratio']:.4f}, reached {a.target} at {r['reached_wall_s']} s / "
                  f"{r['reached_env_steps']} env steps", flush=True)
    report(a)
    return 0


if __name__ == "__main__":
    sys.exit(main())
