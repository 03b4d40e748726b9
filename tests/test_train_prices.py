"""jobs/train_prices.py end to end on Ray: the training data in Parquet (resumable), the MLflow run, a model that
the fleet solver's learned start reads, an --out that holds a model refused."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.io import write_fleet
from eosp.fleet.opportunities import compute

ROOT = Path(__file__).resolve().parents[1]


def job(*args, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "jobs/train_prices.py"), *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


@pytest.mark.ray
def test_data_training_mlflow_resume_and_refusal(tmp_path):
    import mlflow
    import pyarrow.parquet as pq

    from eosp.models.prices import load_price_model

    fleets = []
    for seed in (1, 2):
        f = generate(FleetGenConfig(satellites=4, tasks=300, hours=3.0, window_min_h=1.0, window_max_h=3.0,
                                    placement="cities", seed=seed))
        write_fleet(f, compute(f), tmp_path / f"fleet-{seed}")
        fleets.append(tmp_path / f"fleet-{seed}")
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    common = ["--fleets", *fleets, "--data", tmp_path / "data", "--rounds", 2, "--epochs", 10, "--val", 1,
              "--model.hidden", 8, "--model.layers", 1, "--ray.num-cpus", 2, "--mlflow-uri", uri]
    r = job(*common, "--out", tmp_path / "model", "--dual-epochs", 1, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "held out" in r.stdout and "model ->" in r.stdout
    tables = sorted((tmp_path / "data").glob("*/tasks.parquet"))
    assert len(tables) == 2 and len(pq.read_table(tables[0])) == 300
    load_price_model(tmp_path / "model")
    client = mlflow.MlflowClient(uri)
    run = client.search_runs([client.get_experiment_by_name("eosp-prices").experiment_id])[0]
    assert len(client.get_metric_history(run.info.run_id, "train_loss")) == 1  # epochs 10: logged every 10
    assert len(client.get_metric_history(run.info.run_id, "train_L_over_W")) == 2  # before and after one step
    assert {"val_L_over_W_learned", "val_L_over_W_heuristic", "val_L_over_W_none"} <= set(run.data.metrics)

    # a rerun keeps the data; an --out that holds a model is refused in one line, nothing written
    r = job(*common, "--out", tmp_path / "model", cwd=tmp_path)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0 and "holds a price model" in r.stderr
    r = job(*common, "--out", tmp_path / "model2", "--epochs", 1, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "resuming: 2 of 2 fleets' data complete" in r.stdout


def test_the_training_data_reads_back_as_the_features_the_solver_computes(tmp_path):
    """What the network learns from is what it is given at solve time: every feature column of the data read
    back equals :func:`task_graph` of the fleet (a column of task weights once overwrote the weight feature),
    and data of another version is refused in one line."""
    import json

    import numpy as np

    sys.path.insert(0, str(ROOT / "jobs"))
    from train_prices import build_one, read_graph, read_problem

    from eosp.errors import InputError
    from eosp.kinds.fleet.warmstart import task_graph

    f = generate(FleetGenConfig(satellites=4, tasks=300, hours=3.0, window_min_h=1.0, window_max_h=3.0,
                                placement="cities", seed=3))
    write_fleet(f, compute(f), tmp_path / "fleet")
    rec = build_one(str(tmp_path / "fleet"), str(tmp_path / "data" / "a"), rounds=1)
    g, target = read_graph(tmp_path / "data" / "a")
    want = task_graph(read_problem(str(tmp_path / "fleet")))
    assert want.weight.mean() != pytest.approx(1.0)  # the weight feature differs from the raw weights here
    for name in ("x_task", "x_pass", "x_edge", "edge_task", "edge_pass", "weight", "contested"):
        np.testing.assert_array_equal(getattr(g, name), getattr(want, name), err_msg=name)
    assert ((target >= 0) & (target <= 1)).all() and rec["tasks"] == 300
    record = tmp_path / "data" / "a" / "record.json"
    record.write_text(json.dumps({k: v for k, v in json.loads(record.read_text()).items() if k != "data_version"}))
    with pytest.raises(InputError, match="build it again"):
        read_graph(tmp_path / "data" / "a")
