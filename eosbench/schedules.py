"""EOS-Bench schedule files: read as their schedulers write them (``schedulers/schedule_output.py``), written in
the same form so that their tools read ours.

A schedule file is a JSON object: ``scenario_id``, ``start_time``, ``end_time``, ``assignments`` (task_id,
satellite_id, sat_start_time, sat_end_time, sensor_id, orbit_number, data_volume_GB, power_cost_W, sat_angles,
priority; ground_station_id, gs_start_time, gs_end_time when the scenario has ground stations),
``unassigned_tasks`` and ``metrics`` (TP, TCR, BD, TM, RT, RV).  eosp adds its ownership mark (key ``"eosp"``)
first and an ``"eosp_info"`` object; their readers ignore both.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from eosp.eosbench.model import ONE_US, Scenario, Schedule
from eosp.eosbench.read import AGILE_KEYS, FIXED_KEYS, MAX_ORBIT, Unsupported, parse_time
from eosp.errors import InputError

MARK = "eosbench-schedule"


def read_schedule(path: str, scenario: Scenario) -> Schedule:
    """The schedule file at `path` for `scenario`; one InputError line naming the assignment at fault."""
    path = str(path)
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(path, f"not valid JSON: {exc}") from None
    if not isinstance(data, dict) or not isinstance(data.get("assignments"), list):
        raise InputError(path, "not an EOS-Bench schedule (a JSON object with a list 'assignments')")
    task_of = {t: i for i, t in enumerate(scenario.tasks.ids)}
    sat_of = {s: i for i, s in enumerate(scenario.satellites.ids)}
    gs_of = {g: i for i, g in enumerate(scenario.stations)}
    rows, ptr, pitch, yaw, roll, fixed = [], [0], [], [], [], []
    for i, a in enumerate(data["assignments"]):
        where = f"assignments[{i}]"
        if not isinstance(a, dict):
            raise InputError(path, f"{where}: expected an object")
        if a.get("task_id") not in task_of:
            raise InputError(path, f"{where}: task {a.get('task_id')!r} is not a mission of {scenario.path}")
        if a.get("satellite_id") not in sat_of:
            raise InputError(path, f"{where}: satellite {a.get('satellite_id')!r} is not in {scenario.path}")
        t = (lambda k: (parse_time(path, f"{where}.{k}", a.get(k)) - scenario.start) // ONE_US)
        start, end = t("sat_start_time"), t("sat_end_time")
        gs = a.get("ground_station_id")
        if gs is not None and gs not in gs_of:
            raise InputError(path, f"{where}: ground station {gs!r} is not in {scenario.path}")
        gs_start = t("gs_start_time") if a.get("gs_start_time") is not None else 0
        gs_end = t("gs_end_time") if a.get("gs_end_time") is not None else 0
        has_times = a.get("gs_start_time") is not None and a.get("gs_end_time") is not None
        num = (lambda k: _number(path, f"{where}.{k}", a.get(k, 0.0)))
        orbit = a.get("orbit_number", 0) or 0
        if isinstance(orbit, bool) or not isinstance(orbit, (int, float)) or not np.isfinite(orbit) \
                or orbit != int(orbit) or abs(orbit) > MAX_ORBIT:
            raise InputError(path, f"{where}.orbit_number: expected an integer of at most {MAX_ORBIT:,} in size, "
                                   f"got {orbit!r}")
        rows.append((task_of[a["task_id"]], sat_of[a["satellite_id"]], start, end, int(orbit), num("data_volume_GB"),
                     num("power_cost_W"), gs_of[gs] if gs is not None and has_times else -1, gs_start, gs_end,
                     str(a.get("sensor_id", "") or "")))
        ang = a.get("sat_angles")
        row = (np.nan, np.nan, np.nan)
        if isinstance(ang, dict) and all(k in ang for k in AGILE_KEYS):
            lists = [ang[k] for k in AGILE_KEYS]
            if not all(isinstance(x, list) for x in lists) or len({len(x) for x in lists}) != 1:
                raise InputError(path, f"{where}.sat_angles: {', '.join(AGILE_KEYS)} must be lists of one length")
            try:
                arr = np.asarray(lists, dtype=np.float64)
            except (TypeError, ValueError):
                raise InputError(path, f"{where}.sat_angles: angles must be numbers") from None
            pitch.append(arr[0])
            yaw.append(arr[1])
            roll.append(arr[2])
            ptr.append(ptr[-1] + arr.shape[1])
        elif isinstance(ang, dict) and all(k in ang for k in FIXED_KEYS):
            row = tuple(_number(path, f"{where}.sat_angles.{k}", ang[k]) for k in FIXED_KEYS)
            ptr.append(ptr[-1])
        elif ang is None:
            ptr.append(ptr[-1])
        else:
            raise Unsupported(path, f"{where}.sat_angles: unsupported attitude form (this kind reads "
                                    f"{'/'.join(AGILE_KEYS)} lists or {'/'.join(FIXED_KEYS)} numbers, as their "
                                    "generator writes)")
        fixed.append(row)
    m = len(rows)
    col = (lambda j, dt: np.asarray([r[j] for r in rows], dtype=dt))
    cat = (lambda xs: np.concatenate(xs) if xs else np.zeros(0))
    info = {"metrics": data.get("metrics")} if isinstance(data.get("metrics"), dict) else {}
    if isinstance(data.get("eosp_info"), dict):
        info.update(data["eosp_info"])
    return Schedule(col(0, np.int32), col(1, np.int32), col(2, np.int64), col(3, np.int64), [r[10] for r in rows],
                    col(4, np.int64), col(5, np.float64), col(6, np.float64), np.asarray(ptr, dtype=np.int64),
                    cat(pitch), cat(yaw), cat(roll), np.asarray(fixed, dtype=np.float64).reshape(m, 3),
                    col(7, np.int32), col(8, np.int64), col(9, np.int64), info)


def _number(path: str, where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(path, f"{where}: expected a number, got {value!r}")
    return float(value)


def schedule_json(schedule: Schedule, scenario: Scenario, metrics: dict | None = None,
                  info: dict | None = None) -> dict:
    """The schedule as their ``save_schedule_to_json`` writes it (plus eosp's mark and info)."""
    has_gs = len(scenario.stations) > 0
    assigned = {scenario.tasks.ids[t] for t in schedule.task.tolist()}
    out: dict[str, Any] = {"eosp": MARK, "scenario_id": scenario.name, "start_time": scenario.start.isoformat(),
                           "end_time": scenario.time_of(scenario.horizon_us).isoformat(), "assignments": [],
                           "unassigned_tasks": sorted(set(scenario.tasks.ids) - assigned)}
    for i in range(len(schedule)):
        t, s = int(schedule.task[i]), int(schedule.satellite[i])
        lo, hi = int(schedule.att_ptr[i]), int(schedule.att_ptr[i + 1])
        if hi > lo:
            angles: Any = {"pitch_angles": schedule.pitch[lo:hi].tolist(), "yaw_angles": schedule.yaw[lo:hi].tolist(),
                           "roll_angles": schedule.roll[lo:hi].tolist()}
        elif not np.isnan(schedule.fixed[i]).any():
            angles = dict(zip(FIXED_KEYS, schedule.fixed[i].tolist()))
        else:
            angles = None
        a: dict[str, Any] = {"task_id": scenario.tasks.ids[t], "satellite_id": scenario.satellites.ids[s]}
        gs = int(schedule.station[i])
        if has_gs:
            a["ground_station_id"] = scenario.stations[gs] if gs >= 0 else None
        a.update({"sat_start_time": scenario.iso(schedule.start_us[i]), "sat_end_time": scenario.iso(schedule.end_us[i]),
                  "sensor_id": schedule.sensor_id[i], "orbit_number": int(schedule.orbit[i]),
                  "data_volume_GB": float(schedule.data_gb[i]), "power_cost_W": float(schedule.power_w[i]),
                  "sat_angles": angles})
        if has_gs:
            a["gs_start_time"] = scenario.iso(schedule.gs_start_us[i]) if gs >= 0 else None
            a["gs_end_time"] = scenario.iso(schedule.gs_end_us[i]) if gs >= 0 else None
        a["priority"] = float(scenario.tasks.priority[t])
        out["assignments"].append(a)
    if metrics is not None:
        out["metrics"] = metrics
    if info:
        out["eosp_info"] = info
    return out


def write_schedule(schedule: Schedule, scenario: Scenario, path: str, overwrite: bool = False,
                   metrics: dict | None = None, info: dict | None = None) -> Path:
    """Write `schedule` to `path` (the ownership rule of :mod:`eosp.ownership`, written atomically)."""
    from eosp.atomic import atomic_path
    from eosp.ownership import check_output

    out = check_output(path, MARK, overwrite=overwrite, suffixes=(".json",))
    with atomic_path(out) as tmp:
        # compact: eosp finds its mark in the first MiB of a JSON file (eosp.ownership)
        tmp.write_text(json.dumps(schedule_json(schedule, scenario, metrics, info), ensure_ascii=False,
                                  separators=(",", ":")), encoding="utf-8")
    return out
