"""Realizations of an operations scenario through a planner on Ray, one realization a task (resumable), tracked in
MLflow: the job behind ``eosp simulate`` at scale.

    python jobs/simulate_operations.py --scenario SCEN --out RUN --sim.planner ev-replan --sim.realizations 20
    ray job submit --working-dir . -- python jobs/simulate_operations.py --scenario /shared/SCEN --out /shared/RUN \\
        --mlflow-uri http://mlflow:5000 ...

Each Ray actor builds the scenario's problem once (its pass graphs) and simulates the realizations it is given
(:class:`eosp.kinds.fleet.operations.Simulation`); ``RUN/summary.json`` (docs/formats.md, "Simulation run") is
written after every realization that finishes, so a rerun with the same scenario and options keeps those and runs
the others, and Ctrl-C keeps them too (one line with their means, exit 130).  The MLflow run logs the options,
every realization's figures as steps, the means, and summary.json as an artifact.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

from eosp.args import Parser, add_config_args, config_from_args, run_job
from eosp.config import RayConfig, flatten
from eosp.kinds.fleet.operations import SimulateConfig

FIGURES = ("served", "served_catalogue", "served_urgent", "bound", "regret", "cloud_lost", "failed", "churn")


@dataclass
class SimulateJob:
    """Realizations of an operations scenario through a planner (``jobs/simulate_operations.py``)."""

    scenario: str = ""
    """The scenario directory (eosp scenario)."""
    out: str = ""
    """The run directory (RUN/summary.json; resumed when it holds a run of the same scenario and options)."""
    sim: SimulateConfig = field(default_factory=SimulateConfig)
    ray: RayConfig = field(default_factory=RayConfig)
    mlflow_uri: str = ""
    """MLflow tracking URI (empty: sqlite mlflow.db in the working directory)."""
    experiment: str = "eosp-operations"
    """MLflow experiment."""


class Worker:
    """A Ray actor: one scenario's simulation, built once, run realization by realization."""

    def __init__(self, scen_path: str, cfg: SimulateConfig):
        import os

        os.environ.setdefault("OMP_NUM_THREADS", "1")
        from eosp.kinds.fleet.operations import Simulation
        from eosp.ops import scenario

        self.sim = Simulation.of(scenario.read(scen_path), cfg)

    def run(self, index: int) -> dict:
        return self.sim.run(index)


def run(job: SimulateJob) -> int:
    import logging

    import mlflow
    import ray

    from eosp.jobs.ray_init import init_ray
    from eosp.jobs.tracking import use_experiment
    from eosp.kinds.fleet.operations import prior_realizations, summary_line, write_summary
    from eosp.ops import scenario

    scenario.read(job.scenario)  # a bad scenario is refused before anything is written
    out = Path(job.out)
    done = prior_realizations(out, job.scenario, job.sim, resume=True, overwrite=False)
    logging.getLogger("mlflow").setLevel(logging.WARNING)
    use_experiment(job.mlflow_uri, job.experiment)
    out.mkdir(parents=True, exist_ok=True)
    todo = [i for i in range(job.sim.realizations) if i not in {r["realization"] for r in done}]
    if done:
        print(f"[simulate_operations] resuming: {len(done)} of {job.sim.realizations} realizations done", flush=True)
    with mlflow.start_run(run_name=f"{Path(job.scenario).name}-{job.sim.planner}"):
        mlflow.log_params({k: str(v) for k, v in flatten(job).items() if not k.startswith("ray.")})
        try:
            if todo:
                init_ray(job.ray.address, job.ray.num_cpus)
                actor = ray.remote(num_cpus=1)(Worker)
                n = max(1, min(len(todo), int(ray.available_resources().get("CPU", 1))))
                workers = [actor.remote(job.scenario, job.sim) for _ in range(n)]
                pending = {}
                queue = list(todo)
                for w in workers:
                    if queue:
                        pending[w.run.remote(queue.pop(0))] = w
                while pending:
                    ready, _ = ray.wait(list(pending), num_returns=1)
                    w = pending.pop(ready[0])
                    rec = ray.get(ready[0])
                    done.append(rec)
                    write_summary(out, job.scenario, job.sim, done)
                    mlflow.log_metrics({k: float(rec[k]) for k in FIGURES if rec.get(k) is not None},
                                       step=rec["realization"])
                    print(f"[simulate_operations] realization {rec['realization']}: served {rec['served']:.4f}, "
                          f"bound {rec['bound']:.4f}, valid {rec['valid']} ({len(done)}/{job.sim.realizations})",
                          flush=True)
                    if queue:
                        pending[w.run.remote(queue.pop(0))] = w
        except KeyboardInterrupt:
            if done:
                m = write_summary(out, job.scenario, job.sim, done)
                print(f"simulate_operations.py: interrupted: {summary_line(out / 'summary.json', job.sim, m)}",
                      file=sys.stderr, flush=True)
            else:
                print("simulate_operations.py: interrupted: no realization finished", file=sys.stderr, flush=True)
            return 130
        m = write_summary(out, job.scenario, job.sim, done)
        mlflow.log_metrics({f"mean/{k}": float(v) for k, v in m.items() if isinstance(v, (int, float))})
        mlflow.log_artifact(str(out / "summary.json"))
    print(summary_line(out / "summary.json", job.sim, m), flush=True)
    return 0 if m["valid"] == m["realizations"] else 1


def main(argv: list[str] | None = None, prog: str = "simulate_operations.py") -> int:
    return run_job(_main, argv, prog)


def _main(argv: list[str] | None) -> int:
    from eosp import errors
    from eosp.errors import InputError
    from eosp.jobs.preflight import check_mlflow, require_findable

    p = Parser(prog=errors.PROG, description=__doc__.splitlines()[0])
    add_config_args(p, SimulateJob)
    job = config_from_args(SimulateJob, p.parse_args(argv))
    for flag, value in (("--scenario", job.scenario), ("--out", job.out)):
        if not value:
            raise InputError(flag, "required")
    require_findable(job.scenario, "--scenario")
    require_findable(job.out, "--out")
    check_mlflow(job.mlflow_uri)
    return run(job)


if __name__ == "__main__":
    sys.exit(main())
