"""The fleet kind's solvers: the fleet solver (passes coordinated by task prices, :mod:`eosp.kinds.fleet.coordinator`)
and the fleet greedy (:mod:`eosp.fleet.greedy`), as library calls and as the contract's entries."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from eosp.fleet.check import CheckResult
from eosp.fleet.energy import EnergyWindows
from eosp.fleet.model import Fleet, Schedule
from eosp.fleet.opportunities import Opportunities
from eosp.kinds.fleet.config import FleetConfig, GreedyConfig
from eosp.kinds.fleet.coordinator import Coordinator
from eosp.kinds.fleet.loop import run
from eosp.kinds.fleet.pool import ForkPool, PassPool
from eosp.kinds.lagrange import Prices
from eosp.kinds.fleet.problem import Primal, Problem, primal_of
from eosp.problem import Result


@dataclass
class FleetSolution:
    """The best schedule, the value and bound as fractions of the total weight (WCR), and the run's record."""

    schedule: Schedule
    value: float
    bound: float | None
    history: list[tuple[float, float, float]]
    info: dict
    check: CheckResult | None = None  # the checker's result on `schedule`

    @property
    def gap(self) -> float | None:
        return None if self.bound is None or self.bound <= 0 else (self.bound - self.value) / self.bound


@dataclass
class Resume:
    """Where a stopped run was (saved after every round by a job): prices, step factor, best bound, rounds done.
    Its best schedule is passed as the `initial` schedule of :func:`solve`."""

    lam: np.ndarray
    step: float
    best_bound: float
    bound_source: str
    rounds_done: int
    mu: np.ndarray | None = None  # the energy windows' multipliers (None: a run dir from before they existed)


def resume_mu(resume: Resume, windows: EnergyWindows) -> np.ndarray | None:
    """The saved multipliers of the energy windows, when they are this problem's (else they start at 0)."""
    mu = resume.mu
    return None if mu is None or len(mu) != len(windows) else np.asarray(mu, dtype=np.float64)


def solve(fleet: Fleet, opps: Opportunities, cfg: FleetConfig | None = None, problem: Problem | None = None,
          initial: Schedule | None = None, freeze_until_s: float | np.ndarray | None = None,
          pool: PassPool | None = None,
          on_round: Callable[[Coordinator], None] | None = None, resume: Resume | None = None,
          t0: float | None = None) -> FleetSolution:
    """Schedule a fleet (:mod:`eosp.kinds.fleet.coordinator`); the schedule is checked by the checker before it is
    returned, and an action it rejects is dropped (never expected: the pass graphs and the battery repair use its
    rules).

    `initial`: a schedule to start from; `freeze_until_s`: the passes starting before this time (seconds from
    the horizon start) keep the initial schedule's actions as they are (so every action before it is kept); one
    time per satellite (an array in the fleet's satellite order) freezes each satellite up to its own time, as a
    plan uploaded at each satellite's own ground contact is (:func:`frozen_passes`).
    `pool`: what solves the passes of a price round (:class:`eosp.kinds.fleet.pool.PassPool`, e.g. Ray actors;
    default: forked processes when ``cfg.workers > 1``, else this process); `on_round`: called after every round;
    `resume`: prices and bound of a stopped run (its best schedule as `initial`); `t0`: when the fleet was read
    (``time.perf_counter()``; default: now): ``cfg.time_limit`` counts from it and bounds everything after it
    (the pass graphs when `problem` is not given, the rounds, the battery repairs, the final check: the rounds
    stop early by the final check's estimate, :func:`eosp.kinds.fleet.loop.check_estimate`); when the first schedule comes
    after the limit, it is returned as soon as it is repaired and checked (``info["first_after_limit"]``)."""

    t0 = time.perf_counter() if t0 is None else t0
    cfg = cfg or FleetConfig()
    cfg.validate()  # fields set one by one (eosp.config.apply_overrides) are checked together here
    prob = problem or Problem.build(fleet, opps)
    own_pool = pool is None and cfg.workers > 1
    pool = ForkPool(prob, cfg) if own_pool else pool
    coord = coordinator(prob, cfg, Start(initial, freeze_until_s, t0), pool)
    coord.on_round = on_round
    start_prices(coord, resume)
    try:
        return run_checked(coord)
    finally:
        if own_pool:
            pool.close()


