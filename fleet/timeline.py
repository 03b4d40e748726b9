"""Satellite timelines: what fits where, and the battery repair, shared by the fleet greedy, the fleet solver's
coordinator and the reasons a task is missed.

A :class:`Timeline` is one satellite's observations in time order, with their lines of sight at start and end.
:func:`fits` says which candidate observations fit at their place in a timeline (no overlap; the slew plus
settling from the observation before them, from nadir at the horizon start for a first one, and to the one after
them fit in the gaps: the checker's model, :mod:`eosp.fleet.slew`), optionally once a few neighbours are removed.
:func:`repair_battery` simulates each timeline with the checker's battery model (:mod:`eosp.fleet.battery`) and,
while it runs dry, drops the least valuable observation started before the failure.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from eosp.budget import UNLIMITED, Budget
from eosp.fleet.battery import Intervals, SunCache, simulate
from eosp.fleet.check import timedelta_us
from eosp.fleet.model import US, Fleet, Schedule, strings
from eosp.fleet.slew import MARGIN_S, LineOfSight


@dataclass
class Timeline:
    """One satellite's observations in time order, with their lines of sight at start and end."""

    start: list = field(default_factory=list)
    end: list = field(default_factory=list)
    task: list = field(default_factory=list)
    los0: list = field(default_factory=list)
    los1: list = field(default_factory=list)

    def insert(self, pos: int, row: tuple) -> None:
        for col, v in zip((self.start, self.end, self.task, self.los0, self.los1), row):
            col.insert(pos, v)

    def remove(self, pos: int) -> None:
        for col in (self.start, self.end, self.task, self.los0, self.los1):
            del col[pos]


class Arrays(NamedTuple):
    """A timeline as arrays: starts and ends (s), lines of sight at start and end ([n, 3])."""

    start: np.ndarray
    end: np.ndarray
    los0: np.ndarray
    los1: np.ndarray

    @classmethod
    def of(cls, tl: Timeline) -> Arrays:
        return cls(np.asarray(tl.start, dtype=np.float64), np.asarray(tl.end, dtype=np.float64),
                   np.asarray(tl.los0, dtype=np.float64).reshape(-1, 3),
                   np.asarray(tl.los1, dtype=np.float64).reshape(-1, 3))


class Candidates(NamedTuple):
    """Candidate observations of one satellite: starts and ends (s), lines of sight at start and end."""

    start: np.ndarray
    end: np.ndarray
    los0: np.ndarray
    los1: np.ndarray


def fits(los: LineOfSight, sat: int, tl: Arrays, cand: Candidates, pos: np.ndarray, a: int = 0,
         b: int = 0) -> np.ndarray:
    """Which candidates fit at their positions `pos` of satellite `sat`'s timeline `tl` once the `a` observations
    before and the `b` after each position are removed (see the module docstring)."""
    st, en, l0, l1 = cand
    n = len(tl.start)
    p, q = pos - a - 1, pos + b
    ok = (pos - a >= 0) & (q <= n)
    has_p, has_n = p >= 0, q < n
    if n:
        pi, qi = np.clip(p, 0, n - 1), np.clip(q, 0, n - 1)
        pe, ns = tl.end[pi], tl.start[qi]
        frm = np.where(has_p[:, None], tl.los1[pi], los.nadir(sat, st))
        gap = np.where(has_p, st - pe, st)
        ok &= ~has_p | (pe <= st)
        ok &= los.need_s(sat, frm, l0) + MARGIN_S <= gap
        ok &= ~has_n | ((en <= ns) & (los.need_s(sat, l1, tl.los0[qi]) + MARGIN_S <= ns - en))
    else:
        ok &= los.need_s(sat, los.nadir(sat, st), l0) + MARGIN_S <= st
    return ok


def timelines(fleet: Fleet, los: LineOfSight, sat: np.ndarray, task: np.ndarray, start: np.ndarray,
              end: np.ndarray) -> list[Timeline]:
    """One timeline per satellite of the observations (satellite and task rows, start and end in seconds), each
    in time order (start, then end)."""
    tls = []
    for k in range(len(fleet.satellites)):
        m = np.flatnonzero(sat == k)
        m = m[np.lexsort((end[m], start[m]))]
        tls.append(timeline(los, k, task[m], start[m], end[m]))
    return tls


