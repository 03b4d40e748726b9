"""Array state and numba kernels of the EOSP MDP (the environment's hot loop).

State of an episode (all numpy arrays, copied for a snapshot):

* ``alive``  uint8 [N]: node still in the current discrete graph and not scheduled;
* ``alive_count`` int32 [n]: alive nodes per acquisition (0 = removed or scheduled);
* ``first_alive`` int32 [n]: lower bound of the first alive node of each
  acquisition (nodes only ever die, so it only moves forward);
* ``path`` int32 [n]: scheduled nodes in order, ``scalars`` int64 [3]: path
  length, last node, time-order position of the last node.

A step applies the paper's update to the chosen node w = (a, t):
(1) the other arcs out of the last node go (implicit: only arcs out of alive
nodes and out of the last node exist for the MDP), (2) the other nodes of a
die, (3) nodes no longer reachable from w die.  (3) is one sweep over nodes in
time order (a topological order: arcs go forward in time) starting at w: a node
stays alive iff one of its predecessors is w or alive.  Predecessors are
scanned latest first, so the first one checked usually decides; the arcs of a
node that died are never scanned again: an episode costs O(arcs) of arc work plus
one read of an alive flag per later node and step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from eosp.graphs.discrete import DiscreteGraph, arc_to_acq


@dataclass
class EnvGraph:
    """Per-instance arrays prepared once (cached per instance by the sources)."""

    node_acq: np.ndarray
    node_time: np.ndarray
    node_finish: np.ndarray  # time + duration (the source: its time)
    indptr: np.ndarray
    dst: np.ndarray
    acq_ptr: np.ndarray
    rindptr: np.ndarray  # reverse CSR: predecessors of each node, latest first
    rsrc: np.ndarray
    order: np.ndarray  # nodes by time
    pos: np.ndarray  # position of each node in `order`
    init_alive: np.ndarray  # uint8 [N]: nodes reachable from the source
    init_count: np.ndarray  # int32 [n]


@numba.njit(cache=True)
def _reverse(n_nodes, indptr, dst, order):
    """Reverse CSR with each node's predecessors latest first (filled in decreasing source time)."""
    counts = np.zeros(n_nodes + 1, dtype=np.int64)
    for a in range(dst.shape[0]):
        counts[dst[a] + 1] += 1
    rindptr = np.cumsum(counts)
    fill = rindptr[:-1].copy()
    rsrc = np.empty(dst.shape[0], dtype=np.int32)
    for p in range(n_nodes - 1, -1, -1):
        u = order[p]
        for a in range(indptr[u], indptr[u + 1]):
            v = dst[a]
            rsrc[fill[v]] = u
            fill[v] += 1
    return rindptr, rsrc


def prepare(graph: DiscreteGraph, durations: np.ndarray) -> EnvGraph:
    big_n = graph.n_nodes
    finish = graph.node_time.copy()
    finish[1:] += durations[graph.node_acq[1:]]
    order = np.argsort(graph.node_time, kind="stable").astype(np.int32)
    if order[0] != 0:  # the source stands before everything
        order = np.concatenate([[0], order[order != 0]]).astype(np.int32)
    rindptr, rsrc = _reverse(big_n, graph.indptr, graph.dst, order)
    pos = np.empty(big_n, dtype=np.int32)
    pos[order] = np.arange(big_n, dtype=np.int32)
    eg = EnvGraph(graph.node_acq, graph.node_time, finish, graph.indptr, graph.dst, graph.acq_ptr, rindptr, rsrc,
                  order, pos, np.empty(0, np.uint8), np.empty(0, np.int32))
    alive = np.ones(big_n, dtype=np.uint8)
    alive[0] = 0
    count = np.diff(graph.acq_ptr).astype(np.int32)
    sweep(eg.node_acq, eg.rindptr, eg.rsrc, eg.order, alive, count, 0, 0)
    eg.init_alive = alive
    eg.init_count = count
    return eg


@numba.njit(cache=True)
def sweep(node_acq, rindptr, rsrc, order, alive, alive_count, root_pos, prev_pos):
    """Kill every alive node not reachable from the node at time-order position `root_pos`.

    Alive nodes between `prev_pos` (the previous root) and `root_pos` are before
    the root in time, hence unreachable.
    """
    root = order[root_pos]
    for p in range(prev_pos, root_pos):
        v = order[p]
        if alive[v]:
            alive[v] = 0
            alive_count[node_acq[v]] -= 1
    for p in range(root_pos + 1, order.shape[0]):
        v = order[p]
        if not alive[v]:
            continue
        ok = False
        for a in range(rindptr[v], rindptr[v + 1]):
            q = rsrc[a]
            if q == root or alive[q]:
                ok = True
                break
        if not ok:
            alive[v] = 0
            alive_count[node_acq[v]] -= 1


@numba.njit(cache=True)
def target_node(indptr, dst, acq_ptr, alive, last, action):
    """The alive node of acquisition `action` that the last node has an arc to, or -1."""
    w = arc_to_acq(indptr, dst, acq_ptr, last, action)
    if w < 0 or not alive[w]:
        return -1
    return w


@numba.njit(cache=True)
def apply_action(node_acq, indptr, dst, acq_ptr, rindptr, rsrc, order, pos, alive, alive_count, path, scalars,
                 action):
    """Schedule `action` after the last node; returns the new node, or -1 (state unchanged) if not allowed."""
    n_acq = acq_ptr.shape[0] - 1
    if action < 0 or action >= n_acq:
        return -1
    last = scalars[1]
    w = target_node(indptr, dst, acq_ptr, alive, last, action)
    if w < 0:
        return -1
    for v in range(acq_ptr[action], acq_ptr[action + 1]):  # (2) the other nodes of the acquisition
        alive[v] = 0
    alive_count[action] = 0
    sweep(node_acq, rindptr, rsrc, order, alive, alive_count, pos[w], scalars[2])  # (3) unreachable nodes
    path[scalars[0]] = w
    scalars[0] += 1
    scalars[1] = w
    scalars[2] = pos[w]
    return w


@numba.njit(cache=True)
def action_mask(indptr, dst, node_acq, alive, last, n_acq, out):
    """out[j] = 1 when the last node has an arc to an alive node of j."""
    out[:] = 0
    cnt = 0
    for a in range(indptr[last], indptr[last + 1]):
        v = dst[a]
        if alive[v]:
            out[node_acq[v]] = 1
            cnt += 1
    return cnt


@numba.njit(cache=True)
def advance_first_alive(acq_ptr, alive, alive_count, first_alive):
    for i in range(acq_ptr.shape[0] - 1):
        if alive_count[i] == 0:
            first_alive[i] = acq_ptr[i + 1]
            continue
        v = max(first_alive[i], acq_ptr[i])
        while v < acq_ptr[i + 1] and not alive[v]:
            v += 1
        first_alive[i] = v
