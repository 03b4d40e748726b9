"""Energy in the fleet's Lagrangian bound (eosp.fleet.energy, eosp.kinds.lagrange), against a brute force over
the verifier's rules on tiny fleets whose battery binds.

The brute force knows nothing of passes or windows: per satellite it enumerates every sequence of opportunities
whose slews the checker's rule accepts (lines of sight from brahe, the 1e-9 s tolerance, every start), derives
the maneuver windows as the checker does and runs the verifier's battery recurrence on it; the best schedule is
the best union of one valid sequence per satellite.
"""

import dataclasses
import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eosp.budget import UNLIMITED
from eosp.fleet.battery import Intervals, SunCache, simulate
from eosp.fleet.check import Inertial, timedelta_us, validate
from eosp.fleet.geometry import NUMERICAL_EPS, Geometry, angle_deg, slew_time_s
from eosp.fleet.opportunities import compute
from eosp.kinds.fleet.dual import _dual_round, energy_search
from tests.test_fleet import synthetic_fleet


def weak_battery(n_tasks: int, seed: int, initial_wh: float, sunlit_w: float = 0.0, slack_s: int = 5):
    """The synthetic two-satellite fleet (10-minute horizon) with narrow windows (a few starts per task) and a
    battery that holds a few observations: imaging 300 W, slew 120 W, idle 1 W."""
    fleet = synthetic_fleet(n_tasks=n_tasks, seed=seed)
    tk = fleet.tasks
    mid = 0.5 * (tk.release_s + tk.due_s)
    rel = np.maximum(0.0, np.floor((mid - tk.duration_s / 2 - slack_s / 2) / 5) * 5)
    due = np.minimum(600.0, rel + tk.duration_s + slack_s)
    tasks = dataclasses.replace(tk, release_s=rel, due_s=due)
    k = len(fleet.satellites)
    bat = dataclasses.replace(fleet.satellites.battery, capacity_wh=np.full(k, 3.0), initial_wh=np.full(k, initial_wh),
                              idle_w=np.full(k, 1.0), imaging_w=np.full(k, 300.0), slew_w=np.full(k, 120.0),
                              sunlit_w=np.full(k, sunlit_w))
    return dataclasses.replace(fleet, tasks=tasks, satellites=dataclasses.replace(fleet.satellites, battery=bat))


def valid_sequences(fleet, opps, geo, k: int) -> list[list[int]]:
    """Every sequence of satellite k's opportunities (rows of `opps`) that the checker's slew rule and its
    battery accept."""
    inertial, att = Inertial(fleet, geo), fleet.satellites.attitude
    sun = SunCache(geo)
    step_us = fleet.horizon.action_step_s * 1_000_000
    rows = np.flatnonzero(opps.satellite == k)
    task = opps.task[rows].astype(int)
    st_ = opps.start[rows].astype(np.int64) * step_us
    en = st_ + (fleet.tasks.duration_s[task] * 1_000_000).astype(np.int64)

    def need(frm, to):
        return float(slew_time_s(float(angle_deg(frm, to)), att.max_rate_deg_s[k], att.max_acc_deg_s2[k])) \
            + float(att.settling_s[k])

    n = len(rows)
    l0 = [inertial.los(k, int(task[v]), int(st_[v])) for v in range(n)]
    l1 = [inertial.los(k, int(task[v]), int(en[v])) for v in range(n)]
    first = [need(-inertial.sat_eci(k, int(st_[v])), l0[v]) for v in range(n)]
    nxt = [[need(l1[u], l0[v]) for v in range(n)] for u in range(n)]
    lit, margin = sun.grid(k)
    steady = (lit == lit[0]).all() and (margin > SunCache.SAFE_M).all()  # no shadow boundary in the horizon
    out = []

    def battery_ok(seq):
        needs = [first[seq[0]]] + [nxt[u][v] for u, v in zip(seq, seq[1:])]
        obs = Intervals(st_[seq], en[seq])
        man = Intervals(np.asarray([st_[v] - timedelta_us(x) for v, x in zip(seq, needs)], np.int64), st_[seq])
        return simulate(fleet, sun, k, obs, man).ok

    def extend(seq):
        if seq:
            if battery_ok(seq):
                out.append([int(rows[v]) for v in seq])
            elif steady:
                return  # constant charging: observations added after these only spend more
        for v in range(n):
            if not seq:
                if st_[v] / 1e6 + NUMERICAL_EPS >= first[v]:
                    extend([v])
            else:
                u = seq[-1]
                if st_[v] >= en[u] and (st_[v] - en[u]) / 1e6 + NUMERICAL_EPS >= nxt[u][v]:
                    extend(seq + [v])

    extend([])
    return out


