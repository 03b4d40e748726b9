"""Schedules from the pass solver under true weights, over the solve's state (:class:`Coordinator`): the
construction (passes in time order, in waves of passes that share no task with a pass before them, solved together
on the pass pool) and coordinate descent as sweeps (the passes waiting solved from one schedule, then settled in
pass order); a pass whose utilities are those of its last proven-optimal solve takes that solve's result (the memo).
"""

from __future__ import annotations

import time

import numba
import numpy as np

from eosp.budget import UNLIMITED, Budget
from eosp.kinds.fleet.coordinator import Coordinator, csr_take
from eosp.kinds.fleet.problem import PassResult, Primal, solve_pass

SWEEP_IN_PROCESS = 32  # a descent sweep of fewer passes is solved on the driver, not sent to the pool (a Ray
# round trip costs milliseconds, a small pass under true weights 0.02-0.6 ms: docs/results.md; at 200 satellites on
# two actors, 8 sent the first schedule's small waves to the actors and cost it 16 s)


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


def descend(c: Coordinator, primal: Primal, queue: list[int], budget: Budget) -> None:
    """Coordinate descent as a sweep: the queued passes (frozen ones skipped; those sharing no task that no
    pass serves, :func:`disjoint`) are solved as one batch with every task no other pass serves at the batch's
    start (utilities :meth:`Coordinator._utility`), on the pool; then the results are settled here in ascending pass order
    (:func:`_settle`).  Passes that gain freed tasks, and passes whose result lost tasks to a lower pass of the
    same batch (never with this batch rule; settled all the same), make the next batch; until none is left or
    the budget runs out.

    Why a sweep, not a queue of single solves: one pass after another, each seeing its predecessors'
    changes, is serial, and on a 200-satellite day it took half of a round on the driver whatever the number
    of workers.  Solved from one state, a batch's passes are independent, so the pool spreads them; the
    settling order (pass ids) and the deterministic solver make the schedule the same whoever solved each
    pass, for any number of workers.  Each settled change raises its pass's utility under the schedule and
    changes no other pass, so the descent ends; run to its end (no budget, exact pass solver) no single pass,
    solved alone with the tasks no other pass serves, is worth more than its path (a fixed point of the
    serial descent too).  It takes more solves than the serial queue (a pass solved in a batch before a lower
    pass freed a task it can take is solved again): about a fifth more on aeossp cases."""
    n_pass = len(c.prob.passes)
    todo = np.zeros(n_pass, dtype=bool)
    todo[np.asarray(queue, dtype=np.int64)] = True
    while True:
        todo &= ~c.frozen
        queued = np.flatnonzero(todo)
        if len(queued) == 0:
            return
        if budget.expired():
            return
        open_ = primal.served < 0
        batch = queued[disjoint(queued, c._task_ptr, c._task_idx, c._claimed, open_)].tolist()
        solved = _solve_batch(c, batch, *c._batch_utilities(primal, batch), budget)
        if solved is None:
            return  # the budget ran out: the schedule is as the last batch left it (every edit whole)
        todo[batch] = False
        for p in batch:
            _settle(c, primal, p, solved[p].nodes, todo)


def _settle(c: Coordinator, primal: Primal, p: int, path: np.ndarray, todo: np.ndarray) -> None:
    """Pass p's result of a sweep, against the schedule as the lower passes of the batch left it: the tasks
    another pass took meanwhile are taken out of `path` (the rest re-walked along the graph's arcs, so it
    stays feasible, :func:`eosp.kinds.fleet.problem.rewalk`), and the path is taken when it is worth more
    than the pass's current one under :meth:`Coordinator._utility`.  Marks in `todo` the other passes that can take the
    tasks it freed, and p itself when it lost tasks (solved again with what is left)."""
    pg = c.prob.passes[p]
    again = bool(todo[p])  # a lower pass of the batch freed a task p can take
    # the common case near the end: nothing changes (a memo hit gives the very array the pass holds)
    if path is primal.paths[p] or np.array_equal(path, primal.paths[p]):
        todo[p] = again
        return
    if len(path):
        free = c._available(primal, p)[pg.graph.node_acq[path]]
        if not free.all():
            path = c.prob.rewalk(p, path[free])
            again = True
    if c._path_utility(p, path) > c._path_utility(p, primal.paths[p]) + 1e-9:
        for t in c._assign(primal, p, path):
            todo[c.prob.task_passes[t]] = True
    todo[p] = again  # not for the tasks p freed itself: it just chose without them


