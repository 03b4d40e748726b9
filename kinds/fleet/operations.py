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
from eosp.kinds.fleet.candidates import alternates, onboard_test, replacements
from eosp.kinds.fleet.replan import Replanner
from eosp.kinds.fleet.solve import Start, frozen_passes
from eosp.ops.onboard import Context, Onboard, ScoreRule
from eosp.ops.simulate import Day, Knowledge, Plan, simulate

PLANNERS = ("plan-once", "replan", "ev-replan")
ONBOARD = ("none", "rule", "lookahead")
CHOOSERS = ("first", "score", "policy")
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
    candidates: int = ranged(1, 1, 8)
    """With --onboard lookahead: the replacements each plan sends per primary, the most valuable first (1: one,
    each task once: the rule's; more: a task may be sent for several primaries, the satellite's chooser picks)."""
    choose: str = choice("first", *CHOOSERS)
    """How a satellite picks among the candidates it can fly: first: the first in the order sent (the rule);
    score: the highest value x (1 - gamma x later) x (1 - beta x cloud correlation with the primary just seen)
    (docs/operations.md); policy: the learned onboard policy (--policy)."""
    beta: float = ranged(0.0, 0.0, 1.0)
    """--choose score: how much a candidate's cloud correlation with the primary found cloudy discounts it."""
    gamma: float = ranged(0.0, 0.0, 1.0)
    """--choose score: how much the chance that another primary serves the candidate's task later discounts it."""
    policy: str = ""
    """--choose policy: a directory with the onboard policy's weights (empty: the shipped one,
    models/pretrained-agents/onboard)."""
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
    candidates: int = 1  # replacements sent per primary (lookahead)

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
        # the frozen passes as the ground knows them: a schedule holds a task once, and a task acquired twice
        # there (two replacements taken before the ground knew of either) is still what was done
        kept = know.rows[frozen[o.pass_id[know.rows]]]
        rows = np.union1d(rows[~frozen[o.pass_id[rows]]], kept)
        alt = alt_of = np.zeros(0, np.int64)
        if self.onboard != "none":
            value = np.where(frozen[o.pass_id], 0.0, per_opp)
            if self.onboard == "lookahead":
                alt, alt_of = replacements(prob, rows, frozen, value, self.candidates)
            else:
                alt, alt_of = alternates(prob, rows, frozen, value)
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


@dataclass
class Simulation:
    """What the realizations of one scenario share: the scenario, its problem (pass graphs built once), the day's
    arrays and the planner."""

    scen: object
    cfg: SimulateConfig
    day: Day
    planner: FleetPlanner
    policy: object = None  # the onboard policy (--choose policy), read once

    @classmethod
    def of(cls, scen, cfg: SimulateConfig) -> Simulation:
        """A bad policy directory is refused here, before the problem is built (one line)."""
        policy = None
        if cfg.onboard != "none" and cfg.choose == "policy":
            from eosp.models.onboard import load_policy

            policy = load_policy(cfg.policy or None)
        prob = Problem.build(scen.fleet, scen.opps)
        planner = FleetPlanner(cfg.planner, prob, cfg.solver(), onboard=cfg.onboard, warm=cfg.warm,
                               candidates=cfg.candidates)
        return cls(scen, cfg, Day.of(scen, prob.pass_time[:, 0]), planner, policy)

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
        return simulate(self.day, world, self.planner, self.cfg.time_limit, check, self.onboard(world))

    def onboard(self, world) -> Onboard | None:
        """The onboard rule of the configuration for realization `world` (None: none)."""
        cfg = self.cfg
        if cfg.onboard == "none":
            return None
        ahead = cfg.onboard == "lookahead"
        test = onboard_test(self.planner.prob, ahead)
        if cfg.choose == "first":
            return Onboard(test, ahead)
        ctx = onboard_context(self.scen, self.day, world)
        if cfg.choose == "score":
            return Onboard(test, ahead, ScoreRule(ctx, cfg.beta, cfg.gamma))
        return Onboard(test, ahead, self.policy.chooser(ctx))

    def close(self) -> None:
        self.planner.close()


def record_plans(sim: Simulation, scen_path: str, index: int, out: str | Path) -> dict:
    """Realization `index` simulated with `sim` and its ground plans written to `out` (:mod:`eosp.ops.plan_cache`)
    for onboard choosers' rollouts; its figures."""
    from eosp.ops import plan_cache
    from eosp.ops.world import realize

    world = realize(sim.scen, index)
    got = sim.simulate(world)
    cfg = sim.cfg
    plan_cache.write(out, got.answers, sim.day.pass_start,
                     {"scenario": str(scen_path), "realization": index, "planner": cfg.planner,
                      "time_limit": cfg.time_limit, "candidates": cfg.candidates, "onboard": cfg.onboard,
                      "choose": cfg.choose, "served": got.figures["served"]})
    return got.figures


def onboard_context(scen, day: Day, world) -> Context:
    """What the onboard features read of scenario `scen` and realization `world` (:class:`eosp.ops.onboard.Context`)."""
    from eosp.ops.clouds import surface_km

    t, m = scen.fleet.tasks, scen.config
    return Context(day.weight, surface_km(t.lat_deg, t.lon_deg), day.task, day.start_s, world.forecast,
                   float(m.cloud_length_km), float(m.cloud_tau_h) * 3600.0)


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