def brute_force(fleet, battery: bool = True) -> tuple[float, dict]:
    """(best weight served, per satellite its valid sequences); battery=False: the best without the battery."""
    geo = Geometry(fleet)
    opps = compute(fleet, geo)
    w = fleet.tasks.weight
    seqs = {}
    sets = []
    for k in range(len(fleet.satellites)):
        if battery:
            seqs[k] = valid_sequences(fleet, opps, geo, k)
        else:
            no_battery = dataclasses.replace(fleet.satellites.battery, initial_wh=np.full(len(fleet.satellites), 1e6),
                                             capacity_wh=np.full(len(fleet.satellites), 1e6))
            big = dataclasses.replace(fleet, satellites=dataclasses.replace(fleet.satellites, battery=no_battery))
            seqs[k] = valid_sequences(big, opps, geo, k)
        sets.append({frozenset(opps.task[s].tolist()) for s in seqs[k]} | {frozenset()})
    best = max(sum(w[list(set().union(*combo))]) for combo in itertools.product(*sets))
    return float(best), seqs


def lagrangian(prob, lam: np.ndarray, mu: np.ndarray) -> float:
    """L(lam, mu) as the fleet solver computes it: per pass its term under the priced utilities (the bound
    problem where the pass needs one, else the exact optimum of its priced problem), plus the prices and the
    multipliers times the windows' right-hand sides."""
    from eosp.fleet.passgraph import bound_problem, priced_instance
    from eosp.kinds.lagrange import Prices
    from eosp.kinds.fleet.problem import priced
    from eosp.solvers.base import run_solver

    prices = Prices(lam, prob.windows, mu)
    pi = prices.pass_price()
    terms = []
    for p, pg in enumerate(prob.passes):
        value = priced(prob.pass_values(p), lam[pg.tasks], pg.energy_wh, pi[p])
        pp = priced_instance(pg, value)
        opt = 0.0 if pp is None else run_solver("exact", pp.instance, mode="utility").value
        terms.append(opt if pg.bound_graph is None else max(opt, bound_problem(pg, value)))
    return prices.dual(terms)


def problem_of(fleet):
    from eosp.kinds.fleet.problem import Problem

    return Problem.build(fleet, compute(fleet, Geometry(fleet)))


def test_every_battery_valid_sequence_keeps_every_energy_window():
    """The inequalities themselves: for every sequence the verifier's battery accepts, each window's observations
    spend no more than its right-hand side; and some window binds (the fleet is tight)."""
    fleet = weak_battery(10, 3, initial_wh=1.6)
    prob = problem_of(fleet)
    win = prob.windows
    assert len(win) > 0
    _, seqs = brute_force(fleet)
    row_pass = prob.opps.pass_id
    tight = 0.0
    for k, ss in seqs.items():
        for seq in ss:
            pass_wh = np.zeros(len(prob.passes))
            for r in seq:
                pg = prob.passes[row_pass[r]]
                pass_wh[row_pass[r]] += pg.energy_wh[np.searchsorted(pg.tasks, prob.opps.task[r])]
            used = win.used(pass_wh)
            assert (used <= win.rhs_wh).all(), (seq, used, win.rhs_wh)
            tight = max(tight, float((used / win.rhs_wh).max()))
    assert tight > 0.6  # the windows are not vacuous: valid schedules come close to them


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n_tasks=st.integers(6, 10), seed=st.integers(0, 1000), initial=st.floats(0.9, 2.6),
       sunlit=st.sampled_from([0.0, 40.0]), prices_seed=st.integers(0, 1000))
