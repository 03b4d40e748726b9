"""A lean fleet problem (the driver of Ray's actors: passes without arcs) and the construction in waves.

The driver that keeps no arcs re-walks paths from the geometry (eosp.fleet.passgraph.walk) and has every pass
solved by the pool; the schedule must be the one a driver holding every graph finds.  The first schedule's
construction solves passes in waves of passes that share no task with any pass before them: the same schedule as
one pass after the other."""

from __future__ import annotations

import numpy as np
import pytest

from eosp.fleet.check import validate
from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.geometry import Geometry
from eosp.fleet.opportunities import compute
from eosp.fleet.passgraph import build_pass, walk
from eosp.kinds.fleet.config import FleetConfig
from eosp.kinds.fleet.coordinator import Coordinator
from eosp.kinds.fleet.pool import InProcessPool
from eosp.kinds.fleet.problem import PassSpec, Primal, Problem, rewalk, solve_pass
from eosp.kinds.fleet.solve import solve
from eosp.kinds.fleet.construct import construct, wave


def crowded_fleet(seed: int):
    """Tasks in clusters with long windows: passes of up to 70 tasks and 450 opportunities, paths of several."""
    f = generate(FleetGenConfig(satellites=4, tasks=2000, hours=6.0, window_min_h=2.0, window_max_h=6.0, seed=seed,
                                placement="clusters"))
    return f, compute(f, Geometry(f))


@pytest.fixture(scope="module")
def pair():
    """The same fleet as a full problem and as a lean one."""
    f, opps = crowded_fleet(3)
    geo = Geometry(f)
    return Problem.build(f, opps, geo), Problem.build(f, opps, geo, lean=True)


def test_a_lean_pass_has_the_nodes_of_the_full_one_and_no_arcs(pair):
    full, lean = pair
    assert lean.lean and not full.lean and len(lean.passes) == len(full.passes) > 0
    for a, b in zip(full.passes, lean.passes):
        for x in ("tasks", "rows", "duration", "energy_wh"):
            assert np.array_equal(getattr(a, x), getattr(b, x))
        for x in ("node_acq", "node_time", "acq_ptr"):
            assert np.array_equal(getattr(a.graph, x), getattr(b.graph, x))
        assert b.graph.n_arcs == 0 and b.bound_graph is None
    assert np.array_equal(full.pass_time, lean.pass_time)
    arcs = sum(pg.graph.indptr.nbytes + pg.graph.dst.nbytes + (0 if pg.bound_graph is None else
                                                               pg.bound_graph.dst.nbytes + pg.bound_graph.indptr.nbytes)
               for pg in full.passes)  # what a lean pass leaves out (its indptr: zeros, a view of one)
    assert arcs > 0 and sum(pg.nbytes for pg in lean.passes) == sum(pg.nbytes for pg in full.passes) - arcs
    assert lean.bound_graphs is None and full.bound_graphs is not None


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_walking_from_the_geometry_finds_the_arcs_nodes(pair, seed):
    """Paths as the coordinator re-walks them (a solver's path under random utilities, some of its observations
    taken out, some moved to a later opportunity of their task) and random node sets, re-walked along the arcs and
    from the geometry: the same nodes."""
    full, lean = pair
    rng = np.random.default_rng(seed)
    tried = 0
    big = np.argsort([-pg.n_tasks for pg in full.passes], kind="stable")[:12]  # the passes of most tasks
    for p in rng.permutation(big).tolist():
        pg = full.passes[p]
        g = pg.graph
        for k in range(30):
            if k % 3 == 2:  # any nodes, one per random task
                acqs = rng.permutation(pg.n_tasks)[:rng.integers(1, pg.n_tasks + 1)]
                nodes = np.array([rng.integers(g.acq_ptr[a], g.acq_ptr[a + 1]) for a in acqs.tolist()])
            else:
                path = solve_pass(full, p, rng.uniform(0.1, 1.0, pg.n_tasks), PassSpec()).nodes
                nodes = path[rng.random(len(path)) < 0.7]
                later = np.minimum(nodes + rng.integers(0, 3, len(nodes)), g.acq_ptr[g.node_acq[nodes] + 1] - 1)
                nodes = later if k % 3 == 1 else nodes
            nodes = nodes.astype(np.int64)[np.argsort(g.node_time[nodes], kind="stable")]
            along = rewalk(pg, nodes)
            assert np.array_equal(walk(lean.fleet, lean.opps, lean.los, lean.passes[p], nodes), along)
            assert np.array_equal(lean.rewalk(p, nodes), along)
            tried += len(along) > 1
    assert tried > 200  # most walks keep several observations: the slew rule was exercised


def test_a_lean_problem_builds_a_graph_only_for_a_pass_it_solves(pair):
    full, lean = pair
    lean.built.clear()
    p = int(np.argmax([pg.n_tasks for pg in full.passes]))
    value = full.weight[full.passes[p].tasks]
    a, b = solve_pass(full, p, value, PassSpec()), solve_pass(lean, p, value, PassSpec())
    assert np.array_equal(a.nodes, b.nodes) and a.value == b.value
    assert list(lean.built) == [p]
    assert np.array_equal(lean.graph(p).graph.dst, full.passes[p].graph.dst)


def test_the_arcs_keep_their_nodes_in_uint16(pair):
    full, _ = pair
    assert all(pg.graph.dst.dtype == np.uint16 for pg in full.passes)
    f, opps = full.fleet, full.opps
    pg = build_pass(f, opps, full.los, 0, opps.pass_offsets())
    assert np.array_equal(pg.graph.dst, full.passes[0].graph.dst)


