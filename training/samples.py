"""One labelled decision of imitation: an observation (trimmed to its nodes and edges; padding is added per batch)
with its expert action(s) and value target.  Shared by the single pass's demonstrations (eosp.training.imitation)
and the fleet's (eosp.training.fleet_demos), so that both are batched and learned by the same code."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Sample:
    """One labelled state, its observation trimmed to the instance (padding added per batch)."""

    x: np.ndarray  # float32 [n, F]
    edge_index: np.ndarray  # int32 [2, m]
    edge_attr: np.ndarray  # float32 [m, 2]
    mask: np.ndarray  # int8 [n]
    optimal: np.ndarray  # int32: optimal actions
    value: np.ndarray  # float32 [n_values]: remaining return (NaN: unknown)
    allowed: np.ndarray | None = None  # int32: actions with a known value (None: unknown)
    regret: np.ndarray | None = None  # float32: their regret, (Q* - Q(a)) / the instance's optimum
