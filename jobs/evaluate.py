"""Run solvers over test sets as parallel Ray tasks; write per-instance results, a report, MLflow.

    python jobs/evaluate.py --data data/test100 data/test300 --solvers greedy ramp exact --time-limit 120
    python jobs/evaluate.py --data data/test100 --solvers greedy ramp policy --checkpoint runs/X/checkpoints/best
    ray job submit --working-dir . -- python jobs/evaluate.py --data /shared/data/test100 ...

Work is spread over a pool of Ray actors (one per CPU), each keeping the agents it
has loaded, so a checkpoint is read once per worker and not once per instance.
Every schedule is checked with the independent checker (``instances.schedule.check``);
an infeasible one is a failure of the job.  Outputs in ``--out``: ``results.parquet``
(one row per instance and solver), ``report.md`` (the paper's table of average
scores with ratios to Greedy and RAMP, gaps to the proven optimum or the bound, win/
tie/loss counts), ``schedules/<instance>/<solver>.parquet``, ``reports/<instance>.html`` (the
planner's view of ``eosp report`` for the first ``--html-reports`` instances) and
``class_counts.png`` (acquisitions per priority class and solver); all logged to MLflow.

Each finished (instance, solver) result is kept at once in ``OUT/partial/``; a killed
job rerun with the same settings skips those and gives the same results and report
(solve times aside).  (Tests kill the driver after N results with the environment
variable ``EOSP_FAULT_KILL_AFTER=N``.)
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import signal
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from eosp.args import Parser, add_config_args, config_from_args, prefixed_config, run_job  # noqa: E402
from eosp.config import EvalConfig, RayConfig, flatten  # noqa: E402


class SolverWorker:
    """Solves (shard, index, solver) jobs; keeps agents loaded across calls."""

    def __init__(self):
        import torch

        torch.set_num_threads(1)
        self.agents: dict[str, object] = {}

    def solve(self, shard: str, index: int, solver: str, cfg: EvalConfig, budget: int | None) -> dict:
        import numpy as np

        from eosp.config import N_CLASSES
        from eosp.instances.schedule import check, from_internal_nodes, write_schedule
        from eosp.shards.io import ShardReader
        from eosp.solvers.base import run_solver, takes_time_limit

        inst = ShardReader(shard).read(index)
        options = {"mode": cfg.mode}
        if takes_time_limit(solver):  # the one-shot solvers (random, greedy, policy) refuse a limit
            options["time_limit"] = cfg.time_limit
        if solver in ("sample", "beam"):
            options["time_limit"] = cfg.search_time or None
            options.update({"samples": cfg.samples} if solver == "sample" else {"beam_width": cfg.beam_width})
        if solver == "mcts":
            options["budget"] = budget
        limited = solver != "policy" and options.get("time_limit") is not None
        agent = self._agent(cfg.checkpoint, cfg.mode, inst.n_acq, limited) if solver in LEARNED else None
        if solver in ("sample", "beam", "mcts"):
            options.update(polish=cfg.polish, refine=cfg.refine, windows=cfg.windows, window_graph=cfg.window_graph)
        t0 = time.perf_counter()
        sol = run_solver(solver, inst, agent=agent, **options)
        seconds = time.perf_counter() - t0
        sched = from_internal_nodes(inst, sol.nodes)
        verdict = check(inst, sched)
        label = f"mcts({budget})" if solver == "mcts" else solver
        if cfg.save_schedules and verdict.feasible:  # only schedules that pass the checker are written
            folder = re.sub(r"[^\w.-]", "_", f"{Path(shard).stem}-{index}-{inst.name}")
            write_schedule(sched, Path(cfg.out) / "schedules" / folder / f"{label}.parquet", overwrite=True)
        value = float(len(sched)) if cfg.mode == "unitary" else verdict.value
        counts = np.bincount(inst.priorities()[sched.acq].astype(np.int64), minlength=N_CLASSES)
        return {**{f"class_{c}": int(counts[c]) for c in range(N_CLASSES)},
                "_key": (shard, index), "_schedule": (sched.acq, sched.node, sched.start), "instance": f"{Path(shard).stem}#{index}:{inst.name}", "group": inst.n_acq, "solver": label, "value": value,
                "utility": verdict.value, "acquisitions": len(sched), "seconds": seconds,
                "feasible": verdict.feasible, "reason": verdict.reason,
                "bound": float(sol.info.get("bound", np.nan)), "status": str(sol.info.get("status", "")),
                "family": str(inst.meta.get("family", ""))}

    def _agent(self, checkpoint: str, mode: str, n_acquisitions: int, time_limited: bool):
        """The agent of `checkpoint`, or the shipped model that serves `mode` for this instance and search
        (eosp.models.pretrained.default_name), loaded once per worker."""
        from eosp.models.pretrained import default_name

        key = checkpoint or f"pretrained:{default_name(mode, n_acquisitions, time_limited)}"
        if key not in self.agents:
            from eosp.solvers.policy import resolve_agent

            self.agents[key] = resolve_agent("policy", key, None, mode)
        return self.agents[key]


LEARNED = ("policy", "mcts", "sample", "beam")
SOLVERS = ("random", "greedy", "ramp", "exact", "lns", *LEARNED)


RESUME_KEYS = ("mode", "time_limit", "search_time", "samples", "beam_width", "polish", "refine", "windows",
               "window_graph", "checkpoint", "save_schedules")  # settings a kept result depends on


def _job_file(partial: Path, job: tuple) -> Path:
    shard, index, solver, budget = job
    key = json.dumps([str(Path(shard).resolve()), index, solver, budget])
    return partial / (hashlib.sha1(key.encode()).hexdigest()[:20] + ".json")


def load_partial(cfg: EvalConfig, jobs: list[tuple]) -> tuple[Path, dict[tuple, dict]]:
    """The results a killed run with the same settings kept (job -> row), and the folder they are kept in."""
    from eosp.atomic import atomic_path

    partial = Path(cfg.out) / "partial"
    settings = {k: getattr(cfg, k) for k in RESUME_KEYS}
    stamp = partial / "settings.json"
    kept: dict[tuple, dict] = {}
    if stamp.exists():
        try:
            same = json.loads(stamp.read_text()) == json.loads(json.dumps(settings))
        except (OSError, json.JSONDecodeError):
            same = False
        if not same:
            print(f"[evaluate] {partial}: kept results of other settings discarded", flush=True)
            for f in partial.glob("*.json"):
                f.unlink()
        for job in jobs if same else ():
            f = _job_file(partial, job)
            try:
                row = json.loads(f.read_text())
            except (OSError, json.JSONDecodeError):
                continue  # not finished (or not readable): solve it again
            import numpy as np

            row["_key"] = (job[0], job[1])
            row["_schedule"] = tuple(np.asarray(x, dtype=t) for x, t in zip(row["_schedule"], ("int32", "int32",
                                                                                                  "float64")))
            kept[job] = row
    partial.mkdir(parents=True, exist_ok=True)
    with atomic_path(stamp) as tmp:
        tmp.write_text(json.dumps(settings))
    return partial, kept


def keep_partial(partial: Path, job: tuple, row: dict) -> None:
    from eosp.atomic import atomic_path

    data = {**row, "_key": list(row["_key"]), "_schedule": [a.tolist() for a in row["_schedule"]]}
    with atomic_path(_job_file(partial, job)) as tmp:
        tmp.write_text(json.dumps(data, default=lambda o: o.item() if hasattr(o, "item") else str(o)))


def run(cfg: EvalConfig, ray_cfg: RayConfig) -> "object":
    import mlflow
    import pandas as pd
    import ray
    from ray.util.actor_pool import ActorPool

    from eosp.envs.sources import expand_shards
    from eosp.atomic import atomic_path
    from eosp.jobs.ray_init import init_ray
    from eosp.evaluation.plots import plot_class_counts
    from eosp.evaluation.report import markdown
    from eosp.ownership import kind_of, mark_dir
    from eosp.shards.io import ShardReader

    if set(LEARNED) & set(cfg.solvers) and not cfg.checkpoint:
        from eosp.models.pretrained import FAST, FAST_ABOVE, pretrained_dir

        fast = (f" (searches with a time limit on more than {FAST_ABOVE} acquisitions: "
                f"{pretrained_dir(FAST[cfg.mode])})") if cfg.mode in FAST else ""
        print(f"[evaluate] policy/mcts: the shipped model {pretrained_dir(cfg.mode)}{fast}", flush=True)
    check_eval_out(cfg)
    out = Path(cfg.out)
    if cfg.overwrite and kind_of(out) == EVAL_KIND and not (out / "partial").exists():
        shutil.rmtree(out)  # a finished evaluation of eosp's, replaced as asked
    out.mkdir(parents=True, exist_ok=True)
    if kind_of(out) != EVAL_KIND:
        mark_dir(out, EVAL_KIND)
    jobs = []
    for shard in expand_shards(list(cfg.data)):
        for i in range(len(ShardReader(shard))):
            for s in cfg.solvers:
                for b in (cfg.budgets if s == "mcts" else (None,)):
                    jobs.append((str(shard), i, s, b))
    partial, kept = load_partial(cfg, jobs)
    if kept:
        print(f"[evaluate] resuming: {len(kept)} of {len(jobs)} results kept from a previous run", flush=True)
    todo = [j for j in jobs if j not in kept]
    init_ray(ray_cfg.address, ray_cfg.num_cpus)
    n_workers = max(1, int(ray.available_resources().get("CPU", 1)))
    pool = ActorPool([ray.remote(num_cpus=1)(SolverWorker).remote() for _ in range(n_workers)])
    t0 = time.perf_counter()
    rows = list(kept.values())
    kill_after = int(os.environ.get("EOSP_FAULT_KILL_AFTER", "0") or 0)

    for k, row in enumerate(pool.map_unordered(lambda a, j: a.solve.remote(j[0], j[1], j[2], cfg, j[3]), todo)):
        rows.append(row)
        if not row["feasible"]:
            raise SystemExit(f"{row['solver']} produced an infeasible schedule on {row['instance']}: {row['reason']}")
        job = next(j for j in todo if (j[0], j[1]) == row["_key"] and _label(j) == row["solver"])
        keep_partial(partial, job, row)
        if k + 1 == kill_after:  # fault injection for the tests: die like a killed job
            os.kill(os.getpid(), signal.SIGKILL)
        if (k + 1) % max(1, len(todo) // 20) == 0 or k + 1 == len(todo):
            print(f"[evaluate] {k + 1}/{len(todo)} done ({time.perf_counter() - t0:.0f} s)", flush=True)
    wall = time.perf_counter() - t0
    html = write_html_reports(cfg, jobs, rows)
    for row in rows:
        del row["_key"], row["_schedule"]
    results = pd.DataFrame(rows).sort_values(["group", "instance", "solver"]).reset_index(drop=True)
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / "results.parquet", suffix=".parquet") as tmp:
        results.to_parquet(tmp, index=False)
    report = markdown(results, cfg.mode) + f"\nWall time: {wall:.1f} s on {n_workers} workers.\n"
    if html:
        report += f"\nHTML reports (map, timeline, roll/pitch): {', '.join(p.name for p in html)} in reports/.\n"
    with atomic_path(out / "report.md") as tmp:
        tmp.write_text(report)
    counts_png = plot_class_counts(results, out / "class_counts.png")
    from eosp.jobs.tracking import use_experiment

    use_experiment(cfg.mlflow_uri, cfg.experiment)
    with mlflow.start_run(run_name=out.name):
        mlflow.log_params({k: str(v) for k, v in flatten(cfg).items()})
        for (group, solver), sub in results.groupby(["group", "solver"]):
            # MLflow refuses parentheses in names: mcts(100) -> mcts_100
            mlflow.log_metric(re.sub(r"[^\w./ -]", "_", f"mean/{solver}/{group}").replace("_/", "/").rstrip("_"),
                              float(sub.value.mean()))
        mlflow.log_metric("wall_s", wall)
        mlflow.log_artifact(str(out / "results.parquet"))
        mlflow.log_artifact(str(out / "report.md"))
        mlflow.log_artifact(str(counts_png))
        for p in html:
            mlflow.log_artifact(str(p), artifact_path="reports")
    shutil.rmtree(partial, ignore_errors=True)  # complete: the results are in results.parquet
    print(report)
    return results


EVAL_KIND = "evaluation"  # the mark (eosp.ownership) of an evaluation's --out directory


def check_eval_out(cfg: EvalConfig) -> Path:
    """Refuse, before Ray or MLflow start, an --out that eosp must not write: a file, a directory eosp did not write
    (never written into), or a finished evaluation without --overwrite.  A killed one (OUT/partial/) resumes."""
    from eosp.errors import InputError
    from eosp.ownership import check_output

    out = Path(cfg.out)
    resumable = (out / "partial").is_dir() or not (out / "results.parquet").exists()
    try:
        return check_output(out, EVAL_KIND, cfg.overwrite, directory=True, reuse=resumable and not cfg.overwrite)
    except InputError as exc:
        raise InputError(f"--out {cfg.out}", exc.message) from None


def _label(job: tuple) -> str:
    return f"mcts({job[3]})" if job[2] == "mcts" else job[2]


def write_html_reports(cfg: EvalConfig, jobs: list[tuple], rows: list[dict]) -> list[Path]:
    """One HTML report per instance, for the first ``cfg.html_reports`` instances of the job list."""
    from eosp.evaluation.html_report import write_report
    from eosp.instances.schedule import Schedule
    from eosp.shards.io import ShardReader

    keys = list(dict.fromkeys((shard, index) for shard, index, _, _ in jobs))[:max(0, cfg.html_reports)]
    written = []
    for shard, index in keys:
        mine = [r for r in rows if r["_key"] == (shard, index)]
        scheds = {r["solver"]: Schedule(*r["_schedule"]) for r in sorted(mine, key=lambda r: r["solver"])}
        inst = ShardReader(shard).read(index)
        folder = re.sub(r"[^\w.-]", "_", f"{Path(shard).stem}-{index}-{inst.name}")
        written.append(write_report(inst, scheds, Path(cfg.out) / "reports" / f"{folder}.html",
                                    title=f"{inst.name} ({Path(shard).name} #{index}): {cfg.mode} mode",
                                    overwrite=True))
    return written


def main(argv: list[str] | None = None) -> int:
    """The job; user errors are one line ``evaluate.py: error: ...`` and exit 2 before Ray or MLflow start."""
    return run_job(_main, argv, "evaluate.py")


def _main(argv: list[str] | None) -> int:
    p = Parser(prog="evaluate.py", description=__doc__.splitlines()[0])
    add_config_args(p, EvalConfig)
    add_config_args(p, RayConfig, prefix="ray.")
    ns = p.parse_args(argv)
    cfg = config_from_args(EvalConfig, ns)
    ray_cfg = prefixed_config(RayConfig, ns, "ray.")
    from eosp.jobs.preflight import check_mlflow, require_checkpoint, require_data, require_findable

    require_findable(cfg.out, "--out")
    require_data(cfg.data, "--data")
    unknown = [s for s in cfg.solvers if s not in SOLVERS]
    if unknown:
        p.error(f"--solvers: unknown solver {unknown[0]!r}; one of {', '.join(SOLVERS)}")
    if set(LEARNED) & set(cfg.solvers):
        require_checkpoint(cfg.checkpoint, "--checkpoint")
    check_eval_out(cfg)
    check_mlflow(cfg.mlflow_uri)
    run(cfg, ray_cfg)
    return 0


if __name__ == "__main__":
    sys.exit(main())
