"""The paper's trajectory figure: roll angle against time for schedules of one instance.

Candidates are drawn in gray over their visibility window (their roll curve when the
attitudes are known, else a box spanning roll_min..roll_max), each schedule's
acquisitions as thick colored segments and its maneuvers as arrows from the end of
one acquisition to the start of the next.  Written as PNG and SVG.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from eosp.atomic import atomic_path  # noqa: E402
from eosp.ownership import check_output, mark_svg, png_mark  # noqa: E402
from eosp.instances.instance import Instance  # noqa: E402
from eosp.instances.schedule import Schedule, to_internal_nodes  # noqa: E402


def node_rolls(inst: Instance) -> tuple[np.ndarray, np.ndarray] | None:
    """Roll at the start and at the end of every node, when the instance's attitudes are known."""
    if inst.node_attitude is not None:
        return inst.node_attitude[:, 0].astype(float), inst.node_attitude[:, 2].astype(float)
    cfg = inst.meta.get("config")
    if cfg and inst.acqs.lat is not None and inst.meta.get("generator") == "eosp-open-sim":
        from eosp.instances.generator import scenario_of

        scn = scenario_of(inst)
        g = inst.node_graph
        k = g.node_acq[1:]
        r0, _ = scn.attitude(inst.acqs.lat[k], inst.acqs.lon[k], g.node_time[1:])
        r1, _ = scn.attitude(inst.acqs.lat[k], inst.acqs.lon[k], g.node_time[1:] + inst.acqs.duration[k])
        return np.r_[0.0, r0], np.r_[0.0, r1]
    return None


def plot_trajectories(inst: Instance, schedules: dict[str, Schedule], out: str | Path,
                      title: str | None = None, overwrite: bool = False) -> list[Path]:
    """Roll against time of `schedules`, written as OUT.png and OUT.svg (an existing one replaced only when eosp
    wrote it and `overwrite` is given)."""
    out = Path(out)
    check_plot_out(out, overwrite)
    out.parent.mkdir(parents=True, exist_ok=True)
    g, a = inst.node_graph, inst.acqs
    rolls = node_rolls(inst)
    fig, ax = plt.subplots(figsize=(12, 5))
    if rolls is not None:
        r0, r1 = rolls
        for i in range(inst.n_acq):
            lo, hi = g.acq_ptr[i], g.acq_ptr[i + 1]
            if hi > lo:
                t = np.r_[g.node_time[lo:hi], g.node_time[hi - 1] + a.duration[i]]
                ax.plot(t, np.r_[r0[lo:hi], r1[hi - 1]], color="0.8", lw=1.0, zorder=1)
    elif a.attitude is not None:
        for i in range(inst.n_acq):
            ax.fill_between([a.vtw_start[i], a.vtw_end[i]], a.attitude[i, 0], a.attitude[i, 1], color="0.85", lw=0)
    else:
        for i in range(inst.n_acq):
            ax.plot([a.vtw_start[i], a.vtw_end[i]], [i, i], color="0.8", lw=1.0)
    ylabel = "roll (deg)" if rolls is not None or a.attitude is not None else "acquisition (no attitude data)"
    for k, (label, sched) in enumerate(schedules.items()):
        color = f"C{k}"
        nodes = to_internal_nodes(inst, sched)
        if rolls is not None:
            ys, ye = rolls[0][nodes], rolls[1][nodes]
        elif a.attitude is not None:
            ys = ye = a.attitude[sched.acq, 2]
        else:
            ys = ye = sched.acq.astype(float)
        ends = sched.start + a.duration[sched.acq]
        for j in range(len(sched)):
            ax.plot([sched.start[j], ends[j]], [ys[j], ye[j]], color=color, lw=3, zorder=3,
                    label=f"{label} ({len(sched)} acq., {float(a.utility[sched.acq].sum()):.6g})" if j == 0 else None)
            if j + 1 < len(sched):
                ax.annotate("", xy=(sched.start[j + 1], ys[j + 1]), xytext=(ends[j], ye[j]),
                            arrowprops={"arrowstyle": "->", "color": color, "lw": 1.0}, zorder=2)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title or f"{inst.name}: {inst.n_acq} candidates")
    if ax.get_legend_handles_labels()[0]:  # empty schedules draw nothing to name (matplotlib would warn)
        ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    paths = check_plot_out(out, overwrite)
    for p in paths:
        save_marked(fig, p, dpi=130)
    plt.close(fig)
    return paths


PLOT_KIND = "plot"  # the mark (eosp.ownership): a PNG text chunk, an SVG comment


def check_plot_out(out: str | Path, overwrite: bool = False) -> list[Path]:
    """The PNG and SVG paths of plot `out` (its suffix replaced), each refused before any work when eosp must not
    write it (:func:`eosp.ownership.check_output`)."""
    return [check_output(Path(out).with_suffix(ext), PLOT_KIND, overwrite, suffixes=(ext,)) for ext in (".png", ".svg")]


def save_marked(fig, path: Path, **kwargs) -> Path:
    """Save `fig` atomically as PNG or SVG (by the suffix), with eosp's mark."""
    fmt = path.suffix[1:].lower()
    with atomic_path(path, suffix=path.suffix) as tmp:
        fig.savefig(tmp, format=fmt, metadata=png_mark(PLOT_KIND) if fmt == "png" else None, **kwargs)
        if fmt == "svg":
            mark_svg(tmp, PLOT_KIND)
    return path


def plot_class_counts(results, out: str | Path) -> Path:
    """Mean number of acquisitions per priority class and solver, one panel per instance size (PNG).

    `results` is the evaluation's table, with one ``class_<c>`` column per priority class.
    """
    from eosp.config import CLASS_UTILITIES

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    classes = [c for c in range(len(CLASS_UTILITIES)) if f"class_{c}" in results.columns]
    groups = sorted(results["group"].unique())
    solvers = list(dict.fromkeys(results["solver"]))
    fig, axes = plt.subplots(1, len(groups), figsize=(max(6.0, 4.5 * len(groups)), 4), squeeze=False)
    width = 0.8 / max(1, len(solvers))
    for ax, group in zip(axes[0], groups):
        sub = results[results["group"] == group]
        for k, solver in enumerate(solvers):
            means = [float(sub.loc[sub.solver == solver, f"class_{c}"].mean()) for c in classes]
            ax.bar(np.arange(len(classes)) + (k - (len(solvers) - 1) / 2) * width, means, width, label=solver,
                   color=f"C{k}")
        ax.set_xticks(np.arange(len(classes)), [f"{c}\n({CLASS_UTILITIES[c]:g})" for c in classes], fontsize=8)
        ax.set_xlabel("priority class (utility)")
        ax.set_ylabel("acquisitions per instance (mean)")
        ax.set_title(f"{group} acquisitions, {sub.instance.nunique()} instance(s)")
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(out, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return out
