"""The fleet's Lagrangian bound under the verifier's own rules: bridges kept, repeats allowed, loose margins.

The verifier's slew rule is not hereditary: an observation that tracks its target turns the line of sight at no
charge, so A -> B -> C can be valid while A -> C alone is too short.  The fleets here are built that way (slow
satellites, tasks placed so that each line of sight at the end of one observation is the one at the start of
the next) and the bound is compared with a brute force that uses the checker's geometry (brahe) and its
tolerance, every start of every task, repeats allowed, and nothing of the pass graphs.
"""

import dataclasses
import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eosp.budget import UNLIMITED
from eosp.fleet.geometry import NUMERICAL_EPS, Geometry, angle_deg, brahe_module, slew_time_s
from eosp.fleet.opportunities import compute
from eosp.fleet.passgraph import bound_problem, bridge_triples, build_passes, priced_instance
from eosp.fleet.slew import LineOfSight
from eosp.graphs.discrete import DiscreteGraph, acq_ptr_from_node_acq
from eosp.planning.labels import label_search
from eosp.kinds.fleet.dual import ceiling_prices, ceiling_round
from tests.test_fleet import fixture, strings

SLOW = dict(rate=0.5, acc=0.1, settle=3.5, off_nadir=30.0)  # slower than the benchmark's slowest (0.9, 0.15)


# ------------------------------------------------------------------ the label search with repeats


def _graph_with_repeats(n: int, seed: int) -> tuple[DiscreteGraph, np.ndarray]:
    """A random DAG in canonical order whose nodes may also reach later nodes of their own acquisition."""
    rng = np.random.default_rng(seed)
    per = rng.integers(1, 4, n)
    node_acq = np.r_[-1, np.repeat(np.arange(n), per)].astype(np.int32)
    node_time = np.r_[0.0, rng.uniform(1, 100, per.sum())]
    for a in range(n):  # times increase within an acquisition (canonical order)
        idx = np.flatnonzero(node_acq == a)
        node_time[idx] = np.sort(node_time[idx])
    acq_ptr = acq_ptr_from_node_acq(node_acq, n)
    rows = []
    for u in range(len(node_acq)):
        row = []
        for b in range(n):
            later = [v for v in range(acq_ptr[b], acq_ptr[b + 1]) if node_time[v] > node_time[u] + 1.0]
            if later and (u == 0 or rng.random() < 0.6):
                row.append(later[0])
        rows.append(row)
    indptr = np.r_[0, np.cumsum([len(r) for r in rows])].astype(np.int64)
    dst = np.array([v for r in rows for v in r], dtype=np.int32)
    return DiscreteGraph(node_acq, node_time, indptr, dst, acq_ptr), rng.uniform(0, 10, n).round(2)


def _best_with_repeats(g: DiscreteGraph, w: np.ndarray) -> float:
    best = 0.0
    stack = [(0, frozenset())]
    while stack:
        u, done = stack.pop()
        best = max(best, sum(w[a] for a in done))
        for v in g.dst[g.indptr[u]:g.indptr[u + 1]].tolist():
            stack.append((v, done | {int(g.node_acq[v])}))
    return best


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 6), seed=st.integers(0, 10_000))
def test_label_search_with_repeats_is_the_best_path_crediting_each_acquisition_once(n, seed):
    g, w = _graph_with_repeats(n, seed)
    assert label_search(g, w, beam=0, repeats=True).value == pytest.approx(_best_with_repeats(g, w))


# ------------------------------------------------------------------ fleets where A -> B -> C needs B


