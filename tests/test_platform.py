"""The local platform for real: scripts/platform-up.sh starts a Ray head (2 CPUs) and an MLflow
server, training jobs are submitted with `ray job submit --working-dir .`, parts of them are
killed with SIGKILL, and scripts/platform-down.sh stops everything.

* the services listen on 127.0.0.1 only and the job server refuses requests without the token;
* a submitted job logs its run to the MLflow server, and survives the loss of its environment
  runner (RLlib restarts it and training goes on);
* a job whose driver is killed mid-run is resubmitted with --train.resume true: the iteration
  count continues and nothing logged before is lost.

Only processes that carry this platform's EOSP_PLATFORM_ID are ever signalled.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import secrets
import shutil
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import pytest

from eosp.shards.io import write_shard
from tests.conftest import generated

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
JOB_TIMEOUT = 420

pytestmark = pytest.mark.platform


@dataclass
class Platform:
    state_dir: Path
    state: dict
    env: dict  # environment for the scripts and the ray CLI
    token: str

    @property
    def dashboard(self) -> str:
        return self.state["ray"]["dashboard_url"]

    @property
    def mlflow_uri(self) -> str:
        return self.state["mlflow"]["tracking_uri"]

    def owns(self, pid: int) -> bool:
        """The process was started by this platform (its environment carries the platform's id)."""
        try:
            with open(f"/proc/{pid}/environ", "rb") as f:
                return f"EOSP_PLATFORM_ID={self.state['id']}".encode() in f.read().split(b"\0")
        except OSError:
            return False

    def processes(self) -> list[int]:
        return [int(p) for p in os.listdir("/proc") if p.isdigit() and self.owns(int(p))]

    def jobs(self):
        from ray.job_submission import JobSubmissionClient

        return JobSubmissionClient(self.dashboard, headers={"Authorization": f"Bearer {self.token}"})


def run_script(name: str, env: dict, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([str(ROOT / "scripts" / name)], env=env, capture_output=True, text=True, timeout=timeout,
                          cwd=ROOT)


@contextlib.contextmanager
def running_platform(state_dir: Path, **settings: str):
    """scripts/platform-up.sh on `state_dir` with a fresh token and the EOSP_* `settings`; on exit,
    scripts/platform-down.sh, checking that nothing of the platform survives it."""
    token_file = state_dir / "auth_token"
    token = secrets.token_hex(32)
    token_file.write_text(token)
    token_file.chmod(0o600)
    env = {k: v for k, v in os.environ.items()
           if k not in ("RAY_ADDRESS", "RAY_API_SERVER_ADDRESS", "RAY_AUTH_TOKEN", "MLFLOW_TRACKING_URI")}
    env.update(EOSP_PLATFORM_DIR=str(state_dir), EOSP_PYTHON=sys.executable, RAY_AUTH_MODE="token",
               RAY_AUTH_TOKEN_PATH=str(token_file), **settings)
    t0 = time.monotonic()
    up = run_script("platform-up.sh", env)
    assert up.returncode == 0, up.stdout + up.stderr
    print(f"[platform] up in {time.monotonic() - t0:.1f} s: {up.stdout.strip().splitlines()[0]}")
    p = Platform(state_dir, json.loads((state_dir / "platform.json").read_text()), env, token)
    try:
        yield p
    finally:
        t0 = time.monotonic()
        down = run_script("platform-down.sh", env, timeout=120)
        print(f"[platform] down in {time.monotonic() - t0:.1f} s: {down.stdout.strip()}")
        assert down.returncode == 0, down.stdout + down.stderr
        assert not p.processes(), "processes of the platform survived platform-down.sh"
        assert not (state_dir / "platform.json").exists() and (state_dir / "mlflow" / "mlflow.db").exists()
        ray_tmp = p.state["ray"]["temp_dir"]
        if ray_tmp.startswith("/tmp/eosp-ray-"):  # outside the state directory (its path was too long)
            shutil.rmtree(ray_tmp, ignore_errors=True)


@pytest.fixture(scope="module")
def platform(tmp_path_factory):
    with running_platform(tmp_path_factory.mktemp("platform")) as p:
        yield p


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("platform-data")
    write_shard(d / "train" / "shard-0.parquet", [generated("uniform", 12, s) for s in range(3)])
    write_shard(d / "val" / "shard-0.parquet", [generated("uniform", 12, s) for s in range(100, 102)])
    return d


def submit(p: Platform, data: Path, submission_id: str, run_name: str, iterations: int, *extra: str) -> str:
    """`ray job submit --working-dir .` of a tiny training run; returns the job id."""
    args = ["--train.train-data", data / "train", "--train.val-data", data / "val", "--train.run-dir", data / "runs",
            "--train.run-name", run_name, "--train.mlflow-uri", p.mlflow_uri, "--env.max-acquisitions", 16,
            "--train.train-batch-size", 128, "--train.minibatch-size", 64, "--train.num-epochs", 1,
            "--model.hidden-dim", 8, "--model.n-layers", 2, "--model.heads", 1, "--train.validate-every", 1000,
            "--train.checkpoint-every", 1, "--train.iterations", iterations, "--ray.num-cpus", 2, *extra]
    # through this Python, not the console script's shebang (which may name another environment's Python)
    cmd = [sys.executable, str(BIN / "ray"), "job", "submit", "--no-wait", "--address", p.dashboard, "--submission-id", submission_id,
           "--working-dir", ".", "--runtime-env", "platform/runtime-env.yaml", "--",
           "python", "jobs/train.py", *map(str, args)]
    r = subprocess.run(cmd, env=p.env, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    return submission_id


def wait(p: Platform, job_id: str, until=None, timeout: float = JOB_TIMEOUT):
    """Poll the job until it ends (returns its JobStatus, a str) or until(logs) is True (returns True)."""
    client = p.jobs()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        status = client.get_job_status(job_id)
        if until is not None:
            if until(client.get_job_logs(job_id)) is True:
                return True
        if status.is_terminal():
            return status
        time.sleep(0.5)
    raise AssertionError(f"job {job_id} still {status} after {timeout:.0f} s:\n{client.get_job_logs(job_id)[-3000:]}")


def iterations_logged(logs: str) -> list[tuple[int, float]]:
    """(iteration, env steps/s) of the job's '[train] iteration i/N: ...' lines."""
    return [(int(m.group(1)), float(m.group(2)))
            for m in re.finditer(r"^\[train\] iteration (\d+)/\d+: return \S+, (\d+) env steps/s", logs, re.M)]


def test_services_listen_on_loopback_only_and_require_the_token(platform):
    import psutil

    p = platform
    assert p.state["host"] == "127.0.0.1" and p.state["ray"]["auth_mode"] == "token"
    assert p.dashboard.startswith("http://127.0.0.1:") and p.mlflow_uri.startswith("http://127.0.0.1:")
    env_file = (p.state_dir / "env").read_text()
    assert f"RAY_API_SERVER_ADDRESS={p.dashboard}" in env_file and f"MLFLOW_TRACKING_URI={p.mlflow_uri}" in env_file

    listening = {}
    for pid in p.processes():
        try:
            for c in psutil.Process(pid).net_connections(kind="inet"):
                if c.status == psutil.CONN_LISTEN:
                    listening[c.laddr.port] = c.laddr.ip
        except psutil.Error:
            pass
    ports = {int(u.rsplit(":", 1)[1]) for u in (p.dashboard, p.mlflow_uri, p.state["ray"]["gcs_address"])}
    assert ports <= set(listening), (ports, listening)
    exposed = {port: ip for port, ip in listening.items() if ip not in ("127.0.0.1", "::ffff:127.0.0.1", "::1")}
    assert not exposed, f"listening beyond the loopback: {exposed}"

    # the job server wants the token; the MLflow server answers on the loopback
    for headers, code in (({}, 401), ({"Authorization": "Bearer " + "0" * 64}, 403)):
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(urllib.request.Request(p.dashboard + "/api/jobs/", headers=headers), timeout=10)
        assert e.value.code == code
    assert p.jobs().list_jobs() == []
    assert urllib.request.urlopen(p.mlflow_uri + "/health", timeout=10).read().strip() == b"OK"

    # a second platform-up on the same state directory refuses to start
    again = run_script("platform-up.sh", p.env, timeout=60)
    assert again.returncode == 1 and "already running" in again.stderr


def test_submitted_job_logs_to_mlflow_and_survives_a_killed_env_runner(platform, data):
    from ray.util.state import StateApiClient
    from ray.util.state.common import ListApiOptions, StateResource

    import mlflow

    p, n = platform, 16
    t0 = time.monotonic()
    job = submit(p, data, "eosp-test-runner-kill", "runner-kill", n)
    states = StateApiClient(address=p.dashboard, headers={"Authorization": f"Bearer {p.token}"})

    def env_runners(alive: bool = True):
        filters = [("class_name", "=", "SingleAgentEnvRunner")] + ([("state", "=", "ALIVE")] if alive else [])
        return states.list(StateResource.ACTORS, options=ListApiOptions(filters=filters, detail=True),
                           raise_on_missing_output=False)

    # once training runs (iteration 2 logged), SIGKILL the environment runner
    got = wait(p, job, until=lambda logs: bool(iterations_logged(logs)) and iterations_logged(logs)[-1][0] >= 2)
    assert got is True, f"job ended before iteration 2: {got}\n{p.jobs().get_job_logs(job)[-3000:]}"
    (runner,) = env_runners()
    assert p.owns(runner.pid)
    killed_at = iterations_logged(p.jobs().get_job_logs(job))[-1][0]
    os.kill(runner.pid, signal.SIGKILL)
    print(f"[platform] killed env runner pid {runner.pid} after iteration {killed_at} "
          f"({time.monotonic() - t0:.0f} s after submission)")

    status = wait(p, job)
    logs = p.jobs().get_job_logs(job)
    print(f"[platform] runner-kill job {status} after {time.monotonic() - t0:.0f} s")
    assert status == "SUCCEEDED", logs[-4000:]
    # replaced: Ray restarted the actor, RLlib put it back to work and training went on
    (after,) = [a for a in env_runners(alive=False) if a.actor_id == runner.actor_id]
    assert after.num_restarts >= 1 and after.pid != runner.pid
    its = iterations_logged(logs)
    assert [i for i, _ in its] == list(range(1, n + 1)), logs[-4000:]
    assert killed_at < n - 1 and any(steps > 0 for i, steps in its if i > killed_at + 1), its

    # the run is on the MLflow server: parameters, every iteration's metrics, artifacts (served by it)
    run_id = json.loads((data / "runs" / "runner-kill" / "run.json").read_text())["mlflow_run_id"]
    client = mlflow.tracking.MlflowClient(p.mlflow_uri)
    run = client.get_run(run_id)
    assert run.info.status == "FINISHED" and run.info.run_name == "runner-kill"
    assert run.info.artifact_uri.startswith("mlflow-artifacts:")
    assert run.data.params["model.hidden_dim"] == "8" and run.data.params["train.iterations"] == str(n)
    assert [m.step for m in client.get_metric_history(run_id, "perf/iteration_s")] == list(range(1, n + 1))
    assert client.get_metric_history(run_id, "val/ratio_to_greedy")
    assert "learning_curve.png" in [a.path for a in client.list_artifacts(run_id)]
    assert list((p.state_dir / "mlflow" / "artifacts").rglob("learning_curve.png"))

    # what --working-dir uploaded: the sources, not the local state
    uri = p.jobs().get_job_info(job).runtime_env["working_dir"]  # gcs://_ray_pkg_HASH.zip
    pkg = (Path(p.state["ray"]["temp_dir"]) / "session_latest" / "runtime_resources" / "working_dir_files"
           / uri.rsplit("/", 1)[1].removesuffix(".zip"))
    assert (pkg / "jobs" / "train.py").exists() and (pkg / "core" / "config.py").exists()
    for local in (".venv", "data", "runs", "mlruns", "mlflow.db", ".platform", ".git"):
        assert not (pkg / local).exists(), local


def test_killed_job_resumes_from_its_last_checkpoint(platform, data):
    import mlflow

    p = platform
    run_file = data / "runs" / "resume" / "run.json"
    t0 = time.monotonic()
    job = submit(p, data, "eosp-test-driver-kill", "resume", 40)

    def checkpointed(_logs: str) -> bool:
        try:
            return json.loads(run_file.read_text())["iteration"] >= 2
        except (OSError, ValueError):
            return False

    got = wait(p, job, until=checkpointed)
    assert got is True, f"job ended before its second checkpoint: {got}\n{p.jobs().get_job_logs(job)[-3000:]}"
    driver = int(p.jobs().get_job_info(job).driver_info.pid)
    assert p.owns(driver)
    os.kill(driver, signal.SIGKILL)
    assert wait(p, job) == "FAILED"
    state = json.loads(run_file.read_text())
    k, run_id = state["iteration"], state["mlflow_run_id"]
    client = mlflow.tracking.MlflowClient(p.mlflow_uri)
    before = {(m.step, m.value, m.timestamp) for m in client.get_metric_history(run_id, "perf/iteration_s")}
    print(f"[platform] killed the driver after checkpoint {k} ({time.monotonic() - t0:.0f} s); resubmitting")
    assert k >= 2 and {s for s, _, _ in before} >= set(range(1, k + 1))
    assert client.get_run(run_id).info.status == "RUNNING"  # the killed session could not end it

    job2 = submit(p, data, "eosp-test-resume", "resume", k + 2, "--train.resume", "true")
    status = wait(p, job2)
    logs = p.jobs().get_job_logs(job2)
    print(f"[platform] resumed job {status} ({time.monotonic() - t0:.0f} s after the first submission)")
    assert status == "SUCCEEDED", logs[-4000:]
    assert f"resumed resume at iteration {k}" in logs
    assert [i for i, _ in iterations_logged(logs)] == [k + 1, k + 2]
    after = {(m.step, m.value, m.timestamp) for m in client.get_metric_history(run_id, "perf/iteration_s")}
    assert before <= after  # nothing logged before is lost
    assert {s for s, _, _ in after} == set(range(1, k + 3))
    assert json.loads(run_file.read_text())["iteration"] == k + 2
    run = client.get_run(run_id)
    assert run.info.status == "FINISHED" and run.data.params["model.hidden_dim"] == "8"
