"""Tables of an evaluation: the paper's "average scores" table, ratios, gaps, win/tie/loss."""

from __future__ import annotations

import numpy as np
import pandas as pd

REFERENCES = ("greedy", "ramp")


def _fmt(x: float) -> str:
    if x != x:
        return "-"
    return f"{x:,.0f}" if abs(x) >= 1000 else f"{x:.4g}"


def _ratio(x: float) -> str:
    return "-" if x != x else f"{x:.4f}"


def summary(results: pd.DataFrame) -> pd.DataFrame:
    """One row per (size group, solver): mean score, ratios of means to the references, gaps, W/T/L.

    `results` has one row per (group, instance, solver) with columns value, bound, status.
    """
    rows = []
    for group, gdf in results.groupby("group"):
        wide = gdf.pivot(index="instance", columns="solver", values="value")
        bound = gdf.groupby("instance")["bound"].max().reindex(wide.index)
        proven = gdf[(gdf.solver == "exact") & (gdf.status == "optimal")].instance.tolist()
        for solver in wide.columns:
            v = wide[solver]
            row = {"group": group, "solver": solver, "instances": int(v.notna().sum()), "mean": float(v.mean())}
            for ref in REFERENCES:
                if ref in wide.columns:
                    r = wide[ref]
                    row[f"ratio_{ref}"] = float(v.mean() / r.mean()) if r.mean() > 0 else np.nan
                    tie = np.isclose(v, r, rtol=1e-9, atol=1e-9)
                    row[f"wtl_{ref}"] = f"{int(((v > r) & ~tie).sum())}/{int(tie.sum())}/{int(((v < r) & ~tie).sum())}"
            if proven:
                row["ratio_optimum"] = float(v[proven].mean() / wide["exact"][proven].mean())
                row["proven"] = len(proven)
            if bound.notna().any():
                row["gap_to_bound"] = float(np.nanmean((bound - v) / bound))
            rows.append(row)
    return pd.DataFrame(rows)


def markdown(results: pd.DataFrame, mode: str) -> str:
    s = summary(results)
    solvers = list(dict.fromkeys(results.solver))
    lines = [f"# Evaluation ({mode} mode)", ""]
    lines.append("Average score per method and instance set; ratios are ratios of the average scores "
                 "(as in the paper's table); W/T/L counts instances where the method is above / equal to / "
                 "below the reference; the optimum ratio uses the instances that the exact solver proved.")
    lines.append("")
    head = "| #Acq. | #Inst. | " + " | ".join(solvers) + " |"
    lines += [head, "|" + "---|" * (2 + len(solvers))]
    for group, sub in s.groupby("group"):
        means = {r.solver: r["mean"] for _, r in sub.iterrows()}
        n = int(sub.instances.max())
        lines.append(f"| {group} | {n} | " + " | ".join(_fmt(means.get(x, np.nan)) for x in solvers) + " |")
    lines += ["", "| #Acq. | method | / Greedy | / RAMP | / optimum (proven) | mean gap to bound | W/T/L vs Greedy | "
                  "W/T/L vs RAMP |", "|---|---|---|---|---|---|---|---|"]
    for _, r in s.iterrows():
        ro, gb = r.get("ratio_optimum", np.nan), r.get("gap_to_bound", np.nan)
        opt = f"{ro:.4f} ({int(r['proven'])})" if ro == ro else "-"
        gap = f"{gb:.2%}" if gb == gb else "-"
        lines.append(f"| {r.group} | {r.solver} | {_ratio(r.get('ratio_greedy', np.nan))} | "
                     f"{_ratio(r.get('ratio_ramp', np.nan))} | {opt} | {gap} | {r.get('wtl_greedy', '-')} | "
                     f"{r.get('wtl_ramp', '-')} |")
    lines += mcts_table(results)
    t = results.groupby(["group", "solver"])["seconds"].mean().unstack()
    lines += ["", "Mean solve time per instance (s):", "", "| #Acq. | " + " | ".join(t.columns) + " |",
              "|" + "---|" * (1 + len(t.columns))]
    for g, row in t.iterrows():
        lines.append(f"| {g} | " + " | ".join(f"{x:.3f}" for x in row) + " |")
    return "\n".join(lines) + "\n"


def mcts_table(results: pd.DataFrame) -> list[str]:
    """The paper's MCTS table: mean score, share of instances at or above RAMP, total solve time."""
    names = [s for s in dict.fromkeys(results.solver) if s.startswith("mcts(") or s in ("policy", "ramp")]
    if not any(s.startswith("mcts(") for s in names) or "ramp" not in set(results.solver):
        return []
    wide = results.pivot_table(index=["group", "instance"], columns="solver", values="value")
    secs = results.groupby("solver")["seconds"].sum()
    order = ["ramp", "policy"] + sorted((s for s in names if s.startswith("mcts(")), key=lambda s: int(s[5:-1]))
    lines = ["", "MCTS (budget = simulations before each decision; mcts(0) is the plain policy):", "",
             "| method | mean score | >= RAMP (%) | solve time, sum over instances (min) |", "|---|---|---|---|"]
    for s in order:
        if s not in wide.columns:
            continue
        at_least = np.mean(wide[s] >= wide["ramp"] * (1 - 1e-9)) * 100
        lines.append(f"| {s} | {_fmt(float(wide[s].mean()))} | {at_least:.1f} | "
                     f"{secs.get(s, float('nan')) / 60:.2f} |")
    return lines
