"""``eosp export-schedule PROBLEM SCHEDULE --format NAME --out FILE``: a schedule in another format of its kind
(a fleet: an aeossp solution.json, CSV, CZML, KML; ONERA: its text plan)."""

from __future__ import annotations

import argparse

from eosp.errors import InputError
from eosp.problem import load


def cmd_export_schedule(kind, ns: argparse.Namespace) -> int:
    if ns.format not in kind.exports:
        raise InputError(ns.format, f"unknown export format (choose from {', '.join(kind.exports)})")
    problem = kind.read(ns.problem, solving=False)
    sched = kind.read_schedule(ns.schedule, problem)
    print(load(kind.exports[ns.format].write)(problem, sched, ns.out, overwrite=ns.overwrite))
    return 0
