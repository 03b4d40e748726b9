"""The operations simulator: a planner run through one realization of a scenario, event by event, and scored.

What happens, in time order (docs/operations.md):

* planning calls at the horizon's start and on the scenario's cadence; each gives the planner what the ground
  knows then (:class:`Knowledge`) and the time its plan reaches each satellite: the first ground contact at or
  after the call's time plus the planner's compute budget (``time_limit``; never, when no contact is left);
* a plan governs its satellite from its upload on; everything before the upload is what the satellite was sent
  already (or has done), and a plan may not change it (a planner that does is a defect: refused);
* the satellite executes its timeline as sent; an acquisition succeeds when the realized clouds at its target
  and start allow it (:mod:`eosp.ops.world`), and its outcome reaches the ground at the satellite's next contact
  after its end (downlink latency); a request whose acquisition failed stays open for later opportunities;
* a request is known from its arrival; it is served by its first acquisition that succeeds.

A plan is a set of opportunities (rows of the day's :class:`eosp.fleet.opportunities.Opportunities`: a task, a
satellite, a start), so what is executed is always an acquisition the fleet's geometry allows; every executed
timeline, failed acquisitions included, is checked by the fleet's checker (:func:`eosp.fleet.check.validate`), and
an invalid one is reported as a defect of the planner, never scored.

The bound printed with each realization is the clairvoyant conflict-free bound: the weight of the requests that
have at least one opportunity where the realized clouds let an acquisition succeed.  It bounds every planner,
because a request is served only by a successful acquisition and every acquisition a planner can make is an
opportunity (after the request's arrival: its window opens then).  The fleet kind adds a tighter one, the fleet
solver's on the realized day (:func:`eosp.kinds.fleet.operations.clairvoyant_values`).

Planners live above this module (the fleet solver's are in :mod:`eosp.kinds.fleet.operations`); they are
objects with ``plan(knowledge) -> Plan | None`` (None: no new plan) and a ``name``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from eosp.ops.world import World


@dataclass(frozen=True, eq=False)
class Knowledge:
    """What the ground knows at a planning call, and what its plan may change.

    `rows`: the day's timelines as sent and as executed so far (opportunity rows, sorted); `outcome` per row: 1
    succeeded, 0 failed (reported at a contact before `t`), -1 not known (not executed, or not reported yet);
    `planned_p` per row: the success probability of the forecast the row was planned under (the latest call at or
    before its start, never a later one than this); `upload_s` per satellite: when a plan made now reaches it
    (inf: never); `arrived` per task; `forecast` per opportunity: the success probability issued now."""

    t: float
    call: int
    rows: np.ndarray
    outcome: np.ndarray
    planned_p: np.ndarray
    upload_s: np.ndarray
    arrived: np.ndarray
    forecast: np.ndarray

    def served(self, task_of_row: np.ndarray, n_tasks: int) -> np.ndarray:
        """Bool per task: an acquisition of it succeeded and was reported."""
        out = np.zeros(n_tasks, dtype=bool)
        out[task_of_row[self.rows[self.outcome == 1]]] = True
        return out


@dataclass
class Plan:
    """A planner's answer: the opportunity rows of every satellite's timeline (those before each satellite's
    upload as the knowledge had them), the compute it used (seconds) and what it wants reported."""

    rows: np.ndarray
    compute_s: float
    info: dict = field(default_factory=dict)


class Planner(Protocol):
    name: str

    def plan(self, know: Knowledge) -> Plan | None: ...


@dataclass
class Day:
    """What a simulation reads of a scenario, in arrays: per opportunity its task, satellite, start and end
    (seconds), per task its weight and whether it is urgent, the contacts per satellite, the horizon."""

    task: np.ndarray
    sat: np.ndarray
    start_s: np.ndarray
    end_s: np.ndarray
    weight: np.ndarray
    urgent: np.ndarray
    contact_start: list[np.ndarray]
    contact_end: list[np.ndarray]
    horizon_s: float

    @classmethod
    def of(cls, scen) -> Day:
        f, o = scen.fleet, scen.opps
        step = f.horizon.action_step_s
        start = o.start.astype(np.float64) * step
        end = start + f.tasks.duration_s[o.task]
        cs, ce = zip(*(scen.contacts.of(k) for k in range(len(f.satellites)))) if len(f.satellites) else ((), ())
        return cls(o.task.astype(np.int64), o.satellite.astype(np.int64), start, end,
                   np.asarray(f.tasks.weight, dtype=np.float64), np.asarray(scen.urgent, bool), list(cs), list(ce),
                   float(f.horizon.seconds))

    def next_contact(self, sat: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Per (satellite, time): the first instant at or after it in contact (inf: none left)."""
        out = np.full(len(sat), math.inf)
        for k in np.unique(sat).tolist():
            mine = sat == k
            st, en = self.contact_start[k], self.contact_end[k]
            i = np.searchsorted(en, t[mine], side="left")  # the first contact not over at t
            ok = i < len(en)
            got = np.full(int(mine.sum()), math.inf)
            got[ok] = np.maximum(st[i[ok]], t[mine][ok])
            out[mine] = got
        return out


