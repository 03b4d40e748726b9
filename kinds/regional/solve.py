"""Solvers of the regional_coverage kind: the greedy by marginal coverage, and the coverage search with a bound.

Both work on the candidate strips of :mod:`eosp.kinds.regional.strips` (the rolls' grid, starts and durations
on the public time grid).  ``greedy`` adds, while the action budget lasts, the strip that covers the most value
not yet covered and fits its satellite (no overlap, the slew and settling time to its neighbours, the duty
limit).  ``coverage`` starts from the greedy and runs ruin-and-recreate moves until the time limit (remove a few
strips, or every strip of a satellite's pass, then refill greedily from what is left; a move is kept when it
loses nothing), then spends its last share of the time on the Lagrangian bound of
:mod:`eosp.kinds.regional.bound`.  A schedule whose battery would run dry loses the least valuable strip of that
satellite until it does not (a MIP schedule over its duty limit too); every answer is judged by the checker (the
verifier's rules) before it is returned.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from eosp.budget import Budget
from eosp.config import WEEK_S, ranged
from eosp.kinds.regional.search import Cands, Sats, apply, fits, gains, greedy, value
from eosp.kinds.regional.strips import Strips, build
from eosp.problem import Result
from eosp.regional.check import Report, check, verdict_of
from eosp.regional.geometry import Track
from eosp.regional.model import Case, Plan
from eosp.solvers.base import UtilityConfig


@dataclass
class GreedyConfig(UtilityConfig):
    """Options of ``eosp solve CASE --solver greedy`` (one pass: no time limit)."""

    roll_step: float = ranged(0.25, 0.05, 2.0)
    """Spacing of the candidate rolls, in fields of view of the satellite's sensor (0.25: a strip and the next
    roll's overlap by three quarters; on cases of the benchmark's generator under seeds of eosp's own, 0.25 served
    as much or more than 0.5 with fewer strips)."""

    NAME = "greedy"
    ONE_SHOT = True


@dataclass
class CoverageConfig(UtilityConfig):
    """Options of ``eosp solve CASE --solver coverage``."""

    time_limit: float | None = ranged(60.0, 0, WEEK_S, lo_open=True, zero_unsets=True)
    roll_step: float = ranged(0.25, 0.05, 2.0)
    """Spacing of the candidate rolls, in fields of view of the satellite's sensor (0.25: a strip and the next
    roll's overlap by three quarters; on cases of the benchmark's generator under seeds of eosp's own, 0.25 served
    as much or more than 0.5 with fewer strips)."""
    moves: int | None = ranged(None, 0)
    """Ruin-and-recreate moves (a deterministic budget); unset: as many as the time limit allows."""
    bound_share: float = ranged(0.2, 0.0, 1.0)
    """Share of the time limit kept for the Lagrangian bound (0: report no bound)."""

    NAME = "coverage"
    BUDGET = "moves"


def arrays(case: Case, strips: Strips) -> tuple[Cands, Sats]:
    """The kernels' view of the candidates and the satellites."""
    sats = case.satellites
    cd = Cands(strips.track_sat[strips.cand_track], strips.start_s, strips.end_s, strips.track_roll[strips.cand_track],
               strips.cand_seg0, strips.cand_n, strips.run_seg, strips.cov_ptr, strips.cov_idx, case.sample_value())
    st = Sats(np.array([s.max_roll_rate_deg_per_s for s in sats]), np.array([s.max_roll_acceleration_deg_per_s2 for s in sats]),
              np.array([s.settling_time_s for s in sats]),
              np.array([np.inf if s.imaging_duty_limit_s_per_orbit is None else s.imaging_duty_limit_s_per_orbit
                        for s in sats]), np.array([s.orbit_period_s for s in sats]))
    return cd, st


def plan_of(case: Case, strips: Strips, chosen: np.ndarray) -> Plan:
    c = np.flatnonzero(chosen)
    sat = strips.track_sat[strips.cand_track[c]]
    return Plan.of(case, sat.tolist(), strips.start_s[c].tolist(), (strips.cand_n[c] * strips.step_s).tolist(),
                   strips.track_roll[strips.cand_track[c]].tolist())


