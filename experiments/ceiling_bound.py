"""The bound of the ceiling prices on a fleet, beside the conflict-free bound, without solving it.

Every fleet solve evaluates the ceiling prices (every task more than one pass can serve priced at its weight) at
round 0 (:func:`eosp.kinds.fleet.dual.ceiling_round`).  This prints that bound for fleets
whose solves were measured before it existed, and what it costs: the pass graphs, then one round of pass solves.

    python experiments/ceiling_bound.py FLEET_DIR_OR_CASE ...
"""

from __future__ import annotations

import argparse
import sys
import time


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fleets", nargs="+", help="fleet directories or aeossp case directories")
    args = ap.parse_args(argv)

    from eosp.budget import UNLIMITED
    from eosp.jobs.train_prices import read_problem
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.dual import ceiling_round
    from eosp.memory import peak_rss_gb

    for path in args.fleets:
        t = time.perf_counter()
        prob = read_problem(path)
        graphs_s = time.perf_counter() - t
        coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
        W = prob.total_weight
        t = time.perf_counter()
        ceiling = ceiling_round(coord, UNLIMITED)
        print(f"{path}: conflict-free {coord.conflict_free() / W:.4f}, ceiling prices' L {ceiling / W:.4f} "
              f"({coord.bound_source}); read and pass graphs {graphs_s:.0f} s, ceiling round "
              f"{time.perf_counter() - t:.1f} s, peak {peak_rss_gb():.1f} GB", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
