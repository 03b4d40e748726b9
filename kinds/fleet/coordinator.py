"""The fleet solver's coordinator: a constellation's passes solved by the project's single-pass solvers, held
together by task prices (:mod:`eosp.kinds.fleet.prices`), with an upper bound.

A constellation-day is hundreds of passes (:mod:`eosp.fleet.passgraph`) coupled by one constraint: a task is
served at most once (and each satellite's battery runs from one pass to the next).  Relaxing "at most once"
with prices separates the passes; a price round solves every pass under the prices on a pass pool
(:mod:`eosp.kinds.fleet.pool`), proves the Lagrangian bound when every pass term is an optimum or a bound the
exact solver proved, and moves the prices.

Schedules come from the same pass solver with true weights:

* construction: passes in time order, each solved with the tasks not yet served;
* coordinate descent: a pass is solved again with every task not served by another pass; its new schedule is
  never worse, and the tasks it frees make the passes that hold them worth solving again (a queue);
* large neighbourhoods: the tasks of the passes meeting a random time span are freed, those passes are solved
  again in an order and with utilities perturbed by the prices (a contested task is left to the others when
  its price is high), coordinate descent follows, and the result is kept when it serves at least as much.

Each schedule is checked against the battery with the checker's model (:func:`eosp.fleet.timeline.repair_battery`);
a satellite that runs dry loses its least valuable observations before the failure (and those tasks are barred
from that satellite's passes in later rounds).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from eosp.fleet.battery import SunCache
from eosp.fleet.timeline import Timeline, repair_battery, timelines, to_schedule
from eosp.fleet.model import Schedule
from eosp.kinds.fleet.config import FleetConfig
from eosp.kinds.fleet.pool import InProcessPool, PassPool
from eosp.kinds.fleet.prices import Prices
from eosp.kinds.fleet.problem import PassResult, Primal, Problem, path_tasks, priced, rewalk, solve_pass


@dataclass
class Coordinator:
    """Prices, the best schedule and the best bound of one solve (see the module docstring)."""

    prob: Problem
    cfg: FleetConfig
    prices: Prices = field(init=False)
    best: Primal = field(init=False)
    best_bound: float = math.inf
    barred: np.ndarray = field(init=False)  # [satellite, task]: taken out of that satellite by the battery repair
    history: list[tuple[float, float, float]] = field(default_factory=list)  # (seconds, value, bound)
    t0: float = field(default_factory=time.perf_counter)  # when the problem was read: the time limit counts from it
    pass_solves: int = 0
    rounds_done: int = 0
    interrupted: bool = False
    bound_source: str = "conflict-free"  # until a proven Lagrangian bound is lower
    refused: list[str] = field(default_factory=list)  # Lagrangian bounds refused, and why (see price_round)

    pool: PassPool | None = None  # what solves the passes of a price round (default: this process)
    on_round: Callable[[Coordinator], None] | None = None  # called after every round (checkpoints, MLflow)
    start_round: int = 0  # rounds a resumed run has done already
    round_s: list[float] = field(default_factory=list)  # wall seconds of every finished price round
    initial: Primal | None = None  # a schedule to start from (--init)
    frozen: np.ndarray | None = None  # bool per pass: kept as in `initial`, never solved again (--freeze-until)

    def __post_init__(self) -> None:
        n = len(self.prob.fleet.tasks)
        self.prices = Prices.zero(n)
        self.pool = self.pool or InProcessPool(self.prob, self.cfg)
        self.round_paths = [np.zeros(0, np.int64)] * len(self.prob.passes)
        self.best = Primal.empty(len(self.prob.passes), n)
        self.barred = np.zeros((len(self.prob.fleet.satellites), n), dtype=bool)
        if self.frozen is None:
            self.frozen = np.zeros(len(self.prob.passes), dtype=bool)
        self.sun = SunCache(self.prob.geo)  # sunlight, computed once for every battery simulation
        self.battery_ok: dict[int, tuple] = {}  # satellite -> the timeline last found to hold its battery
        self.best_bound = self.conflict_free()

    # ------------------------------------------------------------------ pass solves
    def _solve(self, p: int, util: np.ndarray) -> PassResult:
        self.pass_solves += 1
        return solve_pass(self.prob, p, util, self.cfg)

    def _available(self, primal: Primal, p: int) -> np.ndarray:
        tasks = self.prob.passes[p].tasks
        s = primal.served[tasks]
        return ((s < 0) | (s == p)) & ~self.barred[self.prob.passes[p].satellite, tasks]

    def _assign(self, primal: Primal, p: int, path: np.ndarray) -> list[int]:
        """Give pass p the schedule `path`; returns the tasks it freed."""
        old = path_tasks(self.prob, p, primal.paths[p])
        new = path_tasks(self.prob, p, path)
        freed = np.setdiff1d(old, new)
        primal.served[freed] = -1
        primal.served[new] = p
        primal.paths[p] = path
        primal.value += float(self.prob.weight[new].sum() - self.prob.weight[old].sum())
        return freed.tolist()

    def descend(self, primal: Primal, queue: list[int], deadline: float | None) -> None:
        """Coordinate descent: solve the queued passes again with every task no other pass serves."""
        w = self.prob.weight
        queued = np.zeros(len(self.prob.passes), dtype=bool)
        queued[queue] = True
        while queue:
            if deadline is not None and time.perf_counter() > deadline:
                return
            p = queue.pop(0)
            queued[p] = False
            if self.frozen[p]:
                continue
            tasks = self.prob.passes[p].tasks
            res = self._solve(p, np.where(self._available(primal, p), w[tasks], 0.0))
            if res.value > float(w[path_tasks(self.prob, p, primal.paths[p])].sum()) + 1e-9:
                for t in self._assign(primal, p, res.nodes):
                    for q in self.prob.task_passes[t].tolist():
                        if q != p and not queued[q]:
                            queued[q] = True
                            queue.append(q)

    def construct(self, order: np.ndarray, util_shift: np.ndarray | None = None,
                  primal: Primal | None = None, deadline: float | None = None) -> Primal:
        """Passes in `order`, each solved with the tasks still free (utility ``w - util_shift``, kept positive)."""
        w = self.prob.weight
        primal = primal or Primal.empty(len(self.prob.passes), len(w))
        for p in order.tolist():
            if deadline is not None and time.perf_counter() > deadline:
                break
            if self.frozen[p]:
                continue
            tasks = self.prob.passes[p].tasks
            u = w[tasks] if util_shift is None else np.maximum(w[tasks] - util_shift[tasks], 1e-3 * w[tasks])
            res = self._solve(p, np.where(self._available(primal, p), u, 0.0))
            self._assign(primal, p, res.nodes)
        return primal

    # ------------------------------------------------------------------ prices and bound
    def price_round(self, deadline: float | None) -> float | None:
        """Every pass under the current prices (on the pool); returns L(lam) (None when cut by the deadline),
        keeps the bound when it is proven and lower, and moves the prices."""
        w, lam = self.prob.weight, self.prices.lam
        todo = np.flatnonzero(~self.frozen).tolist()
        solved = self.pool.solve_priced(todo, lam, deadline)
        if solved is None:
            return None  # cut by the deadline
        self.pass_solves += len(todo)
        count = np.zeros(len(w))
        terms, proven = [], True
        for p in range(len(self.prob.passes)):
            if self.frozen[p]:  # a fixed term: its schedule under the prices
                value = float(priced(w, lam, path_tasks(self.prob, p, self.initial.paths[p])).sum())
                res = PassResult(self.initial.paths[p], value, value)
            else:
                res = solved[p]
            self.round_paths[p] = res.nodes
            proven &= res.bound is not None
            terms.append(res.value if res.bound is None else res.bound)
            count[path_tasks(self.prob, p, res.nodes)] += 1
        total = self.prices.dual(terms)
        if proven and total < self.best_bound:
            if total < self.best.value - 1e-9 * max(1.0, self.best.value):
                # a theorem cannot fall below a schedule: some pass term was wrong; keep the bound known
                self.refused.append(f"round {self.rounds_done + 1}: L(lam) = {total:.6f} below the schedule found "
                                    f"({self.best.value:.6f})")
            else:
                self.best_bound, self.bound_source = total, "lagrangian"
        self.prices.step_towards(count, total, self.best.value)
        return total

    def empty(self) -> Primal:
        """No observation, except those of the frozen passes."""
        primal = Primal.empty(len(self.prob.passes), len(self.prob.weight))
        for p in np.flatnonzero(self.frozen).tolist():
            self._assign(primal, p, self.initial.paths[p])
        return primal

    def recover(self, rng: np.random.Generator, deadline: float | None) -> Primal:
        """A schedule from the last price round's pass schedules: passes in random order keep the tasks no
        earlier pass took (the rest of their path re-walked along the graph's arcs), then coordinate descent."""
        n_pass = len(self.prob.passes)
        primal = self.empty()
        for p in rng.permutation(n_pass).tolist():
            if self.frozen[p]:
                continue
            path = self.round_paths[p]
            if len(path) == 0:
                continue
            free = self._available(primal, p)[self.prob.passes[p].graph.node_acq[path]]
            self._assign(primal, p, rewalk(self.prob.passes[p], path[free]))
        self.descend(primal, list(range(n_pass)), deadline)
        return primal

    # ------------------------------------------------------------------ battery
    def battery_repair(self, primal: Primal, deadline: float | None = None) -> int:
        """Drop observations until every battery holds (checker's model); a dropped task is barred from that
        satellite, and the passes of other satellites that could serve it are solved again once (then the
        batteries are checked and repaired again).  Returns the number dropped."""
        total = 0
        for attempt in range(2):  # the last attempt only repairs: what it returns holds
            tls = self.timelines(primal)
            keys = [tuple(zip(tl.task, tl.start)) for tl in tls]
            todo = [k for k, key in enumerate(keys) if self.battery_ok.get(k) != key]  # satellites not seen as is
            dropped = repair_battery(self.prob.fleet, self.prob.los, tls, sats=todo, sun=self.sun)
            for k in todo:
                self.battery_ok[k] = tuple(zip(tls[k].task, tls[k].start))
            if not dropped:
                break
            total += dropped
            keep = {(k, t) for k, tl in enumerate(tls) for t in tl.task}
            freed = []
            for p, pg in enumerate(self.prob.passes):
                path = primal.paths[p]
                tasks = path_tasks(self.prob, p, path)
                ok = np.array([(pg.satellite, t) in keep for t in tasks.tolist()], dtype=bool)
                if not ok.all():
                    self.barred[pg.satellite, tasks[~ok]] = True
                    self._assign(primal, p, path[ok] if self.frozen[p] else rewalk(pg, path[ok]))
                    freed += tasks[~ok].tolist()
            if attempt < 1:  # one round of re-solves of the passes that could take the dropped tasks
                self.descend(primal, sorted({q for t in freed for q in self.prob.task_passes[t].tolist()}), deadline)
        return total

    def timelines(self, primal: Primal) -> list[Timeline]:
        """The schedule `primal` as one timeline per satellite (:mod:`eosp.fleet.timeline`)."""
        prob = self.prob
        rows = [prob.passes[p].rows[path - 1] for p, path in enumerate(primal.paths) if len(path)]
        rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        task = prob.opps.task[rows]
        st = prob.opps.start[rows].astype(np.float64) * prob.fleet.horizon.action_step_s
        en = st + prob.fleet.tasks.duration_s[task]
        return timelines(prob.fleet, prob.los, prob.opps.satellite[rows], task, st, en)

    def schedule(self, primal: Primal) -> Schedule:
        return to_schedule(self.prob.fleet, self.timelines(primal))

    # ------------------------------------------------------------------ the loop
    def record(self) -> None:
        self.history.append((time.perf_counter() - self.t0, self.best.value, self.best_bound))

    def offer(self, primal: Primal, deadline: float | None = None) -> bool:
        """Keep `primal` (after battery repair) when it serves more than the best."""
        self.battery_repair(primal, deadline)
        if primal.value > self.best.value + 1e-9:
            self.keep(primal)
            return True
        return False

    def keep(self, primal: Primal) -> None:
        """`primal` is the best schedule now; a Lagrangian bound below it was wrong: refused (the conflict-free
        bound, which every schedule respects, takes its place), and said."""
        self.best = primal
        if self.bound_source == "lagrangian" and primal.value > self.best_bound + 1e-9 * max(1.0, primal.value):
            self.refused.append(f"a schedule of {primal.value:.6f} above the Lagrangian bound {self.best_bound:.6f}")
            self.best_bound, self.bound_source = self.conflict_free(), "conflict-free"
        self.record()

    def conflict_free(self) -> float:
        """Every task that has an opportunity, served once."""
        return float(self.prob.weight[np.array([len(h) > 0 for h in self.prob.task_passes], dtype=bool)].sum())

    def neighbourhood(self, rng: np.random.Generator, deadline: float | None) -> None:
        """Free the passes meeting a random time span, rebuild them in a price-perturbed order, descend."""
        prob = self.prob
        horizon = prob.fleet.horizon.seconds
        a = rng.uniform(-self.cfg.span_s, horizon)
        hit = np.flatnonzero((prob.pass_time[:, 1] >= a) & (prob.pass_time[:, 0] <= a + self.cfg.span_s)
                             & ~self.frozen)
        if len(hit) == 0:
            return
        trial = self.best.copy()
        for p in hit.tolist():
            self._assign(trial, p, np.zeros(0, np.int64))
        order = hit[rng.permutation(len(hit))]
        shift = self.prices.lam * rng.uniform(0.0, 1.0)
        self.construct(order, shift, trial, deadline)
        touched = sorted({q for p in hit.tolist() for t in prob.passes[p].tasks.tolist()
                          for q in prob.task_passes[t].tolist()})
        self.descend(trial, touched, deadline)
        if trial.value >= self.best.value - 1e-9:
            self.battery_repair(trial)
            if trial.value >= self.best.value - 1e-9:
                if trial.value > self.best.value + 1e-9:
                    self.keep(trial)
                else:
                    self.best = trial

    def run(self) -> Primal:
        cfg, prob = self.cfg, self.prob
        deadline = None if cfg.time_limit is None else self.t0 + cfg.time_limit
        rng = np.random.default_rng(cfg.seed if self.start_round == 0 else [cfg.seed, self.start_round])
        order = np.argsort(prob.pass_time[:, 0], kind="stable")
        first = self.empty()
        try:  # Ctrl-C while the first schedule is built: the passes built so far are the answer
            if self.initial is not None:  # start from the given schedule (its paths re-walked unless frozen)
                for p in np.flatnonzero(~self.frozen).tolist():
                    path = self.initial.paths[p]
                    free = self._available(first, p)[prob.passes[p].graph.node_acq[path]] if len(path) else path
                    self._assign(first, p, rewalk(prob.passes[p], path[free]) if len(path) else path)
            else:
                self.construct(order, primal=first)
            self.descend(first, list(range(len(prob.passes))), deadline)
        except KeyboardInterrupt:
            self.interrupted = True
        self.offer(first, time.perf_counter() if self.interrupted else None)  # repaired, not improved, after Ctrl-C
        if not self.interrupted:
            try:
                self._rounds(deadline, rng)
            except KeyboardInterrupt:  # Ctrl-C: the best schedule so far is the answer
                self.interrupted = True
        return self.best

    def _rounds(self, deadline: float | None, rng: np.random.Generator) -> None:
        cfg = self.cfg
        rounds = self.start_round
        self.rounds_done = rounds
        while cfg.rounds is None or rounds < cfg.rounds:
            if deadline is not None and time.perf_counter() > deadline:
                break
            if self.best_bound <= self.best.value + 1e-9:
                break  # proven optimal (energy relaxed in the bound, kept in the schedule)
            if cfg.pass_solver == "exact" or rounds == 0:
                before = self.best_bound
                t_round = time.perf_counter()
                if self.price_round(deadline) is None:
                    break
                self.round_s.append(time.perf_counter() - t_round)
                self.prices.stalled(self.best_bound < before - 1e-9)
                self.record()
                if not self.offer(self.recover(rng, deadline)):
                    self.neighbourhood(rng, deadline)
            else:
                self.neighbourhood(rng, deadline)
            rounds += 1
            self.rounds_done = rounds
            if self.on_round is not None:
                self.on_round(self)

    @property
    def bound(self) -> float:
        """The best proven bound: the Lagrangian one when every pass term of a price round was proven (exact pass
        solver; each pass's term its priced optimum where its graph serves the bound, else its bound problem, see
        :func:`eosp.fleet.passgraph.bound_problem`), else the conflict-free bound (every task that has an
        opportunity, served once).  Energy is relaxed.  With frozen passes the Lagrangian bound holds for the
        schedules that keep them as given."""
        return self.best_bound
