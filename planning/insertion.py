"""Greedy insertion on a discrete graph: the operational Greedy's kernel, also run from a mid-episode state.

Acquisitions are taken in a fixed order and each is inserted at the best feasible position of the
current sequence, or skipped when no position is feasible; one already in the sequence may be
postponed, never removed (the algorithm and its choices are documented in eosp.solvers.greedy, which
runs it from the source node on the whole instance).  The environment runs the same kernel from the
last scheduled node over the acquisitions still in the graph, to show the agent Greedy's completion of
the current partial schedule (eosp.envs.observation, ``EnvConfig.plan``), and the HTML report uses its
feasibility test to say why an acquisition was missed: the kernel lives here, below all three, so that
there is one implementation.
"""

from __future__ import annotations

import numba
import numpy as np

from eosp.graphs.discrete import arc_to_acq

ORDERS = ("utility", "start", "deadline", "window", "index")


@numba.njit(cache=True)
def _insertion_cost(indptr, dst, acq_ptr, node_time, seq_acq, seq_node, m, p, a, start):
    """(total start delay of the acquisitions after `p`, node of `a`) for inserting `a`
    at position `p`; (inf, -1) if some arc is missing.  With non-FIFO transitions a
    start can also move earlier: the delay is then negative."""
    prev = start if p == 0 else seq_node[p - 1]
    cur = arc_to_acq(indptr, dst, acq_ptr, prev, a)
    if cur < 0:
        return np.inf, -1
    first = cur
    cost = 0.0
    for k in range(p, m):
        nk = arc_to_acq(indptr, dst, acq_ptr, cur, seq_acq[k])
        if nk < 0:
            return np.inf, -1
        if nk == seq_node[k]:
            break
        cost += node_time[nk] - node_time[seq_node[k]]
        cur = nk
    return cost, first


@numba.njit(cache=True)
def greedy_insert(indptr, dst, acq_ptr, node_time, order, start, skip):
    """Insert the acquisitions of `order` (int32, those with ``skip[a]`` nonzero left out) one by one into a
    sequence that starts after node `start` (0: the source).  Returns (acquisitions, their nodes) in execution
    order and the position each considered acquisition went to (-1: skipped or left out), aligned with
    `order`.  Each acquisition starts at the node its predecessor's node has an arc to (as early as
    possible), so the result is a path of the graph from `start`."""
    n = order.shape[0]
    seq_acq = np.empty(n, dtype=np.int32)
    seq_node = np.empty(n, dtype=np.int32)
    trace_pos = np.full(n, -1, dtype=np.int32)
    # the widest window (last minus first node start): a sequence member starting more than that before a's
    # first node has no node left at or after it, so a cannot go in front of it (no arc goes back in time)
    widest = 0.0
    for i in range(acq_ptr.shape[0] - 1):
        if acq_ptr[i + 1] > acq_ptr[i]:
            widest = max(widest, node_time[acq_ptr[i + 1] - 1] - node_time[acq_ptr[i]])
    m = 0
    for step in range(n):
        a = order[step]
        if skip[a]:
            continue
        first_time = node_time[acq_ptr[a]]
        last_time = node_time[acq_ptr[a + 1] - 1]
        best_p = -1
        best_cost = np.inf
        best_start = np.inf
        # first position worth trying: binary search on the sequence's starts (increasing along it)
        lo, hi = 0, m
        while lo < hi:
            mid = (lo + hi) >> 1
            if node_time[seq_node[mid]] < first_time - widest:
                lo = mid + 1
            else:
                hi = mid
        for p in range(lo, m + 1):
            if p > 0 and node_time[seq_node[p - 1]] >= last_time:
                break  # predecessors only get later along the sequence
            if p < m and node_time[acq_ptr[seq_acq[p] + 1] - 1] < first_time:
                continue  # the member at p has no node left after a's first: it cannot follow a
            cost, first = _insertion_cost(indptr, dst, acq_ptr, node_time, seq_acq, seq_node, m, p, a, start)
            if first < 0:
                continue
            if cost < best_cost or (cost == best_cost and node_time[first] < best_start):
                best_p, best_cost, best_start = p, cost, node_time[first]
        if best_p < 0:
            continue
        # apply: shift the tail, then recompute starts until they settle
        for k in range(m, best_p, -1):
            seq_acq[k] = seq_acq[k - 1]
            seq_node[k] = seq_node[k - 1]
        m += 1
        seq_acq[best_p] = a
        prev = start if best_p == 0 else seq_node[best_p - 1]
        for k in range(best_p, m):
            nk = arc_to_acq(indptr, dst, acq_ptr, prev, seq_acq[k])
            if k > best_p and nk == seq_node[k]:
                break
            seq_node[k] = nk
            prev = nk
        trace_pos[step] = best_p
    return seq_acq[:m].copy(), seq_node[:m].copy(), trace_pos


def insertion_order(node_time: np.ndarray, acq_ptr: np.ndarray, weights: np.ndarray, order: str) -> np.ndarray:
    """The order in which acquisitions are considered (int32), by name (eosp.solvers.greedy explains each):
    'utility' (decreasing `weights`), 'start', 'deadline', 'window', 'index'; ties by index."""
    first = node_time[acq_ptr[:-1]]
    last = node_time[acq_ptr[1:] - 1]
    idx = np.arange(acq_ptr.shape[0] - 1)
    if order == "utility":
        keys = (idx, -np.asarray(weights))
    elif order == "deadline":
        keys = (idx, last - first, last)
    elif order == "window":
        keys = (idx, last, last - first)
    elif order == "start":
        keys = (idx, last - first, first)
    elif order == "index":
        keys = (idx,)
    else:
        raise ValueError(f"unknown greedy order {order!r} ({', '.join(ORDERS)})")
    return np.lexsort(keys).astype(np.int32)


@numba.njit(cache=True)
def earliest_path(indptr, dst, acq_ptr, seq_acq, start):
    """The nodes of the acquisitions `seq_acq` taken in order from node `start`, each at the node its
    predecessor's node has an arc to (as early as possible); -1 from the first that cannot follow.
    This is the sequence form :func:`_insertion_cost` expects (its nodes are the ones an insertion recomputes)."""
    m = seq_acq.shape[0]
    out = np.full(m, -1, dtype=np.int64)
    cur = start
    for k in range(m):
        cur = arc_to_acq(indptr, dst, acq_ptr, cur, seq_acq[k])
        if cur < 0:
            break
        out[k] = cur
    return out


@numba.njit(cache=True)
def first_insertion(indptr, dst, acq_ptr, node_time, seq_acq, seq_node, start, a):
    """The first position of the sequence (`seq_acq`, its :func:`earliest_path` nodes `seq_node`) where
    acquisition `a` can be inserted, the members after it moved as needed (the Greedy kernel's test); -1 if
    none.  Used by the HTML report to say why an acquisition was missed."""
    m = seq_acq.shape[0]
    for p in range(m + 1):
        _, first = _insertion_cost(indptr, dst, acq_ptr, node_time, seq_acq, seq_node, m, p, a, start)
        if first >= 0:
            return p
    return -1
