"""jobs/train_onboard.py end to end on Ray: recordings, the tuned rule, imitation, PPO on RLlib's multi-agent env
runners, the MLflow run, a policy that loads and chooses, a rerun that resumes, an evaluation scenario refused."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from eosp.ops.evaluation import evaluation_seeds
from eosp.ops.scenario import ScenarioConfig, make
from tests.conftest import clustered_scenario

ROOT = Path(__file__).resolve().parents[1]


def job(*args, cwd):
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    return subprocess.run([sys.executable, str(ROOT / "jobs/train_onboard.py"), *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, env=env, timeout=600)


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    root = tmp_path_factory.mktemp("onboard-job")
    clustered_scenario(root, tasks=150)
    return root


def test_train_resume_and_refusal(fleet, tmp_path):
    from eosp.models.onboard import load_policy

    common = ["--scenarios", fleet / "scen", "--work", tmp_path / "work", "--out", tmp_path / "policy",
              "--realizations", 3, "--validation", 1, "--time-limit", 0.5, "--epochs", 3, "--train-batch-size", 32,
              "--runners", 1, "--ray.num-cpus", 2, "--mlflow-uri", f"sqlite:///{tmp_path / 'mlflow.db'}"]
    r = job(*common, "--iterations", 1, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "PPO iteration 1" in r.stdout and "tuned rule" in r.stdout
    meta = json.loads((tmp_path / "policy" / "onboard.json").read_text())
    assert {"rule/beta", "rule/gamma", "validation_served"} <= set(meta)
    load_policy(tmp_path / "policy")
    assert len(list((tmp_path / "work" / "recordings").glob("*.npz"))) == 3
    r = job(*common, "--iterations", 2, cwd=tmp_path)  # resumes after iteration 1: one more
    assert r.returncode == 0, r.stderr[-2000:]
    assert "resuming after PPO iteration 1" in r.stdout and "PPO iteration 2" in r.stdout
    assert "PPO iteration 1:" not in r.stdout

    import mlflow

    mlflow.set_tracking_uri(f"sqlite:///{tmp_path / 'mlflow.db'}")
    runs = mlflow.search_runs(experiment_names=["eosp-onboard"])
    assert len(runs) == 2 and runs["metrics.policy/validation_served"].notna().all()

    seed = sorted(evaluation_seeds())[0]
    make(str(fleet / "fleet"), ScenarioConfig(seed=seed), str(tmp_path / "hidden"))
    r = job("--scenarios", tmp_path / "hidden", "--work", tmp_path / "w2", "--out", tmp_path / "p2", cwd=tmp_path)
    assert r.returncode == 2 and "evaluation scenario" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "w2").exists() and not (tmp_path / "p2").exists()
