"""Graph invariants: arcs follow the simulator's transition times, earliest successors, pruning."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eosp.graphs.continuous import continuous_graph
from eosp.graphs.prune import prune
from eosp.instances.generator import scenario_of
from eosp.sim.geometry import rotation_angle_deg
from eosp.sim.slew import slew_times
from tests.conftest import generated
from tests.synthetic import synthetic_instance


def _independent_attitudes(inst):
    """Start and end attitudes of every node, recomputed from the geometry."""
    scn = scenario_of(inst)
    g, a = inst.unpruned(), inst.acqs
    k = g.node_acq[1:]
    r0, p0 = scn.attitude(a.lat[k], a.lon[k], g.node_time[1:])
    r1, p1 = scn.attitude(a.lat[k], a.lon[k], g.node_time[1:] + a.duration[k])
    att = np.zeros((g.n_nodes, 4))
    att[1:] = np.stack([r0, p0, r1, p1], axis=1)
    return scn, att


def _feasible(scn, att, inst, u, w):
    g, d = inst.unpruned(), inst.acqs.duration
    fin = g.node_time[u] + d[g.node_acq[u]]
    ang = rotation_angle_deg(att[w, 0] - att[u, 2], att[w, 1] - att[u, 3])
    return g.node_time[w] - fin >= slew_times(np.atleast_1d(ang), scn.slew_model)[0] - 1e-6


@pytest.mark.parametrize("slew", ["piecewise", "bang_coast_bang"])
def test_arcs_respect_simulator_and_are_earliest(slew):
    inst = generated("clusters", 12, 4, 2.0, slew)
    scn, att = _independent_attitudes(inst)
    g, d = inst.unpruned(), inst.acqs.duration
    src = g.src()
    real = src > 0
    u, w = src[real], g.dst[real]
    fin = g.node_time[u] + d[g.node_acq[u]]
    ang = rotation_angle_deg(att[w, 0] - att[u, 2], att[w, 1] - att[u, 3])
    assert np.all(g.node_time[w] - fin >= slew_times(ang, scn.slew_model) - 1e-6)
    # earliest: the previous node of the same acquisition is not reachable in time
    prev = w - 1
    has_prev = g.node_acq[prev] == g.node_acq[w]
    for uu, pp in zip(u[has_prev], prev[has_prev]):
        assert not _feasible(scn, att, inst, uu, pp)
    # complete: no arc to j means no node of j is reachable
    rng = np.random.default_rng(0)
    for uu in rng.choice(np.arange(1, g.n_nodes), 60, replace=False):
        have = set(g.node_acq[g.dst[g.indptr[uu]:g.indptr[uu + 1]]].tolist())
        for j in range(inst.n_acq):
            if j == g.node_acq[uu] or j in have:
                continue
            for ww in range(g.acq_ptr[j], g.acq_ptr[j + 1]):
                assert not _feasible(scn, att, inst, uu, ww)


def test_source_reaches_first_node_of_every_acquisition():
    g = generated("uniform", 12, 0).unpruned()
    np.testing.assert_array_equal(g.dst[g.indptr[0]:g.indptr[1]], g.acq_ptr[:-1])


def _insertable(g, d, u, v):
    """Brute force: some k != acq(v) with u -> (k, t_k) -> (j, t') and t' <= t_v."""
    j = g.node_acq[v]
    for a in range(g.indptr[u], g.indptr[u + 1]):
        k = g.dst[a]
        if g.node_acq[k] == j:
            continue
        row = g.dst[g.indptr[k]:g.indptr[k + 1]]
        hit = row[g.node_acq[row] == j]
        if hit.size and g.node_time[hit[0]] <= g.node_time[v]:
            return True
    return False


def _check_pruning(inst):
    g, d = inst.unpruned(), inst.acqs.duration
    p = prune(g, d)
    kept = set(zip(p.src().tolist(), p.dst.tolist()))
    assert kept <= set(zip(g.src().tolist(), g.dst.tolist()))
    for u, v in zip(g.src().tolist(), g.dst.tolist()):
        assert ((u, v) not in kept) == _insertable(g, d, u, v), (u, v)
    return p


def test_pruning_removes_exactly_the_arcs_with_an_insertable_k():
    p = _check_pruning(generated("clusters", 10, 1, 4.0))
    assert p.n_arcs > 0


@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 7), seed=st.integers(0, 10_000))
def test_pruning_property_on_synthetic_instances(n, seed):
    _check_pruning(synthetic_instance(n, seed))


@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 8), seed=st.integers(0, 10_000))
def test_continuous_graph_is_the_set_of_acquisition_pairs(n, seed):
    inst = synthetic_instance(n, seed)
    g = inst.pruned()
    s, t = continuous_graph(g)
    src = g.src()
    real = src > 0
    expected = set(zip(g.node_acq[src[real]].tolist(), g.node_acq[g.dst[real]].tolist()))
    assert set(zip(s.tolist(), t.tolist())) == expected
    assert len(expected) == s.size  # no duplicates
    alive = np.random.default_rng(seed).random(g.n_nodes) < 0.5
    s2, t2 = continuous_graph(g, alive)
    ok = alive[src] & alive[g.dst] & real
    assert set(zip(s2.tolist(), t2.tolist())) == set(zip(g.node_acq[src[ok]].tolist(),
                                                         g.node_acq[g.dst[ok]].tolist()))
