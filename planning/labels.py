"""Label sweeps over a discrete graph (numba): the three the project runs, side by side.

A label is a partial schedule ending at a node: (value, parent label, node).  The graph is a DAG whose arcs go
forward in time, so a sweep visits the nodes by time and extends the labels of each along its arcs; what
keeps a schedule from repeating an acquisition, how many labels a node keeps and which dominate differ by
what the caller needs, and that is why there are three sweeps rather than one with options:

* :func:`label_search` (RAMP, the exact solver, the expert, the fleet's pass solves): forward over the whole
  graph, each label carrying its *open* acquisitions as an explicit sorted set, so that dominance is exact
  (subset test) and a Lagrangian completion bound per node can cut labels.  With no limit on the labels per
  node it is an exact dynamic program; with a beam it is RAMP.  Needs the open sets in memory (labels x
  max_open ints) and runs once per solve.
* :func:`window_sweep` (the window re-planning of :mod:`eosp.planning.windows`): forward, between two kept
  nodes of a schedule, thousands of times per refinement.  Open sets are hashed (XOR of random 64-bit keys) and
  repeats found by walking the chain back within one visibility window, so a label is three words; the work
  per call is bounded (`max_work` arcs, MAX_LABELS labels) and its scratch reused between calls.  Exactness is
  traded for a bounded cost per window.
* :func:`label_togo` (the environment's 'label' plan features): *backward* with one label per node, so that
  one sweep values every allowed action at once (each action's node's best completion); no open sets at all:
  a repeat is refused by walking the completion's chain within the acquisition's window.

RAMP's sweep
------------
The paper's reference "RAMP" is a Dijkstra search in the discrete graph that is
not exact because of the exclusion between the nodes of one acquisition.  The
graph is a DAG whose arcs go forward in time, so Dijkstra's settling order is
simply the nodes by increasing time: a node is settled once all its
predecessors have been.  :func:`label_search` sweeps the nodes in that order and keeps at
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
the prefix of the optimum (the default graph, the pruned one, keeps every
schedule: :mod:`eosp.graphs.prune`).  With ``beam=1`` it is the classic "best
path per node, skip repeats".

When the time limit is reached the rest of the sweep keeps one label per node,
so the result is always a complete schedule.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from eosp.graphs.discrete import DiscreteGraph, arc_to_acq

# ------------------------------------------------------------------ the forward sweep with open sets (RAMP, exact)


def topological_order(graph: DiscreteGraph) -> np.ndarray:
    """Nodes by increasing time, the source first: a topological order, since t_dst > t_src on every arc."""
    t = graph.node_time.copy()
    t[0] = -np.inf
    return np.argsort(t, kind="stable").astype(np.int32)


def acq_last_time(graph: DiscreteGraph) -> np.ndarray:
    """Time of the last node of every acquisition: after it the acquisition can no longer be visited."""
    return graph.node_time[graph.acq_ptr[1:] - 1].astype(np.float64)


STOP_DONE, STOP_GROW, STOP_CHECK = 0, 1, 2  # why _sweep returned
FIRST_LABELS = 1 << 16  # the label store's first size (at least; 4 a node beyond): a search within it never grows it


def max_open(graph: DiscreteGraph) -> int:
    """Largest possible open set: acquisitions visited less than the longest window ago.

    An acquisition j in the open set at node w was visited at some t_j with
    first(j) <= t_j <= t_w < last(j), so within the last W = max(last - first)
    seconds; consecutive visits of a path are at least the shortest arc apart.
    """
    span, gap = _span_and_gap(graph.node_time, graph.acq_ptr, graph.indptr, graph.dst)
    if not np.isfinite(gap):  # no arc between two acquisitions: paths of one node
        return 1
    return int(math.floor(span / max(gap, 1e-9))) + 2


@numba.njit(cache=True)
def _span_and_gap(node_time, acq_ptr, indptr, dst):
    """(longest window: max over acquisitions of last - first node time, 0 with none; :func:`_min_inner_gap`), in
    one call: the label search of every small pass of a fleet's sweeps starts with it."""
    span = 0.0
    for a in range(acq_ptr.shape[0] - 1):
        d = node_time[acq_ptr[a + 1] - 1] - node_time[acq_ptr[a]]
        if d > span:
            span = d
    return span, _min_inner_gap(node_time, indptr, dst)


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


