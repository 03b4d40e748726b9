"""The training job end to end on tiny instances: two PPO iterations, checkpoints, MLflow, resume, solve."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from eosp.shards.io import write_shard
from tests.conftest import generated

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("data")
    write_shard(d / "train" / "shard-0.parquet", [generated("uniform", 12, s) for s in range(3)])
    write_shard(d / "val" / "shard-0.parquet", [generated("uniform", 12, s) for s in range(100, 102)])
    return d


def train(tmp, data, *extra):
    args = [sys.executable, str(ROOT / "jobs" / "train.py"), "--train.train-data", data / "train",
            "--train.val-data", data / "val", "--train.run-dir", tmp / "runs", "--train.run-name", "t",
            "--train.mlflow-uri", f"sqlite:///{tmp / 'mlflow.db'}", "--env.max-acquisitions", 16,
            "--train.train-batch-size", 64, "--train.minibatch-size", 32, "--train.num-epochs", 1,
            "--model.hidden-dim", 8, "--model.n-layers", 2, "--model.heads", 1, "--train.validate-every", 1,
            "--train.checkpoint-every", 1, "--ray.num-cpus", 2, *extra]
    r = subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=600, cwd=tmp)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-5000:]
    return r


def test_two_iterations_checkpoint_mlflow_resume_and_solve(tmp_path, data):
    import mlflow

    r = train(tmp_path, data, "--train.iterations", 2)
    assert "iteration 2/2" in r.stdout and "val ratio to greedy" in r.stdout
    # no error-level line of Ray's (the env runners carry their config: training/ppo.py), which a user reads as a
    # failure; the restart of a killed env runner is tested in tests/test_platform.py
    assert not re.search(r"^\[[^\]]* E \d+ \d+\]", r.stderr, re.M), r.stderr[-3000:]
    run = json.loads((tmp_path / "runs" / "t" / "run.json").read_text())
    assert run["iteration"] == 2 and run["config"]["model"]["hidden_dim"] == 8
    client = mlflow.tracking.MlflowClient(f"sqlite:///{tmp_path / 'mlflow.db'}")
    hist = client.get_metric_history(run["mlflow_run_id"], "train/episode_return_mean")
    assert [m.step for m in hist] == [1, 2]
    assert client.get_run(run["mlflow_run_id"]).data.params["model.hidden_dim"] == "8"
    assert client.get_metric_history(run["mlflow_run_id"], "val/ratio_to_greedy")
    arts = [a.path for a in client.list_artifacts(run["mlflow_run_id"])]
    assert "learning_curve.png" in arts

    # resume: the iteration count continues and nothing logged before is lost
    r = train(tmp_path, data, "--train.iterations", 3, "--train.resume", "true")
    assert "resumed t at iteration 2" in r.stdout and "iteration 3/3" in r.stdout
    hist = client.get_metric_history(run["mlflow_run_id"], "train/episode_return_mean")
    assert [m.step for m in hist] == [1, 2, 3]

    # the checkpoint decodes schedules through the CLI
    inst_dir = tmp_path / "inst"
    from eosp.instances.interchange import write_instance

    write_instance(generated("uniform", 12, 100), inst_dir)
    ck = tmp_path / "runs" / "t" / "checkpoints" / "best"
    out = subprocess.run([sys.executable, "-m", "eosp.cli", "solve", str(inst_dir), "--solver", "policy",
                          "--checkpoint", str(ck), "--out", str(tmp_path / "s.parquet")],
                         capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    val = subprocess.run([sys.executable, "-m", "eosp.cli", "validate", str(inst_dir), str(tmp_path / "s.parquet")],
                         capture_output=True, text=True, cwd=ROOT)
    assert val.returncode == 0 and val.stdout.startswith("feasible")

    # the logged MLflow model loads (from code + weights) and predicts
    import pandas as pd

    mlflow.set_tracking_uri(f"sqlite:///{tmp_path / 'mlflow.db'}")
    model = mlflow.pyfunc.load_model(f"runs:/{run['mlflow_run_id']}/agent")
    pred = model.predict(pd.DataFrame({"instance_dir": [str(inst_dir)]}))
    assert pred["n_acquisitions"][0] > 0 and np.isfinite(pred["value"][0])


def test_ppo_starts_from_an_imitation_checkpoint(tmp_path, data):
    """--train.init-checkpoint: the run takes the checkpoint's architecture and weights (first validation =
    the checkpoint's greedy decoding), and --train.time-budget ends it early."""
    import torch

    from eosp.config import EnvConfig, ModelConfig
    from eosp.envs.sources import expand_shards, prepare_instance
    from eosp.models.agent import EOSPAgent
    from eosp.models.checkpoint import save_agent
    from eosp.shards.io import read_instances
    from eosp.solvers.policy import rollout

    torch.manual_seed(7)
    env_cfg = EnvConfig(max_acquisitions=16)
    agent = EOSPAgent(ModelConfig(hidden_dim=12, n_layers=1, heads=1, value_scale=3.0))
    save_agent(agent, tmp_path / "init", env_cfg)
    expected = np.mean([rollout(agent, prepare_instance(i), env_cfg)[1]
                        for i in read_instances(expand_shards([str(data / "val")]))])
    r = train(tmp_path, data, "--train.iterations", 50, "--train.init-checkpoint", tmp_path / "init",
              "--train.time-budget", 1, "--train.num-epochs", 1, "--train.lr", 1e-9)
    assert "starting from" in r.stdout and "time budget of 1 s reached" in r.stdout
    run = json.loads((tmp_path / "runs" / "t" / "run.json").read_text())
    assert run["config"]["model"]["hidden_dim"] == 12 and run["config"]["model"]["value_scale"] == 3.0
    assert run["iteration"] < 50
    assert f"done: t, {run['iteration']} iterations this session" in r.stdout
    first = run["history"][0]
    assert first["val/policy_mean"] == pytest.approx(expected, rel=1e-6)


def test_the_best_checkpoint_is_picked_by_the_mean_per_instance_ratio():
    """In utility mode values span eight orders of magnitude: the mean value only sees the instances with
    top-class acquisitions.  The selection score is the mean of the per-instance ratios."""
    import numpy as np

    from eosp.training.validation import compare, selection_score

    exact = np.array([3e8, 5e4])
    a = compare(np.array([3e8, 4.6e4]), {"exact": exact, "greedy": np.array([3e8, 4e4])})  # loses 8% on the second
    b = compare(np.array([3e8 - 1e4, 5e4]), {"exact": exact, "greedy": np.array([3e8, 4e4])})  # 3e-5 on the first
    assert a["val/policy_mean"] > b["val/policy_mean"]
    assert a["val/mean_ratio_to_exact"] == 0.5 * (1 + 0.92) and selection_score(b) > selection_score(a)
    assert selection_score(a) == a["val/mean_ratio_to_exact"]
    no_exact = compare(np.array([3e8, 4.6e4]), {"greedy": np.array([3e8, 4e4])})
    assert selection_score(no_exact) == no_exact["val/mean_ratio_to_greedy"] == 0.5 * (1 + 4.6 / 4)
    assert selection_score(compare(np.array([1.0, 2.0]), {})) == 1.5
