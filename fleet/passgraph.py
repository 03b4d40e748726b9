"""Each pass of a fleet as a single-pass problem that the project's solvers take.

A pass (:mod:`eosp.fleet.opportunities`) is a run of one satellite's opportunities that no
other pass of that satellite can conflict with.  Its problem is the paper's: acquisitions (the
pass's tasks) with candidate starts on the action grid, and transitions whose duration depends
on when they start.  It becomes a :class:`~eosp.graphs.discrete.DiscreteGraph` in the project's
canonical order: node 0 the source, then each task's opportunities by increasing start; from a
node, one arc to the EARLIEST opportunity of each other task that can follow it, i.e. that starts
at least the slew plus settling time after the node ends, the slew angle being the angle between
the inertial lines of sight at the end of one and the start of the other (the checker's rule,
with :data:`~eosp.fleet.slew.MARGIN_S` to spare).  Following arcs therefore always gives a
schedule the checker accepts.  The source's arcs apply the checker's rule for a satellite's first
action (a slew from geocentric nadir, the gap counted from the horizon start); any later pass
starts after a full 180-degree slew of time, so the rule never binds there.

Transitions are not FIFO (starting later can need a longer slew), so "earliest" can miss a
better later start; the checker re-derives every slew from geometry, never from an arc.

A priced problem keeps the pass's graph and changes the utilities: :func:`priced_instance`
drops tasks whose priced value is not positive (their nodes and arcs) and returns an
:class:`~eosp.instances.instance.Instance` for any single-pass solver.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from eosp.fleet.energy import observation_wh
from eosp.fleet.geometry import NUMERICAL_EPS
from eosp.fleet.model import Fleet
from eosp.fleet.opportunities import Opportunities
from eosp.fleet.slew import MARGIN_S, LineOfSight
from eosp.graphs.build import first_at_or_after
from eosp.graphs.discrete import DiscreteGraph, arc_to_acq
from eosp.graphs.prune import fifo_violations
from eosp.instances.instance import Acquisitions, Instance
from eosp.planning.labels import label_search
from eosp.sim.slew import bang_coast_bang


# Memory of a fleet's pass graphs (Problem.build, a worker's graphs), on top of the whole horizon's geometry
# (eosp.fleet.opportunities.horizon_bytes), fitted with margin to the solver's peak on generated days of 200
# satellites (0.9 GB: 766,306 opportunities, 13,041 passes) and 1,000 satellites (8.7 GB with int32 arcs, 6.3 GB
# with uint16 ones: 19.5 M opportunities, 62,247 passes, docs/results.md).  Per opportunity its node, lines of
# sight and share of the solver's state; per pass its objects and arrays; arcs: from each node at most one to each
# other task of its pass, uint16 (COMPACT_NODES), measured 0.42-0.49 of (nodes x tasks) a pass, counted at 0.5
# with room for the bound graphs some passes need.
NODE_BYTES = 150
PASS_BYTES = 30_000
PAIR_BYTES = 1.25  # per (node, task of its pass): 0.5 arcs x 2 bytes, x 1.25


def node_task_pairs(opps: Opportunities, n_tasks: int) -> int:
    """Sum over the passes of nodes x distinct tasks: what the pass graphs' arcs scale with (one arc at most per
    node and task).  A pass of a dense fleet holds more tasks, so its graph grows faster than its opportunities."""
    if len(opps) == 0:
        return 0
    key = np.unique(opps.pass_id.astype(np.int64) * max(1, n_tasks) + opps.task)
    tasks_per_pass = np.bincount(key // max(1, n_tasks), minlength=opps.n_passes)
    return int((np.diff(opps.pass_offsets()) * tasks_per_pass).sum())


def graph_bytes(opps: Opportunities, n_tasks: int) -> int:
    """Estimated memory of every pass graph of `opps` and the solver's state around them."""
    return int(len(opps) * NODE_BYTES + opps.n_passes * PASS_BYTES + node_task_pairs(opps, n_tasks) * PAIR_BYTES)