class SweepGraph(NamedTuple):
    """What :func:`_sweep` reads of the graph: the nodes in sweep order (by time), CSR arcs, each node's
    acquisition and time, the objective weight of each acquisition and the time of its last node."""

    order: np.ndarray
    indptr: np.ndarray
    dst: np.ndarray
    node_acq: np.ndarray
    node_time: np.ndarray
    weight: np.ndarray
    last_time: np.ndarray


class Cut(NamedTuple):
    """The bound test of :func:`_sweep`: a label of value v at node w with open set S is cut when
    v + cbound[w] - sum(lam[S]) < incumbent + gain_abs + gain_rel * |incumbent|.  `repeats`: an extension
    to an acquisition of the open set is allowed and worth nothing (see :func:`label_search`)."""

    lam: np.ndarray
    cbound: np.ndarray
    gain_abs: float
    gain_rel: float
    repeats: bool


class Labels(NamedTuple):
    """The label store of :func:`_sweep` (see its docstring): per label its value, parent, node, next label at
    the same node (or in the free list), open set (row of `sets`) and its size; per node the head of its
    labels, their count and the worst value of a full beam; then the store's state, the incumbent's value and
    the counters."""

    val: np.ndarray
    par: np.ndarray
    lnode: np.ndarray
    lnext: np.ndarray
    sets: np.ndarray
    ssize: np.ndarray
    head: np.ndarray
    cnt: np.ndarray
    wval: np.ndarray
    state: np.ndarray
    inc: np.ndarray
    counters: np.ndarray


@numba.njit(cache=True)
def _sweep(pos, sg, cut, beam, max_work, labels):
    """Extend the labels of the nodes sg.order[pos:], in order, until done or told to stop (after `max_work`
    more extensions).

    Returns (pos, stop reason).  Label memory (:class:`Labels`): slots [0, state[0]) were used, the
    freed ones (dropped before their node was swept, so nobody's parent) are
    chained from state[1] through `lnext`, state[3] of them.  state[2] is the
    incumbent label (-1: none), inc[0] its value.  counters = [created, cut by
    bound or beam, dominated, extensions].  wval[w]: value of the worst label at w
    once w holds `beam` labels.
    """
    order, indptr, dst, node_acq, node_time, weight, last_time = sg
    lam, cbound, gain_abs, gain_rel, repeats = cut
    val, par, lnode, lnext, sets, ssize, head, cnt, wval, state, inc, counters = labels
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
                if used and not repeats:
                    continue
                counters[3] += 1
                tw = node_time[w]
                newval = val[l] + (0.0 if used else weight[k])
                # open set at w: the still-open acquisitions of l plus k, sorted
                nb = 0
                lam_sum = 0.0
                placed = used or last_time[k] <= tw  # k already in it, or closed at w: nothing to add
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


@dataclass(frozen=True)
class Bounds:
    """What cuts labels in :func:`label_search`: labels that cannot beat `incumbent` by a meaningful amount (1 in
    unitary mode, a relative 1e-12 otherwise) by their completion bound are cut.  `cbound`: a completion bound
    per node and `lam` the multipliers to subtract for the open set (see
    :func:`eosp.solvers.bound.completion_bound`); None: no bound (the incumbent alone cuts nothing)."""

    incumbent: float = 0.0
    lam: np.ndarray | None = None
    cbound: np.ndarray | None = None
    unitary: bool = False


