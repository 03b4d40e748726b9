"""The task prices by column generation (``--price-step lp``, :mod:`eosp.kinds.fleet.master`): the bound it reaches
is the linear program over every schedule of every pass (solved here from an enumeration of the passes' paths),
and it never falls below the best valid schedule."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.optimize import linprog

from eosp.fleet.geometry import Geometry
from eosp.fleet.opportunities import compute
from tests.test_fleet import synthetic_fleet


def narrow_fleet(n_tasks: int, seed: int, slack_s: float = 5.0):
    """The synthetic two-satellite fleet (10-minute horizon) with windows a few seconds longer than the tasks, so
    that a pass cannot take every task it sees and satellites contend (the battery as it is there)."""
    fleet = synthetic_fleet(n_tasks=n_tasks, seed=seed)
    tk = fleet.tasks
    mid = 0.5 * (tk.release_s + tk.due_s)
    rel = np.maximum(0.0, np.floor((mid - tk.duration_s / 2 - slack_s / 2) / 5) * 5)
    due = np.minimum(600.0, rel + tk.duration_s + slack_s)
    return dataclasses.replace(fleet, tasks=dataclasses.replace(tk, release_s=rel, due_s=due))


def every_task_set(prob, p: int) -> set[frozenset]:
    """The sets of tasks the paths of pass p serve (a depth-first walk of its graph from the source)."""
    pg = prob.passes[p]
    g = pg.graph
    out, stack = set(), [(0, frozenset())]
    while stack:
        u, done = stack.pop()
        out.add(done)
        for v in g.dst[g.indptr[u]:g.indptr[u + 1]].tolist():
            stack.append((v, done | {int(pg.tasks[g.node_acq[v]])}))
    return out


def full_lp(prob) -> float:
    """max sum v_c x_c over every task set c of every pass, a task served at most once, a pass's sets summing to at
    most 1 (scipy's linprog on the enumerated columns, nothing of the solver's master)."""
    n, P = len(prob.weight), len(prob.passes)
    cols = [(p, c) for p in range(P) for c in every_task_set(prob, p) if c]
    A = np.zeros((n + P, len(cols)))
    v = np.zeros(len(cols))
    for j, (p, c) in enumerate(cols):
        A[list(c), j] = 1.0
        A[n + p, j] = 1.0
        v[j] = prob.weight[list(c)].sum()
    res = linprog(-v, A_ub=A, b_ub=np.ones(n + P), bounds=(0, None), method="highs")
    assert res.status == 0
    return -res.fun


@pytest.mark.parametrize("n_tasks,seed", [(12, 0), (12, 1), (16, 1)])  # 40 weighted steps end 2e-5-1e-2 above
def test_column_generation_reaches_the_linear_program_over_every_pass_schedule(n_tasks, seed):
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.problem import Problem
    from eosp.kinds.fleet.solve import solve

    fleet = narrow_fleet(n_tasks, seed)
    prob = Problem.build(fleet, compute(fleet, Geometry(fleet)))
    assert prob.bound_graphs == 0  # every pass term is its priced optimum: L's minimum is the LP's optimum
    lp = full_lp(prob)
    W = float(prob.weight.sum())
    sol = solve(fleet, prob.opps, FleetConfig(rounds=40, time_limit=None, price_step="lp", seed=seed),
                problem=prob)
    assert lp < W - 1e-6  # the passes contend: the LP is below the conflict-free bound
    assert sol.bound >= lp / W - 1e-9  # no Lagrangian bound is below the LP optimum (weak duality)
    assert sol.bound <= lp / W + 1e-6  # and column generation reaches it
    assert sol.value <= sol.bound + 1e-9


def test_the_smoothed_prices_are_between_the_centre_and_the_duals():
    from eosp.kinds.fleet.master import SMOOTHING, Centre

    c = Centre(np.zeros(3))
    c.observe(np.array([1.0, 2.0, 3.0]), 10.0)
    c.observe(np.array([9.0, 9.0, 9.0]), 11.0)  # a higher L does not move the centre
    assert np.allclose(c.lam, [1.0, 2.0, 3.0])
    got = c.towards(np.array([3.0, 2.0, 1.0]))
    assert np.allclose(got, SMOOTHING * np.array([1.0, 2.0, 3.0]) + (1 - SMOOTHING) * np.array([3.0, 2.0, 1.0]))


def test_a_master_slower_than_its_round_gives_way_to_weighted_steps_from_the_start(monkeypatch):
    """When the master's LP is not solved within its time (a 200-satellite day), the solver drops it and goes on
    with weighted subgradient steps from the prices it started with; the bound stays a bound."""
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.master import Master
    from eosp.kinds.fleet.problem import Problem

    fleet = narrow_fleet(12, 0)
    prob = Problem.build(fleet, compute(fleet, Geometry(fleet)))
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
    start = prob.weight * 0.3
    coord.prices.lam = start.copy()
    monkeypatch.setattr(Master, "duals", lambda self, deadline, limit: None)  # as if out of time
    coord.price_round(None)
    assert coord.master is None and not coord.converged
    assert np.array_equal(coord.prices.lam, start)
    coord.price_round(None)  # a weighted step now
    assert not np.array_equal(coord.prices.lam, start)
    assert coord.best_bound >= full_lp(prob) / 1.0 - 1e-9
