"""Moves of a solve over its state (:class:`Coordinator`): large neighbourhoods (the passes meeting a random time
span rebuilt in a price-perturbed order, then descent) and, once the prices have converged, the master's best
integer solution over its columns.
"""

from __future__ import annotations


import numpy as np

from eosp.budget import Budget
from eosp.kinds.fleet.battery import battery_repair, offer
from eosp.kinds.fleet.construct import construct, descend
from eosp.kinds.fleet.coordinator import Coordinator
from eosp.kinds.fleet.problem import schedule_windows

INTEGER_MAX_S = 30.0  # seconds the master's integer solution may take at most (integer_round)
INTEGER_NODES = 200  # its branch-and-bound nodes when the solve has no time limit (--rounds): machine-independent


def neighbourhood(c: Coordinator, rng: np.random.Generator, budget: Budget) -> None:
    """Free the passes meeting a random time span, rebuild them in a price-perturbed order, descend."""
    prob = c.prob
    horizon = prob.fleet.horizon.seconds
    a = rng.uniform(-c.cfg.span_s, horizon)
    hit = np.flatnonzero((prob.pass_time[:, 1] >= a) & (prob.pass_time[:, 0] <= a + c.cfg.span_s)
                         & ~c.frozen)
    if len(hit) == 0:
        return
    trial = c.best.copy()
    for p in hit.tolist():
        c._assign(trial, p, np.zeros(0, np.int64))
    order = hit[rng.permutation(len(hit))]
    shift = c.prices.lam * rng.uniform(0.0, 1.0)
    construct(c, order, shift, trial, budget)
    touched = sorted({q for p in hit.tolist() for t in prob.passes[p].tasks.tolist()
                      for q in prob.task_passes[t].tolist()})
    descend(c, trial, touched, budget)
    if trial.value >= c.best.value - 1e-9:
        if battery_repair(c, trial, budget) is None:
            return
        if trial.value >= c.best.value - 1e-9:
            if trial.value > c.best.value + 1e-9:
                c.keep(trial)
            else:
                c.best = trial


def integer_round(c: Coordinator, budget: Budget) -> None:
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
    :func:`offer` takes out what the batteries still cannot hold (first maneuvers of passes, the windows'
    sunlight over-estimate).  When that schedule is not better than the best, the integer solution without the
    rows is tried as well (with half of the time then left): a repaired schedule is not always a packing of
    columns (the repair keeps part of a column), so the rows can cut off a packing that the repair turns into a
    better schedule (test_hard/case_0004: 0.8847 without the rows, nothing better than 0.8836 with them).  Rows
    only for the batteries a solution runs dry, added after each solve and without the slews, were tried before
    and not kept: the re-solves cost the time the first solve needed and the repair still took out most of what
    they saved."""
    c.integer_done = True
    tries = ([schedule_windows(c.prob)] if c.cfg.integer_energy else []) + [None]
    for windows in tries:
        if not budget.limited:
            sel = c.master.integer(c.best.paths, INTEGER_MAX_S, INTEGER_NODES, windows)
        else:
            left = budget.left()
            if left <= 0:
                return
            sel = c.master.integer(c.best.paths, min(INTEGER_MAX_S, 0.5 * left), windows=windows)
        if not sel:
            continue
        primal = c.empty()
        for i in sel:
            p, path = c.master.col_pass[i], c.master.col_path[i]
            if c.frozen[p]:
                continue
            c._assign(primal, p, path)  # barred tasks too: the battery repair says what the battery allows
        descend(c, primal, list(range(len(c.prob.passes))), budget)
        if offer(c, primal, budget):
            return
