"""The paper's optimality pruning of the discrete graph, made lossless.

The paper removes the arc u = (i, t_i) -> v = (j, t_j) when some other acquisition k can be inserted
between them (u has an arc to (k, t_k) and (k, t_k) has an arc to (j, t'_j) with t'_j <= t_j): an optimal
schedule would rather visit k in between.  As stated this loses schedules: when k was visited before u the
direct arc is gone, and the MDP, RAMP and every search on the pruned graph can dead-end far below the
instance's optimum; and it assumes that reaching j earlier is never worse, which transitions that are not
FIFO break.  Here an acquisition k is a *witness* that removes u -> v only when

1. k cannot be visited before u on any path: its earliest finish plus the shortest transition of the graph
   is after t_i (``first_start[k] + d_k + gap > t_i``; nothing precedes the source);
2. k cannot be visited after v on any path: its last start is before v's earliest successor
   (``last_start[k] < t_j + d_j + gap``);
3. the detour u -> (k, t_k) -> (j, t'_j) exists in the unpruned graph with t'_j <= t_j, and t'_j = t_j
   unless the whole graph is FIFO (:func:`fifo_violations` is 0: a later start of an acquisition never
   reaches another acquisition earlier, or at all where the earlier start cannot).

``gap`` is the smallest transition t_dst - (t_src + d_src) over all arcs, so 1 and 2 are statements about
every path.

**Guarantee.**  For every path P of the unpruned graph (each acquisition at most once) there is a path Q of
the pruned graph that visits every acquisition P visits, and more.  Proof: let u -> v be the first arc of P
that the pruning removed and k its witness.  By 1 and 2, k is not on P (P cannot visit k before u, nor after
v, and k's node is neither u nor v).  Replace u -> v by u -> (k, t_k) -> (j, t'_j) and follow P's remaining
acquisitions from (j, t'_j) by the earliest-start arcs: if t'_j = t_j these are P's own arcs; otherwise the
graph is FIFO, so each next acquisition is reached no later than on P (by induction along P), and the arcs
exist.  The new path P' is a path of the unpruned graph visiting P's acquisitions plus k.  Repeating this
strictly increases the number of acquisitions visited, so it stops, and it stops only at a path with no
removed arc.  Consequences: the best schedule of the MDP (and of an exact search) on the pruned graph
equals the unpruned optimum in both objectives (utilities are nonnegative); and from any state (a node u
and the acquisitions visited so far) where some unvisited acquisition m has an unpruned arc from u, the
pruned graph has an arc from u to an unvisited acquisition (the witness of u -> m, if pruned, is unvisited
by 1; recurse on u -> k, whose witnesses finish earlier still), so an episode never ends while an
acquisition is still insertable.

Condition 2 is what the paper's rule lacks besides 1: a witness k whose window reaches past v could be
visited later on P, and moving it forward would need the direct arc around its old place, which
time-dependent slews do not guarantee.

Algorithm, per node u: sort u's successors by their finish time t_k + d_k.  For an arc u -> (j, t_j), only
successors finishing before t_j - gap can be inserted, so they are tried in finish order and the search
stops at the first that works or at the first that finishes too late.
"""

from __future__ import annotations

import numba
import numpy as np

from eosp.graphs.discrete import DiscreteGraph, arc_to_acq


@numba.njit(cache=True)
def _smallest_gap(node_acq, node_time, indptr, dst, durations):
    """min over arcs of t_dst - (t_src + d_src), source arcs excluded; 0 when negative or no arc."""
    gap = np.inf
    for u in range(1, node_acq.shape[0]):
        fin = node_time[u] + durations[node_acq[u]]
        for a in range(indptr[u], indptr[u + 1]):
            g = node_time[dst[a]] - fin
            if g < gap:
                gap = g
    if gap == np.inf or gap < 0.0:
        gap = 0.0
    return gap


@numba.njit(cache=True)
def _fifo_violations(node_acq, node_time, indptr, dst, acq_ptr):
    # consecutive starts u < v of one acquisition: every acquisition v reaches, u must reach no later.
    # Rows are sorted by destination, hence by acquisition: one merge of the two rows.
    count = 0
    n_acq = acq_ptr.shape[0] - 1
    for a in range(n_acq):
        for u in range(acq_ptr[a], acq_ptr[a + 1] - 1):
            v = u + 1
            p = indptr[u]
            p_end = indptr[u + 1]
            for q in range(indptr[v], indptr[v + 1]):
                w = dst[q]
                b = node_acq[w]
                while p < p_end and dst[p] < acq_ptr[b]:
                    p += 1
                if p == p_end or dst[p] >= acq_ptr[b + 1] or node_time[dst[p]] > node_time[w]:
                    count += 1
    return count


