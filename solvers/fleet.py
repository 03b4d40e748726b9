"""The fleet solver: a constellation's passes solved by the project's single-pass solvers, coordinated by
task prices, with an upper bound.

A constellation-day is hundreds of passes (:mod:`eosp.fleet.passgraph`) coupled by one constraint: a task is
served at most once (and each satellite's battery runs from one pass to the next).  Relaxing "at most once"
with a price ``lam[i] >= 0`` per task separates the passes: each pass is solved on its own with utilities
``w[i] - lam[i]`` (tasks whose priced utility is not positive are left out), and

    L(lam) = sum over passes of (the pass optimum under lam) + sum of lam

bounds the weight any schedule can serve (energy relaxed).  When every pass term is an optimum the exact solver
proved, or a bound it proved, L is proven; the prices move by subgradient steps (Polyak's rule towards the
best schedule known) and the best L is kept.

Schedules come from the same pass solver with true weights:

* construction: passes in time order, each solved with the tasks not yet served;
* coordinate descent: a pass is solved again with every task not served by another pass; its new schedule is
  never worse, and the tasks it frees make the passes that hold them worth solving again (a queue);
* large neighbourhoods: the tasks of the passes meeting a random time span are freed, those passes are solved
  again in an order and with utilities perturbed by the prices (a contested task is left to the others when
  its price is high), coordinate descent follows, and the result is kept when it serves at least as much.

Each schedule is checked against the battery with the checker's model; a satellite that runs dry loses its
least valuable observations before the failure (and those tasks are barred from that satellite's passes in
later rounds).  The final schedule is checked by the checker before it is returned.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from eosp.config import WEEK_S, choice, ranged
from eosp.fleet.battery import SunCache
from eosp.fleet.geometry import Geometry
from eosp.fleet.greedy import Timeline, repair_battery, to_schedule
from eosp.fleet.model import Fleet, Schedule
from eosp.fleet.opportunities import Opportunities
from eosp.fleet.passgraph import PassGraph, build_passes, priced_instance
from eosp.graphs.prune import fifo_violations
from eosp.fleet.slew import LineOfSight

PASS_SOLVERS = ("greedy", "ramp", "exact")
LEARNED_PASS_SOLVERS = ("policy",)  # no model is trained on fleet passes yet: refused with one line


@dataclass
class FleetConfig:
    """Options of the fleet solver (``eosp solve FLEET_DIR --solver fleet``)."""

    pass_solver: str = choice("exact", *PASS_SOLVERS, *LEARNED_PASS_SOLVERS)
    """Single-pass solver of every pass: exact (optima, hence a proven Lagrangian bound), ramp or greedy (the
    conflict-free bound only); policy needs a model trained on fleet passes, which is not shipped yet."""
    time_limit: float = ranged(60.0, 0, WEEK_S, lo_open=True)
    """Seconds of search after the pass graphs are built (not applied with --rounds)."""
    rounds: int | None = ranged(None, 1)
    """Price rounds, each followed by a large-neighbourhood move; unset: as many as the time limit allows.  A run
    with a number of rounds ignores the time limit and is deterministic for a seed."""
    seed: int = ranged(0, 0)
    """Seed of the large-neighbourhood moves."""
    pass_time_limit: float = ranged(5.0, 0, WEEK_S)
    """Seconds the exact solver may spend on one pass (its bound is used when it stops early)."""
    span_s: float = ranged(3600.0, 1)
    """Length of the time span freed by one large-neighbourhood move."""
    workers: int = ranged(1, 1, 256)
    """Processes solving the passes of a price round (forked from this one, the pass graphs shared)."""


@dataclass
class PassResult:
    nodes: np.ndarray  # pass-graph node ids, in order
    value: float  # under the utilities it was solved with
    bound: float | None  # a proven upper bound of that value, None when the solver gives none


@dataclass
class Problem:
    """A fleet, its opportunities and its pass graphs, built once."""

    fleet: Fleet
    opps: Opportunities
    geo: Geometry
    los: LineOfSight
    passes: list[PassGraph]
    weight: np.ndarray  # float64 [tasks]
    task_passes: list[np.ndarray]  # passes holding each task
    pass_time: np.ndarray  # (first start, last end) of each pass, seconds
    fifo_violations: int = 0  # see eosp.graphs.prune.fifo_violations: 0 makes the pass optima the passes'
    build_s: float = 0.0

    @classmethod
    def build(cls, fleet: Fleet, opps: Opportunities, geo: Geometry | None = None) -> Problem:
        t0 = time.perf_counter()
        geo = geo or Geometry(fleet)
        los = LineOfSight(fleet, geo)
        passes = build_passes(fleet, opps, los)
        n = len(fleet.tasks)
        holders: list[list[int]] = [[] for _ in range(n)]
        for pg in passes:
            for t in pg.tasks.tolist():
                holders[t].append(pg.pass_id)
        span = np.array([[pg.graph.node_time[1:].min(),
                          (pg.graph.node_time[1:] + pg.duration[pg.graph.node_acq[1:]]).max()] for pg in passes])
        span = span.reshape(-1, 2)
        fifo = sum(fifo_violations(pg.graph) for pg in passes)
        return cls(fleet, opps, geo, los, passes, fleet.tasks.weight.astype(np.float64),
                   [np.asarray(h, dtype=np.int64) for h in holders], span, fifo, time.perf_counter() - t0)

    @property
    def total_weight(self) -> float:
        return float(self.weight.sum())


def solve_pass(prob: Problem, p: int, value: np.ndarray, cfg: FleetConfig) -> PassResult:
    """Pass `p` with utility `value[a]` per local task (non-positive ones left out)."""
    return solve_pass_graph(prob.passes[p], value, cfg)


def solve_pass_graph(pg: PassGraph, value: np.ndarray, cfg: FleetConfig) -> PassResult:
    """One pass graph with utility `value[a]` per local task: what a worker holding the graph runs."""
    from eosp.solvers.base import run_solver

    pp = priced_instance(pg, value)
    if pp is None:
        return PassResult(np.zeros(0, np.int64), 0.0, 0.0)
    opts = {"time_limit": cfg.pass_time_limit} if cfg.pass_solver in ("exact", "ramp") else {}
    sol = run_solver(cfg.pass_solver, pp.instance, mode="utility", **opts)
    bound = None
    if cfg.pass_solver == "exact":
        bound = sol.value if sol.info.get("status") == "optimal" else float(sol.info.get("bound", math.inf))
    return PassResult(pp.nodes[np.asarray(sol.nodes, dtype=np.int64)], float(sol.value), bound)


def rewalk(pg: PassGraph, path: np.ndarray) -> np.ndarray:
    """The acquisitions of `path` (pass-graph nodes, in order) followed along the graph's arcs from the source:
    each at its earliest node after the previous one; one that cannot follow is skipped."""
    g = pg.graph
    out, node = [], 0
    for acq in g.node_acq[path].tolist():
        nxt = g.successor(node, acq)
        if nxt >= 0:
            out.append(nxt)
            node = nxt
    return np.asarray(out, dtype=np.int64)


_POOL_PROBLEM: Problem | None = None  # the problem a forked worker inherits
_POOL_CFG: FleetConfig | None = None


def _ignore_sigint() -> None:
    """A pool worker leaves Ctrl-C to its parent (a terminal sends SIGINT to the whole process group): the parent
    keeps the best schedule and terminates the pool, instead of every worker printing a traceback."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _solve_chunk(args: tuple[list[int], list[np.ndarray]]) -> list[PassResult]:
    passes, utils = args
    return [solve_pass(_POOL_PROBLEM, p, u, _POOL_CFG) for p, u in zip(passes, utils)]


