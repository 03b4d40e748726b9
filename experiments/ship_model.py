"""Ship a trained checkpoint as the package's pretrained model of a mode, with its record.

    python experiments/ship_model.py --mode unitary --run runs/ship-unitary-v1 \\
        --tests data/expert/parts/test-u100 data/expert/parts/test-c100 data/expert/parts/test-x100

Copies ``RUN/checkpoints/best`` (weights + JSON only) to ``models/pretrained/MODE/``,
decodes every unseen test instance greedily and compares with Greedy, RAMP and the
exact optimum, and writes ``MODEL.md`` beside the weights: the training command (from
the run's recorded configuration), the data sets and their seeds, and the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]


def evaluate(agent_tuple, mode: str, tests: list[str], exact_limit: float) -> list[dict]:
    import numpy as np

    from eosp.envs.sources import expand_shards
    from eosp.shards.io import read_instances
    from eosp.solvers.base import run_solver

    rows = []
    for test in tests:
        for inst in read_instances(expand_shards([test])):
            r = {"test": Path(test).name, "instance": inst.name, "n": inst.n_acq}
            for s in ("greedy", "ramp", "exact", "policy"):
                t0 = time.perf_counter()
                kw = {"agent": agent_tuple} if s == "policy" else ({"time_limit": exact_limit} if s == "exact" else {})
                sol = run_solver(s, inst, mode=mode, **kw)
                r[s], r[f"{s}_s"] = sol.value, time.perf_counter() - t0
                if s == "exact":
                    r["exact_status"] = sol.info.get("status", "")
            rows.append(r)
            print(f"[ship] {r['test']} {inst.name}: policy {r['policy']:.6g} exact {r['exact']:.6g} "
                  f"ramp {r['ramp']:.6g} greedy {r['greedy']:.6g}", flush=True)
    del np
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mode", required=True, choices=["unitary", "utility"])
    p.add_argument("--run", required=True, help="run directory of jobs/pretrain.py or jobs/train.py")
    p.add_argument("--tests", nargs="+", required=True)
    p.add_argument("--exact-limit", type=float, default=60.0, help="seconds of exact search per instance")
    a = p.parse_args()

    import pandas as pd
    import torch

    from eosp.models.checkpoint import load_agent, save_agent
    from eosp.models.pretrained import ROOT as PRE

    torch.set_num_threads(1)
    run = Path(a.run)
    agent, env_cfg, meta = load_agent(run / "checkpoints" / "best")
    dest = PRE / a.mode
    save_agent(agent, dest, env_cfg, {k: v for k, v in meta.items() if k in ("epoch", "iteration", "source")})
    rows = evaluate((agent, env_cfg, meta), a.mode, a.tests, a.exact_limit)
    df = pd.DataFrame(rows)
    per = df.groupby("test").apply(lambda g: pd.Series({
        "instances": len(g), "policy / exact": (g.policy / g.exact).mean(), "policy / RAMP": (g.policy / g.ramp).mean(),
        "policy / Greedy": (g.policy / g.greedy).mean(), "Greedy / exact": (g.greedy / g.exact).mean(),
        "exact proven": int((g.exact_status == "optimal").sum()),
        "at optimum": int((g.policy >= g.exact * (1 - 1e-9)).sum()),
        "below Greedy": int((g.policy < g.greedy * (1 - 1e-9)).sum()),
        "policy s / instance": g.policy_s.mean()}), include_groups=False)
    for c in ("instances", "exact proven", "at optimum", "below Greedy"):
        per[c] = per[c].astype(int).astype(str)  # counts print as integers
    history = run / "history.json"
    cfg = json.loads(history.read_text())["config"] if history.exists() else {}
    data_sets = cfg.get("imitation", {}).get("train_data", [])
    manifests = {}
    for d in data_sets:
        for shard in sorted(Path(d).glob("*.parquet")):
            part = shard.resolve().parent
            if (part / "manifest.json").exists() and part.name not in manifests:
                m = json.loads((part / "manifest.json").read_text())["dataset"]
                manifests[part.name] = {k: m[k] for k in ("family", "n_acquisitions", "n_instances", "seed")}
                manifests[part.name]["instance"] = {k: v for k, v in m.get("instance", {}).items()
                                                   if k in ("graph", "satellite")}
    md = [f"# Pretrained model: {a.mode} mode", "",
          f"Weights `agent.pt` (tensors only, `torch.load(weights_only=True)`) and `agent.json` "
          f"(model {json.dumps(cfg.get('model', {}))}, env reward `{env_cfg.reward}`).  Source run: "
          f"`{run.name}` ({meta.get('source', 'ppo')}, epoch/iteration {meta.get('epoch', meta.get('iteration'))}).",
          "", "## How it was trained", "", "```bash",
          "python experiments/expert_guided.py data      # data sets (seeds below) and expert demos:",
          "#   jobs/build_demos.py --modes unitary --action-sets true --beam 1",
          "#   jobs/build_demos.py --modes utility --action-sets true --beam 1 --sets-max-acquisitions 150",
          "python jobs/pretrain.py " + " ".join(f"--{k.replace('_', '-')} {v}" for k, v in _flags(cfg)), "```", "",
          "Training data (generated with jobs/build_shards.py; instance k of a set uses seed + k):", "",
          "| set | family | acquisitions | instances | seed | generator settings |", "|---|---|---|---|---|---|"]
    for name, m in manifests.items():
        md.append(f"| {name} | {m['family']} | {m['n_acquisitions']} | {m['n_instances']} | {m['seed']} | "
                  f"{json.dumps(m['instance'].get('graph', {}).get('step_s', ''))} s step, "
                  f"{m['instance'].get('satellite', {}).get('slew_model', '')} slews |")
    md += ["", "## Figures on unseen test sets (greedy decoding)", "",
           f"`python experiments/ship_model.py --mode {a.mode} --run {a.run} --exact-limit {a.exact_limit:g} "
           f"--tests {' '.join(a.tests)}`", "",
           "Ratios are means of per-instance ratios; 'exact' is the exact solver's best schedule within the limit "
           "('exact proven' counts the proven optima).", "",
           per.to_markdown(floatfmt=".4f"), ""]
    (dest / "MODEL.md").write_text("\n".join(md))
    df.to_csv(run / f"ship-{a.mode}.csv", index=False)
    print("\n".join(md))


def _flags(cfg: dict) -> list[tuple[str, str]]:
    out = []
    im = cfg.get("imitation", {})
    for k in ("train_data", "val_data", "epochs", "time_budget", "batch_size", "lr", "dagger_every",
              "dagger_instances", "dagger_beam", "regret_coeff", "set_tolerance", "seed"):
        if k in im:
            v = im[k]
            out.append((f"imitation.{k}", " ".join(map(str, v)) if isinstance(v, list) else v))
    env = cfg.get("env", {})
    out += [("env.reward", env.get("reward")), ("env.max-acquisitions", env.get("max_acquisitions"))]
    return out


if __name__ == "__main__":
    main()
