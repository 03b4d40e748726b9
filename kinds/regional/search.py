"""Budgeted maximum coverage over the candidate strips: the greedy, the ruin-and-recreate search, as kernels.

The state is a selection of candidates and, per grid sample, how many selected strips cover it; a candidate's
gain is the value of the samples it covers that nothing selected covers yet (a sample counts once per strip,
however many of the strip's segments hold it).  A candidate fits a satellite's selection when it overlaps no
selected strip of that satellite and leaves, to its neighbours before and after, at least the slew time of the
roll change plus the settling time (the verifier's rule: only consecutive strips of a satellite are tested), and
when no window of one orbital period holds more imaging than the duty limit.  The battery is checked on the
whole schedule afterwards (a satellite that would run dry loses its least valuable strip until it does not).
"""

from __future__ import annotations

import heapq
from typing import NamedTuple

import numba
import numpy as np

from eosp.kinds.regional.strips import strip_samples
from eosp.regional.check import slew_s

TOL = 1.0e-6


class Cands(NamedTuple):
    """The candidates as the kernels read them (see eosp.kinds.regional.strips.Strips)."""

    sat: np.ndarray  # (C,) satellite
    start: np.ndarray  # (C,) seconds
    end: np.ndarray
    roll: np.ndarray
    seg0: np.ndarray  # index of the first slot in run_seg
    n: np.ndarray  # slots
    run_seg: np.ndarray
    cov_ptr: np.ndarray
    cov_idx: np.ndarray
    value: np.ndarray  # (samples,) value of each sample


class Sats(NamedTuple):
    """Per satellite: slew parameters, settling, duty limit (inf: none) and orbital period."""

    rate: np.ndarray
    acc: np.ndarray
    settle: np.ndarray
    duty: np.ndarray
    period: np.ndarray


@numba.njit(cache=True)
def gain(cd, c, cnt, stamp, tag, buf):
    """Value of the samples candidate c covers that no selected strip covers (`stamp`/`tag` dedupe samples)."""
    m = strip_samples(cd.seg0[c], cd.n[c], cd.run_seg, cd.cov_ptr, cd.cov_idx, stamp, tag, buf)
    g = 0.0
    for k in range(m):
        if cnt[buf[k]] == 0:
            g += cd.value[buf[k]]
    return g


@numba.njit(cache=True)
def gains(cd, cnt, stamp):
    """Every candidate's gain (see :func:`gain`)."""
    out = np.zeros(len(cd.sat))
    buf = np.empty(len(cnt), np.int64)
    tag = stamp.max()
    for c in range(len(cd.sat)):
        tag += 1
        out[c] = gain(cd, c, cnt, stamp, tag, buf)
    return out


@numba.njit(cache=True)
def fitting(cd, st, on, cands):
    """Which of `cands` fit among the chosen ones `on` (see :func:`fits`)."""
    out = np.zeros(len(cands), np.bool_)
    for j in range(len(cands)):
        out[j] = fits(cd, st, cands[j], on)
    return out


@numba.njit(cache=True)
def apply(cd, c, cnt, stamp, tag, sign):
    """Add (sign 1) or remove (sign -1) candidate c's samples to or from the counts."""
    buf = np.empty(len(cnt), np.int64)
    m = strip_samples(cd.seg0[c], cd.n[c], cd.run_seg, cd.cov_ptr, cd.cov_idx, stamp, tag, buf)
    for k in range(m):
        cnt[buf[k]] += sign


@numba.njit(cache=True)
def fits(cd, st, c, on):
    """Whether candidate c fits its satellite's strips among the chosen ones `on` (indices)."""
    s = cd.sat[c]
    a, b, r = cd.start[c], cd.end[c], cd.roll[c]
    prev, nxt = -1, -1
    for d in on:
        if cd.sat[d] != s or d == c:
            continue
        if cd.start[d] < b and a < cd.end[d]:
            return False
        if cd.start[d] < a or (cd.start[d] == a and cd.end[d] <= b):
            if prev < 0 or cd.start[d] > cd.start[prev]:
                prev = d
        elif nxt < 0 or cd.start[d] < cd.start[nxt]:
            nxt = d
    if prev >= 0 and a - cd.end[prev] < slew_s(r - cd.roll[prev], st.rate[s], st.acc[s]) + st.settle[s]:
        return False
    if nxt >= 0 and cd.start[nxt] - b < slew_s(cd.roll[nxt] - r, st.rate[s], st.acc[s]) + st.settle[s]:
        return False
    if np.isfinite(st.duty[s]):
        mine = [d for d in on if cd.sat[d] == s and d != c]
        mine.append(c)
        for e in mine:
            for bound in (cd.start[e], cd.end[e]):
                w0 = bound - st.period[s]
                used = 0.0
                for f in mine:
                    lo, hi = max(w0, cd.start[f]), min(bound, cd.end[f])
                    if hi > lo:
                        used += hi - lo
                if used > st.duty[s] - 1.0e-3:
                    return False
    return True


def greedy(cd: Cands, st: Sats, chosen: np.ndarray, cnt: np.ndarray, budget: int, allowed: np.ndarray | None = None,
           stamp: np.ndarray | None = None) -> float:
    """Add candidates to `chosen` (in place, counts too) by largest gain while they fit and the budget lasts
    (lazy: a gain only falls as strips are added).  Returns the value added."""
    stamp = np.zeros(len(cnt), np.int64) if stamp is None else stamp
    tag = [int(stamp.max()) + 1]
    buf = np.empty(len(cnt), np.int64)

    def g(c: int) -> float:
        tag[0] += 1
        return gain(cd, c, cnt, stamp, tag[0], buf)

    first = gains(cd, cnt, stamp)  # every gain in one call; the heap then only re-evaluates its top
    tag[0] = int(stamp.max()) + 1
    open_ = (~chosen) & (first > 0) if allowed is None else (~chosen) & (first > 0) & allowed
    pos = np.flatnonzero(open_)
    pos = pos[fitting(cd, st, np.flatnonzero(chosen), pos)]  # what does not fit now never will as strips are added
    heap = list(zip((-first[pos]).tolist(), pos.tolist()))
    heapq.heapify(heap)
    added = 0.0
    left = budget - int(chosen.sum())
    while heap and left > 0:
        neg, c = heapq.heappop(heap)
        fresh = g(c)
        if fresh <= 0:
            continue
        if heap and fresh < -heap[0][0] - 1e-15:
            heapq.heappush(heap, (-fresh, c))
            continue
        if not fits(cd, st, c, np.flatnonzero(chosen)):
            continue
        chosen[c] = True
        tag[0] += 1
        apply(cd, c, cnt, stamp, tag[0], 1)
        added += fresh
        left -= 1
    return added


def value(cd: Cands, cnt: np.ndarray) -> float:
    return float(cd.value[cnt > 0].sum())
