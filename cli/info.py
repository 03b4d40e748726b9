"""``eosp info PROBLEM``: what a problem holds, as its kind describes it (a single pass: sizes as JSON)."""

from __future__ import annotations

import argparse


def cmd_info(kind, ns: argparse.Namespace) -> int:
    print(kind.describe(kind.read(ns.problem), ns.problem))
    return 0
