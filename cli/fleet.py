"""The fleet commands: import an aeossp case, inspect a fleet, solve, validate and export schedules.

``eosp import CASE``, ``eosp generate --fleet``, ``eosp info|solve|validate FLEET``, ``eosp export-schedule`` (routed by
:mod:`eosp.cli.fleet_main`).

Each function takes plain arguments and returns the exit status (0 done or valid, 1 invalid
schedule); user mistakes raise :class:`~eosp.errors.InputError`, which the CLI prints as one line
with exit status 2.  Heavy modules (brahe, pyarrow, numba) are imported inside the functions so
that ``eosp --help`` stays fast.
"""

from __future__ import annotations

import time
from pathlib import Path

from eosp.errors import InputError

SOLVERS = ("greedy",)
EXPORT_FORMATS = ("aeossp", "csv", "czml", "kml")


def is_aeossp_case(path) -> bool:
    """A directory holding mission.yaml, satellites.yaml and tasks.yaml."""
    from eosp.fleet.aeossp import is_case_dir

    return is_case_dir(path)


def is_fleet_dir(path) -> bool:
    """A fleet interchange directory written by ``eosp import CASE``."""
    from eosp.fleet.io import is_fleet_dir as _is

    return _is(path)


def cmd_fleet_import(case_dir, out, overwrite: bool = False) -> int:
    """Read an aeossp case, compute opportunities and passes, write the fleet directory `out`; the memory of the scan
    (the horizon's instants x satellites, the tasks) is estimated and checked after reading, before any propagation,
    and a fleet without any valid schedule is refused."""
    from eosp.atomic import check_output_dir
    from eosp.fleet.aeossp import read_case
    from eosp.fleet.check import require_feasible
    from eosp.fleet.geometry import Geometry
    from eosp.fleet.io import is_fleet_dir as owned
    from eosp.fleet.io import write_fleet, written_names
    from eosp.fleet.opportunities import compute, require_check_memory, require_scan_memory

    if not is_aeossp_case(case_dir):
        raise InputError(case_dir, "not an aeossp case directory (mission.yaml, satellites.yaml, tasks.yaml)")
    check_output_dir(out, overwrite=overwrite, owned=owned, what="fleet directory", names=written_names)
    t0 = time.perf_counter()
    fleet = read_case(case_dir)
    require_scan_memory(fleet, Path(case_dir) / "mission.yaml")  # the horizon's length as much as the fleet's size
    require_check_memory(fleet, Path(case_dir) / "mission.yaml")  # and the feasibility check below
    geo = Geometry(fleet)
    opps = compute(fleet, geo)
    require_feasible(fleet, case_dir, geo)  # a battery that idling alone runs dry: no schedule is valid
    write_fleet(fleet, opps, out, overwrite=overwrite)
    print(f"{out}: {len(fleet.satellites)} satellites, {len(fleet.tasks)} tasks, {len(opps)} opportunities, "
          f"{opps.n_passes} passes ({time.perf_counter() - t0:.1f} s)")
    return 0


def cmd_fleet_generate(cfg, out, overwrite: bool = False) -> int:
    """Draw a synthetic fleet (:mod:`eosp.fleet.generate`), compute its opportunities, write the fleet directory.

    The memory it needs is estimated from the request and checked against what the machine has before any
    work (one line, exit 2, instead of the kernel's out-of-memory killer hours later)."""
    from eosp.atomic import check_output_dir
    from eosp.fleet.generate import check, estimate_bytes, generate
    from eosp.fleet.geometry import Geometry
    from eosp.fleet.io import is_fleet_dir as owned
    from eosp.fleet.io import write_fleet, written_names
    from eosp.fleet.opportunities import compute
    from eosp.memory import require_memory

    check_output_dir(out, overwrite=overwrite, owned=owned, what="fleet directory", names=written_names)
    try:
        check(cfg)
    except ValueError as exc:  # "FleetGenConfig.planes: reason" -> "--planes: reason"
        name, _, reason = str(exc).partition(": ")
        raise InputError("--" + name.rpartition(".")[2].replace("_", "-"), reason) from None
    require_memory("--satellites/--tasks/--hours", estimate_bytes(cfg),
                   f"a fleet of {cfg.satellites} satellites and {cfg.tasks} tasks over {cfg.hours:g} h "
                   f"({cfg.hours * 720:,.0f} instants of the 5 s grid)")
    t0 = time.perf_counter()
    fleet = generate(cfg)
    opps = compute(fleet, Geometry(fleet))
    write_fleet(fleet, opps, out, overwrite=overwrite)
    print(f"{out}: {len(fleet.satellites)} satellites, {len(fleet.tasks)} tasks, {len(opps)} opportunities, "
          f"{opps.n_passes} passes ({time.perf_counter() - t0:.1f} s)")
    return 0


