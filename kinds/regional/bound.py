"""An upper bound on the coverage ratio of every schedule whose strips lie on the candidate grid.

The grid: the rolls of :mod:`eosp.kinds.regional.strips`, starts and durations on the public time grid.  An
*item* is a strip of the grid given by its track, start and end; only items whose first time step covers a
sample are listed, with every length up to the sensor's maximum (shorter than its minimum too: a relaxation may
hold more than the rules allow).  A strip whose first step covers nothing covers what the item starting at its
first step that covers something and ending with it covers, inside its interval; so every schedule of the grid
maps to a set X of items with the same coverage whose intervals are sub-intervals of the strips'.

The bound.  Let v_i be sample i's value (its share of the coverage ratio), y_i = 1 when a strip covers it, U_c =
sum of u_i over the samples item c covers, for any u with 0 <= u_i <= v_i and any lambda >= 0.  For a feasible
schedule with items X (at most B = max_actions_total; per satellite, consecutive strips at least the settling time
apart, since the slew time is not negative, so every two of its items are that far apart):

    sum_i v_i y_i = sum_i (v_i - u_i) y_i + sum_i u_i y_i
                 <= sum_i (v_i - u_i) + sum_{c in X} U_c              (v - u >= 0, y <= 1, y_i <= #items covering i)
                 =  sum_i (v_i - u_i) + sum_{c in X} (U_c - lambda) + lambda |X|
                 <= sum_i (v_i - u_i) + sum_s WIS_s(U - lambda) + lambda B,

WIS_s being the heaviest set of the satellite's items pairwise at least its settling time apart (weighted interval
scheduling, exact by dynamic programming over the items sorted by end).  Every (u, lambda) gives a bound; a
projected subgradient descent (Polyak's step towards the best schedule found) lowers it, and the lowest one met is
reported.  Not modelled, so only making it weaker: the slew time's dependence on the roll change, the duty limit,
the battery.  tests/test_regional.py holds it against brute force over every grid schedule of tiny cases.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numba
import numpy as np

from eosp.kinds.regional.strips import Strips
from eosp.regional.model import Case


class Items(NamedTuple):
    sat: np.ndarray
    start: np.ndarray  # seconds
    end: np.ndarray
    k: np.ndarray  # first grid index
    n: np.ndarray  # segments
    seg0: np.ndarray  # first slot in run_seg
    order: np.ndarray  # items sorted by (satellite, end)
    pred: np.ndarray  # per item (in `order`), the last compatible position before it in `order` (-1: none)
    first: np.ndarray  # per item (in `order`), the first position of its satellite


def items(case: Case, strips: Strips) -> Items:
    """Every item of the grid (see the module docstring)."""
    per = int(round(case.time_step_s / strips.step_s))
    sat, k, n, seg0 = [], [], [], []
    for c in range(len(strips)):  # a longer item of the same start covers no more, in a longer interval
        s = int(strips.track_sat[strips.cand_track[c]])
        for m in range(per, int(strips.cand_n[c]) + 1, per):
            sat.append(s)
            k.append(int(strips.cand_k[c]))
            n.append(m)
            seg0.append(int(strips.cand_seg0[c]))
    sat_a, k_a, n_a = np.array(sat, np.int64), np.array(k, np.int64), np.array(n, np.int64)
    start, end = k_a * strips.step_s, (k_a + n_a) * strips.step_s
    order = np.lexsort((end, sat_a))
    settle = np.array([s.settling_time_s for s in case.satellites])
    pred = np.full(len(order), -1, np.int64)
    first = np.zeros(len(order), np.int64)
    so, eo, to = sat_a[order], end[order], start[order]
    for s in np.unique(so):
        pos = np.flatnonzero(so == s)
        j = np.searchsorted(eo[pos], to[pos] - settle[s] + 1e-6, side="right") - 1
        pred[pos] = np.where(j >= 0, pos[0] + j, -1)
        first[pos] = pos[0]
    return Items(sat_a, start, end, k_a, n_a, np.array(seg0, np.int64), order, pred, first)


@numba.njit(cache=True)
def _weights(u, seg0, n, run_seg, cov_ptr, cov_idx, stamp):
    w = np.zeros(len(seg0))
    tag = stamp.max()
    for c in range(len(seg0)):
        tag += 1
        total = 0.0
        for j in range(seg0[c], seg0[c] + n[c]):
            s = run_seg[j]
            if s < 0:
                continue
            for q in range(cov_ptr[s], cov_ptr[s + 1]):
                i = cov_idx[q]
                if stamp[i] != tag:
                    stamp[i] = tag
                    total += u[i]
        w[c] = total
    return w


@numba.njit(cache=True)
def _wis(w, order, pred, first):
    """Heaviest compatible sets of every satellite at once: (total, chosen positions mask in `order`)."""
    m = len(order)
    best = np.zeros(m + 1)  # best[j + 1]: best over positions first[j]..j of j's satellite
    take = np.zeros(m, np.bool_)
    total = 0.0
    for j in range(m):
        wj = w[order[j]]
        without = best[j] if j > first[j] else 0.0
        with_ = wj + (best[pred[j] + 1] if pred[j] >= 0 else 0.0)
        if wj > 0 and with_ > without:
            best[j + 1] = with_
            take[j] = True
        else:
            best[j + 1] = without
        if j == m - 1 or first[j + 1] != first[j]:
            total += best[j + 1]
    chosen = np.zeros(m, np.bool_)
    j = m - 1
    while j >= 0:  # walk back each satellite's choices
        if take[j]:
            chosen[j] = True
            j = pred[j] if pred[j] >= first[j] else first[j] - 1
        else:
            j = j - 1
    return total, chosen


@numba.njit(cache=True)
def _counts(chosen_items, seg0, n, run_seg, cov_ptr, cov_idx, cnt, stamp):
    tag = stamp.max()
    for c in chosen_items:
        tag += 1
        for j in range(seg0[c], seg0[c] + n[c]):
            s = run_seg[j]
            if s < 0:
                continue
            for q in range(cov_ptr[s], cov_ptr[s + 1]):
                i = cov_idx[q]
                if stamp[i] != tag:
                    stamp[i] = tag
                    cnt[i] += 1


def lagrangian(case: Case, strips: Strips, found: float, seconds: float, iterations: int = 200) -> tuple[float, int]:
    """The lowest bound met in `iterations` subgradient steps or `seconds` (see the module docstring), and the
    steps taken.  `found`: the best schedule's value (Polyak's target)."""
    v = case.sample_value()
    it = items(case, strips)
    B = case.max_actions if case.max_actions is not None else len(it.sat)
    reach = np.zeros(len(v), bool)
    reach[strips.cov_idx] = True
    u = v.copy()
    lam = 0.0
    stamp = np.zeros(len(v), np.int64)
    best = float(v[reach].sum())  # every item relaxed: each sample paid once
    t0, steps = time.perf_counter(), 0
    theta = 1.0
    stall = 0
    for steps in range(1, iterations + 1):
        w = _weights(u, it.seg0, it.n, strips.run_seg, strips.cov_ptr, strips.cov_idx, stamp)
        stamp[:] = 0
        total, chosen = _wis(w - lam, it.order, it.pred, it.first)
        picked = it.order[chosen]
        value = float((v - u)[reach].sum()) + total + lam * B
        if value < best - 1e-12:
            best, stall = value, 0
        else:
            stall += 1
            if stall >= 5:
                theta, stall = theta / 2, 0
        cnt = np.zeros(len(v), np.int64)
        _counts(picked, it.seg0, it.n, strips.run_seg, strips.cov_ptr, strips.cov_idx, cnt, stamp)
        stamp[:] = 0
        g_u = (cnt - 1).astype(float) * reach  # dL/du_i = -1 + #chosen items covering i
        g_l = B - len(picked)
        norm = float(g_u @ g_u) + g_l * g_l
        if norm <= 0 or best - found <= 1e-12 or time.perf_counter() - t0 > seconds:
            break
        step = theta * (value - found) / norm
        u = np.clip(u - step * g_u, 0.0, v)
        lam = max(0.0, lam - step * g_l)
    return max(best, found), steps
