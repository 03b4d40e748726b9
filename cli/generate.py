"""``eosp generate OUT``: draw one single-pass instance and write it as an interchange directory (fleets:
:mod:`eosp.cli.fleet`)."""

from __future__ import annotations

import argparse
import time

from eosp.args import config_from_args
from eosp.config import InstanceConfig, family_config


def cmd_generate(ns: argparse.Namespace) -> int:
    from eosp.instances.generator import generate
    from eosp.instances.interchange import check_instance_out, write_instance

    check_instance_out(ns.out, overwrite=ns.overwrite)
    # the family's settings first, then every flag given
    base = family_config(getattr(ns, "family", "uniform"), 100, 0)
    cfg = config_from_args(InstanceConfig, ns, base=base)
    from eosp.instances.generator import require_generate_memory

    require_generate_memory(cfg, "--n-acquisitions")  # from the request, before minutes of generation
    t0 = time.perf_counter()
    inst = generate(cfg)
    write_instance(inst, ns.out, overwrite=ns.overwrite)
    print(f"{ns.out}: {inst.n_acq} acquisitions, {inst.n_nodes} nodes, {inst.unpruned().n_arcs} arcs "
          f"({time.perf_counter() - t0:.2f} s)")
    return 0
