"""The acting satellite's observation: its current pass as a padded graph of tasks, plus a 'skip' node.

Slots: node 0 is "skip to the next pass"; the others are the pass's tasks (slot 1 + local task index; with
truncation, a ranking, see :func:`choose_slots`).  The first ten feature columns keep the name, meaning and
position they have in the single-pass observation (:mod:`eosp.envs.observation`: the model's un-padding reads
``scheduled``, ``removed`` and ``last``; a task's window is its opportunities in this pass), then the task's
weight and its share of the pass's weight stand where the single pass has its utility; the others say what the
fleet adds: whether the task is served
already, what it is worth elsewhere (the other passes that can still observe it: how many, on how many
satellites, how soon), and the battery (after each candidate, now).  Times are relative to the satellite's
clock in units of :data:`TIME_SCALE` seconds, clipped to [-10, 10].

Counts that grow with the fleet are in the fleet's own units, so that a policy trained on 5-50 satellites reads
a 200-satellite day in the range it learned: ``other_passes_rel`` and ``other_satellites_rel`` divide by the mean
number of passes, and of distinct satellites, that see a task of this fleet (``FleetArrays.scales``; 1.0-3.4 on
the training fleets, 10 on a generated 200-satellite day), ``passes_left_share`` is the share of the
satellite's passes still ahead.

Edges are the single pass's "earliest" edges: out of the last observation, one to every selectable task's
candidate (flag 1); out of every other task still ahead, from its first opportunity after the clock, the
arcs of the pass graph to the `max_out_degree` earliest starts of other tasks shown (flag 0).  Edge
features: the slack of the transition (start of the target minus end of the source, / 60 s) and the flag.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from eosp.envs.constellation_core import NEVER, apply, next_actor, start
from eosp.envs.observation import LAST as SINGLE_LAST
from eosp.envs.observation import NODE_FEATURES as SINGLE_PASS_FEATURES
from eosp.envs.observation import REMOVED as SINGLE_REMOVED
from eosp.envs.observation import SCHEDULED as SINGLE_SCHEDULED

TIME_SCALE = 300.0
FLEET_NODE_FEATURES = (
    "scheduled", "removed", "selectable", "last",
    "window_start", "window_end", "latest_start", "earliest_start", "alive_fraction",
    "duration", "weight", "weight_share",
    "served", "bridge", "other_passes_rel", "other_satellites_rel", "other_soonest", "own_later_passes",
    "charge_after", "headroom_after", "skip",
    "charge_now", "horizon_left", "passes_left_share", "next_pass_in",
)
N_FLEET_FEATURES = len(FLEET_NODE_FEATURES)
N_EDGE_FEATURES = 2
(SCHEDULED, REMOVED, SELECTABLE, LAST, WINDOW_START, WINDOW_END, LATEST_START, EARLIEST_START, ALIVE_FRACTION,
 DURATION, WEIGHT, WEIGHT_SHARE, SERVED, BRIDGE_F, OTHER_PASSES_REL, OTHER_SATS_REL, OTHER_SOONEST, OWN_LATER,
 CHARGE_AFTER, HEADROOM_AFTER, SKIP, CHARGE_NOW, HORIZON_LEFT, PASSES_LEFT_SHARE,
 NEXT_PASS_IN) = range(N_FLEET_FEATURES)


class ObsArrays(NamedTuple):
    """An observation's arrays, zeroed and padded, which :func:`observe` fills."""

    x: np.ndarray  # float32 [max_nodes, N_FLEET_FEATURES]
    edge_index: np.ndarray  # int32 [2, E_max]
    edge_attr: np.ndarray  # float32 [E_max, N_EDGE_FEATURES]
    mask: np.ndarray  # int8 [max_nodes]


MAX_WEIGHT = 5.0  # weights of the aeossp cases and of generated fleets are 1-5
# the single pass's columns the model reads (its un-padding) and the first ones, same names, same places
assert FLEET_NODE_FEATURES[:DURATION + 1] == SINGLE_PASS_FEATURES[:DURATION + 1]
assert (SCHEDULED, REMOVED, LAST) == (SINGLE_SCHEDULED, SINGLE_REMOVED, SINGLE_LAST)


