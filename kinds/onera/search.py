"""ONERA constellation solver: greedy insertion, then large-neighbourhood search, with a proven bound.

The transition model is time-independent, so a satellite's plan is a sequence of activities and the
classic insertion test of routing with time windows is exact for that order: each position keeps its
earliest start (forward) and latest start (backward) given its neighbours, and an activity fits between
two neighbours when its own earliest start is at most its latest start there.  Downloads are in every
sequence from the start (they are mandatory) and float inside their windows like observations do.

* ``greedy``: requests in decreasing order of value per second of satellite time (fewest opportunities
  first on ties), each at the best observation(s) that fit, at the position adding the least transition
  time: one-shot and video one observation, stereo both images of the best pair that fits (on one
  satellite), periodic one observation in its earliest slot that fits, then (after every request had
  its turn) the best fitting observation of each other slot.
* ``lns``: from the greedy plan, repeatedly free a time span of one satellite and re-insert the freed
  requests and the unserved ones that have opportunities there, in a noisy greedy order; a move that
  lowers the value is undone.  Stops at the time limit.

Times are integer milliseconds: earliest starts are rounded up and latest starts down, so every plan is
valid for :mod:`eosp.onera.check`.  The bound comes from :mod:`eosp.kinds.onera.bound`.
"""

from __future__ import annotations

import math
import random
import time
from bisect import bisect_left, bisect_right
from dataclasses import dataclass, field

import numpy as np

from eosp.budget import Budget
from eosp.config import WEEK_S, choice, ranged
from eosp.solvers.base import UtilityConfig
from eosp.errors import InputError
from eosp.interrupt import HeldInterrupt
from eosp.onera.check import best_values, periodic_value
from eosp.onera.model import PERIODIC, STEREO, TAU_MAX_S, OneraFleet, OneraSchedule
from eosp.problem import Result


MS = 1000  # plan times are integer milliseconds
MAX_EXTRA = 60  # requests not freed by a move that may take the freed time (a random sample beyond)
DENSITY_TAU_S = 3.0  # a typical transition between two targets of one pass (s), for the greedy order


@dataclass
class BoundConfig(UtilityConfig):
    """Options of the ONERA solvers: the bound they prove."""

    bound: str = choice("lp", "lp", "conflict-free", "none")
    """Upper bound: lp (the time-capacity relaxation, solved by HiGHS, certified from its duals),
    conflict-free (each request at its best), none."""
    bound_time_limit: float = ranged(30.0, 0, WEEK_S)
    """Seconds of cutting-plane rounds of the lp bound: under a time limit, at most this and half of the limit are
    kept from the search for it (the bound gets the time left); without one, this many after the plan (the last
    finished solve's certified bound is kept; none finished: the conflict-free bound)."""


@dataclass
class GreedyConfig(BoundConfig):
    """Options of the ONERA greedy (``eosp solve ONERA_DIR --solver greedy``): one pass, then the bound."""

    NAME = "greedy"
    ONE_SHOT = True


@dataclass
class OneraConfig(BoundConfig):
    """Options of the ONERA search (``eosp solve ONERA_DIR --solver onera``): the greedy plan, then
    large-neighbourhood moves until the time limit or the move budget, then the bound."""

    time_limit: float | None = ranged(30.0, 0, WEEK_S, zero_unsets=True)
    seed: int = ranged(0, 0)
    """Seed of the large-neighbourhood moves."""
    moves: int | None = ranged(None, 0)
    """Large-neighbourhood moves (a deterministic budget: the same plan for a seed on any machine, with
    --time-limit 0 or one long enough); unset: as many as the time limit allows."""
    span_s: float = ranged(1200.0, 1)
    """Length of the time span of one satellite freed by one move."""

    NAME = "onera"
    BUDGET = "moves"


@dataclass
class Solution:
    schedule: OneraSchedule
    value: float
    bound: float | None
    gap: float | None
    info: dict = field(default_factory=dict)


