"""An EOS-Bench satellite's orbit as a single-pass problem: its candidate observations as a discrete graph.

Their per-orbit power and storage sums make (satellite, orbit number) the natural pass: every resource constraint
lives inside one pass.  A pass's nodes are the candidate observations of their generator: each observation
window labelled with that orbit, each start on the window's grid from which the task's duration fits (a non-agile
satellite: the window's centre), in the project's canonical order (:mod:`eosp.graphs.discrete`): the source,
then each acquisition's nodes by time.  An acquisition is a (task, sensor) of the pass, so a task seen in two
windows of one orbit is one acquisition and the label search never takes it twice.

From a node, one arc goes to the EARLIEST node of each other acquisition that can follow it: one starting at least
the transition time after the node ends (:mod:`eosp.eosbench.transition`, in microseconds, as their checker adds
it).  Under the code reading (11.66 s always) transitions are FIFO, so a path of earliest arcs loses nothing and
the exact label search is the pass optimum; under the documented reading (time grows with the attitude change) it
is a heuristic, exact only when the attitude change stays in one piece.  A mask of allowed nodes (observations of
the same satellite in neighbouring orbits, tasks served elsewhere) rebuilds the arcs at each solve: a few
milliseconds beside the label search.

What the graph leaves out, and who takes care of it: pairs that are not consecutive on a path (their checker
tests every pair; under the documented reading A -> C may need more than A -> B -> C leaves), and the cap on
observations per orbit (power); the solver (:mod:`eosp.kinds.eosbench.solve`) checks and repairs both.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from eosp.eosbench.model import US, Scenario
from eosp.eosbench.transition import BREAKS, C_SMALL, OFFSETS, PROFILES, SMALL_DG, Rules
from eosp.graphs.build import first_at_or_after
from eosp.graphs.discrete import DiscreteGraph
from eosp.planning.labels import label_search

NO_CAP = 1 << 30


@dataclass(frozen=True, eq=False)
class Pass:
    """One (satellite, orbit): nodes 1..N-1 in canonical order (node 0 the source)."""

    satellite: int
    orbit: int
    tasks: np.ndarray  # int32 [k]: the task of each acquisition
    power: np.ndarray  # float64 [k]: power cost of an observation of it
    data: np.ndarray  # float64 [k]: data volume of an observation of it
    acq_ptr: np.ndarray  # int64 [k + 1]
    node_acq: np.ndarray  # int32 [N]
    start_us: np.ndarray  # int64 [N]
    end_us: np.ndarray  # int64 [N]
    window: np.ndarray  # int64 [N]: window row
    step: np.ndarray  # int64 [N]: k, the start's step in its window
    first: np.ndarray  # float64 [N, 3]: attitude at the start
    last: np.ndarray  # float64 [N, 3]: attitude at the end (the last sample of its slice)
    cap: int  # observations its power and storage allow (NO_CAP: no limit)

    @property
    def n_nodes(self) -> int:
        return len(self.node_acq)


def _nodes_of_window(scenario: Scenario, r: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(steps k, first attitudes, last attitudes, ok) of the candidate starts in window r."""
    w, sats = scenario.windows, scenario.satellites
    dur = float(scenario.tasks.duration_s[w.task[r]])
    step = float(w.step_s[r])
    total = (w.end_us[r] - w.start_us[r]) / US
    if dur <= 0 or dur > total:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, bool)
    max_off = total - dur
    max_k = int(np.floor((max_off + 1e-9) / step))
    if not sats.agile[w.satellite[r]]:
        ks = np.array([max(0, min(max_k, int(round((max_off / 2.0) / step))))], dtype=np.int64)
        fx = np.repeat(w.fixed[r][None, :], 1, axis=0)
        return ks, fx, fx, np.ones(1, bool)
    lo, hi = int(w.att_ptr[r]), int(w.att_ptr[r + 1])
    # a start needs its attitude sample: past the window's samples there is none to point with, so the candidates
    # are as many as the samples read at most, whatever the window's end or time step says (a window stretched
    # to the year 9999 would otherwise ask for terabytes)
    max_k = min(max_k, hi - lo - 1)
    ks = np.arange(max_k + 1, dtype=np.int64)
    n = max(1, int(np.ceil(dur / step - 1e-9)))
    a = lo + ks
    b = np.minimum(a + n, hi) - 1
    ok = a < hi
    att = np.stack([w.pitch[lo:hi], w.yaw[lo:hi], w.roll[lo:hi]], axis=1)  # this window's samples only
    first = np.full((len(ks), 3), np.nan)
    last = np.full((len(ks), 3), np.nan)
    first[ok] = att[a[ok] - lo]
    last[ok] = att[b[ok] - lo]
    return ks, first, last, np.ones(len(ks), bool)


