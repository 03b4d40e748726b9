"""A 2-trial, 1-iteration sweep in local mode, then the MLflow parent run, its children and their metrics."""

import json
import subprocess
import sys
from pathlib import Path

from eosp.shards.io import write_shard
from tests.conftest import generated

ROOT = Path(__file__).resolve().parents[1]


def test_two_trial_sweep_in_mlflow(tmp_path):
    import mlflow

    write_shard(tmp_path / "train" / "s.parquet", [generated("uniform", 12, s) for s in range(2)])
    write_shard(tmp_path / "val" / "s.parquet", [generated("uniform", 12, 50)])
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    args = [sys.executable, str(ROOT / "jobs" / "tune.py"), "--tune.name", "t2", "--tune.hidden-dims", "8", "16",
            "--tune.n-layers", "1", "--tune.grace-period", "1", "--train.iterations", "1",
            "--train.train-data", tmp_path / "train", "--train.val-data", tmp_path / "val",
            "--train.run-dir", tmp_path / "runs", "--train.mlflow-uri", uri, "--train.experiment", "sweep-test",
            "--env.max-acquisitions", "16", "--train.train-batch-size", "64", "--train.minibatch-size", "32",
            "--train.num-epochs", "1", "--model.heads", "1", "--ray.num-cpus", "2"]
    r = subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=900, cwd=tmp_path)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-5000:]
    assert "2 trials; best" in r.stdout
    client = mlflow.tracking.MlflowClient(uri)
    exp = client.get_experiment_by_name("sweep-test")
    runs = client.search_runs([exp.experiment_id])
    parents = [x for x in runs if x.data.tags.get("eosp.kind") == "tune-sweep"]
    assert len(parents) == 1 and parents[0].info.run_name == "t2"
    children = [x for x in runs if x.data.tags.get("mlflow.parentRunId") == parents[0].info.run_id]
    assert len(children) == 2
    assert {c.data.params.get("hidden_dim") for c in children} == {"8", "16"}
    for c in children:
        assert "val_policy_mean" in c.data.metrics and "train_episode_return_mean" in c.data.metrics
    sweep = tmp_path / "runs" / "tune" / "t2"
    best = json.loads((sweep / "best_config.json").read_text())
    assert best["model"]["hidden_dim"] in (8, 16)
    assert (sweep / "best" / "agent.pt").exists()


def test_a_trials_best_is_its_best_iteration_not_its_last():
    """The sweep picks trials and checkpoints by their best iteration (scope "all"): what it prints and logs as
    the best score is that iteration's value, not the trial's last one (a fleet sweep printed 0.9648, the last
    epoch, for a trial chosen for its 0.9714)."""
    from types import SimpleNamespace

    import pandas as pd

    from eosp.jobs.tune import best_of

    df = pd.DataFrame({"iteration": [1, 2, 3, 4], "val_selection_score": [0.96, 0.9714, 0.95, 0.9648]})
    result = SimpleNamespace(metrics_dataframe=df, metrics={"val_selection_score": 0.9648, "iteration": 4})
    assert best_of(result, "val_selection_score") == (0.9714, 2)
    empty = SimpleNamespace(metrics_dataframe=None, metrics={"val_selection_score": 0.5, "iteration": 1})
    assert best_of(empty, "val_selection_score") == (0.5, 1)
