"""What a training run logs to MLflow besides its metrics (issue 41): the primary validation metric under its
own name, the per-instance validation table, the learning curve against env steps and wall time, and a logged
model that carries its iteration and validation figures.  Small pieces, without Ray or PPO."""

import csv
import json

import numpy as np
import pytest

from eosp.training.validation import (SELECTION_KEY, ValidationResult, compare, describe_metric, instance_rows,
                                      primary_metric, selection_score, write_instance_table)


def result() -> ValidationResult:
    policy = np.array([10.0, 2.0, 5.0])
    base = {"greedy": np.array([10.0, 4.0, 0.0]), "ramp": np.array([20.0, 2.0, 5.0])}
    metrics = compare(policy, base)
    metrics[SELECTION_KEY] = selection_score(metrics)
    return ValidationResult(metrics, ["a", "b", "c"], policy, base)


def test_primary_metric_is_the_mean_of_per_instance_ratios():
    m = result().metrics
    assert primary_metric(m) == "val/mean_ratio_to_ramp" and m[SELECTION_KEY] == m["val/mean_ratio_to_ramp"]
    assert m["val/mean_ratio_to_ramp"] == pytest.approx((0.5 + 1 + 1) / 3)
    assert m["val/ratio_to_ramp"] == pytest.approx(17 / 27)  # the ratio of means differs: not the one used
    assert describe_metric("val/mean_ratio_to_ramp") == "mean of per-instance ratios, policy / RAMP"
    assert describe_metric("val/ratio_to_greedy") == "ratio of means, policy / Greedy"


def test_instance_table(tmp_path):
    r = result()
    rows = instance_rows(r)
    assert rows[1] == {"instance": "b", "policy": 2.0, "greedy": 4.0, "policy/greedy": 0.5, "ramp": 2.0,
                       "policy/ramp": 1.0}
    assert np.isnan(rows[2]["policy/greedy"])  # a zero baseline has no ratio
    path = write_instance_table(r, tmp_path / "v" / "t.csv")
    got = list(csv.DictReader(path.open()))
    assert [g["instance"] for g in got] == ["a", "b", "c"] and float(got[0]["policy/ramp"]) == 0.5
    # the table's mean of ratios is the primary metric
    assert np.mean([float(g["policy/ramp"]) for g in got]) == pytest.approx(r.metrics[SELECTION_KEY])


def history() -> list[dict]:
    out = []
    for it in range(1, 7):
        h = {"iteration": it, "train/episode_return_mean": it * 0.1, "perf/env_steps_lifetime": 400 * it,
             "perf/wall_s": 30.0 * it}
        if it % 3 == 0:
            h.update({"val/policy_mean": 1.0, "val/mean_ratio_to_ramp": 0.9 + 0.01 * it, "val/ratio_to_ramp": 0.8,
                      "val/mean_ratio_to_greedy": 1.0, "val/ratio_to_greedy": 1.1})
            h[SELECTION_KEY] = h["val/mean_ratio_to_ramp"]
        out.append(h)
    return out


def test_learning_curve_names_the_primary_metric(tmp_path):
    from eosp.training.plots import learning_curve

    png = learning_curve(history(), tmp_path / "learning_curve")
    svg = png.with_suffix(".svg").read_text()
    assert png.stat().st_size > 10000
    for text in ("mean of per-instance ratios, policy / RAMP (selects best)", "ratio of means, policy / RAMP",
                 "best checkpoint (iteration 6)", "env steps", "wall time (s)"):
        assert text in svg, text
    assert "validation mean ratio" not in svg


