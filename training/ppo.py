"""The RLlib PPO configuration of a run, built from :class:`eosp.config.RunConfig`."""

from __future__ import annotations

from pathlib import Path

from eosp.config import FleetEnvConfig, RunConfig, to_dict
from eosp.reward import reward


def estimate_value_scale(cfg: RunConfig, episodes: int = 8) -> float:
    """Mean return of random episodes on training instances: the scale of the value targets."""
    import numpy as np

    from eosp.envs.eosp_env import EOSPEnv
    from eosp.envs.sources import ShardSource, expand_shards

    env = EOSPEnv(cfg.env, source=ShardSource(expand_shards([cfg.train.train_data]), max_cached=episodes,
                                             prune=cfg.env.prune, unpruned=bool(cfg.env.plan)))
    returns = []
    for ep in range(episodes):
        env.reset(seed=cfg.train.seed + ep)
        total, per_class, done = 0.0, 0.0, not env.action_mask().any()
        while not done:
            _, r, done, _, info = env.step(env.action_space.sample())
            total += r
            per_class = per_class + info.get("reward_vector", 0.0)
        returns.append(env.reward.episode_return(total, per_class))
    return float(max(1.0, np.mean(returns)))


def env_runners_get_their_config_by_value() -> None:
    """Env runners are created with their AlgorithmConfig inside the actor's creation task, not as an object in
    Ray's object store.

    RLlib puts the config in the object store once and hands every env-runner actor its reference; with
    ``restart_failed_env_runners`` the actors have ``max_restarts > 0``, and Ray then logs at error level, for
    every actor, that a restart fails if that object is lost (core_worker.cc), a line a user reads as a failure.
    The config is some 12 kB pickled (below Ray's 100 kB limit for arguments inlined in the task), so each actor
    carries its own copy: a restarted actor (tests/test_platform.py kills one mid-training) needs nothing from the
    object store, and the line is gone.  Installed on RLlib's EnvRunnerGroup once, for this process."""
    from ray.rllib.env.env_runner_group import EnvRunnerGroup

    if isinstance(EnvRunnerGroup.__dict__.get("_remote_config_obj_ref"), property):
        return

    def get(self):
        return self._remote_config

    def put(self, value):  # RLlib's ray.put(config) in __init__: kept in the object store, never handed out
        self.__dict__["_remote_config_ref_unused"] = value

    EnvRunnerGroup._remote_config_obj_ref = property(get, put)


def ppo_config(cfg: RunConfig):
    """PPO on the single pass (`cfg` a RunConfig), or on the constellation (a FleetRunConfig: multi-agent env
    runners over the demo set's fleets, every satellite mapped to the one shared module)."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from eosp.envs.eosp_env import EOSPEnv
    from eosp.training.rl_module import EOSPTorchRLModule, drop_log_message

    env_runners_get_their_config_by_value()
    # RLlib announces the new API stack to every PPO user (it is the default, and what this project uses)
    drop_log_message("ray.rllib.algorithms.algorithm_config", "on the new API stack! This is the new default")

    t = cfg.train
    scale = cfg.model.value_scale or 1.0
    env_config = to_dict(cfg.env)
    fleet = isinstance(cfg.env, FleetEnvConfig)
    if fleet:  # the demo set's fleets, shared out by env-runner index
        from eosp.training.fleet_demos import read_demo_set

        env_config["fleets"] = [r["fleet"] for r in read_demo_set(t.train_data)]
    else:
        env_config["shards"] = [str(Path(t.train_data).resolve())]
    env_config["seed"] = t.seed
    from eosp.training.learner import EOSPPPOLearner

    learner = {"learner_class": EOSPPPOLearner}
    if not fleet and reward(cfg.env.reward).per_class:  # the fleet's rewards ('wcr', 'cr') are scalars
        from eosp.training.lexicographic import LexicographicPPOLearner

        learner = {"learner_class": LexicographicPPOLearner}
    algo_class = None
    if t.overlap_sampling:
        from eosp.training.overlap import OverlappedPPO

        algo_class = OverlappedPPO
    model_config = {**to_dict(cfg.model), "rollout_values": t.rollout_values}  # the latter: the module's own key
    env_class, module_spec = EOSPEnv, RLModuleSpec(module_class=EOSPTorchRLModule, model_config=model_config)
    if fleet:  # one agent per satellite, all acting with one shared module
        from eosp.training.fleet_env import SHARED_MODULE, FleetMultiAgentEnv, policy_mapping, shared_module_spec

        env_class, module_spec = FleetMultiAgentEnv, shared_module_spec(model_config)
    pc = (
        PPOConfig(algo_class=algo_class)
        .environment(env=env_class, env_config=env_config, disable_env_checking=True)
        .framework("torch")
        .env_runners(num_env_runners=t.num_env_runners, num_envs_per_env_runner=t.num_envs_per_env_runner,
                     num_cpus_per_env_runner=1, rollout_fragment_length="auto",
                     gym_env_vectorize_mode="sync",
                     custom_resources_per_env_runner={t.env_runner_resource: 1} if t.env_runner_resource else {})
        .learners(num_learners=0, num_gpus_per_learner=t.num_gpus_per_learner, **learner)
        .rl_module(rl_module_spec=module_spec)
        .training(train_batch_size_per_learner=t.train_batch_size, minibatch_size=t.minibatch_size,
                  num_epochs=t.num_epochs, lr=t.lr, gamma=t.gamma, lambda_=t.gae_lambda, clip_param=t.clip_param,
                  entropy_coeff=t.entropy_coeff, vf_loss_coeff=t.vf_loss_coeff / scale**2, vf_clip_param=1e12,
                  grad_clip=t.grad_clip, use_kl_loss=False)
        .fault_tolerance(restart_failed_env_runners=True)
        .debugging(seed=t.seed, log_level="WARN", log_sys_usage=False)  # perf/*: our own, training/loop.py
        .reporting(metrics_num_episodes_for_smoothing=20)
    )
    if fleet:
        pc = pc.multi_agent(policies={SHARED_MODULE}, policy_mapping_fn=policy_mapping)
    return pc


def module_id(cfg) -> str:
    """The RLlib module the policy is: the single agent's default one, or the fleet's shared one."""
    if isinstance(cfg.env, FleetEnvConfig):
        from eosp.training.fleet_env import SHARED_MODULE

        return SHARED_MODULE
    return "default_policy"
