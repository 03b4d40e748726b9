"""What the verifier's battery implies for every valid schedule: energy inequalities over windows of passes.

The verifier (:mod:`eosp.fleet.battery`) cuts the horizon at every resource-grid instant and every action bound,
takes the load (idle, plus imaging while an observation runs, plus slew power while a maneuver window runs) and
the charging (sunlit at the segment's midpoint) on each segment, clips the charge at the capacity after every
segment and rejects a schedule whose charge falls below -1e-9 Wh.  For a satellite and any two resource-grid
instants A < B (always cut points, whatever the schedule), the segments between them partition [A, B], and:

* the charge at B is at least -1e-9 Wh (clipping at the capacity keeps a value above it above it), and at most
  the charge at A plus everything charged minus everything spent in between (clipping only lowers it);
* the charge at A is the initial charge when A = 0, else at most ``min(capacity, initial + charge(0, A) -
  idle * A)`` (it was clipped at least once; and clipping and spending only lower the unclipped sum);
* charge(A, B) is at most the charging power times the sunlit time, over-estimated on the geometry base grid: a
  base step counts as sunlit unless it is dark at both ends, farther than :data:`SunCache.SAFE_M` from the shadow
  boundary (so the satellite cannot cross it in between; the checker's own sunlight cache rests on the same fact);
* what is spent is at least idle * (B - A), plus for every observation o whose interval [start - settling, end]
  lies in [A, B] its imaging energy ``imaging_w * duration`` (observation bounds are cut points, so its segments
  are exactly its duration) and ``slew_w * settling`` for the last `settling` seconds of its maneuver window
  (every accepted observation has one, ``[start - (slew + settling), start]``, rounded to the microsecond; the
  slew gap rule keeps these stretches of different observations apart, so none is counted twice).

Hence, for every valid schedule, ``sum of e_o over such observations <= R(A, B)`` with the observation's least
energy above idle ``e_o = (imaging_w * duration + slew_w * (settling - 1e-5 s)) / 3600`` (:func:`observation_wh`;
the 1e-5 s covers the microsecond rounding and the verifier's 1e-9 s tolerance) and
``R(A, B) = charge at A (bound above) + charge(A, B) - idle * (B - A) + 1e-6`` (Wh; the 1e-6 covers the float
sums).  A window here is a run of consecutive passes i..j of one satellite, with A the resource-grid instant at
or before the first opportunity start of pass i minus the settling time and B the one at or after the last
opportunity end of pass j: every observation of those passes lies in it, with its settling stretch.  (A window
from the horizon start adds nothing: the window of the same passes with A at pass i is at least as tight.)
Observations of other passes only add energy, so leaving them out keeps the inequality valid, and so does
leaving out any window (:func:`energy_windows` keeps those that some choice of observations could break).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from eosp.fleet.battery import SunCache
from eosp.fleet.model import Fleet

SETTLE_SLACK_S = 1e-5  # seconds of settling not counted (microsecond rounding, the verifier's 1e-9 s tolerance)
RHS_SLACK_WH = 1e-6  # Wh added to every right-hand side (the verifier's -1e-9 Wh, float sums)


def observation_wh(fleet: Fleet, sat: int, tasks: np.ndarray) -> np.ndarray:
    """The least energy (Wh) above idle that an observation of each task takes on satellite `sat`: its imaging
    and the last settling seconds of its maneuver window (see the module docstring)."""
    b, att = fleet.satellites.battery, fleet.satellites.attitude
    settle = max(0.0, float(att.settling_s[sat]) - SETTLE_SLACK_S)
    dur = fleet.tasks.duration_s[np.asarray(tasks, dtype=np.int64)].astype(np.float64)
    return (float(b.imaging_w[sat]) * dur + float(b.slew_w[sat]) * settle) / 3600.0


def sunlit_seconds(sun: SunCache, sat: int) -> tuple[np.ndarray, float]:
    """(S, step): ``S[g]`` over-estimates the sunlit seconds of satellite `sat` from the horizon start to base-grid
    instant g (a base step counts unless it is surely dark, see the module docstring)."""
    lit, margin = sun.grid(sat)
    far = margin > SunCache.SAFE_M
    dark = ~lit[:-1] & ~lit[1:] & far[:-1] & far[1:]
    step = float(sun.geo.base_step_s)
    return np.r_[0.0, np.cumsum(np.where(dark, 0.0, step))], step


def _at(S: np.ndarray, step: float, t: np.ndarray, up: bool) -> np.ndarray:
    """S at instants t (s), t moved to the base grid outwards (down for a window's start, up for its end), and
    past the grid's last instant every second counted."""
    g = np.ceil(t / step - 1e-9) if up else np.floor(t / step + 1e-9)
    g = g.astype(np.int64)
    last = len(S) - 1
    inside = S[np.clip(g, 0, last)]
    return np.where(g > last, S[last] + (t - last * step), inside)


@dataclass(frozen=True, eq=False)
class EnergyWindows:
    """Windows of consecutive passes of one satellite and what the battery allows in each (see the module
    docstring): ``sum over their passes of the e_o of their observations <= rhs_wh``.  Passes are global pass
    ids, consecutive within a satellite (:class:`eosp.fleet.opportunities.Opportunities`); `scale_wh` is a typical
    observation's energy on the window's satellite, the unit in which its multiplier is kept."""

    lo: np.ndarray  # int64 [windows]: first pass
    hi: np.ndarray  # int64 [windows]: last pass
    rhs_wh: np.ndarray  # float64 [windows]
    scale_wh: np.ndarray  # float64 [windows]
    n_passes: int

    def __len__(self) -> int:
        return len(self.lo)

    @classmethod
    def none(cls, n_passes: int) -> EnergyWindows:
        z = np.zeros(0, np.int64)
        return cls(z, z, np.zeros(0), np.zeros(0), n_passes)

    def used(self, pass_wh: np.ndarray) -> np.ndarray:
        """Energy each window's passes spend, given each pass's (float64 [passes])."""
        c = np.r_[0.0, np.cumsum(pass_wh)]
        return c[self.hi + 1] - c[self.lo]

    def pass_price(self, mu: np.ndarray) -> np.ndarray:
        """Each pass's price of a Wh: the sum, over the windows holding it, of their multipliers (per `scale_wh`)."""
        per = mu / self.scale_wh if len(mu) else mu
        d = np.bincount(self.lo, per, self.n_passes + 1) - np.bincount(self.hi + 1, per, self.n_passes + 1)
        return np.cumsum(d)[:self.n_passes]


def energy_windows(fleet: Fleet, sun: SunCache, pass_sat: np.ndarray, pass_time: np.ndarray,
                   pass_max_wh: np.ndarray) -> EnergyWindows:
    """Every window of consecutive passes of one satellite whose passes could spend more than it allows (the
    others never bind): `pass_sat` the satellite of each pass, `pass_time` its (first start, last end) in
    seconds, `pass_max_wh` an upper bound of what its observations can spend (it only decides which windows are
    kept)."""
    h, b, att = fleet.horizon, fleet.satellites.battery, fleet.satellites.attitude
    res, horizon = float(h.resource_step_s), float(h.seconds)
    lo_all, hi_all, rhs_all, scale_all = [], [], [], []
    n = len(pass_sat)
    first = np.flatnonzero(np.r_[True, pass_sat[1:] != pass_sat[:-1]]) if n else np.zeros(0, np.int64)
    for s0, s1 in zip(first.tolist(), np.r_[first[1:], n].astype(np.int64).tolist()):
        k = int(pass_sat[s0])
        ids = np.arange(s0, s1)
        A = np.maximum(0.0, np.floor((pass_time[ids, 0] - float(att.settling_s[k])) / res + 1e-9) * res)
        B = np.minimum(horizon, np.ceil(pass_time[ids, 1] / res - 1e-9) * res)
        S, step = sunlit_seconds(sun, k)
        sa, sb = _at(S, step, A, up=False), _at(S, step, B, up=True)
        sun_w, idle = float(b.sunlit_w[k]), float(b.idle_w[k])
        cap = np.minimum(float(b.capacity_wh[k]), float(b.initial_wh[k]) + (sun_w * sa - idle * A) / 3600.0)
        cap = np.where(A <= 0.0, float(b.initial_wh[k]), cap)
        rhs = cap[:, None] + (sun_w * (sb[None, :] - sa[:, None]) - idle * (B[None, :] - A[:, None])) / 3600.0
        rhs = rhs + RHS_SLACK_WH
        c = np.r_[0.0, np.cumsum(pass_max_wh[ids])]
        most = c[None, 1:] - c[:-1, None]  # [i, j]: what passes i..j could spend at most
        i, j = np.nonzero(np.triu(most > rhs))
        lo_all.append(ids[i])
        hi_all.append(ids[j])
        rhs_all.append(rhs[i, j])
        typical = float(observation_wh(fleet, k, np.arange(len(fleet.tasks))).mean()) if len(fleet.tasks) else 1.0
        scale_all.append(np.full(len(i), typical if typical > 0 and math.isfinite(typical) else 1.0))
    if not lo_all:
        return EnergyWindows.none(n)
    return EnergyWindows(np.concatenate(lo_all).astype(np.int64), np.concatenate(hi_all).astype(np.int64),
                         np.concatenate(rhs_all), np.concatenate(scale_all), n)
