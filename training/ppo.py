"""The RLlib PPO configuration of a run, built from :class:`eosp.config.RunConfig`."""

from __future__ import annotations

from pathlib import Path

from eosp.config import RunConfig, to_dict


def ppo_config(cfg: RunConfig):
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from envs.eosp_env import EOSPEnv
    from training.rl_module import EOSPTorchRLModule

    t = cfg.train
    env_config = to_dict(cfg.env)
    env_config["shards"] = [str(Path(t.train_data).resolve())]
    env_config["seed"] = t.seed
    pc = (
        PPOConfig()
        .environment(env=EOSPEnv, env_config=env_config, disable_env_checking=True)
        .framework("torch")
        .env_runners(num_env_runners=t.num_env_runners, num_envs_per_env_runner=t.num_envs_per_env_runner,
                     num_cpus_per_env_runner=1, rollout_fragment_length="auto",
                     gym_env_vectorize_mode="sync")
        .learners(num_learners=0)
        .rl_module(rl_module_spec=RLModuleSpec(module_class=EOSPTorchRLModule, model_config=to_dict(cfg.model)))
        .training(train_batch_size_per_learner=t.train_batch_size, minibatch_size=t.minibatch_size,
                  num_epochs=t.num_epochs, lr=t.lr, gamma=t.gamma, lambda_=t.gae_lambda, clip_param=t.clip_param,
                  entropy_coeff=t.entropy_coeff, vf_loss_coeff=t.vf_loss_coeff, vf_clip_param=1e6,
                  grad_clip=t.grad_clip, use_kl_loss=False)
        .debugging(seed=t.seed, log_level="WARN")
        .reporting(metrics_num_episodes_for_smoothing=20)
    )
    return pc
