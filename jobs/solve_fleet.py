"""Solve a fleet with the price-coordinated fleet solver, the passes of every price round on Ray actors.

    python jobs/solve_fleet.py --fleet-dir FLEET --run-dir runs/fleet-1 --fleet.workers 2 --fleet.time-limit 600
    ray job submit --working-dir . -- python jobs/solve_fleet.py --fleet-dir /shared/fleet --run-dir /shared/run \\
        --fleet.workers 64 --mlflow-uri http://mlflow:5000

The same code runs on a laptop (a local Ray with ``--ray.num-cpus``) and on a cluster (``ray job submit``, or
``--ray.address``).  Each actor owns the passes of a set of satellites (balanced by opportunities) and builds
their pass graphs once, where they are solved: the fleet goes to the object store once, and a round sends only
pass ids and prices and gets paths back.  The coordinate descent's sweeps and the construction's waves go to
the same actors (each gets its passes' utilities, which depend on the driver's schedule, as one flat vector).
Where the graphs are large (``--lean-driver``) the driver keeps the passes without their arcs and every solve is
the actors'; else it holds every graph too and solves small sweeps itself, where a round trip would cost more than
the solves.

Faults: an actor that dies mid-round costs nothing but time: the driver solves that actor's passes of the round
itself (the same deterministic solver, so the round's result is the same), and Ray restarts the actor where a CPU
is free, which builds its graphs again; while it is away the driver solves its passes, and one not back within a
minute (its node lost on a full cluster) is given up: its satellites go to the live actors (``RayPassPool``).
After every round the driver writes its state to the run dir (prices, step, bound,
rounds done, and the best schedule, each file replaced atomically); a driver killed and started again with the
same run dir resumes from there.  A run dir of another fleet is refused.  (Tests kill an actor in round R with
the environment variable ``EOSP_FAULT_KILL_ACTOR_ROUND=R``, in the S-th descent sweep sent to the actors with
``EOSP_FAULT_KILL_ACTOR_SWEEP=S``, and the driver after round N has been saved with
``EOSP_FAULT_KILL_AFTER=N``.)

MLflow: one run per job: value, bound and gap against rounds and wall time, per-pass solve times (CSV and a
plot), the schedule and a per-satellite summary as artifacts.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from eosp.args import Parser, add_config_args, add_memory_arg, config_from_args, prefixed_config, run_job  # noqa: E402
from eosp.config import RayConfig, choice, flatten  # noqa: E402
from eosp.kinds.fleet.config import FleetConfig  # noqa: E402

RUN_KIND = "fleet-run"
STATE = "state.npz"
BEST = "best.parquet"
META = "run.json"
REVIVE_S = 60.0  # seconds a lost actor may take to come back (restarted by Ray, graphs built) before its passes move


@dataclass
class SolveFleetJob:
    """A fleet solve as a Ray job (``jobs/solve_fleet.py``)."""

    fleet_dir: str = ""
    """Fleet directory to solve (``eosp import`` or ``eosp generate --fleet``)."""
    run_dir: str = ""
    """Where the job keeps its state after every round and writes schedule.parquet and summary.csv; started again
    with the same run dir, it resumes."""
    fleet: FleetConfig = field(default_factory=FleetConfig)
    mlflow_uri: str = ""
    """MLflow tracking URI (empty: sqlite mlflow.db in the working directory)."""
    experiment: str = "eosp-fleet"
    """MLflow experiment."""
    lean_driver: str = choice("auto", "auto", "yes", "no")
    """With --fleet.workers > 1: yes, the driver keeps the passes without their arcs (the actors hold the graphs,
    every pass solve is theirs: the memory of the graphs once, and the first graphs built in parallel); no, it
    holds every graph too (small descent sweeps and those of a prefetched round solved on the driver: faster where
    the graphs are small); auto: yes where the graphs are estimated above 4 GiB."""
    ray: RayConfig = field(default_factory=RayConfig)


class PassWorker:
    """A Ray actor holding the pass graphs of some passes (built here, once) and solving them on demand."""

    def __init__(self, fleet_ref: list, passes: list[int], cfg: FleetConfig):
        """`fleet_ref`: [the object-store reference of (fleet, opportunities)], fetched here (inside a list Ray
        passes the reference as it is, and the pool holds it: a restart fetches it again)."""
        import ray

        from eosp.fleet.geometry import Geometry
        from eosp.fleet.passgraph import build_pass
        from eosp.fleet.slew import LineOfSight

        fleet, opps = ray.get(fleet_ref[0])
        los = LineOfSight(fleet, Geometry(fleet))
        off = opps.pass_offsets()
        self.cfg, self.fleet, self.los, self.sun = cfg, fleet, los, None
        self.weight = fleet.tasks.weight.astype(np.float64)
        self._build = lambda p: build_pass(fleet, opps, los, p, off)
        self.graphs = {p: self._build(p) for p in passes}
        if self.graphs:  # compile the solver's kernels now, not in the first round (numba, per process)
            from eosp.kinds.fleet.problem import solve_pass_graph

            pg = max(self.graphs.values(), key=lambda g: len(g.rows))
            solve_pass_graph(pg, self.weight[pg.tasks], cfg)

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
        from eosp.graphs.prune import fifo_violations

        g = list(self.graphs.values())
        return {"passes": len(g), "bytes": sum(pg.nbytes for pg in g),
                "bound_graphs": sum(pg.bound_graph is not None for pg in g),
                "unprovable": sum(not pg.bound_provable for pg in g),
                "fifo_violations": sum(fifo_violations(pg.graph) for pg in g)}

    def solve_priced(self, passes: np.ndarray, lam: np.ndarray, pass_prices: np.ndarray, left_s: float | None) -> tuple:
        """Every pass of `passes` under task prices `lam` and the passes' energy prices `pass_prices` (utility
        weight - price - pass price * energy), each solve stopped `left_s` seconds from now (this machine's
        clock: the driver's deadline as a duration), packed in a few arrays (a round of thousands of passes costs
        thousands of small objects otherwise): pass ids, values, bounds (NaN: none), CSR offsets and nodes of the
        paths, seconds per pass."""
        from eosp.kinds.fleet.problem import priced, solve_round_pass

        deadline = None if left_s is None else time.perf_counter() + left_s
        n = len(passes)
        value, bound, secs = np.zeros(n), np.full(n, np.nan), np.zeros(n)
        paths = []
        for i, p in enumerate(passes.tolist()):
            pg = self.graphs[p]
            t = time.perf_counter()
            util = priced(self.weight, lam, pg.tasks, pg.energy_wh, pass_prices[p])
            res = solve_round_pass(pg, util, self.cfg, deadline)
            secs[i] = time.perf_counter() - t
            value[i] = res.value
            if res.bound is not None:
                bound[i] = res.bound
            paths.append(res.nodes)
        offsets = np.r_[0, np.cumsum([len(x) for x in paths])].astype(np.int64)
        nodes = np.concatenate(paths).astype(np.int64) if paths else np.zeros(0, np.int64)
        return passes, value, bound, offsets, nodes, secs

    def repair_rows(self, rows, left_s: float | None):
        """The battery repair of some of this actor's satellites (:func:`eosp.fleet.timeline.repair_rows`: whether
        each row is kept; None when stopped `left_s` seconds from now), their sunlight computed here once."""
        from eosp.fleet.battery import SunCache
        from eosp.fleet.timeline import repair_rows

        if self.sun is None:
            self.sun = SunCache(self.los.geo)
        return repair_rows(self.fleet, self.los, rows, self.sun,
                           None if left_s is None else time.perf_counter() + left_s)

    def solve_utilities(self, passes: np.ndarray, util: np.ndarray, util_offsets: np.ndarray,
                        left_s: float | None) -> tuple:
        """A sweep of the coordinate descent: pass ``passes[i]`` with utilities ``util[util_offsets[i]:
        util_offsets[i + 1]]`` (the driver's, from its schedule) by the pass solver alone, each solve stopped
        `left_s` seconds from now; packed as :meth:`solve_priced` (each bound the solver's, NaN when none: the
        driver keeps the proven optima, as it does for its own solves)."""
        from eosp.kinds.fleet.problem import solve_pass_graph

        deadline = None if left_s is None else time.perf_counter() + left_s
        n = len(passes)
        value, bound, secs = np.zeros(n), np.full(n, np.nan), np.zeros(n)
        paths = []
        for i, p in enumerate(passes.tolist()):
            t = time.perf_counter()
            res = solve_pass_graph(self.graphs[p], util[util_offsets[i]:util_offsets[i + 1]], self.cfg, deadline)
            secs[i] = time.perf_counter() - t
            value[i] = res.value
            if res.bound is not None:
                bound[i] = res.bound
            paths.append(res.nodes)
        offsets = np.r_[0, np.cumsum([len(x) for x in paths])].astype(np.int64)
        nodes = np.concatenate(paths).astype(np.int64) if paths else np.zeros(0, np.int64)
        return passes, value, bound, offsets, nodes, secs


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

        self.prob, self.cfg = prob, cfg
        self.owner = assign(prob, cfg.workers)  # actor of every pass (-1: the driver, when no actor is left)
        # held as long as the pool: a restarted actor is built again from it (dropped, Ray deletes the object
        # once the actors are made, and a restart fails for want of its argument)
        self.fleet_ref = ray.put((prob.fleet, prob.opps))
        actor = ray.remote(num_cpus=1, max_restarts=2, max_task_retries=0)(PassWorker)
        self.actors = [actor.remote([self.fleet_ref], np.flatnonzero(self.owner == k).tolist(), cfg)
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
        sat_of = np.array([self.prob.passes[p].satellite for p in mine.tolist()], dtype=np.int64)
        size = np.array([len(self.prob.passes[p].rows) for p in mine.tolist()], dtype=np.float64)
        all_size = np.array([len(pg.rows) for pg in self.prob.passes], dtype=np.float64)
        load = np.array([all_size[self.owner == j].sum() for j in live])
        sats, inv = np.unique(sat_of, return_inverse=True)
        sat_load = np.bincount(inv, weights=size, minlength=len(sats))
        for s in np.argsort(-sat_load, kind="stable").tolist():
            i = int(np.argmin(load))
            load[i] += sat_load[s]
            self.owner[mine[inv == s]] = live[i]
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

    def _test_faults(self, kind: str, count: int) -> None:
        import ray

        kill = {"round": self.kill_round, "sweep": self.kill_sweep, "repair": self.kill_repair}[kind]
        if count == kill and self.actors[0] is not None:
            ray.kill(self.actors[0], no_restart=False)  # a worker lost mid-round or mid-sweep (tests)
        if self.on_sent is not None:
            self.on_sent(kind, count)

    # ------------------------------------------------------------------ calls
    def solve_priced(self, passes: list[int], lam: np.ndarray, pass_prices: np.ndarray,
                     deadline: float | None) -> dict | None:
        """Every pass of `passes` under task prices `lam` and energy prices `pass_prices`: the prices go to the
        object store once, each actor solves its own passes and sends them back packed
        (:meth:`PassWorker.solve_priced`); the passes of a lost actor are solved here meanwhile."""
        return self.submit_priced(passes, lam, pass_prices, deadline)()

    def submit_priced(self, passes: list[int], lam: np.ndarray, pass_prices: np.ndarray,
                      deadline: float | None):
        """:meth:`solve_priced` sent to the actors now, its result waited for when the returned function is called
        (:meth:`eosp.kinds.fleet.pool.PassPool.submit_priced`: the next price round solved while the driver
        recovers a schedule from this one)."""
        import ray
        from ray.exceptions import RayActorError

        from eosp.kinds.fleet.pool import solve_priced_pass
        from eosp.kinds.fleet.problem import PassResult

        self.calls += 1
        ids = np.asarray(passes, dtype=np.int64)
        parts, here = self._spread(ids)
        lam_ref = ray.put(np.asarray(lam, dtype=np.float64))
        pi_ref = ray.put(np.asarray(pass_prices, dtype=np.float64))
        left = None if deadline is None else max(0.0, deadline - time.perf_counter())
        refs = [self.actors[k].solve_priced.remote(ids[idx], lam_ref, pi_ref, left) for k, idx in parts]
        self._test_faults("round", self.calls)
        out = {}

        def locally(idx: np.ndarray) -> bool:
            for p in ids[idx].tolist():
                if deadline is not None and time.perf_counter() > deadline:
                    return False
                out[p] = solve_priced_pass(self.prob, p, lam, pass_prices, self.cfg, deadline)
            return True

        def collect() -> dict | None:
            if not locally(here):
                return None
            timeout = None if deadline is None else max(0.0, deadline - time.perf_counter())
            ready, _ = ray.wait(refs, num_returns=len(refs), timeout=timeout)
            if len(ready) < len(refs):
                return None  # the deadline came first
            busy = [0.0]  # each actor's seconds of solves in this round
            for ref, (k, idx) in zip(refs, parts):
                try:
                    got, value, bound, offsets, nodes, secs = ray.get(ref)
                except RayActorError:
                    self._lost(k)
                    if not locally(idx):
                        return None
                    continue
                for i, p in enumerate(got.tolist()):
                    b = float(bound[i])
                    out[p] = PassResult(nodes[offsets[i]:offsets[i + 1]], float(value[i]), None if b != b else b)
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
                        deadline: float | None) -> dict | None:
        """A sweep of the coordinate descent (:meth:`eosp.kinds.fleet.pool.PassPool.solve_utilities`): each actor
        gets its own passes' utilities as one flat vector and offsets; the passes of a lost actor are solved here
        (the same deterministic solver); None when the deadline came first."""
        import ray
        from ray.exceptions import RayActorError

        from eosp.kinds.fleet.pool import solve_utility_passes
        from eosp.kinds.fleet.problem import PassResult

        self.sweeps += 1
        ids = np.asarray(passes, dtype=np.int64)
        offsets = np.asarray(offsets, dtype=np.int64)
        parts, here = self._spread(ids)
        left = None if deadline is None else max(0.0, deadline - time.perf_counter())

        def pick(idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            lo, hi = offsets[idx], offsets[idx + 1]
            mine = np.concatenate([util[a:b] for a, b in zip(lo.tolist(), hi.tolist())]) if len(idx) else util[:0]
            return mine, np.r_[0, np.cumsum(hi - lo)].astype(np.int64)

        refs, sent = [], []
        for k, idx in parts:
            mine_util, mine_off = pick(idx)
            refs.append(self.actors[k].solve_utilities.remote(ids[idx], mine_util, mine_off, left))
            sent.append((mine_util, mine_off))
        self._test_faults("sweep", self.sweeps)
        out = {}
        if len(here):
            done = solve_utility_passes(self.prob, self.cfg, ids[here].tolist(), *pick(here), deadline)
            if done is None:
                return None
            out.update(done)
        timeout = None if deadline is None else max(0.0, deadline - time.perf_counter())
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=timeout)
        if len(ready) < len(refs):
            return None  # the deadline came first
        for ref, (k, idx), (mine_util, mine_off) in zip(refs, parts, sent):
            try:
                got, value, bound, offs, nodes, secs = ray.get(ref)
            except RayActorError:
                self._lost(k)
                done = solve_utility_passes(self.prob, self.cfg, ids[idx].tolist(), mine_util, mine_off, deadline)
                if done is None:
                    return None
                out.update(done)
                continue
            for i, (p, b) in enumerate(zip(got.tolist(), bound.tolist())):
                out[p] = PassResult(nodes[offs[i]:offs[i + 1]], float(value[i]), None if b != b else b)
        return out

    def repair_rows(self, rows, deadline: float | None) -> np.ndarray | None:
        """The battery repair of the satellites of `rows` (:func:`eosp.fleet.timeline.repair_rows`), each on the
        actor that owns its passes, those of a lost actor here; whether each row is kept, or None when the deadline
        came first.  A satellite's repair reads its own rows only: the same result whoever runs it."""
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
        left = None if deadline is None else max(0.0, deadline - time.perf_counter())
        refs = [self.actors[k].repair_rows.remote(rows.part(idx), left) for k, idx in parts]
        self._test_faults("repair", self.repairs)
        kept = np.ones(len(rows.task), dtype=bool)

        def locally(idx: np.ndarray) -> bool:
            got = repair_rows(self.prob.fleet, self.prob.los, rows.part(idx), self.prob.sun, deadline)
            if got is not None:
                kept[rows.take(idx)] = got
            return got is not None

        if len(here) and not locally(here):
            return None
        timeout = None if deadline is None else max(0.0, deadline - time.perf_counter())
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=timeout)
        if len(ready) < len(refs):
            return None  # the deadline came first
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
            out.append({"passes": len(built), "bytes": sum(pg.nbytes for pg in built),
                        "bound_graphs": sum(pg.bound_graph is not None for pg in built),
                        "unprovable": sum(not pg.bound_provable for pg in built), "fifo_violations": None})
        return out

    def close(self) -> None:
        import ray

        for a in self.actors:
            if a is not None:
                ray.kill(a)


