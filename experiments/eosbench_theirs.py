"""EOS-Bench's own code, driven from its own environment: scenarios from its generator with the randomness pinned,
and its checker's verdict and metrics on schedule files.

Runs under EOS-Bench's interpreter (an environment with their requirements), in a fetched copy of their repository
with that copy on the path: ``cd THEIR_REPO && PYTHONPATH=. THEIR_PYTHON .../experiments/eosbench_theirs.py ...``;
it imports their modules and none of eosp.

``generate``: their ``main_generate._run_single_scenario_task`` (random targets, ``ensure_each_mission_has_window``
as their random mode sets it), with two things pinned so that a scenario can be made again:

* ``random`` seeded (their generator draws targets, priorities and durations from the unseeded module);
* the satellites' epoch: their input files write it as "18 Nov 2025 12:00:00.000", a form their ``_parse_epoch``
  does not read, so it falls back to the current time; here it is read as written (the scenario's start).

``check``: each schedule's assignments replayed, in file order, through their ``ConstraintModel.
is_feasible_assignment`` against the ones before (what every scheduler of theirs does before keeping an assignment),
and their ``compute_evaluation_metrics``; one JSON line per schedule: the index of the first assignment refused
(-1 when none), TP, TCR, BD, TM, or the exception their code raised.
"""

from __future__ import annotations

import argparse
import json
import random
import shutil
import time
from datetime import datetime, timezone
from pathlib import Path


def _pin_epoch() -> None:
    import utils.visibility as vis

    original = vis._parse_epoch

    def parse(epoch):
        if isinstance(epoch, str):
            try:
                return datetime.strptime(epoch.strip(), "%d %b %Y %H:%M:%S.%f").replace(tzinfo=timezone.utc)
            except ValueError:
                pass
        return original(epoch)

    vis._parse_epoch = parse


def generate(ns: argparse.Namespace) -> None:
    random.seed(ns.seed)
    _pin_epoch()
    import main_generate as mg

    info = mg.RANDOM_MISSION_INFOS[1] if ns.dist == 0 else mg.RANDOM_MISSION_INFOS[0]
    assert info.distribution_type == ns.dist
    sat_json = mg.INPUT_DIR / f"{ns.sat_file}.json"
    n_sat = len(json.loads(sat_json.read_text()))
    t0 = time.time()
    res = mg._run_single_scenario_task({
        "scenario_name": ns.name, "sat_json_path": str(sat_json), "n_sat": n_sat, "n_missions": ns.missions,
        "time_period_days": ns.days, "mission_info": info, "ground_stations_dict": {},
        "ensure_each_mission_has_window": True, "targets_file_path": None, "targets_tag": None})
    if not res["ok"]:
        raise SystemExit(f"their generator failed: {res['error']}")
    out = Path(ns.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    shutil.move(str(mg.OUTPUT_DIR / res["out_filename"]), out)
    print(json.dumps({"scenario": str(out), "seconds": time.time() - t0, "seed": ns.seed}))


def _schedule(problem, path: str):
    from schedulers.constraint_model import Assignment, Schedule
    from schedulers.scenario_loader import _parse_iso_time

    data = json.loads(Path(path).read_text())
    out = Schedule()
    for a in data["assignments"]:
        t = (lambda k: _parse_iso_time(a[k]) if a.get(k) else None)
        out.assignments.append(Assignment(
            task_id=a["task_id"], satellite_id=a["satellite_id"], sat_start_time=t("sat_start_time"),
            sat_end_time=t("sat_end_time"), sat_window_id=0, sensor_id=a.get("sensor_id", ""),
            orbit_number=int(a.get("orbit_number", 0) or 0), data_volume_GB=float(a.get("data_volume_GB", 0.0)),
            power_cost_W=float(a.get("power_cost_W", 0.0)), sat_angles=a.get("sat_angles"),
            ground_station_id=a.get("ground_station_id"), gs_start_time=t("gs_start_time"),
            gs_end_time=t("gs_end_time")))
    return out


def check(ns: argparse.Namespace) -> None:
    from schedulers.constraint_model import ConstraintModel, Schedule
    from schedulers.evaluation_metrics import compute_evaluation_metrics
    from schedulers.scenario_loader import load_scheduling_problem_from_json

    problem = load_scheduling_problem_from_json(ns.scenario)
    cm = ConstraintModel(problem=problem, placement_mode="earliest", unassigned_penalty=1000.0,
                         downlink_duration_ratio=ns.downlink_ratio)
    for path in ns.schedules:
        row = {"schedule": path}
        try:
            sched = _schedule(problem, path)
            replay, first = Schedule(), -1
            for i, a in enumerate(sched.assignments):
                if first < 0 and not cm.is_feasible_assignment(a, replay):
                    first = i
                replay.assignments.append(a)
            m = compute_evaluation_metrics(problem, sched, runtime_seconds=0.0)
            row.update(first=first, TP=m.task_profit, TCR=m.task_completion_rate, BD=m.balance_degree,
                       TM=m.timeliness_metric)
        except Exception as exc:  # their code's own failure is the answer (a non-agile satellite: AttributeError)
            row.update(error=f"{type(exc).__name__}: {exc}")
        print(json.dumps(row), flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    g = sub.add_parser("generate")
    g.add_argument("--sat-file", required=True, help="a constellation file of their input/ (3_satellites)")
    g.add_argument("--missions", type=int, required=True)
    g.add_argument("--days", type=float, required=True)
    g.add_argument("--dist", type=int, choices=(0, 1), default=0, help="0 global uniform, 1 five regions")
    g.add_argument("--seed", type=int, required=True)
    g.add_argument("--name", default="Scenario_S1")
    g.add_argument("--out", required=True)
    c = sub.add_parser("check")
    c.add_argument("scenario")
    c.add_argument("schedules", nargs="+")
    c.add_argument("--downlink-ratio", type=float, default=1.0)
    ns = p.parse_args()
    {"generate": generate, "check": check}[ns.command](ns)


if __name__ == "__main__":
    main()
