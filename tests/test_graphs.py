"""Graph invariants: arcs follow the simulator's transition times, earliest successors, pruning."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eosp.config import family_config
from eosp.graphs.continuous import continuous_graph
from eosp.graphs.prune import fifo_violations, paper_prune, prune
from eosp.instances.generator import generate, scenario_of
from eosp.planning.labels import label_search
from eosp.solvers.base import objective_weights
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


def _gap(g, d):
    """Brute force: the smallest transition t_dst - (t_src + d_src) over the arcs not out of the source."""
    gaps = [g.node_time[w] - g.node_time[u] - d[g.node_acq[u]]
            for u in range(1, g.n_nodes) for w in g.dst[g.indptr[u]:g.indptr[u + 1]]]
    return max(0.0, min(gaps, default=0.0))


def _fifo_violations(g):
    """Brute force: pairs (a later start v of an acquisition, an acquisition b) where v reaches b and the
    start just before v does not, or reaches it later."""
    def arc(u, b):
        row = g.dst[g.indptr[u]:g.indptr[u + 1]]
        hit = row[g.node_acq[row] == b]
        return int(hit[0]) if hit.size else -1

    count = 0
    for v in range(2, g.n_nodes):
        u = v - 1
        if g.node_acq[u] != g.node_acq[v]:
            continue
        for b in range(g.n_acq):
            late = arc(v, b)
            early = arc(u, b)
            count += late >= 0 and (early < 0 or g.node_time[early] > g.node_time[late])
    return count


def _witness(g, d, u, v, gap, fifo):
    """Brute force of the lossless rule: some k != acq(v) that no path visits before u nor after v, with
    u -> (k, t_k) -> (j, t') and t' = t_v (t' <= t_v when the graph is FIFO)."""
    j = g.node_acq[v]
    for a in range(g.indptr[u], g.indptr[u + 1]):
        vk = g.dst[a]
        k = g.node_acq[vk]
        if k == j:
            continue
        first, last = g.node_time[g.acq_ptr[k]], g.node_time[g.acq_ptr[k + 1] - 1]
        if u != 0 and first + d[k] + gap <= g.node_time[u]:
            continue  # k could have been visited before u
        if last >= g.node_time[v] + d[j] + gap:
            continue  # k could be visited after v
        row = g.dst[g.indptr[vk]:g.indptr[vk + 1]]
        hit = row[g.node_acq[row] == j]
        if hit.size and (g.node_time[hit[0]] == g.node_time[v] or (fifo and g.node_time[hit[0]] < g.node_time[v])):
            return True
    return False


def _check_pruning(inst):
    g, d = inst.unpruned(), inst.acqs.duration
    p = prune(g, d)
    fifo = _fifo_violations(g)
    assert fifo_violations(g) == fifo
    gap = _gap(g, d)
    kept = set(zip(p.src().tolist(), p.dst.tolist()))
    assert kept <= set(zip(g.src().tolist(), g.dst.tolist()))
    for u, v in zip(g.src().tolist(), g.dst.tolist()):
        assert ((u, v) not in kept) == _witness(g, d, u, v, gap, fifo == 0), (u, v)
    # the paper's rule removes every arc this one removes, and more
    paper = set(zip(*(lambda q: (q.src().tolist(), q.dst.tolist()))(paper_prune(g, d))))
    assert paper <= kept
    return p


def test_pruning_removes_exactly_the_arcs_with_a_witness():
    p = _check_pruning(generated("clusters", 10, 1, 4.0))
    assert 0 < p.n_arcs < generated("clusters", 10, 1, 4.0).unpruned().n_arcs


@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 7), seed=st.integers(0, 10_000), period=st.sampled_from([37.0, 2.0]))
def test_pruning_property_on_synthetic_instances(n, seed, period):
    _check_pruning(synthetic_instance(n, seed, period=period))


def test_fast_drifting_transitions_are_not_fifo():
    """A transition that drifts faster than time breaks FIFO: the rule's fallback (same node only) is tested."""
    assert not any(fifo_violations(synthetic_instance(7, s).unpruned()) for s in range(10))
    assert sum(fifo_violations(synthetic_instance(7, s, period=2.0).unpruned()) > 0 for s in range(10)) >= 5


def _lossless(inst):
    g, pg = inst.unpruned(), inst.pruned()
    for mode in ("utility", "unitary"):
        w = objective_weights(inst, mode)
        assert label_search(pg, w, beam=0).value == label_search(g, w, beam=0).value, mode


@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 9), seed=st.integers(0, 100_000), period=st.sampled_from([37.0, 2.0]))
def test_the_pruned_graph_keeps_the_optimum_of_synthetic_instances(n, seed, period):
    """The MDP's best (the exact DP on the pruned graph) is the unpruned optimum, FIFO or not."""
    _lossless(synthetic_instance(n, seed, period=period))


@settings(max_examples=15, deadline=None)
@given(n=st.integers(10, 40), seed=st.integers(0, 100_000), family=st.sampled_from(["uniform", "clusters", "conflict"]),
       slew=st.sampled_from(["piecewise", "bang_coast_bang"]))
def test_the_pruned_graph_keeps_the_optimum_of_generated_instances(n, seed, family, slew):
    _lossless(generate(family_config(family, n, seed, satellite={"slew_model": slew})))


def test_the_papers_rule_loses_what_this_one_keeps():
    """Seed 900002 at 50 acquisitions: the paper's rule leaves the MDP about a third of the optimum."""
    inst = generate(family_config("uniform", 50, 900002))
    g, w = inst.unpruned(), objective_weights(inst, "utility")
    opt = label_search(g, w, beam=0).value
    assert label_search(paper_prune(g, inst.acqs.duration), w, beam=0).value < 0.5 * opt
    assert label_search(inst.pruned(), w, beam=0).value == opt
    assert label_search(inst.pruned(), w, beam=4).value >= label_search(g, w, beam=4).value


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
