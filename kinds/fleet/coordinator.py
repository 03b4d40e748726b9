"""The fleet solver's coordinator: a constellation's passes solved by the project's single-pass solvers, held
together by task prices (:mod:`eosp.kinds.fleet.prices`), with an upper bound.

A constellation-day is hundreds of passes (:mod:`eosp.fleet.passgraph`) coupled by two constraints: a task is
served at most once, and each satellite's battery runs from one pass to the next (its consequences as energy
windows over runs of passes, :mod:`eosp.fleet.energy`).  Relaxing both with prices separates the passes; a
price round solves every pass under the prices on a pass pool (:mod:`eosp.kinds.fleet.pool`), proves the
Lagrangian bound when every pass term is an optimum or a bound the exact solver proved, and moves the prices.
Before the first round the bound is also taken at the ceiling prices (every contested task at its weight,
:meth:`Coordinator.ceiling_round`), never above the conflict-free bound and cheap to compute.

Schedules come from the same pass solver with true weights:

* construction: passes in time order, each solved with the tasks not yet served (in waves of passes that share
  no task with a pass before them, solved together on the pass pool: the same schedule, :meth:`Coordinator.construct`);
* coordinate descent: a pass is solved again with every task not served by another pass; its new schedule is
  never worse, and the tasks it frees make the passes that hold them worth solving again.  It runs as sweeps
  on the pass pool (:meth:`Coordinator.descend`): the passes waiting are solved together from one schedule,
  then settled in pass order (a task a lower pass took meanwhile is taken out of a result, which is then kept
  only when still better), so the sweep is spread over the workers and its result is the same for any number
  of them;
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

import numba
import numpy as np

from eosp.fleet.check import validate
from eosp.fleet.energy import EnergyWindows
from eosp.fleet.timeline import Rows, Timeline, repair_rows, timeline, to_schedule
from eosp.fleet.model import Schedule
from eosp.kinds.fleet.config import FleetConfig
from eosp.interrupt import HeldInterrupt
from eosp.kinds.fleet.master import Centre, Master
from eosp.kinds.fleet.pool import InProcessPool, PassPool
from eosp.kinds.fleet.prices import Prices
from eosp.kinds.fleet.problem import (PassResult, Primal, Problem, path_tasks, path_wh, priced,
                                      schedule_windows, solve_pass)

CHECK_MARGIN = 1.5  # the final check's estimate times this (a better schedule has more actions, a loaded machine)
MASTER_MIN_S = 1.0  # seconds a master LP solve may always take (else at most the round's pass solves' time)
MASTER_MIN_ITERATIONS = 1000  # simplex iterations a master LP solve may always take when rounds are fixed
MASTER_PATIENCE = 3  # master solves in a row cut by that time before the master is dropped (weighted steps then;
# before a first solve has finished in its time, one miss drops it)
ENERGY_STEPS = 12  # bisection steps of an energy window's multiplier (Coordinator.energy_search)
CHECK_SLACK_S = 0.2  # seconds added to it (the time the first steps after the deadline take)
INTEGER_MAX_S = 30.0  # seconds the master's integer solution may take at most (Coordinator.integer_round)
INTEGER_NODES = 200  # its branch-and-bound nodes when the solve has no time limit (--rounds): machine-independent
REPAIR_AWAY = 4  # a battery repair of fewer satellites runs on the driver, not on the pool (a round trip costs
# milliseconds, a satellite's simulation about one)
SWEEP_IN_PROCESS = 32  # a descent sweep of fewer passes is solved on the driver, not sent to the pool (a Ray
# round trip costs milliseconds, a small pass under true weights 0.02-0.6 ms: docs/results.md; at 200 satellites on
# two actors, 8 sent the first schedule's small waves to the actors and cost it 16 s)


def csr_take(ptr: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows `rows` of a CSR layout with pointers `ptr`: the positions of their entries, one flat vector in the
    order of `rows`, and its offsets by row."""
    lens = ptr[rows + 1] - ptr[rows]
    offsets = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum(lens, out=offsets[1:])
    return np.repeat(ptr[rows] - offsets[:-1], lens) + np.arange(offsets[-1]), offsets


@numba.njit(cache=True)
def _take(order, ptr, idx, claimed, in_order, open_):
    """Mask of `order` (pass ids): each pass taken when it shares no open task (`open_`, bool per task) with a pass
    taken before it, or, with `in_order`, with any pass before it, taken or not; `claimed` (bool per task) is left
    all False."""
    take = np.zeros(len(order), dtype=np.bool_)
    for i in range(len(order)):
        p = order[i]
        free = True
        for j in range(ptr[p], ptr[p + 1]):
            if claimed[idx[j]] and open_[idx[j]]:
                free = False
                break
        take[i] = free
        if free or in_order:
            for j in range(ptr[p], ptr[p + 1]):
                claimed[idx[j]] = True
    for i in range(len(order)):
        p = order[i]
        for j in range(ptr[p], ptr[p + 1]):
            claimed[idx[j]] = False
    return take


def disjoint(queued, ptr, idx, claimed, open_):
    """Mask of `queued` (ascending pass ids): each pass taken when it shares no open task (`open_`: bool per task,
    those no pass serves) with a pass taken before it: a sweep's batch whose results cannot conflict, since a
    pass of the batch can take only a task no pass serves at the batch's start (one another pass serves is worth
    0 to it); `claimed` (bool per task) is left all False.

    Why open tasks only: a freed task queues every pass that can serve it, and once one of them has taken it
    again the others still share it; counted, they would be solved one per sweep (hundreds of sweeps of a pass or
    two, each a round trip to the pool on a lean driver)."""
    return _take(queued, ptr, idx, claimed, False, open_)


