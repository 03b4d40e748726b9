"""The ``eosp`` parser: the commands, and the arguments of the one being run as the problem's kind defines them
(:meth:`eosp.kinds.base.KindBase.arguments`)."""

from __future__ import annotations

import argparse

from eosp.args import Parser

DESCRIPTION = "The ``eosp`` command: generate, import, export, inspect, solve, validate, plot, report."
COMMANDS = {  # what `eosp --help` lists
    "generate": "generate an instance directory (interchange format)",
    "import": "import instance directories into a Parquet shard",
    "export": "export one instance of a shard as an interchange directory",
    "info": "sizes of an instance (directory, or SHARD#INDEX)",
    "validate": "check a schedule against an instance; exit 0 when feasible",
    "solve": "solve an instance and write a schedule file",
    "build-shards": "generate a data set of Parquet shards with Ray (jobs/build_shards.py)",
    "plot": "trajectory plot (roll against time) of schedules of one instance",
    "export-schedule": "write a fleet schedule as an aeossp solution.json or a CSV (fleets: import, info, solve, "
                       "validate take a fleet directory too)",
    "report": "one self-contained HTML page: map, timeline, roll/pitch and a summary table of schedules of one "
              "instance",
    "scenario": "a fleet's day in operation: requests that arrive, ground stations and contacts, clouds "
                "(docs/operations.md)",
    "simulate": "a planner run through realizations of an operations scenario, scored against a clairvoyant bound "
                "(docs/operations.md)",
}


def build_parser(solver: str | None = None, command: str | None = None, kind=None) -> argparse.ArgumentParser:
    """The ``eosp`` parser, with the arguments of `command` as `kind` defines them (default: the first kind that
    offers the command).  `solver`: the --solver of a solve command (:func:`eosp.cli.solve.solver_of`), whose
    config gives ``eosp solve`` its flags; with no command, a solve's."""
    from eosp.cli.commands import COMMAND_FUNCTIONS
    from eosp.kinds import offering

    command = command or ("solve" if solver is not None else None)
    p = Parser(prog="eosp", description=DESCRIPTION)
    sub = p.add_subparsers(dest="command", required=True)
    for name, help_text in COMMANDS.items():
        s = sub.add_parser(name, help=help_text, add_help=name != "build-shards")
        s.set_defaults(func=COMMAND_FUNCTIONS[name])
        if name == command:
            kind = kind or offering(name)
            s.set_defaults(kind=kind.name)
            kind.arguments(name, s, solver)
    return p
