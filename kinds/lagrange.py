"""The Lagrangian pieces two kinds share (the fleet solver, :mod:`eosp.kinds.fleet`, and the EOS-Bench solver,
:mod:`eosp.kinds.eosbench`): the prices and their steps (:class:`Prices`), the set-packing model of a master LP or
integer program over pass schedules (:func:`packing_highs`) and a binary program run from a start
(:func:`run_from`).  Written here for the fleet's terms: the Lagrangian dual of "a task is served at most once" and
of the battery's energy windows (:mod:`eosp.fleet.energy`; EOS-Bench has none, ``windows=None``).

With a price ``lam[i] >= 0`` per task and a multiplier ``mu[w] >= 0`` per energy window w (its inequality
``sum of e_o over the observations of its passes <= R_w``), each pass p is solved on its own with utilities
``w[i] - lam[i] - pi[p] * e[i]`` (w[i] the task's weight, or its value in pass p when the problem has values:
:meth:`eosp.kinds.fleet.problem.Problem.set_values`; the argument below holds for either), ``pi[p]`` the sum of the multipliers of the windows holding p (per Wh), and

    L(lam, mu) = sum over passes of (the pass optimum under these utilities) + sum of lam + sum of mu[w] R_w

bounds the weight any valid schedule can serve.  Why, for a valid schedule x observing the tasks c_p(x) in pass
p (repeats allowed, each credited once; E_p(x) the sum of e_o over all its observations in p):

* a pass's term is at least ``sum over c_p(x) of (w - lam)^+ - pi[p] E_p(x)``: the pass's bound problem credits
  each task observed once at ``(w - lam - pi e)^+`` (:func:`eosp.fleet.passgraph.bound_problem`; where the pass
  graph serves the bound, its priced optimum is that), and ``(w - lam)^+ - pi e <= (w - lam - pi e)^+`` for the
  observation credited, ``-pi e <= 0`` for any other (a bridge, a repeat);
* summed over passes, ``- sum_p pi[p] E_p(x) = - sum_w mu[w] * (the energy of x in w)``, and with
  ``mu[w] R_w`` added this is ``sum_w mu[w] (R_w - energy of x in w) >= 0``: x is valid, so its battery keeps
  every window's inequality;
* what is left, ``sum lam + sum_p sum over c_p(x) of (w - lam)^+``, is at least the weight x serves (a served
  task's ``lam + (w - lam)^+ >= w``; an unserved one's ``lam >= 0``).

A price round gives the pass terms (:meth:`Prices.dual`); the prices then take one projected subgradient step
by Polyak's rule towards the best schedule known (:meth:`Prices.step_towards`): a task's component is 1 - (the
passes serving it), a window's ``(R_w - energy of the round's paths in w) / scale_w`` (each window's inequality
measured in typical observations of its satellite), each part with its own Polyak norm, the task prices' in
the metric of the task weights by default (``--price-step weighted``: each price moves in proportion to its
weight); the step factor is halved when the bound stalls for three rounds (:meth:`Prices.stalled`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eosp.fleet.energy import EnergyWindows

STALL_ROUNDS = 3  # rounds without a better bound before the step factor is halved
ENERGY_SHARE = 0.5  # the multipliers' Polyak step, as a share of the one that alone would close the gap


@dataclass
class Prices:
    """The task prices, the energy windows' multipliers, the step factor and the rounds since the bound last
    improved."""

    lam: np.ndarray
    windows: EnergyWindows | None = None  # None: no energy window (task prices only)
    mu: np.ndarray = field(default=None)  # per window, in typical observations of its satellite (scale_wh)
    factor: float = 1.0
    stall: int = 0

    def __post_init__(self) -> None:
        if self.windows is None:
            self.windows = EnergyWindows.none(0)
        if self.mu is None:
            self.mu = np.zeros(len(self.windows))

    @classmethod
    def zero(cls, n_tasks: int, windows: EnergyWindows | None = None) -> Prices:
        return cls(np.zeros(n_tasks), windows)

    def pass_price(self) -> np.ndarray:
        """Each pass's price of a Wh (the sum of the multipliers of the windows holding it)."""
        return self.windows.pass_price(self.mu)

    def dual(self, terms: list[float]) -> float:
        """L(lam, mu): the pass terms (each pass's optimum or a bound of it under the prices) plus the prices and
        the multipliers times their windows' right-hand sides."""
        total = float(self.lam.sum()) + float(self.mu @ (self.windows.rhs_wh / self.windows.scale_wh))
        for t in terms:
            total += t
        return total

    def step_towards(self, served: np.ndarray, dual: float, best: float, pass_wh: np.ndarray | None = None,
                     scale: np.ndarray | None = None, tasks: bool = True) -> None:
        """Move the prices by a subgradient step: `served[i]` is how many passes of the round serve task i, and
        `pass_wh[p]` the energy (sum of e_o) of pass p's path of the round (None: no window); the step Polyak's
        towards the best value known `best` from the dual value `dual`, taken by the task prices and the
        multipliers each with its own norm (the multipliers :data:`ENERGY_SHARE` of theirs): one norm over both
        let thousands of windows shrink the task prices' steps until the bound stalled above the conflict-free
        one (test_hard); any nonnegative prices give a valid bound, so the step rule is a matter of speed only;
        a price or multiplier at 0 cannot go lower.  With `scale` (a positive number per task: ``--price-step
        weighted`` gives the task weights) the task prices' step is Polyak's in that metric: price i moves by
        ``target * scale[i] * g[i] / sum(scale * g^2)``, so a task's price moves in proportion to its weight (from
        prices proportional to the weights, as the heuristic start and the ceiling prices are, the uniform step moves
        a light and a heavy task by the same amount)."""
        g = 1.0 - served
        g[(self.lam <= 0) & (g > 0)] = 0.0
        win = self.windows
        h = (win.rhs_wh - win.used(pass_wh)) / win.scale_wh if pass_wh is not None else np.zeros(len(win))
        h[(self.mu <= 0) & (h > 0)] = 0.0
        target = self.factor * max(dual - best, 1e-6 * dual)
        d = g if scale is None else scale * g
        if tasks and float(g @ d) > 0:  # tasks=False: the multipliers only (the task prices set otherwise)
            self.lam = np.maximum(0.0, self.lam - target / float(g @ d) * d)
        if float(h @ h) > 0:
            self.mu = np.maximum(0.0, self.mu - ENERGY_SHARE * target / float(h @ h) * h)

    def stalled(self, improved: bool) -> None:
        """Count the rounds without a better bound; halve the step factor after :data:`STALL_ROUNDS` of them."""
        self.stall = 0 if improved else self.stall + 1
        if self.stall >= STALL_ROUNDS:
            self.factor, self.stall = self.factor / 2, 0


