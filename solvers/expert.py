"""The exact solver as a teacher: best continuations from any environment state.

The environment builds a schedule chronologically in its discrete graph (the
pruned one by default): an action is the next acquisition, started at the
earliest node the last scheduled node has an arc to.  From any state, what is
left is itself an EOSP instance: the *residual graph* made of the last scheduled
node (as the source) and the nodes still alive, with the arcs between them.
Its optimum is the best value the policy can still collect, so

* from the initial state it gives the expert trajectory (the optimal schedule
  of the environment's own graph, replayable action by action), and
* from any state visited by a learner it gives a label (DAgger): the value
  Q*(s, a) = r(a) + V*(s after a) of every allowed action, hence the *set* of
  optimal actions.  Ties are common (in unitary mode most states have several
  optimal next acquisitions); a learner trained on one arbitrary optimal action
  per state is taught tie-breaking noise, one trained on the set is not.

Solving: :func:`optimal_path` runs the project's exact machinery on a graph
(RAMP incumbent, Lagrangian bound, bounded label-setting DP, see
:mod:`eosp.solvers.exact`) with a time limit, returning the best schedule found
and its gap.  :func:`action_values` uses RAMP's beam search on each child
(near-exact and ~10x cheaper; the value of the expert's own action is exact).

Why residual graphs are exact: every node that can still be scheduled is alive
(the environment kills exactly the nodes that became unreachable or belong to a
scheduled acquisition), and all acquisitions scheduled so far have no alive node
left, so "each acquisition at most once" only concerns the residual nodes.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from eosp.envs.core import EnvGraph
from eosp.graphs.discrete import DiscreteGraph, acq_ptr_from_node_acq
from eosp.planning.labels import Bounds, label_search
from eosp.solvers.base import objective_weights
from eosp.solvers.bound import completion_bound, lagrangian


@dataclass
class Residual:
    """The problem left from a state, on a compact graph of its own."""

    graph: DiscreteGraph
    node_map: np.ndarray  # residual node -> environment graph node (0 -> the last scheduled node)
    acq_map: np.ndarray  # residual acquisition -> instance acquisition


def residual(eg: EnvGraph, alive: np.ndarray, last: int) -> Residual:
    """The residual graph of a state: ``last`` as the source, then the alive nodes."""
    keep = np.flatnonzero(alive).astype(np.int64)
    keep = keep[keep != last]
    node_map = np.concatenate([[last], keep]).astype(np.int64)  # canonical order kept (alive nodes sorted)
    new_id = np.full(eg.node_acq.shape[0], -1, dtype=np.int64)
    new_id[node_map] = np.arange(node_map.shape[0])
    acqs = np.unique(eg.node_acq[keep])
    acq_new = np.full(int(eg.acq_ptr.shape[0] - 1), -1, dtype=np.int64)
    acq_new[acqs] = np.arange(acqs.shape[0])
    node_acq = np.concatenate([[-1], acq_new[eg.node_acq[keep]]]).astype(np.int32)
    # arcs: out of `last` and out of alive nodes, into alive nodes
    starts, ends = eg.indptr[node_map], eg.indptr[node_map + 1]
    lens = ends - starts
    idx = np.repeat(starts - np.concatenate([[0], np.cumsum(lens)[:-1]]), lens) + np.arange(lens.sum())
    dst = new_id[eg.dst[idx]]
    src = np.repeat(np.arange(node_map.shape[0]), lens)
    ok = dst > 0
    src, dst = src[ok], dst[ok]
    indptr = np.zeros(node_map.shape[0] + 1, dtype=np.int64)
    np.cumsum(np.bincount(src, minlength=node_map.shape[0]), out=indptr[1:])
    g = DiscreteGraph(node_acq, eg.node_time[node_map].astype(np.float64), indptr, dst.astype(np.int32),
                      acq_ptr_from_node_acq(node_acq, acqs.shape[0]))
    return Residual(g, node_map, acqs.astype(np.int64))


@dataclass
class ExpertPath:
    actions: np.ndarray  # int32: acquisitions in order (the environment's actions)
    value: float  # objective value of the path (weights of `optimal_path`)
    bound: float
    status: str  # "optimal" or "time_limit"
    seconds: float

    @property
    def gap(self) -> float:
        return 0.0 if self.bound <= self.value else (self.bound - self.value) / max(abs(self.bound), 1e-300)


def optimal_path(res: Residual, weights: np.ndarray, *, unitary: bool, time_limit: float | None = None,
                 lagrangian_iterations: int = 200) -> ExpertPath:
    """Best path of a residual graph (exact up to `time_limit`); `weights` per instance acquisition."""
    t0 = time.perf_counter()
    g = res.graph
    if g.n_acq == 0 or g.indptr[1] == 0:
        return ExpertPath(np.zeros(0, np.int32), 0.0, 0.0, "optimal", time.perf_counter() - t0)
    w = np.asarray(weights, dtype=np.float64)[res.acq_map]

    def left() -> float | None:
        return None if time_limit is None else max(0.0, time_limit - (time.perf_counter() - t0))

    def done(nodes: np.ndarray, value: float, bound: float, status: str) -> ExpertPath:
        acts = res.acq_map[g.node_acq[nodes]].astype(np.int32) if nodes.size else np.zeros(0, np.int32)
        return ExpertPath(acts, float(value), float(bound), status, time.perf_counter() - t0)

    inc = label_search(g, w, beam=4)
    nodes, value = inc.nodes, inc.value
    budget = left()
    lb = lagrangian(g, w, wait=False, lower=value, iterations=lagrangian_iterations, integral=unitary,
                    time_limit=None if budget is None else 0.3 * budget)
    bound = math.floor(lb.bound + 1e-6) if unitary else lb.bound
    if bound <= value + (0.0 if unitary else 1e-12 * abs(value)):
        return done(nodes, value, value, "optimal")
    r = label_search(g, w, beam=0, bounds=Bounds(value, lb.lam, completion_bound(lb, g), unitary),
                     time_limit=left(), on_limit="stop")
    if r.nodes.size and r.value > value:
        nodes, value = r.nodes, r.value
    if r.complete:
        return done(nodes, value, value, "optimal")
    frontier = math.floor(r.frontier_bound + 1e-6) if unitary else r.frontier_bound
    return done(nodes, value, min(bound, max(value, frontier)), "time_limit")


def beam_path(res: Residual, weights: np.ndarray, beam: int = 4) -> tuple[np.ndarray, float]:
    """RAMP's beam search on a residual graph: its actions (instance acquisitions) and value."""
    g = res.graph
    if g.n_acq == 0 or g.indptr[1] == 0:
        return np.zeros(0, np.int32), 0.0
    r = label_search(g, np.asarray(weights, dtype=np.float64)[res.acq_map], beam=beam)
    return res.acq_map[g.node_acq[r.nodes]].astype(np.int32), float(r.value)


