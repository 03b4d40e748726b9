"""The constellation environment: one agent per satellite, over the fleet's pass graphs (multi-agent API).

Contract
--------
Fleets
    Injected (``ConstellationEnv(cfg, source=prepared_fleet_or_list)``, see
    :func:`eosp.envs.constellation_data.prepare_fleet`); from ``fleets`` (fleet or aeossp case directories, each
    RLlib env runner owning every num_workers-th); or one small generated fleet.  ``reset(options={"fleet":
    prepared})`` forces one.  :class:`ScheduleFollower` gives the actions that replay a schedule.
Agents
    A fixed pool of slots ``sat_0 .. sat_{K-1}`` (``possible_agents``), K = ``max_satellites`` or the largest
    fleet of the source; satellite i of the current fleet is ``sat_i``; the slots of a smaller fleet never act.
    Every agent has the same spaces (``observation_spaces``, ``action_spaces``).
Event clock
    Each satellite is free at the end of its last observation (at the first start of its pass when it has
    none there).  The satellite free earliest acts, ties to the lowest index; exactly one agent acts per step
    (``step`` takes ``{agent: action}`` and returns the next agent's observation).  A satellite with nothing
    admissible in its pass moves to its next pass by itself (never asked); one without passes left is done.
Action
    ``Discrete(max_nodes)``: a slot of the observation.  Slot 0 skips to the satellite's next pass; slot s >= 1
    observes the task shown there at its candidate start: the earliest opportunity of the task in the current
    pass that the pass graph's arcs allow after the last observation (the slew from its line of sight at the
    end, or from nadir for the satellite's first observation, with the checker's bang-coast-bang model plus
    1e-6 s), or, when the battery refuses that one, the first later opportunity of the task whose slew and
    battery both pass.  A masked or out-of-range action raises :class:`InvalidAction` (state unchanged).
Masks
    ``action_mask[s] = 1`` iff slot s is admissible: slot 0 always while the agent acts; a task's slot when the
    task has a candidate start (its slew and the battery admit it) and either nobody served the task yet (a task
    taken by one satellite is masked for every other, and for itself) or it is offered as a bridge at zero
    reward (``bridges``: 'useful' when from its node some task nobody served starts earlier than it can
    directly; 'all'; 'off').  The battery admits an observation iff, with it and only the idle draw afterwards,
    the checker's charge recurrence stays >= 1e-6 Wh at every segment end to the horizon
    (:mod:`eosp.envs.constellation_core`).
Observation (per agent, float32 / int32 / int8, padded, the single-pass layout that RLlib batches as is)

    ==================  ===========================  =======  ============================================
    key                 shape                        dtype    meaning
    ==================  ===========================  =======  ============================================
    ``x``               (max_nodes, F)               float32  node features (FLEET_NODE_FEATURES), 0 pad
    ``edge_index``      (2, E_max)                   int32    precedence edges (src slot, dst slot), 0 pad
    ``edge_attr``       (E_max, 2)                   float32  transition slack / 60 s, from-last flag
    ``n_nodes``         (1,)                         int32    slots used (skip + tasks shown)
    ``n_edges``         (1,)                         int32    valid edges
    ``action_mask``     (max_nodes,)                 int8     1 = admissible
    ==================  ===========================  =======  ============================================

    F = 25 (:data:`eosp.envs.constellation_obs.FLEET_NODE_FEATURES`), E_max = ``max_edges`` or
    max_nodes x (max_out_degree + 1).  A pass with more tasks than max_nodes - 1 is refused when the fleet is
    loaded unless ``truncate`` (then the observation shows the last observed task, the selectable ones by
    start, then the others still ahead by earliest start; a task not shown cannot be chosen at that step).
Reward
    ``wcr``: a task served for the first time earns w / W (W: the fleet's total weight), so the sum of every
    agent's rewards over an episode is the schedule's WCR; ``cr``: 1 / tasks (the sum is its CR).  Bridges and
    skips earn 0.  Each agent earns what it serves; with ``team_reward`` = a, an agent receives (1 - a) x its
    own rewards plus a x every reward of the fleet (its own included) since its previous observation.  Rewards
    are carried to the agent's next observation (its final one at the end); the environment does not
    discount: a learner's gamma applies per decision of the receiving agent.
Termination
    When no satellite has an admissible action left: ``terminateds`` holds True for every agent that has
    observed in the episode and ``"__all__"``, with a final observation for each (the skip node alone, nothing
    admissible) and its carried reward; never truncated.  :meth:`ConstellationEnv.schedule` is the schedule
    (checked by the fleet checker: valid, its WCR the return), :meth:`ConstellationEnv.episode_info` its figures.

What the action set keeps (see docs/environment.md): every schedule the checker accepts can be played, task
for task (each observation at its earliest admissible start, never later than in the schedule), when the pass
graphs are FIFO (``fifo_violations`` 0; counted per fleet), ``bridges='all'``, no slew of the schedule is within
1e-6 s of its limit and no charge within 1e-6 Wh of zero, and sunlight near a shadow boundary costs it nothing
(no charging is credited within a base step of one); with the battery binding, an earlier start is not proven to
keep every later option.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import fields
from pathlib import Path
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np

from eosp.config import FleetEnvConfig, from_dict, validate_fields
from eosp.envs import constellation_core as core
from eosp.envs.constellation_data import PreparedFleet, prepare_fleet
from eosp.envs.constellation_obs import N_EDGE_FEATURES, N_FLEET_FEATURES, ObsArrays, advance, begin, observe_done
from eosp.envs.eosp_env import InvalidAction, MaskedDiscrete
from eosp.errors import InputError
from eosp.fleet.model import Schedule, strings


class Snapshot(NamedTuple):
    """A copy of an episode's state (:meth:`ConstellationEnv.snapshot`)."""

    prepared: PreparedFleet
    arrays: tuple  # the Episode's arrays (its actions cut to those taken)
    agents: tuple  # per satellite: carried own reward, team total seen, acted
    scalars: tuple  # team total, return so far, acting satellite
    mask: np.ndarray


