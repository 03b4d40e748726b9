"""Window re-planning (planning/windows.py, its sweep planning/labels.window_sweep): exact over a whole small horizon, feasible and never worse elsewhere."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eosp.envs.sources import prepare_instance
from eosp.instances.schedule import check, from_internal_nodes
from eosp.search.polish import Polisher
from eosp.planning.chain import graph_arrays
from eosp.planning.labels import Sweep, scratch, window_sweep
from eosp.planning.windows import WindowPlan
from eosp.solvers.base import objective_weights, run_solver
from tests.conftest import generated
from tests.test_polish import _random_episode


def _plan(pol: Polisher, u: int, e: int, blocked: np.ndarray, beam: int, max_work: int = 10**9):
    g = pol.eg
    sc = scratch(g, beam, max_work)
    sc.blocked[:] = blocked
    sc.calls[0] = 1
    sw = Sweep(pol.weight, pol.key, pol.span, pol.by_time, pol.sorted_t, pol.tol, max_work)
    m, value = window_sweep(graph_arrays(g), sw, sc, u, e, beam, np.zeros(1, np.int64))
    return sc.seg[:m].copy(), value


@pytest.mark.parametrize("family,seed,mode", [("uniform", 0, "unitary"), ("conflict", 1, "utility"),
                                              ("clusters", 2, "unitary"), ("conflict", 3, "unitary")])
def test_a_window_over_the_whole_horizon_with_a_wide_beam_finds_the_optimum(family, seed, mode):
    """From the source with no end node, the window's label sweep is a dynamic program over the whole unpruned
    graph; with room for every label it must agree with the exact solver (a different algorithm: Lagrangian
    bounds and open-set dominance)."""
    inst = generated(family, 16, seed)
    pol = Polisher(inst.unpruned(), objective_weights(inst, mode))
    nodes, value = _plan(pol, 0, -1, np.zeros(inst.n_acq, dtype=np.bool_), beam=512)
    exact = run_solver("exact", inst, mode=mode)
    assert exact.info.get("status", "optimal") == "optimal"
    assert value == pytest.approx(exact.value, rel=1e-12)
    assert pol.value(nodes) == pytest.approx(value, rel=1e-12)
    assert check(inst, from_internal_nodes(inst, nodes)).feasible


def test_a_window_respects_its_anchors_and_the_blocked_acquisitions():
    inst = generated("uniform", 40, 4)
    pol = Polisher(inst.unpruned(), objective_weights(inst, "unitary"))
    ramp = run_solver("ramp", inst, mode="unitary").nodes
    s, r = 2, 3
    blocked = np.zeros(inst.n_acq, dtype=np.bool_)
    blocked[inst.node_acq[ramp]] = True
    blocked[inst.node_acq[ramp[s:s + r]]] = False
    seg, value = _plan(pol, int(ramp[s - 1]), int(ramp[s + r]), blocked, beam=8)
    assert value >= r  # the old stretch is one of the plans
    t = pol.eg.node_time
    assert np.all(t[seg] > t[ramp[s - 1]]) and np.all(t[seg] < t[ramp[s + r]])
    assert not blocked[inst.node_acq[seg]].any()
    last = seg[-1] if seg.size else ramp[s - 1]
    x = pol.eg.successor(int(last), int(inst.node_acq[ramp[s + r]]))
    assert x >= 0 and t[x] <= t[ramp[s + r]]  # the next kept acquisition is reached no later than before


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(family=st.sampled_from(["uniform", "clusters", "conflict"]), seed=st.integers(0, 3),
       walk=st.integers(0, 10_000), mode=st.sampled_from(["unitary", "utility"]), span=st.integers(1, 8),
       beam=st.integers(1, 6), max_work=st.sampled_from([50, 5_000, 3_000_000]),
       budget=st.sampled_from([0, 20_000, 10**12]), pruned_windows=st.booleans(), long_span=st.sampled_from([0, 40]),
       long_beam=st.sampled_from([1, 2, 16]))
def test_window_rounds_keep_random_schedules_feasible_and_never_worse(family, seed, walk, mode, span, beam, max_work,
                                                                      budget, pruned_windows, long_span, long_beam):
    """Random windows (some aborted for their cost; with `long_span`, half of them long ones with `long_beam`
    labels per node) over random complete episodes, planned over the unpruned or the pruned graph's arcs: the
    result is a path of the unpruned graph (the walk from its acquisitions gives it back), each acquisition at
    most once, feasible for the independent checker, and its value never below the start's."""
    inst = generated(family, 40, seed)
    prepared = prepare_instance(inst, True)
    pol = Polisher(inst.unpruned(), objective_weights(inst, mode), window=span, window_beam=beam,
                   window_graph=inst.pruned() if pruned_windows else None)
    nodes = _random_episode(prepared, np.random.default_rng(walk))
    path = np.zeros(inst.n_acq + 1, dtype=np.int32)
    path[: nodes.size] = nodes
    sw = Sweep(pol.weight, pol.key, pol.span, pol.by_time, pol.sorted_t, pol.tol, max_work)
    plan = WindowPlan(span, beam, long_span, long_beam, 200, walk, budget)
    n, tried, aborted, arcs, long_tried, long_aborted = pol._repair(
        graph_arrays(pol.eg), graph_arrays(pol.wg), sw, path, nodes.size, plan,
        scratch(pol.wg, max(beam, long_beam), max_work))
    out = path[:n]
    assert 0 <= aborted <= tried <= 200 and arcs >= 0
    assert 0 <= long_aborted <= long_tried <= tried and long_aborted <= aborted
    assert long_span > span or long_tried == 0
    if budget < 10**9:  # the arcs budget stops the round (after the window that crossed it)
        assert tried == 200 or arcs >= budget
    # never worse, up to the rounding of sums in another order (values reach 2e6 in utility mode: 2.6e-8 seen)
    assert pol.value(out) >= pol.value(nodes) - 1e-12 * max(1.0, abs(pol.value(nodes)))
    assert len(set(inst.node_acq[out].tolist())) == n
    assert list(pol.nodes_of(inst.node_acq[out])) == list(out)
    verdict = check(inst, from_internal_nodes(inst, out))
    assert verdict.feasible, verdict.reason


@pytest.mark.parametrize("pruned_windows", [False, True])
def test_refine_with_windows_is_deterministic_and_at_least_as_good_on_a_conflict_instance(pruned_windows):
    inst = generated("conflict", 60, 6)
    pol = Polisher(inst.unpruned(), objective_weights(inst, "unitary"),
                   window_graph=inst.pruned() if pruned_windows else None)
    greedy = run_solver("greedy", inst, mode="unitary")
    a = pol.refine(greedy.nodes, iterations=256, seed=1, windows=True)
    assert pol.window_rounds > 0
    b = pol.refine(greedy.nodes, iterations=256, seed=1, windows=True)
    assert list(a) == list(b)
    assert check(inst, from_internal_nodes(inst, a)).feasible
    assert pol.value(a) >= pol.value(pol(greedy.nodes)) - 1e-9
