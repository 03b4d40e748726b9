"""RLlib glue of the onboard policy: the environment under RLlib's ``MultiAgentEnv``, the policy as an RLModule
(every satellite one agent, all acting with one shared module), and PPO's configuration.

The module is :class:`eosp.models.onboard.OnboardNet` as it is: logits over the candidate slots and "none"
(empty slots masked), the value from the same pooled features, so the weights PPO trains are the weights
shipped (``onboard.pt``), with no conversion.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis.value_function_api import ValueFunctionAPI
from ray.rllib.core.rl_module.torch.torch_rl_module import TorchRLModule
from ray.rllib.env.multi_agent_env import MultiAgentEnv

from eosp.envs.onboard import OnboardEnv, OnboardEnvConfig
from eosp.models.onboard import OnboardNet
from eosp.ops.onboard import CANDIDATES, FEATURES

SHARED_MODULE = "onboard"


def spaces() -> tuple[Any, Any]:
    import gymnasium as gym

    obs = gym.spaces.Dict({"x": gym.spaces.Box(-1e6, 1e6, (CANDIDATES, len(FEATURES)), np.float32),
                           "mask": gym.spaces.Box(0, 1, (CANDIDATES,), np.int8)})
    return obs, gym.spaces.Discrete(CANDIDATES + 1)


class OnboardMultiAgentEnv(MultiAgentEnv):
    """:class:`eosp.envs.onboard.OnboardEnv` under RLlib's base class; `config`: an OnboardEnvConfig's fields,
    the recordings shared out by env-runner index (each runner flies its own subset)."""

    def __init__(self, config: Any = None):
        super().__init__()
        cfg = dict(config or {})
        recs = list(cfg.get("recordings", []))
        runner = int(getattr(config, "worker_index", 0) or 0)
        runners = int(getattr(config, "num_workers", 0) or 0)
        if runners > 1 and runner >= 1 and len(recs) >= runners:
            recs = recs[runner - 1::runners]
        self.env = OnboardEnv(OnboardEnvConfig(recs, int(cfg.get("seed", 0)) + 1000 * runner))
        self.possible_agents = list(self.env.possible_agents)
        self.agents = []
        obs, act = spaces()
        self.observation_spaces = {a: obs for a in self.possible_agents}
        self.action_spaces = {a: act for a in self.possible_agents}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed)
        self.agents = list(obs)
        return obs, info

    def step(self, action_dict: dict):
        out = self.env.step(action_dict)
        self.agents = [a for a in out[0] if not out[2].get(a, False)]
        return out


def policy_mapping(agent_id: str, *args, **kwargs) -> str:
    return SHARED_MODULE


class OnboardRLModule(TorchRLModule, ValueFunctionAPI):
    """:class:`eosp.models.onboard.OnboardNet` as an RLModule (see the module docstring)."""

    def setup(self) -> None:
        self.net = OnboardNet(int(self.model_config.get("hidden", 32)))

    def _run(self, batch: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor]:
        obs = batch[Columns.OBS]
        return self.net(obs["x"].float(), obs["mask"].bool())

    def _forward(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        logits, _ = self._run(batch)
        return {Columns.ACTION_DIST_INPUTS: logits}

    def _forward_train(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        logits, values = self._run(batch)
        return {Columns.ACTION_DIST_INPUTS: logits, Columns.EMBEDDINGS: values}

    def compute_values(self, batch: dict[str, Any], embeddings: Any | None = None) -> torch.Tensor:
        if embeddings is not None:
            return embeddings
        return self._run(batch)[1]


def ppo_config(recordings: list[str], seed: int, runners: int, train: dict):
    """PPO over the onboard environment: `runners` env runners (each its share of the recordings), one shared
    module; `train`: PPO's numbers (lr, train_batch_size, minibatch_size, num_epochs, entropy_coeff, gamma)."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from eosp.training.ppo import env_runners_get_their_config_by_value
    from eosp.training.rl_module import drop_log_message

    env_runners_get_their_config_by_value()
    drop_log_message("ray.rllib.algorithms.algorithm_config", "on the new API stack! This is the new default")
    spec = MultiRLModuleSpec(rl_module_specs={SHARED_MODULE: RLModuleSpec(
        module_class=OnboardRLModule, model_config={"hidden": int(train.get("hidden", 32))})})
    return (
        PPOConfig()
        .environment(env=OnboardMultiAgentEnv, env_config={"recordings": recordings, "seed": seed},
                     disable_env_checking=True)
        .framework("torch")
        .env_runners(num_env_runners=runners, num_envs_per_env_runner=1, num_cpus_per_env_runner=1,
                     rollout_fragment_length="auto")
        .learners(num_learners=0)
        .rl_module(rl_module_spec=spec)
        .multi_agent(policies={SHARED_MODULE}, policy_mapping_fn=policy_mapping)
        .training(train_batch_size_per_learner=int(train["train_batch_size"]),
                  minibatch_size=int(train["minibatch_size"]), num_epochs=int(train["num_epochs"]),
                  lr=float(train["lr"]), gamma=float(train["gamma"]), lambda_=0.95, clip_param=0.2,
                  entropy_coeff=float(train["entropy_coeff"]), vf_loss_coeff=1.0, vf_clip_param=1e6, grad_clip=1.0)
        .debugging(seed=seed, log_level="WARN", log_sys_usage=False)
        .reporting(metrics_num_episodes_for_smoothing=10)
    )
