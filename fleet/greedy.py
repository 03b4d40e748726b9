"""A greedy baseline for fleets: each task once, by weight, inserted where it still fits.

Tasks are taken by decreasing weight (then weight per second of observation, then earliest
due time).  A task goes to the opportunity that ends earliest among those that fit in their
satellite's timeline: no overlap, and slew plus settling time (the checker's model, see
:mod:`eosp.fleet.slew`) to and from the neighbouring observations, from nadir at the horizon
start for the first one.  Candidates of one (task, satellite) are tested together as arrays.

The battery is not planned ahead: each satellite's timeline is then simulated with the
checker's battery model and, while it runs dry, the least valuable observation started before
the failure is dropped (and the timeline re-checked for slews).  A final run of the checker
guards the result: an action it rejects is dropped and the schedule checked again.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eosp.fleet.battery import Intervals, SunCache, simulate
from eosp.fleet.check import timedelta_us, validate
from eosp.fleet.geometry import Geometry
from eosp.fleet.model import US, Fleet, Schedule, strings
from eosp.fleet.opportunities import Opportunities
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


def task_order(fleet: Fleet) -> np.ndarray:
    tk = fleet.tasks
    return np.lexsort((tk.due_s, -(tk.weight / tk.duration_s), -tk.weight))


def _feasible(los: LineOfSight, tl: Timeline, sat: int, cand: tuple) -> np.ndarray:
    """Which candidate (start, end, los0, los1) arrays fit into timeline `tl` of satellite `sat`."""
    st, en, l0, l1 = cand
    S = np.asarray(tl.start, dtype=np.float64)
    E = np.asarray(tl.end, dtype=np.float64)
    pos = np.searchsorted(S, st)
    ok = np.ones(len(st), dtype=bool)
    has_p, has_n = pos > 0, pos < len(S)
    if len(S):
        pe = E[np.maximum(pos - 1, 0)]
        ns = S[np.minimum(pos, len(S) - 1)]
        ok &= ~has_p | (pe <= st)
        ok &= ~has_n | (en <= ns)
        P1 = np.asarray(tl.los1).reshape(-1, 3)
        N0 = np.asarray(tl.los0).reshape(-1, 3)
        frm = np.where(has_p[:, None], P1[np.maximum(pos - 1, 0)], los.nadir(sat, st))
        gap = np.where(has_p, st - pe, st)
        ok &= los.need_s(sat, frm, l0) + MARGIN_S <= gap
        need_n = los.need_s(sat, l1, N0[np.minimum(pos, len(S) - 1)])
        ok &= ~has_n | (need_n + MARGIN_S <= ns - en)
    else:
        ok &= los.need_s(sat, los.nadir(sat, st), l0) + MARGIN_S <= st
    return ok


def insert_greedily(fleet: Fleet, opps: Opportunities, los: LineOfSight) -> list[Timeline]:
    """Timelines built by inserting tasks in :func:`task_order` at their earliest-ending fit."""
    step = fleet.horizon.action_step_s
    dur = fleet.tasks.duration_s
    tls = [Timeline() for _ in range(len(fleet.satellites))]
    by_task = np.argsort(opps.task, kind="stable")
    bounds = np.searchsorted(opps.task[by_task], np.arange(len(fleet.tasks) + 1))
    for t in task_order(fleet).tolist():
        rows = by_task[bounds[t]:bounds[t + 1]]
        if len(rows) == 0:
            continue
        best = None
        for sat in np.unique(opps.satellite[rows]).tolist():
            r = rows[opps.satellite[rows] == sat]
            st = opps.start[r].astype(np.float64) * step
            en = st + dur[t]
            tt = np.full(len(r), t)
            l0, l1 = los.los(sat, tt, st), los.los(sat, tt, en)
            ok = _feasible(los, tls[sat], sat, (st, en, l0, l1))
            if not ok.any():
                continue
            j = int(np.flatnonzero(ok)[np.argmin(en[ok])])
            if best is None or en[j] < best[0]:
                best = (en[j], sat, (st[j], en[j], t, l0[j], l1[j]))
        if best is not None:
            _, sat, row = best
            tls[sat].insert(int(np.searchsorted(np.asarray(tls[sat].start), row[0])), row)
    return tls


def _recheck_slews(los: LineOfSight, tl: Timeline, sat: int) -> None:
    """Drop observations whose slew no longer fits after a removal (first one kept)."""
    k = 0
    while k < len(tl.start):
        frm = tl.los1[k - 1] if k else los.nadir(sat, tl.start[k])
        gap = tl.start[k] - (tl.end[k - 1] if k else 0.0)
        if float(los.need_s(sat, np.asarray(frm), np.asarray(tl.los0[k]))) + MARGIN_S > gap:
            tl.remove(k)
            continue
        k += 1


def _intervals(los: LineOfSight, tl: Timeline, sat: int) -> tuple[Intervals, Intervals]:
    st = np.round(np.asarray(tl.start, dtype=np.float64) * US).astype(np.int64)
    en = np.round(np.asarray(tl.end, dtype=np.float64) * US).astype(np.int64)
    w0 = []
    for k in range(len(st)):
        frm = tl.los1[k - 1] if k else los.nadir(sat, tl.start[k])
        need = float(los.need_s(sat, np.asarray(frm), np.asarray(tl.los0[k])))
        w0.append(st[k] - timedelta_us(need))
    return Intervals(st, en), Intervals(np.asarray(w0, dtype=np.int64), st.copy())


def repair_battery(fleet: Fleet, los: LineOfSight, tls: list[Timeline], sats=None, sun: SunCache | None = None) -> int:
    """Drop the least valuable observations until every battery stays above zero; returns drops.

    `sats`: only these satellites' timelines (default: all); `sun`: a cache of sunlight kept between calls."""
    sun = sun or SunCache(los.geo)
    w, dur = fleet.tasks.weight, fleet.tasks.duration_s
    dropped = 0
    for sat in range(len(tls)) if sats is None else sats:
        tl = tls[sat]
        while True:
            run = simulate(fleet, sun, sat, *_intervals(los, tl, sat))
            if run.ok or not tl.start:
                break
            before = [k for k in range(len(tl.start)) if tl.start[k] * US <= run.fail_us] or list(range(len(tl.start)))
            k = min(before, key=lambda k: (w[tl.task[k]], w[tl.task[k]] / dur[tl.task[k]], -tl.start[k]))
            tl.remove(k)
            dropped += 1
            _recheck_slews(los, tl, sat)
    return dropped


