"""The battery of each satellite as the benchmark integrates it, and where each satellite is sunlit.

The verifier steps every satellite over the sample-step mesh of the whole horizon plus every boundary of its
actions and slews, and on each interval takes the loads at the midpoint (idle; imaging inside an action;
slewing inside a slew window) and the charge when the satellite is sunlit there: brahe's GCRF position and Sun
at that instant, a cylindrical shadow of radius R_EARTH.  Evaluating brahe at all ~50,000 midpoints of a 72 h
case per satellite is what makes the verifier slow; :class:`Sun` gets the same verdicts from brahe's frames once a
minute: a minute whose two ends are lit alike and further from the shadow's boundary than half the way the
satellite travels in a minute holds that verdict throughout; the midpoints inside other minutes are evaluated
exactly (brahe's GCRF state and Sun at the instant).
"""

from __future__ import annotations

import numba
import numpy as np

from eosp.regional.geometry import Track
from eosp.regional.model import Case

US = 1_000_000
COARSE_S = 60
SAFE_M = 300_000.0  # more than half the way a satellite travels in a minute (< 8 km/s): a path of length L
# between two points each further than L/2 from the shadow's boundary cannot reach it


def _lit(pos: np.ndarray, sun: np.ndarray, r_earth: float) -> tuple[np.ndarray, np.ndarray]:
    """(sunlit, a lower bound of the distance in metres to the other state): the shadow is the half-cylinder
    behind the Earth (projection on the Sun's direction negative, distance from its axis below R_EARTH)."""
    hat = sun / np.linalg.norm(sun, axis=-1, keepdims=True)
    proj = np.sum(pos * hat, axis=-1)
    perp = np.linalg.norm(pos - proj[..., None] * hat, axis=-1)
    shadow = (proj < 0.0) & (perp < r_earth)
    to_shadow = np.where(proj < 0.0, perp - r_earth,
                         np.where(perp < r_earth, proj, np.hypot(proj, np.maximum(perp - r_earth, 0.0))))
    to_light = np.minimum(-proj, r_earth - perp)
    return ~shadow, np.where(shadow, to_light, to_shadow)


