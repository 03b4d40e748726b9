"""What a satellite decides on its own: at a primary found cloudy, which of the candidates sent with its plan to
take (docs/operations.md, "The onboard rule", "The rule that looks ahead", "The onboard policy").

A decision (:class:`Decision`) is made by the satellite with what it knows: its last upload (the plan of that
planning call, every satellite's, as the ground made it, and the forecasts the ground had then), the outcomes of
its own acquisitions (its detector saw them) and the candidates it can fly (each tested against what it really
flew: :func:`fly_test`).  A chooser (:data:`Chooser`) maps a decision to the index of a candidate, or -1 for none.

The choosers here are classical: :func:`first` (the rule: the first candidate it can fly, in the order sent,
which is the planner's value) and :class:`ScoreRule` (a score per candidate from :func:`features`, the weights
tuned on training scenarios).  The learned one is :mod:`eosp.models.onboard`; all read the same features.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

CANDIDATES = 3  # the most candidates a plan sends per primary for a chooser (the rule's replacements: one)
FEATURES = ("value", "p", "weight", "corr", "distance", "dt", "later", "remaining", "p_primary", "cloudy_recent",
            "contact_h", "rank")
RECENT = 5  # the satellite's own acquisitions whose outcomes `cloudy_recent` averages


@dataclass(frozen=True, eq=False)
class Decision:
    """A satellite's choice at a primary found cloudy: `sat`, `primary` (an opportunity row), `cands` (rows it can
    fly instead, or after it without looking ahead, in the order sent), `call` (the planning call of its last
    upload; -1: none yet), `later_p` per candidate (the chance, by that call's forecasts, that another primary of
    that call's plan serves the candidate's task later), `recent` (the outcomes its own last acquisitions met:
    True clear), `contact_s` (seconds from the primary's start to the satellite's next ground contact; inf: none
    left)."""

    sat: int
    primary: int
    cands: np.ndarray
    call: int
    later_p: np.ndarray
    recent: np.ndarray
    contact_s: float = float("inf")


Chooser = Callable[[Decision], int]


def first(d: Decision) -> int:  # noqa: ARG001 - the rule reads no feature
    """The rule: the first candidate the satellite can fly, in the order sent."""
    return 0


@dataclass(frozen=True)
class Onboard:
    """What a satellite decides on its own: `test(k, rows)` says whether satellite k can fly a timeline of
    opportunity rows (its battery, and with `ahead` its slews); `ahead` False: the target is found cloudy as it
    is acquired (Phi-Sat-1's detection, flown) and a candidate sent for it is taken after it; True: a detector
    looking ahead sees the next target cloudy before the satellite slews to it (proposed, not flown), the primary
    is skipped and a candidate taken in its place; `choose`: which candidate (None: the first it can fly, tested
    in the order sent, as the rule does; otherwise every candidate is tested and the chooser sees those it can
    fly)."""

    test: Callable[[int, np.ndarray], bool]
    ahead: bool = False
    choose: Chooser | None = None


@dataclass(frozen=True, eq=False)
class Context:
    """What the features read of the day besides a decision: per task its weight and surface point (km), per
    opportunity its start, the forecasts (opportunities, calls) of the realization, the cloud model's length
    and time."""

    weight: np.ndarray
    xyz_km: np.ndarray
    task: np.ndarray
    start_s: np.ndarray
    forecast: np.ndarray
    length_km: float
    tau_s: float
    order: np.ndarray = field(default=None)  # opportunity rows by (task, start)
    ptr: np.ndarray = field(default=None)  # per task: its slice of `order`

    def __post_init__(self) -> None:
        if self.order is None:
            order = np.lexsort((self.start_s, self.task))
            object.__setattr__(self, "order", order)
            object.__setattr__(self, "ptr", np.searchsorted(self.task[order], np.arange(len(self.weight) + 1)))

    def remaining(self, rows: np.ndarray, call: int) -> np.ndarray:
        """Per row: the chance, by the forecasts of `call`, that one of its task's opportunities after it (any
        satellite's) would succeed."""
        out = np.zeros(len(rows))
        for i, r in enumerate(rows.tolist()):
            t = self.task[r]
            mine = self.order[self.ptr[t]:self.ptr[t + 1]]
            after = mine[self.start_s[mine] > self.start_s[r]]
            out[i] = 1.0 - float(np.prod(1.0 - self.forecast[after, call]))
        return out


def features(ctx: Context, d: Decision, slots: int = CANDIDATES) -> tuple[np.ndarray, np.ndarray]:
    """Per candidate slot the features of :data:`FEATURES` (float32 (slots, len(FEATURES)); 0 in empty slots) and
    the mask of the slots filled.  `value`: weight times the forecast of the satellite's last upload, divided by
    the day's largest weight; `corr`: the latent cloud field's correlation between the candidate and the primary
    found cloudy (exp(-distance / L - |dt| / tau), the scenario's model), with `distance` / L and `dt` / tau;
    `later`: :attr:`Decision.later_p`; `remaining`: :meth:`Context.remaining` (the request's later
    opportunities across the fleet, its window); `p_primary`: the forecast the primary was sent with;
    `cloudy_recent`: the share of the satellite's last acquisitions found cloudy; `contact_h`: hours to its next
    contact (capped at 24); `rank`: the order sent over `slots`."""
    out = np.zeros((slots, len(FEATURES)), dtype=np.float32)
    c = d.cands[:slots]
    n = len(c)
    mask = np.zeros(slots, dtype=bool)
    mask[:n] = True
    if n == 0:
        return out, mask
    call = max(d.call, 0)
    p = ctx.forecast[c, call]
    w = ctx.weight[ctx.task[c]]
    wmax = float(ctx.weight.max()) or 1.0
    dist = np.linalg.norm(ctx.xyz_km[ctx.task[c]] - ctx.xyz_km[ctx.task[d.primary]], axis=1) / ctx.length_km
    dt = np.abs(ctx.start_s[c] - ctx.start_s[d.primary]) / ctx.tau_s
    recent = 1.0 - float(np.mean(d.recent)) if len(d.recent) else 0.5
    contact = min(d.contact_s / 3600.0, 24.0)
    out[:n] = np.stack([w * p / wmax, p, w / wmax, np.exp(-dist - dt), dist, dt, d.later_p[:slots],
                        ctx.remaining(c, call), np.full(n, ctx.forecast[d.primary, call]), np.full(n, recent),
                        np.full(n, contact), np.arange(n) / slots], axis=1)
    return out, mask


@dataclass(frozen=True)
class ScoreRule:
    """A classical chooser: per candidate ``value * (1 - gamma * later) * (1 - beta * corr)``, the highest taken
    when above 0.  beta discounts a candidate whose clouds are correlated with the primary's just seen (beta = 1:
    a candidate at the same point and time is worth nothing); gamma one that another primary will likely serve
    anyway.  beta = gamma = 0 is the rule (:func:`first`, when the candidates are sent by value)."""

    ctx: Context
    beta: float = 0.0
    gamma: float = 0.0

    def __call__(self, d: Decision) -> int:
        x, mask = features(self.ctx, d)
        f = {name: x[:, i] for i, name in enumerate(FEATURES)}
        score = f["value"] * (1.0 - self.gamma * f["later"]) * (1.0 - self.beta * f["corr"])
        score = np.where(mask, score, -math.inf)
        i = int(np.argmax(score))
        return i if score[i] > 0 else -1


def fly_test(fleet, opps, los, sun, slews: bool = False) -> Callable[[int, np.ndarray], bool]:
    """The onboard test (:class:`Onboard`): whether satellite k can fly a timeline of opportunity rows of the
    fleet's `opps`: its battery holds (the checker's battery model, :mod:`eosp.fleet.battery`, with the fleet's
    `sun`) and, with `slews`, no two overlap and every slew plus settling fits before its observation (the
    checker's rules, :mod:`eosp.fleet.slew`, by `los`; the rule after acquisition needs no such test: its
    alternates fit by construction)."""
    from eosp.fleet.battery import simulate as battery
    from eosp.fleet.slew import MARGIN_S
    from eosp.fleet.timeline import intervals, timeline

    start = opps.start.astype(np.float64) * float(fleet.horizon.action_step_s)
    end = start + fleet.tasks.duration_s[opps.task]

    def holds(k: int, rows: np.ndarray) -> bool:
        rows = rows[np.lexsort((end[rows], start[rows]))]
        tl = timeline(los, k, opps.task[rows].astype(np.int64), start[rows], end[rows])
        if slews and len(rows):
            st, en = start[rows], end[rows]
            to = np.asarray(tl.los0, dtype=np.float64).reshape(-1, 3)
            frm = np.empty_like(to)
            frm[0] = los.nadir(k, st[0])
            frm[1:] = np.asarray(tl.los1[:-1], dtype=np.float64).reshape(-1, 3)
            gap = st - np.r_[0.0, en[:-1]]
            if (gap < 0).any() or (los.need_s(k, frm, to) + MARGIN_S > gap).any():
                return False
        return battery(fleet, sun, k, *intervals(los, tl, k)).ok

    return holds