class Plan:
    """Per-satellite sequences with earliest/latest starts, and the requests' assignments."""

    def __init__(self, f: OneraFleet):
        o, d = f.observations, f.downloads
        self.f = f
        self.n_obs = n_obs = len(o)
        # times in integer milliseconds (windows are whole seconds; rounding a start up to a whole second would
        # cost up to a second per transition, much of a pass of 1-2 s observations)
        dur = np.round(np.concatenate([o.duration.astype(np.float64), d.duration]) * MS).astype(np.int64)
        ws = np.concatenate([o.start, d.start]).astype(np.int64) * MS
        ls = np.concatenate([o.end, d.end]).astype(np.int64) * MS - dur
        self.WS, self.LS, self.DUR = ws.tolist(), ls.tolist(), dur.tolist()
        self.LAT = np.concatenate([o.lat, d.lat]).tolist()
        self.LON = np.concatenate([o.lon, d.lon]).tolist()
        self.REQ = np.concatenate([o.request, np.full(len(d), -1)]).tolist()
        self.SAT = np.concatenate([o.satellite, d.satellite]).tolist()
        self.VAL = o.value.tolist()
        self.SLOT = o.slot.tolist()
        self.KIND = f.requests.kind.tolist()
        n_sat = len(f.satellites)
        self.seq: list[list[int]] = [[] for _ in range(n_sat)]
        self.est: list[list[int]] = [[] for _ in range(n_sat)]
        self.lst: list[list[int]] = [[] for _ in range(n_sat)]
        self.assigned: list[list[int]] = [[] for _ in range(len(f.requests))]
        self.value = [0.0] * len(f.requests)
        self.in_plan = bytearray(n_obs + len(d))
        self.journal: list | None = None
        self._slots = {}
        for g in sorted(range(len(d)), key=lambda j: d.start[j]):
            gg = n_obs + g
            s = self.SAT[gg]
            found = self.find(s, gg)
            if found is None:
                raise ValueError(f"download {d.id[g]}: no room in satellite {f.satellites[s]}'s plan (overlapping "
                                 "mandatory downloads): the instance has no valid plan")
            self.insert(s, gg, found)

    # ---------------------------------------------------------------- timing
    def tau(self, a: int, b: int) -> float:
        """The transition from activity `a` to `b`, in milliseconds."""
        ra = self.REQ[a]
        if ra >= 0 and ra == self.REQ[b]:
            return 0.0
        t = math.hypot(self.LAT[a] - self.LAT[b], self.LON[a] - self.LON[b])
        return MS * (t if t < TAU_MAX_S else TAU_MAX_S)

    def find(self, s: int, g: int) -> int | None:
        """The position of satellite `s`'s sequence where activity `g` fits at the least added transition time
        (cheapest insertion: a pass zig-zagging between targets wastes its time in slews), or None."""
        seq, est, lst = self.seq[s], self.est[s], self.lst[s]
        ws, ls, d = self.WS[g], self.LS[g], self.DUR[g]
        p = bisect_left(lst, ws + d)  # a next activity must be able to start after g ends
        hi = bisect_right(est, ls)  # a previous activity must start before g's latest start
        p = min(p, hi)
        n = len(seq)
        best, best_cost = None, math.inf
        while p <= hi and p <= n:
            if p > 0:
                q = seq[p - 1]
                e = est[p - 1] + self.DUR[q] + self.tau(q, g)
                e = max(ws, math.ceil(e - 1e-9))
            else:
                e = ws
            if p < n:
                q = seq[p]
                l_ = min(ls, math.floor(lst[p] - d - self.tau(g, q) + 1e-9))
            else:
                l_ = ls
            if e <= l_:
                if p == 0 or p == n:
                    cost = 0.0 if n == 0 else self.tau(seq[p - 1], g) if p else self.tau(g, seq[0])
                else:
                    a, b = seq[p - 1], seq[p]
                    cost = self.tau(a, g) + self.tau(g, b) - self.tau(a, b)
                if cost < best_cost - 1e-9:
                    best, best_cost = p, cost
            p += 1
        return best

    def insert(self, s: int, g: int, p: int) -> None:
        seq, est, lst = self.seq[s], self.est[s], self.lst[s]
        seq.insert(p, g)
        est.insert(p, self.WS[g])
        lst.insert(p, self.LS[g])
        self._forward(s, p)
        self._backward(s, p)
        self.in_plan[g] = 1
        if self.journal is not None:
            self.journal.append((0, s, g, p))

    def remove(self, s: int, g: int) -> None:
        seq = self.seq[s]
        p = seq.index(g)
        del seq[p], self.est[s][p], self.lst[s][p]
        if p < len(seq):
            self._forward(s, p, removal=True)
        if p > 0:
            self._backward(s, p - 1, removal=True)
        self.in_plan[g] = 0
        if self.journal is not None:
            self.journal.append((1, s, g, p))

    def _forward(self, s: int, p: int, removal: bool = False) -> None:
        seq, est = self.seq[s], self.est[s]
        n = len(seq)
        q = p
        while q < n:
            g = seq[q]
            if q > 0:
                a = seq[q - 1]
                e = max(self.WS[g], math.ceil(est[q - 1] + self.DUR[a] + self.tau(a, g) - 1e-9))
            else:
                e = self.WS[g]
            if e == est[q] and q != p:
                break
            est[q] = e
            q += 1

    def _backward(self, s: int, p: int, removal: bool = False) -> None:
        seq, lst = self.seq[s], self.lst[s]
        n = len(seq)
        q = p
        while q >= 0:
            g = seq[q]
            if q < n - 1:
                b = seq[q + 1]
                l_ = min(self.LS[g], math.floor(lst[q + 1] - self.DUR[g] - self.tau(g, b) + 1e-9))
            else:
                l_ = self.LS[g]
            if l_ == lst[q] and q != p:
                break
            lst[q] = l_
            q -= 1

    # ---------------------------------------------------------------- requests
    def request_value(self, r: int) -> float:
        rows = self.assigned[r]
        if not rows:
            return 0.0
        if self.KIND[r] != PERIODIC:
            return float(sum(self.VAL[g] for g in rows))
        slots = self._slot_list(r)
        served = np.zeros(len(slots), bool)
        classes = np.zeros(len(slots))
        for g in rows:
            k = slots.index(self.SLOT[g])
            served[k] = True
            classes[k] = self.VAL[g]
        return periodic_value(classes, served)

    def _slot_list(self, r: int) -> list[int]:
        sl = self._slots.get(r)
        if sl is None:
            sl = self._slots[r] = self.f.slots(r).tolist()
        return sl

    def set_assigned(self, r: int, rows: list[int]) -> None:
        if self.journal is not None:
            self.journal.append((2, r, list(self.assigned[r]), self.value[r]))
        self.assigned[r] = rows
        self.value[r] = self.request_value(r)

    def try_place(self, g: int) -> bool:
        s = self.SAT[g]
        p = self.find(s, g)
        if p is None:
            return False
        self.insert(s, g, p)
        return True

    def undo(self, mark: int) -> None:
        """Undo the journal's entries after `mark`, newest first."""
        j = self.journal
        self.journal = None
        while len(j) > mark:
            op = j.pop()
            if op[0] == 0:
                self.remove(op[1], op[2])
            elif op[0] == 1:
                s, g, p = op[1], op[2], op[3]
                seq = self.seq[s]
                seq.insert(p, g)
                self.est[s].insert(p, self.WS[g])
                self.lst[s].insert(p, self.LS[g])
                self._forward(s, p)
                self._backward(s, p)
                self.in_plan[g] = 1
            else:
                self.assigned[op[1]], self.value[op[1]] = op[2], op[3]
        self.journal = j

    def schedule(self) -> OneraSchedule:
        f = self.f
        ids = np.concatenate([f.observations.id, f.downloads.id])
        sat, act, start = [], [], []
        for s in range(len(self.seq)):
            sat += [int(f.satellites[s])] * len(self.seq[s])
            act += self.seq[s]
            start += self.est[s]
        return OneraSchedule(np.asarray(sat, np.int64), ids[np.asarray(act, np.int64)] if act else np.zeros(0, np.int64),
                             np.asarray(start, np.int64) / MS)


