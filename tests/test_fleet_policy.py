"""The learned fleet scheduler's parts: the team view's snapshots replay exactly, decoded schedules (network, hand
rule, sampling) are valid with WCR = return, demonstrations replay into labelled decisions, imitation learns them,
and fleet checkpoints round-trip and refuse another layout or objective in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from eosp.config import EnvConfig, FleetEnvConfig, FleetImitationConfig, ModelConfig
from eosp.envs.constellation_data import prepare_fleet
from eosp.envs.constellation_obs import N_FLEET_FEATURES
from eosp.envs.constellation_team import TeamEnv
from eosp.errors import InputError
from eosp.fleet.check import validate
from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.geometry import Geometry
from eosp.fleet.opportunities import compute

SMALL = ModelConfig(hidden_dim=16, n_layers=2, heads=2, value_scale=0.5)


def small_fleet(seed: int, satellites: int = 6, tasks: int = 800):
    """A generated fleet of 4 h whose passes hold up to ~20 tasks (cities): a few hundred decisions."""
    f = generate(FleetGenConfig(satellites=satellites, tasks=tasks, hours=4.0, window_min_h=1.0, window_max_h=4.0,
                                placement="cities", seed=seed))
    geo = Geometry(f)
    return prepare_fleet(f, compute(f, geo), geo=geo, name=f"fleet-{seed}")


@pytest.fixture(scope="module")
def fleet():
    return small_fleet(3)


def agent(seed: int = 0):
    from eosp.models.agent import EOSPAgent

    torch.manual_seed(seed)
    return EOSPAgent(SMALL, N_FLEET_FEATURES).eval()


def test_a_restored_snapshot_replays_the_same_decisions_and_returns(fleet):
    env = TeamEnv(FleetEnvConfig(), fleet)
    rng = np.random.default_rng(0)
    obs, _ = env.reset()
    trace, snaps = [], []
    while obs["action_mask"].any():
        snaps.append((env.snapshot(), obs))
        a = int(rng.choice(np.flatnonzero(obs["action_mask"])))
        obs, r, done, _, _ = env.step(a)
        trace.append((a, r, obs["x"].copy(), obs["action_mask"].copy()))
        if done:
            break
    full = env.value
    assert len(trace) > 20
    for k in (0, len(trace) // 3, len(trace) - 1):  # from any state, the same actions give the same episode
        snap, first = snaps[k]
        env.restore(snap)
        total = sum(r for _, r, _, _ in trace[:k])
        for a, r, x, mask in trace[k:]:
            obs, r2, _, _, _ = env.step(a)
            assert r2 == pytest.approx(r, abs=1e-15)
            assert np.array_equal(obs["x"], x) and np.array_equal(obs["action_mask"], mask)
            total += r2
        assert env.value == pytest.approx(full, abs=1e-12) and total == pytest.approx(full, abs=1e-12)
    res = validate(fleet.fleet, env.schedule(), fleet.geo)
    assert res.valid and res.metrics["WCR"] == pytest.approx(full, abs=1e-9)


@pytest.mark.parametrize("how", ["network", "rule", "sample"])
def test_decoded_schedules_are_valid_and_their_return_is_the_checker_wcr(fleet, how):
    from eosp.solvers.fleet_policy import DEFAULT_RULE, FEATURE_RULES, decode, rule_scorer, sample_best

    cfg = FleetEnvConfig()
    if how == "sample":
        greedy = decode(agent(), fleet, cfg)
        out = sample_best(agent(), fleet, cfg, samples=4, temperature=1.0, seed=1, time_limit=None)
        assert out.info["episodes"] == 4 and out.value >= greedy.value - 1e-12  # the greedy episode is one of them
    else:
        out = decode(agent() if how == "network" else rule_scorer(FEATURE_RULES[DEFAULT_RULE]), fleet, cfg)
    res = validate(fleet.fleet, out.schedule, fleet.geo)
    assert res.valid, res.first
    assert res.metrics["WCR"] == pytest.approx(out.value, abs=1e-9)
    assert len(out.schedule) > 0


def test_a_rule_naming_an_unknown_feature_is_refused():
    from eosp.solvers.fleet_policy import rule_scorer

    with pytest.raises(ValueError, match="unknown node feature.*nope"):
        rule_scorer({"nope": 1.0})


def test_a_solver_schedule_replays_into_admissible_labels_with_the_fleet_return_to_go(fleet):
    from eosp.envs.constellation import ConstellationEnv
    from eosp.fleet.greedy import solve as fleet_greedy
    from eosp.training.fleet_demos import samples_along

    sched = fleet_greedy(fleet.fleet, fleet.opps, fleet.geo)
    wcr = validate(fleet.fleet, sched, fleet.geo).metrics["WCR"]
    env = ConstellationEnv(FleetEnvConfig(), source=fleet)
    samples, info = samples_along(env, fleet, sched)
    assert info["dropped"] == 0 and info["return"] == pytest.approx(wcr, abs=1e-9)
    assert info["decisions"] == len(samples) > 0
    values = np.array([s.value[0] for s in samples])
    assert values[0] == pytest.approx(wcr, abs=1e-6)  # float32 targets
    assert np.all(np.diff(values) <= 1e-6) and values[-1] >= -1e-7
    for s in samples:
        assert s.mask[s.optimal[0]] == 1 and s.x.shape == (len(s.mask), N_FLEET_FEATURES)
    later = samples_along(env, fleet, sched, after_s=fleet.fleet.horizon.seconds / 2)[0]
    assert 0 < len(later) < len(samples)


def write_demo_set(root: Path, fleets: list) -> Path:
    """A demo set as jobs/build_fleet_demos.py writes it, of the fleet greedy's schedules (fast)."""
    from eosp.fleet.greedy import solve as fleet_greedy
    from eosp.fleet.io import fingerprint, write_fleet, write_schedule

    root.mkdir(parents=True, exist_ok=True)
    demos = []
    for pf in fleets:
        d = write_fleet(pf.fleet, pf.opps, root / "fleets" / pf.name)
        sched = fleet_greedy(pf.fleet, pf.opps, pf.geo)
        key = fingerprint(pf.fleet)[:16]
        write_schedule(sched, pf.fleet, root / f"{key}.parquet")
        demos.append({"fleet": str(d), "schedule": f"{key}.parquet",
                      "wcr": validate(pf.fleet, sched, pf.geo).metrics["WCR"]})
    (root / "manifest.json").write_text(json.dumps({"demos": demos}))
    return root


