"""Orbits and pointing geometry with brahe: SGP4 from TLEs, ITRF/GCRF frames, WGS84, zero EOP.

The aeossp_standard benchmark defines its geometry through brahe 1.3.4 with a static zero
Earth-orientation provider; calling the same library the same way gives the same numbers.
Propagation is batched: one brahe call per satellite for a whole array of epochs.

Inertial (GCRF) vectors are obtained as ``R(t) @ v_itrf`` with ``R(t)`` brahe's ITRF->GCRF
rotation; for a satellite position this agrees with brahe's own GCRF state to about a
nanometre, and ``R(t)`` depends only on the time, so one rotation per instant serves every
satellite and target.  brahe's rotation (precession-nutation) is costly, so it is computed once
a minute and carried to any instant by the Earth's rotation angle; the neglected
precession-nutation drift over 30 s is below a millimetre at orbit distance.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from math import gcd

import numpy as np

from eosp.fleet.model import Fleet
from eosp.sim.slew import bang_coast_bang_array

NUMERICAL_EPS = 1.0e-9  # the benchmark's tolerance on times, angles and energies
OFF_NADIR_TOL_DEG = 1.0e-6
EARTH_RATE = 2.0 * np.pi * 1.00273781191135448 / 86400.0  # rad/s, Earth rotation angle rate (UT1 = UTC)
FRAME_STEP_S = 60  # rotations are computed by brahe every minute and carried to any instant by Earth's spin

_EOP_READY = False


def brahe_module():
    """brahe, with the zero static EOP provider installed once (imported lazily: it is heavy)."""
    global _EOP_READY
    import brahe

    if not _EOP_READY:
        brahe.set_global_eop_provider_from_static_provider(brahe.StaticEOPProvider.from_zero())
        _EOP_READY = True
    return brahe


def epochs(start: datetime, offsets_us) -> list:
    """brahe UTC epochs at `start` + each offset (microseconds), built from the calendar date and
    the seconds with their microseconds, as the benchmark builds them."""
    bh = brahe_module()
    out = []
    for off in np.asarray(offsets_us, dtype=np.int64).tolist():
        v = (start + timedelta(microseconds=off)).astimezone(UTC)
        out.append(bh.Epoch.from_datetime(v.year, v.month, v.day, v.hour, v.minute,
                                          float(v.second) + v.microsecond / 1_000_000.0, 0.0,
                                          bh.TimeSystem.UTC))
    return out


def target_ecef(lat_deg, lon_deg, alt_m) -> np.ndarray:
    """WGS84 geodetic -> ITRF positions (n, 3) in metres."""
    bh = brahe_module()
    out = np.empty((len(lat_deg), 3))
    for i, (la, lo, al) in enumerate(zip(np.asarray(lat_deg).tolist(), np.asarray(lon_deg).tolist(),
                                         np.asarray(alt_m).tolist())):
        out[i] = bh.position_geodetic_to_ecef([lo, la, al], bh.AngleFormat.DEGREES)
    return out


def rotations(eps: list) -> np.ndarray:
    """ITRF -> GCRF rotation matrices (n, 3, 3) at the given epochs."""
    bh = brahe_module()
    if not eps:
        return np.zeros((0, 3, 3))
    return np.asarray([bh.rotation_ecef_to_eci(e) for e in eps], dtype=float).reshape(len(eps), 3, 3)


def norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between vectors (last axis), degrees; 0 when either is (numerically) zero."""
    na, nb = norm(a), norm(b)
    small = (na <= NUMERICAL_EPS) | (nb <= NUMERICAL_EPS)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.einsum("...i,...i->...", a, b) / (na * nb)
    cos = np.clip(np.where(small, 1.0, cos), -1.0, 1.0)
    return np.where(small, 0.0, np.degrees(np.arccos(cos)))


def off_nadir_deg(sat_ecef: np.ndarray, tgt_ecef: np.ndarray) -> np.ndarray:
    """Angle between the nadir (-r_sat) and the line of sight (r_tgt - r_sat)."""
    return angle_deg(-sat_ecef, tgt_ecef - sat_ecef)


def visible(sat_ecef: np.ndarray, tgt_ecef: np.ndarray) -> np.ndarray:
    """The satellite is above the target's local horizontal plane (geocentric normal)."""
    n = norm(tgt_ecef)
    with np.errstate(invalid="ignore", divide="ignore"):
        up = tgt_ecef / n[..., None]
    return (n > NUMERICAL_EPS) & (np.einsum("...i,...i->...", sat_ecef - tgt_ecef, up) > 0.0)


def pointing_ok(sat_ecef: np.ndarray, tgt_ecef: np.ndarray, max_off_nadir_deg) -> tuple[np.ndarray, np.ndarray]:
    """(visible, off-nadir within its limit) at each instant."""
    return visible(sat_ecef, tgt_ecef), off_nadir_deg(sat_ecef, tgt_ecef) <= np.asarray(max_off_nadir_deg) + OFF_NADIR_TOL_DEG


