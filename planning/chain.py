"""Edits of a schedule path that keep it a path of its graph (numba): insert, replace or drop one position.

Why a module of its own: the moves (:mod:`eosp.planning.moves`) and the window re-planning
(:mod:`eosp.planning.windows`) both change a stretch of a schedule and must then re-reach the nodes after it
(:func:`rechain`); kept here, below both, so that each imports it and neither imports the other's internals.

A schedule is a path source -> n_1 -> ... -> n_L of a discrete graph whose arcs go from a node to the one
node of the target acquisition it reaches (:func:`eosp.graphs.discrete.arc_to_acq`), so a path is fixed by
its sequence of acquisitions: after an edit, the nodes that follow are re-reached one arc at a time until a
re-reached node equals the old one (from there on the path is unchanged).  A missing arc makes the edit
infeasible.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from eosp.graphs.discrete import arc_to_acq


class GraphArrays(NamedTuple):
    """The arrays of a discrete graph the kernels read, as one argument (numba passes a NamedTuple of arrays into
    njit functions as it passes the arrays): CSR arcs (indptr [N+1], dst), the nodes of each acquisition
    (acq_ptr [n_acq+1]), each node's acquisition and time."""

    indptr: np.ndarray
    dst: np.ndarray
    acq_ptr: np.ndarray
    node_acq: np.ndarray
    node_time: np.ndarray


@numba.njit(cache=True)
def rechain(indptr, dst, acq_ptr, node_acq, path, n, i0, cur, tmp, m):
    """From node `cur`, re-reach the acquisitions of path[i0:n] one arc at a time, writing the new nodes to
    tmp[m:], until one equals the old node (from there the path is unchanged: an arc's destination depends
    only on its source and target acquisition).  Returns the end of tmp's new nodes, or -1 when an arc is
    missing."""
    for i in range(i0, n):
        nx = arc_to_acq(indptr, dst, acq_ptr, cur, node_acq[path[i]])
        if nx < 0:
            return -1
        if nx == path[i]:
            break
        tmp[m] = nx
        m += 1
        cur = nx
    return m


@numba.njit(cache=True)
def try_put(indptr, dst, acq_ptr, node_acq, path, n, k, j, tmp, drop):
    """Nodes of path[:n] with acquisition j put at position k, as tmp[:m]: inserted before position k (drop 0:
    tmp replaces path[k:k+m-1]) or replacing position k's acquisition (drop 1: tmp replaces path[k:k+m]; in
    the pruned graph the arc that would skip position k is often pruned, so a swap is tried as a replacement,
    not as a removal followed by an insertion).  Returns m, or -1 when a needed arc is missing."""
    v = arc_to_acq(indptr, dst, acq_ptr, 0 if k == 0 else path[k - 1], j)
    if v < 0:
        return -1
    tmp[0] = v
    return rechain(indptr, dst, acq_ptr, node_acq, path, n, k + drop, v, tmp, 1)


@numba.njit(cache=True)
def apply_insert(path, n, k, tmp, m):
    """Put tmp[:m] (what :func:`try_put` returned with drop 0) in place of path[k:k+m-1]; returns the new length."""
    for i in range(n, k, -1):
        path[i] = path[i - 1]
    for i in range(m):
        path[k + i] = tmp[i]
    return n + 1


@numba.njit(cache=True)
def remove(indptr, dst, acq_ptr, node_acq, path, n, k, tmp):
    """Drop position k in place; returns the new length, or -1 (path unchanged) when a needed arc is missing."""
    m = rechain(indptr, dst, acq_ptr, node_acq, path, n, k + 1, 0 if k == 0 else path[k - 1], tmp, 0)
    if m < 0:
        return -1
    for i in range(k, n - 1):
        path[i] = path[i + 1]
    for i in range(m):
        path[k + i] = tmp[i]
    return n - 1


@numba.njit(cache=True)
def _walk(indptr, dst, acq_ptr, actions, out):
    """out[i] = the node playing actions[i] reaches from out[i - 1] (the source first); returns the index of
    the first action with no arc, or -1 when all have one."""
    cur = 0
    for i in range(actions.shape[0]):
        cur = arc_to_acq(indptr, dst, acq_ptr, cur, actions[i])
        if cur < 0:
            return i
        out[i] = cur
    return -1


def walk(graph, actions) -> np.ndarray | int:
    """The path (node indices of `graph`) that playing acquisitions `actions` from the source follows, each one's
    arc; the position of the first action without an arc from the previous node otherwise."""
    actions = np.asarray(actions, dtype=np.int64)
    out = np.empty(actions.shape[0], dtype=np.int32)
    bad = _walk(graph.indptr, graph.dst, graph.acq_ptr, actions, out)
    return int(bad) if bad >= 0 else out


def graph_arrays(graph) -> GraphArrays:
    """The :class:`GraphArrays` of a discrete graph (anything with indptr, dst, acq_ptr, node_acq, node_time: an
    eosp.graphs.discrete.DiscreteGraph or the environment's graph)."""
    return GraphArrays(graph.indptr, graph.dst, graph.acq_ptr, graph.node_acq, graph.node_time)