def label_search(graph: DiscreteGraph, weights: np.ndarray, *, beam: int = 0, bounds: Bounds | None = None,
                 time_limit: float | None = None, max_labels: int = 20_000_000,
                 on_limit: str = "beam1", check_every: int = 250_000, repeats: bool = False) -> SearchResult:
    """Sweep the graph with labels; see the module docstring.

    `beam` = 0: unlimited labels per node (exact DP).  `bounds`: the incumbent and completion bounds that cut
    labels (:class:`Bounds`).  `on_limit`: at the time or label limit, "beam1" finishes the sweep with one
    label per node, "stop" returns at once (the result is then the best label seen).
    The clock is read every `check_every` label extensions.  `repeats`: a path may visit an acquisition again
    (the graph may then have arcs between nodes of one acquisition), its weight counted once: the best path
    where observing a target twice is allowed and credited once (the fleet bound's pass problems,
    :mod:`eosp.fleet.passgraph`).
    """
    t0 = time.perf_counter()
    w = np.asarray(weights, dtype=np.float64)
    n_nodes = graph.n_nodes
    if bounds is None and beam == 0 and not repeats and max_labels > 0:  # the plain DP: one call, most end there
        deadline = math.inf if time_limit is None else t0 + time_limit
        complete, frontier, n_labels, nodes, counters = _search_alone(
            graph.indptr, graph.dst, graph.node_acq, graph.node_time, graph.acq_ptr, w,
            Limits(max_labels, check_every, 4 * n_nodes + 1024, deadline))
        if complete or on_limit == "stop":  # else the loop below runs it again, finishing with one label a node
            value = float(np.sum(w[graph.node_acq[nodes]])) if nodes.size else 0.0
            return SearchResult(nodes, value, complete, frontier, int(n_labels), int(counters[1]),
                                int(counters[2]), int(counters[3]), time.perf_counter() - t0)
    b = bounds or Bounds()
    lam = np.zeros(w.shape[0]) if b.lam is None else np.asarray(b.lam, dtype=np.float64)
    cbound = np.full(n_nodes, np.inf) if b.cbound is None else np.asarray(b.cbound, dtype=np.float64)
    cut = Cut(lam, cbound, *((1.0 - 1e-6, 0.0) if b.unitary else (0.0, 1e-12)), repeats)
    order = topological_order(graph)
    sg = SweepGraph(order, graph.indptr, graph.dst, graph.node_acq, graph.node_time, w, acq_last_time(graph))
    m = max_open(graph)
    cap = min(max_labels, max(FIRST_LABELS, 4 * n_nodes))
    # [slots used, head of the free list, incumbent label, free slots]
    state = np.array([1, -1, 0 if b.incumbent <= 0.0 else -1, 0], np.int64)
    labels = Labels(np.empty(cap, np.float64), np.empty(cap, np.int32), np.empty(cap, np.int32),
                    np.empty(cap, np.int32), np.empty((cap, m), np.int32), np.empty(cap, np.int32),
                    np.full(n_nodes, -1, np.int32), np.zeros(n_nodes, np.int32),
                    np.full(n_nodes, -np.inf),  # value of the worst label of a full beam
                    state, np.array([max(b.incumbent, 0.0)]), np.zeros(4, np.int64))
    val, par, lnode, lnext, sets, ssize, head, cnt, wval, _, _, counters = labels
    # root label at the source
    val[0], par[0], lnode[0], lnext[0], ssize[0] = 0.0, -1, 0, -1, 0
    head[0], cnt[0] = 0, 1
    pos = 0
    complete = True
    frontier = -np.inf
    deadline = None if time_limit is None else t0 + time_limit
    while True:
        pos, why = _sweep(pos, sg, cut, beam, check_every, labels)
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
                labels = labels._replace(val=val, par=par, lnode=lnode, lnext=lnext, sets=sets, ssize=ssize)
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
    acqs = graph.node_acq[nodes]
    value = float(np.sum(w[np.unique(acqs) if repeats else acqs])) if nodes.size else 0.0
    return SearchResult(nodes, value, complete, float(frontier), n_labels, int(counters[1]), int(counters[2]),
                        int(counters[3]), time.perf_counter() - t0)


@numba.njit(cache=True)
def _grown(a, cap):
    """`a` in a new array of `cap` rows, its rows copied (the rest uninitialised: slots not yet used)."""
    out = np.empty((cap,) + a.shape[1:], a.dtype)
    out[:a.shape[0]] = a
    return out


class Limits(NamedTuple):
    """What stops :func:`_search_alone`: label slots (`max_labels`; the store starts at `first` and doubles), and
    the clock (`deadline`, a ``time.perf_counter()`` instant, math.inf for none), read every `max_work`
    extensions."""

    max_labels: int
    max_work: int
    first: int
    deadline: float


@numba.njit(cache=True)
def _now():
    with numba.objmode(t="float64"):
        t = time.perf_counter()
    return t