@dataclass
class Start:
    """Where a solve starts: a schedule (`initial`), the passes kept as it has them (`freeze_until_s`: one time,
    or one per satellite, :func:`frozen_passes`) and when the problem was read (`t0`, ``time.perf_counter()``;
    None: now)."""

    initial: Schedule | None = None
    freeze_until_s: float | np.ndarray | None = None
    t0: float | None = None
    claim_frozen: bool = True
    """Whether the frozen passes' observations serve their tasks.  False in operations (:mod:`eosp.ops`): what a
    satellite has executed or been sent stays in its timeline (it took the time, the slews and the energy), but
    its outcome is the planner's to say through the values: an acquisition found cloudy leaves its request open,
    one not yet reported is worth what the planner expects of a second try.  The frozen observations are then
    worth 0 and the task prices pass them by (their fixed terms of the Lagrangian bound are their energy's price
    alone), so the bound is over the schedules that keep them as they are and serve each task at most once in
    the other passes; a task may then appear twice in a schedule (the checker counts it once)."""


def coordinator(prob: Problem, cfg: FleetConfig, start: Start, pool: PassPool | None) -> Coordinator:
    """The state of a solve of `prob` from `start` (:class:`Coordinator`), its prices at zero."""
    first = None if start.initial is None else primal_of(prob, start.initial, repeats=not start.claim_frozen)
    frozen = None
    if start.freeze_until_s is not None:
        frozen = frozen_passes(prob, start.freeze_until_s)
        first = first or Primal.empty(len(prob.passes), len(prob.fleet.tasks))
    return Coordinator(prob, cfg, t0=time.perf_counter() if start.t0 is None else start.t0, pool=pool,
                       initial=first, frozen=frozen, claim_frozen=start.claim_frozen)


def run_checked(coord: Coordinator) -> FleetSolution:
    """Run a solve (:func:`eosp.kinds.fleet.loop.run`) and check its schedule: the solution and its record."""
    best = run(coord)
    cfg, prob, fleet = coord.cfg, coord.prob, coord.prob.fleet
    t_final = time.perf_counter()
    sched, res, dropped = checked(fleet, coord.schedule(best), prob.geo)
    W = prob.total_weight
    value = float(res.metrics.get("WCR", 0.0))
    if prob.values is None and coord.bound_source == "lagrangian" and W > 0 and value > coord.bound / W + 1e-9:
        coord.keep(coord.best)  # the checked schedule above the bound: the bound was wrong, refused (never expected)
    bound = coord.bound
    source = coord.bound_source
    if source == "lagrangian" and coord.frozen.any():
        source = "lagrangian, frozen passes as given"  # what it bounds: the schedules that keep them
    info = {"pass_solver": cfg.pass_solver, "rounds": coord.rounds_done, "pass_solves": coord.pass_solves,
            "memo_hits": coord.memo_hits,
            "prefetched_rounds": coord.prefetched,
            "passes": len(prob.passes), "build_s": round(prob.build_s, 3), "checker_drops": dropped,
            "battery_barred": int(coord.barred.sum()), "repair_removed": coord.repair_drops,
            "repair_first": coord.first_repair_drops, "energy_windows": len(coord.windows),
            "first_schedule_s": None if coord.first_s is None else round(coord.first_s, 3),
            "first_after_limit": cfg.time_limit is not None and coord.first_s is not None
            and coord.first_s > cfg.time_limit, "check_reserve_s": round(coord.check_s, 3),
            "final_check_s": round(time.perf_counter() - t_final, 3),
            "metrics": res.metrics, "interrupted": coord.interrupted,
            "bound_source": source, "price_round_s": [round(x, 4) for x in coord.round_s],
            "round_phases_s": coord.phases,
            "bound_graphs": prob.bound_graphs, "bound_refused": list(coord.refused),
            "no_lagrangian_bound_because": None if coord.bound_source == "lagrangian" else (
                f"pass solver {cfg.pass_solver} proves no pass bound" if cfg.pass_solver != "exact"
                else f"refused: {coord.refused[-1]}" if coord.refused
                else "none was lower than the conflict-free bound" if coord.rounds_done
                else "none needed: the conflict-free bound is met" if coord.best_bound <= coord.best.value + 1e-9
                else "no price round finished")}
    if prob.values is not None:  # the objective is the values; the bound bounds it, not the WCR
        info["objective"] = "values"
        info["objective_value"] = coord.best.value / W if W > 0 else 0.0
    hist = [(t, v / W, b / W) for t, v, b in coord.history]
    return FleetSolution(sched, value, min(1.0, bound / W) if W > 0 else 0.0, hist, info, res)