class Search:
    """Greedy and large-neighbourhood search over a :class:`Plan`."""

    def __init__(self, f: OneraFleet, seed: int = 0):
        self.f = f
        self.plan = Plan(f)
        self.moves = 0  # moves tried so far (also when Ctrl-C stops the search)
        self.held: HeldInterrupt | None = None  # set by solve(): Ctrl-C is answered between two whole edits
        o, r = f.observations, f.requests
        self.rng = random.Random(seed)
        first = r.first.tolist()
        val = o.value.tolist()
        self.best = best_values(f)
        # candidates per request: one-shot/video a list of rows; stereo a list of (g1, g2, value) pairs; periodic
        # a list per slot; each sorted by value, best first (earliest window first on ties)
        self.cands: list = []
        starts = o.start.tolist()
        slot = o.slot.tolist()
        for k in range(len(r)):
            rows = sorted(range(first[k], first[k + 1]), key=lambda g: (-val[g], starts[g]))
            kind = int(r.kind[k])
            if kind == STEREO:
                by: dict[int, list[int]] = {}
                for g in sorted(range(first[k], first[k + 1]), key=lambda g: starts[g]):
                    by.setdefault(slot[g], []).append(g)
                pairs = [(a, b, val[a] + val[b]) for a, b in by.values()]
                self.cands.append(sorted(pairs, key=lambda t: (-t[2], starts[t[0]])))
            elif kind == PERIODIC:
                by = {}
                for g in rows:
                    by.setdefault(slot[g], []).append(g)
                self.cands.append([by[sl] for sl in sorted(by)])
            else:
                self.cands.append(rows)
        self.pair_value = [0.0] * len(o)  # stereo: the value of the pair an observation belongs to
        for k in np.flatnonzero(r.kind == STEREO).tolist():
            for a, b, v in self.cands[k]:
                self.pair_value[a] = self.pair_value[b] = v
        n_opp = np.diff(r.first)
        # value per second of satellite time (its mean duration plus a typical transition): short observations
        # of valuable requests first, since a satellite's time is what requests compete for
        mean_d = np.bincount(o.request, weights=o.duration.astype(np.float64), minlength=len(r)) / np.maximum(n_opp, 1)
        self.density = (self.best / (mean_d + DENSITY_TAU_S)).tolist()
        self.order = sorted(range(len(r)), key=lambda k: (-self.density[k], n_opp[k], k))
        # opportunities of each satellite by window start, to find the requests a freed span may serve
        self.sat_rows = []
        self.sat_starts = []
        for s in range(len(f.satellites)):
            rows = np.flatnonzero(o.satellite == s)
            rows = rows[np.argsort(o.start[rows], kind="stable")]
            self.sat_rows.append(rows)
            self.sat_starts.append(o.start[rows])

    @property
    def objective(self) -> float:
        return float(sum(self.plan.value))

    def place(self, k: int, full: bool = True) -> bool:
        """Insert request `k` at its best fitting observations.  A periodic request first gets one observation
        in its earliest slot that fits (``full`` False: with the authors' max gap, a trailing run of unserved
        slots costs nothing, so that one observation earns the most of the 0.5 x slots), then (``full``) its
        other unserved slots."""
        pl = self.plan
        kind = pl.KIND[k]
        if kind == PERIODIC and not full:
            if pl.assigned[k]:
                return False
            for slot_rows in self.cands[k]:
                for g in slot_rows:
                    if pl.try_place(g):
                        pl.set_assigned(k, [g])
                        return True
            return False
        if kind == PERIODIC:
            done = {pl.SLOT[g] for g in pl.assigned[k]}
            added = []
            for slot_rows in self.cands[k]:
                if pl.SLOT[slot_rows[0]] in done:
                    continue
                for g in slot_rows:
                    if pl.try_place(g):
                        added.append(g)
                        break
            if added:
                pl.set_assigned(k, pl.assigned[k] + added)
            return bool(added)
        if pl.assigned[k]:
            return False
        if kind == STEREO:
            for a, b, _ in self.cands[k]:
                if not pl.try_place(a):
                    continue
                if pl.try_place(b):
                    pl.set_assigned(k, [a, b])
                    return True
                pl.remove(pl.SAT[a], a)
            return False
        for g in self.cands[k]:
            if pl.try_place(g):
                pl.set_assigned(k, [g])
                return True
        return False

    def greedy(self, order: list[int] | None = None) -> None:
        """Every request of `order` (default: by value) once, then the periodic ones' other slots."""
        order = self.order if order is None else order
        held = self.held
        for k in order:
            if held is not None and held.seen:  # Ctrl-C, answered between two whole placements
                raise KeyboardInterrupt
            self.place(k, full=False)
        for k in order:
            if held is not None and held.seen:
                raise KeyboardInterrupt
            if self.plan.KIND[k] == PERIODIC:
                self.place(k)

    def lns(self, stop: Stop, span_s: float, trace: list, t0: float) -> int:
        """Destroy-and-repair moves until `stop` (its time budget, moves or the value of an upper bound); the number
        of moves."""
        pl = self.plan
        pl.journal = []
        try:
            return self._moves(stop, span_s, trace, t0)
        except KeyboardInterrupt:  # Ctrl-C: the move in flight undone, the plan as it was before it
            if pl.journal:
                pl.undo(0)
            raise
        finally:
            pl.journal = None

    def _moves(self, stop: Stop, span_s: float, trace: list, t0: float) -> int:
        pl, rng, f = self.plan, self.rng, self.f
        n_sat = len(f.satellites)
        obj = self.objective
        moves = 0
        held = self.held
        while not stop.reached(moves, obj):
            if held is not None and held.seen:  # Ctrl-C between two moves: the plan is whole here
                raise KeyboardInterrupt
            moves += 1
            self.moves += 1
            s = rng.randrange(n_sat)
            rows = self.sat_rows[s]
            if not len(rows):
                continue
            centre = int(self.sat_starts[s][rng.randrange(len(rows))])
            lo = centre - span_s * rng.random()
            hi = lo + span_s
            mark = len(pl.journal)
            seq, est = pl.seq[s], pl.est[s]
            a, b = bisect_left(est, lo * MS), bisect_right(est, hi * MS)
            touched = {pl.REQ[g] for g in seq[a:b] if g < pl.n_obs}
            i0, i1 = np.searchsorted(self.sat_starts[s], [lo - 300, hi])
            span_rows = rows[i0:i1].tolist()
            for g in span_rows:  # requests served elsewhere that the span could serve better move too
                k = pl.REQ[g]
                if pl.assigned[k] and pl.KIND[k] != PERIODIC and k not in touched:
                    better = pl.VAL[g] > pl.value[k] + 1e-12 if pl.KIND[k] != STEREO else \
                        self.pair_value[g] > pl.value[k] + 1e-12
                    if better:
                        touched.add(k)
            for k in touched:  # free the whole request (a stereo pair goes as a whole), a periodic request
                keep = []      # only its observations in the span
                for g in pl.assigned[k]:
                    if pl.KIND[k] != PERIODIC or (pl.SAT[g] == s and lo * MS <= pl.est[s][pl.seq[s].index(g)] <= hi * MS):
                        pl.remove(pl.SAT[g], g)
                    else:
                        keep.append(g)
                pl.set_assigned(k, keep)
            extra = set()
            for g in span_rows:
                k = pl.REQ[g]
                if k not in touched and (not pl.assigned[k] or pl.KIND[k] == PERIODIC):
                    extra.add(k)
            if len(extra) > MAX_EXTRA:  # a congested span: a sample, so that a move stays short
                extra = set(rng.sample(sorted(extra), MAX_EXTRA))
            cand = touched | extra
            order = sorted(cand, key=lambda k: -self.density[k] * (0.7 + 0.6 * rng.random()))
            self.greedy(order)
            new = self.objective
            if new >= obj - 1e-9:
                if new > obj + 1e-9:
                    trace.append((time.perf_counter() - t0, new))
                obj = new
                pl.journal.clear()
            else:
                pl.undo(mark)
                pl.journal.clear()
        return moves