def _stats(values) -> str:
    import numpy as np

    v = np.asarray(values)
    if len(v) == 0:
        return "none"
    return f"min {v.min():g}, median {np.median(v):g}, mean {v.mean():.1f}, max {v.max():g}"


def cmd_fleet_info(fleet_dir) -> int:
    """Print the fleet's size, its opportunities and passes, and the conflict-free upper bound."""
    import numpy as np

    from eosp.fleet.io import read_fleet

    fleet, opps = read_fleet(fleet_dir)
    tk = fleet.tasks
    per_task = opps.per_task(len(tk))
    served = per_task > 0
    nodes = np.diff(opps.pass_offsets())
    h = fleet.horizon
    print(f"fleet: {fleet_dir} (source {fleet.source or '-'} {fleet.source_commit}, case {fleet.case_id or '-'})")
    print(f"horizon: {h.start.isoformat()} .. {h.end.isoformat()} ({h.seconds} s; action step {h.action_step_s} s, "
          f"geometry {h.geometry_step_s} s, resource {h.resource_step_s} s)")
    sensors = {s: int((fleet.satellites.sensor == s).sum()) for s in sorted(set(fleet.satellites.sensor.tolist()))}
    print(f"satellites: {len(fleet.satellites)} ({', '.join(f'{k} {v}' for k, v in sensors.items())})")
    print(f"tasks: {len(tk)}, total weight {tk.weight.sum():g}")
    print(f"opportunities: {len(opps)}; per task: {_stats(per_task)}")
    print(f"passes: {opps.n_passes}; nodes per pass: {_stats(nodes)}")
    print(f"tasks no satellite can serve: {int((~served).sum())}")
    total = float(tk.weight.sum())
    ub = float(tk.weight[served].sum()) / total if total > 0 else 0.0
    print(f"conflict-free upper bound (WCR): {ub:.6f}")
    return 0


def cmd_fleet_solve(fleet_dir, solver: str = "greedy", out=None, overwrite: bool = False,
                    time_limit: float | None = None, seed: int = 0) -> int:
    """Solve a fleet and write a fleet schedule (Parquet) to `out`.

    The greedy solver is deterministic and fast: it ignores `seed` and `time_limit`."""
    from eosp.ownership import check_output
    from eosp.fleet.check import validate
    from eosp.fleet.greedy import solve
    from eosp.fleet.io import read_fleet, write_schedule
    from eosp.fleet.passgraph import require_solvable

    if solver not in SOLVERS:
        raise InputError(solver, f"unknown fleet solver (choose from {', '.join(SOLVERS)})")
    if out is None:
        raise InputError(fleet_dir, "give --out SCHEDULE.parquet")
    out = check_output(out, "fleet-schedule", overwrite=overwrite, suffixes=(".parquet",))
    t0 = time.perf_counter()
    fleet, opps = read_fleet(fleet_dir)
    geo = require_solvable(fleet, opps, Path(fleet_dir) / "meta.json")
    sched = solve(fleet, opps, geo)
    res = validate(fleet, sched, geo)
    if not res.valid:  # the solver guarantees validity: this is a bug, not a user error
        raise RuntimeError(f"greedy produced an invalid schedule: {res.first}")
    elapsed = time.perf_counter() - t0
    write_schedule(sched, fleet, out, overwrite=overwrite,
                   info={"value": res.metrics["WCR"], "solver": solver, "seconds": round(elapsed, 3)})
    m = res.metrics
    print(f"{out}: {len(sched)} observations, WCR {m['WCR']:.6f} CR {m['CR']:.6f} "
          f"TAT {m['TAT'] if m['TAT'] is None else round(m['TAT'], 3)} PC {m['PC']:.3f} ({elapsed:.1f} s)")
    return 0


