"""RAMP: label-setting search for the best path of the discrete graph.

The paper's reference "RAMP" is a Dijkstra search in the discrete graph that is not exact because of the
exclusion between the nodes of one acquisition.  Here it is the forward label sweep of
:func:`eosp.planning.labels.label_search` (the nodes by time, labels carrying their open acquisitions) with
``beam`` labels per node: a heuristic (a label dropped for lack of room may have been the prefix of the
optimum; the default graph, the pruned one, keeps every schedule: :mod:`eosp.graphs.prune`).  With ``beam=1``
it is the classic "best path per node, skip repeats"; with no beam, the exact
solver's dynamic program (:mod:`eosp.solvers.exact`).

When the time limit is reached the rest of the sweep keeps one label per node, so the result is always a
complete schedule.
"""

from __future__ import annotations

from dataclasses import dataclass

from eosp.config import ranged
from eosp.instances.instance import Instance
from eosp.planning.labels import label_search
from eosp.solvers.base import Solution, SolverConfig, objective_weights


@dataclass
class RampConfig(SolverConfig):
    """RAMP: label setting with a beam of labels per node.  At the time limit the rest of the sweep keeps
    one label per node, so the answer is always a complete schedule."""

    beam: int = ranged(4, 1)
    """Labels kept per node (1: the classic best path per node, skipping repeats)."""
    pruned: bool = True
    """Search the pruned graph (false: the unpruned one, slower; both hold every schedule)."""

    NAME = "ramp"


def solve(inst: Instance, cfg: RampConfig | None = None) -> Solution:
    """RAMP with `cfg.beam` labels per node on the pruned (default) or unpruned graph."""
    cfg = cfg or RampConfig()
    cfg.validate()
    g = inst.graph_for(cfg.pruned)
    w = objective_weights(inst, cfg.mode)
    res = label_search(g, w, beam=cfg.beam, time_limit=cfg.time_limit)
    return Solution(res.nodes, res.value, {"solver": "ramp", "beam": cfg.beam, "pruned": cfg.pruned,
                                           "complete": res.complete, "labels": res.labels,
                                           "seconds": res.seconds})