class Search:
    """The state of a solve: candidates, the chosen mask, the coverage counts, the best found."""

    def __init__(self, case: Case, strips: Strips, seed: int):
        self.case, self.strips = case, strips
        self.cd, self.st = arrays(case, strips)
        self.budget = case.max_actions if case.max_actions is not None else len(strips)
        self.chosen = np.zeros(len(strips), dtype=bool)
        self.cnt = np.zeros(len(case.lon), np.int64)
        self.stamp = np.zeros(len(case.lon), np.int64)
        self.rng = np.random.default_rng(seed)
        self.usable = strips.cand_usable.copy()
        self.value = 0.0
        self.moves = self.kept = 0

    def fill(self) -> None:
        greedy(self.cd, self.st, self.chosen, self.cnt, self.budget, self.usable, self.stamp)
        self.value = value(self.cd, self.cnt)

    def set(self, chosen: np.ndarray) -> None:
        """Take `chosen` as the selection (the counts and the value rebuilt)."""
        self.chosen = chosen.copy()
        self.cnt[:] = 0
        for c in np.flatnonzero(chosen).tolist():
            apply(self.cd, c, self.cnt, self.stamp, int(self.stamp.max()) + 1, 1)
        self.value = value(self.cd, self.cnt)

    def _remove(self, c: int) -> None:
        self.chosen[c] = False
        apply(self.cd, c, self.cnt, self.stamp, int(self.stamp.max()) + 1, -1)

    def _make_room(self) -> np.ndarray:
        """Force in one of the strips of largest gain that does not fit, after removing the strips of its
        satellite it collides with; the strips removed."""
        g = gains(self.cd, self.cnt, self.stamp)
        g[~self.usable | self.chosen] = 0.0
        top = np.flatnonzero(g > 0)
        if not len(top):
            return np.zeros(0, np.int64)
        top = top[np.argsort(-g[top], kind="stable")[:20]]
        c = int(self.rng.choice(top))
        s = self.cd.sat[c]
        on = np.flatnonzero(self.chosen & (self.cd.sat == s))
        drop = []
        for d in on.tolist():
            if not fits(self.cd, self.st, c, np.array([d])):
                drop.append(d)
        if len(on) - len(drop) >= self.budget or self.chosen.sum() - len(drop) >= self.budget:
            others = np.setdiff1d(np.flatnonzero(self.chosen), drop)
            drop.append(int(self.rng.choice(others)))  # the budget is full: one more strip makes room
        for d in drop:
            self._remove(d)
        if fits(self.cd, self.st, c, np.flatnonzero(self.chosen)) and self.chosen.sum() < self.budget:
            self.chosen[c] = True
            apply(self.cd, c, self.cnt, self.stamp, int(self.stamp.max()) + 1, 1)
        return np.array(drop, np.int64)

    def move(self) -> bool:
        """One ruin-and-recreate move; True when kept (no loss)."""
        on = np.flatnonzero(self.chosen)
        if not len(on):
            return False
        old_chosen, old_cnt, old_value = self.chosen.copy(), self.cnt.copy(), self.value
        kind = self.rng.random()
        if kind < 1 / 3:  # a strip that would cover something new, in place of the strips it collides with
            drop = self._make_room()
        else:
            if kind < 2 / 3:  # a few strips anywhere
                drop = self.rng.choice(on, size=min(len(on), int(self.rng.integers(1, 4))), replace=False)
            else:  # every strip of one satellite within an orbit of one of them
                c = int(self.rng.choice(on))
                s = self.cd.sat[c]
                near = np.abs(self.cd.start[on] - self.cd.start[c]) < self.st.period[s]
                drop = on[(self.cd.sat[on] == s) & near]
            for c in drop.tolist():
                self._remove(c)
        banned = self.usable.copy()
        if self.rng.random() < 0.5:
            banned[drop] = False  # force a change
        greedy(self.cd, self.st, self.chosen, self.cnt, self.budget, banned, self.stamp)
        greedy(self.cd, self.st, self.chosen, self.cnt, self.budget, self.usable, self.stamp)
        self.moves += 1
        new = value(self.cd, self.cnt)
        if new >= old_value - 1e-15 and (new > old_value + 1e-15 or self.chosen.sum() <= old_chosen.sum()):
            self.value = new
            self.kept += 1
            return True
        self.chosen, self.cnt, self.value = old_chosen, old_cnt, old_value
        return False


