"""The passes of a fleet solve on Ray actors: a :class:`eosp.kinds.fleet.pool.PassPool` beside the in-process and
forked ones (:mod:`eosp.kinds.fleet.pool`), used by ``jobs/solve_fleet.py`` on a laptop or a cluster.

Each actor (:class:`PassWorker`) owns the passes of a set of satellites (balanced by opportunities,
:func:`assign`) and builds their pass graphs once, where they are solved: the fleet goes to the object store
once, and a round sends only pass ids and prices and gets paths back.  The coordinate descent's sweeps and the
construction's waves go to the same actors (each gets its passes' utilities, which depend on the driver's
schedule, as one flat vector), and so do the battery repairs of their satellites.

Faults: an actor that dies mid-round costs nothing but time: the driver solves its passes of the round (the same
deterministic solver, the same result), and Ray restarts it where a CPU is free, which builds its graphs again;
meanwhile the driver solves its passes, and one not back within :data:`REVIVE_S` seconds (its node lost on a full
cluster) is given up: its satellites go to the live actors (:func:`rehome`).  Tests kill an actor in round R
(``EOSP_FAULT_KILL_ACTOR_ROUND=R``), sweep S (``..._SWEEP=S``) or battery repair B (``..._REPAIR=B``).
"""

from __future__ import annotations

import os
import time

import numpy as np

from eosp.budget import Budget
from eosp.kinds.fleet.config import FleetConfig
from eosp.kinds.fleet.problem import PassSpec, priced, solve_pass_graph, solve_round_pass

REVIVE_S = 60.0  # seconds a lost actor may take to come back (restarted by Ray, graphs built) before its passes move

def inject_faults(pool: RayPassPool, kind: str, count: int) -> None:
    """The tests' fault injection once a call's work is sent: the first actor killed in the round, sweep or repair
    the environment names (``EOSP_FAULT_KILL_ACTOR_*``), and the tests' callback told."""
    import ray

    kill = {"round": pool.kill_round, "sweep": pool.kill_sweep, "repair": pool.kill_repair}[kind]
    if count == kill and pool.actors[0] is not None:
        ray.kill(pool.actors[0], no_restart=False)  # a worker lost mid-round or mid-sweep (tests)
    if pool.on_sent is not None:
        pool.on_sent(kind, count)


def unpack(passes: np.ndarray, value: np.ndarray, bound: np.ndarray, offsets: np.ndarray, nodes: np.ndarray) -> dict:
    """An actor's packed answer (:meth:`PassWorker.solve_priced`) as a PassResult per pass (a NaN bound: none)."""
    from eosp.kinds.fleet.problem import PassResult

    out = {}
    for i, (p, b) in enumerate(zip(passes.tolist(), bound.tolist())):
        out[p] = PassResult(nodes[offsets[i]:offsets[i + 1]], float(value[i]), None if b != b else b)
    return out


def packed(passes: np.ndarray, solve_one) -> tuple:
    """Each of `passes` solved by ``solve_one(i, pass)`` (a PassResult), timed, and packed in a few arrays (a round
    of thousands of passes costs thousands of small objects otherwise): pass ids, values, bounds (NaN: none), CSR
    offsets and nodes of the paths, seconds per pass (:func:`unpack` reads them back)."""
    n = len(passes)
    value, bound, secs = np.zeros(n), np.full(n, np.nan), np.zeros(n)
    paths = []
    for i, p in enumerate(passes.tolist()):
        t = time.perf_counter()
        res = solve_one(i, p)
        secs[i] = time.perf_counter() - t
        value[i] = res.value
        if res.bound is not None:
            bound[i] = res.bound
        paths.append(res.nodes)
    offsets = np.r_[0, np.cumsum([len(x) for x in paths])].astype(np.int64)
    nodes = np.concatenate(paths).astype(np.int64) if paths else np.zeros(0, np.int64)
    return passes, value, bound, offsets, nodes, secs


