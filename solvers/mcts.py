"""MCTS with the trained agent: ``eosp solve INST --solver mcts --checkpoint CK --budget 100``."""

from __future__ import annotations

import time

import numpy as np
import torch

from envs.sources import prepare_instance
from instances.instance import Instance
from search.mcts import solve as mcts_solve
from solvers.base import Solution, objective_weights
from solvers.policy import evaluate, make_env_for


def solve(inst: Instance, *, mode: str = "utility", time_limit: float | None = None, seed: int = 0,
          checkpoint: str = "", agent: tuple | None = None, budget: int | None = 100, c_puct: float = 1.25,
          **_: object) -> Solution:
    from models.checkpoint import load_agent

    if agent is None:
        if not checkpoint:
            raise ValueError("the mcts solver needs --checkpoint (a directory holding agent.pt and agent.json)")
        torch.set_num_threads(1)
        agent = load_agent(checkpoint)
    model, env_cfg, _ = agent
    env = make_env_for(prepare_instance(inst, env_cfg.prune), env_cfg)
    t0 = time.perf_counter()
    nodes, ret, stats = mcts_solve(env, lambda obs: _evaluate(model, obs), num_simulations=int(budget or 0),
                                   c_puct=c_puct, seed=seed)
    w = objective_weights(inst, mode)
    value = float(w[inst.graph.node_acq[nodes]].sum()) if len(nodes) else 0.0
    return Solution(nodes, value, {"solver": "mcts", "budget": budget, "simulations": stats.simulations,
                                   "expansions": stats.expansions, "seconds": time.perf_counter() - t0,
                                   "return": ret})


def _evaluate(model, obs: dict) -> tuple[np.ndarray, float]:
    logits, values = evaluate(model, obs)
    return logits, float(values[0])
