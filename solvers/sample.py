"""Best of K policy samples, batched: ``eosp solve INST --solver sample --samples 32 --time-limit 5``.

One network call per step for all K episodes (:func:`eosp.search.rollouts.sample`);
the first episode is the greedy one, so the result is never below ``--solver policy``.
With a time limit, rounds of K episodes go on until it is reached (anytime).
"""

from __future__ import annotations

import time

from eosp.envs.sources import prepare_instance
from eosp.instances.instance import Instance
from eosp.search.rollouts import replay, sample
from eosp.solvers.base import Solution
from eosp.solvers.policy import evaluate_batch, make_env_for, resolve_agent


def solve(inst: Instance, *, mode: str = "utility", time_limit: float | None = None, seed: int = 0,
          checkpoint: str = "", agent: tuple | None = None, samples: int = 16, temperature: float = 1.0,
          **_: object) -> Solution:
    if samples < 1:
        raise ValueError(f"samples must be at least 1, got {samples}")
    model, env_cfg, _ = resolve_agent("sample", checkpoint, agent, mode)
    env = make_env_for(prepare_instance(inst, env_cfg.prune), env_cfg)
    t0 = time.perf_counter()
    best = sample(env, lambda obss: evaluate_batch(model, obss), samples=samples, temperature=temperature,
                  seed=seed, time_limit=time_limit)
    nodes, _ = replay(env, best.actions, seed)
    return Solution.from_path(inst, nodes, mode, {"solver": "sample", "samples": samples, "episodes": best.episodes,
                                   "evaluations": best.evaluations, "seconds": time.perf_counter() - t0})