def graphs_summary(graphs: list, fifo: bool) -> dict:
    """Of some pass graphs: how many, their bytes, those whose bound needs a bound problem, those with none
    provable, and (`fifo`) their FIFO violations (None: not counted)."""
    from eosp.graphs.prune import fifo_violations

    return {"passes": len(graphs), "bytes": sum(pg.nbytes for pg in graphs),
            "bound_graphs": sum(pg.bound_graph is not None for pg in graphs),
            "unprovable": sum(not pg.bound_provable for pg in graphs),
            "fifo_violations": sum(fifo_violations(pg.graph) for pg in graphs) if fifo else None}


class PassWorker:
    """A Ray actor holding the pass graphs of some passes (built here, once) and solving them on demand."""

    def __init__(self, fleet_ref: list, passes: list[int], spec: PassSpec):
        """`fleet_ref`: [the object-store reference of (fleet, opportunities)], fetched here (inside a list Ray
        passes the reference as it is, and the pool holds it: a restart fetches it again)."""
        import ray

        from eosp.fleet.geometry import Geometry
        from eosp.fleet.passgraph import build_pass
        from eosp.fleet.slew import LineOfSight

        fleet, opps = ray.get(fleet_ref[0])
        los = LineOfSight(fleet, Geometry(fleet))
        off = opps.pass_offsets()
        self.spec, self.fleet, self.los, self.sun = spec, fleet, los, None
        self.weight = fleet.tasks.weight.astype(np.float64)
        self._build = lambda p: build_pass(fleet, opps, los, p, off)
        self.graphs = {p: self._build(p) for p in passes}
        if self.graphs:  # compile the solver's kernels now, not in the first round (numba, per process)
            pg = max(self.graphs.values(), key=lambda g: len(g.rows))
            solve_pass_graph(pg, self.weight[pg.tasks], spec)

    def adopt(self, passes: list[int]) -> int:
        """Build the graphs of more passes (those of a lost actor); returns how many this actor holds."""
        for p in passes:
            if p not in self.graphs:
                self.graphs[p] = self._build(p)
        return len(self.graphs)

    def ready(self) -> str:
        """The Ray node this actor runs on (once its graphs are built)."""
        import ray

        return ray.get_runtime_context().get_node_id()

    def summary(self) -> dict:
        """What the driver of a lean problem cannot count itself: of the graphs held here, their bytes, the passes
        whose bound needs a bound problem, those with none provable, and the FIFO violations."""
        return graphs_summary(list(self.graphs.values()), fifo=True)

    def solve_priced(self, passes: np.ndarray, lam: np.ndarray, pass_prices: np.ndarray, budget_s: float | None,
                     values: tuple | None = None) -> tuple:
        """Every pass of `passes` under task prices `lam` and energy prices `pass_prices` (utility value - price -
        pass price * energy) within `budget_s` seconds (the driver's :meth:`eosp.budget.Budget.wire`), packed (pass
        ids, values, bounds (NaN: none), CSR offsets and nodes of the paths, seconds per pass).  `values`: the
        problem's (values per (pass, task), task offsets) when it has any (:func:`values_ref`: with every round, so
        a restarted actor has them too), else the weights."""
        budget = Budget.of(budget_s)

        def one(i: int, p: int):
            pg = self.graphs[p]
            value = self.weight[pg.tasks] if values is None else values[0][values[1][p]:values[1][p + 1]]
            return solve_round_pass(pg, priced(value, lam[pg.tasks], pg.energy_wh, pass_prices[p]), self.spec, budget)
        return packed(passes, one)

    def repair_rows(self, rows, budget_s: float | None):
        """The battery repair of some of this actor's satellites (:func:`eosp.fleet.timeline.repair_rows`: whether
        each row is kept; None when stopped `budget_s` seconds from now), their sunlight computed here once."""
        from eosp.fleet.battery import SunCache
        from eosp.fleet.timeline import repair_rows

        if self.sun is None:
            self.sun = SunCache(self.los.geo)
        return repair_rows(self.fleet, self.los, rows, self.sun, Budget.of(budget_s))

    def solve_utilities(self, passes: np.ndarray, util: np.ndarray, util_offsets: np.ndarray,
                        budget_s: float | None) -> tuple:
        """A sweep of the coordinate descent: pass ``passes[i]`` with utilities ``util[util_offsets[i]:
        util_offsets[i + 1]]`` (the driver's, from its schedule) by the pass solver alone, within `budget_s`
        seconds from now; packed as :meth:`solve_priced` (each bound the solver's, NaN when none: the
        driver keeps the proven optima, as it does for its own solves)."""
        budget = Budget.of(budget_s)
        return packed(passes, lambda i, p: solve_pass_graph(self.graphs[p], util[util_offsets[i]:util_offsets[i + 1]],
                                                             self.spec, budget))