@numba.njit(cache=True)
def _search_alone(indptr, dst, node_acq, node_time, acq_ptr, weight, limits):
    """:func:`label_search` with no bound, no beam and no repeats, from the graph's arrays to the best path in one
    compiled call: (complete, frontier bound, label slots used, path, counters).  At a limit (the label slots,
    the clock) it stops as the loop of :func:`label_search` does with ``on_limit="stop"``: not complete, the
    best label's path, the best bound of a label not swept (:func:`_max_frontier_bound`).  The same sweep
    (:func:`_sweep`), the same labels, at the same points the same checks.

    Why: a fleet's price round solves thousands of passes of a few dozen nodes, and the store's set-up, the
    sweep order and the call of :func:`_sweep` with its three tuples cost 50 us a pass in Python against a few
    us of sweeping (a pass of 38 nodes of a 200-satellite day: 65 us, 15 of them the call)."""
    max_labels, max_work, first, deadline = limits
    n_nodes = node_time.shape[0]
    t = node_time.astype(np.float64)
    t[0] = -np.inf
    order = np.argsort(t, kind="mergesort").astype(np.int32)  # topological_order: by time, stable
    n_acq = acq_ptr.shape[0] - 1
    last_time = np.empty(n_acq, np.float64)
    for a in range(n_acq):
        last_time[a] = node_time[acq_ptr[a + 1] - 1]
    span, gap = _span_and_gap(node_time, acq_ptr, indptr, dst)
    m = 1 if not np.isfinite(gap) else int(math.floor(span / max(gap, 1e-9))) + 2  # max_open
    cap = max(1, min(max_labels, first))
    sg = SweepGraph(order, indptr, dst, node_acq, node_time, weight, last_time)
    cut = Cut(np.zeros(n_acq), np.full(n_nodes, np.inf), 0.0, 1e-12, False)
    state = np.zeros(4, np.int64)
    state[0], state[1] = 1, -1  # one slot used (the root), no free slot, the root the incumbent
    labels = Labels(np.empty(cap, np.float64), np.empty(cap, np.int32), np.empty(cap, np.int32),
                    np.empty(cap, np.int32), np.empty((cap, m), np.int32), np.empty(cap, np.int32),
                    np.full(n_nodes, -1, np.int32), np.zeros(n_nodes, np.int32), np.full(n_nodes, -np.inf),
                    state, np.zeros(1), np.zeros(4, np.int64))
    labels.val[0], labels.par[0], labels.lnode[0], labels.lnext[0], labels.ssize[0] = 0.0, -1, 0, -1, 0
    labels.head[0], labels.cnt[0] = 0, 1
    complete = True
    frontier = -np.inf
    pos, why = _sweep(0, sg, cut, 0, max_work, labels)
    while why != STOP_DONE:
        if why == STOP_GROW:
            v = order[pos]
            need = state[0] + labels.cnt[v] * (indptr[v + 1] - indptr[v])
            if need <= max_labels:
                cap = min(max_labels, max(need, 2 * cap))
                labels = Labels(_grown(labels.val, cap), _grown(labels.par, cap), _grown(labels.lnode, cap),
                                _grown(labels.lnext, cap), _grown(labels.sets, cap), _grown(labels.ssize, cap),
                                labels.head, labels.cnt, labels.wval, state, labels.inc, labels.counters)
                if _now() <= deadline:  # the loop reads the clock at every stop
                    pos, why = _sweep(pos, sg, cut, 0, max_work, labels)
                    continue
        elif _now() <= deadline:  # STOP_CHECK within the time
            pos, why = _sweep(pos, sg, cut, 0, max_work, labels)
            continue
        complete = False  # out of label memory or of time
        frontier = _max_frontier_bound(pos, order, labels.head, labels.lnext, labels.val, cut.cbound, cut.lam,
                                       labels.sets, labels.ssize)
        break
    n = 0
    q = state[2]
    while q > 0:
        n += 1
        q = labels.par[q]
    path = np.empty(n, np.int64)
    q = state[2]
    while q > 0:  # label 0 is the root at the source
        n -= 1
        path[n] = labels.lnode[q]
        q = labels.par[q]
    return complete, frontier, state[0], path, labels.counters


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



# ------------------------------------------------------------------ the window sweep (re-planning a stretch)

MAX_WORK = 100_000_000  # arcs a window may look at (~1 s; the refinement also caps it by the time left)
MAX_LABELS = 3_000_000  # labels a window may create (72 MB of scratch); a window that needs more stops


