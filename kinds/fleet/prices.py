"""The task prices of the fleet solver and their update: the Lagrangian dual of "a task is served at most once".

With a price ``lam[i] >= 0`` per task, each pass is solved on its own with utilities ``w[i] - lam[i]``, and

    L(lam) = sum over passes of (the pass optimum under lam) + sum of lam

bounds the weight any schedule can serve (energy relaxed).  A price round gives the pass terms (:meth:`Prices.
dual`); the prices then take a projected subgradient step by Polyak's rule towards the best schedule known
(:meth:`Prices.step_towards`), whose factor is halved when the bound stalls for three rounds (:meth:`Prices.
stalled`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STALL_ROUNDS = 3  # rounds without a better bound before the step factor is halved


@dataclass
class Prices:
    """The prices, the step factor and the rounds since the bound last improved."""

    lam: np.ndarray
    factor: float = 1.0
    stall: int = 0

    @classmethod
    def zero(cls, n_tasks: int) -> Prices:
        return cls(np.zeros(n_tasks))

    def dual(self, terms: list[float]) -> float:
        """L(lam): the pass terms (each pass's optimum or a bound of it under the prices) plus the prices."""
        total = float(self.lam.sum())
        for t in terms:
            total += t
        return total

    def step_towards(self, served: np.ndarray, dual: float, best: float) -> None:
        """Move the prices by a subgradient step: `served[i]` is how many passes of the round serve task i (the
        subgradient is 1 - served), the step Polyak's towards the best value known `best` from the dual value
        `dual`; a free task at price 0 cannot go lower."""
        g = 1.0 - served
        g[(self.lam <= 0) & (g > 0)] = 0.0
        norm2 = float(g @ g)
        if norm2 > 0:
            step = self.factor * max(dual - best, 1e-6 * dual) / norm2
            self.lam = np.maximum(0.0, self.lam - step * g)

    def stalled(self, improved: bool) -> None:
        """Count the rounds without a better bound; halve the step factor after :data:`STALL_ROUNDS` of them."""
        self.stall = 0 if improved else self.stall + 1
        if self.stall >= STALL_ROUNDS:
            self.factor, self.stall = self.factor / 2, 0