REPAIRED = ("battery depletes", "imaging duty limit exceeded")  # a satellite's violations a dropped strip mends


def _repair(case: Case, track: Track, search: Search) -> tuple[Plan, Report]:
    """The plan, with the least valuable strip of a satellite whose battery runs dry or whose duty limit is
    exceeded removed until none is (the searches never break the duty limit; the MIP has no row for it); the
    plan and the checker's report of it."""
    while True:
        plan = plan_of(case, search.strips, search.chosen)
        rep = check(case, plan, track)
        bad = [v for v in rep.violations if any(w in v for w in REPAIRED)]
        if not bad:
            return plan, rep
        sat_id = bad[0].split()[1].rstrip(":")
        s = case.sat_index()[sat_id]
        on = [c for c in np.flatnonzero(search.chosen) if search.cd.sat[c] == s]
        worth = []
        for c in on:
            search._remove(c)
            worth.append(value(search.cd, search.cnt))
            search.chosen[c] = True
            apply(search.cd, c, search.cnt, search.stamp, int(search.stamp.max()) + 1, 1)
        search._remove(on[int(np.argmax(worth))])
        search.value = value(search.cd, search.cnt)


def prepare(case: Case, roll_step: float) -> tuple[Track, Strips, dict]:
    t0 = time.perf_counter()
    track = Track(case)
    strips = build(case, track, roll_step)
    return track, strips, {"candidates": time.perf_counter() - t0}


def _result(case: Case, track: Track, search: Search, timings: dict, bound: float | None, info: dict) -> Result:
    plan, rep = _repair(case, track, search)
    v = verdict_of(rep)  # the repair's last check is the answer's
    val = float(v.metrics["coverage_ratio"])
    if bound is not None:
        bound = max(bound, val)
    return Result(plan, val, bound, "lagrangian (candidate grid)" if bound is not None else None,
                  timings=timings, info={**info, "candidates": len(search.strips), "moves": search.moves,
                                         "kept": search.kept}, verdict=v)


def solve_greedy(case: Case, cfg: GreedyConfig) -> Result:
    """The greedy by marginal coverage (see the module docstring)."""
    track, strips, timings = prepare(case, cfg.roll_step)
    search = Search(case, strips, cfg.seed)
    t = time.perf_counter()
    search.fill()
    timings["greedy"] = time.perf_counter() - t
    return _result(case, track, search, timings, None, {})


def _moves(search: Search, end: Budget, moves: int | None) -> None:
    while not end.expired() and (moves is None or search.moves < moves):
        search.move()


def solve(case: Case, cfg: CoverageConfig) -> Result:
    """The coverage search (see the module docstring)."""
    from eosp.kinds.regional.bound import lagrangian

    t0 = time.perf_counter()
    end = Budget.of(cfg.time_limit, start=t0)
    track, strips, timings = prepare(case, cfg.roll_step)
    search = Search(case, strips, cfg.seed)
    search.fill()
    timings["greedy"] = time.perf_counter() - t0 - timings["candidates"]
    share = cfg.bound_share if end.limited else 0.0
    moves_end = end.less(share * (cfg.time_limit or 0.0)) if end.limited else end
    t = time.perf_counter()
    bound, steps = None, 0
    try:
        _moves(search, moves_end, cfg.moves)
        if cfg.bound_share > 0:
            tb = time.perf_counter()
            secs = max(1.0, end.left()) if end.limited else 60.0
            bound, steps = lagrangian(case, strips, search.value, secs)
            timings["bound"] = time.perf_counter() - tb
        _moves(search, end, cfg.moves)  # what the bound left of the time
    except KeyboardInterrupt:
        pass
    timings["moves"] = time.perf_counter() - t - timings.get("bound", 0.0)
    return _result(case, track, search, timings, bound, {"bound_steps": steps})