def agent_id(k: int) -> str:
    return f"sat_{k}"


def read_fleet_dir(path: str | Path, with_opportunities: bool = True):
    """(fleet, opportunities) of a fleet directory (``eosp generate --fleet``, ``eosp import``; opportunities read)
    or of an aeossp case directory (opportunities computed); opportunities None when not asked for; InputError
    for anything else."""
    from eosp.fleet.aeossp import is_case_dir, read_case
    from eosp.fleet.io import is_fleet_dir, read_fleet

    root = Path(path)
    if is_fleet_dir(root):
        return read_fleet(root, with_opportunities=with_opportunities)
    if is_case_dir(root):
        from eosp.fleet.opportunities import compute

        fleet = read_case(root)
        return fleet, compute(fleet) if with_opportunities else None
    raise InputError(root, "not a fleet directory (eosp generate --fleet) nor an aeossp case directory")


def load_fleet(path: str | Path) -> PreparedFleet:
    """A fleet directory or an aeossp case directory (:func:`read_fleet_dir`), prepared."""
    fleet, opps = read_fleet_dir(path)
    return prepare_fleet(fleet, opps, name=str(Path(path)))


def expand_fleets(paths: tuple[str, ...] | list[str]) -> list[Path]:
    """Each path as is when it is a fleet or case directory, else the fleet and case directories it holds."""
    from eosp.fleet.aeossp import is_case_dir
    from eosp.fleet.io import is_fleet_dir

    out: list[Path] = []
    for p in map(Path, paths):
        if is_fleet_dir(p) or is_case_dir(p):
            out.append(p)
            continue
        if not p.is_dir():
            raise InputError(p, "not a directory of fleets")
        found = sorted(q for q in p.iterdir() if is_fleet_dir(q) or is_case_dir(q))
        if not found:
            raise InputError(p, "holds no fleet directory (eosp generate --fleet) and no aeossp case directory")
        out.extend(found)
    return out


class FixedFleets:
    """Prepared fleets given in memory, drawn uniformly."""

    def __init__(self, fleets: PreparedFleet | list[PreparedFleet]):
        self.fleets = list(fleets) if isinstance(fleets, (list, tuple)) else [fleets]
        if not self.fleets:
            raise ValueError("FixedFleets needs at least one fleet")

    def all(self) -> list[PreparedFleet]:
        return self.fleets

    def max_satellites(self) -> int:
        return max(f.n_satellites for f in self.fleets)

    def sizes(self) -> dict[str, int]:
        return {f.name: f.n_satellites for f in self.fleets}

    def sample(self, rng: np.random.Generator) -> PreparedFleet:
        return self.fleets[int(rng.integers(len(self.fleets)))]


