"""The fleet solver's coordinate descent as a parallel sweep (eosp.kinds.fleet.construct.descend): valid and never worse than its
start, the same schedule on every pool and any number of workers, and a fixed point (no pass alone, solved with
the tasks no other pass serves, is worth more than its path), checked by brute force."""

from __future__ import annotations

import numpy as np
import pytest

from eosp.budget import UNLIMITED
from eosp.fleet.check import validate
from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.geometry import NUMERICAL_EPS, Geometry
from eosp.fleet.opportunities import compute
from eosp.fleet.slew import LineOfSight
from eosp.kinds.fleet import construct as coord_mod
from eosp.kinds.fleet.config import FleetConfig
from eosp.kinds.fleet.coordinator import Coordinator
from eosp.kinds.fleet.pool import ForkPool, InProcessPool
from eosp.kinds.fleet.problem import Primal, Problem, path_tasks, rewalk, solve_pass
from eosp.kinds.fleet.construct import _solve_batch, construct, descend
from eosp.kinds.fleet.dual import _path_stats
from eosp.kinds.fleet.recovery import _take_in_order
from tests.test_fleet import synthetic_fleet


def generated(seed: int) -> Problem:
    """A crowded small fleet (tasks in clusters: passes compete for them, so a sweep has conflicts to settle)."""
    f = generate(FleetGenConfig(satellites=6, tasks=400, hours=4.0, window_min_h=1.0, window_max_h=3.0, seed=seed,
                                placement="clusters"))
    return Problem.build(f, compute(f, Geometry(f)))


@pytest.fixture(scope="module")
def crowded():
    return [generated(s) for s in (5, 6)]


def start(coord: Coordinator, seed: int) -> Primal:
    """A schedule that is no fixed point: passes in a random order, each with the tasks still free and its
    utilities perturbed at random (the large-neighbourhood move's construction)."""
    rng = np.random.default_rng(seed)
    n = len(coord.prob.passes)
    shift = coord.prob.weight * rng.uniform(0.0, 1.0, len(coord.prob.weight))
    return construct(coord, rng.permutation(n)[: n // 2 + 1], shift)


def consistent(prob: Problem, primal: Primal) -> None:
    """Every path is a walk of its pass graph, every task served once and by the pass `served` names, the value
    the weight served."""
    seen = np.full(len(prob.weight), -1)
    for p, path in enumerate(primal.paths):
        assert np.array_equal(rewalk(prob.passes[p], path), path), p
        tasks = path_tasks(prob, p, path)
        assert len(set(tasks.tolist())) == len(tasks) and (seen[tasks] < 0).all()
        seen[tasks] = p
    assert np.array_equal(seen, primal.served)
    assert primal.value == pytest.approx(float(prob.weight[seen >= 0].sum()))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_sweep_is_valid_and_never_worse_than_its_start(crowded, seed):
    for prob in crowded:
        coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
        primal = start(coord, seed)
        before = primal.value
        consistent(prob, primal)
        descend(coord, primal, list(range(len(prob.passes))), UNLIMITED)
        consistent(prob, primal)
        assert primal.value >= before - 1e-12
        assert validate(prob.fleet, coord.schedule(primal), prob.geo).valid
    # from an empty schedule every pass wants every task at once: the settling must keep each task once
    empty = Coordinator(crowded[0], FleetConfig(rounds=1, time_limit=None))
    primal = empty.empty()
    descend(empty, primal, list(range(len(crowded[0].passes))), UNLIMITED)
    consistent(crowded[0], primal)
    assert primal.value > 0 and validate(crowded[0].fleet, empty.schedule(primal), crowded[0].geo).valid


def test_frozen_passes_are_never_solved_again(crowded):
    prob = crowded[0]
    first = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
    primal = start(first, 3)
    frozen = np.zeros(len(prob.passes), dtype=bool)
    frozen[::3] = True
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None), initial=primal.copy(), frozen=frozen)
    kept = [primal.paths[p] for p in np.flatnonzero(frozen)]
    descend(coord, primal, list(range(len(prob.passes))), UNLIMITED)
    assert all(np.array_equal(primal.paths[p], k) for p, k in zip(np.flatnonzero(frozen), kept))
    consistent(prob, primal)


def sweep(prob: Problem, pool, seed: int) -> tuple[list, float, int]:
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None), pool=pool)
    primal = start(coord, seed)
    descend(coord, primal, list(range(len(prob.passes))), UNLIMITED)
    return [p.tolist() for p in primal.paths], primal.value, coord.pass_solves


