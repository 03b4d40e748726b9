"""A fleet's arrays for the constellation environment, prepared once per fleet (after its pass graphs).

Every pass graph of the fleet (:mod:`eosp.fleet.passgraph`) is concatenated into one set of flat arrays with
global ids: nodes (each pass's source node first, then its opportunities), arcs (CSR, rows sorted by
destination), acquisitions (a task in a pass) and passes, plus per-task lists of the acquisitions that can
serve the task.  Lines of sight are stored per node so that the kernels can re-derive any slew.

The battery tables reproduce the checker's battery (:mod:`eosp.fleet.battery`) on the resource grid: the
idle net energy of every grid segment (sunlight at its midpoint), and for every grid instant what an idle
continuation to the horizon needs: the lowest unclipped charge change ahead (``tail_min``) and the largest
drop between two later instants (``tail_drop``, which the capacity must cover).  Sunlight at the 2.5 s
instants where the checker can meet a segment midpoint is the checker's own verdict (``lit_half``); at any
other instant (a midpoint next to a maneuver start) it is read from the base grid where the satellite is far
from the shadow boundary at both ends of the step, and counted as shadow otherwise (``lit_base`` -1): no
charging is credited that the checker might not credit.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from math import gcd
from typing import NamedTuple

import numpy as np

from eosp.errors import InputError
from eosp.fleet.battery import SunCache, half_even_div2
from eosp.fleet.geometry import Geometry, slew_time_s
from eosp.fleet.model import US, Fleet
from eosp.fleet.opportunities import Opportunities
from eosp.fleet.passgraph import PassGraph, build_passes
from eosp.fleet.slew import LineOfSight
from eosp.graphs.prune import fifo_violations


class FleetArrays(NamedTuple):
    """A fleet's static arrays (see the module docstring); times in microseconds from the horizon start
    unless named ``_s``.  ``dims``: horizon, resource step, half step, base step (µs)."""

    dims: np.ndarray  # int64 [4]
    sat_slew: np.ndarray  # float64 [K, 3]: max rate (deg/s), max acceleration (deg/s2), settling (s)
    sat_power: np.ndarray  # float64 [K, 6]: capacity, initial (Wh); idle, imaging, slew, sunlit (W)
    sat_pass_ptr: np.ndarray  # int64 [K + 1]: passes of satellite k
    pass_sat: np.ndarray  # int64 [P]
    pass_first_us: np.ndarray  # int64 [P]: first start of the pass
    pass_entry_us: np.ndarray  # int64 [P]: a resource-grid instant no maneuver of the pass starts before
    pass_src: np.ndarray  # int64 [P]: the pass's source node
    pass_acq_ptr: np.ndarray  # int64 [P + 1]: acquisitions of pass p
    acq_task: np.ndarray  # int64 [A]
    acq_pass: np.ndarray  # int64 [A]
    acq_lo: np.ndarray  # int64 [A]: nodes acq_lo .. acq_hi - 1, by start
    acq_hi: np.ndarray
    acq_share: np.ndarray  # float64 [A]: the task's weight / the weight of the pass's tasks
    node_acq: np.ndarray  # int64 [N]: -1 for a source
    node_start_us: np.ndarray  # int64 [N]
    node_end_us: np.ndarray  # int64 [N]
    node_time: np.ndarray  # float64 [N]: start (s); 0 for a source
    node_finish: np.ndarray  # float64 [N]: end (s); 0 for a source
    los0: np.ndarray  # float64 [N, 3]: inertial line of sight at the start
    los1: np.ndarray  # float64 [N, 3]: at the end
    nadir: np.ndarray  # float64 [N, 3]: geocentric nadir at the start (a satellite's first slew)
    indptr: np.ndarray  # int64 [N + 1]: arcs of the pass graphs (earliest successor of every other task)
    dst: np.ndarray  # int64 [M]
    task_weight: np.ndarray  # float64 [T]
    task_acq_ptr: np.ndarray  # int64 [T + 1]: acquisitions of task t (in every pass), by first start
    task_acqs: np.ndarray  # int64
    grid_us: np.ndarray  # int64 [G + 1]: resource-grid cut points, the horizon end last
    idle_delta: np.ndarray  # float64 [K, G]: idle net energy of each grid segment (Wh)
    tail_min: np.ndarray  # float64 [K, G + 1]: min over j >= g of C[j] - C[g] (C: cumulative idle net energy)
    tail_drop: np.ndarray  # float64 [K, G + 1]: max over g <= i <= j of C[i] - C[j]
    lit_half: np.ndarray  # uint8 [K, H]: checker's sunlight at every half-step instant
    lit_base: np.ndarray  # int8 [K, B]: sunlight over each base step: 1 / 0 certain, -1 uncertain
    scales: np.ndarray  # float64 [2]: mean passes, mean distinct satellites, of a task with any (features' units)


@dataclass(eq=False)
class PreparedFleet:
    """A fleet and everything the environment reads from it, built once (cached by the sources)."""

    name: str
    fleet: Fleet
    opps: Opportunities
    geo: Geometry
    arrays: FleetArrays
    max_pass_tasks: int
    fifo_violations: int  # see eosp.graphs.prune.fifo_violations: 0 makes earliest starts lose no schedule
    prepare_s: float  # seconds to prepare after the pass graphs were built

    @property
    def n_satellites(self) -> int:
        return len(self.fleet.satellites)


def _sunlight(fleet: Fleet, geo: Geometry, total_us: int, half_us: int) -> tuple[np.ndarray, np.ndarray]:
    """(lit_half [K, H], lit_base [K, B]): see the module docstring."""
    sun = SunCache(geo)
    half_t = np.arange(0, total_us + 1, half_us, dtype=np.int64)
    k_sats = len(fleet.satellites)
    lit_half = np.zeros((k_sats, len(half_t)), dtype=np.uint8)
    lit_base = np.full((k_sats, geo.n_base), -1, dtype=np.int8)
    for k in range(k_sats):
        lit_half[k] = sun.sunlit(k, half_t)
        lit, margin = sun.grid(k)
        safe = (lit[:-1] == lit[1:]) & (margin[:-1] > sun.SAFE_M) & (margin[1:] > sun.SAFE_M)
        lit_base[k, :-1] = np.where(safe, lit[:-1].astype(np.int8), -1)
    return lit_half, lit_base


def _battery_tables(fleet: Fleet, grid_us: np.ndarray, lit_half: np.ndarray,
                    half_us: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(idle_delta, tail_min, tail_drop): see the module docstring and FleetArrays."""
    b = fleet.satellites.battery
    d = np.diff(grid_us)
    mid = grid_us[:-1] + half_even_div2(d)
    dt = d.astype(np.float64) / 1e6
    k_sats = len(fleet.satellites)
    n = len(grid_us)
    delta = np.empty((k_sats, n - 1))
    tail_min = np.empty((k_sats, n))
    tail_drop = np.empty((k_sats, n))
    for k in range(k_sats):
        ch = np.where(lit_half[k, mid // half_us] > 0, b.sunlit_w[k], 0.0)
        delta[k] = ((ch - b.idle_w[k]) * dt) / 3600.0
        c = np.r_[0.0, np.cumsum(delta[k])]
        suf = np.minimum.accumulate(c[::-1])[::-1]
        tail_min[k] = suf - c
        tail_drop[k] = np.maximum.accumulate((c - suf)[::-1])[::-1]
    return delta, tail_min, tail_drop


def prepare_fleet(fleet: Fleet, opps: Opportunities, passes: list[PassGraph] | None = None,
                  geo: Geometry | None = None, name: str = "") -> PreparedFleet:
    """The environment's arrays of `fleet` (its pass graphs built here unless given, with `geo`).

    Raises :class:`eosp.errors.InputError` (naming the fleet) when the fleet has no opportunity."""
    name = name or fleet.case_id or "fleet"
    if len(opps) == 0:
        raise InputError(name, "no opportunities: no satellite can observe any task, nothing to schedule")
    geo = geo or Geometry(fleet)
    los = LineOfSight(fleet, geo)
    if passes is None:
        passes = build_passes(fleet, opps, los)
    t0 = time.perf_counter()
    h = fleet.horizon
    total_us = h.seconds * US
    res_us = h.resource_step_s * US
    half_us = gcd(h.action_step_s * US, res_us) // 2
    base_us = geo.base_step_s * US
    sats, tasks = fleet.satellites, fleet.tasks
    att, bat = sats.attitude, sats.battery
    n_pass = len(passes)
    pass_sat = np.array([pg.satellite for pg in passes], dtype=np.int64)
    n_nodes = np.array([pg.graph.n_nodes for pg in passes], dtype=np.int64)
    n_acq = np.array([pg.n_tasks for pg in passes], dtype=np.int64)
    node_off = np.r_[0, np.cumsum(n_nodes)]
    acq_off = np.r_[0, np.cumsum(n_acq)]
    arc_off = np.r_[0, np.cumsum([pg.graph.n_arcs for pg in passes])]
    node_acq = np.concatenate([np.where(pg.graph.node_acq < 0, -1, pg.graph.node_acq + acq_off[p])
                               for p, pg in enumerate(passes)]).astype(np.int64)
    node_time = np.concatenate([pg.graph.node_time for pg in passes])
    dur = tasks.duration_s.astype(np.float64)
    acq_task = np.concatenate([pg.tasks for pg in passes]).astype(np.int64)
    src = node_acq < 0
    node_task = np.where(src, 0, acq_task[np.maximum(node_acq, 0)])
    node_finish = np.where(src, 0.0, node_time + dur[node_task])
    step_us = h.action_step_s * US
    start_idx = np.zeros(len(node_acq), dtype=np.int64)
    start_idx[~src] = np.concatenate([opps.start[pg.rows] for pg in passes]).astype(np.int64)
    node_start_us = start_idx * step_us
    node_end_us = np.where(src, 0, node_start_us + np.round(dur[node_task] * US).astype(np.int64))
    indptr = np.r_[np.concatenate([pg.graph.indptr[:-1] + arc_off[p] for p, pg in enumerate(passes)]),
                   arc_off[-1]].astype(np.int64)
    dst = np.concatenate([pg.graph.dst.astype(np.int64) + node_off[p] for p, pg in enumerate(passes)])
    acq_lo = np.concatenate([pg.graph.acq_ptr[:-1] + node_off[p] for p, pg in enumerate(passes)]).astype(np.int64)
    acq_hi = np.concatenate([pg.graph.acq_ptr[1:] + node_off[p] for p, pg in enumerate(passes)]).astype(np.int64)
    acq_pass = np.repeat(np.arange(n_pass, dtype=np.int64), n_acq)
    w = tasks.weight.astype(np.float64)
    pass_w = np.bincount(acq_pass, weights=w[acq_task], minlength=n_pass)
    acq_share = w[acq_task] / np.maximum(pass_w[acq_pass], 1e-300)
    # lines of sight, one vectorised call per satellite over all of its nodes
    los0 = np.zeros((len(node_acq), 3))
    los1 = np.zeros((len(node_acq), 3))
    nadir = np.zeros((len(node_acq), 3))
    node_sat = np.repeat(pass_sat, n_nodes)
    for k in np.unique(pass_sat).tolist():
        sel = np.flatnonzero((node_sat == k) & ~src)
        los0[sel] = los.los(k, node_task[sel], node_time[sel])
        los1[sel] = los.los(k, node_task[sel], node_finish[sel])
        nadir[sel] = los.nadir(k, node_time[sel])
    sat_pass_ptr = np.searchsorted(pass_sat, np.arange(len(sats) + 1)).astype(np.int64)
    pass_first_us = np.minimum.reduceat(np.where(src, np.iinfo(np.int64).max, node_start_us), node_off[:-1])
    sep_s = slew_time_s(180.0, att.max_rate_deg_s, att.max_acc_deg_s2) + att.settling_s  # the longest maneuver
    sep_us = np.ceil(sep_s * US).astype(np.int64)
    pass_entry_us = np.maximum(0, (pass_first_us - sep_us[pass_sat]) // res_us * res_us)
    order = np.lexsort((node_start_us[acq_lo], acq_task))
    task_acq_ptr = np.searchsorted(acq_task[order], np.arange(len(tasks) + 1)).astype(np.int64)
    grid_us = np.unique(np.r_[np.arange(0, total_us, res_us, dtype=np.int64), total_us])
    lit_half, lit_base = _sunlight(fleet, geo, total_us, half_us)
    delta, tail_min, tail_drop = _battery_tables(fleet, grid_us, lit_half, half_us)
    seen = np.bincount(acq_task, minlength=len(tasks)) > 0
    task_sat = np.unique(acq_task * len(sats) + pass_sat[acq_pass]) // len(sats)
    scales = np.array([len(acq_task) / max(1, seen.sum()), len(task_sat) / max(1, seen.sum())], dtype=np.float64)
    arrays = FleetArrays(
        np.array([total_us, res_us, half_us, base_us], dtype=np.int64),
        np.stack([att.max_rate_deg_s, att.max_acc_deg_s2, att.settling_s], axis=1).astype(np.float64),
        np.stack([bat.capacity_wh, bat.initial_wh, bat.idle_w, bat.imaging_w, bat.slew_w, bat.sunlit_w],
                 axis=1).astype(np.float64),
        sat_pass_ptr, pass_sat, pass_first_us, pass_entry_us.astype(np.int64), node_off[:-1].astype(np.int64),
        acq_off.astype(np.int64), acq_task, acq_pass, acq_lo, acq_hi, acq_share, node_acq, node_start_us,
        node_end_us, node_time, node_finish, los0, los1, nadir, indptr, dst, w, task_acq_ptr,
        order.astype(np.int64), grid_us, delta, tail_min, tail_drop, lit_half, lit_base, scales)
    fifo = sum(fifo_violations(pg.graph) for pg in passes)
    return PreparedFleet(name, fleet, opps, geo, arrays, int(n_acq.max()), int(fifo), time.perf_counter() - t0)