class FleetDirs:
    """Fleets of directories, loaded and prepared on first use, kept in an LRU cache."""

    def __init__(self, paths: list[Path], max_cached: int = 8):
        if not paths:
            raise ValueError("FleetDirs needs at least one fleet directory")
        self.paths = list(paths)
        self.max_cached = max_cached
        self.cache: OrderedDict[int, PreparedFleet] = OrderedDict()
        self._sizes: list[int] | None = None

    def sizes(self) -> dict[str, int]:
        """Satellites of each fleet (read once, without opportunities)."""
        if self._sizes is None:
            self._sizes = {str(p): len(read_fleet_dir(p, with_opportunities=False)[0].satellites) for p in self.paths}
        return self._sizes

    def max_satellites(self) -> int:
        return max(self.sizes().values())

    def get(self, i: int) -> PreparedFleet:
        if i in self.cache:
            self.cache.move_to_end(i)
            return self.cache[i]
        prepared = load_fleet(self.paths[i])
        self.cache[i] = prepared
        if len(self.cache) > self.max_cached:
            self.cache.popitem(last=False)
        return prepared

    def all(self) -> list[PreparedFleet]:
        return []  # checked as they load

    def sample(self, rng: np.random.Generator) -> PreparedFleet:
        return self.get(int(rng.integers(len(self.paths))))


def owned_fleets(paths: list[Path], worker_index: int, num_workers: int) -> list[Path]:
    """The fleets of one env runner: every num_workers-th, from its index (worker 0, or fewer fleets than
    workers: all of them), as the single-pass shards are shared (eosp.envs.sources.owned_shards)."""
    from eosp.envs.sources import owned_shards

    return owned_shards(paths, worker_index, num_workers)


def embedded_fleet(seed: int) -> PreparedFleet:
    """A small generated fleet (4 satellites, 300 tasks, 6 h): the source when none is given."""
    from eosp.fleet.generate import FleetGenConfig, generate
    from eosp.fleet.geometry import Geometry
    from eosp.fleet.opportunities import compute

    fleet = generate(FleetGenConfig(satellites=4, tasks=300, hours=6.0, window_min_h=1.0, window_max_h=6.0,
                                    placement="cities", seed=seed))
    geo = Geometry(fleet)
    return prepare_fleet(fleet, compute(fleet, geo), geo=geo)


class ScheduleFollower:
    """The actions that play a given schedule of a fleet (e.g. a solver's, for imitation): at each decision the
    acting satellite takes the next observation of its part of the schedule when that lies in its current pass
    (at the environment's candidate start for the task, which under FIFO is never later than the schedule's),
    skips to its next pass when the next one lies in a later pass or none is left.  An observation that is not
    admissible when its turn comes is dropped (counted in ``dropped``); one of a pass the satellite has left
    already, too.  Actions that are no opportunity of the fleet are refused when the follower is built."""

    def __init__(self, prepared: PreparedFleet, schedule: Schedule):
        f, o, fa = prepared.fleet, prepared.opps, prepared.arrays
        si, ti = f.satellite_index(), f.task_index()
        step_us = f.horizon.action_step_s * 1_000_000
        n_sat, n_start = len(f.satellites), f.horizon.n_action
        key_of = (o.task.astype(np.int64) * n_sat + o.satellite) * n_start + o.start
        order = np.argsort(key_of)
        self.queues: list[list[int]] = [[] for _ in range(n_sat)]
        for i in np.argsort(schedule.start_us, kind="stable").tolist():
            sat, task = si.get(str(schedule.satellite[i]), -1), ti.get(str(schedule.task[i]), -1)
            st = int(schedule.start_us[i])
            key = (task * n_sat + sat) * n_start + st // step_us
            j = int(np.searchsorted(key_of, key, sorter=order))
            if sat < 0 or task < 0 or st % step_us or j == len(order) or key_of[order[j]] != key:
                raise ValueError(f"action {i} ({schedule.satellite[i]}, {schedule.task[i]}, {st} us) is not an "
                                 f"opportunity of the fleet")
            p = int(o.pass_id[order[j]])
            a0 = int(fa.pass_acq_ptr[p])
            local = int(np.flatnonzero(fa.acq_task[a0:fa.pass_acq_ptr[p + 1]] == task)[0])
            self.queues[sat].append((p, local))
        self.next = [0] * n_sat
        self.dropped = 0

    def action(self, env: ConstellationEnv) -> int:
        """The slot the acting satellite plays now."""
        k, ep = env.actor, env.ep
        p, q = int(ep.sat_pass[k]), self.queues[k]
        mask = env.action_mask()
        while self.next[k] < len(q):
            qp, local = q[self.next[k]]
            if qp > p:
                return 0
            self.next[k] += 1
            slot = int(ep.acq_slot[local]) if qp == p else -1
            if slot > 0 and mask[slot]:
                return slot
            self.dropped += 1
        return 0


