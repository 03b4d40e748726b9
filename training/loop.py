"""One PPO training loop shared by jobs/train.py and every trial of jobs/tune.py."""

from __future__ import annotations

from eosp.config import RunConfig


def iteration_metrics(r: dict, prev_steps: int, module: str = "default_policy") -> tuple[dict[str, float], int]:
    """MLflow-ready metrics of one `algo.train()` result (`module`: the learner's module), and the lifetime step
    count."""
    er = r.get("env_runners", {})
    lr = r.get("learners", {}).get(module, {})
    steps = int(r.get("num_env_steps_sampled_lifetime", 0))
    dt = float(r.get("time_this_iter_s", 0.0)) or 1e-9
    out = {
        "train/episode_return_mean": er.get("episode_return_mean"),
        "train/episode_len_mean": er.get("episode_len_mean"),
        "train/policy_loss": lr.get("policy_loss"), "train/vf_loss": lr.get("vf_loss"),
        "train/entropy": lr.get("entropy"), "train/vf_explained_var": lr.get("vf_explained_var"),
        "train/total_loss": lr.get("total_loss"),
        "perf/iteration_s": dt, "perf/env_steps_per_s": (steps - prev_steps) / dt,
        "perf/env_steps_lifetime": steps,
    }
    clean = {}
    for k, v in out.items():
        try:
            f = float(v)
        except (TypeError, ValueError):
            continue
        if f == f:
            clean[k] = f
    return clean, steps


class Trainer:
    """An RLlib PPO algorithm for a RunConfig, with validation and agent extraction."""

    def __init__(self, cfg: RunConfig, validator=None):
        from eosp.training.ppo import module_id, ppo_config

        self.cfg = cfg
        self.module = module_id(cfg)
        self.validator = validator
        self.algo = ppo_config(cfg).build_algo()
        self.steps = 0
        self.last_validation = None  # the ValidationResult of the latest validation

    def agent(self):
        from eosp.models.checkpoint import agent_from_rllib_weights

        from eosp.config import FleetEnvConfig
        from eosp.envs.constellation_obs import N_FLEET_FEATURES
        from eosp.envs.observation import N_NODE_FEATURES

        width = N_FLEET_FEATURES if isinstance(self.cfg.env, FleetEnvConfig) else N_NODE_FEATURES
        return agent_from_rllib_weights(self.algo.learner_group.get_weights()[self.module], self.cfg.model, width)

    def load(self, agent) -> None:
        """Start from an agent's weights (resume)."""
        from eosp.models.checkpoint import rllib_weights_from_agent

        self.algo.learner_group.set_weights({self.module: rllib_weights_from_agent(agent)})
        self.algo.env_runner_group.sync_weights(from_worker_or_learner_group=self.algo.learner_group,
                                                inference_only=True)

    def train(self, validate: bool) -> tuple[dict[str, float], object | None]:
        """One PPO iteration; with `validate`, the validation metrics and the agent that got them."""
        metrics, self.steps = iteration_metrics(self.algo.train(), self.steps, self.module)
        agent = None
        if validate and self.validator is not None:
            agent = self.agent()
            self.last_validation = self.validator.run(agent)  # the per-instance figures behind the metrics
            metrics.update(self.last_validation.metrics)
        return metrics, agent

    def stop(self) -> None:
        self.algo.stop()
