"""The GNN agent of the paper (PyTorch Geometric), importable without Ray.

``EOSPAgent`` maps a batch of continuous graphs to one logit per acquisition and
a value per graph; ``batch_from_padded`` turns the environment's padded
observations into a PyG-style batch without Python loops over nodes.
"""

from eosp.models.agent import EOSPAgent, GraphBatch, batch_from_padded  # noqa: F401
