"""Opportunities (when can a satellite observe a task) and passes (runs of them that interact).

An opportunity is a (task, satellite, start) with the start on the action grid such that the
whole action [start, start + duration] lies in the task's window and passes the checker's
geometry test (visible and within the off-nadir limit at its start, its end and every
geometry-grid instant inside), for a satellite carrying the task's sensor.  Satellites are
propagated once over the horizon on the base grid; each satellite then tests all of its tasks'
window instants in one vectorised pass, and a cumulative sum turns instant tests into action
tests.

A pass is a maximal run of one satellite's opportunities, in time, such that a new pass starts
when the next opportunity begins at least ``slew(180 deg) + settling`` after every earlier one
has ended: two opportunities of different passes can never conflict, so passes can be scheduled
one by one.  Arrays are flat and sorted by (pass, start, task), so one pass is a slice.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eosp.fleet.geometry import Geometry, pointing_ok, slew_time_s
from eosp.fleet.model import Fleet


@dataclass(frozen=True, eq=False)
class Opportunities:
    """Flat opportunity arrays sorted by (pass, start, task); `start` is an action-grid index."""

    task: np.ndarray  # int32, row of fleet.tasks
    satellite: np.ndarray  # int32, row of fleet.satellites
    start: np.ndarray  # int32, start = start * action_step_s seconds from the horizon start
    pass_id: np.ndarray  # int32, 0..n_passes-1, increasing with (satellite, time)

    def __len__(self) -> int:
        return len(self.task)

    @property
    def n_passes(self) -> int:
        return int(self.pass_id.max()) + 1 if len(self.pass_id) else 0

    def pass_offsets(self) -> np.ndarray:
        """CSR offsets: pass p is rows offsets[p]:offsets[p+1]."""
        return np.searchsorted(self.pass_id, np.arange(self.n_passes + 1)).astype(np.int64)

    def pass_satellite(self) -> np.ndarray:
        off = self.pass_offsets()
        return self.satellite[off[:-1]] if self.n_passes else np.zeros(0, np.int32)

    def per_task(self, n_tasks: int) -> np.ndarray:
        """Number of opportunities of each task."""
        return np.bincount(self.task, minlength=n_tasks)


@dataclass(frozen=True, eq=False)
class PassView:
    """One pass, ready for a single-pass solver: starts (s), ends (s), tasks and the satellite."""

    satellite: int
    rows: np.ndarray  # rows of the Opportunities arrays
    task: np.ndarray
    start_s: np.ndarray
    end_s: np.ndarray


def pass_view(fleet: Fleet, opps: Opportunities, p: int, offsets: np.ndarray | None = None) -> PassView:
    off = opps.pass_offsets() if offsets is None else offsets
    rows = np.arange(off[p], off[p + 1])
    task = opps.task[rows]
    start_s = opps.start[rows].astype(np.float64) * fleet.horizon.action_step_s
    return PassView(int(opps.satellite[rows[0]]) if len(rows) else -1, rows, task, start_s,
                    start_s + fleet.tasks.duration_s[task])


def _ranges(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Concatenated integer ranges [lo_i, hi_i] (inclusive): (owner index, value)."""
    n = np.maximum(hi - lo + 1, 0)
    owner = np.repeat(np.arange(len(lo)), n)
    first = np.repeat(np.cumsum(n) - n, n)
    return owner, np.arange(int(n.sum())) - first + lo[owner]


def satellite_opportunities(fleet: Fleet, geo: Geometry, sat: int) -> tuple[np.ndarray, np.ndarray]:
    """(task, start action-grid index) of every opportunity of satellite `sat`."""
    h, tk = fleet.horizon, fleet.tasks
    base = geo.base_step_s
    tasks = np.flatnonzero(tk.sensor == fleet.satellites.sensor[sat])
    if len(tasks) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    lo = np.round(tk.release_s[tasks] / base).astype(np.int64)
    hi = np.round(tk.due_s[tasks] / base).astype(np.int64)
    owner, j = _ranges(lo, hi)
    pos = geo.grid_positions(sat)
    vis, on = pointing_ok(pos[j], geo.target_ecef[tasks[owner]], fleet.satellites.attitude.max_off_nadir_deg[sat])
    ok = vis & on
    g_ratio = h.geometry_step_s // base
    bad_g = ~ok & ((j % g_ratio) == 0)
    cs = np.cumsum(bad_g)  # flat; differences within one task's segment count its bad grid points
    seg0 = np.cumsum(np.maximum(hi - lo + 1, 0)) - np.maximum(hi - lo + 1, 0)
    dur_b = np.round(tk.duration_s[tasks] / base).astype(np.int64)
    a_ratio = h.action_step_s // base
    # candidate starts: base indices on the action grid with the action inside the window
    s_lo = -(-lo // a_ratio) * a_ratio
    s_hi = hi - dur_b
    k_owner, k_start = _ranges(s_lo // a_ratio, np.floor_divide(s_hi, a_ratio))
    b = k_start * a_ratio
    e = b + dur_b[k_owner]
    fb = seg0[k_owner] + (b - lo[k_owner])
    fe = seg0[k_owner] + (e - lo[k_owner])
    inside_bad = cs[fe - 1] - cs[fb]
    good = ok[fb] & ok[fe] & (inside_bad == 0)
    return tasks[k_owner[good]], k_start[good]


def passes(fleet: Fleet, sat_of: np.ndarray, task: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Pass ids of opportunities already sorted by (satellite, start, task)."""
    if len(task) == 0:
        return np.zeros(0, np.int64)
    att = fleet.satellites.attitude
    sep = slew_time_s(180.0, att.max_rate_deg_s, att.max_acc_deg_s2) + att.settling_s
    t0 = start.astype(np.float64) * fleet.horizon.action_step_s
    t1 = t0 + fleet.tasks.duration_s[task]
    new = np.ones(len(task), dtype=bool)
    bounds = np.flatnonzero(np.r_[True, sat_of[1:] != sat_of[:-1], True])
    for lo, hi in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
        run_end = np.maximum.accumulate(t1[lo:hi])
        new[lo + 1:hi] = t0[lo + 1:hi] - run_end[:-1] >= sep[sat_of[lo]]
    return np.cumsum(new) - 1


def compute(fleet: Fleet, geo: Geometry | None = None) -> Opportunities:
    """Every opportunity of the fleet, with its pass."""
    geo = geo or Geometry(fleet)
    tasks, sats, starts = [], [], []
    for k in range(len(fleet.satellites)):
        t, s = satellite_opportunities(fleet, geo, k)
        order = np.lexsort((t, s))
        tasks.append(t[order])
        starts.append(s[order])
        sats.append(np.full(len(t), k, dtype=np.int64))
    task, sat, start = (np.concatenate(x) if x else np.zeros(0, np.int64) for x in (tasks, sats, starts))
    pid = passes(fleet, sat, task, start)
    return Opportunities(task.astype(np.int32), sat.astype(np.int32), start.astype(np.int32), pid.astype(np.int32))