def test_imitation_learns_the_demonstrations_of_a_tiny_set(fleet, tmp_path):
    from eosp.solvers.fleet_policy import decode
    from eosp.training.fleet_demos import FleetDemoData
    from eosp.training.imitation import train_epoch

    demos = write_demo_set(tmp_path / "demos", [fleet])
    data = FleetDemoData([str(demos)], FleetEnvConfig())
    assert len(data.samples) > 20 and data.replays[0]["dropped"] == 0
    torch.set_num_threads(1)
    torch.manual_seed(0)
    net = agent()
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    im = FleetImitationConfig(batch_size=16)
    rng = np.random.default_rng(0)
    first = train_epoch(net, opt, data.samples, im, rng)
    for _ in range(25):
        last = train_epoch(net, opt, data.samples, im, rng)
    assert last["train/policy_loss"] < 0.5 * first["train/policy_loss"]
    assert last["train/accuracy"] > 0.9
    cloned = decode(net, data.fleets[0], FleetEnvConfig()).value
    assert cloned >= 0.9 * data.start_values[0]  # the replayed demonstration's WCR


def test_fleet_checkpoints_round_trip_and_refuse_another_layout_or_objective(tmp_path, fleet):
    from eosp.models.checkpoint import load_agent, load_fleet_agent, save_agent
    from eosp.solvers.fleet_policy import decode

    net = agent(1)
    d = save_agent(net, tmp_path / "ck", FleetEnvConfig(), {"source": "test"})
    meta = json.loads((d / "agent.json").read_text())
    assert meta["env_kind"] == "fleet" and len(meta["features"]) == N_FLEET_FEATURES
    back, env_cfg, _ = load_fleet_agent(d)
    assert env_cfg == FleetEnvConfig()
    assert decode(back, fleet, env_cfg).value == decode(net, fleet, env_cfg).value
    with pytest.raises(InputError, match="a fleet policy .*not a single-pass agent"):
        load_agent(d)
    with pytest.raises(InputError, match="trained for reward 'wcr', not 'cr'"):
        load_fleet_agent(d, reward="cr")
    meta["features"][12] = "something_else"
    (d / "agent.json").write_text(json.dumps(meta))
    with pytest.raises(InputError, match="another observation layout.*column 12 is 'something_else' there, 'served'"):
        load_fleet_agent(d)
    meta["features"] = meta["features"][:10]
    (d / "agent.json").write_text(json.dumps(meta))
    with pytest.raises(InputError, match="another observation layout.*10 node features there, 25 here"):
        load_fleet_agent(d)
    from eosp.models.agent import EOSPAgent

    single = save_agent(EOSPAgent(SMALL), tmp_path / "single", EnvConfig())
    with pytest.raises(InputError, match="a single-pass agent .*not a fleet policy"):
        load_fleet_agent(single)
    (d / "agent.pt").write_bytes(b"PK\x03\x04 truncated")
    meta["features"] = list(json.loads(json.dumps(meta))["features"])
    with pytest.raises(InputError):
        load_fleet_agent(d)