def _on_ray(bh, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """The point of the ray origin + s * direction (ITRF) at geodetic altitude 0 (bisection on s)."""
    lo, hi = 0.0, 4.0e6
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        alt = bh.position_ecef_to_geodetic(origin + mid * direction, bh.AngleFormat.DEGREES)[2]
        lo, hi = (mid, hi) if alt > 0 else (lo, mid)
    return origin + lo * direction


def bridge_fleet(start: int = 150, duration: float = 15.0, gap: float = 5.0, jitter=(0.0, 0.0), n_chain: int = 3,
                 weights=None, shared: bool = False):
    """Satellite 0 of a verifier fixture made slow; tasks t0, t1, ... observed back to back by it from `start` s,
    each `duration` s long with `gap` s between them, each placed where the line of sight at the start of its
    observation is the one at the end of the previous (then moved by `jitter` km east and north); windows
    allow a few starts around the chain's.  Satellite 1 (a few minutes behind on a nearby track) can observe
    them only when `shared`: else its sensor is of another type."""
    bh = brahe_module()
    fleet, _ = fixture("duplicate_observation_no_bonus_valid")
    geo = Geometry(fleet)
    step = geo.base_step_s
    pos, rot = geo.grid_positions(0), geo.grid_rotations()
    i0 = start // step
    lon, lat, _ = bh.position_ecef_to_geodetic(pos[i0 + int(duration // 2) // step], bh.AngleFormat.DEGREES)
    tgt = [np.asarray(bh.position_geodetic_to_ecef([lon + 0.05, lat, 0.0], bh.AngleFormat.DEGREES))]
    times = [float(start)]
    for k in range(1, n_chain):
        t_end = times[-1] + duration
        t_next = t_end + gap
        ie, i_n = int(round(t_end / step)), int(round(t_next / step))
        los_end = rot[ie] @ (tgt[-1] - pos[ie])
        direction = rot[i_n].T @ (los_end / np.linalg.norm(los_end))
        p = _on_ray(bh, pos[i_n], direction)
        lo_, la_, _ = bh.position_ecef_to_geodetic(p, bh.AngleFormat.DEGREES)
        east, north = jitter
        lo_ += east / (111.32 * np.cos(np.radians(la_)))
        la_ += north / 110.57
        tgt.append(np.asarray(bh.position_geodetic_to_ecef([lo_, la_, 0.0], bh.AngleFormat.DEGREES)))
        times.append(t_next)
    geod = np.array([bh.position_ecef_to_geodetic(t, bh.AngleFormat.DEGREES) for t in tgt])
    n = n_chain
    tasks = dataclasses.replace(
        fleet.tasks, ids=strings([f"t{i}" for i in range(n)]), names=strings([f"n{i}" for i in range(n)]),
        lat_deg=geod[:, 1], lon_deg=geod[:, 0], alt_m=np.zeros(n),
        release_s=np.array([t - 10.0 for t in times]), due_s=np.array([t + duration + 10.0 for t in times]),
        duration_s=np.full(n, duration), weight=np.asarray(weights if weights is not None else np.ones(n), float),
        sensor=strings([fleet.satellites.sensor[0]] * n))
    k = len(fleet.satellites)
    att = dataclasses.replace(fleet.satellites.attitude, max_rate_deg_s=np.full(k, SLOW["rate"]),
                              max_acc_deg_s2=np.full(k, SLOW["acc"]), settling_s=np.full(k, SLOW["settle"]),
                              max_off_nadir_deg=np.full(k, SLOW["off_nadir"]))
    sensor = fleet.satellites.sensor.copy()
    if not shared:
        sensor[1] = "infrared" if sensor[0] != "infrared" else "visible"
    sats = dataclasses.replace(fleet.satellites, attitude=att, sensor=strings(list(sensor)))
    return dataclasses.replace(fleet, tasks=tasks, satellites=sats)


def brute_force(fleet, value: np.ndarray | None = None) -> float:
    """The best weight any schedule can serve, battery aside (which only lowers it): per satellite every sequence
    of its opportunities (every start, tasks observed again allowed and credited once) whose consecutive slews
    the checker's rule accepts (lines of sight from brahe, gap + 1e-9 s >= slew + settling), then the best union
    over satellites.  `value[k, t]`: what task t is worth observed by satellite k (default: its weight); a task
    two satellites observe counts once, at the more valuable."""
    from eosp.fleet.check import Inertial

    geo = Geometry(fleet)
    opps = compute(fleet, geo)
    inertial = Inertial(fleet, geo)
    att, w = fleet.satellites.attitude, fleet.tasks.weight
    step_us = fleet.horizon.action_step_s * 1_000_000
    per_sat = []
    for k in range(len(fleet.satellites)):
        rows = np.flatnonzero(opps.satellite == k)
        task = opps.task[rows].astype(int)
        st = opps.start[rows].astype(np.int64) * step_us
        en = st + (fleet.tasks.duration_s[task] * 1_000_000).astype(np.int64)
        l0 = [inertial.los(k, int(t), int(s)) for t, s in zip(task, st)]
        l1 = [inertial.los(k, int(t), int(e)) for t, e in zip(task, en)]

        def need(frm, to):
            return float(slew_time_s(float(angle_deg(frm, to)), att.max_rate_deg_s[k], att.max_acc_deg_s2[k])) \
                + float(att.settling_s[k])

        first = [st[v] / 1e6 + NUMERICAL_EPS >= need(-inertial.sat_eci(k, int(st[v])), l0[v]) for v in range(len(rows))]
        ok = [[st[v] >= en[u] and (st[v] - en[u]) / 1e6 + NUMERICAL_EPS >= need(l1[u], l0[v])
               for v in range(len(rows))] for u in range(len(rows))]
        seen = {(v, frozenset([task[v]])) for v in range(len(rows)) if first[v]}
        frontier = set(seen)
        while frontier:
            nxt = set()
            for u, done in frontier:
                for v in range(len(rows)):
                    if ok[u][v]:
                        s = (v, done | {task[v]})
                        if s not in seen:
                            seen.add(s)
                            nxt.add(s)
            frontier = nxt
        per_sat.append({d for _, d in seen} | {frozenset()})
    if value is None:
        return max(sum(w[list(set().union(*combo))]) for combo in itertools.product(*per_sat))
    best = 0.0
    for combo in itertools.product(*per_sat):
        got: dict = {}
        for k, done in enumerate(combo):
            for t in done:
                got[t] = max(got.get(t, 0.0), float(value[k, t]))
        best = max(best, sum(got.values()))
    return best


def lagrangian(fleet, lam: np.ndarray) -> tuple[float, float]:
    """(L(lam) as the fleet solver's bound computes it, what it was before bridges were kept): per pass its bound
    problem where the pass needs one, else the exact optimum of its priced problem; plus the sum of prices."""
    from eosp.solvers.base import run_solver

    geo = Geometry(fleet)
    passes = build_passes(fleet, compute(fleet, geo), LineOfSight(fleet, geo))
    w = fleet.tasks.weight
    total, before = float(lam.sum()), float(lam.sum())
    for pg in passes:
        value = w[pg.tasks] - lam[pg.tasks]
        pp = priced_instance(pg, value)
        opt = 0.0 if pp is None else run_solver("exact", pp.instance, mode="utility").value
        before += opt
        total += opt if pg.bound_graph is None else bound_problem(pg, value)
    return total, before


def test_a_bridge_is_kept_in_the_bound():
    """t1 is needed between t0 and t1: priced out (price = its weight), the old bound fell below what the fleet
    can do; the pass's bound problem keeps it at value zero."""
    fleet = bridge_fleet()
    geo = Geometry(fleet)
    passes = build_passes(fleet, compute(fleet, geo), LineOfSight(fleet, geo))
    chain = [pg for pg in passes if pg.satellite == 0]
    assert len(chain) == 1 and chain[0].bound_graph is not None and bridge_triples(chain[0].bound_graph) > 0
    best = brute_force(fleet)
    assert best == 3.0
    lam = np.array([0.0, 1.0, 0.0])
    total, before = lagrangian(fleet, lam)
    assert before == pytest.approx(2.0)  # the pass alone: t0 or t2, not both, without t1
    assert total >= best - 1e-9


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(duration=st.sampled_from([10.0, 15.0]), gap=st.sampled_from([5.0, 10.0]),
       east=st.floats(-1, 1), north=st.floats(-1, 1), n_chain=st.integers(2, 4), shared=st.booleans(),
       seed=st.integers(0, 1000))
def test_the_bound_holds_for_any_prices_on_bridge_fleets(duration, gap, east, north, n_chain, shared, seed):
    rng = np.random.default_rng(seed)
    fleet = bridge_fleet(duration=duration, gap=gap, jitter=(east, north), n_chain=n_chain,
                         weights=rng.integers(1, 6, n_chain), shared=shared)
    best = brute_force(fleet)
    for _ in range(3):
        lam = rng.uniform(0, 1.5, n_chain) * fleet.tasks.weight * (rng.random(n_chain) < 0.7)
        total, _ = lagrangian(fleet, lam)
        assert total >= best - 1e-9, (lam, total, best)


@pytest.mark.parametrize("price_step", ["uniform", "weighted", "lp"])
def test_the_fleet_solver_bounds_its_own_schedules_on_a_bridge_fleet(price_step):
    """The fleet solver on a fleet where B is a bridge and contested: its Lagrangian bound, with the bridge
    pass's bound problem, stays above the schedule it found and above the brute force, whichever the step."""
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import solve

    fleet = bridge_fleet(shared=True, weights=[1.0, 3.0, 1.0])
    sol = solve(fleet, compute(fleet, Geometry(fleet)), FleetConfig(rounds=8, time_limit=None,
                                                                    price_step=price_step))
    assert sol.info["bound_graphs"] >= 1 and sol.info["bound_refused"] == []
    best = brute_force(fleet) / fleet.tasks.weight.sum()
    assert sol.bound >= best - 1e-9 >= sol.value - 2e-9


def test_a_bound_below_a_schedule_is_refused(monkeypatch):
    """Were the pass terms wrong (here made to answer 0), the solver would not report a bound below the schedule
    it found: it refuses it, says so and keeps the conflict-free bound."""
    from eosp.kinds.fleet import pool
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.problem import PassResult, solve_round_pass
    from eosp.kinds.fleet.solve import solve
    from tests.test_fleet import synthetic_fleet

    def wrong(pg, value, spec, budget):
        res = solve_round_pass(pg, value, spec, budget)
        return PassResult(res.nodes, res.value, 0.0)

    monkeypatch.setattr(pool, "solve_round_pass", wrong)
    fleet = synthetic_fleet(n_tasks=40, seed=3)  # not every task can be served: price rounds run
    sol = solve(fleet, compute(fleet, Geometry(fleet)), FleetConfig(rounds=2, time_limit=None))
    assert sol.info["bound_refused"] and "below the schedule found" in sol.info["bound_refused"][0]
    assert sol.info["bound_source"] == "conflict-free" and sol.bound >= sol.value
    assert sol.info["no_lagrangian_bound_because"].startswith("refused:")


def _decisions(monkeypatch, fleet) -> list[tuple[bool, bool]]:
    """(what build_pass decided about a bridge triple, what the exhaustive count says) for every pass whose loose
    graph is FIFO and equal to its pass graph (the passes where the question is asked)."""
    from eosp.fleet import passgraph

    seen = []
    fast = passgraph.has_bridge_triple

    def record(graph, tracking_fits=False):
        decided = fast(graph, tracking_fits)
        seen.append((decided, bridge_triples(graph) > 0, tracking_fits))
        return decided

    monkeypatch.setattr(passgraph, "has_bridge_triple", record)
    geo = Geometry(fleet)
    build_passes(fleet, compute(fleet, geo), LineOfSight(fleet, geo))
    return seen


def test_the_tracking_argument_skips_only_rows_without_bridge_triples(monkeypatch):
    """build_pass searches only the source's row for bridge triples when every observation turns the line of sight
    slower than a slew could (has_bridge_triple's triangle argument): on a generated fleet (where it holds and the
    search is cut to one row) and on the bridge fleet (built so that a tracking observation is a bridge: it must
    not hold there) its answer is the exhaustive count's."""
    from eosp.fleet.generate import FleetGenConfig, generate

    gen = _decisions(monkeypatch, generate(FleetGenConfig(satellites=6, tasks=500, hours=4.0, window_min_h=1.0,
                                                          window_max_h=3.0)))
    assert len(gen) > 10 and all(d == exact for d, exact, _ in gen)
    assert any(t for _, _, t in gen)  # the shortcut is taken
    assert all(d == exact for d, exact, _ in _decisions(monkeypatch, bridge_fleet()))
    # the bridge fleet's chain pass has bridge triples (its bound graph is kept for them): the argument must
    # not hold there, else the shortcut would have missed them
    from eosp.fleet.passgraph import _tracking_fits, has_bridge_triple, tracking_slack
    from eosp.fleet.slew import MARGIN_S

    fleet = bridge_fleet()
    geo = Geometry(fleet)
    los = LineOfSight(fleet, geo)
    (pg,) = [pg for pg in build_passes(fleet, compute(fleet, geo), los) if pg.satellite == 0]
    g = pg.bound_graph
    acq = g.node_acq[1:]
    end = np.r_[0.0, g.node_time[1:] + pg.duration[acq]]
    los_start = np.vstack([np.zeros((1, 3)), los.los(0, pg.tasks[acq], g.node_time[1:])])
    los_end = np.vstack([np.zeros((1, 3)), los.los(0, pg.tasks[acq], end[1:])])
    att = fleet.satellites.attitude
    slew = np.array([att.max_rate_deg_s[0], att.max_acc_deg_s2[0], att.settling_s[0]])
    fits = _tracking_fits(los_start, los_end, g.node_time, end, slew, MARGIN_S + NUMERICAL_EPS, tracking_slack(slew))
    assert bridge_triples(g) > 0 and not fits and has_bridge_triple(g, fits)


def test_both_graphs_of_a_pass_are_the_earliest_followers_by_their_margins():
    """fleet.passgraph._arcs builds the schedule's graph and the loose graph in one scan: each arc checked against
    the definition, node by node in Python (the earliest node of each acquisition starting after u ends whose gap
    covers the slew plus settling, + the margin for the schedule's graph, - it for the loose one, which also has
    later starts of u's own acquisition), and `same` against a comparison of the arc sets."""
    from eosp.fleet.generate import FleetGenConfig, generate
    from eosp.fleet.passgraph import _arcs, _need
    from eosp.fleet.slew import MARGIN_S

    fleet = generate(FleetGenConfig(satellites=3, tasks=1500, hours=3.0, window_min_h=1.0, window_max_h=2.0, seed=4))
    geo = Geometry(fleet)
    los = LineOfSight(fleet, geo)
    m = MARGIN_S + NUMERICAL_EPS
    checked = 0
    for pg in build_passes(fleet, compute(fleet, geo), los):
        g = pg.graph
        acq, t = g.node_acq, g.node_time
        end = np.r_[0.0, t[1:] + pg.duration[acq[1:]]]
        ls = np.vstack([np.zeros((1, 3)), los.los(pg.satellite, pg.tasks[acq[1:]], t[1:])])
        le = np.vstack([np.zeros((1, 3)), los.los(pg.satellite, pg.tasks[acq[1:]], end[1:])])
        nadir = np.vstack([np.zeros((1, 3)), los.nadir(pg.satellite, t[1:])])
        att = fleet.satellites.attitude
        slew = np.array([att.max_rate_deg_s[pg.satellite], att.max_acc_deg_s2[pg.satellite],
                         att.settling_s[pg.satellite]])
        ip_s, dst_s, ip_l, dst_l, same = _arcs(g.acq_ptr, t, end, ls, le, nadir, slew, m)
        assert np.array_equal(ip_s, g.indptr) and np.array_equal(dst_s, g.dst)
        rows = {}
        for u in range(g.n_nodes):
            for margin, ip, dst, repeats in ((m, ip_s, dst_s, False), (-m, ip_l, dst_l, True)):
                want = []
                for b in range(g.n_acq):
                    if u and b == acq[u] and not repeats:
                        continue
                    for v in range(g.acq_ptr[b], g.acq_ptr[b + 1]):
                        if u == 0:
                            ok = t[v] >= _need(nadir[v], ls[v], *slew) + margin
                        else:
                            ok = t[v] >= end[u] and t[v] - end[u] >= _need(le[u], ls[v], *slew) + margin
                        if ok:
                            want.append(v)
                            break
                assert dst[ip[u]:ip[u + 1]].tolist() == want, (pg.pass_id, u, margin)
                rows[u, repeats] = [v for v in want if not u or acq[v] != acq[u]] if repeats else want
                checked += 1
        assert same == all(rows[u, True] == rows[u, False] for u in range(g.n_nodes))
    assert checked > 400


@pytest.mark.parametrize("weights", [[1.0, 3.0, 1.0], [2.0, 1.0, 2.0]])
def test_the_ceiling_prices_bound_the_brute_force_and_stay_below_conflict_free(weights):
    """Every contested task priced at its weight: L is at least the best any schedule serves (brute force on
    the checker's rules, bridges kept) and never above the conflict-free bound; the solver keeps the lower."""
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.problem import Problem

    fleet = bridge_fleet(shared=True, weights=weights)
    prob = Problem.build(fleet, compute(fleet, Geometry(fleet)))
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
    free = coord.conflict_free()
    ceiling = ceiling_round(coord, UNLIMITED)
    best = brute_force(fleet)
    lam = ceiling_prices(coord)
    assert lam[[len(h) > 1 for h in prob.task_passes]].tolist() == fleet.tasks.weight[
        [len(h) > 1 for h in prob.task_passes]].tolist() and lam.sum() > 0
    assert best - 1e-9 <= ceiling <= free + 1e-9
    assert coord.best_bound == pytest.approx(min(free, ceiling))


def test_the_ceiling_bound_is_below_conflict_free_where_passes_are_crowded():
    """A pass that cannot take all the tasks only it can serve: L at the ceiling prices is below the
    conflict-free bound, and a solve's bound is never above it."""
    from eosp.fleet.generate import FleetGenConfig, generate
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.problem import Problem
    from eosp.kinds.fleet.solve import solve

    fleet = generate(FleetGenConfig(satellites=3, tasks=400, hours=3.0, placement="cities", seed=5))
    opps = compute(fleet)
    prob = Problem.build(fleet, opps)
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
    ceiling = ceiling_round(coord, UNLIMITED)
    assert ceiling < coord.conflict_free() - 1e-6
    sol = solve(fleet, opps, FleetConfig(rounds=3, time_limit=None), problem=prob)
    W = fleet.tasks.weight.sum()
    assert sol.check.valid and sol.value - 1e-9 <= sol.bound <= ceiling / W + 1e-9


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), share=st.floats(0.1, 1.0))
def test_the_weighted_step_moves_each_price_in_proportion_to_its_weight(seed, share):
    """Polyak's step in the metric of the weights: from prices proportional to the weights, the tasks that no
    pass serves all lose the same share of their price, those served twice gain the same share, and the step
    closes the same gap as the uniform one (sum of scale * g * move = target)."""
    from eosp.kinds.lagrange import Prices

    rng = np.random.default_rng(seed)
    w = rng.integers(1, 10, 40).astype(np.float64)
    served = rng.integers(0, 3, 40).astype(np.float64)
    prices = Prices(share * w)
    prices.step_towards(served, dual=10.0, best=9.0, scale=w)
    ratio = prices.lam / (share * w)
    for k in (0, 2):
        moved = ratio[served == k]
        if len(moved):
            assert np.allclose(moved, moved[0])
    assert np.allclose(ratio[served == 1], 1.0)
    g = 1.0 - served
    assert float(g @ (share * w - prices.lam)) == pytest.approx(1.0) or (prices.lam == 0).any()
