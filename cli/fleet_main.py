"""The command line for fleets: the same commands as for a single pass, taking a fleet where a pass was.

``eosp import CASE_DIR --out FLEET_DIR`` (an astro-reason aeossp case), ``eosp generate --fleet ... --out
FLEET_DIR`` (a synthetic fleet), ``eosp info FLEET_DIR``,
``eosp solve FLEET_DIR --solver greedy|fleet ...``, ``eosp validate FLEET_DIR S``, and
``eosp export-schedule FLEET_DIR S --format aeossp|csv --out FILE``.  :func:`route` recognizes a fleet
command from its first path argument and parses it here (one-line errors, exit 2); any other command
line goes on to the single-pass parser.  Heavy modules are imported only by the command that runs.
"""

from __future__ import annotations

import sys
import time
from datetime import timedelta
from pathlib import Path

from eosp.args import Parser, add_config_args, add_memory_arg, config_from_args
from eosp.errors import InputError

FLEET_SOLVERS = ("greedy", "fleet")


def _first_path(argv: list[str]) -> str | None:
    for a in argv[1:]:
        if not a.startswith("-"):
            return a
    return None


def is_fleet_command(argv: list[str]) -> bool:
    """Does this command line act on a fleet (an aeossp case to import, a fleet directory otherwise)?"""
    if not argv:
        return False
    if argv[0] == "export-schedule":
        return True
    if argv[0] == "generate":
        return "--fleet" in argv
    path = _first_path(argv)
    if path is None or argv[0] not in ("import", "info", "solve", "validate", "report"):
        return False
    from eosp.cli.fleet import is_aeossp_case, is_fleet_dir
    from eosp.cli.onera import wants as onera

    if onera(argv):
        return True
    if argv[0] == "report":  # the fleet page takes an ONERA fleet directory too
        from eosp.cli.onera import is_onera_dir

        return is_fleet_dir(path) or is_onera_dir(path)
    return is_aeossp_case(path) if argv[0] == "import" else is_fleet_dir(path)


def parser(command: str) -> Parser:
    from eosp.solvers.fleet import FleetConfig

    p = Parser(prog=f"eosp {command}")
    if command == "generate":
        from eosp.fleet.generate import FleetGenConfig

        p.description = "Draw a synthetic fleet (Walker-delta orbits, tasks on land, in cities or clusters)."
        p.add_argument("--fleet", action="store_true", required=True, help="generate a fleet (not a single pass)")
        p.add_argument("--out", required=True, help="fleet directory to write")
        p.add_argument("--overwrite", action="store_true", help="replace a fleet directory eosp wrote")
        add_memory_arg(p)
        add_config_args(p, FleetGenConfig)
    elif command == "import":
        p.add_argument("case_dir", help="an astro-reason aeossp_standard case (mission.yaml, satellites.yaml, "
                                        "tasks.yaml)")
        p.add_argument("--out", required=True, help="fleet directory to write")
        p.add_argument("--overwrite", action="store_true", help="replace a fleet directory eosp wrote")
        add_memory_arg(p)
    elif command == "info":
        p.add_argument("fleet_dir")
    elif command == "report":
        p.description = ("One self-contained HTML page of a constellation day: Gantt per satellite (UTC), map with "
                         "tracks and targets, every task with the reason it was missed, summaries, differences.")
        p.add_argument("fleet_dir")
        p.add_argument("schedules", nargs="+", help="fleet schedules (.parquet) or aeossp solutions (.json)")
        p.add_argument("--out", required=True, help="HTML file to write")
        p.add_argument("--title", default="")
        p.add_argument("--overwrite", action="store_true")
        add_memory_arg(p)
    elif command == "validate":
        p.add_argument("fleet_dir")
        p.add_argument("schedule", help="fleet schedule (.parquet) or aeossp solution (.json)")
        add_memory_arg(p)
    elif command == "export-schedule":
        p.add_argument("fleet_dir")
        p.add_argument("schedule")
        p.add_argument("--format", required=True, choices=("aeossp", "csv", "czml", "kml"),
                       help="aeossp solution.json, CSV, CZML (Cesium) or KML (tracks, targets, observations)")
        p.add_argument("--out", required=True)
        p.add_argument("--overwrite", action="store_true")
        add_memory_arg(p)
    elif command == "solve":
        p.add_argument("fleet_dir")
        p.add_argument("--solver", required=True, choices=FLEET_SOLVERS,
                       help="greedy (each task once, by weight) or fleet (passes coordinated by prices, with a bound)")
        p.add_argument("--out", required=True, help="fleet schedule file (.parquet)")
        p.add_argument("--overwrite", action="store_true")
        p.add_argument("--init", default="", help="a schedule of this fleet to start from")
        p.add_argument("--freeze-until", default="", metavar="UTC",
                       help="keep the passes that start before this time (ISO 8601) as in --init")
        add_memory_arg(p)
        add_config_args(p, FleetConfig)
    else:
        raise InputError(command, "not a fleet command")
    return p