@numba.njit(cache=True, inline="always")
def _in_chain(lab_node, lab_par, node_acq, node_time, l, k, t_first):
    """Is acquisition k, whose first node is at time `t_first`, in label l's chain (its start label excluded)?
    The chain runs backwards in time, so the walk stops at the first node earlier than k's first node: only
    the last few nodes (those within k's visibility window) are looked at, however long the window."""
    while l >= 0 and lab_par[l] >= 0:
        v = lab_node[l]
        if node_time[v] < t_first:
            return False
        if node_acq[v] == k:
            return True
        l = lab_par[l]
    return False


@numba.njit(cache=True, inline="always")
def _open_key(lab_node, lab_par, node_acq, node_time, acq_ptr, key, l, k, t_w, span):
    """XOR of the keys of the acquisitions still open at time t_w (with a node later than t_w: the only ones a
    later extension could repeat) among k and label l's chain: two labels at one node with the same open set
    have the same futures, as in RAMP.  The chain is walked back only over the last `span` seconds (the
    longest visibility window: an acquisition visited earlier has closed)."""
    h = key[k] if node_time[acq_ptr[k + 1] - 1] > t_w else np.uint64(0)
    t_min = t_w - span
    while l >= 0 and lab_par[l] >= 0:
        v = lab_node[l]
        if node_time[v] < t_min:
            break
        j = node_acq[v]
        if node_time[acq_ptr[j + 1] - 1] > t_w:
            h ^= key[j]
        l = lab_par[l]
    return h


@numba.njit(cache=True)
def window_sweep(wg, sw, sc, u, e, beam, tally):
    """Best path from node u (exclusive) through the acquisitions not blocked in `sc.blocked` that reaches e's
    acquisition no later than e (e < 0: no end condition), over the arcs of `wg`
    (:class:`eosp.planning.chain.GraphArrays`).  Writes its nodes to `sc.seg`; returns (length, value), length
    -1 when the label memory ran out or more than `sw.max_work` arcs were looked at (no answer: the cost of a
    window is bounded, so a time limit is kept even on graphs of hundreds of arcs per node).

    The nodes between the anchors are visited by increasing time, keeping the `beam` best labels per node with
    distinct open sets (:func:`_open_key`; `sw.span`: the longest visibility window); of two with the same open
    set, the better; a label of the smallest open set a node allows drops those of no more value (RAMP's
    dominance in its most frequent case, which removes most labels of a wide sweep).  A candidate's repeat is
    found by walking the label's chain back only as far as the candidate's first node (:func:`_in_chain`).
    With a large enough beam it is exact within the window.  Scratch `sc` (:func:`scratch`): `slot` [N, >=
    beam], `cnt` [N], `wval` [N] (the worst value of a full beam: most extensions are refused on it alone, with
    no walk and no look at the beam), `mval` [N] (the smallest open set's), `stamp` [N] are kept between calls
    (stamp == sc.calls[0] marks this call's entries); tally[0] grows by the arcs looked at."""
    indptr, dst, acq_ptr, node_acq, node_time = wg
    weight, key, span, by_time, sorted_t, tol, max_work = sw
    slot, cnt, wval, mval, stamp, lab_node, lab_par, lab_val, lab_key, out, _tmp, _work, blocked, calls = sc
    call = calls[0]
    cap = lab_node.shape[0]
    t_u = node_time[u] if u > 0 else -np.inf
    t_e = node_time[e] if e >= 0 else np.inf
    acq_e = node_acq[e] if e >= 0 else -1
    # nodes strictly between the anchors' times, by time
    lo = np.searchsorted(sorted_t, t_u, side="right")
    hi = np.searchsorted(sorted_t, t_e, side="left")
    n_lab = 1
    lab_node[0] = u
    lab_par[0] = -1
    lab_val[0] = 0.0
    lab_key[0] = 0
    best_l = -1
    best_v = -np.inf
    work = 0
    for idx in range(lo - 1, hi):
        if idx < lo:
            v = u
            stamp[v] = call
            cnt[v] = 1
            slot[v, 0] = 0
        else:
            v = by_time[idx]
            if stamp[v] != call or cnt[v] == 0:
                continue
        # can the labels of v end the window (reach e's acquisition no later than e)?
        if e >= 0:
            x = arc_to_acq(indptr, dst, acq_ptr, v, acq_e)
            ends = x >= 0 and node_time[x] <= t_e
        else:
            ends = True
        for q in range(cnt[v]):
            l = slot[v, q]
            lv = lab_val[l]
            if ends and lv > best_v + tol:  # ties: the earliest end, which leaves the most room after it
                best_v = lv
                best_l = l
            work += indptr[v + 1] - indptr[v]
            tally[0] += indptr[v + 1] - indptr[v]
            if work > max_work:
                return -1, 0.0
            for a in range(indptr[v], indptr[v + 1]):
                w = dst[a]
                if node_time[w] >= t_e:
                    continue
                k = node_acq[w]
                if blocked[k]:
                    continue
                nv = lv + weight[k]
                if stamp[w] != call:
                    stamp[w] = call
                    cnt[w] = 0
                    mval[w] = -np.inf
                c = cnt[w]
                # dominated by a label of the smallest open set, or a full beam's worst: only a better one enters
                if nv <= mval[w] + tol or (c >= beam and nv <= wval[w] + tol):
                    continue
                if _in_chain(lab_node, lab_par, node_acq, node_time, l, k, node_time[acq_ptr[k]]):
                    continue
                nk = _open_key(lab_node, lab_par, node_acq, node_time, acq_ptr, key, l, k, node_time[w], span)
                if n_lab >= cap:
                    return -1, 0.0
                lab_node[n_lab] = w
                lab_par[n_lab] = l
                lab_val[n_lab] = nv
                lab_key[n_lab] = nk
                if nk == (key[k] if node_time[acq_ptr[k + 1] - 1] > node_time[w] else np.uint64(0)):
                    # the smallest open set a label at w can have (k's own, while its window is open): this label
                    # dominates every one here of no more value (RAMP's dominance in its most frequent case); at
                    # least the worst of a full beam goes, so there is room
                    mval[w] = nv
                    z = 0
                    for y in range(c):
                        o = slot[w, y]
                        if lab_val[o] > nv + tol:
                            slot[w, z] = o
                            z += 1
                    c = z + 1
                    cnt[w] = c
                else:
                    z = c
                    for y in range(c):
                        if lab_key[slot[w, y]] == nk:  # the same open set (up to a 64-bit hash collision)
                            z = y
                            break
                    if z < c:
                        if nv <= lab_val[slot[w, z]] + tol:
                            continue
                    elif c < beam:
                        c += 1
                        cnt[w] = c
                    else:  # replaces the worst
                        for y in range(c):
                            if lab_val[slot[w, y]] == wval[w]:
                                z = y
                                break
                slot[w, z] = n_lab
                n_lab += 1
                if c >= beam:
                    lo_v = np.inf
                    for y in range(c):
                        lo_v = min(lo_v, lab_val[slot[w, y]])
                    wval[w] = lo_v
    if best_l < 0:
        return 0, -np.inf
    m = 0
    x = best_l
    while lab_par[x] >= 0:
        m += 1
        x = lab_par[x]
    x = best_l
    for i in range(m - 1, -1, -1):
        out[i] = lab_node[x]
        x = lab_par[x]
    return m, best_v


