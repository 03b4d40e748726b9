"""Imitation of the fleet solver by the fleet policy (the shared GATv2 agent, one module for every satellite).

    python jobs/build_fleet_demos.py --fleets FLEETS... --out data/demos/train      # demonstrations (Ray tasks)
    python jobs/build_fleet_demos.py --fleets VAL_FLEETS... --out data/demos/val
    python jobs/pretrain_fleet.py --imitation.train-data data/demos/train --imitation.val-data data/demos/val \\
        --imitation.epochs 20 --imitation.time-budget 1200
    python jobs/train_fleet.py --train.init-checkpoint runs/NAME/checkpoints/best ...    # PPO fine-tuning

Each demonstration (the fleet solver's schedule of a training fleet) is played in the constellation environment
(eosp.training.fleet_demos): every decision of the acting satellite is a labelled state (the follower's action,
and the fleet's WCR still to come as the value target).  The loop is the single pass's (eosp.training.imitation.fit:
cosine learning rate, weight averaging, DAgger rounds where the fleet solver completes days the policy began).
Writes ``<run_dir>/<run_name>/checkpoints/{best,last}`` (``agent.pt`` weights + ``agent.json``, marked as a fleet
policy with the node features it reads), a learning curve, ``history.json`` and one MLflow run with the accuracy,
the value error and the validation WCR against the fleet solver, the fleet greedy and the features-only decoder
(greedy decoding).  Every flag is a field of :class:`eosp.config.FleetPretrainConfig` (``--help``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from eosp.args import Parser, add_config_args, config_from_args, run_job  # noqa: E402
from eosp.config import (MODEL_PRESETS, FleetImitationConfig, FleetPretrainConfig, ModelConfig, flatten,  # noqa: E402
                         from_dict, to_dict)
from eosp.errors import InputError  # noqa: E402

INERT = ("regret_coeff", "set_tolerance", "dagger_beam")  # single-pass fields the fleet demonstrations cannot serve


def parse(argv: list[str] | None) -> FleetPretrainConfig:
    p = Parser(prog="pretrain_fleet.py", description=__doc__.splitlines()[0],
               formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    add_config_args(p, FleetPretrainConfig)
    ns = p.parse_args(argv)
    preset = vars(ns).get("imitation.preset", "cpu")
    if preset not in MODEL_PRESETS:
        p.error(f"--imitation.preset: unknown preset {preset!r}; one of {', '.join(MODEL_PRESETS)}")
    base = FleetPretrainConfig(model=from_dict(ModelConfig, MODEL_PRESETS[preset]))
    cfg = config_from_args(FleetPretrainConfig, ns, base=base)
    for name in INERT:
        if getattr(cfg.imitation, name) != getattr(FleetImitationConfig(), name):
            raise InputError(f"--imitation.{name.replace('_', '-')}", "the fleet demonstrations carry no action values")
    if not cfg.imitation.run_name:
        cfg.imitation.run_name = "fleet-imitation-" + time.strftime("%Y%m%d-%H%M%S")
    return cfg


def run(cfg: FleetPretrainConfig) -> dict:
    import mlflow
    import numpy as np
    import torch

    from eosp.envs.constellation_obs import N_FLEET_FEATURES
    from eosp.jobs.preflight import make_run_dir
    from eosp.jobs.ray_init import init_ray
    from eosp.models.agent import EOSPAgent
    from eosp.training.fleet_demos import FleetDemoData
    from eosp.training.imitation import fit
    from eosp.training.validation import FleetValidator

    torch.set_num_threads(1)
    im = cfg.imitation
    torch.manual_seed(im.seed)
    init_ray(cfg.ray.address, cfg.ray.num_cpus)
    t_load = time.perf_counter()
    agent = None
    if im.init_checkpoint:
        from eosp.models.checkpoint import load_fleet_agent

        agent, _, _ = load_fleet_agent(im.init_checkpoint, cfg.env.reward)
        cfg.model = agent.cfg
        print(f"[pretrain_fleet] starting from {im.init_checkpoint}", flush=True)
    data = FleetDemoData(im.train_data, cfg.env)
    if cfg.model.value_scale <= 0:
        cfg.model.value_scale = float(np.mean(data.start_values)) or 1.0
    dropped = sum(r["dropped"] for r in data.replays)
    print(f"[pretrain_fleet] {len(data.fleets)} training fleets, {len(data.samples)} decisions "
          f"({time.perf_counter() - t_load:.1f} s; {dropped} observations of the demonstrations not playable); "
          f"value scale {cfg.model.value_scale:.3g}", flush=True)
    validator = FleetValidator(im.val_data, cfg.env, im.max_val_instances) if im.val_data else None
    if validator is not None:
        print("[pretrain_fleet] validation baselines (mean WCR): " + ", ".join(
            f"{k} {v.mean():.4f}" for k, v in validator.baselines.items()), flush=True)
    run_dir = Path(im.run_dir) / im.run_name
    make_run_dir(run_dir, im.overwrite)
    if agent is None:
        agent = EOSPAgent(cfg.model, N_FLEET_FEATURES)
    from eosp.jobs.tracking import use_experiment

    use_experiment(im.mlflow_uri, im.experiment)
    mlflow.start_run(run_name=im.run_name)
    mlflow.set_tags({"env_kind": "fleet", "reward": cfg.env.reward})
    mlflow.log_params({k: (json.dumps(v) if isinstance(v, (list, tuple)) else v) for k, v in flatten(cfg).items()})
    mlflow.log_dict(to_dict(cfg), "config.json")
    mlflow.log_dict({"replays": data.replays}, "demonstrations.json")
    mlflow.log_metrics({"data/fleets": len(data.fleets), "data/expert_states": len(data.samples),
                        "data/unplayable_observations": dropped}, step=0)
    if validator is not None:
        mlflow.log_metrics({f"val/{k}_mean": float(v.mean()) for k, v in validator.baselines.items()}, step=0)

    def dagger(policy, rng):
        from eosp.jobs.build_fleet_demos import complete_day

        return data.add_policy_states(policy, im.dagger_instances, complete_day, im.dagger_time_limit, rng)

    history = fit(agent, data, validator, im, cfg.env, run_dir, to_dict(cfg), dagger, job="pretrain_fleet")
    mlflow.end_run()
    return {"history": history, "checkpoint": str(run_dir / "checkpoints" / "best"), "run_dir": str(run_dir)}


def main(argv: list[str] | None = None) -> int:
    """The job; user errors are one line ``pretrain_fleet.py: error: ...`` and exit 2 before Ray or MLflow start."""
    return run_job(_main, argv, "pretrain_fleet.py")


def _main(argv: list[str] | None) -> int:
    cfg = parse(argv)
    from eosp.jobs.preflight import check_mlflow, require_findable, require_run_dir
    from eosp.training.fleet_demos import read_demo_set

    im = cfg.imitation
    require_findable(im.run_dir, "--imitation.run-dir")
    require_run_dir(Path(im.run_dir) / im.run_name, "run", "--imitation", overwrite=im.overwrite)
    for d in im.train_data + ((im.val_data,) if im.val_data else ()):
        read_demo_set(d)  # a demo set, or one line naming what it is not
    if im.init_checkpoint and not Path(im.init_checkpoint).exists():
        raise InputError(f"--imitation.init-checkpoint {im.init_checkpoint}", "checkpoint not found")
    check_mlflow(im.mlflow_uri, "--imitation.mlflow-uri")
    out = run(cfg)
    h = out["history"][-1]
    print(f"[pretrain_fleet] done: checkpoints in {Path(out['checkpoint']).parent}"
          + (f"; last validation (mean WCR): policy {h['val/policy_mean']:.4f}, fleet solver {h['val/fleet_mean']:.4f}, "
             f"features-only {h['val/features_mean']:.4f}, fleet greedy {h['val/greedy_mean']:.4f}"
             if "val/policy_mean" in h else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
