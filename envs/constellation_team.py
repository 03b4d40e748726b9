"""The constellation environment as one decision process: the acting satellite's observation, the fleet's reward.

The searches written for one agent (:mod:`eosp.search.rollouts`: batched sampling and beam; :mod:`eosp.search.mcts`)
play a fleet through this view.  Each step is the decision of the satellite acting now (the event clock of
:class:`eosp.envs.constellation.ConstellationEnv`, unchanged), its reward what the whole fleet gains by it (so an
episode's return is the schedule's WCR, as the sum of every agent's rewards is), and ``snapshot`` / ``restore``
branch the whole fleet's state.  The decisions are the multi-agent environment's; only who is credited differs,
which a search over the team's return needs.  The observation after the last decision has nothing admissible.
"""

from __future__ import annotations

import numpy as np

from eosp.config import FleetEnvConfig
from eosp.envs.constellation import ConstellationEnv, Snapshot
from eosp.envs.constellation_data import PreparedFleet
from eosp.fleet.model import Schedule


class TeamEnv:
    """One fleet played as a single-agent environment (see the module docstring): ``reset``, ``step(action)`` ->
    (observation, fleet reward, done, False, info), ``snapshot`` / ``restore``, :meth:`schedule`."""

    def __init__(self, cfg: FleetEnvConfig, prepared: PreparedFleet):
        self.prepared = prepared
        self.env = ConstellationEnv(cfg, source=prepared)
        space = self.env.observation_space
        self._empty = {k: np.zeros(b.shape, dtype=b.dtype) for k, b in space.spaces.items()}

    def _one(self, obs: dict) -> dict:
        """The acting satellite's observation (the empty one, nothing admissible, when the episode is over)."""
        a = self.env.acting_agent
        return obs[a] if a is not None else self._empty

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        obs, info = self.env.reset(seed=seed, options={"fleet": self.prepared})
        return self._one(obs), info

    def step(self, action: int) -> tuple[dict, float, bool, bool, dict]:
        before = self.env.value
        obs, _, term, _, info = self.env.step({self.env.acting_agent: int(action)})
        done = bool(term["__all__"])
        return self._one(obs), self.env.value - before, done, False, info

    def snapshot(self) -> Snapshot:
        return self.env.snapshot()

    def restore(self, snap: Snapshot) -> None:
        self.env.restore(snap)

    @property
    def value(self) -> float:
        """The return so far: the WCR (or CR) of the schedule built so far."""
        return self.env.value

    def schedule(self) -> Schedule:
        return self.env.schedule()

    def path(self) -> Schedule:
        """The schedule so far (what the searches call a path)."""
        return self.env.schedule()