def rehome(prob, owner: np.ndarray, mine: np.ndarray, live: list[int]) -> None:
    """The passes `mine` (a lost actor's) to the `live` actors in `owner` (the actor of every pass), whole
    satellites onto the least loaded (by opportunities), the heaviest satellites first."""
    sat_of = np.array([prob.passes[p].satellite for p in mine.tolist()], dtype=np.int64)
    size = np.array([len(prob.passes[p].rows) for p in mine.tolist()], dtype=np.float64)
    all_size = np.array([len(pg.rows) for pg in prob.passes], dtype=np.float64)
    load = np.array([all_size[owner == j].sum() for j in live])
    sats, inv = np.unique(sat_of, return_inverse=True)
    sat_load = np.bincount(inv, weights=size, minlength=len(sats))
    for s in np.argsort(-sat_load, kind="stable").tolist():
        i = int(np.argmin(load))
        load[i] += sat_load[s]
        owner[mine[inv == s]] = live[i]


def values_ref(pool: RayPassPool):
    """The problem's values per (pass, task) and its task offsets in the object store, put again when the
    driver's problem has other values than the last put (a re-plan's revaluation); None without values."""
    import ray

    values = pool.prob.values
    if values is None:
        return None
    if pool.values_put is None or pool.values_put[0] is not values:
        pool.values_put = (values, ray.put((values, pool.prob.task_ptr)))
    return pool.values_put[1]


def assign(prob, workers: int) -> np.ndarray:
    """Worker of every pass: whole satellites per worker (an actor then propagates only its satellites), the
    heaviest satellites (opportunities) first onto the least loaded worker."""
    sat_of = np.array([pg.satellite for pg in prob.passes], dtype=np.int64)
    size = np.array([len(pg.rows) for pg in prob.passes], dtype=np.int64)
    load_sat = np.bincount(sat_of, weights=size, minlength=len(prob.fleet.satellites))
    owner_sat = np.zeros(len(load_sat), dtype=np.int64)
    load = np.zeros(workers)
    for s in np.argsort(-load_sat, kind="stable").tolist():
        k = int(np.argmin(load))
        owner_sat[s] = k
        load[k] += load_sat[s]
    return owner_sat[sat_of]


