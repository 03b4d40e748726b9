"""What solves the passes of a price round: :class:`PassPool`, and its in-process and forked implementations
(the Ray actors' is :class:`jobs.solve_fleet.RayPassPool`).

A pool takes pass ids, the task prices and the passes' energy prices (one vector each, :mod:`eosp.kinds.fleet.
prices`), never utilities: whoever holds a pass's graph prices its tasks (:func:`eosp.kinds.fleet.problem.priced`),
so a round sends two vectors of prices and gets paths back.  The pass
graphs stay where they were built: in this process, in forked children that share them, or on Ray actors that
own whole satellites.  The same split is where the rest of the loop (coordinate descent, battery repair, the
moves) can move to the owners of the satellites later: the protocol names passes, never graphs.
"""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np

from eosp.kinds.fleet.config import FleetConfig
from eosp.kinds.fleet.problem import PassResult, Problem, priced, solve_round_pass


class PassPool(Protocol):
    """Solves passes under task prices and energy prices."""

    def solve_priced(self, passes: list[int], prices: np.ndarray, pass_prices: np.ndarray,
                     deadline: float | None) -> dict[int, PassResult] | None:
        """Every pass p of `passes` with utilities weight - price - pass_prices[p] * energy of its tasks
        (:func:`eosp.kinds.fleet.problem.solve_round_pass`: its path and its term of the bound); None when the
        deadline (a ``time.perf_counter()`` instant) came first (no pass solve runs much past it)."""
        ...

    def close(self) -> None: ...


class InProcessPool:
    """The passes solved in this process, one after another (the deadline checked before each)."""

    def __init__(self, prob: Problem, cfg: FleetConfig):
        self.prob, self.cfg = prob, cfg

    def solve_priced(self, passes: list[int], prices: np.ndarray, pass_prices: np.ndarray,
                     deadline: float | None) -> dict[int, PassResult] | None:
        out = {}
        for p in passes:
            if deadline is not None and time.perf_counter() > deadline:
                return None
            out[p] = solve_priced_pass(self.prob, p, prices, pass_prices, self.cfg, deadline)
        return out

    def close(self) -> None:
        pass


def solve_priced_pass(prob: Problem, p: int, prices: np.ndarray, pass_prices: np.ndarray, cfg: FleetConfig,
                      deadline: float | None) -> PassResult:
    """Pass `p` of a price round (:func:`eosp.kinds.fleet.problem.solve_round_pass`) under the prices."""
    pg = prob.passes[p]
    return solve_round_pass(pg, priced(prob.weight, prices, pg.tasks, pg.energy_wh, pass_prices[p]), cfg, deadline)


_FORKED: tuple[Problem, FleetConfig] | None = None  # the problem and config a forked worker inherits


def _ignore_sigint() -> None:
    """A pool worker leaves Ctrl-C to its parent (a terminal sends SIGINT to the whole process group): the parent
    keeps the best schedule and terminates the pool, instead of every worker printing a traceback."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _solve_chunk(args: tuple[list[int], np.ndarray, np.ndarray, float | None]) -> list[PassResult]:
    passes, prices, pass_prices, deadline = args
    prob, cfg = _FORKED
    return [solve_priced_pass(prob, p, prices, pass_prices, cfg, deadline) for p in passes]


class ForkPool:
    """Processes that solve passes under given prices.  They are forked once the pass graphs are built, so every
    worker holds them without any copy; a round sends only pass ids and prices, and gets paths back."""

    def __init__(self, prob: Problem, cfg: FleetConfig):
        import multiprocessing

        global _FORKED
        _FORKED = (prob, cfg)
        self.workers = cfg.workers
        self.pool = multiprocessing.get_context("fork").Pool(cfg.workers, initializer=_ignore_sigint)

    def solve_priced(self, passes: list[int], prices: np.ndarray, pass_prices: np.ndarray,
                     deadline: float | None) -> dict[int, PassResult] | None:
        """Every pass of `passes` (in chunks, about four per worker; the children share this machine's clock)."""
        import multiprocessing

        n = max(1, len(passes) // (4 * self.workers))
        chunks = [(passes[i:i + n], prices, pass_prices, deadline) for i in range(0, len(passes), n)]
        job = self.pool.map_async(_solve_chunk, chunks)
        timeout = None if deadline is None else max(0.0, deadline - time.perf_counter())
        try:
            results = job.get(timeout)
        except multiprocessing.TimeoutError:
            return None
        return {p: r for chunk, res in zip(chunks, results) for p, r in zip(chunk[0], res)}

    def close(self) -> None:
        self.pool.terminate()
        self.pool.join()
