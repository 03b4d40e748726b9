"""Ray Tune sweep over hidden_dim, n_layers and the learning rate, with ASHA, tracked in MLflow.

    python jobs/tune.py --tune.name arch --tune.hidden-dims 16 32 64 --tune.n-layers 2 3 5 \\
        --train.train-data data/gen/train100 --train.val-data data/gen/val100 --train.iterations 30
    ray job submit --working-dir . -- python jobs/tune.py ...     # unchanged on a cluster

Every trial is a PPO training (the same loop as jobs/train.py) reporting its
validation score each iteration; ASHA stops the poor ones after
``grace_period`` iterations.  MLflow: one parent run named after the sweep, one
child run per trial (parameters and per-iteration metrics).  Trials checkpoint
every iteration; rerunning the same command resumes an interrupted sweep.  At the
end the best trial's configuration is written to ``best_config.json``
(``python jobs/train.py --config .../best_config.json``) and its agent to
``best/`` (``eosp solve --solver policy --checkpoint .../best``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from eosp.args import Parser, add_config_args, config_from_args, prefixed_config, run_job  # noqa: E402
from eosp.config import MODEL_PRESETS, ModelConfig, RunConfig, TuneConfig, from_dict, to_dict  # noqa: E402
from eosp.reward import objective_mode, reward  # noqa: E402


def trial(config: dict) -> None:
    """One Tune trial: `config["run"]` is a RunConfig dict with the sampled values applied."""
    import torch
    from ray import tune

    from eosp.models.checkpoint import load_agent, save_agent
    from eosp.training.loop import Trainer
    from eosp.training.ppo import estimate_value_scale
    from eosp.training.validation import Validator

    torch.set_num_threads(1)
    cfg = from_dict(RunConfig, config["run"])
    cfg.model.hidden_dim = int(config["hidden_dim"])
    cfg.model.n_layers = int(config["n_layers"])
    cfg.train.lr = float(config["lr"])
    cfg.train.num_env_runners = 0  # sampling inside the trial: one CPU per trial
    start = 0
    ck = tune.get_checkpoint()
    state = None
    if ck is not None:
        with ck.as_directory() as d:
            state = json.loads((Path(d) / "trial.json").read_text())
            agent, _, _ = load_agent(d)
        cfg.model.value_scale = state["value_scale"]
        start = state["iteration"]
    elif cfg.model.value_scale <= 0:
        cfg.model.value_scale = estimate_value_scale(cfg)
    validator = Validator(cfg.train.val_data, cfg.env) if cfg.train.val_data else None
    trainer = Trainer(cfg, validator)
    if state is not None:
        trainer.load(agent)
    for it in range(start, cfg.train.iterations):
        metrics, agent = trainer.train(validate=True)
        agent = agent or trainer.agent()
        with tempfile.TemporaryDirectory() as d:
            save_agent(agent, d, cfg.env, {"iteration": it + 1})
            (Path(d) / "trial.json").write_text(json.dumps({"iteration": it + 1, "value_scale": cfg.model.value_scale,
                                                            "run": to_dict(cfg)}))
            tune.report({**{k.replace("/", "_"): v for k, v in metrics.items()}, "iteration": it + 1},
                        checkpoint=tune.Checkpoint.from_directory(d))
    trainer.stop()


def sweep(trainable, space: dict, tc: TuneConfig, sweep_dir: Path, experiment: str, uri: str, max_t: int,
          resources: dict, state: dict):
    """Run a Ray Tune grid `space` of `trainable` (trials report ``iteration`` and ``tc.metric`` with "/" as "_"),
    ASHA stopping the poor trials after ``tc.grace_period`` iterations, tracked in MLflow (`uri`, `experiment`):
    one parent run named ``tc.name`` (created here, not by racing trials; its id kept in ``sweep.json`` beside
    `state`), one child run per trial.  A sweep directory with a Tuner state resumes.  Returns (results, the best
    trial's result, its best checkpoint, the parent run id, the MLflow client).  Shared by jobs/tune.py (PPO
    trials) and jobs/tune_fleet.py (fleet imitation trials)."""
    import mlflow
    from ray import tune
    from ray.air.integrations.mlflow import MLflowLoggerCallback
    from ray.tune.schedulers import ASHAScheduler

    from eosp.ownership import kind_of, mark_dir

    from eosp.jobs.tracking import use_experiment

    state_file = sweep_dir / "sweep.json"
    if state_file.exists():  # a sweep of this name ran: it resumes only with the same settings
        try:
            old = json.loads(state_file.read_text())
        except ValueError:
            old = None
        mine = json.loads(json.dumps({"tune": to_dict(tc), **state}))
        if not isinstance(old, dict) or any(old.get(k) != v for k, v in mine.items()):
            from eosp.errors import InputError

            raise InputError(f"--tune.name {tc.name}", f"{sweep_dir} holds a sweep of other settings: choose another "
                                                       "name (or the same settings to resume it)")
        print(f"[tune] resuming sweep {tc.name} from {sweep_dir} (the same settings)", flush=True)
    exp = use_experiment(uri, experiment)  # the database and the experiment created here, not by racing trials
    sweep_dir.mkdir(parents=True, exist_ok=True)
    if kind_of(sweep_dir) != SWEEP_KIND:
        mark_dir(sweep_dir, SWEEP_KIND)
    client = mlflow.tracking.MlflowClient(uri)
    if state_file.exists():
        parent_id = json.loads(state_file.read_text())["mlflow_parent_run_id"]
    else:
        parent_id = client.create_run(exp.experiment_id, run_name=tc.name, tags={"eosp.kind": "tune-sweep"}).info.run_id
        client.log_param(parent_id, "search_space", json.dumps(to_dict(tc)))
        state_file.write_text(json.dumps({"mlflow_parent_run_id": parent_id, "tune": to_dict(tc), **state}))
    metric = tc.metric.replace("/", "_")
    trainable = tune.with_resources(trainable, resources)
    callbacks = [MLflowLoggerCallback(tracking_uri=uri, experiment_name=experiment,
                                      tags={"mlflow.parentRunId": parent_id, "eosp.sweep": tc.name})]
    if tune.Tuner.can_restore(str(sweep_dir)) and (sweep_dir / "tuner.pkl").exists():
        print(f"[tune] resuming sweep {tc.name} from {sweep_dir}", flush=True)
        tuner = tune.Tuner.restore(str(sweep_dir), trainable, resume_errored=True, param_space=space)
    else:
        tuner = tune.Tuner(
            trainable, param_space=space,
            tune_config=tune.TuneConfig(metric=metric, mode="max", num_samples=tc.num_samples,
                                        scheduler=ASHAScheduler(time_attr="iteration", grace_period=tc.grace_period,
                                                                max_t=max(max_t, tc.grace_period))),
            run_config=tune.RunConfig(name=tc.name, storage_path=str(sweep_dir.parent), callbacks=callbacks,
                                      failure_config=tune.FailureConfig(max_failures=1),
                                      checkpoint_config=tune.CheckpointConfig(num_to_keep=1)),
        )
    # Ctrl-C stays the job's: Tune's own handler would stop the trials gracefully (saving, 10 s and more) and return
    # a result grid the job could not tell from a finished sweep.  The trials' checkpoints are on disk when they
    # are reported, the experiment's state every few seconds; the rerun resumes from them.
    os.environ["TUNE_DISABLE_SIGINT_HANDLER"] = "1"
    results = tuner.fit()
    if not any(r.checkpoint is not None for r in results):  # every trial failed: a defect, shown as such
        raise RuntimeError(f"no trial of sweep {tc.name} reported; the first error: "
                           f"{results.errors[0] if results.errors else None}")
    best = results.get_best_result(metric=metric, mode="max", scope="all")
    ck = best.get_best_checkpoint(metric=metric, mode="max") or best.checkpoint
    return results, best, ck, parent_id, client


def run(cfg: RunConfig, tc: TuneConfig) -> dict:
    import ray
    from ray import tune

    from eosp.jobs.ray_init import init_ray
    from eosp.training.validation import baseline_values

    init_ray(cfg.ray.address, cfg.ray.num_cpus)
    from eosp.config import default_mlflow_uri
    from eosp.jobs.preflight import ray_nodes, require_cluster_fits

    # what a trial runs (its learner and its sampling in the trial's actor), before anything is written
    require_cluster_fits(replace(cfg.train, num_env_runners=0, env_runner_resource=""), ray_nodes())

    # trials run in their own working directories: every path they read must be absolute
    cfg.train.train_data = str(Path(cfg.train.train_data).resolve())
    if cfg.train.val_data:
        cfg.train.val_data = str(Path(cfg.train.val_data).resolve())

    uri = default_mlflow_uri(cfg.train.mlflow_uri)
    sweep_dir = (Path(cfg.train.run_dir) / "tune").resolve() / tc.name
    # baselines once, in the driver, before the trials hold the CPUs
    if cfg.train.val_data:
        baseline_values(cfg.train.val_data, objective_mode(cfg.env))
    space = {"run": to_dict(cfg), "hidden_dim": tune.grid_search(list(tc.hidden_dims)),
             "n_layers": tune.grid_search(list(tc.n_layers)), "lr": tune.grid_search(list(tc.lrs))}
    gpus = cfg.train.num_gpus_per_learner  # a trial's learner runs in the trial's actor: Ray gives it the GPU
    results, best, ck, parent_id, client = sweep(
        trial, space, tc, sweep_dir, cfg.train.experiment, uri, cfg.train.iterations,
        {"cpu": tc.cpus_per_trial, **({"gpu": gpus} if gpus else {})}, {"run": to_dict(cfg)})
    metric = tc.metric.replace("/", "_")
    best_cfg = from_dict(RunConfig, best.config["run"])
    best_cfg.model.hidden_dim = int(best.config["hidden_dim"])
    best_cfg.model.n_layers = int(best.config["n_layers"])
    best_cfg.train.lr = float(best.config["lr"])
    best_cfg.train.num_env_runners = cfg.train.num_env_runners  # trials sample in-process; a full run need not
    out_best = sweep_dir / "best"
    if out_best.exists():
        shutil.rmtree(out_best)
    with ck.as_directory() as d:
        shutil.copytree(d, out_best)
        best_cfg.model.value_scale = json.loads((Path(d) / "trial.json").read_text())["value_scale"]
    (sweep_dir / "best_config.json").write_text(json.dumps(to_dict(best_cfg), indent=1))
    summary = {"best_score": best_of(best, metric)[0], "hidden_dim": best_cfg.model.hidden_dim,
               "n_layers": best_cfg.model.n_layers, "lr": best_cfg.train.lr, "trials": len(results)}
    client.log_metric(parent_id, "best_score", summary["best_score"])
    for k in ("hidden_dim", "n_layers", "lr"):
        client.set_tag(parent_id, f"best.{k}", str(summary[k]))
    client.log_artifact(parent_id, str(sweep_dir / "best_config.json"))
    client.set_terminated(parent_id)
    print(f"[tune] {len(results)} trials; best {metric} = {summary['best_score']:.6g} with hidden_dim "
          f"{summary['hidden_dim']}, n_layers {summary['n_layers']}, lr {summary['lr']}; config "
          f"{sweep_dir / 'best_config.json'}, checkpoint {out_best}", flush=True)
    ray.shutdown()
    return summary


def best_of(result, metric: str) -> tuple[float, int]:
    """A trial's best reported `metric` and the iteration it came at: the sweep picks trials and checkpoints by it
    (``scope="all"``), so it is what to print; a trial's last value can be lower."""
    df = result.metrics_dataframe
    if df is None or metric not in df or df[metric].isna().all():
        return float(result.metrics.get(metric, float("nan"))), int(result.metrics.get("iteration", 0) or 0)
    i = df[metric].idxmax()
    return float(df[metric][i]), int(df["iteration"][i]) if "iteration" in df else -1


