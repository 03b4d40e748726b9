"""Policy-guided beam search with rollouts: ``eosp solve INST --solver beam --beam-width 4 --time-limit 10``.

Keeps the W best partial schedules, extends each by the policy's top-k actions and
scores each child by a greedy policy rollout (:func:`eosp.search.rollouts.beam`).
Anytime: with a time limit it returns the best complete schedule met so far; the
first one is the plain policy's, so it never does worse.
"""

from __future__ import annotations

from dataclasses import dataclass

from eosp.instances.instance import Instance
from eosp.search.rollouts import beam
from eosp.config import ranged
from eosp.solvers.base import SearchConfig, Solution
from eosp.solvers.policy import run_search


@dataclass
class BeamConfig(SearchConfig):
    """Policy-guided beam search with rollouts; anytime: at the time limit, the best complete schedule met."""

    beam_width: int = ranged(4, 1)
    """Partial schedules kept."""
    expand: int = ranged(4, 1)
    """Children of each partial schedule: the policy's top actions."""

    NAME = "beam"


def solve(inst: Instance, cfg: BeamConfig | None = None, *, agent: tuple | None = None) -> Solution:
    cfg = cfg or BeamConfig()
    cfg.validate()
    return run_search("beam", inst, cfg, agent,
                      lambda env, ev, improve, limit, on_best: beam(env, ev, width=cfg.beam_width, expand=cfg.expand,
                                                                    seed=cfg.seed, time_limit=limit, improve=improve,
                                                                    on_best=on_best),
                      beam_width=cfg.beam_width)
