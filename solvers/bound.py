"""Upper bounds on the best schedule: the Lagrangian relaxation of "at most once".

A schedule is a path from the source in the discrete graph (a DAG: every arc goes
forward in time) that visits each acquisition at most once.  Without that
exclusion the best path is one longest-path pass over the nodes in time order,
but it is a poor bound: it repeats the same valuable acquisition at several
start times (1.5-5x the optimum in utility mode).

Relaxing "sum of the visits of acquisition j <= 1" with multipliers lam_j >= 0
gives, for every path P that visits each acquisition at most once,

    value(P) = sum_{j in P} (w_j - lam_j) + sum_{j in P} lam_j
             <= max_P' sum_{v in P'} (w_{acq v} - lam_{acq v}) + sum_j lam_j  =: L(lam)

and L(lam) is again one longest-path pass, with node costs w - lam.  Its minimum
over lam equals the LP bound of the arc-flow model (the subproblem has integral
paths), at the cost of one O(arcs) pass per subgradient step instead of a large
LP.  The pass runs backwards, so it also gives for every node v the best
completion ``togo[v]`` after v, which the exact search uses to bound partial
schedules (see :func:`completion_bound`).

The pass runs on the PRUNED graph with *waiting* allowed (a move from (j, t) to
the next node of j, free), which gives the same value as the unpruned graph with
waiting, hence a valid bound for the unpruned problem, with 3-9x fewer arcs.
Why: keep 0 <= lam <= w, so every cost is >= 0.  A pruned arc u -> (j, t_j) has
a witness k with arcs u -> (k, t_k) -> (j, t') and t' <= t_j; replacing the arc
by these two (plus waiting from t' to t_j) adds c_k >= 0 and ends at the same
node.  Both new arcs span strictly less time than the old one, so repeating the
replacement on arcs that are themselves pruned terminates: every relaxed path of
the unpruned graph maps to one of the pruned graph with waiting that is worth at
least as much, from any node.  (Repeats are allowed in the relaxation, which is
what makes the witness usable even if k was already visited.)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numba
import numpy as np

from eosp.graphs.discrete import DiscreteGraph
from eosp.instances.instance import Instance
from eosp.planning.labels import acq_last_time, topological_order
from eosp.solvers.base import objective_weights


@numba.njit(cache=True)
def togo_pass(order, indptr, dst, node_acq, cost, togo, nxt, wait):
    """Backward longest path: togo[v] = best sum of `cost` over a path after v (>= 0, empty allowed).

    nxt[v] is the next node on that path (-1 to stop).  With `wait`, a path may
    also move from (j, t) to the next node of j at no cost (start j later).
    Returns togo at the source.
    """
    n = node_acq.shape[0]
    for i in range(order.shape[0] - 1, -1, -1):
        v = order[i]
        best = 0.0
        arg = -1
        for a in range(indptr[v], indptr[v + 1]):
            w = dst[a]
            val = cost[node_acq[w]] + togo[w]
            if val > best:
                best = val
                arg = w
        if wait and v > 0 and v + 1 < n and node_acq[v + 1] == node_acq[v] and togo[v + 1] > best:
            best = togo[v + 1]
            arg = v + 1
        togo[v] = best
        nxt[v] = arg
    return togo[order[0]]


@numba.njit(cache=True)
def _visits(nxt, node_acq, counts):
    """Visits per acquisition of the path from the source (a wait move is no new visit)."""
    counts[:] = 0
    v = 0
    w = nxt[0]
    while w >= 0:
        if node_acq[w] != node_acq[v]:
            counts[node_acq[w]] += 1
        v = w
        w = nxt[w]


@dataclass
class LagrangianBound:
    """Result of :func:`lagrangian`: the bound, its multipliers and completion values."""

    bound: float  # best L(lam) found, an upper bound of every schedule's value
    lam: np.ndarray  # float64 [n], the multipliers of that bound
    togo: np.ndarray  # float64 [N], best completion after each node with costs w - lam
    iterations: int
    seconds: float


def lagrangian(graph: DiscreteGraph, weights: np.ndarray, *, wait: bool, lower: float = 0.0,
               iterations: int = 300, time_limit: float | None = None, integral: bool = False) -> LagrangianBound:
    """Minimize L(lam) over 0 <= lam <= w by projected subgradient steps (Polyak step sizes).

    `graph` with `wait=False`: the unpruned graph itself; with `wait=True`: the
    pruned graph (see the module docstring).  `lower` is the value of a known
    schedule (the Polyak target): the closer, the faster.  With `integral` (all
    weights integers, unitary mode) it stops as soon as floor(L) <= `lower`,
    which then is proven optimal.
    """
    t0 = time.perf_counter()
    w = np.asarray(weights, dtype=np.float64)
    n = w.shape[0]
    order = topological_order(graph)
    togo = np.zeros(graph.n_nodes, dtype=np.float64)
    nxt = np.full(graph.n_nodes, -1, dtype=np.int32)
    counts = np.zeros(n, dtype=np.int64)
    # Start from lam = w / 2: a repeated acquisition then gains little from its
    # second visit, which already removes most of the repetitions of lam = 0.
    lam = 0.5 * w
    # Steps scaled per acquisition by sqrt(w_j): utilities span 1 to 1e8, and with a
    # plain step the large gaps of the top classes throw the small multipliers from 0
    # to w and back.  (Measured: 50 scaled steps reach the gap that 400 plain ones do.)
    scale = np.sqrt(w)
    best = math.inf
    best_lam = lam.copy()
    theta = 1.0
    stall = 0
    it = 0
    for it in range(1, iterations + 1):
        val = togo_pass(order, graph.indptr, graph.dst, graph.node_acq, w - lam, togo, nxt, wait) + math.fsum(lam)
        if val < best - 1e-12 * abs(best) or not math.isfinite(best):
            best, best_lam, stall = val, lam.copy(), 0
        else:
            stall += 1
            if stall >= 10:
                theta, stall = theta * 0.5, 0
        if integral and math.floor(best + 1e-6) <= lower:
            break
        if best - lower <= 1e-12 * max(1.0, abs(lower)) or theta < 1e-4:
            break
        if time_limit is not None and time.perf_counter() - t0 > time_limit:
            break
        _visits(nxt, graph.node_acq, counts)
        g = 1.0 - counts  # subgradient of L at lam
        # projection on 0 <= lam <= w: a multiplier above w_j only hides j (lowering it to
        # w_j lowers sum(lam) and no path value), and costs w - lam >= 0 make `wait` valid
        g[((lam <= 0.0) & (g > 0.0)) | ((lam >= w) & (g < 0.0))] = 0.0
        dg = scale * g
        norm = float(g @ dg)
        if norm == 0.0:  # the relaxed path is a feasible schedule: L is attained
            break
        step = theta * (val - max(lower, 0.0)) / norm
        lam = np.clip(lam - step * dg, 0.0, w)
    togo_pass(order, graph.indptr, graph.dst, graph.node_acq, w - best_lam, togo, nxt, wait)
    return LagrangianBound(best, best_lam, togo, it, time.perf_counter() - t0)


def upper_bound(inst: Instance, mode: str = "utility", *, lower: float | None = None, iterations: int = 300,
                time_limit: float | None = None) -> float:
    """An upper bound of the value of every schedule (path of the unpruned graph), at any size.

    Lagrangian on the pruned graph with waiting.  Without `lower`, the greedy
    schedule's value is the subgradient target.  Rounded down in unitary mode.
    """
    inst.unpruned("the upper bound")
    w = objective_weights(inst, mode)
    if lower is None:
        from eosp.solvers.greedy import GreedyConfig
        from eosp.solvers.greedy import solve as greedy

        lower = greedy(inst, GreedyConfig(mode=mode)).value
    lb = lagrangian(inst.pruned(), w, wait=True, lower=lower, iterations=iterations, time_limit=time_limit,
                    integral=mode == "unitary")
    return float(math.floor(lb.bound + 1e-6)) if mode == "unitary" else lb.bound


def completion_bound(lb: LagrangianBound, graph: DiscreteGraph) -> np.ndarray:
    """Per node v: an upper bound of what a schedule can still collect after v,
    before subtracting the multipliers of the acquisitions it has already used
    and that are still open (their last node is after v).

    Every acquisition j that can follow v has last_time(j) > t_v, so the
    completion is worth at most togo[v] + sum_{j: last_time(j) > t_v} lam_j.
    `graph` has the nodes of the graph `lb` was computed on.
    """
    last = acq_last_time(graph)
    by_last = np.argsort(last, kind="stable")
    # suffix sums of lam over acquisitions sorted by last time
    suffix = np.concatenate([np.cumsum(lb.lam[by_last][::-1])[::-1], [0.0]])
    k = np.searchsorted(last[by_last], graph.node_time, side="right")  # first j with last > t_v
    return lb.togo + suffix[k]
