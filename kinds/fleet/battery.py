"""The battery of a schedule over the solve's state (:class:`Coordinator`): observations dropped until every
battery holds (the checker's model), on the pool's actors when they own the satellites; a schedule offered and kept
when, repaired, it serves more than the best.
"""

from __future__ import annotations

import time

import numpy as np

from eosp.budget import UNLIMITED, Budget
from eosp.fleet.timeline import Rows, repair_rows
from eosp.kinds.fleet.construct import descend
from eosp.kinds.fleet.coordinator import Coordinator
from eosp.kinds.fleet.problem import Primal, path_tasks

REPAIR_AWAY = 4  # a battery repair of fewer satellites runs on the driver, not on the pool (a round trip costs
# milliseconds, a satellite's simulation about one)


def battery_repair(c: Coordinator, primal: Primal, budget: Budget = UNLIMITED, whole: bool = False) -> int | None:
    """Drop observations until every battery holds (checker's model); a dropped task is barred from that
    satellite, and the passes of other satellites that could serve it are solved again once (then the
    batteries are checked and repaired again).  Returns the number dropped (also counted in
    :attr:`repair_drops`), or None when `budget` ran out first: `primal` is then not repaired and must not be
    kept.  `whole` (the first schedule): the repair runs to its end whatever the budget (the re-solves
    still stop at its end).  Only the satellites whose observations changed since their battery was last seen to
    hold are simulated, on the pool when it offers it (:func:`_repair_rows`).  The frozen passes' observations
    are dropped only when nothing after them comes before a battery runs dry (:func:`kept_until`)."""
    total = 0
    guard = kept_until(c)
    for attempt in range(2):  # the last attempt only repairs: what it returns holds
        rows = c.rows(primal)
        if guard is not None:
            rows = rows._replace(kept_until=guard[rows.sats])
        keys = [rows.task[a:b].tobytes() + rows.start[a:b].tobytes()
                for a, b in zip(rows.offsets[:-1].tolist(), rows.offsets[1:].tolist())]
        todo = np.array([i for i, k in enumerate(rows.sats.tolist()) if c.battery_ok.get(k) != keys[i]],
                        dtype=np.int64)  # satellites not seen as they are
        part = rows.part(todo)
        kept = _repair_rows(c, part, UNLIMITED if whole else budget)
        if kept is None:
            return None
        for i, k in enumerate(part.sats.tolist()):
            a, b = int(part.offsets[i]), int(part.offsets[i + 1])
            ok = kept[a:b]
            c.battery_ok[k] = part.task[a:b][ok].tobytes() + part.start[a:b][ok].tobytes()
        dropped = int((~kept).sum())
        if not dropped:
            break
        total += dropped
        c.repair_drops += dropped
        drop_task = part.task[~kept]
        drop_sat = np.repeat(part.sats, np.diff(part.offsets))[~kept]
        drop_pass = primal.served[drop_task]
        c.barred[drop_sat, drop_task] = True
        for p in np.unique(drop_pass).tolist():  # ascending, as the passes always were
            path = primal.paths[p]
            ok = ~np.isin(path_tasks(c.prob, p, path), drop_task[drop_pass == p])
            c._assign(primal, p, path[ok] if c.frozen[p] else c.prob.rewalk(p, path[ok]))
        if attempt < 1:  # one round of re-solves of the passes that could take the dropped tasks
            descend(c, primal, sorted({q for t in drop_task.tolist() for q in c.prob.task_passes[t].tolist()}),
                         budget)
    return total


def kept_until(c: Coordinator) -> np.ndarray | None:
    """Per satellite, the end of its last frozen pass (-inf: none); None when no pass is frozen.  Why: a frozen
    pass is kept as given (a plan already uploaded, in operation one already executed), so the battery repair
    takes what the battery cannot hold from the passes after it (:func:`eosp.fleet.timeline.repair_battery`,
    `kept_until`), and from a frozen pass only when the battery runs dry before any of them."""
    if not c.frozen.any():
        return None
    guard = np.full(len(c.prob.fleet.satellites), -np.inf)
    np.maximum.at(guard, c._pass_sat[c.frozen], c.prob.pass_time[c.frozen, 1])
    return guard


def _repair_rows(c: Coordinator, rows: Rows, budget: Budget) -> np.ndarray | None:
    """:func:`eosp.fleet.timeline.repair_rows` of `rows`: on the pool when it offers ``repair_rows`` (Ray's
    actors, each repairing the satellites it owns), is free (no prefetched round still on it) and there are
    at least :data:`REPAIR_AWAY` satellites; else here.  The same result either way (a satellite's repair reads
    its own rows only)."""
    away = getattr(c.pool, "repair_rows", None)
    if away is not None and len(rows.sats) >= REPAIR_AWAY and not c._pool_busy():
        t = time.perf_counter()
        c._pool_calls += 1
        try:
            return away(rows, budget)
        finally:
            c._pool_s += time.perf_counter() - t
    return repair_rows(c.prob.fleet, c.prob.los, rows, c.sun, budget)


def offer(c: Coordinator, primal: Primal, budget: Budget = UNLIMITED) -> bool:
    """Keep `primal` (after battery repair) when it serves more than the best (not when the budget cut its
    repair)."""
    if battery_repair(c, primal, budget) is None:
        return False
    if primal.value > c.best.value + 1e-9:
        c.keep(primal)
        return True
    return False
