"""Local improvement of a complete schedule: the driver of planning's moves and windows (no torch, no Ray).

Why: what a learned policy typically loses is one or two decisions per episode, each
costing one acquisition in unitary mode or one low-priority acquisition in utility
mode (docs/results.md).  Those are exactly the schedules that one insertion or one
swap repairs, and checking a move costs a few binary searches, so every complete
schedule a learned search meets can be polished for milliseconds before the search
compares it with the others (``--polish``, on by default for sample, beam and mcts).

The moves (insert, swap, ruin and recreate: :mod:`eosp.planning.moves`) and window re-planning (a
stretch of the schedule planned again by a label sweep, which finds the sequences a first-fit refill
misses: :mod:`eosp.planning.windows`) are planning's kernels; every result is a path of the same graph
(:mod:`eosp.planning.chain`), so on the environment's graph it replays action by action and on the
unpruned graph it is a feasible schedule that may use arcs the pruning removed.  This module drives
them: :class:`Polisher` compiles them once per instance, polishes (insert and swap until none
improves) and refines (:meth:`Polisher.refine`: ruin and recreate alternating with rounds of windows,
their sizes and labels per node adapted to what the time allows).

Weights are the objective's (:func:`eosp.solvers.base.objective_weights`: the
utility, or 1 per acquisition), so a polished schedule is never worse than its input.
"""

from __future__ import annotations

import numpy as np

from eosp.planning.chain import graph_arrays, walk
from eosp.planning.moves import Candidates, Ruin, polish, ruin_recreate
from eosp.planning.windows import FIRST_WORK, LONG_BEAM, MAX_WORK, Sweep, WindowPlan, replan_windows, scratch

__all__ = ["Polisher", "walk"]