def wave(order, ptr, idx, claimed):
    """Mask of `order` (pass ids): each pass taken when it shares no task with any pass before it in `order`,
    taken or not (the passes a one-by-one construction in that order would solve from the same state);
    `claimed` (bool per task) is left all False.  The first pass is always taken."""
    return _take(order, ptr, idx, claimed, True, np.ones(len(claimed), dtype=np.bool_))


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
    prefetched: int = 0  # price rounds whose passes were sent before the recovery of the round before (prefetch)
    repair_drops: int = 0  # observations the battery repair took out, over the whole run
    first_repair_drops: int | None = None  # those it took out of the first schedule
    rounds_done: int = 0
    first_s: float | None = None  # seconds from t0 to the first schedule (repaired)
    check_s: float = 0.0  # seconds kept before the deadline for the final check (check_estimate)
    interrupted: bool = False
    bound_source: str = "conflict-free"  # until a proven Lagrangian bound is lower
    refused: list[str] = field(default_factory=list)  # Lagrangian bounds refused, and why (see price_round)

    pool: PassPool | None = None  # what solves the passes of a price round (default: this process)
    on_round: Callable[[Coordinator], None] | None = None  # called after every round (checkpoints, MLflow)
    start_round: int = 0  # rounds a resumed run has done already
    round_s: list[float] = field(default_factory=list)  # wall seconds of every finished price round
    # where each round's wall time went (seconds): waiting for the price round's passes ("round"), the master LP
    # and the price step ("prices"), the recovery, the battery repair of what it recovered, the neighbourhood
    # moves, and of these the time spent waiting for sweeps and waves on the pool ("pool", in "pool_calls" calls)
    phases: list[dict] = field(default_factory=list)
    initial: Primal | None = None  # a schedule to start from (--init)
    frozen: np.ndarray | None = None  # bool per pass: kept as in `initial`, never solved again (--freeze-until)

    def __post_init__(self) -> None:
        n = len(self.prob.fleet.tasks)
        self.windows = self.prob.windows if self.cfg.energy_bound else EnergyWindows.none(len(self.prob.passes))
        self.prices = Prices.zero(n, self.windows)
        self.master = Master(self.prob) if self.cfg.price_step == "lp" else None  # the LP of --price-step lp
        self.centre = Centre(np.zeros(n))  # the prices of the lowest L (set by the first round)
        self._start_lam = None  # the prices of the first price round (where the master's fallback starts)
        self.converged = False  # --price-step lp: the bound is L's minimum; rounds are moves only from then on
        self._lp_misses = 0  # master solves in a row that did not finish in their time (MASTER_PATIENCE)
        self._lp_solved = False  # whether a master solve ever finished in its time (else one miss drops it)
        self.integer_done = False  # whether the master's integer solution was tried (once, when converged)
        self._pending = None  # (prices, pass prices, result, when sent) of a price round sent ahead (prefetch)
        self._pool_s = 0.0  # seconds waited for sweeps and waves on the pool (see phases)
        self._pool_calls = 0  # sweeps and waves sent to the pool (see phases)
        self._wait_s = 0.0  # seconds the last price round waited for its passes
        self._solve_s = 0.0  # seconds the last price round's pass solves took (the master LP's time limit)
        self._pass_sat = np.array([pg.satellite for pg in self.prob.passes], dtype=np.int64)
        self._terms = np.zeros(len(self.prob.passes))  # the pass terms of the last price round
        self._no_shift = np.zeros(n)  # zero task prices, made once (a descent sweep prices every pass twice)
        lens = np.array([len(pg.tasks) for pg in self.prob.passes], dtype=np.int64)
        self._task_ptr = np.r_[0, np.cumsum(lens)].astype(np.int64)  # the passes' tasks, CSR (disjoint batches)
        self._task_idx = (np.concatenate([pg.tasks for pg in self.prob.passes]).astype(np.int64) if len(lens)
                          else np.zeros(0, np.int64))
        self._task_wh = (np.concatenate([pg.energy_wh for pg in self.prob.passes]).astype(np.float64) if len(lens)
                         else np.zeros(0))  # each pass task's least energy, as _task_idx
        self._claimed = np.zeros(n, dtype=np.bool_)
        # every pass's nodes' acquisitions, one flat vector (a round's serve counts and energies as arrays)
        self._node_ptr = np.r_[0, np.cumsum([len(pg.graph.node_acq) for pg in self.prob.passes])].astype(np.int64)
        self._node_acq = (np.concatenate([pg.graph.node_acq for pg in self.prob.passes]) if len(lens)
                          else np.zeros(0, np.int32))
        # the last proven-optimal solve of each pass under true weights (a sweep's or a wave's): its utilities, in
        # the passes' task CSR (NaN: none, never equal), and its result (see _solve_batch)
        self._memo_util = np.full(len(self._task_idx), np.nan)
        self._memo_res: list[PassResult | None] = [None] * len(self.prob.passes)
        self._memo_ok = np.zeros(len(self.prob.passes), dtype=bool)  # whether _memo_res holds a pass's result
        self.memo_hits = 0  # pass solves a sweep or wave took from the memo instead of solving again
        self.spend = np.zeros(len(self.prob.passes))  # price of a Wh in each pass for the schedules (energy_price)
        self.pool = self.pool or InProcessPool(self.prob, self.cfg)
        self.round_paths = [np.zeros(0, np.int64)] * len(self.prob.passes)
        self.best = Primal.empty(len(self.prob.passes), n)
        self.barred = np.zeros((len(self.prob.fleet.satellites), n), dtype=bool)
        if self.frozen is None:
            self.frozen = np.zeros(len(self.prob.passes), dtype=bool)
        self.sun = self.prob.sun  # sunlight, computed once for every battery simulation
        self.battery_ok: dict[int, bytes] = {}  # satellite -> its tasks and starts last found to hold its battery
        self.best_bound = self.conflict_free()

    # ------------------------------------------------------------------ pass solves
    def _utility(self, primal: Primal, p: int, shift: np.ndarray | None = None) -> np.ndarray:
        """The utilities of pass p's tasks for a schedule: weight, less `shift` (kept below the weight), less the
        pass's price of the energy they take (:attr:`spend`); 0 (left out) for a task another pass serves or the
        battery repair barred from this satellite."""
        pg = self.prob.passes[p]
        w = self.prob.weight
        shift = self._no_shift if shift is None else np.minimum(shift, 0.999 * w)
        util = priced(w, shift, pg.tasks, pg.energy_wh, self.spend[p])
        return np.where(self._available(primal, p), util, 0.0)

    def _path_utility(self, p: int, path: np.ndarray) -> float:
        """The utility :meth:`_utility` gives pass p's `path` (its tasks are its own)."""
        pg = self.prob.passes[p]
        acq = pg.graph.node_acq[path]
        return float(priced(self.prob.weight, self._no_shift, pg.tasks[acq], pg.energy_wh[acq], self.spend[p]).sum())

    def _available(self, primal: Primal, p: int) -> np.ndarray:
        tasks = self.prob.passes[p].tasks
        s = primal.served[tasks]
        return ((s < 0) | (s == p)) & ~self.barred[self.prob.passes[p].satellite, tasks]

    def _assign(self, primal: Primal, p: int, path: np.ndarray) -> list[int]:
        """Give pass p the schedule `path`; returns the tasks it freed.  Whole or not at all: a Ctrl-C waits for
        the end of the edit (the first schedule, interrupted while it is built, is the answer)."""
        old = path_tasks(self.prob, p, primal.paths[p])
        new = path_tasks(self.prob, p, path)
        mark = self._claimed  # all False between uses: the tasks of `old` not in `new` (no sort, a path's are unique)
        mark[new] = True
        freed = old[~mark[old]]
        mark[new] = False
        with HeldInterrupt():
            primal.served[freed] = -1
            primal.served[new] = p
            primal.paths[p] = path
            primal.value += float(self.prob.weight[new].sum() - self.prob.weight[old].sum())
        return freed.tolist()

    def descend(self, primal: Primal, queue: list[int], deadline: float | None) -> None:
        """Coordinate descent as a sweep: the queued passes (frozen ones skipped; those sharing no task that no
        pass serves, :func:`disjoint`) are solved as one batch with every task no other pass serves at the batch's
        start (utilities :meth:`_utility`), on the pool; then the results are settled here in ascending pass order
        (:meth:`_settle`).  Passes that gain freed tasks, and passes whose result lost tasks to a lower pass of the
        same batch (never with this batch rule; settled all the same), make the next batch; until none is left or
        the deadline.

        Why a sweep, not a queue of single solves: one pass after another, each seeing its predecessors'
        changes, is serial, and on a 200-satellite day it took half of a round on the driver whatever the number
        of workers.  Solved from one state, a batch's passes are independent, so the pool spreads them; the
        settling order (pass ids) and the deterministic solver make the schedule the same whoever solved each
        pass, for any number of workers.  Each settled change raises its pass's utility under the schedule and
        changes no other pass, so the descent ends; run to its end (no deadline, exact pass solver) no single pass,
        solved alone with the tasks no other pass serves, is worth more than its path (a fixed point of the
        serial descent too).  It takes more solves than the serial queue (a pass solved in a batch before a lower
        pass freed a task it can take is solved again): about a fifth more on aeossp cases."""
        n_pass = len(self.prob.passes)
        todo = np.zeros(n_pass, dtype=bool)
        todo[np.asarray(queue, dtype=np.int64)] = True
        while True:
            todo &= ~self.frozen
            queued = np.flatnonzero(todo)
            if len(queued) == 0:
                return
            if deadline is not None and time.perf_counter() > deadline:
                return
            open_ = primal.served < 0
            batch = queued[disjoint(queued, self._task_ptr, self._task_idx, self._claimed, open_)].tolist()
            solved = self._solve_batch(batch, *self._batch_utilities(primal, batch), deadline)
            if solved is None:
                return  # cut by the deadline: the schedule is as the last batch left it (every edit whole)
            todo[batch] = False
            for p in batch:
                self._settle(primal, p, solved[p].nodes, todo)

    def _settle(self, primal: Primal, p: int, path: np.ndarray, todo: np.ndarray) -> None:
        """Pass p's result of a sweep, against the schedule as the lower passes of the batch left it: the tasks
        another pass took meanwhile are taken out of `path` (the rest re-walked along the graph's arcs, so it
        stays feasible, :func:`eosp.kinds.fleet.problem.rewalk`), and the path is taken when it is worth more
        than the pass's current one under :meth:`_utility`.  Marks in `todo` the other passes that can take the
        tasks it freed, and p itself when it lost tasks (solved again with what is left)."""
        pg = self.prob.passes[p]
        again = bool(todo[p])  # a lower pass of the batch freed a task p can take
        # the common case near the end: nothing changes (a memo hit gives the very array the pass holds)
        if path is primal.paths[p] or np.array_equal(path, primal.paths[p]):
            todo[p] = again
            return
        if len(path):
            free = self._available(primal, p)[pg.graph.node_acq[path]]
            if not free.all():
                path = self.prob.rewalk(p, path[free])
                again = True
        if self._path_utility(p, path) > self._path_utility(p, primal.paths[p]) + 1e-9:
            for t in self._assign(primal, p, path):
                todo[self.prob.task_passes[t]] = True
        todo[p] = again  # not for the tasks p freed itself: it just chose without them

    def _batch_utilities(self, primal: Primal, batch: list[int],
                         shift: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_utility` of every pass of `batch` at once: one flat float64 vector and CSR offsets (the same
        numbers: weight less `shift` and the pass's price of the tasks' energy, 0 where another pass serves the task
        or the repair barred it), gathered from the passes' tasks as CSR instead of pass by pass."""
        b = np.asarray(batch, dtype=np.int64)
        pos, offsets = csr_take(self._task_ptr, b)
        tasks, owner = self._task_idx[pos], np.repeat(b, np.diff(offsets))
        w = self.prob.weight
        shift = self._no_shift if shift is None else np.minimum(shift, 0.999 * w)
        util = priced(w, shift, tasks, self._task_wh[pos], self.spend[owner])
        s = primal.served[tasks]
        free = ((s < 0) | (s == owner)) & ~self.barred[self._pass_sat[owner], tasks]
        return np.where(free, util, 0.0), offsets

    def _solve_batch(self, batch: list[int], util: np.ndarray, offsets: np.ndarray,
                     deadline: float | None) -> dict[int, PassResult] | None:
        """The passes of a sweep or a wave under their utilities (flat, CSR `offsets`).  A pass whose utilities
        are those of its last proven-optimal solve takes that solve's result (the memo); the others are solved on
        the pool, or here when they are few (:data:`SWEEP_IN_PROCESS`: a round trip would cost more than the
        solves; the exact solver gives the same paths anywhere) or a prefetched round holds the pool; always on
        the pool when the problem is lean (the driver holds no arcs).

        Why the memo: a pass's utilities under true weights change only when a task of its own changes hands,
        its satellite is barred from one, or its energy price moves; on a 200-satellite day 55% of the sweeps'
        and waves' solves saw the utilities of the pass's last solve.  The exact solver is deterministic, so the
        result is the one a new solve would give, wherever it ran: the schedules are unchanged, the solves fewer.
        Only results proven optimal are kept (a solve cut by its time limit could differ)."""
        b = np.asarray(batch, dtype=np.int64)
        pos, _ = csr_take(self._task_ptr, b)
        differ = np.r_[0, np.cumsum(util != self._memo_util[pos])]  # NaN (nothing kept) differs from any value
        hit = (differ[offsets[1:]] == differ[offsets[:-1]]) & self._memo_ok[b]
        out = {p: self._memo_res[p] for p in b[hit].tolist()}
        self.memo_hits += len(out)
        if hit.all():
            return out
        miss = np.flatnonzero(~hit)
        if len(out):  # the missing passes' utilities, as their own flat vector and offsets
            take, sub = csr_take(offsets, miss)
            batch, util, offsets = b[miss].tolist(), util[take], sub
        solved = self._solve_missing(batch, util, offsets, deadline)
        if solved is None:
            return None
        for i, p in enumerate(batch):
            res = solved[p]
            kept = res.bound is not None and res.value >= res.bound
            self._memo_res[p], self._memo_ok[p] = (res if kept else None), kept
            if kept:
                s = self._task_ptr[p]
                self._memo_util[s:s + offsets[i + 1] - offsets[i]] = util[offsets[i]:offsets[i + 1]]
        out.update(solved)
        return out

    def _solve_missing(self, batch: list[int], util: np.ndarray, offsets: np.ndarray,
                       deadline: float | None) -> dict[int, PassResult] | None:
        """The passes of :meth:`_solve_batch` the memo did not have, solved (here or on the pool)."""
        self.pass_solves += len(batch)
        if not self.prob.lean and (len(batch) < SWEEP_IN_PROCESS or self._pool_busy()):
            return {p: solve_pass(self.prob, p, util[offsets[i]:offsets[i + 1]], self.cfg, deadline)
                    for i, p in enumerate(batch)}
        t = time.perf_counter()
        self._pool_calls += 1
        try:
            return self.pool.solve_utilities(batch, util, offsets, deadline)
        finally:
            self._pool_s += time.perf_counter() - t

    def _pool_busy(self) -> bool:
        """Whether a prefetched price round still holds the pool (a sweep sent now would wait behind it).  Why ask:
        the actors finish the round while the driver recovers, and before, every sweep of the recovery and of the
        moves was solved on the driver for the rest of the round, the actors idle (a 200-satellite day on two
        actors: no sweep sent in 99 rounds)."""
        if self._pending is None:
            return False
        idle = getattr(self._pending[2], "idle", None)
        return idle is None or not idle()

    def construct(self, order: np.ndarray, util_shift: np.ndarray | None = None,
                  primal: Primal | None = None, deadline: float | None = None, whole: bool = False) -> Primal:
        """Passes in `order`, each solved with the tasks still free (utilities :meth:`_utility`, `util_shift`
        taken off the weights); stops at `deadline` unless `whole` (the first schedule: every pass, each solve
        then cut short past the deadline).

        Solved in waves (:func:`wave`): each wave the passes that share no task with a pass before them in `order`
        still waiting, solved together (on the pool when large) and assigned in order: a pass's utilities depend
        only on its own tasks, which nothing before it in the wave touches, so the schedule is the one-by-one
        construction's, whoever solves each pass."""
        primal = primal or Primal.empty(len(self.prob.passes), len(self.prob.weight))
        left = order[~self.frozen[order]]
        while len(left):
            if not whole and deadline is not None and time.perf_counter() > deadline:
                break
            take = wave(left, self._task_ptr, self._task_idx, self._claimed)
            batch = left[take].tolist()
            left = left[~take]
            util, offsets = self._batch_utilities(primal, batch, util_shift)
            solved = self._solve_batch(batch, util, offsets, deadline)
            if solved is None:
                if not whole:
                    break
                solved = self._solve_late(batch, util, offsets, deadline)
            for p in batch:
                self._assign(primal, p, solved[p].nodes)
        return primal

    def _solve_late(self, batch: list[int], util: np.ndarray, offsets: np.ndarray,
                    deadline: float) -> dict[int, PassResult]:
        """The passes of a wave of the first schedule that the deadline cut: every one solved all the same, here,
        each cut short (:func:`eosp.kinds.fleet.problem.pass_limit`: 10 ms past the deadline), or on the pool with
        no deadline (each within the pass time limit) when the problem is lean."""
        if self.prob.lean:
            return self.pool.solve_utilities(batch, util, offsets, None)
        return {p: solve_pass(self.prob, p, util[offsets[i]:offsets[i + 1]], self.cfg, deadline)
                for i, p in enumerate(batch)}

    # ------------------------------------------------------------------ prices and bound
    def _dual_round(self, lam: np.ndarray, deadline: float | None) -> tuple | None:
        """Every pass under task prices `lam` and the current energy multipliers (on the pool): L(lam, mu), whether
        every pass term is proven, each task's serve count, each pass's energy and path; None when cut by the
        deadline.  A price above its task's weight is taken at the weight: no pass takes the task either way (its
        utility is not positive), so the pass terms are the same and L is lower."""
        w = self.prob.weight
        lam = np.minimum(lam, w)
        pi = self.prices.pass_price()
        todo = np.flatnonzero(~self.frozen).tolist()
        pending, self._pending = self._pending, None
        t = time.perf_counter()
        if pending is not None and np.array_equal(pending[0], lam) and np.array_equal(pending[1], pi):
            solved = pending[2]()  # sent before the last recovery (prefetch): the same prices, the same passes
            self.prefetched += 1
            # the master's limit: what the round took on the pool (its busiest worker's solves), not the time
            # since it was sent (that counts the recovery it ran beside)
            self._solve_s = getattr(self.pool, "round_solve_s", None) or time.perf_counter() - pending[3]
        else:
            solved = self.pool.solve_priced(todo, lam, pi, deadline)
            self._solve_s = time.perf_counter() - t
        self._wait_s = time.perf_counter() - t
        if solved is None:
            return None  # cut by the deadline
        self.pass_solves += len(todo)
        paths = [np.zeros(0, np.int64)] * len(self.prob.passes)
        terms, proven = [], True
        for p in range(len(self.prob.passes)):
            if self.frozen[p]:  # a fixed term: its schedule under the prices
                pg, path = self.prob.passes[p], self.initial.paths[p]
                acq = pg.graph.node_acq[path]
                value = float(priced(w, lam, pg.tasks[acq], pg.energy_wh[acq], pi[p]).sum())
                res = PassResult(path, value, value)
            else:
                res = solved[p]
            paths[p] = res.nodes
            proven &= res.bound is not None
            terms.append(res.value if res.bound is None else res.bound)
        count, pass_wh = self._path_stats(paths)
        total = Prices(lam, self.prices.windows, self.prices.mu).dual(terms)
        self._terms = np.asarray(terms, dtype=np.float64)  # the round's pass terms (the energy search starts there)
        return total, proven, count, pass_wh, paths

    def _path_stats(self, paths: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Of one path per pass: how many paths serve each task (float64 per task), and each path's energy (the sum
        of its observations' least energy, :func:`eosp.kinds.fleet.problem.path_wh`): gathered from the flat
        node and task vectors at once, not pass by pass (at 200 satellites 13,152 passes a round)."""
        owner, _, pos = self._flat(np.arange(len(paths)), paths)
        count = np.bincount(self._task_idx[pos], minlength=len(self.prob.weight)).astype(np.float64)
        return count, np.bincount(owner, weights=self._task_wh[pos], minlength=len(paths))

    def _flat(self, passes: np.ndarray, paths: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Paths of `passes` as flat vectors, a row per node: its pass, the path's index in `paths`, and its
        observation's place in the passes' task CSR (``_task_idx[pos]`` its task, ``_task_wh[pos]`` its energy)."""
        lens = np.fromiter((len(x) for x in paths), np.int64, len(paths))
        nodes = np.concatenate(paths).astype(np.int64) if lens.sum() else np.zeros(0, np.int64)
        owner = np.repeat(np.asarray(passes, dtype=np.int64), lens)
        pos = self._task_ptr[owner] + self._node_acq[self._node_ptr[owner] + nodes]
        return owner, np.repeat(np.arange(len(paths)), lens), pos

    def prefetch(self, deadline: float | None) -> None:
        """Send the next price round's passes to the pool now, at the prices the last round set, when the pool
        can work while the driver does (its ``submit_priced``: Ray actors); :meth:`_dual_round` takes the
        result when its prices are these.  Why: the next round's prices never depend on the recovery that
        follows a round (the master's duals and the subgradient step are taken before it, from the round's own
        results), so the actors solve round k + 1 while the driver recovers and repairs a schedule from round k
        (its descent sweeps then solved here, not queued behind the round): the same results as one after the
        other, in less time."""
        submit = getattr(self.pool, "submit_priced", None)
        if submit is None:
            return
        lam = np.minimum(self.prices.lam, self.prob.weight)
        pi = self.prices.pass_price()
        self._pending = (lam, pi, submit(np.flatnonzero(~self.frozen).tolist(), lam, pi, deadline),
                         time.perf_counter())

    def _bound_from(self, total: float, proven: bool, what: str) -> None:
        """Keep L = `total` as the bound when it is proven and lower (never below a schedule found: refused and
        said, see :meth:`keep`)."""
        if proven and total < self.best_bound:
            if total < self.best.value - 1e-9 * max(1.0, self.best.value):
                # a theorem cannot fall below a schedule: some pass term was wrong; keep the bound known
                self.refused.append(f"{what}: L(lam) = {total:.6f} below the schedule found ({self.best.value:.6f})")
            else:
                self.best_bound, self.bound_source = total, "lagrangian"

    def price_round(self, deadline: float | None) -> float | None:
        """Every pass under the current prices (on the pool); returns L(lam, mu) (None when cut by the deadline),
        keeps the bound when it is proven and lower, and moves the prices."""
        if self._start_lam is None:
            self._start_lam = self.prices.lam.copy()
        got = self._dual_round(self.prices.lam, deadline)
        if got is None:
            return None
        t_solves = self._solve_s  # the master's limit
        total, proven, count, pass_wh, self.round_paths = got
        self._bound_from(total, proven, f"round {self.rounds_done + 1}")
        lam = self.prices.lam.copy()
        scale = None if self.cfg.price_step == "uniform" else self.prob.weight  # lp's fallback: weighted steps
        search = self.cfg.energy_search and len(self.windows) > 0
        if self.master is not None:  # column generation: the round's pass optima are the master's new columns
            self.centre.observe(lam, total)
            added = self.master.add(self.round_paths)
            # no new column and L at the master's value: lam minimises L, later rounds would repeat this one
            self.converged = added == 0 and proven and total <= self.master.value + 1e-9 * max(1.0, total)
            # with a fixed number of rounds (no deadline) the LP's limit is in iterations, about one per pass
            # solved (at 200 satellites 13,152 passes, ~4 s of HiGHS here as of a round's pass solves on one core):
            # the time a round's solves took depends on the machine and the workers, the schedule must not
            iters = None if deadline is not None else max(MASTER_MIN_ITERATIONS, len(self.round_paths))
            duals = self.master.duals(deadline, max(MASTER_MIN_S, t_solves), iters)
            if duals is not None:
                self._lp_misses, self._lp_solved = 0, True
                self.prices.lam = self.centre.towards(duals)
                if not search:
                    self.prices.step_towards(count, total, self.best.value, pass_wh, scale, tasks=False)
            elif deadline is None or time.perf_counter() < deadline:
                self._lp_misses += 1
                # a master that never finished a solve in its time is not one slow solve: at 1,000 satellites its
                # first three solves ran out, 41-97 s each, and the rounds waited for them (docs/results.md)
                if self._lp_misses < MASTER_PATIENCE and self._lp_solved:
                    # one slow solve (near the optimum the LP degenerates: a generated test_hard-like case took
                    # longer than a round's pass solves at round 26 of 27): a weighted step for this round, and the
                    # LP goes on from its basis at the next one
                    self.prices.step_towards(count, total, self.best.value, None if search else pass_wh, scale)
                else:
                    # the master outgrew the round (a 200-satellite day: 69 s for its second solve against 5 s of
                    # pass solves): weighted subgradient steps from the prices the run started with, as if they
                    # had been the rule from the start (at 200 satellites those steps from the centre, the ceiling
                    # prices, found schedules 0.0013 of the weight lower in 300 s)
                    self.master, self.converged = None, False
                    self.prices.lam = self._start_lam.copy()
        else:
            self.prices.step_towards(count, total, self.best.value, None if search else pass_wh, scale)
        if search and proven:
            lower = self.energy_search(lam, total, pass_wh, deadline)
            if lower is not None:
                self._bound_from(lower, True, f"round {self.rounds_done + 1}, energy search")
                total = lower
        self.spend = self.cfg.energy_price * self.prices.pass_price()
        return total

    def energy_search(self, lam: np.ndarray, total: float, pass_wh: np.ndarray,
                      deadline: float | None) -> float | None:
        """Line searches of the energy windows' multipliers at the task prices `lam` of the round just solved (its
        L(lam, mu) = `total`, its pass terms and each pass's energy `pass_wh`): on every satellite the window its
        round's paths overspend most (in typical observations) gets the multiplier increase x (per Wh) that
        minimises ``phi(x) = sum over its passes of their terms at pass price + x, + x R_w``, by bisection on
        where the passes' energy crosses R_w (:data:`ENERGY_STEPS` solves of the window's passes, every
        satellite's window solved together on the pool).  A window whose multiplier is above 0 and
        whose passes spend less than it allows may be the satellite's instead (x then between minus its multiplier
        and 0).  Returns L(lam, mu) with the new multipliers (None when no window moves, a term is not proven, or
        the deadline came).

        Why a search, not only the subgradient steps: at fixed task prices each window's phi is convex and
        piecewise linear in x (a pass term is the maximum over its paths of linear functions of its price), so
        the x it keeps never raises L (phi(0) is evaluated, and an x is kept only when lower); the Polyak steps
        of the multipliers, sized by the task prices' gap, kept the bound above the conflict-free one where the
        battery binds (test_hard).  Windows of different satellites share no pass, so the searches are
        independent; x is kept per window in :attr:`Prices.mu` (units of its `scale_wh`) and paid by the
        schedules' pass problems as every multiplier is (``--energy-price``)."""
        win = self.windows
        pass_sat = self._pass_sat
        over = (win.used(pass_wh) - win.rhs_wh) / win.scale_wh
        mu_wh = self.prices.mu / win.scale_wh  # each window's multiplier per Wh
        slope = np.where(over > 1e-6, over, np.where((mu_wh > 0) & (over < -1e-6), -over, 0.0))
        cand = np.flatnonzero(slope > 0)
        if not (over > 1e-6).any():  # nothing overspent: L gains little from lowering multipliers alone
            return None
        cand = cand[np.lexsort((-slope[cand], pass_sat[win.lo[cand]]))]
        chosen = cand[np.r_[True, pass_sat[win.lo[cand[1:]]] != pass_sat[win.lo[cand[:-1]]]]]
        lens = win.hi[chosen] - win.lo[chosen] + 1
        passes = np.concatenate([np.arange(a, b + 1) for a, b in zip(win.lo[chosen], win.hi[chosen])])
        owner = np.repeat(np.arange(len(chosen)), lens)  # the chosen window of each of `passes`
        live = ~self.frozen[passes]
        w = self.prob.weight
        top = np.zeros(len(chosen))  # past this price of a Wh no observation of the window is worth anything
        for k, p in zip(owner.tolist(), passes.tolist()):
            pg = self.prob.passes[p]
            e = pg.energy_wh
            if len(e):
                gain = (w[pg.tasks] - lam[pg.tasks]) / np.maximum(e, 1e-12)
                top[k] = max(top[k], float(gain.max()))
        rhs = win.rhs_wh[chosen]
        best_phi = np.bincount(owner, self._terms[passes], len(chosen))
        phi0 = best_phi.copy()
        best_x = np.zeros(len(chosen))
        up = over[chosen] > 0  # overspent: x up to `top`; else a multiplier above 0 may come down to 0
        lo = np.where(up, 0.0, -mu_wh[chosen])
        hi = np.where(up, top * (1 + 1e-9) + 1e-12, 0.0)
        pi = self.prices.pass_price()
        todo = passes[live].tolist()
        for _ in range(ENERGY_STEPS):
            x = 0.5 * (lo + hi)
            pp = pi.copy()
            pp[passes] += x[owner]
            solved = self.pool.solve_priced(todo, lam, pp, deadline)
            if solved is None:
                return None
            self.pass_solves += len(todo)
            terms = np.zeros(len(passes))
            used = np.zeros(len(passes))
            for i, p in enumerate(passes.tolist()):
                pg = self.prob.passes[p]
                if self.frozen[p]:
                    path = self.initial.paths[p]
                    acq = pg.graph.node_acq[path]
                    terms[i] = float(priced(w, lam, pg.tasks[acq], pg.energy_wh[acq], pp[p]).sum())
                    used[i] = path_wh(pg, path)
                    continue
                res = solved[p]
                if res.bound is None:
                    return None
                terms[i], used[i] = res.bound, path_wh(pg, res.nodes)
            phi = np.bincount(owner, terms, len(chosen)) + x * rhs
            better = phi < best_phi
            best_phi, best_x = np.where(better, phi, best_phi), np.where(better, x, best_x)
            spent = np.bincount(owner, used, len(chosen)) > rhs
            lo, hi = np.where(spent, x, lo), np.where(spent, hi, x)
        gain = best_phi - phi0
        if not (gain < 0).any():
            return None
        mu = self.prices.mu.copy()
        mu[chosen] = np.maximum(0.0, mu[chosen] + best_x * win.scale_wh[chosen])
        self.prices.mu = mu
        self.spend = self.cfg.energy_price * self.prices.pass_price()
        return total + float(gain.sum())

    def ceiling_prices(self) -> np.ndarray:
        """Every task more than one pass can serve priced at its weight, the others at 0."""
        contested = np.array([len(h) > 1 for h in self.prob.task_passes], dtype=bool)
        return np.where(contested, self.prob.weight, 0.0)

    def ceiling_round(self, deadline: float | None) -> float | None:
        """L at :meth:`ceiling_prices`, kept as the bound when lower; the prices the rounds move are left as they
        are.  Under those prices no pass gains anything from a contested task, so L is the contested tasks'
        weight plus each pass's best schedule of the tasks only it can serve: never above the conflict-free
        bound, below it where passes cannot take all their own tasks, and cheap (most utilities are 0).  Where
        rounds are expensive it is the best bound for a long time: on a generated 200-satellite day (seed 7) L is
        0.6680 of the weight here against 0.8816 for the heuristic start and 0.6717 conflict-free, which 63 price
        rounds from any start never got below."""
        ceiling = self.ceiling_prices()
        got = self._dual_round(ceiling, deadline)
        if got is None:
            return None
        self._bound_from(got[0], got[1], "ceiling prices")
        if self.master is not None:  # the lowest L so far may be this one (at 200 satellites, by far)
            self.centre.observe(ceiling, got[0])
            self.master.add(got[4])
        return got[0]

    def empty(self) -> Primal:
        """No observation, except those of the frozen passes."""
        primal = Primal.empty(len(self.prob.passes), len(self.prob.weight))
        for p in np.flatnonzero(self.frozen).tolist():
            self._assign(primal, p, self.initial.paths[p])
        return primal

    def recover(self, rng: np.random.Generator, deadline: float | None) -> Primal:
        """A schedule from the last price round's pass schedules: passes in random order keep the tasks no
        earlier pass took (the rest of their path re-walked along the graph's arcs), then coordinate descent.
        With the master (``--price-step lp``) the columns of its last solution come first, by decreasing share."""
        n_pass = len(self.prob.passes)
        primal = self.empty()
        done = self.frozen.copy()
        ranked = self.master.ranked() if self.master is not None else []
        order: list[int] = []
        paths: list[np.ndarray] = []
        # --price-step lp: the master's solution first (its columns by decreasing share), then the round's paths
        for p, path in ranked + [(p, self.round_paths[p]) for p in rng.permutation(n_pass).tolist()]:
            if done[p]:
                continue
            done[p] = True
            if len(path):
                order.append(p)
                paths.append(path)
        self._take_in_order(primal, order, paths)
        self.descend(primal, list(range(n_pass)), deadline)
        return primal

    def _take_in_order(self, primal: Primal, order: list[int], paths: list[np.ndarray]) -> None:
        """Each pass of `order` in turn takes its path's tasks that no pass before it took (and the repair did not
        bar from its satellite), the rest of its path re-walked along the graph's arcs (a solver's path follows
        them: re-walked only when some of its tasks are taken); `primal` holds the frozen passes only.

        Why not one pass after another: at 200 satellites that loop was a third of the recovery, and on the lean
        driver with two actors the recovery sets the pace of a round.  A pass none of whose tasks is on the path of
        a pass before it in `order` (nor barred, nor a frozen pass's) takes its path whole whatever the others do,
        and no pass before it can want its tasks: those are assigned at once, and only the others, most of them
        near none, are walked in turn, each seeing every pass before it.  The same schedule, and the same value
        summed in the same order, as the loop."""
        if not order:
            return
        owner, rank, pos = self._flat(np.asarray(order, dtype=np.int64), paths)
        tasks = self._task_idx[pos]
        first = np.full(len(self.prob.weight), len(order), dtype=np.int64)
        np.minimum.at(first, tasks, rank)  # the first pass in `order` whose path holds each task
        bad = (first[tasks] != rank) | (primal.served[tasks] >= 0) | self.barred[self._pass_sat[owner], tasks]
        clean = np.ones(len(order), dtype=bool)
        clean[rank[bad]] = False
        ends = np.r_[0, np.cumsum([len(x) for x in paths])]
        w = self.prob.weight
        with HeldInterrupt():
            whole = clean[rank]
            primal.served[tasks[whole]] = owner[whole]
            for i in np.flatnonzero(clean).tolist():
                primal.paths[order[i]] = paths[i]
        for i, p in enumerate(order):
            if clean[i]:  # what _assign adds for a path taken whole into an empty pass, in the loop's order
                primal.value += float(w[tasks[ends[i]:ends[i + 1]]].sum())
                continue
            path = paths[i]
            free = self._available(primal, p)[self.prob.passes[p].graph.node_acq[path]]
            self._assign(primal, p, path if free.all() else self.prob.rewalk(p, path[free]))

    # ------------------------------------------------------------------ battery
    def battery_repair(self, primal: Primal, deadline: float | None = None, whole: bool = False) -> int | None:
        """Drop observations until every battery holds (checker's model); a dropped task is barred from that
        satellite, and the passes of other satellites that could serve it are solved again once (then the
        batteries are checked and repaired again).  Returns the number dropped (also counted in
        :attr:`repair_drops`), or None when `deadline` came first: `primal` is then not repaired and must not be
        kept.  `whole` (the first schedule): the repair runs to its end whatever the deadline (the re-solves
        still stop at it).  Only the satellites whose observations changed since their battery was last seen to
        hold are simulated, on the pool when it offers it (:meth:`_repair_rows`)."""
        total = 0
        for attempt in range(2):  # the last attempt only repairs: what it returns holds
            rows = self.rows(primal)
            keys = [rows.task[a:b].tobytes() + rows.start[a:b].tobytes()
                    for a, b in zip(rows.offsets[:-1].tolist(), rows.offsets[1:].tolist())]
            todo = np.array([i for i, k in enumerate(rows.sats.tolist()) if self.battery_ok.get(k) != keys[i]],
                            dtype=np.int64)  # satellites not seen as they are
            part = rows.part(todo)
            kept = self._repair_rows(part, None if whole else deadline)
            if kept is None:
                return None
            for i, k in enumerate(part.sats.tolist()):
                a, b = int(part.offsets[i]), int(part.offsets[i + 1])
                ok = kept[a:b]
                self.battery_ok[k] = part.task[a:b][ok].tobytes() + part.start[a:b][ok].tobytes()
            dropped = int((~kept).sum())
            if not dropped:
                break
            total += dropped
            self.repair_drops += dropped
            drop_task = part.task[~kept]
            drop_sat = np.repeat(part.sats, np.diff(part.offsets))[~kept]
            drop_pass = primal.served[drop_task]
            self.barred[drop_sat, drop_task] = True
            for p in np.unique(drop_pass).tolist():  # ascending, as the passes always were
                path = primal.paths[p]
                ok = ~np.isin(path_tasks(self.prob, p, path), drop_task[drop_pass == p])
                self._assign(primal, p, path[ok] if self.frozen[p] else self.prob.rewalk(p, path[ok]))
            if attempt < 1:  # one round of re-solves of the passes that could take the dropped tasks
                self.descend(primal, sorted({q for t in drop_task.tolist() for q in self.prob.task_passes[t].tolist()}),
                             deadline)
        return total

    def _repair_rows(self, rows: Rows, deadline: float | None) -> np.ndarray | None:
        """:func:`eosp.fleet.timeline.repair_rows` of `rows`: on the pool when it offers ``repair_rows`` (Ray's
        actors, each repairing the satellites it owns), is free (no prefetched round still on it) and there are
        at least :data:`REPAIR_AWAY` satellites; else here.  The same result either way (a satellite's repair reads
        its own rows only)."""
        away = getattr(self.pool, "repair_rows", None)
        if away is not None and len(rows.sats) >= REPAIR_AWAY and not self._pool_busy():
            t = time.perf_counter()
            self._pool_calls += 1
            try:
                return away(rows, deadline)
            finally:
                self._pool_s += time.perf_counter() - t
        return repair_rows(self.prob.fleet, self.prob.los, rows, self.sun, deadline)

    def rows(self, primal: Primal) -> Rows:
        """The schedule `primal` as rows by satellite (:class:`eosp.fleet.timeline.Rows`: each satellite with an
        observation, its observations in time order)."""
        prob = self.prob
        got = [prob.passes[p].rows[path - 1] for p, path in enumerate(primal.paths) if len(path)]
        idx = np.concatenate(got) if got else np.zeros(0, np.int64)
        sat, task = prob.opps.satellite[idx].astype(np.int64), prob.opps.task[idx].astype(np.int64)
        st = prob.opps.start[idx].astype(np.float64) * prob.fleet.horizon.action_step_s
        en = st + prob.fleet.tasks.duration_s[task]
        order = np.lexsort((en, st, sat))
        sat, task, st, en = sat[order], task[order], st[order], en[order]
        first = np.flatnonzero(np.r_[True, sat[1:] != sat[:-1]]) if len(sat) else np.zeros(0, np.int64)
        return Rows(sat[first], np.r_[first, len(sat)].astype(np.int64), task, st, en)

    def timelines(self, primal: Primal) -> list[Timeline]:
        """The schedule `primal` as one timeline per satellite (:mod:`eosp.fleet.timeline`), from its :meth:`rows`."""
        rows = self.rows(primal)
        tls = [Timeline() for _ in range(len(self.prob.fleet.satellites))]
        for k, a, b in zip(rows.sats.tolist(), rows.offsets[:-1].tolist(), rows.offsets[1:].tolist()):
            tls[k] = timeline(self.prob.los, k, rows.task[a:b], rows.start[a:b], rows.end[a:b])
        return tls

    def schedule(self, primal: Primal) -> Schedule:
        return to_schedule(self.prob.fleet, self.timelines(primal))

    # ------------------------------------------------------------------ the loop
    def record(self) -> None:
        self.history.append((time.perf_counter() - self.t0, self.best.value, self.best_bound))

    def offer(self, primal: Primal, deadline: float | None = None) -> bool:
        """Keep `primal` (after battery repair) when it serves more than the best (not when the deadline cut its
        repair)."""
        if self.battery_repair(primal, deadline) is None:
            return False
        if primal.value > self.best.value + 1e-9:
            self.keep(primal)
            return True
        return False

    def keep(self, primal: Primal) -> None:
        """`primal` is the best schedule now; a Lagrangian bound below it was wrong: refused (the conflict-free
        bound, which every schedule respects, takes its place), and said."""
        self.best = primal
        if self.master is not None:  # a schedule kept: its paths are columns (the master then serves at least it)
            self.master.add(primal.paths)
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
            if self.battery_repair(trial, deadline) is None:
                return
            if trial.value >= self.best.value - 1e-9:
                if trial.value > self.best.value + 1e-9:
                    self.keep(trial)
                else:
                    self.best = trial

    def integer_round(self, deadline: float | None) -> None:
        """A schedule from the master's best integer solution over its columns (:meth:`Master.integer`, started
        from the best schedule), filled by coordinate descent and offered (battery repair, kept when better).
        Once, when the prices have converged: given half of the time left, at most :data:`INTEGER_MAX_S`
        seconds, and with no time limit (``--rounds``) :data:`INTEGER_NODES` nodes as well, so that the schedule is
        the same on any machine (where those nodes take less than the seconds).

        With ``integer_energy`` (the default) the battery's energy windows are rows of the integer program, each
        column's energy its observations' least energy plus the slews between them (:func:`schedule_windows`,
        :meth:`Master.energy_rows`).  Why: on test_hard/case_0005 the first schedule runs five batteries dry, each
        from the horizon start without a full charge again (6-10 h), and there the windows' accounting without the
        slews left 202-248 Wh a battery of slack, what the slews spent beyond the settling (82-87% of it between
        observations of one pass, the rest the first maneuver of each pass; experiments/battery_stretches.py);
        counted, the packing is one the batteries nearly hold: WCR at 120 s 0.8498 -> 0.8576 (docs/results.md).  The
        columns may hold tasks the battery repair barred from their satellite: they are kept, and the repair of
        :meth:`offer` takes out what the batteries still cannot hold (first maneuvers of passes, the windows'
        sunlight over-estimate).  When that schedule is not better than the best, the integer solution without the
        rows is tried as well (with half of the time then left): a repaired schedule is not always a packing of
        columns (the repair keeps part of a column), so the rows can cut off a packing that the repair turns into a
        better schedule (test_hard/case_0004: 0.8847 without the rows, nothing better than 0.8836 with them).  Rows
        only for the batteries a solution runs dry, added after each solve and without the slews, were tried before
        and not kept: the re-solves cost the time the first solve needed and the repair still took out most of what
        they saved."""
        self.integer_done = True
        tries = ([schedule_windows(self.prob)] if self.cfg.integer_energy else []) + [None]
        for windows in tries:
            if deadline is None:
                sel = self.master.integer(self.best.paths, INTEGER_MAX_S, INTEGER_NODES, windows)
            else:
                left = deadline - time.perf_counter()
                if left <= 0:
                    return
                sel = self.master.integer(self.best.paths, min(INTEGER_MAX_S, 0.5 * left), windows=windows)
            if not sel:
                continue
            primal = self.empty()
            for i in sel:
                p, path = self.master.col_pass[i], self.master.col_path[i]
                if self.frozen[p]:
                    continue
                self._assign(primal, p, path)  # barred tasks too: the battery repair says what the battery allows
            self.descend(primal, list(range(len(self.prob.passes))), deadline)
            if self.offer(primal, deadline):
                return

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
                    self._assign(first, p, prob.rewalk(p, path[free]) if len(path) else path)
            else:  # every pass, each solve cut short past the deadline
                self.construct(order, primal=first, deadline=deadline, whole=True)
            self.descend(first, list(range(len(prob.passes))), deadline)
        except KeyboardInterrupt:
            self.interrupted = True
        # the first schedule is repaired whole (its re-solves stop at the deadline; none after Ctrl-C)
        self.first_repair_drops = self.battery_repair(first, time.perf_counter() if self.interrupted else deadline,
                                                      whole=True)
        if first.value > self.best.value + 1e-9:
            self.keep(first)
        self.first_s = time.perf_counter() - self.t0
        if not self.interrupted:
            if deadline is not None and time.perf_counter() < deadline:  # past it: no round, nothing to reserve
                self.check_s = self.check_estimate(first)  # kept for the final check of a schedule like this one
                deadline -= self.check_s
            try:
                self._rounds(deadline, rng)
            except KeyboardInterrupt:  # Ctrl-C: the best schedule so far is the answer
                self.interrupted = True
        return self.best

    def check_estimate(self, primal: Primal) -> float:
        """Seconds the final steps will take on a schedule like `primal` (its timelines and the checker on it,
        :func:`eosp.fleet.check.validate`), with a margin: the checker's fixed cost (timed on no action) plus its
        cost per action, timed on the actions of the first satellites (a tenth of the actions, at least 40),
        scaled to all (the checker's work is per satellite and per action)."""
        t = time.perf_counter()
        sched = self.schedule(primal)
        n = len(sched)
        t_fixed = time.perf_counter()
        validate(self.prob.fleet, Schedule(*(np.zeros(0, a.dtype) for a in
                                             (sched.satellite, sched.task, sched.start_us, sched.end_us))),
                 self.prob.geo)
        t_sub = time.perf_counter()
        fixed = t_sub - t_fixed
        per_action = 0.0
        if n:
            sats, counts = np.unique(sched.satellite, return_counts=True)
            upto = int(np.searchsorted(np.cumsum(counts), max(0.1 * n, min(n, 40)))) + 1
            keep = np.isin(sched.satellite, sats[:upto])
            validate(self.prob.fleet, Schedule(sched.satellite[keep], sched.task[keep], sched.start_us[keep],
                                               sched.end_us[keep]), self.prob.geo)
            per_action = max(0.0, time.perf_counter() - t_sub - fixed) / int(keep.sum())
        return CHECK_MARGIN * ((t_fixed - t) + fixed + per_action * n) + CHECK_SLACK_S

    def _rounds(self, deadline: float | None, rng: np.random.Generator) -> None:
        cfg = self.cfg
        rounds = self.start_round
        self.rounds_done = rounds
        while cfg.rounds is None or rounds < cfg.rounds:
            if deadline is not None and time.perf_counter() > deadline:
                break
            if self.best_bound <= self.best.value + 1e-9:
                break  # proven optimal
            if cfg.pass_solver == "exact" and rounds == 0:
                if self.ceiling_round(deadline) is None:
                    break
                self.record()
            if (cfg.pass_solver == "exact" or rounds == 0) and not self.converged:
                before = self.best_bound
                t_round = time.perf_counter()
                if self.price_round(deadline) is None:
                    break
                self.round_s.append(time.perf_counter() - t_round)
                self.prices.stalled(self.best_bound < before - 1e-9)
                self.record()
                if cfg.pass_solver == "exact" and not self.converged and (cfg.rounds is None
                                                                          or rounds + 1 < cfg.rounds):
                    self.prefetch(deadline)
                self._pool_s, self._pool_calls, t = 0.0, 0, [time.perf_counter()]
                primal = self.recover(rng, deadline)
                t.append(time.perf_counter())
                kept = self.offer(primal, deadline)
                t.append(time.perf_counter())
                if not kept:
                    self.neighbourhood(rng, deadline)
                t.append(time.perf_counter())
                self.phases.append({"round": round(self._wait_s, 3),
                                    "prices": round(self.round_s[-1] - self._wait_s, 3),
                                    "recover": round(t[1] - t[0], 3), "repair": round(t[2] - t[1], 3),
                                    "moves": round(t[3] - t[2], 3), "pool": round(self._pool_s, 3),
                                    "pool_calls": self._pool_calls})
            elif self.converged and not self.integer_done and self.master is not None:
                self.integer_round(deadline)
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
        opportunity, served once).  With ``energy_bound`` energy enters the Lagrangian bound through the
        battery's energy windows (:mod:`eosp.fleet.energy`, their multipliers in :mod:`eosp.kinds.fleet.prices`);
        else it is relaxed.  With frozen passes the Lagrangian bound holds for the schedules that keep them as
        given."""
        return self.best_bound
