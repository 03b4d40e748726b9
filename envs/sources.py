"""Where environments get their instances from (injected, as jumanji injects generators).

A source hands out :class:`PreparedInstance` objects: the instance plus the
arrays the environment needs, prepared once and cached.  ``ShardSource`` gives
each environment copy its own subset of the shards (by worker index), so that
rollout workers do not all read every file.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eosp.envs.core import EnvGraph, prepare
from eosp.envs.observation import Candidates, candidates
from eosp.instances.instance import Instance


@dataclass
class PreparedInstance:
    inst: Instance
    eg: EnvGraph
    cand: Candidates  # the acquisitions' arrays of the observation
    priority: np.ndarray  # int8 [n]
    mean_utility: float


def prepare_instance(inst: Instance, prune: bool = True) -> PreparedInstance:
    pg = inst.graph_for(prune)
    prio = inst.priorities()
    eg = prepare(pg, inst.acqs.duration)
    return PreparedInstance(inst, eg, candidates(inst.acqs, prio, eg.node_time, eg.acq_ptr, inst.unpruned_graph),
                            prio, float(np.mean(inst.acqs.utility)))


class FixedSource:
    """Always the same instance (or a uniform draw from a short list)."""

    def __init__(self, instances: Instance | PreparedInstance | list, prune: bool = True):
        insts = list(instances) if isinstance(instances, (list, tuple)) else [instances]
        if not insts:
            raise ValueError("FixedSource needs at least one instance")
        self.prepared = [i if isinstance(i, PreparedInstance) else prepare_instance(i, prune) for i in insts]

    def max_acquisitions(self) -> int:
        return max(p.inst.n_acq for p in self.prepared)

    def sample(self, rng: np.random.Generator) -> PreparedInstance:
        if len(self.prepared) == 1:
            return self.prepared[0]
        return self.prepared[int(rng.integers(len(self.prepared)))]


def expand_shards(paths: list[str] | tuple[str, ...]) -> list[Path]:
    from eosp.shards.io import dataset_shards

    out: list[Path] = []
    for p in paths:
        out.extend(dataset_shards(p))
    return out


def owned_shards(paths: list[Path], worker_index: int, num_workers: int) -> list[Path]:
    """The shards of one rollout worker: every num_workers-th, starting at its index.

    Worker 0 (the local one, used for evaluation) and the case of fewer shards
    than workers see every shard.
    """
    if num_workers <= 0 or worker_index <= 0 or len(paths) < num_workers:
        return list(paths)
    return list(paths[(worker_index - 1) % num_workers::num_workers])


class ShardSource:
    """Instances of a set of shards, drawn uniformly, loaded lazily, kept in an LRU cache."""

    def __init__(self, paths: list[Path], max_cached: int = 256, prune: bool = True, unpruned: bool = False):
        from eosp.shards.io import ShardReader

        if not paths:
            raise ValueError("ShardSource needs at least one shard")
        self.readers = [ShardReader(p) for p in paths]
        self.index = [(r, i) for r in range(len(self.readers)) for i in range(len(self.readers[r]))]
        if not self.index:
            raise ValueError(f"the shards {', '.join(map(str, paths))} hold no instance")
        self.cache: OrderedDict[tuple[int, int], PreparedInstance] = OrderedDict()
        self.max_cached = max_cached
        self.prune = prune
        self.unpruned = unpruned or not prune  # load the unpruned arcs (the plan features need them)

    def __len__(self) -> int:
        return len(self.index)

    def get(self, k: int) -> PreparedInstance:
        key = self.index[k]
        if key in self.cache:
            self.cache.move_to_end(key)
            return self.cache[key]
        prepared = prepare_instance(self.readers[key[0]].read(key[1], unpruned=self.unpruned), self.prune)
        self.cache[key] = prepared
        if len(self.cache) > self.max_cached:
            self.cache.popitem(last=False)
        return prepared

    def max_acquisitions(self) -> int:
        import pyarrow.compute as pc

        return max(int(pc.max(r._file.read(columns=["n_acq"]).column("n_acq")).as_py()) for r in self.readers)

    def sample(self, rng: np.random.Generator) -> PreparedInstance:
        return self.get(int(rng.integers(len(self.index))))
