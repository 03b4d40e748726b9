"""Slew-time models: how long the satellite needs to rotate by an angle.

Both models are functions of the total rotation angle between two attitudes
(:func:`eosp.sim.geometry.rotation_angle_deg`).  They are packed into a flat
float64 array so that the numba graph builder can evaluate them in its hot loop:

* ``piecewise``: ``[0, k, a_0..a_{k-1}, t_0..t_{k-1}]``, linear interpolation of
  time over angle breakpoints (extrapolated with the last slope).
* ``bang_coast_bang``: ``[1, rate, accel, settle]``: accelerate at ``accel`` up
  to ``rate``, coast, decelerate, then settle.  A short slew never reaches the
  maximum rate: ``2 sqrt(angle / accel)``.
"""

from __future__ import annotations

import numba
import numpy as np

from eosp.config import SatelliteConfig

PIECEWISE, BANG_COAST_BANG = 0, 1


def pack_slew_model(sat: SatelliteConfig) -> np.ndarray:
    if sat.slew_model == "piecewise":
        a = np.asarray(sat.piecewise_angles_deg, dtype=np.float64)
        t = np.asarray(sat.piecewise_times_s, dtype=np.float64)
        if a.size < 2 or a.size != t.size or np.any(np.diff(a) <= 0) or np.any(np.diff(t) < 0) or a[0] != 0:
            raise ValueError("piecewise slew model needs increasing angles from 0 and non-decreasing times "
                             "of the same length")
        return np.concatenate([[PIECEWISE, a.size], a, t])
    if sat.slew_model == "bang_coast_bang":
        if min(sat.max_rate_deg_s, sat.max_accel_deg_s2) <= 0 or sat.settle_s < 0:
            raise ValueError("bang_coast_bang slew model needs positive rate and acceleration")
        return np.array([BANG_COAST_BANG, sat.max_rate_deg_s, sat.max_accel_deg_s2, sat.settle_s])
    raise ValueError(f"unknown slew model {sat.slew_model!r} (piecewise, bang_coast_bang)")


@numba.njit(cache=True, fastmath=False)
def slew_time(angle_deg: float, model: np.ndarray) -> float:
    if model[0] == PIECEWISE:
        k = int(model[1])
        a = model[2:2 + k]
        t = model[2 + k:2 + 2 * k]
        for s in range(1, k):
            if angle_deg <= a[s]:
                return t[s - 1] + (t[s] - t[s - 1]) * (angle_deg - a[s - 1]) / (a[s] - a[s - 1])
        return t[k - 1] + (t[k - 1] - t[k - 2]) * (angle_deg - a[k - 1]) / (a[k - 1] - a[k - 2])
    rate, accel, settle = model[1], model[2], model[3]
    if angle_deg <= rate * rate / accel:
        return 2.0 * np.sqrt(angle_deg / accel) + settle
    return angle_deg / rate + rate / accel + settle


def slew_times(angles_deg: np.ndarray, model: np.ndarray) -> np.ndarray:
    """Vectorized slew time (plain numpy, independent of the numba kernel; used by checks)."""
    angles_deg = np.asarray(angles_deg, dtype=np.float64)
    if model[0] == PIECEWISE:
        k = int(model[1])
        a, t = model[2:2 + k], model[2 + k:2 + 2 * k]
        out = np.interp(angles_deg, a, t)
        beyond = angles_deg > a[-1]
        out[beyond] = t[-1] + (t[-1] - t[-2]) * (angles_deg[beyond] - a[-1]) / (a[-1] - a[-2])
        return out
    rate, accel, settle = model[1], model[2], model[3]
    return np.where(angles_deg <= rate * rate / accel, 2.0 * np.sqrt(angles_deg / accel),
                    angles_deg / rate + rate / accel) + settle
