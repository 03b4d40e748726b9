"""Plots of a training run (PNG + SVG), logged to MLflow as artifacts."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def learning_curve(history: list[dict], out: str | Path) -> Path:
    """Training return and validation ratios against the iteration; returns the PNG path."""
    out = Path(out)
    it = [h["iteration"] for h in history]
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    ax[0].plot(it, [h.get("train/episode_return_mean", float("nan")) for h in history], color="C0")
    ax[0].set_xlabel("iteration")
    ax[0].set_ylabel("training episode return")
    val = [h for h in history if "val/ratio_to_greedy" in h]
    if val:
        for key, label, color in (("val/ratio_to_greedy", "policy / Greedy", "C1"),
                                  ("val/ratio_to_ramp", "policy / RAMP", "C2")):
            ax[1].plot([h["iteration"] for h in val], [h[key] for h in val], marker="o", label=label, color=color)
        ax[1].axhline(1.0, color="gray", lw=0.8, ls="--")
        ax[1].set_xlabel("iteration")
        ax[1].set_ylabel("validation mean ratio")
        ax[1].legend()
    return _save(fig, out)


def imitation_curve(history: list[dict], out: str | Path) -> Path:
    """Expert-action accuracy and validation ratios (to the exact optimum, RAMP, Greedy) against wall time."""
    out = Path(out)
    t = [h["wall_s"] for h in history]
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    ax[0].plot(t, [h.get("train/accuracy", float("nan")) for h in history], marker=".", color="C0")
    ax[0].set_xlabel("wall time (s)")
    ax[0].set_ylabel("training accuracy (argmax optimal)")
    val = [h for h in history if "val/ratio_to_exact" in h]
    for key, label, color in (("val/ratio_to_exact", "policy / optimum", "C3"),
                              ("val/ratio_to_ramp", "policy / RAMP", "C2"),
                              ("val/ratio_to_greedy", "policy / Greedy", "C1")):
        if val:
            ax[1].plot([h["wall_s"] for h in val], [h[key] for h in val], marker="o", label=label, color=color)
    ax[1].axhline(1.0, color="gray", lw=0.8, ls="--")
    ax[1].set_xlabel("wall time (s)")
    ax[1].set_ylabel("validation mean ratio")
    if val:
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
