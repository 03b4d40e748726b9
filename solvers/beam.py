"""Policy-guided beam search with rollouts: ``eosp solve INST --solver beam --beam-width 4 --time-limit 10``.

Keeps the W best partial schedules, extends each by the policy's top-k actions and
scores each child by a greedy policy rollout (:func:`eosp.search.rollouts.beam`).
Anytime: with a time limit it returns the best complete schedule met so far; the
first one is the plain policy's, so it never does worse.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from eosp.envs.sources import prepare_instance
from eosp.instances.instance import Instance
from eosp.search.rollouts import beam, replay
from eosp.config import ranged
from eosp.solvers.base import LearnedConfig, Solution
from eosp.solvers.policy import evaluate_batch, make_env_for, resolve_agent


@dataclass
class BeamConfig(LearnedConfig):
    """Policy-guided beam search with rollouts; anytime: at the time limit, the best complete schedule met."""

    beam_width: int = ranged(4, 1)
    """Partial schedules kept."""
    expand: int = ranged(4, 1)
    """Children of each partial schedule: the policy's top actions."""

    NAME = "beam"


def solve(inst: Instance, cfg: BeamConfig | None = None, *, agent: tuple | None = None) -> Solution:
    cfg = cfg or BeamConfig()
    cfg.validate()
    mode, time_limit, seed, beam_width, expand = cfg.mode, cfg.time_limit, cfg.seed, cfg.beam_width, cfg.expand
    model, env_cfg, _ = resolve_agent("beam", cfg.checkpoint, agent, mode)
    env = make_env_for(prepare_instance(inst, env_cfg.prune), env_cfg)
    t0 = time.perf_counter()
    best = beam(env, lambda obss: evaluate_batch(model, obss), width=beam_width, expand=expand, seed=seed,
                time_limit=time_limit)
    nodes, _ = replay(env, best.actions, seed)
    return Solution.from_path(inst, nodes, mode, {"solver": "beam", "beam_width": beam_width, "episodes": best.episodes,
                                   "evaluations": best.evaluations, "seconds": time.perf_counter() - t0})