def fifo_violations(graph: DiscreteGraph) -> int:
    """How often starting an acquisition later lets another acquisition start earlier (or at all) after it.

    With none, following the earliest-start arcs loses no schedule: any feasible sequence of acquisitions,
    re-timed to each one's earliest start after the previous one, stays feasible."""
    return int(_fifo_violations(graph.node_acq, graph.node_time, graph.indptr, graph.dst, graph.acq_ptr))


@numba.njit(cache=True)
def _prune(node_acq, node_time, indptr, dst, acq_ptr, durations, fifo, lossless):
    n_nodes = node_acq.shape[0]
    n_acq = acq_ptr.shape[0] - 1
    keep = np.ones(dst.shape[0], dtype=np.bool_)
    gap = _smallest_gap(node_acq, node_time, indptr, dst, durations)
    first_fin = np.empty(n_acq)  # earliest finish of each acquisition
    last_start = np.empty(n_acq)
    for k in range(n_acq):
        first_fin[k] = node_time[acq_ptr[k]] + durations[k]
        last_start[k] = node_time[acq_ptr[k + 1] - 1]
    max_deg = 0
    for u in range(n_nodes):
        max_deg = max(max_deg, indptr[u + 1] - indptr[u])
    finish = np.empty(max_deg, dtype=np.float64)
    before_ok = np.empty(max_deg, dtype=np.bool_)  # condition 1 for each successor of u
    for u in range(n_nodes):
        lo = indptr[u]
        deg = indptr[u + 1] - lo
        if deg == 0:
            continue
        for a in range(deg):
            k = node_acq[dst[lo + a]]
            finish[a] = node_time[dst[lo + a]] + durations[k]
            before_ok[a] = u == 0 or first_fin[k] + gap > node_time[u] or not lossless
        order = np.argsort(finish[:deg])
        # the earliest-finishing admissible successor k0 removes most arcs: its arc to every j is found in
        # one merge of the two sorted rows instead of one binary search per arc
        b0 = 0
        while b0 < deg and not before_ok[order[b0]]:
            b0 += 1
        v0 = -1
        f0 = np.inf
        last0 = np.inf
        p = 0
        p_end = 0
        if b0 < deg:
            v0 = dst[lo + order[b0]]
            f0 = finish[order[b0]] + gap
            last0 = last_start[node_acq[v0]]
            p = indptr[v0]
            p_end = indptr[v0 + 1]
        for a in range(deg):
            v = dst[lo + a]
            j = node_acq[v]
            tj = node_time[v]
            after = tj + durations[j] + gap if lossless else np.inf  # condition 2: a witness's last start is before this
            tried0 = f0 <= tj and last0 < after and node_acq[v0] != j
            if tried0:
                while p < p_end and dst[p] < acq_ptr[j]:
                    p += 1
                if p < p_end and dst[p] < acq_ptr[j + 1]:
                    tw = node_time[dst[p]]
                    if tw == tj or (fifo and tw < tj):
                        keep[lo + a] = False
                        continue
            for b in range(b0 + 1 if tried0 else b0, deg):
                kb = order[b]
                if finish[kb] + gap > tj:
                    break
                vk = dst[lo + kb]
                k = node_acq[vk]
                if k == j or not before_ok[kb] or last_start[k] >= after:
                    continue
                w = arc_to_acq(indptr, dst, acq_ptr, vk, j)
                if w >= 0 and (node_time[w] == tj or (fifo and node_time[w] < tj)):
                    keep[lo + a] = False
                    break
    new_indptr = np.zeros(n_nodes + 1, dtype=np.int64)
    for u in range(n_nodes):
        c = 0
        for a in range(indptr[u], indptr[u + 1]):
            if keep[a]:
                c += 1
        new_indptr[u + 1] = new_indptr[u] + c
    return new_indptr, dst[keep]


def prune(graph: DiscreteGraph, durations: np.ndarray) -> DiscreteGraph:
    """The pruned graph (same nodes, a subset of the arcs) that loses no schedule (see the module)."""
    fifo = fifo_violations(graph) == 0
    indptr, dst = _prune(graph.node_acq, graph.node_time, graph.indptr, graph.dst, graph.acq_ptr,
                         np.asarray(durations, dtype=np.float64), fifo, True)
    return graph.with_arcs(indptr, dst)


def paper_prune(graph: DiscreteGraph, durations: np.ndarray) -> DiscreteGraph:
    """The paper's rule as published (any witness k, an earlier arrival at j taken as no worse): fewer arcs,
    but it can remove every way to a schedule the instance allows.  Kept to measure that
    (benchmarks/bench_prune.py); nothing else uses it."""
    indptr, dst = _prune(graph.node_acq, graph.node_time, graph.indptr, graph.dst, graph.acq_ptr,
                         np.asarray(durations, dtype=np.float64), True, False)
    return graph.with_arcs(indptr, dst)
