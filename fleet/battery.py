"""Battery simulation of one satellite's timeline, as the aeossp_standard benchmark defines it.

The horizon is cut at every resource-grid instant and at every observation and maneuver bound;
on each segment the load (idle, plus imaging during an observation, plus slew during a maneuver)
and the charging (when sunlit, cylindrical shadow) are taken at the segment's midpoint and held
over the segment.  The charge is clipped at the capacity and the timeline is invalid as soon as
it drops below -1e-9 Wh.  Instants are integer microseconds from the horizon start, the
resolution of UTC timestamps, so cut points and midpoints are the benchmark's exactly.
"""

from __future__ import annotations

import functools

from typing import NamedTuple

import numba
import numpy as np

from eosp.fleet.geometry import Geometry, epochs, sunlit
from eosp.fleet.model import Fleet

US = 1_000_000


class Intervals(NamedTuple):
    """Sorted, non-overlapping [start, end) intervals in microseconds."""

    start: np.ndarray
    end: np.ndarray


class BatteryRun(NamedTuple):
    """Outcome of one satellite's simulation."""

    ok: bool
    gross_wh: float  # gross consumption up to the end (or up to the failing segment)
    fail_us: int  # midpoint of the failing segment, -1 when ok
    fail_action: int  # position (in the observations given) active at the failure, -1 if none
    min_wh: float


def half_even_div2(d: np.ndarray) -> np.ndarray:
    """d / 2 rounded half to even, in integers (Python's ``timedelta / 2``)."""
    q = d // 2
    odd = (d % 2) == 1
    return q + (odd & ((q % 2) == 1))


def cut_points(fleet: Fleet, obs: Intervals, man: Intervals) -> np.ndarray:
    """The resource grid, the horizon's end and every action bound, sorted and unique (µs).  The few action
    bounds are merged into the grid (thousands of points, sorted already) instead of sorting them all together."""
    h = fleet.horizon
    total = h.seconds * US
    grid = _grid(total, h.resource_step_s * US)
    extra = np.unique(np.concatenate([[0, total], obs.start, obs.end, man.start, man.end]).astype(np.int64))
    at = np.searchsorted(grid, extra)
    new = extra[(at == len(grid)) | (grid[np.minimum(at, len(grid) - 1)] != extra)]
    return np.insert(grid, np.searchsorted(grid, new), new)


@functools.lru_cache(maxsize=8)
def _grid(total_us: int, step_us: int) -> np.ndarray:
    g = np.arange(0, total_us, step_us, dtype=np.int64)
    g.flags.writeable = False
    return g


def active(intervals: Intervals, t: np.ndarray) -> np.ndarray:
    """Position of the interval holding each instant (start <= t < end), or -1."""
    if len(intervals.start) == 0:
        return np.full(len(t), -1, dtype=np.int64)
    i = np.searchsorted(intervals.start, t, side="right") - 1
    ok = (i >= 0) & (t < intervals.end[np.maximum(i, 0)])
    return np.where(ok, i, -1)


