"""A fleet as the fleet solver sees it: its pass graphs and the battery's energy windows built once, a pass solved
by a single-pass solver, and a schedule as one path per pass (:class:`Primal`)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from eosp.fleet.battery import SunCache
from eosp.fleet.energy import EnergyWindows, energy_windows
from eosp.fleet.geometry import Geometry
from eosp.fleet.model import Fleet, Schedule
from eosp.fleet.opportunities import Opportunities
from eosp.fleet.passgraph import (PassGraph, bound_problem, build_pass, build_passes, lean_pass, priced_graph,
                                  priced_pass, walk)
from eosp.fleet.slew import LineOfSight
from eosp.budget import UNLIMITED, Budget
from eosp.graphs.prune import fifo_violations
from eosp.kinds.fleet.config import FleetConfig


@dataclass(frozen=True)
class PassSpec:
    """What one pass solve reads of the solver's config, and all that is sent with it to a worker: the pass
    solver and the seconds one solve may take."""

    solver: str = "exact"
    time_limit: float = 5.0

    @classmethod
    def of(cls, cfg: FleetConfig) -> PassSpec:
        return cls(cfg.pass_solver, cfg.pass_time_limit)


@dataclass
class PassResult:
    nodes: np.ndarray  # pass-graph node ids, in order
    value: float  # under the utilities it was solved with
    bound: float | None  # a proven upper bound of that value, None when the solver gives none


@dataclass
class Problem:
    """A fleet, its opportunities and its pass graphs, built once.

    A *lean* problem (``Problem.build(..., lean=True)``) holds its passes without their arcs
    (:func:`eosp.fleet.passgraph.lean_pass`): the driver of a pool whose workers own the graphs (Ray actors,
    whole satellites each) keeps what coordination needs, the passes' nodes, tasks and energy; its paths are
    re-walked from the geometry (:meth:`rewalk`, the same nodes as along the arcs) and a pass it must solve itself
    (a lost worker's) gets its graph built then (:meth:`graph`)."""

    fleet: Fleet
    opps: Opportunities
    geo: Geometry
    los: LineOfSight
    passes: list[PassGraph]
    weight: np.ndarray  # float64 [tasks]
    task_passes: list[np.ndarray]  # passes holding each task
    pass_time: np.ndarray  # (first start, last end) of each pass, seconds
    windows: EnergyWindows | None = None  # what the battery allows in runs of passes (eosp.fleet.energy)
    sun: SunCache | None = None  # sunlight of the satellites, computed once (the windows, the battery repair)
    fifo_violations: int | None = 0  # see eosp.graphs.prune.fifo_violations (None: lean, the workers' graphs)
    build_s: float = 0.0
    lean: bool = False  # passes without arcs (see the class docstring)
    built: dict[int, PassGraph] = field(default_factory=dict)  # lean: the graphs built here (lost workers' passes)
    values: np.ndarray | None = None  # what each task is worth in each pass (set_values); None: its weight
    cap: np.ndarray = field(init=False)  # float64 [tasks]: the most a task is worth in any pass (set_values)
    task_ptr: np.ndarray = field(init=False)  # the passes' tasks as CSR: pass p's are task_idx[ptr[p]:ptr[p+1]]
    task_idx: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        lens = np.array([len(pg.tasks) for pg in self.passes], dtype=np.int64)
        self.task_ptr = np.r_[0, np.cumsum(lens)].astype(np.int64)
        self.task_idx = (np.concatenate([pg.tasks for pg in self.passes]).astype(np.int64) if len(lens)
                         else np.zeros(0, np.int64))
        self.set_values(self.values)

    def set_values(self, values: np.ndarray | None) -> None:
        """What serving each task in each pass is worth, one float per (pass, task) in the passes' task order
        (:attr:`task_ptr`; e.g. a task's weight times the chance that an observation in that pass succeeds, or 0
        for a request that has not arrived); None: every task its weight in every pass.  The schedules, the
        moves and the bound then count these values (:attr:`Primal.value`, :func:`priced`): the Lagrangian
        bound, built on per-pass terms, holds for them as it does for the weights, and the conflict-free bound is
        each task at its most valuable pass (:attr:`cap`, which the prices are also clipped at).  A ValueError
        for a vector of another length or a value below 0 or not finite."""
        if values is None:
            self.values, self.cap = None, self.weight
            return
        values = np.array(values, dtype=np.float64)  # a copy: a new object whenever the values change
        if values.shape != self.task_idx.shape:
            raise ValueError(f"values: one per (pass, task) ({len(self.task_idx)}), got shape {values.shape}")
        if not np.isfinite(values).all() or (values < 0).any():
            raise ValueError("values: every value finite and at least 0")
        self.values = values
        self.cap = np.zeros(len(self.weight))
        np.maximum.at(self.cap, self.task_idx, values)

    def pass_values(self, p: int) -> np.ndarray:
        """What each of pass p's tasks (:attr:`PassGraph.tasks` order) is worth in it (:meth:`set_values`)."""
        if self.values is None:
            return self.weight[self.passes[p].tasks]
        return self.values[self.task_ptr[p]:self.task_ptr[p + 1]]

    def flat_values(self) -> np.ndarray:
        """:meth:`pass_values` of every pass, one flat vector in the order of :attr:`task_idx`."""
        return self.weight[self.task_idx] if self.values is None else self.values

    @property
    def bound_graphs(self) -> int | None:
        """Passes whose bound term needs their bound problem (bridges, repeats, transitions between the margins);
        None in a lean problem (its workers know)."""
        return None if self.lean else sum(pg.bound_graph is not None for pg in self.passes)

    @property
    def unprovable(self) -> int | None:
        """Passes on which no bound problem can be proven (their bound graph is not FIFO): their term of the
        Lagrangian bound is the sum of their tasks' positive values (:func:`solve_round_pass`); None when lean."""
        return None if self.lean else sum(not pg.bound_provable for pg in self.passes)

    def graph(self, p: int) -> PassGraph:
        """Pass `p` with its arcs: as held, or in a lean problem built now and kept (a lost worker's passes, solved
        by the driver)."""
        if not self.lean:
            return self.passes[p]
        pg = self.built.get(p)
        if pg is None:
            pg = self.built[p] = build_pass(self.fleet, self.opps, self.los, p, self.opps.pass_offsets())
        return pg

    def rewalk(self, p: int, path: np.ndarray) -> np.ndarray:
        """:func:`rewalk` of pass `p`'s `path`, along its arcs or, lean, from the geometry (the same nodes)."""
        if self.lean:
            return walk(self.fleet, self.opps, self.los, self.passes[p], path)
        return rewalk(self.passes[p], path)

    @classmethod
    def build(cls, fleet: Fleet, opps: Opportunities, geo: Geometry | None = None, lean: bool = False) -> Problem:
        """`lean`: the passes without their arcs (see the class docstring)."""
        t0 = time.perf_counter()
        geo = geo or Geometry(fleet)
        los = LineOfSight(fleet, geo)
        if lean:
            off = opps.pass_offsets()
            passes = [lean_pass(fleet, opps, p, off) for p in range(opps.n_passes)]
        else:
            passes = build_passes(fleet, opps, los)
        n = len(fleet.tasks)
        holders: list[list[int]] = [[] for _ in range(n)]
        for pg in passes:
            for t in pg.tasks.tolist():
                holders[t].append(pg.pass_id)
        span = np.array([[pg.graph.node_time[1:].min(),
                          (pg.graph.node_time[1:] + pg.duration[pg.graph.node_acq[1:]]).max()] for pg in passes])
        span = span.reshape(-1, 2)
        fifo = None if lean else sum(fifo_violations(pg.graph) for pg in passes)
        sun = SunCache(geo)
        windows = energy_windows(fleet, sun, np.array([pg.satellite for pg in passes], dtype=np.int64), span,
                                 np.array([most_wh(fleet, pg) for pg in passes]))
        return cls(fleet, opps, geo, los, passes, fleet.tasks.weight.astype(np.float64),
                   [np.asarray(h, dtype=np.int64) for h in holders], span, windows, sun, fifo,
                   time.perf_counter() - t0, lean)

    @property
    def total_weight(self) -> float:
        return float(self.weight.sum())


def opportunity_values(prob: Problem, per_opportunity: np.ndarray) -> np.ndarray:
    """Values per (pass, task), as :meth:`Problem.set_values` takes them, from one value per opportunity (a row of
    :attr:`Problem.opps`; e.g. its weight times the chance that this observation succeeds): a task's value in a
    pass is its opportunity's there (the largest, should a pass hold two of one task)."""
    per_opportunity = np.asarray(per_opportunity, dtype=np.float64)
    if per_opportunity.shape != (len(prob.opps),):
        raise ValueError(f"values: one per opportunity ({len(prob.opps)}), got shape {per_opportunity.shape}")
    out = np.zeros(len(prob.task_idx))
    for p, pg in enumerate(prob.passes):
        np.maximum.at(out, prob.task_ptr[p] + pg.graph.node_acq[1:], per_opportunity[pg.rows])
    return out


def most_wh(fleet: Fleet, pg: PassGraph) -> float:
    """An upper bound of the energy (sum of e_o) a path of pass `pg` can spend: every task once, and no more
    than imaging and slewing throughout the pass (which of the energy windows can bind)."""
    b = fleet.satellites.battery
    t = pg.graph.node_time[1:]
    span = float((t + pg.duration[pg.graph.node_acq[1:]]).max() - t.min()) if len(t) else 0.0
    busy = (float(b.imaging_w[pg.satellite]) + float(b.slew_w[pg.satellite])) * span / 3600.0
    return min(float(pg.energy_wh.sum()), busy + float(pg.energy_wh.max(initial=0.0)))


def priced(value: np.ndarray, price: np.ndarray, energy_wh: np.ndarray | None = None,
           pass_price: float | np.ndarray = 0.0) -> np.ndarray:
    """The utilities of some tasks of a pass, given what each is worth there (`value`: :meth:`Problem.pass_values`,
    or the weights), their prices and the pass's price of a Wh: value - price - pass_price * energy (`energy_wh`
    the tasks' least energy on the pass's satellite, :attr:`PassGraph.energy_wh`; none: task prices only); the one
    place utilities are computed, on the driver and on the workers alike.  `pass_price` may be one per task (the
    tasks of several passes at once, each with its pass's price)."""
    util = value - price
    if energy_wh is None or (np.ndim(pass_price) == 0 and pass_price == 0):
        return util
    return util - pass_price * energy_wh


def pass_limit(spec: PassSpec, budget: Budget) -> float:
    """Seconds one pass solve may take: the pass time limit, or what is left of `budget` when that is less
    (rounded up to 10 ms, so that the solver's config, checked once per distinct value, is not checked again for
    every pass near the end)."""
    left = budget.left()
    return spec.time_limit if left >= spec.time_limit else max(0.01, math.ceil(left * 100) / 100)


def solve_pass(prob: Problem, p: int, value: np.ndarray, spec: PassSpec, budget: Budget = UNLIMITED) -> PassResult:
    """Pass `p` with utility `value[a]` per local task (non-positive ones left out)."""
    return solve_pass_graph(prob.graph(p), value, spec, budget)


def solve_pass_graph(pg: PassGraph, value: np.ndarray, spec: PassSpec, budget: Budget = UNLIMITED) -> PassResult:
    """One pass graph with utility `value[a]` per local task: what a worker holding the graph runs; the solver
    stops within `budget` (:func:`pass_limit`)."""
    from eosp.solvers import exact
    from eosp.solvers.base import run_solver

    priced = priced_graph(pg, value)
    if priced is None:
        return PassResult(np.zeros(0, np.int64), 0.0, 0.0)
    limit = pass_limit(spec, budget)
    if spec.solver == "exact":  # the sweep alone first, on the graph (most passes end there), as exact.solve
        t0 = time.perf_counter()
        graph, nodes, acqs = priced
        res = exact.sweep_alone(graph, value[acqs].astype(np.float64), limit, exact.MAX_LABELS)
        if res is not None:
            return PassResult(nodes[res.nodes], res.value, res.value)
        pp = priced_pass(pg, value, *priced)
        sol = exact.solve_steps(pp.instance, exact.ExactConfig(mode="utility", time_limit=limit), t0)
    else:
        pp = priced_pass(pg, value, *priced)
        sol = run_solver(spec.solver, pp.instance, mode="utility",
                         **({"time_limit": limit} if spec.solver == "ramp" else {}))
    bound = None
    if spec.solver == "exact":
        bound = sol.value if sol.info.get("status") == "optimal" else float(sol.info.get("bound", math.inf))
    return PassResult(pp.nodes[np.asarray(sol.nodes, dtype=np.int64)], float(sol.value), bound)


def solve_round_pass(pg: PassGraph, value: np.ndarray, spec: PassSpec, budget: Budget = UNLIMITED) -> PassResult:
    """A pass of a price round: its priced problem solved (the path moves the prices and seeds the recovery), with
    its term of the Lagrangian bound as `bound`: the priced optimum where the pass graph serves the bound, else
    the pass's bound problem (:func:`eosp.fleet.passgraph.bound_problem`: bridges and repeats kept, the verifier's
    tolerance); where neither is proven (a pass solver that proves none, a bound graph that is not FIFO, a bound
    problem cut by the pass time limit or the budget), the sum of the pass's positive values: any sequence of its
    observations credits each task once, so it serves at most that (and never more is taken than that anyway).
    So one unprovable pass (1 of 13,041 in a generated 200-satellite day) does not leave the fleet without a bound."""
    res = solve_pass_graph(pg, value, spec, budget)
    every = float(np.maximum(np.asarray(value, dtype=np.float64), 0.0).sum())
    proven = res.bound
    if pg.bound_graph is not None and proven is not None:
        b = bound_problem(pg, value, pass_limit(spec, budget))
        proven = max(b, proven) if math.isfinite(b) else None
    term = every if proven is None or not math.isfinite(proven) else min(proven, every)
    return PassResult(res.nodes, res.value, term)


def path_wh(pg: PassGraph, path: np.ndarray) -> float:
    """The energy (sum of e_o, :attr:`PassGraph.energy_wh`) of a path of pass `pg`."""
    return float(pg.energy_wh[pg.graph.node_acq[path]].sum())


def path_slew_wh(prob: Problem, p: int, path: np.ndarray) -> float:
    """The slew energy (Wh, slew power times slew time) of the maneuvers between consecutive observations of a path
    of pass `p` at their nodes' times (:meth:`LineOfSight.between`, the settling left out: :func:`path_wh` counts
    it).  The maneuver into the path's first observation, from the pass before, is not counted."""
    if len(path) < 2:
        return 0.0
    pg, fleet = prob.passes[p], prob.fleet
    sat = pg.satellite
    rows = pg.rows[np.asarray(path, dtype=np.int64) - 1]
    task = prob.opps.task[rows]
    st = prob.opps.start[rows].astype(np.float64) * fleet.horizon.action_step_s
    en = st + fleet.tasks.duration_s[task]
    need = prob.los.between(sat, task[:-1], en[:-1], task[1:], st[1:])
    slew_s = np.maximum(0.0, need - float(fleet.satellites.attitude.settling_s[sat]))
    return float(fleet.satellites.battery.slew_w[sat]) * float(slew_s.sum()) / 3600.0


def schedule_windows(prob: Problem) -> EnergyWindows:
    """The battery's energy windows (:func:`eosp.fleet.energy.energy_windows`) that a path's energy with its slews
    (:func:`path_wh` + :func:`path_slew_wh`) could overspend: a pass may spend its observations' energy plus slewing
    throughout it.  For schedules only (the integer round's rows): slews between observations are not part of
    the bound's accounting."""
    fleet, b = prob.fleet, prob.fleet.satellites.battery
    span = prob.pass_time[:, 1] - prob.pass_time[:, 0]
    most = np.array([float(pg.energy_wh.sum()) + float(b.slew_w[pg.satellite]) * float(span[p]) / 3600.0
                     for p, pg in enumerate(prob.passes)])
    sats = np.array([pg.satellite for pg in prob.passes], dtype=np.int64)
    return energy_windows(fleet, prob.sun or SunCache(prob.geo), sats, prob.pass_time, most)


def rewalk(pg: PassGraph, path: np.ndarray) -> np.ndarray:
    """The acquisitions of `path` (pass-graph nodes, in order) followed along the graph's arcs from the source:
    each at its earliest node after the previous one; one that cannot follow is skipped."""
    g = pg.graph
    out, node = [], 0
    for acq in g.node_acq[path].tolist():
        nxt = g.successor(node, acq)
        if nxt >= 0:
            out.append(nxt)
            node = nxt
    return np.asarray(out, dtype=np.int64)


@dataclass
class Primal:
    """A schedule as pass paths; ``served[i]`` = pass serving task i, or -1."""

    paths: list[np.ndarray]
    served: np.ndarray
    value: float = 0.0

    def copy(self) -> Primal:
        return Primal(list(self.paths), self.served.copy(), self.value)

    @classmethod
    def empty(cls, n_passes: int, n_tasks: int) -> Primal:
        return cls([np.zeros(0, np.int64)] * n_passes, np.full(n_tasks, -1, np.int64))


def path_tasks(prob: Problem, p: int, path: np.ndarray) -> np.ndarray:
    pg = prob.passes[p]
    return pg.tasks[pg.graph.node_acq[path]]


def primal_of(prob: Problem, sched: Schedule, repeats: bool = False) -> Primal:
    """A schedule as pass paths: each action at its opportunity's node (an action that is no opportunity, or a
    task's second observation in a pass, or in any pass unless `repeats`, is left out; ``served`` holds a task's
    first)."""
    f, o = prob.fleet, prob.opps
    step_us = f.horizon.action_step_s * 1_000_000
    row_of = {key: r for r, key in enumerate(zip(o.task.tolist(), o.satellite.tolist(), o.start.tolist()))}
    node_of = np.zeros(len(o), dtype=np.int64)
    for pg in prob.passes:
        node_of[pg.rows] = np.arange(1, len(pg.rows) + 1)
    ti, si = f.task_index(), f.satellite_index()
    per_pass: dict[int, list[tuple[int, int]]] = {}
    seen = set()
    for sat, task, st in zip(sched.satellite.tolist(), sched.task.tolist(), sched.start_us.tolist()):
        r = row_of.get((ti.get(task, -1), si.get(sat, -1), int(st // step_us)))
        if r is None or st % step_us:
            continue
        key = (task, int(o.pass_id[r])) if repeats else task
        if key in seen:
            continue
        seen.add(key)
        per_pass.setdefault(int(o.pass_id[r]), []).append((int(st), int(node_of[r])))
    primal = Primal.empty(len(prob.passes), len(f.tasks))
    for p, acts in per_pass.items():
        path = np.asarray([n for _, n in sorted(acts)], dtype=np.int64)
        tasks = path_tasks(prob, p, path)
        primal.paths[p] = path
        primal.served[tasks] = np.where(primal.served[tasks] < 0, p, primal.served[tasks])
        primal.value += float(prob.pass_values(p)[prob.passes[p].graph.node_acq[path]].sum())
    return primal
