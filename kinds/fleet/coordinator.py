"""The fleet solver's state: what one solve holds (prices, the best schedule and bound, the pass pool, the memo)
and its shared edits (a pass's utilities, assigning a path whole, a schedule's rows, keeping a schedule).

The fleet solver is a package of phases, each a module of functions over this state (:class:`Coordinator`):

* :mod:`eosp.kinds.fleet.construct`: the construction (passes in time order, in waves solved together on the
  pass pool) and coordinate descent as sweeps (the passes waiting solved from one schedule, settled in pass
  order: the same schedule for any number of workers), with the memo of proven-optimal pass solves;
* :mod:`eosp.kinds.fleet.dual`: price rounds (every pass under the task prices and the energy multipliers; the
  Lagrangian bound when every pass term is proven; the price step or the master LP's duals), the ceiling round,
  the energy windows' line searches, the next round sent ahead (prefetch);
* :mod:`eosp.kinds.fleet.recovery`: a schedule from a price round's pass schedules, then descent;
* :mod:`eosp.kinds.fleet.battery`: observations dropped until every battery holds (the checker's model), and a
  schedule offered (repaired, kept when better);
* :mod:`eosp.kinds.fleet.moves`: large neighbourhoods and the master's integer solution;
* :mod:`eosp.kinds.fleet.loop`: the run: the first schedule, then rounds until the budget, the limit or the bound.

A constellation-day is hundreds of passes (:mod:`eosp.fleet.passgraph`) coupled by two constraints: a task is
served at most once, and each satellite's battery runs from one pass to the next (its consequences as energy
windows over runs of passes, :mod:`eosp.fleet.energy`).  Relaxing both with prices separates the passes
(:mod:`eosp.kinds.lagrange`); schedules come from the same pass solver with true weights.  A phase module imports this one
and those below it (construct, then dual, recovery and battery, then moves, then loop); this one imports none.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from eosp.fleet.energy import EnergyWindows
from eosp.fleet.timeline import Rows, Timeline, timeline, to_schedule
from eosp.fleet.model import Schedule
from eosp.kinds.fleet.config import FleetConfig
from eosp.interrupt import HeldInterrupt
from eosp.kinds.fleet.master import Centre, Master
from eosp.kinds.fleet.pool import InProcessPool, PassPool
from eosp.kinds.lagrange import Prices
from eosp.kinds.fleet.problem import PassResult, PassSpec, Primal, Problem, priced


def csr_take(ptr: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows `rows` of a CSR layout with pointers `ptr`: the positions of their entries, one flat vector in the
    order of `rows`, and its offsets by row."""
    lens = ptr[rows + 1] - ptr[rows]
    offsets = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum(lens, out=offsets[1:])
    return np.repeat(ptr[rows] - offsets[:-1], lens) + np.arange(offsets[-1]), offsets


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
    check_s: float = 0.0  # seconds kept before the budget's end for the final check (check_estimate)
    interrupted: bool = False
    bound_source: str = "conflict-free"  # until a proven Lagrangian bound is lower
    refused: list[str] = field(default_factory=list)  # Lagrangian bounds refused, and why (see price_round)
    bound_lam: np.ndarray | None = None  # the task prices of the kept Lagrangian bound (dual._bound_from)

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
    claim_frozen: bool = True  # whether the frozen passes' observations serve their tasks (Start.claim_frozen)

    def __post_init__(self) -> None:
        n = len(self.prob.fleet.tasks)
        self.spec = PassSpec.of(self.cfg)  # what a pass solve reads of the config
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
        self._task_ptr, self._task_idx = self.prob.task_ptr, self.prob.task_idx  # the passes' tasks, CSR
        self._task_val = self.prob.flat_values()  # what each pass task is worth there, as _task_idx
        self._task_wh = (np.concatenate([pg.energy_wh for pg in self.prob.passes]).astype(np.float64)
                         if len(self.prob.passes) else np.zeros(0))  # each pass task's least energy, as _task_idx
        self._claimed = np.zeros(n, dtype=np.bool_)
        # every pass's nodes' acquisitions, one flat vector (a round's serve counts and energies as arrays)
        self._node_ptr = np.r_[0, np.cumsum([len(pg.graph.node_acq) for pg in self.prob.passes])].astype(np.int64)
        self._node_acq = (np.concatenate([pg.graph.node_acq for pg in self.prob.passes]) if len(self.prob.passes)
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
        # whether an observation at each place of the passes' task CSR serves its task (see Start.claim_frozen)
        self._claims = np.ones(len(self._task_idx), dtype=bool)
        if not self.claim_frozen:
            self._claims = ~np.repeat(self.frozen, np.diff(self._task_ptr))
            self._task_val = np.where(self._claims, self._task_val, 0.0)  # a copy: the problem's values stay
        self.sun = self.prob.sun  # sunlight, computed once for every battery simulation
        self.battery_ok: dict[int, bytes] = {}  # satellite -> its tasks and starts last found to hold its battery
        self.best_bound = self.conflict_free()
        if self.frozen.any():  # the frozen passes are in every schedule, the best so far too (worth 0 or not)
            self.best = self.empty()

    # ------------------------------------------------------------------ shared edits
    def _utility(self, primal: Primal, p: int, shift: np.ndarray | None = None) -> np.ndarray:
        """The utilities of pass p's tasks for a schedule: weight, less `shift` (kept below the weight), less the
        pass's price of the energy they take (:attr:`spend`); 0 (left out) for a task another pass serves or the
        battery repair barred from this satellite."""
        pg = self.prob.passes[p]
        value = self._values_of(p)
        price = self._no_shift[pg.tasks] if shift is None else np.minimum(shift[pg.tasks], 0.999 * value)
        util = priced(value, price, pg.energy_wh, self.spend[p])
        return np.where(self._available(primal, p), util, 0.0)

    def _path_utility(self, p: int, path: np.ndarray) -> float:
        """The utility :meth:`_utility` gives pass p's `path` (its tasks are its own)."""
        pg = self.prob.passes[p]
        acq = pg.graph.node_acq[path]
        return float(priced(self._values_of(p)[acq], self._no_shift[pg.tasks[acq]], pg.energy_wh[acq],
                            self.spend[p]).sum())

    def _values_of(self, p: int) -> np.ndarray:
        """What pass p's tasks are worth in it: a view of the flat vector made once (:attr:`_task_val`), not a
        gather per call."""
        return self._task_val[self._task_ptr[p]:self._task_ptr[p + 1]]

    def _available(self, primal: Primal, p: int) -> np.ndarray:
        tasks = self.prob.passes[p].tasks
        s = primal.served[tasks]
        return ((s < 0) | (s == p)) & ~self.barred[self.prob.passes[p].satellite, tasks]

    def _assign(self, primal: Primal, p: int, path: np.ndarray) -> list[int]:
        """Give pass p the schedule `path`; returns the tasks it freed.  Whole or not at all: a Ctrl-C waits for
        the end of the edit (the first schedule, interrupted while it is built, is the answer)."""
        pg = self.prob.passes[p]
        old_acq, new_acq = pg.graph.node_acq[primal.paths[p]], pg.graph.node_acq[path]
        value = self._values_of(p)
        if self.claim_frozen or not self.frozen[p]:
            old, new = pg.tasks[old_acq], pg.tasks[new_acq]
        else:  # observations that occupy the satellite and serve nothing (worth 0: see __post_init__)
            old = new = pg.tasks[:0]
        mark = self._claimed  # all False between uses: the tasks of `old` not in `new` (no sort, a path's are unique)
        mark[new] = True
        freed = old[~mark[old]]
        mark[new] = False
        with HeldInterrupt():
            primal.served[freed] = -1
            primal.served[new] = p
            primal.paths[p] = path
            primal.value += float(value[new_acq].sum() - value[old_acq].sum())
        return freed.tolist()

    def _batch_utilities(self, primal: Primal, batch: list[int],
                         shift: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_utility` of every pass of `batch` at once: one flat float64 vector and CSR offsets (the same
        numbers: weight less `shift` and the pass's price of the tasks' energy, 0 where another pass serves the task
        or the repair barred it), gathered from the passes' tasks as CSR instead of pass by pass."""
        b = np.asarray(batch, dtype=np.int64)
        pos, offsets = csr_take(self._task_ptr, b)
        tasks, owner = self._task_idx[pos], np.repeat(b, np.diff(offsets))
        value = self._task_val[pos]
        price = self._no_shift[tasks] if shift is None else np.minimum(shift[tasks], 0.999 * value)
        util = priced(value, price, self._task_wh[pos], self.spend[owner])
        s = primal.served[tasks]
        free = ((s < 0) | (s == owner)) & ~self.barred[self._pass_sat[owner], tasks]
        return np.where(free, util, 0.0), offsets

    def _pool_busy(self) -> bool:
        """Whether a prefetched price round still holds the pool (a sweep sent now would wait behind it).  Why ask:
        the actors finish the round while the driver recovers, and before, every sweep of the recovery and of the
        moves was solved on the driver for the rest of the round, the actors idle (a 200-satellite day on two
        actors: no sweep sent in 99 rounds)."""
        if self._pending is None:
            return False
        idle = getattr(self._pending[2], "idle", None)
        return idle is None or not idle()

    def _flat(self, passes: np.ndarray, paths: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Paths of `passes` as flat vectors, a row per node: its pass, the path's index in `paths`, and its
        observation's place in the passes' task CSR (``_task_idx[pos]`` its task, ``_task_wh[pos]`` its energy)."""
        lens = np.fromiter((len(x) for x in paths), np.int64, len(paths))
        nodes = np.concatenate(paths).astype(np.int64) if lens.sum() else np.zeros(0, np.int64)
        owner = np.repeat(np.asarray(passes, dtype=np.int64), lens)
        pos = self._task_ptr[owner] + self._node_acq[self._node_ptr[owner] + nodes]
        return owner, np.repeat(np.arange(len(paths)), lens), pos

    def empty(self) -> Primal:
        """No observation, except those of the frozen passes."""
        primal = Primal.empty(len(self.prob.passes), len(self.prob.weight))
        for p in np.flatnonzero(self.frozen).tolist():
            self._assign(primal, p, self.initial.paths[p])
        return primal

    # ------------------------------------------------------------------ the schedule as rows and timelines

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

    def record(self) -> None:
        self.history.append((time.perf_counter() - self.t0, self.best.value, self.best_bound))

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
        """Every task that has an opportunity, served once (in its most valuable pass: :attr:`Problem.cap`)."""
        return float(self.prob.cap[np.array([len(h) > 0 for h in self.prob.task_passes], dtype=bool)].sum())

    @property
    def bound(self) -> float:
        """The best proven bound: the Lagrangian one when every pass term of a price round was proven (exact pass
        solver; each pass's term its priced optimum where its graph serves the bound, else its bound problem, see
        :func:`eosp.fleet.passgraph.bound_problem`), else the conflict-free bound (every task that has an
        opportunity, served once).  With ``energy_bound`` energy enters the Lagrangian bound through the
        battery's energy windows (:mod:`eosp.fleet.energy`, their multipliers in :mod:`eosp.kinds.lagrange`);
        else it is relaxed.  With frozen passes the Lagrangian bound holds for the schedules that keep them as
        given."""
        return self.best_bound
