"""``eosp scenario FLEET_DIR --out SCEN/``: a fleet's day in operation written as a scenario directory
(:mod:`eosp.ops.scenario`)."""

from __future__ import annotations

import argparse


def cmd_scenario(kind, ns: argparse.Namespace) -> int:  # noqa: ARG001 - the fleet kind, the one offering it
    from eosp.args import config_from_args
    from eosp.ops.scenario import ScenarioConfig, make

    print(make(ns.problem, config_from_args(ScenarioConfig, ns), ns.out, overwrite=ns.overwrite))
    return 0
