"""The fleet solver as a planner in operations (:mod:`eosp.ops.simulate`): plan once, re-plan on weights, re-plan
on expected values.

Every call is one solve of the day's problem (built once, :class:`eosp.kinds.fleet.replan.Replanner`: prices and
columns kept from call to call) from the timelines as they stand, each satellite's passes frozen up to its next
upload (what it was sent and what it did stays, :func:`eosp.kinds.fleet.solve.frozen_passes`).  The frozen
observations serve nothing in the solve (``Start.claim_frozen=False``): what they are worth is said through the
values of the other passes, which is where the planners differ:

* ``plan-once``: the first call only, every request that has arrived at its weight;
* ``replan``: every call; a request at its weight unless it is known served or an acquisition of it is pending
  (sent, or made and not reported yet: taken as a success), 0 before it arrives;
* ``ev-replan``: every call; an opportunity is worth the request's weight times the chance that it is still
  open (each pending acquisition failing, by the forecast it was planned under) times the forecast's chance that
  this acquisition succeeds.  Serving a task twice is then priced right: a second try of a pending one is worth
  what it adds.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eosp.config import WEEK_S, choice, ranged
from eosp.fleet.model import Schedule
from eosp.kinds.fleet.config import FleetConfig
from eosp.kinds.fleet.problem import Problem, opportunity_values
from eosp.kinds.fleet.replan import Replanner
from eosp.kinds.fleet.solve import Start, frozen_passes
from eosp.ops.simulate import Day, Knowledge, Onboard, Plan, simulate

PLANNERS = ("plan-once", "replan", "ev-replan")
ONBOARD = ("none", "rule", "lookahead")
RUN_KIND = "eosp-simulation"
MEANS = ("served", "served_catalogue", "served_urgent", "bound", "regret", "cloud_lost", "urgent_latency_h", "churn",
         "conflict_free_bound", "clairvoyant_schedule", "clairvoyant_gap")


@dataclass
class SimulateConfig:
    """A planner run through realizations of an operations scenario (``eosp simulate SCEN --out RUN/``)."""

    planner: str = choice("ev-replan", *PLANNERS)
    """plan-once: the fleet solver at the start, on the weights; replan: the same on every planning call;
    ev-replan: every call, each opportunity worth its weight times the forecast's chance of success and the
    chance the request is still open (docs/operations.md)."""
    realizations: int = ranged(4, 1, 100_000)
    """Realizations of the clouds (numbers 0 to this, less one; the same for every planner)."""
    time_limit: float = ranged(30.0, 0.0, WEEK_S, lo_open=True)
    """Seconds of compute a planning call may take; its plan is uploaded at the first contact after the call's
    time plus this."""
    rounds: int | None = ranged(None, 1)
    """Price rounds of a planning call instead of its time limit (the same plans on any machine); uploads still
    wait for the time limit."""
    seed: int = ranged(0, 0)
    """Seed of the fleet solver."""
    warm: bool = True
    """Keep the solver's prices and master columns from one planning call to the next (false: every call starts
    cold, as a separate solve would)."""
    onboard: str = choice("none", *ONBOARD)
    """rule: a satellite that finds its target cloudy as it acquires it takes the alternate sent for it after it
    (each plan sends one per gap between primaries that fits there and with the battery); lookahead: a detector
    looking ahead (proposed, not flown) sees the target cloudy before the slew, and the satellite takes the
    replacement sent for it in its place (each plan sends, per primary, the most valuable opportunity that fits
    there instead) where its slews and battery hold; none: it flies what it was sent."""
    bound_time_limit: float = ranged(30.0, 0.0, WEEK_S)
    """Seconds of the fleet solver's clairvoyant solve of each realization, for its bound (0: the conflict-free
    clairvoyant bound alone); with --rounds, that many price rounds instead."""

    def solver(self) -> FleetConfig:
        return FleetConfig(time_limit=None if self.rounds else self.time_limit, rounds=self.rounds, seed=self.seed)


@dataclass
class FleetPlanner:
    """One of :data:`PLANNERS` over a problem built once (see the module docstring); :meth:`reset` before each
    realization (prices and columns start again), :meth:`close` at the end."""

    name: str
    prob: Problem
    cfg: FleetConfig
    onboard: str = "none"  # with each plan, what the onboard rule may take: alternates (rule), replacements (lookahead)
    warm: bool = True  # prices and columns kept from call to call (else every call starts cold)

    def __post_init__(self) -> None:
        if self.name not in PLANNERS:
            raise ValueError(f"planner {self.name!r}: one of {', '.join(PLANNERS)}")
        o = self.prob.opps
        self._task = o.task.astype(np.int64)
        step_us = self.prob.fleet.horizon.action_step_s * 1_000_000
        self._row_of = {k: r for r, k in enumerate(zip(o.task.tolist(), o.satellite.tolist(), o.start.tolist()))}
        self._step_us = step_us
        self._pair_pass = np.repeat(np.arange(len(self.prob.passes)), np.diff(self.prob.task_ptr))
        self.replanner = Replanner(self.prob, self.cfg)

    def reset(self) -> None:
        self.replanner.prices = None
        self.replanner.master = None
        self.replanner.calls = 0

    def close(self) -> None:
        self.replanner.close()

    def plan(self, know: Knowledge) -> Plan | None:
        if self.name == "plan-once" and know.call > 0:
            return None
        if not self.warm:
            self.reset()
        prob, o = self.prob, self.prob.opps
        until, frozen, per_opp, values = self.values(know)
        self.replanner.revalue(values)
        t = time.perf_counter()
        sol = self.replanner.solve(Start(self.schedule(know.rows), until, t, claim_frozen=False))
        rows = self.rows(sol.schedule)
        alt = alt_of = np.zeros(0, np.int64)
        if self.onboard != "none":
            pick = replacements if self.onboard == "lookahead" else alternates
            alt, alt_of = pick(prob, rows, frozen, np.where(frozen[o.pass_id], 0.0, per_opp))
        compute = time.perf_counter() - t
        info = {"objective": sol.info.get("objective_value"), "bound": sol.bound, "rounds": sol.info["rounds"]}
        return Plan(rows, compute, info, alt, alt_of)

    def values(self, know: Knowledge) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """What a call on `know` solves for: the freeze times per satellite, the frozen passes, the value of each
        opportunity and of each (pass, task) (0 in the frozen passes)."""
        prob, o = self.prob, self.prob.opps
        until = np.where(np.isfinite(know.upload_s), know.upload_s, prob.fleet.horizon.seconds + 1.0)
        frozen = frozen_passes(prob, until)
        per_opp = self.opportunity_values(know, frozen[o.pass_id[know.rows]])
        values = opportunity_values(prob, per_opp)
        values[frozen[self._pair_pass]] = 0.0
        return until, frozen, per_opp, values

    def opportunity_values(self, know: Knowledge, fixed: np.ndarray) -> np.ndarray:
        """What an acquisition at each opportunity is worth to this planner, from what the ground knows;
        `fixed`: per row of ``know.rows``, whether the solve keeps it (its pass frozen)."""
        w = self.prob.weight
        n = len(w)
        open_ = know.arrived & ~know.served(self._task, n)
        pending = fixed & (know.outcome < 0)
        task = self._task[know.rows]
        if self.name != "ev-replan":  # an alternate is taken when its primary fails, which these take as served
            pending &= ~know.alternate
        if self.name == "ev-replan":
            still = np.ones(n)
            np.multiply.at(still, task[pending], 1.0 - know.planned_p[pending])
            return (w * open_ * still)[self._task] * know.forecast
        waiting = np.zeros(n, dtype=bool)
        waiting[task[pending]] = True
        return (w * (open_ & ~waiting))[self._task]

    def schedule(self, rows: np.ndarray) -> Schedule:
        """Opportunity rows as a schedule of the day's fleet."""
        f, o = self.prob.fleet, self.prob.opps
        start = o.start[rows].astype(np.int64) * self._step_us
        dur = (f.tasks.duration_s[o.task[rows]] * 1_000_000).astype(np.int64)
        return Schedule(f.satellites.ids[o.satellite[rows]], f.tasks.ids[o.task[rows]], start, start + dur)

    def rows(self, sched: Schedule) -> np.ndarray:
        """A schedule of the day's fleet as opportunity rows (every action is one: the solver's are)."""
        ti, si = self.prob.fleet.task_index(), self.prob.fleet.satellite_index()
        return np.array(sorted(self._row_of[(ti[t], si[s], int(st // self._step_us))]
                               for s, t, st in zip(sched.satellite.tolist(), sched.task.tolist(),
                                                   sched.start_us.tolist())), dtype=np.int64)


def _times(prob: Problem) -> tuple[np.ndarray, np.ndarray]:
    """Each opportunity's start and end (seconds from the horizon's start)."""
    o = prob.opps
    start = o.start.astype(np.float64) * float(prob.fleet.horizon.action_step_s)
    return start, start + prob.fleet.tasks.duration_s[o.task]


def _open_candidates(prob: Problem, rows: np.ndarray, frozen: np.ndarray, value: np.ndarray, taken: np.ndarray):
    """For each satellite with primaries (`rows`) in passes the plan may change: (satellite, its primaries in time
    order, its opportunities worth something (`value` > 0) in those passes of a task not `taken`, the primaries'
    timeline, where each candidate would go in it).  `taken` is read per satellite: what the caller marks taken
    while it handles one satellite is no candidate of the next."""
    from eosp.fleet.timeline import Arrays, timeline

    o, los = prob.opps, prob.los
    start, end = _times(prob)
    task = o.task.astype(np.int64)
    live = ~frozen[o.pass_id] & (value > 0)
    for k in np.unique(o.satellite[rows[~frozen[o.pass_id[rows]]]]).tolist():
        mine = rows[o.satellite[rows] == k]
        mine = mine[np.lexsort((end[mine], start[mine]))]
        cand = np.flatnonzero(live & (o.satellite == k) & ~taken[task])
        if not len(cand):
            continue
        tl = Arrays.of(timeline(los, k, task[mine], start[mine], end[mine]))
        yield k, mine, cand, tl, np.searchsorted(tl.start, start[cand], side="right")


def alternates(prob: Problem, rows: np.ndarray, frozen: np.ndarray, value: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Alternates for the onboard rule (:func:`eosp.ops.simulate.execute`) of a plan's primaries `rows` in the
    passes it may change (not `frozen`): after each primary, the most valuable opportunity (`value`, per
    opportunity; 0: never) of the same satellite and pass that fits between it and the next primary (the slew and
    settling from it and to the next, no overlap: the checker's rules, :func:`eosp.fleet.timeline.fits`), of a
    task no primary holds and no other alternate took; then, per satellite, alternates dropped from the least
    valuable until its battery holds with all of them.  Why one per gap: taken or not, every sequence the
    satellite can then fly (a primary, perhaps its alternate, the next primary) is one the checker accepts, and
    with every alternate in, the battery held on the ground.  Returns the alternates and their primaries."""
    from eosp.fleet.battery import SunCache
    from eosp.fleet.battery import simulate as battery
    from eosp.fleet.timeline import Candidates, fits, intervals, timeline

    o, los = prob.opps, prob.los
    start, end = _times(prob)
    task = o.task.astype(np.int64)
    sun = prob.sun or SunCache(prob.geo)
    taken = np.zeros(len(prob.weight), dtype=bool)
    taken[task[rows]] = True
    out_alt, out_of = [], []
    for k, mine, cand, tl, pos in _open_candidates(prob, rows, frozen, value, taken):
        prev = mine[np.maximum(pos - 1, 0)]
        ok = (pos > 0) & (o.pass_id[prev] == o.pass_id[cand]) & ~frozen[o.pass_id[prev]]
        cand, pos, prev = cand[ok], pos[ok], prev[ok]
        if not len(cand):
            continue
        c = Candidates(start[cand], end[cand], los.los(k, task[cand], start[cand]), los.los(k, task[cand], end[cand]))
        ok = fits(los, k, tl, c, pos)
        cand, prev = cand[ok], prev[ok]
        got: dict[int, int] = {}
        for i in np.argsort(-value[cand], kind="stable").tolist():  # the most valuable first, one per gap and task
            if prev[i] not in got and not taken[task[cand[i]]]:
                got[int(prev[i])] = int(cand[i])
                taken[task[cand[i]]] = True
        alt = sorted(got.items(), key=lambda kv: value[kv[1]])  # the least valuable first: dropped first
        while alt:
            both = np.concatenate([mine, [a for _, a in alt]])
            both = both[np.lexsort((end[both], start[both]))]
            tlb = timeline(los, k, task[both], start[both], end[both])
            if battery(prob.fleet, sun, k, *intervals(los, tlb, k)).ok:
                break
            alt = alt[1:]
        out_of += [p for p, _ in alt]
        out_alt += [a for _, a in alt]
    return np.asarray(out_alt, dtype=np.int64), np.asarray(out_of, dtype=np.int64)


def onboard_test(prob: Problem, slews: bool = False):
    """The onboard rule's test (:class:`eosp.ops.simulate.Onboard`): whether satellite k can fly a timeline of
    opportunity rows: its battery holds (the checker's battery model, :mod:`eosp.fleet.battery`) and, with
    `slews`, no two overlap and every slew plus settling fits before its observation (the checker's rules,
    :mod:`eosp.fleet.slew`; the rule after acquisition needs no such test: its alternates fit by construction)."""
    from eosp.fleet.battery import SunCache
    from eosp.fleet.battery import simulate as battery
    from eosp.fleet.slew import MARGIN_S
    from eosp.fleet.timeline import intervals, timeline

    o, los = prob.opps, prob.los
    start, end = _times(prob)
    sun = prob.sun or SunCache(prob.geo)

    def holds(k: int, rows: np.ndarray) -> bool:
        rows = rows[np.lexsort((end[rows], start[rows]))]
        tl = timeline(los, k, o.task[rows].astype(np.int64), start[rows], end[rows])
        if slews and len(rows):
            st, en = start[rows], end[rows]
            to = np.asarray(tl.los0, dtype=np.float64).reshape(-1, 3)
            frm = np.empty_like(to)
            frm[0] = los.nadir(k, st[0])
            frm[1:] = np.asarray(tl.los1[:-1], dtype=np.float64).reshape(-1, 3)
            gap = st - np.r_[0.0, en[:-1]]
            if (gap < 0).any() or (los.need_s(k, frm, to) + MARGIN_S > gap).any():
                return False
        return battery(prob.fleet, sun, k, *intervals(los, tl, k)).ok

    return holds


def replacements(prob: Problem, rows: np.ndarray, frozen: np.ndarray,
                 value: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Replacements for the onboard rule that looks ahead (:class:`eosp.ops.simulate.Onboard`) of a plan's
    primaries `rows` in the passes it may change (not `frozen`): for each primary, the most valuable opportunity
    (`value`, per opportunity; 0: never) of the same satellite and pass that fits in its place, between the
    primaries before and after it (slews and settling, no overlap: :func:`eosp.fleet.timeline.fits` with the
    primary removed), of a task no primary holds and no other replacement took.  The battery is the satellite's
    to test when it decides (a replacement changes the slews around it).  Returns the replacements and their
    primaries."""
    from eosp.fleet.timeline import Candidates, fits

    o, los = prob.opps, prob.los
    start, end = _times(prob)
    task = o.task.astype(np.int64)
    taken = np.zeros(len(prob.weight), dtype=bool)
    taken[task[rows]] = True
    out_alt, out_of = [], []
    for k, mine, cand, tl, pos in _open_candidates(prob, rows, frozen, value, taken):
        c = Candidates(start[cand], end[cand], los.los(k, task[cand], start[cand]), los.los(k, task[cand], end[cand]))
        # the primary replaced: the one after the insertion point (b=1) or the one before it (a=1)
        got: dict[int, int] = {}
        for a, b, at in ((0, 1, pos), (1, 0, pos - 1)):
            inside = (at >= 0) & (at < len(mine))
            prim = mine[np.clip(at, 0, len(mine) - 1)]
            ok = inside & (o.pass_id[prim] == o.pass_id[cand]) & ~frozen[o.pass_id[prim]]
            ok &= fits(los, k, tl, c, pos, a, b)
            for i in np.flatnonzero(ok)[np.argsort(-value[cand[ok]], kind="stable")].tolist():
                p_, r_ = int(prim[i]), int(cand[i])
                if not taken[task[r_]] and (p_ not in got or value[r_] > value[got[p_]]):
                    if p_ in got:
                        taken[task[got[p_]]] = False
                    got[p_] = r_
                    taken[task[r_]] = True
        out_of += list(got)
        out_alt += list(got.values())
    return np.asarray(out_alt, dtype=np.int64), np.asarray(out_of, dtype=np.int64)


@dataclass
class Simulation:
    """What the realizations of one scenario share: the scenario, its problem (pass graphs built once), the day's
    arrays and the planner."""

    scen: object
    cfg: SimulateConfig
    day: Day
    planner: FleetPlanner

    @classmethod
    def of(cls, scen, cfg: SimulateConfig) -> Simulation:
        prob = Problem.build(scen.fleet, scen.opps)
        planner = FleetPlanner(cfg.planner, prob, cfg.solver(), onboard=cfg.onboard, warm=cfg.warm)
        return cls(scen, cfg, Day.of(scen, prob.pass_time[:, 0]), planner)

    def run(self, index: int) -> dict:
        """Realization `index` simulated: its figures and each planning call's record."""
        from eosp.fleet.check import validate
        from eosp.ops.world import realize

        prob = self.planner.prob

        def check(rows: np.ndarray) -> tuple[bool, str | None]:
            res = validate(prob.fleet, self.planner.schedule(rows), prob.geo)
            return res.valid, None if res.valid else str(res.first)

        world = realize(self.scen, index)
        got = self.simulate(world, check)
        out = {**got.figures, **self.clairvoyant(world, got.figures), "calls": got.calls}
        self.last = (world, got)  # for a replay page of this realization (eosp.evaluation.replay_page)
        return out

    def clairvoyant(self, world, figures: dict) -> dict:
        """The fleet solver on the realized day (see :func:`clairvoyant_values`): its proven bound, kept as the
        realization's bound when below the conflict-free one; the realized value of its schedule (a clairvoyant
        plan executed: its tasks served where their chosen start is clear) and its gap to the bound."""
        from eosp.kinds.fleet.solve import solve

        cfg, conflict_free = self.cfg, figures["bound"]
        if cfg.bound_time_limit <= 0 and not cfg.rounds:
            return {"bound_source": "conflict-free clairvoyant"}
        prob = self.planner.prob
        prob.set_values(clairvoyant_values(prob, world))
        solver = dataclasses.replace(cfg.solver(), time_limit=None if cfg.rounds else cfg.bound_time_limit)
        sol = solve(prob.fleet, prob.opps, solver, problem=prob)
        rows = self.planner.rows(sol.schedule)
        served = np.zeros(len(prob.weight), dtype=bool)
        served[prob.opps.task[rows[world.clear[rows]]]] = True
        found = float(prob.weight[served].sum() / prob.total_weight) if prob.total_weight > 0 else 0.0
        bound, source = conflict_free, "conflict-free clairvoyant"
        if sol.bound is not None and sol.bound < bound:
            bound, source = sol.bound, f"clairvoyant fleet solver ({sol.info['bound_source']})"
        if found > bound + 1e-9:
            raise RuntimeError(f"realization {world.index}: a clairvoyant schedule of {found} above the bound {bound}")
        if figures["served"] > bound + 1e-9:
            raise RuntimeError(f"realization {world.index}: served {figures['served']} above the bound {bound}")
        return {"bound": bound, "regret": bound - figures["served"], "bound_source": source,
                "conflict_free_bound": conflict_free,
                "clairvoyant_schedule": found, "clairvoyant_gap": (bound - found) / bound if bound > 0 else 0.0}

    def simulate(self, world, check=None):
        """The planner, reset, through `world` (:func:`eosp.ops.simulate.simulate`)."""
        self.planner.reset()
        ahead = self.cfg.onboard == "lookahead"
        onboard = None if self.cfg.onboard == "none" else Onboard(onboard_test(self.planner.prob, ahead), ahead)
        return simulate(self.day, world, self.planner, self.cfg.time_limit, check, onboard)

    def close(self) -> None:
        self.planner.close()


def clairvoyant_values(prob: Problem, world) -> np.ndarray:
    """Values per (pass, task) of the realized day: a task's weight in a pass where one of its opportunities is
    clear (after its arrival), else 0.

    Why the fleet solver's bound under these values bounds what every planner serves in this realization: an
    executed day is a schedule the checker accepts (each satellite's timeline, failed acquisitions included, and
    tasks observed twice), and a request it serves has a clear executed acquisition, whose pass is worth the
    request's weight here; so its value under these values, each task credited once at its best pass, is at least
    the weight it served.  The solver's Lagrangian bound holds for every such schedule: each pass's term is the
    best over every sequence the verifier accepts, tasks observed again included and credited once, of the
    positive priced values (:func:`eosp.fleet.passgraph.bound_problem`), and the task prices are non-negative;
    its conflict-free bound too.  Uploads, knowledge and compute are relaxed (the clairvoyant knows every
    outcome and arrival at the start and plans everything at once)."""
    o = prob.opps
    ok = world.clear & (o.start.astype(np.float64) * prob.fleet.horizon.action_step_s >= world.arrival_s[o.task])
    return opportunity_values(prob, np.where(ok, prob.weight[o.task], 0.0))


def means(done: list[dict]) -> dict:
    """The mean of each figure over the realizations that have it (None where none has)."""
    out = {}
    for key in MEANS:
        vals = [r[key] for r in done if r.get(key) is not None]
        out[key] = float(np.mean(vals)) if vals else None
    calls = [c for r in done for c in r["compute_s"]]
    out["compute_s_per_call"] = float(np.mean(calls)) if calls else None
    out["valid"] = sum(bool(r["valid"]) for r in done)
    out["realizations"] = len(done)
    return out


def summary_line(out: str | Path, cfg: SimulateConfig, m: dict) -> str:
    urgent = "" if m["served_urgent"] is None else f", urgent {m['served_urgent']:.4f}"
    per_call = "" if m["compute_s_per_call"] is None else f", {m['compute_s_per_call']:.1f} s a call"
    return (f"{out}: {cfg.planner} over {m['realizations']} realizations: served {m['served']:.4f} of the weight "
            f"(catalogue {m['served_catalogue']:.4f}{urgent}), clairvoyant bound {m['bound']:.4f}, regret "
            f"{m['regret']:.4f}; {m['valid']} of {m['realizations']} executions valid{per_call}")


def read_run(out: Path) -> dict | None:
    """The summary of a run directory eosp wrote (None when there is none)."""
    try:
        got = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    return got if isinstance(got, dict) and got.get("kind") == RUN_KIND else None


def prior_realizations(out: Path, scen_path: str, cfg: SimulateConfig, resume: bool, overwrite: bool) -> list[dict]:
    """The realizations a run directory holds to go on from: none when `out` does not exist or `overwrite`; those
    below ``cfg.realizations`` when `resume` and it is a run of the same scenario and options (the number of
    realizations aside).  An InputError for anything else (a directory eosp did not write, another run without
    --resume or --overwrite, another scenario or other options with --resume)."""
    import dataclasses

    from eosp.errors import InputError

    if not (out.exists() or out.is_symlink()):
        return []
    prior = read_run(out) if out.is_dir() else None
    if prior is None:
        raise InputError(out, "exists and is not a run directory written by eosp simulate: refusing to write into it")
    if not (resume or overwrite):
        raise InputError(out, "already exists (--resume goes on from its realizations, --overwrite starts again)")
    if not resume:
        return []
    from eosp.config import apply_overrides

    try:  # options the run's eosp did not have yet are at their defaults
        theirs = dataclasses.asdict(apply_overrides(SimulateConfig(), dict(prior.get("config") or {})))
    except (ValueError, TypeError):
        theirs = None
    mine = dataclasses.asdict(cfg)
    if theirs is not None:
        theirs["realizations"] = mine["realizations"]
    if prior.get("scenario") != str(Path(scen_path).resolve()) or theirs != mine:
        raise InputError(out, "holds a run of another scenario or other options: --resume goes on with the same ones")
    return [r for r in prior.get("realizations") or [] if r["realization"] < cfg.realizations]


def write_summary(out: Path, scen_path: str, cfg: SimulateConfig, done: list[dict]) -> dict:
    """RUN/summary.json, replaced whole (atomically) after each realization."""
    import dataclasses

    from eosp.atomic import atomic_path

    m = means(done)
    body = {"kind": RUN_KIND, "scenario": str(Path(scen_path).resolve()), "config": dataclasses.asdict(cfg),
            "means": m, "realizations": sorted(done, key=lambda r: r["realization"])}
    with atomic_path(out / "summary.json") as tmp:
        tmp.write_text(json.dumps(body, indent=1) + "\n")
    return m
