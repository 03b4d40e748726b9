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

    from eosp.atomic import atomic_path
    from eosp.jobs.ray_init import init_ray
    from eosp.models.agent import EOSPAgent
    from eosp.models.checkpoint import save_agent
    from eosp.training.imitation import DemoData, WeightAverage, cosine_lr, train_epoch
    from eosp.training.plots import imitation_curve
    from eosp.training.validation import Validator, selection_score

    torch.set_num_threads(1)
    im = cfg.imitation
    torch.manual_seed(im.seed)
    rng = np.random.default_rng(im.seed)
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
    ckpt = run_dir / "checkpoints"
    from eosp.jobs.preflight import make_run_dir

    make_run_dir(run_dir, im.overwrite)

    if agent is None:
        agent = EOSPAgent(cfg.model)
    opt = torch.optim.Adam(agent.parameters(), lr=im.lr, weight_decay=im.weight_decay)
    from eosp.jobs.tracking import use_experiment

    use_experiment(im.mlflow_uri, im.experiment)
    mlflow.start_run(run_name=im.run_name)
    mlflow.log_params({k: (json.dumps(v) if isinstance(v, (list, tuple)) else v) for k, v in flatten(cfg).items()})
    mlflow.log_dict(to_dict(cfg), "config.json")
    mlflow.log_metrics({"data/instances": len(data.instances), "data/expert_states": len(data.samples)}, step=0)

    history, best = [], float("-inf")
    average = WeightAverage(agent, im.ema) if im.ema > 0 else None
    t0 = time.perf_counter()
    deadline = t0 + im.time_budget if im.time_budget > 0 else None
    for epoch in range(1, im.epochs + 1):
        lr_at = None
        if im.lr_schedule == "cosine":
            def lr_at(done: float, epoch: int = epoch) -> float:
                by_epochs = (epoch - 1 + done) / im.epochs
                by_time = (time.perf_counter() - t0) / im.time_budget if deadline is not None else 0.0
                return cosine_lr(im.lr, max(by_epochs, by_time))
        metrics = train_epoch(agent, opt, data.samples, im, rng, deadline, average, lr_at)
        metrics["train/lr"] = opt.param_groups[0]["lr"]
        policy = average.model if average is not None else agent  # what is validated, saved and rolled out
        out_of_time = deadline is not None and time.perf_counter() > deadline
        last = epoch == im.epochs or out_of_time
        if validator is not None and (epoch % im.validate_every == 0 or last):
            metrics.update(validator.run(policy).metrics)
            if selection_score(metrics) > best:
                best = selection_score(metrics)
                save_agent(policy, ckpt / "best", cfg.env, {"epoch": epoch, "val": metrics, "source": "imitation"})
        if im.dagger_every and epoch % im.dagger_every == 0 and not last:
            metrics.update(data.add_policy_states(policy, im.dagger_instances, im.dagger_beam, rng))
        metrics["wall_s"] = time.perf_counter() - t0
        history.append({"epoch": epoch, **metrics})
        mlflow.log_metrics(metrics, step=epoch)
        print(f"[pretrain] epoch {epoch}: loss {metrics['train/policy_loss']:.4f} accuracy "
              f"{metrics['train/accuracy']:.4f} value {metrics['train/value_loss']:.4f}"
              + (f"  val /optimum {metrics['val/ratio_to_exact']:.4f} /ramp {metrics['val/ratio_to_ramp']:.4f} "
                 f"/greedy {metrics['val/ratio_to_greedy']:.4f} (per instance /optimum "
                 f"{metrics['val/mean_ratio_to_exact']:.4f})" if "val/ratio_to_exact" in metrics else "")
              + (f"  dagger +{metrics['dagger/states_added']:.0f} states" if "dagger/states_added" in metrics else "")
              + f"  ({metrics['wall_s']:.0f} s)", flush=True)
        if out_of_time:
            print(f"[pretrain] time budget of {im.time_budget:.0f} s reached", flush=True)
            break
    policy = average.model if average is not None else agent
    save_agent(policy, ckpt / "last", cfg.env, {"epoch": history[-1]["epoch"], "source": "imitation"})
    if validator is None:
        save_agent(policy, ckpt / "best", cfg.env, {"epoch": history[-1]["epoch"], "source": "imitation"})
    png = imitation_curve(history, run_dir / "learning_curve")
    mlflow.log_artifact(str(png))
    mlflow.log_artifact(str(png.with_suffix(".svg")))
    with atomic_path(run_dir / "history.json") as tmp:
        tmp.write_text(json.dumps({"config": to_dict(cfg), "history": history}, indent=1))
    mlflow.log_metric("perf/train_wall_s", time.perf_counter() - t0)
    mlflow.end_run()
    return {"history": history, "checkpoint": str(ckpt / "best"), "run_dir": str(run_dir)}


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
