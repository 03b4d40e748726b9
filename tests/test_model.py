"""The GNN agent: shapes, masking, permutation equivariance, batching, checkpoints."""

import numpy as np
import pytest
import torch

from eosp.envs.eosp_env import EOSPEnv
from eosp.envs.sources import FixedSource
from eosp.config import EnvConfig, ModelConfig
from eosp.models.agent import MASKED, EOSPAgent, batch_from_padded
from eosp.models.checkpoint import load_agent, save_agent
from eosp.solvers.policy import rollout
from tests.conftest import generated

torch.set_num_threads(1)


def observations(n_obs=6, n=30, n_max=40, seed=1):
    env = EOSPEnv(EnvConfig(max_acquisitions=n_max), source=FixedSource(generated("uniform", n, seed)))
    obs, _ = env.reset(seed=0)
    out = [obs]
    while len(out) < n_obs:
        obs, _, done, _, _ = env.step(env.action_space.sample())
        out.append(obs)
        if done:
            obs, _ = env.reset()
            out.append(obs)
    return out[:n_obs]


def stack(obss):
    return {k: torch.as_tensor(np.stack([o[k] for o in obss])) for k in obss[0]}


@pytest.fixture(scope="module")
def agent():
    torch.manual_seed(0)
    return EOSPAgent(ModelConfig(hidden_dim=16, n_layers=3, heads=2)).eval()


def test_shapes_and_masking(agent):
    obss = observations()
    gb, valid = batch_from_padded(stack(obss))
    logits, values = agent(gb)
    assert values.shape == (len(obss), 1)
    padded = agent.padded_logits(logits, valid)
    assert padded.shape == (len(obss), 40)
    mask = torch.as_tensor(np.stack([o["action_mask"] for o in obss])) > 0
    assert torch.all(padded[~mask] == MASKED)
    assert torch.all(padded[mask] > MASKED / 2)
    probs = torch.softmax(padded, dim=-1)
    assert torch.all(probs[~mask] == 0)
    # sampling never picks a masked action
    draws = torch.distributions.Categorical(logits=padded).sample((2000,))
    assert torch.all(mask.gather(1, draws.T))


def test_lexicographic_value_heads():
    agent = EOSPAgent(ModelConfig(hidden_dim=8, n_layers=1, heads=1, n_values=7))
    gb, _ = batch_from_padded(stack(observations(3)))
    assert agent(gb)[1].shape == (3, 7)


