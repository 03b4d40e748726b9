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
    """Acquisitions, the discrete graph (unpruned and pruned), and bookkeeping.

    Both graphs share their nodes (``node_acq``, ``node_time``, ``acq_ptr``) and
    differ in their arcs.  ``unpruned_graph`` is None for a shard instance stored
    (or read) with its pruned arcs only: :meth:`unpruned` then raises an
    :class:`~eosp.errors.InputError`.  ``pruned_graph`` is computed from the
    unpruned one the first time :meth:`pruned` is called, unless given.
    ``node_ids`` maps the canonical node index to the id used in the instance's
    own files (identity for generated instances); schedules are written with it.
    ``node_attitude`` (float32 [N, 4]: roll, pitch at start, roll, pitch at end)
    is known only for instances that come from our simulator.
    """

    name: str
    acqs: Acquisitions
    unpruned_graph: DiscreteGraph | None
    node_ids: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)
    node_attitude: np.ndarray | None = None
    pruned_graph: DiscreteGraph | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.unpruned_graph is None and self.pruned_graph is None:
            raise ValueError(f"instance {self.name!r}: needs its unpruned or its pruned graph")

    @property
    def n_acq(self) -> int:
        return len(self.acqs)

    @property
    def horizon(self) -> float:
        return float(self.meta.get("horizon_s", float(np.max(self.acqs.vtw_end)) if self.n_acq else 0.0))

    @property
    def node_graph(self) -> DiscreteGraph:
        """Either graph, for what both share: the nodes (node_acq, node_time, acq_ptr, n_nodes), not the arcs."""
        return self.unpruned_graph if self.unpruned_graph is not None else self.pruned_graph

    @property
    def n_nodes(self) -> int:
        return self.node_graph.n_nodes

    @property
    def node_acq(self) -> np.ndarray:
        """Acquisition of every node (-1 for the source); the same in both graphs."""
        return self.node_graph.node_acq

    @property
    def node_time(self) -> np.ndarray:
        """Start time of every node; the same in both graphs."""
        return self.node_graph.node_time

    @property
    def acq_ptr(self) -> np.ndarray:
        """The nodes of acquisition a are acq_ptr[a] .. acq_ptr[a + 1] - 1; the same in both graphs."""
        return self.node_graph.acq_ptr

    def pruned(self) -> DiscreteGraph:
        """The pruned discrete graph (computed once)."""
        if self.pruned_graph is None:
            from eosp.graphs.prune import prune

            self.pruned_graph = prune(self.unpruned_graph, self.acqs.duration)
        return self.pruned_graph

    def unpruned(self, what: str = "this operation") -> DiscreteGraph:
        """The unpruned discrete graph; an InputError naming `what` when it was not stored."""
        if self.unpruned_graph is None:
            from eosp.errors import InputError

            raise InputError(self.meta.get("source", self.name), f"{what} needs the unpruned arcs, and this "
                             "instance was stored with its pruned graph only (build shards with "
                             "--include-unpruned true)")
        return self.unpruned_graph

    def graph_for(self, prune: bool) -> DiscreteGraph:
        """The pruned graph when `prune`, else the unpruned one (the one switch: EnvConfig.prune)."""
        return self.pruned() if prune else self.unpruned("playing in the unpruned graph (prune false)")

    def priorities(self) -> np.ndarray:
        """Priority classes; when absent they are ranked from the utilities (0 = highest)."""
        if self.acqs.priority is not None:
            return self.acqs.priority
        from eosp.config import CLASS_UTILITIES

        bounds = np.asarray(CLASS_UTILITIES)
        # class c holds utilities in [V_c, V_{c-1}): c = number of class values above u.
        idx = np.searchsorted(-bounds, -self.acqs.utility, side="left")
        return np.clip(idx, 0, len(bounds) - 1).astype(np.int8)
