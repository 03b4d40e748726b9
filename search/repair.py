"""Window repair: re-plan a stretch of a schedule by a label sweep (numba; no torch, no Ray).

Why: the insert/swap moves and the ruin-and-recreate of :mod:`eosp.search.polish` refill a gap
greedily, one acquisition at a time, in some order.  The schedules they leave are often one
acquisition (or one low-class utility) short of RAMP's, and the better one needs a different
*sequence* over several consecutive positions (four acquisitions where there were three), which a
first-fit refill rarely builds.  RAMP finds it because its label sweep compares all sequences
through every node.  This module runs the same kind of sweep, but only over the time between two
kept nodes of a schedule, so at 100 acquisitions a window costs well under a millisecond and the
refinement repeats it at random stretches until its time is up.

The window between anchors u = path[s - 1] (the source when s = 0) and e = path[s + r] (none when the
window reaches the end) is re-planned as the best path from u through acquisitions not scheduled
outside the window, ending at a node from which e's acquisition is reached no later than e (then the
rest of the schedule re-chains no later than before: a node's arc to an acquisition depends only on the
node and reaches no later from an earlier node of the same acquisition in the graphs of this project;
the re-chaining checks it and refuses the move otherwise).  The sweep visits the nodes of the window by
increasing time (arcs go forward in time) and keeps the `beam` best labels per node (value, parent);
a label's acquisitions are its chain, checked for repeats by walking it back only as far as the
candidate acquisition's first node (the chain runs backwards in time).  As in RAMP, what a label can still
do depends only on its node and its *open* acquisitions (visited, with a node later than the label's): two
labels at one node with the same open set (the XOR of random 64-bit keys of its acquisitions) keep the
better, and a label whose open set is the smallest possible there drops every label of no more value (the
most frequent dominance, which removes most labels of a wide sweep on large instances).  With a
large enough beam it is exact within the window; the default keeps it a heuristic like RAMP's.  A window
stops (no answer) after `max_work` arcs or MAX_LABELS labels, so its cost is bounded on graphs of hundreds
of arcs per node.

Two kinds of windows: short ones (up to 16 positions, 4 labels per node) and long ones (up to the
whole schedule: a sweep like RAMP's, anchored on the kept part, whose labels per node the refinement
raises 1, 2, 4, ... as RAMP's beam is raised with the time).  At 100 acquisitions the short ones do the
work; at 1000-1500 the schedules that reach RAMP's value differ from the learned one over much of the
horizon, which only the long ones reach.  The arcs swept are the pruned graph's by default
(:class:`eosp.search.polish.Polisher` ``window_graph``), ~10x fewer than the unpruned graph's at 1500
acquisitions.
"""
from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from eosp.graphs.discrete import arc_to_acq
from eosp.search.chain import GraphArrays, rechain

MAX_WORK = 100_000_000  # arcs a window may look at (~1 s; the refinement also caps it by the time left)
FIRST_WORK = 3_000_000  # arcs of a refinement's first round of windows, before their rate is known (~10 ms)
MAX_LABELS = 3_000_000  # labels a window may create (72 MB of scratch); a window that needs more stops
LONG_BEAM = 16  # labels per node a long window may keep at most (the refinement doubles them round by round)


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
def _window(indptr, dst, acq_ptr, node_acq, node_time, weight, key, span, by_time, sorted_t, blocked, u, e, beam,
            lab_node, lab_par, lab_val, lab_key, slot, cnt, wval, mval, stamp, call, out, tol, max_work, tally):
    """Best path from node u (exclusive) through unblocked acquisitions that reaches e's acquisition no
    later than e (e < 0: no end condition).  Writes its nodes to `out`; returns (length, value), length
    -1 when the label memory ran out or more than `max_work` arcs were looked at (no answer: the cost of a
    window is bounded, so a time limit is kept even on graphs of hundreds of arcs per node).  Keeps the `beam`
    best labels per node with distinct open sets (:func:`_open_key`; `span`: the longest visibility window);
    of two with the same open set, the better; a label of the smallest open set a node allows drops those of no
    more value.  `slot` [N, >= beam], `cnt` [N], `wval` [N] (the worst value of a full beam: most extensions are
    refused on it alone, with no walk and no look at the beam), `mval` [N] (the smallest open set's), `stamp` [N] are
    scratch kept between calls (stamp == call marks this call's entries); tally[0] grows by the arcs looked at."""
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


@numba.njit(cache=True)
def _splice(indptr, dst, acq_ptr, node_acq, path, n, s, r, seg, m, tmp, work):
    """path[:s] + seg[:m] + path[s + r:n] re-chained from the segment's last node, into work; returns the
    new length, or -1 when the re-chaining misses an arc."""
    cur = seg[m - 1] if m > 0 else (path[s - 1] if s > 0 else 0)
    k = rechain(indptr, dst, acq_ptr, node_acq, path, n, s + r, cur, tmp, 0)
    if k < 0:
        return -1
    for i in range(s):
        work[i] = path[i]
    for i in range(m):
        work[s + i] = seg[i]
    for i in range(k):
        work[s + m + i] = tmp[i]
    j = s + m + k
    for i in range(s + r + k, n):
        work[j] = path[i]
        j += 1
    return j


