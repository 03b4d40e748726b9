"""Ctrl-C of the fleet learning jobs as a terminal gives it: SIGINT to the job's whole process group (the driver, its
Ray workers and actors, Tune's trials) at the phases where a job used to hang or print a traceback: PPO in the middle
of an iteration (env runners sampling, the learner's update, validation), imitation while DAgger's Ray tasks run,
a Tune sweep with its trials running.  Each must stop within 10 s with exit 130 and one line of its own, keep what
it completed (checkpoints), end its MLflow run as KILLED, and a sweep must resume from where it stopped."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.io import write_fleet
from eosp.fleet.opportunities import compute
from tests.conftest import sigint_as_a_terminal_gives, sigint_to_group

pytestmark = pytest.mark.ray


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """Two tiny training fleets with the fleet solver's demonstrations, one validation fleet."""
    import ray

    from eosp.jobs.build_fleet_demos import main as demos

    root = tmp_path_factory.mktemp("ctrl-c")
    for seed, split in ((1, "train"), (2, "train"), (9, "val")):
        f = generate(FleetGenConfig(satellites=3, tasks=300, hours=3.0, window_min_h=1.0, window_max_h=3.0,
                                    placement="cities", seed=seed))
        write_fleet(f, compute(f), root / "fleets" / split / f"fleet-{seed:05d}")
    ray.init(address="local", num_cpus=2, include_dashboard=False)
    try:
        for split in ("train", "val"):
            assert demos(["--fleets", str(root / "fleets" / split), "--out", str(root / split),
                          "--time-limit", "3"]) == 0
    finally:
        ray.shutdown()
    return root


def interrupt(argv: list, marker: str, delay: float, cwd: Path) -> tuple[int, list[str], float, str]:
    """Run `argv` in its own process group, wait for `marker` in its stdout, then `delay` seconds, and send SIGINT
    to the group; (exit status, the job's own stderr lines, seconds from the signal to the last process of the
    group gone, stdout)."""
    log = cwd / f"stdout-{time.monotonic_ns()}.txt"
    with open(log, "w") as out:
        p = subprocess.Popen([str(a) for a in argv], stdout=out, stderr=subprocess.PIPE, text=True, cwd=cwd,
                             start_new_session=True, preexec_fn=sigint_as_a_terminal_gives)
        t0 = time.monotonic()
        while p.poll() is None and marker not in log.read_text() and time.monotonic() - t0 < 240:
            time.sleep(0.05)
        assert p.poll() is None, f"the job ended before {marker!r}: {p.communicate()[1][-2000:]}"
        time.sleep(delay)
        rc, err, took = sigint_to_group(p, wait_s=60.0)  # Ray's processes too
    assert "Traceback" not in err, err[-3000:]
    prog = Path(str(argv[2]).rsplit(".", 1)[-1]).name + ".py:"
    return rc, [x for x in err.splitlines() if x.startswith(prog)], took, log.read_text()


def status_of(uri_db: Path, run_name: str) -> str | None:
    """The MLflow run's status (None: the job was stopped before it started its run)."""
    if not uri_db.exists():
        return None
    with sqlite3.connect(uri_db) as db:
        if db.execute("select name from sqlite_master where name = 'runs'").fetchone() is None:
            return None
        row = db.execute("select status from runs where name = ?", (run_name,)).fetchone()
    return None if row is None else row[0]


def test_ppo_fine_tuning_stopped_mid_iteration_keeps_its_last_checkpoint(data):
    from eosp.models.checkpoint import load_fleet_agent

    argv = [sys.executable, "-m", "eosp.jobs.train_fleet", "--train.train-data", data / "train",
            "--train.val-data", data / "val", "--train.run-dir", data / "runs", "--train.mlflow-uri",
            f"sqlite:///{data / 'mlflow.db'}", "--train.iterations", "200", "--train.validate-every", "1",
            "--train.checkpoint-every", "1", "--train.num-env-runners", "1", "--train.train-batch-size", "64",
            "--train.minibatch-size", "32", "--train.num-envs-per-env-runner", "1", "--model.hidden-dim", "8",
            "--model.n-layers", "1", "--ray.num-cpus", "2"]
    for n, delay in enumerate((0.05, 0.4)):  # sampling, the learner's update or validation of the next iteration
        rc, ours, took, out = interrupt([*argv, "--train.run-name", f"ppo{n}"], "iteration 2/", delay, data)
        assert rc == 130 and len(ours) == 1 and "interrupted" in ours[0], (rc, ours)
        assert took < 10.0, took
        agent, _, meta = load_fleet_agent(data / "runs" / f"ppo{n}" / "checkpoints" / "last")
        assert meta["iteration"] >= 2 and agent.cfg.hidden_dim == 8
        assert status_of(data / "mlflow.db", f"ppo{n}") == "KILLED"


