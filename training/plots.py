"""Plots of a training run (PNG + SVG), logged to MLflow as artifacts."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def learning_curve(history: list[dict], out: str | Path) -> Path:
    """Training return and validation against env steps, and validation against wall time; returns the PNG.

    The validation panels draw the primary metric, the mean of per-instance ratios (the one that picks the
    `best` checkpoint, eosp.training.validation.primary_metric), under its own name, with the best checkpoint
    marked; the ratios of means are drawn thin and dashed and labelled as such (issue 41: a curve of ratios
    of means was labelled "validation mean ratio")."""
    from eosp.training.validation import describe_metric, primary_metric, selection_score

    out = Path(out)
    steps = [h.get("perf/env_steps_lifetime", h["iteration"]) for h in history]
    x_steps = "env steps" if any("perf/env_steps_lifetime" in h for h in history) else "iteration"
    fig, ax = plt.subplots(1, 3, figsize=(15, 3.8))
    ax[0].plot(steps, [h.get("train/episode_return_mean", float("nan")) for h in history], color="C0")
    ax[0].set_xlabel(x_steps)
    ax[0].set_ylabel("training episode return")
    val = [(x, h) for x, h in zip(steps, history) if "val/policy_mean" in h]
    if val:
        key = primary_metric(val[-1][1])
        best = max(range(len(val)), key=lambda k: selection_score(val[k][1]))
        for a, xs, xlabel in ((ax[1], [x for x, _ in val], x_steps),
                              (ax[2], [h.get("perf/wall_s", float("nan")) for _, h in val], "wall time (s)")):
            a.plot(xs, [h.get(key, float("nan")) for _, h in val], marker="o", color="C3", lw=2,
                   label=describe_metric(key) + " (selects best)")
            a.plot([xs[best]], [val[best][1].get(key, float("nan"))], marker="*", ms=14, color="C3", ls="none",
                   label=f"best checkpoint (iteration {val[best][1]['iteration']})")
            for other, color in (("greedy", "C1"), ("ramp", "C2")):
                for k, style in ((f"val/mean_ratio_to_{other}", {"lw": 1.2, "marker": "."}),
                                 (f"val/ratio_to_{other}", {"lw": 0.8, "ls": "--"})):
                    if k != key and any(k in h for _, h in val):
                        a.plot(xs, [h.get(k, float("nan")) for _, h in val], color=color, label=describe_metric(k),
                               **style)
            if key != "val/policy_mean":
                a.axhline(1.0, color="gray", lw=0.8, ls=":")
            a.set_xlabel(xlabel)
            a.set_ylabel(describe_metric(key) if key == "val/policy_mean" else "validation: policy / baseline")
        ax[1].legend(fontsize=7)
    return _save(fig, out)


def imitation_curve(history: list[dict], out: str | Path) -> Path:
    """Expert-action accuracy and validation ratios against wall time: to the exact optimum, RAMP and Greedy (the
    single pass), or to the fleet solver, the features-only decoder and the fleet greedy (fleets)."""
    out = Path(out)
    t = [h["wall_s"] for h in history]
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    ax[0].plot(t, [h.get("train/accuracy", float("nan")) for h in history], marker=".", color="C0")
    ax[0].set_xlabel("wall time (s)")
    ax[0].set_ylabel("training accuracy (argmax optimal)")
    val = [h for h in history if "val/policy_mean" in h]
    shown = False
    for key, label, color in (("val/ratio_to_exact", "policy / optimum", "C3"),
                              ("val/ratio_to_fleet", "policy / fleet solver", "C3"),
                              ("val/ratio_to_ramp", "policy / RAMP", "C2"),
                              ("val/ratio_to_features", "policy / features-only decoder", "C2"),
                              ("val/ratio_to_greedy", "policy / Greedy", "C1")):
        if val and key in val[-1]:
            ax[1].plot([h["wall_s"] for h in val], [h[key] for h in val], marker="o", label=label, color=color)
            shown = True
    ax[1].axhline(1.0, color="gray", lw=0.8, ls="--")
    ax[1].set_xlabel("wall time (s)")
    ax[1].set_ylabel("validation ratio of means")
    if shown:
        ax[1].legend()
    return _save(fig, out)


def _save(fig, out: Path) -> Path:
    """PNG and SVG beside each other; returns the PNG."""
    fig.tight_layout()
    png = out.with_suffix(".png")
    fig.savefig(png, dpi=120)
    fig.savefig(out.with_suffix(".svg"))
    plt.close(fig)
    return png
