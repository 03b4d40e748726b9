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
    msg = str(exc.value.code)
    assert "\n" not in msg and flag in msg and "absolute path" in msg and "working_dir_files" in msg
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
    ("train", ["--train.train-data", "DATA", "--train.run-dir", "OUT", "--train.mlflow-uri", "URI"]),
    ("pretrain", ["--imitation.run-dir", "OUT", "--imitation.mlflow-uri", "URI"]),
    ("tune", ["--train.run-dir", "OUT", "--train.mlflow-uri", "URI"]),
])
def test_mlflow_unreachable_is_one_line_before_work(tmp_path, module, argv):
    import importlib

    import ray

    if ray.is_initialized():  # left by an earlier test: the check below is about this job only
        ray.shutdown()
    uri = f"http://127.0.0.1:{closed_port()}"
    argv = [{"DATA": str(tmp_path / "data"), "OUT": str(tmp_path / "out"), "URI": uri}.get(a, a) for a in argv]
    with pytest.raises(SystemExit) as exc:
        importlib.import_module(f"eosp.jobs.{module}").main(argv)
    msg = str(exc.value.code)
    assert "\n" not in msg and uri in msg and "unreachable" in msg
    assert not ray.is_initialized() and not (tmp_path / "out").exists()


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
    assert f"resuming: {len(first)} of 3 shards already complete" in so
    for name, mtime in first.items():  # complete shards are kept, not rebuilt
        assert (out / name).stat().st_mtime_ns == mtime
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "shard-00000.parquet", "shard-00001.parquet",
                                                     "shard-00002.parquet"]  # no temporaries left
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
