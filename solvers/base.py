"""What every solver returns, and the registry behind ``eosp solve --solver NAME``."""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from eosp.instances.instance import Instance


@dataclass
class Solution:
    """A path in the discrete graph: canonical node indices in execution order (source excluded)."""

    nodes: np.ndarray
    value: float
    info: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_path(cls, inst: Instance, nodes: np.ndarray, mode: str, info: dict[str, Any] | None = None) -> Solution:
        """The solution of a path, valued with the objective of `mode` (:func:`objective_weights`)."""
        nodes = np.asarray(nodes)
        value = float(objective_weights(inst, mode)[inst.node_acq[nodes]].sum()) if len(nodes) else 0.0
        return cls(nodes, value, info or {})


def objective_weights(inst: Instance, mode: str) -> np.ndarray:
    """Per-acquisition weight: the utility, or 1 per acquisition in unitary mode."""
    if mode == "utility":
        return inst.acqs.utility
    if mode == "unitary":
        return np.ones(inst.n_acq)
    raise ValueError(f"unknown objective mode {mode!r} (utility, unitary)")


# name -> "module:function"; each function is solve(inst, *, mode, time_limit, seed, **kw) -> Solution
REGISTRY: dict[str, str] = {
    "random": "eosp.solvers.random_walk:solve",
    "policy": "eosp.solvers.policy:solve",
    "mcts": "eosp.solvers.mcts:solve",
    "sample": "eosp.solvers.sample:solve",
    "beam": "eosp.solvers.beam:solve",
    "greedy": "eosp.solvers.greedy:solve",
    "ramp": "eosp.solvers.ramp:solve",
    "exact": "eosp.solvers.exact:solve",
}


def get_solver(name: str) -> Callable[..., Solution]:
    if name not in REGISTRY:
        raise ValueError(f"unknown solver {name!r}; available: {', '.join(sorted(REGISTRY))}")
    module, func = REGISTRY[name].split(":")
    return getattr(importlib.import_module(module), func)