class Sweep(NamedTuple):
    """What every window of one :func:`replan_windows` call reads: objective weights [n_acq], the random 64-bit
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
    """The working arrays of the windows of one graph (:func:`scratch`)."""

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


@numba.njit(cache=True)
def _try(g, wg, sw, sc, path, n, s, r, beam, tally):
    """Re-plan positions s..s+r-1 of path[:n] with `beam` labels per node; applied in place when it does not
    lose (plateaus are walked).  The window is planned over the arcs of `wg`, a subset of `g`'s on the same
    nodes (e.g. the pruned graph's), the rest of the path re-chained over `g`'s; `sc.calls[0]` is this window's
    id in the scratch `sc`, tally[0] grows by the arcs looked at.  Returns (new length, gained, aborted: the
    window was too costly to plan)."""
    indptr, dst, acq_ptr, node_acq, node_time = g
    w_indptr, w_dst = wg.indptr, wg.dst
    weight, key, span, by_time, sorted_t, tol, max_work = sw
    slot, cnt, wval, mval, stamp, lab_node, lab_par, lab_val, lab_key, seg, tmp, work, blocked, calls = sc
    call = calls[0]
    old = 0.0
    for i in range(s, s + r):
        blocked[node_acq[path[i]]] = False
        old += weight[node_acq[path[i]]]
    u = path[s - 1] if s > 0 else 0
    e = path[s + r] if s + r < n else -1
    m, val = _window(w_indptr, w_dst, acq_ptr, node_acq, node_time, weight, key, span, by_time, sorted_t, blocked,
                     u, e, beam, lab_node, lab_par, lab_val, lab_key, slot, cnt, wval, mval, stamp, call, seg, tol,
                     max_work, tally)
    wn = -1
    aborted = m < 0
    if m >= 0 and val >= old - tol:  # a gain, or a plateau (tol >= 0)
        wn = _splice(indptr, dst, acq_ptr, node_acq, path, n, s, r, seg, m, tmp, work)
    if wn < 0:
        for i in range(s, s + r):
            blocked[node_acq[path[i]]] = True
        return n, False, aborted
    for i in range(wn):
        path[i] = work[i]
    for i in range(s, s + m):
        blocked[node_acq[path[i]]] = True
    return wn, val > old + tol, False


def scratch(graph, beam: int, max_work: int = MAX_WORK) -> Scratch:
    """The working arrays of :func:`replan_windows` for one graph, allocated once (a search's refinement runs
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


@numba.njit(cache=True)
def replan_windows(indptr, dst, w_indptr, w_dst, acq_ptr, node_acq, node_time, weight, key, span, by_time, sorted_t,
                   path, n, window, beam, long_window, long_beam, iters, seed, tol, max_work, budget, scratch):
    """Re-plan up to `iters` windows of path[:n] (int32) in place, each 1..window consecutive positions at
    random with `beam` labels per node, or (every other window on average, when `long_window` > window)
    1..long_window positions with `long_beam` labels per node: a long stretch swept like RAMP's sweep, which
    finds what a different sequence over much of the schedule gains (at 1000-1500 acquisitions the short
    windows stop one or two acquisitions short of RAMP); until `budget` arcs were looked at in all (the
    caller turns a time into arcs at the rate it measured).  A window's new plan is kept when it is not worse
    (plateaus are walked: equal-value schedules lead elsewhere), so the value never drops.  Windows are
    planned over the arcs (w_indptr, w_dst) (:func:`_try`).  `scratch`: :func:`scratch` of that graph, with
    room for max(beam, long_beam) labels per node.  Returns (new length, windows tried, windows
    aborted for their cost, arcs looked at, long windows tried, long windows aborted)."""
    np.random.seed(seed)
    slot, cnt, wval, mval, stamp, lab_node, lab_par, lab_val, lab_key, seg, tmp, work, blocked, calls = scratch
    assert max(beam, long_beam) <= slot.shape[1]
    blocked[:] = False
    for i in range(n):
        blocked[node_acq[path[i]]] = True
    aborted = tried = long_aborted = long_tried = 0
    tally = np.zeros(1, dtype=np.int64)
    g = GraphArrays(indptr, dst, acq_ptr, node_acq, node_time)
    wg = GraphArrays(w_indptr, w_dst, acq_ptr, node_acq, node_time)
    sw = Sweep(weight, key, span, by_time, sorted_t, tol, max_work)
    for _ in range(iters):
        if n == 0 or tally[0] >= budget:
            break
        tried += 1
        calls[0] += 1
        b = beam
        is_long = long_window > window and np.random.random() < 0.5
        if is_long:
            r, b = min(1 + np.random.randint(0, long_window), n), long_beam
            long_tried += 1
        else:
            r = min(1 + np.random.randint(0, window), n)
        s = np.random.randint(0, n - r + 1)
        n, _g, a = _try(g, wg, sw, scratch, path, n, s, r, b, tally)
        aborted += a
        if a and is_long:
            long_aborted += 1
    return n, tried, aborted, tally[0], long_tried, long_aborted
