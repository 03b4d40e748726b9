"""Ray Tune sweep of the fleet policy over hidden_dim, n_layers and the learning rate: imitation trials, ASHA,
MLflow (one parent run, one child per trial).

    python jobs/tune_fleet.py --tune.name fleet-arch --tune.hidden-dims 32 64 --tune.n-layers 2 4 \\
        --imitation.train-data data/demos/train --imitation.val-data data/demos/val --imitation.epochs 8

Every trial is an imitation run of the fleet policy (the loop of jobs/pretrain_fleet.py: the same demonstrations,
the same epochs) that reports its validation each epoch (``--tune.metric``, by default the selection score: the
mean per-fleet ratio of greedy decoding to the fleet solver's schedules); ASHA stops the poor ones after
``grace_period`` epochs.  The sweep's scaffolding (MLflow parent and children, resuming, the best trial) is
jobs/tune.py's.  At the end the best trial's configuration goes to ``best_config.json`` and its agent to ``best/``
(a fleet checkpoint: ``--imitation.init-checkpoint``, ``--checkpoint`` of the fleet solvers).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from eosp.args import Parser, add_config_args, config_from_args, prefixed_config, run_job  # noqa: E402
from eosp.config import MODEL_PRESETS, FleetPretrainConfig, ModelConfig, TuneConfig, from_dict, to_dict  # noqa: E402


def trial(config: dict) -> None:
    """One Tune trial: `config["run"]` a FleetPretrainConfig dict, with the sampled values applied."""
    import numpy as np
    import torch
    from ray import tune

    from eosp.envs.constellation_obs import N_FLEET_FEATURES
    from eosp.models.agent import EOSPAgent
    from eosp.models.checkpoint import load_fleet_agent, save_agent
    from eosp.training.fleet_demos import FleetDemoData
    from eosp.training.imitation import train_epoch
    from eosp.training.validation import FleetValidator

    torch.set_num_threads(1)
    cfg = from_dict(FleetPretrainConfig, config["run"])
    cfg.model.hidden_dim, cfg.model.n_layers = int(config["hidden_dim"]), int(config["n_layers"])
    im = cfg.imitation
    im.lr = float(config["lr"])
    torch.manual_seed(im.seed)
    rng = np.random.default_rng(im.seed)
    data = FleetDemoData(im.train_data, cfg.env)
    validator = FleetValidator(im.val_data, cfg.env, im.max_val_instances)
    start, ck = 0, tune.get_checkpoint()
    if ck is not None:
        with ck.as_directory() as d:
            start = json.loads((Path(d) / "trial.json").read_text())["epoch"]
            agent, _, _ = load_fleet_agent(d, cfg.env.reward)
    else:
        cfg.model.value_scale = cfg.model.value_scale or float(np.mean(data.start_values)) or 1.0
        agent = EOSPAgent(cfg.model, N_FLEET_FEATURES)
    opt = torch.optim.Adam(agent.parameters(), lr=im.lr, weight_decay=im.weight_decay)
    for epoch in range(start, im.epochs):
        metrics = train_epoch(agent, opt, data.samples, im, rng)
        metrics.update(validator.run(agent).metrics)
        with tempfile.TemporaryDirectory() as d:
            save_agent(agent, d, cfg.env, {"epoch": epoch + 1, "source": "tune"})
            (Path(d) / "trial.json").write_text(json.dumps({"epoch": epoch + 1, "run": to_dict(cfg)}))
            tune.report({**{k.replace("/", "_"): v for k, v in metrics.items()}, "iteration": epoch + 1},
                        checkpoint=tune.Checkpoint.from_directory(d))


def run(cfg: FleetPretrainConfig, tc: TuneConfig) -> dict:
    import ray
    from ray import tune

    from eosp.config import default_mlflow_uri
    from eosp.jobs.ray_init import init_ray
    from eosp.jobs.tune import best_of, sweep

    init_ray(cfg.ray.address, cfg.ray.num_cpus)
    im = cfg.imitation
    # trials run in their own working directories: every path they read must be absolute
    im.train_data = tuple(str(Path(p).resolve()) for p in im.train_data)
    im.val_data = str(Path(im.val_data).resolve())
    uri = default_mlflow_uri(im.mlflow_uri)
    sweep_dir = (Path(im.run_dir) / "tune").resolve() / tc.name
    space = {"run": to_dict(cfg), "hidden_dim": tune.grid_search(list(tc.hidden_dims)),
             "n_layers": tune.grid_search(list(tc.n_layers)), "lr": tune.grid_search(list(tc.lrs))}
    results, best, ck, parent_id, client = sweep(trial, space, tc, sweep_dir, im.experiment, uri, im.epochs,
                                                 {"cpu": tc.cpus_per_trial}, {"run": to_dict(cfg)})
    metric = tc.metric.replace("/", "_")
    best_cfg = from_dict(FleetPretrainConfig, best.config["run"])
    best_cfg.model.hidden_dim, best_cfg.model.n_layers = int(best.config["hidden_dim"]), int(best.config["n_layers"])
    best_cfg.imitation.lr = float(best.config["lr"])
    out_best = sweep_dir / "best"
    if out_best.exists():
        shutil.rmtree(out_best)
    with ck.as_directory() as d:
        shutil.copytree(d, out_best)
    (sweep_dir / "best_config.json").write_text(json.dumps(to_dict(best_cfg), indent=1))
    rows = [{"hidden_dim": r.config["hidden_dim"], "n_layers": r.config["n_layers"], "lr": r.config["lr"],
             "epochs": r.metrics.get("iteration"), metric: r.metrics.get(metric),
             "val_policy_mean": r.metrics.get("val_policy_mean"), "best": best_of(r, metric)[0],
             "best_epoch": best_of(r, metric)[1]} for r in results]
    (sweep_dir / "trials.json").write_text(json.dumps(rows, indent=1))
    summary = {"best_score": best_of(best, metric)[0], "hidden_dim": best_cfg.model.hidden_dim,
               "n_layers": best_cfg.model.n_layers, "lr": best_cfg.imitation.lr, "trials": rows}
    client.log_metric(parent_id, "best_score", summary["best_score"])
    for k in ("hidden_dim", "n_layers", "lr"):
        client.set_tag(parent_id, f"best.{k}", str(summary[k]))
    client.log_artifact(parent_id, str(sweep_dir / "best_config.json"))
    client.log_artifact(parent_id, str(sweep_dir / "trials.json"))
    client.set_terminated(parent_id)
    for r in rows:
        print(f"[tune_fleet] hidden_dim {r['hidden_dim']}, n_layers {r['n_layers']}, lr {r['lr']}: {metric} "
              f"{r[metric]:.4f} after {r['epochs']} epochs (validation WCR {r['val_policy_mean']:.4f}), best "
              f"{r['best']:.4f} at epoch {r['best_epoch']}", flush=True)
    print(f"[tune_fleet] {len(rows)} trials; best {metric} = {summary['best_score']:.6g} with hidden_dim "
          f"{summary['hidden_dim']}, n_layers {summary['n_layers']}, lr {summary['lr']}; config "
          f"{sweep_dir / 'best_config.json'}, checkpoint {out_best}", flush=True)
    ray.shutdown()
    return summary


BASELINES = ("exact", "fleet", "ramp", "features", "greedy")
METRICS = ("val/selection_score", "val/policy_mean", *(f"val/{m}_to_{b}" for m in ("ratio", "mean_ratio")
                                                         for b in BASELINES))


def check_tune(tc: TuneConfig) -> None:
    """The sweep's options that Tune would only meet after it started: a sweep name that is a plain name (the
    sweep stays in RUN_DIR/tune/), a metric the trials report (:data:`METRICS`)."""
    from eosp.errors import InputError
    from eosp.jobs.tune import check_sweep_name

    check_sweep_name(tc)
    if tc.metric not in METRICS:
        raise InputError("--tune.metric", f"{tc.metric!r} is no metric the trials report; one of {', '.join(METRICS)}")


def main(argv: list[str] | None = None) -> int:
    """The job; user errors are one line ``tune_fleet.py: error: ...`` and exit 2 before Ray or MLflow start."""
    return run_job(_main, argv, "tune_fleet.py")


def _main(argv: list[str] | None) -> int:
    from eosp.errors import InputError
    from eosp.jobs.preflight import check_mlflow, require_findable
    from eosp.jobs.tune import SWEEP_KIND
    from eosp.ownership import check_output
    from eosp.training.fleet_demos import read_demo_set

    p = Parser(prog="tune_fleet.py", description=__doc__.splitlines()[0],
               formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    add_config_args(p, TuneConfig, prefix="tune.")
    add_config_args(p, FleetPretrainConfig)
    ns = p.parse_args(argv)
    preset = vars(ns).get("imitation.preset", "cpu")
    if preset not in MODEL_PRESETS:
        raise InputError("--imitation.preset", f"unknown preset {preset!r}; one of {', '.join(MODEL_PRESETS)}")
    cfg = config_from_args(FleetPretrainConfig, ns,
                           base=FleetPretrainConfig(model=from_dict(ModelConfig, MODEL_PRESETS[preset])))
    tc = prefixed_config(TuneConfig, ns, "tune.")
    if "tune.metric" not in vars(ns):
        tc.metric = "val/selection_score"  # the mean per-fleet ratio to the fleet solver (FleetValidator)
    check_tune(tc)
    im = cfg.imitation
    if not im.val_data:
        raise InputError("--imitation.val-data", "a sweep needs held-out fleets to compare its trials")
    for d in im.train_data + (im.val_data,):
        read_demo_set(d)
    require_findable(im.run_dir, "--imitation.run-dir")
    sweep_dir = Path(im.run_dir) / "tune" / tc.name
    try:  # a sweep resumes in its own directory; one eosp did not write is never written into
        check_output(sweep_dir, SWEEP_KIND, directory=True, reuse=True)
    except InputError as exc:
        raise InputError(f"--imitation.run-dir {im.run_dir} --tune.name {tc.name}", f"{sweep_dir} {exc.message}") \
            from None
    check_mlflow(im.mlflow_uri, "--imitation.mlflow-uri")
    run(cfg, tc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
