"""``eosp validate PROBLEM SCHEDULE``: the kind's checker's verdict; exit 0 when valid, 1 when not."""

from __future__ import annotations

import argparse


def cmd_validate(kind, ns: argparse.Namespace) -> int:
    problem = kind.read(ns.problem, solving=False)
    verdict = kind.check(problem, kind.read_schedule(ns.schedule, problem))
    print(verdict.line)
    return 0 if verdict.valid else 1
