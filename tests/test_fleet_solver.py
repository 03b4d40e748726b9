"""The fleet solver: valid schedules, each task once, a bound that holds, agreement with brute force per pass."""

import numpy as np
import pytest

from eosp.fleet.check import validate
from eosp.fleet.geometry import NUMERICAL_EPS, Geometry
from eosp.fleet.opportunities import compute
from eosp.fleet.slew import LineOfSight
from tests.test_fleet import synthetic_fleet


def build(n_tasks: int, seed: int):
    from eosp.kinds.fleet.problem import Problem

    fleet = synthetic_fleet(n_tasks=n_tasks, seed=seed)
    return Problem.build(fleet, compute(fleet, Geometry(fleet)))


@pytest.fixture(scope="module")
def problem():
    return build(16, 5)


def brute_force_pass(prob, p: int) -> float:
    """The best weight one pass can serve, by dynamic programming over (tasks used, last opportunity) with
    every start of every task and the checker's slew rule evaluated pair by pair: independent of the pass
    graph and of its earliest-start arcs."""
    pg = prob.passes[p]
    fleet, los, sat = prob.fleet, LineOfSight(prob.fleet, prob.geo), pg.satellite
    rows = pg.rows
    task = prob.opps.task[rows]
    local = np.searchsorted(pg.tasks, task)
    st = prob.opps.start[rows].astype(float) * fleet.horizon.action_step_s
    en = st + fleet.tasks.duration_s[task]
    n, k = len(rows), len(pg.tasks)
    l0, l1 = los.los(sat, task, st), los.los(sat, task, en)
    need = np.array([[los.need_s(sat, l1[u], l0[v]) for v in range(n)] for u in range(n)])
    ok = (st[None, :] - en[:, None]) + NUMERICAL_EPS >= need
    first = st + NUMERICAL_EPS >= los.need_s(sat, los.nadir(sat, st), l0)
    w = fleet.tasks.weight[pg.tasks]
    best = {}  # (mask, last node) -> reachable
    frontier = {(1 << local[v], v) for v in range(n) if first[v]}
    seen = set(frontier)
    while frontier:
        nxt = set()
        for mask, u in frontier:
            for v in np.flatnonzero(ok[u]).tolist():
                if mask >> local[v] & 1:
                    continue
                s = (mask | 1 << local[v], v)
                if s not in seen:
                    seen.add(s)
                    nxt.add(s)
        frontier = nxt
    for mask, _ in seen:
        best[mask] = sum(w[a] for a in range(k) if mask >> a & 1)
    return max(best.values(), default=0.0)


@pytest.mark.parametrize("seed", [5, 6, 7])
def test_exact_pass_optimum_equals_brute_force_over_every_start(seed):
    from eosp.kinds.fleet.problem import PassSpec, solve_pass

    problem = build(6, seed)
    small = [p for p, pg in enumerate(problem.passes) if 2 <= pg.n_tasks <= 7]
    assert len(small) >= 1
    for p in small:
        pg = problem.passes[p]
        res = solve_pass(problem, p, problem.weight[pg.tasks], PassSpec())
        assert res.value == pytest.approx(brute_force_pass(problem, p)), p
        assert res.bound == pytest.approx(res.value)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_pass_solve_from_its_graph_is_the_exact_solvers_on_its_instance(seed, monkeypatch):
    """The fleet's exact pass solves run the sweep alone on the priced pass graph, with no instance built: the
    same path and value as the exact solver on the pass's priced instance, and when the sweep alone cannot finish
    (no label budget for it) the solver's steps on that instance give the same optimum, proven."""
    import eosp.solvers.exact as exact
    from eosp.fleet.passgraph import priced_instance
    from eosp.kinds.fleet.problem import PassSpec, solve_pass_graph
    from eosp.solvers.base import run_solver

    prob, spec = build(40, seed), PassSpec()
    rng = np.random.default_rng(seed)
    cases = [(pg, np.where(rng.random(pg.n_tasks) < share, prob.weight[pg.tasks] * rng.uniform(0.5, 1.0, pg.n_tasks),
                           0.0)) for pg in prob.passes if pg.n_tasks >= 2 for share in (0.1, 0.3, 0.6, 1.0)]
    assert sum((value > 0).sum() > exact.SMALL_INSTANCE for _, value in cases) >= 2  # both sides of SMALL_INSTANCE
    assert sum(1 <= (value > 0).sum() <= exact.SMALL_INSTANCE for _, value in cases) >= 2
    for pg, value in cases:
        res = solve_pass_graph(pg, value, spec)
        pp = priced_instance(pg, value)
        if pp is None:
            assert len(res.nodes) == 0 and res.value == 0.0
            continue
        sol = run_solver("exact", pp.instance, mode="utility", time_limit=spec.time_limit)
        assert np.array_equal(res.nodes, pp.nodes[sol.nodes]) and res.value == sol.value == res.bound
        with monkeypatch.context() as m:
            m.setattr(exact, "SMALL_INSTANCE", 0)
            m.setattr(exact, "ALONE_LABELS", 0)
            steps = solve_pass_graph(pg, value, spec)
        assert steps.value == pytest.approx(res.value, rel=1e-12) and steps.bound == pytest.approx(res.value)


