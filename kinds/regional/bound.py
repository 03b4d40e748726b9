"""An upper bound on the coverage ratio of every schedule whose strips lie on the candidate grid.

The grid: the rolls of :mod:`eosp.kinds.regional.strips`, starts and durations on the public time grid.  An
*item* is a strip of the grid given by its track, start and end; only items whose first time step covers a
sample are listed, with every length up to the sensor's maximum (shorter than its minimum too: a relaxation may
hold more than the rules allow).  A strip whose first step covers nothing covers what the item starting at its
first step that covers something and ending with it covers, inside its interval; so every schedule of the grid
maps to a set X of items with the same coverage whose intervals are sub-intervals of the strips'.

The bound.  Let v_i be sample i's value (its share of the coverage ratio), y_i = 1 when a strip covers it, U_c =
sum of u_i over the samples item c covers, for any u with 0 <= u_i <= v_i and any lambda >= 0.  For a feasible
schedule with items X (at most B = max_actions_total; per satellite a chain: consecutive strips at least the
settling time plus the slew time of their roll change apart, which the items keep, their intervals being inside
the strips'):

    sum_i v_i y_i = sum_i (v_i - u_i) y_i + sum_i u_i y_i
                 <= sum_i (v_i - u_i) + sum_{c in X} U_c              (v - u >= 0, y <= 1, y_i <= #items covering i)
                 =  sum_i (v_i - u_i) + sum_{c in X} (U_c - lambda) + lambda |X|
                 <= sum_i (v_i - u_i) + sum_s CHAIN_s(U - lambda) + lambda B,

CHAIN_s being the heaviest chain of the satellite's items (exact, by dynamic programming over the items by start:
:func:`_chains`).  Every (u, lambda) gives a bound; a projected subgradient descent (Polyak's step towards the
best schedule found) lowers it, and the lowest one met is reported.  Not modelled, so only making it weaker: the
duty limit, the battery, and that a sample counts once however many strips cover it (priced by u, not enforced).  tests/test_regional.py holds it against brute force over every grid schedule of tiny cases.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numba
import numpy as np

from eosp.kinds.regional.strips import Strips, strip_samples
from eosp.regional.check import slew_s
from eosp.regional.model import Case


class Items(NamedTuple):
    sat: np.ndarray
    start: np.ndarray  # seconds
    end: np.ndarray
    roll: np.ndarray
    n: np.ndarray  # segments
    seg0: np.ndarray  # first slot in run_seg
    order: np.ndarray  # items sorted by (satellite, start): the order of the chains' recursion
    t_ptr: np.ndarray  # per track, its items sorted by end (CSR): the predecessors a chain looks up
    t_items: np.ndarray
    t_end: np.ndarray
    t_roll: np.ndarray
    s_ptr: np.ndarray  # per satellite, its tracks (CSR)
    s_tracks: np.ndarray
    settle: np.ndarray  # per satellite
    rate: np.ndarray
    acc: np.ndarray


def items(case: Case, strips: Strips) -> Items:
    """Every item of the grid (see the module docstring)."""
    per = int(round(case.time_step_s / strips.step_s))
    track, k, n, seg0 = [], [], [], []
    for c in range(len(strips)):  # a longer item of the same start covers no more, in a longer interval
        for m in range(per, int(strips.cand_n[c]) + 1, per):
            track.append(int(strips.cand_track[c]))
            k.append(int(strips.cand_k[c]))
            n.append(m)
            seg0.append(int(strips.cand_seg0[c]))
    tr, k_a, n_a = np.array(track, np.int64), np.array(k, np.int64), np.array(n, np.int64)
    sat = strips.track_sat[tr] if len(tr) else np.zeros(0, np.int64)
    start, end = k_a * strips.step_s, (k_a + n_a) * strips.step_s
    by_track = np.lexsort((end, tr))
    t_ptr = np.r_[0, np.cumsum(np.bincount(tr, minlength=len(strips.track_sat)))].astype(np.int64)
    ts = np.argsort(strips.track_sat, kind="stable")
    s_ptr = np.r_[0, np.cumsum(np.bincount(strips.track_sat, minlength=len(case.satellites)))].astype(np.int64)
    sats = case.satellites
    return Items(sat, start, end, strips.track_roll[tr] if len(tr) else np.zeros(0), n_a, np.array(seg0, np.int64),
                 np.lexsort((start, sat)), t_ptr, by_track, end[by_track], strips.track_roll.astype(float),
                 s_ptr, ts.astype(np.int64), np.array([x.settling_time_s for x in sats]),
                 np.array([x.max_roll_rate_deg_per_s for x in sats]),
                 np.array([x.max_roll_acceleration_deg_per_s2 for x in sats]))


@numba.njit(cache=True)
def _weights(u, seg0, n, run_seg, cov_ptr, cov_idx, stamp):
    w = np.zeros(len(seg0))
    buf = np.empty(len(u), np.int64)
    tag = stamp.max()
    for c in range(len(seg0)):
        tag += 1
        m = strip_samples(seg0[c], n[c], run_seg, cov_ptr, cov_idx, stamp, tag, buf)
        total = 0.0
        for k in range(m):
            total += u[buf[k]]
        w[c] = total
    return w


@numba.njit(cache=True)
def _chains(w, it):
    """Every satellite's heaviest chain of items, consecutive ones at least the settling time plus the slew time
    of their roll change apart (the verifier's rule): (the sum over satellites, the items chosen).  A chain ending
    at item j continues the best chain ending, on any track of j's satellite, at an item whose end leaves the
    gap that track's roll needs; each track's items are sorted by end with a running maximum, filled as far as
    asked (every item ending before j starts was computed before j: starts come before ends)."""
    n = len(w)
    best = np.zeros(n)
    back = np.full(n, -1, np.int64)
    pref = np.zeros(len(it.t_items))
    parg = np.full(len(it.t_items), -1, np.int64)
    filled = it.t_ptr[:-1].copy()
    top = np.zeros(len(it.settle))
    top_arg = np.full(len(it.settle), -1, np.int64)
    for j in it.order:
        s = it.sat[j]
        th0 = it.start[j] - it.settle[s] + 1.0e-6
        m, marg = 0.0, -1
        for q in range(it.s_ptr[s], it.s_ptr[s + 1]):
            t = it.s_tracks[q]
            lo, hi = it.t_ptr[t], it.t_ptr[t + 1]
            if hi == lo:
                continue
            th = th0 - slew_s(it.t_roll[t] - it.roll[j], it.rate[s], it.acc[s])
            p = lo + np.searchsorted(it.t_end[lo:hi], th, side="right") - 1
            if p < lo:
                continue
            while filled[t] <= p:
                k = filled[t]
                cand = best[it.t_items[k]]
                if k > lo and pref[k - 1] >= cand:
                    pref[k], parg[k] = pref[k - 1], parg[k - 1]
                else:
                    pref[k], parg[k] = cand, it.t_items[k]
                filled[t] += 1
            if pref[p] > m:
                m, marg = pref[p], parg[p]
        best[j] = w[j] + m
        back[j] = marg
        if best[j] > top[s]:
            top[s], top_arg[s] = best[j], j
    chosen = np.zeros(n, np.bool_)
    for s in range(len(top)):
        j = top_arg[s]
        while j >= 0:
            chosen[j] = True
            j = back[j]
    return top.sum(), chosen


@numba.njit(cache=True)
def _counts(chosen_items, seg0, n, run_seg, cov_ptr, cov_idx, cnt, stamp):
    buf = np.empty(len(cnt), np.int64)
    tag = stamp.max()
    for c in chosen_items:
        tag += 1
        m = strip_samples(seg0[c], n[c], run_seg, cov_ptr, cov_idx, stamp, tag, buf)
        for k in range(m):
            cnt[buf[k]] += 1


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
        total, chosen = _chains(w - lam, it)
        picked = np.flatnonzero(chosen)
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
