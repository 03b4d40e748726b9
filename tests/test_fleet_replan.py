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
from tests.test_fleet_master import every_task_set, narrow_fleet

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


def test_kept_prices_follow_each_task_s_values(contended):
    """After a call, values doubled for half the tasks and zeroed for a few: the carried prices are the kept ones
    doubled, zeroed and unchanged where each task's values were, and with carry "keep" the kept ones as they are;
    the next call from them is still the cold solve's value."""
    fleet, opps = contended
    prob = Problem.build(fleet, opps)
    planner = Replanner(prob, FleetConfig(rounds=ROUNDS, time_limit=None, seed=1))
    rng = np.random.default_rng(2)
    values = random_values(prob, rng)
    planner.revalue(values)
    planner.solve(Start())
    lam = planner.prices.lam.copy()
    assert (lam > 0).any()
    factor = np.where(np.arange(len(prob.weight)) % 2 == 0, 2.0, 1.0)
    factor[::7] = 0.0
    planner.revalue(values * factor[prob.task_idx])
    expect = np.where(planner._cap > 0, lam * factor, lam)  # a task worth nothing before keeps its price
    assert np.allclose(planner.carried(), expect)
    planner.carry = "keep"
    assert np.array_equal(planner.carried(), lam)
    planner.carry = "scale"
    warm = planner.solve(Start())
    cold_prob = Problem.build(fleet, opps)
    cold_prob.set_values(values * factor[prob.task_idx])
    cold = solve(fleet, opps, FleetConfig(rounds=ROUNDS, time_limit=None, seed=1), problem=cold_prob)
    assert objective(warm, prob) == pytest.approx(objective(cold, cold_prob), abs=1e-6)


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


@pytest.fixture(scope="module")
def weak_day():
    """A greedy schedule of a generated fleet, and the same fleet with batteries too weak for it."""
    import dataclasses

    from eosp.fleet.generate import FleetGenConfig, generate
    from eosp.fleet.greedy import solve as greedy

    fleet = generate(FleetGenConfig(satellites=5, tasks=300, hours=4.0, window_min_h=1.0, window_max_h=3.0, seed=2))
    geo = Geometry(fleet)
    opps = compute(fleet, geo)
    sched = greedy(fleet, opps, geo)
    b = fleet.satellites.battery
    weak = dataclasses.replace(b, initial_wh=0.05 * b.capacity_wh, sunlit_w=0.3 * b.sunlit_w)
    weak = dataclasses.replace(fleet, satellites=dataclasses.replace(fleet.satellites, battery=weak))
    return weak, opps, geo, sched


def prefix_holds(fleet, sched, geo, until_s: float) -> bool:
    from eosp.fleet.check import validate
    from eosp.fleet.model import Schedule

    keep = sched.start_us <= until_s * 1e6
    part = Schedule(sched.satellite[keep], sched.task[keep], sched.start_us[keep], sched.end_us[keep])
    return validate(fleet, part, geo).valid


def test_the_battery_repair_keeps_what_is_kept_until_a_time_when_later_observations_can_go(weak_day):
    """repair_battery with `kept_until` (per satellite): when the observations up to that time hold the battery on
    their own, none of them is dropped (the repair takes later ones), and the result still holds; without it, the
    same repair drops some of them (so the test can fail)."""
    from eosp.fleet.reasons import schedule_timelines
    from eosp.fleet.slew import LineOfSight
    from eosp.fleet.timeline import repair_battery, to_schedule

    weak, opps, geo, sched = weak_day
    los = LineOfSight(weak, geo)
    horizon = weak.horizon.seconds
    guard = next(t for t in np.linspace(0.6, 0.1, 11) * horizon if prefix_holds(weak, sched, geo, t))
    plain = schedule_timelines(weak, sched, los)
    repair_battery(weak, los, plain)
    tls = schedule_timelines(weak, sched, los)
    kept = {k: guard for k in range(len(weak.satellites))}
    assert repair_battery(weak, los, tls, kept_until=kept) > 0
    before = {(k, t, s) for k, tl in enumerate(schedule_timelines(weak, sched, los)) for t, s in zip(tl.task, tl.start)
              if s <= guard}
    after = {(k, t, s) for k, tl in enumerate(tls) for t, s in zip(tl.task, tl.start)}
    assert before <= after  # every observation up to the guard kept
    assert not before <= {(k, t, s) for k, tl in enumerate(plain) for t, s in zip(tl.task, tl.start)}
    from eosp.fleet.check import validate

    assert validate(weak, to_schedule(weak, tls), geo).valid


