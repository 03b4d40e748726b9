"""A strip's geometry as the benchmark derives it: SGP4 states, the roll-only boresight, WGS84 ray hits.

Every action of a valid solution starts on the public time grid and lasts a multiple of it, and the verifier
samples it every `coverage_sample_step_s` from its start, its end included; with the public cases' 10 s grid and
5 s sampling every sample instant is on the 5 s grid from the horizon start.  So the satellites' states are
propagated once, on that grid (:class:`Track`: brahe's SGP4 from the TLE, ITRF, zero EOP, epochs built from the
calendar time as the verifier builds them: the same library called the same way gives the same numbers), and
a strip of any roll is computed from them in arrays:

* the satellite's local axes: nadir = -r/|r|; along = the velocity without its nadir part, normalised;
  across = along x nadir, normalised;
* a look at signed angle `a`: nadir + tan(a) across, normalised; its hit, the nearest positive root of the
  ray-ellipsoid quadratic (WGS84 semi-axes);
* a segment of the strip between two sample instants: the quadrilateral (inner_a, outer_a, outer_b, inner_b) of
  the edge hits in longitude/latitude, the edges at signed |roll| -/+ half the field of view.

Longitudes and latitudes come from a closed-form geodetic conversion (:func:`geodetic`) that agrees with brahe's
to about 1e-12 degrees; the checker converts with brahe itself.
"""

from __future__ import annotations

from datetime import timedelta

import numpy as np

from eosp.regional.model import Case

WGS84_A = 6_378_137.0
WGS84_B = 6_356_752.314_245_179
EPS = 1.0e-9


class Track:
    """The satellites' ITRF states (position, velocity) on the sample grid of a case, propagated once."""

    def __init__(self, case: Case):
        from eosp.fleet.geometry import brahe_module, epochs

        bh = brahe_module()
        self.case = case
        self.step_s = case.sample_step_s
        self.n = int(case.horizon_s // self.step_s) + 1
        offs = np.arange(self.n, dtype=np.int64) * self.step_s * 1_000_000
        self.epochs = epochs(case.horizon_start, offs)
        self.props = [bh.SGPPropagator.from_tle(s.tle_line1, s.tle_line2, float(case.sample_step_s))
                      for s in case.satellites]
        self._states: dict[int, np.ndarray] = {}

    def states(self, sat: int) -> np.ndarray:
        """(n, 6) ITRF states of satellite `sat` on the grid (brahe's state_ecef, batched)."""
        st = self._states.get(sat)
        if st is None:
            st = np.asarray(self.props[sat].states_itrf(self.epochs), dtype=float).reshape(self.n, 6)
            self._states[sat] = st
        return st

    def state_at(self, sat: int, offset_s: float) -> np.ndarray:
        """The state at any instant (brahe's own call; the grid's value where the instant is on it)."""
        k = offset_s / self.step_s
        if float(k).is_integer() and 0 <= k < self.n:
            return self.states(sat)[int(k)]
        from eosp.fleet.geometry import epochs

        e = epochs(self.case.horizon_start, [int(round(offset_s * 1e6))])[0]
        return np.asarray(self.props[sat].state_ecef(e), dtype=float).reshape(6)


def axes(pos: np.ndarray, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(nadir, across) unit vectors, (n, 3) each (the verifier's local axes)."""
    nadir = -pos / np.linalg.norm(pos, axis=-1, keepdims=True)
    along = vel - np.sum(vel * nadir, axis=-1, keepdims=True) * nadir
    along = along / np.linalg.norm(along, axis=-1, keepdims=True)
    across = np.cross(along, nadir)
    across = across / np.linalg.norm(across, axis=-1, keepdims=True)
    return nadir, across


def hits(pos: np.ndarray, nadir: np.ndarray, across: np.ndarray, look_deg) -> tuple[np.ndarray, np.ndarray]:
    """Ground hits (n, 3) of the looks at signed angles `look_deg` (scalar or (n,)), and whether each hit
    exists (a ray that misses the ellipsoid gives NaN there)."""
    v = nadir + np.tan(np.radians(np.asarray(look_deg, dtype=float)))[..., None] * across
    d = v / np.linalg.norm(v, axis=-1, keepdims=True)
    a2, b2 = WGS84_A * WGS84_A, WGS84_B * WGS84_B
    ox, oy, oz = pos[..., 0], pos[..., 1], pos[..., 2]
    dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
    aa = (dx * dx + dy * dy) / a2 + dz * dz / b2
    bb = 2.0 * ((ox * dx + oy * dy) / a2 + oz * dz / b2)
    cc = (ox * ox + oy * oy) / a2 + oz * oz / b2 - 1.0
    disc = bb * bb - 4.0 * aa * cc
    ok = disc >= 0.0
    sq = np.sqrt(np.where(ok, disc, 0.0))
    t1 = (-bb - sq) / (2.0 * aa)
    t2 = (-bb + sq) / (2.0 * aa)
    t = np.where(t1 > EPS, t1, np.where(t2 > EPS, t2, np.nan))
    ok &= np.isfinite(t)
    return pos + np.where(ok, t, np.nan)[..., None] * d, ok


def geodetic(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lon, lat) in degrees of ECEF points (n, 3) on or near the WGS84 ellipsoid (Bowring's formula with two
    refinements: about 1e-12 degrees from brahe's conversion at the surface)."""
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    a, b = WGS84_A, WGS84_B
    e2 = 1.0 - (b * b) / (a * a)
    ep2 = (a * a) / (b * b) - 1.0
    r = np.hypot(x, y)
    lon = np.degrees(np.arctan2(y, x))
    beta = np.arctan2(z * a, r * b)
    lat = np.arctan2(z + ep2 * b * np.sin(beta) ** 3, r - e2 * a * np.cos(beta) ** 3)
    for _ in range(2):
        beta = np.arctan2(b * np.sin(lat), a * np.cos(lat))
        lat = np.arctan2(z + ep2 * b * np.sin(beta) ** 3, r - e2 * a * np.cos(beta) ** 3)
    return lon, np.degrees(lat)


def sample_offsets(case: Case, start_s: float, duration_s: float) -> list[float]:
    """The instants (seconds from the horizon start) at which the verifier samples an action: its start, every
    `coverage_sample_step_s` after it while before its end, and its end."""
    start = case.horizon_start + timedelta(seconds=start_s)
    end = start + timedelta(seconds=duration_s)
    if end <= start:
        return [start_s]
    out, cur, step = [start], start, timedelta(seconds=case.sample_step_s)
    while cur + step < end:
        cur = cur + step
        out.append(cur)
    if out[-1] != end:
        out.append(end)
    return [(t - case.horizon_start).total_seconds() for t in out]
