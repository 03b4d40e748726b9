"""Moves on a complete schedule (numba): insert, swap, ruin and recreate.

A schedule is a path source -> n_1 -> ... -> n_L of a discrete graph, fixed by its sequence of acquisitions
(:mod:`eosp.planning.chain`: an edit re-reaches the nodes after it, a missing arc makes it infeasible), so every
move here returns a path of the same graph: on the environment's graph it replays action by action, on the
unpruned graph it is a feasible schedule that may use arcs the pruning removed.

Moves (first improvement; candidates in `Candidates.order`, by decreasing weight then earliest window end):

* insert (:func:`insert_pass`): an acquisition not scheduled, at the first position where it fits;
* swap (:func:`swap_pass`): drop the acquisition at one position, or replace it by an unscheduled one (the
  first `max_replace` that fit), and insert unscheduled ones in the positions around it (two before to two or
  three after, growing with each insertion); kept when the weight gained exceeds the weight dropped (in unitary
  mode: two for one);
* ruin and recreate (:func:`ruin_recreate`): drop a few consecutive positions, refill the gap in a random
  order, keep the result when it is not worse.

:func:`polish` repeats insert and swap until a round gains nothing.  The drivers (when to polish, how long to
refine, the window re-planning in between) are :class:`eosp.search.polish.Polisher`'s.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from eosp.planning.chain import apply_insert, remove, try_put


class Candidates(NamedTuple):
    """What the moves know of the acquisitions they may insert: objective weights [n_acq], the order in which
    they are tried (int64), each one's first and last node time [n_acq] and the longest window (`span`)."""

    weight: np.ndarray
    order: np.ndarray
    first_t: np.ndarray
    last_t: np.ndarray
    span: float


class Inserted(NamedTuple):
    """The moves' bookkeeping: which acquisitions are in the schedule being built (bool [n_acq]), a buffer of
    re-chained nodes (:func:`eosp.planning.chain.try_put`'s `tmp`) and the list of the acquisitions inserted."""

    in_path: np.ndarray
    tmp: np.ndarray
    ins: np.ndarray


class Ruin(NamedTuple):
    """One :func:`ruin_recreate` call's settings: rounds, the most consecutive positions dropped at once, the
    noise of the refill order and the random seed."""

    iters: int
    max_ruin: int
    noise: float
    seed: int


@numba.njit(cache=True)
def _first_position(node_time, path, n, t):
    """First position p with node_time[path[p]] >= t (n when none)."""
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) >> 1
        if node_time[path[mid]] < t:
            lo = mid + 1
        else:
            hi = mid
    return lo


@numba.njit(cache=True)
def insert_pass(g, c, in_path, path, n, tmp):
    """Insert every unscheduled acquisition (in `c.order`) where it first fits in path[:n] (a path of graph `g`,
    :class:`eosp.planning.chain.GraphArrays`); returns the new length."""
    indptr, dst, acq_ptr, node_acq, node_time = g
    order, first_t, last_t, span = c.order, c.first_t, c.last_t, c.span
    for j in order:
        if in_path[j]:
            continue
        # inserted before position p: path[p] is pushed to after j's start >= first_t[j], and a node moves
        # at most within its window, so path[p] started no earlier than first_t[j] - span
        p = _first_position(node_time, path, n, first_t[j] - span)
        while p <= n:
            if p > 0 and node_time[path[p - 1]] > last_t[j]:
                break
            m = try_put(indptr, dst, acq_ptr, node_acq, path, n, p, j, tmp, 0)
            if m > 0:
                n = apply_insert(path, n, p, tmp, m)
                in_path[j] = True
                break
            p += 1
    return n


