"""The constellation environment under RLlib's MultiAgentEnv base class, and a shared-policy multi-agent spec.

RLlib's multi-agent env runners accept only subclasses of ``MultiAgentEnv``; :class:`FleetMultiAgentEnv` is
:class:`eosp.envs.constellation.ConstellationEnv` (whose API already is RLlib's: dicts keyed by agent id,
``"__all__"``, one acting agent per step, rewards carried to each agent's next observation) under that base, built
from an ``env_config`` dict (RLlib's EnvContext: worker and vector index choose the fleets and seeds).  Vectorized
runners (``num_envs_per_env_runner`` > 1) use RLlib's synchronous multi-agent vector env.

:func:`shared_module_spec` maps every satellite slot to one module (parameter sharing): the project's RLModule
(:class:`eosp.training.rl_module.EOSPTorchRLModule`), which reads the padded graph observation as it reads the
single pass's (its input width taken from the observation space).
"""

from __future__ import annotations

from typing import Any

from ray.rllib.env.multi_agent_env import MultiAgentEnv

from eosp.envs.constellation import ConstellationEnv

SHARED_MODULE = "satellite"


class FleetMultiAgentEnv(MultiAgentEnv):
    """:class:`eosp.envs.constellation.ConstellationEnv` as an RLlib ``MultiAgentEnv`` (same contract)."""

    def __init__(self, config: Any = None, source: Any = None):
        super().__init__()
        self.env = ConstellationEnv(config, source)
        self.possible_agents = list(self.env.possible_agents)
        self.agents = []
        self.observation_spaces = self.env.observation_spaces
        self.action_spaces = self.env.action_spaces

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        out = self.env.reset(seed=seed, options=options)
        self.agents = list(self.env.agents)
        return out

    def step(self, action_dict: dict):
        return self.env.step(action_dict)


def policy_mapping(agent_id: str, *args, **kwargs) -> str:
    """Every satellite slot acts with the one shared module."""
    return SHARED_MODULE


def shared_module_spec(model_config: dict):
    """A MultiRLModuleSpec with the project's RLModule as the one module every satellite uses."""
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from eosp.training.rl_module import EOSPTorchRLModule

    return MultiRLModuleSpec(rl_module_specs={SHARED_MODULE: RLModuleSpec(module_class=EOSPTorchRLModule,
                                                                          model_config=model_config)})