def test_the_validator_compares_greedy_decoding_with_the_fleet_solver_greedy_and_features(fleet, tmp_path):
    from eosp.training.validation import SELECTION_KEY, FleetValidator

    demos = write_demo_set(tmp_path / "val", [fleet, small_fleet(5, satellites=3)])
    v = FleetValidator(str(demos), FleetEnvConfig())
    res = v.run(agent())
    m = res.metrics
    assert set(v.baselines) == {"fleet", "greedy", "features"}
    assert m[SELECTION_KEY] == m["val/mean_ratio_to_fleet"]  # the fleet solver's schedules select the best
    assert 0 < m["val/policy_mean"] <= 1 and len(res.policy) == 2
    assert np.allclose(v.baselines["fleet"], v.baselines["greedy"])  # these demos are the fleet greedy's


def test_pretrain_fleet_refuses_options_the_fleet_demonstrations_cannot_serve(capsys):
    from eosp.jobs.pretrain_fleet import main

    assert main(["--imitation.regret-coeff", "0.5"]) == 2
    assert "--imitation.regret-coeff: the fleet demonstrations carry no action values" in capsys.readouterr().err


def test_build_fleet_demos_refuses_a_directory_it_did_not_write_and_missing_options(tmp_path, capsys):
    from eosp.jobs.build_fleet_demos import main

    assert main(["--fleets", str(tmp_path)]) == 2
    assert "--out: required" in capsys.readouterr().err
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    assert main(["--fleets", str(tmp_path), "--out", str(foreign)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "exists and is not" in err and "refusing" in err


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory, fleet):
    from eosp.fleet.io import write_fleet

    return write_fleet(fleet.fleet, fleet.opps, tmp_path_factory.mktemp("fleetdir") / "fleet")


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    from eosp.models.checkpoint import save_agent

    return save_agent(agent(2), tmp_path_factory.mktemp("ck") / "policy", FleetEnvConfig())


def test_eosp_solve_fleet_policy_sample_and_features_write_checked_schedules(fleet_dir, checkpoint, tmp_path,
                                                                             capsys):
    from eosp.cli import main
    from eosp.fleet.io import read_fleet, read_schedule

    fleet, _ = read_fleet(fleet_dir, with_opportunities=False)
    runs = {"fleet-policy": ["--checkpoint", str(checkpoint)],
            "fleet-sample": ["--checkpoint", str(checkpoint), "--time-limit", "8", "--samples", "4"],
            "fleet-features": ["--polish", "none"]}
    for solver, flags in runs.items():
        out = tmp_path / f"{solver}.parquet"
        assert main(["solve", str(fleet_dir), "--solver", solver, "--out", str(out), *flags]) == 0
        line = capsys.readouterr().out
        assert "raw decode" in line and ("polish none" in line) == (solver == "fleet-features")
        sched, info = read_schedule(out, fleet)
        res = validate(fleet, sched)
        assert res.valid and res.metrics["WCR"] == pytest.approx(float(info["value"]), abs=1e-12)
        assert float(info["value"]) >= float(info["raw_wcr"]) - 1e-12  # fill is kept only when it serves more
        assert main(["validate", str(fleet_dir), str(out)]) == 0
        capsys.readouterr()


def test_a_single_pass_or_corrupt_checkpoint_is_one_line_before_the_fleet_is_read(fleet_dir, tmp_path, capsys):
    from eosp.cli import main
    from eosp.models.agent import EOSPAgent
    from eosp.models.checkpoint import save_agent

    single = save_agent(EOSPAgent(SMALL), tmp_path / "single", EnvConfig())
    out = tmp_path / "x.parquet"
    assert main(["solve", str(fleet_dir), "--solver", "fleet-policy", "--checkpoint", str(single),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a single-pass agent" in err and "not a fleet policy" in err
    (single / "agent.json").write_text("{not json")
    assert main(["solve", str(fleet_dir), "--solver", "fleet-sample", "--checkpoint", str(single),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not valid JSON" in err
    assert main(["solve", str(fleet_dir), "--solver", "fleet-policy", "--time-limit", "5", "--out", str(out)]) == 2
    assert "takes no time_limit" in capsys.readouterr().err
    assert not out.exists()


def test_fill_never_drops_a_served_task_it_cannot_keep_for_nothing(fleet):
    """fill: every task the decode served stays served unless the battery repair drops it, and what it adds is
    the fleet greedy's insertion: on a fleet whose batteries do not bind, the filled schedule serves a superset."""
    from eosp.fleet.greedy import fill
    from eosp.solvers.fleet_policy import DEFAULT_RULE, FEATURE_RULES, decode, rule_scorer

    out = decode(rule_scorer({**FEATURE_RULES[DEFAULT_RULE], "skip": 100.0}), fleet, FleetEnvConfig())  # skips early
    filled = fill(fleet.fleet, fleet.opps, out.schedule, fleet.geo)
    res = validate(fleet.fleet, filled, fleet.geo)
    assert res.valid and res.metrics["WCR"] > out.value
    assert set(out.schedule.task.tolist()) <= set(filled.task.tolist())


class _Trap:
    """Unpickling this object would create the file it names: the sign that a checkpoint was unpickled."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_a_fleet_checkpoint_of_another_layout_objective_or_pickled_weights_is_one_line_exit_2(
        fleet_dir, checkpoint, tmp_path, capsys):
    """Through `eosp solve`: what differs is named in one line, exit 2, no schedule written, and a weights file
    holding Python objects is refused without being unpickled."""
    import pickle
    import shutil

    import torch

    from eosp.cli import main

    out = tmp_path / "x.parquet"
    d = tmp_path / "ck"
    shutil.copytree(checkpoint, d)
    meta = json.loads((d / "agent.json").read_text())
    for change, why in ((lambda m: m["features"].__setitem__(3, "other"),
                         "(column 3 is 'other' there, 'last' here)"),
                        (lambda m: m["env"].__setitem__("reward", "cr"), "trained for reward 'cr', not 'wcr'")):
        bad = json.loads(json.dumps(meta))
        change(bad)
        (d / "agent.json").write_text(json.dumps(bad))
        assert main(["solve", str(fleet_dir), "--solver", "fleet-policy", "--checkpoint", str(d),
                     "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and why in err and "agent.json" in err
    (d / "agent.json").write_text(json.dumps(meta))
    trap = tmp_path / "unpickled"
    torch.save({"w": _Trap(trap)}, d / "agent.pt")  # a zip archive like real weights, with a pickled object
    assert main(["solve", str(fleet_dir), "--solver", "fleet-sample", "--checkpoint", str(d), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "agent.pt" in err and "never unpickled" in err
    (d / "agent.pt").write_bytes(pickle.dumps(_Trap(trap)))  # a bare pickle
    assert main(["solve", str(fleet_dir), "--solver", "fleet-policy", "--checkpoint", str(d), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a torch weights file" in err
    assert not trap.exists() and not out.exists()
