"""Array state and numba kernels of the EOSP MDP (the environment's hot loop).

The kernels take two NamedTuples of arrays (numba passes them as typed tuples):
:class:`EnvGraph`, the instance's arrays prepared once, and :class:`Episode`,
the state of an episode, updated in place (copied for a snapshot).

A step applies the paper's update to the chosen node w = (a, t):
(1) the other arcs out of the last node go (implicit: only arcs out of alive
nodes and out of the last node exist for the MDP), (2) the other nodes of a
die, (3) nodes no longer reachable from w die.  (3) is one sweep over nodes in
time order (a topological order: arcs go forward in time) starting at w: a node
stays alive iff one of its predecessors is w or alive.  Predecessors are
scanned latest first, so the first one checked usually decides; the arcs of a
node that died are never scanned again.  The sweep stops where no node can die
any more: a node that dies has lost a predecessor (one that died, or the
previous last node), and its arcs are at most that node's longest arc
(:attr:`EnvGraph.span`) long, so past the latest death plus its span nothing
changes (exact, not a heuristic).  A step thus costs the arcs of the nodes it
kills plus a read of an alive flag per node up to that horizon, not per node to
the end of the orbit.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from eosp.graphs.discrete import DiscreteGraph, arc_to_acq


class EnvGraph(NamedTuple):
    """Per-instance arrays prepared once (cached per instance by the sources)."""

    node_acq: np.ndarray  # int32 [N], -1 for the source
    node_time: np.ndarray  # float64 [N]
    node_finish: np.ndarray  # time + duration (the source: its time)
    indptr: np.ndarray  # CSR arcs of the environment's graph
    dst: np.ndarray
    acq_ptr: np.ndarray  # nodes of acquisition a: acq_ptr[a] .. acq_ptr[a + 1] - 1
    rindptr: np.ndarray  # reverse CSR: predecessors of each node, latest first
    rsrc: np.ndarray
    order: np.ndarray  # nodes by time
    pos: np.ndarray  # position of each node in `order`
    init_alive: np.ndarray  # uint8 [N]: nodes reachable from the source
    init_count: np.ndarray  # int32 [n]
    span: np.ndarray  # float64 [N]: time from each node to the latest node it has an arc to (0: none)


class Episode(NamedTuple):
    """The state of an episode: arrays the kernels update in place (one-element arrays for the scalars)."""

    alive: np.ndarray  # uint8 [N]: node still in the current discrete graph and not scheduled
    alive_count: np.ndarray  # int32 [n]: alive nodes per acquisition (0 = removed or scheduled)
    first_alive: np.ndarray  # int32 [n]: lower bound of the first alive node of each acquisition
    #                          (nodes only ever die, so it only moves forward)
    path: np.ndarray  # int32 [n]: scheduled nodes in order
    n_scheduled: np.ndarray  # int64 [1]: length of the path
    last: np.ndarray  # int64 [1]: last scheduled node (0, the source, at the start)
    last_pos: np.ndarray  # int64 [1]: position of the last node in the time order
    scheduled: np.ndarray  # float32 [n]: 1 for a scheduled acquisition
    mask: np.ndarray  # int8 [n]: 1 for an allowed action

    @classmethod
    def start(cls, eg: EnvGraph) -> Episode:
        n = eg.acq_ptr.shape[0] - 1
        return cls(eg.init_alive.copy(), eg.init_count.copy(), eg.acq_ptr[:-1].astype(np.int32),
                   np.zeros(n, dtype=np.int32), np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64),
                   np.zeros(1, dtype=np.int64), np.zeros(n, dtype=np.float32), np.zeros(n, dtype=np.int8))

    def copy(self) -> Episode:
        return Episode._make([a.copy() for a in self])


@numba.njit(cache=True)
def _span(indptr, dst, node_time):
    out = np.zeros(indptr.shape[0] - 1)
    for u in range(out.shape[0]):
        for a in range(indptr[u], indptr[u + 1]):
            out[u] = max(out[u], node_time[dst[a]] - node_time[u])
    return out


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
    alive = np.ones(big_n, dtype=np.uint8)
    alive[0] = 0
    count = np.diff(graph.acq_ptr).astype(np.int32)
    eg = EnvGraph(graph.node_acq, graph.node_time, finish, graph.indptr, graph.dst, graph.acq_ptr, rindptr, rsrc,
                  order, pos, alive, count, _span(graph.indptr, graph.dst, graph.node_time))
    sweep(eg, alive, count, 0, 0)  # fills init_alive and init_count (the same arrays): the whole orbit
    return eg


@numba.njit(cache=True)
def sweep(g, alive, alive_count, root_pos, prev_pos, horizon=np.inf):
    """Kill every alive node not reachable from the node at time-order position `root_pos`.

    Alive nodes between `prev_pos` (the previous root) and `root_pos` are before
    the root in time, hence unreachable.  The scan stops at the first node later than `horizon`, which
    every death moves to the dead node's time plus its span: the caller passes the latest time a node
    can lose its last way in by the change it made (:func:`apply_action`), or inf (the default) to scan
    the whole orbit when alive nodes need not be reachable yet (:func:`prepare`).
    """
    order, node_acq, rindptr, rsrc, node_time, span = g.order, g.node_acq, g.rindptr, g.rsrc, g.node_time, g.span
    root = order[root_pos]
    for p in range(prev_pos, root_pos):
        v = order[p]
        if alive[v]:
            alive[v] = 0
            alive_count[node_acq[v]] -= 1
            horizon = max(horizon, node_time[v] + span[v])
    for p in range(root_pos + 1, order.shape[0]):
        v = order[p]
        if node_time[v] > horizon:
            break
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
            horizon = max(horizon, node_time[v] + span[v])


@numba.njit(cache=True)
def target_node(g, alive, last, action):
    """The alive node of acquisition `action` that the node `last` has an arc to, or -1."""
    w = arc_to_acq(g.indptr, g.dst, g.acq_ptr, last, action)
    if w < 0 or not alive[w]:
        return -1
    return w


@numba.njit(cache=True)
def sweep_horizon(g, alive, last, action):
    """The sweep's starting horizon: the latest time a node can lose its last way in when `action` follows
    `last`, before the cascade: the ends of the longest arcs out of `last` (no longer a root) and out of the
    alive nodes of `action` (which die).  Call before :func:`kill`."""
    h = g.node_time[last] + g.span[last]
    for v in range(g.acq_ptr[action], g.acq_ptr[action + 1]):
        if alive[v]:
            h = max(h, g.node_time[v] + g.span[v])
    return h


@numba.njit(cache=True)
def kill(g, alive, alive_count, action):
    """Remove every node of `action` (scheduled, or given up) from the graph."""
    for v in range(g.acq_ptr[action], g.acq_ptr[action + 1]):
        alive[v] = 0
    alive_count[action] = 0


@numba.njit(cache=True)
def apply_action(g, ep, action):
    """Schedule `action` after the last node; returns the new node, or -1 (state unchanged) if not allowed.

    Updates the graph part of the episode (alive, alive_count, path, n_scheduled, last, last_pos), not
    its `scheduled` and `mask` (the environment's).
    """
    n_acq = g.acq_ptr.shape[0] - 1
    if action < 0 or action >= n_acq:
        return -1
    w = target_node(g, ep.alive, ep.last[0], action)
    if w < 0:
        return -1
    h = sweep_horizon(g, ep.alive, ep.last[0], action)
    kill(g, ep.alive, ep.alive_count, action)  # (2) the other nodes of the acquisition
    sweep(g, ep.alive, ep.alive_count, g.pos[w], ep.last_pos[0], h)  # (3) unreachable nodes
    ep.path[ep.n_scheduled[0]] = w
    ep.n_scheduled[0] += 1
    ep.last[0] = w
    ep.last_pos[0] = g.pos[w]
    return w


@numba.njit(cache=True)
def action_mask(g, ep):
    """ep.mask[j] = 1 when the last node has an arc to an alive node of j; returns the number of such arcs."""
    out, alive, last = ep.mask, ep.alive, ep.last[0]
    out[:] = 0
    cnt = 0
    for a in range(g.indptr[last], g.indptr[last + 1]):
        v = g.dst[a]
        if alive[v]:
            out[g.node_acq[v]] = 1
            cnt += 1
    return cnt


@numba.njit(cache=True)
def advance_first_alive(g, ep):
    """Move every ep.first_alive[i] to the first alive node of acquisition i (acq_ptr[i + 1] when none)."""
    acq_ptr, alive, alive_count, first_alive = g.acq_ptr, ep.alive, ep.alive_count, ep.first_alive
    for i in range(acq_ptr.shape[0] - 1):
        if alive_count[i] == 0:
            first_alive[i] = acq_ptr[i + 1]
            continue
        v = max(first_alive[i], acq_ptr[i])
        while v < acq_ptr[i + 1] and not alive[v]:
            v += 1
        first_alive[i] = v


@numba.njit(cache=True)
def step(g, ep, action):
    """One environment step in one kernel call: :func:`apply_action`, mark it scheduled, then the new mask
    and first alive nodes.  Returns the new node, or -1 (state unchanged) if `action` is not allowed."""
    w = apply_action(g, ep, action)
    if w >= 0:
        ep.scheduled[action] = 1.0
        action_mask(g, ep)
        advance_first_alive(g, ep)
    return w


@numba.njit(cache=True)
def start(g, ep):
    """The mask and first alive nodes of a fresh episode (:meth:`Episode.start`)."""
    action_mask(g, ep)
    advance_first_alive(g, ep)