def require_solve_memory(fleet: Fleet, opps: Opportunities, where: object, processes: int = 1,
                         lean: bool = False) -> None:
    """Refuse (one line with the estimate) a fleet whose pass graphs cannot fit in memory, before building them.
    `processes`: processes on this machine that each build the geometry of the whole horizon and a share of the
    graphs (the driver and local Ray actors; forked workers share the driver's).  `lean`: the driver keeps the
    passes without arcs (:func:`lean_pass`), so the graphs are held once, by the actors, and the nodes and the
    solver's state twice; else the driver holds every graph beside the actors' shares."""
    from eosp.fleet.opportunities import horizon_bytes
    from eosp.memory import require_memory

    geometry, n = horizon_bytes(fleet, processes)
    graphs = graph_bytes(opps, len(fleet.tasks))
    need = geometry + (graphs + len(opps) * NODE_BYTES if lean else graphs * (2 if processes > 1 else 1))
    on = f" in {processes} processes" if processes > 1 else ""
    require_memory(where, int(need), f"the pass graphs of {len(opps):,} opportunities of "
                                     f"{len(fleet.satellites)} satellites over {fleet.horizon.seconds:,} s "
                                     f"({n:,} instants){on}")


def require_solvable(fleet: Fleet, opps: Opportunities, where: object, geo=None, processes: int = 1,
                     lean: bool = False):
    """Before solving: the pass graphs' memory estimated and checked (:func:`require_solve_memory`), then the fleet
    feasible (:func:`eosp.fleet.check.require_feasible`); returns the Geometry it checked with (`geo`, or a new one
    built once the memory is known to suffice)."""
    from eosp.fleet.check import require_feasible
    from eosp.fleet.geometry import Geometry

    require_solve_memory(fleet, opps, where, processes, lean)
    geo = geo or Geometry(fleet)
    require_feasible(fleet, where, geo)
    return geo


LEAN_ABOVE_BYTES = 4 * 1024 ** 3  # the fleet job's driver is lean by default where the graphs are estimated above
# this (a 1,000-satellite day: 12 GiB; a 200-satellite one, 1 GiB, keeps them: its small sweeps are solved there)


COMPACT_NODES = 65_536  # a pass graph of at most this many nodes keeps its arcs' destinations as uint16


@dataclass(frozen=True, eq=False)
class PassGraph:
    """One pass as a discrete graph over its opportunities.

    ``rows[i]`` is the opportunity (row of :class:`Opportunities`) of node i + 1; ``tasks[a]`` the
    fleet task of local acquisition a; ``graph`` holds every task of the pass (unpruned arcs)."""

    pass_id: int
    satellite: int
    tasks: np.ndarray  # int32 [k]
    rows: np.ndarray  # int64 [N - 1]
    duration: np.ndarray  # float64 [k]
    graph: DiscreteGraph
    energy_wh: np.ndarray  # float64 [k]: the least energy above idle an observation of each task takes (energy.py)
    bound_graph: DiscreteGraph | None = None  # see bound_problem(); None: `graph` serves the bound as it is
    bound_provable: bool = True  # False: the bound graph is not FIFO, no pass bound can be proven on it
    lean: bool = False  # built without arcs (lean_pass): solved elsewhere, its paths re-walked by walk()

    @property
    def n_tasks(self) -> int:
        return len(self.tasks)

    @property
    def nbytes(self) -> int:
        """Bytes of its arrays (a bound graph's node arrays are the pass graph's own: counted once)."""
        arrays = [self.tasks, self.rows, self.duration, self.energy_wh, self.graph.node_acq, self.graph.node_time,
                  self.graph.indptr, self.graph.dst, self.graph.acq_ptr]
        if self.bound_graph is not None:
            arrays += [self.bound_graph.indptr, self.bound_graph.dst]
        return sum(a.nbytes for a in arrays if 0 not in a.strides)  # (a lean pass's indptr: a view of one zero)


def _slew(fleet: Fleet, sat: int) -> np.ndarray:
    """Max rate, max acceleration and settling time of satellite `sat` (what :func:`_need` takes)."""
    att = fleet.satellites.attitude
    return np.array([att.max_rate_deg_s[sat], att.max_acc_deg_s2[sat], att.settling_s[sat]], dtype=np.float64)


