"""Whether the pass graphs' shortcut for bridge triples agrees with the exhaustive count on the aeossp cases.

    python experiments/bridge_triple_agreement.py ASTRO/benchmarks/aeossp_standard/dataset/cases

Builds every pass graph of every case under the directory (its ``*/case_*`` folders) and, wherever
:func:`eosp.fleet.passgraph.build_pass` asks whether the loose graph has a bridge triple, compares its answer
(:func:`~eosp.fleet.passgraph.has_bridge_triple`: one dense pass over two-arc paths, only the source's row when the
tracking argument holds) with the exhaustive count (:func:`~eosp.fleet.passgraph.bridge_triples`).  Prints the
passes asked, those where the tracking argument held, those with a triple, and the disagreements (expected 0).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def main() -> None:
    from eosp.fleet import passgraph
    from eosp.fleet.aeossp import read_case
    from eosp.fleet.geometry import Geometry
    from eosp.fleet.opportunities import compute
    from eosp.fleet.slew import LineOfSight

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", type=Path, help="the aeossp dataset's cases directory")
    args = ap.parse_args()
    fast = passgraph.has_bridge_triple
    stats = {"cases": 0, "asked": 0, "tracking_fits": 0, "triples": 0, "disagree": 0}

    def compare(graph, tracking_fits=False):
        decided = fast(graph, tracking_fits)
        exact = passgraph.bridge_triples(graph) > 0
        stats["asked"] += 1
        stats["tracking_fits"] += bool(tracking_fits)
        stats["triples"] += exact
        stats["disagree"] += decided != exact
        return decided

    passgraph.has_bridge_triple = compare
    for case in sorted(args.cases.glob("*/case_*")):
        fleet = read_case(case)
        geo = Geometry(fleet)
        passgraph.build_passes(fleet, compute(fleet, geo), LineOfSight(fleet, geo))
        stats["cases"] += 1
    print(json.dumps(stats))


if __name__ == "__main__":
    main()