def _load_state(run: Path, fleet, fp: str):
    """The saved state of a run dir of this fleet: (Resume, best schedule), or None for a new run; every value
    checked (a truncated, edited or foreign state file is one line, never a traceback or a wrong resume)."""
    from eosp.errors import InputError
    from eosp.fleet.io import read_schedule
    from eosp.kinds.fleet.solve import Resume

    meta_path = run / META
    if not meta_path.exists():
        return None
    try:
        meta = json.loads(meta_path.read_text())
    except (ValueError, UnicodeDecodeError):
        raise InputError(meta_path, "not readable JSON: not a fleet run dir eosp wrote") from None
    if not isinstance(meta, dict):
        raise InputError(meta_path, "not a JSON object: not a fleet run dir eosp wrote")
    if meta.get("fingerprint") != fp:
        raise InputError(f"--run-dir {run}", f"a run dir of another fleet ({meta.get('case_id', '?')}): use another "
                                             "--run-dir")
    if not (run / STATE).exists() or not (run / BEST).exists():
        return None
    state = _read_state(run / STATE, len(fleet.tasks))
    best, _ = read_schedule(run / BEST, fleet)
    return Resume(state["lam"], float(state["step"]), float(state["best_bound"]), str(state["bound_source"]),
                  int(state["rounds_done"]), state.get("mu")), best


