"""A greedy baseline for fleets: each task once, by weight, inserted where it still fits.

Tasks are taken by decreasing weight (then weight per second of observation, then earliest
due time).  A task goes to the opportunity that ends earliest among those that fit in their
satellite's timeline (:func:`eosp.fleet.timeline.fits`: no overlap, and slew plus settling time to
and from the neighbouring observations, from nadir at the horizon start for the first one).
Candidates of one (task, satellite) are tested together as arrays.

The battery is not planned ahead: each satellite's timeline is then repaired
(:func:`eosp.fleet.timeline.repair_battery`: while it runs dry, the least valuable observation
started before the failure is dropped, and the timeline re-checked for slews).  A final run of the checker
guards the result: an action it rejects is dropped and the schedule checked again.

:func:`fill` is the same insertion started from a given schedule (the tasks it serves kept where they are): the
post-processing of the learned fleet solvers, named ``fill`` in their options.
"""

from __future__ import annotations

import numpy as np

from eosp.fleet.check import validate
from eosp.fleet.geometry import Geometry
from eosp.fleet.model import Fleet, Schedule
from eosp.fleet.opportunities import Opportunities
from eosp.fleet.slew import LineOfSight
from eosp.fleet.timeline import Arrays, Candidates, Timeline, fits, repair_battery, to_schedule


def task_order(fleet: Fleet) -> np.ndarray:
    tk = fleet.tasks
    return np.lexsort((tk.due_s, -(tk.weight / tk.duration_s), -tk.weight))


def insert_greedily(fleet: Fleet, opps: Opportunities, los: LineOfSight,
                    tls: list[Timeline] | None = None) -> list[Timeline]:
    """Timelines built by inserting tasks in :func:`task_order` at their earliest-ending fit; `tls`: the timelines to
    insert into (the tasks they hold are not inserted again), empty ones when None."""
    step = fleet.horizon.action_step_s
    dur = fleet.tasks.duration_s
    tls = tls if tls is not None else [Timeline() for _ in range(len(fleet.satellites))]
    held = np.zeros(len(fleet.tasks), dtype=bool)
    held[[t for tl in tls for t in tl.task]] = True
    by_task = np.argsort(opps.task, kind="stable")
    bounds = np.searchsorted(opps.task[by_task], np.arange(len(fleet.tasks) + 1))
    for t in task_order(fleet).tolist():
        rows = by_task[bounds[t]:bounds[t + 1]]
        if len(rows) == 0 or held[t]:
            continue
        best = None
        for sat in np.unique(opps.satellite[rows]).tolist():
            r = rows[opps.satellite[rows] == sat]
            st = opps.start[r].astype(np.float64) * step
            en = st + dur[t]
            tt = np.full(len(r), t)
            l0, l1 = los.los(sat, tt, st), los.los(sat, tt, en)
            tl = Arrays.of(tls[sat])
            ok = fits(los, sat, tl, Candidates(st, en, l0, l1), np.searchsorted(tl.start, st))
            if not ok.any():
                continue
            j = int(np.flatnonzero(ok)[np.argmin(en[ok])])
            if best is None or en[j] < best[0]:
                best = (en[j], sat, (st[j], en[j], t, l0[j], l1[j]))
        if best is not None:
            _, sat, row = best
            tls[sat].insert(int(np.searchsorted(np.asarray(tls[sat].start), row[0])), row)
    return tls


def solve(fleet: Fleet, opps: Opportunities, geo: Geometry | None = None) -> Schedule:
    """A schedule the checker accepts (see the module docstring)."""
    geo = geo or Geometry(fleet)
    los = LineOfSight(fleet, geo)
    return finish(fleet, geo, los, insert_greedily(fleet, opps, los))


def fill(fleet: Fleet, opps: Opportunities, schedule: Schedule, geo: Geometry | None = None) -> Schedule:
    """`schedule` with the tasks it does not serve inserted where they still fit (:func:`insert_greedily` from its
    timelines), then the battery repaired and the checker's guard (:func:`finish`): the repair may drop
    observations of `schedule` itself, so the caller compares the two."""
    from eosp.fleet.timeline import timelines

    geo = geo or Geometry(fleet)
    los = LineOfSight(fleet, geo)
    si, ti = fleet.satellite_index(), fleet.task_index()
    sat = np.array([si[s] for s in schedule.satellite.tolist()], dtype=np.int64)
    task = np.array([ti[t] for t in schedule.task.tolist()], dtype=np.int64)
    tls = timelines(fleet, los, sat, task, schedule.start_us / 1e6, schedule.end_us / 1e6)
    return finish(fleet, geo, los, insert_greedily(fleet, opps, los, tls))


def finish(fleet: Fleet, geo: Geometry, los: LineOfSight, tls: list[Timeline]) -> Schedule:
    """The timelines with their batteries repaired, as a schedule the checker accepts (an action it rejects is
    dropped, and the schedule checked again)."""
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
