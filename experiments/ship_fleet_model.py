"""Ship a fleet policy checkpoint as the package's fleet model (models/pretrained-agents/fleet), with its record.

    python experiments/ship_fleet_model.py --run runs/fleet-dagger --checkpoint best \\
        --bench runs/bench-fleet-policy/results.csv

Copies ``RUN/checkpoints/CHECKPOINT`` (weights + JSON, a fleet checkpoint: refused when it is not one) to
``models/pretrained-agents/fleet/`` and writes ``MODEL.md`` beside it: the commands that trained it (from the
run's recorded configuration, and those of the runs it started from), its training fleets (the demo sets'
manifests), its validation figures, and the evaluation summary of ``--bench`` (benchmarks/bench_fleet_policy.py).
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

JOBS = {"imitation": "jobs/pretrain_fleet.py", "train": "jobs/train_fleet.py"}


def run_config(run: Path) -> tuple[str, dict]:
    """(the job section name, the recorded configuration) of a fleet run directory."""
    for name, section in (("history.json", "imitation"), ("run.json", "train")):
        if (run / name).exists():
            return section, json.loads((run / name).read_text())["config"]
    raise SystemExit(f"error: {run} holds no history.json or run.json: not a run of {' or '.join(JOBS.values())}")


def command(section: str, cfg: dict) -> str:
    """The command line of a run, from its recorded configuration (the fields that differ from the defaults)."""
    from eosp.config import FleetPretrainConfig, FleetRunConfig, changed, from_dict

    cls = FleetPretrainConfig if section == "imitation" else FleetRunConfig
    diff = changed(from_dict(cls, cfg), cls())
    flags = []
    for k, v in diff.items():
        if k.startswith("model.") or k in ("ray.num_cpus",):
            continue  # the model comes from the preset or the starting checkpoint; Ray's CPUs are the machine's
        v = " ".join(map(str, v)) if isinstance(v, (list, tuple)) else str(v).lower() if isinstance(v, bool) else v
        flags.append(f"--{k.replace('_', '-')} {v}")
    model = cfg.get("model", {})
    if not cfg.get(section, {}).get("init_checkpoint"):
        flags += [f"--model.hidden-dim {model.get('hidden_dim')}", f"--model.n-layers {model.get('n_layers')}",
                  f"--model.heads {model.get('heads')}"]
    return f"python {JOBS[section]} " + " ".join(flags)


def flags(diff: dict) -> str:
    """Command-line flags of the fields in `diff` (dotted names)."""
    out = []
    for k, v in diff.items():
        v = " ".join(map(str, v)) if isinstance(v, (list, tuple)) else str(v).lower() if isinstance(v, bool) else v
        out.append(f"--{k.replace('_', '-')} {v}")
    return " ".join(out)


def data_recipe(demo_sets: list[str]) -> list[str]:
    """The commands that made the demo sets' fleets: generate_fleets.py (from each fleet set's manifest) or eosp
    import (an aeossp case, by its case id), then build_fleet_demos.py (from the demo set's manifest)."""
    from eosp.config import changed, from_dict
    from eosp.jobs.build_fleet_demos import FleetDemoConfig
    from eosp.jobs.generate_fleets import FleetSetConfig

    lines = []
    for d in demo_sets:
        settings = json.loads((Path(d) / "manifest.json").read_text())["settings"]
        for f in settings["fleets"]:
            manifest = Path(f) / "manifest.json"
            if manifest.exists():
                cfg = from_dict(FleetSetConfig, json.loads(manifest.read_text())["settings"])
                diff = {k: v for k, v in changed(cfg, FleetSetConfig()).items() if not k.startswith("ray.")}
                lines.append(f"python jobs/generate_fleets.py {flags(diff)}")
            elif (Path(f) / "meta.json").exists():
                meta = json.loads((Path(f) / "meta.json").read_text())
                lines.append(f"eosp import ASTRO/benchmarks/aeossp_standard/dataset/cases/train/{meta['case_id']} "
                             f"--out {f}   # the aeossp train split, astro-reason {meta.get('source_commit', '')}")
        cfg = from_dict(FleetDemoConfig, settings)
        diff = {k: v for k, v in changed(cfg, FleetDemoConfig()).items() if not k.startswith("ray.")}
        lines.append(f"python jobs/build_fleet_demos.py {flags(diff)}")
    return lines


def recipe(run: Path) -> list[str]:
    """The commands of `run` and of the runs it started from, oldest first."""
    section, cfg = run_config(run)
    lines = [command(section, cfg)]
    init = cfg.get(section, {}).get("init_checkpoint", "")
    if init and Path(init).parent.name == "checkpoints":
        lines = recipe(Path(init).parent.parent) + [f"# then, from its checkpoint {Path(init).name}:"] + lines
    return lines


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--run", required=True)
    p.add_argument("--checkpoint", default="best", choices=["best", "last"])
    p.add_argument("--bench", default="", help="results.csv of benchmarks/bench_fleet_policy.py with this model")
    p.add_argument("--note", default="", help="a paragraph for MODEL.md (what was tried and not kept)")
    a = p.parse_args()
    from eosp.envs.constellation_obs import FLEET_NODE_FEATURES
    from eosp.models.checkpoint import load_fleet_agent, save_agent
    from eosp.models.pretrained import FLEET, ROOT
    from eosp.training.fleet_demos import read_demo_set

    run = Path(a.run)
    agent, env_cfg, meta = load_fleet_agent(run / "checkpoints" / a.checkpoint)
    dest = ROOT / FLEET
    lines = recipe(run)
    section, cfg = run_config(run)
    save_agent(agent, dest, env_cfg, {k: v for k, v in meta.items() if k in ("epoch", "iteration", "source", "val")})
    sets = []
    first = run
    while True:  # the demo sets of the first run of the chain (the imitation)
        s, c = run_config(first)
        init = c.get(s, {}).get("init_checkpoint", "")
        if not init or Path(init).parent.name != "checkpoints":
            break
        first = Path(init).parent.parent
    demo_sets = list(run_config(first)[1].get("imitation", {}).get("train_data", []))
    val_set = run_config(first)[1].get("imitation", {}).get("val_data", "")
    for d in demo_sets:
        recs = read_demo_set(d)
        sats = sorted(r.get("satellites", 0) for r in recs)
        sets.append(f"| {d} | {len(recs)} | {sats[0]}-{sats[-1]} | "
                    f"{sum(r.get('wcr', 0) for r in recs) / len(recs):.4f} |")
    val = meta.get("val", {})
    md = ["# Shipped model: the fleet policy", "",
          f"Weights `agent.pt` (tensors only, `torch.load(weights_only=True)`) and `agent.json` (a fleet checkpoint: "
          f"`env_kind` fleet, the {len(FLEET_NODE_FEATURES)} node features it reads, model "
          f"{json.dumps(cfg.get('model', {}))}, reward `{env_cfg.reward}`).  Source run: `{run.name}`, checkpoint "
          f"`{a.checkpoint}` ({meta.get('source', '')}, epoch/iteration {meta.get('epoch', meta.get('iteration'))}).  "
          "Used by `eosp solve FLEET_DIR --solver fleet-policy|fleet-sample` without `--checkpoint`.", "",
          "## How it was trained", "", "```bash",
          *data_recipe([*demo_sets, val_set] if val_set else demo_sets),
          *lines, "```", "", "Demonstrations (the fleet solver, 60 s a fleet, exact pass solver):", "",
          "| demo set | fleets | satellites | mean WCR of the fleet solver |", "|---|---|---|---|", *sets, ""]
    if val:
        md += ["## Validation (greedy decoding, held-out fleets: data/demos/val)", "",
               f"Mean WCR {val.get('val/policy_mean', float('nan')):.4f}; fleet solver (60 s) "
               f"{val.get('val/fleet_mean', float('nan')):.4f}, features-only decoder "
               f"{val.get('val/features_mean', float('nan')):.4f}, fleet greedy {val.get('val/greedy_mean', float('nan')):.4f}; "
               f"mean per-fleet ratio to the fleet solver {val.get('val/mean_ratio_to_fleet', float('nan')):.4f}.", ""]
    if a.bench:
        rows = list(csv.DictReader(open(a.bench)))
        aeossp = [r for r in rows if r["fleet"].split("/")[0].startswith("test")]
        num = (lambda r, k: float(r[k]) if r.get(k) not in (None, "") else float("nan"))
        md += ["## Evaluation", "", f"`python benchmarks/bench_fleet_policy.py ...` ({a.bench}; tables and commands in "
               "docs/results.md, \"The learned fleet scheduler\"): over the "
               f"{len(aeossp)} aeossp evaluation cases, mean WCR of the raw decode "
               f"{sum(num(r, 'raw') for r in aeossp) / max(len(aeossp), 1):.4f}, fleet-policy "
               f"{sum(num(r, 'policy') for r in aeossp) / max(len(aeossp), 1):.4f}, features-only "
               f"{sum(num(r, 'features') for r in aeossp) / max(len(aeossp), 1):.4f}, fleet greedy "
               f"{sum(num(r, 'greedy') for r in aeossp) / max(len(aeossp), 1):.4f}.", ""]
    if a.note:
        md += ["## Tried and not kept", "", a.note, ""]
    (dest / "MODEL.md").write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