def timeline(los: LineOfSight, sat: int, task: np.ndarray, start: np.ndarray, end: np.ndarray) -> Timeline:
    """Satellite `sat`'s timeline of observations given in time order (task rows, start and end in seconds)."""
    if len(task) == 0:
        return Timeline()
    l0, l1 = los.los(sat, task, start), los.los(sat, task, end)
    return Timeline(start.tolist(), end.tolist(), task.tolist(), list(l0), list(l1))


def recheck_slews(los: LineOfSight, tl: Timeline, sat: int) -> None:
    """Drop observations whose slew no longer fits after a removal (first one kept)."""
    k = 0
    while k < len(tl.start):
        frm = tl.los1[k - 1] if k else los.nadir(sat, tl.start[k])
        gap = tl.start[k] - (tl.end[k - 1] if k else 0.0)
        if float(los.need_s(sat, np.asarray(frm), np.asarray(tl.los0[k]))) + MARGIN_S > gap:
            tl.remove(k)
            continue
        k += 1


def intervals(los: LineOfSight, tl: Timeline, sat: int) -> tuple[Intervals, Intervals]:
    """The observations and the maneuver windows before them (µs), as the battery simulation takes them."""
    st = np.round(np.asarray(tl.start, dtype=np.float64) * US).astype(np.int64)
    en = np.round(np.asarray(tl.end, dtype=np.float64) * US).astype(np.int64)
    w0 = np.zeros(len(st), dtype=np.int64)
    if len(st):
        to = np.asarray(tl.los0, dtype=np.float64).reshape(-1, 3)
        frm = np.empty_like(to)
        frm[0] = los.nadir(sat, tl.start[0])
        frm[1:] = np.asarray(tl.los1[:-1], dtype=np.float64).reshape(-1, 3)
        need = los.need_s(sat, frm, to)  # the angles of all the maneuvers at once
        w0 = st - np.array([timedelta_us(s) for s in need.tolist()], dtype=np.int64)
    return Intervals(st, en), Intervals(w0, st.copy())


def repair_battery(fleet: Fleet, los: LineOfSight, tls: list[Timeline] | dict[int, Timeline], sats=None,
                   sun: SunCache | None = None, budget: Budget = UNLIMITED, kept_until: dict | None = None
                   ) -> int | None:
    """Drop the least valuable observations until every battery stays above zero; returns drops, or None when
    `budget` ran out first (the timelines are then half repaired).

    `sats`: only these satellites' timelines (default: all); `sun`: a cache of sunlight kept between calls;
    `kept_until`: satellite -> seconds up to which its observations are kept as they are (a plan already uploaded,
    the passes a solve froze): an observation starting then or before is dropped only when none after it comes
    before the battery runs dry."""
    sun = sun or SunCache(los.geo)
    w, dur = fleet.tasks.weight, fleet.tasks.duration_s
    dropped = 0
    for sat in range(len(tls)) if sats is None else sats:
        tl = tls[sat]
        while True:
            if budget.expired():
                return None
            run = simulate(fleet, sun, sat, *intervals(los, tl, sat))
            if run.ok or not tl.start:
                break
            before = [k for k in range(len(tl.start)) if tl.start[k] * US <= run.fail_us] or list(range(len(tl.start)))
            guard = (kept_until or {}).get(sat)
            if guard is not None:
                before = [k for k in before if tl.start[k] > guard] or before
            k = min(before, key=lambda k: (w[tl.task[k]], w[tl.task[k]] / dur[tl.task[k]], -tl.start[k]))
            tl.remove(k)
            dropped += 1
            recheck_slews(los, tl, sat)
    return dropped


