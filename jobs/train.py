"""Train the GNN agent with RLlib PPO, tracked in MLflow.

    python jobs/train.py --demo                       # small embedded defaults, local Ray
    python jobs/train.py --train.train-data data/train --train.val-data data/val --train.iterations 200
    ray job submit --working-dir . -- python jobs/train.py --train.train-data /shared/data/train ...
    python jobs/train.py --train.run-name NAME --train.resume true    # continue a run

Every flag comes from :class:`eosp.config.RunConfig` (``--help`` lists them):
``--model.hidden-dim 64`` goes to ``ModelConfig.hidden_dim``, then to the
RLModule's ``model_config``, then to ``EOSPAgent``'s layers.

Outputs (RUN_DIR/RUN_NAME): ``checkpoints/last`` and ``checkpoints/best`` (agent
weights + JSON config, loadable by ``eosp solve --solver policy``), ``run.json``
(the configuration and the MLflow run id), validation results and plots.  The
MLflow run gets the parameters, tags ``mode`` and ``reward`` (and ``primary_metric``),
per-iteration training and validation metrics (``val/selection_score``, the mean of
per-instance ratios that picks ``best``, under its own name; ``by_env_steps/...`` with
env steps as the step), a per-instance table of each validation (``validation/``), HTML
reports of the logged agent on the first validation instances (``validation/reports/``),
the agent as an MLflow model carrying its iteration and validation figures (metadata and
model metrics), and the learning curve against env steps and wall time.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from eosp.args import Parser, add_config_args, config_from_args, run_job  # noqa: E402
from eosp.config import MODEL_PRESETS, DatasetConfig, ModelConfig, RunConfig, flatten, from_dict, to_dict  # noqa: E402
from eosp.errors import InputError  # noqa: E402
from eosp.reward import objective_mode, reward  # noqa: E402

DEMO = {
    "train.train_data": "data/demo/train", "train.val_data": "data/demo/val", "train.iterations": 6,
    "train.train_batch_size": 400, "train.minibatch_size": 100, "train.validate_every": 3,
    "train.checkpoint_every": 3, "env.max_acquisitions": 64, "train.run_name": "demo",
    "train.overwrite": True,  # the demo's own run, replaced by each demo
}
DEMO_DATA = {"data/demo/train": (24, 1000), "data/demo/val": (8, 900_000)}
DEMO_ACQ = 50


def read_config_file(path: str, cls: type):
    """The config dataclass `cls` of a JSON file (--config); a one-line InputError naming the file otherwise."""
    from eosp.errors import InputError

    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"--config {path}", "file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"--config {path}", f"cannot be read: {exc}") from None
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise InputError(path, f"must hold a JSON object (a {cls.__name__}), not {type(data).__name__}")
    try:
        return from_dict(cls, data)
    except (ValueError, TypeError, KeyError) as exc:
        raise InputError(path, f"not a valid {cls.__name__}: {exc}") from None


def parse(argv: list[str] | None) -> tuple[RunConfig, argparse.Namespace]:
    p = Parser(prog="train.py", description=__doc__.splitlines()[0],
               formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    p.add_argument("--demo", action="store_true",
                   help="small embedded defaults: build a tiny data set if missing, train briefly, compare to Greedy")
    p.add_argument("--config", default="", help="a RunConfig JSON (e.g. a sweep's best_config.json) used as the "
                                                "base; flags given on the command line apply on top")
    add_config_args(p, RunConfig)
    ns = p.parse_args(argv)
    if ns.demo:
        for k, v in DEMO.items():
            if k not in vars(ns):
                setattr(ns, k, v)
    preset = vars(ns).get("train.preset", "cpu")
    if preset not in MODEL_PRESETS:
        p.error(f"--train.preset: unknown preset {preset!r}; one of {', '.join(MODEL_PRESETS)}")
    if ns.config:
        base = read_config_file(ns.config, RunConfig)
        base.train.resume, base.train.run_name, base.train.overwrite = False, "", False
    else:
        base = RunConfig(model=from_dict(ModelConfig, MODEL_PRESETS[preset]))
    cfg = config_from_args(RunConfig, ns, base=base)
    need = reward(cfg.env.reward).n_values  # the value heads the reward needs (lexicographic: one per class)
    if need > 1:
        cfg.model.n_values = max(cfg.model.n_values, need)
    if not cfg.train.run_name:
        cfg.train.run_name = time.strftime("%Y%m%d-%H%M%S")
    return cfg, ns


def mlflow_uri(cfg: RunConfig) -> str:
    from eosp.config import default_mlflow_uri

    return default_mlflow_uri(cfg.train.mlflow_uri)


def ensure_demo_data(cfg: RunConfig) -> None:
    """The demo's data sets, built when missing, and built again when an older eosp wrote them in a shard format
    this one no longer reads (they are the demo's own: eosp-marked directories of generated instances)."""
    import shutil

    from eosp.errors import InputError
    from eosp.jobs.build_shards import DATASET_KIND
    from eosp.jobs.build_shards import run as build
    from eosp.ownership import kind_of
    from eosp.shards.io import ShardReader

    for path, (n, seed) in DEMO_DATA.items():
        shards = sorted(Path(path).glob("shard-*.parquet"))
        if (Path(path) / "manifest.json").exists() and shards and kind_of(Path(path)) == DATASET_KIND:
            try:
                ShardReader(shards[0])
            except InputError as exc:
                print(f"[train] the demo data set {path} cannot be read ({exc.message}): building it again",
                      flush=True)
                shutil.rmtree(path)
        if not (Path(path) / "manifest.json").exists():
            print(f"[train] building demo data set {path} ({n} instances of {DEMO_ACQ} acquisitions)", flush=True)
            build(DatasetConfig(out=path, family="uniform", n_acquisitions=DEMO_ACQ, n_instances=n, per_shard=4,
                                seed=seed), cfg.ray)


def main(argv: list[str] | None = None) -> int:
    """The job; user errors are one line ``train.py: error: ...`` and exit 2 before Ray or MLflow start."""
    return run_job(_main, argv, "train.py")


def preflight(cfg: RunConfig, ns: argparse.Namespace) -> None:
    """What is refused before Ray starts: the run dir (missing to resume, or not ours to replace), the data sets,
    the starting checkpoint, an unreachable MLflow."""
    from eosp.jobs.preflight import check_mlflow, require_data, require_findable, require_run_dir

    require_findable(cfg.train.run_dir, "--train.run-dir")
    run_dir = Path(cfg.train.run_dir) / cfg.train.run_name
    if cfg.train.resume and not (run_dir / "run.json").exists():
        raise InputError("--train.resume", f"no run {run_dir / 'run.json'} to resume")
    require_run_dir(run_dir, "run", "--train", resume=cfg.train.resume, overwrite=cfg.train.overwrite)
    if not ns.demo:  # the demo builds its data set when missing
        require_data(cfg.train.train_data, "--train.train-data")
        if cfg.train.val_data:
            require_data(cfg.train.val_data, "--train.val-data")
    if cfg.train.init_checkpoint and not Path(cfg.train.init_checkpoint).exists():
        raise InputError(f"--train.init-checkpoint {cfg.train.init_checkpoint}", "checkpoint not found")
    check_mlflow(cfg.train.mlflow_uri, "--train.mlflow-uri")


def resumed(cfg: RunConfig, ns: argparse.Namespace, run_file: Path) -> tuple[RunConfig, str, int, float, list]:
    """A resumed run's saved configuration (with the iterations asked now), MLflow run, iteration, best score and
    history; flags given beside --train.resume are ignored, and said."""
    prev = json.loads(run_file.read_text())
    given = {k for k in vars(ns) if "." in k and k not in ("train.resume", "train.iterations", "train.run_name",
                                                             "train.run_dir")}
    if given:
        print(f"[train] warning: --train.resume continues the saved configuration; ignoring "
              f"{', '.join('--' + k.replace('_', '-') for k in sorted(given))}", file=sys.stderr)
    cfg = from_dict(RunConfig, {**prev["config"], "train": {**prev["config"]["train"],
                                                             "iterations": cfg.train.iterations, "resume": True}})
    return (cfg, prev["mlflow_run_id"], prev["iteration"], prev.get("best_score", float("-inf")),
            prev.get("history", []))


def say_done(cfg: RunConfig, ns: argparse.Namespace, history: list, start_iter: int, wall: float) -> None:
    """The run's closing lines: iterations done, the validation against the baselines and what it means (demo)."""
    t = cfg.train
    summary = history[-1] if history else {}
    done = history[-1]["iteration"] - start_iter if history else 0  # fewer than asked when the time budget ended it
    print(f"[train] done: {t.run_name}, {done} iterations this session in {wall:.0f} s; "
          f"checkpoints in {Path(t.run_dir) / t.run_name / 'checkpoints'}")
    if "val/ratio_to_greedy" in summary:
        print("[train] validation (greedy decoding) vs baselines:")
        for s in ("greedy", "ramp"):
            print(f"  {s:7s} mean {summary[f'val/{s}_mean']:.6g}  policy/{s} {summary[f'val/ratio_to_{s}']:.4f}  "
                  f"wins/ties/losses {summary[f'val/wins_vs_{s}']:.0f}/{summary[f'val/ties_vs_{s}']:.0f}/"
                  f"{summary[f'val/losses_vs_{s}']:.0f}")
    if ns.demo and "val/ratio_to_greedy" in summary:
        show_shipped(cfg, wall)


def log_artifacts(history: list, run_dir: Path, validator) -> None:
    """The run's artifacts: the learning curve, the agent as an MLflow model (loaded from code + weights, no
    pickle), the validation reports of the final checkpoint (the best, else the last)."""
    import mlflow

    from eosp.training.plots import learning_curve

    if history:
        png = learning_curve(history, run_dir / "learning_curve")
        mlflow.log_artifact(str(png))
        mlflow.log_artifact(str(png.with_suffix(".svg")))
    ckpt_dir = run_dir / "checkpoints"
    final = ckpt_dir / ("best" if (ckpt_dir / "best").exists() else "last")
    if final.exists():
        log_agent_model(final)
        if validator is not None:
            log_validation_reports(validator, final, run_dir)


def _main(argv: list[str] | None) -> int:
    cfg, ns = parse(argv)
    from eosp.jobs.preflight import make_run_dir, ray_nodes, require_cluster_fits

    preflight(cfg, ns)
    import mlflow
    import ray
    import torch

    from eosp.jobs.ray_init import init_ray
    from eosp.models.checkpoint import load_agent, load_start, save_agent
    from eosp.training.loop import Trainer
    from eosp.training.ppo import estimate_value_scale
    from eosp.training.validation import Validator, selection_score

    torch.set_num_threads(1)
    init_ray(cfg.ray.address, cfg.ray.num_cpus)
    t = cfg.train
    run_dir = Path(t.run_dir) / t.run_name
    ckpt_dir = run_dir / "checkpoints"
    run_file = run_dir / "run.json"
    start_iter, best = 0, float("-inf")
    run_id = None
    history: list[dict] = []
    if t.resume:
        cfg, run_id, start_iter, best, history = resumed(cfg, ns, run_file)
        t = cfg.train
    # before anything is written or built: can this Ray cluster run the env runners and the learner?
    require_cluster_fits(t, ray_nodes(), torch.cuda.device_count() if t.num_gpus_per_learner > 0 else None)
    if ns.demo:
        ensure_demo_data(cfg)
    make_run_dir(run_dir, t.overwrite and not t.resume)
    init = None
    if t.init_checkpoint and not t.resume:
        init = load_start(t.init_checkpoint, cfg.env.reward, "train")
        cfg.model = init.cfg
    if cfg.model.value_scale <= 0:
        cfg.model.value_scale = estimate_value_scale(cfg)
        print(f"[train] value scale {cfg.model.value_scale:.3g} (mean return of random episodes)", flush=True)

    logging.getLogger("mlflow").setLevel(logging.WARNING)  # its INFO lines (creating tables, experiments) are noise
    from eosp.jobs.tracking import use_experiment

    use_experiment(mlflow_uri(cfg), t.experiment)
    active = mlflow.start_run(run_id=run_id, run_name=None if run_id else t.run_name)
    run_id = active.info.run_id
    # what a run list filters on: the objective and the reward variant
    mlflow.set_tags({"mode": objective_mode(cfg.env), "reward": cfg.env.reward})
    if not t.resume:
        mlflow.log_params({k: (json.dumps(v) if isinstance(v, (list, tuple)) else v) for k, v in flatten(cfg).items()})
        mlflow.log_dict(to_dict(cfg), "config.json")

    def save_state(iteration: int) -> None:
        state = {"config": to_dict(cfg), "mlflow_run_id": run_id, "iteration": iteration, "best_score": best,
                 "history": history}
        from eosp.atomic import atomic_path

        with atomic_path(run_file) as tmp:
            tmp.write_text(json.dumps(state, indent=1))

    # baselines first: their Ray tasks need the CPUs that the env runners will hold
    validator = Validator(t.val_data, cfg.env) if t.val_data else None
    if validator:
        base = {f"val/{s}_mean": float(v.mean()) for s, v in validator.baselines.items()}
        mlflow.log_metrics(base, step=0)
    trainer = Trainer(cfg, validator)
    if t.resume and (ckpt_dir / "last").exists():
        trainer.load(load_agent(ckpt_dir / "last")[0])
        print(f"[train] resumed {t.run_name} at iteration {start_iter}", flush=True)
    elif init is not None:
        trainer.load(init)

    t_start = time.perf_counter()
    wall0 = history[-1].get("perf/wall_s", 0.0) if history else 0.0  # wall time of the sessions before (resume)
    for it in range(start_iter, t.iterations):
        out_of_time = t.time_budget > 0 and time.perf_counter() - t_start > t.time_budget
        last = it + 1 == t.iterations or out_of_time
        metrics, agent = trainer.train(validate=(it + 1) % t.validate_every == 0 or last)
        metrics["perf/wall_s"] = wall0 + time.perf_counter() - t_start
        improved = agent is not None and selection_score(metrics) > best
        if improved:
            best = selection_score(metrics)
            save_agent(agent, ckpt_dir / "best", cfg.env, {"iteration": it + 1, "val": metrics})
            save_state(max(start_iter, it + 1 - (it + 1) % t.checkpoint_every))  # `best` is never lost
        mlflow.log_metrics(metrics, step=it + 1)
        if agent is not None:
            log_validation(trainer.last_validation, metrics, run_dir, it + 1, improved)
        history.append({"iteration": it + 1, **metrics})
        print(f"[train] iteration {it + 1}/{t.iterations}: return {metrics.get('train/episode_return_mean', 0):.3f}"
              f", {metrics.get('perf/env_steps_per_s', 0):.0f} env steps/s"
              + (f", val ratio to greedy {metrics['val/ratio_to_greedy']:.4f} to ramp {metrics['val/ratio_to_ramp']:.4f}"
                 f" (ratios of means); selection score {selection_score(metrics):.4f}"
                 if "val/ratio_to_greedy" in metrics else ""), flush=True)
        if (it + 1) % t.checkpoint_every == 0 or last:
            agent = agent or trainer.agent()
            save_agent(agent, ckpt_dir / "last", cfg.env, {"iteration": it + 1})
            save_state(it + 1)
        if out_of_time:
            print(f"[train] time budget of {t.time_budget:.0f} s reached", flush=True)
            break
    wall = time.perf_counter() - t_start

    log_artifacts(history, run_dir, validator)
    mlflow.log_metric("perf/train_wall_s", wall)
    mlflow.end_run()
    trainer.stop()
    say_done(cfg, ns, history, start_iter, wall)
    uri = mlflow_uri(cfg)
    where = f"open {uri}" if uri.startswith("http") else f"mlflow ui --backend-store-uri {uri}"
    print(f"[train] MLflow: {where}   (run {run_id}, experiment '{t.experiment}')")
    ray.shutdown()
    return 0


def show_shipped(cfg: RunConfig, wall: float) -> None:
    """The demo's last words: what its numbers mean, then the shipped model of the same objective on the demo's
    validation instances and on conflict-family ones (where Greedy is weak), against Greedy, RAMP and the optimum."""
    from eosp.config import family_config
    from eosp.evaluation.shipped import compare, reading
    from eosp.instances.generator import generate

    mode = objective_mode(cfg.env)
    print(f"[train] what this means: policy/X is the mean over the validation instances of the trained policy's value "
          f"over X's (1.0 = as good); wins/ties/losses count the instances where it is above / equal / below. "
          f"{wall:.0f} s of PPO from scratch rarely beats Greedy; imitation of the exact solver does. The shipped "
          f"{mode} model (models/pretrained-agents/{mode}), solving with its defaults:", flush=True)
    # the demo's validation instances again, from their seeds: the data set keeps only their pruned arcs, the
    # exact solver needs all of them
    n_val, seed = DEMO_DATA["data/demo/val"]
    val = [generate(family_config("uniform", DEMO_ACQ, seed + k)) for k in range(n_val)]
    conflict = [generate(family_config("conflict", DEMO_ACQ, 990_000 + i)) for i in range(8)]
    comps = [compare(f"demo validation ({len(val)})", val, mode),
             compare(f"conflict family ({len(conflict)})", conflict, mode)]
    for c in comps:
        print(c.line(), flush=True)
    print(f"[train] {reading(comps)}", flush=True)


def log_validation(result, metrics: dict, run_dir: Path, iteration: int, best: bool) -> None:
    """After a validation: the primary metric's name as a tag, the training return and the primary metric
    against env steps (``by_env_steps/...``, step = env steps: MLflow charts them on that axis; wall time is
    MLflow's own axis), and the per-instance table as an artifact (``validation/``; the best one also as
    ``validation/best_instances.csv``)."""
    import mlflow

    from eosp.training.validation import SELECTION_KEY, primary_metric, write_instance_table

    mlflow.set_tag("primary_metric", f"{SELECTION_KEY} = {primary_metric(metrics)}")
    steps = int(metrics.get("perf/env_steps_lifetime", iteration))
    mlflow.log_metrics({f"by_env_steps/{k}": metrics[k] for k in (SELECTION_KEY, "train/episode_return_mean")
                        if k in metrics}, step=steps)
    if result is None:
        return
    table = write_instance_table(result, run_dir / "validation" / f"instances_iter{iteration:05d}.csv")
    mlflow.log_artifact(str(table), "validation")
    if best:
        mlflow.log_artifact(str(write_instance_table(result, run_dir / "validation" / "best_instances.csv")),
                            "validation")


def write_validation_reports(validator, agent, out_dir: Path, n: int = 2) -> list[Path]:
    """HTML reports (eosp.evaluation.html_report) of the first `n` validation instances: the policy's schedule
    (greedy decoding, the reference) next to Greedy's, each missed acquisition explained; only where the data
    set kept the unpruned arcs that checking a schedule needs."""
    from eosp.evaluation.html_report import write_report
    from eosp.instances.schedule import from_internal_nodes
    from eosp.solvers.base import run_solver
    from eosp.solvers.policy import rollout

    pages = []
    for p in validator.prepared[:n]:
        inst = with_unpruned_arcs(p.inst)
        if inst is None:  # a data set stored without them: the report cannot check its schedules
            continue
        nodes, _ = rollout(agent, p, validator.env_cfg)
        scheds = {"policy": from_internal_nodes(inst, nodes),
                  "greedy": from_internal_nodes(inst, run_solver("greedy", inst, mode=validator.mode).nodes)}
        pages.append(write_report(inst, scheds, Path(out_dir) / f"{inst.name}.html", reference="policy",
                                  overwrite=True))
    return pages


def with_unpruned_arcs(inst):
    """`inst` with its unpruned arcs, read again from its shard when validation loaded only the pruned ones
    (the reports check schedules on every arc); None when the shard does not store them."""
    from eosp.shards.io import ShardReader

    if inst.unpruned_graph is not None:
        return inst
    path, _, row = str(inst.meta.get("source", "")).rpartition("#")
    if not path or not row.isdigit():
        return None
    full = ShardReader(path).read(int(row), unpruned=True)
    return full if full.unpruned_graph is not None else None


def log_validation_reports(validator, checkpoint: Path, run_dir: Path, n: int = 2) -> None:
    """:func:`write_validation_reports` of the checkpoint, logged to ``validation/reports``; a failure only warns."""
    import mlflow

    from eosp.models.checkpoint import load_agent

    try:
        for page in write_validation_reports(validator, load_agent(checkpoint)[0], run_dir / "validation" / "reports",
                                             n):
            mlflow.log_artifact(str(page), "validation/reports")
    except Exception as exc:  # the reports must not lose the run
        print(f"[train] warning: could not write the validation reports: {exc}", file=sys.stderr)


def model_metadata(checkpoint: Path) -> dict:
    """What the logged model carries about itself: the iteration it was saved at and its validation figures
    (from the checkpoint's agent.json), the primary metric named."""
    from eosp.training.validation import SELECTION_KEY, primary_metric

    meta = json.loads((checkpoint / "agent.json").read_text())
    val = {k: float(v) for k, v in (meta.get("val") or {}).items() if k.startswith("val/")}
    out = {"checkpoint": checkpoint.name, "iteration": meta.get("iteration"), "validation": val}
    if val:
        out["primary_metric"] = primary_metric(val)
        out[SELECTION_KEY] = val.get(SELECTION_KEY, val[primary_metric(val)])
    return out


def log_agent_model(checkpoint: Path) -> None:
    """Log the agent as an MLflow pyfunc model built from code (eosp.training.mlflow_model) and its weights,
    carrying its iteration and validation figures (:func:`model_metadata`) as metadata and as the model's
    metrics."""
    import importlib.util

    import mlflow

    # the file itself is logged (MLflow runs it when loading), never a pickled object
    code = Path(importlib.util.find_spec("eosp.training.mlflow_model").origin)
    try:
        # a progress bar for copying two small local files is noise in a job's log
        os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")
        meta = model_metadata(checkpoint)
        from mlflow.models import ModelSignature
        from mlflow.types import ColSpec, Schema
        from mlflow.types.schema import Array

        # what predict takes and returns (eosp.training.mlflow_model): instance directories in, schedules out
        signature = ModelSignature(inputs=Schema([ColSpec("string", "instance_dir")]),
                                   outputs=Schema([ColSpec("string", "instance_dir"), ColSpec("long", "n_acquisitions"),
                                                   ColSpec("double", "value"), ColSpec(Array("long"), "nodes")]))
        with warnings.catch_warnings():  # an input example would be an instance directory: none travels with it
            warnings.filterwarnings("ignore", message=".*input example was not provided.*")
            info = mlflow.pyfunc.log_model(name="agent", python_model=str(code), artifacts={"agent": str(checkpoint)},
                                           metadata=meta, signature=signature)
        if meta["validation"] and getattr(info, "model_id", None):
            mlflow.log_metrics(meta["validation"], step=int(meta["iteration"] or 0), model_id=info.model_id)
    except Exception as exc:  # logging the model must not lose the run
        print(f"[train] warning: could not log the MLflow model: {exc}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
