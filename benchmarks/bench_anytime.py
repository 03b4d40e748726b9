"""Anytime benchmark: value reached against time per instance, learned searches vs RAMP and exact.

    python benchmarks/bench_anytime.py --sizes 100 300 --families uniform conflict \\
        --modes unitary utility --times 0.1 1 10 --instances 4 --out runs/anytime

For every unseen generated instance (seeds --seed-base, default 900000, + ...), mode and time T (seconds of
search per instance, model loading and instance preparation excluded):

* policy: the shipped (or given) model's greedy decoding (one run; its own time);
* sample, beam, mcts: the learned searches with ``time_limit=T`` (anytime), each complete
  schedule they meet polished by insert/swap moves unless ``--no-polish``, the best one refined
  (ruin and recreate alternating with window re-planning unless ``--no-windows``);
* ramp: beam widths 1, 2, 4, ... each run to completion; the value at T is the best
  reached by a width whose run took at most T (RAMP is not anytime: a width too slow
  for T gives nothing, and its first width is reported with its own time);
* exact: ``time_limit=T`` (best schedule found at the limit);
* lns: the operational Greedy's schedule, polished and refined by the same moves as the
  learned searches' (ruin and recreate) for T: what the learned start is worth.

The best known value of an instance is the best over everything.  Prints the mean
value / best known per method and T, per size, family and mode, writes
``results.parquet``, ``anytime.md`` and one plot per size (value / best against T, log
x) to --out, and logs them to MLflow.  One process, one core: run it on a quiet machine.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[100, 300])
    p.add_argument("--families", nargs="+", default=["uniform", "conflict"])
    p.add_argument("--modes", nargs="+", default=["unitary", "utility"])
    p.add_argument("--times", type=float, nargs="+", default=[0.1, 1.0, 10.0])
    p.add_argument("--instances", type=int, default=4)
    p.add_argument("--methods", nargs="+", default=["policy", "sample", "beam", "mcts", "ramp", "exact", "lns"])
    p.add_argument("--checkpoint", default="", help="agent checkpoint; default: the shipped model of each mode")
    p.add_argument("--seed-base", type=int, default=900_000,
                   help="instance seeds: BASE + 1000 * size + 100 * family index + k (another base: other instances)")
    p.add_argument("--step", type=float, default=1.0, help="time step of the generated discrete graphs (s)")
    p.add_argument("--no-polish", dest="polish", action="store_false",
                   help="learned searches without the insert/swap polish of their schedules (search.polish)")
    p.add_argument("--window-graph", choices=("pruned", "unpruned"), default="pruned",
                   help="the arcs the refinement's windows sweep (learned searches and lns)")
    p.add_argument("--no-windows", dest="windows", action="store_false",
                   help="refinement (learned searches and lns) without window re-planning (planning.windows)")
    p.add_argument("--out", default="runs/anytime")
    p.add_argument("--mlflow-uri", default="")
    p.add_argument("--report", default="", metavar="DIR",
                   help="only rebuild DIR/anytime.md and the plots from an earlier run's DIR/results.parquet")
    a = p.parse_args()
    if any(t <= 0 for t in a.times):
        p.error("--times must be positive")

    import numpy as np
    import pandas as pd
    import torch

    from eosp.config import family_config
    from eosp.instances.generator import generate
    from eosp.solvers.base import run_solver
    from eosp.solvers.policy import resolve_agent

    if a.report:
        out = Path(a.report)
        if not (out / "results.parquet").is_file():
            p.error(f"--report {out}: no results.parquet there")
        report(pd.read_parquet(out / "results.parquet"), out, a)
        return
    torch.set_num_threads(1)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    from eosp.models.pretrained import PREFIX, default_name

    loaded = {}

    def agent_for(mode: str, n: int, limited: bool):
        """--checkpoint, or the shipped model a solver without one would use (by size and time limit)."""
        key = a.checkpoint or PREFIX + default_name(mode, n, limited)
        if key not in loaded:
            loaded[key] = resolve_agent("policy", key, None, mode)
        return loaded[key]

    for size in a.sizes:
        for family in a.families:
            for k in range(a.instances):
                seed = a.seed_base + 1000 * size + 100 * a.families.index(family) + k
                inst = generate(family_config(family, size, seed, graph={"step_s": a.step}))
                inst.pruned()
                for mode in a.modes:
                    def add(method, t, value, seconds, **extra):
                        rows.append({"size": size, "family": family, "instance": inst.name, "mode": mode,
                                     "method": method, "T": t, "value": value, "seconds": seconds, **extra})
                        print(f"[anytime] {inst.name} {mode} {method} T={t:g}: {value:.6g} ({seconds:.2f} s)",
                              flush=True)

                    if "policy" in a.methods:
                        t0 = time.perf_counter()
                        sol = run_solver("policy", inst, mode=mode, agent=agent_for(mode, inst.n_acq, False))
                        dt = time.perf_counter() - t0
                        for t in a.times:
                            add("policy", t, sol.value if dt <= t else np.nan, dt)
                    if "ramp" in a.methods:
                        runs, beam = [], 1
                        while True:
                            t0 = time.perf_counter()
                            sol = run_solver("ramp", inst, mode=mode, beam=beam)
                            runs.append((time.perf_counter() - t0, sol.value, beam))
                            if runs[-1][0] > max(a.times) or beam >= 256:
                                break
                            beam *= 2
                        for t in a.times:
                            ok = [r for r in runs if r[0] <= t]
                            v, dt, bw = ((max(r[1] for r in ok), max(r[0] for r in ok), max(r[2] for r in ok))
                                         if ok else (np.nan, runs[0][0], 1))
                            add("ramp", t, v, dt, beam=bw)
                    for method in ("sample", "beam", "mcts", "exact", "lns"):
                        if method not in a.methods:
                            continue
                        for t in a.times:
                            refine = {"windows": a.windows, "window_graph": a.window_graph}
                            kw = ({} if method == "exact" else refine if method == "lns" else
                                  {"agent": agent_for(mode, inst.n_acq, True), "polish": a.polish, **refine})
                            if method == "sample":
                                kw["samples"] = 16
                            if method == "beam":
                                kw["beam_width"] = 4
                            t0 = time.perf_counter()
                            sol = run_solver(method, inst, mode=mode, time_limit=t, **kw)
                            add(method, t, sol.value, time.perf_counter() - t0,
                                status=str(sol.info.get("status", "")))
    df = pd.DataFrame(rows)
    best = df.groupby(["instance", "mode"])["value"].transform("max")
    df["ratio"] = df["value"] / best
    df.to_parquet(out / "results.parquet")
    report(df, out, a)


def against_ramp(df) -> str:
    """Per size, mode and T: on how many instances each method is at or above RAMP's value, and the best of the
    learned searches (sample, beam, mcts) on each instance; with the mean of that best / best known."""
    import numpy as np
    import pandas as pd

    rows = []
    for (size, mode, t), d in df.groupby(["size", "mode", "T"]):
        piv = d.pivot_table(index="instance", columns="method", values="value")
        if "ramp" not in piv:
            continue
        best = piv.max(axis=1)
        learned = [m for m in ("sample", "beam", "mcts") if m in piv]
        cols = dict(piv.items())
        if learned:
            cols["best learned"] = piv[learned].max(axis=1)
        for m, v in cols.items():
            if m == "ramp":
                continue
            ok = v >= piv["ramp"] * (1 - 1e-12)
            rows.append({"size": size, "mode": mode, "T": t, "method": m,
                         "at or above RAMP": f"{int(ok.sum())}/{len(ok)}",
                         "mean / best known": round(float(np.nanmean(v / best)), 6)})
    return pd.DataFrame(rows).to_markdown(index=False) if rows else "(no RAMP runs)"


def report(df, out: Path, a) -> None:
    if "ratio" not in df:
        best = df.groupby(["instance", "mode"])["value"].transform("max")
        df["ratio"] = df["value"] / best
    table = (df.groupby(["size", "family", "mode", "method", "T"])["ratio"].mean().unstack("T").round(4))
    at_best = (df.assign(hit=(df["ratio"] >= 1 - 1e-9)).groupby(["size", "family", "mode", "method", "T"])["hit"]
               .mean().unstack("T").round(2))
    md = ("# Anytime benchmark\n\nMean value / best known (NaN: nothing within T)\n\n" + table.to_markdown()
          + "\n\nShare of instances at the best known value\n\n" + at_best.to_markdown()
          + "\n\nInstances at or above RAMP (T: the same time for both)\n\n" + against_ramp(df) + "\n")
    (out / "anytime.md").write_text(md)
    print(md)
    plots = plot(df, out)
    try:
        import mlflow

        from eosp.config import default_mlflow_uri

        mlflow.set_tracking_uri(default_mlflow_uri(a.mlflow_uri))
        mlflow.set_experiment("anytime")
        with mlflow.start_run(run_name=time.strftime("anytime-%Y%m%d-%H%M%S")):
            mlflow.log_params(vars(a) | {"sizes": str(a.sizes), "times": str(a.times)})
            for f in [out / "results.parquet", out / "anytime.md", *plots]:
                mlflow.log_artifact(str(f))
    except Exception as exc:  # the figures are on disk either way
        print(f"[anytime] MLflow logging skipped: {exc}")


def plot(df, out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for size, g in df.groupby("size"):
        modes = sorted(g["mode"].unique())
        fig, axes = plt.subplots(1, len(modes), figsize=(5 * len(modes), 3.6), squeeze=False)
        for ax, mode in zip(axes[0], modes):
            h = g[g["mode"] == mode].groupby(["method", "T"])["ratio"].mean().reset_index()
            for method, m in h.groupby("method"):
                ax.plot(m["T"], m["ratio"], marker="o", label=method)
            ax.set_xscale("log")
            ax.set_xlabel("seconds per instance")
            ax.set_ylabel("value / best known")
            ax.set_title(f"{size} acquisitions, {mode}")
            ax.legend(fontsize=8)
        fig.tight_layout()
        path = out / f"anytime-{size}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


if __name__ == "__main__":
    main()
