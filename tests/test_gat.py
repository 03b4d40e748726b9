"""The fused GATv2 kernel (models/gat.py) against torch_geometric's GATv2Conv and its own torch path."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from torch_geometric.nn import GATv2Conv

from eosp.models.gat import N_TYPES, EdgeStructure, GATv2Layer


def random_graph(seed: int, n: int, e: int, isolated: int = 0):
    """Typed edges with two numeric attributes; the last `isolated` nodes receive no edge."""
    g = torch.Generator().manual_seed(seed)
    src = torch.randint(0, n, (e,), generator=g)
    dst = torch.randint(0, max(1, n - isolated), (e,), generator=g)
    types = torch.randint(0, N_TYPES, (e,), generator=g)
    attr = torch.randn(e, 2, generator=g)
    attr[types >= 2] = 0.0  # edges to and from global nodes carry no attribute, as in models.agent
    return torch.stack([src, dst]), types, attr


def layers(dim: int, heads: int, seed: int):
    torch.manual_seed(seed)
    pyg = GATv2Conv(dim, dim, heads=heads, concat=True, edge_dim=dim, add_self_loops=False)
    ours = GATv2Layer(dim, heads)
    ours.load_state_dict(pyg.state_dict())  # same parameter names and shapes
    with torch.no_grad():  # PyG starts the bias at zero: make it count
        ours.bias.normal_()
        pyg.bias.copy_(ours.bias)
    type_embed, attr_embed = torch.nn.Embedding(N_TYPES, dim), torch.nn.Linear(2, dim, bias=False)
    return pyg, ours, type_embed, attr_embed


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 40), e=st.integers(0, 200), heads=st.sampled_from([1, 2, 4]),
       isolated=st.integers(0, 3))
def test_layer_matches_torch_geometric_gatv2conv_with_gradients(seed, n, e, heads, isolated):
    dim = 8
    pyg, ours, type_embed, attr_embed = layers(dim, heads, seed)
    edge_index, types, attr = random_graph(seed, n, e, isolated)
    x = torch.randn(n, dim, generator=torch.Generator().manual_seed(seed + 1))
    basis = torch.cat([type_embed.weight.T, attr_embed.weight], dim=1)
    edges = EdgeStructure(edge_index, types, attr, n)
    weight = torch.randn(n, heads * dim)  # a loss that reaches every output

    x_ref = x.clone().requires_grad_()
    ref = pyg(x_ref, edge_index, type_embed(types) + attr_embed(attr))
    (ref * weight).sum().backward()
    for fused in (True, False):
        ours.zero_grad()
        x_ours = x.clone().requires_grad_()
        out = ours(x_ours, edges, basis, fused=fused)
        assert torch.allclose(out, ref, atol=2e-5, rtol=1e-4), (fused, (out - ref).abs().max())
        (out * weight).sum().backward()
        assert torch.allclose(x_ours.grad, x_ref.grad, atol=1e-4, rtol=1e-3), (fused, (x_ours.grad - x_ref.grad).abs().max())
        mine, theirs = dict(ours.named_parameters()), dict(pyg.named_parameters())
        for name, p in mine.items():
            assert torch.allclose(p.grad, theirs[name].grad, atol=1e-4, rtol=1e-3), (fused, name)
        pyg_grads = {k: v.grad.clone() for k, v in theirs.items()}
        for name in mine:  # every parameter gets a gradient (bias included), equal to PyG's
            assert pyg_grads[name].shape == mine[name].grad.shape


def test_kernel_gradients_reach_the_edge_embedding_like_torch():
    """The gradient of the [heads * dim, N_BASIS] edge map flows to both embeddings as through the torch path."""
    dim, heads = 8, 2
    _, ours, type_embed, attr_embed = layers(dim, heads, 3)
    edge_index, types, attr = random_graph(3, 30, 150)
    edges = EdgeStructure(edge_index, types, attr, 30)
    x = torch.randn(30, dim)
    grads = []
    for fused in (True, False):
        type_embed.zero_grad(), attr_embed.zero_grad()
        basis = torch.cat([type_embed.weight.T, attr_embed.weight], dim=1)
        ours(x, edges, basis, fused=fused).pow(2).sum().backward()
        grads.append((type_embed.weight.grad.clone(), attr_embed.weight.grad.clone()))
    for a, b in zip(*grads):
        assert a.abs().sum() > 0 and torch.allclose(a, b, atol=1e-4, rtol=1e-3)


def test_agent_fused_and_torch_paths_agree_on_real_observations(tiny_instance_obs):
    from eosp.config import MODEL_PRESETS, ModelConfig, from_dict
    from eosp.models.agent import EOSPAgent, batch_from_padded

    torch.manual_seed(0)
    agent = EOSPAgent(from_dict(ModelConfig, MODEL_PRESETS["cpu"]))
    obs = {k: torch.as_tensor(np.stack([o[k] for o in tiny_instance_obs])) for k in tiny_instance_obs[0]}
    gb, _ = batch_from_padded(obs)
    out = {}
    for fused in (True, False):
        agent.fused = fused
        logits, values = agent(gb)
        out[fused] = logits[gb.mask], values
    assert torch.allclose(out[True][0], out[False][0], atol=1e-4)
    assert torch.allclose(out[True][1], out[False][1], atol=1e-4)


@pytest.fixture
def tiny_instance_obs():
    """Observations along a random episode of a small generated instance."""
    from eosp.config import EnvConfig
    from eosp.envs.eosp_env import EOSPEnv
    from eosp.envs.sources import FixedSource
    from tests.conftest import generated

    env = EOSPEnv(EnvConfig(max_acquisitions=64), source=FixedSource(generated("clusters", 40, seed=5)))
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=0)
    out, done = [], False
    while not done and len(out) < 16:
        out.append(obs)
        obs, _, done, _, _ = env.step(int(rng.choice(np.flatnonzero(obs["action_mask"]))))
    return out


def test_initialization_follows_gatv2conv():
    """Same parameter distributions as GATv2Conv at creation (glorot over the last two dims, zero biases)."""
    dim, heads = 32, 2
    ours = torch.stack([GATv2Layer(dim, heads).att.detach().abs().max() for _ in range(20)]).max()
    pyg = torch.stack([GATv2Conv(dim, dim, heads=heads, edge_dim=dim, add_self_loops=False).att.detach().abs().max()
                       for _ in range(20)]).max()
    bound = (6.0 / (heads + dim)) ** 0.5
    assert 0.9 * bound < ours <= bound and 0.9 * bound < pyg <= bound
    layer = GATv2Layer(dim, heads)
    assert layer.lin_l.bias.abs().sum() == 0 and layer.bias.abs().sum() == 0
