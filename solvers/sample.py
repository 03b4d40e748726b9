"""Best of K policy samples, batched: ``eosp solve INST --solver sample --samples 32 --time-limit 5``.

One network call per step for all K episodes (:func:`eosp.search.rollouts.sample`);
the first episode is the greedy one, so the result is never below the policy's own greedy episode
(``--solver policy --incumbent false``; the policy solver's incumbent, a Greedy completion of one of its
states, can be above it).
With a time limit, rounds of K episodes go on until it is reached (anytime).
"""

from __future__ import annotations

from dataclasses import dataclass

from eosp.instances.instance import Instance
from eosp.search.rollouts import sample
from eosp.config import ranged
from eosp.solvers.base import SearchConfig, Solution
from eosp.solvers.policy import run_search


@dataclass
class SampleConfig(SearchConfig):
    """Best of batched policy samples; with a time limit, rounds go on until it is reached (anytime)."""

    samples: int = ranged(16, 1)
    """Episodes per batched round (the first one is the greedy episode)."""
    temperature: float = ranged(1.0, 0)
    """Softmax temperature of the sampled episodes (0: the argmax)."""

    NAME = "sample"


def solve(inst: Instance, cfg: SampleConfig | None = None, *, agent: tuple | None = None) -> Solution:
    cfg = cfg or SampleConfig()
    cfg.validate()
    return run_search("sample", inst, cfg, agent,
                      lambda env, ev, improve, limit, on_best: sample(env, ev, samples=cfg.samples,
                                                                      temperature=cfg.temperature, seed=cfg.seed,
                                                                      time_limit=limit, improve=improve,
                                                                      on_best=on_best),
                      samples=cfg.samples)