def slew_time_s(angle, max_rate, max_acc) -> np.ndarray:
    """Bang-coast-bang rest-to-rest slew time for an angle (degrees), without settling: the one formula,
    :func:`eosp.sim.slew.bang_coast_bang`, over arrays."""
    return bang_coast_bang_array(np.maximum(0.0, np.asarray(angle, dtype=float)), np.asarray(max_rate, dtype=float),
                                 np.asarray(max_acc, dtype=float))


def sunlit(pos_eci: np.ndarray, sun_eci: np.ndarray, r_earth: float) -> tuple[np.ndarray, np.ndarray]:
    """Cylindrical-shadow sunlight: (sunlit, distance in metres to the shadow boundary)."""
    sun_hat = sun_eci / norm(sun_eci)[..., None]
    proj = np.einsum("...i,...i->...", pos_eci, sun_hat)
    perp = norm(pos_eci - proj[..., None] * sun_hat)
    shadow = (proj < 0.0) & (perp < r_earth)
    margin = np.where(proj < 0.0, np.abs(perp - r_earth), np.minimum(np.abs(proj), np.abs(perp - r_earth)))
    return ~shadow, margin


class Geometry:
    """Per-fleet geometry: propagators, target positions, and satellite positions and frame
    rotations on the base grid (the finest grid both the action and geometry steps fall on)."""

    def __init__(self, fleet: Fleet):
        bh = brahe_module()
        self.fleet = fleet
        h = fleet.horizon
        self.base_step_s = gcd(h.action_step_s, h.geometry_step_s)
        self.n_base = h.seconds // self.base_step_s + 1
        sats = fleet.satellites
        step = float(min(h.action_step_s, h.geometry_step_s))
        self.propagators = [bh.SGPPropagator.from_tle(l1, l2, step)
                            for l1, l2 in zip(sats.tle.line1.tolist(), sats.tle.line2.tolist())]
        t = fleet.tasks
        self.target_ecef = target_ecef(t.lat_deg, t.lon_deg, t.alt_m)
        self._grid_pos: dict[int, np.ndarray] = {}
        self._grid_rot: np.ndarray | None = None
        self._base_epochs: list | None = None
        self._coarse_rot: dict[int, np.ndarray] = {}

    def base_epochs(self) -> list:
        if self._base_epochs is None:
            offs = np.arange(self.n_base, dtype=np.int64) * self.base_step_s * 1_000_000
            self._base_epochs = epochs(self.fleet.horizon.start, offs)
        return self._base_epochs

    def grid_positions(self, sat: int) -> np.ndarray:
        """ITRF positions (n_base, 3) of satellite `sat` on the base grid."""
        pos = self._grid_pos.get(sat)
        if pos is None:
            pos = self.positions_ecef(sat, self.base_epochs())
            self._grid_pos[sat] = pos
        return pos

    def grid_rotations(self) -> np.ndarray:
        """ITRF -> GCRF rotations (n_base, 3, 3) on the base grid."""
        if self._grid_rot is None:
            us = np.arange(self.n_base, dtype=np.int64) * self.base_step_s * 1_000_000
            self._grid_rot = self.rotation_at(us)
        return self._grid_rot

    def rotation_at(self, t_us: np.ndarray) -> np.ndarray:
        """ITRF -> GCRF rotations (n, 3, 3) at instants in microseconds from the horizon start:
        brahe's rotation at the nearest whole minute times the Earth's spin over the difference."""
        t_us = np.asarray(t_us, dtype=np.int64)
        step = FRAME_STEP_S * 1_000_000
        idx = (t_us + step // 2) // step
        missing = sorted(set(np.unique(idx).tolist()) - set(self._coarse_rot))
        if missing:
            for k, r in zip(missing, rotations(epochs(self.fleet.horizon.start, np.asarray(missing) * step))):
                self._coarse_rot[k] = r
        base = np.asarray([self._coarse_rot[k] for k in idx.tolist()]).reshape(-1, 3, 3)
        d = (t_us - idx * step) / 1e6
        c, s = np.cos(EARTH_RATE * d), np.sin(EARTH_RATE * d)
        spin = np.zeros((len(d), 3, 3))
        spin[:, 0, 0], spin[:, 0, 1], spin[:, 1, 0], spin[:, 1, 1], spin[:, 2, 2] = c, -s, s, c, 1.0
        return base @ spin

    def positions_ecef(self, sat: int, eps: list) -> np.ndarray:
        if not eps:
            return np.zeros((0, 3))
        return np.asarray(self.propagators[sat].states_itrf(eps), dtype=float).reshape(len(eps), 6)[:, :3]

    def positions_eci(self, sat: int, eps: list) -> np.ndarray:
        """brahe's own GCRF positions (exact path; slower than rotating ITRF ones)."""
        if not eps:
            return np.zeros((0, 3))
        return np.asarray(self.propagators[sat].states_eci(eps), dtype=float).reshape(len(eps), 6)[:, :3]
