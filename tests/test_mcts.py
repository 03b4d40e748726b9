"""MCTS: budget 0 is the policy, a large budget finds the optimum of a tiny instance, determinism."""

import numpy as np
import pytest
import torch

from eosp.envs.sources import prepare_instance
from eosp.config import EnvConfig, ModelConfig
from eosp.models.agent import EOSPAgent
from eosp.search.mcts import SearchParams
from eosp.search.mcts import solve as mcts_solve
from eosp.solvers.policy import evaluate_batch, make_env_for, rollout
from tests.conftest import generated
from tests.synthetic import all_paths, synthetic_instance

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def agent():
    torch.manual_seed(3)
    return EOSPAgent(ModelConfig(hidden_dim=8, n_layers=2, heads=1)).eval()


def run(agent, inst, budget, reward="utility", seed=0, batch=8):
    cfg = EnvConfig(reward=reward)
    env = make_env_for(prepare_instance(inst), cfg)
    return mcts_solve(env, lambda obss: evaluate_batch(agent, obss), SearchParams(budget, batch=batch), seed=seed)


def test_budget_zero_is_the_policy_argmax(agent):
    inst = generated("uniform", 30, 2)
    nodes, _, stats = run(agent, inst, 0)
    ref, _ = rollout(agent, prepare_instance(inst), EnvConfig(reward="utility"))
    np.testing.assert_array_equal(nodes, ref)
    assert stats.simulations == 0


@pytest.mark.parametrize("seed,batch", [(1, 1), (2, 8), (3, 1), (4, 8)])
def test_large_budget_finds_the_optimum_of_a_tiny_instance(agent, seed, batch):
    inst = synthetic_instance(6, seed)
    best = max(inst.acqs.utility[inst.node_acq[p]].sum() if p else 0.0
               for p in all_paths(inst, inst.pruned()))
    nodes, ret, _ = run(agent, inst, 400, batch=batch)
    value = inst.acqs.utility[inst.node_acq[nodes]].sum()
    assert value == pytest.approx(best, rel=1e-12) and ret == pytest.approx(best, rel=1e-9)
    from eosp.solvers.exact import ExactConfig
    from eosp.solvers.exact import solve as exact

    assert value <= exact(inst, ExactConfig(time_limit=30)).value * (1 + 1e-12)


def test_batched_evaluation_makes_fewer_network_calls(agent):
    # over four instances: one short episode alone (7 decisions) leaves little to batch (37 -> 25 calls)
    calls_one = calls_eight = 0
    for seed in (4, 5, 6, 7):
        inst = generated("uniform", 30, seed)
        one = run(agent, inst, 40, batch=1, reward="unitary")
        eight = run(agent, inst, 40, batch=8, reward="unitary")
        calls_one, calls_eight = calls_one + one[2].evaluations, calls_eight + eight[2].evaluations
        assert eight[1] >= run(agent, inst, 0, reward="unitary")[1]
    assert calls_eight * 2 < calls_one  # measured 224 against 541


def test_same_seed_same_result(agent):
    inst = generated("clusters", 30, 1)
    a = run(agent, inst, 8, seed=5)
    b = run(agent, inst, 8, seed=5)
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1] == b[1] and a[2].expansions == b[2].expansions


def test_search_beats_or_matches_the_policy(agent):
    inst = generated("uniform", 30, 4)
    pol = run(agent, inst, 0, reward="unitary")[1]
    assert run(agent, inst, 20, reward="unitary")[1] >= pol


def test_gumbel_root_selection_finds_the_optimum_of_tiny_instances_and_is_seeded():
    import numpy as np
    import torch

    from eosp.config import EnvConfig, ModelConfig
    from eosp.models.agent import EOSPAgent
    from eosp.solvers.base import run_solver
    from tests.synthetic import synthetic_instance

    torch.manual_seed(0)
    agent = (EOSPAgent(ModelConfig(hidden_dim=8, n_layers=1, heads=1, value_scale=5.0)), EnvConfig(reward="unitary"), {})
    for seed in range(3):
        inst = synthetic_instance(8, seed)
        best = run_solver("exact", inst, mode="unitary").value
        a = run_solver("mcts", inst, mode="unitary", agent=agent, budget=200, gumbel=True, seed=1)
        b = run_solver("mcts", inst, mode="unitary", agent=agent, budget=200, gumbel=True, seed=1)
        assert a.value == best and np.array_equal(a.nodes, b.nodes)
        small = run_solver("mcts", inst, mode="unitary", agent=agent, budget=4, gumbel=True)
        policy = run_solver("policy", inst, mode="unitary", agent=agent, polish=False)
        assert small.value >= policy.value - 1  # a handful of simulations never loses much to the policy
