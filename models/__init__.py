"""The GNN agent of the paper (PyTorch Geometric), importable without Ray.

``EOSPAgent`` maps a batch of continuous graphs to one logit per acquisition and
a value per graph; ``batch_from_padded`` turns the environment's padded
observations into a PyG-style batch without Python loops over nodes.

The names are loaded on first use, so that ``eosp.models.pretrained`` (the shipped models' names and
paths, read by the command line) does not import torch.
"""

_LAZY = {"EOSPAgent", "GraphBatch", "batch_from_padded"}


def __getattr__(name: str):
    if name in _LAZY:
        from eosp.models import agent

        return getattr(agent, name)
    raise AttributeError(f"module 'eosp.models' has no attribute {name!r}")