@numba.njit(cache=True, inline="always")
def _need(u, v, rate, acc, settle):
    """Slew (bang-coast-bang, :func:`eosp.sim.slew.bang_coast_bang`) plus settling time between two pointing
    vectors."""
    nu = np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    nv = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if nu <= 1e-9 or nv <= 1e-9:
        return settle
    c = (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]) / (nu * nv)
    c = min(1.0, max(-1.0, c))
    angle = np.degrees(np.arccos(c))
    return bang_coast_bang(angle, rate, acc) + settle


@numba.njit(cache=True)
def _arcs(acq_ptr, node_time, node_end, los_start, los_end, nadir, slew, margin):
    """Both graphs of a pass in one scan: the schedule's (`margin` to spare, no arc to the node's own acquisition)
    and the loose one (`margin` granted, later starts of the node's own acquisition too).  CSR arcs from each node
    to the earliest node of every acquisition that can follow it; rows sorted by destination.  Each slew is
    computed once and tested against both margins (the loose arc is found at or before the schedule's one).
    Returns (indptr, dst) of each and whether the loose graph, its repeats aside, has the same arcs.
    `slew` = (max rate, max acceleration, settling)."""
    rate, acc, settle = slew[0], slew[1], slew[2]
    n = node_time.shape[0]
    k = acq_ptr.shape[0] - 1
    ip_s = np.zeros(n + 1, dtype=np.int64)
    ip_l = np.zeros(n + 1, dtype=np.int64)
    dst_s = np.empty(max(1, n * k), dtype=np.int32)
    dst_l = np.empty(max(1, n * k + k), dtype=np.int32)
    cs = 0
    cl = 0
    same = True
    for b in range(k):  # the source: a first action slews from nadir, its gap counted from the horizon start
        found_l = -1
        found_s = -1
        for v in range(acq_ptr[b], acq_ptr[b + 1]):
            need = _need(nadir[v], los_start[v], rate, acc, settle)
            if found_l < 0 and node_time[v] >= need - margin:
                found_l = v
            if node_time[v] >= need + margin:
                found_s = v
                break
        if found_l >= 0:
            dst_l[cl] = found_l
            cl += 1
        if found_s >= 0:
            dst_s[cs] = found_s
            cs += 1
        if found_l != found_s:
            same = False
    ip_s[1] = cs
    ip_l[1] = cl
    acq = 0
    for u in range(1, n):
        while u >= acq_ptr[acq + 1]:
            acq += 1
        for b in range(k):
            own = b == acq
            lo = first_at_or_after(node_time, acq_ptr[b], acq_ptr[b + 1], node_end[u])  # first of b after u ends
            found_l = -1
            found_s = -1
            for v in range(lo, acq_ptr[b + 1]):
                gap = node_time[v] - node_end[u]
                need = _need(los_end[u], los_start[v], rate, acc, settle)
                if found_l < 0 and gap >= need - margin:
                    found_l = v
                    if own:
                        break
                if not own and gap >= need + margin:
                    found_s = v
                    break
            if found_l >= 0:
                dst_l[cl] = found_l
                cl += 1
            if found_s >= 0:
                dst_s[cs] = found_s
                cs += 1
            if not own and found_l != found_s:
                same = False
        ip_s[u + 1] = cs
        ip_l[u + 1] = cl
    return ip_s, dst_s[:cs].copy(), ip_l, dst_l[:cl].copy(), same


