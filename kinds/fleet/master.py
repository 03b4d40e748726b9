"""The restricted master linear program of the fleet solver's price rounds (``--price-step lp``).

The best Lagrangian bound, the minimum over task prices lam >= 0 of L(lam) (:mod:`eosp.kinds.lagrange`), is
the value of the linear program

    max sum over c of v_c x_c   s.t.   sum over the c holding task i of x_c <= 1   (every task i)
                                       sum over the c of pass p of x_c <= 1        (every pass p),   x >= 0

over every schedule c of every pass (v_c the weight of the tasks it serves): the passes' schedules convexified,
a task served at most once in all.  The master holds the schedules found so far (the price rounds' pass optima,
the paths of the schedules kept), and its row duals are task prices lam_LP and pass values; a price round at
task prices lam is exactly the pricing problem of column generation (a pass optimum worth more than its pass's
value under lam is a new column), and its L(lam) is a proven bound whatever lam is: the master only chooses lam.
Raw duals jump between vertices (a task's price at 0 or at its weight, from one round to the next), so the rounds
are taken at smoothed prices ``a * centre + (1 - a) * lam_LP`` (Wentges' rule, a = :data:`SMOOTHING`), the centre
the prices of the lowest L so far (:class:`Centre`).  Once no round adds a column and L equals the master's value,
lam is a minimiser: the Lagrangian bound can go no lower.  The same master, its columns integral
(:meth:`Master.integer`), is then a set packing of the pass schedules found; with the battery's energy windows as
rows (each column's energy with the slews between its observations) a packing the batteries nearly hold.

Why: measured on aeossp cases, the subgradient steps (``--price-step weighted``) end 120 s at L = 0.8272 of the
weight on test_easy/case_0003, where this master reaches the optimum 0.8250 in 35 rounds (9 s); on
test_hard/case_0005 0.8642 in about 30 rounds (20 s), which 96 subgradient rounds approach (0.8644).  The
battery's energy windows are left out of the master: at its optimum on test_hard/case_0005 their duals were 0
(with ``--energy-bound`` their multipliers are searched at each round's prices, :func:`eosp.kinds.fleet.dual.energy_search`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from eosp.budget import UNLIMITED, Budget
from eosp.fleet.energy import EnergyWindows
from eosp.kinds.fleet.problem import Problem, path_slew_wh, path_tasks, path_wh
from eosp.kinds.lagrange import packing_highs, quiet_highs, run_from

SMOOTHING = 0.5  # Wentges' a: the share of the centre in the prices of the next round
ENERGY_ROW_NONZEROS = 2_000_000  # entries of the integer program's energy rows at most (Master.energy_rows)


@dataclass
class Centre:
    """The prices of the lowest L seen (the stability centre of the smoothed prices)."""

    lam: np.ndarray
    value: float = np.inf

    def observe(self, lam: np.ndarray, value: float) -> None:
        if value < self.value:
            self.lam, self.value = lam.copy(), value

    def towards(self, lam_lp: np.ndarray) -> np.ndarray:
        """The next round's prices: the centre moved towards the master's duals."""
        return SMOOTHING * self.lam + (1.0 - SMOOTHING) * lam_lp


@dataclass
class Master:
    """The restricted master LP (HiGHS, kept between rounds so that each solve starts from the last basis): one
    row per task and per pass, one column per distinct schedule of a pass (its pass and its set of tasks)."""

    prob: Problem
    seen: dict = field(default_factory=dict)  # (pass, its tasks as bytes) -> the column's index
    value: float = 0.0  # the master's last optimum (the weight the columns serve, fractionally)
    solved: bool = False  # whether the last solve reached the optimum (its solution is then :meth:`ranked`)
    col_pass: list = field(default_factory=list)  # each column's pass
    col_path: list = field(default_factory=list)  # and its path in the pass graph
    col_wh: list = field(default_factory=list)  # its energy with its slews (energy_rows), computed when first needed

    def __post_init__(self) -> None:
        import highspy

        self._hs = highspy
        self._h = packing_highs(len(self.prob.weight) + len(self.prob.passes))

    @property
    def columns(self) -> int:
        return len(self.seen)

    def add(self, paths: list[np.ndarray]) -> int:
        """Every pass's schedule in `paths` (one path per pass) not held yet; returns how many were added."""
        n = len(self.prob.weight)
        cost, starts, index = [], [], []
        for p, path in enumerate(paths):
            if len(path) == 0:
                continue
            tasks = np.unique(path_tasks(self.prob, p, path))
            key = (p, tasks.tobytes())
            if key in self.seen:
                continue
            self.seen[key] = len(self.col_pass)
            self.col_pass.append(p)
            self.col_path.append(path)
            cost.append(self._cost(p, path))
            starts.append(len(index))
            index.extend(tasks.tolist())
            index.append(n + p)
        if cost:
            inf = self._hs.kHighsInf
            self._h.addCols(len(cost), np.asarray(cost), np.zeros(len(cost)), np.full(len(cost), inf), len(index),
                            np.asarray(starts, np.int32), np.asarray(index, np.int32), np.ones(len(index)))
        return len(cost)

    def _cost(self, p: int, path: np.ndarray) -> float:
        """What column (p, path) serves: its tasks' values in pass p (:meth:`Problem.pass_values`), summed in task
        order."""
        acq = np.unique(self.prob.passes[p].graph.node_acq[path])
        return float(self.prob.pass_values(p)[acq].sum())

    def revalue(self) -> None:
        """Every column's cost under the problem's values as they are now (:meth:`Problem.set_values`): the columns
        and the LP's basis are kept across a change of values (a re-plan starts from what the last one found),
        only what each column serves changes."""
        if self.col_pass:
            cost = np.array([self._cost(p, path) for p, path in zip(self.col_pass, self.col_path)])
            self._h.changeColsCost(len(cost), np.arange(len(cost), dtype=np.int32), cost)

    def duals(self, budget: Budget, iterations: int | None = None) -> np.ndarray | None:
        """The task prices of the master's optimum (its task rows' duals), or None when it was not solved to
        optimality within `budget` (the caller's cap of its own, :meth:`eosp.budget.Budget.cap`), or, with
        `iterations`, within that many simplex iterations instead of any time (the same on every machine and for any number of workers: a solve with
        a fixed number of rounds)."""
        if iterations is not None:
            self._h.setOptionValue("time_limit", self._hs.kHighsInf)
            self._h.setOptionValue("simplex_iteration_limit", int(iterations))
        else:
            limit = budget.left()
            # HiGHS compares its time limit with the run time of all the solves of this instance together: the
            # limit of this solve is counted from the time already run (else the master seemed to outgrow the
            # rounds once its solves added up to a round's time: at round 25 on a test_hard-like case)
            self._h.setOptionValue("time_limit", float(self._h.getRunTime()) + max(0.01, limit))
            self._h.setOptionValue("simplex_iteration_limit", 2**31 - 1)
        self._h.run()
        self.solved = self._h.getModelStatus() == self._hs.HighsModelStatus.kOptimal
        if not self.solved:
            return None
        self.value = float(self._h.getInfo().objective_function_value)
        d = np.abs(np.asarray(self._h.getSolution().row_dual[:len(self.prob.weight)], dtype=np.float64))
        return d  # prices above a weight are kept here (the smoothing needs them); the rounds clip them

    def ranked(self) -> list[tuple[int, np.ndarray]]:
        """The columns the master's last optimum uses, (pass, path), by decreasing share (ties by column order):
        where the LP is close to integral, as on the aeossp cases (0.8250 against schedules of 0.8228), taking them
        in this order is close to its optimum."""
        if not self.solved:
            return []
        x = np.asarray(self._h.getSolution().col_value, dtype=np.float64)
        used = np.flatnonzero(x > 1e-9)
        used = used[np.argsort(-x[used], kind="stable")]
        return [(self.col_pass[i], self.col_path[i]) for i in used.tolist()]

    def energy_rows(self, windows: EnergyWindows, start: list[np.ndarray], max_nonzeros: int = ENERGY_ROW_NONZEROS,
                    budget: Budget = UNLIMITED) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """The rows ``sum over the columns c of a window's passes of E_c x_c <= rhs`` of the battery's energy
        `windows`, E_c a column's energy with its slews (:func:`path_wh` + :func:`path_slew_wh`): the windows kept
        (indices), and the rows as CSR over them (starts, column indices, values).  At most `max_nonzeros`
        entries: beyond them the windows with the least slack under the schedule `start` (one path per pass) are
        kept first (a 200-satellite day has 258,185 windows of 33 passes each on average).  None when the columns'
        energies are not all computed within `budget` (those computed are kept)."""
        prob = self.prob
        for i in range(len(self.col_wh), len(self.col_pass)):
            if i % 256 == 0 and budget.expired():
                return None
            p, path = self.col_pass[i], self.col_path[i]
            self.col_wh.append(path_wh(prob.passes[p], path) + path_slew_wh(prob, p, path))
        col_pass = np.asarray(self.col_pass, dtype=np.int64)
        by_pass = np.argsort(col_pass, kind="stable")
        ptr = np.searchsorted(col_pass[by_pass], np.arange(len(prob.passes) + 1))
        count = ptr[windows.hi + 1] - ptr[windows.lo]
        keep = np.arange(len(windows))
        if int(count.sum()) > max_nonzeros:
            pass_wh = np.array([path_wh(prob.passes[p], path) + path_slew_wh(prob, p, path) if len(path) else 0.0
                                for p, path in enumerate(start)])
            slack = windows.rhs_wh - windows.used(pass_wh)
            keep = np.argsort(slack, kind="stable")
            keep = np.sort(keep[np.cumsum(count[keep]) <= max_nonzeros])
        wh = np.asarray(self.col_wh)
        starts = np.r_[0, np.cumsum(count[keep])[:-1]].astype(np.int32) if len(keep) else np.zeros(0, np.int32)
        index = [by_pass[ptr[lo]:ptr[hi + 1]] for lo, hi in zip(windows.lo[keep].tolist(), windows.hi[keep].tolist())]
        idx = np.concatenate(index) if index else np.zeros(0, np.int64)
        return keep, starts, idx.astype(np.int32), wh[idx]

    def integer(self, start: list[np.ndarray], limit: float, nodes: int | None = None,
                windows: EnergyWindows | None = None) -> list[int]:
        """The best integer solution of the master over the columns held (each pass one of its columns or none,
        each task at most once: a schedule apart from the battery) that HiGHS finds within `limit` seconds (and
        `nodes` branch-and-bound nodes when given: the same result on any machine when they end first), started from the
        schedule `start` (one path per pass; those of its paths the master holds, :meth:`add`).  With `windows`
        the battery's energy windows are rows as well (:meth:`energy_rows`: each column's energy with the slews
        between its observations; left out when computing them takes more than half of `limit`), so that the
        packing is one the batteries nearly hold.  The LP of the price
        rounds is left as it is (a copy is solved).  Returns the indices of its columns (:attr:`col_pass`,
        :attr:`col_path`); empty when none is found.

        Why: once the prices minimise L, the columns the rounds found hold schedules close to the LP's value
        (0.8213 of the weight on a generated test_hard-like case, where the moves stayed at 0.8070 for 90 s);
        picking the best integral combination of them is a set packing that the MIP solver settles where random
        recoveries and local moves do not."""
        m = len(self.col_pass)
        if m == 0:
            return []
        hs = self._hs
        h = quiet_highs()
        h.setOptionValue("threads", 1)
        h.passModel(self._h.getLp())
        h.changeColsIntegrality(m, np.arange(m, dtype=np.int32), np.full(m, hs.HighsVarType.kInteger))
        t0 = time.perf_counter()
        rows = None
        if windows is not None and len(windows):
            rows = self.energy_rows(windows, start, budget=Budget.of(0.5 * limit, start=t0))
        if rows is not None:  # without them when their energies take more than half the time
            keep, starts, idx, val = rows
            h.addRows(len(keep), np.full(len(keep), -hs.kHighsInf), windows.rhs_wh[keep], len(idx), starts, idx, val)
        h.setOptionValue("time_limit", max(0.01, float(limit) - (time.perf_counter() - t0)))
        if nodes is not None:
            h.setOptionValue("mip_max_nodes", int(nodes))
        x0 = np.zeros(m)
        for p, path in enumerate(start):
            i = self.seen.get((p, np.unique(path_tasks(self.prob, p, path)).tobytes())) if len(path) else None
            if i is not None:
                x0[i] = 1.0
        return run_from(h, x0)