class Rows(NamedTuple):
    """Observations of some satellites as flat rows, each satellite's in time order: ``sats[i]``'s are the rows
    ``offsets[i]:offsets[i + 1]`` of task rows `task`, starts and ends (s).  What a battery repair sends to
    the worker that owns the satellites: a few arrays, not a list of timelines."""

    sats: np.ndarray
    offsets: np.ndarray
    task: np.ndarray
    start: np.ndarray
    end: np.ndarray
    kept_until: np.ndarray | None = None  # per satellite of `sats`: see repair_battery (None: nothing kept)

    @classmethod
    def of(cls, tls: list[Timeline]) -> Rows:
        """The satellites of `tls` (one timeline per satellite) that have an observation."""
        sats = np.array([k for k, tl in enumerate(tls) if tl.task], dtype=np.int64)
        cols = [np.concatenate([np.asarray(getattr(tls[k], c)) for k in sats.tolist()]) if len(sats) else
                np.zeros(0, dt) for c, dt in (("task", np.int64), ("start", np.float64), ("end", np.float64))]
        return cls(sats, np.r_[0, np.cumsum([len(tls[k].task) for k in sats.tolist()])].astype(np.int64), *cols)

    def take(self, idx: np.ndarray) -> np.ndarray:
        """The positions of the rows of the satellites ``sats[idx]``, in that order."""
        lo, hi = self.offsets[idx], self.offsets[idx + 1]
        first = np.r_[0, np.cumsum(hi - lo)[:-1]].astype(np.int64)  # where each satellite's rows go
        return np.repeat(lo - first, hi - lo) + np.arange(int((hi - lo).sum()), dtype=np.int64)

    def part(self, idx: np.ndarray) -> Rows:
        """The satellites ``sats[idx]`` alone."""
        lo, hi = self.offsets[idx], self.offsets[idx + 1]
        take = self.take(idx)
        return Rows(self.sats[idx], np.r_[0, np.cumsum(hi - lo)].astype(np.int64), self.task[take],
                    self.start[take], self.end[take], None if self.kept_until is None else self.kept_until[idx])


def repair_rows(fleet: Fleet, los: LineOfSight, rows: Rows, sun: SunCache,
                budget: Budget = UNLIMITED) -> np.ndarray | None:
    """:func:`repair_battery` of the satellites of `rows`: whether each row is kept (one bool per row), or None
    when the budget ran out first.  Each satellite's repair reads its own rows only, so the result is the same
    wherever it runs and however the satellites are split."""
    tls = {int(k): timeline(los, int(k), rows.task[a:b], rows.start[a:b], rows.end[a:b])
           for k, a, b in zip(rows.sats.tolist(), rows.offsets[:-1].tolist(), rows.offsets[1:].tolist())}
    kept = None if rows.kept_until is None else {int(k): float(t) for k, t in zip(rows.sats, rows.kept_until)
                                                 if np.isfinite(t)}
    if repair_battery(fleet, los, tls, sats=list(tls), sun=sun, budget=budget, kept_until=kept) is None:
        return None
    kept = np.ones(len(rows.task), dtype=bool)
    for i, k in enumerate(rows.sats.tolist()):
        a, b = int(rows.offsets[i]), int(rows.offsets[i + 1])
        left = list(zip(tls[k].task, tls[k].start))  # what is left: a subsequence of the satellite's rows
        if len(left) < b - a:
            j = 0
            for r in range(a, b):
                kept[r] = j < len(left) and left[j] == (rows.task[r], rows.start[r])
                j += bool(kept[r])
    return kept


def to_schedule(fleet: Fleet, tls: list[Timeline]) -> Schedule:
    sat, k_of, task, st, en = [], [], [], [], []
    for k, tl in enumerate(tls):
        sat += [fleet.satellites.ids[k]] * len(tl.start)
        k_of += [k] * len(tl.start)
        task += [fleet.tasks.ids[t] for t in tl.task]
        st += tl.start
        en += tl.end
    st_us = np.round(np.asarray(st, dtype=np.float64) * US).astype(np.int64)
    order = np.lexsort((np.asarray(k_of, dtype=np.int64), st_us))
    return Schedule(strings(sat)[order], strings(task)[order], st_us[order],
                    np.round(np.asarray(en, dtype=np.float64) * US).astype(np.int64)[order])
