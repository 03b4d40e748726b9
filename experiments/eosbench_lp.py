"""EOS-Bench: how low the Lagrangian bound of the eosbench solver's pass decomposition can go, by column generation.

Usage::

    python experiments/eosbench_lp.py SCENARIO.json [--time-limit 30] [--rounds 40] [--transition code]

The solver (:mod:`eosp.kinds.eosbench.solve`) bounds a scenario by L(lam) = sum of lam + sum of pass terms, for task
prices lam found by subgradient steps.  Whatever the prices, L(lam) is at least the value of the linear program
over every capped path of every pass (one path a pass at most, each task at most once, fractions allowed): the
pass terms are at least the passes' capped optima, and the LP is their convex combination.  This script solves
the solver for ``--time-limit`` seconds, takes the paths it committed as the LP's first columns, then runs
column generation: each round solves the LP (HiGHS), takes prices between its duals and the best prices so far
(Wentges' smoothing, a = 0.5), computes L there with the solver's own bound round, and adds each pass's best
capped path under those prices and under the raw duals (the solver's pass solve) as new columns.  Prints per
round the LP value over the columns held (a lower bound on the full LP, so on every L) and the best L (a proven
upper bound on the optimum).  When the two meet, no choice of prices gives a lower bound of this decomposition.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from eosp.budget import UNLIMITED
from eosp.eosbench.read import read_scenario
from eosp.eosbench.transition import READINGS, Rules
from eosp.errors import InputError
from eosp.kinds.eosbench import solve as eb
from eosp.kinds.eosbench.dual import PriceLP


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario")
    ap.add_argument("--time-limit", type=float, default=30.0, help="seconds of the solver before the LP")
    ap.add_argument("--rounds", type=int, default=40, help="rounds of column generation")
    ap.add_argument("--transition", choices=READINGS, default="code", help="transition reading of the solve")
    ns = ap.parse_args(argv)
    try:
        scen = read_scenario(ns.scenario)
    except InputError as e:
        print(e, file=sys.stderr)
        return 2
    states = []
    init = eb.State.__post_init__

    def keep(self):  # the solver's state, for its committed paths
        init(self)
        states.append(self)

    eb.State.__post_init__ = keep
    res = eb.solve(scen, eb.EosBenchConfig(time_limit=ns.time_limit, transition=ns.transition))
    eb.State.__post_init__ = init
    st = states[-1]
    print(f"solver: TP {res.value:.1f}, bound {res.bound:.1f} ({res.bound_kind}), {len(st.columns)} paths committed")
    lp = PriceLP(st.prio, len(st.passes))
    for (k, tasks) in st.columns:  # the committed paths: the first columns
        lp.add(k, np.frombuffer(tasks, dtype=np.int32))
    alone = eb.State(scen, Rules(ns.transition), st.passes, st.cfg)  # its pass solves see no other pass
    lam, value, proven = np.zeros(len(scen.tasks)), math.inf, False
    t0 = time.perf_counter()
    for r in range(ns.rounds):
        lam = lp.next_prices(lam, value if proven else math.inf, UNLIMITED)  # smoothed towards the lowest L's prices
        value, _, proven = eb.bound_round(st, lam)
        added = 0
        for prices in (lam, lp.last_duals):
            for k, p in enumerate(st.passes):
                path = eb.solve_pass(alone, k, st.prio[p.tasks] - prices[p.tasks], UNLIMITED)
                if 0 < len(path) <= p.cap:
                    added += lp.add(k, p.tasks[p.node_acq[path]])
        best = min(value if proven else math.inf, lp.centre_value)
        print(f"round {r}: LP over {len(lp.held)} columns {lp.value:.1f}, L {value:.1f}, best L {best:.1f}, "
              f"{added} new columns, {time.perf_counter() - t0:.1f} s", flush=True)
        if not added:
            break
    return 0


if __name__ == "__main__":
    sys.exit(main())
