"""The operations simulator: a planner run through one realization of a scenario, event by event, and scored.

What happens, in time order (docs/operations.md):

* planning calls at the horizon's start and on the scenario's cadence; each gives the planner what the ground
  knows then (:class:`Knowledge`) and the time its plan reaches each satellite: the first ground contact at or
  after the call's time plus the planner's compute budget (``time_limit``; never, when no contact is left);
* a plan governs the passes of a satellite that start after its upload there; the passes before are what the
  satellite was sent already (or has done), and a plan may not change them (a planner that does is a defect:
  refused);
* the satellite executes its timeline as sent; an acquisition succeeds when the realized clouds at its target
  and start allow it (:mod:`eosp.ops.world`), and its outcome reaches the ground at the satellite's next contact
  after its end (downlink latency); a request whose acquisition failed stays open for later opportunities; with
  an onboard rule, a primary found cloudy lets the satellite take the alternate sent for it, after it or, when the
  rule looks ahead, in its place (:func:`execute`);
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
from typing import Generator, Protocol

import numpy as np

from eosp.ops.onboard import RECENT, Decision, Onboard
from eosp.ops.stations import Contacts
from eosp.ops.world import World


@dataclass(frozen=True, eq=False)
class Knowledge:
    """What the ground knows at a planning call, and what its plan may change.

    `rows`: the day's timelines as the ground knows them (opportunity rows, sorted): what was sent and what was
    reported done, the alternates sent (`alternate`) unless reported not taken; `outcome` per row: 1 succeeded, 0
    failed (reported at a contact before `t`), -1 not known (not done, or not reported yet); `planned_p` per row:
    the chance it serves its task by the forecasts it was planned under (the latest call at or before its start,
    never a later one than this; an alternate's, that its primary fails and it succeeds); `upload_s` per
    satellite: when a plan made now reaches it (inf: never); `arrived` per task; `forecast` per opportunity: the
    success probability issued now."""

    t: float
    call: int
    rows: np.ndarray
    outcome: np.ndarray
    planned_p: np.ndarray
    upload_s: np.ndarray
    arrived: np.ndarray
    forecast: np.ndarray
    alternate: np.ndarray

    def served(self, task_of_row: np.ndarray, n_tasks: int) -> np.ndarray:
        """Bool per task: an acquisition of it succeeded and was reported."""
        out = np.zeros(n_tasks, dtype=bool)
        out[task_of_row[self.rows[self.outcome == 1]]] = True
        return out


@dataclass
class Plan:
    """A planner's answer: the opportunity rows of every satellite's timeline (those of the passes that start
    before each satellite's upload as the knowledge had them), the compute it used (seconds) and what it wants
    reported; with the onboard rule, `alternates` (rows) each taken only when the primary `alternate_of` (a row
    of `rows`) fails."""

    rows: np.ndarray
    compute_s: float
    info: dict = field(default_factory=dict)
    alternates: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    alternate_of: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


class Planner(Protocol):
    name: str

    def plan(self, know: Knowledge) -> Plan | None: ...


@dataclass
class Day:
    """What a simulation reads of a scenario, in arrays: per opportunity its task, satellite, start and end
    (seconds), per task its weight and whether it is urgent, the contacts, the horizon, the satellites."""

    task: np.ndarray
    sat: np.ndarray
    start_s: np.ndarray
    end_s: np.ndarray
    weight: np.ndarray
    urgent: np.ndarray
    contacts: Contacts
    horizon_s: float
    satellites: int
    pass_id: np.ndarray  # per opportunity: its pass
    pass_start: np.ndarray  # per pass: when it starts (a plan governs the passes that start after its upload)

    @classmethod
    def of(cls, scen, pass_start: np.ndarray | None = None) -> Day:
        """The day of scenario `scen`; `pass_start`: when each pass starts as the planners see it (default: its
        first opportunity's start)."""
        f, o = scen.fleet, scen.opps
        step = f.horizon.action_step_s
        start = o.start.astype(np.float64) * step
        end = start + f.tasks.duration_s[o.task]
        if pass_start is None:
            pass_start = np.full(o.n_passes, np.inf)
            np.minimum.at(pass_start, o.pass_id, start)
        return cls(o.task.astype(np.int64), o.satellite.astype(np.int64), start, end,
                   np.asarray(f.tasks.weight, dtype=np.float64), np.asarray(scen.urgent, bool), scen.contacts,
                   float(f.horizon.seconds), len(f.satellites), o.pass_id.astype(np.int64), np.asarray(pass_start, dtype=np.float64))

    def fixed(self, rows: np.ndarray, upload: np.ndarray) -> np.ndarray:
        """Bool per row: its pass starts before its satellite's upload (what a plan uploaded then cannot change)."""
        return self.pass_start[self.pass_id[rows]] < upload[self.sat[rows]]

    def next_contact(self, sat: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Per (satellite, time): the first instant at or after it in contact (inf: none left)."""
        return self.contacts.next_contacts(sat, t)


@dataclass
class Sent:
    """What the satellites were sent and what they did: primaries and alternates (opportunity rows; each alternate
    with the primary whose failure lets it be taken), the rows done in the order done (primaries, and alternates
    the onboard rule took), and the time up to which what they do is decided."""

    prim: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    alt: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    alt_of: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    done: list[int] = field(default_factory=list)
    taken: set[int] = field(default_factory=set)
    until: float = 0.0
    ahead: bool = False  # the alternates are replacements, taken in their primary's place (Onboard.ahead)
    uploads: list[tuple[int, np.ndarray]] = field(default_factory=list)  # (call, upload time per satellite)
    plans: dict[int, np.ndarray] = field(default_factory=dict)  # per call: its plan's primaries (every satellite)
    flew_candidate: set[int] = field(default_factory=set)  # satellites that took a candidate
    unsure: set[int] = field(default_factory=set)  # of those, the ones whose timeline as sent fails their test
    skipped: set[int] = field(default_factory=set)  # primaries a satellite refused (its slews or battery fail)


def execute(day: Day, world: World, sent: Sent, t: float, onboard: Onboard | None) -> None:
    """The satellites' work up to time `t` (:func:`executing`), each decision answered by ``onboard.choose``."""
    _drive(executing(day, world, sent, t, onboard), onboard)


def executing(day: Day, world: World, sent: Sent, t: float,
              onboard: Onboard | None) -> Generator[Decision, int, None]:
    """The satellites' work up to time `t`: every primary starting before it done; with an onboard rule, a primary
    found cloudy lets the satellite take a candidate sent for it (after the primary, or in its place when the
    rule looks ahead), when its task is not one the satellite has served itself and the satellite can fly it
    (:class:`Onboard`: what it did, the candidate, the primaries it was sent after it).  With a chooser
    (``onboard.choose``) each such choice among the candidates it can fly is yielded (a :class:`Decision`) and
    answered by the index taken (-1: none); without, the first it can fly is taken.  A satellite that looks ahead
    and has taken a candidate refuses a primary it cannot fly after what it flew (slews, battery: a plan uploaded
    before the ground learnt what it took may not hold with it) and reports it as not served; every executed
    timeline is then one the checker accepts.  What was decided is never decided again."""
    s = day.start_s
    new = sent.prim[(s[sent.prim] >= sent.until) & (s[sent.prim] < t)]
    for r in new[np.argsort(s[new], kind="stable")].tolist():
        if onboard is not None and onboard.ahead and day.sat[r] in sent.unsure:
            mine = np.asarray(sent.done, dtype=np.int64)
            if not onboard.test(int(day.sat[r]), np.concatenate([mine[day.sat[mine] == day.sat[r]], [r]])):
                sent.skipped.add(r)  # a plan made before the ground knew what it took: refused onboard
                continue
        if onboard is None or world.clear[r]:
            sent.done.append(r)
            continue
        if not onboard.ahead:
            sent.done.append(r)
        k = day.sat[r]
        mine = np.asarray(sent.done, dtype=np.int64)
        mine = mine[day.sat[mine] == k]
        fly = []
        for a in sent.alt[sent.alt_of == r].tolist():
            if (world.clear[mine] & (day.task[mine] == day.task[a])).any():
                continue  # served already, by this satellite
            later = sent.prim[(day.sat[sent.prim] == k) & (s[sent.prim] > s[a]) & (sent.prim != r)]
            if onboard.test(int(k), np.concatenate([mine, [a], later])):
                fly.append(a)
                if onboard.choose is None:
                    break
        took = -1
        if fly:
            took = 0 if onboard.choose is None else (yield _decision(day, world, sent, r, np.asarray(fly), mine))
        if took >= 0:
            sent.done.append(fly[took])
            sent.taken.add(fly[took])
            sent.flew_candidate.add(int(k))
            sent.unsure.discard(int(k))  # its test held with every primary sent after it
        elif onboard.ahead:
            sent.done.append(r)  # no candidate taken: the primary as sent (found cloudy)
    sent.until = max(sent.until, t)


def _decision(day: Day, world: World, sent: Sent, r: int, cands: np.ndarray, mine: np.ndarray) -> Decision:
    """What satellite ``day.sat[r]`` knows when it finds primary `r` cloudy (:class:`Decision`)."""
    k, s = int(day.sat[r]), day.start_s
    call = -1
    for c, up in sent.uploads:
        if up[k] <= s[r]:
            call = c
    later = np.zeros(len(cands))
    if call >= 0:
        rows = sent.plans[call]
        for i, a in enumerate(cands.tolist()):
            same = rows[(day.task[rows] == day.task[a]) & (s[rows] > s[a])]
            later[i] = 1.0 - float(np.prod(1.0 - world.forecast[same, call]))
    contact = float(day.next_contact(np.array([k]), np.array([s[r]]))[0]) - s[r]
    return Decision(k, int(r), cands, call, later, world.clear[mine[-RECENT:]], contact)


def _drive(gen: Generator, onboard: Onboard | None):
    """Run a generator of decisions to its end, each answered by ``onboard.choose``; its return value."""
    try:
        d = next(gen)
        while True:
            d = gen.send(onboard.choose(d))
    except StopIteration as stop:
        return stop.value


def knowledge(day: Day, world: World, sent: Sent, call: int, upload_s: np.ndarray) -> Knowledge:
    """What the ground knows at planning call `call` (:class:`Knowledge`), after :func:`execute` up to it."""
    t = float(world.calls_s[call])
    s = day.start_s
    alt_report = day.next_contact(day.sat[sent.alt], day.end_s[sent.alt])
    decided = s[sent.alt_of] < sent.until
    taken = np.isin(sent.alt, np.fromiter(sent.taken, np.int64, len(sent.taken)))
    prim = sent.prim
    if sent.ahead:  # the timelines the ground knows: a replacement once reported taken, in its primary's place
        keep = taken & (alt_report <= t)
        prim = prim[~np.isin(prim, sent.alt_of[keep])]
    else:
        keep = ~decided | taken | (alt_report > t)  # an alternate not taken is known only once reported
    rows = np.concatenate([prim, sent.alt[keep]])
    is_alt = np.r_[np.zeros(len(prim), bool), np.ones(int(keep.sum()), bool)]
    order = np.argsort(rows, kind="stable")
    rows, is_alt = rows[order], is_alt[order]
    report = day.next_contact(day.sat[rows], day.end_s[rows])
    known = (s[rows] < t) & (report <= t)
    flown = world.clear[rows] & ~np.isin(rows, np.fromiter(sent.skipped, np.int64, len(sent.skipped)))
    outcome = np.where(known, flown.astype(np.int64), -1)  # a refused primary is reported as not served
    planned = _planned(day, world, rows, call)
    if is_alt.any():  # an alternate serves when its primary fails and it succeeds
        of = dict(zip(sent.alt.tolist(), sent.alt_of.tolist()))
        prim = np.array([of[r] for r in rows[is_alt].tolist()], dtype=np.int64)
        planned[is_alt] *= 1.0 - _planned(day, world, prim, call)
    return Knowledge(t, call, rows, outcome, planned, upload_s, world.arrival_s <= t, world.forecast[:, call],
                     is_alt)


def _planned(day: Day, world: World, rows: np.ndarray, call: int) -> np.ndarray:
    """The forecast each row was planned under: the latest call at or before its start, this one at the latest."""
    at = np.minimum(np.searchsorted(world.calls_s, day.start_s[rows], side="right") - 1, call)
    return world.forecast[rows, np.maximum(at, 0)].copy()


@dataclass
class Run:
    """One realization simulated: the executed timelines (opportunity rows), each call's record, and the
    figures (:func:`figures`)."""

    rows: np.ndarray
    calls: list[dict]
    figures: dict
    plans: list[tuple[int, np.ndarray]] = field(default_factory=list)  # (call, the rows it answered), in order
    uploads: list[tuple[float, np.ndarray]] = field(default_factory=list)  # (call time, upload time per satellite)
    alternates_taken: set[int] = field(default_factory=set)  # the alternates the onboard rule took
    answers: list[tuple[int, Plan]] = field(default_factory=list)  # (call, the planner's answer), in order


def simulate(day: Day, world: World, planner: Planner, time_limit: float, check=None,
             onboard: Onboard | None = None) -> Run:
    """Run `planner` through `world` (see the module docstring).  `time_limit`: the compute budget of a call (its
    plan is uploaded at the first contact after the call's time plus this); `check`: a function of the executed
    rows returning (valid, first violation or None), e.g. the fleet checker's; `onboard`: the onboard rule
    (:class:`Onboard`; None: none, alternates are never taken), its decisions answered by ``onboard.choose``."""
    return _drive(running(day, world, planner, time_limit, check, onboard), onboard)


def running(day: Day, world: World, planner: Planner, time_limit: float, check=None,
            onboard: Onboard | None = None, sent: Sent | None = None) -> Generator[Decision, int, Run]:
    """:func:`simulate` as a generator: each onboard decision yielded and answered by the index of the candidate
    taken (:func:`executing`); returns the :class:`Run`.  `sent`: the satellites' state to run on (a new one by
    default; given, the caller sees what is done as it is done)."""
    n_sat = day.satellites
    sent = sent if sent is not None else Sent(ahead=onboard is not None and onboard.ahead)
    calls, plans, uploads, answers = [], [], [], []
    for call, t in enumerate(world.calls_s.tolist()):
        yield from executing(day, world, sent, t, onboard)
        upload = day.next_contact(np.arange(n_sat), np.full(n_sat, t + time_limit))
        know = knowledge(day, world, sent, call, upload)
        wall = time.perf_counter()
        plan = planner.plan(know)
        wall = time.perf_counter() - wall
        if plan is None:
            continue
        plans.append((call, np.asarray(plan.rows, dtype=np.int64)))
        answers.append((call, plan))
        uploads.append((t, upload))
        sent.uploads.append((call, upload))
        sent.plans[call] = np.asarray(plan.rows, dtype=np.int64)
        churn = _upload(day, sent, know, plan, upload)
        if onboard is not None and onboard.ahead:
            _recheck(day, sent, onboard, upload)
        calls.append({"t_s": t, "compute_s": round(plan.compute_s, 3), "wall_s": round(wall, 3), "churn": churn,
                      "uploads": int(np.isfinite(upload).sum()), "alternates": int(len(plan.alternates)),
                      **plan.info})
    yield from executing(day, world, sent, math.inf, onboard)
    done = np.asarray(sent.done, dtype=np.int64)
    return Run(done, calls, figures(day, world, done, calls, check, len(sent.taken)), plans, uploads, sent.taken,
               answers)


@dataclass
class Replayed:
    """A planner answering each call with the plan recorded for it in another run of the same realization (the
    ground planner not re-run: an onboard chooser's rollouts, issue 76): the recorded primaries and candidates of
    the passes the plan may change, and in the passes it may not, what this run's ground knows (it may differ
    from the recorded run's: other candidates taken)."""

    day: Day
    answers: dict[int, Plan]
    name: str = "replayed"

    def plan(self, know: Knowledge) -> Plan | None:
        got = self.answers.get(know.call)
        if got is None:
            return None
        rows = np.asarray(got.rows, dtype=np.int64)
        rows = np.union1d(rows[~self.day.fixed(rows, know.upload_s)], know.rows[self.day.fixed(know.rows, know.upload_s)])
        return Plan(rows, got.compute_s, {}, got.alternates, got.alternate_of)


def _recheck(day: Day, sent: Sent, onboard: Onboard, upload: np.ndarray) -> None:
    """After an upload, each satellite that took a candidate and got a new plan tests what it flew with what it
    was now sent (a plan made before the ground knew what it took); where that fails, :func:`executing` tests
    each primary before flying it (every prefix of a timeline that holds holds, so where it passes nothing
    needs testing)."""
    s = day.start_s
    for k in sorted(sent.flew_candidate):
        if not np.isfinite(upload[k]):
            continue
        done = np.asarray(sent.done, dtype=np.int64)
        later = sent.prim[(day.sat[sent.prim] == k) & (s[sent.prim] >= sent.until)]
        if onboard.test(k, np.concatenate([done[day.sat[done] == k], later])):
            sent.unsure.discard(k)
        else:
            sent.unsure.add(k)


def _upload(day: Day, sent: Sent, know: Knowledge, plan: Plan, upload: np.ndarray) -> int:
    """Each satellite's passes that start after its upload take the plan's primaries and alternates, the others
    keep theirs; returns the churn (primaries that changed among those the plan could change).  A plan whose
    rows in the passes it cannot change are not those the ground knew is refused (a ValueError: a planner's
    defect)."""
    new = np.asarray(plan.rows, dtype=np.int64)
    if not np.array_equal(np.sort(know.rows[day.fixed(know.rows, upload)]), np.sort(new[day.fixed(new, upload)])):
        raise ValueError("the plan changes passes its satellites were sent before its upload")
    keep = day.fixed(sent.prim, upload)
    take = new[~day.fixed(new, upload)]
    churn = len(np.setxor1d(sent.prim[~keep], take))
    sent.prim = np.sort(np.concatenate([sent.prim[keep], take]))
    alt, alt_of = np.asarray(plan.alternates, np.int64), np.asarray(plan.alternate_of, np.int64)
    mine = ~day.fixed(alt, upload) & np.isin(alt_of, take)
    kept = day.fixed(sent.alt, upload)
    sent.alt = np.concatenate([sent.alt[kept], alt[mine]])
    sent.alt_of = np.concatenate([sent.alt_of[kept], alt_of[mine]])
    return churn


def clairvoyant_bound(day: Day, world: World) -> float:
    """The weight of the requests with an opportunity where an acquisition succeeds (see the module docstring)."""
    ok = np.zeros(len(day.weight), dtype=bool)
    ok[day.task[world.clear & (day.start_s >= world.arrival_s[day.task])]] = True
    return float(day.weight[ok].sum())


def figures(day: Day, world: World, rows: np.ndarray, calls: list[dict], check=None, alternates: int = 0) -> dict:
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
            "acquisitions": int(len(rows)), "failed": int((~ok).sum()), "alternates_taken": alternates,
            "cloud_lost": float(w[attempted & ~served].sum() / W) if W > 0 else 0.0,
            "urgent_latency_h": (float(np.mean((first_end[late] - world.arrival_s[late]) / 3600.0))
                                 if late.any() else None),
            "churn": int(sum(c["churn"] for c in calls)),
            "compute_s": [c["compute_s"] for c in calls],
            "valid": valid, "violation": violation}