@numba.njit(cache=True, inline="always")
def _rel(t_us, now_us):
    return min(10.0, max(-10.0, (t_us - now_us) / (TIME_SCALE * 1e6)))


@numba.njit(cache=True)
def first_ahead(fa, lo, hi, now_us):
    """The first node in [lo, hi) starting at or after `now_us` (hi: none)."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if fa.node_start_us[mid] < now_us:
            lo = mid + 1
        else:
            hi = mid
    return lo


@numba.njit(cache=True)
def _agent_features(fa, ep, k, x, n_slots):
    p = ep.sat_pass[k]
    now = ep.sat_clock[k] if ep.sat_clock[k] != NEVER else fa.dims[0]
    cap = fa.sat_power[k, 0]
    left = fa.sat_pass_ptr[k + 1] - 1 - p if p >= 0 else 0
    total = max(1, fa.sat_pass_ptr[k + 1] - fa.sat_pass_ptr[k])
    nxt = 10.0
    if p >= 0 and p + 1 < fa.sat_pass_ptr[k + 1]:
        nxt = _rel(fa.pass_first_us[p + 1], now)
    for s in range(n_slots):
        x[s, CHARGE_NOW] = ep.bat_wh[k] / cap if cap > 0 else 0.0
        x[s, HORIZON_LEFT] = (fa.dims[0] - now) / fa.dims[0]
        x[s, PASSES_LEFT_SHARE] = left / total
        x[s, NEXT_PASS_IN] = nxt
    x[0, SKIP] = 1.0
    x[0, WINDOW_START] = nxt
    x[0, EARLIEST_START] = nxt
    return nxt


@numba.njit(cache=True)
def choose_slots(fa, ep, k, n_max, truncate):
    """Fill ep.slot_acq / ep.acq_slot; returns the number of slots (skip included).  Without truncation every
    task of the pass has slot 1 + its index; with it, the last observed task, then the selectable ones by
    start, then the others still ahead by earliest start, as many as fit."""
    p, u = ep.sat_pass[k], ep.sat_last[k]
    a0 = fa.pass_acq_ptr[p]
    na = fa.pass_acq_ptr[p + 1] - a0
    ep.slot_acq[0] = -1
    for a in range(na):
        ep.acq_slot[a] = -1
    if not truncate or na < n_max:
        for a in range(na):
            ep.slot_acq[a + 1] = a
            ep.acq_slot[a] = a + 1
        return na + 1
    now = ep.sat_clock[k]
    last = fa.node_acq[u] - a0 if fa.node_acq[u] >= 0 else -1
    key = np.full(na, np.inf)
    for a in range(na):
        if a == last:
            key[a] = -1.0
        elif ep.cand_node[a] >= 0:
            key[a] = 1e18 + fa.node_start_us[ep.cand_node[a]]
        elif ep.served_by[fa.acq_task[a0 + a]] < 0:
            f = first_ahead(fa, fa.acq_lo[a0 + a], fa.acq_hi[a0 + a], now)
            if f < fa.acq_hi[a0 + a]:
                key[a] = 2e18 + fa.node_start_us[f]
    order = np.argsort(key)
    n = 1
    for i in range(na):
        a = order[i]
        if n >= n_max or key[a] == np.inf:
            break
        ep.slot_acq[n] = a
        ep.acq_slot[a] = n
        n += 1
    return n


@numba.njit(cache=True, inline="always")
def _active(x, s):
    """Slot s is a node of the model's graph (eosp.models.agent.batch_from_padded): not removed, and not
    scheduled unless it is the last observation's task."""
    return x[s, REMOVED] == 0.0 and (x[s, SCHEDULED] == 0.0 or x[s, LAST] == 1.0)


