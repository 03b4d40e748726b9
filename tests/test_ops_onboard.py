"""Onboard decisions (eosp.ops.onboard), the environment that asks them of one agent per satellite
(eosp.envs.onboard) and the onboard policy's files (eosp.models.onboard): the environment's executed timelines are
valid, its rewards sum to the simulator's served weight for the same realization and decisions, a recording
replayed with the recorded run's chooser is that run, and a policy directory that is anything else is refused in
one line, never unpickled."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from eosp.errors import InputError
from eosp.kinds.fleet.operations import SimulateConfig, Simulation, record_plans
from eosp.ops import scenario
from eosp.ops.onboard import CANDIDATES, FEATURES, Context, Decision, ScoreRule, features
from tests.conftest import clustered_scenario

CFG = SimulateConfig(planner="ev-replan", onboard="lookahead", candidates=3, rounds=3, time_limit=60.0)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A clustered day (passes with several primaries), two realizations recorded with the rule's choice."""
    root = tmp_path_factory.mktemp("onboard")
    clustered_scenario(root, tasks=150)
    scen = scenario.read(root / "scen")
    sim = Simulation.of(scen, CFG)
    figures = [record_plans(sim, str(root / "scen"), i, root / f"r{i}.npz") for i in range(2)]
    sim.close()
    return sim, [str(root / f"r{i}.npz") for i in range(2)], figures


def _fly(env, episode: int, pick):
    """Episode `episode` of `env` with actions from `pick(obs)`; the rewards paid, summed, and the last infos."""
    from eosp.envs.onboard import NONE

    obs, _ = env.reset(episode=episode)
    total = 0.0
    while True:
        (aid,) = obs
        assert obs[aid]["x"].shape == (CANDIDATES, len(FEATURES)) and obs[aid]["mask"].any()
        a = pick(obs[aid])
        obs, rew, done, _, info = env.step({aid: NONE if a < 0 else a})
        total += sum(rew.values())
        if done["__all__"]:
            return total, info


@pytest.mark.parametrize("how", ["first", "none", "random"])
def test_every_episode_is_valid_and_its_rewards_sum_to_the_served_weight(recorded, how):
    from eosp.envs.onboard import OnboardEnv, OnboardEnvConfig
    from eosp.fleet.check import validate

    sim, recs, figures = recorded
    env = OnboardEnv(OnboardEnvConfig(recs, seed=1))
    rng = np.random.default_rng(0)
    pick = {"first": lambda o: 0, "none": lambda o: -1,
            "random": lambda o: int(rng.integers(-1, int(o["mask"].sum())))}[how]
    for episode in range(len(recs)):
        paid, info = _fly(env, episode, pick)
        run = env.run
        served = run.figures["served"]
        assert validate(sim.planner.prob.fleet, sim.planner.schedule(np.sort(run.rows)), sim.planner.prob.geo).valid
        assert env.returns.sum() == pytest.approx(served, abs=1e-12)
        assert paid <= served + 1e-12  # what agents that never act earned is in env.returns only
        assert [v for v in info.values() if v][0]["served"] == served
        if how == "first":  # the recording's own chooser: the recorded run again
            assert served == pytest.approx(figures[episode]["served"], abs=1e-12)


def test_a_chooser_gives_the_same_run_in_the_simulator_and_in_the_environment(recorded):
    """The tuned rule through the environment (one agent asked per decision) and through the simulator's own
    driver (eosp.ops.simulate.simulate, the chooser answering) fly the same timelines."""
    from eosp.envs.onboard import OnboardEnv, OnboardEnvConfig
    from eosp.ops.onboard import Onboard
    from eosp.ops.simulate import Replayed, simulate

    _, recs, _ = recorded
    env = OnboardEnv(OnboardEnvConfig(recs))
    for i in range(len(recs)):
        served = env.play(i, lambda ctx: ScoreRule(ctx, 0.8, 1.0))
        rows = np.sort(env.run.rows)
        rec = env.recorded[i]
        src = env._source(rec)
        run = simulate(src.day, env.world, Replayed(src.day, rec.answers), float(rec.meta["time_limit"]),
                       onboard=Onboard(src.test, True, ScoreRule(env.ctx, 0.8, 1.0)))
        assert run.figures["served"] == served and np.array_equal(np.sort(run.rows), rows)


