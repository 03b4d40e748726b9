"""The fleet solver's hooks for operations (eosp.kinds.fleet.replan, Problem.set_values): what each (pass, task)
is worth as an input, the solver's state kept and revalued between calls, requests that arrive as a revaluation,
a freeze per satellite (tests/test_fleet_solver.py holds that one)."""

from __future__ import annotations

import numpy as np
import pytest

from eosp.fleet.geometry import Geometry
from eosp.fleet.opportunities import compute
from eosp.kinds.fleet.config import FleetConfig
from eosp.kinds.fleet.problem import Problem, opportunity_values
from eosp.kinds.fleet.replan import Replanner
from eosp.kinds.fleet.solve import Start, solve
from tests.test_fleet import synthetic_fleet
from tests.test_fleet_master import narrow_fleet

ROUNDS = 30


def objective(sol, prob: Problem) -> float:
    return sol.info["objective_value"] * prob.total_weight


def served_value(sol, prob: Problem) -> float:
    """What the checked schedule serves under the problem's values, recomputed from its rows: each observation at
    its opportunity, worth its task's value in that opportunity's pass (independent of the solver's bookkeeping)."""
    f, o = prob.fleet, prob.opps
    step_us = f.horizon.action_step_s * 1_000_000
    row = {(int(t), int(s), int(st)): r for r, (t, s, st) in enumerate(zip(o.task, o.satellite, o.start))}
    ti, si = f.task_index(), f.satellite_index()
    total = 0.0
    for sat, task, start in zip(sol.schedule.satellite.tolist(), sol.schedule.task.tolist(),
                                sol.schedule.start_us.tolist()):
        r = row[(ti[task], si[sat], int(start // step_us))]
        p = int(o.pass_id[r])
        acq = np.flatnonzero(prob.passes[p].tasks == ti[task])[0]
        total += float(prob.pass_values(p)[acq])
    return total


def random_values(prob: Problem, rng: np.random.Generator) -> np.ndarray:
    """Each opportunity worth its task's weight times a chance of success (a fifth of them none: clouds)."""
    o = prob.opps
    share = rng.uniform(0.1, 1.0, len(o)) * (rng.random(len(o)) < 0.8)
    return opportunity_values(prob, prob.fleet.tasks.weight[o.task] * share)


@pytest.fixture(scope="module")
def contended():
    fleet = narrow_fleet(16, 1)  # four passes that contend for tasks
    opps = compute(fleet, Geometry(fleet))
    return fleet, opps


def test_weights_given_as_values_change_nothing():
    """Values equal to the weights in every pass: the same schedule, value and bound as without values."""
    fleet = synthetic_fleet(n_tasks=24, seed=1)
    opps = compute(fleet, Geometry(fleet))
    cfg = FleetConfig(rounds=4, time_limit=None, seed=2)
    plain = solve(fleet, opps, cfg, problem=Problem.build(fleet, opps))
    prob = Problem.build(fleet, opps)
    assert all(len(h) for h in prob.task_passes)  # every task has an opportunity: the same conflict-free bound
    prob.set_values(prob.weight[prob.task_idx])
    valued = solve(fleet, opps, cfg, problem=prob)
    assert valued.schedule.task.tolist() == plain.schedule.task.tolist()
    assert np.array_equal(valued.schedule.start_us, plain.schedule.start_us)
    assert valued.value == plain.value and valued.bound == pytest.approx(plain.bound, abs=1e-12)
    assert valued.info["objective_value"] == pytest.approx(plain.value)


def test_a_replan_after_a_revaluation_equals_a_cold_solve(contended):
    """Three forecasts, one after another, through one Replanner (prices and columns kept, revalued): each call's
    value equals a cold solve's of the same values (a new problem, prices at zero) where that one is proven
    optimal (all three here); each bound holds for both, and the schedules serve what the solver says under the
    values."""
    fleet, opps = contended
    cfg = FleetConfig(rounds=ROUNDS, time_limit=None, seed=1)
    prob = Problem.build(fleet, opps)
    planner = Replanner(prob, cfg)
    rng = np.random.default_rng(1)
    for call in range(3):
        values = random_values(prob, rng)
        planner.revalue(values)
        warm = planner.solve(Start())
        cold_prob = Problem.build(fleet, opps)
        cold_prob.set_values(values)
        cold = solve(fleet, opps, cfg, problem=cold_prob)
        W = prob.total_weight
        assert cold.bound * W == pytest.approx(objective(cold, cold_prob), abs=1e-6), call  # proven optimal
        assert objective(warm, prob) == pytest.approx(objective(cold, cold_prob), abs=1e-6), call
        assert warm.bound * W >= objective(cold, cold_prob) - 1e-6  # a bound of the same values
        assert served_value(warm, prob) == pytest.approx(objective(warm, prob), abs=1e-9)
        assert warm.info["replan_call"] == call + 1 and warm.check.valid
    assert planner.master is not None and planner.master.columns > 0  # the columns went from call to call


def test_requests_arrive_as_a_revaluation(contended):
    """Five requests worth nothing yet: no schedule serves them and no bound counts them; once they arrive (their
    weights) the next call, from the prices and columns of the first, equals a cold solve of the whole day."""
    fleet, opps = contended
    cfg = FleetConfig(rounds=ROUNDS, time_limit=None, seed=1)
    prob = Problem.build(fleet, opps)
    late = np.arange(len(fleet.tasks)) % 3 == 0
    planner = Replanner(prob, cfg)
    planner.revalue(np.where(late[prob.task_idx], 0.0, prob.weight[prob.task_idx]))
    before = planner.solve(Start())
    ti = fleet.task_index()
    assert not any(late[ti[t]] for t in before.schedule.task.tolist())
    assert before.bound * prob.total_weight <= prob.weight[~late].sum() + 1e-9
    planner.revalue(None)  # they arrived: every task its weight
    after = planner.solve(Start())
    cold = solve(fleet, opps, cfg, problem=Problem.build(fleet, opps))
    assert after.value == pytest.approx(cold.value, abs=1e-9) and after.value >= before.value
    assert any(late[ti[t]] for t in after.schedule.task.tolist())


def test_forked_workers_see_values_set_after_they_were_forked(contended):
    """The forked pool's children hold the problem as it was when they were forked: a revaluation afterwards
    reaches them with the round (the same schedules as in this process)."""
    fleet, opps = contended
    got = []
    for workers in (1, 2):
        prob = Problem.build(fleet, opps)
        planner = Replanner(prob, FleetConfig(rounds=6, time_limit=None, seed=1, workers=workers))
        try:
            run = []
            for seed in (5, 6):
                planner.revalue(random_values(prob, np.random.default_rng(seed)))
                sol = planner.solve(Start())
                run.append((sol.schedule.task.tolist(), sol.schedule.start_us.tolist(), sol.bound))
            got.append(run)
        finally:
            planner.close()
    assert got[0] == got[1]


def test_values_are_checked():
    fleet = synthetic_fleet(n_tasks=12, seed=2)
    opps = compute(fleet, Geometry(fleet))
    prob = Problem.build(fleet, opps)
    n = len(prob.task_idx)
    for bad, why in ((np.ones(n + 1), "one per"), (-np.ones(n), "at least 0"), (np.full(n, np.nan), "finite")):
        with pytest.raises(ValueError, match=why):
            prob.set_values(bad)
    with pytest.raises(ValueError, match="one per opportunity"):
        opportunity_values(prob, np.ones(len(opps) + 2))
    assert prob.values is None and prob.cap is prob.weight  # nothing half set
