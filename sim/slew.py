"""Slew-time models: how long the satellite needs to rotate by an angle.

Both models are functions of the total rotation angle between two attitudes
(:func:`eosp.sim.geometry.rotation_angle_deg`).  They are packed into a flat
float64 array so that the numba graph builder can evaluate them in its hot loop:

* ``piecewise``: ``[0, k, a_0..a_{k-1}, t_0..t_{k-1}]``, linear interpolation of
  time over angle breakpoints (extrapolated with the last slope).
* ``bang_coast_bang``: ``[1, rate, accel, settle]``: accelerate at ``accel`` up
  to ``rate``, coast, decelerate, then settle.  A short slew never reaches the
  maximum rate: ``2 sqrt(angle / accel)``.  The formula is written once
  (:func:`bang_coast_bang`): the fleets' pass graphs and checker use it too.
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


SMALL_DEG = 1.0e-9  # a rotation this small costs no slew, only settling (the aeossp benchmark's tolerance)


def _bang_coast_bang(angle_deg: float, rate: float, accel: float) -> float:
    """Rest-to-rest slew time (s, settling excluded) of a rotation by `angle_deg` at most `rate` deg/s and `accel`
    deg/s^2: accelerate, coast, decelerate; a short slew never reaches the rate (2 sqrt(angle / accel)); a rotation
    of at most :data:`SMALL_DEG` costs nothing, any other one forever without a positive rate and acceleration.
    The aeossp benchmark's model, its float operations in its order: the one formula of the single pass, the
    fleet's pass graphs and the fleet checker, compiled as a scalar kernel (:data:`bang_coast_bang`) and as a
    ufunc over arrays (:data:`bang_coast_bang_array`, broadcasting)."""
    if angle_deg <= SMALL_DEG:
        return 0.0
    if rate <= 0.0 or accel <= 0.0:
        return np.inf
    if angle_deg <= rate * rate / accel:
        return 2.0 * np.sqrt(angle_deg / accel)
    return 2.0 * (rate / accel) + (angle_deg - rate * rate / accel) / rate


bang_coast_bang = numba.njit(cache=True, fastmath=False)(_bang_coast_bang)
bang_coast_bang_array = numba.vectorize(["float64(float64, float64, float64)"], cache=True)(_bang_coast_bang)


@numba.njit(cache=True, fastmath=False)
def slew_time(angle_deg: float, model: np.ndarray) -> float:
    """Slew plus settling time of a rotation by `angle_deg` under a packed model (:func:`pack_slew_model`)."""
    if model[0] == PIECEWISE:
        k = int(model[1])
        a = model[2:2 + k]
        t = model[2 + k:2 + 2 * k]
        for s in range(1, k):
            if angle_deg <= a[s]:
                return t[s - 1] + (t[s] - t[s - 1]) * (angle_deg - a[s - 1]) / (a[s] - a[s - 1])
        return t[k - 1] + (t[k - 1] - t[k - 2]) * (angle_deg - a[k - 1]) / (a[k - 1] - a[k - 2])
    return bang_coast_bang(angle_deg, model[1], model[2]) + model[3]


@numba.njit(cache=True, fastmath=False)
def slew_times(angles_deg: np.ndarray, model: np.ndarray) -> np.ndarray:
    """:func:`slew_time` of every angle of an array."""
    out = np.empty(angles_deg.shape[0])
    for i in range(angles_deg.shape[0]):
        out[i] = slew_time(angles_deg[i], model)
    return out