def _solve_batch(c: Coordinator, batch: list[int], util: np.ndarray, offsets: np.ndarray,
                 budget: Budget) -> dict[int, PassResult] | None:
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
    pos, _ = csr_take(c._task_ptr, b)
    differ = np.r_[0, np.cumsum(util != c._memo_util[pos])]  # NaN (nothing kept) differs from any value
    hit = (differ[offsets[1:]] == differ[offsets[:-1]]) & c._memo_ok[b]
    out = {p: c._memo_res[p] for p in b[hit].tolist()}
    c.memo_hits += len(out)
    if hit.all():
        return out
    miss = np.flatnonzero(~hit)
    if len(out):  # the missing passes' utilities, as their own flat vector and offsets
        take, sub = csr_take(offsets, miss)
        batch, util, offsets = b[miss].tolist(), util[take], sub
    solved = _solve_missing(c, batch, util, offsets, budget)
    if solved is None:
        return None
    for i, p in enumerate(batch):
        res = solved[p]
        kept = res.bound is not None and res.value >= res.bound
        c._memo_res[p], c._memo_ok[p] = (res if kept else None), kept
        if kept:
            s = c._task_ptr[p]
            c._memo_util[s:s + offsets[i + 1] - offsets[i]] = util[offsets[i]:offsets[i + 1]]
    out.update(solved)
    return out


def _solve_missing(c: Coordinator, batch: list[int], util: np.ndarray, offsets: np.ndarray,
                   budget: Budget) -> dict[int, PassResult] | None:
    """The passes of :func:`_solve_batch` the memo did not have, solved (here or on the pool)."""
    c.pass_solves += len(batch)
    if not c.prob.lean and (len(batch) < SWEEP_IN_PROCESS or c._pool_busy()):
        return {p: solve_pass(c.prob, p, util[offsets[i]:offsets[i + 1]], c.spec, budget)
                for i, p in enumerate(batch)}
    t = time.perf_counter()
    c._pool_calls += 1
    try:
        return c.pool.solve_utilities(batch, util, offsets, budget)
    finally:
        c._pool_s += time.perf_counter() - t


def construct(c: Coordinator, order: np.ndarray, util_shift: np.ndarray | None = None,
              primal: Primal | None = None, budget: Budget = UNLIMITED, whole: bool = False) -> Primal:
    """Passes in `order`, each solved with the tasks still free (utilities :meth:`Coordinator._utility`, `util_shift`
    taken off the weights); stops when `budget` runs out unless `whole` (the first schedule: every pass, each
    solve then cut short past the budget's end).

    Solved in waves (:func:`wave`): each wave the passes that share no task with a pass before them in `order`
    still waiting, solved together (on the pool when large) and assigned in order: a pass's utilities depend
    only on its own tasks, which nothing before it in the wave touches, so the schedule is the one-by-one
    construction's, whoever solves each pass."""
    primal = primal or Primal.empty(len(c.prob.passes), len(c.prob.weight))
    left = order[~c.frozen[order]]
    while len(left):
        if not whole and budget.expired():
            break
        take = wave(left, c._task_ptr, c._task_idx, c._claimed)
        batch = left[take].tolist()
        left = left[~take]
        util, offsets = c._batch_utilities(primal, batch, util_shift)
        solved = _solve_batch(c, batch, util, offsets, budget)
        if solved is None:
            if not whole:
                break
            solved = _solve_late(c, batch, util, offsets, budget)
        for p in batch:
            c._assign(primal, p, solved[p].nodes)
    return primal


def _solve_late(c: Coordinator, batch: list[int], util: np.ndarray, offsets: np.ndarray,
                budget: Budget) -> dict[int, PassResult]:
    """The passes of a wave of the first schedule that the budget cut: every one solved all the same, here,
    each cut short (:func:`eosp.kinds.fleet.problem.pass_limit`: 10 ms past the budget's end), or on the
    pool with no limit but each pass's own (each within the pass time limit) when the problem is lean."""
    if c.prob.lean:
        return c.pool.solve_utilities(batch, util, offsets, UNLIMITED)
    return {p: solve_pass(c.prob, p, util[offsets[i]:offsets[i + 1]], c.spec, budget)
            for i, p in enumerate(batch)}