@numba.njit(cache=True)
def _edges_from(fa, ep, u, src_slot, a0, k_out, now, out, m):
    """Append the edges out of node `u` (slot `src_slot`) to the k_out earliest starts of other tasks shown,
    still ahead and nodes of the model's graph (:func:`_active`); returns the new edge count."""
    x, edge_index, edge_attr = out.x, out.edge_index, out.edge_attr
    e_max = edge_index.shape[1]
    best_t = np.full(k_out, NEVER)
    best_v = np.full(k_out, -1, dtype=np.int64)
    for i in range(fa.indptr[u], fa.indptr[u + 1]):
        v = fa.dst[i]
        a = fa.node_acq[v] - a0
        if ep.acq_slot[a] < 0 or fa.node_start_us[v] < now or not _active(x, ep.acq_slot[a]):
            continue
        t = fa.node_start_us[v]
        if t >= best_t[k_out - 1]:
            continue
        s = k_out - 1
        while s > 0 and best_t[s - 1] > t:
            best_t[s] = best_t[s - 1]
            best_v[s] = best_v[s - 1]
            s -= 1
        best_t[s] = t
        best_v[s] = v
    for s in range(k_out):
        if best_v[s] < 0 or m >= e_max:
            break
        edge_index[0, m] = src_slot
        edge_index[1, m] = ep.acq_slot[fa.node_acq[best_v[s]] - a0]
        edge_attr[m, 0] = (fa.node_time[best_v[s]] - fa.node_finish[u]) / 60.0
        m += 1
    return m


@numba.njit(cache=True)
def _other_opportunities(fa, ep, k, t, p, stamp, token):
    """(other passes that can still observe task t, their distinct satellites, soonest start there (µs),
    this satellite's later passes among them)."""
    count, sats, own, soonest = 0, 0, 0, NEVER
    for i in range(fa.task_acq_ptr[t], fa.task_acq_ptr[t + 1]):
        b = fa.task_acqs[i]
        q = fa.acq_pass[b]
        if q == p:
            continue
        j = fa.pass_sat[q]
        cur = ep.sat_pass[j]
        if cur < 0 or q < cur:
            continue
        last_start = fa.node_start_us[fa.acq_hi[b] - 1]
        if q == cur and last_start < ep.sat_clock[j]:
            continue
        count += 1
        if j == k:
            own += 1
        if stamp[j] != token:
            stamp[j] = token
            sats += 1
        soonest = min(soonest, max(fa.node_start_us[fa.acq_lo[b]], ep.sat_clock[j] if q == cur else 0))
    return count, sats, soonest, own


