"""Array state and numba kernels of the constellation environment (its hot loop).

The state of an episode is :class:`Episode`, a NamedTuple of arrays updated in place; the fleet's static
arrays are :class:`eosp.envs.constellation_data.FleetArrays`.  Per satellite: its current pass, its last
observation (the pass's source node when it has none there yet), its clock (when it is next free: the end of
its last observation, or the first start of its pass) and its battery point (an instant no later than any
maneuver it can still start, and the charge there).

Event clock: the satellite with the earliest clock acts (ties: the lowest index).  Its candidates are the
tasks of its current pass; for each task the arcs of the pass graph give the earliest opportunity that the slew
from the last observation allows (the pass graphs' rule, :mod:`eosp.fleet.passgraph`); when the battery
refuses that one, later opportunities of the task are tried in turn (their slew checked from the same lines of
sight).  A satellite without any admissible candidate moves to its next pass by itself; without passes left it
is done.

Battery: an observation is admissible iff, with it and nothing but the idle draw afterwards, the charge stays at
least :data:`BATTERY_MARGIN_WH` at the end of every segment of the checker's battery simulation to the horizon.
The segments from the battery point to the end of the observation are simulated one by one (the checker's cut
points: the resource grid, the maneuver start, the observation's start and end); the idle continuation is read
from the fleet's tables in O(1) (see :mod:`eosp.envs.constellation_data`).  Since every admitted observation
keeps the committed timeline plus idle above the margin, and later observations only change the timeline after
their maneuver starts, every schedule the environment builds passes the checker's battery stage.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from eosp.fleet.geometry import NUMERICAL_EPS
from eosp.fleet.passgraph import _need
from eosp.fleet.slew import MARGIN_S

SLEW_MARGIN_S = MARGIN_S + NUMERICAL_EPS  # the pass graphs' arcs' margin, for the opportunities tried beyond them
BATTERY_MARGIN_WH = 1.0e-6  # the charge an admissible timeline keeps at every segment end (the checker: -1e-9)
NEVER = np.iinfo(np.int64).max
EARN, BRIDGE = 1, 2  # kinds of a candidate: a task not served yet, a served one (zero reward)
BRIDGE_MODES = ("off", "useful", "all")
# Episode.counts: actions taken, battery refusals (an opportunity refused by the battery), bridges taken,
# passes left without a decision (no admissible candidate)
N_ACTIONS, N_BATTERY, N_BRIDGES, N_AUTO_SKIPS = range(4)


class Episode(NamedTuple):
    """The state of an episode (see the module docstring); the ``cand_*`` arrays hold the acting satellite's
    candidates, one entry per task of its pass (-1 / 0 when not admissible)."""

    served_by: np.ndarray  # int64 [T]: satellite that first served the task, -1
    sat_pass: np.ndarray  # int64 [K]: current pass, -1 when done
    sat_last: np.ndarray  # int64 [K]: last observation's node in the current pass (its source at entry)
    sat_prev: np.ndarray  # int64 [K]: last observation's node in any pass, -1 before the first
    sat_clock: np.ndarray  # int64 [K]: when the satellite is next free (µs); NEVER when done
    bat_t: np.ndarray  # int64 [K]: battery point (µs)
    bat_wh: np.ndarray  # float64 [K]: charge there
    actions: np.ndarray  # int64 [N]: the observations' nodes, in the order taken
    counts: np.ndarray  # int64 [4]: see N_ACTIONS .. N_AUTO_SKIPS
    cand_node: np.ndarray  # int64 [max tasks of a pass]
    cand_kind: np.ndarray  # int8: EARN, BRIDGE or 0
    cand_wh: np.ndarray  # float64: charge at the observation's end
    cand_head: np.ndarray  # float64: lowest charge to the horizon with it
    direct: np.ndarray  # int64: the arcs' target of each task from the last observation (-1: none)
    slot_acq: np.ndarray  # int64 [max_nodes]: local task shown in each observation slot (slot 0: skip, -1)
    acq_slot: np.ndarray  # int64 [max tasks of a pass]: slot of each local task, -1 when not shown


def new_episode(fa, max_pass_tasks: int, max_nodes: int) -> Episode:
    n_tasks, k_sats, n_nodes = fa.task_weight.shape[0], fa.sat_pass_ptr.shape[0] - 1, fa.node_acq.shape[0]
    m = max(1, max_pass_tasks)
    i64 = np.int64
    return Episode(np.full(n_tasks, -1, i64), np.full(k_sats, -1, i64), np.zeros(k_sats, i64),
                   np.full(k_sats, -1, i64), np.full(k_sats, NEVER, i64), np.zeros(k_sats, i64), np.zeros(k_sats),
                   np.zeros(n_nodes, i64),
                   np.zeros(4, i64), np.full(m, -1, i64), np.zeros(m, np.int8), np.zeros(m), np.zeros(m),
                   np.full(m, -1, i64), np.full(max_nodes, -1, i64), np.full(m, -1, i64))


@numba.njit(cache=True, inline="always")
def _half_even(d):
    """d // 2 rounded half to even (the checker's segment midpoints, eosp.fleet.battery.half_even_div2)."""
    q = d // 2
    return q + 1 if (d % 2 == 1 and q % 2 == 1) else q


