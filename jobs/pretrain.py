"""Imitation pretraining of the agent on the exact solver's demonstrations (then DAgger).

    python jobs/build_demos.py --data data/train data/val
    python jobs/pretrain.py --imitation.train-data data/train --imitation.val-data data/val \\
        --env.reward unitary --imitation.epochs 20 --imitation.dagger-every 2
    python jobs/train.py --train.init-checkpoint runs/NAME/checkpoints/best ...   # PPO fine-tuning

Writes ``<run_dir>/<run_name>/checkpoints/{best,last}`` (the PPO checkpoint format:
``agent.pt`` weights + ``agent.json``), a learning curve, and one MLflow run with the
expert-action accuracy, the value error and the validation ratios to the exact
optimum, RAMP and Greedy (greedy decoding).  Every flag is a field of
:class:`eosp.config.PretrainConfig` (``--help``).
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
from eosp.config import MODEL_PRESETS, ModelConfig, PretrainConfig, flatten, from_dict, to_dict  # noqa: E402
from eosp.errors import InputError  # noqa: E402
from eosp.reward import reward  # noqa: E402


def parse(argv: list[str] | None) -> PretrainConfig:
    p = Parser(prog="pretrain.py", description=__doc__.splitlines()[0],
               formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    add_config_args(p, PretrainConfig)
    ns = p.parse_args(argv)
    preset = vars(ns).get("imitation.preset", "cpu")
    if preset not in MODEL_PRESETS:
        p.error(f"--imitation.preset: unknown preset {preset!r}; one of {', '.join(MODEL_PRESETS)}")
    cfg = config_from_args(PretrainConfig, ns, base=PretrainConfig(model=from_dict(ModelConfig, MODEL_PRESETS[preset])))
    need = reward(cfg.env.reward).n_values  # the value heads the reward needs (lexicographic: one per class)
    if need > 1:
        cfg.model.n_values = max(cfg.model.n_values, need)
    if not cfg.imitation.run_name:
        cfg.imitation.run_name = "imitation-" + time.strftime("%Y%m%d-%H%M%S")
    return cfg


def run(cfg: PretrainConfig) -> dict:
    import mlflow
    import numpy as np
    import torch

    from eosp.jobs.ray_init import init_ray
    from eosp.models.agent import EOSPAgent
    from eosp.training.imitation import DemoData, fit
    from eosp.training.validation import Validator

    torch.set_num_threads(1)
    im = cfg.imitation
    torch.manual_seed(im.seed)
    init_ray(cfg.ray.address, cfg.ray.num_cpus)
    t_load = time.perf_counter()
    agent = None
    if im.init_checkpoint:
        from eosp.models.checkpoint import load_start

        agent = load_start(im.init_checkpoint, cfg.env.reward, "pretrain")
        cfg.model = agent.cfg
    data = DemoData(im.train_data, cfg.env, cfg.model.n_values, im.set_tolerance)
    if cfg.model.value_scale <= 0:
        cfg.model.value_scale = float(max(1.0, np.mean(data.start_values)))
    print(f"[pretrain] {len(data.instances)} training instances, {len(data.samples)} expert states "
          f"({time.perf_counter() - t_load:.1f} s); value scale {cfg.model.value_scale:.3g}", flush=True)
    validator = None
    if im.val_data:
        validator = Validator(im.val_data, cfg.env, im.max_val_instances, baselines=("greedy", "ramp", "exact"))
    run_dir = Path(im.run_dir) / im.run_name
    from eosp.jobs.preflight import make_run_dir

    make_run_dir(run_dir, im.overwrite)

    if agent is None:
        agent = EOSPAgent(cfg.model)
    from eosp.jobs.tracking import use_experiment

    use_experiment(im.mlflow_uri, im.experiment)
    mlflow.start_run(run_name=im.run_name)
    mlflow.log_params({k: (json.dumps(v) if isinstance(v, (list, tuple)) else v) for k, v in flatten(cfg).items()})
    mlflow.log_dict(to_dict(cfg), "config.json")
    mlflow.log_metrics({"data/instances": len(data.instances), "data/expert_states": len(data.samples)}, step=0)

    dagger = (lambda policy, rng: data.add_policy_states(policy, im.dagger_instances, im.dagger_beam, rng))
    history = fit(agent, data, validator, im, cfg.env, run_dir, to_dict(cfg), dagger)
    mlflow.end_run()
    return {"history": history, "checkpoint": str(run_dir / "checkpoints" / "best"), "run_dir": str(run_dir)}


def main(argv: list[str] | None = None) -> int:
    """The job; user errors are one line ``pretrain.py: error: ...`` and exit 2 before Ray or MLflow start."""
    return run_job(_main, argv, "pretrain.py")


def _main(argv: list[str] | None) -> int:
    cfg = parse(argv)
    from eosp.jobs.preflight import check_mlflow, require_data, require_findable, require_run_dir

    im = cfg.imitation
    require_findable(im.run_dir, "--imitation.run-dir")
    require_run_dir(Path(im.run_dir) / im.run_name, "run", "--imitation", overwrite=im.overwrite)
    require_data(im.train_data, "--imitation.train-data")
    if im.val_data:
        require_data(im.val_data, "--imitation.val-data")
    if im.init_checkpoint and not Path(im.init_checkpoint).exists():
        raise InputError(f"--imitation.init-checkpoint {im.init_checkpoint}", "checkpoint not found")
    check_mlflow(im.mlflow_uri, "--imitation.mlflow-uri")
    out = run(cfg)
    h = out["history"][-1]
    print(f"[pretrain] done: checkpoints in {Path(out['checkpoint']).parent}"
          + (f"; last validation: policy / optimum {h['val/ratio_to_exact']:.4f}, / RAMP {h['val/ratio_to_ramp']:.4f}, "
             f"/ Greedy {h['val/ratio_to_greedy']:.4f}" if "val/ratio_to_exact" in h else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