@numba.njit(cache=True)
def fill(g, c, mv, work, wn, lo, hi, skip, n_ins):
    """Insert unscheduled acquisitions (not `skip`) of candidates `c` at positions lo..hi of work[:wn] (a path of
    graph `g`), first fit in `c.order`, the window growing with each insertion; marks them in `mv.in_path` and
    lists them in `mv.ins` from position `n_ins`.  Returns (wn, weight gained, n_ins)."""
    indptr, dst, acq_ptr, node_acq, node_time = g
    weight, order, first_t, last_t, span = c
    in_path, tmp, ins = mv
    gain = 0.0
    t_lo = node_time[work[lo - 1]] if lo > 0 else -np.inf
    for j in order:
        if in_path[j] or j == skip or last_t[j] < t_lo:
            continue
        if hi < wn and first_t[j] > node_time[work[hi]] + span:
            continue
        for p in range(lo, hi + 1):
            m = try_put(indptr, dst, acq_ptr, node_acq, work, wn, p, j, tmp, 0)
            if m > 0:
                wn = apply_insert(work, wn, p, tmp, m)
                in_path[j] = True
                ins[n_ins] = j
                n_ins += 1
                gain += weight[j]
                hi = min(hi + 1, wn)
                break
    return wn, gain, n_ins


@numba.njit(cache=True)
def swap_pass(g, c, mv, path, n, work, tol, max_replace):
    """At every position of path[:n], drop its acquisition (or replace it by an unscheduled one) and insert others
    around it; kept when the weight gained exceeds the weight dropped by more than `tol`.  `work`: a buffer of
    n_acq + 1 nodes.  Returns the new length."""
    indptr, dst, acq_ptr, node_acq, node_time = g
    weight, order, first_t, last_t, span = c
    in_path, tmp, ins = mv
    k = 0
    while k < n:
        a = node_acq[path[k]]
        kept = False
        # (1) drop position k, then fill the gap
        for i in range(n):
            work[i] = path[i]
        wn = remove(indptr, dst, acq_ptr, node_acq, work, n, k, tmp)
        n_ins = 0
        if wn >= 0:
            wn, gain, n_ins = fill(g, c, mv, work, wn, max(k - 2, 0), min(k + 2, wn), a, 0)
            kept = gain - weight[a] > tol
        # (2) replace position k by an unscheduled acquisition, then fill around it
        t_k = node_time[path[k]]
        tries = 0
        for j in order:
            if kept or tries >= max_replace:
                break
            if in_path[j] or last_t[j] < (node_time[path[k - 1]] if k > 0 else -np.inf) or first_t[j] > t_k + span:
                continue
            for q in range(n_ins):  # undo the previous attempt
                in_path[ins[q]] = False
            n_ins = 0
            m = try_put(indptr, dst, acq_ptr, node_acq, path, n, k, j, tmp, 1)
            if m < 0:
                continue
            tries += 1
            for i in range(n):
                work[i] = path[i]
            for i in range(m):
                work[k + i] = tmp[i]
            wn = n
            in_path[j] = True
            ins[0] = j
            wn, gain, n_ins = fill(g, c, mv, work, wn, max(k - 2, 0), min(k + 3, wn), a, 1)
            kept = weight[j] + gain - weight[a] > tol
        if kept:
            in_path[a] = False
            for i in range(wn):
                path[i] = work[i]
            n = wn
            k = max(k - 2, 0)  # the neighbourhood changed: look again from just before it
        else:
            for q in range(n_ins):
                in_path[ins[q]] = False
            k += 1
    return n