@pytest.mark.parametrize("small", [1, coord_mod.SWEEP_IN_PROCESS])
def test_the_sweep_gives_the_same_schedule_on_every_pool(crowded, monkeypatch, small):
    """Whoever solves a batch (this process, two forked workers), and whatever batch is small enough to stay here:
    the same paths, value and solve count."""
    monkeypatch.setattr(coord_mod, "SWEEP_IN_PROCESS", small)
    prob = crowded[1]
    here = sweep(prob, InProcessPool(prob, FleetConfig()), 4)
    pool = ForkPool(prob, FleetConfig(workers=2))
    try:
        forked = sweep(prob, pool, 4)
    finally:
        pool.close()
    assert forked == here


def test_fixed_rounds_give_the_same_schedule_with_one_and_two_workers(crowded):
    from eosp.kinds.fleet.solve import solve

    prob = crowded[0]
    one, two = (solve(prob.fleet, prob.opps, FleetConfig(rounds=3, seed=2, workers=w, time_limit=None), problem=prob)
                for w in (1, 2))
    assert one.schedule.task.tolist() == two.schedule.task.tolist()
    assert np.array_equal(one.schedule.start_us, two.schedule.start_us)
    assert (one.value, one.bound, one.info["pass_solves"]) == (two.value, two.bound, two.info["pass_solves"])


def forgetful(solve_batch):
    """The sweeps' and waves' batch solve without its memo: every pass solved again."""
    def run(c, batch, util, offsets, budget):
        c._memo_ok[:] = False
        return solve_batch(c, batch, util, offsets, budget)
    return run


def test_the_memo_changes_no_schedule_only_the_solves(crowded, monkeypatch):
    """A pass whose utilities are those of its last proven-optimal solve takes that result: fixed rounds give the
    same schedule, value and bound as solving every pass again, and the solves saved are the memo's hits."""
    from eosp.kinds.fleet import solve as solve_mod

    for prob in crowded:
        cfg = FleetConfig(rounds=3, seed=1, time_limit=None)
        memo = solve_mod.solve(prob.fleet, prob.opps, cfg, problem=prob)
        monkeypatch.setattr(coord_mod, "_solve_batch", forgetful(coord_mod._solve_batch))
        again = solve_mod.solve(prob.fleet, prob.opps, cfg, problem=prob)
        monkeypatch.undo()
        assert memo.schedule.task.tolist() == again.schedule.task.tolist()
        assert np.array_equal(memo.schedule.start_us, again.schedule.start_us)
        assert (memo.value, memo.bound) == (again.value, again.bound)
        assert again.info["memo_hits"] == 0 and memo.info["memo_hits"] > 0
        assert memo.info["pass_solves"] + memo.info["memo_hits"] == again.info["pass_solves"]


def test_a_memo_hit_is_the_pass_solved_again(crowded):
    """Every result the memo gives in a descent equals a fresh solve of the pass under the same utilities."""
    prob = crowded[1]
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
    primal = start(coord, 3)
    descend(coord, primal, list(range(len(prob.passes))), UNLIMITED)
    n = len(prob.passes)
    util, offsets = coord._batch_utilities(primal, list(range(n)))
    hits_before = coord.memo_hits
    got = _solve_batch(coord, list(range(n)), util, offsets, UNLIMITED)
    assert coord.memo_hits > hits_before
    for p in range(n):
        fresh = solve_pass(prob, p, util[offsets[p]:offsets[p + 1]], coord.spec)
        assert np.array_equal(got[p].nodes, fresh.nodes) and got[p].value == fresh.value, p


