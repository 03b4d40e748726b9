"""One subprocess smoke run per jobs/ entry point, on tiny settings with a local Ray."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_job(script, *args, timeout=600):
    r = subprocess.run([sys.executable, str(ROOT / "jobs" / script), *map(str, args)], capture_output=True,
                       text=True, timeout=timeout, cwd=ROOT)
    assert r.returncode == 0, f"{script} failed\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    return r


def test_build_shards(tmp_path):
    out = tmp_path / "ds"
    r = run_job("build_shards.py", "--out", out, "--n-acquisitions", 10, "--n-instances", 3, "--per-shard", 2,
                "--seed", 5, "--ray.num-cpus", 2, "--instance.graph.step-s", 4,
                "--instance.satellite.slew-model", "bang_coast_bang")
    assert "shard 2/2" in r.stdout
    manifest = json.loads((out / "manifest.json").read_text())
    assert [s["file"] for s in manifest["shards"]] == ["shard-00000.parquet", "shard-00001.parquet"]
    from eosp.shards.io import read_instances

    insts = read_instances(sorted(out.glob("*.parquet")))
    assert [i.meta["seed"] for i in insts] == [5, 6, 7]
    assert insts[0].meta["config"]["graph"]["step_s"] == 4.0
    assert insts[0].meta["config"]["satellite"]["slew_model"] == "bang_coast_bang"


def test_evaluate(tmp_path):
    import pandas as pd

    from eosp.shards.io import write_shard
    from tests.conftest import generated

    write_shard(tmp_path / "data" / "shard-0.parquet", [generated("uniform", 12, s) for s in range(3)])
    r = run_job("evaluate.py", "--data", tmp_path / "data", "--solvers", "greedy", "ramp", "exact",
                "--time-limit", 30, "--out", tmp_path / "out", "--mlflow-uri", f"sqlite:///{tmp_path / 'm.db'}",
                "--ray.num-cpus", 2, "--html-reports", 2)
    res = pd.read_parquet(tmp_path / "out" / "results.parquet")
    assert len(res) == 9 and res.feasible.all()
    wide = res.pivot(index="instance", columns="solver", values="value")
    assert (wide["greedy"] <= wide["exact"] * (1 + 1e-12)).all() and (wide["ramp"] <= wide["exact"] * (1 + 1e-12)).all()
    report = (tmp_path / "out" / "report.md").read_text()
    assert "/ Greedy" in report and "| 12 | 3 |" in report
    assert (tmp_path / "out" / "schedules").is_dir()
    assert "Wall time" in r.stdout
    # per-class counts, HTML reports of the first two instances, all logged to MLflow
    assert (res[[f"class_{c}" for c in range(7)]].sum(axis=1) == res.acquisitions).all()
    pages = sorted((tmp_path / "out" / "reports").glob("*.html"))
    assert len(pages) == 2 and "reports/" in report
    text = pages[0].read_text()
    assert text.count("<tr data-schedule=") == 3 and "id='map-section'" in text
    assert (tmp_path / "out" / "class_counts.png").stat().st_size > 5000
    import mlflow

    client = mlflow.MlflowClient(f"sqlite:///{tmp_path / 'm.db'}")
    run = client.search_runs([client.get_experiment_by_name("eosp-eval").experiment_id])[0]
    names = {a.path for a in client.list_artifacts(run.info.run_id)}
    assert {"class_counts.png", "report.md", "results.parquet", "reports"} <= names
    assert len(client.list_artifacts(run.info.run_id, "reports")) == 2


def test_demo_data_built_by_an_older_eosp_is_built_again(tmp_path, monkeypatch, capsys):
    """make demo after an upgrade: the demo's own data sets, in a shard format this eosp refuses, are rebuilt
    (instead of the training failing on them); current ones are kept as they are."""
    from eosp.jobs import train

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(train, "DEMO_DATA", {"data/demo/train": (2, 1000)})
    monkeypatch.setattr(train, "DEMO_ACQ", 10)
    cfg, _ = train.parse(["--demo", "--ray.num-cpus", "1"])
    try:
        rebuild_and_keep(train, cfg, tmp_path, capsys)
    finally:
        import ray

        if ray.is_initialized():  # the shard build starts Ray in this process; the next Ray test starts its own
            ray.shutdown()


def rebuild_and_keep(train, cfg, tmp_path, capsys):
    import pyarrow.parquet as pq

    from eosp.shards.io import ShardReader

    train.ensure_demo_data(cfg)
    shard = tmp_path / "data/demo/train/shard-00000.parquet"
    t = pq.read_table(shard)
    pq.write_table(t.replace_schema_metadata({**t.schema.metadata, b"eosp.schema_version": b"1"}), shard)
    before = shard.stat().st_mtime_ns
    train.ensure_demo_data(cfg)
    assert "cannot be read" in capsys.readouterr().out
    assert len(ShardReader(shard)) == 2 and shard.stat().st_mtime_ns != before
    train.ensure_demo_data(cfg)  # current: kept
    assert "building" not in capsys.readouterr().out