class SunCache:
    """Sunlight of each satellite at arbitrary instants: ITRF positions rotated to GCRF
    (:meth:`Geometry.rotation_at`, shared by all satellites); instants within a metre of the
    shadow boundary are recomputed with brahe's own GCRF state, the benchmark's path, so the
    verdict is the benchmark's."""

    SAFE_M = 60_000.0  # farther than this from the shadow boundary at both ends of a base step: no crossing
    # in between (a satellite moves under 8 km/s, 40 km in a 5 s step)

    def __init__(self, geo: Geometry):
        self.geo = geo
        self._sun: dict[int, np.ndarray] = {}
        self._grid: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._sun_grid: np.ndarray | None = None
        self._exact: dict[int, dict[int, bool]] = {}  # satellite -> {instant (µs): sunlit} near the shadow boundary

    def grid(self, sat: int) -> tuple[np.ndarray, np.ndarray]:
        """(sunlit, metres to the shadow boundary) of satellite `sat` at every base-grid instant, once."""
        g = self._grid.get(sat)
        if g is None:
            from eosp.fleet.geometry import brahe_module

            bh = brahe_module()
            if self._sun_grid is None:
                self._sun_grid = np.asarray([bh.sun_position(e) for e in self.geo.base_epochs()], dtype=float)
            pos = np.einsum("nij,nj->ni", self.geo.grid_rotations(), self.geo.grid_positions(sat))
            g = sunlit(pos, self._sun_grid, bh.R_EARTH)
            self._grid[sat] = g
        return g

    def _frames(self, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        missing = [t for t in np.unique(t_us).tolist() if t not in self._sun]
        if missing:
            from eosp.fleet.geometry import brahe_module

            bh = brahe_module()
            for t, e in zip(missing, epochs(self.geo.fleet.horizon.start, missing)):
                self._sun[t] = np.asarray(bh.sun_position(e), dtype=float)
        return (self.geo.rotation_at(t_us),
                np.asarray([self._sun[k] for k in t_us.tolist()]).reshape(-1, 3))

    def positions_ecef(self, sat: int, t_us: np.ndarray) -> np.ndarray:
        geo = self.geo
        base = geo.base_step_s * US
        on_grid = (t_us % base) == 0
        out = np.empty((len(t_us), 3))
        if on_grid.any():
            out[on_grid] = geo.grid_positions(sat)[t_us[on_grid] // base]
        if (~on_grid).any():
            out[~on_grid] = geo.positions_ecef(sat, epochs(geo.fleet.horizon.start, t_us[~on_grid]))
        return out

    def sunlit(self, sat: int, t_us: np.ndarray) -> np.ndarray:
        """Sunlight at each instant: read from the base grid where the satellite is far from the shadow boundary
        at both ends of the step holding the instant (it cannot cross it in between), computed as the benchmark
        does elsewhere (:meth:`sunlit_exact`).  The same verdicts, without rotating and propagating each of the
        ~10,000 segment midpoints of every simulation."""
        t_us = np.asarray(t_us, dtype=np.int64)
        if len(t_us) == 0:
            return np.zeros(0, dtype=bool)
        lit, margin = self.grid(sat)
        base = self.geo.base_step_s * US
        i = np.clip(t_us // base, 0, len(lit) - 1)
        j = np.minimum(i + 1, len(lit) - 1)
        safe = (lit[i] == lit[j]) & (margin[i] > self.SAFE_M) & (margin[j] > self.SAFE_M)
        out = lit[i].copy()
        if not safe.all():
            # near the boundary, each instant computed once: a repair simulates a satellite again and again, and
            # most of its segments' midpoints (between resource-grid points) come back
            memo = self._exact.setdefault(sat, {})
            near = t_us[~safe].tolist()
            new = np.array(sorted({t for t in near if t not in memo}), dtype=np.int64)
            if len(new):
                memo.update(zip(new.tolist(), self.sunlit_exact(sat, new).tolist()))
            out[~safe] = [memo[t] for t in near]
        return out

    def sunlit_exact(self, sat: int, t_us: np.ndarray) -> np.ndarray:
        from eosp.fleet.geometry import brahe_module

        if len(t_us) == 0:
            return np.zeros(0, dtype=bool)
        rot, sun = self._frames(t_us)
        pos = np.einsum("nij,nj->ni", rot, self.positions_ecef(sat, t_us))
        lit, margin = sunlit(pos, sun, brahe_module().R_EARTH)
        close = np.flatnonzero(margin < 1.0)
        if len(close):
            eps = epochs(self.geo.fleet.horizon.start, t_us[close])
            exact = self.geo.positions_eci(sat, eps)
            lit[close] = sunlit(exact, sun[close], brahe_module().R_EARTH)[0]
        return lit


@numba.njit(cache=True)
def _run(load: np.ndarray, charge: np.ndarray, dur: np.ndarray, initial: float, capacity: float,
         levels: np.ndarray) -> tuple[int, float, float]:
    """The charge recurrence, segment by segment (sequential by nature): the benchmark's float64 operations in
    its order, compiled without fast-math, so every rounding is the benchmark's.  Returns the first failing
    segment (-1: none), the gross consumption up to it (or to the end) and the lowest charge before it; stops at
    the failure unless `levels` has a slot per segment, which then gets the charge at the end of every segment,
    the whole curve."""
    battery = initial
    gross = 0.0
    low = initial
    keep = levels.shape[0] == load.shape[0]
    fail, fail_gross, fail_low = -1, 0.0, 0.0
    for k in range(len(load)):
        ld, ch, dt = load[k], charge[k], dur[k]
        gross += (ld * dt) / 3600.0
        battery += ((ch - ld) * dt) / 3600.0
        if battery < -1.0e-9 and fail < 0:
            fail, fail_gross, fail_low = k, gross, low
            if not keep:
                break
        battery = min(capacity, battery)
        if keep:
            levels[k] = battery
        if battery < low:
            low = battery
    if fail >= 0:
        return fail, fail_gross, fail_low
    return -1, gross, low


class Segments(NamedTuple):
    """The simulation's segments of one satellite's horizon: midpoints and ends (µs), load and charging power
    (W), durations (s), and the observation active at each midpoint (-1: none)."""

    mid: np.ndarray
    end: np.ndarray
    load: np.ndarray
    charge: np.ndarray
    dur: np.ndarray
    obs: np.ndarray


def segments(fleet: Fleet, sun: SunCache, sat: int, obs: Intervals, man: Intervals) -> Segments:
    """Cut the horizon at the resource grid and every action bound; load and charging at each midpoint."""
    b = fleet.satellites.battery
    pts = cut_points(fleet, obs, man)
    d = np.diff(pts)
    keep = d > 0
    seg_start, d = pts[:-1][keep], d[keep]
    mid = seg_start + half_even_div2(d)
    a_obs, a_man = active(obs, mid), active(man, mid)
    load = b.idle_w[sat] + np.where(a_obs >= 0, b.imaging_w[sat], 0.0)
    load = load + np.where(a_man >= 0, b.slew_w[sat], 0.0)
    charge = np.where(sun.sunlit(sat, mid), b.sunlit_w[sat], 0.0)
    return Segments(mid, seg_start + d, load, charge, d.astype(np.float64) / 1e6, a_obs)


def simulate(fleet: Fleet, sun: SunCache, sat: int, obs: Intervals, man: Intervals) -> BatteryRun:
    """Simulate satellite `sat` over the horizon with observations `obs` and maneuvers `man`."""
    b = fleet.satellites.battery
    mid, _, load, charge, dur, a_obs = segments(fleet, sun, sat, obs, man)
    k, gross, low = _run(np.ascontiguousarray(load, dtype=np.float64), np.ascontiguousarray(charge, dtype=np.float64),
                         dur, float(b.initial_wh[sat]), float(b.capacity_wh[sat]), np.zeros(0))
    if k < 0:
        return BatteryRun(True, float(gross), -1, -1, float(low))
    return BatteryRun(False, float(gross), int(mid[k]), int(a_obs[k]), float(low))


def levels(fleet: Fleet, sun: SunCache, sat: int, obs: Intervals, man: Intervals) -> tuple[np.ndarray, np.ndarray]:
    """The segments' ends (µs) and the battery charge (Wh) at each: the curve of :func:`simulate`, whole (the
    reasons' battery bound, the report's curve)."""
    b = fleet.satellites.battery
    seg = segments(fleet, sun, sat, obs, man)
    out = np.empty(len(seg.dur))
    _run(np.ascontiguousarray(seg.load, dtype=np.float64), np.ascontiguousarray(seg.charge, dtype=np.float64),
         seg.dur, float(b.initial_wh[sat]), float(b.capacity_wh[sat]), out)
    return seg.end, out

