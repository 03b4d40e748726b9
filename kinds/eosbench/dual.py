"""Task prices of the EOS-Bench solver from a linear program (``--price-step lp``): column generation on the
bound's own relaxation.

Whatever the prices lam, the solver's bound L(lam) (:func:`eosp.kinds.eosbench.solve.bound_round`) is at least the
value of the linear program

    max sum over c of v_c x_c   s.t.   sum over the c holding task i of x_c <= 1   (every task i)
                                       sum over the c of pass k of x_c <= 1        (every pass k),   x >= 0

over every path c of at most `cap` observations of every pass in the bound's relaxation (the code reading's
transitions, other passes ignored), v_c the priorities it serves.  Its row duals are prices at which L comes
closest to it, so the rounds take their prices from the LP over the paths met so far: each bound round's pass
paths of at most `cap` observations and the paths the moves committed are its new columns.
Raw duals jump between vertices, so the next prices are ``a * centre + (1 - a) * duals`` (Wentges, a =
:data:`SMOOTHING`), the centre the prices of the lowest L so far.  Measured on 10 satellites x 500 tasks, 40
fixed rounds: bound 2,742.4 against the conflict-free 2,753 that the uniform steps leave (same TP, 2,662 / 2,663);
the LP's floor is 2,733.0 (experiments/eosbench_lp.py).  Early rounds' L is far above the conflict-free bound
(4,264 at round 1, 2,887 at round 25), so it pays on long runs only.
"""

from __future__ import annotations

import math

import numpy as np

from eosp.budget import Budget

SMOOTHING = 0.5  # Wentges' a: the share of the centre in the next round's prices
LP_LIMIT_S = 5.0  # seconds one LP solve may take with a time limit (the centre's prices are kept beyond)


class PriceLP:
    """The restricted master LP (HiGHS, kept between rounds: each solve starts from the last basis)."""

    def __init__(self, prio: np.ndarray, n_passes: int) -> None:
        import highspy

        from eosp.kinds.lagrange import packing_highs

        self._hs = highspy
        self.prio = prio
        n = len(prio)
        self._h = packing_highs(n + n_passes)
        self.held: set = set()
        self.committed = 0  # how many of the solver's committed paths (State.columns, in insertion order) were added
        self.centre = np.zeros(n)
        self.centre_value = math.inf
        self.value = math.nan  # the LP's last optimum
        self.last_duals = np.zeros(n)

    def add(self, k: int, tasks: np.ndarray) -> bool:
        """The column of pass k serving `tasks` (once each); False when held already."""
        tasks = np.unique(tasks).astype(np.int32)
        key = (k, tasks.tobytes())
        if not len(tasks) or key in self.held:
            return False
        self.held.add(key)
        idx = np.r_[tasks, len(self.prio) + k].astype(np.int32)
        self._h.addCol(float(self.prio[tasks].sum()), 0.0, self._hs.kHighsInf, len(idx), idx, np.ones(len(idx)))
        return True

    def duals(self, budget: Budget) -> np.ndarray | None:
        """The task rows' duals of the LP over the columns held (clipped to the priorities; its value in
        :attr:`value`), or None when it is not solved (within `budget`, at most :data:`LP_LIMIT_S`; without a limit
        it is solved to the end, the same on every machine)."""
        h = self._h
        if budget.limited:
            left = min(LP_LIMIT_S, budget.left())
            h.setOptionValue("time_limit", float(h.getRunTime()) + max(0.01, left))
        h.run()
        if h.getModelStatus() != self._hs.HighsModelStatus.kOptimal:
            return None
        self.value = float(h.getInfo().objective_function_value)
        return np.minimum(np.abs(np.asarray(h.getSolution().row_dual[:len(self.prio)], dtype=np.float64)), self.prio)

    def next_prices(self, lam: np.ndarray, value: float, budget: Budget) -> np.ndarray:
        """The prices of the next round, given that L(`lam`) = `value` (inf when not proven): the LP's duals
        (:meth:`duals`, kept in :attr:`last_duals`) smoothed towards the centre, or the centre when the LP is not
        solved."""
        if value < self.centre_value:
            self.centre, self.centre_value = lam.copy(), value
        duals = self.duals(budget)
        if duals is None:
            return self.centre.copy()
        self.last_duals = duals
        if not math.isfinite(self.centre_value):
            return duals
        return SMOOTHING * self.centre + (1.0 - SMOOTHING) * duals
