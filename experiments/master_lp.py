"""Column generation on one fleet, alone: how fast the price rounds reach the minimum of the Lagrangian bound, and
what the battery's energy windows weigh at that minimum when they are rows of the linear program.

The fleet solver (``--price-step lp``, :mod:`eosp.kinds.fleet.master`) interleaves this loop with schedules; here
it runs by itself from the first schedule and the heuristic prices: each round solves every pass under the
smoothed prices (the solver's own :meth:`Coordinator._dual_round`), adds the passes' schedules as columns of a
HiGHS LP (task rows, pass rows and, with ``--energy-rows``, one row per energy window with each column's energy:
its observations' least energy, plus with ``--slews`` the slews between them, :func:`path_slew_wh`), and prints L,
the lowest L so far, the LP's value and how many windows have a dual above 0.

    python experiments/master_lp.py CASE_OR_FLEET_DIR --time 60 [--energy-rows [--slews]]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fleet", help="an aeossp case directory or a fleet directory")
    ap.add_argument("--time", type=float, default=60.0, help="seconds of rounds after the first schedule")
    ap.add_argument("--energy-rows", action="store_true", help="the energy windows as rows of the LP")
    ap.add_argument("--slews", action="store_true", help="with --energy-rows: each column's energy with its slews")
    args = ap.parse_args(argv)

    import highspy

    from eosp.budget import UNLIMITED
    from eosp.jobs.train_prices import read_problem
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.dual import _dual_round
    from eosp.kinds.fleet.loop import run
    from eosp.kinds.fleet.master import SMOOTHING
    from eosp.kinds.lagrange import quiet_highs
    from eosp.kinds.fleet.problem import path_slew_wh, path_tasks, path_wh
    from eosp.kinds.fleet.warmstart import heuristic_prices

    prob = read_problem(args.fleet)
    W, w, n, P = prob.total_weight, prob.weight, len(prob.weight), len(prob.passes)
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=8.0, energy_bound=args.energy_rows))
    t0 = time.perf_counter()
    run(coord)
    print(f"first schedule {coord.best.value / W:.4f} in {time.perf_counter() - t0:.1f} s; "
          f"energy windows {len(coord.windows)}", flush=True)
    win = coord.windows
    holders = [[] for _ in range(P)]
    for k in range(len(win)):
        for p in range(int(win.lo[k]), int(win.hi[k]) + 1):
            holders[p].append(k)
    h = quiet_highs()
    h.changeObjectiveSense(highspy.ObjSense.kMaximize)
    rows = n + P + len(win)
    h.addRows(rows, np.full(rows, -highspy.kHighsInf), np.r_[np.ones(n + P), win.rhs_wh], 0,
              np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0))
    seen: set = set()

    def add(paths) -> int:
        cost, starts, index, value = [], [], [], []
        for p in range(P):
            tasks = np.unique(path_tasks(prob, p, paths[p]))
            key = (p, tasks.tobytes())
            if len(tasks) == 0 or key in seen:
                continue
            seen.add(key)
            e = path_wh(prob.passes[p], paths[p]) + (path_slew_wh(prob, p, paths[p]) if args.slews else 0.0)
            cost.append(float(w[tasks].sum()))
            starts.append(len(index))
            index += tasks.tolist() + [n + p] + [n + P + k for k in holders[p]]
            value += [1.0] * (len(tasks) + 1) + [e] * len(holders[p])
        if cost:
            h.addCols(len(cost), np.array(cost), np.zeros(len(cost)), np.full(len(cost), highspy.kHighsInf),
                      len(index), np.array(starts, np.int32), np.array(index, np.int32), np.array(value))
        return len(cost)

    add(coord.best.paths)
    centre, centre_mu = heuristic_prices(prob), np.zeros(len(win))
    lam, mu, lowest, k = centre.copy(), centre_mu.copy(), np.inf, 0
    t1 = time.perf_counter()
    while time.perf_counter() - t1 < args.time:
        coord.prices.mu = mu * win.scale_wh
        total, _, _, _, paths = _dual_round(coord, lam, UNLIMITED)
        if total < lowest:
            lowest, centre, centre_mu = total, lam.copy(), mu.copy()
        added = add(paths)
        h.run()
        d = np.abs(np.asarray(h.getSolution().row_dual))
        lam = SMOOTHING * centre + (1 - SMOOTHING) * d[:n]
        mu = SMOOTHING * centre_mu + (1 - SMOOTHING) * d[n + P:]
        k += 1
        print(f"round {k} at {time.perf_counter() - t1:.1f} s: L {total / W:.4f}, lowest {lowest / W:.4f}, "
              f"LP {h.getInfo().objective_function_value / W:.4f}, columns {len(seen)} (+{added}), "
              f"windows with a dual above 0: {int((d[n + P:] > 1e-12).sum())}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
