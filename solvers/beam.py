"""Policy-guided beam search with rollouts: ``eosp solve INST --solver beam --beam-width 4 --time-limit 10``.

Keeps the W best partial schedules, extends each by the policy's top-k actions and
scores each child by a greedy policy rollout (:func:`eosp.search.rollouts.beam`).
Anytime: with a time limit it returns the best complete schedule met so far; the
first one is the plain policy's, so it never does worse.
"""

from __future__ import annotations

import time

from eosp.envs.sources import prepare_instance
from eosp.instances.instance import Instance
from eosp.search.rollouts import beam, replay
from eosp.solvers.base import Solution
from eosp.solvers.policy import evaluate_batch, make_env_for, resolve_agent


def solve(inst: Instance, *, mode: str = "utility", time_limit: float | None = None, seed: int = 0,
          checkpoint: str = "", agent: tuple | None = None, beam_width: int = 4, expand: int = 4,
          **_: object) -> Solution:
    if beam_width < 1 or expand < 1:
        raise ValueError(f"beam width and expansion must be at least 1, got {beam_width} and {expand}")
    model, env_cfg, _ = resolve_agent("beam", checkpoint, agent, mode)
    env = make_env_for(prepare_instance(inst, env_cfg.prune), env_cfg)
    t0 = time.perf_counter()
    best = beam(env, lambda obss: evaluate_batch(model, obss), width=beam_width, expand=expand, seed=seed,
                time_limit=time_limit)
    nodes, _ = replay(env, best.actions, seed)
    return Solution.from_path(inst, nodes, mode, {"solver": "beam", "beam_width": beam_width, "episodes": best.episodes,
                                   "evaluations": best.evaluations, "seconds": time.perf_counter() - t0})