SWEEP_KIND = "sweep"  # the mark (eosp.ownership) of a sweep directory: rerunning the sweep resumes in it


def main(argv: list[str] | None = None) -> int:
    """The job; user errors are one line ``tune.py: error: ...`` and exit 2 before Ray or MLflow start."""
    return run_job(_main, argv, "tune.py")


def check_sweep_name(tc: TuneConfig) -> None:
    """A sweep name that is a plain name: the sweep stays in RUN_DIR/tune/ (``../x`` would write elsewhere)."""
    from eosp.errors import InputError

    if tc.name in ("", ".", "..") or Path(tc.name).name != tc.name or "\\" in tc.name:
        raise InputError("--tune.name", f"{tc.name!r} is not a plain name: the sweep goes to RUN_DIR/tune/NAME")


def _main(argv: list[str] | None) -> int:
    p = Parser(prog="tune.py", description=__doc__.splitlines()[0],
               formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    add_config_args(p, TuneConfig, prefix="tune.")
    add_config_args(p, RunConfig)
    ns = p.parse_args(argv)
    preset = vars(ns).get("train.preset", "cpu")
    if preset not in MODEL_PRESETS:
        p.error(f"--train.preset: unknown preset {preset!r}; one of {', '.join(MODEL_PRESETS)}")
    cfg = config_from_args(RunConfig, ns, base=RunConfig(model=from_dict(ModelConfig, MODEL_PRESETS[preset])))
    tc = prefixed_config(TuneConfig, ns, "tune.")
    check_sweep_name(tc)
    need = reward(cfg.env.reward).n_values  # the value heads the reward needs (lexicographic: one per class)
    if need > 1:
        cfg.model.n_values = max(cfg.model.n_values, need)
    from eosp.errors import InputError
    from eosp.jobs.preflight import check_mlflow, require_data, require_findable
    from eosp.ownership import check_output

    require_findable(cfg.train.run_dir, "--train.run-dir")
    require_data(cfg.train.train_data, "--train.train-data")
    if cfg.train.val_data:
        require_data(cfg.train.val_data, "--train.val-data")
    sweep_dir = Path(cfg.train.run_dir) / "tune" / tc.name
    try:  # a sweep resumes in its own directory; one eosp did not write is never written into
        check_output(sweep_dir, SWEEP_KIND, directory=True, reuse=True)
    except InputError as exc:
        raise InputError(f"--train.run-dir {cfg.train.run_dir} --tune.name {tc.name}", f"{sweep_dir} {exc.message}") \
            from None
    check_mlflow(cfg.train.mlflow_uri, "--train.mlflow-uri")
    run(cfg, tc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