def test_batch_equals_one_by_one(agent):
    obss = observations(5)
    gb, valid = batch_from_padded(stack(obss))
    logits, values = agent(gb)
    padded = agent.padded_logits(logits, valid)
    for k, o in enumerate(obss):
        g1, v1 = batch_from_padded(stack([o]))
        l1, val1 = agent(g1)
        torch.testing.assert_close(agent.padded_logits(l1, v1)[0], padded[k], rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(val1[0], values[k], rtol=1e-5, atol=1e-5)


def test_node_logits_are_permutation_equivariant(agent):
    (o,) = observations(1)
    n = int(o["n_nodes"][0])
    m = int(o["n_edges"][0])
    perm = np.random.default_rng(0).permutation(n)  # new slot of old node i is inv[i]
    inv = np.argsort(perm)
    p = {k: v.copy() for k, v in o.items()}
    p["x"][:n] = o["x"][perm]
    p["action_mask"][:n] = o["action_mask"][perm]
    p["edge_index"][:, :m] = inv[o["edge_index"][:, :m]]
    shuffle = np.random.default_rng(1).permutation(m)  # edge order does not matter either
    p["edge_index"][:, :m] = p["edge_index"][:, :m][:, shuffle]
    p["edge_attr"][:m] = o["edge_attr"][:m][shuffle]
    g0, v0 = batch_from_padded(stack([o]))
    g1, v1 = batch_from_padded(stack([p]))
    l0, val0 = agent(g0)
    l1, val1 = agent(g1)
    a = agent.padded_logits(l0, v0)[0, :n]
    b = agent.padded_logits(l1, v1)[0, :n]
    torch.testing.assert_close(b, a[perm], rtol=1e-4, atol=1e-4)
    torch.testing.assert_close(val0, val1, rtol=1e-4, atol=1e-4)


def test_any_number_of_nodes(agent):
    """Trained for small instances, runs on bigger ones (no size in the weights)."""
    from eosp.envs.sources import prepare_instance

    for n in (8, 60):
        inst = generated("uniform", n, 3)
        nodes, value = rollout(agent, prepare_instance(inst), EnvConfig())
        assert len(nodes) > 0


def test_checkpoint_round_trip_same_actions(tmp_path, agent):
    from eosp.envs.sources import prepare_instance

    save_agent(agent, tmp_path / "ck", EnvConfig(reward="unitary"))
    back, env_cfg, meta = load_agent(tmp_path / "ck")
    assert env_cfg.reward == "unitary" and meta["model"]["hidden_dim"] == 16
    p = prepare_instance(generated("clusters", 30, 2))
    np.testing.assert_array_equal(rollout(agent, p, EnvConfig())[0], rollout(back, p, EnvConfig())[0])
    # sampling is seeded
    a = rollout(back, p, EnvConfig(), sample=True, seed=5)[0]
    b = rollout(back, p, EnvConfig(), sample=True, seed=5)[0]
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("width", ["LOSES", "PLAN"])
def test_a_checkpoint_without_the_newer_features_loads_and_decides_as_before(tmp_path, agent, width):
    """Checkpoints saved before the lookahead features (LOSES inputs) or the plan features (PLAN inputs)
    existed, their first node layer narrower, load with zero weights for the missing columns: the same
    decisions as the agent with those weights zeroed."""
    import copy

    from eosp.envs import observation
    from eosp.envs.observation import N_NODE_FEATURES
    from eosp.envs.sources import prepare_instance

    w = getattr(observation, width)
    old = copy.deepcopy(agent)
    with torch.no_grad():
        old.node_embed[0].weight[:, w:] = torch.randn(old.node_embed[0].weight.shape[0], N_NODE_FEATURES - w)
    save_agent(old, tmp_path / "ck", EnvConfig())
    state = torch.load(tmp_path / "ck" / "agent.pt", weights_only=True)
    state["node_embed.0.weight"] = state["node_embed.0.weight"][:, :w].clone()
    torch.save(state, tmp_path / "ck" / "agent.pt")
    back = load_agent(tmp_path / "ck")[0]
    assert torch.all(back.node_embed[0].weight[:, w:] == 0)
    with torch.no_grad():
        old.node_embed[0].weight[:, w:] = 0.0
    p = prepare_instance(generated("conflict", 40, 4, step=1.0))
    np.testing.assert_array_equal(rollout(old, p, EnvConfig())[0], rollout(back, p, EnvConfig())[0])
    # any other width is still refused with one line
    state["node_embed.0.weight"] = state["node_embed.0.weight"][:, :w - 1].clone()
    torch.save(state, tmp_path / "ck" / "agent.pt")
    from eosp.errors import InputError

    with pytest.raises(InputError, match="weights do not match the model configuration"):
        load_agent(tmp_path / "ck")


def test_unknown_or_bad_checkpoint(tmp_path, agent):
    from eosp.errors import InputError

    with pytest.raises(InputError, match="nothing: checkpoint not found"):
        load_agent(tmp_path / "nothing")
    save_agent(agent, tmp_path / "ck", EnvConfig())
    (tmp_path / "ck" / "agent.pt").write_bytes(b"\x80\x04not a zip")
    with pytest.raises(InputError, match="agent.pt: not a torch weights file") as exc:
        load_agent(tmp_path / "ck")
    assert "\n" not in str(exc.value) and "weights_only" not in str(exc.value)  # never torch's unsafe advice


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_numba_rewiring_is_the_torch_rewiring_and_the_head_is_the_paper_head(agent, seed):
    """The CPU path builds the rewired CSR in one numba pass and sums the action head layer by layer;
    both must be exactly what the plain torch construction (the GPU path) and the concatenated head give."""
    from eosp.models.gat import EdgeStructure

    obss = observations(n_obs=7, n=25 + 5 * seed, seed=seed)
    gb, _ = batch_from_padded(stack(obss))
    fast = agent.edges(gb)
    ref = EdgeStructure(*agent.rewire(gb), gb.x.shape[0] + gb.n_graphs)
    for name in ("indptr", "src", "dst", "types", "attr"):
        assert torch.equal(getattr(fast, name), getattr(ref, name)), name
    assert fast.max_degree == ref.max_degree
    # head: linear layer over [all layers of the node | all layers of its global node]
    with torch.no_grad():
        total, b = gb.x.shape[0], gb.n_graphs
        basis = torch.cat([agent.edge_type_embed.weight.T, agent.edge_attr_embed.weight], dim=1)
        h = torch.cat([agent.node_embed(gb.x), agent.global_init.expand(b, -1)])
        layers = [h]
        for conv, red, norm in zip(agent.convs, agent.reduce, agent.norms):
            h = norm(h + red(conv(h, ref, basis, fused=False)))
            layers.append(h)
        stacked = torch.cat(layers, dim=-1)
        pair = torch.cat([stacked[:total], stacked[total:][gb.batch]], dim=-1)
        expected = agent.action_head(pair)[:, 0]
        logits, values = agent(gb)
    assert torch.allclose(logits[gb.mask], expected[gb.mask], atol=1e-5)
    assert torch.allclose(values, agent.value_head(stacked[total:]), atol=1e-5)