class Sweep(NamedTuple):
    """What every :func:`window_sweep` of one :func:`eosp.planning.windows.replan_windows` call reads: objective weights [n_acq], the random 64-bit
    key of each acquisition, the longest window (`span`), the nodes by time (`by_time`) and their times
    (`sorted_t`), the gain below which a gain is none (`tol`) and the arcs a window may look at (`max_work`)."""

    weight: np.ndarray
    key: np.ndarray
    span: float
    by_time: np.ndarray
    sorted_t: np.ndarray
    tol: float
    max_work: int


class Scratch(NamedTuple):
    """The working arrays of the windows of one graph (:func:`scratch`): those of :func:`window_sweep`, then
    the path buffers of :func:`eosp.planning.windows.replan_windows`, the blocked flags and the window counter."""

    slot: np.ndarray
    cnt: np.ndarray
    wval: np.ndarray
    mval: np.ndarray
    stamp: np.ndarray
    lab_node: np.ndarray
    lab_par: np.ndarray
    lab_val: np.ndarray
    lab_key: np.ndarray
    seg: np.ndarray
    tmp: np.ndarray
    work: np.ndarray
    blocked: np.ndarray
    calls: np.ndarray



def scratch(graph, beam: int, max_work: int = MAX_WORK) -> Scratch:
    """The working arrays of :func:`eosp.planning.windows.replan_windows` for one graph, allocated once (a search's refinement runs
    thousands of rounds; fresh arrays each round cost ~1 ms of page faults at 100 acquisitions): slot
    [N, beam] (`beam`: the most labels per node any window keeps), cnt [N], wval [N], mval [N], stamp [N] (stamp == a
    window's id marks its entries, so nothing is cleared between windows), the label arrays (at most one label
    per arc looked at, and at most MAX_LABELS), the path buffers, the blocked flags and the window counter."""
    n_nodes, n_acq = graph.node_acq.shape[0], graph.acq_ptr.shape[0] - 1
    cap = min(max_work, MAX_LABELS) + int(np.max(np.diff(graph.indptr), initial=0)) + 2
    return Scratch(np.empty((n_nodes, beam), dtype=np.int32), np.zeros(n_nodes, dtype=np.int32), np.empty(n_nodes),
                   np.empty(n_nodes), np.full(n_nodes, -1, dtype=np.int64), np.empty(cap, dtype=np.int32),
                   np.empty(cap, dtype=np.int32), np.empty(cap, dtype=np.float64), np.empty(cap, dtype=np.uint64),
                   np.empty(n_acq + 1, dtype=np.int32), np.empty(n_acq + 2, dtype=np.int32),
                   np.empty(n_acq + 1, dtype=np.int32), np.zeros(n_acq, dtype=np.bool_), np.zeros(1, dtype=np.int64))