def _prepared(f) -> PreparedFleet:
    """reset's ``options["fleet"]``: a :class:`PreparedFleet`, or (fleet, opportunities[, ...]) as
    :func:`eosp.envs.constellation_data.prepare_fleet` takes them; a ValueError naming the option otherwise."""
    if isinstance(f, PreparedFleet):
        return f
    from eosp.fleet.model import Fleet
    from eosp.fleet.opportunities import Opportunities

    if not (isinstance(f, (tuple, list)) and len(f) >= 2 and isinstance(f[0], Fleet)
            and isinstance(f[1], Opportunities)):
        raise ValueError(f"reset(options=...): 'fleet' must be a PreparedFleet or (Fleet, Opportunities, ...), "
                         f"got {type(f).__name__}")
    return prepare_fleet(*f)


def _slot(action, agent: str) -> int:
    """An action as a slot index: an integer (numpy's included), or a float that is one (1.0); 1.7 is refused
    rather than truncated to slot 1."""
    if isinstance(action, (bool, np.bool_, str, bytes)):
        raise InvalidAction(f"action of {agent} must be a slot index, got {action!r}")
    if isinstance(action, (int, np.integer)):
        return int(action)
    try:
        value = float(np.asarray(action).item())
    except (TypeError, ValueError):
        raise InvalidAction(f"action of {agent} must be a slot index, got {action!r}") from None
    if not value.is_integer():
        raise InvalidAction(f"action of {agent} must be a slot index, got {action!r}")
    return int(value)


