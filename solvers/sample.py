"""Best of K policy samples, batched: ``eosp solve INST --solver sample --samples 32 --time-limit 5``.

One network call per step for all K episodes (:func:`eosp.search.rollouts.sample`);
the first episode is the greedy one, so the result is never below ``--solver policy``.
With a time limit, rounds of K episodes go on until it is reached (anytime).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from eosp.envs.sources import prepare_instance
from eosp.instances.instance import Instance
from eosp.search.rollouts import replay, sample
from eosp.config import ranged
from eosp.solvers.base import LearnedConfig, Solution
from eosp.solvers.policy import evaluate_batch, make_env_for, resolve_agent


@dataclass
class SampleConfig(LearnedConfig):
    """Best of batched policy samples; with a time limit, rounds go on until it is reached (anytime)."""

    samples: int = ranged(16, 1)
    """Episodes per batched round (the first one is the greedy episode)."""
    temperature: float = ranged(1.0, 0)
    """Softmax temperature of the sampled episodes (0: the argmax)."""

    NAME = "sample"


def solve(inst: Instance, cfg: SampleConfig | None = None, *, agent: tuple | None = None) -> Solution:
    cfg = cfg or SampleConfig()
    cfg.validate()
    mode, time_limit, seed, samples, temperature = cfg.mode, cfg.time_limit, cfg.seed, cfg.samples, cfg.temperature
    model, env_cfg, _ = resolve_agent("sample", cfg.checkpoint, agent, mode)
    env = make_env_for(prepare_instance(inst, env_cfg.prune), env_cfg)
    t0 = time.perf_counter()
    best = sample(env, lambda obss: evaluate_batch(model, obss), samples=samples, temperature=temperature,
                  seed=seed, time_limit=time_limit)
    nodes, _ = replay(env, best.actions, seed)
    return Solution.from_path(inst, nodes, mode, {"solver": "sample", "samples": samples, "episodes": best.episodes,
                                   "evaluations": best.evaluations, "seconds": time.perf_counter() - t0})