def cmd_fleet_validate(fleet_dir, schedule) -> int:
    """Check a schedule (fleet schedule .parquet or aeossp solution .json): 0 valid, 1 invalid."""
    from eosp.fleet.check import validate
    from eosp.fleet.io import read_fleet, read_schedule
    from eosp.fleet.opportunities import require_check_memory

    fleet, _ = read_fleet(fleet_dir, with_opportunities=False)
    sched, _ = read_schedule(schedule, fleet)
    require_check_memory(fleet, Path(fleet_dir) / "meta.json")
    res = validate(fleet, sched)
    if not res.valid:
        print(f"invalid: {res.first}")
        return 1
    m = res.metrics
    tat = "null" if m["TAT"] is None else repr(m["TAT"])
    print(f"valid: WCR {m['WCR']!r} CR {m['CR']!r} TAT {tat} PC {m['PC']!r}")
    return 0


def cmd_fleet_report(fleet_dir, schedules, out, overwrite: bool = False, title: str = "") -> int:
    """Write the planner's page of a fleet's day (:mod:`eosp.evaluation.fleet_report`) for one or more schedules;
    a schedule of another fleet is refused (fingerprint) before anything is written."""
    from eosp.evaluation.fleet_report import check_report_out, write_page
    from eosp.fleet.io import read_fleet, read_schedule

    check_report_out(out, overwrite)
    t0 = time.perf_counter()
    if is_fleet_dir(fleet_dir):
        from eosp.fleet.opportunities import require_check_memory

        fleet, opps = read_fleet(fleet_dir)
        require_check_memory(fleet, Path(fleet_dir) / "meta.json")  # the page checks and draws the whole horizon
        n_tasks = len(fleet.tasks)
    else:  # an ONERA fleet directory: its own model and schedules (no orbits)
        from eosp.fleet.onera import read_onera
        from eosp.fleet.onera import read_schedule as read_onera_schedule

        fleet, opps, read_schedule = read_onera(fleet_dir), None, read_onera_schedule
        n_tasks = len(fleet.requests)
    scheds = {}
    for path in schedules:
        label = Path(path).stem
        while label in scheds:
            label += "'"
        scheds[label] = read_schedule(path, fleet)[0]
    page = write_page(fleet, opps, scheds, out, overwrite=overwrite, title=title or None)
    print(f"{page}: {len(scheds)} schedule(s) of {len(fleet.satellites)} satellites and {n_tasks} tasks "
          f"({page.stat().st_size / 1e6:.1f} MB, {time.perf_counter() - t0:.1f} s)")
    return 0


def cmd_fleet_export_schedule(fleet_dir, schedule, fmt: str, out, overwrite: bool = False) -> int:
    """Write a schedule as an aeossp ``solution.json`` (fmt "aeossp"), a CSV (fmt "csv"), or for globe viewers
    as CZML (fmt "czml", Cesium) or KML (fmt "kml"; :mod:`eosp.fleet.export`)."""
    from eosp.fleet.aeossp import write_solution
    from eosp.fleet.io import read_fleet, read_schedule, write_csv

    if fmt not in EXPORT_FORMATS:
        raise InputError(fmt, f"unknown export format (choose from {', '.join(EXPORT_FORMATS)})")
    fleet, _ = read_fleet(fleet_dir, with_opportunities=False)
    sched, _ = read_schedule(schedule, fleet)
    if fmt in ("czml", "kml"):  # tracks over the whole horizon
        from eosp.fleet.opportunities import require_check_memory

        require_check_memory(fleet, Path(fleet_dir) / "meta.json")
    if fmt == "aeossp":
        path = write_solution(sched, fleet.horizon, out, overwrite=overwrite)
    elif fmt in ("czml", "kml"):
        from eosp.fleet.export import write_export

        path = write_export(fleet, sched, fmt, out, overwrite=overwrite)
    else:
        path = write_csv(sched, fleet, out, overwrite=overwrite)
    print(f"{Path(path)}: {len(sched)} observations")
    return 0
