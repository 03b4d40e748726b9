"""The PPO learner's batched gradient clipping is RLlib's, number for number."""

import numpy as np
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from ray.rllib.utils.torch_utils import clip_gradients as rllib_clip

from eosp.training.learner import clip_gradients


@settings(max_examples=60, deadline=None)
@given(shapes=st.lists(st.lists(st.integers(1, 5), min_size=1, max_size=3), min_size=1, max_size=8),
       log_scale=st.floats(-4, 4), clip=st.sampled_from([0.5, 1.0, 40.0]), seed=st.integers(0, 2**16),
       with_inf=st.booleans(), by=st.sampled_from(["global_norm", "norm", "value"]))
def test_batched_clipping_is_rllib_clipping(shapes, log_scale, clip, seed, with_inf, by):
    gen = torch.Generator().manual_seed(seed)
    grads = {i: torch.randn(*s, generator=gen) * 10.0 ** log_scale for i, s in enumerate(shapes)}
    if with_inf:
        grads[0].view(-1)[0] = float("inf")
    ours = {k: v.clone() for k, v in grads.items()}
    expected = rllib_clip(grads, grad_clip=clip, grad_clip_by=by)
    got = clip_gradients(ours, grad_clip=clip, grad_clip_by=by)
    if by == "global_norm":
        assert torch.allclose(got, expected, rtol=1e-6, equal_nan=True)
    for k in grads:
        np.testing.assert_allclose(ours[k].numpy(), grads[k].numpy(), rtol=1e-6, atol=0, equal_nan=True)
