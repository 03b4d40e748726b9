"""``eosp import SOURCE... --out OUT``: a format some kind imports (interchange directories into a Parquet shard,
an aeossp case or an ONERA .pb into a fleet directory); ``eosp export SHARD --out DIR`` (a single pass: one
instance of a shard back to an interchange directory)."""

from __future__ import annotations

import argparse

from eosp.errors import InputError
from eosp.problem import load


def cmd_import(kind, ns: argparse.Namespace) -> int:
    paths = kind.import_paths(ns)
    src = next((s for s in kind.sources if load(s.detect)(paths[0]).ok), kind.sources[0])
    print(load(src.convert)(paths, ns.out, ns.overwrite, **kind.import_options(ns)))
    return 0


def cmd_export(kind, ns: argparse.Namespace) -> int:
    from eosp.instances.interchange import check_instance_out, write_instance
    from eosp.shards.io import ShardReader

    check_instance_out(ns.out, overwrite=ns.overwrite)
    reader = ShardReader(ns.shard)
    inst = reader.read(ns.index)
    if inst.unpruned_graph is None:
        raise InputError(ns.shard, "this shard holds only pruned arcs; the interchange format needs the unpruned "
                                   "graph", row=ns.index)
    inst.meta.pop("source", None)
    write_instance(inst, ns.out, overwrite=ns.overwrite)
    print(f"{ns.out}: exported {inst.name}")
    return 0
