"""The ONERA benchmark's commands: import a ``.pb`` file, inspect, solve, validate and export plans.

``eosp import FILE.pb --out DIR``, ``eosp info|solve|validate DIR``, ``eosp export-schedule DIR S
--format onera --out PLAN.txt`` (routed by :mod:`eosp.cli.fleet_main` when the first path is an ONERA
file or directory).  Each returns the exit status; user mistakes raise :class:`~eosp.errors.InputError`
(one line, exit 2).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from eosp.errors import InputError

SOLVERS = ("greedy", "onera")


def is_onera_file(path) -> bool:
    from eosp.fleet.onera import is_onera_file as _is

    return _is(path)


def is_onera_dir(path) -> bool:
    from eosp.fleet.onera import is_onera_dir as _is

    return _is(path)


def cmd_import(pb_file, out, overwrite: bool = False) -> int:
    """Read an ONERA ``.pb`` instance and write its fleet directory."""
    from eosp.atomic import check_output_dir
    from eosp.fleet.onera import KIND_SHORT, TABLE_FILES, read_pb, write_onera

    check_output_dir(out, overwrite=overwrite, owned=is_onera_dir, what="ONERA fleet directory",
                     names=lambda _: TABLE_FILES)
    t0 = time.perf_counter()
    f = read_pb(pb_file)
    write_onera(f, out, overwrite=overwrite, source=Path(pb_file).name)
    kinds = ", ".join(f"{KIND_SHORT[k]} {int((f.requests.kind == k).sum())}" for k in range(4))
    print(f"{out}: {len(f.satellites)} satellites, {len(f.requests)} requests ({kinds}), {len(f.observations)} "
          f"observations, {len(f.downloads)} downloads ({time.perf_counter() - t0:.1f} s)")
    return 0


def cmd_info(fleet_dir) -> int:
    """Sizes, opportunities per request and the conflict-free upper bound."""
    import numpy as np

    from eosp.fleet.onera import KIND_SHORT, read_onera
    from eosp.fleet.onera_check import best_values

    f = read_onera(fleet_dir)
    per = np.diff(f.requests.first)
    print(f"ONERA fleet: {fleet_dir} ({f.name})")
    print(f"satellites: {len(f.satellites)}; downloads: {len(f.downloads)} (mandatory)")
    for k in range(4):
        sel = f.requests.kind == k
        if sel.any():
            print(f"{KIND_SHORT[k]}: {int(sel.sum())} requests, {int(per[sel].sum())} observations")
    best = best_values(f)
    print(f"requests without opportunity: {int((per == 0).sum())}")
    print(f"conflict-free upper bound: {best.sum():.6g}")
    return 0


def cmd_solve(fleet_dir, solver: str, out, cfg, overwrite: bool = False) -> int:
    """Solve (greedy: the greedy plan; onera: greedy + large-neighbourhood search and a bound), check, write."""
    from eosp.fleet.onera import read_onera, write_schedule
    from eosp.fleet.onera_check import validate
    from eosp.ownership import check_output
    from eosp.solvers.onera import solve

    if solver not in SOLVERS:
        raise InputError(solver, f"unknown solver for an ONERA fleet (choose from {', '.join(SOLVERS)})")
    out = check_output(out, "onera-schedule", overwrite=overwrite, suffixes=(".parquet",))
    f = read_onera(fleet_dir)
    try:
        sol = solve(f, cfg, greedy_only=solver == "greedy")
    except ValueError as exc:  # an instance whose mandatory downloads do not fit
        raise InputError(fleet_dir, str(exc)) from None
    res = validate(f, sol.schedule)
    interrupted = sol.info.get("interrupted", False)
    if interrupted:
        import signal

        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not leave a half-written file
        if not res.valid:  # never write what the checker refuses
            print(f"eosp solve: interrupted: the plan so far is refused by the checker ({res.first}), nothing "
                  "written", file=sys.stderr)
            return 130
    elif not res.valid:  # the solver guarantees validity: a bug, not a user error
        raise RuntimeError(f"the ONERA solver produced an invalid plan: {res.first}")
    info = {"value": sol.value, "solver": solver, "bound": sol.bound, "gap": sol.gap,
            "bound_source": sol.info["bound_source"], "seconds": round(sol.info["seconds"], 3)}
    write_schedule(sol.schedule, f, out, overwrite=overwrite, info=info)
    served = ", ".join(f"{k} {v}" for k, v in res.served.items())
    bound = "" if sol.bound is None else f", bound {sol.bound:.4f} ({sol.info['bound_source']}), gap {sol.gap:.2%}"
    print(f"{out}: value {sol.value:.4f}{bound}; served {served}; {sol.info['moves']} moves "
          f"({sol.info['seconds']:.1f} s)")
    if interrupted:
        print(f"eosp solve: interrupted: wrote the best valid plan so far to {out} (value {sol.value:.4f})",
              file=sys.stderr)
        return 130
    return 0


def cmd_validate(fleet_dir, schedule) -> int:
    """0 and the value when the plan is valid, 1 and its first violation otherwise."""
    from eosp.fleet.onera import read_onera, read_schedule
    from eosp.fleet.onera_check import validate

    f = read_onera(fleet_dir)
    s, _ = read_schedule(schedule, f)
    res = validate(f, s)
    if not res.valid:
        print(f"invalid: {res.first}")
        return 1
    served = ", ".join(f"{k} {v}" for k, v in res.served.items())
    print(f"valid: value {res.value!r}; served {served}")
    return 0


def cmd_export(fleet_dir, schedule, fmt: str, out, overwrite: bool = False) -> int:
    """Write a plan as the ONERA text plan (docs/formats.md, "ONERA plan")."""
    from eosp.fleet.onera import read_onera, read_schedule, write_plan

    if fmt != "onera":
        raise InputError(fmt, "an ONERA fleet's plans export as --format onera")
    f = read_onera(fleet_dir)
    s, _ = read_schedule(schedule, f)
    path = write_plan(s, f, out, overwrite=overwrite)
    print(f"{Path(path)}: {len(s)} activities")
    return 0


def wants(argv: list[str]) -> bool:
    """Is this command line for ONERA: ``import FILE.pb``, or info/solve/validate/export-schedule of an ONERA
    fleet directory?"""
    if not argv or argv[0] not in ("import", "info", "solve", "validate", "export-schedule"):
        return False
    path = next((a for a in argv[1:] if not a.startswith("-")), None)
    if path is None:
        return False
    return is_onera_file(path) if argv[0] == "import" else is_onera_dir(path)


def parser(command: str):
    from eosp.args import Parser, add_config_args
    from eosp.solvers.onera import OneraConfig

    p = Parser(prog=f"eosp {command}")
    if command == "import":
        p.add_argument("pb_file", help="an ONERA benchmark instance (.pb)")
        p.add_argument("--out", required=True, help="ONERA fleet directory to write")
        p.add_argument("--overwrite", action="store_true", help="replace an ONERA fleet directory eosp wrote")
    elif command == "info":
        p.add_argument("fleet_dir")
    elif command == "validate":
        p.add_argument("fleet_dir")
        p.add_argument("schedule", help="ONERA schedule (.parquet) or text plan (.txt)")
    elif command == "export-schedule":
        p.add_argument("fleet_dir")
        p.add_argument("schedule")
        p.add_argument("--format", required=True, choices=("onera",), help="the ONERA text plan")
        p.add_argument("--out", required=True, help="text plan to write (.txt)")
        p.add_argument("--overwrite", action="store_true")
    else:  # solve
        p.add_argument("fleet_dir")
        p.add_argument("--solver", required=True, choices=SOLVERS,
                       help="greedy (requests by value, each at its best fitting observations) or onera (greedy, then "
                            "large-neighbourhood search, with a proven bound)")
        p.add_argument("--out", required=True, help="ONERA schedule file (.parquet)")
        p.add_argument("--overwrite", action="store_true")
        add_config_args(p, OneraConfig)
    return p


def route(argv: list[str]) -> int:
    """Run an ONERA command line (:func:`wants`); user errors are one line and exit 2."""
    from eosp.args import config_from_args

    command = argv[0]
    ns = parser(command).parse_args(argv[1:])
    try:
        if command == "import":
            return cmd_import(ns.pb_file, ns.out, overwrite=ns.overwrite)
        if command == "info":
            return cmd_info(ns.fleet_dir)
        if command == "validate":
            return cmd_validate(ns.fleet_dir, ns.schedule)
        if command == "export-schedule":
            return cmd_export(ns.fleet_dir, ns.schedule, ns.format, ns.out, overwrite=ns.overwrite)
        from eosp.solvers.onera import OneraConfig

        return cmd_solve(ns.fleet_dir, ns.solver, ns.out, config_from_args(OneraConfig, ns), overwrite=ns.overwrite)
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
