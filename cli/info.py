"""``eosp info INSTANCE``: the sizes of an instance (directory, or SHARD#INDEX) as JSON."""

from __future__ import annotations

import argparse
import json

from eosp.cli.load import load_instance


def cmd_info(ns: argparse.Namespace) -> int:
    from eosp.graphs.continuous import continuous_graph

    inst = load_instance(ns.instance)
    pg = inst.pruned()
    cs, _ = continuous_graph(pg)
    out = {"name": inst.name, "acquisitions": inst.n_acq, "nodes": inst.n_nodes,
           "arcs_unpruned": None if inst.unpruned_graph is None else inst.unpruned_graph.n_arcs, "arcs_pruned": pg.n_arcs, "continuous_arcs_pruned": int(cs.size),
           "family": inst.meta.get("family")}
    print(json.dumps(out, indent=1))
    return 0
