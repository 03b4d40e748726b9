"""Orbit, Earth rotation, Sun and pointing geometry of one agile satellite.

Frames and conventions (documented in docs/simulator.md):

* ECI: inertial, z = Earth's axis.  Earth is a sphere of radius R_EARTH rotating
  at OMEGA_EARTH; a target at (lat, lon) is at ``Rz(gmst0 + OMEGA_EARTH t)`` of
  its Earth-fixed position.
* LVLH (local orbital frame): z points to nadir, y along the negative orbit
  normal, x = y cross z (along the velocity for a circular orbit).
* Attitude: roll phi about x then pitch theta about y, ``R = Rx(phi) Ry(theta)``;
  the boresight (body z) is ``R e_z = (sin th, -sin ph cos th, cos ph cos th)``
  in LVLH.  Yaw is steered and plays no part.
* The rotation angle between two attitudes has a closed form depending only on
  the roll and pitch differences (see :func:`rotation_angle_deg`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MU_EARTH = 398600.4418  # km^3/s^2
R_EARTH = 6378.137  # km
OMEGA_EARTH = 7.2921159e-5  # rad/s
J2 = 1.08262668e-3
SIDEREAL_YEAR_S = 365.2422 * 86400.0


def sun_synchronous_inclination(a_km: float) -> float:
    """Inclination (rad) whose J2 nodal precession follows the mean Sun."""
    n = np.sqrt(MU_EARTH / a_km**3)
    omega_dot = 2.0 * np.pi / SIDEREAL_YEAR_S
    cos_i = -omega_dot / (1.5 * J2 * (R_EARTH / a_km) ** 2 * n)
    if not -1.0 <= cos_i <= 1.0:
        raise ValueError(f"no sun-synchronous orbit at semi-major axis {a_km} km")
    return float(np.arccos(cos_i))


def sun_direction(day_of_year: float) -> np.ndarray:
    """Unit Sun vector in ECI (low-precision almanac, good to ~0.01 deg)."""
    n = day_of_year - 1.5  # days from J2000.0 within the year; only the annual phase matters
    mean_lon = np.deg2rad(280.46 + 0.9856474 * n)
    g = np.deg2rad(357.528 + 0.9856003 * n)
    lam = mean_lon + np.deg2rad(1.915) * np.sin(g) + np.deg2rad(0.020) * np.sin(2 * g)
    eps = np.deg2rad(23.439)
    return np.array([np.cos(lam), np.cos(eps) * np.sin(lam), np.sin(eps) * np.sin(lam)])


@dataclass(frozen=True)
class Orbit:
    """Satellite ephemeris over the horizon, as position/velocity callables in ECI."""

    a_km: float
    inclination: float
    raan: float
    u0: float
    gmst0: float
    period_s: float
    tle_lines: tuple[str, str] | None = None
    tle_start_jd: float = 0.0

    @staticmethod
    def circular_sso(altitude_km: float, ltan_hours: float, sun: np.ndarray, gmst0: float) -> "Orbit":
        a = R_EARTH + altitude_km
        inc = sun_synchronous_inclination(a)
        sun_ra = np.arctan2(sun[1], sun[0])
        raan = sun_ra + np.deg2rad((ltan_hours - 12.0) * 15.0)
        period = 2.0 * np.pi * np.sqrt(a**3 / MU_EARTH)
        return Orbit(a, inc, float(raan), 0.0, float(gmst0), float(period))

    @staticmethod
    def from_tle(line1: str, line2: str, start_offset_s: float = 0.0) -> "Orbit":
        from sgp4.api import Satrec

        sat = Satrec.twoline2rv(line1, line2)
        a = sat.a * R_EARTH if sat.a > 0 else (MU_EARTH / (sat.no_kozai / 60.0) ** 2) ** (1 / 3)
        period = 2.0 * np.pi / (sat.no_kozai / 60.0)
        jd0 = sat.jdsatepoch + sat.jdsatepochF + start_offset_s / 86400.0
        return Orbit(float(a), float(sat.inclo), float(sat.nodeo), 0.0, float(_gmst(jd0)), float(period),
                     tle_lines=(line1, line2), tle_start_jd=float(jd0))

    def shifted(self, dt: float) -> "Orbit":
        """The same trajectory with its time origin moved `dt` seconds later."""
        from dataclasses import replace

        n = 2.0 * np.pi / self.period_s
        return replace(self, u0=self.u0 + n * dt, gmst0=self.gmst0 + OMEGA_EARTH * dt,
                       tle_start_jd=self.tle_start_jd + (dt / 86400.0 if self.tle_lines else 0.0))

    def state(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """ECI position (km) and velocity (km/s) at times t (s), shapes (T, 3)."""
        t = np.asarray(t, dtype=np.float64)
        if self.tle_lines is not None:
            return self._tle_state(t)
        n = 2.0 * np.pi / self.period_s
        u = self.u0 + n * t
        cu, su = np.cos(u), np.sin(u)
        cO, sO = np.cos(self.raan), np.sin(self.raan)
        ci, si = np.cos(self.inclination), np.sin(self.inclination)
        r = self.a_km * np.stack([cu * cO - su * ci * sO, cu * sO + su * ci * cO, su * si], axis=-1)
        v = self.a_km * n * np.stack([-su * cO - cu * ci * sO, -su * sO + cu * ci * cO, cu * si], axis=-1)
        return r, v

    def _tle_state(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from sgp4.api import Satrec

        sat = Satrec.twoline2rv(*self.tle_lines)
        jd = self.tle_start_jd + t / 86400.0
        jd_i = np.floor(jd)
        err, r, v = sat.sgp4_array(jd_i, jd - jd_i)
        if np.any(err):
            raise ValueError(f"SGP4 propagation failed (error code {int(err[err != 0][0])})")
        return np.asarray(r), np.asarray(v)

    def gmst(self, t: np.ndarray) -> np.ndarray:
        return self.gmst0 + OMEGA_EARTH * np.asarray(t, dtype=np.float64)


def _gmst(jd: float) -> float:
    from sgp4.propagation import gstime

    return float(gstime(jd))


def target_ecef(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    lat, lon = np.deg2rad(lat_deg), np.deg2rad(lon_deg)
    return R_EARTH * np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)


def ecef_to_eci(p_ecef: np.ndarray, gmst: np.ndarray) -> np.ndarray:
    """Rotate Earth-fixed points (..., 3) by the sidereal angle (broadcast over leading dims)."""
    c, s = np.cos(gmst), np.sin(gmst)
    x, y, z = p_ecef[..., 0], p_ecef[..., 1], p_ecef[..., 2]
    return np.stack([c * x - s * y, s * x + c * y, np.broadcast_to(z, np.broadcast(x, c).shape)], axis=-1)


def lvlh_basis(r: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    z = -r / np.linalg.norm(r, axis=-1, keepdims=True)
    h = np.cross(r, v)
    y = -h / np.linalg.norm(h, axis=-1, keepdims=True)
    x = np.cross(y, z)
    return x, y, z


@dataclass
class Pointing:
    """Roll, pitch (deg), Sun elevation at the target (deg) and off-nadir cosine."""

    roll: np.ndarray
    pitch: np.ndarray
    sun_elevation: np.ndarray
    boresight_z: np.ndarray


def pointing(orbit: Orbit, sun: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray,
             t: np.ndarray) -> Pointing:
    """Attitude needed to point at targets at times t.

    ``lat_deg``/``lon_deg``/``t`` broadcast together (e.g. targets (M, 1) against
    times (1, T), or one time per target).
    """
    lat_deg, lon_deg, t = np.broadcast_arrays(np.asarray(lat_deg, float), np.asarray(lon_deg, float),
                                              np.asarray(t, float))
    r, v = orbit.state(t.reshape(-1))
    r = r.reshape(t.shape + (3,))
    v = v.reshape(t.shape + (3,))
    p = ecef_to_eci(target_ecef(lat_deg, lon_deg), orbit.gmst(t))
    los = p - r
    los /= np.linalg.norm(los, axis=-1, keepdims=True)
    x, y, z = lvlh_basis(r, v)
    bx = np.sum(los * x, axis=-1)
    by = np.sum(los * y, axis=-1)
    bz = np.sum(los * z, axis=-1)
    pitch = np.rad2deg(np.arcsin(np.clip(bx, -1.0, 1.0)))
    roll = np.rad2deg(np.arctan2(-by, bz))
    up = p / R_EARTH
    sun_el = np.rad2deg(np.arcsin(np.clip(np.sum(up * sun, axis=-1), -1.0, 1.0)))
    return Pointing(roll, pitch, sun_el, bz)


def rotation_angle_deg(droll_deg: np.ndarray, dpitch_deg: np.ndarray) -> np.ndarray:
    """Angle of the rotation taking attitude (r1, p1) to (r2, p2), from the differences.

    With R = Rx(roll) Ry(pitch), trace(R1^T R2) = cos dp + cos dr + cos dr cos dp,
    so the angle is arccos((trace - 1) / 2).
    """
    cr = np.cos(np.deg2rad(droll_deg))
    cp = np.cos(np.deg2rad(dpitch_deg))
    c = np.clip((cp + cr + cr * cp - 1.0) * 0.5, -1.0, 1.0)
    return np.rad2deg(np.arccos(c))