def best_alone(prob: Problem, p: int, allowed: np.ndarray) -> float:
    """The best weight pass p can serve with its `allowed` tasks (a bool per local task), by a search over (tasks
    used, last opportunity) with the checker's slew rule evaluated pair by pair: independent of the pass graph
    (as tests/test_fleet_solver.brute_force_pass)."""
    pg = prob.passes[p]
    fleet, los, sat = prob.fleet, LineOfSight(prob.fleet, prob.geo), pg.satellite
    task = prob.opps.task[pg.rows]
    local = np.searchsorted(pg.tasks, task)
    keep = allowed[local]
    rows, local, task = pg.rows[keep], local[keep], task[keep]
    if not len(rows):
        return 0.0
    st = prob.opps.start[rows].astype(float) * fleet.horizon.action_step_s
    en = st + fleet.tasks.duration_s[task]
    n = len(rows)
    l0, l1 = los.los(sat, task, st), los.los(sat, task, en)
    need = np.array([[los.need_s(sat, l1[u], l0[v]) for v in range(n)] for u in range(n)])
    ok = (st[None, :] - en[:, None]) + NUMERICAL_EPS >= need
    first = st + NUMERICAL_EPS >= los.need_s(sat, los.nadir(sat, st), l0)
    w = prob.weight[pg.tasks]
    frontier = {(1 << int(local[v]), v) for v in range(n) if first[v]}
    seen = set(frontier)
    while frontier:
        nxt = set()
        for mask, u in frontier:
            for v in np.flatnonzero(ok[u]).tolist():
                if not mask >> int(local[v]) & 1 and (mask | 1 << int(local[v]), v) not in seen:
                    seen.add((mask | 1 << int(local[v]), v))
                    nxt.add((mask | 1 << int(local[v]), v))
        frontier = nxt
    return max((sum(w[a] for a in range(len(w)) if mask >> a & 1) for mask, _ in seen), default=0.0)


def tiny(kind: str, seed: int) -> Problem:
    if kind == "two passes":  # two passes sharing every task
        fleet = synthetic_fleet(n_tasks=8, seed=seed)
    else:  # a handful of passes of 1-8 tasks, some tasks contested
        sats, tasks = {"6x120": (6, 120), "8x150": (8, 150)}[kind]
        fleet = generate(FleetGenConfig(satellites=sats, tasks=tasks, hours=3.0, window_min_h=1.0, window_max_h=2.5,
                                        seed=seed, placement="clusters"))
    return Problem.build(fleet, compute(fleet, Geometry(fleet)))


@pytest.mark.parametrize("kind,seed", [("two passes", 5), ("two passes", 6), ("6x120", 7), ("8x150", 5),
                                       ("8x150", 7)])
def test_after_the_sweep_no_pass_alone_is_worth_more(kind, seed):
    """From an empty schedule (every pass wants every task in the first batch), descend to its end; then no pass,
    solved alone by brute force with the tasks no other pass serves, serves more weight than its path."""
    prob = tiny(kind, seed)
    assert sum(len(h) > 1 for h in prob.task_passes) >= 5  # contested tasks: a sweep has conflicts to settle
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
    primal = coord.empty()
    descend(coord, primal, list(range(len(prob.passes))), UNLIMITED)
    consistent(prob, primal)
    checked = 0
    for p, pg in enumerate(prob.passes):
        if pg.n_tasks > 10:
            continue
        mine = path_tasks(prob, p, primal.paths[p])
        allowed = (primal.served[pg.tasks] < 0) | (primal.served[pg.tasks] == p)
        assert best_alone(prob, p, allowed) <= float(prob.weight[mine].sum()) + 1e-9, p
        checked += 1
    assert checked >= 2 and primal.value > 0


