"""The task prices by column generation (``--price-step lp``, :mod:`eosp.kinds.fleet.master`): the bound it reaches
is the linear program over every schedule of every pass (solved here from an enumeration of the passes' paths),
and it never falls below the best valid schedule."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.optimize import linprog

from eosp.budget import UNLIMITED, Budget
from eosp.fleet.geometry import Geometry
from eosp.fleet.opportunities import compute
from eosp.kinds.fleet.dual import _dual_round, price_round
from eosp.kinds.fleet.loop import run
from tests.test_fleet import synthetic_fleet


def narrow_fleet(n_tasks: int, seed: int, slack_s: float = 5.0):
    """The synthetic two-satellite fleet (10-minute horizon) with windows a few seconds longer than the tasks, so
    that a pass cannot take every task it sees and satellites contend (the battery as it is there)."""
    fleet = synthetic_fleet(n_tasks=n_tasks, seed=seed)
    tk = fleet.tasks
    mid = 0.5 * (tk.release_s + tk.due_s)
    rel = np.maximum(0.0, np.floor((mid - tk.duration_s / 2 - slack_s / 2) / 5) * 5)
    due = np.minimum(600.0, rel + tk.duration_s + slack_s)
    return dataclasses.replace(fleet, tasks=dataclasses.replace(tk, release_s=rel, due_s=due))


def every_task_set(prob, p: int) -> set[frozenset]:
    """The sets of tasks the paths of pass p serve (a depth-first walk of its graph from the source)."""
    pg = prob.passes[p]
    g = pg.graph
    out, stack = set(), [(0, frozenset())]
    while stack:
        u, done = stack.pop()
        out.add(done)
        for v in g.dst[g.indptr[u]:g.indptr[u + 1]].tolist():
            stack.append((v, done | {int(pg.tasks[g.node_acq[v]])}))
    return out


def full_lp(prob) -> float:
    """max sum v_c x_c over every task set c of every pass, a task served at most once, a pass's sets summing to at
    most 1 (scipy's linprog on the enumerated columns, nothing of the solver's master)."""
    n, P = len(prob.weight), len(prob.passes)
    cols = [(p, c) for p in range(P) for c in every_task_set(prob, p) if c]
    A = np.zeros((n + P, len(cols)))
    v = np.zeros(len(cols))
    for j, (p, c) in enumerate(cols):
        A[list(c), j] = 1.0
        A[n + p, j] = 1.0
        v[j] = prob.weight[list(c)].sum()
    res = linprog(-v, A_ub=A, b_ub=np.ones(n + P), bounds=(0, None), method="highs")
    assert res.status == 0
    return -res.fun


@pytest.mark.parametrize("n_tasks,seed", [(12, 0), (12, 1), (16, 1)])  # 40 weighted steps end 2e-5-1e-2 above
def test_column_generation_reaches_the_linear_program_over_every_pass_schedule(n_tasks, seed):
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.problem import Problem
    from eosp.kinds.fleet.solve import solve

    fleet = narrow_fleet(n_tasks, seed)
    prob = Problem.build(fleet, compute(fleet, Geometry(fleet)))
    assert prob.bound_graphs == 0  # every pass term is its priced optimum: L's minimum is the LP's optimum
    lp = full_lp(prob)
    W = float(prob.weight.sum())
    sol = solve(fleet, prob.opps, FleetConfig(rounds=40, time_limit=None, price_step="lp", seed=seed),
                problem=prob)
    assert lp < W - 1e-6  # the passes contend: the LP is below the conflict-free bound
    assert sol.bound >= lp / W - 1e-9  # no Lagrangian bound is below the LP optimum (weak duality)
    assert sol.bound <= lp / W + 1e-6  # and column generation reaches it
    assert sol.value <= sol.bound + 1e-9


def test_the_smoothed_prices_are_between_the_centre_and_the_duals():
    from eosp.kinds.fleet.master import SMOOTHING, Centre

    c = Centre(np.zeros(3))
    c.observe(np.array([1.0, 2.0, 3.0]), 10.0)
    c.observe(np.array([9.0, 9.0, 9.0]), 11.0)  # a higher L does not move the centre
    assert np.allclose(c.lam, [1.0, 2.0, 3.0])
    got = c.towards(np.array([3.0, 2.0, 1.0]))
    assert np.allclose(got, SMOOTHING * np.array([1.0, 2.0, 3.0]) + (1 - SMOOTHING) * np.array([3.0, 2.0, 1.0]))


def test_a_master_slower_than_its_round_gives_way_to_weighted_steps_from_the_start(monkeypatch):
    """When the master's LP, once solved in its time, is then not solved within it (a 200-satellite day)
    MASTER_PATIENCE rounds in a row, the solver drops it and goes on with weighted subgradient steps from the prices
    it started with; before that each such round takes a weighted step and keeps the master; the bound stays a
    bound."""
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.dual import MASTER_PATIENCE
    from eosp.kinds.fleet.master import Master
    from eosp.kinds.fleet.problem import Problem

    fleet = narrow_fleet(12, 0)
    prob = Problem.build(fleet, compute(fleet, Geometry(fleet)))
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
    start = prob.weight * 0.3
    coord.prices.lam = start.copy()
    price_round(coord, UNLIMITED)  # solved in its time
    assert coord.master is not None and coord.master.solved
    monkeypatch.setattr(Master, "duals", lambda self, budget, iterations=None: None)  # out of time
    for _ in range(MASTER_PATIENCE - 1):
        before = coord.prices.lam.copy()
        price_round(coord, UNLIMITED)
        assert coord.master is not None  # one slow solve: kept
        assert not np.array_equal(coord.prices.lam, before)  # a weighted step for the round
    price_round(coord, UNLIMITED)
    assert coord.master is None and not coord.converged
    assert np.array_equal(coord.prices.lam, start)
    price_round(coord, UNLIMITED)  # a weighted step now
    assert not np.array_equal(coord.prices.lam, start)
    assert coord.best_bound >= full_lp(prob) / 1.0 - 1e-9


def test_a_master_that_never_solved_in_its_time_is_dropped_at_its_first_miss(monkeypatch):
    """A master whose first solve runs out of its time is not one slow solve near the optimum (a 1,000-satellite
    day: its first three solves ran out, each as long as the round's pass solves): dropped at once, the prices back
    where the run started."""
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.master import Master
    from eosp.kinds.fleet.problem import Problem

    fleet = narrow_fleet(12, 0)
    prob = Problem.build(fleet, compute(fleet, Geometry(fleet)))
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
    start = prob.weight * 0.3
    coord.prices.lam = start.copy()
    monkeypatch.setattr(Master, "duals", lambda self, budget, iterations=None: None)  # out of time
    price_round(coord, UNLIMITED)
    assert coord.master is None and np.array_equal(coord.prices.lam, start)


def test_the_master_time_limit_counts_from_the_time_already_run():
    """HiGHS compares its time limit with the run time of every solve of the instance: a master whose solves added
    up past one round's time must still solve the next LP within that time."""
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.master import Master
    from eosp.kinds.fleet.problem import Problem

    fleet = narrow_fleet(16, 1)
    prob = Problem.build(fleet, compute(fleet, Geometry(fleet)))
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
    master = Master(prob)
    rng = np.random.default_rng(0)
    for _ in range(5):  # columns from rounds at random prices, a solve after each
        got = _dual_round(coord, rng.uniform(0.0, 1.0, len(prob.weight)) * prob.weight, UNLIMITED)
        master.add(got[4])
        before = float(master._h.getRunTime())
        assert master.duals(Budget.of(0.5)) is not None
        # the limit HiGHS got is this solve's time (what was left of the budget) on top of all the solves before it
        assert float(master._h.getOptionValue("time_limit")[1]) >= before + 0.4
    assert float(master._h.getRunTime()) > 0.0


def test_with_fixed_rounds_the_master_is_limited_in_iterations_not_seconds():
    """Without a deadline (a fixed number of rounds) a master LP solve stops at a number of simplex iterations
    (whatever the time: the same schedule on any machine and for any number of workers): the same LP from the same
    columns is cut at 1 iteration and solved with enough of them, and the duals are those of an unlimited solve."""
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.master import Master
    from eosp.kinds.fleet.problem import Problem

    fleet = narrow_fleet(16, 1)
    prob = Problem.build(fleet, compute(fleet, Geometry(fleet)))
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
    rng = np.random.default_rng(0)
    rounds = [_dual_round(coord, rng.uniform(0.0, 1.0, len(prob.weight)) * prob.weight, UNLIMITED)[4] for _ in range(4)]

    def master():
        m = Master(prob)
        for paths in rounds:
            m.add(paths)
        return m

    assert master().duals(Budget.of(0.0), iterations=1) is None
    free = master().duals(Budget.of(60.0))
    got = master().duals(Budget.of(0.0), iterations=100_000)  # no time at all, enough iterations
    assert got is not None and np.allclose(got, free)


@pytest.mark.parametrize("n_tasks,seed", [(12, 0), (16, 1), (20, 2)])
def test_the_integer_master_is_a_schedule_of_its_columns_at_least_the_start(n_tasks, seed):
    """The master's integer solution over its columns: one column per pass at most, every task at most once, worth
    at least the schedule it starts from and at most the LP; the best of all packings of the columns (brute force
    over the passes' columns where they are few)."""
    import itertools

    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.problem import Problem, path_tasks

    fleet = narrow_fleet(n_tasks, seed)
    prob = Problem.build(fleet, compute(fleet, Geometry(fleet)))
    coord = Coordinator(prob, FleetConfig(rounds=12, time_limit=None, price_step="lp", seed=seed))
    run(coord)
    master = coord.master
    assert master is not None and master.columns > 0
    sel = master.integer(coord.best.paths, 30.0)
    w = prob.weight
    passes = [master.col_pass[i] for i in sel]
    assert len(passes) == len(set(passes))
    tasks = np.concatenate([path_tasks(prob, master.col_pass[i], master.col_path[i]) for i in sel] or [[]])
    assert len(tasks) == len(np.unique(tasks))
    value = float(w[tasks.astype(np.int64)].sum())
    assert value >= coord.best.value - 1e-9
    master.duals(Budget.of(10.0))
    assert value <= master.value + 1e-9
    by_pass: dict[int, list[set]] = {}
    for p, path in zip(master.col_pass, master.col_path):
        by_pass.setdefault(p, []).append(set(path_tasks(prob, p, path).tolist()))
    choices = [[set()] + cs for cs in by_pass.values()]
    if np.prod([len(c) for c in choices]) <= 200_000:
        best = 0.0
        for combo in itertools.product(*choices):
            union = set().union(*combo)
            if sum(len(c) for c in combo) == len(union):
                best = max(best, float(w[list(union)].sum()) if union else 0.0)
        assert value == pytest.approx(best, abs=1e-9)


@pytest.mark.parametrize("n_tasks,seed,initial", [(12, 0, 3.0), (16, 1, 2.5), (20, 2, 3.0)])
def test_the_integer_master_with_energy_rows_keeps_every_window_with_the_checkers_slews(n_tasks, seed, initial):
    """With the battery's energy windows as rows (:meth:`Master.integer` with ``windows``), on fleets whose battery
    binds: each column's energy (:meth:`Master.energy_rows`) is its observations' least energy plus the slews
    between them as the checker's timelines derive them (maneuver windows of :func:`eosp.fleet.timeline.intervals`,
    settling left out after the first); the solution keeps every row; it is the best packing of the columns that
    keeps them (brute force), and at most the packing without rows."""
    import itertools

    from eosp.fleet.timeline import intervals, timelines
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.problem import Problem, path_slew_wh, path_tasks, path_wh, schedule_windows
    from tests.test_fleet_energy import weak_battery

    fleet = weak_battery(n_tasks, seed, initial)
    prob = Problem.build(fleet, compute(fleet, Geometry(fleet)))
    coord = Coordinator(prob, FleetConfig(rounds=12, time_limit=None, price_step="lp", seed=seed,
                                          integer_energy=False))
    run(coord)
    master = coord.master
    for p, path in enumerate(coord.round_paths):  # more columns: the last round's optima, battery or not
        master.add([path if q == p else np.zeros(0, np.int64) for q in range(len(prob.passes))])
    windows = schedule_windows(prob)
    assert len(windows) > 0
    assert master.energy_rows(windows, coord.best.paths, budget=Budget.spent()) is None  # spent: no rows
    keep, starts, idx, val = master.energy_rows(windows, coord.best.paths)
    assert np.array_equal(keep, np.arange(len(windows)))
    b = fleet.satellites.battery
    settle = fleet.satellites.attitude.settling_s
    for i, (p, path) in enumerate(zip(master.col_pass, master.col_path)):  # each column's energy, from the checker
        pg = prob.passes[p]
        rows = pg.rows[path - 1]
        task = prob.opps.task[rows]
        st = prob.opps.start[rows].astype(np.float64) * fleet.horizon.action_step_s
        tl = timelines(fleet, prob.los, prob.opps.satellite[rows], task, st, st + fleet.tasks.duration_s[task])
        obs, man = intervals(prob.los, tl[pg.satellite], pg.satellite)
        slew_s = ((obs.start - man.start) / 1e6 - settle[pg.satellite])[1:]
        want = path_wh(pg, path) + float(b.slew_w[pg.satellite]) * float(slew_s.sum()) / 3600.0
        assert master.col_wh[i] == pytest.approx(want, rel=1e-6, abs=1e-9)
    sel = master.integer(coord.best.paths, 30.0, windows=windows)
    x = np.zeros(master.columns)
    x[sel] = 1.0
    ends = np.r_[starts, len(idx)]
    used = np.array([float((val[a:z] * x[idx[a:z]]).sum()) for a, z in zip(ends[:-1], ends[1:])])
    assert (used <= windows.rhs_wh + 1e-7).all()
    # under a budget of entries, the windows with the least slack under the schedule given are the rows kept
    pass_wh = np.array([path_wh(prob.passes[p], path) + path_slew_wh(prob, p, path) if len(path) else 0.0
                        for p, path in enumerate(coord.best.paths)])
    order = np.argsort(windows.rhs_wh - windows.used(pass_wh), kind="stable")
    budget = int(np.diff(ends).max())
    few, _, f_idx, _ = master.energy_rows(windows, coord.best.paths, max_nonzeros=budget)
    assert 1 <= len(few) < len(windows) and len(f_idx) <= budget
    assert np.array_equal(few, np.sort(order[:len(few)]))
    w = prob.weight

    def value(cols) -> float:
        tasks = [t for i in cols for t in path_tasks(prob, master.col_pass[i], master.col_path[i]).tolist()]
        return float(w[tasks].sum())

    got = value(sel)
    assert got <= value(master.integer(coord.best.paths, 30.0)) + 1e-9
    by_pass: dict[int, list[int]] = {}
    for i, p in enumerate(master.col_pass):
        by_pass.setdefault(p, []).append(i)
    choices = [[None] + cs for cs in by_pass.values()]
    if np.prod([len(c) for c in choices]) <= 100_000:
        best = 0.0
        for combo in itertools.product(*choices):
            cols = [i for i in combo if i is not None]
            tasks = [t for i in cols for t in path_tasks(prob, master.col_pass[i], master.col_path[i]).tolist()]
            if len(tasks) != len(set(tasks)):
                continue
            y = np.zeros(master.columns)
            y[cols] = 1.0
            if all(float((val[a:z] * y[idx[a:z]]).sum()) <= r + 1e-9
                   for a, z, r in zip(ends[:-1], ends[1:], windows.rhs_wh)):
                best = max(best, value(cols))
        assert got == pytest.approx(best, abs=1e-9)