def test_fleet_schedule_is_valid_each_task_once_and_under_its_bound(problem):
    from eosp.fleet.greedy import solve as greedy
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import solve

    fleet = problem.fleet
    sol = solve(fleet, problem.opps, FleetConfig(rounds=4), problem=problem)
    res = validate(fleet, sol.schedule, problem.geo)
    assert res.valid and len(set(sol.schedule.task.tolist())) == len(sol.schedule)
    assert sol.value == pytest.approx(res.metrics["WCR"])
    base = validate(fleet, greedy(fleet, problem.opps, problem.geo), problem.geo).metrics["WCR"]
    assert sol.value >= base - 1e-12
    assert problem.fifo_violations == 0
    assert sol.value <= sol.bound + 1e-9 and 0 <= sol.gap <= 1
    # the bound can only fall, the value only rise, along the run
    values = [v for _, v, _ in sol.history]
    bounds = [b for _, _, b in sol.history if b < 1e9]
    assert values == sorted(values) and bounds == sorted(bounds, reverse=True)


def test_a_run_with_rounds_is_deterministic_for_a_seed(problem):
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import solve

    a, b = (solve(problem.fleet, problem.opps, FleetConfig(rounds=3, seed=7, time_limit=None), problem=problem)
            for _ in range(2))
    assert a.schedule.task.tolist() == b.schedule.task.tolist()
    assert np.array_equal(a.schedule.start_us, b.schedule.start_us) and a.bound == b.bound


def test_each_price_round_says_where_its_time_went():
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import solve

    prob = build(40, 1)
    sol = solve(prob.fleet, prob.opps, FleetConfig(rounds=3, seed=7, time_limit=None), problem=prob)
    phases, rounds_s = sol.info["round_phases_s"], sol.info["price_round_s"]
    assert len(phases) == len(rounds_s) == 3
    for ph, s in zip(phases, rounds_s):  # the round's wait and its price step add up to its wall time
        assert set(ph) == {"round", "prices", "recover", "repair", "moves", "pool", "pool_calls"}
        assert min(ph.values()) >= 0 and abs(ph["round"] + ph["prices"] - s) < 2e-3


def test_ramp_passes_give_a_schedule_and_no_bound(problem):
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import solve

    sol = solve(problem.fleet, problem.opps, FleetConfig(pass_solver="ramp", rounds=2),
                problem=problem)
    assert validate(problem.fleet, sol.schedule, problem.geo).valid
    # RAMP proves no pass bound: the bound is the conflict-free one (every task with an opportunity, once)
    assert sol.info["bound_source"] == "conflict-free"
    assert sol.value <= sol.bound + 1e-12
    if sol.info["rounds"]:
        assert "ramp" in sol.info["no_lagrangian_bound_because"]


def test_replanning_keeps_the_frozen_actions_and_never_loses_the_initial_value(problem):
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import solve

    fleet = problem.fleet
    first = solve(fleet, problem.opps, FleetConfig(rounds=1, seed=1), problem=problem)
    cut = float(np.median(problem.pass_time[:, 0])) + 1.0
    again = solve(fleet, problem.opps, FleetConfig(rounds=2, seed=2), problem=problem,
                  initial=first.schedule, freeze_until_s=cut)
    assert validate(fleet, again.schedule, problem.geo).valid
    assert again.value >= first.value - 1e-12
    before = {(s, t, a) for s, t, a in zip(first.schedule.satellite, first.schedule.task, first.schedule.start_us)
              if a < cut * 1e6}
    after = set(zip(again.schedule.satellite, again.schedule.task, again.schedule.start_us))
    assert before and before <= after
    # what its bound bounds is named: with passes frozen, the schedules that keep them
    assert again.info["bound_source"] in ("conflict-free", "lagrangian, frozen passes as given")