@numba.njit(cache=True)
def polish(g, c, path, n, max_rounds, tol, max_replace):
    """Rounds of :func:`insert_pass` then :func:`swap_pass` on path[:n] (int32, room for n_acq + 1 nodes) in
    place, until a round gains no more than `tol` or after `max_rounds`; returns the new length."""
    acq_ptr, node_acq = g.acq_ptr, g.node_acq
    weight = c.weight
    n_acq = acq_ptr.shape[0] - 1
    in_path = np.zeros(n_acq, dtype=np.bool_)
    for i in range(n):
        in_path[node_acq[path[i]]] = True
    tmp = np.empty(n_acq + 2, dtype=path.dtype)
    work = np.empty(n_acq + 1, dtype=path.dtype)
    ins = np.empty(n_acq + 1, dtype=np.int64)
    mv = Inserted(in_path, tmp, ins)
    for _ in range(max_rounds):
        value0 = 0.0
        for i in range(n):
            value0 += weight[node_acq[path[i]]]
        n = insert_pass(g, c, in_path, path, n, tmp)
        n = swap_pass(g, c, mv, path, n, work, tol, max_replace)
        value = 0.0
        for i in range(n):
            value += weight[node_acq[path[i]]]
        if value <= value0 + tol:
            break
    return n


@numba.njit(cache=True)
def ruin_recreate(g, c, path, n, ruin, tol):
    """`ruin.iters` rounds of: drop 1..ruin.max_ruin consecutive positions of the current schedule at random,
    refill the gap (two positions either side) with unscheduled acquisitions in a random order (weights times
    exp(ruin.noise * U[0, 1)): in unitary mode a uniformly random order; `c.order` is not used), and keep the
    result as the current schedule when it is not worse (plateaus are walked: equal-value schedules lead
    elsewhere).  path[:n] is the start on entry and the best met on exit; returns its length."""
    acq_ptr, node_acq, node_time = g.acq_ptr, g.node_acq, g.node_time
    weight, first_t, last_t, span = c.weight, c.first_t, c.last_t, c.span
    iters, max_ruin, noise = ruin.iters, ruin.max_ruin, ruin.noise
    np.random.seed(ruin.seed)
    n_acq = acq_ptr.shape[0] - 1
    cur = path.copy()
    work = path.copy()
    best = path.copy()
    in_cur = np.zeros(n_acq, dtype=np.bool_)
    for i in range(n):
        in_cur[node_acq[path[i]]] = True
    in_work = in_cur.copy()
    tmp = np.empty(n_acq + 2, dtype=path.dtype)
    ins = np.empty(n_acq + 1, dtype=np.int64)
    mv = Inserted(in_work, tmp, ins)
    cand = np.empty(n_acq, dtype=np.int64)
    key = np.empty(n_acq, dtype=np.float64)
    cn, bn = n, n
    cval = 0.0
    for i in range(n):
        cval += weight[node_acq[path[i]]]
    bval = cval
    for _ in range(iters):
        for i in range(cn):
            work[i] = cur[i]
        in_work[:] = in_cur
        wn = cn
        s = np.random.randint(0, wn) if wn > 0 else 0
        r = min(1 + np.random.randint(0, max_ruin), wn - s)
        lost = 0.0
        for _q in range(r):
            a = node_acq[work[s]]
            m = remove(g.indptr, g.dst, acq_ptr, node_acq, work, wn, s, tmp)
            if m < 0:
                break
            wn = m
            in_work[a] = False
            lost += weight[a]
        lo = max(s - 2, 0)
        hi = min(s + 2, wn)
        t_lo = node_time[work[lo - 1]] if lo > 0 else -np.inf
        t_hi = node_time[work[hi]] + span if hi < wn else np.inf
        nc = 0
        for j in range(n_acq):
            if not in_work[j] and last_t[j] >= t_lo and first_t[j] <= t_hi:
                cand[nc] = j
                key[nc] = -weight[j] * np.exp(noise * np.random.random())
                nc += 1
        order = cand[:nc][np.argsort(key[:nc])]
        wn, gain, _n = fill(g, Candidates(weight, order, first_t, last_t, span), mv, work, wn, lo, hi, -1, 0)
        val = cval - lost + gain
        if val >= cval - tol:
            for i in range(wn):
                cur[i] = work[i]
            cn = wn
            in_cur[:] = in_work
            cval = val
            if val > bval + tol:
                for i in range(wn):
                    best[i] = work[i]
                bn = wn
                bval = val
    for i in range(bn):
        path[i] = best[i]
    return bn
