"""The dual side of a solve over its state (:class:`Coordinator`): price rounds (every pass under the task prices
and the energy multipliers on the pass pool, the Lagrangian bound when every term is proven, the price step or the
master LP's duals), the ceiling round before the first, the energy windows' line searches, and the next round sent
ahead (prefetch) while the driver recovers a schedule.
"""

from __future__ import annotations

import time

import numpy as np

from eosp.budget import Budget
from eosp.kinds.fleet.coordinator import Coordinator
from eosp.kinds.lagrange import Prices
from eosp.kinds.fleet.problem import PassResult, path_wh, priced

MASTER_MIN_S = 1.0  # seconds a master LP solve may always take (else at most the round's pass solves' time)
MASTER_MIN_ITERATIONS = 1000  # simplex iterations a master LP solve may always take when rounds are fixed
MASTER_PATIENCE = 3  # master solves in a row cut by that time before the master is dropped (weighted steps then;
# before a first solve has finished in its time, one miss drops it)
ENERGY_STEPS = 12  # bisection steps of an energy window's multiplier (energy_search)


def _dual_round(c: Coordinator, lam: np.ndarray, budget: Budget) -> tuple | None:
    """Every pass under task prices `lam` and the current energy multipliers (on the pool): L(lam, mu), whether
    every pass term is proven, each task's serve count, each pass's energy and path; None when the
    budget ran out.  A price above its task's weight is taken at the weight: no pass takes the task either way (its
    utility is not positive), so the pass terms are the same and L is lower."""
    lam = np.minimum(lam, c.prob.cap)
    pi = c.prices.pass_price()
    todo = np.flatnonzero(~c.frozen).tolist()
    pending, c._pending = c._pending, None
    t = time.perf_counter()
    if pending is not None and np.array_equal(pending[0], lam) and np.array_equal(pending[1], pi):
        solved = pending[2]()  # sent before the last recovery (prefetch): the same prices, the same passes
        c.prefetched += 1
        # the master's limit: what the round took on the pool (its busiest worker's solves), not the time
        # since it was sent (that counts the recovery it ran beside)
        c._solve_s = getattr(c.pool, "round_solve_s", None) or time.perf_counter() - pending[3]
    else:
        solved = c.pool.solve_priced(todo, lam, pi, budget)
        c._solve_s = time.perf_counter() - t
    c._wait_s = time.perf_counter() - t
    if solved is None:
        return None  # the budget ran out
    c.pass_solves += len(todo)
    paths = [np.zeros(0, np.int64)] * len(c.prob.passes)
    terms, proven = [], True
    for p in range(len(c.prob.passes)):
        if c.frozen[p]:  # a fixed term: its schedule under the prices
            pg, path = c.prob.passes[p], c.initial.paths[p]
            acq = pg.graph.node_acq[path]
            value = float(priced(c._values_of(p)[acq], _frozen_lam(c, p, acq, lam), pg.energy_wh[acq], pi[p]).sum())
            res = PassResult(path, value, value)
        else:
            res = solved[p]
        paths[p] = res.nodes
        proven &= res.bound is not None
        terms.append(res.value if res.bound is None else res.bound)
    count, pass_wh = _path_stats(c, paths)
    total = Prices(lam, c.prices.windows, c.prices.mu).dual(terms)
    c._terms = np.asarray(terms, dtype=np.float64)  # the round's pass terms (the energy search starts there)
    return total, proven, count, pass_wh, paths