class RayPassPool:
    """The passes of a price round solved by Ray actors: a :class:`eosp.kinds.fleet.pool.PassPool`.

    Faults: a call an actor fails (it died: killed, or its node lost) is solved by the driver, the same
    deterministic solver, so the round's result is the same.  Ray restarts the actor where a CPU is free (its
    graphs built again from the fleet in the object store); until it answers, the driver solves its passes beside
    the other actors.  An actor not back within :data:`REVIVE_S` seconds (``EOSP_REVIVE_S``: no CPU left for it, as
    when its node is lost on a full cluster) is given up and its passes go to the live actors, which build their
    graphs (by opportunities, least loaded first); with none left the driver solves everything."""

    def __init__(self, prob, cfg: FleetConfig):
        import ray

        self.prob, self.spec = prob, PassSpec.of(cfg)
        self.owner = assign(prob, cfg.workers)  # actor of every pass (-1: the driver, when no actor is left)
        # held as long as the pool: a restarted actor is built again from it (dropped, Ray deletes the object
        # once the actors are made, and a restart fails for want of its argument)
        self.fleet_ref = ray.put((prob.fleet, prob.opps))
        actor = ray.remote(num_cpus=1, max_restarts=2, max_task_retries=0)(PassWorker)
        self.actors = [actor.remote([self.fleet_ref], np.flatnonzero(self.owner == k).tolist(), self.spec)
                       for k in range(cfg.workers)]
        self.nodes = ray.get([a.ready.remote() for a in self.actors])  # node of each actor
        self.adopted: list[list[int]] = [[] for _ in self.actors]  # passes each actor took over from lost ones
        self.reviving: dict[int, tuple] = {}  # lost actor -> (its ready() call, when it was lost)
        self.revive_s = float(os.environ.get("EOSP_REVIVE_S", "") or REVIVE_S)
        self.given_up = 0  # actors whose passes went to the others
        self.calls = 0
        self.round_solve_s = 0.0  # the last round collected: its busiest actor's seconds of solves
        self.faults = 0  # actor calls lost to a dead actor (their passes solved by the driver)
        self.times: list[tuple[int, float, int]] = []  # (pass, seconds, worker): price-round passes actors solved
        self.kill_round = int(os.environ.get("EOSP_FAULT_KILL_ACTOR_ROUND", "0") or 0)
        self.sweeps = 0  # calls of solve_utilities (coordinate-descent sweeps sent to the actors)
        self.kill_sweep = int(os.environ.get("EOSP_FAULT_KILL_ACTOR_SWEEP", "0") or 0)
        self.repairs = 0  # calls of repair_rows (battery repairs sent to the actors)
        self.kill_repair = int(os.environ.get("EOSP_FAULT_KILL_ACTOR_REPAIR", "0") or 0)
        self.pass_sat = np.array([pg.satellite for pg in prob.passes], dtype=np.int64)
        self.values_put = None  # (the problem's values last put, their object-store reference): values_ref
        self.on_sent = None  # tests: called with ("round" or "sweep", its count) once a call's work is sent

    # ------------------------------------------------------------------ faults
    def _lost(self, k: int) -> None:
        """Actor k failed a call: wait for it (Ray restarts it) without blocking the rounds."""
        self.faults += 1
        if k not in self.reviving:
            self.reviving[k] = (self.actors[k].ready.remote(), time.perf_counter())

    def live(self) -> list[int]:
        """The actors that take calls now: those never lost, and those back from a restart (given again the passes
        they had adopted: a restart builds only its first ones); the ones lost for longer than :attr:`revive_s`, or
        dead for good, are given up."""
        import ray
        from ray.exceptions import ActorUnavailableError, RayActorError

        live, gone = [], []
        for k, a in enumerate(self.actors):
            if a is None:
                continue
            if k not in self.reviving:
                live.append(k)
                continue
            ref, since = self.reviving[k]
            if ray.wait([ref], timeout=0)[0]:
                try:
                    self.nodes[k] = ray.get(ref)
                except ActorUnavailableError:  # still restarting: asked again
                    self.reviving[k] = (a.ready.remote(), since)
                except RayActorError:  # dead for good (its restarts spent)
                    gone.append(k)
                    continue
                else:
                    del self.reviving[k]
                    if self.adopted[k]:
                        a.adopt.remote(self.adopted[k])
                    live.append(k)
                    continue
            if time.perf_counter() - since > self.revive_s:
                gone.append(k)
        for k in gone:
            self._give_up(k, live)
        return live

    def _give_up(self, k: int, live: list[int]) -> None:
        """Actor k's passes to the live actors, whole satellites onto the least loaded (opportunities), or to the
        driver when none is left."""
        import ray

        ray.kill(self.actors[k], no_restart=True)
        self.actors[k] = None
        self.reviving.pop(k, None)
        self.given_up += 1
        mine = np.flatnonzero(self.owner == k)
        if not live:
            self.owner[mine] = -1
            return
        rehome(self.prob, self.owner, mine, live)
        for j in live:
            got = mine[self.owner[mine] == j].tolist()
            if got:
                self.adopted[j] += got
                self.actors[j].adopt.remote(got)

    def _spread(self, ids: np.ndarray) -> tuple[list[tuple[int, np.ndarray]], np.ndarray]:
        """Positions in `ids` of each live actor's passes, and of those the driver solves (its actor lost)."""
        live = self.live()
        owner = self.owner[ids]
        parts = [(k, np.flatnonzero(owner == k)) for k in live]
        return [(k, idx) for k, idx in parts if len(idx)], np.flatnonzero(~np.isin(owner, live))

    # ------------------------------------------------------------------ calls
    def solve_priced(self, passes: list[int], lam: np.ndarray, pass_prices: np.ndarray,
                     budget: Budget) -> dict | None:
        """Every pass of `passes` under task prices `lam` and energy prices `pass_prices`: the prices go to the
        object store once, each actor solves its own passes and sends them back packed
        (:meth:`PassWorker.solve_priced`); the passes of a lost actor are solved here meanwhile."""
        return self.submit_priced(passes, lam, pass_prices, budget)()

    def submit_priced(self, passes: list[int], lam: np.ndarray, pass_prices: np.ndarray,
                      budget: Budget):
        """:meth:`solve_priced` sent to the actors now, its result waited for when the returned function is called
        (:meth:`eosp.kinds.fleet.pool.PassPool.submit_priced`: the next price round solved while the driver
        recovers a schedule from this one)."""
        import ray
        from ray.exceptions import RayActorError

        from eosp.kinds.fleet.pool import solve_priced_pass

        self.calls += 1
        ids = np.asarray(passes, dtype=np.int64)
        parts, here = self._spread(ids)
        lam_ref = ray.put(np.asarray(lam, dtype=np.float64))
        pi_ref = ray.put(np.asarray(pass_prices, dtype=np.float64))
        left = budget.wire()
        values = values_ref(self)
        refs = [self.actors[k].solve_priced.remote(ids[idx], lam_ref, pi_ref, left, values) for k, idx in parts]
        inject_faults(self, "round", self.calls)
        out = {}

        def locally(idx: np.ndarray) -> bool:
            for p in ids[idx].tolist():
                if budget.expired():
                    return False
                out[p] = solve_priced_pass(self.prob, p, lam, pass_prices, self.spec, budget)
            return True

        def collect() -> dict | None:
            if not locally(here):
                return None
            timeout = budget.wire()
            ready, _ = ray.wait(refs, num_returns=len(refs), timeout=timeout)
            if len(ready) < len(refs):
                return None  # the budget ran out first
            busy = [0.0]  # each actor's seconds of solves in this round
            for ref, (k, idx) in zip(refs, parts):
                try:
                    got, value, bound, offsets, nodes, secs = ray.get(ref)
                except RayActorError:
                    self._lost(k)
                    if not locally(idx):
                        return None
                    continue
                out.update(unpack(got, value, bound, offsets, nodes))
                self.times += list(zip(got.tolist(), secs.tolist(), [k] * len(got)))
                busy.append(float(secs.sum()))
            self.round_solve_s = max(busy)
            return out

        def idle() -> bool:
            """Whether every actor has finished its part of this round (a sweep sent now would not wait behind
            it); never blocks."""
            return len(ray.wait(refs, num_returns=len(refs), timeout=0)[0]) == len(refs)

        collect.idle = idle
        return collect

    def solve_utilities(self, passes: list[int], util: np.ndarray, offsets: np.ndarray,
                        budget: Budget) -> dict | None:
        """A sweep of the coordinate descent (:meth:`eosp.kinds.fleet.pool.PassPool.solve_utilities`): each actor
        gets its own passes' utilities as one flat vector and offsets; the passes of a lost actor are solved here
        (the same deterministic solver); None when the budget ran out first."""
        import ray
        from ray.exceptions import RayActorError

        from eosp.kinds.fleet.pool import solve_utility_passes

        self.sweeps += 1
        ids = np.asarray(passes, dtype=np.int64)
        offsets = np.asarray(offsets, dtype=np.int64)
        parts, here = self._spread(ids)
        left = budget.wire()

        def pick(idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            lo, hi = offsets[idx], offsets[idx + 1]
            mine = np.concatenate([util[a:b] for a, b in zip(lo.tolist(), hi.tolist())]) if len(idx) else util[:0]
            return mine, np.r_[0, np.cumsum(hi - lo)].astype(np.int64)

        refs, sent = [], []
        for k, idx in parts:
            mine_util, mine_off = pick(idx)
            refs.append(self.actors[k].solve_utilities.remote(ids[idx], mine_util, mine_off, left))
            sent.append((mine_util, mine_off))
        inject_faults(self, "sweep", self.sweeps)
        out = {}
        if len(here):
            done = solve_utility_passes(self.prob, self.spec, ids[here].tolist(), *pick(here), budget)
            if done is None:
                return None
            out.update(done)
        timeout = budget.wire()
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=timeout)
        if len(ready) < len(refs):
            return None  # the budget ran out first
        for ref, (k, idx), (mine_util, mine_off) in zip(refs, parts, sent):
            try:
                got, value, bound, offs, nodes, secs = ray.get(ref)
            except RayActorError:
                self._lost(k)
                done = solve_utility_passes(self.prob, self.spec, ids[idx].tolist(), mine_util, mine_off, budget)
                if done is None:
                    return None
                out.update(done)
                continue
            out.update(unpack(got, value, bound, offs, nodes))
        return out

    def repair_rows(self, rows, budget: Budget) -> np.ndarray | None:
        """The battery repair of the satellites of `rows` (:func:`eosp.fleet.timeline.repair_rows`), each on the
        actor that owns its passes, those of a lost actor here; whether each row is kept, or None when the budget
        ran out first.  A satellite's repair reads its own rows only: the same result whoever runs it."""
        import ray
        from ray.exceptions import RayActorError

        from eosp.fleet.timeline import repair_rows

        self.repairs += 1
        owner_sat = np.full(len(self.prob.fleet.satellites), -1, dtype=np.int64)
        owner_sat[self.pass_sat] = self.owner  # whole satellites per actor
        live = self.live()
        owner = owner_sat[rows.sats]
        parts = [(k, idx) for k in live if len(idx := np.flatnonzero(owner == k))]
        here = np.flatnonzero(~np.isin(owner, live))
        left = budget.wire()
        refs = [self.actors[k].repair_rows.remote(rows.part(idx), left) for k, idx in parts]
        inject_faults(self, "repair", self.repairs)
        kept = np.ones(len(rows.task), dtype=bool)

        def locally(idx: np.ndarray) -> bool:
            got = repair_rows(self.prob.fleet, self.prob.los, rows.part(idx), self.prob.sun, budget)
            if got is not None:
                kept[rows.take(idx)] = got
            return got is not None

        if len(here) and not locally(here):
            return None
        timeout = budget.wire()
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=timeout)
        if len(ready) < len(refs):
            return None  # the budget ran out first
        for ref, (k, idx) in zip(refs, parts):
            try:
                got = ray.get(ref)
            except RayActorError:
                self._lost(k)
                if not locally(idx):
                    return None
                continue
            if got is None:
                return None
            kept[rows.take(idx)] = got
        return kept

    def summary(self) -> list[dict]:
        """:meth:`PassWorker.summary` of every live actor (and, alike, of the graphs the driver built for lost
        actors' passes)."""
        import ray
        from ray.exceptions import RayActorError

        out = []
        for a in self.actors:
            if a is not None:
                try:
                    out.append(ray.get(a.summary.remote()))
                except RayActorError:
                    continue
        built = list(getattr(self.prob, "built", {}).values())
        if built:
            out.append(graphs_summary(built, fifo=False))
        return out

    def close(self) -> None:
        import ray

        for a in [a for a in self.actors if a is not None]:
            ray.kill(a)