class Polisher:
    """Polish complete schedules of one instance: ``Polisher(graph, weights)(nodes) -> nodes``.

    `graph`: the arcs the moves may use, in canonical node order (a :class:`eosp.graphs.discrete.DiscreteGraph`,
    e.g. the unpruned one, or the environment's :class:`eosp.envs.core.EnvGraph`: anything with node_acq,
    node_time, indptr, dst, acq_ptr); `weights`: float [n] objective weight per acquisition.  The
    per-instance orders are computed once.  The pruned graph's arcs are a subset of the unpruned graph's, so
    a path of the environment is a path of either.  `window_graph`: the arcs window re-planning sweeps, a subset
    of `graph`'s on the same nodes (the pruned graph's); None: `graph`'s.
    """

    def __init__(self, graph, weights: np.ndarray, max_rounds: int = 20, max_replace: int = 8, window: int = 16,
                 window_beam: int = 4, window_graph=None):
        self.eg = eg = graph
        # the arcs window re-planning sweeps: `graph`'s, or a subset of them on the same nodes (the pruned
        # graph's, 3-10x fewer: what makes windows affordable where the unpruned graph has hundreds of arcs per
        # node); the moves and the re-chaining after a window use `graph`'s
        self.wg = wg = graph if window_graph is None else window_graph
        assert wg.node_acq.shape == eg.node_acq.shape, "the window graph must have the same nodes"
        self.window, self.window_beam = window, window_beam
        self.weight = np.asarray(weights, dtype=np.float64)
        acq_ptr = eg.acq_ptr
        self.first_t = eg.node_time[acq_ptr[:-1]].astype(np.float64)
        self.last_t = eg.node_time[acq_ptr[1:] - 1].astype(np.float64)
        self.span = float(np.max(self.last_t - self.first_t)) if self.first_t.size else 0.0
        self.order = np.lexsort((self.last_t, -self.weight)).astype(np.int64)
        # gains below this are not gains: 1e-12 of the largest weight (1e-4 for a top class of 1e8) still sees
        # the differences between two class-6 acquisitions (utilities ~1 that differ in the third decimal)
        self.tol = 1e-12 * max(float(np.max(self.weight)) if self.weight.size else 1.0, 1e-300)
        self.max_rounds = max_rounds
        self.max_replace = max_replace
        self.rounds = 0
        # on_improve(nodes, value): told of each better schedule met (the solvers' incumbent, for Ctrl-C)
        self.on_improve = None
        # compile (or load from numba's cache) the kernels for these array types now, with empty schedules, so
        # that a search's time limit, which starts after the set-up, never pays for the compilation
        empty = np.zeros(1, dtype=np.int32)
        self.g, self.w_arrays = graph_arrays(eg), graph_arrays(wg)
        self.cand = Candidates(self.weight, self.order, self.first_t, self.last_t, self.span)
        polish(self.g, self.cand, empty, 0, 0, self.tol, 1)
        walk(eg, np.zeros(0, dtype=np.int64))
        ruin_recreate(self.g, self.cand, empty, 0, Ruin(0, 1, 1.0, 0), self.tol)
        # window re-planning (planning/windows.py): nodes by time, and a random 64-bit key per acquisition whose
        # XOR over a label's acquisitions tells equal sets apart
        self._repair, self._max_work, self._first_work = replan_windows, MAX_WORK, FIRST_WORK
        self.window_time = 0.5  # the share of the time left one window may take at most
        # the most time window re-planning may take over the ruin and recreate's: at 1000-1500 acquisitions the
        # windows find what is left (a long window takes ~0.5-1.3 s there), the ruin and recreate little
        self.window_ratio = 3.0
        self.long_beam = LONG_BEAM  # the most labels per node of a long window
        self._scratch = scratch(wg, max(window_beam, self.long_beam), MAX_WORK)
        self.by_time = (np.argsort(eg.node_time[1:], kind="stable") + 1).astype(np.int32)
        self.sorted_t = eg.node_time[self.by_time].astype(np.float64)
        self.key = np.random.default_rng(0).integers(1, 2**63, size=eg.acq_ptr.shape[0] - 1, dtype=np.uint64)
        self._run_windows(empty, 0, 0, 0, 0)

    def __call__(self, nodes) -> np.ndarray:
        eg = self.eg
        n_acq = eg.acq_ptr.shape[0] - 1
        path = np.zeros(n_acq + 1, dtype=np.int32)
        nodes = np.asarray(nodes, dtype=np.int32)
        path[: nodes.size] = nodes
        n = polish(self.g, self.cand, path, nodes.size, self.max_rounds, self.tol, self.max_replace)
        self._tell(path[:n])
        return path[:n].copy()

    def _tell(self, nodes) -> None:
        """Report `nodes` (a complete schedule) to :attr:`on_improve`, when one is set."""
        if self.on_improve is not None:
            self.on_improve(nodes, self.value(nodes))

    def refine(self, nodes, *, deadline: float | None = None, iterations: int = 2000, seed: int = 0,
               max_ruin: int = 6, noise: float = 1.0, windows: bool = True) -> np.ndarray:
        """Ruin-and-recreate from `nodes` (see :func:`eosp.planning.moves.ruin_recreate`) until `deadline`
        (time.perf_counter()) or for `iterations`, then one polish; the best schedule met (never worse than `nodes`).

        With `windows`, rounds of window re-planning (:mod:`eosp.planning.windows`) alternate with the ruin
        and recreate, a round after each of its rounds until the windows took `window_ratio` (3) times its
        time (16 windows a round when there is no deadline); half of the windows are long ones (up to the whole
        schedule, with 1 label per node, then twice as many after each round of them, up to `long_beam`); when
        most windows of a round were too costly to plan (graphs of hundreds of arcs per node), long ones go back
        to half their labels, and the stretches are halved, down to none.
        """
        import time

        eg = self.eg
        n_acq = eg.acq_ptr.shape[0] - 1
        path = np.zeros(n_acq + 1, dtype=np.int32)
        nodes = np.asarray(nodes, dtype=np.int32)
        path[: nodes.size] = nodes
        n, done, chunk = nodes.size, 0, 64
        t_rr = t_win = 0.0
        # rate: arcs looked at per second of windows (all rounds so far: one round's short or long windows alone
        # may sweep at half or twice the mean rate, and a long window given too few arcs stops); long windows
        # may span the whole schedule, with one label per node at first, twice as many after each round of them
        # (up to beam_cap)
        use_windows, span, long_span, rate, all_arcs = windows, self.window, n_acq, 0.0, 0
        long_beam, beam_cap = 1, self.long_beam
        self.window_rounds = 0
        while (deadline is None and done < iterations) or (deadline is not None and time.perf_counter() < deadline):
            t0 = time.perf_counter()
            n = ruin_recreate(self.g, self.cand, path, n, Ruin(chunk, max_ruin, noise, seed + done), self.tol)
            t1 = time.perf_counter()
            t_rr += t1 - t0
            # without a deadline: 16 windows per round (deterministic); with one: a round of windows after each
            # round of ruin and recreate, its arcs budgeted to that round's time at the rate measured so far (a
            # small probe first), unless the windows already took window_ratio times the ruin and recreate's time
            # (a window runs to its end, past its round's budget: a long one takes 0.5-1.3 s at 1000-1500
            # acquisitions, a round of ruin and recreate 0.1-0.5 s); one window given half of the time left at
            # most, so that the limit holds
            probe = deadline is not None and rate == 0.0
            if use_windows and (deadline is None or (t_win <= self.window_ratio * t_rr and t1 < deadline)):
                if deadline is None:
                    # of the first round's size: nothing else bounds them, so a refinement without a time limit
                    # (lns's default) keeps each window to 3M arcs
                    count, budget, work = 16, np.iinfo(np.int64).max, self._first_work
                elif probe:  # a probe of the rate: its windows stop early and say nothing of their cost
                    count, budget, work = 1 << 20, self._first_work, self._first_work
                else:  # as many windows as the budget allows
                    count = 1 << 20
                    budget = int(rate * min(t1 - t0, 0.5 * (deadline - t1)))
                    work = int(min(self._max_work, max(rate * self.window_time * (deadline - t1), 1.0)))
                n, tried, aborted, arcs, long_tried, long_aborted = self._run_windows(
                    path, n, count, budget, seed + done, span, long_span, work, long_beam)
                dt = time.perf_counter() - t1
                t_win += dt
                all_arcs += arcs
                rate = all_arcs / max(t_win, 1e-6) if all_arcs > 0 else rate
                self.window_rounds += tried
                # (not after the probe) most windows of a kind too costly to plan: the long ones back to half
                # their labels per node for good, then shorter ones; the short ones shorter, then none (apart:
                # long ones that stop at their bound must not shrink the short ones).  Long windows that all
                # ran: twice the labels per node for the next ones, as RAMP's beam is raised with the time (at
                # 1000-1500 acquisitions the last utilities RAMP finds need 2-8 labels per node; each width
                # costs about twice the one before, so the widths before the last take no more than the last)
                short_tried, short_aborted = tried - long_tried, aborted - long_aborted
                if not probe:
                    if long_tried and 2 * long_aborted > long_tried:
                        if long_beam > 1:
                            long_beam = beam_cap = long_beam // 2
                        else:
                            long_span //= 2
                    elif long_tried and long_aborted == 0:
                        long_beam = min(2 * long_beam, beam_cap)
                    if short_tried and 2 * short_aborted > short_tried:
                        use_windows = span > 1
                        span = max(1, span // 2)
            done += chunk
            self._tell(path[:n])
        self.rounds = done
        return self(path[:n])

    def _run_windows(self, path, n, count, budget, seed, span=1, long_span=0, max_work=None, long_beam=1):
        """`count` windows of 1..span positions at most (or, half of them, 1..long_span with `long_beam` labels
        per node: :func:`eosp.planning.windows.replan_windows`), until `budget` arcs: (length, tried, aborted, arcs,
        long tried, long aborted)."""
        sw = Sweep(self.weight, self.key, self.span, self.by_time, self.sorted_t, self.tol,
                   self._max_work if max_work is None else max_work)
        plan = WindowPlan(span, self.window_beam, long_span, long_beam, count, seed, budget)
        return self._repair(self.g, self.w_arrays, sw, path, n, plan, self._scratch)

    def nodes_of(self, actions) -> np.ndarray:
        """The path that playing acquisitions `actions` from the source follows (each one's arc)."""
        out = walk(self.eg, actions)
        if isinstance(out, int):
            raise ValueError(f"action {out} (acquisition {int(actions[out])}) has no arc from the previous node")
        return out

    def value(self, nodes) -> float:
        nodes = np.asarray(nodes, dtype=np.int64)
        return float(self.weight[self.eg.node_acq[nodes]].sum()) if nodes.size else 0.0

    def actions(self, actions) -> tuple[float, list]:
        """Polish the schedule that `actions` play; its objective value and the actions that play it."""
        nodes = self(self.nodes_of(actions))
        return self.value(nodes), [int(a) for a in self.eg.node_acq[nodes]]