def _frozen_lam(c: Coordinator, p: int, acq: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """The task prices a frozen pass's observations `acq` pay in its fixed term: their tasks' prices where they
    serve them, 0 where frozen observations serve nothing (:attr:`eosp.kinds.fleet.solve.Start.claim_frozen`)."""
    tasks = c.prob.passes[p].tasks[acq]
    return lam[tasks] if c.claim_frozen else np.zeros(len(tasks))


def _path_stats(c: Coordinator, paths: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Of one path per pass: how many paths serve each task (float64 per task), and each path's energy (the sum
    of its observations' least energy, :func:`eosp.kinds.fleet.problem.path_wh`): gathered from the flat
    node and task vectors at once, not pass by pass (at 200 satellites 13,152 passes a round)."""
    owner, _, pos = c._flat(np.arange(len(paths)), paths)
    count = np.bincount(c._task_idx[pos], c._claims[pos], minlength=len(c.prob.weight)).astype(np.float64)
    return count, np.bincount(owner, weights=c._task_wh[pos], minlength=len(paths))


def prefetch(c: Coordinator, budget: Budget) -> None:
    """Send the next price round's passes to the pool now, at the prices the last round set, when the pool
    can work while the driver does (its ``submit_priced``: Ray actors); :func:`_dual_round` takes the
    result when its prices are these.  Why: the next round's prices never depend on the recovery that
    follows a round (the master's duals and the subgradient step are taken before it, from the round's own
    results), so the actors solve round k + 1 while the driver recovers and repairs a schedule from round k
    (its descent sweeps then solved here, not queued behind the round): the same results as one after the
    other, in less time."""
    submit = getattr(c.pool, "submit_priced", None)
    if submit is None:
        return
    lam = np.minimum(c.prices.lam, c.prob.cap)
    pi = c.prices.pass_price()
    c._pending = (lam, pi, submit(np.flatnonzero(~c.frozen).tolist(), lam, pi, budget),
                     time.perf_counter())


def _bound_from(c: Coordinator, total: float, proven: bool, what: str, lam: np.ndarray) -> None:
    """Keep L = `total`, proven at task prices `lam`, as the bound when it is proven and lower (never below a
    schedule found: refused and said, see :meth:`Coordinator.keep`); its prices in :attr:`Coordinator.bound_lam`."""
    if proven and total < c.best_bound:
        if total < c.best.value - 1e-9 * max(1.0, c.best.value):
            # a theorem cannot fall below a schedule: some pass term was wrong; keep the bound known
            c.refused.append(f"{what}: L(lam) = {total:.6f} below the schedule found ({c.best.value:.6f})")
        else:
            c.best_bound, c.bound_source, c.bound_lam = total, "lagrangian", lam


def price_round(c: Coordinator, budget: Budget) -> float | None:
    """Every pass under the current prices (on the pool); returns L(lam, mu) (None when cut by the budget),
    keeps the bound when it is proven and lower, and moves the prices."""
    if c._start_lam is None:
        c._start_lam = c.prices.lam.copy()
    got = _dual_round(c, c.prices.lam, budget)
    if got is None:
        return None
    t_solves = c._solve_s  # the master's limit
    total, proven, count, pass_wh, c.round_paths = got
    _bound_from(c, total, proven, f"round {c.rounds_done + 1}", c.prices.lam.copy())
    lam = c.prices.lam.copy()
    scale = None if c.cfg.price_step == "uniform" else c.prob.cap  # lp's fallback: weighted steps
    search = c.cfg.energy_search and len(c.windows) > 0
    if c.master is not None:  # column generation: the round's pass optima are the master's new columns
        c.centre.observe(lam, total)
        added = c.master.add(c.round_paths)
        # no new column and L at the master's value: lam minimises L, later rounds would repeat this one
        c.converged = added == 0 and proven and total <= c.master.value + 1e-9 * max(1.0, total)
        # with a fixed number of rounds (no budget) the LP's limit is in iterations, about one per pass
        # solved (at 200 satellites 13,152 passes, ~4 s of HiGHS here as of a round's pass solves on one core):
        # the time a round's solves took depends on the machine and the workers, the schedule must not
        iters = None if budget.limited else max(MASTER_MIN_ITERATIONS, len(c.round_paths))
        duals = c.master.duals(budget.cap(max(MASTER_MIN_S, t_solves)), iters)
        if duals is not None:
            c._lp_misses, c._lp_solved = 0, True
            c.prices.lam = c.centre.towards(duals)
            if not search:
                c.prices.step_towards(count, total, c.best.value, pass_wh, scale, tasks=False)
        elif not budget.expired():
            c._lp_misses += 1
            # a master that never finished a solve in its time is not one slow solve: at 1,000 satellites its
            # first three solves ran out, 41-97 s each, and the rounds waited for them (docs/results.md)
            if c._lp_misses < MASTER_PATIENCE and c._lp_solved:
                # one slow solve (near the optimum the LP degenerates: a generated test_hard-like case took
                # longer than a round's pass solves at round 26 of 27): a weighted step for this round, and the
                # LP goes on from its basis at the next one
                c.prices.step_towards(count, total, c.best.value, None if search else pass_wh, scale)
            else:
                # the master outgrew the round (a 200-satellite day: 69 s for its second solve against 5 s of
                # pass solves): weighted subgradient steps from the prices the run started with, as if they
                # had been the rule from the start (at 200 satellites those steps from the centre, the ceiling
                # prices, found schedules 0.0013 of the weight lower in 300 s)
                c.master, c.converged = None, False
                c.prices.lam = c._start_lam.copy()
    else:
        c.prices.step_towards(count, total, c.best.value, None if search else pass_wh, scale)
    if search and proven:
        lower = energy_search(c, lam, total, pass_wh, budget)
        if lower is not None:
            _bound_from(c, lower, True, f"round {c.rounds_done + 1}, energy search", lam)
            total = lower
    c.spend = c.cfg.energy_price * c.prices.pass_price()
    return total


def energy_search(c: Coordinator, lam: np.ndarray, total: float, pass_wh: np.ndarray,
                  budget: Budget) -> float | None:
    """Line searches of the energy windows' multipliers at the task prices `lam` of the round just solved (its
    L(lam, mu) = `total`, its pass terms and each pass's energy `pass_wh`): on every satellite the window its
    round's paths overspend most (in typical observations) gets the multiplier increase x (per Wh) that
    minimises ``phi(x) = sum over its passes of their terms at pass price + x, + x R_w``, by bisection on
    where the passes' energy crosses R_w (:data:`ENERGY_STEPS` solves of the window's passes, every
    satellite's window solved together on the pool).  A window whose multiplier is above 0 and
    whose passes spend less than it allows may be the satellite's instead (x then between minus its multiplier
    and 0).  Returns L(lam, mu) with the new multipliers (None when no window moves, a term is not proven, or
    the budget ran out).

    Why a search, not only the subgradient steps: at fixed task prices each window's phi is convex and
    piecewise linear in x (a pass term is the maximum over its paths of linear functions of its price), so
    the x it keeps never raises L (phi(0) is evaluated, and an x is kept only when lower); the Polyak steps
    of the multipliers, sized by the task prices' gap, kept the bound above the conflict-free one where the
    battery binds (test_hard).  Windows of different satellites share no pass, so the searches are
    independent; x is kept per window in :attr:`Prices.mu` (units of its `scale_wh`) and paid by the
    schedules' pass problems as every multiplier is (``--energy-price``)."""
    win = c.windows
    pass_sat = c._pass_sat
    over = (win.used(pass_wh) - win.rhs_wh) / win.scale_wh
    mu_wh = c.prices.mu / win.scale_wh  # each window's multiplier per Wh
    slope = np.where(over > 1e-6, over, np.where((mu_wh > 0) & (over < -1e-6), -over, 0.0))
    cand = np.flatnonzero(slope > 0)
    if not (over > 1e-6).any():  # nothing overspent: L gains little from lowering multipliers alone
        return None
    cand = cand[np.lexsort((-slope[cand], pass_sat[win.lo[cand]]))]
    chosen = cand[np.r_[True, pass_sat[win.lo[cand[1:]]] != pass_sat[win.lo[cand[:-1]]]]]
    lens = win.hi[chosen] - win.lo[chosen] + 1
    passes = np.concatenate([np.arange(a, b + 1) for a, b in zip(win.lo[chosen], win.hi[chosen])])
    owner = np.repeat(np.arange(len(chosen)), lens)  # the chosen window of each of `passes`
    live = ~c.frozen[passes]
    top = np.zeros(len(chosen))  # past this price of a Wh no observation of the window is worth anything
    for k, p in zip(owner.tolist(), passes.tolist()):
        pg = c.prob.passes[p]
        e = pg.energy_wh
        if len(e):
            gain = (c.prob.pass_values(p) - lam[pg.tasks]) / np.maximum(e, 1e-12)
            top[k] = max(top[k], float(gain.max()))
    rhs = win.rhs_wh[chosen]
    best_phi = np.bincount(owner, c._terms[passes], len(chosen))
    phi0 = best_phi.copy()
    best_x = np.zeros(len(chosen))
    up = over[chosen] > 0  # overspent: x up to `top`; else a multiplier above 0 may come down to 0
    lo = np.where(up, 0.0, -mu_wh[chosen])
    hi = np.where(up, top * (1 + 1e-9) + 1e-12, 0.0)
    pi = c.prices.pass_price()
    todo = passes[live].tolist()
    for _ in range(ENERGY_STEPS):
        x = 0.5 * (lo + hi)
        pp = pi.copy()
        pp[passes] += x[owner]
        solved = c.pool.solve_priced(todo, lam, pp, budget)
        if solved is None:
            return None
        c.pass_solves += len(todo)
        got = _window_terms(c, passes, solved, lam, pp)
        if got is None:
            return None
        terms, used = got
        phi = np.bincount(owner, terms, len(chosen)) + x * rhs
        better = phi < best_phi
        best_phi, best_x = np.where(better, phi, best_phi), np.where(better, x, best_x)
        spent = np.bincount(owner, used, len(chosen)) > rhs
        lo, hi = np.where(spent, x, lo), np.where(spent, hi, x)
    gain = best_phi - phi0
    if not (gain < 0).any():
        return None
    mu = c.prices.mu.copy()
    mu[chosen] = np.maximum(0.0, mu[chosen] + best_x * win.scale_wh[chosen])
    c.prices.mu = mu
    c.spend = c.cfg.energy_price * c.prices.pass_price()
    return total + float(gain.sum())


def _window_terms(c: Coordinator, passes: np.ndarray, solved: dict, lam: np.ndarray,
                  pp: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Of a bisection step of :func:`energy_search`: each of `passes`'s term at pass prices `pp` (a frozen pass's
    schedule priced, the others' proven bounds from `solved`) and the energy of its path; None when a term is not
    proven."""
    terms = np.zeros(len(passes))
    used = np.zeros(len(passes))
    for i, p in enumerate(passes.tolist()):
        pg = c.prob.passes[p]
        if c.frozen[p]:
            path = c.initial.paths[p]
            acq = pg.graph.node_acq[path]
            terms[i] = float(priced(c._values_of(p)[acq], _frozen_lam(c, p, acq, lam), pg.energy_wh[acq], pp[p]).sum())
            used[i] = path_wh(pg, path)
            continue
        res = solved[p]
        if res.bound is None:
            return None
        terms[i], used[i] = res.bound, path_wh(pg, res.nodes)
    return terms, used


def ceiling_prices(c: Coordinator) -> np.ndarray:
    """Every task more than one pass can serve priced at its weight (its most valuable pass's value), the
    others at 0."""
    contested = np.array([len(h) > 1 for h in c.prob.task_passes], dtype=bool)
    return np.where(contested, c.prob.cap, 0.0)


def ceiling_round(c: Coordinator, budget: Budget) -> float | None:
    """L at :func:`ceiling_prices`, kept as the bound when lower; the prices the rounds move are left as they
    are.  Under those prices no pass gains anything from a contested task, so L is the contested tasks'
    weight plus each pass's best schedule of the tasks only it can serve: never above the conflict-free
    bound, below it where passes cannot take all their own tasks, and cheap (most utilities are 0).  Where
    rounds are expensive it is the best bound for a long time: on a generated 200-satellite day (seed 7) L is
    0.6680 of the weight here against 0.8816 for the heuristic start and 0.6717 conflict-free, which 63 price
    rounds from any start never got below."""
    ceiling = ceiling_prices(c)
    got = _dual_round(c, ceiling, budget)
    if got is None:
        return None
    _bound_from(c, got[0], got[1], "ceiling prices", ceiling)
    if c.master is not None:  # the lowest L so far may be this one (at 200 satellites, by far)
        c.centre.observe(ceiling, got[0])
        c.master.add(got[4])
    return got[0]