class PassPool:
    """Processes that solve passes under given utilities.  They are forked once the pass graphs are built, so
    every worker holds them without any copy; a round sends only pass ids and utilities, and gets paths back."""

    def __init__(self, prob: Problem, cfg: FleetConfig):
        import multiprocessing

        global _POOL_PROBLEM, _POOL_CFG
        _POOL_PROBLEM, _POOL_CFG = prob, cfg
        self.workers = cfg.workers
        self.pool = multiprocessing.get_context("fork").Pool(cfg.workers, initializer=_ignore_sigint)

    def solve(self, passes: list[int], utils: list[np.ndarray],
              deadline: float | None) -> dict[int, PassResult] | None:
        """Every pass of `passes` (in chunks, about four per worker); None when the deadline came first."""
        n = max(1, len(passes) // (4 * self.workers))
        chunks = [(passes[i:i + n], utils[i:i + n]) for i in range(0, len(passes), n)]
        job = self.pool.map_async(_solve_chunk, chunks)
        timeout = None if deadline is None else max(0.0, deadline - time.perf_counter())
        import multiprocessing

        try:
            results = job.get(timeout)
        except multiprocessing.TimeoutError:
            return None
        return {p: r for chunk, res in zip(chunks, results) for p, r in zip(chunk[0], res)}

    def close(self) -> None:
        self.pool.terminate()
        self.pool.join()


@dataclass
class Primal:
    """A schedule as pass paths; ``served[i]`` = pass serving task i, or -1."""

    paths: list[np.ndarray]
    served: np.ndarray
    value: float = 0.0

    def copy(self) -> Primal:
        return Primal(list(self.paths), self.served.copy(), self.value)


def path_tasks(prob: Problem, p: int, path: np.ndarray) -> np.ndarray:
    pg = prob.passes[p]
    return pg.tasks[pg.graph.node_acq[path]]


@dataclass
class Coordinator:
    """Prices, the best schedule and the best bound of one solve (see the module docstring)."""

    prob: Problem
    cfg: FleetConfig
    lam: np.ndarray = field(init=False)
    best: Primal = field(init=False)
    best_bound: float = math.inf
    barred: np.ndarray = field(init=False)  # [satellite, task]: taken out of that satellite by the battery repair
    history: list[tuple[float, float, float]] = field(default_factory=list)  # (seconds, value, bound)
    t0: float = field(default_factory=time.perf_counter)
    pass_solves: int = 0
    step: float = 1.0  # Polyak step factor, halved when the bound stalls
    rounds_done: int = 0
    interrupted: bool = False
    bound_source: str = "conflict-free"  # until a proven Lagrangian bound is lower

    pool: PassPool | None = None  # workers for the price rounds: processes (--workers > 1) or Ray actors
    on_round: Callable[[Coordinator], None] | None = None  # called after every round (checkpoints, MLflow)
    start_round: int = 0  # rounds a resumed run has done already
    round_s: list[float] = field(default_factory=list)  # wall seconds of every finished price round
    initial: Primal | None = None  # a schedule to start from (--init)
    frozen: np.ndarray | None = None  # bool per pass: kept as in `initial`, never solved again (--freeze-until)

    def __post_init__(self) -> None:
        n = len(self.prob.fleet.tasks)
        self.lam = np.zeros(n)
        self.round_paths = [np.zeros(0, np.int64)] * len(self.prob.passes)
        self.best = Primal([np.zeros(0, np.int64)] * len(self.prob.passes), np.full(n, -1, np.int64))
        self.barred = np.zeros((len(self.prob.fleet.satellites), n), dtype=bool)
        if self.frozen is None:
            self.frozen = np.zeros(len(self.prob.passes), dtype=bool)
        self.sun = SunCache(self.prob.geo)  # sunlight, computed once for every battery simulation
        self.battery_ok: dict[int, tuple] = {}  # satellite -> the timeline last found to hold its battery
        # the conflict-free bound: every task that has an opportunity, served once
        served_somewhere = np.array([len(h) > 0 for h in self.prob.task_passes], dtype=bool)
        self.best_bound = float(self.prob.weight[served_somewhere].sum())

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
        primal = primal or Primal([np.zeros(0, np.int64)] * len(self.prob.passes),
                                  np.full(len(w), -1, np.int64))
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
        """Every pass under the current prices; returns L(lam) (None when cut by the deadline), moves prices."""
        w = self.prob.weight
        count = np.zeros(len(w))
        total = float(self.lam.sum())
        proven = True
        todo = np.flatnonzero(~self.frozen).tolist()
        solved = None
        if self.pool is not None:
            if hasattr(self.pool, "solve_priced"):  # workers that hold the weights take the prices alone
                solved = self.pool.solve_priced(todo, self.lam, deadline)
            else:
                solved = self.pool.solve(todo, [w[self.prob.passes[p].tasks] - self.lam[self.prob.passes[p].tasks]
                                                for p in todo], deadline)
            if solved is None:
                return None  # cut by the deadline
            self.pass_solves += len(todo)
        for p, pg in enumerate(self.prob.passes):
            if deadline is not None and time.perf_counter() > deadline:
                return None
            if self.frozen[p]:  # a fixed term: its schedule under the prices
                kept = path_tasks(self.prob, p, self.initial.paths[p])
                res = PassResult(self.initial.paths[p], float((w[kept] - self.lam[kept]).sum()), None)
                res.bound = res.value
            elif solved is not None:
                res = solved[p]
            else:
                res = self._solve(p, w[pg.tasks] - self.lam[pg.tasks])
            self.round_paths[p] = res.nodes
            if res.bound is None:
                proven = False
                total += res.value
            else:
                total += res.bound
            count[path_tasks(self.prob, p, res.nodes)] += 1
        if proven and self.prob.fifo_violations == 0 and total < self.best_bound:
            self.best_bound, self.bound_source = total, "lagrangian"
        g = 1.0 - count
        g[(self.lam <= 0) & (g > 0)] = 0.0  # a free task at price 0 cannot go lower
        norm2 = float(g @ g)
        if norm2 > 0:
            step = self.step * max(total - self.best.value, 1e-6 * total) / norm2
            self.lam = np.maximum(0.0, self.lam - step * g)
        return total

    def empty(self) -> Primal:
        """No observation, except those of the frozen passes."""
        n_pass = len(self.prob.passes)
        primal = Primal([np.zeros(0, np.int64)] * n_pass, np.full(len(self.prob.weight), -1, np.int64))
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
        prob = self.prob
        step = prob.fleet.horizon.action_step_s
        tls = [Timeline() for _ in range(len(prob.fleet.satellites))]
        for p, pg in enumerate(prob.passes):
            path = primal.paths[p]
            if len(path) == 0:
                continue
            rows = pg.rows[path - 1]
            task = prob.opps.task[rows]
            st = prob.opps.start[rows].astype(np.float64) * step
            en = st + prob.fleet.tasks.duration_s[task]
            l0, l1 = prob.los.los(pg.satellite, task, st), prob.los.los(pg.satellite, task, en)
            tl = tls[pg.satellite]
            for k in range(len(rows)):
                tl.insert(len(tl.start), (float(st[k]), float(en[k]), int(task[k]), l0[k], l1[k]))
        for tl in tls:  # passes of a satellite are in time order already; keep it explicit
            order = np.argsort(np.asarray(tl.start), kind="stable")
            for col in (tl.start, tl.end, tl.task, tl.los0, tl.los1):
                col[:] = [col[i] for i in order]
        return tls

    def schedule(self, primal: Primal) -> Schedule:
        return to_schedule(self.prob.fleet, self.timelines(primal))

    # ------------------------------------------------------------------ the loop
    def record(self) -> None:
        self.history.append((time.perf_counter() - self.t0, self.best.value, self.best_bound))

    def offer(self, primal: Primal, deadline: float | None = None) -> bool:
        """Keep `primal` (after battery repair) when it serves more than the best."""
        self.battery_repair(primal, deadline)
        if primal.value > self.best.value + 1e-9:
            self.best = primal
            self.record()
            return True
        return False

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
        shift = self.lam * rng.uniform(0.0, 1.0)
        self.construct(order, shift, trial, deadline)
        touched = sorted({q for p in hit.tolist() for t in prob.passes[p].tasks.tolist()
                          for q in prob.task_passes[t].tolist()})
        self.descend(trial, touched, deadline)
        if trial.value >= self.best.value - 1e-9:
            self.battery_repair(trial)
            if trial.value >= self.best.value - 1e-9:
                improved = trial.value > self.best.value + 1e-9
                self.best = trial
                if improved:
                    self.record()

    def run(self) -> Primal:
        cfg, prob = self.cfg, self.prob
        deadline = None if cfg.rounds is not None else self.t0 + cfg.time_limit
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
        rounds, stall = self.start_round, 0
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
                stall = 0 if self.best_bound < before - 1e-9 else stall + 1
                if stall >= 3:
                    self.step, stall = self.step / 2, 0
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
        solver) and every pass graph is FIFO (:func:`eosp.graphs.prune.fifo_violations`), else the
        conflict-free bound (every task that has an opportunity, served once)."""
        return self.best_bound


@dataclass
class FleetSolution:
    """The best schedule, the value and bound as fractions of the total weight (WCR), and the run's record."""

    schedule: Schedule
    value: float
    bound: float | None
    history: list[tuple[float, float, float]]
    info: dict

    @property
    def gap(self) -> float | None:
        return None if self.bound is None or self.bound <= 0 else (self.bound - self.value) / self.bound