STATE_KEYS = {"lam": "f", "step": "f", "best_bound": "f", "bound_source": "U", "rounds_done": "i"}


def _read_state(path: Path, n_tasks: int) -> dict:
    """state.npz as :class:`Checkpoint` writes it: the prices (n_tasks finite numbers >= 0), the step (> 0), the best
    bound (finite), its source (text) and the rounds done (>= 0), each checked."""
    import zipfile

    from eosp.errors import InputError

    try:
        with np.load(path, allow_pickle=False) as z:  # never unpickle a file
            state = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(path, f"not a state file eosp wrote (truncated or edited?): {exc}") from None
    for key, kind in STATE_KEYS.items():
        if key not in state:
            raise InputError(path, f"no {key!r}: not a state file eosp wrote (truncated or edited?)")
        v = state[key]
        if v.dtype.kind not in (kind, "i" if kind == "f" else kind) or (key != "lam" and v.ndim != 0):
            raise InputError(path, f"{key!r} is not a {'vector' if key == 'lam' else 'single'} value of the right type")
    lam = state["lam"]
    if lam.ndim != 1 or len(lam) != n_tasks:
        raise InputError(path, f"prices of another fleet ({lam.size} prices, {n_tasks} tasks)")
    if not np.all(np.isfinite(lam)) or np.any(lam < 0):
        raise InputError(path, "prices must be finite numbers >= 0")
    if not (np.isfinite(state["step"]) and state["step"] > 0 and np.isfinite(state["best_bound"])
            and state["rounds_done"] >= 0):
        raise InputError(path, "step must be > 0, best_bound finite and rounds_done >= 0")
    return state


