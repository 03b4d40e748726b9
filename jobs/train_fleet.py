"""PPO fine-tuning of the fleet policy on Ray: multi-agent env runners over the training fleets, one shared module.

    python jobs/train_fleet.py --train.init-checkpoint runs/fleet-imitation/checkpoints/best \\
        --train.train-data data/demos/train --train.val-data data/demos/val --env.team-reward 1 \\
        --train.iterations 20 --train.num-env-runners 1

The constellation environment (eosp.training.fleet_env) runs on RLlib's multi-agent env runners, each owning every
num_env_runners-th fleet of the demo set given as ``--train.train-data`` (its fleets; the demonstrations
themselves are not used here); every satellite slot maps to one module, the project's RLModule (parameter
sharing).  ``--env.team-reward 1`` gives every agent the fleet's rewards from its decision on: its return is the
fleet's WCR still to come, what the imitation run's value head learned (eosp.training.fleet_demos).  Validation:
greedy decoding on held-out fleets against the fleet solver, the fleet greedy and the features-only decoder.
Writes ``<run_dir>/<run_name>/checkpoints/{best,last}`` (weights + JSON, a fleet policy), ``run.json``, the
learning curve, and one MLflow run (parameters, per-iteration training and validation metrics).  Every flag is a
field of :class:`eosp.config.FleetRunConfig` (``--help``).
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
from eosp.config import MODEL_PRESETS, FleetRunConfig, ModelConfig, flatten, from_dict, to_dict  # noqa: E402
from eosp.errors import InputError  # noqa: E402


def parse(argv: list[str] | None) -> FleetRunConfig:
    p = Parser(prog="train_fleet.py", description=__doc__.splitlines()[0],
               formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    add_config_args(p, FleetRunConfig)
    ns = p.parse_args(argv)
    preset = vars(ns).get("train.preset", "cpu")
    if preset not in MODEL_PRESETS:
        p.error(f"--train.preset: unknown preset {preset!r}; one of {', '.join(MODEL_PRESETS)}")
    cfg = config_from_args(FleetRunConfig, ns, base=FleetRunConfig(model=from_dict(ModelConfig, MODEL_PRESETS[preset])))
    if cfg.train.overlap_sampling:
        raise InputError("--train.overlap-sampling", "not for fleets (multi-agent episodes)")
    if cfg.train.resume:
        raise InputError("--train.resume", "a fleet run starts from a checkpoint instead (--train.init-checkpoint)")
    if not cfg.train.run_name:
        cfg.train.run_name = "fleet-ppo-" + time.strftime("%Y%m%d-%H%M%S")
    return cfg


def run(cfg: FleetRunConfig) -> dict:
    import mlflow
    import ray
    import torch

    from eosp.atomic import atomic_path
    from eosp.jobs.preflight import make_run_dir
    from eosp.jobs.ray_init import init_ray
    from eosp.models.checkpoint import load_fleet_agent, save_agent
    from eosp.training.loop import Trainer
    from eosp.training.plots import learning_curve
    from eosp.training.validation import FleetValidator, selection_score

    torch.set_num_threads(1)
    t = cfg.train
    init_ray(cfg.ray.address, cfg.ray.num_cpus)
    init = None
    if t.init_checkpoint:
        init, _, _ = load_fleet_agent(t.init_checkpoint, cfg.env.reward)
        cfg.model = init.cfg
    if cfg.model.value_scale <= 0:
        cfg.model.value_scale = 1.0  # returns are fractions of the fleet's weight
    validator = FleetValidator(t.val_data, cfg.env) if t.val_data else None
    run_dir = Path(t.run_dir) / t.run_name
    make_run_dir(run_dir, t.overwrite)
    ckpt = run_dir / "checkpoints"
    from eosp.jobs.tracking import use_experiment

    use_experiment(t.mlflow_uri, t.experiment)
    active = mlflow.start_run(run_name=t.run_name)
    mlflow.set_tags({"env_kind": "fleet", "reward": cfg.env.reward})
    mlflow.log_params({k: (json.dumps(v) if isinstance(v, (list, tuple)) else v) for k, v in flatten(cfg).items()})
    mlflow.log_dict(to_dict(cfg), "config.json")
    trainer = Trainer(cfg, validator)
    if init is not None:
        trainer.load(init)
    history, best = [], float("-inf")
    if validator is not None and init is not None:  # the starting point, as iteration 0
        res = validator.run(init)
        history.append({"iteration": 0, "perf/wall_s": 0.0, **res.metrics})
        best = selection_score(res.metrics)
        save_agent(init, ckpt / "best", cfg.env, {"iteration": 0, "val": res.metrics, "source": "init"})
        mlflow.log_metrics(res.metrics, step=0)
    t0 = time.perf_counter()
    for it in range(t.iterations):
        out_of_time = t.time_budget > 0 and time.perf_counter() - t0 > t.time_budget
        last = it + 1 == t.iterations or out_of_time
        metrics, agent = trainer.train(validate=(it + 1) % t.validate_every == 0 or last)
        metrics["perf/wall_s"] = time.perf_counter() - t0
        if agent is not None and selection_score(metrics) > best:
            best = selection_score(metrics)
            save_agent(agent, ckpt / "best", cfg.env, {"iteration": it + 1, "val": metrics, "source": "ppo"})
        mlflow.log_metrics(metrics, step=it + 1)
        history.append({"iteration": it + 1, **metrics})
        print(f"[train_fleet] iteration {it + 1}/{t.iterations}: return {metrics.get('train/episode_return_mean', 0):.4f}"
              f", {metrics.get('perf/env_steps_per_s', 0):.0f} env steps/s"
              + (f", validation WCR {metrics['val/policy_mean']:.4f} (fleet solver {metrics['val/fleet_mean']:.4f}, "
                 f"features-only {metrics['val/features_mean']:.4f})" if "val/policy_mean" in metrics else ""),
              flush=True)
        if (it + 1) % t.checkpoint_every == 0 or last:
            save_agent(agent or trainer.agent(), ckpt / "last", cfg.env, {"iteration": it + 1, "source": "ppo"})
        if out_of_time:
            print(f"[train_fleet] time budget of {t.time_budget:.0f} s reached", flush=True)
            break
    trainer.stop()
    if history:
        png = learning_curve([h for h in history if h["iteration"] > 0] or history, run_dir / "learning_curve")
        mlflow.log_artifact(str(png))
    with atomic_path(run_dir / "run.json") as tmp:
        tmp.write_text(json.dumps({"config": to_dict(cfg), "mlflow_run_id": active.info.run_id,
                                   "iteration": history[-1]["iteration"], "best_score": best, "history": history},
                                  indent=1))
    mlflow.log_metric("perf/train_wall_s", time.perf_counter() - t0)
    mlflow.end_run()
    ray.shutdown()
    return {"history": history, "run_dir": str(run_dir), "best": best}


def main(argv: list[str] | None = None) -> int:
    """The job; user errors are one line ``train_fleet.py: error: ...`` and exit 2 before Ray or MLflow start."""
    return run_job(_main, argv, "train_fleet.py")


def _main(argv: list[str] | None) -> int:
    cfg = parse(argv)
    from eosp.jobs.preflight import check_mlflow, require_findable, require_run_dir
    from eosp.training.fleet_demos import read_demo_set

    t = cfg.train
    require_findable(t.run_dir, "--train.run-dir")
    require_run_dir(Path(t.run_dir) / t.run_name, "run", "--train", overwrite=t.overwrite)
    for d in (t.train_data,) + ((t.val_data,) if t.val_data else ()):
        read_demo_set(d)
    if t.init_checkpoint:
        from eosp.models.checkpoint import load_fleet_agent

        load_fleet_agent(t.init_checkpoint, cfg.env.reward)  # another layout or objective: one line, before Ray
    check_mlflow(t.mlflow_uri, "--train.mlflow-uri")
    out = run(cfg)
    h = out["history"][-1] if out["history"] else {}
    print(f"[train_fleet] done: checkpoints in {Path(out['run_dir']) / 'checkpoints'}"
          + (f"; last validation WCR {h['val/policy_mean']:.4f}" if "val/policy_mean" in h else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
