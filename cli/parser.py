"""The ``eosp`` parser of single-pass commands: each subcommand's arguments and the module that runs it
(``func``).  Fleet and ONERA command lines are parsed by :mod:`eosp.cli.fleet_main` and :mod:`eosp.cli.onera`."""

from __future__ import annotations

import argparse

from eosp.args import Parser, add_config_args, add_memory_arg
from eosp.cli.build_shards import cmd_build_shards
from eosp.cli.generate import cmd_generate
from eosp.cli.import_export import cmd_export, cmd_import
from eosp.cli.info import cmd_info
from eosp.cli.plot import cmd_plot
from eosp.cli.report import cmd_report
from eosp.cli.solve import cmd_solve
from eosp.cli.validate import cmd_validate
from eosp.config import InstanceConfig

DESCRIPTION = "The ``eosp`` command: generate, import, export, inspect, solve, validate, plot, report."
OVERWRITE_HELP = "replace an existing output that eosp wrote (a file or directory eosp did not write is never replaced)"


def build_parser(solver: str | None = None) -> argparse.ArgumentParser:
    """The ``eosp`` parser.  `solver`: the --solver of a solve command (:func:`eosp.cli.solve.solver_of`), whose config
    (:mod:`eosp.solvers.base`) gives ``eosp solve`` its flags; "" or an unknown name: the shared ones."""
    p = Parser(prog="eosp", description=DESCRIPTION)
    sub = p.add_subparsers(dest="command", required=True)

    g = sub.add_parser("generate", help="generate an instance directory (interchange format)")
    g.add_argument("out", help="instance directory to create")
    g.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(g)
    add_config_args(g, InstanceConfig)
    g.set_defaults(func=cmd_generate)

    i = sub.add_parser("import", help="import instance directories into a Parquet shard")
    i.add_argument("instance_dirs", nargs="+")
    i.add_argument("--out", required=True, help="shard file to write")
    i.add_argument("--pruned-only", action="store_true", help="do not store the unpruned arcs")
    i.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(i)
    i.set_defaults(func=cmd_import)

    e = sub.add_parser("export", help="export one instance of a shard as an interchange directory")
    e.add_argument("shard")
    e.add_argument("--index", type=int, default=0)
    e.add_argument("--out", required=True)
    e.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(e)
    e.set_defaults(func=cmd_export)

    n = sub.add_parser("info", help="sizes of an instance (directory, or SHARD#INDEX)")
    n.add_argument("instance")
    add_memory_arg(n)
    n.set_defaults(func=cmd_info)

    v = sub.add_parser("validate", help="check a schedule against an instance; exit 0 when feasible")
    v.add_argument("instance_dir")
    v.add_argument("schedule")
    add_memory_arg(v)
    v.set_defaults(func=cmd_validate)

    s = sub.add_parser("solve", help="solve an instance and write a schedule file",
                       epilog="Each solver has its own options: eosp solve --solver NAME --help lists them.")
    s.add_argument("instance_dir", help="instance directory (or SHARD#INDEX)")
    s.add_argument("--solver", required=True, help="random, greedy, ramp, exact, lns, policy, sample, beam, mcts")
    s.add_argument("--out", required=True, help="schedule file (.parquet, or .jsonl)")
    s.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(s)
    if solver is not None:
        from eosp.solvers.base import REGISTRY, SolverConfig, solver_config_class

        add_config_args(s, solver_config_class(solver) if solver in REGISTRY else SolverConfig)
    s.set_defaults(func=cmd_solve)

    b = sub.add_parser("build-shards", help="generate a data set of Parquet shards with Ray (jobs/build_shards.py)",
                       add_help=False)
    b.set_defaults(func=None, passthrough=cmd_build_shards)

    pl = sub.add_parser("plot", help="trajectory plot (roll against time) of schedules of one instance")
    pl.add_argument("instance_dir")
    pl.add_argument("schedules", nargs="+")
    pl.add_argument("--out", required=True, help="output path without extension (PNG and SVG are written)")
    pl.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(pl)
    pl.set_defaults(func=cmd_plot)

    x = sub.add_parser("export-schedule", help="write a fleet schedule as an aeossp solution.json or a CSV "
                                               "(fleets: import, info, solve, validate take a fleet directory too)")
    x.add_argument("fleet_dir")
    x.add_argument("schedule")
    x.add_argument("--format", choices=("aeossp", "csv"), required=True)
    x.add_argument("--out", required=True)

    r = sub.add_parser("report", help="one self-contained HTML page: map, timeline, roll/pitch and a summary "
                                      "table of schedules of one instance")
    r.add_argument("instance_dir", help="instance directory (or SHARD#INDEX)")
    r.add_argument("schedules", nargs="+", help="schedule files (.parquet or .jsonl); infeasible ones are drawn too")
    r.add_argument("--out", required=True, help="HTML file to write")
    r.add_argument("--title", default="", help="page title (default: the instance name)")
    r.add_argument("--reference", default="", help="the schedule (its label: the file name without suffix) the "
                                                   "others are compared with and whose missed acquisitions are "
                                                   "explained (default: the best feasible one)")
    r.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    add_memory_arg(r)
    r.set_defaults(func=cmd_report)
    return p
