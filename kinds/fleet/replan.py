"""The fleet solver called again and again over one day (re-planning in operations): what the solves share is
kept between calls, what the day changes is given to each.

Kept (:class:`Replanner`): the problem (its pass graphs, built once), the pass pool (forked processes or Ray
actors, which hold the graphs), the task prices and the energy multipliers where the last call left them, and
the master LP's columns with its basis (``--price-step lp``).  Given to each call: what every (pass, task) is
worth now (:meth:`Replanner.revalue`: a new cloud forecast, a request that arrived), the schedule to start from
and the passes kept as they are (:class:`eosp.kinds.fleet.solve.Start`: those before each satellite's next ground
contact, uploaded already), and the time.

A request that arrives during the day is one the problem holds from the start, worth 0 until it arrives: a
non-positive utility leaves it out of every pass solve, so it is neither served nor counted in a bound, and its
arrival is a revaluation; no pass graph is built again.  Why not add tasks to built graphs: a pass graph's nodes
and arcs are its opportunities in time order, so a new task means new graphs for the passes that see it (on the
workers that own them), and the prices, columns and memo indexed by tasks would all move; a scenario knows every
request its day will hold (:mod:`eosp.fleet` builds their opportunities with the catalogue's), so the cheaper
route serves.

Why keep the prices: a revaluation moves few values (the tasks that arrived, the acquisitions reported), so the
last call's prices are near the new minimiser of the bound and the first rounds of a cold start (the bound falls
from the conflict-free one) are saved.  A new forecast moves every value, each task's passes together (the chance
of clear sky at its target), so each kept price is scaled by its task's change (:meth:`Replanner.carried`): on the
generated 200-satellite day that took a warm 60 s re-plan after a forecast from 2.4% to 1.3% short of a cold
600 s solve of the same state (docs/results.md); on an aeossp day, where 5 s reach the cold solve either way, it
changes nothing.  What is not kept is what depends on the values and the frozen passes as a
whole: the best schedule and the proven bound (a bound under other values bounds nothing now), which each call
finds again.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from eosp.kinds.fleet.config import FleetConfig
from eosp.kinds.fleet.master import Master
from eosp.kinds.fleet.pool import ForkPool, PassPool
from eosp.kinds.lagrange import Prices
from eosp.kinds.fleet.problem import Problem
from eosp.kinds.fleet.solve import FleetSolution, Start, coordinator, run_checked, start_prices


@dataclass
class Replanner:
    """The state kept between the solves of one problem (see the module docstring).  `pool`: what solves the
    passes (default: forked processes when ``cfg.workers > 1``, made once, else this process); :meth:`close`
    ends a pool made here."""

    prob: Problem
    cfg: FleetConfig
    pool: PassPool | None = None
    prices: Prices | None = None  # where the last call left the prices (None: the first call starts as solve does)
    master: Master | None = None  # the master LP of the last call, its columns revalued (--price-step lp)
    calls: int = 0
    carry: str = "scale"  # how kept prices meet new values: "scale" (each task's by its cap's change) or "keep"
    _cap: np.ndarray | None = dataclasses.field(default=None, init=False, repr=False)  # caps the prices were found under

    def __post_init__(self) -> None:
        self.cfg.validate()
        self._own_pool = self.pool is None and self.cfg.workers > 1
        if self._own_pool:
            self.pool = ForkPool(self.prob, self.cfg)

    def revalue(self, values: np.ndarray | None) -> None:
        """What each (pass, task) is worth from now on (:meth:`Problem.set_values`; None: the weights); the
        master's columns take their new costs, the prices are kept."""
        self.prob.set_values(values)
        if self.master is not None:
            self.master.revalue()

    def solve(self, start: Start, time_limit: float | None = None) -> FleetSolution:
        """One solve from `start` within `time_limit` seconds from ``start.t0`` (None: the config's limit, or its
        ``rounds`` alone when that is unset), the prices and columns where the last call left them."""
        cfg = self.cfg if time_limit is None else dataclasses.replace(self.cfg, time_limit=time_limit)
        coord = coordinator(self.prob, cfg, start, self.pool)
        if self.prices is None:
            start_prices(coord, None)
        else:
            coord.prices = Prices(np.minimum(self.carried(), self.prob.cap), coord.windows, self.prices.mu.copy(),
                                  self.prices.factor)
        if self.master is not None and coord.master is not None:
            coord.master = self.master
        sol = run_checked(coord)
        self.prices, self.master, self._cap = coord.prices, coord.master, self.prob.cap.copy()
        self.calls += 1
        sol.info["replan_call"] = self.calls
        return sol

    def carried(self) -> np.ndarray:
        """The kept task prices for the values now: with ``carry="scale"`` each multiplied by its task's cap (its
        most valuable pass) now over the cap it was found under, since a task's price is the value it gives up in
        the pass that takes it and a forecast moves all of a task's values together (the cap of a task worth
        nothing then or now leaves its price as it is); with "keep", as they are.  Clipped at the cap by the
        caller."""
        lam = self.prices.lam
        if self.carry != "scale" or self._cap is None:
            return lam
        ratio = np.divide(self.prob.cap, self._cap, out=np.ones_like(lam), where=self._cap > 0)
        return lam * ratio

    def close(self) -> None:
        if self._own_pool:
            self.pool.close()