def test_the_energy_bound_holds_for_any_prices_where_the_battery_binds(n_tasks, seed, initial, sunlit, prices_seed):
    fleet = weak_battery(n_tasks, seed, initial_wh=initial, sunlit_w=sunlit)
    prob = problem_of(fleet)
    best, _ = brute_force(fleet)
    rng = np.random.default_rng(prices_seed)
    for _ in range(3):
        lam = rng.uniform(0, 1.5, n_tasks) * prob.weight * (rng.random(n_tasks) < 0.6)
        mu = rng.exponential(2.0, len(prob.windows)) * (rng.random(len(prob.windows)) < 0.7)
        assert lagrangian(prob, lam, mu) >= best - 1e-9, (lam, mu, best)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n_tasks=st.integers(6, 10), seed=st.integers(0, 1000), initial=st.floats(0.9, 2.6),
       sunlit=st.sampled_from([0.0, 40.0]), prices_seed=st.integers(0, 1000))
def test_the_energy_search_lowers_l_at_fixed_prices_and_stays_a_bound(n_tasks, seed, initial, sunlit, prices_seed):
    """The windows' line search at fixed task prices: the L it returns is L at its multipliers (recomputed here
    pass by pass), never above L before it, and never below the best valid schedule (brute force)."""
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator

    fleet = weak_battery(n_tasks, seed, initial_wh=initial, sunlit_w=sunlit)
    prob = problem_of(fleet)
    best, _ = brute_force(fleet)
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None, energy_bound=True))
    rng = np.random.default_rng(prices_seed)
    lam = rng.uniform(0, 0.8, n_tasks) * prob.weight * (rng.random(n_tasks) < 0.5)
    for _ in range(3):  # successive searches at the same prices, from the multipliers the last one left
        before = lagrangian(prob, lam, coord.prices.mu)
        total, proven, _, pass_wh, _ = _dual_round(coord, lam, UNLIMITED)
        assert proven and abs(total - before) < 1e-6
        got = energy_search(coord, lam, total, pass_wh, UNLIMITED)
        if got is None:
            break
        assert got <= before + 1e-9
        assert abs(got - lagrangian(prob, lam, coord.prices.mu)) < 1e-6
        assert got >= best - 1e-9


def test_energy_makes_the_bound_tighter_than_any_energy_blind_bound():
    """Where the battery binds, the fleet solver's bound falls below the best schedule without a battery (which
    every energy-relaxed bound is at least), stays above the best valid one, and its schedule is valid."""
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import solve

    from eosp.kinds.fleet.problem import path_wh, primal_of

    fleet = weak_battery(10, 3, initial_wh=1.6)
    best, _ = brute_force(fleet)
    blind, _ = brute_force(fleet, battery=False)
    W = float(fleet.tasks.weight.sum())
    assert best < blind - 1  # the battery binds
    prob = problem_of(fleet)
    sol = solve(fleet, prob.opps, FleetConfig(rounds=30, time_limit=None, energy_bound=True), problem=prob)
    assert sol.info["bound_source"] == "lagrangian"
    assert best / W - 1e-9 <= sol.bound < blind / W
    assert validate(fleet, sol.schedule).valid and sol.value <= best / W + 1e-9
    primal = primal_of(prob, sol.schedule)  # the solver's schedule keeps every window too
    pass_wh = np.array([path_wh(pg, primal.paths[p]) for p, pg in enumerate(prob.passes)])
    assert (prob.windows.used(pass_wh) <= prob.windows.rhs_wh).all()


def test_a_window_from_the_pass_graphs_is_on_the_resource_grid_and_holds_its_passes():
    fleet = weak_battery(10, 3, initial_wh=1.6)
    prob = problem_of(fleet)
    win = prob.windows
    sat = np.array([pg.satellite for pg in prob.passes])
    assert (sat[win.lo] == sat[win.hi]).all() and (win.lo <= win.hi).all()
    pi = win.pass_price(np.ones(len(win)))
    for p in range(len(prob.passes)):
        held = (win.lo <= p) & (p <= win.hi)
        assert pi[p] == pytest.approx(float((1.0 / win.scale_wh[held]).sum()))