@dataclass(frozen=True)
class Stop:
    """When the search stops: when `budget` runs out, after `moves` moves (None: no limit on them), or once the
    plan's value reaches `target` (an upper bound)."""

    budget: Budget
    moves: int | None
    target: float

    def reached(self, done: int, value: float) -> bool:
        return ((self.moves is not None and done >= self.moves) or value >= self.target - 1e-9
                or self.budget.expired())


def solve(f: OneraFleet, cfg: BoundConfig | None = None) -> Solution:
    """The greedy plan, then (an :class:`OneraConfig`) large-neighbourhood search until the time limit or the move
    budget, then the bound, all within the time limit (counted from the call: the search stops early by the lp
    bound's share, ``bound_time_limit``).  Ctrl-C keeps the plan as it was before the move in flight (status
    "interrupted", the conflict-free bound)."""
    cfg = cfg or OneraConfig()
    cfg.validate()  # fields set one by one (eosp.config.apply_overrides) are checked together here
    t0 = time.perf_counter()
    search = Search(f, seed=cfg.seed)
    limit = cfg.time_limit  # None for the greedy (one pass) and for a search bounded by its moves alone
    reserve = min(cfg.bound_time_limit, limit / 2) if cfg.bound == "lp" and limit is not None else 0.0
    trace: list = []
    status = "done"
    try:
        with HeldInterrupt() as search.held:  # Ctrl-C is answered between edits of the plan, never inside one
            search.greedy()
            trace.append((time.perf_counter() - t0, search.objective))
            if isinstance(cfg, OneraConfig):
                stop = Stop(Budget.of(limit, start=t0).less(reserve), cfg.moves, float(search.best.sum()))
                moves = search.lns(stop, cfg.span_s, trace, t0)
                status = "optimal" if search.objective >= stop.target - 1e-9 else "budget" if moves == cfg.moves \
                    else "time_limit"
    except KeyboardInterrupt:
        status = "interrupted"
    finally:
        search.held = None
    if not trace:
        trace.append((time.perf_counter() - t0, search.objective))
    greedy_value = trace[0][1]
    value = search.objective
    t_search = time.perf_counter() - t0
    schedule = search.plan.schedule()
    free = float(search.best.sum())  # the conflict-free bound
    bound, source = None, cfg.bound
    if cfg.bound == "conflict-free" or (cfg.bound == "lp" and (status == "interrupted" or value >= free - 1e-9)):
        bound, source = free, "conflict-free"  # the plan meets it, or Ctrl-C: no LP after it
    elif cfg.bound == "lp":
        from eosp.kinds.onera.bound import lp_bound

        lp_info: dict = {}
        budget = cfg.bound_time_limit if limit is None else \
            min(cfg.bound_time_limit, max(0.0, t0 + limit - time.perf_counter()))
        try:
            bound = min(lp_bound(f, time_limit=budget, info=lp_info), free)
            source = f"lp ({lp_info.get('rounds', 0)} rounds, {lp_info.get('cuts', 0)} cuts)"
        except KeyboardInterrupt:
            status, bound, source = "interrupted", free, "conflict-free"
    gap = None if bound is None else (0.0 if bound <= 0 else max(0.0, (bound - value) / bound))
    t99 = next((t for t, v in trace if v >= 0.99 * value - 1e-12), trace[-1][0])
    return Solution(schedule, value, bound, gap,
                    {"greedy_value": greedy_value, "moves": search.moves, "seconds_search": t_search,
                     "seconds": time.perf_counter() - t0, "time_to_99": t99, "bound_source": source,
                     "trace": trace, "status": status})


def solve_greedy(f: OneraFleet, cfg: GreedyConfig) -> Result:
    """The contract's entry of ``--solver greedy`` (:mod:`eosp.kinds.onera.kind`)."""
    return result_of(f, cfg)


def solve_onera(f: OneraFleet, cfg: OneraConfig) -> Result:
    """The contract's entry of ``--solver onera`` (:mod:`eosp.kinds.onera.kind`)."""
    return result_of(f, cfg)


def result_of(f: OneraFleet, cfg: BoundConfig) -> Result:
    try:
        sol = solve(f, cfg)
    except ValueError as exc:  # an instance whose mandatory downloads do not fit
        raise InputError(f.name or "the ONERA fleet", str(exc)) from None
    info = dict(sol.info)
    return Result(sol.schedule, sol.value, sol.bound, None if sol.bound is None else info["bound_source"],
                  info.pop("status"), {"solve": info["seconds"], "search": info["seconds_search"]}, info)