def frozen_passes(prob: Problem, until_s: float | np.ndarray) -> np.ndarray:
    """Bool per pass: it starts before `until_s` (seconds from the horizon start), one time for the whole fleet or
    one per satellite (its passes against its own time); an array of another length is a ValueError."""
    until = np.asarray(until_s, dtype=np.float64)
    if until.ndim == 0:
        return prob.pass_time[:, 0] < float(until)
    n_sat = len(prob.fleet.satellites)
    if until.shape != (n_sat,):
        raise ValueError(f"freeze times: one per satellite ({n_sat}), got an array of shape {until.shape}")
    sat = np.fromiter((pg.satellite for pg in prob.passes), np.int64, len(prob.passes))
    return prob.pass_time[:, 0] < until[sat]


def start_prices(coord: Coordinator, resume: Resume | None) -> None:
    """Where the prices start: a stopped run's prices, step, rounds and bound (`resume`), else ``--warm-start``'s
    (none: zero)."""
    cfg, prob = coord.cfg, coord.prob
    if resume is None and cfg.warm_start != "none":
        from eosp.kinds.fleet.warmstart import start_prices as warm

        coord.prices = Prices(warm(prob, cfg.warm_start, cfg.price_model or None), coord.windows)
    if resume is not None:
        if len(resume.lam) != len(prob.fleet.tasks):
            raise ValueError("resume: prices of another fleet")
        coord.prices = Prices(resume.lam.astype(np.float64), coord.windows, resume_mu(resume, coord.windows),
                              resume.step)
        coord.start_round = resume.rounds_done
        if resume.best_bound < coord.best_bound:
            coord.best_bound, coord.bound_source = resume.best_bound, resume.bound_source


def checked(fleet: Fleet, sched: Schedule, geo) -> tuple[Schedule, object, int]:
    """The schedule as the checker accepts it: the actions it rejects dropped (never expected: the pass graphs and
    the battery repair use its rules), its verdict, and how many were dropped."""
    from eosp.fleet.check import validate

    res = validate(fleet, sched, geo)
    dropped = 0
    while not res.valid and len(sched):
        bad = sorted({v.action for v in res.violations if v.action >= 0}) or [0]
        keep = np.setdiff1d(np.arange(len(sched)), bad)
        sched = Schedule(sched.satellite[keep], sched.task[keep], sched.start_us[keep], sched.end_us[keep])
        dropped += len(bad)
        res = validate(fleet, sched, geo)
    return sched, res, dropped


def solve_fleet(data, cfg: FleetConfig, initial: Schedule | None = None,
                freeze_until_s: float | None = None) -> Result:
    """The contract's entry of ``--solver fleet`` (:mod:`eosp.kinds.fleet.kind`): `data` a fleet directory read."""
    t0 = time.perf_counter()
    cfg.validate()  # before the pass graphs are built
    prob = Problem.build(data.fleet, data.opps, data.geo)  # the Geometry the kind's checks built, when they did
    sol = solve(data.fleet, data.opps, cfg, problem=prob, initial=initial, freeze_until_s=freeze_until_s, t0=t0)
    status = "interrupted" if sol.info["interrupted"] else "optimal" if sol.gap == 0 else \
        "first_schedule" if sol.info["first_after_limit"] else \
        "budget" if cfg.rounds is not None and sol.info["rounds"] >= cfg.rounds else "time_limit"
    return Result(sol.schedule, sol.value, sol.bound, sol.info["bound_source"], status,
                  {"solve": time.perf_counter() - t0, "build": sol.info["build_s"]}, sol.info, sol.check.verdict())


def solve_greedy(data, cfg: GreedyConfig) -> Result:
    """The contract's entry of the fleet greedy: each task once, by weight (:mod:`eosp.fleet.greedy`); checked."""
    from eosp.fleet.check import validate
    from eosp.fleet.geometry import Geometry
    from eosp.fleet.greedy import solve as greedy

    t0 = time.perf_counter()
    geo = data.geo or Geometry(data.fleet)
    sched = greedy(data.fleet, data.opps, geo)
    verdict = validate(data.fleet, sched, geo).verdict()
    return Result(sched, float(verdict.metrics["WCR"]), None, None, "done", {"solve": time.perf_counter() - t0},
                  {}, verdict)
