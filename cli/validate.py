"""``eosp validate INSTANCE_DIR SCHEDULE``: the independent checker's verdict; exit 0 when feasible, 1 when not."""

from __future__ import annotations

import argparse


def cmd_validate(ns: argparse.Namespace) -> int:
    from eosp.instances.interchange import read_instance
    from eosp.instances.schedule import check, read_schedule

    inst = read_instance(ns.instance_dir)
    verdict = check(inst, read_schedule(ns.schedule))
    if verdict.feasible:
        print(f"feasible: {verdict.n} acquisitions, value {verdict.value:.6f}")
        return 0
    print(f"infeasible: {verdict.reason}")
    return 1