def build_passes(scenario: Scenario) -> list[Pass]:
    """Every (satellite, orbit) with a window, in (satellite, orbit) order."""
    w, sats = scenario.windows, scenario.satellites
    out = []
    keys = np.stack([w.satellite.astype(np.int64), w.orbit], axis=1)
    for sat, orbit in sorted({(int(a), int(b)) for a, b in keys.tolist()}):
        rows = np.flatnonzero((w.satellite == sat) & (w.orbit == orbit))
        acq_key = [(int(w.task[r]), int(w.sensor[r])) for r in rows]
        uniq = sorted(set(acq_key))
        local = {key: a for a, key in enumerate(uniq)}
        parts = []
        for r, key in zip(rows.tolist(), acq_key):
            ks, first, last, _ = _nodes_of_window(scenario, r)
            if len(ks) == 0:
                continue
            start = w.start_us[r] + np.rint(ks * w.step_s[r] * US).astype(np.int64)
            dur = int(np.rint(scenario.tasks.duration_s[w.task[r]] * US))
            parts.append((np.full(len(ks), local[key], np.int32), start, start + dur, np.full(len(ks), r), ks,
                          first, last))
        if not parts:
            continue
        acq, start, end, win, ks, first, last = (np.concatenate([p[i] for p in parts]) for i in range(7))
        order = np.lexsort((start, acq))
        acq, start, end, win, ks, first, last = (x[order] for x in (acq, start, end, win, ks, first, last))
        k = len(uniq)
        present = np.bincount(acq, minlength=k) > 0
        if not present.all():  # acquisitions whose windows all are too short: drop them
            remap = np.cumsum(present) - 1
            acq = remap[acq].astype(np.int32)
            uniq = [u for u, p in zip(uniq, present) if p]
            k = len(uniq)
        tasks = np.asarray([t for t, _ in uniq], dtype=np.int32)
        sensor = np.asarray([s for _, s in uniq], dtype=np.int64)
        rate = np.where(sensor >= 0, sats.sensor_rate_mbps[np.maximum(sensor, 0)], 0.0)
        power = np.where(sensor >= 0, sats.sensor_power_w[np.maximum(sensor, 0)], 0.0)
        data = rate * scenario.tasks.duration_s[tasks] / (8.0 * 1024.0)
        acq_ptr = np.r_[0, np.cumsum(np.bincount(acq, minlength=k))].astype(np.int64) + 1
        out.append(Pass(sat, orbit, tasks, power, data, acq_ptr, np.r_[-1, acq].astype(np.int32),
                        np.r_[0, start].astype(np.int64), np.r_[0, end].astype(np.int64), np.r_[-1, win],
                        np.r_[-1, ks], np.vstack([np.full((1, 3), np.nan), first]),
                        np.vstack([np.full((1, 3), np.nan), last]),
                        _cap(power, data, float(sats.max_power_w[sat]), float(sats.max_storage_gb[sat]))))
    return out


def _cap(power: np.ndarray, data: np.ndarray, max_power: float, max_storage: float) -> int:
    """How many observations an orbit may hold when every observation costs the same (their generator: one
    sensor per satellite); their sums in order, with their 1e-9 tolerance.  NO_CAP when no limit applies;
    a pass whose costs differ gets the count of its cheapest observations (an upper bound, refined by the
    solver's repair)."""
    if max_power <= 0 and max_storage <= 0:
        return NO_CAP
    cap = NO_CAP
    for cost, limit in ((np.sort(power), max_power), (np.sort(data), max_storage)):
        if limit <= 0 or len(cost) == 0 or cost[0] <= 0:
            continue
        total, c = 0.0, 0
        while c < len(cost) and total + cost[c] - limit <= 1e-9:
            total += cost[c]
            c += 1
        if c == len(cost):  # every acquisition fits once: keep going with the cheapest
            while total + cost[0] - limit <= 1e-9 and c < 10 * len(cost) + 10:
                total += cost[0]
                c += 1
        cap = min(cap, c)
    return cap


