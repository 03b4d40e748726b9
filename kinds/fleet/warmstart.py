"""Where the fleet solver's task prices start (``--warm-start none|heuristic|learned``).

The coordinator's prices are the Lagrangian multipliers of "a task is served at most once"; their optimum is a
function of how contested each task is, by which passes, how crowded those passes are.  A start near it saves
price rounds, the expensive part of a large fleet's solve.  Three starts:

* ``none``: every price 0 (the pass optima then serve every task they can: the round-0 bound is weak);
* ``heuristic``: each task's weight times ``1 - 1/s``, s the number of satellites that can serve it (a task only
  one satellite sees is not contested, one seen by many is nearly free to leave to the others);
* ``learned``: the price network of :mod:`eosp.models.prices` over the task-opportunity graph below (the shipped
  model: ``models/pretrained-prices``), trained by jobs/train_prices.py on the aeossp train split and generated
  fleets.

Any start is valid: L(lam) bounds every schedule for every lam >= 0, so a start changes how soon the bound and
the schedules are good, never whether the bound holds.  A task held by at most one pass gets price 0 in every
start: its subgradient 1 - served is never negative, so lowering its price never raises L.

The task-opportunity graph (:func:`task_graph`): a node per task and per pass, an edge per (task, pass) pair the
pass can serve; features are scale-free (weights over the fleet's mean weight, times in minutes or hours).
"""

from __future__ import annotations

import math

import numpy as np

from eosp.kinds.fleet.problem import Problem
from eosp.models.prices import PASS_FEATURES, TaskGraph

START_KINDS = ("none", "heuristic", "learned")


def satellites_per_task(prob: Problem) -> np.ndarray:
    sat = np.array([pg.satellite for pg in prob.passes], dtype=np.int64)
    return np.array([len(np.unique(sat[h])) for h in prob.task_passes], dtype=np.float64)


def heuristic_prices(prob: Problem) -> np.ndarray:
    """Each task's weight times 1 - 1/(satellites that can serve it); 0 for a task held by at most one pass."""
    s = satellites_per_task(prob)
    npass = np.array([len(h) for h in prob.task_passes])
    return np.where(npass > 1, prob.weight * (1.0 - 1.0 / np.maximum(s, 1.0)), 0.0)


def task_graph(prob: Problem) -> TaskGraph:
    """The graph and its features (see the module docstring); one pass over the opportunities, numpy only."""
    fleet, opps = prob.fleet, prob.opps
    w = prob.weight
    mean_w = float(w.mean()) if len(w) and w.mean() > 0 else 1.0
    tasks = fleet.tasks
    step = float(fleet.horizon.action_step_s)
    dur = tasks.duration_s.astype(np.float64)
    npass = np.array([len(h) for h in prob.task_passes], dtype=np.float64)
    nsat = satellites_per_task(prob)
    x_task = np.column_stack([
        w / mean_w, dur / 60.0, np.log1p((tasks.due_s - tasks.release_s).astype(np.float64) / 3600.0),
        np.log1p(npass), np.log1p(nsat), 1.0 - 1.0 / np.maximum(nsat, 1.0), 1.0 - 1.0 / np.maximum(npass, 1.0)])

    # edges: the (pass, task) pairs of the opportunities, with the first and last start of each pair
    key = opps.pass_id.astype(np.int64) * len(w) + opps.task
    uniq, count = np.unique(key, return_counts=True)
    order = np.lexsort((opps.start, key))
    last = order[np.searchsorted(key[order], uniq, side="right") - 1]
    e_pass, e_task = uniq // len(w), uniq % len(w)
    t_first = opps.start[order[np.searchsorted(key[order], uniq)]].astype(np.float64) * step
    t_last = opps.start[last].astype(np.float64) * step + dur[e_task]
    P = len(prob.passes)
    span = np.maximum(prob.pass_time[:, 1] - prob.pass_time[:, 0], 1.0) if P else np.zeros(0)
    conflicts = np.zeros(len(uniq))
    rival_w = np.zeros(len(uniq))
    bounds = np.searchsorted(e_pass, np.arange(P + 1))
    for p in range(P):  # tasks of a pass whose observation intervals overlap this one's
        a, b = bounds[p], bounds[p + 1]
        if b - a < 2:
            continue
        s, e, ww = t_first[a:b], t_last[a:b], w[e_task[a:b]]
        ov = (s[:, None] < e[None, :]) & (s[None, :] < e[:, None])
        np.fill_diagonal(ov, False)
        conflicts[a:b] = ov.sum(1)
        rival_w[a:b] = ov.astype(np.float64) @ ww
    k = np.bincount(e_pass, minlength=P).astype(np.float64)
    demand = np.bincount(e_pass, weights=w[e_task], minlength=P)
    work = np.bincount(e_pass, weights=w[e_task] * dur[e_task], minlength=P)
    x_pass = np.column_stack([np.log1p(k), demand / mean_w / np.maximum(k, 1.0), work / mean_w / span,
                              np.log1p(span / 60.0)]) if P else np.zeros((0, len(PASS_FEATURES)))
    pos = (t_first - prob.pass_time[e_pass, 0]) / span[e_pass] if P else np.zeros(0)
    x_edge = np.column_stack([np.log1p(count.astype(np.float64)), np.log1p(conflicts),
                              w[e_task] / (w[e_task] + rival_w + 1e-12), pos])
    return TaskGraph(x_task.astype(np.float32), x_pass.astype(np.float32), e_task.astype(np.int64),
                     e_pass.astype(np.int64), x_edge.astype(np.float32), w, npass > 1)


def start_prices(prob: Problem, kind: str, model_dir: str | None = None) -> np.ndarray:
    """The prices a solve starts from (see the module docstring); `model_dir` None: the shipped price model."""
    if kind == "none":
        return np.zeros(len(prob.weight))
    if kind == "heuristic":
        return heuristic_prices(prob)
    from eosp.models.prices import load_price_model, predict

    model = load_price_model(model_dir)
    g = task_graph(prob)
    return np.where(g.contested, predict(model, g) * g.weight, 0.0)


def dual_round(prob: Problem, lam: np.ndarray) -> tuple[float, np.ndarray]:
    """One price round under `lam`: L(lam) as a fraction of the total weight (each pass's proven term, see
    :func:`eosp.kinds.fleet.problem.solve_round_pass`, plus the prices; inf when a pass term is not proven) and
    how many passes serve each task (L's subgradient is 1 - that count)."""
    from eosp.kinds.fleet.problem import PassSpec, path_tasks, priced, solve_round_pass

    spec = PassSpec()
    total = float(lam.sum())
    count = np.zeros(len(prob.weight))
    for pg in prob.passes:
        res = solve_round_pass(pg, priced(prob.pass_values(pg.pass_id), lam[pg.tasks]), spec)
        total += math.inf if res.bound is None else res.bound
        count[path_tasks(prob, pg.pass_id, res.nodes)] += 1
    return total / prob.total_weight, count


def dual_value(prob: Problem, lam: np.ndarray) -> float:
    """L(lam) as a fraction of the total weight (:func:`dual_round`)."""
    return dual_round(prob, lam)[0]