def test_logged_model_carries_its_validation(tmp_path, monkeypatch):
    import mlflow

    from eosp.config import EnvConfig, ModelConfig
    from eosp.jobs.train import log_agent_model, log_validation, model_metadata
    from eosp.models.agent import EOSPAgent
    from eosp.models.checkpoint import save_agent

    r = result()
    ckpt = save_agent(EOSPAgent(ModelConfig(hidden_dim=8, n_layers=1, heads=1)), tmp_path / "best", EnvConfig(),
                      {"iteration": 6, "val": {**r.metrics, "perf/wall_s": 3.0}})
    meta = model_metadata(ckpt)
    assert meta["iteration"] == 6 and meta["primary_metric"] == "val/mean_ratio_to_ramp"
    assert meta[SELECTION_KEY] == r.metrics[SELECTION_KEY] and "perf/wall_s" not in meta["validation"]
    mlflow.set_tracking_uri(f"sqlite:///{tmp_path / 'mlflow.db'}")
    mlflow.set_experiment("t")
    with mlflow.start_run() as run:
        log_validation(r, {**r.metrics, "perf/env_steps_lifetime": 1200}, tmp_path / "run", 6, best=True)
        log_agent_model(ckpt)
    client = mlflow.tracking.MlflowClient()
    data = client.get_run(run.info.run_id).data
    assert data.tags["primary_metric"] == f"{SELECTION_KEY} = val/mean_ratio_to_ramp"
    assert [m.step for m in client.get_metric_history(run.info.run_id, f"by_env_steps/{SELECTION_KEY}")] == [1200]
    arts = [a.path for a in client.list_artifacts(run.info.run_id, "validation")]
    assert "validation/best_instances.csv" in arts and "validation/instances_iter00006.csv" in arts
    model = mlflow.models.get_model_info(f"runs:/{run.info.run_id}/agent")
    assert model.metadata["iteration"] == 6 and model.metadata[SELECTION_KEY] == r.metrics[SELECTION_KEY]
    assert json.loads(json.dumps(model.metadata["validation"])) == meta["validation"]
    logged = mlflow.get_logged_model(model.model_id)  # the figures are the model's own metrics too
    assert {m.key: m.value for m in logged.metrics}[SELECTION_KEY] == pytest.approx(r.metrics[SELECTION_KEY])


def test_validation_reports(tmp_path):
    """The few validation reports: the policy's schedule (the reference) next to Greedy's, one page each."""
    from eosp.config import EnvConfig, ModelConfig
    from eosp.envs.sources import prepare_instance
    from eosp.models.agent import EOSPAgent
    from eosp.jobs.train import write_validation_reports
    from eosp.training.validation import Validator
    from tests.conftest import generated

    v = Validator.__new__(Validator)  # without shards, baselines or Ray: only what the reports read
    v.env_cfg, v.mode = EnvConfig(), "utility"
    v.prepared = [prepare_instance(generated("uniform", 12, s), True) for s in (100, 101, 102)]
    pages = write_validation_reports(v, EOSPAgent(ModelConfig(hidden_dim=8, n_layers=1, heads=1)).eval(),
                                     tmp_path / "reports", 2)
    assert [p.name for p in pages] == [f"{p.inst.name}.html" for p in v.prepared[:2]]
    text = pages[0].read_text()
    assert "policy <small>(reference)</small>" in text and "<tr data-schedule='greedy'" in text
    assert "id='missed-section'" in text


@pytest.mark.parametrize("stored", [True, False])
def test_validation_reports_of_a_data_set_read_with_its_pruned_arcs(tmp_path, stored):
    """Validation reads its shards without the unpruned arcs; the reports read them back when the shard has
    them (the demo's case: a page each, no warning) and skip the instances whose shard does not."""
    from eosp.config import EnvConfig, ModelConfig
    from eosp.envs.sources import prepare_instance
    from eosp.models.agent import EOSPAgent
    from eosp.jobs.train import write_validation_reports
    from eosp.shards.io import read_instances, write_shard
    from eosp.training.validation import Validator
    from tests.conftest import generated

    shard = write_shard(tmp_path / "val.parquet", [generated("uniform", 12, s) for s in (100, 101)],
                        include_unpruned=stored)
    v = Validator.__new__(Validator)
    v.env_cfg, v.mode = EnvConfig(), "utility"
    v.prepared = [prepare_instance(i, True) for i in read_instances([str(shard)], unpruned=False)]
    assert all(p.inst.unpruned_graph is None for p in v.prepared)
    pages = write_validation_reports(v, EOSPAgent(ModelConfig(hidden_dim=8, n_layers=1, heads=1)).eval(),
                                     tmp_path / "reports", 2)
    assert len(pages) == (2 if stored else 0)
    if stored:
        assert "<tr data-schedule='greedy'" in pages[0].read_text()