@numba.njit(cache=True, inline="always")
def _need_us(last, first, code, v, non_agile_us, agile):
    """Transition time in microseconds (eosp.eosbench.transition, one pair)."""
    if not agile:
        return non_agile_us
    if code:
        return np.int64(np.rint(C_SMALL * 1e6))
    if np.isnan(last[0]) or np.isnan(first[0]):
        return np.int64(np.rint(C_SMALL * 1e6))
    dg = (abs(first[2] - last[2]) + abs(first[0] - last[0])) + abs(first[1] - last[1])
    if dg <= SMALL_DG:
        return np.int64(np.rint(C_SMALL * 1e6))
    piece = 3
    for i in range(3):
        if dg <= BREAKS_NB[i]:
            piece = i
            break
    return np.int64(np.rint((OFFSETS_NB[piece] + dg / v[piece]) * 1e6))


BREAKS_NB = BREAKS.copy()
OFFSETS_NB = OFFSETS.copy()


@numba.njit(cache=True)
def _arcs(acq_ptr, nodes, allowed, release, code, v, non_agile_us, agile):
    """CSR arcs over the allowed nodes (`nodes`: start, end, first and last attitudes): from the source to each
    acquisition's first allowed node starting at or after `release`; from each allowed node to the earliest
    allowed node of every other acquisition that can follow it.

    Linear in the arcs it writes: acquisitions without an allowed node are skipped, each scan jumps from allowed
    node to allowed node (`nxt`), and where the transition time is one constant (the code reading, non-agile
    satellites) one binary search finds the arc."""
    start, end, first, last = nodes
    n = start.shape[0]
    k = acq_ptr.shape[0] - 1
    nxt = np.empty(n + 1, dtype=np.int64)  # the first allowed node at or after x in x's acquisition, or its end
    live = np.zeros(k, dtype=np.int64)  # acquisitions with an allowed node
    n_live = 0
    for b in range(k):
        hi = acq_ptr[b + 1]
        nxt_x = hi
        for x in range(hi - 1, acq_ptr[b] - 1, -1):
            if allowed[x]:
                nxt_x = x
            nxt[x] = nxt_x
        nxt[hi] = hi
        if nxt_x < hi:
            live[n_live] = b
            n_live += 1
    const = code or not agile
    need_c = np.int64(np.rint(C_SMALL * 1e6)) if agile else non_agile_us
    indptr = np.zeros(n + 1, dtype=np.int64)
    dst = np.empty(max(1, n_live + int(allowed.sum()) * max(n_live - 1, 0)), dtype=np.int32)
    cnt = 0
    for i in range(n_live):
        b = live[i]
        lo = first_at_or_after(start, acq_ptr[b], acq_ptr[b + 1], release)
        if lo < acq_ptr[b + 1] and nxt[lo] < acq_ptr[b + 1]:
            dst[cnt] = nxt[lo]
            cnt += 1
    indptr[1] = cnt
    acq = 0
    for u in range(1, n):
        while u >= acq_ptr[acq + 1]:
            acq += 1
        if allowed[u]:
            for i in range(n_live):
                b = live[i]
                if b == acq:
                    continue
                end_b = acq_ptr[b + 1]
                x = nxt[first_at_or_after(start, acq_ptr[b], end_b, end[u] + need_c if const else end[u])]
                if not const:
                    while x < end_b and start[x] < end[u] + _need_us(last[u], first[x], code, v, non_agile_us,
                                                                      agile):
                        x = nxt[x + 1]
                if x < end_b:
                    dst[cnt] = x
                    cnt += 1
        indptr[u + 1] = cnt
    return indptr, dst[:cnt].copy()


def graph(p: Pass, rules: Rules, agile: bool, allowed: np.ndarray | None = None, release_us: int = -(1 << 62)
          ) -> DiscreteGraph:
    """The pass's discrete graph under `rules` over the `allowed` nodes (all by default)."""
    if allowed is None:
        allowed = np.ones(p.n_nodes, dtype=bool)
    v = np.asarray(PROFILES[rules.agility], dtype=np.float64)
    indptr, dst = _arcs(p.acq_ptr, (p.start_us, p.end_us, p.first, p.last), allowed, np.int64(release_us),
                        rules.transition == "code", v, np.int64(np.rint(rules.non_agile_s * US)), agile)
    return DiscreteGraph(p.node_acq, p.start_us.astype(np.float64) / US, indptr, dst, p.acq_ptr)


def best_path(g: DiscreteGraph, weights: np.ndarray, time_limit: float | None) -> tuple[np.ndarray, float, bool]:
    """The best path (canonical nodes, its value, whether it is proven optimal) under per-acquisition weights;
    acquisitions of non-positive weight should be masked out of `g` by the caller."""
    res = label_search(g, np.asarray(weights, dtype=np.float64), beam=0, time_limit=time_limit, on_limit="beam1")
    return res.nodes.astype(np.int64), float(res.value), bool(res.complete)
