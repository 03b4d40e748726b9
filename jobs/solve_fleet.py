"""Solve a fleet with the price-coordinated fleet solver, the passes of every price round on Ray actors.

    python jobs/solve_fleet.py --fleet-dir FLEET --run-dir runs/fleet-1 --fleet.workers 2 --fleet.time-limit 600
    ray job submit --working-dir . -- python jobs/solve_fleet.py --fleet-dir /shared/fleet --run-dir /shared/run \\
        --fleet.workers 64 --mlflow-uri http://mlflow:5000

The same code runs on a laptop (a local Ray with ``--ray.num-cpus``) and on a cluster (``ray job submit``, or
``--ray.address``).  The passes are solved by Ray actors that own satellites' pass graphs
(:mod:`eosp.kinds.fleet.raypool`: what they hold, what a round sends, how a lost actor is replaced).  Where the
graphs are large (``--lean-driver``) the driver keeps the passes without their arcs and every solve is the
actors'; else it holds every graph too and solves small sweeps itself, where a round trip would cost more than
the solves.

This job owns the run: after every round the driver writes its state to the run dir (prices, step, bound, rounds
done, and the best schedule, each file replaced atomically); a driver killed and started again with the same run
dir resumes from there.  A run dir of another fleet is refused.  (Tests kill the driver after round N has been
saved with the environment variable ``EOSP_FAULT_KILL_AFTER=N``; the actors' faults: :mod:`eosp.kinds.fleet.raypool`.)

MLflow: one run per job: value, bound and gap against rounds and wall time, per-pass solve times (CSV and a
plot), the schedule and a per-satellite summary as artifacts.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from eosp.args import Parser, add_config_args, add_memory_arg, config_from_args, run_job  # noqa: E402
from eosp.config import RayConfig, choice, flatten  # noqa: E402
from eosp.kinds.fleet.config import FleetConfig  # noqa: E402

RUN_KIND = "fleet-run"
STATE = "state.npz"
BEST = "best.parquet"
META = "run.json"


@dataclass
class SolveFleetJob:
    """A fleet solve as a Ray job (``jobs/solve_fleet.py``)."""

    fleet_dir: str = ""
    """Fleet directory to solve (``eosp import`` or ``eosp generate --fleet``)."""
    run_dir: str = ""
    """Where the job keeps its state after every round and writes schedule.parquet and summary.csv; started again
    with the same run dir, it resumes."""
    fleet: FleetConfig = field(default_factory=FleetConfig)
    mlflow_uri: str = ""
    """MLflow tracking URI (empty: sqlite mlflow.db in the working directory)."""
    experiment: str = "eosp-fleet"
    """MLflow experiment."""
    lean_driver: str = choice("auto", "auto", "yes", "no")
    """With --fleet.workers > 1: yes, the driver keeps the passes without their arcs (the actors hold the graphs,
    every pass solve is theirs: the memory of the graphs once, and the first graphs built in parallel); no, it
    holds every graph too (small descent sweeps and those of a prefetched round solved on the driver: faster where
    the graphs are small); auto: yes where the graphs are estimated above 4 GiB."""
    ray: RayConfig = field(default_factory=RayConfig)


def _load_state(run: Path, fleet, fp: str):
    """The saved state of a run dir of this fleet: (Resume, best schedule), or None for a new run; every value
    checked (a truncated, edited or foreign state file is one line, never a traceback or a wrong resume)."""
    from eosp.errors import InputError
    from eosp.fleet.io import read_schedule
    from eosp.kinds.fleet.solve import Resume

    meta_path = run / META
    if not meta_path.exists():
        return None
    try:
        meta = json.loads(meta_path.read_text())
    except (ValueError, UnicodeDecodeError):
        raise InputError(meta_path, "not readable JSON: not a fleet run dir eosp wrote") from None
    if not isinstance(meta, dict):
        raise InputError(meta_path, "not a JSON object: not a fleet run dir eosp wrote")
    if meta.get("fingerprint") != fp:
        raise InputError(f"--run-dir {run}", f"a run dir of another fleet ({meta.get('case_id', '?')}): use another "
                                             "--run-dir")
    if not (run / STATE).exists() or not (run / BEST).exists():
        return None
    state = _read_state(run / STATE, len(fleet.tasks))
    best, _ = read_schedule(run / BEST, fleet)
    return Resume(state["lam"], float(state["step"]), float(state["best_bound"]), str(state["bound_source"]),
                  int(state["rounds_done"]), state.get("mu")), best


STATE_KEYS = {"lam": "f", "step": "f", "best_bound": "f", "bound_source": "U", "rounds_done": "i"}


def _read_state(path: Path, n_tasks: int) -> dict:
    """state.npz as :class:`Checkpoint` writes it: the prices (n_tasks finite numbers >= 0), the step (> 0), the best
    bound (finite), its source (text) and the rounds done (>= 0), each checked."""
    import zipfile

    from eosp.errors import InputError

    try:
        with np.load(path, allow_pickle=False) as z:  # never unpickle a file
            state = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(path, f"not a state file eosp wrote (truncated or edited?): {exc}") from None
    for key, kind in STATE_KEYS.items():
        if key not in state:
            raise InputError(path, f"no {key!r}: not a state file eosp wrote (truncated or edited?)")
        v = state[key]
        if v.dtype.kind not in (kind, "i" if kind == "f" else kind) or (key != "lam" and v.ndim != 0):
            raise InputError(path, f"{key!r} is not a {'vector' if key == 'lam' else 'single'} value of the right type")
    lam = state["lam"]
    if lam.ndim != 1 or len(lam) != n_tasks:
        raise InputError(path, f"prices of another fleet ({lam.size} prices, {n_tasks} tasks)")
    if not np.all(np.isfinite(lam)) or np.any(lam < 0):
        raise InputError(path, "prices must be finite numbers >= 0")
    if not (np.isfinite(state["step"]) and state["step"] > 0 and np.isfinite(state["best_bound"])
            and state["rounds_done"] >= 0):
        raise InputError(path, "step must be > 0, best_bound finite and rounds_done >= 0")
    return state


class Checkpoint:
    """After every round: state and best schedule into the run dir (atomic replaces), metrics to MLflow."""

    def __init__(self, run: Path, fleet, mlflow, W: float):
        self.run, self.fleet, self.mlflow, self.W = run, fleet, mlflow, W
        self.t0 = time.perf_counter()
        self.last_value = -1.0
        self.phases = 0  # round phases logged so far

    def __call__(self, coord) -> None:
        from eosp.atomic import atomic_path
        from eosp.fleet.io import write_schedule

        with atomic_path(self.run / STATE) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, lam=coord.prices.lam, mu=coord.prices.mu, step=np.float64(coord.prices.factor),
                         best_bound=np.float64(coord.best_bound),
                         bound_source=np.str_(coord.bound_source), rounds_done=np.int64(coord.rounds_done))
        if coord.best.value != self.last_value:
            write_schedule(coord.schedule(coord.best), self.fleet, self.run / BEST, overwrite=True,
                           info={"value": coord.best.value / self.W, "partial": True})
            self.last_value = coord.best.value
        if coord.rounds_done == int(os.environ.get("EOSP_FAULT_KILL_AFTER", "0") or 0):
            os.kill(os.getpid(), signal.SIGKILL)  # fault injection for the tests: die like a killed driver
        v, b = coord.best.value / self.W, min(1.0, coord.best_bound / self.W)
        if self.mlflow is not None:
            new = len(coord.phases) > self.phases  # this round's phases (a price round's)
            phases = {f"phase/{k}" + ("" if k == "pool_calls" else "_s"): x
                      for k, x in coord.phases[-1].items()} if new else {}
            self.phases = len(coord.phases)
            self.mlflow.log_metrics({"value": v, "bound": b, "gap": (b - v) / b if b > 0 else 0.0,
                                     "wall_s": time.perf_counter() - self.t0, **phases}, step=coord.rounds_done)


def summary_rows(fleet, sched) -> list[dict]:
    """Per satellite: observations, weight served, seconds observing."""
    ti = fleet.task_index()
    rows = []
    for sid in fleet.satellites.ids.tolist():
        m = sched.satellite == sid
        tasks = np.array([ti[t] for t in sched.task[m].tolist()], dtype=np.int64)
        rows.append({"satellite": sid, "observations": int(m.sum()),
                     "weight": float(fleet.tasks.weight[tasks].sum()) if len(tasks) else 0.0,
                     "observing_s": float((sched.end_us[m] - sched.start_us[m]).sum() / 1e6)})
    return rows


def lean_driver(job: SolveFleetJob, fleet, opps) -> bool:
    """Whether the driver keeps its passes without arcs (``--lean-driver``; only with Ray's actors)."""
    from eosp.fleet.passgraph import LEAN_ABOVE_BYTES, graph_bytes

    if job.fleet.workers < 2 or job.lean_driver == "no":
        return False
    return job.lean_driver == "yes" or graph_bytes(opps, len(fleet.tasks)) > LEAN_ABOVE_BYTES


def run(job: SolveFleetJob) -> dict:
    import csv

    import mlflow

    from eosp.atomic import atomic_path
    from eosp.fleet.io import fingerprint, read_fleet, write_schedule
    from eosp.fleet.passgraph import require_solvable
    from eosp.jobs.preflight import make_run_dir
    from eosp.jobs.ray_init import init_ray
    from eosp.jobs.tracking import use_experiment
    from eosp.kinds.fleet.problem import Problem
    from eosp.kinds.fleet.solve import solve
    from eosp.memory import peak_rss_gb

    import logging

    logging.getLogger("mlflow").setLevel(logging.WARNING)  # its INFO lines (creating tables, experiments) are noise
    t0 = time.perf_counter()
    fleet, opps = read_fleet(job.fleet_dir)
    t_read = time.perf_counter()  # --fleet.time-limit counts from here
    peak = {"read": peak_rss_gb()}  # the driver's peak resident memory after each step (GB)
    fp = fingerprint(fleet)
    run_dir = Path(job.run_dir)
    saved = _load_state(run_dir, fleet, fp) if run_dir.is_dir() else None
    local_actors = job.fleet.workers if job.fleet.workers > 1 and not job.ray.address else 0
    if local_actors:  # more workers than CPUs: refused before anything is written
        _require_cpus(job.fleet.workers, "")
    lean = lean_driver(job, fleet, opps)
    geo = require_solvable(fleet, opps, f"--fleet-dir {job.fleet_dir}", processes=1 + local_actors, lean=lean)
    if job.fleet.workers > 1:
        init_ray(job.ray.address, max(job.ray.num_cpus, job.fleet.workers))
        if job.ray.address:  # a cluster's CPUs are known once connected
            _require_cpus(job.fleet.workers, job.ray.address)
    use_experiment(job.mlflow_uri, job.experiment)  # before the run dir: a store MLflow refuses leaves nothing behind
    make_run_dir(run_dir, replace=False, kind=RUN_KIND)
    (run_dir / META).write_text(json.dumps({"fingerprint": fp, "case_id": fleet.case_id,
                                            "fleet_dir": str(Path(job.fleet_dir).resolve())}, indent=1))
    prob = Problem.build(fleet, opps, geo, lean=lean)  # the Geometry the feasibility check built (not built twice)
    t_build = time.perf_counter() - t0
    peak["graphs"] = peak_rss_gb()
    pool = None
    if job.fleet.workers > 1:
        from eosp.kinds.fleet.raypool import RayPassPool

        pool = RayPassPool(prob, job.fleet)
    t_pool = time.perf_counter() - t0
    with mlflow.start_run(run_name=run_dir.name):
        mlflow.log_params({k: str(v) for k, v in flatten(job).items()})
        mlflow.set_tags({"case": fleet.case_id, "resumed": str(saved is not None)})
        ckpt = Checkpoint(run_dir, fleet, mlflow, prob.total_weight)
        resume, initial = (saved if saved is not None else (None, None))
        try:
            sol = solve(fleet, opps, job.fleet, problem=prob, initial=initial, pool=pool, on_round=ckpt, resume=resume,
                        t0=t_read)
            graphs = [] if pool is None else pool.summary()
        finally:
            if pool is not None:
                pool.close()
        wall = time.perf_counter() - t0
        peak["solve"] = peak_rss_gb()
        info = {"value": sol.value, "bound": sol.bound, "gap": sol.gap, "solver": "fleet", "seconds": round(wall, 3),
                "pass_solver": job.fleet.pass_solver, "rounds": sol.info["rounds"],
                "time_limit": job.fleet.time_limit, "warm_start": job.fleet.warm_start}
        write_schedule(sol.schedule, fleet, run_dir / "schedule.parquet", overwrite=True, info=info)
        with atomic_path(run_dir / "summary.csv") as tmp:
            with open(tmp, "w", newline="") as fh:
                rows = summary_rows(fleet, sol.schedule)
                w = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ["satellite"])
                w.writeheader()
                w.writerows(rows)
        times = pool.times if pool is not None else []
        with atomic_path(run_dir / "pass_times.csv") as tmp:
            with open(tmp, "w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(["pass", "opportunities", "seconds", "worker"])
                w.writerows([(p, len(prob.passes[p].rows), round(s, 6), k) for p, s, k in times])
        first_t = sol.history[0][0] if sol.history else None
        result = {"value": sol.value, "bound": sol.bound, "gap": sol.gap, "rounds": sol.info["rounds"],
                  "pass_solves": sol.info["pass_solves"], "memo_hits": sol.info["memo_hits"],
                  "passes": len(prob.passes), "build_s": round(t_build, 2),
                  "pool_s": round(t_pool - t_build, 2), "first_schedule_s": None if first_t is None else
                  round(first_t + t_read - t0, 2), "wall_s": round(wall, 2), "faults": 0 if pool is None else pool.faults,
                  "actors_given_up": 0 if pool is None else pool.given_up,
                  "workers": job.fleet.workers, "nodes": 0 if pool is None else len(set(pool.nodes)),
                  "lean_driver": lean,
                  "resumed_from_round": 0 if resume is None else resume.rounds_done,
                  "price_round_s": sol.info["price_round_s"], "round_phases_s": sol.info["round_phases_s"],
                  "interrupted": sol.info["interrupted"],
                  "check_reserve_s": sol.info["check_reserve_s"], "final_check_s": sol.info["final_check_s"],
                  "driver_peak_gb": {k: None if v is None else round(v, 3) for k, v in peak.items()},
                  "graph_mb": round(sum(pg.nbytes for pg in prob.passes) / 1e6, 1),  # the driver's (lean: nodes)
                  "actor_graph_mb": None if pool is None else round(sum(x["bytes"] for x in graphs) / 1e6, 3),
                  "bound_graphs": sol.info["bound_graphs"] if pool is None else sum(x["bound_graphs"] for x in graphs),
                  "read_s": round(t_read - t0, 2),  # the solve's history counts from the read (the graphs in it)
                  "history": [(round(t + t_read - t0, 3), v, b) for t, v, b in sol.history]}
        (run_dir / "result.json").write_text(json.dumps(result, indent=1))
        mlflow.log_metrics({"final/value": sol.value, "final/bound": sol.bound or 0.0, "final/gap": sol.gap or 0.0,
                            "final/wall_s": wall, "final/faults": result["faults"]})
        for name in ("schedule.parquet", "summary.csv", "pass_times.csv", "result.json"):
            mlflow.log_artifact(str(run_dir / name))
    return result


def main(argv: list[str] | None = None, prog: str = "solve_fleet.py") -> int:
    return run_job(_main, argv, prog)


def _main(argv: list[str] | None) -> int:
    from eosp import errors
    from eosp.errors import InputError
    from eosp.fleet.io import is_fleet_dir
    from eosp.jobs.preflight import check_mlflow, is_run_dir, require_findable

    p = Parser(prog=errors.PROG, description=__doc__.splitlines()[0])
    add_config_args(p, SolveFleetJob)
    add_memory_arg(p)
    ns = p.parse_args(argv)
    job = config_from_args(SolveFleetJob, ns)
    for flag, value in (("--fleet-dir", job.fleet_dir), ("--run-dir", job.run_dir)):
        if not value:
            raise InputError(flag, "required")
        require_findable(value, flag)
    if not is_fleet_dir(job.fleet_dir):
        raise InputError(f"--fleet-dir {job.fleet_dir}", "not a fleet directory (eosp import / eosp generate --fleet)")
    try:
        job.fleet.validate()  # the rules across its fields (a time limit or a number of rounds), set by the flags
    except ValueError as exc:
        raise InputError("--fleet", str(exc)) from None
    if job.fleet.pass_solver == "policy":
        raise InputError("--fleet.pass-solver", "policy: no model trained on fleet passes is shipped yet")
    run_dir = Path(job.run_dir)
    if run_dir.is_dir() and any(run_dir.iterdir()) and not is_run_dir(run_dir, RUN_KIND):
        raise InputError(f"--run-dir {run_dir}", "exists and is not a fleet run dir eosp wrote: refusing to write "
                                                 "into it")
    check_mlflow(job.mlflow_uri)
    if job.ray.address and job.fleet.workers > 1:
        _require_ray_address(job.ray.address)
    from eosp.memory import memory_ceiling

    with memory_ceiling(ns.max_memory_gb):
        r = run(job)
    gap = "" if r["gap"] is None else f", gap {r['gap']:.4%}"
    print(f"[solve_fleet] {job.run_dir}: WCR {r['value']:.6f}, bound {r['bound']:.6f}{gap}; {r['rounds']} rounds, "
          f"{r['pass_solves']} pass solves on {r['workers']} worker(s), {r['faults']} lost to faults "
          f"({r['wall_s']:.1f} s)")
    if r.get("interrupted"):  # Ctrl-C: the best schedule so far was checked and written with the run's files
        print(f"{errors.PROG}: interrupted: wrote the best valid schedule so far to "
              f"{Path(job.run_dir) / 'schedule.parquet'} (WCR {r['value']:.6f})", file=sys.stderr, flush=True)
        return 130
    return 0


def _require_cpus(workers: int, address: str) -> None:
    """One line when the workers outnumber the CPUs: the cluster's (Ray's resources) or, for a local Ray, this
    machine's (a local Ray is started with as many logical CPUs as workers, so its own count says nothing)."""
    import os

    from eosp.errors import InputError

    if address:
        import ray

        cpus = float(ray.cluster_resources().get("CPU", 0))
    else:
        cpus = float(os.cpu_count() or 1)
    if workers > cpus:
        where = "the cluster has" if address else "this machine has"
        raise InputError(f"--fleet.workers {workers}", f"more than the {cpus:g} CPUs {where}")


def _require_ray_address(address: str) -> None:
    """One line, before any work, when the Ray address does not answer (host:port of a GCS, or ray://)."""
    import socket

    from eosp.errors import InputError

    if address in ("auto", "local"):
        return
    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    try:
        socket.create_connection((host or "127.0.0.1", int(port)), timeout=5).close()
    except (OSError, ValueError) as exc:
        raise InputError(f"--ray.address {address}", f"unreachable ({exc.__class__.__name__}: {exc})") from None


if __name__ == "__main__":
    sys.exit(main())
