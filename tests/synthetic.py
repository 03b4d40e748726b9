"""Small instances that do not come from our simulator, for tests.

Transition times come from a random rule (a base distance between acquisitions
plus a time-dependent drift), nodes sit on a per-acquisition grid, and the arcs
are found by brute force: the earliest node reachable.  Built with plain numpy
and Python loops, independently of the project's numba graph builder.
"""

from __future__ import annotations

import numpy as np

from eosp.graphs.discrete import DiscreteGraph, acq_ptr_from_node_acq
from eosp.instances.instance import Acquisitions, Instance


def transition(base: np.ndarray, i: int, j: int, t_end: float, period: float = 37.0) -> float:
    """With the default period the transition changes slower than time (FIFO); with a short one, faster."""
    return float(base[i, j] * (1.0 + 0.3 * np.sin(t_end / period + i - j)))


def synthetic_instance(n: int, seed: int, horizon: float = 400.0, step: float = 4.0, period: float = 37.0) -> Instance:
    rng = np.random.default_rng(seed)
    dur = np.round(rng.uniform(3.0, 12.0, n), 1)
    start = np.round(rng.uniform(0.0, horizon - 60.0, n), 2)
    length = dur + rng.uniform(step, 50.0, n)
    end = start + length
    pts = rng.uniform(0, 1, (n, 2))
    base = 2.0 + 25.0 * np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    utility = rng.choice([1.0, 120.0, 3300.0, 1e4, 1e6], size=n) * (1 + 1e-3 * rng.uniform(0, 1, n))
    times = [start[i] + step * np.arange(int(np.floor((end[i] - dur[i] - start[i]) / step + 1e-9)) + 1)
             for i in range(n)]
    node_acq = np.concatenate([[-1]] + [np.full(len(t), i) for i, t in enumerate(times)]).astype(np.int32)
    node_time = np.concatenate([[0.0]] + times)
    acq_ptr = acq_ptr_from_node_acq(node_acq, n)
    rows = []
    for u in range(node_acq.size):
        i = node_acq[u]
        row = []
        for j in range(n):
            if j == i:
                continue
            if i < 0:
                row.append(int(acq_ptr[j]))
                continue
            fin = node_time[u] + dur[i]
            ready = fin + transition(base, i, j, fin, period)
            for w in range(acq_ptr[j], acq_ptr[j + 1]):
                if node_time[w] >= ready:
                    row.append(w)
                    break
        rows.append(row)
    indptr = np.zeros(node_acq.size + 1, dtype=np.int64)
    indptr[1:] = np.cumsum([len(r) for r in rows])
    dst = np.array([w for r in rows for w in r], dtype=np.int32)
    acqs = Acquisitions(duration=dur, vtw_start=start, vtw_end=end, utility=utility,
                        priority=None, lat=None, lon=None, attitude=None)
    graph = DiscreteGraph(node_acq, node_time, indptr, dst, acq_ptr)
    return Instance(name=f"synthetic-{n}-{seed}", acqs=acqs, unpruned_graph=graph,
                    node_ids=np.arange(node_acq.size, dtype=np.int32), meta={"generator": "tests.synthetic"})


def all_paths(inst: Instance, graph: DiscreteGraph | None = None):
    """Every path from the source in `graph` (default: unpruned) that uses each acquisition at most once."""
    g = graph or inst.unpruned()

    def rec(u, used, path):
        yield list(path)
        for a in range(g.indptr[u], g.indptr[u + 1]):
            w = int(g.dst[a])
            j = int(g.node_acq[w])
            if j in used:
                continue
            used.add(j)
            path.append(w)
            yield from rec(w, used, path)
            path.pop()
            used.discard(j)

    yield from rec(0, set(), [])