@pytest.mark.parametrize("seed", [0, 1])
def test_a_sweeps_utilities_are_each_pass_utility(crowded, seed):
    """The utilities a sweep sends (gathered for the whole batch at once) are, pass by pass and bit for bit, those of
    Coordinator._utility: 0 for a task another pass serves or the repair barred from the satellite, weight less the
    pass's price of the task's energy otherwise."""
    rng = np.random.default_rng(seed)
    for prob in crowded:
        coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
        primal = start(coord, seed)
        n_pass = len(prob.passes)
        coord.spend = np.where(rng.uniform(size=n_pass) < 0.5, rng.uniform(0.0, 0.01, n_pass), 0.0)
        coord.barred[rng.integers(0, len(prob.fleet.satellites), 30), rng.integers(0, len(prob.weight), 30)] = True
        batch = np.sort(rng.choice(n_pass, size=n_pass // 2, replace=False)).tolist()
        util, offsets = coord._batch_utilities(primal, batch)
        assert len(offsets) == len(batch) + 1 and offsets[-1] == len(util)
        for i, p in enumerate(batch):
            assert np.array_equal(util[offsets[i]:offsets[i + 1]], coord._utility(primal, p))


@pytest.mark.parametrize("seed", [0, 1])
def test_a_rounds_serve_counts_and_energies_are_each_paths(crowded, seed):
    """What a price round counts from its paths (gathered from flat vectors at once): how many paths serve each
    task, exactly, and each path's energy, to rounding, as path_tasks and path_wh give them pass by pass; on
    random paths of every pass (tasks served by several passes included) and on a schedule's paths."""
    from eosp.kinds.fleet.problem import path_tasks, path_wh

    rng = np.random.default_rng(seed)
    for prob in crowded:
        coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
        paths = []  # nodes of distinct acquisitions, as a path's are
        for pg in prob.passes:
            nodes = rng.permutation(np.arange(1, len(pg.graph.node_acq)))[:rng.integers(0, 4)]
            paths.append(np.sort(nodes[np.unique(pg.graph.node_acq[nodes], return_index=True)[1]]))
        for ps in (paths, start(coord, seed).paths):
            count, wh = _path_stats(coord, ps)
            want = np.zeros(len(prob.weight))
            for p, path in enumerate(ps):
                want[path_tasks(prob, p, path)] += 1
            assert np.array_equal(count, want) and want.max() >= 1
            assert np.allclose(wh, [path_wh(pg, path) for pg, path in zip(prob.passes, ps)], rtol=1e-12, atol=0)


def test_a_sweeps_batch_shares_no_open_task():
    """Passes 0-4 over tasks {0,1}, {1,2}, {3}, {0}, {4}.  With every task open the batch is 0, 2, 4 (1 and 3 share
    a task with 0); with task 1 served (by some pass) 1 joins (it shares only task 1 with 0), 3 still shares the open
    task 0; with 0 and 1 served all five.  Passes not queued are not looked at."""
    tasks = [[0, 1], [1, 2], [3], [0], [4]]
    ptr = np.r_[0, np.cumsum([len(t) for t in tasks])].astype(np.int64)
    idx = np.array([t for ts in tasks for t in ts], dtype=np.int64)
    claimed = np.zeros(5, dtype=bool)
    queued = np.arange(5, dtype=np.int64)
    for served, want in [([], [0, 2, 4]), ([1], [0, 1, 2, 4]), ([0, 1], [0, 1, 2, 3, 4])]:
        open_ = np.ones(5, dtype=bool)
        open_[served] = False
        assert np.flatnonzero(coord_mod.disjoint(queued, ptr, idx, claimed, open_)).tolist() == want
        assert not claimed.any()
    every = np.ones(5, dtype=bool)
    assert np.flatnonzero(coord_mod.disjoint(queued[[1, 3, 4]], ptr, idx, claimed, every)).tolist() == [0, 1, 2]
    assert np.flatnonzero(coord_mod.wave(queued[[3, 0, 1]], ptr, idx, claimed)).tolist() == [0]


@pytest.mark.parametrize("seed", [0, 1])
def test_the_recovery_takes_the_paths_in_order_as_one_pass_after_another(crowded, seed):
    """The recovery's first step (each pass in a random order takes its path's tasks no pass before it took, the
    rest re-walked) assigns the passes no earlier path touches at once: the same paths, owners and value, to the
    bit, as the plain loop over the passes, with frozen passes and tasks barred from satellites."""
    rng = np.random.default_rng(seed)
    for prob in crowded:
        n = len(prob.passes)
        first = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
        frozen = np.zeros(n, dtype=bool)
        frozen[rng.permutation(n)[: n // 6]] = True
        coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None), initial=start(first, seed),
                            frozen=frozen)
        sats = np.array([pg.satellite for pg in prob.passes])
        coord.barred[sats[rng.integers(0, n, 40)], rng.integers(0, len(prob.weight), 40)] = True
        paths = [solve_pass(prob, p, prob.weight[pg.tasks] * rng.uniform(0.2, 1.0, pg.n_tasks), coord.spec).nodes
                 for p, pg in enumerate(prob.passes)]
        order = [p for p in rng.permutation(n).tolist() if not frozen[p] and len(paths[p])]
        want = coord.empty()
        for p in order:  # the plain loop
            path = paths[p]
            free = coord._available(want, p)[prob.passes[p].graph.node_acq[path]]
            coord._assign(want, p, path if free.all() else prob.rewalk(p, path[free]))
        got = coord.empty()
        _take_in_order(coord, got, order, [paths[p] for p in order])
        assert np.array_equal(got.served, want.served) and got.value == want.value
        assert all(np.array_equal(a, b) for a, b in zip(got.paths, want.paths))
        cut = sum(len(want.paths[p]) < len(paths[p]) for p in order)
        assert cut >= 3 and sum(len(want.paths[p]) == len(paths[p]) for p in order) >= 3  # both kinds met
        consistent(prob, got)
