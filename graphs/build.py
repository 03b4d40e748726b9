"""Build the unpruned discrete graph's arcs from the simulator's attitudes.

A maneuver from node u = (i, t_i) to acquisition j starting at t is feasible when

    t - (t_i + d_i) >= slew(angle(attitude of i at t_i + d_i, attitude of j at t))

(the target of j moves while the satellite slews, so the attitude of j is the
one at the arrival time t).  The transition duration of the paper is then
Delta_ij(t_i) = min{tau >= 0 : the maneuver arriving at t_i + d_i + tau is
feasible}, and the arc u -> j goes to the earliest node (j, t_j) with
t_j >= t_i + d_i + Delta_ij(t_i), found by scanning j's nodes in time order.

Shortcut that makes the builder fast: every attitude lies within the pointing
limits, so no slew exceeds ``max_slew`` = slew(angle(2 roll_max, 2 pitch_max));
when j's first node is at least ``max_slew`` after t_i + d_i the arc goes to it
without any evaluation.  Only acquisitions whose window overlaps the next
``max_slew`` seconds need the scan.
"""

from __future__ import annotations

import numba
import numpy as np

from eosp.sim.geometry import rotation_angle_deg
from eosp.sim.slew import PIECEWISE, slew_time, slew_times


@numba.njit(cache=True, inline="always")
def first_at_or_after(node_time, lo, hi, t):
    """The first node in [lo, hi) (sorted by time, one acquisition's) at or after `t`; hi when none."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if node_time[mid] < t:
            lo = mid + 1
        else:
            hi = mid
    return lo


@numba.njit(cache=True)
def _build_arcs(node_acq, node_time, trig, durations, acq_ptr, model, max_slew, min_slew, lipschitz):
    n_nodes = node_acq.shape[0]
    n_acq = acq_ptr.shape[0] - 1
    indptr = np.zeros(n_nodes + 1, dtype=np.int64)
    cap = max(1024, n_nodes * 16)
    dst = np.empty(cap, dtype=np.int32)
    e = 0
    last_time = np.empty(n_acq, dtype=np.float64)
    first_time = np.empty(n_acq, dtype=np.float64)
    for j in range(n_acq):
        first_time[j] = node_time[acq_ptr[j]]
        last_time[j] = node_time[acq_ptr[j + 1] - 1]
    for u in range(n_nodes):
        if e + n_acq > cap:
            cap = max(cap * 2, e + n_acq)
            grown = np.empty(cap, dtype=np.int32)
            grown[:e] = dst[:e]
            dst = grown
        i = node_acq[u]
        if i < 0:  # source: the initial attitude is free
            for j in range(n_acq):
                dst[e] = acq_ptr[j]
                e += 1
            indptr[u + 1] = e
            continue
        finish = node_time[u] + durations[i]
        # cos/sin of roll and pitch at the end of u
        cr_u, sr_u, cp_u, sp_u = trig[u, 4], trig[u, 5], trig[u, 6], trig[u, 7]
        for j in range(n_acq):
            if j == i or last_time[j] < finish + min_slew:
                continue
            if first_time[j] >= finish + max_slew:
                dst[e] = acq_ptr[j]
                e += 1
                continue
            end = acq_ptr[j + 1]
            w = first_at_or_after(node_time, acq_ptr[j], end, finish + min_slew)
            while w < end:
                # rotation angle from cos of the roll and pitch differences
                cr = cr_u * trig[w, 0] + sr_u * trig[w, 1]
                cp = cp_u * trig[w, 2] + sp_u * trig[w, 3]
                c = (cp + cr + cr * cp - 1.0) * 0.5
                c = min(1.0, max(-1.0, c))
                f = node_time[w] - finish - slew_time(np.rad2deg(np.arccos(c)), model)
                if f >= 0.0:
                    dst[e] = w
                    e += 1
                    break
                if lipschitz > 0.0:
                    # no feasible start before node_time[w] - f / (1 + L): the slew time
                    # cannot drop faster than L seconds per second
                    nxt = first_at_or_after(node_time, w + 1, end, node_time[w] - f / (1.0 + lipschitz))
                    w = max(w + 1, nxt)
                else:
                    w += 1
        indptr[u + 1] = e
    return indptr, dst[:e].copy()


def build_arcs(node_acq: np.ndarray, node_time: np.ndarray, node_att: np.ndarray, durations: np.ndarray,
               acq_ptr: np.ndarray, slew_model: np.ndarray, max_slew: float) -> tuple[np.ndarray, np.ndarray]:
    """CSR arcs (indptr int64 [N+1], dst int32 [E]) of the unpruned discrete graph.

    ``node_att`` is float64 [N, 4]: roll and pitch at the node's start time, then
    roll and pitch at its end (start + duration); nodes are in canonical order.
    """
    att = np.deg2rad(np.asarray(node_att, dtype=np.float64))
    trig = np.ascontiguousarray(np.stack([np.cos(att[:, 0]), np.sin(att[:, 0]), np.cos(att[:, 1]),
                                          np.sin(att[:, 1]), np.cos(att[:, 2]), np.sin(att[:, 2]),
                                          np.cos(att[:, 3]), np.sin(att[:, 3])], axis=1))
    min_slew = float(slew_times(np.array([0.0]), slew_model)[0])
    return _build_arcs(node_acq, node_time, trig, durations, acq_ptr, slew_model, float(max_slew),
                       min_slew, _lipschitz(node_acq, node_time, node_att, acq_ptr, slew_model))


def _lipschitz(node_acq, node_time, node_att, acq_ptr, slew_model) -> float:
    """Bound on |d slew / dt| while the target of j moves (0 = unknown: scan node by node).

    It is the model's largest slope (s/deg) times the fastest attitude change of
    any target between consecutive nodes (deg/s), with a 25% margin.
    """
    if slew_model[0] != PIECEWISE:
        return 0.0  # bang-coast-bang has an unbounded slope at small angles
    k = int(slew_model[1])
    a, t = slew_model[2:2 + k], slew_model[2 + k:2 + 2 * k]
    slope = float(np.max(np.diff(t) / np.diff(a)))
    same = node_acq[1:-1] == node_acq[2:]
    if not same.any():
        return 0.0
    dt = (node_time[2:] - node_time[1:-1])[same]
    ang = rotation_angle_deg(node_att[2:, 0] - node_att[1:-1, 0], node_att[2:, 1] - node_att[1:-1, 1])[same]
    rate = float(np.max(ang / dt))
    lip = 1.25 * slope * rate
    return lip if lip < 1.0 else 0.0