@dataclass(frozen=True, eq=False)
class PassNodes:
    """A pass's opportunities as its graph's nodes, before any arc (node 0 the source; the canonical order: by
    acquisition, then start), with what the slew rule reads of each: what :func:`build_pass` scans for arcs and
    :func:`walk` for one path."""

    sat: int
    rows: np.ndarray  # int64 [N - 1]: the opportunity of node i + 1
    tasks: np.ndarray  # int64 [k]: the fleet task of local acquisition a
    duration: np.ndarray  # float64 [k]
    node_acq: np.ndarray  # int32 [N], -1 for the source
    node_time: np.ndarray  # float64 [N]
    node_end: np.ndarray  # float64 [N]
    acq_ptr: np.ndarray  # int64 [k + 1]
    slew: np.ndarray  # float64 [3]: max rate, max acceleration, settling

    @classmethod
    def of(cls, fleet: Fleet, opps: Opportunities, p: int, offsets: np.ndarray) -> PassNodes:
        """Pass `p`'s nodes (``offsets``: :meth:`Opportunities.pass_offsets`)."""
        rows = np.arange(offsets[p], offsets[p + 1])
        sat = int(opps.satellite[rows[0]])
        tasks, local = np.unique(opps.task[rows], return_inverse=True)
        start = opps.start[rows].astype(np.float64) * fleet.horizon.action_step_s
        order = np.lexsort((start, local))  # canonical: by acquisition, then start
        rows, local, start = rows[order], local[order], start[order]
        duration = fleet.tasks.duration_s[tasks].astype(np.float64)
        acq_ptr = np.r_[0, np.cumsum(np.bincount(local, minlength=len(tasks)))].astype(np.int64) + 1
        # node 0 is the source: its slots in the per-node arrays are never read as a destination
        return cls(sat, rows.astype(np.int64), tasks, duration, np.r_[-1, local].astype(np.int32), np.r_[0.0, start],
                   np.r_[0.0, start + duration[local]], acq_ptr, _slew(fleet, sat))

    @classmethod
    def of_pass(cls, fleet: Fleet, pg: PassGraph) -> PassNodes:
        """The nodes of a built pass (lean or not): the same numbers as :meth:`of` gave when it was built."""
        g = pg.graph
        return cls(pg.satellite, pg.rows, pg.tasks, pg.duration, g.node_acq, g.node_time,
                   np.r_[0.0, g.node_time[1:] + pg.duration[g.node_acq[1:]]], g.acq_ptr, _slew(fleet, pg.satellite))

    def sight(self, opps: Opportunities, los: LineOfSight) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Lines of sight at every node's start and end, and nadir at its start ([N, 3] each, zeros at the source),
        computed for the whole pass at once: the same numbers wherever they are needed (:func:`build_pass`'s arcs,
        :func:`walk` on a driver without them)."""
        task = opps.task[self.rows]
        start, end = self.node_time[1:], self.node_end[1:]
        zero = np.zeros((1, 3))
        return (np.vstack([zero, los.los(self.sat, task, start)]), np.vstack([zero, los.los(self.sat, task, end)]),
                np.vstack([zero, los.nadir(self.sat, start)]))


def build_pass(fleet: Fleet, opps: Opportunities, los: LineOfSight, p: int, offsets: np.ndarray) -> PassGraph:
    """The discrete graph of pass `p` (``offsets``: :meth:`Opportunities.pass_offsets`)."""
    nd = PassNodes.of(fleet, opps, p, offsets)
    los_start, los_end, nadir = nd.sight(opps, los)
    node_acq, node_time, node_end, acq_ptr = nd.node_acq, nd.node_time, nd.node_end, nd.acq_ptr
    ip_s, dst_s, ip_l, dst_l, same = _arcs(acq_ptr, node_time, node_end, los_start, los_end, nadir, nd.slew,
                                           MARGIN_S + NUMERICAL_EPS)
    if len(node_time) <= COMPACT_NODES:  # half the memory of the arcs, most of a dense fleet's graphs
        dst_s, dst_l = dst_s.astype(np.uint16), dst_l.astype(np.uint16)
    graph = DiscreteGraph(node_acq, node_time, ip_s, dst_s, acq_ptr)
    loose = DiscreteGraph(node_acq, node_time, ip_l, dst_l, acq_ptr)
    fifo = fifo_violations(loose) == 0
    if fifo and same and not has_bridge_triple(
            loose, _tracking_fits(los_start, los_end, node_time, node_end, nd.slew, MARGIN_S + NUMERICAL_EPS,
                                  tracking_slack(nd.slew))):
        loose = None  # the pass graph serves the bound (bound_problem)
    return PassGraph(p, nd.sat, nd.tasks.astype(np.int32), nd.rows, nd.duration, graph,
                     observation_wh(fleet, nd.sat, nd.tasks), loose, fifo)


NO_ARCS = np.zeros(0, dtype=np.uint16)
_ZERO = np.zeros(1, dtype=np.int64)


def lean_pass(fleet: Fleet, opps: Opportunities, p: int, offsets: np.ndarray) -> PassGraph:
    """Pass `p` without its arcs (:attr:`PassGraph.lean`): what a driver whose passes are solved elsewhere keeps
    of it (its nodes, tasks and energy: a tenth of the graph's memory at 1,000 satellites), built without the
    geometry's scan of every pair of nodes."""
    nd = PassNodes.of(fleet, opps, p, offsets)
    # no arc from any node: an indptr of zeros as a view of one zero (no memory: 19.5 M nodes at 1,000 satellites)
    graph = DiscreteGraph(nd.node_acq, nd.node_time, np.broadcast_to(_ZERO, len(nd.node_time) + 1), NO_ARCS,
                          nd.acq_ptr)
    return PassGraph(p, nd.sat, nd.tasks.astype(np.int32), nd.rows, nd.duration, graph,
                     observation_wh(fleet, nd.sat, nd.tasks), None, True, lean=True)


@numba.njit(cache=True)
def _walk(acq_ptr, node_acq, node_time, node_end, los_start, los_end, nadir, slew, margin, acqs):
    """The acquisitions `acqs` followed from the source, each at the node :func:`_arcs` would make the schedule
    graph's arc to (the same scan, the same numbers); one that cannot follow is skipped."""
    rate, acc, settle = slew[0], slew[1], slew[2]
    out = np.empty(acqs.shape[0], dtype=np.int64)
    m = 0
    u = 0
    for i in range(acqs.shape[0]):
        b = acqs[i]
        found = -1
        if u == 0:
            for v in range(acq_ptr[b], acq_ptr[b + 1]):
                if node_time[v] >= _need(nadir[v], los_start[v], rate, acc, settle) + margin:
                    found = v
                    break
        elif b != node_acq[u]:
            lo = first_at_or_after(node_time, acq_ptr[b], acq_ptr[b + 1], node_end[u])  # first of b after u ends
            for v in range(lo, acq_ptr[b + 1]):
                if node_time[v] - node_end[u] >= _need(los_end[u], los_start[v], rate, acc, settle) + margin:
                    found = v
                    break
        if found >= 0:
            out[m] = found
            m += 1
            u = found
    return out[:m]


def walk(fleet: Fleet, opps: Opportunities, los: LineOfSight, pg: PassGraph, path: np.ndarray) -> np.ndarray:
    """:func:`eosp.kinds.fleet.problem.rewalk` without the arcs: the acquisitions of `path` (nodes of `pg`, in
    order) followed from the source, each at its earliest node that can follow the one before under the schedule
    graph's rule, found from the geometry; the same nodes as along the arcs (tested): the lines of sight are those
    :func:`build_pass` computed (:meth:`PassNodes.sight`, the whole pass at once) and the scan is its scan."""
    path = np.asarray(path, dtype=np.int64)
    if len(path) == 0:
        return path
    nd = PassNodes.of_pass(fleet, pg)
    los_start, los_end, nadir = nd.sight(opps, los)
    return _walk(nd.acq_ptr, nd.node_acq, nd.node_time, nd.node_end, los_start, los_end, nadir, nd.slew,
                 MARGIN_S + NUMERICAL_EPS, nd.node_acq[path].astype(np.int64))


@numba.njit(cache=True)
def _bridge_triples(node_acq, node_time, indptr, dst, acq_ptr):
    count = 0
    for u in range(node_acq.shape[0]):
        for a in range(indptr[u], indptr[u + 1]):
            v = dst[a]
            for b in range(indptr[v], indptr[v + 1]):
                x = dst[b]
                y = arc_to_acq(indptr, dst, acq_ptr, u, node_acq[x])
                if y < 0 or node_time[y] > node_time[x]:
                    count += 1
    return count


def bridge_triples(graph: DiscreteGraph) -> int:
    """Consecutive arcs u -> v -> x after which u has no arc to x's acquisition arriving by x's time: places
    where leaving v out of a schedule can break it (v a bridge)."""
    return int(_bridge_triples(graph.node_acq, graph.node_time, graph.indptr, graph.dst, graph.acq_ptr))


@numba.njit(cache=True)
def _has_bridge_triple(node_acq, node_time, indptr, dst, n_acq, u_end):
    """:func:`_bridge_triples` > 0 over the nodes u < `u_end`, in one pass over the two-arc paths without a search:
    per node u, the earliest time at which each acquisition is reached in two arcs (a dense row, reset after u),
    against the time of u's own arc to it (one at most an acquisition: arcs go to the earliest node that can
    follow)."""
    inf = np.inf
    best = np.full(n_acq, inf)
    direct = np.full(n_acq, inf)
    touched = np.empty(n_acq, np.int64)
    for u in range(u_end):
        m = 0
        for a in range(indptr[u], indptr[u + 1]):
            v = dst[a]
            for b in range(indptr[v], indptr[v + 1]):
                x = dst[b]
                k = node_acq[x]
                if best[k] == inf:
                    touched[m] = k
                    m += 1
                if node_time[x] < best[k]:
                    best[k] = node_time[x]
        for a in range(indptr[u], indptr[u + 1]):
            v = dst[a]
            k = node_acq[v]
            if node_time[v] < direct[k]:
                direct[k] = node_time[v]
        found = False
        for i in range(m):
            k = touched[i]
            if direct[k] > best[k]:
                found = True
            best[k] = inf
        for a in range(indptr[u], indptr[u + 1]):
            direct[node_acq[dst[a]]] = inf
        if found:
            return True
    return False


@numba.njit(cache=True)
def _tracking_fits(los_start, los_end, node_time, node_end, slew, margin, slack):
    """Whether every observation turns the line of sight by less than a slew could in its time: for every node v
    but the source, slew(angle(start, end of v)) + `slack` <= duration(v) + settling - `margin` (lines of sight
    of norm above 1e-9)."""
    rate, acc, settle = slew[0], slew[1], slew[2]
    for v in range(1, node_time.shape[0]):
        su, eu = los_start[v], los_end[v]
        if np.sqrt(su[0] * su[0] + su[1] * su[1] + su[2] * su[2]) <= 1e-9 or \
                np.sqrt(eu[0] * eu[0] + eu[1] * eu[1] + eu[2] * eu[2]) <= 1e-9:
            return False
        if _need(su, eu, rate, acc, settle) - settle + slack > node_end[v] - node_time[v] + settle - margin:
            return False
    return True


ANGLE_SLACK_DEG = 1.0e-4  # more than the rounding of four computed angles (arccos near 1: about 1e-6 degrees each)


def tracking_slack(slew: np.ndarray) -> float:
    """Seconds that cover what the slew function's rounding and its cut at SMALL_DEG can add to the triangle
    argument of :func:`has_bridge_triple`: three times the concave slew of 2e-9 degrees (the function is 0 below
    1e-9 degrees, its concave extension is not) plus the slew of :data:`ANGLE_SLACK_DEG`."""
    return 3.0 * bang_coast_bang(2.0e-9, slew[0], slew[1]) + bang_coast_bang(ANGLE_SLACK_DEG, slew[0], slew[1])


def has_bridge_triple(graph: DiscreteGraph, tracking_fits: bool = False) -> bool:
    """Whether :func:`bridge_triples` finds any (what :func:`build_pass` asks), in O(two-arc paths).

    `tracking_fits` (:func:`_tracking_fits` holds on the graph's pass, margins of the loose graph): then no node
    but the source can start a bridge triple, and only the source's row is searched.  Why: let u -> v -> x be
    arcs of the loose graph, u not the source, e_u the line of sight at u's end, s_v and e_v at v's start and end,
    s_x at x's start, f the bang-coast-bang slew (settling s apart), m the loose margin.  The arcs say
    t_v - end_u >= f(e_u, s_v) + s - m and t_x - end_v >= f(e_v, s_x) + s - m, so
    t_x - end_u >= f(e_u, s_v) + f(e_v, s_x) + d_v + 2 s - 2 m.  Angles obey the triangle inequality,
    angle(e_u, s_x) <= angle(e_u, s_v) + angle(s_v, e_v) + angle(e_v, s_x), and f is increasing and, but for its
    cut to 0 below 1e-9 degrees, concave with f(0) = 0, hence subadditive: f(e_u, s_x) <= f(e_u, s_v) +
    f(s_v, e_v) + f(e_v, s_x) + :func:`tracking_slack` (the cut and the angles' rounding).  With tracking_fits,
    f(s_v, e_v) + slack <= d_v + s - m, so t_x - end_u >= f(e_u, s_x) + s - m: x itself can follow u, and u's
    arc to x's acquisition (the earliest node of it that can follow u, searched from the first starting after u
    ends, which x does) arrives by t_x.  The source's rule (a slew from the nadir at the destination's own start)
    is not covered by this argument: its row is always searched."""
    u_end = 1 if tracking_fits else graph.n_nodes
    return bool(_has_bridge_triple(graph.node_acq, graph.node_time, graph.indptr, graph.dst, max(1, graph.n_acq),
                                   u_end))


def bound_problem(pg: PassGraph, value: np.ndarray, time_limit: float | None = None) -> float:
    """An upper bound of what pass `pg` can serve under prices, for the fleet's Lagrangian bound: the best, over
    every sequence of the pass's opportunities the verifier accepts (tasks observed again included, each
    credited once), of the sum of ``max(0, value[a])`` over the tasks it observes; inf when none is proven.

    Why it needs care: the verifier's slew rule is not hereditary (an observation that tracks its target turns
    the line of sight for free, so A -> B -> C can be valid while A -> C is too short), so a task whose priced
    value is not positive can still be needed as a bridge, and a task observed twice can be one too.  The
    *loose* graph has an arc for every transition the verifier accepts (its 1e-9 s tolerance and our slew
    numbers' last digits on the accepting side: arcs need the slew minus MARGIN_S + 1e-9 s, where the
    schedule's graph asks for that much more), earliest starts only, and arcs to later starts of the same task.
    When it is FIFO, any sequence the verifier accepts, re-timed to each task's earliest start after the
    previous one, is one of its paths; the label search with repeats over it, weights ``max(0, value)``, is
    then the best above.  When moreover it has no bridge triple (:func:`bridge_triples`) and, repeats aside,
    equals the schedule's graph, leaving any observation out of a path keeps a path (by induction along it,
    with FIFO), so the best is reached by a path of the schedule's graph over the tasks of positive value
    alone: the pass's ordinary priced problem (:func:`priced_instance`), whose optimum the caller computes
    anyway.  That case (``pg.bound_graph is None``) is not this function's to answer."""
    if pg.bound_graph is None:
        raise ValueError(f"pass {pg.pass_id}: its priced problem is its bound problem")
    if not pg.bound_provable:
        return math.inf
    res = label_search(pg.bound_graph, np.maximum(np.asarray(value, dtype=np.float64), 0.0), beam=0,
                       time_limit=time_limit, on_limit="stop", repeats=True)
    return float(res.value) if res.complete else math.inf


def build_passes(fleet: Fleet, opps: Opportunities, los: LineOfSight) -> list[PassGraph]:
    """Every pass of the fleet, in pass order."""
    off = opps.pass_offsets()
    return [build_pass(fleet, opps, los, p, off) for p in range(opps.n_passes)]


def _subgraph(graph: DiscreteGraph, keep_acq: np.ndarray) -> tuple[DiscreteGraph, np.ndarray]:
    """The graph restricted to the acquisitions in `keep_acq` (bool [k]): the source and the nodes of the kept
    acquisitions, renumbered in order, with the arcs between them in their order; (graph, kept old node ids).

    One kernel (:func:`_restrict`): a sweep solves thousands of small passes, and the same steps as a dozen numpy
    calls cost 77 us a pass on a 200-satellite day, more than the pass's label search."""
    node_acq, node_time, indptr, dst, acq_ptr, kept = _restrict(graph.node_acq, graph.node_time, graph.indptr,
                                                                graph.dst, keep_acq)
    return DiscreteGraph(node_acq, node_time, indptr, dst, acq_ptr), kept


@numba.njit(cache=True)
def _restrict(node_acq, node_time, indptr, dst, keep_acq):
    """:func:`_subgraph`'s arrays: node_acq (int32), node_time, indptr (int64), dst (int32), acq_ptr (int64) of
    the restricted graph, and the old ids of its nodes (int64)."""
    n = node_acq.shape[0]
    new_id = np.full(n, -1, np.int64)
    m = 0
    for v in range(n):
        if v == 0 or keep_acq[node_acq[v]]:
            new_id[v] = m
            m += 1
    acq_new = np.empty(keep_acq.shape[0], np.int64)
    k = 0
    for a in range(keep_acq.shape[0]):
        acq_new[a] = k
        if keep_acq[a]:
            k += 1
    kept = np.empty(m, np.int64)
    out_acq = np.empty(m, np.int32)
    out_time = np.empty(m, node_time.dtype)
    out_ptr = np.zeros(m + 1, np.int64)
    n_arcs = 0
    for v in range(n):
        i = new_id[v]
        if i < 0:
            continue
        kept[i] = v
        out_acq[i] = -1 if v == 0 else acq_new[node_acq[v]]
        out_time[i] = node_time[v]
        for e in range(indptr[v], indptr[v + 1]):
            if new_id[dst[e]] >= 0:
                n_arcs += 1
        out_ptr[i + 1] = n_arcs
    out_dst = np.empty(n_arcs, np.int32)
    j = 0
    for v in range(n):
        if new_id[v] < 0:
            continue
        for e in range(indptr[v], indptr[v + 1]):
            w = new_id[dst[e]]
            if w >= 0:
                out_dst[j] = w
                j += 1
    out_acq_ptr = np.zeros(k + 1, np.int64)  # nodes grouped by acquisition in acquisition order (canonical)
    out_acq_ptr[0] = 1
    for i in range(1, m):
        out_acq_ptr[out_acq[i] + 1] += 1
    for b in range(k):
        out_acq_ptr[b + 1] += out_acq_ptr[b]
    return out_acq, out_time, out_ptr, out_dst, out_acq_ptr, kept


@dataclass(frozen=True, eq=False)
class PricedPass:
    """A pass's problem under prices: the instance a single-pass solver takes, and how to map back
    (``nodes[i]`` = node of the pass graph of the instance's node i; ``acqs`` = kept local acquisitions)."""

    pass_graph: PassGraph
    instance: Instance
    nodes: np.ndarray
    acqs: np.ndarray


def priced_instance(pg: PassGraph, value: np.ndarray) -> PricedPass | None:
    """The pass's problem with utility `value[a]` per local acquisition; tasks whose value is not
    positive are left out.  None when no task is left."""
    priced = priced_graph(pg, value)
    return None if priced is None else priced_pass(pg, value, *priced)


def priced_graph(pg: PassGraph, value: np.ndarray) -> tuple[DiscreteGraph, np.ndarray, np.ndarray] | None:
    """The graph of :func:`priced_instance` alone, with its `nodes` and `acqs` maps (None when no task is left):
    what a solver that needs no instance takes (the fleet's exact pass solves, most of which end with the sweep
    alone, :func:`eosp.solvers.exact.sweep_alone`)."""
    keep = value > 0
    if not keep.any():
        return None
    graph, nodes = (pg.graph, np.arange(pg.graph.n_nodes)) if keep.all() else _subgraph(pg.graph, keep)
    return graph, nodes, np.flatnonzero(keep)


def priced_pass(pg: PassGraph, value: np.ndarray, graph: DiscreteGraph, nodes: np.ndarray,
                acqs: np.ndarray) -> PricedPass:
    """:func:`priced_instance` from its :func:`priced_graph`."""
    t = graph.node_time
    first = t[graph.acq_ptr[:-1]]
    last = t[graph.acq_ptr[1:] - 1] + pg.duration[acqs]
    inst = Instance(f"pass-{pg.pass_id}", Acquisitions(pg.duration[acqs].copy(), first, last,
                                                     value[acqs].astype(np.float64)),
                    graph, np.arange(graph.n_nodes, dtype=np.int64), meta={"horizon_s": float(last.max())})
    inst.pruned_graph = None
    return PricedPass(pg, inst, nodes, acqs)