def test_features_say_what_the_cloud_model_says():
    """A candidate at the primary's point and time has correlation 1; far away, 0; values scale with weight and
    forecast; empty slots are masked."""
    xyz = np.array([[6371.0, 0.0, 0.0], [6371.0, 0.0, 0.0], [0.0, 6371.0, 0.0]])
    ctx = Context(np.array([1.0, 2.0, 4.0]), xyz, np.arange(3), np.array([0.0, 0.0, 60.0]),
                  np.array([[0.5], [0.25], [1.0]]), 300.0, 6 * 3600.0)
    x, mask = features(ctx, Decision(0, 0, np.array([1, 2]), 0, np.array([0.0, 0.5]), np.array([False, True])))
    f = {n: x[:, i] for i, n in enumerate(FEATURES)}
    assert mask.tolist() == [True, True, False] and not x[2].any()
    assert f["corr"][0] == pytest.approx(1.0) and f["corr"][1] < 1e-9
    assert f["value"][:2] == pytest.approx([2 * 0.25 / 4, 4 * 1.0 / 4])
    assert f["cloudy_recent"][0] == pytest.approx(0.5) and f["p_primary"][0] == pytest.approx(0.5)
    d = Decision(0, 0, np.array([1, 2]), 0, np.array([0.0, 0.0]), np.zeros(0, bool))
    assert ScoreRule(ctx)(d) == 1  # the higher value
    near = Context(ctx.weight, ctx.xyz_km, ctx.task, ctx.start_s, np.array([[0.5], [1.0], [0.3]]), 300.0, 21600.0)
    assert ScoreRule(near)(d) == 0 and ScoreRule(near, beta=1.0)(d) == 1  # beta: the correlated one discounted


def test_a_policy_directory_that_is_anything_else_is_refused_in_one_line(tmp_path):
    from eosp.models.onboard import OnboardNet, load_policy, save_policy

    good = save_policy(OnboardNet(8), tmp_path / "good")
    policy = load_policy(good)
    assert policy.net.hidden == 8
    cases = {
        "missing": lambda d: None,
        "not json": lambda d: (d / "onboard.json").write_text("{"),
        "another format": lambda d: (d / "onboard.json").write_text(json.dumps({"format": "eosp-prices"})),
        "other features": lambda d: (d / "onboard.json").write_text(json.dumps(
            {**json.loads((good / "onboard.json").read_text()), "features": ["value"]})),
        "a pickle": lambda d: ((d / "onboard.json").write_text((good / "onboard.json").read_text()),
                               (d / "onboard.pt").write_bytes(pickle.dumps(object()))),
        "other sizes": lambda d: ((d / "onboard.json").write_text((good / "onboard.json").read_text()),
                                  save_policy(OnboardNet(16), d / "x"), (d / "x" / "onboard.pt").rename(d / "onboard.pt")),
    }
    for name, make_case in cases.items():
        d = tmp_path / name.replace(" ", "-")
        d.mkdir()
        make_case(d)
        with pytest.raises(InputError) as e:
            load_policy(d)
        assert "\n" not in str(e.value) and str(d) in str(e.value), name


def test_a_satellite_that_took_a_candidate_refuses_a_primary_it_cannot_fly(recorded):
    """A satellite that took a replacement and then meets a primary its test refuses (a plan made before the ground
    knew what it took) skips it and reports it as not served; another satellite's primaries are flown as sent."""
    import dataclasses
    import math

    from eosp.ops.onboard import Onboard
    from eosp.ops.simulate import Sent, _recheck, execute, knowledge
    from eosp.ops.world import realize

    sim, recs, _ = recorded
    day = sim.day
    rec = __import__("eosp.ops.plan_cache", fromlist=["read"]).read(recs[0])
    plan = np.sort(rec.answers[0].rows)
    sats, counts = np.unique(day.sat[plan], return_counts=True)
    k = int(sats[np.argmax(counts)])
    mine = plan[day.sat[plan] == k]
    mine = mine[np.argsort(day.start_s[mine])]
    first, last = int(mine[0]), int(mine[-1])
    other = np.flatnonzero((day.sat == k) & ~np.isin(np.arange(len(day.sat)), plan))[0]
    w = realize(sim.scen, 0)
    world = dataclasses.replace(w, clear=np.where(np.arange(len(w.clear)) == first, False, True))
    sent = Sent(prim=plan, alt=np.array([other]), alt_of=np.array([first]), ahead=True)

    def refuse(sat: int, rows: np.ndarray) -> bool:  # the last primary, once the replacement was flown
        return not (sat == k and last in rows.tolist() and other in sent.done)

    onboard = Onboard(refuse, ahead=True)
    execute(day, world, sent, float(day.start_s[first]) + 1.0, onboard)  # the replacement taken
    _recheck(day, sent, onboard, np.zeros(day.satellites))  # then a plan uploaded: the same primaries
    execute(day, world, sent, math.inf, onboard)
    assert sent.taken == {int(other)} and sent.skipped == {last} and last not in sent.done
    assert set(plan[day.sat[plan] != k].tolist()) <= set(sent.done)
    know = knowledge(day, world, sent, len(world.calls_s) - 1, np.full(day.satellites, math.inf))
    if last in know.rows.tolist() and know.outcome[know.rows.tolist().index(last)] >= 0:
        assert know.outcome[know.rows.tolist().index(last)] == 0  # reported as not served


def test_eosp_simulate_refuses_a_missing_policy_in_one_line_and_writes_nothing(recorded, tmp_path, capsys):
    from eosp.cli import main

    sim, _, _ = recorded
    rc = main(["simulate", str(sim.scen.path), "--onboard", "lookahead", "--candidates", "3", "--choose", "policy",
               "--policy", str(tmp_path / "nope"), "--realizations", "1", "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "onboard.json" in err
    assert not (tmp_path / "run").exists()