def to_schedule(fleet: Fleet, tls: list[Timeline]) -> Schedule:
    sat, task, st, en = [], [], [], []
    for k, tl in enumerate(tls):
        sat += [fleet.satellites.ids[k]] * len(tl.start)
        task += [fleet.tasks.ids[t] for t in tl.task]
        st += tl.start
        en += tl.end
    st_us = np.round(np.asarray(st, dtype=np.float64) * US).astype(np.int64)
    order = np.lexsort((np.asarray([fleet.satellite_index()[s] for s in sat], dtype=np.int64), st_us))
    return Schedule(strings(sat)[order], strings(task)[order], st_us[order],
                    np.round(np.asarray(en, dtype=np.float64) * US).astype(np.int64)[order])


def solve(fleet: Fleet, opps: Opportunities, geo: Geometry | None = None) -> Schedule:
    """A schedule the checker accepts (see the module docstring)."""
    geo = geo or Geometry(fleet)
    los = LineOfSight(fleet, geo)
    tls = insert_greedily(fleet, opps, los)
    repair_battery(fleet, los, tls)
    sched = to_schedule(fleet, tls)
    for _ in range(len(sched) + 1):
        res = validate(fleet, sched, geo)
        if res.valid:
            return sched
        bad = {v.action for v in res.violations if v.action >= 0}
        if not bad:  # a battery failure outside any observation: drop that satellite's first action
            sid = res.violations[0].satellite
            hits = np.flatnonzero(sched.satellite == sid)
            if len(hits) == 0:
                return Schedule.empty()
            bad = {int(hits[0])}
        keep = np.asarray([i for i in range(len(sched)) if i not in bad], dtype=np.int64)
        sched = Schedule(sched.satellite[keep], sched.task[keep], sched.start_us[keep], sched.end_us[keep])
    return Schedule.empty()
