"""RAMP: label-setting search for the best path of the discrete graph.

The paper's reference "RAMP" is a Dijkstra search in the discrete graph that is
not exact because of the exclusion between the nodes of one acquisition.  The
graph is a DAG whose arcs go forward in time, so Dijkstra's settling order is
simply the nodes by increasing time: a node is settled once all its
predecessors have been.  This module sweeps the nodes in that order and keeps at
every node a set of *labels* (partial schedules from the source ending there).

Each acquisition at most once
-----------------------------
A label carries the acquisitions it used whose window is still *open*, i.e.
whose last node is later than the label's node: only those can be repeated by
an extension, since every later node is later in time.  Windows last at most a
couple of minutes, so this set is small (its size is bounded by the window
length over the shortest arc, ``max_open``), and it is the whole state: two
labels at one node with the same open set have the same futures.  An extension
to an acquisition in the open set is refused.  Label A dominates label B at the
same node when value(A) >= value(B) and open(A) is a subset of open(B); B is
then dropped.

With no limit on the number of labels per node this is an exact dynamic
program (:mod:`solvers.exact` runs it so, with Lagrangian bounds to cut labels).
RAMP keeps only the ``beam`` best labels per node (by value, then by the smaller
open set), so it is a heuristic: a label dropped for lack of room may have been
the prefix of the optimum, and the default graph is the pruned one, which can
lose optima because its pruning ignores the exclusion.  With ``beam=1`` it is
the classic "best path per node, skip repeats".

When the time limit is reached the rest of the sweep keeps one label per node,
so the result is always a complete schedule.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numba
import numpy as np

from eosp.graphs.discrete import DiscreteGraph
from eosp.instances.instance import Instance
from eosp.config import ranged
from eosp.solvers.base import Solution, SolverConfig, objective_weights
from eosp.solvers.bound import acq_last_time, topological_order

STOP_DONE, STOP_GROW, STOP_CHECK = 0, 1, 2  # why _sweep returned


def max_open(graph: DiscreteGraph) -> int:
    """Largest possible open set: acquisitions visited less than the longest window ago.

    An acquisition j in the open set at node w was visited at some t_j with
    first(j) <= t_j <= t_w < last(j), so within the last W = max(last - first)
    seconds; consecutive visits of a path are at least the shortest arc apart.
    """
    first = graph.node_time[graph.acq_ptr[:-1]]
    last = graph.node_time[graph.acq_ptr[1:] - 1]
    span = float(np.max(last - first)) if last.size else 0.0
    gap = _min_inner_gap(graph.node_time, graph.indptr, graph.dst)
    if not np.isfinite(gap):  # no arc between two acquisitions: paths of one node
        return 1
    return int(math.floor(span / max(gap, 1e-9))) + 2


@numba.njit(cache=True)
def _min_inner_gap(node_time, indptr, dst):
    """Smallest t_dst - t_src over the arcs that do not leave the source."""
    gap = np.inf
    for u in range(1, node_time.shape[0]):
        for a in range(indptr[u], indptr[u + 1]):
            d = node_time[dst[a]] - node_time[u]
            if d < gap:
                gap = d
    return gap


@numba.njit(cache=True, inline="always")
def _is_subset(sets, a, na, b_buf, nb):
    """Is sorted set a (row of `sets`) included in sorted b_buf[:nb]?"""
    j = 0
    for i in range(na):
        x = sets[a, i]
        while j < nb and b_buf[j] < x:
            j += 1
        if j == nb or b_buf[j] != x:
            return False
        j += 1
    return True


@numba.njit(cache=True)
def _sweep(pos, order, indptr, dst, node_acq, node_time, weight, last_time, lam, cbound, gain_abs, gain_rel,
           beam, max_work, val, par, lnode, lnext, sets, ssize, head, cnt, wval, state, inc, counters):
    """Extend the labels of the nodes order[pos:], in order, until done or told to stop.

    Returns (pos, stop reason).  Label memory: slots [0, state[0]) were used, the
    freed ones (dropped before their node was swept, so nobody's parent) are
    chained from state[1] through `lnext`, state[3] of them.  state[2] is the
    incumbent label (-1: none), inc[0] its value.  counters = [created, cut by
    bound or beam, dominated, extensions].  wval[w]: value of the worst label at w
    once w holds `beam` labels.
    """
    cap = val.shape[0]
    m = sets.shape[1]
    buf = np.empty(m + 1, dtype=np.int32)
    work0 = counters[3]
    n_nodes = order.shape[0]
    while pos < n_nodes:
        v = order[pos]
        deg = indptr[v + 1] - indptr[v]
        if cap - state[0] + state[3] < cnt[v] * deg:
            return pos, STOP_GROW
        if counters[3] - work0 > max_work:
            return pos, STOP_CHECK
        l = head[v]
        while l >= 0:
            nl = ssize[l]
            for a in range(indptr[v], indptr[v + 1]):
                w = dst[a]
                k = node_acq[w]
                used = False
                for i in range(nl):
                    if sets[l, i] == k:
                        used = True
                        break
                if used:
                    continue
                counters[3] += 1
                tw = node_time[w]
                newval = val[l] + weight[k]
                # open set at w: the still-open acquisitions of l plus k, sorted
                nb = 0
                lam_sum = 0.0
                placed = last_time[k] <= tw  # k closed at w: nothing to add
                for i in range(nl):
                    x = sets[l, i]
                    if not placed and k < x:
                        buf[nb] = k
                        nb += 1
                        lam_sum += lam[k]
                        placed = True
                    if last_time[x] > tw:
                        buf[nb] = x
                        nb += 1
                        lam_sum += lam[x]
                if not placed:
                    buf[nb] = k
                    nb += 1
                    lam_sum += lam[k]
                if newval + cbound[w] - lam_sum < inc[0] + gain_abs + gain_rel * abs(inc[0]):
                    counters[1] += 1
                    continue
                # a full beam whose worst label is better: the new label would be evicted at once
                if beam > 0 and cnt[w] >= beam and newval < wval[w]:
                    counters[1] += 1
                    continue
                # dominance against the labels at w; drop those it dominates, find the worst
                dominated = False
                replaces_inc = False
                worst = -1
                prev = -1
                e = head[w]
                while e >= 0:
                    ne = lnext[e]
                    if val[e] >= newval and _is_subset(sets, e, ssize[e], buf, nb):
                        dominated = True
                        break
                    if newval >= val[e] and _is_subset_rev(buf, nb, sets, e, ssize[e]):
                        if prev < 0:
                            head[w] = ne
                        else:
                            lnext[prev] = ne
                        cnt[w] -= 1
                        counters[2] += 1
                        replaces_inc = replaces_inc or e == state[2]
                        lnext[e] = state[1]
                        state[1] = e
                        state[3] += 1
                        e = ne
                        continue
                    if worst < 0 or val[e] < val[worst] or (val[e] == val[worst] and ssize[e] > ssize[worst]):
                        worst = e
                    prev = e
                    e = ne
                if dominated:
                    counters[2] += 1
                    continue
                if beam > 0 and cnt[w] >= beam:
                    if newval < val[worst] or (newval == val[worst] and nb >= ssize[worst]):
                        counters[1] += 1
                        continue
                    _unlink(head, lnext, w, worst)
                    cnt[w] -= 1
                    replaces_inc = replaces_inc or worst == state[2]
                    lnext[worst] = state[1]
                    state[1] = worst
                    state[3] += 1
                # store the new label in a freed slot or a fresh one
                if state[3] > 0:
                    q = state[1]
                    state[1] = lnext[q]
                    state[3] -= 1
                else:
                    q = state[0]
                    state[0] += 1
                val[q] = newval
                par[q] = l
                lnode[q] = w
                ssize[q] = nb
                for i in range(nb):
                    sets[q, i] = buf[i]
                lnext[q] = head[w]
                head[w] = q
                cnt[w] += 1
                if beam > 0 and cnt[w] >= beam:
                    wv = np.inf
                    e = head[w]
                    while e >= 0:
                        if val[e] < wv:
                            wv = val[e]
                        e = lnext[e]
                    wval[w] = wv
                counters[0] += 1
                if newval > inc[0] or replaces_inc:
                    inc[0] = max(inc[0], newval)
                    state[2] = q
            l = lnext[l]
        pos += 1
    return pos, STOP_DONE


@numba.njit(cache=True, inline="always")
def _is_subset_rev(buf, nb, sets, b, n_b):
    """Is sorted buf[:nb] included in sorted set b (row of `sets`)?"""
    j = 0
    for i in range(nb):
        x = buf[i]
        while j < n_b and sets[b, j] < x:
            j += 1
        if j == n_b or sets[b, j] != x:
            return False
        j += 1
    return True


@numba.njit(cache=True)
def _unlink(head, lnext, w, target):
    prev = -1
    e = head[w]
    while e >= 0:
        if e == target:
            if prev < 0:
                head[w] = lnext[e]
            else:
                lnext[prev] = lnext[e]
            return
        prev = e
        e = lnext[e]


@numba.njit(cache=True)
def _max_frontier_bound(pos, order, head, lnext, val, cbound, lam, sets, ssize):
    """Largest bound of a label at a node not yet swept (for a time-limited exact search)."""
    best = -np.inf
    for i in range(pos, order.shape[0]):
        l = head[order[i]]
        while l >= 0:
            s = 0.0
            for t in range(ssize[l]):
                s += lam[sets[l, t]]
            b = val[l] + cbound[order[i]] - s
            if b > best:
                best = b
            l = lnext[l]
    return best


@dataclass
class SearchResult:
    nodes: np.ndarray  # canonical nodes of the best label's path, source excluded
    value: float
    complete: bool  # the sweep ran to the end with the requested beam
    frontier_bound: float  # max bound over the labels left unswept (-inf when complete)
    labels: int  # label slots used (memory high-water mark)
    pruned: int
    dominated: int
    extensions: int
    seconds: float


def label_search(graph: DiscreteGraph, weights: np.ndarray, *, beam: int = 0, incumbent: float = 0.0,
                 lam: np.ndarray | None = None, cbound: np.ndarray | None = None, unitary: bool = False,
                 time_limit: float | None = None, max_labels: int = 20_000_000,
                 on_limit: str = "beam1", check_every: int = 250_000) -> SearchResult:
    """Sweep the graph with labels; see the module docstring.

    `beam` = 0: unlimited labels per node (exact DP).  `cbound`/`lam`: a completion
    bound per node and the multipliers to subtract for the open set (see
    :func:`solvers.bound.completion_bound`); labels that cannot beat `incumbent`
    by a meaningful amount (1 in unitary mode, a relative 1e-12 otherwise) are cut.
    `on_limit`: at the time or label limit, "beam1" finishes the sweep with one
    label per node, "stop" returns at once (the result is then the best label seen).
    The clock is read every `check_every` label extensions.
    """
    t0 = time.perf_counter()
    n_nodes = graph.n_nodes
    w = np.asarray(weights, dtype=np.float64)
    last = acq_last_time(graph)
    lam = np.zeros(w.shape[0]) if lam is None else np.asarray(lam, dtype=np.float64)
    cbound = np.full(n_nodes, np.inf) if cbound is None else np.asarray(cbound, dtype=np.float64)
    gain_abs, gain_rel = (1.0 - 1e-6, 0.0) if unitary else (0.0, 1e-12)
    order = topological_order(graph)
    m = max_open(graph)
    cap = min(max_labels, max(1 << 16, 4 * n_nodes))
    val = np.empty(cap, np.float64)
    par = np.empty(cap, np.int32)
    lnode = np.empty(cap, np.int32)
    lnext = np.empty(cap, np.int32)
    sets = np.empty((cap, m), np.int32)
    ssize = np.empty(cap, np.int32)
    head = np.full(n_nodes, -1, np.int32)
    cnt = np.zeros(n_nodes, np.int32)
    wval = np.full(n_nodes, -np.inf)  # value of the worst label of a full beam
    # root label at the source
    val[0], par[0], lnode[0], lnext[0], ssize[0] = 0.0, -1, 0, -1, 0
    head[0], cnt[0] = 0, 1
    # [slots used, head of the free list, incumbent label, free slots]
    state = np.array([1, -1, 0 if incumbent <= 0.0 else -1, 0], np.int64)
    inc = np.array([max(incumbent, 0.0)])
    counters = np.zeros(4, np.int64)
    pos = 0
    complete = True
    frontier = -np.inf
    deadline = None if time_limit is None else t0 + time_limit
    while True:
        pos, why = _sweep(pos, order, graph.indptr, graph.dst, graph.node_acq, graph.node_time, w, last, lam, cbound,
                          gain_abs, gain_rel, beam, check_every, val, par, lnode, lnext, sets, ssize, head, cnt, wval,
                          state, inc, counters)
        if why == STOP_DONE:
            break
        limit_hit = deadline is not None and time.perf_counter() > deadline
        if why == STOP_GROW:
            v = order[pos]
            need = int(state[0]) + int(cnt[v]) * int(graph.indptr[v + 1] - graph.indptr[v])
            if need <= max_labels:
                new_cap = min(max_labels, max(need, 2 * cap))
                val, par, lnode, lnext, ssize = (np.resize(a, new_cap) for a in (val, par, lnode, lnext, ssize))
                grown = np.empty((new_cap, m), np.int32)
                grown[:cap] = sets
                sets, cap = grown, new_cap
            elif not complete:
                break  # even one label per node does not fit
            else:
                limit_hit = True  # out of label memory: treated like the time limit
        if limit_hit and complete:
            complete = False
            frontier = _max_frontier_bound(pos, order, head, lnext, val, cbound, lam, sets, ssize)
            if on_limit == "stop":
                break
            _trim_to_one(pos, order, head, lnext, cnt, val, wval)
            beam = 1
    best_label = int(state[2])
    n_labels = int(state[0])
    nodes = _path(best_label, par, lnode) if best_label >= 0 else np.zeros(0, np.int64)
    value = float(np.sum(w[graph.node_acq[nodes]])) if nodes.size else 0.0
    return SearchResult(nodes, value, complete, float(frontier), n_labels, int(counters[1]), int(counters[2]),
                        int(counters[3]), time.perf_counter() - t0)


@numba.njit(cache=True)
def _trim_to_one(pos, order, head, lnext, cnt, val, wval):
    """Keep only the best label at every node not yet swept."""
    for i in range(pos, order.shape[0]):
        v = order[i]
        best = head[v]
        e = head[v]
        while e >= 0:
            if val[e] > val[best]:
                best = e
            e = lnext[e]
        if best >= 0:
            lnext[best] = -1
            head[v] = best
            cnt[v] = 1
            wval[v] = val[best]


def _path(label: int, par: np.ndarray, lnode: np.ndarray) -> np.ndarray:
    out = []
    while label > 0:  # label 0 is the root at the source
        out.append(int(lnode[label]))
        label = int(par[label])
    return np.asarray(out[::-1], dtype=np.int64)


@dataclass
class RampConfig(SolverConfig):
    """RAMP: label setting with a beam of labels per node.  At the time limit the rest of the sweep keeps
    one label per node, so the answer is always a complete schedule."""

    beam: int = ranged(4, 1)
    """Labels kept per node (1: the classic best path per node, skipping repeats)."""
    pruned: bool = True
    """Search the pruned graph (false: the unpruned one, slower, never worse at equal beam)."""

    NAME = "ramp"


def solve(inst: Instance, cfg: RampConfig | None = None) -> Solution:
    """RAMP with `cfg.beam` labels per node on the pruned (default) or unpruned graph."""
    cfg = cfg or RampConfig()
    cfg.validate()
    g = inst.graph_for(cfg.pruned)
    w = objective_weights(inst, cfg.mode)
    res = label_search(g, w, beam=cfg.beam, time_limit=cfg.time_limit)
    return Solution(res.nodes, res.value, {"solver": "ramp", "beam": cfg.beam, "pruned": cfg.pruned,
                                           "complete": res.complete, "labels": res.labels,
                                           "seconds": res.seconds})
