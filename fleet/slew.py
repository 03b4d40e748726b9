"""Slew times between observations, vectorised on the base grid, with the checker's model.

The slew angle between two observations is the angle between the inertial (GCRF) lines of
sight at the end of the first and the start of the second; before the first observation the
satellite points at geocentric nadir.  Lines of sight are ``R(t) @ (r_target - r_sat(t))`` with
the satellite and the rotation taken on the base grid, which every action bound falls on.
Numbers agree with the checker's brahe path to far below its 1e-9 s tolerance; solvers keep a
small margin (:data:`MARGIN_S`) on top.
"""

from __future__ import annotations

import numpy as np

from eosp.fleet.geometry import Geometry, angle_deg, slew_time_s
from eosp.fleet.model import Fleet

MARGIN_S = 1.0e-6


class LineOfSight:
    """GCRF lines of sight and nadir directions of a fleet's satellites at base-grid instants."""

    def __init__(self, fleet: Fleet, geo: Geometry):
        self.fleet, self.geo = fleet, geo
        self.rot = geo.grid_rotations()
        self.base = geo.base_step_s

    def _idx(self, t_s) -> np.ndarray:
        return np.round(np.asarray(t_s, dtype=np.float64) / self.base).astype(np.int64)

    def los(self, sat: int, task, t_s) -> np.ndarray:
        i = self._idx(t_s)
        rel = self.geo.target_ecef[np.asarray(task)] - self.geo.grid_positions(sat)[i]
        return np.einsum("...ij,...j->...i", self.rot[i], rel)

    def nadir(self, sat: int, t_s) -> np.ndarray:
        i = self._idx(t_s)
        return -np.einsum("...ij,...j->...i", self.rot[i], self.geo.grid_positions(sat)[i])

    def need_s(self, sat: int, frm: np.ndarray, to: np.ndarray) -> np.ndarray:
        """Slew plus settling time (s) from pointing `frm` to pointing `to`."""
        att = self.fleet.satellites.attitude
        return slew_time_s(angle_deg(frm, to), att.max_rate_deg_s[sat], att.max_acc_deg_s2[sat]) + att.settling_s[sat]

    def between(self, sat: int, task_a, end_a_s, task_b, start_b_s) -> np.ndarray:
        """Slew plus settling time from observing `task_a` (ending at `end_a_s`) to `task_b` (starting
        at `start_b_s`): the arc cost between two opportunities of one pass."""
        return self.need_s(sat, self.los(sat, task_a, end_a_s), self.los(sat, task_b, start_b_s))
