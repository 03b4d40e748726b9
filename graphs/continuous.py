"""The continuous graph G^C: one node per acquisition, an arc i -> j when some
discrete arc goes from a node of i to a node of j.

It is what the GNN sees (with node attributes from the acquisitions table: the
window and the attitude statistics).  The source's arcs are not part of it.
"""

from __future__ import annotations

import numba
import numpy as np

from eosp.graphs.discrete import DiscreteGraph


@numba.njit(cache=True)
def continuous_arcs(node_acq, indptr, dst, acq_ptr, alive):
    """Unique (i, j) acquisition pairs joined by a discrete arc between alive nodes.

    Arcs come out grouped by i, each group sorted by j (rows are sorted by
    destination and acquisitions own contiguous node ranges).
    """
    n_acq = acq_ptr.shape[0] - 1
    stamp = np.full(n_acq, -1, dtype=np.int64)
    cap = 1024
    out_src = np.empty(cap, dtype=np.int32)
    out_dst = np.empty(cap, dtype=np.int32)
    m = 0
    buf = np.empty(n_acq, dtype=np.int32)
    for i in range(n_acq):
        nb = 0
        for u in range(acq_ptr[i], acq_ptr[i + 1]):
            if not alive[u]:
                continue
            for a in range(indptr[u], indptr[u + 1]):
                v = dst[a]
                if not alive[v]:
                    continue
                j = node_acq[v]
                if stamp[j] != i:
                    stamp[j] = i
                    buf[nb] = j
                    nb += 1
        if m + nb > cap:
            cap = max(2 * cap, m + nb)
            s2 = np.empty(cap, dtype=np.int32)
            d2 = np.empty(cap, dtype=np.int32)
            s2[:m] = out_src[:m]
            d2[:m] = out_dst[:m]
            out_src, out_dst = s2, d2
        srt = np.sort(buf[:nb])
        for b in range(nb):
            out_src[m] = i
            out_dst[m] = srt[b]
            m += 1
    return out_src[:m].copy(), out_dst[:m].copy()


def continuous_graph(graph: DiscreteGraph, alive: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(src_acq, dst_acq) int32 arrays of the continuous graph of `graph` (optionally of its alive part)."""
    if alive is None:
        alive = np.ones(graph.n_nodes, dtype=np.bool_)
    return continuous_arcs(graph.node_acq, graph.indptr, graph.dst, graph.acq_ptr, alive)
