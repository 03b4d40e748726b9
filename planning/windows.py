"""Window re-planning: a stretch of a schedule planned again by a label sweep (numba).

Why: the insert/swap moves and the ruin-and-recreate of :mod:`eosp.planning.moves` refill a gap
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
the re-chaining checks it and refuses the move otherwise).  The sweep is
:func:`eosp.planning.labels.window_sweep` (`beam` labels per node, open sets hashed, as in RAMP two labels
with the same open set keep the better); with a large enough beam it is exact within the window, the default
keeps it a heuristic like RAMP's.  A window stops (no answer) after `max_work` arcs or MAX_LABELS labels, so
its cost is bounded on graphs of hundreds of arcs per node.

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

from eosp.planning.chain import rechain
from eosp.planning.labels import MAX_LABELS, MAX_WORK, Scratch, Sweep, scratch, window_sweep

__all__ = ["FIRST_WORK", "LONG_BEAM", "MAX_LABELS", "MAX_WORK", "Scratch", "Sweep", "WindowPlan", "replan_windows",
           "scratch", "try_window"]

FIRST_WORK = 3_000_000  # arcs of a refinement's first round of windows, before their rate is known (~10 ms)
LONG_BEAM = 16  # labels per node a long window may keep at most (the refinement doubles them round by round)


class WindowPlan(NamedTuple):
    """One :func:`replan_windows` call: up to `iters` windows of 1..window positions with `beam` labels per node,
    or (every other one on average, when `long_window` > window) 1..long_window positions with `long_beam`;
    the random seed; and the arcs all windows may look at together (`budget`)."""

    window: int
    beam: int
    long_window: int
    long_beam: int
    iters: int
    seed: int
    budget: int


@numba.njit(cache=True)
def _splice(g, path, n, s, r, seg, m, tmp, work):
    """path[:s] + seg[:m] + path[s + r:n] re-chained (over graph `g`) from the segment's last node, into work;
    returns the new length, or -1 when the re-chaining misses an arc."""
    cur = seg[m - 1] if m > 0 else (path[s - 1] if s > 0 else 0)
    k = rechain(g.indptr, g.dst, g.acq_ptr, g.node_acq, path, n, s + r, cur, tmp, 0)
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


@numba.njit(cache=True)
def try_window(g, wg, sw, sc, path, n, s, r, beam, tally):
    """Re-plan positions s..s+r-1 of path[:n] with `beam` labels per node; applied in place when it does not
    lose (plateaus are walked).  The window is planned over the arcs of `wg`, a subset of `g`'s on the same
    nodes (e.g. the pruned graph's), the rest of the path re-chained over `g`'s; `sc.calls[0]` is this window's
    id in the scratch `sc`, tally[0] grows by the arcs looked at.  Returns (new length, gained, aborted: the
    window was too costly to plan)."""
    node_acq = g.node_acq
    weight, tol = sw.weight, sw.tol
    seg, tmp, work, blocked = sc.seg, sc.tmp, sc.work, sc.blocked
    old = 0.0
    for i in range(s, s + r):
        blocked[node_acq[path[i]]] = False
        old += weight[node_acq[path[i]]]
    u = path[s - 1] if s > 0 else 0
    e = path[s + r] if s + r < n else -1
    m, val = window_sweep(wg, sw, sc, u, e, beam, tally)
    wn = -1
    aborted = m < 0
    if m >= 0 and val >= old - tol:  # a gain, or a plateau (tol >= 0)
        wn = _splice(g, path, n, s, r, seg, m, tmp, work)
    if wn < 0:
        for i in range(s, s + r):
            blocked[node_acq[path[i]]] = True
        return n, False, aborted
    for i in range(wn):
        path[i] = work[i]
    for i in range(s, s + m):
        blocked[node_acq[path[i]]] = True
    return wn, val > old + tol, False


@numba.njit(cache=True)
def replan_windows(g, wg, sw, path, n, plan, sc):
    """Re-plan up to `plan.iters` windows of path[:n] (int32) in place, each 1..plan.window consecutive positions
    at random with `plan.beam` labels per node, or (every other window on average, when `plan.long_window` >
    plan.window) 1..long_window positions with `plan.long_beam` labels per node: a long stretch swept like
    RAMP's sweep, which finds what a different sequence over much of the schedule gains (at 1000-1500
    acquisitions the short windows stop one or two acquisitions short of RAMP); until `plan.budget` arcs were
    looked at in all (the caller turns a time into arcs at the rate it measured).  A window's new plan is kept
    when it is not worse (plateaus are walked: equal-value schedules lead elsewhere), so the value never drops.
    Windows are planned over the arcs of `wg` (:func:`try_window`), the rest re-chained over `g`'s.  `sc`:
    :func:`eosp.planning.labels.scratch` of `wg`, with room for max(beam, long_beam) labels per node.  Returns
    (new length, windows tried, windows aborted for their cost, arcs looked at, long windows tried, long
    windows aborted)."""
    window, beam, long_window, long_beam, iters, seed, budget = plan
    np.random.seed(seed)
    node_acq = g.node_acq
    blocked, calls = sc.blocked, sc.calls
    assert max(beam, long_beam) <= sc.slot.shape[1]
    blocked[:] = False
    for i in range(n):
        blocked[node_acq[path[i]]] = True
    aborted = tried = long_aborted = long_tried = 0
    tally = np.zeros(1, dtype=np.int64)
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
        n, _g, a = try_window(g, wg, sw, sc, path, n, s, r, b, tally)
        aborted += a
        if a and is_long:
            long_aborted += 1
    return n, tried, aborted, tally[0], long_tried, long_aborted
