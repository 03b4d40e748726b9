"""The EOS-Bench solver: each (satellite, orbit) a pass solved exactly by the project's label search, passes held
together by task prices, with a Lagrangian upper bound.

What maps onto the fleet solver's machinery and what does not.  Their scenario is the fleet problem's shape: a
task is served at most once across passes, and within a pass a satellite observes one task after another with a
transition between them.  So the pass graphs are the project's discrete graphs (:mod:`eosp.kinds.eosbench.passes`)
swept by :func:`eosp.planning.labels.label_search` (exact), and the prices and their update are the fleet solver's
(:class:`eosp.kinds.lagrange.Prices`).  What differs: their windows and attitudes are given (no orbits to
propagate: the fleet's geometry, line-of-sight and battery model do not apply), transitions follow their model,
and the per-(satellite, orbit) power and storage sums are hard caps inside a pass rather than a battery running
from pass to pass, so the fleet's coordinator (battery repair, pass pools over aeossp fleets) is not used.

Schedules.  Passes in time order, each solved with the tasks not yet served (construction), then each solved
again with every task no other pass serves (coordinate descent: never worse), then large-neighbourhood moves:
the passes meeting a random time span are emptied and solved again in a random order, kept when the profit does
not fall.  A pass's cap on observations (power, storage) is kept by a price on its observations, raised by
bisection until the best path fits; observations of the same satellite in other passes mask the nodes they
conflict with; a path is checked pair by pair under their every-pair rule and repaired.  Every few rounds and
at the end, the paths committed so far are packed (:func:`pack`: a set packing solved by HiGHS, one path a pass,
each task once), kept when it serves more.  The schedule returned is checked by
:func:`eosp.eosbench.check.check` under the configured reading.

Bound.  For task prices lam >= 0 and pos = max(priority - lam, 0), every pass's term is the smallest of
(a) its optimum under utilities pos with the cap dropped, over the code reading's graph (11.66 s transitions, the
documented reading's minimum, so the term bounds both readings; FIFO, so the exact label search over earliest arcs
is the pass optimum; transitions to other passes dropped); (b) the sum of its `cap` largest positive utilities
(the power and storage caps with transitions dropped); and (c), for any mu >= 0, (a) under utilities pos - mu,
plus mu * cap: a path P of at most cap observations has sum pos <= sum (pos - mu)^+ + mu |P|, and P's nodes of
pos > mu are themselves a path (dropping an observation never breaks a constant transition); (a) is (c) at mu = 0
and the term takes the least over a few mu.  Sum of terms + sum of lam bounds the profit of any schedule valid
under either reading.  A pass whose label search stops at its time limit keeps term (b) or, without a cap, the sum
of its positive utilities.  Prices move by the fleet's projected subgradient step, or with ``--price-step lp`` to
the smoothed duals of a linear program over the passes' paths (:mod:`eosp.kinds.eosbench.dual`).
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from eosp.budget import UNLIMITED, Budget
from eosp.config import WEEK_S, choice, ranged
from eosp.eosbench.check import check, verdict
from eosp.eosbench.model import Scenario, Schedule
from eosp.eosbench.transition import PROFILES, READINGS, Rules, to_us, transition_s
from eosp.errors import InputError
from eosp.kinds.eosbench.dual import PriceLP
from eosp.kinds.eosbench.passes import NO_CAP, Pass, best_path, build_passes, graph
from eosp.kinds.lagrange import Prices
from eosp.problem import Result
from eosp.solvers.base import UtilityConfig

CUTS = 8  # cutting planes of a capped pass's bound term
PACK_EVERY = 5  # price rounds between two packings of the paths met (pack)
PACK_RESERVE_S = 2.0  # seconds a packing may take at most, kept for the last one before the time limit
PACK_NODES = 200  # branch-and-bound nodes of a packing with a fixed number of rounds


@dataclass
class EosBenchConfig(UtilityConfig):
    """Options of the EOS-Bench solver (``eosp solve SCENARIO.json --solver eosbench``)."""

    time_limit: float | None = ranged(60.0, 0, WEEK_S, lo_open=True, zero_unsets=True)
    seed: int = ranged(0, 0)
    """Seed of the large-neighbourhood moves."""
    transition: str = choice("documented", *READINGS)
    """Transition reading the schedule must satisfy: documented (their paper's piecewise function of the attitude
    change) or code (11.66 s, what their checker applies); a schedule valid as documented is valid for both."""
    agility: str = choice("Standard-Agility", *PROFILES)
    """Agility profile of the documented transitions (their scheduler's default: Standard-Agility)."""
    rounds: int | None = ranged(None, 1)
    """Price rounds, each followed by `moves_per_round` large-neighbourhood moves (a deterministic budget); unset: as many as the
    time limit allows."""
    price_step: str = choice("uniform", "uniform", "lp")
    """The prices of the next round: uniform (Polyak's subgradient step, every price by the same amount per unit of
    its subgradient) or lp (the smoothed duals of a linear program over the pass paths of the bound rounds so far,
    eosp.kinds.eosbench.dual: a tighter bound after more rounds, at an LP solve a round)."""
    moves_per_round: int = ranged(4, 1)
    """Large-neighbourhood moves after each price round (a price round costs several moves' time: on 10 satellites
    x 500 tasks, 4 moves a round served more than 1 at 30 s)."""
    pass_time_limit: float = ranged(2.0, 0)
    """Seconds the label search may spend on one pass."""
    span_s: float = ranged(5400.0, 1)
    """Length of the time span a large-neighbourhood move empties."""

    NAME = "eosbench"
    BUDGET = "rounds"


@dataclass
class State:
    """Passes, the schedule as one path per pass, the prices and the bound (see the module docstring)."""

    scenario: Scenario
    rules: Rules
    passes: list[Pass]
    cfg: EosBenchConfig
    paths: list[np.ndarray] = field(init=False)
    served: np.ndarray = field(init=False)  # pass serving each task, -1
    t0: float = field(default_factory=time.perf_counter)
    pass_solves: int = 0
    columns: dict = field(default_factory=dict)  # (pass, its tasks as bytes) -> a path of it serving them (pack)

    def __post_init__(self) -> None:
        self.paths = [np.zeros(0, np.int64) for _ in self.passes]
        self.served = np.full(len(self.scenario.tasks), -1, np.int64)
        self.prio = self.scenario.tasks.priority.astype(np.float64)
        self.agile = [bool(self.scenario.satellites.agile[p.satellite]) for p in self.passes]
        self.by_sat: dict[int, list[int]] = {}
        for i, p in enumerate(self.passes):
            self.by_sat.setdefault(p.satellite, []).append(i)
        self.span = np.array([[p.start_us[1:].min(), p.end_us[1:].max()] for p in self.passes]).reshape(-1, 2)
        # the passes seeing each task (CSR by task, passes in increasing order)
        tasks = np.concatenate([p.tasks for p in self.passes]) if self.passes else np.zeros(0, np.int32)
        of = np.repeat(np.arange(len(self.passes)), [len(p.tasks) for p in self.passes])
        by_task = np.argsort(tasks, kind="stable")
        self.task_ptr = np.searchsorted(tasks[by_task], np.arange(len(self.scenario.tasks) + 1))
        self.task_passes = of[by_task]

    def passes_of(self, task: int) -> np.ndarray:
        return self.task_passes[self.task_ptr[task]:self.task_ptr[task + 1]]

    @property
    def value(self) -> float:
        return float(self.prio[self.served >= 0].sum())

    def path_tasks(self, p: int, path: np.ndarray) -> np.ndarray:
        return self.passes[p].tasks[self.passes[p].node_acq[path]]

    def commit(self, p: int, path: np.ndarray) -> None:
        old = self.path_tasks(p, self.paths[p])
        self.served[old[self.served[old] == p]] = -1
        tasks = self.path_tasks(p, path)
        _, first = np.unique(tasks, return_index=True)  # a task seen by two sensors of one orbit: once
        path = path[np.sort(first)]
        self.paths[p] = path
        self.served[self.path_tasks(p, path)] = p
        if len(path):
            self.columns.setdefault((p, np.sort(self.path_tasks(p, path)).tobytes()), path)

    def pass_value(self, p: int, path: np.ndarray | None = None) -> float:
        return float(self.prio[np.unique(self.path_tasks(p, self.paths[p] if path is None else path))].sum())


def _pair_conflicts(rules: Rules, agile: bool, a: tuple, b: tuple) -> np.ndarray:
    """[len(a), len(b)] bool: observation a_i and b_j break their every-pair rule (a, b: start, end, first and
    last attitudes)."""
    a0, a1, af, al = a
    b0, b1, bf, bl = b
    shape = (len(a0), len(b0))
    if not shape[0] or not shape[1]:
        return np.zeros(shape, dtype=bool)
    ii = np.repeat(np.arange(shape[0]), shape[1])
    jj = np.tile(np.arange(shape[1]), shape[0])
    t_ba = to_us(transition_s(rules, agile, bl[jj], af[ii])).reshape(shape)
    t_ab = to_us(transition_s(rules, agile, al[ii], bf[jj])).reshape(shape)
    a_after = a0[:, None] >= b0[None, :]
    return np.where(a_after, b1[None, :] + t_ba > a0[:, None], a1[:, None] + t_ab > b0[None, :])


def _obs(p: Pass, nodes: np.ndarray) -> tuple:
    return p.start_us[nodes], p.end_us[nodes], p.first[nodes], p.last[nodes]


def _neighbour_mask(st: State, k: int) -> np.ndarray:
    """Nodes of pass k that break the every-pair rule with an observation of the same satellite in another pass."""
    p = st.passes[k]
    ok = np.ones(p.n_nodes, dtype=bool)
    reach = 200 * 1_000_000  # transitions stay far below 200 s on their attitude limits
    lo, hi = st.span[k, 0] - reach, st.span[k, 1] + reach
    others = [q for q in st.by_sat[p.satellite] if q != k and len(st.paths[q]) and st.span[q, 1] >= lo
              and st.span[q, 0] <= hi]
    if not others:
        return ok
    nb = tuple(np.concatenate(x) for x in zip(*(_obs(st.passes[q], st.paths[q]) for q in others)))
    near = (nb[0] >= lo) & (nb[0] <= hi)
    if not near.any():
        return ok
    nb = tuple(x[near] for x in nb)
    nodes = np.arange(1, p.n_nodes)
    ok[1:] = ~_pair_conflicts(st.rules, st.agile[k], _obs(p, nodes), nb).any(axis=1)
    return ok


def _repair_path(st: State, k: int, path: np.ndarray) -> np.ndarray:
    """The path with observations dropped (the later of the first pair that breaks the every-pair rule) until
    every pair holds."""
    p = st.passes[k]
    while len(path) > 2:
        obs = _obs(p, path)
        bad = _pair_conflicts(st.rules, st.agile[k], obs, obs)
        np.fill_diagonal(bad, False)
        bad = np.triu(bad)
        if not bad.any():
            break
        i, j = np.argwhere(bad)[0]
        path = np.delete(path, max(i, j))
    return path


def solve_pass(st: State, k: int, util: np.ndarray, budget: Budget) -> np.ndarray:
    """The best path of pass k under per-acquisition utilities `util` within the pass's cap, the other passes of
    its satellite fixed (see the module docstring)."""
    p = st.passes[k]
    base = _neighbour_mask(st, k)
    tl = st.cfg.pass_time_limit
    if budget.limited:
        tl = max(0.05, min(tl, budget.left()))

    def run(u: np.ndarray) -> np.ndarray:
        allowed = base & np.r_[True, u[p.node_acq[1:]] > 0]
        if not allowed[1:].any():
            return np.zeros(0, np.int64)
        st.pass_solves += 1
        return best_path(graph(p, st.rules, st.agile[k], allowed), np.maximum(u, 0.0), tl)[0]

    path = run(util)
    if len(path) > p.cap:  # a price on every observation, raised until the best path fits the cap
        lo, hi, best, best_val = 0.0, float(util.max()), None, -1.0
        for _ in range(14):
            mu = (lo + hi) / 2
            cand = run(util - mu)
            if len(cand) <= p.cap:
                hi = mu
                val = float(util[p.node_acq[cand]].sum())
                if val > best_val:
                    best, best_val = cand, val
            else:
                lo = mu
        path = best if best is not None else path[np.argsort(-util[p.node_acq[path]])[:p.cap]]
        path = np.sort(path, kind="stable")
        path = path[np.argsort(p.start_us[path], kind="stable")]
    return _repair_path(st, k, path)


def _fill(st: State, k: int, path: np.ndarray, util: np.ndarray, base: np.ndarray) -> np.ndarray:
    """The path with acquisitions inserted, best utility first, at their earliest node that keeps every pair
    (up to the pass's cap), and, once full, one swapped for a better one in place of the path's weakest.  The
    price on observations that keeps a path within the cap jumps over path lengths when utilities tie; this
    takes the room it leaves."""
    p = st.passes[k]
    in_path = np.zeros(len(p.tasks), dtype=bool)
    in_path[p.node_acq[path]] = True
    served = set(p.tasks[p.node_acq[path]].tolist())
    for a in np.argsort(-util, kind="stable").tolist():
        if util[a] <= 0:
            break
        if in_path[a] or int(p.tasks[a]) in served:
            continue
        nodes = np.arange(p.acq_ptr[a], p.acq_ptr[a + 1])
        nodes = nodes[base[nodes]]
        if not len(nodes):
            continue
        drop = None
        if len(path) >= p.cap:
            weakest = int(np.argmin(util[p.node_acq[path]]))
            if util[p.node_acq[path[weakest]]] >= util[a]:
                continue
            drop = weakest
        rest = path if drop is None else np.delete(path, drop)
        bad = _pair_conflicts(st.rules, st.agile[k], _obs(p, nodes), _obs(p, rest)).any(axis=1)
        if bad.all():
            continue
        if drop is not None:
            in_path[p.node_acq[path[drop]]] = False
            served.discard(int(p.tasks[p.node_acq[path[drop]]]))
        path = np.append(rest, nodes[np.argmin(bad)])
        path = path[np.argsort(p.start_us[path], kind="stable")]
        in_path[a] = True
        served.add(int(p.tasks[a]))
    return path


def improve(st: State, k: int, budget: Budget) -> bool:
    """Pass k solved again with every task no other pass serves; kept when it serves more profit."""
    p = st.passes[k]
    owner = st.served[p.tasks]
    util = np.where((owner < 0) | (owner == k), st.prio[p.tasks], 0.0)
    path = solve_pass(st, k, util, budget)
    gain = float(util[p.node_acq[path]].sum()) if len(path) else 0.0
    if gain > st.pass_value(k) + 1e-9:
        st.commit(k, path)
        return True
    return False


def polish(st: State) -> None:
    """Every pass filled with tasks no other pass serves (:func:`_fill`), kept when it serves more profit: never
    worse, and what the cap's price leaves on passes whose cap binds."""
    for k, p in enumerate(st.passes):
        owner = st.served[p.tasks]
        util = np.where((owner < 0) | (owner == k), st.prio[p.tasks], 0.0)
        path = _fill(st, k, st.paths[k], util, _neighbour_mask(st, k))
        if st.pass_value(k, path) > st.pass_value(k) + 1e-9:
            st.commit(k, path)


def descend(st: State, order: list[int], budget: Budget) -> None:
    """Coordinate descent: passes solved again until none improves (or the budget)."""
    queue = deque(order)
    queued = set(queue)
    while queue:
        if budget.expired():
            return
        k = queue.popleft()
        queued.discard(k)
        before = set(st.path_tasks(k, st.paths[k]).tolist())
        if improve(st, k, budget):
            freed = before - set(st.path_tasks(k, st.paths[k]).tolist())
            for t in freed:  # passes holding a task this one gave up may now take it
                for q in st.passes_of(t).tolist():
                    if q not in queued:
                        queue.append(q)
                        queued.add(q)


def _cap_term(p: Pass, pos: np.ndarray, build, time_limit: float
              ) -> tuple[float, np.ndarray, bool, np.ndarray]:
    """min over mu >= 0 of g(mu) = opt(pos - mu) + mu * cap (see the module docstring), the path at the best mu,
    whether that value is proven (every label search it rests on finished), and the most valuable path of at most
    `cap` observations among those the search met (a column of :mod:`eosp.kinds.eosbench.dual`).  g is convex and
    piecewise linear in mu with slope cap - |path(mu)|, so its minimum is found by cutting planes on one variable:
    the tangent lines at the two ends of the bracket meet at the next mu; the search stops when the value there is
    on those lines (mu is optimal), after a few cuts, or at an unfinished search (the best proven g so far
    stands)."""
    fit, fit_value = np.zeros(0, np.int64), 0.0

    def at(mu: float) -> tuple[float, int, np.ndarray, bool]:
        nonlocal fit, fit_value
        allowed = np.r_[True, pos[p.node_acq[1:]] > mu]
        if not allowed[1:].any():
            return mu * p.cap, p.cap, np.zeros(0, np.int64), True
        nodes, val, done = best_path(build(allowed), np.maximum(pos - mu, 0.0), time_limit)
        if len(nodes) <= p.cap and float(pos[p.node_acq[nodes]].sum()) > fit_value:
            fit, fit_value = nodes, float(pos[p.node_acq[nodes]].sum())
        return val + mu * p.cap, p.cap - len(nodes), nodes, done

    g0, s0, nodes, done = at(0.0)
    if not done:
        return math.inf, nodes, False, fit
    best, best_nodes = g0, nodes
    if s0 >= 0 or p.cap >= NO_CAP:  # the cap does not bind at mu = 0: g is smallest there
        return best, best_nodes, True, fit
    lo, hi = (0.0, g0, s0), (float(pos.max()), float(pos.max()) * p.cap, p.cap)
    if hi[1] < best:
        best, best_nodes = hi[1], np.zeros(0, np.int64)
    for _ in range(CUTS):
        mu = (hi[1] - lo[1] + lo[2] * lo[0] - hi[2] * hi[0]) / (lo[2] - hi[2])
        if not lo[0] < mu < hi[0]:
            break
        line = lo[1] + lo[2] * (mu - lo[0])
        g, slope, nodes, done = at(mu)
        if not done:
            break
        if g < best:
            best, best_nodes = g, nodes
        if g >= line - 1e-9 or slope == 0:  # on both tangents: mu minimises g
            break
        lo, hi = ((mu, g, slope), hi) if slope < 0 else (lo, (mu, g, slope))
    return best, best_nodes, True, fit


def bound_round(st: State, lam: np.ndarray, paths: list | None = None, budget: Budget = UNLIMITED
                ) -> tuple[float, np.ndarray, bool]:
    """L(lam) (see the module docstring), the count of passes taking each task, and whether every pass term came
    from a finished label search or a cap; with `paths`, (pass, tasks) of paths of at most `cap` observations of
    each pass in the relaxation: the best its term's search met, and the path of its term cut to its `cap` most
    valuable observations (:mod:`eosp.kinds.eosbench.dual`'s columns).  Once `budget` is
    spent a pass's term is (b), or without a cap the sum of its positive utilities, without a label search: still
    a bound, a weaker one."""
    total = float(lam.sum())
    taken = np.zeros(len(st.scenario.tasks))
    proven = True
    code = Rules("code", st.rules.agility)
    for k, p in enumerate(st.passes):
        u = st.prio[p.tasks] - lam[p.tasks]
        pos = np.maximum(u, 0.0)
        if not (pos > 0).any():
            continue
        top = np.sort(pos)[::-1][:p.cap] if p.cap < NO_CAP else None

        def build(allowed: np.ndarray, k: int = k, p: Pass = p):
            st.pass_solves += 1
            return graph(p, code, True, allowed) if st.agile[k] else graph(p, st.rules, False, allowed)

        limit = min(st.cfg.pass_time_limit, budget.left())
        if limit > 0:
            exact, nodes, _, fit = _cap_term(p, pos, build, max(0.05, limit))
        else:  # the budget spent: the cap's term, or every positive utility
            exact, nodes, fit = math.inf, np.zeros(0, np.int64), np.zeros(0, np.int64)
        if paths is not None:
            if len(fit):
                paths.append((k, p.tasks[p.node_acq[fit]]))
            if len(nodes) > p.cap:  # the path at the best mu, cut to its cap most valuable observations
                acq = p.node_acq[nodes]
                paths.append((k, p.tasks[acq[np.argsort(-pos[acq], kind="stable")[:p.cap]]]))
        capped = float(top.sum()) if top is not None else math.inf
        if math.isinf(exact) and math.isinf(capped):  # an unfinished search without a cap: every positive utility
            total += float(pos.sum())
            np.add.at(taken, np.unique(p.tasks[pos > 0]), 1.0)
            proven = False
        elif exact <= capped:
            total += exact
            np.add.at(taken, np.unique(p.tasks[p.node_acq[nodes]]), 1.0)
        else:
            total += capped
            take = np.argsort(-pos, kind="stable")[:p.cap]
            np.add.at(taken, p.tasks[take[pos[take] > 0]], 1.0)
    return total, taken, proven


def conflict_free(st: State) -> float:
    """Every task that has a candidate observation, at its priority."""
    seen = np.zeros(len(st.scenario.tasks), dtype=bool)
    for p in st.passes:
        seen[p.tasks] = True
    return float(st.prio[seen].sum())


def to_schedule(st: State) -> Schedule:
    rows = []
    for k, path in enumerate(st.paths):
        p = st.passes[k]
        rows += [(int(p.start_us[n]), int(p.window[n]), int(p.step[n])) for n in path.tolist()]
    rows.sort()
    return Schedule.build(st.scenario, [(r, s) for _, r, s in rows])


def _lns(st: State, rng: np.random.Generator, lam: np.ndarray, budget: Budget) -> None:
    """Empty the passes meeting a random time span (one that meets a random pass) and solve them again in a random
    order, each task's utility lowered by a random share of its price (a contested task is left to the passes that
    need it most), then coordinate descent with the true priorities; kept when the profit does not fall."""
    span = st.cfg.span_s * 1_000_000
    t = st.span[int(rng.integers(len(st.passes))), 0] - rng.uniform(0, span)  # a span meeting a random pass
    hit = np.flatnonzero((st.span[:, 1] >= t) & (st.span[:, 0] <= t + span)).tolist()
    if not hit:
        return
    before = (st.value, list(st.paths), st.served.copy())  # commit replaces a path, never edits one in place
    for k in hit:
        st.commit(k, np.zeros(0, np.int64))
    order = rng.permutation(hit).tolist()
    share = rng.uniform(0.0, 1.0)
    for k in order:
        if budget.expired():
            break
        p = st.passes[k]
        util = np.where(st.served[p.tasks] < 0, st.prio[p.tasks] - share * lam[p.tasks], 0.0)
        path = solve_pass(st, k, util, budget)
        if len(path):
            st.commit(k, path)
    descend(st, order, budget)
    if st.value < before[0] - 1e-9:  # the descent may have moved passes outside the span too: all restored
        st.paths, st.served = before[1], before[2]


def pack(st: State, limit: float | None, nodes: int | None = None) -> bool:
    """The schedule as the best set packing of the pass paths committed so far (:attr:`State.columns`: each pass
    one of its paths or none, each task at most once) that HiGHS finds within `limit` seconds (`nodes`
    branch-and-bound nodes: the same result on any machine), started from the current schedule; a chosen path
    that breaks the every-pair rule with a neighbouring pass's is dropped, then every pass is filled (:func:`polish`).
    Kept, and True, when it serves more profit.

    Why: the moves meet many good paths of each pass that no single schedule held together; on 10 satellites x
    500 tasks the packing of those met in 30 s served 19-30 more than the moves' best (solved to optimality in
    half a second)."""
    import highspy

    from eosp.kinds.lagrange import packing_highs, run_from

    keys = list(st.columns)
    if not keys:
        return False
    n, m = len(st.scenario.tasks), len(keys)
    cost, starts, index = np.zeros(m), np.zeros(m, np.int32), []
    for i, (k, tasks) in enumerate(keys):
        t = np.frombuffer(tasks, dtype=np.int32)
        cost[i], starts[i] = float(st.prio[t].sum()), len(index)
        index.extend(t.tolist())
        index.append(n + k)
    h = packing_highs(n + len(st.passes))
    h.addCols(m, cost, np.zeros(m), np.ones(m), len(index), starts, np.asarray(index, np.int32), np.ones(len(index)))
    h.changeColsIntegrality(m, np.arange(m, dtype=np.int32), np.full(m, highspy.HighsVarType.kInteger))
    if limit is not None:
        h.setOptionValue("time_limit", max(0.01, float(limit)))
    if nodes is not None:
        h.setOptionValue("mip_max_nodes", int(nodes))
    where = {key: i for i, key in enumerate(keys)}
    x0 = np.zeros(m)
    for k, path in enumerate(st.paths):
        if len(path):
            x0[where[(k, np.sort(st.path_tasks(k, path)).tobytes())]] = 1.0
    chosen = run_from(h, x0)
    if not chosen:
        return False
    before = (st.value, list(st.paths), st.served.copy())
    for k in range(len(st.passes)):
        st.commit(k, np.zeros(0, np.int64))
    for i in chosen:
        st.commit(keys[i][0], st.columns[keys[i]])
    for k in range(len(st.passes)):  # the every-pair rule with the neighbouring passes the packing does not see
        if len(st.paths[k]) and not _neighbour_mask(st, k)[st.paths[k]].all():
            st.commit(k, np.zeros(0, np.int64))
    polish(st)
    if st.value > before[0] + 1e-9:
        return True
    st.paths, st.served = before[1], before[2]
    return False


def _pack_limit(cfg: EosBenchConfig, budget: Budget) -> float | None:
    """Seconds a packing may take: none with a fixed number of rounds (a node limit instead), else what is left
    of `budget`, at most :data:`PACK_RESERVE_S`."""
    if cfg.rounds is not None and not budget.limited:
        return None
    return min(PACK_RESERVE_S, max(0.01, budget.left()))


@dataclass
class Search:
    """Where a solve stands, kept outside its loops so that Ctrl-C finds it: the best schedule (value, paths,
    served; None before the construction ends), the best bound and its kind, rounds done."""

    bound: float
    kind: str = "conflict-free"
    value: float = -math.inf
    paths: list | None = None
    served: np.ndarray | None = None
    rounds: int = 0
    interrupted: bool = False

    def keep(self, st: State) -> None:
        self.value, self.paths, self.served = st.value, list(st.paths), st.served.copy()


def _rounds(st: State, cfg: EosBenchConfig, budget: Budget, run: Search) -> None:
    """Price rounds, each followed by its moves and every few rounds a packing, until the budget, the rounds or
    the bound; the best schedule and bound kept in `run` as they are found."""
    prices = Prices.zero(len(st.scenario.tasks))
    lp = PriceLP(st.prio, len(st.paths)) if cfg.price_step == "lp" else None
    rng = np.random.default_rng(cfg.seed)
    best_dual = math.inf
    while cfg.rounds is None or run.rounds < cfg.rounds:
        if budget.expired() and run.rounds > 0:
            break
        lam = prices.lam
        columns: list | None = [] if lp is not None else None
        dual, taken, proven = bound_round(st, lam, columns, budget)
        run.rounds += 1
        prices.stalled(dual < best_dual - 1e-9)  # the step shrinks when the dual stalls, whatever bound stands
        best_dual = min(best_dual, dual)
        if proven and dual < run.bound - 1e-9:
            run.bound, run.kind = dual, "lagrangian"
        if run.bound <= run.value + 1e-9:  # proven optimal: nothing left to search
            break
        if lp is None:
            prices.step_towards(taken, dual if math.isfinite(dual) else run.bound, run.value)
        else:
            for k, tasks in columns:
                lp.add(k, tasks)
            for k, tasks in list(st.columns)[lp.committed:]:  # the paths the moves committed: valid, so relaxed too
                lp.add(k, np.frombuffer(tasks, dtype=np.int32))
            lp.committed = len(st.columns)
            prices.lam = lp.next_prices(lam, dual if proven else math.inf, budget)
        if budget.expired():
            break
        for _ in range(cfg.moves_per_round):
            if budget.expired():
                break
            _lns(st, rng, prices.lam, budget)
            polish(st)
            if st.value > run.value + 1e-9:
                run.keep(st)
        if run.rounds % PACK_EVERY == 0 and not budget.expired():
            st.paths, st.served = list(run.paths), run.served.copy()
            if pack(st, _pack_limit(cfg, budget), PACK_NODES if cfg.rounds is not None else None):
                run.keep(st)


def solve(scenario: Scenario, cfg: EosBenchConfig) -> Result:
    """Solve `scenario` (see the module docstring)."""
    t0 = time.perf_counter()
    end = Budget.of(cfg.time_limit, start=t0)
    budget = end.less(min(PACK_RESERVE_S, 0.05 * cfg.time_limit)) if end.limited else end  # the last packing's time
    rules = Rules(cfg.transition, cfg.agility)
    if len(scenario.stations):
        raise InputError(scenario.path, "unsupported by the eosbench solver: downlinks (the scenario has ground "
                                        "stations); `eosp validate` checks such schedules")
    if cfg.transition == "code" and not scenario.satellites.agile.all():
        raise InputError(scenario.path, "unsupported: the code reading has no transition rule for non-agile "
                                        "satellites (their checker raises AttributeError); use --transition "
                                        "documented")
    passes = build_passes(scenario)
    st = State(scenario, rules, passes, cfg, t0=t0)
    timings = {"passes": time.perf_counter() - t0}
    order = sorted(range(len(passes)), key=lambda k: (st.span[k, 0], k))
    run = Search(bound=conflict_free(st))
    try:  # Ctrl-C: the best schedule so far is the answer (checked and written by eosp solve)
        for k in order:  # construction
            if budget.expired():
                break
            improve(st, k, budget)
        descend(st, order, budget)
        polish(st)
        timings["construction"] = time.perf_counter() - t0 - timings["passes"]
        run.keep(st)
        _rounds(st, cfg, budget, run)
    except KeyboardInterrupt:
        run.interrupted = True
    if run.paths is not None:  # else Ctrl-C came during the construction: what it built (the checker has its say)
        st.paths, st.served = run.paths, run.served
    if not run.interrupted:  # each step may take seconds: after Ctrl-C the schedule is written at once
        polish(st)
        pack(st, _pack_limit(cfg, end), PACK_NODES if cfg.rounds is not None else None)
    bound, kind, rounds = run.bound, run.kind, run.rounds
    sched = to_schedule(st)
    rep = check(scenario, sched, rules)
    while not rep.valid:  # a safety net: the construction keeps every rule, the checker has the last word
        keep = [i for i in range(len(sched)) if i != rep.first]
        sched = Schedule.build(scenario, [(_row(scenario, sched, i)) for i in keep])
        rep = check(scenario, sched, rules)
    value = rep.metrics["TP"]
    if bound < value - 1e-6:  # never report a bound below a schedule found
        raise AssertionError(f"bound {bound} below the schedule's profit {value}")
    timings["solve"] = time.perf_counter() - t0
    status = "interrupted" if run.interrupted else "optimal" if bound <= value + 1e-9 else \
        "budget" if cfg.rounds is not None and rounds >= cfg.rounds else "time_limit"
    info = {"rounds": rounds, "passes": len(passes), "pass_solves": st.pass_solves, "metrics": rep.metrics,
            "transition": cfg.transition, "agility": cfg.agility}
    # the verdict under the reading solved for (the command line's default check is the documented reading)
    return Result(sched, value, bound, kind, status, timings, info, verdict(scenario, sched, rules))


def _row(scenario: Scenario, sched: Schedule, i: int) -> tuple[int, int]:
    """(window row, step) of assignment i of a schedule built by :meth:`Schedule.build`."""
    w = scenario.windows
    rows = np.flatnonzero((w.task == sched.task[i]) & (w.satellite == sched.satellite[i]) &
                          (w.start_us <= sched.start_us[i]) & (sched.end_us[i] <= w.end_us))
    r = int(rows[0])
    return r, int(round((sched.start_us[i] - w.start_us[r]) / (w.step_s[r] * 1_000_000)))
