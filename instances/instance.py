"""An EOSP instance in memory: candidate acquisitions plus the discrete graph.

This is the one in-memory form shared by the generator, the interchange import,
the shards and the solvers.  Everything is a numpy array; there is no per-node
Python object anywhere.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from eosp.graphs.discrete import DiscreteGraph

ATTITUDE_COLUMNS = ("roll_min", "roll_max", "roll_mean", "pitch_min", "pitch_max", "pitch_mean")


@dataclass
class Acquisitions:
    duration: np.ndarray  # float64 [n]
    vtw_start: np.ndarray  # float64 [n]
    vtw_end: np.ndarray  # float64 [n]
    utility: np.ndarray  # float64 [n]
    priority: np.ndarray | None = None  # int8 [n], 0 = highest
    lat: np.ndarray | None = None  # float64 [n]
    lon: np.ndarray | None = None
    attitude: np.ndarray | None = None  # float64 [n, 6] in ATTITUDE_COLUMNS order

    def __len__(self) -> int:
        return int(self.duration.shape[0])


@dataclass
class Instance:
    """Acquisitions, the UNPRUNED discrete graph, and bookkeeping.

    ``node_ids`` maps the canonical node index to the id used in the instance's
    own files (identity for generated instances); schedules are written with it.
    ``node_attitude`` (float32 [N, 4]: roll, pitch at start, roll, pitch at end)
    is known only for instances that come from our simulator.
    """

    name: str
    acqs: Acquisitions
    graph: DiscreteGraph
    node_ids: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)
    node_attitude: np.ndarray | None = None
    _pruned: DiscreteGraph | None = field(default=None, repr=False)

    @property
    def n_acq(self) -> int:
        return len(self.acqs)

    @property
    def horizon(self) -> float:
        return float(self.meta.get("horizon_s", float(np.max(self.acqs.vtw_end)) if self.n_acq else 0.0))

    def pruned(self) -> DiscreteGraph:
        """The pruned discrete graph (computed once)."""
        if self._pruned is None:
            from eosp.graphs.prune import prune

            self._pruned = prune(self.graph, self.acqs.duration)
        return self._pruned

    def require_unpruned(self, what: str) -> None:
        """Refuse to go on with a shard instance stored without its unpruned arcs."""
        if self.meta.get("unpruned_arcs", True) is False:
            from eosp.errors import InputError

            raise InputError(self.meta.get("source", self.name), f"{what} needs the unpruned arcs, and this "
                             "instance was stored with its pruned graph only (build shards with "
                             "--include-unpruned true)")

    def set_pruned(self, graph: DiscreteGraph) -> None:
        self._pruned = graph

    def priorities(self) -> np.ndarray:
        """Priority classes; when absent they are ranked from the utilities (0 = highest)."""
        if self.acqs.priority is not None:
            return self.acqs.priority
        from eosp.config import CLASS_UTILITIES

        bounds = np.asarray(CLASS_UTILITIES)
        # class c holds utilities in [V_c, V_{c-1}): c = number of class values above u.
        idx = np.searchsorted(-bounds, -self.acqs.utility, side="left")
        return np.clip(idx, 0, len(bounds) - 1).astype(np.int8)
