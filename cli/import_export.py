"""``eosp import DIR... --out SHARD`` (interchange directories into a Parquet shard) and ``eosp export SHARD
--out DIR`` (one instance of a shard back to an interchange directory)."""

from __future__ import annotations

import argparse

from eosp.errors import InputError


def cmd_import(ns: argparse.Namespace) -> int:
    from eosp.instances.interchange import read_instance
    from eosp.shards.io import check_shard_out, write_shard

    check_shard_out(ns.out, ns.overwrite)
    insts, first = [], {}
    for d in ns.instance_dirs:
        inst = read_instance(d)
        if inst.name in first:  # a shard's instances are told apart by their names
            raise InputError(d, f"instance name {inst.name!r} already given by {first[inst.name]}: a shard holds "
                                "distinct instances (rename one in its meta.json)")
        first[inst.name] = d
        insts.append(inst)
    write_shard(ns.out, insts, include_unpruned=not ns.pruned_only, overwrite=ns.overwrite)
    print(f"{ns.out}: {len(insts)} instance(s)")
    return 0


def cmd_export(ns: argparse.Namespace) -> int:
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