def quiet_highs():
    """A HiGHS instance that prints nothing: its constructor writes a banner to the process's standard output
    (file descriptor 1, below Python's sys.stdout), which would land in the middle of a command's output."""
    import os
    import sys

    import highspy

    sys.stdout.flush()
    saved, null = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        h = highspy.Highs()
        h.setOptionValue("output_flag", False)
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)
    return h


def packing_highs(rows: int):
    """A quiet, one-thread HiGHS model that maximises, with `rows` rows ``sum of its columns <= 1`` and no column
    yet: a set packing's (one row per task and per pass; the columns, each a pass's schedule, come later)."""
    import highspy

    h = quiet_highs()
    h.setOptionValue("threads", 1)
    h.changeObjectiveSense(highspy.ObjSense.kMaximize)
    h.addRows(rows, np.full(rows, -highspy.kHighsInf), np.ones(rows), 0, np.zeros(0, np.int32), np.zeros(0, np.int32),
              np.zeros(0))
    return h


def run_from(h, x0: np.ndarray) -> list[int]:
    """Run the binary program `h` (HiGHS) from the solution `x0` (0/1 per column; the solver keeps it if it finds
    none better); the columns set in the best solution found, [] when there is none."""
    import highspy

    sol = highspy.HighsSolution()
    sol.col_value = np.asarray(x0, dtype=np.float64).tolist()
    sol.value_valid = True
    h.setSolution(sol)
    h.run()
    x = np.asarray(h.getSolution().col_value, dtype=np.float64)
    if len(x) != len(x0):
        return []
    return np.flatnonzero(x > 0.5).tolist()