def test_a_freeze_per_satellite_keeps_each_satellites_actions_up_to_its_own_time(problem):
    """One freeze time per satellite (a plan uploaded at each satellite's own contact): the passes of satellite k
    starting before its time keep the initial schedule's actions, the others are re-planned; one time for all is
    the same as that time for each; a wrong length is refused.  Here the first satellite is frozen to the end of
    the horizon, the second not at all."""
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import frozen_passes, solve

    fleet, n_sat = problem.fleet, len(problem.fleet.satellites)
    first = solve(fleet, problem.opps, FleetConfig(rounds=1, seed=1), problem=problem)
    until = np.where(np.arange(n_sat) == 0, float(fleet.horizon.seconds), 0.0)
    frozen = frozen_passes(problem, until)
    sat = np.array([pg.satellite for pg in problem.passes])
    assert np.array_equal(frozen, sat == 0) and frozen.any() and (~frozen).any()
    t = float(np.median(problem.pass_time[:, 0])) + 1.0
    assert np.array_equal(frozen_passes(problem, t), frozen_passes(problem, np.full(n_sat, t)))
    with pytest.raises(ValueError, match="one per satellite"):
        frozen_passes(problem, np.zeros(n_sat + 1))
    again = solve(fleet, problem.opps, FleetConfig(rounds=2, seed=2), problem=problem, initial=first.schedule,
                  freeze_until_s=until)
    assert validate(fleet, again.schedule, problem.geo).valid and again.value >= first.value - 1e-12
    s0 = fleet.satellites.ids[0]
    rows = lambda sch: {(t, a, e) for s, t, a, e in zip(sch.satellite, sch.task, sch.start_us, sch.end_us) if s == s0}
    assert rows(first.schedule) and rows(again.schedule) == rows(first.schedule)


def test_a_battery_that_binds_is_repaired_and_its_tasks_go_to_other_satellites():
    import dataclasses

    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.problem import Problem
    from eosp.kinds.fleet.solve import solve

    fleet = synthetic_fleet(n_tasks=16, seed=5)
    b = fleet.satellites.battery
    weak = dataclasses.replace(b, initial_wh=np.array([6.0, 400.0]), capacity_wh=np.array([6.0, 400.0]),
                               idle_w=np.array([1.0, 1.0]), imaging_w=np.array([600.0, 10.0]), sunlit_w=np.zeros(2))
    fleet = dataclasses.replace(fleet, satellites=dataclasses.replace(fleet.satellites, battery=weak))
    prob = Problem.build(fleet, compute(fleet, Geometry(fleet)))
    sol = solve(fleet, prob.opps, FleetConfig(rounds=2), problem=prob)
    res = validate(fleet, sol.schedule, prob.geo)
    assert res.valid and sol.info["battery_barred"] > 0
    by_sat = {s: int((sol.schedule.satellite == s).sum()) for s in fleet.satellites.ids}
    assert by_sat[fleet.satellites.ids[1]] > by_sat[fleet.satellites.ids[0]]  # the strong battery serves more
    assert sol.value <= sol.bound + 1e-9


def test_two_worker_processes_give_the_same_run_as_one(problem):
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import solve

    one, two = (solve(problem.fleet, problem.opps, FleetConfig(rounds=2, seed=3, workers=w, time_limit=None),
                      problem=problem)
                for w in (1, 2))
    assert one.schedule.task.tolist() == two.schedule.task.tolist() and one.bound == two.bound


def test_the_graph_memory_estimate_counts_nodes_by_tasks_and_covers_the_built_graphs():
    """The solve's memory check (fleet.passgraph.graph_bytes) scales with nodes x tasks of each pass, counted from
    the opportunities alone: equal to the count over the built graphs, which have at most one arc per node and
    task, and whose arrays the estimate covers."""
    from eosp.fleet.generate import FleetGenConfig, generate
    from eosp.fleet.passgraph import PAIR_BYTES, build_passes, graph_bytes, node_task_pairs

    fleet = generate(FleetGenConfig(satellites=6, tasks=600, hours=4.0, window_min_h=1.0, window_max_h=3.0))
    geo = Geometry(fleet)
    opps = compute(fleet, geo)
    passes = build_passes(fleet, opps, LineOfSight(fleet, geo))
    assert len(opps) > 100
    assert node_task_pairs(opps, len(fleet.tasks)) == sum(len(pg.rows) * pg.n_tasks for pg in passes)
    for pg in passes:
        assert pg.graph.n_arcs <= len(pg.rows) * pg.n_tasks + pg.n_tasks  # the source's arcs, one per task
    arcs = sum(pg.graph.dst.nbytes + (0 if pg.bound_graph is None else pg.bound_graph.dst.nbytes) for pg in passes)
    assert arcs <= node_task_pairs(opps, len(fleet.tasks)) * PAIR_BYTES
    assert sum(pg.nbytes for pg in passes) <= graph_bytes(opps, len(fleet.tasks))