def one_by_one(coord: Coordinator, order: np.ndarray, shift: np.ndarray | None) -> Primal:
    """The construction as it was: passes in `order`, each solved alone with the tasks still free."""
    primal = Primal.empty(len(coord.prob.passes), len(coord.prob.weight))
    for p in order.tolist():
        res = solve_pass(coord.prob, p, coord._utility(primal, p, shift), coord.spec)
        coord._assign(primal, p, res.nodes)
    return primal


@pytest.mark.parametrize("seed", [0, 1])
def test_the_construction_in_waves_is_the_one_by_one_construction(pair, seed):
    full, _ = pair
    coord = Coordinator(full, FleetConfig(rounds=1, time_limit=None))
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(full.passes))
    shift = full.weight * rng.uniform(0.0, 1.0, len(full.weight)) if seed else None
    waves = construct(coord, order, shift)
    alone = one_by_one(coord, order, shift)
    assert [p.tolist() for p in waves.paths] == [p.tolist() for p in alone.paths]
    assert np.array_equal(waves.served, alone.served) and waves.value == alone.value > 0
    # each wave: no pass shares a task with a pass before it in the order still waiting
    take = wave(order, coord._task_ptr, coord._task_idx, coord._claimed)
    assert take[0] and not coord._claimed.any()
    seen: set[int] = set()
    for p, t in zip(order.tolist(), take.tolist()):
        tasks = set(full.passes[p].tasks.tolist())
        assert t == (not tasks & seen)
        seen |= tasks


def test_a_lean_driver_finds_the_schedule_of_a_driver_holding_every_graph(pair, monkeypatch):
    """Fixed rounds: a lean problem whose passes a pool solves on the full graphs (as Ray's actors do) gives the
    schedule, value, bound and solve count of the full problem solved in this process."""
    import eosp.kinds.fleet.problem as problem_mod

    full, lean = pair
    cfg = FleetConfig(rounds=4, seed=1, time_limit=None)
    here = solve(full.fleet, full.opps, cfg, problem=full)
    lean.built.clear()
    walks = []
    monkeypatch.setattr(problem_mod, "walk", lambda *a: walks.append(1) or walk(*a))
    away = solve(lean.fleet, lean.opps, cfg, problem=lean, pool=InProcessPool(full, cfg))
    assert walks  # paths were re-walked on the lean driver (conflicts settled, the battery repaired)
    assert away.schedule.task.tolist() == here.schedule.task.tolist()
    assert np.array_equal(away.schedule.start_us, here.schedule.start_us)
    assert (away.value, away.bound, away.info["pass_solves"]) == (here.value, here.bound, here.info["pass_solves"])
    assert not lean.built  # the driver built no graph: every solve went to the pool
    assert validate(full.fleet, away.schedule, full.geo).valid


def restricted_by_definition(g, keep_acq):
    """A graph restricted to some acquisitions, node by node: the source and the kept acquisitions' nodes in their
    order, each kept acquisition renumbered by its rank, the arcs between kept nodes in their order."""
    kept = [v for v in range(g.n_nodes) if v == 0 or keep_acq[g.node_acq[v]]]
    new = {v: i for i, v in enumerate(kept)}
    rank = np.cumsum(keep_acq) - 1
    node_acq = [-1] + [int(rank[g.node_acq[v]]) for v in kept[1:]]
    indptr, dst = [0], []
    for v in kept:
        dst += [new[int(w)] for w in g.dst[g.indptr[v]:g.indptr[v + 1]] if int(w) in new]
        indptr.append(len(dst))
    acq_ptr = [1 + sum(1 for a in node_acq[1:] if a < b) for b in range(int(keep_acq.sum()) + 1)]
    return kept, node_acq, indptr, dst, acq_ptr


@pytest.mark.parametrize("seed", [0, 1])
def test_a_priced_pass_keeps_the_graph_between_its_positive_tasks(pair, seed):
    """The priced problem's graph (one kernel, :func:`eosp.fleet.passgraph._subgraph`) is the pass graph restricted
    to the tasks of positive utility, by definition, on every pass of the crowded fleet (uint16 arcs) under random
    masks; and the label search's bound on its open sets (:func:`eosp.planning.labels.max_open`) is its formula."""
    from eosp.fleet.passgraph import _subgraph
    from eosp.planning.labels import max_open

    full, _ = pair
    rng = np.random.default_rng(seed)
    for pg in full.passes:
        g = pg.graph
        for q in (0.2, 0.6, 1.0):
            keep = rng.random(pg.n_tasks) < q
            if not keep.any():
                continue
            sub, nodes = _subgraph(g, keep)
            kept, node_acq, indptr, dst, acq_ptr = restricted_by_definition(g, keep)
            assert nodes.tolist() == kept and sub.node_acq.tolist() == node_acq
            assert sub.indptr.tolist() == indptr and sub.dst.tolist() == dst and sub.acq_ptr.tolist() == acq_ptr
            assert np.array_equal(sub.node_time, g.node_time[kept])
            span = max(sub.node_time[sub.acq_ptr[a + 1] - 1] - sub.node_time[sub.acq_ptr[a]] for a in range(sub.n_acq))
            gaps = [sub.node_time[w] - sub.node_time[v] for v in range(1, sub.n_nodes)
                    for w in sub.dst[sub.indptr[v]:sub.indptr[v + 1]]]
            assert max_open(sub) == (int(np.floor(span / max(min(gaps), 1e-9))) + 2 if gaps else 1)
