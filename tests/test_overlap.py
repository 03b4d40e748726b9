"""Overlapped sampling (training/overlap.py): same batches and step counts as PPO, and no weight sync lost."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from eosp.shards.io import write_shard
from tests.conftest import generated


@pytest.fixture
def algo(tmp_path):
    import ray

    from eosp.config import RunConfig
    from eosp.training.ppo import ppo_config

    write_shard(tmp_path / "train" / "shard-0.parquet", [generated("uniform", 12, s) for s in range(3)])
    cfg = RunConfig()
    cfg.train.train_data, cfg.train.val_data = str(tmp_path / "train"), ""
    cfg.train.train_batch_size, cfg.train.minibatch_size, cfg.train.num_epochs = 64, 32, 2
    cfg.train.overlap_sampling = True
    cfg.env.max_acquisitions, cfg.env.reward = 16, "unitary"
    cfg.model.hidden_dim, cfg.model.n_layers, cfg.model.heads, cfg.model.value_scale = 8, 2, 1, 5.0
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    algo = ppo_config(cfg).build_algo()
    yield algo
    algo.stop()
    ray.shutdown()


def test_overlapped_ppo_counts_every_batch_and_never_drops_a_weight_sync(algo):
    from eosp.training.overlap import OverlappedPPO

    assert isinstance(algo, OverlappedPPO)
    learner = algo.learner_group._learner

    def runner_weights():
        # runs on the runner after the in-flight sample and the queued weight sync
        (state,) = algo.env_runner_group.foreach_env_runner(lambda r: r.module.get_state(), local_env_runner=False)
        return {k: torch.as_tensor(np.array(v)) for k, v in state.items()}

    steps = []
    for i in range(3):
        result = algo.train()
        steps.append(int(result["num_env_steps_sampled_lifetime"]))
        assert algo._in_flight == 1  # the next batch is already being sampled while this returns
        if i == 0:
            after_first = runner_weights()
    # every iteration counts one whole batch: 64 steps, or a step or two more when RLlib's vectorized envs
    # overshoot (plain PPO on this fixture counts 65 / 130 / 195 as well); a dropped or doubled batch fails
    per_iteration = np.diff([0] + steps)
    assert np.all((per_iteration >= 64) & (per_iteration <= 64 + 2)), steps
    assert np.isfinite(result["learners"]["default_policy"]["policy_loss"])

    # the runner then holds exactly the learner's latest weights (a dropped sync would leave older ones),
    # and they moved since the first iteration
    now = runner_weights()
    learner_state = learner.module["default_policy"].get_state()
    assert set(now) <= set(learner_state)
    for name, value in now.items():
        assert torch.equal(value, torch.as_tensor(np.array(learner_state[name]))), name
    assert any(not torch.equal(now[k], after_first[k]) for k in now)


@pytest.mark.parametrize("reward", ["unitary", "lexicographic"])
def test_rollout_values_are_the_learners_own_values(tmp_path, reward):
    """GAE's values taken from the runners' pass (--train.rollout-values, on by default) equal a full learner pass
    when the runner holds the learner's weights (plain PPO, first batch); the bootstrap rows are evaluated."""
    import ray
    from ray.rllib.core.columns import Columns

    from eosp.config import RunConfig
    from eosp.training.ppo import ppo_config

    write_shard(tmp_path / "train" / "shard-0.parquet", [generated("uniform", 12, s) for s in range(3)])
    cfg = RunConfig()
    cfg.train.train_data, cfg.train.val_data = str(tmp_path / "train"), ""
    cfg.train.train_batch_size, cfg.train.minibatch_size, cfg.train.num_epochs = 64, 32, 2
    cfg.train.overlap_sampling = False
    assert cfg.train.rollout_values
    cfg.env.max_acquisitions, cfg.env.reward = 16, reward
    cfg.model.hidden_dim, cfg.model.n_layers, cfg.model.heads, cfg.model.value_scale = 8, 2, 1, 5.0
    if reward == "lexicographic":
        from eosp.config import N_CLASSES

        cfg.model.n_values = N_CLASSES
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        algo = ppo_config(cfg).build_algo()
        (episodes,) = algo.env_runner_group.foreach_env_runner(lambda r: r.sample(), local_env_runner=False)
        learner = algo.learner_group._learner
        module = learner.module["default_policy"]
        seen = []
        own = module.compute_values

        def spy(batch, embeddings=None):
            values = own(batch, embeddings)
            if embeddings is None:
                assert Columns.VF_PREDS in batch  # the runners' values reached the learner
                full = own({k: v for k, v in batch.items() if k != Columns.VF_PREDS})
                seen.append((values, full, batch[Columns.LOSS_MASK]))
            return values

        module.compute_values = spy
        learner._learner_connector(rl_module=learner.module, batch={}, episodes=episodes, shared_data={},
                                   metrics=None)
        (values, full, loss_mask), = seen
        assert values.shape == full.shape and values.shape[0] == loss_mask.shape[0] >= 64
        assert int((~loss_mask.bool()).sum()) >= 1  # bootstrap rows were there, and evaluated
        assert torch.allclose(values, full, atol=1e-5), float((values - full).abs().max())
        assert float(full.abs().max()) > 1e-3
        result = algo.train()
        assert np.isfinite(result["learners"]["default_policy"]["total_loss"])
        algo.stop()
    finally:
        ray.shutdown()
