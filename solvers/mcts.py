"""MCTS with the trained agent: ``eosp solve INST --solver mcts --checkpoint CK --budget 100``."""

from __future__ import annotations

import time


from eosp.envs.sources import prepare_instance
from eosp.instances.instance import Instance
from eosp.search.mcts import solve as mcts_solve
from eosp.solvers.base import Solution
from eosp.solvers.policy import evaluate_batch, make_env_for, resolve_agent, value_weights


def solve(inst: Instance, *, mode: str = "utility", time_limit: float | None = None, seed: int = 0,
          checkpoint: str = "", agent: tuple | None = None, budget: int | None = None, c_puct: float = 1.25,
          batch: int = 8, gumbel: bool = False, **_: object) -> Solution:
    if budget is not None and budget < 0:
        raise ValueError(f"budget must be a non-negative number of simulations, got {budget}")
    model, env_cfg, _ = resolve_agent("mcts", checkpoint, agent, mode)
    prepared = prepare_instance(inst, env_cfg.prune)
    env = make_env_for(prepared, env_cfg)
    vw = value_weights(model, prepared)  # lexicographic heads: per-class values weighed by class utilities
    t0 = time.perf_counter()
    if budget is None:  # with a time limit, bounded by it only
        budget = 1_000_000 if time_limit is not None else 100
    nodes, ret, stats = mcts_solve(env, lambda obss: evaluate_batch(model, obss, vw), num_simulations=int(budget or 0),
                                   c_puct=c_puct, batch=batch, seed=seed, time_limit=time_limit,
                                   gumbel=gumbel)
    return Solution.from_path(inst, nodes, mode, {"solver": "mcts", "budget": budget, "simulations": stats.simulations,
                                   "expansions": stats.expansions, "evaluations": stats.evaluations,
                                   "seconds": time.perf_counter() - t0,
                                   "return": ret})
