"""A random feasible schedule: a random walk in the pruned discrete graph.

From the last node, pick uniformly one of its arcs to an acquisition not used
yet; stop when there is none.  A baseline for sanity checks, nothing more.
"""

from __future__ import annotations

import numpy as np

from eosp.instances.instance import Instance
from dataclasses import dataclass

from eosp.solvers.base import Solution, SolverConfig


@dataclass
class RandomConfig(SolverConfig):
    """The random walk: only the shared options; one pass, so no time limit."""

    NAME = "random"
    ONE_SHOT = True


def solve(inst: Instance, cfg: RandomConfig | None = None) -> Solution:
    cfg = cfg or RandomConfig()
    cfg.validate()
    g = inst.pruned()
    rng = np.random.default_rng(cfg.seed)
    used = np.zeros(inst.n_acq, dtype=bool)
    node = 0
    path = []
    while True:
        row = g.dst[g.indptr[node]:g.indptr[node + 1]]
        row = row[~used[g.node_acq[row]]]
        if row.size == 0:
            break
        node = int(row[rng.integers(row.size)])
        used[g.node_acq[node]] = True
        path.append(node)
    nodes = np.asarray(path, dtype=np.int64)
    return Solution.from_path(inst, nodes, cfg.mode, {"solver": "random"})
