"""What a fleet's satellites do over the horizon, for drawing: ground tracks and sunlight.

Ground tracks are the satellites' ITRF positions on the base grid (:class:`eosp.fleet.geometry.Geometry`,
the checker's propagation), taken every `step_s` seconds and turned into WGS84 geodetic latitude,
longitude and height (Bowring's closed form: far below a pixel of any map).  Sunlight is the
checker's cylindrical shadow (:class:`eosp.fleet.battery.SunCache`) sampled on the same times and
turned into eclipse intervals; an interval's ends are known to the sampling step, which is what a
drawing needs (the battery itself is always simulated exactly).
"""

from __future__ import annotations

import numpy as np

from eosp.fleet.battery import SunCache
from eosp.fleet.geometry import Geometry

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563


def geodetic(ecef: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lat deg, lon deg, height m) of ITRF positions (..., 3)."""
    a, f = WGS84_A, WGS84_F
    b = a * (1.0 - f)
    e2 = f * (2.0 - f)
    ep2 = (a * a - b * b) / (b * b)
    x, y, z = ecef[..., 0], ecef[..., 1], ecef[..., 2]
    p = np.hypot(x, y)
    th = np.arctan2(z * a, p * b)
    lat = np.arctan2(z + ep2 * b * np.sin(th) ** 3, p - e2 * a * np.cos(th) ** 3)
    n = a / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.where(np.abs(np.cos(lat)) > 1e-9, p / np.cos(lat) - n, np.abs(z) - b)
    return np.degrees(lat), np.degrees(np.arctan2(y, x)), h


def sample_times(geo: Geometry, step_s: int) -> np.ndarray:
    """Seconds from the horizon start, every `step_s` (rounded to the base grid) and the horizon end."""
    base = geo.base_step_s
    k = max(1, int(round(step_s / base)))
    idx = np.r_[np.arange(0, geo.n_base, k), geo.n_base - 1]
    return np.unique(idx) * base


def positions(geo: Geometry, sat: int, t_s: np.ndarray) -> np.ndarray:
    """ITRF positions (n, 3) of satellite `sat` at base-grid times `t_s`."""
    return geo.grid_positions(sat)[np.asarray(t_s, dtype=np.int64) // geo.base_step_s]


def ground_track(geo: Geometry, sat: int, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lat, lon, height) of satellite `sat` at base-grid times `t_s`."""
    return geodetic(positions(geo, sat, t_s))


def eclipses(sun: SunCache, sat: int, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(start, end) seconds of the runs of samples in shadow (an interval runs to the next lit sample)."""
    t_s = np.asarray(t_s, dtype=np.int64)
    lit = sun.sunlit(sat, t_s * 1_000_000)
    dark = np.r_[False, ~lit, False].astype(np.int8)
    d = np.diff(dark)
    on, off = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    ends = np.minimum(off, len(t_s) - 1)
    return t_s[on].astype(np.float64), t_s[ends].astype(np.float64)
