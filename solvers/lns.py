"""Greedy, then local search until the time limit: ``eosp solve INST --solver lns --time-limit 10``.

The classical control of the learned searches.  Their schedules are polished and
refined by the same moves (:mod:`eosp.search.polish`: insert and swap, then ruin
and recreate); this solver starts those moves from the operational Greedy's
schedule instead of the policy's, so that a benchmark can tell what the learned
start is worth at equal time (``benchmarks/bench_anytime.py --methods ... lns``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from eosp.config import choice, ranged
from eosp.instances.instance import Instance
from eosp.search.polish import Polisher
from eosp.solvers.base import INCUMBENT, Solution, SolverConfig, objective_weights
from eosp.solvers.greedy import GreedyConfig
from eosp.solvers.greedy import solve as greedy


@dataclass
class LnsConfig(SolverConfig):
    """The operational Greedy's schedule, polished, then ruin and recreate until the time limit."""

    iterations: int = ranged(20_000, 1)
    """Ruin-and-recreate rounds when no time limit is given."""
    windows: bool = True
    """Alternate window re-planning with the ruin and recreate (eosp.planning.windows), as the learned searches do."""
    window_graph: str = choice("pruned", "pruned", "unpruned")
    """The arcs a window's label sweep looks at: the pruned graph's (RAMP's: 6-170 arcs per node against 50-770
    unpruned from 100 to 1500 acquisitions, so many more windows per second where schedules are long) or the
    unpruned graph's (every arc; windows there mostly exceed their work bound from ~500 acquisitions on).  The
    schedule itself may keep using every arc."""

    NAME = "lns"


def solve(inst: Instance, cfg: LnsConfig | None = None) -> Solution:
    cfg = cfg or LnsConfig()
    cfg.validate()
    polisher = Polisher(inst.unpruned("the lns solver"), objective_weights(inst, cfg.mode),  # set-up: kernels
                        window_graph=inst.pruned() if cfg.window_graph == "pruned" else None)
    polisher.on_improve = INCUMBENT.offer  # each better schedule is the incumbent (Ctrl-C writes it)
    t0 = time.perf_counter()
    start = greedy(inst, GreedyConfig(mode=cfg.mode))
    INCUMBENT.offer(start.nodes, start.value)
    deadline = None if cfg.time_limit is None else t0 + cfg.time_limit
    nodes = polisher.refine(polisher(start.nodes), deadline=deadline, iterations=cfg.iterations, seed=cfg.seed,
                            windows=cfg.windows)
    return Solution.from_path(inst, nodes, cfg.mode, {"solver": "lns", "greedy": start.value,
                                                      "rounds": polisher.rounds,
                                                      "windows": polisher.window_rounds,
                                                      "seconds": time.perf_counter() - t0})