@numba.njit(cache=True)
def _lit(fa, k, t0, t1, exact):
    """Sunlight at the checker's midpoint of segment [t0, t1): its own verdict on the half-step grid when `exact`
    (both ends on the action or resource grid), else the base grid's where certain, shadow otherwise."""
    half, base = fa.dims[2], fa.dims[3]
    mid = t0 + _half_even(t1 - t0)
    if exact and mid % half == 0:
        return fa.lit_half[k, mid // half] > 0
    i = mid // base
    return i < fa.lit_base.shape[1] and fa.lit_base[k, i] == 1


@numba.njit(cache=True)
def run_battery(fa, k, t0, b0, m, s, e):
    """The checker's charge recurrence for satellite `k` from (t0, b0) to `e`: idle until the maneuver start `m`,
    slewing until the observation starts at `s`, imaging until `e`; cut at the resource grid.  Returns the
    charge at `e` (clipped) and the lowest unclipped charge at a segment end."""
    res = fa.dims[1]
    cap, idle, img, slw, sunw = fa.sat_power[k, 0], fa.sat_power[k, 2], fa.sat_power[k, 3], fa.sat_power[k, 4], \
        fa.sat_power[k, 5]
    grid = fa.grid_us
    t, b, low = t0, b0, np.inf
    while t < e:
        g = t // res
        g_next = grid[g + 1]
        nxt = min(g_next, e)
        if t < m:
            nxt = min(nxt, m)
        elif t < s:
            nxt = min(nxt, s)
        if t < m and t == grid[g] and nxt == g_next:
            d = fa.idle_delta[k, g]
        else:
            load = idle
            if m <= t < s:
                load += slw
            elif s <= t:
                load += img
            ch = sunw if _lit(fa, k, t, nxt, t != m and nxt != m) else 0.0
            d = ((ch - load) * ((nxt - t) / 1e6)) / 3600.0
        b += d
        low = min(low, b)
        b = min(cap, b)
        t = nxt
    return b, low


@numba.njit(cache=True)
def battery_check(fa, k, t0, b0, m, s, e):
    """(admissible, charge at e, lowest charge to the horizon) of an observation [s, e) whose maneuver starts at
    `m`, from the battery point (t0, b0), idle afterwards (see the module docstring)."""
    res, total = fa.dims[1], fa.dims[0]
    cap = fa.sat_power[k, 0]
    b_e, low = run_battery(fa, k, t0, b0, m, s, e)
    g = fa.grid_us.shape[0] - 1 if e >= total else min(-(-e // res), fa.grid_us.shape[0] - 1)
    b = b_e
    if e < fa.grid_us[g]:  # the idle piece up to the next grid instant
        ch = fa.sat_power[k, 5] if _lit(fa, k, e, fa.grid_us[g], True) else 0.0
        b += ((ch - fa.sat_power[k, 2]) * ((fa.grid_us[g] - e) / 1e6)) / 3600.0
        low = min(low, b)
        b = min(cap, b)
    head = min(low, b + fa.tail_min[k, g])
    ok = head >= BATTERY_MARGIN_WH and cap - fa.tail_drop[k, g] >= BATTERY_MARGIN_WH
    return ok, b_e, head


@numba.njit(cache=True)
def slew_need(fa, k, prev, w):
    """Slew plus settling time (s) to node `w` from the satellite's previous observation `prev` (-1: none, a
    first slew from nadir), as the checker measures it: the maneuver that the battery pays for."""
    frm = fa.nadir[w] if prev < 0 else fa.los1[prev]
    return _need(frm, fa.los0[w], fa.sat_slew[k, 0], fa.sat_slew[k, 1], fa.sat_slew[k, 2])


@numba.njit(cache=True)
def slew_ok(fa, k, prev, w):
    """The checker's slew rule for `w` after the previous observation `prev` (-1: from nadir, the gap counted
    from the horizon start), with the pass graphs' margin."""
    if prev < 0:
        gap = fa.node_time[w]
    else:
        gap = fa.node_time[w] - fa.node_finish[prev]
        if gap < 0.0:
            return False
    return gap >= slew_need(fa, k, prev, w) + SLEW_MARGIN_S


@numba.njit(cache=True)
def _useful(fa, ep, v, a0):
    """A served task's node `v` is a useful bridge: from it some task nobody served starts earlier than it can
    from the last observation directly (or at all)."""
    for i in range(fa.indptr[v], fa.indptr[v + 1]):
        x = fa.dst[i]
        ax = fa.node_acq[x] - a0
        if ep.served_by[fa.acq_task[a0 + ax]] >= 0:
            continue
        d = ep.direct[ax]
        if d < 0 or fa.node_time[x] < fa.node_time[d]:
            return True
    return False


@numba.njit(cache=True)
def candidates(fa, ep, k, bridges):
    """Fill ep.cand_* for satellite `k` in its current pass; returns the number of admissible tasks."""
    p, u = ep.sat_pass[k], ep.sat_last[k]
    a0 = fa.pass_acq_ptr[p]
    na = fa.pass_acq_ptr[p + 1] - a0
    for a in range(na):
        ep.direct[a] = -1
        ep.cand_node[a] = -1
        ep.cand_kind[a] = 0
    for i in range(fa.indptr[u], fa.indptr[u + 1]):
        v = fa.dst[i]
        ep.direct[fa.node_acq[v] - a0] = v
    t0, b0 = ep.bat_t[k], ep.bat_wh[k]
    prev = ep.sat_prev[k]  # the last observation, maybe in an earlier pass: the arcs of a pass source assume a
    #                        first slew from nadir, right for feasibility (passes are a full 180-degree slew apart),
    #                        not for the maneuver's duration, which the battery pays; its slew is checked anyway
    recheck = fa.node_acq[u] < 0 and prev >= 0
    n_ok = 0
    for a in range(na):
        v = ep.direct[a]
        if v < 0:
            continue
        kind = EARN
        if ep.served_by[fa.acq_task[a0 + a]] >= 0:
            if bridges == 0 or (bridges == 1 and not _useful(fa, ep, v, a0)):
                continue
            kind = BRIDGE
        for w in range(v, fa.acq_hi[a0 + a]):
            if (w != v or recheck) and not slew_ok(fa, k, prev, w):
                continue
            need_us = np.int64(np.rint(slew_need(fa, k, prev, w) * 1e6))
            s, e = fa.node_start_us[w], fa.node_end_us[w]
            ok, b_e, head = battery_check(fa, k, t0, b0, s - need_us, s, e)
            if ok:
                ep.cand_node[a] = w
                ep.cand_kind[a] = kind
                ep.cand_wh[a] = b_e
                ep.cand_head[a] = head
                n_ok += 1
                break
            ep.counts[N_BATTERY] += 1
    return n_ok


@numba.njit(cache=True)
def _enter(fa, ep, k, q):
    """Satellite `k` enters pass `q`: its clock at the pass's first start, its battery advanced idle to the
    pass's entry instant."""
    ep.sat_pass[k] = q
    ep.sat_last[k] = fa.pass_src[q]
    ep.sat_clock[k] = fa.pass_first_us[q]
    e = max(ep.bat_t[k], fa.pass_entry_us[q])
    if e > ep.bat_t[k]:
        b, _ = run_battery(fa, k, ep.bat_t[k], ep.bat_wh[k], e, e, e)
        ep.bat_t[k] = e
        ep.bat_wh[k] = b


@numba.njit(cache=True)
def leave_pass(fa, ep, k):
    p = ep.sat_pass[k]
    if p >= 0 and p + 1 < fa.sat_pass_ptr[k + 1]:
        _enter(fa, ep, k, p + 1)
    else:
        ep.sat_pass[k] = -1
        ep.sat_clock[k] = NEVER


@numba.njit(cache=True)
def start(fa, ep):
    """A fresh episode: every satellite at its first pass with its initial charge; a satellite whose idle draw
    alone empties its battery before the horizon never acts."""
    for k in range(ep.sat_pass.shape[0]):
        ep.bat_t[k] = 0
        ep.bat_wh[k] = fa.sat_power[k, 1]
        cap = fa.sat_power[k, 0]
        idle_ok = (fa.sat_power[k, 1] + fa.tail_min[k, 0] >= BATTERY_MARGIN_WH
                   and cap - fa.tail_drop[k, 0] >= BATTERY_MARGIN_WH)
        if fa.sat_pass_ptr[k] < fa.sat_pass_ptr[k + 1] and idle_ok:
            _enter(fa, ep, k, fa.sat_pass_ptr[k])
        else:
            ep.sat_pass[k] = -1
            ep.sat_clock[k] = NEVER


@numba.njit(cache=True)
def next_actor(fa, ep, bridges):
    """The satellite that acts next (its candidates filled), passes without candidates left on the way; -1 when
    every satellite is done."""
    while True:
        k = np.argmin(ep.sat_clock)
        if ep.sat_clock[k] == NEVER:
            return -1
        if candidates(fa, ep, k, bridges) > 0:
            return k
        ep.counts[N_AUTO_SKIPS] += 1
        leave_pass(fa, ep, k)


@numba.njit(cache=True)
def apply(fa, ep, k, a, task_reward):
    """Satellite `k` takes its candidate for local task `a` (-1: skip to its next pass); returns the reward
    (``task_reward`` of a task served for the first time, else 0)."""
    if a < 0:
        leave_pass(fa, ep, k)
        return 0.0
    w = ep.cand_node[a]
    ep.actions[ep.counts[N_ACTIONS]] = w
    ep.counts[N_ACTIONS] += 1
    ep.sat_last[k] = w
    ep.sat_prev[k] = w
    ep.sat_clock[k] = fa.node_end_us[w]
    ep.bat_t[k] = fa.node_end_us[w]
    ep.bat_wh[k] = ep.cand_wh[a]
    t = fa.acq_task[fa.node_acq[w]]
    if ep.served_by[t] < 0:
        ep.served_by[t] = k
        return task_reward[t]
    ep.counts[N_BRIDGES] += 1
    return 0.0
