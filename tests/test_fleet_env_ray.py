"""The constellation environment on RLlib's new API stack: vectorized multi-agent env runners sample it with
the project's RLModule shared by every satellite, and one PPO iteration learns from those episodes."""

from __future__ import annotations

import numpy as np
import pytest

from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.io import write_fleet
from eosp.fleet.opportunities import compute

pytestmark = pytest.mark.ray

MODEL = {"hidden_dim": 16, "n_layers": 1, "heads": 1, "value_scale": 1.0}


@pytest.fixture(scope="module")
def fleets(tmp_path_factory):
    root = tmp_path_factory.mktemp("fleets")
    for seed in (1, 2):
        f = generate(FleetGenConfig(satellites=3, tasks=300, hours=3.0, window_min_h=1.0, window_max_h=3.0,
                                    placement="cities", seed=seed))
        write_fleet(f, compute(f), root / f"fleet-{seed:05d}")
    return root


def ppo_config(fleets, envs: int):
    from ray.rllib.algorithms.ppo import PPOConfig

    from eosp.training.fleet_env import SHARED_MODULE, FleetMultiAgentEnv, policy_mapping, shared_module_spec

    return (PPOConfig()
            .environment(FleetMultiAgentEnv, env_config={"fleets": [str(fleets)], "max_nodes": 48, "seed": 1},
                         disable_env_checking=True)
            .framework("torch")
            .env_runners(num_env_runners=0, num_envs_per_env_runner=envs, gym_env_vectorize_mode="sync",
                         rollout_fragment_length="auto")
            .learners(num_learners=0)
            .multi_agent(policies={SHARED_MODULE}, policy_mapping_fn=policy_mapping)
            .rl_module(rl_module_spec=shared_module_spec(MODEL))
            .training(train_batch_size_per_learner=64, minibatch_size=32, num_epochs=1))


def test_vectorized_env_runner_samples_with_one_shared_module(fleets):
    import torch
    from ray.rllib.env.multi_agent_env_runner import MultiAgentEnvRunner

    torch.set_num_threads(1)
    runner = MultiAgentEnvRunner(config=ppo_config(fleets, envs=2))
    assert runner.num_envs == 2
    episodes = runner.sample(num_timesteps=150, random_actions=False)
    done = [e for e in episodes if e.is_done]
    assert done
    for e in done:
        # each satellite's own rewards: their sum over agents is the schedule's WCR, a fraction of the weight
        assert 0.0 <= e.get_return() <= 1.0
        assert set(e.agent_episodes) <= {f"sat_{k}" for k in range(3)}
        for sa in e.agent_episodes.values():
            actions = np.asarray(sa.get_actions())
            obs = sa.get_observations()
            masks = np.asarray(obs["action_mask"] if isinstance(obs, dict) else
                               [o["action_mask"] for o in obs])[:len(actions)]
            assert masks[np.arange(len(actions)), actions].all()  # the module never chose a masked slot
    runner.stop()


def test_one_ppo_iteration_on_the_fleet_env(fleets):
    import ray

    ray.init(address="local", num_cpus=2, include_dashboard=False)
    try:
        algo = ppo_config(fleets, envs=2).build_algo()
        result = algo.train()
        assert result["env_runners"]["num_env_steps_sampled"] >= 64
        learner = result["learners"]["satellite"]
        assert np.isfinite(learner["total_loss"])
        algo.stop()
    finally:
        ray.shutdown()