class ConstellationEnv:
    __doc__ = __doc__

    def __init__(self, config: FleetEnvConfig | dict | None = None, source: Any | None = None):
        worker_index = int(getattr(config, "worker_index", 0) or 0)
        num_workers = int(getattr(config, "num_workers", 0) or 0)
        vector_index = int(getattr(config, "vector_index", 0) or 0)
        if config is None:
            cfg = FleetEnvConfig()
        elif isinstance(config, FleetEnvConfig):
            cfg = validate_fields(config)  # fields may have been set after it was made
        else:  # RLlib's EnvContext: a dict with its own keys besides ours
            names = {f.name for f in fields(FleetEnvConfig)}
            cfg = from_dict(FleetEnvConfig, {k: v for k, v in dict(config).items() if k in names})
        self.cfg = cfg
        if source is None:
            if cfg.fleets:
                source = FleetDirs(owned_fleets(expand_fleets(cfg.fleets), worker_index, num_workers),
                                   cfg.max_cached_fleets)
            else:
                source = FixedFleets(embedded_fleet(cfg.seed))
        elif isinstance(source, (PreparedFleet, list, tuple)):
            source = FixedFleets(source)
        self.source = source
        self.k_slots = cfg.max_satellites or source.max_satellites()
        for name, n in source.sizes().items():
            if n > self.k_slots:
                raise InputError(name, f"{n} satellites, more than the {self.k_slots} agent slots (max_satellites)")
        for f in source.all():
            self._check(f)
        self.n_max = cfg.max_nodes
        self.e_max = cfg.max_edges or cfg.max_nodes * (cfg.max_out_degree + 1)
        self._params = np.array([cfg.max_out_degree, int(cfg.truncate)], dtype=np.int64)
        self._bridges = core.BRIDGE_MODES.index(cfg.bridges)
        self.possible_agents = [agent_id(k) for k in range(self.k_slots)]
        self.agents: list[str] = []
        self.observation_space = gym.spaces.Dict({
            "x": gym.spaces.Box(-np.inf, np.inf, (self.n_max, N_FLEET_FEATURES), np.float32),
            "edge_index": gym.spaces.Box(0, self.n_max - 1, (2, self.e_max), np.int32),
            "edge_attr": gym.spaces.Box(-np.inf, np.inf, (self.e_max, N_EDGE_FEATURES), np.float32),
            "n_nodes": gym.spaces.Box(0, self.n_max, (1,), np.int32),
            "n_edges": gym.spaces.Box(0, self.e_max, (1,), np.int32),
            "action_mask": gym.spaces.Box(0, 1, (self.n_max,), np.int8),
        })
        self.observation_spaces = {a: self.observation_space for a in self.possible_agents}
        self.action_spaces = {a: MaskedDiscrete(self.n_max) for a in self.possible_agents}
        self.action_space = self.action_spaces[self.possible_agents[0]]
        self.worker_index, self.vector_index = worker_index, vector_index
        self._rng = np.random.default_rng([cfg.seed, worker_index, vector_index])
        self.prepared: PreparedFleet | None = None
        self.ep: core.Episode | None = None
        self.actor = -1

    # ------------------------------------------------------------------ checks
    def _check(self, f: PreparedFleet) -> None:
        """A fleet this environment cannot play: one line naming it (InputError)."""
        if f.n_satellites > self.k_slots:
            raise InputError(f.name, f"{f.n_satellites} satellites, more than the {self.k_slots} agent slots "
                                     f"(max_satellites)")
        if f.max_pass_tasks > self.cfg.max_nodes - 1 and not self.cfg.truncate:
            raise InputError(f.name, f"a pass holds {f.max_pass_tasks} tasks, more than max_nodes - 1 = "
                                     f"{self.cfg.max_nodes - 1} (raise max_nodes, or set truncate)")

    # ------------------------------------------------------------------ multi-agent API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng([seed, self.worker_index, self.vector_index])
        options = options or {}
        unknown = sorted(set(options) - {"fleet"})
        if unknown:
            raise ValueError(f"reset(options=...): unknown option {unknown[0]!r} (known: 'fleet')")
        if "fleet" in options:
            prepared = _prepared(options["fleet"])
        else:
            prepared = self.source.sample(self._rng)
        self._check(prepared)
        self.prepared = prepared
        fa = prepared.arrays
        k_sats = prepared.n_satellites
        self.ep = core.new_episode(fa, prepared.max_pass_tasks, self.n_max)
        W = float(fa.task_weight.sum())
        n_tasks = len(fa.task_weight)
        self._task_reward = (fa.task_weight / W if W > 0 else np.zeros(n_tasks)) if self.cfg.reward == "wcr" \
            else np.full(n_tasks, 1.0 / max(n_tasks, 1))
        self._own = np.zeros(k_sats)  # rewards carried to each agent's next observation
        self._team_seen = np.zeros(k_sats)
        self._team_total = 0.0
        self._acted = np.zeros(k_sats, dtype=bool)
        self.value = 0.0  # the episode's return so far (sum of every reward): WCR or CR of the schedule
        self.agents = [agent_id(k) for k in range(k_sats)]
        bufs = self._buffers()
        k, n, m = begin(fa, self.ep, self._bridges, self._params, bufs)
        self.actor = int(k)
        if k < 0:  # nothing admissible anywhere: an episode without a decision
            return {}, {}
        self._collect(self.actor)
        return {agent_id(self.actor): self._publish(bufs, n, m)}, {}

    def step(self, action_dict: dict):
        if self.ep is None:
            raise RuntimeError("call reset() before step()")
        if self.actor < 0:
            raise RuntimeError("the episode is over: call reset()")
        me = agent_id(self.actor)
        if set(action_dict) != {me}:
            raise InvalidAction(f"{me} acts now; got actions for {sorted(action_dict)}")
        s = _slot(action_dict[me], me)
        mask = self._mask
        if not 0 <= s < self.n_max or not mask[s]:
            raise InvalidAction(f"action {s} of {me} is not allowed; allowed: {np.flatnonzero(mask).tolist()}")
        bufs = self._buffers()
        r, k, n, m = advance(self.prepared.arrays, self.ep, self.actor, int(self.ep.slot_acq[s]), self._task_reward,
                             self._bridges, self._params, bufs)
        if r:
            self.value += r
            a = self.cfg.team_reward
            self._own[self.actor] += (1.0 - a) * r
            self._team_total += a * r
        self.actor = k = int(k)
        if k < 0:
            return self._final()
        obs = {agent_id(k): self._publish(bufs, n, m)}
        return obs, {agent_id(k): self._collect(k)}, {"__all__": False}, {"__all__": False}, {}

    # ------------------------------------------------------------------ results
    def schedule(self) -> Schedule:
        """The observations taken so far, as a fleet schedule (satellite and task ids, microseconds)."""
        fa, f = self.prepared.arrays, self.prepared.fleet
        nodes = self.ep.actions[: self.ep.counts[core.N_ACTIONS]]
        acq = fa.node_acq[nodes]
        sat = fa.pass_sat[fa.acq_pass[acq]]
        task = fa.acq_task[acq]
        return Schedule(strings(f.satellites.ids[sat]), strings(f.tasks.ids[task]), fa.node_start_us[nodes].copy(),
                        fa.node_end_us[nodes].copy())

    def episode_info(self) -> dict:
        """The fleet and what the episode did: return, served tasks, decisions, battery refusals, bridges."""
        c = self.ep.counts
        return {"fleet": self.prepared.name, "satellites": self.prepared.n_satellites, "return": self.value,
                "observations": int(c[core.N_ACTIONS]), "served": int((self.ep.served_by >= 0).sum()),
                "battery_refusals": int(c[core.N_BATTERY]), "bridges": int(c[core.N_BRIDGES]),
                "passes_left_without_decision": int(c[core.N_AUTO_SKIPS]),
                "fifo_violations": self.prepared.fifo_violations}

    def action_mask(self) -> np.ndarray:
        return self._mask.copy()

    def snapshot(self) -> Snapshot:
        """A copy of the episode's state (arrays of a few entries per task and satellite, the observations taken
        so far), for searches that branch (:mod:`eosp.search.rollouts`, :mod:`eosp.search.mcts`) through
        :class:`eosp.envs.constellation_team.TeamEnv`."""
        ep = self.ep
        n = int(ep.counts[core.N_ACTIONS])
        arrays = tuple(a[:n].copy() if f == "actions" else a.copy() for f, a in zip(ep._fields, ep))
        return Snapshot(self.prepared, arrays, (self._own.copy(), self._team_seen.copy(), self._acted.copy()),
                        (self._team_total, self.value, self.actor), self._mask.copy())

    def restore(self, snap: Snapshot) -> None:
        """Back to the state of `snap` (taken on this environment, on the fleet it plays now)."""
        if snap.prepared is not self.prepared:
            raise ValueError("a snapshot of another fleet: reset(options={'fleet': ...}) to it first")
        for f, dst, src in zip(self.ep._fields, self.ep, snap.arrays):
            if f == "actions":
                dst[:len(src)] = src
            else:
                dst[...] = src
        self._own[:], self._team_seen[:], self._acted[:] = snap.agents
        self._team_total, self.value, self.actor = snap.scalars
        self._mask = snap.mask.copy()
        if self.actor >= 0:
            self.action_spaces[agent_id(self.actor)].current_mask = self._mask

    @property
    def acting_agent(self) -> str | None:
        return agent_id(self.actor) if self.actor >= 0 else None

    # ------------------------------------------------------------------ internals
    def _collect(self, k: int) -> float:
        """The reward carried to agent k's observation now (0 at its first one)."""
        if not self._acted[k]:
            self._acted[k] = True
            self._team_seen[k] = self._team_total
            self._own[k] = 0.0
            return 0.0
        r = self._own[k] + self._team_total - self._team_seen[k]
        self._own[k] = 0.0
        self._team_seen[k] = self._team_total
        return float(r)

    def _buffers(self) -> ObsArrays:
        return ObsArrays(np.zeros((self.n_max, N_FLEET_FEATURES), dtype=np.float32),
                         np.zeros((2, self.e_max), dtype=np.int32),
                         np.zeros((self.e_max, N_EDGE_FEATURES), dtype=np.float32), np.zeros(self.n_max, dtype=np.int8))

    def _pack(self, bufs: ObsArrays, n: int, m: int) -> dict[str, np.ndarray]:
        return {"x": bufs.x, "edge_index": bufs.edge_index, "edge_attr": bufs.edge_attr,
                "n_nodes": np.array([n], dtype=np.int32), "n_edges": np.array([m], dtype=np.int32),
                "action_mask": bufs.mask}

    def _publish(self, bufs, n: int, m: int) -> dict[str, np.ndarray]:
        """The acting agent's observation; its mask becomes the one its action space samples from."""
        self._mask = bufs.mask
        self.action_spaces[agent_id(self.actor)].current_mask = self._mask
        return self._pack(bufs, n, m)

    def _final(self):
        """Every agent that observed gets its final observation, its carried reward and terminated."""
        obs, rew, term = {}, {}, {"__all__": True}
        for k in np.flatnonzero(self._acted).tolist():
            bufs = self._buffers()
            n, m = observe_done(self.prepared.arrays, self.ep, k, bufs.x)
            a = agent_id(k)
            obs[a] = self._pack(bufs, n, m)
            rew[a] = self._collect(k)
            term[a] = True
        self._mask = np.zeros(self.n_max, dtype=np.int8)
        info = self.episode_info()
        return obs, rew, term, {"__all__": False}, {a: dict(info) for a in obs}