def route(argv: list[str]) -> int:
    """Run a fleet command line (:func:`is_fleet_command`); user errors are one line and exit 2."""
    from eosp.cli import onera

    if onera.wants(argv):  # an ONERA .pb file or fleet directory: its own model and commands
        return onera.route(argv)
    from eosp.memory import memory_ceiling

    command = argv[0]
    ns = parser(command).parse_args(argv[1:])
    try:
        with memory_ceiling(getattr(ns, "max_memory_gb", None)):
            return _run(command, ns)
    except InputError as exc:
        print(f"eosp {command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"eosp {command}: interrupted: nothing written", file=sys.stderr)
        return 130
    except OSError as exc:  # the system refused a path of the user's (permission, disk full, not found, ...)
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"eosp {command}: error: {where}{(exc.strerror or str(exc)).lower()}", file=sys.stderr)
        return 2


def _run(command: str, ns) -> int:
    from eosp.cli import fleet as cmds

    if command == "generate":
        from eosp.fleet.generate import FleetGenConfig

        return cmds.cmd_fleet_generate(config_from_args(FleetGenConfig, ns), ns.out, overwrite=ns.overwrite)
    if command == "import":
        return cmds.cmd_fleet_import(ns.case_dir, ns.out, overwrite=ns.overwrite)
    if command == "info":
        return cmds.cmd_fleet_info(ns.fleet_dir)
    if command == "report":
        return cmds.cmd_fleet_report(ns.fleet_dir, ns.schedules, ns.out, overwrite=ns.overwrite, title=ns.title)
    if command == "validate":
        return cmds.cmd_fleet_validate(ns.fleet_dir, ns.schedule)
    if command == "export-schedule":
        return cmds.cmd_fleet_export_schedule(ns.fleet_dir, ns.schedule, ns.format, ns.out, overwrite=ns.overwrite)
    if ns.solver == "greedy":
        if ns.init or ns.freeze_until:
            raise InputError("--init", "re-planning is done by --solver fleet")
        return cmds.cmd_fleet_solve(ns.fleet_dir, "greedy", ns.out, overwrite=ns.overwrite)
    return solve_fleet(ns)


def solve_fleet(ns) -> int:
    """``eosp solve FLEET_DIR --solver fleet``: the schedule, its value (WCR), bound and gap."""
    from eosp.fleet.check import validate
    from eosp.fleet.io import read_fleet, read_schedule, write_schedule
    from eosp.fleet.model import parse_utc
    from eosp.ownership import check_output
    from eosp.fleet.passgraph import require_solvable
    from eosp.solvers.fleet import FleetConfig, solve

    cfg = config_from_args(FleetConfig, ns)
    if cfg.pass_solver == "policy":
        raise InputError("--pass-solver", "policy: no model trained on fleet passes is shipped yet; use exact, ramp "
                                          "or greedy")
    out = check_output(ns.out, "fleet-schedule", overwrite=ns.overwrite, suffixes=(".parquet",))
    t0 = time.perf_counter()
    fleet, opps = read_fleet(ns.fleet_dir)
    require_solvable(fleet, opps, Path(ns.fleet_dir) / "meta.json")
    initial, freeze_s = None, None
    if ns.init:
        initial, _ = read_schedule(ns.init, fleet)  # a schedule of another fleet is refused (fingerprint)
        res = validate(fleet, initial)
        if not res.valid:
            raise InputError(ns.init, f"not a valid schedule of this fleet: {res.first}")
    if ns.freeze_until:
        try:
            at = parse_utc(ns.freeze_until)
        except ValueError as exc:
            raise InputError("--freeze-until", str(exc)) from None
        h = fleet.horizon
        if not h.start <= at <= h.end:
            raise InputError("--freeze-until", f"{ns.freeze_until} is outside the horizon "
                                               f"{h.start.isoformat()} .. {h.end.isoformat()}")
        if initial is None:
            raise InputError("--freeze-until", "needs --init (the schedule whose actions are kept)")
        freeze_s = (at - h.start) / timedelta(seconds=1)
    sol = solve(fleet, opps, cfg, initial=initial, freeze_until_s=freeze_s)
    if sol.info.get("interrupted"):
        import signal

        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not leave a half-written file
    elapsed = time.perf_counter() - t0
    info = {"value": sol.value, "solver": "fleet", "pass_solver": cfg.pass_solver, "seconds": round(elapsed, 3),
            "bound": sol.bound, "gap": sol.gap, "bound_source": sol.info["bound_source"]}
    write_schedule(sol.schedule, fleet, out, overwrite=ns.overwrite, info=info)
    why = sol.info["no_lagrangian_bound_because"]
    source = sol.info["bound_source"] + ("" if why is None else f": {why}")
    gap = "-" if sol.gap is None else f"{sol.gap:.4%}"
    bound = "" if sol.bound is None else f", bound {sol.bound:.6f} ({source}), gap {gap}"
    print(f"{Path(out)}: {len(sol.schedule)} observations, WCR {sol.value:.6f}{bound}; {sol.info['rounds']} rounds, "
          f"{sol.info['pass_solves']} pass solves ({elapsed:.1f} s)")
    if sol.info.get("interrupted"):  # Ctrl-C: the best schedule so far (checked by the checker) was written
        print(f"eosp solve: interrupted: wrote the best valid schedule so far to {out} ({len(sol.schedule)} "
              f"observations, WCR {sol.value:.6f})", file=sys.stderr)
        return 130
    return 0
