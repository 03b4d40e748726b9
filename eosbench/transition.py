"""EOS-Bench's attitude transition time, in its two readings.

*Documented* (their paper and ``schedulers/transition_utils.py``): the attitude change from the last sample of one
observation to the first sample of the next, dg = |d roll| + |d pitch| + |d yaw| in degrees, gives

    t(dg) = 11.66 s              when dg <= 10
            a_i + dg / v_i       for dg in (10, 30], (30, 60], (60, 90], above 90, a = (5, 10, 16, 22) s,

with the agility profile's rates v (deg/s; "Standard-Agility" (1.5, 2, 2.5, 3), their scheduler's default).  A
non-agile satellite needs a fixed time (their ``non_agile_transition_s``, 10 s).  Missing attitudes fall back to
11.66 s, as their code does.

*Code* (what their checker applies): the attitude slices their candidate generator stores are keyed
``pitch_angles``/``yaw_angles``/``roll_angles``, which their ``delta_g_between`` does not read, so every agile
transition takes the 11.66 s fallback whatever the angles; and their ``ConstraintModel`` never stores its agility
profile or non-agile time, so a non-agile satellite's second assignment raises AttributeError there.  This reading
therefore has no rule for non-agile satellites (:func:`refuses_non_agile`).

The two differ in one direction only: 11.66 s is the documented function's minimum (10 + 10/1.5 > 11.66 on the
first slope and every later piece is longer), so a schedule valid under the documented reading is valid under the
code reading, and a bound under the code reading bounds both.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

C_SMALL = 11.66  # s, dg <= 10 deg
SMALL_DG = 10.0
BREAKS = np.array([30.0, 60.0, 90.0])
OFFSETS = np.array([5.0, 10.0, 16.0, 22.0])
PROFILES = {
    "High-Agility": (3.00, 4.00, 5.00, 6.00),
    "Standard-Agility": (1.50, 2.00, 2.50, 3.00),
    "Low-Agility": (0.75, 1.00, 1.25, 1.50),
    "Limited-Agility": (0.50, 0.67, 0.83, 1.00),
}
READINGS = ("documented", "code")


@dataclass(frozen=True)
class Rules:
    """How a schedule is judged: the transition reading, the agility profile and non-agile time of the
    documented one, and their downlink duration ratio (a downlink lasts ratio x the observation's duration)."""

    transition: str = "documented"
    agility: str = "Standard-Agility"
    non_agile_s: float = 10.0
    downlink_ratio: float = 1.0

    def __post_init__(self) -> None:
        if self.transition not in READINGS:
            raise ValueError(f"transition must be one of {', '.join(READINGS)}, not {self.transition!r}")
        if self.agility not in PROFILES:
            raise ValueError(f"agility must be one of {', '.join(PROFILES)}, not {self.agility!r}")


def documented_s(dg: np.ndarray, agility: str = "Standard-Agility") -> np.ndarray:
    """The documented transition time (s) for attitude changes `dg` (deg)."""
    dg = np.asarray(dg, dtype=np.float64)
    v = np.asarray(PROFILES[agility])
    piece = np.searchsorted(BREAKS, dg, side="left")  # (10, 30] -> 0, (30, 60] -> 1, ...
    out = OFFSETS[piece] + dg / v[piece]
    return np.where(dg <= SMALL_DG, C_SMALL, out)


def delta_g(last: np.ndarray, first: np.ndarray) -> np.ndarray:
    """dg between attitudes (pitch, yaw, roll rows): the sum of the absolute angle changes, in their order of
    summation (roll, pitch, yaw)."""
    d = np.abs(np.asarray(first) - np.asarray(last))
    return (d[..., 2] + d[..., 0]) + d[..., 1]


def transition_s(rules: Rules, agile: bool, last: np.ndarray, first: np.ndarray) -> np.ndarray:
    """Transition times (s) from attitudes `last` to attitudes `first` (rows of pitch, yaw, roll; NaN rows where
    an observation carries no agile attitude) on a satellite, under `rules`."""
    last, first = np.atleast_2d(last), np.atleast_2d(first)
    n = max(len(last), len(first))
    if not agile:
        if rules.transition == "code":
            raise ValueError("the code reading has no transition rule for a non-agile satellite")
        return np.full(n, float(rules.non_agile_s))
    if rules.transition == "code":
        return np.full(n, C_SMALL)
    missing = np.isnan(last).any(axis=-1) | np.isnan(first).any(axis=-1)
    dg = np.where(missing, 0.0, delta_g(np.nan_to_num(last), np.nan_to_num(first)))
    return np.where(missing, C_SMALL, documented_s(dg, rules.agility))


def to_us(seconds: np.ndarray) -> np.ndarray:
    """Seconds as their checker adds them to a datetime (``timedelta(seconds=x)``: microseconds, half to even)."""
    return np.rint(np.asarray(seconds, dtype=np.float64) * 1e6).astype(np.int64)


def max_transition_s(rules: Rules, max_dg: float) -> float:
    """The longest transition under `rules` for attitude changes up to `max_dg` degrees."""
    if rules.transition == "code":
        return C_SMALL
    grid = np.r_[np.linspace(0.0, max(max_dg, 0.0), 64), BREAKS[BREAKS <= max_dg], max(max_dg, 0.0)]
    return float(max(documented_s(grid, rules.agility).max(), rules.non_agile_s, C_SMALL))
