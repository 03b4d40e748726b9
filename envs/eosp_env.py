"""The EOSP environment: build a schedule chronologically in the pruned discrete graph.

Contract
--------
Instance source
    Injected: ``EOSPEnv(config, source=FixedSource(inst))``; from ``config.shards``
    (each copy owns a subset by its RLlib worker index, see
    :func:`envs.sources.owned_shards`); or, with neither, one small embedded
    generated instance.  ``reset(options={"instance": inst})`` forces one.
State
    The pruned discrete graph restricted to the nodes still alive, plus the
    partial schedule (a path from the source).  See :mod:`envs.core`.
Action
    ``Discrete(N_max)``: the next acquisition.  Allowed when the last scheduled
    node has an arc to an alive node of it; it then starts at that node's time
    (the earliest discrete start).  A masked or out-of-range action raises
    :class:`InvalidAction` and leaves the state unchanged.
    ``action_space.sample()`` draws among the currently allowed actions.
Observation
    ``Dict`` of fixed-size padded arrays (RLlib's new API stack batches them as is):

    ==================  ====================  =======  ===========================================
    key                 shape                 dtype    meaning
    ==================  ====================  =======  ===========================================
    ``x``               (N_max, F)            float32  node features (:data:`NODE_FEATURES`), 0 pad
    ``edge_index``      (2, E_max)            int32    continuous-graph arcs (src, dst), 0 pad
    ``edge_attr``       (E_max, 2)            float32  transition slack / 60 s, from-last flag
    ``n_nodes``         (1,)                  int32    number of acquisitions n
    ``n_edges``         (1,)                  int32    number of valid edges
    ``action_mask``     (N_max,)              int8     1 = allowed
    ==================  ====================  =======  ===========================================

    N_max = ``max_acquisitions`` (or the instance's n when 0), E_max = ``max_edges``.
Reward (float, per step, chosen by ``config.reward``)
    ``normalized``: u_a / mean(u) over the instance's candidates (the paper);
    ``utility``: u_a; ``unitary``: 1; ``lexicographic``: the scalar reward is the
    normalized one and ``info["reward_vector"]`` (float32, (7,)) holds
    u_a / V_c in the component of a's class c (0 = highest), 0 elsewhere: a
    learner compares returns class by class, highest first (see docs/environment.md).
Termination
    ``terminated`` when no action is allowed; never truncated.
    ``info["value"]`` is the utility of the schedule so far (float64);
    :meth:`EOSPEnv.schedule` gives it in the interchange schedule format.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import gymnasium as gym
import numpy as np

from eosp.envs import core
from eosp.envs.observation import (LABEL_PLANS, N_EDGE_FEATURES, N_NODE_FEATURES, PLAN_ORDERS, UNITARY_PLANS,
                                   build_observation, plan_completion,
                                   step_and_observe_fields)
from eosp.envs.sources import FixedSource, PreparedInstance, ShardSource, expand_shards, owned_shards, prepare_instance
from eosp.config import EnvConfig, from_dict
from eosp.instances.instance import Instance
from eosp.reward import reward

# the plan features' kernel codes (envs/observation.PLAN_ORDERS) per objective: Greedy's two orders, the label sweep
PLANS = {"unitary": ("start+deadline", "label:count"), "utility": ("utility+class", "label:utility")}


class InvalidAction(ValueError):
    """An action that the mask forbids, or out of range."""


class MaskedDiscrete(gym.spaces.Discrete):
    """``Discrete(n)`` whose ``sample()`` without a mask draws among the actions allowed now."""

    def __init__(self, n: int, seed: int | None = None):
        super().__init__(n, seed=seed)
        self.current_mask: np.ndarray | None = None

    def sample(self, mask=None, probability=None):  # noqa: D401
        if mask is None and probability is None and self.current_mask is not None and self.current_mask.any():
            mask = self.current_mask
        return super().sample(mask=mask, probability=probability)

    def __deepcopy__(self, memo):
        out = MaskedDiscrete(int(self.n))
        out.np_random.bit_generator.state = self.np_random.bit_generator.state
        return out


@dataclass
class Snapshot:
    """Everything that changes during an episode (a few small arrays, :class:`eosp.envs.core.Episode`)."""

    prepared: PreparedInstance
    ep: core.Episode
    value: float


def _embedded_default(seed: int) -> Instance:
    from eosp.config import family_config
    from eosp.instances.generator import generate

    return generate(family_config("uniform", 30, seed, graph={"step_s": 2.0}))


class EOSPEnv(gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": []}

    def __init__(self, config: EnvConfig | dict | None = None, source: Any | None = None):
        worker_index = int(getattr(config, "worker_index", 0) or 0)
        num_workers = int(getattr(config, "num_workers", 0) or 0)
        vector_index = int(getattr(config, "vector_index", 0) or 0)
        if config is None:
            cfg = EnvConfig()
        elif isinstance(config, EnvConfig):
            cfg = config
        else:
            names = {f.name for f in fields(EnvConfig)}
            cfg = from_dict(EnvConfig, {k: v for k, v in dict(config).items() if k in names})
        self.reward = reward(cfg.reward)  # a ValueError for an unknown name
        if cfg.obs_edges not in ("earliest", "full"):
            raise ValueError(f"unknown obs_edges {cfg.obs_edges!r} (earliest, full)")
        self.cfg = cfg
        # the plan features' kernel code (envs/observation.PLAN_ORDERS): Greedy's order for this reward's objective
        order, label = PLANS[self.reward.objective]
        if cfg.plan == "label":
            self._plan = PLAN_ORDERS.index(label)
        else:
            self._plan = 0 if not cfg.plan else PLAN_ORDERS.index(order if cfg.plan == "greedy2"
                                                                  else order.split("+")[0])
        self._completion_orders = self._plan or PLAN_ORDERS.index(order)  # without plan features: both orders
        self._needs_unpruned = self._plan not in LABEL_PLANS  # Greedy's plans and completions use its arcs
        self.worker_index, self.vector_index = worker_index, vector_index
        if source is None:
            if cfg.shards:
                source = ShardSource(owned_shards(expand_shards(cfg.shards), worker_index, num_workers),
                                     max_cached=cfg.max_cached_instances, prune=cfg.prune,
                                     unpruned=bool(cfg.plan) and self._needs_unpruned)
            else:
                source = FixedSource(_embedded_default(cfg.seed), prune=cfg.prune)
        self.source = source
        n_max = cfg.max_acquisitions or source.max_acquisitions()
        if cfg.max_acquisitions and source.max_acquisitions() > cfg.max_acquisitions:
            raise ValueError(f"instances have up to {source.max_acquisitions()} acquisitions but the observation "
                             f"is padded to max_acquisitions={cfg.max_acquisitions}")
        if cfg.max_out_degree < 1:
            raise ValueError("max_out_degree must be at least 1")
        self.n_max = n_max
        # the plan the last observation showed (plan_features' plan_out: length, then nodes) and the episode state
        # it belongs to: completion() reads it instead of computing the plan again (a restore() makes it stale)
        self._plan_out = np.full(n_max + 1, -1, dtype=np.int32)
        self._plan_of = None
        # 'full' keeps every surviving arc of the continuous graph: room for all of them by default
        self.e_max = cfg.max_edges or (n_max * max(n_max - 1, 1) if cfg.obs_edges == "full"
                                       else n_max * (cfg.max_out_degree + 4))
        self.observation_space = gym.spaces.Dict({
            "x": gym.spaces.Box(-np.inf, np.inf, (n_max, N_NODE_FEATURES), np.float32),
            "edge_index": gym.spaces.Box(0, max(n_max - 1, 0), (2, self.e_max), np.int32),
            "edge_attr": gym.spaces.Box(-np.inf, np.inf, (self.e_max, N_EDGE_FEATURES), np.float32),
            "n_nodes": gym.spaces.Box(0, n_max, (1,), np.int32),
            "n_edges": gym.spaces.Box(0, self.e_max, (1,), np.int32),
            "action_mask": gym.spaces.Box(0, 1, (n_max,), np.int8),
        })
        self.action_space = MaskedDiscrete(n_max)
        self._np_random = np.random.default_rng([cfg.seed, worker_index, vector_index])
        self.state: Snapshot | None = None

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            super().reset(seed=seed)
            self._np_random = np.random.default_rng([seed, self.worker_index, self.vector_index])
        options = options or {}
        if "instance" in options:
            inst = options["instance"]
            prepared = inst if isinstance(inst, PreparedInstance) else prepare_instance(inst, self.cfg.prune)
            if prepared.inst.n_acq > self.n_max:
                raise ValueError(f"instance has {prepared.inst.n_acq} acquisitions > max_acquisitions={self.n_max}")
        else:
            prepared = self.source.sample(self.np_random)
        if self._plan and self._needs_unpruned and \
                prepared.cand.plan_indptr.shape[0] != prepared.eg.node_time.shape[0] + 1:
            prepared.inst.unpruned("the plan features (--env.plan greedy)")  # not loaded: a one-line InputError
            raise ValueError(f"{prepared.inst.name}: its unpruned graph does not have the environment graph's nodes")
        self.state = Snapshot(prepared=prepared, ep=core.Episode.start(prepared.eg), value=0.0)
        core.start(prepared.eg, self.state.ep)
        self._publish_mask()
        bufs = self._buffers()
        m = build_observation(prepared.eg, self.state.ep, prepared.cand, self._obs_options(), (*bufs, self._plan_out))
        self._plan_of = self.state.ep
        return self._observation(bufs, m), {"instance": prepared.inst.name, "n_acquisitions": prepared.inst.n_acq}

    def step(self, action):
        s = self.state
        if s is None:
            raise RuntimeError("call reset() before step()")
        eg, ep = s.prepared.eg, s.ep
        a = int(action)
        n = s.prepared.inst.n_acq
        if not 0 <= a < n or not ep.mask[a]:
            why = "out of range" if not 0 <= a < n else "masked (no arc from the last scheduled node to it)"
            raise InvalidAction(f"action {a} is not allowed: {why}; allowed: {np.flatnonzero(ep.mask).tolist()}")
        bufs = self._buffers()
        w, m = step_and_observe_fields(tuple(eg), tuple(ep), tuple(s.prepared.cand), a, self._obs_options(),
                                       (*bufs, self._plan_out))
        assert w >= 0
        self._plan_of = ep
        u = float(s.prepared.inst.acqs.utility[a])
        s.value += u
        self._publish_mask()
        terminated = not ep.mask.any()
        info = {"value": s.value, "n_scheduled": int(ep.n_scheduled[0]), "start": float(eg.node_time[w])}
        r = self.reward.step(u, a, s.prepared, info)
        return self._observation(bufs, m), r, terminated, False, info

    # ------------------------------------------------------------------ search support
    def snapshot(self) -> Snapshot:
        """A copy of the episode state (a few arrays): cheap enough for tree search."""
        s = self.state
        return Snapshot(s.prepared, s.ep.copy(), s.value)

    def restore(self, snap: Snapshot) -> None:
        self.state = Snapshot(snap.prepared, snap.ep.copy(), snap.value)
        self._publish_mask()

    def completion(self) -> tuple[np.ndarray, float, float] | None:
        """Greedy's completion of the current partial schedule: the plan the plan features show (EnvConfig.plan's
        order(s); without plan features, the better of the reward's two orders, as ``greedy2``; with 'label', the
        label sweep's chain, a path of the environment's graph): the nodes that follow :meth:`path` (a path of
        the instance's unpruned graph), the utility of the whole schedule (path + completion) and its worth in the
        plan's units (utility; unitary reward: the count).  None when Greedy needs the instance's unpruned graph
        and it is not loaded.  Every state's completion is a complete feasible schedule: the
        decoder keeps the best one seen (eosp.solvers.policy.rollout's `incumbent`)."""
        s = self.state
        if self._needs_unpruned and s.prepared.cand.plan_indptr.shape[0] != s.prepared.eg.node_time.shape[0] + 1:
            return None
        unitary = self._completion_orders in UNITARY_PLANS
        m = int(self._plan_out[0])
        if self._plan_of is s.ep and m >= 0:  # the plan the current observation shows (plan features on)
            nodes = self._plan_out[1:1 + m]
            acqs = s.prepared.eg.node_acq[nodes]
            worth = float(m) if unitary else float(s.prepared.cand.utility[acqs].sum())
        else:
            acqs, nodes, worth = plan_completion(s.prepared.eg, s.ep, s.prepared.cand, self._completion_orders)
        value = s.value + float(s.prepared.inst.acqs.utility[acqs].sum())
        return nodes.copy(), value, (int(s.ep.n_scheduled[0]) + worth) if unitary else value

    def action_mask(self) -> np.ndarray:
        return self.state.ep.mask.copy()

    def path(self) -> np.ndarray:
        """Scheduled nodes (canonical indices of the instance) in order."""
        ep = self.state.ep
        return ep.path[: ep.n_scheduled[0]].copy()

    def schedule(self):
        from eosp.instances.schedule import from_internal_nodes

        return from_internal_nodes(self.state.prepared.inst, self.path())

    @property
    def instance(self) -> Instance:
        return self.state.prepared.inst

    # ------------------------------------------------------------------ internals
    def _publish_mask(self) -> None:
        """The current mask (computed by the kernels), padded, for the observation and the action space."""
        mask = self.state.ep.mask
        self._mask_padded = np.zeros(self.n_max, dtype=np.int8)
        self._mask_padded[: mask.shape[0]] = mask
        self.action_space.current_mask = self._mask_padded

    def _obs_options(self) -> tuple:
        """The observation kernels' options (k_out, k_last_cap, full, horizon, look, plan), a plain tuple."""
        cfg = self.cfg
        return (cfg.max_out_degree, cfg.last_edges_cap, cfg.obs_edges == "full", float(cfg.obs_horizon_s),
                bool(cfg.lookahead), self._plan)

    def _buffers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Zeroed x, edge_index, edge_attr of an observation (the kernels fill them)."""
        return (np.zeros((self.n_max, N_NODE_FEATURES), dtype=np.float32), np.zeros((2, self.e_max), dtype=np.int32),
                np.zeros((self.e_max, N_EDGE_FEATURES), dtype=np.float32))

    def _observation(self, bufs: tuple[np.ndarray, np.ndarray, np.ndarray], m: int) -> dict[str, np.ndarray]:
        x, ei, ea = bufs
        return {"x": x, "edge_index": ei, "edge_attr": ea,
                "n_nodes": np.array([self.state.prepared.inst.n_acq], dtype=np.int32),
                "n_edges": np.array([m], dtype=np.int32), "action_mask": self._mask_padded.copy()}
