"""The paper's optimality pruning of the discrete graph.

The arc u = (i, t_i) -> v = (j, t_j) is removed when some other acquisition k can
be inserted between them: u has an arc to (k, t_k) and (k, t_k) has an arc to a
node (j, t'_j) with t'_j <= t_j (arriving earlier and waiting is allowed).  Every
optimal schedule using u and then v would rather visit k in between, so v is not
an *immediate* successor of u.  The test uses the arcs of the unpruned graph
only, so the result does not depend on the order in which arcs are examined.

(The argument ignores the "each acquisition at most once" exclusion: if k was
already scheduled before u, the pruned graph loses the direct arc.  This is the
paper's construction; the solvers that must be exact work on the unpruned graph.)

Algorithm, per node u: sort u's successors by their finish time t_k + d_k.  For
an arc u -> (j, t_j), only successors finishing before t_j can be inserted, so
they are tried in finish order and the search stops at the first that works or
at the first that finishes after t_j.  Far successors are pruned by the first
candidate; arcs that survive are near ones with few candidates before them.
"""

from __future__ import annotations

import numba
import numpy as np

from eosp.graphs.discrete import DiscreteGraph, arc_to_acq


@numba.njit(cache=True)
def _prune(node_acq, node_time, indptr, dst, acq_ptr, durations):
    n_nodes = node_acq.shape[0]
    keep = np.zeros(dst.shape[0], dtype=np.bool_)
    max_deg = 0
    for u in range(n_nodes):
        d = indptr[u + 1] - indptr[u]
        if d > max_deg:
            max_deg = d
    # smallest transition gap t_dst - (t_src + d_src) over all arcs: a k finishing
    # later than t_j - gap cannot reach j by t_j
    gap = np.inf
    for u in range(1, n_nodes):
        fin = node_time[u] + durations[node_acq[u]]
        for a in range(indptr[u], indptr[u + 1]):
            g = node_time[dst[a]] - fin
            if g < gap:
                gap = g
    if gap == np.inf or gap < 0.0:
        gap = 0.0
    finish = np.empty(max_deg, dtype=np.float64)
    for u in range(n_nodes):
        lo = indptr[u]
        hi = indptr[u + 1]
        deg = hi - lo
        if deg == 0:
            continue
        for a in range(deg):
            v = dst[lo + a]
            finish[a] = node_time[v] + durations[node_acq[v]]
        order = np.argsort(finish[:deg])
        # the earliest-finishing successor k0 prunes most arcs: find its arc to every j
        # in one merge of the two sorted rows instead of one binary search per arc
        vk0 = dst[lo + order[0]]
        f0 = finish[order[0]] + gap
        p = indptr[vk0]
        p_end = indptr[vk0 + 1]
        for a in range(deg):
            v = dst[lo + a]
            j = node_acq[v]
            tj = node_time[v]
            if f0 <= tj and node_acq[vk0] != j:
                first = acq_ptr[j]
                while p < p_end and dst[p] < first:
                    p += 1
                if p < p_end and dst[p] < acq_ptr[j + 1] and node_time[dst[p]] <= tj:
                    keep[lo + a] = False
                    continue
            insertable = False
            for b in range(deg):
                kb = order[b]
                if finish[kb] + gap > tj:
                    break
                vk = dst[lo + kb]
                if node_acq[vk] == j:
                    continue
                w = arc_to_acq(indptr, dst, acq_ptr, vk, j)
                if w >= 0 and node_time[w] <= tj:
                    insertable = True
                    break
            keep[lo + a] = not insertable
    new_indptr = np.zeros(n_nodes + 1, dtype=np.int64)
    for u in range(n_nodes):
        c = 0
        for a in range(indptr[u], indptr[u + 1]):
            if keep[a]:
                c += 1
        new_indptr[u + 1] = new_indptr[u] + c
    return new_indptr, dst[keep]


def prune(graph: DiscreteGraph, durations: np.ndarray) -> DiscreteGraph:
    """The pruned graph (same nodes, a subset of the arcs)."""
    indptr, dst = _prune(graph.node_acq, graph.node_time, graph.indptr, graph.dst, graph.acq_ptr,
                         np.asarray(durations, dtype=np.float64))
    return graph.with_arcs(indptr, dst)
