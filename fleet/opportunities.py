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


# Memory of the scan, measured with eosp import on aeossp cases stretched to 30 days and a year (2-16 satellites,
# peak RSS): the process itself, then per base-grid instant brahe's epochs and the frame rotations, and per satellite
# and instant its ITRF positions (kept) and propagated states (transient); per opportunity its candidate arrays
# and row.
BASE_BYTES = 300 * 1024 ** 2
INSTANT_BYTES = 320
SATELLITE_INSTANT_BYTES = 48
OPPORTUNITY_BYTES = 416


def instants(horizon_s: float, base_step_s: float) -> int:
    """Base-grid instants of a horizon (both ends)."""
    return int(horizon_s // max(base_step_s, 1e-9)) + 1


def scan_bytes(n_sat: int, n_instants: int, n_opportunities: float = 0.0) -> int:
    """Peak memory of propagating the satellites over the horizon and scanning `n_opportunities` opportunities
    (the horizon's length counts as much as the fleet's size: a year at 5 s is 6.3 M instants)."""
    return int(BASE_BYTES + n_instants * (INSTANT_BYTES + SATELLITE_INSTANT_BYTES * n_sat)
               + n_opportunities * OPPORTUNITY_BYTES)


SAMPLE_SATELLITES = 8  # satellites scanned to estimate a fleet's opportunities (spread over the sensors)
SAMPLE_MARGIN = 1.5  # the estimate's margin over the sample's mean (satellites of one sensor differ in their orbits)


def sample_scan(fleet: Fleet, geo: Geometry, count: int = SAMPLE_SATELLITES) -> dict:
    """The opportunities of a few satellites (:func:`satellite_opportunities`), spread evenly over each sensor's
    satellites in proportion to their number (one at least per sensor): what :func:`expected_opportunities` scales
    up, and what :func:`compute` then does not scan again: satellite -> (task, start)."""
    sensors = fleet.satellites.sensor
    out = {}
    for sensor in np.unique(sensors).tolist():
        idx = np.flatnonzero(sensors == sensor)
        take = max(1, round(count * len(idx) / len(sensors)))
        for k in idx[np.unique(np.linspace(0, len(idx) - 1, min(take, len(idx))).round().astype(np.int64))].tolist():
            out[k] = satellite_opportunities(fleet, geo, k)
    return out


def expected_opportunities(fleet: Fleet, sample: dict[int, tuple[np.ndarray, np.ndarray]]) -> float:
    """The fleet's opportunities estimated from :func:`sample_scan`: per sensor, its satellites times the sampled
    mean, with :data:`SAMPLE_MARGIN`.  A formula from the windows alone cannot do this: where the windows are drawn
    around the satellites' accesses (the aeossp cases) a satellite-task pair has six times the opportunities of
    the uniform case, and where tasks are long the passes leave few starts (generated fleets: a fifth of it)."""
    sensors = fleet.satellites.sensor
    total = 0.0
    for sensor in np.unique(sensors).tolist():
        idx = np.flatnonzero(sensors == sensor)
        counts = [len(sample[k][0]) for k in idx.tolist() if k in sample]
        total += len(idx) * float(np.mean(counts)) * (SAMPLE_MARGIN if len(counts) < len(idx) else 1.0)
    return total


# Memory of the geometry a check or a solve keeps over the whole horizon (frame rotations on the base grid, sunlight,
# battery simulations), measured with eosp validate of a 30-day, 2-satellite fleet (860 bytes an instant).
HORIZON_INSTANT_BYTES = 1000


def horizon_bytes(fleet: Fleet, processes: int = 1) -> tuple[int, int]:
    """(bytes, base-grid instants) of the whole-horizon geometry of a check or a solve: per process the instants'
    rotations and sunlight, once the satellites' positions."""
    from math import gcd

    h = fleet.horizon
    n = instants(h.seconds, gcd(h.action_step_s, h.geometry_step_s))
    return processes * (BASE_BYTES + n * HORIZON_INSTANT_BYTES) + n * SATELLITE_INSTANT_BYTES * len(fleet.satellites), n


def require_check_memory(fleet: Fleet, where: object) -> None:
    """Refuse (one line with the estimate) a fleet whose checker (battery and sunlight over the horizon) cannot fit
    in memory: before validating, reporting or exporting a schedule of it."""
    from eosp.memory import require_memory

    need, n = horizon_bytes(fleet)
    require_memory(where, need, f"checking {len(fleet.satellites)} satellites over {fleet.horizon.seconds:,} s "
                                f"({n:,} instants)")


def require_scan_memory(fleet: Fleet, where: object) -> tuple[Geometry, dict]:
    """Refuse (one line with the estimate, :func:`eosp.memory.require_memory`) a fleet whose opportunity scan cannot
    fit in memory: the horizon's geometry first, before any propagation; then the opportunities, from a sample of
    satellites (:func:`sample_scan`, a few seconds at 1,000 satellites).  Returns the Geometry and the sample, for
    :func:`compute` to go on with."""
    from math import gcd

    from eosp.memory import require_memory

    h, tk = fleet.horizon, fleet.tasks
    n = instants(h.seconds, gcd(h.action_step_s, h.geometry_step_s))
    what = (f"the opportunities of {len(fleet.satellites)} satellites and {len(tk)} tasks over {h.seconds:,} s "
            f"({n:,} instants of the {gcd(h.action_step_s, h.geometry_step_s)} s grid)")
    require_memory(where, scan_bytes(len(fleet.satellites), n), what)
    geo = Geometry(fleet)
    sample = sample_scan(fleet, geo)
    expected = expected_opportunities(fleet, sample)
    require_memory(where, scan_bytes(len(fleet.satellites), n, expected), f"{what}, about {expected:,.0f} expected")
    return geo, sample


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


REACH_STEP_S = 60  # the reach scan samples each satellite once a minute
R_POLAR_M = 6356752.314245  # WGS84 semi-minor axis: no target is nearer the Earth's centre (at altitude >= 0)


def reach_segments(fleet: Fleet, geo: Geometry, sat: int, tasks: np.ndarray, lo: np.ndarray,
                   hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Base-grid index ranges (owner, first, last) inside each task's window [lo, hi] that hold every instant
    at which satellite `sat` could see the task; the fine test then scans only these.

    A target is seen only within the Earth-central angle ``asin(r sin(eta) / R) - eta`` of the sub-satellite
    point (off-nadir limit eta, satellite radius r, target radius R; also below the horizon angle
    ``acos(R / r)``), largest for the highest satellite radius and the smallest target radius.  The satellite
    is sampled once a minute; a target within that angle plus the ground-track motion over half a minute of
    a sample is paired with the sample's minute (neighbours overlap by a base step), and the pairs of a task
    are merged into contiguous ranges.  Without it the scan tests every task at every instant of its window:
    satellites x tasks x window samples, 10^10 tests for a 200-satellite, 20,000-task day.
    """
    from scipy.spatial import cKDTree

    base = geo.base_step_s
    pos = geo.grid_positions(sat)
    n_base = len(pos)
    ratio = max(1, REACH_STEP_S // base)
    coarse = pos[::ratio]
    r_max = float(np.sqrt((pos ** 2).sum(axis=1)).max())
    r_tgt = max(1.0, R_POLAR_M + min(0.0, float(fleet.tasks.alt_m[tasks].min())))
    eta = np.radians(float(fleet.satellites.attitude.max_off_nadir_deg[sat]) + 1e-3)
    horizon_angle = np.arccos(min(1.0, r_tgt / r_max))
    x = r_max * np.sin(eta) / r_tgt
    reach = horizon_angle if x >= 1.0 else min(horizon_angle, np.arcsin(x) - eta)
    unit = coarse / np.sqrt((coarse ** 2).sum(axis=1))[:, None]
    step_angle = np.arccos(np.clip((unit[1:] * unit[:-1]).sum(axis=1), -1.0, 1.0)).max() if len(unit) > 1 else 0.0
    theta = min(np.pi, reach + 0.6 * step_angle + np.radians(0.1))
    tgt = geo.target_ecef[tasks]
    tgt = tgt / np.maximum(np.sqrt((tgt ** 2).sum(axis=1)), 1.0)[:, None]
    pairs = cKDTree(tgt).sparse_distance_matrix(cKDTree(unit), 2.0 * np.sin(theta / 2.0), output_type="ndarray")
    owner, k = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    half = ratio // 2 + 1
    first = np.maximum(k * ratio - half, lo[owner])
    last = np.minimum(np.minimum(k * ratio + half, n_base - 1), hi[owner])
    keep = first <= last
    owner, first, last = owner[keep], first[keep], last[keep]
    order = np.lexsort((first, owner))
    owner, first, last = owner[order], first[order], last[order]
    if len(owner) == 0:
        return owner, first, last
    big = np.int64(n_base + 2)
    run_end = np.maximum.accumulate(owner * big + last) - owner * big  # latest end so far within the task
    new = np.r_[True, (owner[1:] != owner[:-1]) | (first[1:] > run_end[:-1] + 1)]
    seg = np.cumsum(new) - 1
    seg_last = np.zeros(int(seg[-1]) + 1, np.int64)
    np.maximum.at(seg_last, seg, last)
    return owner[new], first[new], seg_last


def satellite_opportunities(fleet: Fleet, geo: Geometry, sat: int) -> tuple[np.ndarray, np.ndarray]:
    """(task, start action-grid index) of every opportunity of satellite `sat`."""
    h, tk = fleet.horizon, fleet.tasks
    base = geo.base_step_s
    tasks = np.flatnonzero(tk.sensor == fleet.satellites.sensor[sat])
    if len(tasks) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    t_lo = np.round(tk.release_s[tasks] / base).astype(np.int64)
    t_hi = np.round(tk.due_s[tasks] / base).astype(np.int64)
    seg_task, lo, hi = reach_segments(fleet, geo, sat, tasks, t_lo, t_hi)  # seg_task: index into `tasks`
    owner, j = _ranges(lo, hi)
    pos = geo.grid_positions(sat)
    vis, on = pointing_ok(pos[j], geo.target_ecef[tasks[seg_task[owner]]],
                          fleet.satellites.attitude.max_off_nadir_deg[sat])
    ok = vis & on
    g_ratio = h.geometry_step_s // base
    bad_g = ~ok & ((j % g_ratio) == 0)
    cs = np.cumsum(bad_g)  # flat; differences within one segment count its bad grid points
    seg0 = np.cumsum(np.maximum(hi - lo + 1, 0)) - np.maximum(hi - lo + 1, 0)
    dur_b = np.round(tk.duration_s[tasks[seg_task]] / base).astype(np.int64)
    a_ratio = h.action_step_s // base
    # candidate starts: base indices on the action grid with the action inside the segment
    s_lo = -(-lo // a_ratio) * a_ratio
    s_hi = hi - dur_b
    k_owner, k_start = _ranges(s_lo // a_ratio, np.floor_divide(s_hi, a_ratio))
    b = k_start * a_ratio
    e = b + dur_b[k_owner]
    fb = seg0[k_owner] + (b - lo[k_owner])
    fe = seg0[k_owner] + (e - lo[k_owner])
    inside_bad = cs[fe - 1] - cs[fb]
    good = ok[fb] & ok[fe] & (inside_bad == 0)
    return tasks[seg_task[k_owner[good]]], k_start[good]


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


def compute(fleet: Fleet, geo: Geometry | None = None, scanned: dict | None = None) -> Opportunities:
    """Every opportunity of the fleet, with its pass (`scanned`: satellites already scanned, :func:`sample_scan`)."""
    geo = geo or Geometry(fleet)
    scanned = scanned or {}
    tasks, sats, starts = [], [], []
    for k in range(len(fleet.satellites)):
        t, s = scanned[k] if k in scanned else satellite_opportunities(fleet, geo, k)
        order = np.lexsort((t, s))
        tasks.append(t[order])
        starts.append(s[order])
        sats.append(np.full(len(t), k, dtype=np.int64))
    task, sat, start = (np.concatenate(x) if x else np.zeros(0, np.int64) for x in (tasks, sats, starts))
    pid = passes(fleet, sat, task, start)
    return Opportunities(task.astype(np.int32), sat.astype(np.int32), start.astype(np.int32), pid.astype(np.int32))
