"""The fleet policy's jobs on Ray, end to end on tiny fleets: the fleet solver's demonstrations (one Ray task a
fleet, resumable), imitation with a DAgger round (the fleet solver completing days the policy began, as Ray
tasks), PPO fine-tuning on multi-agent env runners from that checkpoint, and a Tune sweep (MLflow parent and
children)."""

from __future__ import annotations

import json

import pytest

from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.io import write_fleet
from eosp.fleet.opportunities import compute

pytestmark = pytest.mark.ray


@pytest.fixture(scope="module")
def fleets(tmp_path_factory):
    root = tmp_path_factory.mktemp("fleets")
    for seed in (1, 2):
        f = generate(FleetGenConfig(satellites=3, tasks=300, hours=3.0, window_min_h=1.0, window_max_h=3.0,
                                    placement="cities", seed=seed))
        write_fleet(f, compute(f), root / "train" / f"fleet-{seed:05d}")
    f = generate(FleetGenConfig(satellites=3, tasks=300, hours=3.0, window_min_h=1.0, window_max_h=3.0,
                                placement="cities", seed=9))
    write_fleet(f, compute(f), root / "val" / "fleet-00009")
    return root


def test_demonstrations_imitation_with_dagger_ppo_and_a_sweep(fleets, tmp_path, capsys):
    import ray

    from eosp.jobs.build_fleet_demos import main as demos
    from eosp.jobs.pretrain_fleet import main as pretrain
    from eosp.jobs.train_fleet import main as train
    from eosp.jobs.tune_fleet import main as tune
    from eosp.models.checkpoint import load_fleet_agent

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    ray.init(address="local", num_cpus=2, include_dashboard=False)
    try:
        assert demos(["--fleets", str(fleets / "train"), "--out", str(tmp_path / "demos"), "--time-limit", "3"]) == 0
        assert demos(["--fleets", str(fleets / "val"), "--out", str(tmp_path / "val"), "--time-limit", "3"]) == 0
        manifest = json.loads((tmp_path / "demos" / "manifest.json").read_text())
        assert len(manifest["demos"]) == 2 and all(0 < d["wcr"] <= d["bound"] + 1e-9 for d in manifest["demos"])
        capsys.readouterr()
        assert demos(["--fleets", str(fleets / "train"), "--out", str(tmp_path / "demos"), "--time-limit", "3"]) == 0
        assert "resuming: 2 of 2 fleets already solved" in capsys.readouterr().out
        assert demos(["--fleets", str(fleets / "train"), "--out", str(tmp_path / "demos"), "--time-limit", "4"]) == 2
        assert "demonstrations of other settings" in capsys.readouterr().err

        common = ["--imitation.train-data", str(tmp_path / "demos"), "--imitation.val-data", str(tmp_path / "val"),
                  "--imitation.run-dir", str(tmp_path / "runs"), "--imitation.mlflow-uri", uri,
                  "--model.hidden-dim", "8", "--model.n-layers", "1"]
        assert pretrain([*common, "--imitation.run-name", "bc", "--imitation.epochs", "2",
                         "--imitation.dagger-every", "1", "--imitation.dagger-instances", "1",
                         "--imitation.dagger-time-limit", "3"]) == 0
        out = capsys.readouterr().out
        assert "dagger +" in out
        history = json.loads((tmp_path / "runs" / "bc" / "history.json").read_text())["history"]
        assert history[0]["dagger/states_added"] > 0
        assert history[1]["val/policy_mean"] > 0
        agent, env_cfg, meta = load_fleet_agent(tmp_path / "runs" / "bc" / "checkpoints" / "best")
        assert meta["env_kind"] == "fleet" and agent.cfg.hidden_dim == 8

        assert train(["--train.init-checkpoint", str(tmp_path / "runs" / "bc" / "checkpoints" / "best"),
                      "--train.train-data", str(tmp_path / "demos"), "--train.val-data", str(tmp_path / "val"),
                      "--train.run-dir", str(tmp_path / "runs"), "--train.run-name", "ppo", "--train.mlflow-uri", uri,
                      "--train.iterations", "1", "--train.num-env-runners", "0", "--train.train-batch-size", "64",
                      "--train.minibatch-size", "32", "--train.num-envs-per-env-runner", "1",
                      "--env.team-reward", "1"]) == 0
        run = json.loads((tmp_path / "runs" / "ppo" / "run.json").read_text())
        assert [h["iteration"] for h in run["history"]] == [0, 1]  # the starting point validated, then PPO
        assert "val/policy_mean" in run["history"][1]
        load_fleet_agent(tmp_path / "runs" / "ppo" / "checkpoints" / "last")
    finally:
        ray.shutdown()

    assert tune(["--tune.name", "arch", "--tune.hidden-dims", "8", "--tune.n-layers", "1", "2",
                 "--tune.grace-period", "1", *common, "--imitation.epochs", "1", "--ray.num-cpus", "2"]) == 0
    out = capsys.readouterr().out
    assert "2 trials; best val_selection_score" in out
    sweep = tmp_path / "runs" / "tune" / "arch"
    assert len(json.loads((sweep / "trials.json").read_text())) == 2
    load_fleet_agent(sweep / "best")
    import mlflow

    client = mlflow.tracking.MlflowClient(uri)
    exp = client.get_experiment_by_name("eosp-fleet-imitation")
    runs = client.search_runs([exp.experiment_id])
    parent = [r for r in runs if r.data.tags.get("eosp.kind") == "tune-sweep"]
    assert len(parent) == 1
    assert len([r for r in runs if r.data.tags.get("mlflow.parentRunId") == parent[0].info.run_id]) == 2