class Checkpoint:
    """After every round: state and best schedule into the run dir (atomic replaces), metrics to MLflow."""

    def __init__(self, run: Path, fleet, mlflow, W: float):
        self.run, self.fleet, self.mlflow, self.W = run, fleet, mlflow, W
        self.t0 = time.perf_counter()
        self.last_value = -1.0
        self.phases = 0  # round phases logged so far

    def __call__(self, coord) -> None:
        from eosp.atomic import atomic_path
        from eosp.fleet.io import write_schedule

        with atomic_path(self.run / STATE) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, lam=coord.prices.lam, mu=coord.prices.mu, step=np.float64(coord.prices.factor),
                         best_bound=np.float64(coord.best_bound),
                         bound_source=np.str_(coord.bound_source), rounds_done=np.int64(coord.rounds_done))
        if coord.best.value != self.last_value:
            write_schedule(coord.schedule(coord.best), self.fleet, self.run / BEST, overwrite=True,
                           info={"value": coord.best.value / self.W, "partial": True})
            self.last_value = coord.best.value
        if coord.rounds_done == int(os.environ.get("EOSP_FAULT_KILL_AFTER", "0") or 0):
            os.kill(os.getpid(), signal.SIGKILL)  # fault injection for the tests: die like a killed driver
        v, b = coord.best.value / self.W, min(1.0, coord.best_bound / self.W)
        if self.mlflow is not None:
            new = len(coord.phases) > self.phases  # this round's phases (a price round's)
            phases = {f"phase/{k}" + ("" if k == "pool_calls" else "_s"): x
                      for k, x in coord.phases[-1].items()} if new else {}
            self.phases = len(coord.phases)
            self.mlflow.log_metrics({"value": v, "bound": b, "gap": (b - v) / b if b > 0 else 0.0,
                                     "wall_s": time.perf_counter() - self.t0, **phases}, step=coord.rounds_done)