@numba.njit(cache=True)
def observe(fa, ep, k, params, out):
    """Fill satellite k's observation (`out`: :class:`ObsArrays`, zeroed) from its candidates; `params` =
    (max_out_degree, truncate).  Returns (slots, edges)."""
    x, edge_index, edge_attr, mask = out.x, out.edge_index, out.edge_attr, out.mask
    k_out, truncate = params[0], params[1] != 0
    n_max = x.shape[0]
    p, u = ep.sat_pass[k], ep.sat_last[k]
    a0 = fa.pass_acq_ptr[p]
    now = ep.sat_clock[k]
    cap = fa.sat_power[k, 0]
    n = choose_slots(fa, ep, k, n_max, truncate)
    _agent_features(fa, ep, k, x, n)
    mask[0] = 1
    x[0, SELECTABLE] = 1.0
    last = fa.node_acq[u] - a0 if fa.node_acq[u] >= 0 else -1
    stamp = np.zeros(fa.sat_pass_ptr.shape[0] - 1, dtype=np.int64)
    for s in range(1, n):
        a = ep.slot_acq[s]
        b = a0 + a
        t = fa.acq_task[b]
        lo, hi = fa.acq_lo[b], fa.acq_hi[b]
        f = first_ahead(fa, lo, hi, now)
        served = ep.served_by[t]
        sel = ep.cand_node[a] >= 0
        dur = fa.node_end_us[lo] - fa.node_start_us[lo]
        x[s, SCHEDULED] = 1.0 if (served == k and not sel) else 0.0
        x[s, REMOVED] = 1.0 if (not sel and served != k and (served >= 0 or f == hi)) else 0.0
        x[s, SELECTABLE] = 1.0 if sel else 0.0
        x[s, LAST] = 1.0 if a == last else 0.0
        x[s, WINDOW_START] = _rel(fa.node_start_us[lo], now)
        x[s, WINDOW_END] = _rel(fa.node_start_us[hi - 1] + dur, now)
        x[s, LATEST_START] = _rel(fa.node_start_us[hi - 1], now)
        if sel:
            x[s, EARLIEST_START] = _rel(fa.node_start_us[ep.cand_node[a]], now)
        elif f < hi:
            x[s, EARLIEST_START] = _rel(fa.node_start_us[f], now)
        x[s, ALIVE_FRACTION] = (hi - f) / (hi - lo)
        x[s, DURATION] = dur / 60e6
        x[s, WEIGHT] = fa.task_weight[t] / MAX_WEIGHT
        x[s, WEIGHT_SHARE] = fa.acq_share[b]
        x[s, SERVED] = 1.0 if served >= 0 else 0.0
        x[s, BRIDGE_F] = 1.0 if (sel and served >= 0) else 0.0
        count, sats, soonest, own = _other_opportunities(fa, ep, k, t, p, stamp, s)
        x[s, OTHER_PASSES_REL] = count / fa.scales[0]
        x[s, OTHER_SATS_REL] = sats / fa.scales[1]
        x[s, OTHER_SOONEST] = _rel(soonest, now) if soonest != NEVER else 10.0
        x[s, OWN_LATER] = own / 10.0
        if sel:
            x[s, CHARGE_AFTER] = ep.cand_wh[a] / cap
            x[s, HEADROOM_AFTER] = ep.cand_head[a] / cap
            mask[s] = 1
    m = 0
    if last >= 0:
        src_slot = ep.acq_slot[last]
        for s in range(1, n):
            a = ep.slot_acq[s]
            w = ep.cand_node[a]
            if w < 0 or src_slot < 0 or m >= edge_index.shape[1]:
                continue
            edge_index[0, m] = src_slot
            edge_index[1, m] = s
            edge_attr[m, 0] = (fa.node_time[w] - fa.node_finish[u]) / 60.0
            edge_attr[m, 1] = 1.0
            m += 1
    for s in range(1, n):
        a = ep.slot_acq[s]
        if a == last or not _active(x, s):
            continue
        f = first_ahead(fa, fa.acq_lo[a0 + a], fa.acq_hi[a0 + a], now)
        if f < fa.acq_hi[a0 + a]:
            m = _edges_from(fa, ep, f, s, a0, k_out, now, out, m)
    return n, m


@numba.njit(cache=True)
def observe_done(fa, ep, k, x):
    """The final observation of satellite k: the skip node alone, nothing selectable (the mask stays zero)."""
    _agent_features(fa, ep, k, x, 1)
    return 1, 0


@numba.njit(cache=True)
def begin(fa, ep, bridges, params, out):
    """A fresh episode (:func:`eosp.envs.constellation_core.start`), its first actor and that actor's
    observation, in one call (the fleet's arrays cross into numba once).  Returns (actor or -1, slots,
    edges)."""
    start(fa, ep)
    k = next_actor(fa, ep, bridges)
    if k < 0:
        return k, 0, 0
    n, m = observe(fa, ep, k, params, out)
    return k, n, m


@numba.njit(cache=True)
def advance(fa, ep, k, a, task_reward, bridges, params, out):
    """One step in one call: satellite k takes local task a (-1: skip), the next actor is found and observes.
    Returns (reward, next actor or -1, slots, edges)."""
    r = apply(fa, ep, k, a, task_reward)
    j = next_actor(fa, ep, bridges)
    if j < 0:
        return r, j, 0, 0
    n, m = observe(fa, ep, j, params, out)
    return r, j, n, m