def beam_value(res: Residual, weights: np.ndarray, beam: int = 4) -> float:
    """Value of RAMP's beam search on a residual graph (a lower bound of its optimum, usually equal)."""
    if res.graph.n_acq == 0 or res.graph.indptr[1] == 0:
        return 0.0
    w = np.asarray(weights, dtype=np.float64)[res.acq_map]
    return float(label_search(res.graph, w, beam=beam).value)


# ---------------------------------------------------------------- environment states
def objective(inst, mode: str) -> np.ndarray:
    """Weights of the expert's objective: 1 per acquisition (unitary) or the utilities (utility modes)."""
    return objective_weights(inst, "unitary" if mode == "unitary" else "utility")


def state_residual(env) -> Residual:
    """The residual problem of an :class:`eosp.envs.eosp_env.EOSPEnv`'s current state."""
    s = env.state
    return residual(s.prepared.eg, s.ep.alive, int(s.ep.last[0]))


def child_residual(env, action: int) -> Residual:
    """The residual problem after `action` (the environment itself is left unchanged)."""
    from eosp.envs import core

    s = env.state
    child = s.ep.copy()
    w = core.apply_action(s.prepared.eg, child, int(action))
    if w < 0:
        raise ValueError(f"action {action} is not allowed in this state")
    return residual(s.prepared.eg, child.alive, int(w))


def action_values(env, weights: np.ndarray, beam: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Allowed actions and their values Q(s, a) = w_a + (beam search value of the child's residual)."""
    allowed = np.flatnonzero(env.state.ep.mask).astype(np.int32)
    q = np.array([weights[a] + beam_value(child_residual(env, int(a)), weights, beam) for a in allowed])
    return allowed, q


def optimal_set(q: np.ndarray, unitary: bool) -> np.ndarray:
    """Indices of the actions whose value is the best (ties within 0.5 in unitary mode, a relative 1e-9 else)."""
    best = float(q.max())
    tol = 0.5 if unitary else 1e-9 * abs(best)
    return np.flatnonzero(q >= best - tol)
