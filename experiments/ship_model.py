"""Ship a trained checkpoint as the package's pretrained model of a mode, with its record.

    python experiments/ship_model.py --mode unitary --run runs/ship-unitary-v1 \\
        --tests data/expert/parts/test-u100 data/expert/parts/test-c100 data/expert/parts/test-x100

Copies ``RUN/checkpoints/best`` (weights + JSON only) to ``models/pretrained-agents/MODE/``,
decodes every unseen test instance greedily and compares with Greedy, RAMP and the
exact optimum, and writes ``MODEL.md`` beside the weights: the training command (from
the run's recorded configuration; when the run started from the shipped model, that
model's own recipe first), the data sets and their seeds, and the figures.

``--baselines experiments/records/ship-baselines-MODE.csv`` takes Greedy, RAMP and exact from an earlier
record of the same test instances (they do not depend on the model; the exact solver
alone takes minutes at 1000 acquisitions); ``--evaluate-only`` writes the record
``RUN/ship-MODE-CHECKPOINT.csv`` and prints the table without shipping anything.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]


BASELINES = ("greedy", "ramp", "exact")


def evaluate(agent_tuple, mode: str, tests: list[str], exact_limit: float, known=None) -> list[dict]:
    """Per test instance: value and seconds of Greedy, RAMP, exact and the policy.  `known`: a record
    (DataFrame of an earlier run of this script) whose baseline columns are taken instead of solving."""
    import numpy as np

    from eosp.envs.sources import expand_shards
    from eosp.shards.io import read_instances
    from eosp.solvers.base import run_solver

    rows = []
    for test in tests:
        for inst in read_instances(expand_shards([test])):
            r = {"test": Path(test).name, "instance": inst.name, "n": inst.n_acq}
            solvers = ("greedy", "ramp", "exact", "policy")
            if known is not None:
                key = (r["test"], inst.name)
                if key not in known.index:
                    raise SystemExit(f"error: --baselines has no row for {key[0]} / {key[1]}")
                old = known.loc[key]
                for b in BASELINES:
                    r[b], r[f"{b}_s"] = float(old[b]), float(old[f"{b}_s"])
                r["exact_status"] = old["exact_status"]
                solvers = ("policy",)
            for s in solvers:
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
    p.add_argument("--baselines", default="", help="an earlier ship-MODE.csv of the same tests: reuse its baselines")
    p.add_argument("--evaluate-only", action="store_true", help="write the record and print; do not ship")
    p.add_argument("--name", default="", help="ship as models/pretrained-agents/NAME (a variant, eosp.models.pretrained."
                                              "VARIANTS) instead of the mode's default model")
    p.add_argument("--checkpoint", default="best", choices=["best", "last"],
                   help="which checkpoint of the run: 'best' on its validation set, or 'last' (with a cosine decay and "
                        "a weight average the last is the settled one; a 20-instance validation cannot tell 0.5%%)")
    a = p.parse_args()

    import pandas as pd
    import torch

    from eosp.models.checkpoint import load_agent, save_agent
    from eosp.models.pretrained import ROOT as PRE

    torch.set_num_threads(1)
    run = Path(a.run)
    agent, env_cfg, meta = load_agent(run / "checkpoints" / a.checkpoint)
    dest = PRE / (a.name or a.mode)
    known = pd.read_csv(a.baselines).set_index(["test", "instance"]) if a.baselines else None
    rows = evaluate((agent, env_cfg, meta), a.mode, a.tests, a.exact_limit, known)
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
    df.to_csv(run / f"ship-{a.mode}-{a.checkpoint}.csv", index=False)
    if a.evaluate_only:
        print(per.to_markdown(floatfmt=".4f"))
        return
    history = run / "history.json"
    cfg = json.loads(history.read_text())["config"] if history.exists() else {}
    parent, ancestor = _parent_recipe(cfg, PRE)  # read before the new weights replace the old ones
    save_agent(agent, dest, env_cfg, {k: v for k, v in meta.items() if k in ("epoch", "iteration", "source")})
    data_sets = cfg.get("imitation", {}).get("train_data", [])
    manifests = {}
    for d in data_sets:
        for shard in sorted(Path(d).glob("*.parquet")):
            part = shard.resolve().parent
            if (part / "manifest.json").exists() and part.name not in manifests:
                m = json.loads((part / "manifest.json").read_text())["dataset"]
                manifests[part.name] = {k: m[k] for k in ("family", "n_acquisitions", "n_instances", "seed")}
                manifests[part.name]["instance"] = m.get("instance", {})
    md = [f"# Pretrained model: {a.mode} mode" + (f", variant `{a.name}` (`--checkpoint pretrained:{a.name}`)"
                                                  if a.name else ""), "",
          f"Weights `agent.pt` (tensors only, `torch.load(weights_only=True)`) and `agent.json` "
          f"(model {json.dumps(cfg.get('model', {}))}, env reward `{env_cfg.reward}`).  Source run: "
          f"`{run.name}`, checkpoint `{a.checkpoint}` ({meta.get('source', 'ppo')}, epoch/iteration "
          f"{meta.get('epoch', meta.get('iteration'))}).",
          "", "## How it was trained", ""]
    if parent:
        md += ["Descends from a model shipped before it (`--imitation.init-checkpoint models/pretrained-agents/"
               f"{ancestor}`, directly or through the runs named below), which was trained by:", "", "```bash",
               *parent, "```", "", "then:", ""]
    md.append("```bash")
    if not parent:  # a parent recipe already built the first mix
        md += ["python experiments/expert_guided.py data      # data sets (seeds below) and expert demos:",
               "#   jobs/build_demos.py --modes unitary --action-sets true --beam 1",
               "#   jobs/build_demos.py --modes utility --action-sets true --beam 1 --sets-max-acquisitions 150"]
    if any("train2" in str(d) for d in data_sets):
        md.append(f"python experiments/expert_guided.py data --more --modes {a.mode}   # the second mix, train2/")
    if any("train3" in str(d) for d in data_sets):
        md.append(f"python experiments/expert_guided.py data --dense --modes {a.mode}   # the third mix, train3/")
    md += ["python jobs/pretrain.py " + " ".join(f"--{k.replace('_', '-')} {v}" for k, v in _flags(cfg)), "```", "",
           "Training data (generated with jobs/build_shards.py; instance k of a set uses seed + k):", "",
           "| set | family | acquisitions | instances | seed | generator settings |", "|---|---|---|---|---|---|"]
    for name, m in manifests.items():
        md.append(f"| {name} | {m['family']} | {m['n_acquisitions']} | {m['n_instances']} | {m['seed']} | "
                  f"{_settings(m['instance'])} |")
    md += ["", "## Figures on unseen test sets (greedy decoding)", "",
           f"`python experiments/ship_model.py --mode {a.mode}" + (f" --name {a.name}" if a.name else "")
           + f" --run {a.run} --checkpoint {a.checkpoint} "
           f"--exact-limit {a.exact_limit:g}" + (f" --baselines {a.baselines}" if a.baselines else "")
           + f" --tests {' '.join(a.tests)}`" + (f" (Greedy, RAMP and exact from `{a.baselines}`, the record of an "
                                                  "earlier run of this script on the same instances)" if a.baselines else ""),
           "",
           "Ratios are means of per-instance ratios; 'exact' is the exact solver's best schedule within the limit "
           "('exact proven' counts the proven optima).", "",
           per.to_markdown(floatfmt=".4f"), ""]
    (dest / "MODEL.md").write_text("\n".join(md))
    print("\n".join(md))


def _settings(inst: dict) -> str:
    """The generator settings of a data set in a few words (orbit, agility, step, durations)."""
    orbit, sat, tg = inst.get("orbit", {}), inst.get("satellite", {}), inst.get("targets", {})
    return (f"{inst.get('graph', {}).get('step_s', '')} s step, {sat.get('slew_model', '')} slews "
            f"(rate {sat.get('max_rate_deg_s', '')} deg/s, accel {sat.get('max_accel_deg_s2', '')} deg/s2), "
            f"roll <= {sat.get('roll_max_deg', '')} deg, altitude {orbit.get('altitude_km', '')} km, "
            f"acquisitions {tg.get('duration_min_s', '')}-{tg.get('duration_max_s', '')} s")


def _parent_recipe(cfg: dict, shipped: Path) -> tuple[list[str], str]:
    """(the bash lines of a shipped model's recipe, its name) when this run descends from a model under `shipped`
    (else nothing): started from it, or from a checkpoint of a run (runs/NAME/checkpoints/C) that descends from
    it, whose command is then added."""
    init = cfg.get("imitation", {}).get("init_checkpoint", "") or cfg.get("train", {}).get("init_checkpoint", "")
    if not init:
        return [], ""
    start = Path(init)
    if start.resolve().parent == shipped.resolve():
        md = start / "MODEL.md"
        if not md.exists() or "```bash" not in md.read_text():
            return [], ""
        block = md.read_text().split("## How it was trained", 1)[-1]
        return [line for chunk in block.split("```bash")[1:]
                for line in chunk.split("```", 1)[0].strip().splitlines()], start.resolve().name
    history = start.parent.parent / "history.json"
    if start.parent.name != "checkpoints" or not history.exists():
        return [], ""
    up = json.loads(history.read_text())["config"]
    lines, ancestor = _parent_recipe(up, shipped)
    if not lines:
        return [], ""
    command = "python jobs/pretrain.py " + " ".join(f"--{k.replace('_', '-')} {v}" for k, v in _flags(up))
    return lines + [f"# then (its checkpoint {start.name} starts the next command):", command], ancestor


def _flags(cfg: dict) -> list[tuple[str, str]]:
    out = []
    im = cfg.get("imitation", {})
    for k in ("train_data", "val_data", "init_checkpoint", "epochs", "time_budget", "batch_size", "lr", "lr_schedule",
              "ema", "dagger_every", "dagger_instances", "dagger_beam", "regret_coeff", "set_tolerance", "seed",
              "run_name"):
        if k in im and not (k in ("init_checkpoint", "run_name") and not im[k]):
            v = im[k]
            out.append((f"imitation.{k}", " ".join(map(str, v)) if isinstance(v, list) else v))
    env = cfg.get("env", {})
    out += [("env.reward", env.get("reward")), ("env.max-acquisitions", env.get("max_acquisitions"))]
    out += [(f"env.{k}", str(env[k]).lower() if isinstance(env[k], bool) else env[k])
            for k in ("lookahead", "plan") if env.get(k)]
    return out


if __name__ == "__main__":
    main()
