"""The fleet kind: a constellation day in the astro-reason aeossp_standard model (an imported case, or a synthetic
fleet), checked by the benchmark verifier's rules (:mod:`eosp.fleet.check`), solved by the fleet greedy or by
passes coordinated by task prices (:mod:`eosp.kinds.fleet.solve`).

``eosp import CASE_DIR --out FLEET_DIR``, ``eosp generate --fleet ... --out FLEET_DIR``, ``eosp info|solve|validate|
report FLEET_DIR ...``, ``eosp export-schedule FLEET_DIR S --format aeossp|csv|czml|kml --out FILE``.  Heavy
modules (brahe, pyarrow, numba) are imported inside the functions, so that ``eosp --help`` stays fast.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path
from typing import Any

from eosp.errors import InputError
from eosp.kinds.base import KindBase, Words, labelled
from eosp.problem import Detection, Export, Generator, Result, Solver, Source, Verdict

HERE = "eosp.kinds.fleet.kind"


@dataclass
class FleetData:
    """A fleet directory read: the fleet, its opportunities (None when read for checking only), the meta.json that
    the size checks name, and the Geometry a solve's checks built (:meth:`FleetKind.before_solve`; the solvers and
    the checker reuse it)."""

    fleet: Any
    opps: Any
    meta: Path
    geo: Any = None


def is_case(path: str) -> Detection:
    """An aeossp case directory: mission.yaml, satellites.yaml and tasks.yaml."""
    from eosp.fleet.aeossp import is_case_dir

    if is_case_dir(path):
        return Detection(True, "an aeossp case")
    return Detection(False, "not an aeossp case directory (mission.yaml, satellites.yaml, tasks.yaml)")


def _written(out, fleet, opps, t0: float) -> str:
    return (f"{out}: {len(fleet.satellites)} satellites, {len(fleet.tasks)} tasks, {len(opps)} opportunities, "
            f"{opps.n_passes} passes ({time.perf_counter() - t0:.1f} s)")


def import_case(paths: list[str], out: str, overwrite: bool = False) -> str:
    """Read an aeossp case, compute opportunities and passes, write the fleet directory `out`; the memory of the scan
    (the horizon's instants x satellites, the tasks) is estimated and checked after reading, before any propagation,
    and a fleet without any valid schedule is refused."""
    from eosp.atomic import check_output_dir
    from eosp.fleet.aeossp import read_case
    from eosp.fleet.check import require_feasible
    from eosp.fleet.io import is_fleet_dir, write_fleet, written_names
    from eosp.fleet.opportunities import compute, require_check_memory, require_scan_memory

    (case_dir,) = paths
    check_output_dir(out, overwrite=overwrite, owned=is_fleet_dir, what="fleet directory", names=written_names)
    t0 = time.perf_counter()
    fleet = read_case(case_dir)
    require_check_memory(fleet, Path(case_dir) / "mission.yaml")  # the feasibility check below
    # the horizon's length as much as the fleet's size, then the opportunities from a sample of satellites
    geo, sample = require_scan_memory(fleet, Path(case_dir) / "mission.yaml")
    opps = compute(fleet, geo, sample)
    require_feasible(fleet, case_dir, geo)  # a battery that idling alone runs dry: no schedule is valid
    write_fleet(fleet, opps, out, overwrite=overwrite)
    return _written(out, fleet, opps, t0)


def generate(cfg, out: str, overwrite: bool = False) -> str:
    """Draw a synthetic fleet (:mod:`eosp.fleet.generate`), compute its opportunities, write the fleet directory.

    The memory it needs is estimated and checked against what the machine has before the work it is for (one
    line, exit 2, instead of the kernel's out-of-memory killer hours later): drawing and propagating from the
    request, the opportunities from a sample of the drawn satellites."""
    from eosp.atomic import check_output_dir
    from eosp.fleet.generate import check, estimate_bytes
    from eosp.fleet.generate import generate as draw
    from eosp.fleet.io import is_fleet_dir, write_fleet, written_names
    from eosp.fleet.opportunities import compute, require_scan_memory
    from eosp.memory import require_memory

    check_output_dir(out, overwrite=overwrite, owned=is_fleet_dir, what="fleet directory", names=written_names)
    try:
        check(cfg)
    except ValueError as exc:  # "FleetGenConfig.planes: reason" -> "--planes: reason"
        name, _, reason = str(exc).partition(": ")
        raise InputError("--" + name.rpartition(".")[2].replace("_", "-"), reason) from None
    require_memory("--satellites/--tasks/--hours", estimate_bytes(cfg),
                   f"a fleet of {cfg.satellites} satellites and {cfg.tasks} tasks over {cfg.hours:g} h "
                   f"({cfg.hours * 720:,.0f} instants of the 5 s grid)")
    t0 = time.perf_counter()
    fleet = draw(cfg)
    opps = compute(fleet, *require_scan_memory(fleet, "--satellites/--tasks/--hours"))
    write_fleet(fleet, opps, out, overwrite=overwrite)
    return _written(out, fleet, opps, t0)


def _stats(values) -> str:
    import numpy as np

    v = np.asarray(values)
    if len(v) == 0:
        return "none"
    return f"min {v.min():g}, median {np.median(v):g}, mean {v.mean():.1f}, max {v.max():g}"


def export_aeossp(data: FleetData, schedule, out: str, overwrite: bool = False) -> str:
    from eosp.fleet.aeossp import write_solution

    path = write_solution(schedule, data.fleet.horizon, out, overwrite=overwrite)
    return f"{Path(path)}: {len(schedule)} observations"


def export_csv(data: FleetData, schedule, out: str, overwrite: bool = False) -> str:
    from eosp.fleet.io import write_csv

    return f"{Path(write_csv(schedule, data.fleet, out, overwrite=overwrite))}: {len(schedule)} observations"


def export_globe(fmt: str):
    """CZML (Cesium) or KML: tracks, targets and observations for globe viewers (:mod:`eosp.fleet.export`)."""

    def write(data: FleetData, schedule, out: str, overwrite: bool = False) -> str:
        from eosp.fleet.export import write_export
        from eosp.fleet.opportunities import require_check_memory

        require_check_memory(data.fleet, data.meta)  # tracks over the whole horizon
        path = write_export(data.fleet, schedule, fmt, out, overwrite=overwrite)
        return f"{Path(path)}: {len(schedule)} observations"

    return write


export_czml, export_kml = export_globe("czml"), export_globe("kml")


def late_because(res: Result) -> str:
    """Why a first schedule came after the time limit, in the solve's line: the seconds spent compiling kernels not
    yet cached (`make demo`, or ``python -m eosp.cli.warmup``, compiles them once), those building the pass graphs (their share
    of compiling included), and reading, before the limit started counting."""
    t = res.timings
    compiling = t.get("compile", 0.0)
    hint = " (python -m eosp.cli.warmup compiles them once)" if compiling >= 1.0 else ""
    return (f"{compiling:.1f} s of it compiling kernels{hint}, {t.get('build', 0.0):.1f} s building the pass graphs; "
            f"reading took {t.get('read', 0.0):.1f} s before")


class FleetKind(KindBase):
    name = "fleet"
    title = "an aeossp fleet directory (eosp import CASE, eosp generate --fleet)"
    words = Words(problem="fleet_dir", schedule="fleet schedule (.parquet) or aeossp solution (.json)",
                  schedules="fleet schedules (.parquet) or aeossp solutions (.json)",
                  solver="greedy (each task once, by weight), fleet (passes coordinated by prices, with a bound), "
                         "fleet-policy (the learned fleet policy, greedy decoding), fleet-sample (its batched samples, "
                         "the best kept) or fleet-features (the same decoder with a hand rule over the same features)",
                  out="fleet schedule file (.parquet)", overwrite=None,
                  formats="aeossp solution.json, CSV, CZML (Cesium) or KML (tracks, targets, observations)",
                  source="case_dir", written="fleet directory to write",
                  overwrite_written="replace a fleet directory eosp wrote",
                  generate_flag="generate a fleet (not a single pass)")
    schedule_mark = "fleet-schedule"
    extra_commands = ("scenario", "simulate")
    memory_checked = ("import", "generate", "solve", "validate", "report", "export-schedule")
    solvers = {"greedy": Solver("greedy", "eosp.kinds.fleet.config:GreedyConfig", "eosp.kinds.fleet.solve:solve_greedy",
                                "each task once, by weight"),
               "fleet": Solver("fleet", "eosp.kinds.fleet.config:FleetConfig", "eosp.kinds.fleet.solve:solve_fleet",
                               "passes coordinated by prices, with a bound"),
               "fleet-policy": Solver("fleet-policy", "eosp.kinds.fleet.config:FleetPolicyConfig",
                                      "eosp.kinds.fleet.policy:solve_policy", "the learned fleet policy, greedy decoding"),
               "fleet-sample": Solver("fleet-sample", "eosp.kinds.fleet.config:FleetSampleConfig",
                                      "eosp.kinds.fleet.policy:solve_sample", "batched samples of the fleet policy"),
               "fleet-features": Solver("fleet-features", "eosp.kinds.fleet.config:FleetFeaturesConfig",
                                        "eosp.kinds.fleet.policy:solve_features",
                                        "the fleet policy's decoder with a hand rule, no network")}
    sources = (Source("an astro-reason aeossp_standard case (mission.yaml, satellites.yaml, tasks.yaml)",
                      f"{HERE}:is_case", f"{HERE}:import_case"),)
    generators = (Generator("--fleet", "eosp.fleet.generate:FleetGenConfig", f"{HERE}:generate"),)
    exports = {"aeossp": Export("aeossp", "aeossp solution.json", f"{HERE}:export_aeossp"),
               "csv": Export("csv", "CSV", f"{HERE}:export_csv"),
               "czml": Export("czml", "CZML (Cesium)", f"{HERE}:export_czml"),
               "kml": Export("kml", "KML (tracks, targets, observations)", f"{HERE}:export_kml")}

    def detect(self, path: str) -> Detection:
        from eosp.fleet.io import KIND, is_fleet_dir

        if is_fleet_dir(path):
            return Detection(True, "a fleet directory")
        return Detection(False, f"not a fleet directory (no meta.json of kind {KIND!r} beside satellites.parquet)")

    def read(self, path: str, solving: bool = True) -> FleetData:
        from eosp.fleet.io import read_fleet

        return FleetData(*read_fleet(path, with_opportunities=solving), Path(path) / "meta.json")

    def read_schedule(self, path: str, problem: FleetData) -> Any:
        from eosp.fleet.io import read_schedule

        return read_schedule(path, problem.fleet)[0]

    def write_schedule(self, schedule: Any, problem: FleetData, path: str, overwrite: bool = False,
                       info: dict | None = None) -> Path:
        from eosp.fleet.io import write_schedule

        return write_schedule(schedule, problem.fleet, path, overwrite=overwrite, info=info)

    def check(self, problem: FleetData, schedule: Any) -> Verdict:
        """The checker's verdict, its memory over the horizon estimated before any geometry."""
        from eosp.fleet.check import validate
        from eosp.fleet.opportunities import require_check_memory

        if problem.geo is None:
            require_check_memory(problem.fleet, problem.meta)
        return validate(problem.fleet, schedule, problem.geo).verdict()

    def describe(self, problem: FleetData, path: str) -> str:
        import numpy as np

        fleet, opps = problem.fleet, problem.opps
        tk = fleet.tasks
        per_task = opps.per_task(len(tk))
        served = per_task > 0
        nodes = np.diff(opps.pass_offsets())
        h = fleet.horizon
        sensors = {s: int((fleet.satellites.sensor == s).sum()) for s in sorted(set(fleet.satellites.sensor.tolist()))}
        total = float(tk.weight.sum())
        ub = float(tk.weight[served].sum()) / total if total > 0 else 0.0
        return "\n".join([
            f"fleet: {path} (source {fleet.source or '-'} {fleet.source_commit}, case {fleet.case_id or '-'})",
            f"horizon: {h.start.isoformat()} .. {h.end.isoformat()} ({h.seconds} s; action step {h.action_step_s} s, "
            f"geometry {h.geometry_step_s} s, resource {h.resource_step_s} s)",
            f"satellites: {len(fleet.satellites)} ({', '.join(f'{k} {v}' for k, v in sensors.items())})",
            f"tasks: {len(tk)}, total weight {tk.weight.sum():g}",
            f"opportunities: {len(opps)}; per task: {_stats(per_task)}",
            f"passes: {opps.n_passes}; nodes per pass: {_stats(nodes)}",
            f"tasks no satellite can serve: {int((~served).sum())}",
            f"conflict-free upper bound (WCR): {ub:.6f}"])

    def report(self, path: str, schedules: list[str], out: str, ns: argparse.Namespace) -> str:
        """The planner's page of the fleet's day for one or more schedules; a schedule of another fleet is refused
        (fingerprint) before anything is written."""
        from eosp.evaluation.fleet_report import check_report_out, report_page
        from eosp.fleet.io import read_schedule
        from eosp.fleet.opportunities import require_check_memory

        check_report_out(out, ns.overwrite)
        t0 = time.perf_counter()
        data = self.read(path)
        require_check_memory(data.fleet, data.meta)  # the page checks and draws the whole horizon
        scheds = labelled(schedules, lambda s: read_schedule(s, data.fleet))
        return report_page(data.fleet, data.opps, scheds, out, ns, t0)

    # ------------------------------------------------------------------ the command line
    def solver_config(self, solver: str | None) -> type:
        from eosp.kinds.fleet.config import FleetConfig

        return super().solver_config(solver) if solver in self.solvers else FleetConfig

    def before_read(self, solver: str, cfg: Any) -> None:
        import os

        workers, cpus = getattr(cfg, "workers", 1), os.cpu_count() or 1
        if workers > cpus:  # forked workers beyond the cores only share them, and each holds its own share of state
            raise InputError(f"--workers {workers}", f"more than this machine's {cpus} CPUs")
        if getattr(cfg, "pass_solver", "") == "policy":
            raise InputError("--pass-solver", "policy: no model trained on fleet passes is shipped yet; use exact, "
                                              "ramp or greedy")
        if solver in ("fleet-policy", "fleet-sample"):  # a missing, corrupt or foreign checkpoint: before any reading
            from eosp.models.pretrained import load_fleet_pretrained

            load_fleet_pretrained(cfg.checkpoint)

    def before_solve(self, problem: FleetData, path: str) -> None:
        """The pass graphs' memory over the horizon estimated, then the fleet feasible (a battery that idling alone
        runs dry has no valid schedule), before any solver runs; the Geometry built for it is kept for the solve."""
        from eosp.fleet.passgraph import require_solvable

        problem.geo = require_solvable(problem.fleet, problem.opps, problem.meta)

    def solve_inputs(self, ns: argparse.Namespace, problem: FleetData) -> dict:
        """--init (a schedule of this fleet to start from) and --freeze-until (the passes that start before it keep
        the initial schedule's actions), for the fleet solver."""
        from eosp.fleet.check import validate
        from eosp.fleet.model import parse_utc

        if ns.solver != "fleet":
            if ns.init or ns.freeze_until:
                raise InputError("--init", "re-planning is done by --solver fleet")
            return {}
        fleet = problem.fleet
        initial, freeze_s = None, None
        if ns.init:
            initial = self.read_schedule(ns.init, problem)  # a schedule of another fleet is refused (fingerprint)
            res = validate(fleet, initial, problem.geo)
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
        return {"initial": initial, "freeze_until_s": freeze_s}

    def solved(self, out: Path, solver: str, cfg: Any, res: Result, seconds: float) -> tuple[dict, str]:
        n = len(res.schedule)
        if solver == "greedy":
            m = res.verdict.metrics
            info = {"value": m["WCR"], "solver": solver, "seconds": round(seconds, 3)}
            return info, (f"{out}: {n} observations, WCR {m['WCR']:.6f} CR {m['CR']:.6f} "
                          f"TAT {m['TAT'] if m['TAT'] is None else round(m['TAT'], 3)} PC {m['PC']:.3f} "
                          f"({seconds:.1f} s)")
        if solver in ("fleet-policy", "fleet-sample", "fleet-features"):
            i = res.info
            info = {"value": res.value, "solver": solver, "raw_wcr": i["raw_wcr"], "polish": i["polish"],
                    "seconds": round(seconds, 3), "time_limit": getattr(cfg, "time_limit", None)}
            extra = f", {i['episodes']} episodes" if "episodes" in i else ""
            return info, (f"{out}: {n} observations, WCR {res.value:.6f} (raw decode {i['raw_wcr']:.6f}, polish "
                          f"{i['polish']}); {i['decisions']} decisions, {i['decisions_per_s']:.0f} a second{extra} "
                          f"({seconds:.1f} s)")
        info = {"value": res.value, "solver": "fleet", "pass_solver": cfg.pass_solver, "seconds": round(seconds, 3),
                "bound": res.bound, "gap": res.gap, "bound_source": res.bound_kind, "time_limit": cfg.time_limit,
                "rounds": res.info["rounds"], "warm_start": cfg.warm_start}
        why = res.info["no_lagrangian_bound_because"]
        source = f"{res.bound_kind}{'' if why is None else f': {why}'}"
        bound = "" if res.bound is None else f", bound {res.bound:.6f} ({source}), gap {res.gap:.4%}"
        stop = (f" (the first schedule, found after the time limit at {res.info['first_schedule_s']:.1f} s: "
                f"{late_because(res)})" if res.info.get("first_after_limit") else "")
        return info, (f"{out}: {n} observations, WCR {res.value:.6f}{bound}; {res.info['rounds']} rounds, "
                      f"{res.info['pass_solves']} pass solves ({seconds:.1f} s){stop}")

    def solve_arguments(self, p: argparse.ArgumentParser) -> None:
        p.add_argument("--init", default="", help="a schedule of this fleet to start from")
        p.add_argument("--freeze-until", default="", metavar="UTC",
                       help="keep the passes that start before this time (ISO 8601) as in --init")

    def arguments(self, command: str, p: argparse.ArgumentParser, solver: str | None) -> None:
        if command == "generate":
            p.description = "Draw a synthetic fleet (Walker-delta orbits, tasks on land, in cities or clusters)."
        elif command == "report":
            from eosp.evaluation.fleet_report import PAGE

            p.description = PAGE
        elif command == "scenario":
            from eosp.args import add_config_args
            from eosp.ops.scenario import ScenarioConfig

            p.description = ("A fleet's day in operation (docs/operations.md): the catalogue and urgent requests that "
                             "arrive, ground stations and their contacts, the cloud model's parameters; written as "
                             "a scenario directory (docs/formats.md).")
            p.add_argument("problem", metavar="FLEET_DIR", help="a fleet directory (eosp import, eosp generate --fleet)")
            p.add_argument("--out", required=True, help="the scenario directory to write")
            p.add_argument("--overwrite", action="store_true", help="replace a scenario directory eosp wrote")
            add_config_args(p, ScenarioConfig)
        elif command == "simulate":
            from eosp.args import add_config_args
            from eosp.kinds.fleet.operations import SimulateConfig

            p.description = ("A planner run through realizations of an operations scenario: planning calls on its "
                             "cadence, plans uploaded at ground contacts, acquisitions met by the realized clouds, "
                             "every executed timeline checked; served weight against the clairvoyant bound "
                             "(docs/operations.md).")
            p.add_argument("problem", metavar="SCEN", help="a scenario directory (eosp scenario)")
            p.add_argument("--out", required=True, help="the run directory to write (RUN/summary.json)")
            p.add_argument("--resume", action="store_true", help="go on from the realizations RUN holds")
            p.add_argument("--overwrite", action="store_true", help="start a run directory eosp wrote again")
            p.add_argument("--replay", type=int, default=0, metavar="N",
                           help="write the replay page of the first N realizations (RUN/replay-NNNN.html: per "
                                "satellite its contacts, uploads and acquisitions, per contact what it reported, "
                                "every urgent request's service)")
            add_config_args(p, SimulateConfig)
        super().arguments(command, p, solver)


KIND = FleetKind()