def test_imitation_stopped_while_dagger_runs_on_ray(data):
    argv = [sys.executable, "-m", "eosp.jobs.pretrain_fleet", "--imitation.train-data", data / "train",
            "--imitation.val-data", data / "val", "--imitation.run-dir", data / "runs", "--imitation.mlflow-uri",
            f"sqlite:///{data / 'mlflow.db'}", "--model.hidden-dim", "8", "--model.n-layers", "1",
            "--imitation.run-name", "bc", "--imitation.epochs", "50", "--imitation.dagger-every", "1",
            "--imitation.dagger-instances", "2", "--imitation.dagger-time-limit", "20"]
    rc, ours, took, _ = interrupt(argv, "validation baselines", 0.2, data)
    assert rc == 130 and len(ours) == 1 and "interrupted" in ours[0], (rc, ours)
    assert took < 10.0, took
    assert status_of(data / "mlflow.db", "bc") in (None, "KILLED")  # never left RUNNING


def test_a_sweep_stopped_with_its_trials_running_resumes(data):
    argv = [sys.executable, "-m", "eosp.jobs.tune_fleet", "--tune.name", "arch", "--tune.hidden-dims", "8",
            "--tune.n-layers", "1", "2", "--tune.grace-period", "1", "--imitation.train-data", data / "train",
            "--imitation.val-data", data / "val", "--imitation.run-dir", data / "runs", "--imitation.mlflow-uri",
            f"sqlite:///{data / 'mlflow.db'}", "--imitation.epochs", "30", "--ray.num-cpus", "2"]
    rc, ours, took, _ = interrupt(argv, "trial", 3.0, data)
    assert rc == 130 and len(ours) == 1 and "interrupted" in ours[0], (rc, ours)
    assert took < 10.0, took
    r = subprocess.run([str(a) for a in argv], capture_output=True, text=True, cwd=data, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "resuming sweep arch" in r.stdout and "2 trials; best" in r.stdout, r.stdout[-2000:]


def test_onboard_training_stopped_in_ppo_keeps_its_state_and_resumes(tmp_path):
    """jobs/train_onboard.py stopped during PPO's second iteration: exit 130, one line, within 10 s; the state of
    the first iteration kept (WORK/ppo.json); the rerun resumes after it."""
    import json

    from tests.conftest import clustered_scenario

    clustered_scenario(tmp_path, tasks=150)
    argv = [sys.executable, "-m", "eosp.jobs.train_onboard", "--scenarios", tmp_path / "scen", "--work", tmp_path / "work", "--out", tmp_path / "policy",
            "--realizations", 3, "--validation", 1, "--time-limit", 0.5, "--epochs", 3, "--train-batch-size", 64,
            "--runners", 1, "--iterations", 3, "--ray.num-cpus", 2, "--mlflow-uri", f"sqlite:///{tmp_path / 'm.db'}"]
    rc, ours, took, _ = interrupt(argv, "PPO iteration 1", 0.5, tmp_path)
    assert rc == 130 and len(ours) == 1 and "interrupted" in ours[0], (rc, ours)
    assert took < 10.0, took
    assert json.loads((tmp_path / "work" / "ppo.json").read_text())["iteration"] >= 1
    r = subprocess.run([str(a) for a in argv], capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert r.returncode == 0 and "resuming after PPO iteration" in r.stdout, r.stderr[-2000:]
