"""MCTS with the trained agent: ``eosp solve INST --solver mcts --checkpoint CK --budget 100``."""

from __future__ import annotations

import time
from dataclasses import dataclass

from eosp.envs.sources import prepare_instance
from eosp.instances.instance import Instance
from eosp.search.mcts import SearchParams
from eosp.search.mcts import solve as mcts_solve
from eosp.config import ranged
from eosp.solvers.base import INCUMBENT, SearchConfig, Solution
from eosp.solvers.policy import (evaluate_batch, finish, incumbent_reporter, make_env_for, polisher_for, resolve_agent,
                                 search_time, value_weights)


@dataclass
class MctsConfig(SearchConfig):
    """MCTS guided by the trained agent; with a time limit it stops searching at the deadline and plays
    the rest of the episode from the tree and the policy."""

    budget: int | None = ranged(None, 0)
    """Simulations per decision; unset: 100, or unbounded (the time limit only) when a time limit is given."""
    c_puct: float = ranged(1.25, 0)
    """Exploration constant of the PUCT rule."""
    batch: int = ranged(8, 1)
    """Leaves evaluated per network call (virtual loss)."""
    gumbel: bool = False
    """Gumbel root selection with sequential halving."""

    NAME = "mcts"


def solve(inst: Instance, cfg: MctsConfig | None = None, *, agent: tuple | None = None) -> Solution:
    cfg = cfg or MctsConfig()
    cfg.validate()
    mode, time_limit, seed, budget = cfg.mode, cfg.time_limit, cfg.seed, cfg.budget
    c_puct, batch, gumbel = cfg.c_puct, cfg.batch, cfg.gumbel
    model, env_cfg, _ = resolve_agent("mcts", cfg.checkpoint, agent, mode, n_acquisitions=inst.n_acq,
                                      time_limited=time_limit is not None)
    prepared = prepare_instance(inst, env_cfg.prune)
    env = make_env_for(prepared, env_cfg)
    vw = value_weights(model, prepared)  # lexicographic heads: per-class values weighed by class utilities
    polisher = polisher_for(prepared, cfg)  # set-up (kernels compiled), before the clock starts
    if polisher is not None:  # every polished schedule is the incumbent (Ctrl-C writes it)
        polisher.on_improve = INCUMBENT.offer
    t0 = time.perf_counter()
    if budget is None:  # with a time limit, bounded by it only
        budget = 1_000_000 if time_limit is not None else 100
    params = SearchParams(int(budget or 0), c_puct=c_puct, batch=batch, gumbel=gumbel)
    nodes, ret, stats = mcts_solve(env, lambda obss: evaluate_batch(model, obss, vw, cfg.guard), params, seed=seed,
                                   time_limit=search_time(cfg), on_best=incumbent_reporter(prepared, mode))
    if polisher is not None:  # the played episode and the best one met, both polished: the better
        options = [polisher.actions(prepared.eg.node_acq[nodes])]
        if stats.best_actions:
            options.append(polisher.actions(stats.best_actions))
        ret, acts = max(options, key=lambda o: o[0])
        nodes = finish(polisher, polisher.nodes_of(acts), cfg, t0)
    return Solution.from_path(inst, nodes, mode, {"solver": "mcts", "budget": budget, "simulations": stats.simulations,
                                   "polish": cfg.polish, "refine": cfg.refine, "windows": cfg.windows,
                                   "window_graph": cfg.window_graph,
                                   "expansions": stats.expansions,
                                   "evaluations": stats.evaluations,
                                   "seconds": time.perf_counter() - t0,
                                   "return": ret})
