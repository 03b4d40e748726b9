"""``eosp report PROBLEM SCHEDULE... --out PAGE.html``: one self-contained HTML page of schedules of one problem,
as its kind draws it."""

from __future__ import annotations

import argparse


def cmd_report(kind, ns: argparse.Namespace) -> int:
    print(kind.report(ns.problem, ns.schedules, ns.out, ns))
    return 0
