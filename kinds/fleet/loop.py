"""The run of a solve over its state (:class:`Coordinator`): the first schedule (constructed, or from an initial
schedule, then descent and the battery repair), then rounds (the ceiling round, price rounds each followed by a
recovered schedule and moves, the integer round once converged) until the budget, the time limit or the bound.
"""

from __future__ import annotations

import time

import numpy as np

from eosp.budget import Budget
from eosp.fleet.check import validate
from eosp.fleet.model import Schedule
from eosp.kinds.fleet.battery import battery_repair, offer
from eosp.kinds.fleet.construct import construct, descend
from eosp.kinds.fleet.coordinator import Coordinator
from eosp.kinds.fleet.dual import ceiling_round, prefetch, price_round
from eosp.kinds.fleet.moves import integer_round, neighbourhood
from eosp.kinds.fleet.problem import Primal
from eosp.kinds.fleet.recovery import recover

CHECK_MARGIN = 1.5  # the final check's estimate times this (a better schedule has more actions, a loaded machine)
CHECK_SLACK_S = 0.2  # seconds added to it (the time the first steps after the budget's end take)


def run(c: Coordinator) -> Primal:
    cfg, prob = c.cfg, c.prob
    budget = Budget.of(cfg.time_limit, start=c.t0)  # the time limit counts from when the problem was read
    rng = np.random.default_rng(cfg.seed if c.start_round == 0 else [cfg.seed, c.start_round])
    order = np.argsort(prob.pass_time[:, 0], kind="stable")
    first = c.empty()
    try:  # Ctrl-C while the first schedule is built: the passes built so far are the answer
        if c.initial is not None:  # start from the given schedule (its paths re-walked unless frozen)
            for p in np.flatnonzero(~c.frozen).tolist():
                path = c.initial.paths[p]
                free = c._available(first, p)[prob.passes[p].graph.node_acq[path]] if len(path) else path
                c._assign(first, p, prob.rewalk(p, path[free]) if len(path) else path)
        else:  # every pass, each solve cut short past the budget's end
            construct(c, order, primal=first, budget=budget, whole=True)
        descend(c, first, list(range(len(prob.passes))), budget)
    except KeyboardInterrupt:
        c.interrupted = True
    # the first schedule is repaired whole (its re-solves stop at the budget's end; none after Ctrl-C)
    c.first_repair_drops = battery_repair(c, first, Budget.spent() if c.interrupted else budget,
                                                  whole=True)
    if first.value > c.best.value + 1e-9:
        c.keep(first)
    c.first_s = time.perf_counter() - c.t0
    if not c.interrupted:
        if budget.limited and not budget.expired():  # past it: no round, nothing to reserve
            c.check_s = check_estimate(c, first)  # kept for the final check of a schedule like this one
            budget = budget.less(c.check_s)
        try:
            _rounds(c, budget, rng)
        except KeyboardInterrupt:  # Ctrl-C: the best schedule so far is the answer
            c.interrupted = True
    return c.best


def check_estimate(c: Coordinator, primal: Primal) -> float:
    """Seconds the final steps will take on a schedule like `primal` (its timelines and the checker on it,
    :func:`eosp.fleet.check.validate`), with a margin: the checker's fixed cost (timed on no action) plus its
    cost per action, timed on the actions of the first satellites (a tenth of the actions, at least 40),
    scaled to all (the checker's work is per satellite and per action)."""
    t = time.perf_counter()
    sched = c.schedule(primal)
    n = len(sched)
    t_fixed = time.perf_counter()
    validate(c.prob.fleet, Schedule(*(np.zeros(0, a.dtype) for a in
                                         (sched.satellite, sched.task, sched.start_us, sched.end_us))),
             c.prob.geo)
    t_sub = time.perf_counter()
    fixed = t_sub - t_fixed
    per_action = 0.0
    if n:
        sats, counts = np.unique(sched.satellite, return_counts=True)
        upto = int(np.searchsorted(np.cumsum(counts), max(0.1 * n, min(n, 40)))) + 1
        keep = np.isin(sched.satellite, sats[:upto])
        validate(c.prob.fleet, Schedule(sched.satellite[keep], sched.task[keep], sched.start_us[keep],
                                           sched.end_us[keep]), c.prob.geo)
        per_action = max(0.0, time.perf_counter() - t_sub - fixed) / int(keep.sum())
    return CHECK_MARGIN * ((t_fixed - t) + fixed + per_action * n) + CHECK_SLACK_S


def _rounds(c: Coordinator, budget: Budget, rng: np.random.Generator) -> None:
    cfg = c.cfg
    rounds = c.start_round
    c.rounds_done = rounds
    while cfg.rounds is None or rounds < cfg.rounds:
        if budget.expired():
            break
        if c.best_bound <= c.best.value + 1e-9:
            break  # proven optimal
        if cfg.pass_solver == "exact" and rounds == 0:
            if ceiling_round(c, budget) is None:
                break
            c.record()
        if (cfg.pass_solver == "exact" or rounds == 0) and not c.converged:
            before = c.best_bound
            t_round = time.perf_counter()
            if price_round(c, budget) is None:
                break
            c.round_s.append(time.perf_counter() - t_round)
            c.prices.stalled(c.best_bound < before - 1e-9)
            c.record()
            if cfg.pass_solver == "exact" and not c.converged and (cfg.rounds is None
                                                                      or rounds + 1 < cfg.rounds):
                prefetch(c, budget)
            c._pool_s, c._pool_calls, t = 0.0, 0, [time.perf_counter()]
            primal = recover(c, rng, budget)
            t.append(time.perf_counter())
            kept = offer(c, primal, budget)
            t.append(time.perf_counter())
            if not kept:
                neighbourhood(c, rng, budget)
            t.append(time.perf_counter())
            c.phases.append({"round": round(c._wait_s, 3),
                                "prices": round(c.round_s[-1] - c._wait_s, 3),
                                "recover": round(t[1] - t[0], 3), "repair": round(t[2] - t[1], 3),
                                "moves": round(t[3] - t[2], 3), "pool": round(c._pool_s, 3),
                                "pool_calls": c._pool_calls})
        elif c.converged and not c.integer_done and c.master is not None:
            integer_round(c, budget)
        else:
            neighbourhood(c, rng, budget)
        rounds += 1
        c.rounds_done = rounds
        if c.on_round is not None:
            c.on_round(c)