def summary_rows(fleet, sched) -> list[dict]:
    """Per satellite: observations, weight served, seconds observing."""
    ti = fleet.task_index()
    rows = []
    for sid in fleet.satellites.ids.tolist():
        m = sched.satellite == sid
        tasks = np.array([ti[t] for t in sched.task[m].tolist()], dtype=np.int64)
        rows.append({"satellite": sid, "observations": int(m.sum()),
                     "weight": float(fleet.tasks.weight[tasks].sum()) if len(tasks) else 0.0,
                     "observing_s": float((sched.end_us[m] - sched.start_us[m]).sum() / 1e6)})
    return rows


def lean_driver(job: SolveFleetJob, fleet, opps) -> bool:
    """Whether the driver keeps its passes without arcs (``--lean-driver``; only with Ray's actors)."""
    from eosp.fleet.passgraph import LEAN_ABOVE_BYTES, graph_bytes

    if job.fleet.workers < 2 or job.lean_driver == "no":
        return False
    return job.lean_driver == "yes" or graph_bytes(opps, len(fleet.tasks)) > LEAN_ABOVE_BYTES


def run(job: SolveFleetJob) -> dict:
    import csv

    import mlflow

    from eosp.atomic import atomic_path
    from eosp.fleet.io import fingerprint, read_fleet, write_schedule
    from eosp.fleet.passgraph import require_solvable
    from eosp.jobs.preflight import make_run_dir
    from eosp.jobs.ray_init import init_ray
    from eosp.jobs.tracking import use_experiment
    from eosp.kinds.fleet.problem import Problem
    from eosp.kinds.fleet.solve import solve
    from eosp.memory import peak_rss_gb

    import logging

    logging.getLogger("mlflow").setLevel(logging.WARNING)  # its INFO lines (creating tables, experiments) are noise
    t0 = time.perf_counter()
    fleet, opps = read_fleet(job.fleet_dir)
    t_read = time.perf_counter()  # --fleet.time-limit counts from here
    peak = {"read": peak_rss_gb()}  # the driver's peak resident memory after each step (GB)
    fp = fingerprint(fleet)
    run_dir = Path(job.run_dir)
    saved = _load_state(run_dir, fleet, fp) if run_dir.is_dir() else None
    local_actors = job.fleet.workers if job.fleet.workers > 1 and not job.ray.address else 0
    if local_actors:  # more workers than CPUs: refused before anything is written
        _require_cpus(job.fleet.workers, "")
    lean = lean_driver(job, fleet, opps)
    geo = require_solvable(fleet, opps, f"--fleet-dir {job.fleet_dir}", processes=1 + local_actors, lean=lean)
    if job.fleet.workers > 1:
        init_ray(job.ray.address, max(job.ray.num_cpus, job.fleet.workers))
        if job.ray.address:  # a cluster's CPUs are known once connected
            _require_cpus(job.fleet.workers, job.ray.address)
    use_experiment(job.mlflow_uri, job.experiment)  # before the run dir: a store MLflow refuses leaves nothing behind
    make_run_dir(run_dir, replace=False, kind=RUN_KIND)
    (run_dir / META).write_text(json.dumps({"fingerprint": fp, "case_id": fleet.case_id,
                                            "fleet_dir": str(Path(job.fleet_dir).resolve())}, indent=1))
    prob = Problem.build(fleet, opps, geo, lean=lean)  # the Geometry the feasibility check built (not built twice)
    t_build = time.perf_counter() - t0
    peak["graphs"] = peak_rss_gb()
    pool = None
    if job.fleet.workers > 1:
        pool = RayPassPool(prob, job.fleet)
    t_pool = time.perf_counter() - t0
    with mlflow.start_run(run_name=run_dir.name):
        mlflow.log_params({k: str(v) for k, v in flatten(job).items()})
        mlflow.set_tags({"case": fleet.case_id, "resumed": str(saved is not None)})
        ckpt = Checkpoint(run_dir, fleet, mlflow, prob.total_weight)
        resume, initial = (saved if saved is not None else (None, None))
        try:
            sol = solve(fleet, opps, job.fleet, problem=prob, initial=initial, pool=pool, on_round=ckpt, resume=resume,
                        t0=t_read)
            graphs = [] if pool is None else pool.summary()
        finally:
            if pool is not None:
                pool.close()
        wall = time.perf_counter() - t0
        peak["solve"] = peak_rss_gb()
        info = {"value": sol.value, "bound": sol.bound, "gap": sol.gap, "solver": "fleet", "seconds": round(wall, 3),
                "pass_solver": job.fleet.pass_solver, "rounds": sol.info["rounds"],
                "time_limit": job.fleet.time_limit, "warm_start": job.fleet.warm_start}
        write_schedule(sol.schedule, fleet, run_dir / "schedule.parquet", overwrite=True, info=info)
        with atomic_path(run_dir / "summary.csv") as tmp:
            with open(tmp, "w", newline="") as fh:
                rows = summary_rows(fleet, sol.schedule)
                w = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ["satellite"])
                w.writeheader()
                w.writerows(rows)
        times = pool.times if pool is not None else []
        with atomic_path(run_dir / "pass_times.csv") as tmp:
            with open(tmp, "w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(["pass", "opportunities", "seconds", "worker"])
                w.writerows([(p, len(prob.passes[p].rows), round(s, 6), k) for p, s, k in times])
        first_t = sol.history[0][0] if sol.history else None
        result = {"value": sol.value, "bound": sol.bound, "gap": sol.gap, "rounds": sol.info["rounds"],
                  "pass_solves": sol.info["pass_solves"], "memo_hits": sol.info["memo_hits"],
                  "passes": len(prob.passes), "build_s": round(t_build, 2),
                  "pool_s": round(t_pool - t_build, 2), "first_schedule_s": None if first_t is None else
                  round(first_t + t_read - t0, 2), "wall_s": round(wall, 2), "faults": 0 if pool is None else pool.faults,
                  "actors_given_up": 0 if pool is None else pool.given_up,
                  "workers": job.fleet.workers, "nodes": 0 if pool is None else len(set(pool.nodes)),
                  "lean_driver": lean,
                  "resumed_from_round": 0 if resume is None else resume.rounds_done,
                  "price_round_s": sol.info["price_round_s"], "round_phases_s": sol.info["round_phases_s"],
                  "interrupted": sol.info["interrupted"],
                  "check_reserve_s": sol.info["check_reserve_s"], "final_check_s": sol.info["final_check_s"],
                  "driver_peak_gb": {k: None if v is None else round(v, 3) for k, v in peak.items()},
                  "graph_mb": round(sum(pg.nbytes for pg in prob.passes) / 1e6, 1),  # the driver's (lean: nodes)
                  "actor_graph_mb": None if pool is None else round(sum(x["bytes"] for x in graphs) / 1e6, 3),
                  "bound_graphs": sol.info["bound_graphs"] if pool is None else sum(x["bound_graphs"] for x in graphs),
                  "read_s": round(t_read - t0, 2),  # the solve's history counts from the read (the graphs in it)
                  "history": [(round(t + t_read - t0, 3), v, b) for t, v, b in sol.history]}
        (run_dir / "result.json").write_text(json.dumps(result, indent=1))
        mlflow.log_metrics({"final/value": sol.value, "final/bound": sol.bound or 0.0, "final/gap": sol.gap or 0.0,
                            "final/wall_s": wall, "final/faults": result["faults"]})
        for name in ("schedule.parquet", "summary.csv", "pass_times.csv", "result.json"):
            mlflow.log_artifact(str(run_dir / name))
    return result


def main(argv: list[str] | None = None, prog: str = "solve_fleet.py") -> int:
    return run_job(_main, argv, prog)


def _main(argv: list[str] | None) -> int:
    from eosp import errors
    from eosp.errors import InputError
    from eosp.fleet.io import is_fleet_dir
    from eosp.jobs.preflight import check_mlflow, is_run_dir, require_findable

    p = Parser(prog=errors.PROG, description=__doc__.splitlines()[0])
    add_config_args(p, SolveFleetJob)
    add_memory_arg(p)
    ns = p.parse_args(argv)
    job = config_from_args(SolveFleetJob, ns)
    for flag, value in (("--fleet-dir", job.fleet_dir), ("--run-dir", job.run_dir)):
        if not value:
            raise InputError(flag, "required")
        require_findable(value, flag)
    if not is_fleet_dir(job.fleet_dir):
        raise InputError(f"--fleet-dir {job.fleet_dir}", "not a fleet directory (eosp import / eosp generate --fleet)")
    try:
        job.fleet.validate()  # the rules across its fields (a time limit or a number of rounds), set by the flags
    except ValueError as exc:
        raise InputError("--fleet", str(exc)) from None
    if job.fleet.pass_solver == "policy":
        raise InputError("--fleet.pass-solver", "policy: no model trained on fleet passes is shipped yet")
    run_dir = Path(job.run_dir)
    if run_dir.is_dir() and any(run_dir.iterdir()) and not is_run_dir(run_dir, RUN_KIND):
        raise InputError(f"--run-dir {run_dir}", "exists and is not a fleet run dir eosp wrote: refusing to write "
                                                 "into it")
    check_mlflow(job.mlflow_uri)
    if job.ray.address and job.fleet.workers > 1:
        _require_ray_address(job.ray.address)
    from eosp.memory import memory_ceiling

    with memory_ceiling(ns.max_memory_gb):
        r = run(job)
    gap = "" if r["gap"] is None else f", gap {r['gap']:.4%}"
    print(f"[solve_fleet] {job.run_dir}: WCR {r['value']:.6f}, bound {r['bound']:.6f}{gap}; {r['rounds']} rounds, "
          f"{r['pass_solves']} pass solves on {r['workers']} worker(s), {r['faults']} lost to faults "
          f"({r['wall_s']:.1f} s)")
    if r.get("interrupted"):  # Ctrl-C: the best schedule so far was checked and written with the run's files
        print(f"{errors.PROG}: interrupted: wrote the best valid schedule so far to "
              f"{Path(job.run_dir) / 'schedule.parquet'} (WCR {r['value']:.6f})", file=sys.stderr, flush=True)
        return 130
    return 0


def _require_cpus(workers: int, address: str) -> None:
    """One line when the workers outnumber the CPUs: the cluster's (Ray's resources) or, for a local Ray, this
    machine's (a local Ray is started with as many logical CPUs as workers, so its own count says nothing)."""
    import os

    from eosp.errors import InputError

    if address:
        import ray

        cpus = float(ray.cluster_resources().get("CPU", 0))
    else:
        cpus = float(os.cpu_count() or 1)
    if workers > cpus:
        where = "the cluster has" if address else "this machine has"
        raise InputError(f"--fleet.workers {workers}", f"more than the {cpus:g} CPUs {where}")


def _require_ray_address(address: str) -> None:
    """One line, before any work, when the Ray address does not answer (host:port of a GCS, or ray://)."""
    import socket

    from eosp.errors import InputError

    if address in ("auto", "local"):
        return
    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    try:
        socket.create_connection((host or "127.0.0.1", int(port)), timeout=5).close()
    except (OSError, ValueError) as exc:
        raise InputError(f"--ray.address {address}", f"unreachable ({exc.__class__.__name__}: {exc})") from None


if __name__ == "__main__":
    sys.exit(main())