def test_a_solve_keeps_its_frozen_passes_when_the_battery_binds(weak_day):
    """--init with --freeze-until on batteries too weak for the initial schedule: the frozen passes' observations
    all stay (they hold the battery on their own); the repair takes what it must from the passes after them."""
    weak, opps, geo, sched = weak_day
    prob = Problem.build(weak, opps, geo)
    until = next(t for t in np.linspace(0.6, 0.1, 11) * weak.horizon.seconds if prefix_holds(weak, sched, geo, t))
    sol = solve(weak, opps, FleetConfig(rounds=2, time_limit=None, seed=1), problem=prob, initial=sched,
                freeze_until_s=until)
    frozen_end = prob.pass_time[prob.pass_time[:, 0] < until, 1].max()
    assert sol.check.valid and sol.info["repair_removed"] > 0
    want = {r for r in zip(sched.satellite.tolist(), sched.task.tolist(), sched.start_us.tolist())
            if r[2] <= frozen_end * 1e6}
    got = set(zip(sol.schedule.satellite.tolist(), sol.schedule.task.tolist(), sol.schedule.start_us.tolist()))
    frozen_rows = {r for r in want if r[2] < until * 1e6}
    assert frozen_rows and frozen_rows <= got


def best_over_passes(prob: Problem, passes: list[int]) -> float:
    """The most the passes `passes` serve together under the problem's values, each task at most once among
    them (their task sets enumerated along the graphs' arcs, every combination tried; the battery left out)."""
    from itertools import product

    sets = [[sorted(c) for c in every_task_set(prob, p)] for p in passes]
    worth = [dict(zip(prob.passes[p].tasks.tolist(), prob.pass_values(p).tolist())) for p in passes]
    best = 0.0
    for combo in product(*sets):
        tasks = [t for c in combo for t in c]
        if len(tasks) == len(set(tasks)):
            best = max(best, sum(w[t] for w, c in zip(worth, combo) for t in c))
    return best


@pytest.mark.parametrize("claim", [True, False])
def test_frozen_observations_that_serve_nothing(contended, claim):
    """The first satellite's passes frozen as a solve left them.  With ``claim_frozen=False`` (operations: an
    acquisition found cloudy leaves its request open) the frozen observations stay, worth nothing, and their tasks
    may be served again in the other passes; the objective equals a brute force over the other passes (the
    frozen tasks free in them), and the Lagrangian bound is at least it.  With True they serve their tasks, which
    the other passes then cannot take."""
    fleet, opps = contended
    cfg = FleetConfig(rounds=ROUNDS, time_limit=None, seed=1)
    prob = Problem.build(fleet, opps)
    first = solve(fleet, opps, cfg, problem=prob)
    sat = np.array([pg.satellite for pg in prob.passes])
    until = np.where(np.arange(len(fleet.satellites)) == 0, fleet.horizon.seconds, -1.0)
    frozen = sat == 0  # the other satellite's passes see the same tasks (this fixture's passes contend)
    kept = {(s, t, int(st)) for s, t, st in zip(first.schedule.satellite.tolist(), first.schedule.task.tolist(),
                                                first.schedule.start_us.tolist())
            if frozen[int(opps.pass_id[np.flatnonzero((opps.task == fleet.task_index()[t])
                                                      & (opps.satellite == fleet.satellite_index()[s]))[0]])]}
    assert kept  # the frozen passes observe something
    values = prob.weight[prob.task_idx].copy()
    if not claim:
        values[np.repeat(frozen, np.diff(prob.task_ptr))] = 0.0  # what a frozen observation is worth: nothing
    prob.set_values(values)
    again = Replanner(prob, cfg).solve(Start(first.schedule, until, claim_frozen=claim))
    rows = set(zip(again.schedule.satellite.tolist(), again.schedule.task.tolist(), again.schedule.start_us.tolist()))
    assert kept <= rows and again.check.valid
    others = [p for p in range(len(prob.passes)) if not frozen[p]]
    if claim:
        taken = {fleet.task_index()[t] for _, t, _ in kept}
        expect = best_over_passes(prob, others) if not taken else None
        again_tasks = [fleet.task_index()[t] for t in again.schedule.task.tolist()]
        assert len(again_tasks) == len(set(again_tasks))  # each task once
        assert expect is None or objective(again, prob) <= expect + 1e-9
    else:
        brute = best_over_passes(prob, others)
        assert objective(again, prob) == pytest.approx(brute, abs=1e-9)
        assert again.bound * prob.total_weight >= brute - 1e-9
        repeated = len(again.schedule.task) - len(set(again.schedule.task.tolist()))
        assert repeated > 0  # some frozen task served again by the other satellite