def primal_of(prob: Problem, sched: Schedule) -> Primal:
    """A schedule as pass paths: each action at its opportunity's node (an action that is no opportunity, or a
    task's second observation, is left out)."""
    f, o = prob.fleet, prob.opps
    step_us = f.horizon.action_step_s * 1_000_000
    row_of = {key: r for r, key in enumerate(zip(o.task.tolist(), o.satellite.tolist(), o.start.tolist()))}
    node_of = np.zeros(len(o), dtype=np.int64)
    for pg in prob.passes:
        node_of[pg.rows] = np.arange(1, len(pg.rows) + 1)
    ti, si = f.task_index(), f.satellite_index()
    per_pass: dict[int, list[tuple[int, int]]] = {}
    seen = set()
    for sat, task, st in zip(sched.satellite.tolist(), sched.task.tolist(), sched.start_us.tolist()):
        r = row_of.get((ti.get(task, -1), si.get(sat, -1), int(st // step_us)))
        if r is None or task in seen or st % step_us:
            continue
        seen.add(task)
        per_pass.setdefault(int(o.pass_id[r]), []).append((int(st), int(node_of[r])))
    primal = Primal([np.zeros(0, np.int64)] * len(prob.passes), np.full(len(f.tasks), -1, np.int64))
    for p, acts in per_pass.items():
        path = np.asarray([n for _, n in sorted(acts)], dtype=np.int64)
        tasks = path_tasks(prob, p, path)
        primal.paths[p] = path
        primal.served[tasks] = p
        primal.value += float(prob.weight[tasks].sum())
    return primal


@dataclass
class Resume:
    """Where a stopped run was (saved after every round by a job): prices, step, best bound, rounds done.  Its
    best schedule is passed as the `initial` schedule of :func:`solve`."""

    lam: np.ndarray
    step: float
    best_bound: float
    bound_source: str
    rounds_done: int


def solve(fleet: Fleet, opps: Opportunities, cfg: FleetConfig | None = None, problem: Problem | None = None,
          initial: Schedule | None = None, freeze_until_s: float | None = None, pool=None,
          on_round: Callable[[Coordinator], None] | None = None, resume: Resume | None = None) -> FleetSolution:
    """Schedule a fleet (see the module docstring); the schedule is checked by the checker before it is returned,
    and an action it rejects is dropped (never expected: the pass graphs and the battery repair use its rules).

    `initial`: a schedule to start from; `freeze_until_s`: the passes starting before this time (seconds from
    the horizon start) keep the initial schedule's actions as they are (so every action before it is kept).
    `pool`: what solves the passes of a price round (anything with PassPool's ``solve``, or ``solve_priced(passes,
    prices, deadline)``, and ``close``, e.g. Ray actors; default: forked processes when ``cfg.workers > 1``); `on_round`: called after every round;
    `resume`: prices and bound of a stopped run (its best schedule as `initial`)."""
    from eosp.fleet.check import validate

    cfg = cfg or FleetConfig()
    prob = problem or Problem.build(fleet, opps)
    start = None if initial is None else primal_of(prob, initial)
    frozen = None
    if freeze_until_s is not None:
        frozen = prob.pass_time[:, 0] < freeze_until_s
        start = start or Primal([np.zeros(0, np.int64)] * len(prob.passes), np.full(len(fleet.tasks), -1, np.int64))
    own_pool = pool is None and cfg.workers > 1
    pool = PassPool(prob, cfg) if own_pool else pool
    coord = Coordinator(prob, cfg, pool=pool, initial=start, frozen=frozen, on_round=on_round)
    if resume is not None:
        if len(resume.lam) != len(fleet.tasks):
            raise ValueError("resume: prices of another fleet")
        coord.lam, coord.step, coord.start_round = resume.lam.astype(np.float64), resume.step, resume.rounds_done
        if resume.best_bound < coord.best_bound:
            coord.best_bound, coord.bound_source = resume.best_bound, resume.bound_source
    try:
        best = coord.run()
    finally:
        if own_pool:
            pool.close()
    sched = coord.schedule(best)
    res = validate(fleet, sched, prob.geo)
    dropped = 0
    while not res.valid and len(sched):
        bad = sorted({v.action for v in res.violations if v.action >= 0}) or [0]
        keep = np.setdiff1d(np.arange(len(sched)), bad)
        sched = Schedule(sched.satellite[keep], sched.task[keep], sched.start_us[keep], sched.end_us[keep])
        dropped += len(bad)
        res = validate(fleet, sched, prob.geo)
    W = prob.total_weight
    bound = coord.bound
    info = {"pass_solver": cfg.pass_solver, "rounds": coord.rounds_done, "pass_solves": coord.pass_solves,
            "passes": len(prob.passes), "build_s": round(prob.build_s, 3), "checker_drops": dropped,
            "battery_barred": int(coord.barred.sum()), "metrics": res.metrics, "interrupted": coord.interrupted,
            "bound_source": coord.bound_source, "price_round_s": [round(x, 4) for x in coord.round_s],
            "no_lagrangian_bound_because": None if coord.bound_source == "lagrangian" else (
                f"pass solver {cfg.pass_solver} proves no pass bound" if cfg.pass_solver != "exact"
                else "a pass graph is not FIFO" if prob.fifo_violations
                else "none was lower than the conflict-free bound" if coord.rounds_done
                else "none needed: the conflict-free bound is met" if coord.best_bound <= coord.best.value + 1e-9
                else "no price round finished")}
    hist = [(t, v / W, b / W) for t, v, b in coord.history]
    return FleetSolution(sched, float(res.metrics.get("WCR", 0.0)), min(1.0, bound / W) if W > 0 else 0.0, hist, info)
