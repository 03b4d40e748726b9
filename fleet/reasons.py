"""Why a schedule misses each task it misses: a stated procedure, checked against the checker.

For every task the schedule does not observe, the first of these that applies is its reason:

1. **sensor mismatch** - no satellite of the fleet carries the task's sensor;
2. **no opportunity** - satellites carry its sensor, but none can observe it inside its window
   within its off-nadir limit (it has no row in the opportunities, :mod:`eosp.fleet.opportunities`);
3. **insertable** - one of its opportunities fits into its satellite's timeline as it is: no
   overlap, the slew and settling from the observation before it (from nadir at the horizon
   start for a first one) and to the one after it fit in the gaps (the checker's model,
   :func:`eosp.fleet.timeline.fits`), and the battery stays above zero with it: value left on
   the table;
4. **energy** - some opportunity fits in time, as in 3, but with every one tried the battery
   would go below zero;
5. **blocked** - no opportunity fits in time as the timeline is; the smallest set of at most
   three observations adjacent to an opportunity (up to three before it and after it, together)
   whose removal makes it fit, in time and in energy, is named.  When no such set exists the
   task is blocked with no small removal that frees it.

Every opportunity of a missed task is tried at its one position in its satellite's timeline
(the timeline is ordered in time, so an opportunity has exactly one place; removals open that
place).  Time tests are vectorised per satellite over all opportunities of missed tasks and all
ten removal patterns (a before, b after, a + b <= 3).  The battery is tested with a bound first:
the charge curve of the satellite as scheduled (:func:`eosp.fleet.battery.levels`) minus the energy the insertion
adds (imaging, and the slews into and out of it), less a margin for the charge sampled at new cut
points, must stay above zero from the insertion on (clipping at the capacity only narrows a
deficit); a candidate that fails the bound is simulated exactly (:func:`eosp.fleet.battery.simulate`
on the changed timeline), at most :data:`MAX_EXACT` of them per task, spread over its candidates.
An 'energy' verdict therefore means: every candidate tried exactly depletes the battery.

The schedule must be valid (:func:`eosp.fleet.check.validate`); tests confirm each verdict with
the checker on the changed schedule.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eosp.fleet.battery import SunCache, levels, simulate
from eosp.fleet.geometry import Geometry
from eosp.fleet.model import US, Fleet, Schedule, iso_z
from eosp.fleet.opportunities import Opportunities
from eosp.fleet.slew import LineOfSight
from eosp.fleet.timeline import Arrays, Candidates, Timeline, fits, intervals, timelines

KINDS = ("sensor mismatch", "no opportunity", "insertable", "energy", "blocked", "blocked, no small removal")
SENSOR, NO_OPP, INSERTABLE, ENERGY, BLOCKED, BLOCKED_NONE = range(len(KINDS))
MAX_REMOVED = 3
MAX_EXACT = 6  # exact battery simulations per task and verdict, spread over its candidates
PATTERNS = [(a, r - a) for r in range(MAX_REMOVED + 1) for a in range(r, -1, -1)]  # (before, after), fewest first


@dataclass(frozen=True, eq=False)
class Reasons:
    """One row per missed task (rows of fleet.tasks, in task order).

    `satellite`, `start_s`: the opportunity a verdict of kind insertable / energy / blocked is about
    (-1 / NaN otherwise); `blockers`: task rows whose observations on that satellite would be
    removed (-1 padded to three); `candidates`: opportunities of the task."""

    task: np.ndarray
    kind: np.ndarray  # int8, index into KINDS
    satellite: np.ndarray
    start_s: np.ndarray
    blockers: np.ndarray  # (n, 3) int64
    candidates: np.ndarray

    def __len__(self) -> int:
        return len(self.task)

    def counts(self) -> dict[str, int]:
        return {k: int((self.kind == i).sum()) for i, k in enumerate(KINDS)}


def describe(fleet: Fleet, r: Reasons, i: int) -> str:
    """The reason of row `i` in words (what a planner reads)."""
    k, t = int(r.kind[i]), int(r.task[i])
    tk, sats = fleet.tasks, fleet.satellites
    where = ""
    if r.satellite[i] >= 0:
        where = f"{sats.ids[r.satellite[i]]} at {iso_z(fleet.horizon.utc(int(round(r.start_s[i] * US))))}"
    if k == SENSOR:
        return f"sensor mismatch: no satellite carries its sensor ({tk.sensor[t]})"
    if k == NO_OPP:
        return (f"no opportunity: no {tk.sensor[t]} satellite sees it within its window and off-nadir limit")
    if k == INSERTABLE:
        return f"insertable as it is ({where}): value left on the table (weight {tk.weight[t]:g})"
    if k == ENERGY:
        return f"energy: fits in time ({where}) but the battery would go below zero"
    if k == BLOCKED:
        names = ", ".join(str(tk.ids[b]) for b in r.blockers[i] if b >= 0)
        together = " together" if (r.blockers[i] >= 0).sum() > 1 else ""
        return f"blocked ({where}): removing {names}{together} would free it"
    return (f"blocked: no removal of up to {MAX_REMOVED} neighbouring observations frees any of its "
            f"{int(r.candidates[i])} opportunities")


def schedule_timelines(fleet: Fleet, schedule: Schedule, los: LineOfSight) -> list[Timeline]:
    """The schedule as one time-ordered :class:`~eosp.fleet.timeline.Timeline` per satellite (ids must be the
    fleet's)."""
    si, ti = fleet.satellite_index(), fleet.task_index()
    sat = np.asarray([si[s] for s in schedule.satellite.tolist()], dtype=np.int64)
    task = np.asarray([ti[t] for t in schedule.task.tolist()], dtype=np.int64)
    return timelines(fleet, los, sat, task, schedule.start_us / US, schedule.end_us / US)


class _Sat:
    """One satellite's timeline as arrays, with its battery curve's suffix minimum."""

    def __init__(self, fleet: Fleet, los: LineOfSight, sun: SunCache, tl: Timeline, k: int):
        self.tl = tl
        self.arrays = Arrays.of(tl)
        self.S, self.E, self.L0, self.L1 = self.arrays
        self.T = np.asarray(tl.task, dtype=np.int64)
        ends, lv = levels(fleet, sun, k, *intervals(los, tl, k))
        self.ends = ends
        self.suffix_min = np.minimum.accumulate(lv[::-1])[::-1]


def _extra_wh(fleet: Fleet, los: LineOfSight, k: int, s: _Sat, cand: Candidates, pos, a, b):
    """An upper bound on the energy an insertion adds (Wh): imaging, the slew in and the slew out (the
    slews it replaces and the observations it removes are not credited), plus the charge that sampling the
    sunlight at moved cut points may shift (one resource step of charging per cut point added or removed);
    and the slew time into it (s)."""
    st, en, l0, l1 = cand
    bt = fleet.satellites.battery
    n = len(s.S)
    p, q = pos - a - 1, pos + b
    pi, qi = np.clip(p, 0, max(n - 1, 0)), np.clip(q, 0, max(n - 1, 0))
    frm = np.where((p >= 0)[:, None], s.L1[pi], los.nadir(k, st)) if n else los.nadir(k, st)
    need_in = los.need_s(k, frm, l0)
    need_out = np.where(q < n, los.need_s(k, l1, s.L0[qi]), 0.0) if n else np.zeros(len(st))
    e = bt.imaging_w[k] * (en - st) + bt.slew_w[k] * (need_in + need_out)
    moved = 5.0 + 3.0 * (a + b)
    shift = moved * bt.sunlit_w[k] * fleet.horizon.resource_step_s
    return (e + shift) / 3600.0, need_in


def _exact_ok(fleet: Fleet, los: LineOfSight, sun: SunCache, k: int, s: _Sat, row: tuple, pos: int, a: int,
              b: int) -> bool:
    """The changed timeline (a before and b after `pos` removed, `row` inserted) simulated exactly."""
    tl = s.tl
    cols = (tl.start, tl.end, tl.task, tl.los0, tl.los1)
    keep = list(range(0, pos - a)) + list(range(pos + b, len(tl.start)))
    new = Timeline(*([c[j] for j in keep] for c in cols))
    new.insert(pos - a, row)
    return simulate(fleet, sun, k, *intervals(los, new, k)).ok


def explain(fleet: Fleet, opps: Opportunities, schedule: Schedule, geo: Geometry | None = None,
            los: LineOfSight | None = None, sun: SunCache | None = None) -> Reasons:
    """A reason for every task `schedule` (valid, of this fleet) misses; see the module docstring."""
    geo = geo or Geometry(fleet)
    los = los or LineOfSight(fleet, geo)
    sun = sun or SunCache(geo)
    tk, n_sat = fleet.tasks, len(fleet.satellites)
    step = fleet.horizon.action_step_s
    ti = fleet.task_index()
    served = np.zeros(len(tk), dtype=bool)
    served[[ti[t] for t in schedule.task.tolist()]] = True
    missed = np.flatnonzero(~served)
    n = len(missed)
    row_of = np.full(len(tk), -1, dtype=np.int64)
    row_of[missed] = np.arange(n)
    kind = np.full(n, BLOCKED_NONE, dtype=np.int8)
    sat_out = np.full(n, -1, dtype=np.int64)
    start_out = np.full(n, np.nan)
    blockers = np.full((n, MAX_REMOVED), -1, dtype=np.int64)
    per_task = opps.per_task(len(tk))
    carried = np.isin(tk.sensor, np.unique(fleet.satellites.sensor))
    kind[~carried[missed]] = SENSOR
    kind[carried[missed] & (per_task[missed] == 0)] = NO_OPP
    open_ = (kind == BLOCKED_NONE)
    if not open_.any():
        return Reasons(missed, kind, sat_out, start_out, blockers, per_task[missed])

    # every opportunity of a still-open missed task, with its fewest removals (99: none up to three)
    rows = np.flatnonzero(open_[np.maximum(row_of[opps.task], 0)] & (row_of[opps.task] >= 0))
    tls = schedule_timelines(fleet, schedule, los)
    sats: dict[int, _Sat] = {}
    cand = {"row": [], "sat": [], "st": [], "en": [], "l0": [], "l1": [], "pos": [], "a": [], "b": [], "fast": []}
    for k in range(n_sat):
        r = rows[opps.satellite[rows] == k]
        if len(r) == 0:
            continue
        s = sats[k] = _Sat(fleet, los, sun, tls[k], k)
        t = opps.task[r].astype(np.int64)
        st = opps.start[r].astype(np.float64) * step
        en = st + tk.duration_s[t]
        l0, l1 = los.los(k, t, st), los.los(k, t, en)
        pos = np.searchsorted(s.S, st)
        best_a = np.full(len(r), -1)
        best_b = np.full(len(r), -1)
        for a, b in PATTERNS:
            todo = best_a < 0
            if not todo.any():
                break
            ok = np.zeros(len(r), dtype=bool)
            ok[todo] = fits(los, k, s.arrays, Candidates(st[todo], en[todo], l0[todo], l1[todo]), pos[todo], a, b)
            best_a[ok], best_b[ok] = a, b
        has = best_a >= 0
        if not has.any():
            continue
        r, t, st, en, l0, l1, pos, a, b = (x[has] for x in (r, t, st, en, l0, l1, pos, best_a, best_b))
        # the battery bound: the curve's minimum from the slew into it on, less the added energy
        extra, need_in = _extra_wh(fleet, los, k, s, Candidates(st, en, l0, l1), pos, a, b)
        if len(s.ends):
            at = np.minimum(np.searchsorted(s.ends, np.floor((st - need_in - 1.0) * US)), len(s.ends) - 1)
            fast = s.suffix_min[at] - extra > 1.0e-9
        else:
            fast = np.zeros(len(r), dtype=bool)
        for key, v in (("row", r), ("st", st), ("en", en), ("l0", l0), ("l1", l1), ("pos", pos), ("a", a),
                       ("b", b), ("fast", fast)):
            cand[key].append(v)
        cand["sat"].append(np.full(len(r), k))
    if cand["row"]:
        c = {k: np.concatenate(v) for k, v in cand.items()}
        c["task"] = opps.task[c["row"]].astype(np.int64)
        c["removed"] = c["a"] + c["b"]
        # per task: fewest removals first, then those the bound clears, then time
        order = np.lexsort((c["st"], ~c["fast"], c["removed"], c["task"]))
        bounds = np.flatnonzero(np.r_[True, np.diff(c["task"][order]) != 0, True])
        for lo, hi in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
            grp = order[lo:hi]
            t = int(c["task"][grp[0]])
            i = int(row_of[t])
            fewest = int(c["removed"][grp[0]])
            grp = grp[c["removed"][grp] == fewest]
            chosen = -1
            if c["fast"][grp[0]]:
                chosen = int(grp[0])
            else:
                pick = grp[np.unique(np.linspace(0, len(grp) - 1, min(MAX_EXACT, len(grp))).round().astype(int))]
                for j in pick.tolist():
                    k = int(c["sat"][j])
                    row = (float(c["st"][j]), float(c["en"][j]), t, c["l0"][j], c["l1"][j])
                    if _exact_ok(fleet, los, sun, k, sats[k], row, int(c["pos"][j]), int(c["a"][j]),
                                 int(c["b"][j])):
                        chosen = j
                        break
            if fewest == 0:
                kind[i] = INSERTABLE if chosen >= 0 else ENERGY
                j = chosen if chosen >= 0 else int(grp[0])
            elif chosen >= 0:
                kind[i], j = BLOCKED, chosen
                k, p, a, b = int(c["sat"][j]), int(c["pos"][j]), int(c["a"][j]), int(c["b"][j])
                names = sats[k].T[p - a:p + b]
                blockers[i, :len(names)] = names
            else:
                continue
            sat_out[i], start_out[i] = int(c["sat"][j]), float(c["st"][j])
    return Reasons(missed, kind, sat_out, start_out, blockers, per_task[missed])
