"""What solves the passes of a price round and of a coordinate-descent sweep: :class:`PassPool`, and its
in-process and forked implementations (the Ray actors' is :class:`eosp.kinds.fleet.raypool.RayPassPool`).

For a price round a pool takes pass ids, the task prices and the passes' energy prices (one vector each,
:mod:`eosp.kinds.lagrange`), never utilities: whoever holds a pass's graph prices its tasks
(:func:`eosp.kinds.fleet.problem.priced`), so a round sends two vectors of prices and gets paths back.  A sweep of
the coordinate descent (:func:`eosp.kinds.fleet.construct.descend`) depends on the schedule (a task
another pass serves is worth 0 to this one), which only the driver holds: it sends each pass's utilities,
packed as one flat float64 vector and CSR offsets (a sweep of thousands of passes would be thousands of small
objects otherwise).  The pass graphs stay where they were built: in this process, in forked children that
share them, or on Ray actors that own whole satellites (the driver then holds its passes without arcs, a lean
:class:`~eosp.kinds.fleet.problem.Problem`, and sends every solve to the pool); the protocol names passes, never
graphs.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from eosp.kinds.fleet.config import FleetConfig
from eosp.budget import Budget
from eosp.kinds.fleet.problem import PassResult, PassSpec, Problem, priced, solve_pass, solve_round_pass


class PassPool(Protocol):
    """Solves passes under task prices and energy prices.  A pool whose workers run beside the driver may also
    offer ``submit_priced(passes, prices, pass_prices, budget)``: :meth:`solve_priced` sent now, returning a
    function that waits for its result (Ray's actors; the coordinator then solves the next price round while it
    recovers a schedule, :func:`eosp.kinds.fleet.dual.prefetch`; the function may offer
    ``idle()``: whether the workers have finished that round, so that a sweep sent now would not wait behind it);
    it then says, as ``round_solve_s``, the seconds of solves of its busiest worker in the last round it returned
    (the master LP's time limit: the time since such a round was sent counts the recovery it ran beside).  Such a
    pool may also offer ``repair_rows(rows, budget)``: the battery repair of some satellites
    (:func:`eosp.fleet.timeline.repair_rows`, its result), each on the worker that owns it."""

    def solve_priced(self, passes: list[int], prices: np.ndarray, pass_prices: np.ndarray,
                     budget: Budget) -> dict[int, PassResult] | None:
        """Every pass p of `passes` with utilities weight - price - pass_prices[p] * energy of its tasks
        (:func:`eosp.kinds.fleet.problem.solve_round_pass`: its path and its term of the bound); None when the
        budget ran out first (no pass solve runs much past it)."""
        ...

    def solve_utilities(self, passes: list[int], util: np.ndarray, offsets: np.ndarray,
                        budget: Budget) -> dict[int, PassResult] | None:
        """Every pass ``passes[i]`` with utilities ``util[offsets[i]:offsets[i + 1]]`` (one per task of the pass,
        :attr:`PassGraph.tasks` order; non-positive ones left out) by the pass solver alone
        (:func:`eosp.kinds.fleet.problem.solve_pass_graph`: its path and value, no bound problem); None when the
        budget ran out first.  Without a time limit the exact solver is deterministic, so the result is the same
        wherever a pass is solved."""
        ...

    def close(self) -> None: ...


class InProcessPool:
    """The passes solved in this process, one after another (the budget checked before each)."""

    def __init__(self, prob: Problem, cfg: FleetConfig):
        self.prob, self.spec = prob, PassSpec.of(cfg)

    def solve_priced(self, passes: list[int], prices: np.ndarray, pass_prices: np.ndarray,
                     budget: Budget) -> dict[int, PassResult] | None:
        out = {}
        for p in passes:
            if budget.expired():
                return None
            out[p] = solve_priced_pass(self.prob, p, prices, pass_prices, self.spec, budget)
        return out

    def solve_utilities(self, passes: list[int], util: np.ndarray, offsets: np.ndarray,
                        budget: Budget) -> dict[int, PassResult] | None:
        return solve_utility_passes(self.prob, self.spec, passes, util, offsets, budget)

    def close(self) -> None:
        pass


def solve_utility_passes(prob: Problem, spec: PassSpec, passes: list[int], util: np.ndarray, offsets: np.ndarray,
                         budget: Budget) -> dict[int, PassResult] | None:
    """:meth:`PassPool.solve_utilities` in this process, one pass after another (the budget checked before
    each)."""
    out = {}
    for i, p in enumerate(passes):
        if budget.expired():
            return None
        out[p] = solve_pass(prob, p, util[offsets[i]:offsets[i + 1]], spec, budget)
    return out


def solve_priced_pass(prob: Problem, p: int, prices: np.ndarray, pass_prices: np.ndarray, spec: PassSpec,
                      budget: Budget, value: np.ndarray | None = None) -> PassResult:
    """Pass `p` of a price round (:func:`eosp.kinds.fleet.problem.solve_round_pass`) under the prices; `value`:
    what its tasks are worth (default: :meth:`Problem.pass_values`)."""
    pg = prob.graph(p)
    value = prob.pass_values(p) if value is None else value
    return solve_round_pass(pg, priced(value, prices[pg.tasks], pg.energy_wh, pass_prices[p]), spec, budget)


_FORKED: tuple[Problem, PassSpec] | None = None  # the problem and pass spec a forked worker inherits


def _ignore_sigint() -> None:
    """A pool worker leaves Ctrl-C to its parent (a terminal sends SIGINT to the whole process group): the parent
    keeps the best schedule and terminates the pool, instead of every worker printing a traceback."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _solve_chunk(args: tuple[list[int], np.ndarray, np.ndarray, Budget, list | None]) -> list[PassResult]:
    passes, prices, pass_prices, budget, values = args
    prob, spec = _FORKED
    return [solve_priced_pass(prob, p, prices, pass_prices, spec, budget, None if values is None else values[i])
            for i, p in enumerate(passes)]


def _solve_utility_chunk(args: tuple[list[int], np.ndarray, np.ndarray, Budget]) -> list[PassResult]:
    passes, util, offsets, budget = args
    prob, spec = _FORKED
    return [solve_pass(prob, p, util[offsets[i]:offsets[i + 1]], spec, budget) for i, p in enumerate(passes)]


class ForkPool:
    """Processes that solve passes under given prices.  They are forked once the pass graphs are built, so every
    worker holds them without any copy; a round sends only pass ids and prices, and gets paths back."""

    def __init__(self, prob: Problem, cfg: FleetConfig):
        import multiprocessing

        global _FORKED
        _FORKED = (prob, PassSpec.of(cfg))
        self.prob = prob
        self.workers = cfg.workers
        self.pool = multiprocessing.get_context("fork").Pool(cfg.workers, initializer=_ignore_sigint)

    def solve_priced(self, passes: list[int], prices: np.ndarray, pass_prices: np.ndarray,
                     budget: Budget) -> dict[int, PassResult] | None:
        """Every pass of `passes` (in chunks, about four per worker; the children share this machine's clock, so
        the budget goes as it is)."""
        n = max(1, len(passes) // (4 * self.workers))
        chunks = [(passes[i:i + n], prices, pass_prices, budget, self._values(passes[i:i + n]))
                  for i in range(0, len(passes), n)]
        return self._map(_solve_chunk, chunks, budget)

    def _values(self, passes: list[int]) -> list | None:
        """What the tasks of `passes` are worth, when the problem has values (they may have changed since the
        workers were forked: a re-plan's revaluation); None without."""
        return None if self.prob.values is None else [self.prob.pass_values(p) for p in passes]

    def solve_utilities(self, passes: list[int], util: np.ndarray, offsets: np.ndarray,
                        budget: Budget) -> dict[int, PassResult] | None:
        """Every pass of `passes` under its utilities (in chunks, about four per worker, each with its slice of
        the flat utilities)."""
        n = max(1, len(passes) // (4 * self.workers))
        chunks = []
        for i in range(0, len(passes), n):
            j = min(i + n, len(passes))
            chunks.append((passes[i:j], util[offsets[i]:offsets[j]], offsets[i:j + 1] - offsets[i], budget))
        return self._map(_solve_utility_chunk, chunks, budget)

    def _map(self, fn, chunks: list[tuple], budget: Budget) -> dict[int, PassResult] | None:
        """`fn` over the chunks on the workers (each chunk's first item its pass ids): the results by pass, or
        None when the budget ran out first."""
        import multiprocessing

        job = self.pool.map_async(fn, chunks)
        timeout = budget.wire()
        try:
            results = job.get(timeout)
        except multiprocessing.TimeoutError:
            return None
        return {p: r for chunk, res in zip(chunks, results) for p, r in zip(chunk[0], res)}

    def close(self) -> None:
        self.pool.terminate()
        self.pool.join()
