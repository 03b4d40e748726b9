"""Faults of the Ray jobs: killed and rerun, MLflow unreachable, outputs lost in Ray's working dir copy."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def closed_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


@pytest.fixture(scope="module")
def shards(tmp_path_factory) -> Path:
    """A data set directory of one small shard, outside the tests' own folders (they must stay empty)."""
    sys.path.insert(0, str(ROOT))
    from eosp.shards.io import write_shard
    from tests.conftest import generated

    d = tmp_path_factory.mktemp("data")
    write_shard(d / "shard-0.parquet", [generated("uniform", 12, s) for s in range(2)])
    return d


def job(script, *args, kill_after=0, timeout=600):
    """Run a job in its own session; with `kill_after` it SIGKILLs itself after that many results."""
    env = {**os.environ, "EOSP_FAULT_KILL_AFTER": str(kill_after)}
    p = subprocess.Popen([sys.executable, str(ROOT / "jobs" / script), *map(str, args)], cwd=ROOT, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = p.communicate(timeout=timeout)
    finally:
        try:  # the local Ray it started dies with it
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return p.returncode, out, err


# --------------------------------------------------------------------------- before any work (no Ray)

def _in_ray_working_dir_copy(tmp_path, monkeypatch):
    d = tmp_path / "session_x" / "runtime_resources" / "working_dir_files" / "_ray_pkg_abc"
    d.mkdir(parents=True)
    monkeypatch.chdir(d)


@pytest.mark.parametrize("module,argv,flag", [
    ("train", ["--train.run-dir", "runs"], "--train.run-dir"),
    ("tune", ["--train.run-dir", "runs"], "--train.run-dir"),
    ("pretrain", ["--imitation.run-dir", "runs"], "--imitation.run-dir"),
    ("evaluate", ["--out", "runs/eval"], "--out"),
    ("build_shards", ["--out", "data/train"], "--out"),
    ("build_demos", ["--data", "data/demo/train"], "--data"),
])
def test_relative_output_refused_in_uploaded_working_dir(tmp_path, monkeypatch, module, argv, flag):
    import importlib

    import ray

    if ray.is_initialized():  # left by an earlier test: the check below is about this job only
        ray.shutdown()
    _in_ray_working_dir_copy(tmp_path, monkeypatch)
    main = importlib.import_module(f"eosp.jobs.{module}").main
    with pytest.raises(SystemExit) as exc:
        main(argv)
    msg = exc.value.message
    assert exc.value.code == 2 and "\n" not in msg and flag in msg
    assert "absolute path" in msg and "working_dir_files" in msg
    assert not ray.is_initialized()
    assert list(Path.cwd().iterdir()) == []  # nothing written there


def test_absolute_output_accepted_in_uploaded_working_dir(tmp_path, monkeypatch):
    from eosp.jobs.preflight import require_findable, uploaded_working_dir

    _in_ray_working_dir_copy(tmp_path, monkeypatch)
    assert uploaded_working_dir() is not None
    require_findable(str(tmp_path / "out"), "--out")  # no error
    monkeypatch.chdir(tmp_path)
    assert uploaded_working_dir() is None
    require_findable("runs", "--out")  # an ordinary working directory: relative is fine


@pytest.mark.parametrize("module,argv", [
    ("evaluate", ["--data", "DATA", "--out", "OUT", "--mlflow-uri", "URI"]),
    ("train", ["--train.train-data", "DATA", "--train.val-data", "DATA", "--train.run-dir", "OUT",
               "--train.mlflow-uri", "URI"]),
    ("pretrain", ["--imitation.train-data", "DATA", "--imitation.val-data", "DATA", "--imitation.run-dir", "OUT",
                  "--imitation.mlflow-uri", "URI"]),
    ("tune", ["--train.train-data", "DATA", "--train.val-data", "DATA", "--train.run-dir", "OUT",
              "--train.mlflow-uri", "URI"]),
])
def test_mlflow_unreachable_is_one_line_before_work(tmp_path, shards, module, argv):
    import importlib

    import ray

    if ray.is_initialized():  # left by an earlier test: the check below is about this job only
        ray.shutdown()
    uri = f"http://127.0.0.1:{closed_port()}"
    argv = [{"DATA": str(shards), "OUT": str(tmp_path / "out"), "URI": uri}.get(a, a) for a in argv]
    with pytest.raises(SystemExit) as exc:
        importlib.import_module(f"eosp.jobs.{module}").main(argv)
    msg = exc.value.message
    assert exc.value.code == 2 and "\n" not in msg and uri in msg and "unreachable" in msg
    assert not ray.is_initialized() and not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- what the Ray cluster offers

HEAD = {"CPU": 2.0, "memory": 8e9, "object_store_memory": 2e9, "node:127.0.0.1": 1.0, "node:__internal_head__": 1.0}
RUNNER_NODE = {"CPU": 1.0, "eosp_runner": 1.0, "memory": 8e9, "object_store_memory": 2e9, "node:127.0.0.1": 1.0}
GPU_NODE = {"CPU": 8.0, "GPU": 1.0, "accelerator_type:H100": 1.0, "memory": 8e9, "node:10.0.0.3": 1.0}


def _train(**kw):
    from eosp.config import TrainConfig

    return TrainConfig(**kw)


@pytest.mark.parametrize("train,nodes,driver_gpus,expected", [
    # fits: no message
    (dict(), [HEAD], None, None),
    (dict(num_env_runners=2), [HEAD], None, None),
    (dict(num_env_runners=0), [{"CPU": 1.0}], None, None),
    (dict(num_env_runners=3), [HEAD, RUNNER_NODE], None, None),
    (dict(num_env_runners=1, env_runner_resource="eosp_runner"), [HEAD, RUNNER_NODE], None, None),
    (dict(num_gpus_per_learner=1), [HEAD, GPU_NODE], 1, None),
    (dict(num_gpus_per_learner=0.5), [GPU_NODE], None, None),
    # (a) more env runners than CPUs
    (dict(num_env_runners=5), [HEAD], None,
     "--train.num-env-runners 5: each env runner takes 1 CPU and this Ray cluster has 2 (resources: 2 CPU on 1 node); "
     "pass --train.num-env-runners 2 or fewer, or add nodes"),
    (dict(num_env_runners=4), [HEAD, RUNNER_NODE], None,
     "--train.num-env-runners 4: each env runner takes 1 CPU and this Ray cluster has 3 (resources: 3 CPU, "
     "1 eosp_runner on 2 nodes); pass --train.num-env-runners 3 or fewer, or add nodes"),
    (dict(num_env_runners=2), [{"CPU": 1.5}], None, "this Ray cluster has 1 (resources: 1.5 CPU on 1 node)"),
    # (b) a GPU learner without a GPU
    (dict(num_gpus_per_learner=1), [HEAD], None,
     "--train.num-gpus-per-learner 1: this Ray cluster has no GPU (resources: 2 CPU on 1 node)"),
    (dict(num_gpus_per_learner=2), [GPU_NODE], None,
     "--train.num-gpus-per-learner 2: this Ray cluster has 1 GPU (resources: 8 CPU, 1 GPU on 1 node)"),
    (dict(num_gpus_per_learner=1), [HEAD, GPU_NODE], 0,
     "--train.num-gpus-per-learner 1: the learner runs in the driver (num_learners=0), which sees no CUDA device"),
    # (c) env runners placed on a custom resource
    (dict(env_runner_resource="eosp_runner"), [HEAD], None,
     "--train.env-runner-resource eosp_runner: no node of this Ray cluster offers it (resources: 2 CPU on 1 node); "
     "start nodes with: ray start --address HEAD:PORT --resources '{\"eosp_runner\": K}'"),
    (dict(num_env_runners=2, env_runner_resource="eosp_runner"), [HEAD, RUNNER_NODE], None,
     "--train.env-runner-resource eosp_runner --train.num-env-runners 2: each env runner takes 1 eosp_runner and "
     "1 CPU of the same node, and the nodes that offer eosp_runner have room for 1 (resources: 3 CPU, 1 eosp_runner "
     "on 2 nodes); pass --train.num-env-runners 1 or fewer, or add nodes"),
    # a node offering 4 units but 1 CPU hosts one runner
    (dict(num_env_runners=2, env_runner_resource="r"), [HEAD, {"CPU": 1.0, "r": 4.0}], None, "have room for 1"),
    (dict(num_env_runners=0, env_runner_resource="eosp_runner"), [HEAD, RUNNER_NODE], None,
     "--train.env-runner-resource eosp_runner places env runners, but --train.num-env-runners is 0 (sampling in "
     "the driver): pass --train.num-env-runners 1 or more"),
])
def test_cluster_that_cannot_run_the_training_is_refused(train, nodes, driver_gpus, expected):
    from eosp.jobs.preflight import cluster_problem, require_cluster_fits

    t = _train(**train)
    got = cluster_problem(t, nodes, driver_gpus)
    if expected is None:
        assert got is None
        require_cluster_fits(t, nodes, driver_gpus)
        return
    assert got is not None and expected in got and "\n" not in got, got
    with pytest.raises(SystemExit) as exc:
        require_cluster_fits(t, nodes, driver_gpus)
    assert exc.value.code == 2 and exc.value.message == f"error: {got}"


def test_cluster_resources_dict_stands_for_one_node():
    """ray.cluster_resources() (the totals) is accepted as a one-node cluster."""
    from eosp.jobs.preflight import cluster_problem

    totals = {"CPU": 3.0, "eosp_runner": 1.0, "memory": 1e9}
    assert cluster_problem(_train(num_env_runners=3), [totals]) is None
    assert "has 3 (resources: 3 CPU, 1 eosp_runner on 1 node)" in cluster_problem(_train(num_env_runners=4), [totals])


def test_new_train_flags_reach_rllib():
    from eosp.config import RunConfig
    from eosp.training.ppo import ppo_config

    cfg = RunConfig()
    pc = ppo_config(cfg)
    assert pc.custom_resources_per_env_runner == {} and pc.num_gpus_per_learner == 0 and pc.num_learners == 0
    cfg.train.env_runner_resource, cfg.train.num_gpus_per_learner = "eosp_runner", 0.5
    pc = ppo_config(cfg)
    assert pc.custom_resources_per_env_runner == {"eosp_runner": 1} and pc.num_gpus_per_learner == 0.5


@pytest.mark.parametrize("args,line", [
    (["--train.num-env-runners", 5],
     "train.py: error: --train.num-env-runners 5: each env runner takes 1 CPU and this Ray cluster has 2 (resources: 2 CPU on "
     "1 node); pass --train.num-env-runners 2 or fewer, or add nodes"),
    (["--train.preset", "reference", "--train.num-gpus-per-learner", 1],
     "train.py: error: --train.num-gpus-per-learner 1: this Ray cluster has no GPU (resources: 2 CPU on 1 node)"),
])
def test_train_job_refuses_what_the_local_ray_cannot_run(tmp_path, shards, args, line):
    """`python jobs/train.py` on a local Ray of 2 CPUs and no GPU: one line, before anything is written."""
    import time

    t0 = time.monotonic()
    rc, so, se = job("train.py", "--train.train-data", shards, "--train.val-data", shards,
                     "--train.run-dir", tmp_path / "runs", "--train.mlflow-uri", f"sqlite:///{tmp_path / 'm.db'}",
                     "--ray.num-cpus", 2, *args, timeout=180)
    assert rc == 2, (rc, so, se[-3000:])
    assert se.strip().splitlines()[-1] == line, se[-3000:]
    assert se.count("error:") == 1 and "Traceback" not in se, se[-3000:]
    assert list(tmp_path.iterdir()) == []  # no run directory, no MLflow database
    assert time.monotonic() - t0 < 120


def test_tune_refuses_a_gpu_learner_without_a_gpu(tmp_path, shards):
    import ray

    from eosp.jobs.tune import main

    if ray.is_initialized():
        ray.shutdown()
    try:
        with pytest.raises(SystemExit) as exc:
            main(["--train.train-data", str(shards), "--train.val-data", str(shards),
                  "--train.run-dir", str(tmp_path / "runs"), "--train.mlflow-uri", f"sqlite:///{tmp_path / 'm.db'}",
                  "--train.num-gpus-per-learner", "1", "--ray.num-cpus", "1"])
    finally:
        ray.shutdown()
    assert exc.value.code == 2 and exc.value.message == ("error: --train.num-gpus-per-learner 1: this Ray cluster has "
                                                         "no GPU (resources: 1 CPU on 1 node)")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- killed and rerun (local Ray)

def test_build_shards_killed_and_rerun_resumes(tmp_path):
    from eosp.shards.io import read_instances

    out = tmp_path / "ds"
    args = ["--out", out, "--n-acquisitions", 10, "--n-instances", 3, "--per-shard", 1, "--seed", 5,
            "--ray.num-cpus", 1, "--instance.graph.step-s", 4]
    rc, so, se = job("build_shards.py", *args, kill_after=1)
    assert rc == -signal.SIGKILL, (rc, so, se)
    assert not (out / "manifest.json").exists()
    first = {p.name: p.stat().st_mtime_ns for p in out.glob("shard-*.parquet")}
    assert 1 <= len(first) < 3
    rc, so, se = job("build_shards.py", *args)
    assert rc == 0, se[-3000:]
    # the killed driver's running task may still finish its shard (its worker belongs to the local Ray, not to the
    # driver's process group) between the listing above and the rerun: at least those listed are kept
    import re

    kept = re.search(r"resuming: (\d) of 3 shards already complete", so)
    assert kept and len(first) <= int(kept.group(1)) < 3, so
    for name, mtime in first.items():  # complete shards are kept, not rebuilt
        assert (out / name).stat().st_mtime_ns == mtime
    assert sorted(p.name for p in out.iterdir()) == [".eosp.json", "manifest.json", "shard-00000.parquet",
                                                     "shard-00001.parquet", "shard-00002.parquet"]  # no temporaries
    manifest = json.loads((out / "manifest.json").read_text())
    assert [len(s["instances"]) for s in manifest["shards"]] == [1, 1, 1]
    assert [i.meta["seed"] for i in read_instances(sorted(out.glob("shard-*.parquet")))] == [5, 6, 7]
    # another configuration in the same folder is refused, not mixed in
    rc, so, se = job("build_shards.py", *args[:-2], "--instance.graph.step-s", 2)
    assert rc != 0 and "other settings" in se and "Traceback" not in se
    assert (out / "shard-00000.parquet").stat().st_mtime_ns == first.get("shard-00000.parquet",
                                                                        (out / "shard-00000.parquet").stat().st_mtime_ns)


def test_evaluate_killed_and_rerun_gives_the_same_report(tmp_path):
    import pandas as pd

    from eosp.shards.io import write_shard
    from tests.conftest import generated

    write_shard(tmp_path / "data" / "shard-0.parquet", [generated("uniform", 12, s) for s in range(3)])

    def args(out):
        return ["--data", tmp_path / "data", "--solvers", "greedy", "ramp", "--time-limit", 10, "--out", out,
                "--mlflow-uri", f"sqlite:///{tmp_path / 'm.db'}", "--ray.num-cpus", 1, "--html-reports", 1]

    rc, so, se = job("evaluate.py", *args(tmp_path / "a"), kill_after=2)
    assert rc == -signal.SIGKILL, (rc, so, se)
    assert not (tmp_path / "a" / "report.md").exists()
    assert len(list((tmp_path / "a" / "partial").glob("*.json"))) == 3  # 2 results and the settings
    rc, so, se = job("evaluate.py", *args(tmp_path / "a"))
    assert rc == 0, se[-3000:]
    assert "resuming: 2 of 6 results kept" in so and "4/4 done" in so
    rc, so, se = job("evaluate.py", *args(tmp_path / "b"))  # uninterrupted
    assert rc == 0, se[-3000:]
    a, b = (pd.read_parquet(tmp_path / d / "results.parquet").drop(columns="seconds") for d in "ab")
    pd.testing.assert_frame_equal(a, b)

    def scores(d):  # the report, solve times aside
        return (tmp_path / d / "report.md").read_text().split("Mean solve time")[0]
    assert scores("a") == scores("b") and "/ Greedy" in scores("a")
    assert not (tmp_path / "a" / "partial").exists()