class Sun:
    """Sunlit verdicts per satellite at any instant (microseconds from the horizon start), as the verifier
    computes them (see the module docstring)."""

    def __init__(self, case: Case, track: Track):
        from eosp.fleet.geometry import brahe_module

        self.bh = brahe_module()
        self.case, self.track = case, track
        self.every = max(1, -(-COARSE_S // track.step_s))  # grid points per coarse step
        self.coarse_s = self.every * track.step_s
        idx = np.arange(0, track.n, self.every)
        self.coarse_idx = np.r_[idx, track.n - 1] if idx[-1] != track.n - 1 else idx
        self.coarse_eps = [track.epochs[i] for i in self.coarse_idx.tolist()]
        self.coarse_sun = np.asarray([self.bh.sun_position(e) for e in self.coarse_eps], dtype=float)
        self.coarse_rot = np.asarray([self.bh.rotation_ecef_to_eci(e) for e in self.coarse_eps],
                                     dtype=float).reshape(-1, 3, 3)
        self._grid: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def _coarse(self, sat: int) -> tuple[np.ndarray, np.ndarray]:
        g = self._grid.get(sat)
        if g is None:
            # GCRF = the rotation at the instant times the ITRF position: brahe's own states to about a nanometre
            pos = np.einsum("nij,nj->ni", self.coarse_rot, self.track.states(sat)[self.coarse_idx, :3])
            g = self._grid[sat] = _lit(pos, self.coarse_sun, self.bh.R_EARTH)
        return g

    def exact(self, sat: int, t_us: np.ndarray) -> np.ndarray:
        from eosp.fleet.geometry import epochs

        if len(t_us) == 0:
            return np.zeros(0, dtype=bool)
        eps = epochs(self.case.horizon_start, t_us)
        pos = np.asarray(self.track.props[sat].states_eci(eps), dtype=float).reshape(-1, 6)[:, :3]
        sun = np.asarray([self.bh.sun_position(e) for e in eps], dtype=float)
        return _lit(pos, sun, self.bh.R_EARTH)[0]

    def near(self, sat: int, t_us: np.ndarray) -> np.ndarray:
        """Verdicts near the boundary: the instant's ITRF position turned by the nearest coarse rotation and the
        Earth's spin since, the coarse Sun (within about 100 m of brahe's GCRF position and Sun: the Sun moves
        0.04 deg a minute); exact where that puts the satellite within a kilometre of the boundary."""
        from eosp.fleet.geometry import EARTH_RATE, epochs

        eps = epochs(self.case.horizon_start, t_us)
        itrf = np.asarray(self.track.props[sat].states_itrf(eps), dtype=float).reshape(-1, 6)[:, :3]
        k = np.clip(np.rint(t_us / (self.coarse_s * US)).astype(np.int64), 0, len(self.coarse_idx) - 1)
        d = (t_us - self.coarse_idx[k] * self.track.step_s * US) / US
        c, s = np.cos(EARTH_RATE * d), np.sin(EARTH_RATE * d)
        spun = np.stack([c * itrf[:, 0] - s * itrf[:, 1], s * itrf[:, 0] + c * itrf[:, 1], itrf[:, 2]], axis=1)
        lit, margin = _lit(np.einsum("nij,nj->ni", self.coarse_rot[k], spun), self.coarse_sun[k], self.bh.R_EARTH)
        close = margin < 1000.0
        if close.any():
            lit[close] = self.exact(sat, t_us[close])
        return lit

    def lit(self, sat: int, t_us: np.ndarray) -> np.ndarray:
        lit, margin = self._coarse(sat)
        i = np.clip(t_us // (self.coarse_s * US), 0, len(lit) - 2)
        safe = (lit[i] == lit[i + 1]) & (margin[i] > SAFE_M) & (margin[i + 1] > SAFE_M)
        out = lit[i].copy()
        if not safe.all():
            out[~safe] = self.near(sat, t_us[~safe])
        return out


def _midpoints(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a + (b - a) / 2 as datetime arithmetic gives it: the half of a microsecond rounded to even."""
    q, r = np.divmod(b - a, 2)
    return a + q + (r & (q & 1))


@numba.njit(cache=True)
def _integrate(dur, charge, load, initial, capacity):
    """The verifier's recurrence (its float operations in its order): the lowest charge and the index of the
    interval where it first falls below -1e-9 (-1: never)."""
    battery = initial
    low = initial
    for k in range(len(dur)):
        nxt = battery + ((charge[k] - load[k]) * dur[k] / 3600.0)
        if nxt < -1.0e-9:
            return min(low, nxt), k, nxt
        battery = min(capacity, nxt)
        low = min(low, battery)
    return low, -1, battery


def simulate(case: Case, track: Track, acts: list, slews: list, sun: Sun | None = None) -> tuple[dict, list[str]]:
    """Rule 5 for every satellite: {satellite id: {min_battery_wh, final_battery_wh}}, and the violations."""
    sun = sun or Sun(case, track)
    horizon_us = int(round(case.horizon_s * US))
    mesh = np.minimum(np.arange(0, horizon_us + case.sample_step_s * US, case.sample_step_s * US), horizon_us)
    out, bad = {}, []
    for s, sat in enumerate(case.satellites):
        mine = [p for p in acts if p.ok and p.sat == s]
        img = np.array([(p.start_us, p.end_us) for p in mine], dtype=np.int64).reshape(-1, 2)
        slw = np.array([(a, b) for q, a, b in slews if q == s], dtype=np.int64).reshape(-1, 2)
        pts = np.unique(np.concatenate([mesh, img.ravel(), slw.ravel()]))
        a, b = pts[:-1], pts[1:]
        mid = _midpoints(a, b)
        imaging = np.zeros(len(mid), dtype=bool)
        for x, y in img:
            imaging |= (mid >= x) & (mid < y)
        slewing = np.zeros(len(mid), dtype=bool)
        for x, y in slw:
            slewing |= (mid >= x) & (mid < y)
        load = np.full(len(mid), sat.idle_power_w)
        load = np.where(imaging, load + sat.imaging_power_w, load)
        load = np.where(slewing, load + sat.slew_power_w, load)
        charge = np.where(sun.lit(s, mid), sat.sunlit_charge_power_w, 0.0)
        low, fail, last = _integrate((b - a) / US, charge, load, sat.initial_battery_wh, sat.battery_capacity_wh)
        if fail >= 0:
            t = case.at(float(mid[fail]) / US).strftime("%Y-%m-%dT%H:%M:%SZ")
            bad.append(f"satellite {sat.id}: battery depletes below zero around {t}")
        out[sat.id] = {"min_battery_wh": float(low), "final_battery_wh": float(last)}
    return out, bad