def knowledge(day: Day, world: World, rows: np.ndarray, call: int, upload_s: np.ndarray) -> Knowledge:
    """What the ground knows at planning call `call` (:class:`Knowledge`), the timelines being `rows`."""
    t = float(world.calls_s[call])
    report = day.next_contact(day.sat[rows], day.end_s[rows])
    known = (day.start_s[rows] < t) & (report <= t)
    outcome = np.where(known, world.clear[rows].astype(np.int64), -1)
    # the forecast each row was planned under: the latest call at or before its start, this one at the latest
    at = np.minimum(np.searchsorted(world.calls_s, day.start_s[rows], side="right") - 1, call)
    planned = world.forecast[rows, np.maximum(at, 0)]
    return Knowledge(t, call, rows, outcome, planned, upload_s, world.arrival_s <= t, world.forecast[:, call])


@dataclass
class Run:
    """One realization simulated: the executed timelines (opportunity rows), each call's record, and the
    figures (:func:`figures`)."""

    rows: np.ndarray
    calls: list[dict]
    figures: dict
    plans: list[tuple[int, np.ndarray]] = field(default_factory=list)  # (call, the rows it answered), in order


def simulate(day: Day, world: World, planner: Planner, time_limit: float, check=None) -> Run:
    """Run `planner` through `world` (see the module docstring).  `time_limit`: the compute budget of a call (its
    plan is uploaded at the first contact after the call's time plus this); `check`: a function of the executed
    rows returning (valid, first violation or None), e.g. the fleet checker's."""
    n_sat = len(day.contact_start)
    rows = np.zeros(0, np.int64)
    calls, plans = [], []
    for call, t in enumerate(world.calls_s.tolist()):
        upload = day.next_contact(np.arange(n_sat), np.full(n_sat, t + time_limit))
        know = knowledge(day, world, rows, call, upload)
        wall = time.perf_counter()
        plan = planner.plan(know)
        wall = time.perf_counter() - wall
        if plan is None:
            continue
        plans.append((call, np.asarray(plan.rows, dtype=np.int64)))
        rows, churn = _upload(day, rows, plans[-1][1], upload)
        calls.append({"t_s": t, "compute_s": round(plan.compute_s, 3), "wall_s": round(wall, 3), "churn": churn,
                      "uploads": int(np.isfinite(upload).sum()), **plan.info})
    return Run(rows, calls, figures(day, world, rows, calls, check), plans)


def _upload(day: Day, rows: np.ndarray, new: np.ndarray, upload: np.ndarray) -> tuple[np.ndarray, int]:
    """The timelines after a plan's uploads: each satellite's rows before its upload as they were, the plan's
    from it on; and the churn (rows that changed among those the plan could change).  A plan that changes a row
    before an upload is refused (a ValueError: a planner's defect)."""
    old_fixed = day.start_s[rows] < upload[day.sat[rows]]
    new_fixed = day.start_s[new] < upload[day.sat[new]]
    if not np.array_equal(np.sort(rows[old_fixed]), np.sort(new[new_fixed])):
        raise ValueError("the plan changes what its satellites were sent before its upload")
    churn = len(np.setxor1d(rows[~old_fixed], new[~new_fixed]))
    return np.sort(np.concatenate([rows[old_fixed], new[~new_fixed]])), churn


def clairvoyant_bound(day: Day, world: World) -> float:
    """The weight of the requests with an opportunity where an acquisition succeeds (see the module docstring)."""
    ok = np.zeros(len(day.weight), dtype=bool)
    ok[day.task[world.clear & (day.start_s >= world.arrival_s[day.task])]] = True
    return float(day.weight[ok].sum())


def figures(day: Day, world: World, rows: np.ndarray, calls: list[dict], check=None) -> dict:
    """A realization's figures: served weight as fractions of all, of the catalogue's and of the urgent requests'
    weight; the clairvoyant bound and the regret (bound - served, of all); acquisitions made and failed; the
    weight of requests attempted and never served (cloud losses); mean hours from an urgent request's arrival to
    its first successful acquisition's end; churn and compute over the calls; the checker's verdict."""
    task, ok = day.task[rows], world.clear[rows]
    served = np.zeros(len(day.weight), dtype=bool)
    served[task[ok]] = True
    first_end = np.full(len(day.weight), math.inf)
    np.minimum.at(first_end, task[ok], day.end_s[rows][ok])
    attempted = np.zeros(len(day.weight), dtype=bool)
    attempted[task] = True
    w = day.weight
    W, Wc, Wu = w.sum(), w[~day.urgent].sum(), w[day.urgent].sum()
    late = served & day.urgent
    valid, violation = check(rows) if check is not None else (None, None)
    bound = clairvoyant_bound(day, world)
    return {"realization": world.index,
            "served": float(w[served].sum() / W) if W > 0 else 0.0,
            "served_catalogue": float(w[served & ~day.urgent].sum() / Wc) if Wc > 0 else 0.0,
            "served_urgent": float(w[served & day.urgent].sum() / Wu) if Wu > 0 else None,
            "bound": bound / W if W > 0 else 0.0,
            "regret": float((bound - w[served].sum()) / W) if W > 0 else 0.0,
            "acquisitions": int(len(rows)), "failed": int((~ok).sum()),
            "cloud_lost": float(w[attempted & ~served].sum() / W) if W > 0 else 0.0,
            "urgent_latency_h": (float(np.mean((first_end[late] - world.arrival_s[late]) / 3600.0))
                                 if late.any() else None),
            "churn": int(sum(c["churn"] for c in calls)),
            "compute_s": [c["compute_s"] for c in calls],
            "valid": valid, "violation": violation}
