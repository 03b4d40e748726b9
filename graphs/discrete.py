"""The discrete graph G^D as arrays.

Nodes are (acquisition, start time) pairs plus a source.  The project keeps them
in a *canonical order*: node 0 is the source, then the nodes of acquisition 0 by
increasing time, then those of acquisition 1, and so on.  Consequences used by
the hot loops:

* the nodes of acquisition ``a`` are ``acq_ptr[a] .. acq_ptr[a+1]-1``;
* arcs are stored in CSR (``indptr``, ``dst``) with each row sorted by ``dst``,
  hence by acquisition, so "the arc from node v to acquisition j" is one binary
  search in v's row restricted to ``[acq_ptr[j], acq_ptr[j+1])``.

Instances imported in another node numbering are brought to this order on import
(their original ids are kept for writing schedules back).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np


@dataclass
class DiscreteGraph:
    node_acq: np.ndarray  # int32 [N]; -1 for the source (node 0)
    node_time: np.ndarray  # float64 [N]
    indptr: np.ndarray  # int64 [N+1]
    dst: np.ndarray  # int32 [E] (uint16 in a fleet's pass graphs of at most 65,536 nodes: their arcs' memory)
    acq_ptr: np.ndarray  # int64 [n+1]

    @property
    def n_nodes(self) -> int:
        return int(self.node_acq.shape[0])

    @property
    def n_arcs(self) -> int:
        return int(self.dst.shape[0])

    @property
    def n_acq(self) -> int:
        return int(self.acq_ptr.shape[0] - 1)

    def src(self) -> np.ndarray:
        """Source node of every arc (int32 [E])."""
        return np.repeat(np.arange(self.n_nodes, dtype=np.int32), np.diff(self.indptr))

    def successor(self, node: int, acq: int) -> int:
        """The node of `acq` that `node` has an arc to, or -1."""
        return int(arc_to_acq(self.indptr, self.dst, self.acq_ptr, node, acq))

    def with_arcs(self, indptr: np.ndarray, dst: np.ndarray) -> "DiscreteGraph":
        return DiscreteGraph(self.node_acq, self.node_time, indptr, dst, self.acq_ptr)


def acq_ptr_from_node_acq(node_acq: np.ndarray, n_acq: int) -> np.ndarray:
    """Node ranges per acquisition, for nodes in canonical order."""
    counts = np.bincount(node_acq[1:], minlength=n_acq)
    ptr = np.empty(n_acq + 1, dtype=np.int64)
    ptr[0] = 1
    np.cumsum(counts, out=ptr[1:])
    ptr[1:] += 1
    return ptr


@numba.njit(cache=True, inline="always")
def arc_to_acq(indptr, dst, acq_ptr, node, acq):
    """Binary search in `node`'s sorted row for a destination of acquisition `acq`; -1 if none."""
    lo = indptr[node]
    hi = indptr[node + 1]
    first = acq_ptr[acq]
    while lo < hi:
        mid = (lo + hi) >> 1
        if dst[mid] < first:
            lo = mid + 1
        else:
            hi = mid
    if lo < indptr[node + 1] and dst[lo] < acq_ptr[acq + 1]:
        return dst[lo]
    return -1


@numba.njit(cache=True)
def first_backward_arc(node_acq, node_time, indptr, dst, durations):
    """Index of the first arc whose destination starts before its source ends (-1 if none)."""
    for u in range(node_acq.shape[0]):
        fin = node_time[u]
        if node_acq[u] >= 0:
            fin += durations[node_acq[u]]
        for a in range(indptr[u], indptr[u + 1]):
            if node_time[dst[a]] < fin - 1e-6:
                return a
    return -1