# ------------------------------------------------------------------ the backward sweep (one label per node)

@numba.njit(cache=True)
def label_togo(g, alive, after, weight, togo, nxt):
    """One label per node, swept backward in time over a graph restricted to its `alive` nodes (uint8 [N]) after
    position `after` of `g.order` (`g`: anything with node_acq, node_time, indptr, dst, acq_ptr and `order`, the
    nodes by time: the environment's graph, whose `after` is the last scheduled node's position):
    togo[v] = weight of v's acquisition + the largest togo[u] over the arcs v -> u whose chain (u, nxt[u], ...)
    does not hold v's acquisition; nxt[v] = that u (-1: none).  Nodes not alive after the last scheduled one:
    togo -1.  Every chain is a path of the environment's graph over alive nodes, each acquisition at most once,
    so from an allowed action's node it is a completion the environment can play.

    Why: in unitary mode Greedy's insertion is at 0.77-0.87 of the optimum, so its rollout values (the
    'greedy' plan features) hardly tell apart the 3-10 allowed actions of which exactly one keeps the optimum,
    the decisions where a unitary policy loses; a label sweep with one label per node (RAMP's sweep with a beam
    of 1, backward so that one sweep values every action) tells the optimal action apart in such decisions.
    Cost: one pass over the alive nodes' arcs; a candidate u is checked by walking its
    chain only while the chain is inside v's acquisition's window (an acquisition appears nowhere else).
    Ties go to the first arc."""
    node_acq, node_time, indptr, dst, acq_ptr, order = g.node_acq, g.node_time, g.indptr, g.dst, g.acq_ptr, g.order
    for p in range(order.shape[0] - 1, after, -1):
        v = order[p]
        togo[v] = -1.0
        nxt[v] = -1
        if alive[v] == 0 or v == 0:
            continue
        a = node_acq[v]
        end = node_time[acq_ptr[a + 1] - 1]
        best, arg = 0.0, -1
        for k in range(indptr[v], indptr[v + 1]):
            u = dst[k]
            if alive[u] == 0 or togo[u] <= best:
                continue
            c, ok = u, True
            while c >= 0 and node_time[c] <= end:
                if node_acq[c] == a:
                    ok = False
                    break
                c = nxt[c]
            if ok:
                best, arg = togo[u], u
        togo[v] = weight[a] + best
        nxt[v] = arg


@numba.njit(cache=True)
def togo_chain(node_acq, nxt, start, weight):
    """The chain of :func:`label_togo` from node `start` (-1: empty), following `nxt`: (acquisitions, nodes, worth
    by `weight` [n_acq])."""
    m, c = 0, start
    while c >= 0:
        m += 1
        c = nxt[c]
    acqs = np.empty(m, dtype=np.int32)
    nodes = np.empty(m, dtype=np.int32)
    worth, c = 0.0, start
    for i in range(m):
        nodes[i] = c
        acqs[i] = node_acq[c]
        worth += weight[acqs[i]]
        c = nxt[c]
    return acqs, nodes, worth
