"""A schedule recovered from a price round's pass schedules (or the master's columns first), over the solve's state
(:class:`Coordinator`): passes in turn keep the tasks no earlier pass took, then coordinate descent.
"""

from __future__ import annotations

import numpy as np

from eosp.budget import Budget
from eosp.interrupt import HeldInterrupt
from eosp.kinds.fleet.construct import descend
from eosp.kinds.fleet.coordinator import Coordinator
from eosp.kinds.fleet.problem import Primal


def recover(c: Coordinator, rng: np.random.Generator, budget: Budget) -> Primal:
    """A schedule from the last price round's pass schedules: passes in random order keep the tasks no
    earlier pass took (the rest of their path re-walked along the graph's arcs), then coordinate descent.
    With the master (``--price-step lp``) the columns of its last solution come first, by decreasing share."""
    n_pass = len(c.prob.passes)
    primal = c.empty()
    done = c.frozen.copy()
    ranked = c.master.ranked() if c.master is not None else []
    order: list[int] = []
    paths: list[np.ndarray] = []
    # --price-step lp: the master's solution first (its columns by decreasing share), then the round's paths
    for p, path in ranked + [(p, c.round_paths[p]) for p in rng.permutation(n_pass).tolist()]:
        if done[p]:
            continue
        done[p] = True
        if len(path):
            order.append(p)
            paths.append(path)
    _take_in_order(c, primal, order, paths)
    descend(c, primal, list(range(n_pass)), budget)
    return primal


def _take_in_order(c: Coordinator, primal: Primal, order: list[int], paths: list[np.ndarray]) -> None:
    """Each pass of `order` in turn takes its path's tasks that no pass before it took (and the repair did not
    bar from its satellite), the rest of its path re-walked along the graph's arcs (a solver's path follows
    them: re-walked only when some of its tasks are taken); `primal` holds the frozen passes only.

    Why not one pass after another: at 200 satellites that loop was a third of the recovery, and on the lean
    driver with two actors the recovery sets the pace of a round.  A pass none of whose tasks is on the path of
    a pass before it in `order` (nor barred, nor a frozen pass's) takes its path whole whatever the others do,
    and no pass before it can want its tasks: those are assigned at once, and only the others, most of them
    near none, are walked in turn, each seeing every pass before it.  The same schedule, and the same value
    summed in the same order, as the loop."""
    if not order:
        return
    owner, rank, pos = c._flat(np.asarray(order, dtype=np.int64), paths)
    tasks = c._task_idx[pos]
    first = np.full(len(c.prob.weight), len(order), dtype=np.int64)
    np.minimum.at(first, tasks, rank)  # the first pass in `order` whose path holds each task
    bad = (first[tasks] != rank) | (primal.served[tasks] >= 0) | c.barred[c._pass_sat[owner], tasks]
    clean = np.ones(len(order), dtype=bool)
    clean[rank[bad]] = False
    ends = np.r_[0, np.cumsum([len(x) for x in paths])]
    value = c._task_val[pos]
    with HeldInterrupt():
        whole = clean[rank]
        primal.served[tasks[whole]] = owner[whole]
        for i in np.flatnonzero(clean).tolist():
            primal.paths[order[i]] = paths[i]
    for i, p in enumerate(order):
        if clean[i]:  # what _assign adds for a path taken whole into an empty pass, in the loop's order
            primal.value += float(value[ends[i]:ends[i + 1]].sum())
            continue
        path = paths[i]
        free = c._available(primal, p)[c.prob.passes[p].graph.node_acq[path]]
        c._assign(primal, p, path if free.all() else c.prob.rewalk(p, path[free]))
