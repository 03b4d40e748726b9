"""Exact solver: label-setting dynamic programming with Lagrangian bounds.

The optimum is the best path from the source of the discrete graph that visits
each acquisition at most once.  The sweep runs on the unpruned graph, the
reference (the pruned graph has the same optimum, :mod:`eosp.graphs.prune`, and
the fleet's pass graphs are not pruned).

Why not an arc-flow integer program: it has one binary per arc (0.5M at 100
acquisitions); HiGHS takes 1-23 s at 30 acquisitions where this DP takes
milliseconds (tests/test_solvers.py checks that both agree), and the program
grows with the arcs (tens of millions at 1000 acquisitions).  The
structure that makes the problem easy instead is that windows are short (at
most ~2.5 minutes in a ~97 minute orbit): an acquisition can only be repeated
while its window is open, so the state of a partial schedule is its last node
plus the few acquisitions it used whose window is still open.  The DP over these
states, with dominance, is exact (:func:`eosp.planning.labels.label_search` with no
beam); it needs no LP at all.

Steps:

1. incumbent: the better of greedy and RAMP;
2. bound: the Lagrangian relaxation of "at most once" (:mod:`solvers.bound`, on
   the pruned graph with waiting, which bounds the unpruned problem), run for a
   short budget; in unitary mode floor(bound) == incumbent already proves
   optimality (the common case), in utility mode it sometimes does too;
3. the exact label sweep over the unpruned graph, in which a label is cut when
   its value plus the Lagrangian completion bound of its node (minus the
   multipliers of its open acquisitions, which it cannot use again) cannot beat
   the incumbent.  When the sweep ends, the incumbent is optimal.

Every instance starts with the sweep alone, with nothing to cut against: up to :data:`SMALL_INSTANCE`
acquisitions with the whole label memory (most passes of a fleet under its prices; on a generated
200-satellite day the incumbent and the bound took three quarters of the pass solves' time), above with at most
:data:`ALONE_LABELS` live labels, where it stops early and the steps run.  Why above too: the fleet's larger
passes have short windows and few open sets, so the sweep alone proves them in a few thousand labels; on passes
of over 300 opportunities of a 1,000-satellite day under prices, pruning the graph for RAMP and the bound took
62% of a solve and the sweep alone gave the same optima in a fifth of the time.  Should it not finish (its label
budget, or the time limit), the steps run as for any instance.

With a time (or label memory) limit the sweep stops and the result is the best
schedule known, with ``info["bound"]`` = min(Lagrangian bound, max(incumbent,
best bound of a label not swept yet)), ``info["gap"]`` = (bound - value) / bound
and ``info["status"]`` = "time_limit"; otherwise "optimal" (gap 0, up to a
relative 1e-12 in utility mode).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from eosp.instances.instance import Instance
from eosp.config import ranged
from eosp.solvers.base import INCUMBENT, Solution, SolverConfig, objective_weights
from eosp.solvers.bound import completion_bound, lagrangian
from eosp.solvers.greedy import GreedyConfig
from eosp.solvers.greedy import solve as greedy
from eosp.graphs.discrete import DiscreteGraph
from eosp.planning.labels import FIRST_LABELS, Bounds, SearchResult, label_search
from eosp.solvers.ramp import RampConfig
from eosp.solvers.ramp import solve as ramp


MAX_LABELS = 20_000_000  # the exact sweep's label memory unless configured (about 1 GB at a few open acquisitions)


@dataclass
class ExactConfig(SolverConfig):
    """The exact label-setting DP with Lagrangian bounds.  At the time (or label memory) limit it returns
    the best schedule known with its bound and gap (status "time_limit")."""

    lagrangian_iterations: int = ranged(400, 0)
    """Subgradient iterations of the Lagrangian bound."""
    max_labels: int = ranged(MAX_LABELS, 1)
    """Label memory of the exact sweep; reaching it stops the sweep like the time limit."""

    NAME = "exact"


SMALL_INSTANCE = 12  # acquisitions: up to this many, the label sweep runs alone first
ALONE_LABELS = FIRST_LABELS  # above it, live labels the sweep alone may hold before the incumbent and bound take
# over: the label store's first size, so a sweep that stops there has allocated nothing more


def solve(inst: Instance, cfg: ExactConfig | None = None) -> Solution:
    cfg = cfg or ExactConfig()
    cfg.validate()
    t0 = time.perf_counter()
    res = sweep_alone(inst.unpruned("the exact solver"), objective_weights(inst, cfg.mode), cfg.time_limit,
                      cfg.max_labels)
    if res is not None:
        INCUMBENT.offer(res.nodes, res.value)
        info = {"solver": "exact", "start": "label_search", "start_value": float(res.value),
                "labels": res.labels, "pruned": res.pruned, "dominated": res.dominated}
        return _done(res.nodes, res.value, res.value, "optimal", info, t0)
    return solve_steps(inst, cfg, t0)


def sweep_alone(graph: DiscreteGraph, w: np.ndarray, time_limit: float | None,
                max_labels: int) -> SearchResult | None:
    """The first step of :func:`solve`, on a graph and its acquisitions' weights `w`: the label sweep with nothing
    to cut against, with the whole label memory up to :data:`SMALL_INSTANCE` acquisitions and at most
    :data:`ALONE_LABELS` live labels above; its result when it finished (the optimum), else None.  Taken apart so
    that the fleet's pass solves run it on a pass graph without building an instance first (most passes end
    here; those that do not go on with :func:`solve_steps`)."""
    alone = max_labels if len(w) <= SMALL_INSTANCE else min(max_labels, ALONE_LABELS)
    if alone <= 0:
        return None
    res = label_search(graph, w, beam=0, time_limit=time_limit, max_labels=alone, on_limit="stop")
    return res if res.complete else None


def solve_steps(inst: Instance, cfg: ExactConfig, t0: float) -> Solution:
    """:func:`solve` once the sweep alone did not finish (started at `t0`, whose time counts): the incumbent,
    the bound, the sweep cut by both."""
    mode, time_limit = cfg.mode, cfg.time_limit
    lagrangian_iterations, max_labels = cfg.lagrangian_iterations, cfg.max_labels
    unitary = mode == "unitary"
    w = objective_weights(inst, mode)
    g = inst.unpruned("the exact solver")

    def left() -> float | None:
        return None if time_limit is None else max(0.0, time_limit - (time.perf_counter() - t0))

    starts = [greedy(inst, GreedyConfig(mode=mode))]
    INCUMBENT.offer(starts[0].nodes, starts[0].value)  # what Ctrl-C writes while RAMP runs
    starts.append(ramp(inst, RampConfig(mode=mode, time_limit=None if time_limit is None else 0.2 * time_limit)))
    best = max(starts, key=lambda s: s.value)
    nodes, value = best.nodes, best.value
    INCUMBENT.offer(nodes, value)  # what Ctrl-C writes while the bound and the sweep run
    info = {"solver": "exact", "start": best.info["solver"], "start_value": value}

    budget = left()
    pg = inst.pruned()
    lb = lagrangian(pg, w, wait=True, lower=value, iterations=lagrangian_iterations, integral=unitary,
                    time_limit=None if budget is None else 0.3 * budget)
    bound = math.floor(lb.bound + 1e-6) if unitary else lb.bound
    info.update(lagrangian_bound=float(lb.bound), lagrangian_iterations=lb.iterations,
                lagrangian_seconds=round(lb.seconds, 3))
    if bound <= value + (0.0 if unitary else 1e-12 * abs(value)):
        return _done(nodes, value, value, "optimal", info, t0)

    res = label_search(g, w, beam=0, bounds=Bounds(value, lb.lam, completion_bound(lb, pg), unitary),
                       time_limit=left(), max_labels=max_labels, on_limit="stop")
    info.update(labels=res.labels, pruned=res.pruned, dominated=res.dominated)
    if res.nodes.size and res.value > value:
        nodes, value = res.nodes, res.value
    if res.complete:
        return _done(nodes, value, value, "optimal", info, t0)
    frontier = res.frontier_bound
    if unitary:
        frontier = math.floor(frontier + 1e-6)
    return _done(nodes, value, min(bound, max(value, frontier)), "time_limit", info, t0)


def _done(nodes: np.ndarray, value: float, bound: float, status: str, info: dict, t0: float) -> Solution:
    gap = 0.0 if bound <= value else (bound - value) / max(abs(bound), 1e-300)
    info.update(bound=float(bound), gap=float(gap), status=status, seconds=round(time.perf_counter() - t0, 3))
    return Solution(np.asarray(nodes, dtype=np.int64), float(value), info)
