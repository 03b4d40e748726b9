"""Read an astro-reason ``aeossp_standard`` case directory and its ``solution.json``; write solutions.

A case is three YAML files (mission.yaml, satellites.yaml, tasks.yaml).  Every rule the
benchmark's loader enforces is enforced here too, and, stricter, an unknown field is refused
(a misspelt optional field would otherwise be silently ignored).  Each refusal is an
:class:`~eosp.errors.InputError` naming the file, the entry and the reason.  A task that no
satellite can serve is valid input.
"""

from __future__ import annotations

import json
import os
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

from eosp.errors import InputError
from eosp.fleet.model import (NORAD_MAX, SENSORS, Attitude, Battery, Fleet, Horizon, Satellites, Schedule, Tasks,
                              Tles, iso_z, parse_utc, satellite_fault, strings, task_fault)

SOURCE = "aeossp_standard"
SOURCE_COMMIT = "ffd1e89"
EPS = 1.0e-9

MISSION_KEYS = {"case_id", "horizon_start", "horizon_end", "action_time_step_s", "geometry_sample_step_s",
                "resource_sample_step_s", "propagation", "scoring"}
PROPAGATION_KEYS = {"model", "frame_inertial", "frame_fixed", "earth_shape"}
SCORING_KEYS = {"ranking_order", "reported_metrics"}
SAT_KEYS = {"satellite_id", "norad_catalog_id", "tle_line1", "tle_line2", "sensor", "attitude_model",
            "resource_model"}
ATTITUDE_KEYS = ("max_off_nadir_deg", "max_slew_velocity_deg_per_s", "max_slew_acceleration_deg_per_s2",
                 "settling_time_s")
RESOURCE_KEYS = ("battery_capacity_wh", "initial_battery_wh", "idle_power_w", "imaging_power_w",
                 "slew_power_w", "sunlit_charge_power_w")
TASK_KEYS = {"task_id", "name", "latitude_deg", "longitude_deg", "altitude_m", "release_time", "due_time",
             "required_duration_s", "required_sensor_type", "weight"}
CASE_FILES = ("mission.yaml", "satellites.yaml", "tasks.yaml")


class _Doc:
    """One YAML file being read: raises InputError naming the file and the entry."""

    def __init__(self, path: Path):
        self.path = path

    def fail(self, where: str, reason: str):
        raise InputError(self.path, f"{where}: {reason}" if where else reason)

    def load(self, top: str):
        import yaml

        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise InputError(self.path, "file not found (an aeossp case directory holds "
                                        + ", ".join(CASE_FILES) + ")") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(self.path, f"cannot read: {exc}") from None
        try:  # the C loader when the build has it; either way a safe one
            doc = yaml.load(text, Loader=yaml.CSafeLoader) if hasattr(yaml, "CSafeLoader") else yaml.safe_load(text)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            at = f" at line {mark.line + 1}" if mark is not None else ""
            raise InputError(self.path, f"not valid YAML{at}: {getattr(exc, 'problem', None) or exc}") from None
        if not isinstance(doc, dict):
            self.fail("", f"expected a mapping with the key '{top}'")
        self.fields(doc, "", {top}, {top})
        return doc[top]

    def fields(self, raw, where: str, known, required) -> dict:
        if not isinstance(raw, dict):
            self.fail(where, "expected a mapping")
        unknown = sorted(str(k) for k in raw if k not in known)
        if unknown:
            self.fail(where, f"unknown field {unknown[0]!r}")
        missing = sorted(k for k in required if k not in raw)
        if missing:
            self.fail(where, f"missing field {missing[0]!r}")
        return raw

    def string(self, raw: dict, key: str, where: str) -> str:
        v = raw.get(key)
        if not isinstance(v, str) or not v:
            self.fail(where, f"{key} must be a non-empty string, got {v!r}")
        return v

    def integer(self, raw: dict, key: str, where: str) -> int:
        v = raw.get(key)
        if not isinstance(v, int) or isinstance(v, bool):
            self.fail(where, f"{key} must be an integer, got {v!r}")
        return v

    def number(self, raw: dict, key: str, where: str) -> float:
        v = raw.get(key)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v):
            self.fail(where, f"{key} must be a finite number, got {v!r}")
        return float(v)

    def time(self, raw: dict, key: str, where: str) -> datetime:
        v = self.string(raw, key, where)
        try:
            return parse_utc(v)
        except ValueError as exc:
            self.fail(where, f"{key}: {exc}")

    def items(self, raw, where: str) -> list:
        if not isinstance(raw, list):
            self.fail(where, "expected a list")
        return raw


def _aligned(seconds: float, step: int) -> bool:
    return abs(seconds / step - round(seconds / step)) <= EPS


def _read_mission(path: Path) -> tuple[Horizon, str]:
    d = _Doc(path)
    m = d.fields(d.load("mission"), "mission", MISSION_KEYS, MISSION_KEYS - {"scoring"})
    case_id = d.string(m, "case_id", "mission")
    start, end = d.time(m, "horizon_start", "mission"), d.time(m, "horizon_end", "mission")
    if end <= start:
        d.fail("mission", "horizon_end must be after horizon_start")
    seconds = (end - start).total_seconds()
    if abs(seconds - round(seconds)) > EPS:
        d.fail("mission", "the horizon must be a whole number of seconds")
    steps = []
    for key in ("action_time_step_s", "geometry_sample_step_s", "resource_sample_step_s"):
        step = d.integer(m, key, "mission")
        if not 0 < step <= seconds:
            d.fail("mission", f"{key} must be > 0 and at most the horizon ({seconds:g} s), got {step}")
        if not _aligned(seconds, step):
            d.fail("mission", f"the horizon ({seconds:g} s) is not a multiple of {key} ({step} s)")
        steps.append(step)
    prop = d.fields(m["propagation"], "mission.propagation", PROPAGATION_KEYS, {"model"})
    if d.string(prop, "model", "mission.propagation") != "sgp4":
        d.fail("mission.propagation", f"model must be 'sgp4', got {prop['model']!r}")
    if "scoring" in m:
        d.fields(m["scoring"], "mission.scoring", SCORING_KEYS, set())
    return Horizon(start, end, *steps), case_id


def _read_satellites(path: Path) -> Satellites:
    from eosp.fleet.geometry import brahe_module

    bh = brahe_module()
    d = _Doc(path)
    rows = d.items(d.load("satellites"), "satellites")
    if not rows:
        d.fail("satellites", "the list is empty (a fleet needs a satellite)")
    seen: dict[str, int] = {}
    cols: dict[str, list] = {k: [] for k in ("id", "sensor", "l1", "l2", "norad", *ATTITUDE_KEYS, *RESOURCE_KEYS)}
    for i, raw in enumerate(rows):
        where = f"satellites[{i}]"
        if isinstance(raw, dict) and isinstance(raw.get("satellite_id"), str):
            where = f"satellite {raw['satellite_id']!r} (satellites[{i}])"
        d.fields(raw, where, SAT_KEYS, SAT_KEYS)
        sid = d.string(raw, "satellite_id", where)
        if sid in seen:
            d.fail(where, f"duplicate satellite_id {sid!r} (first at satellites[{seen[sid]}])")
        seen[sid] = i
        l1, l2 = d.string(raw, "tle_line1", where), d.string(raw, "tle_line2", where)
        try:
            ok = bh.validate_tle_lines(l1, l2)
            if ok:
                bh.SGPPropagator.from_tle(l1, l2, 60.0)
        except Exception:  # brahe raises its own types on a malformed TLE
            ok = False
        if not ok:
            d.fail(where, "tle_line1/tle_line2 are not a valid TLE pair (format or checksum)")
        sensor = d.fields(raw["sensor"], f"{where}.sensor", {"sensor_type"}, {"sensor_type"})
        stype = d.string(sensor, "sensor_type", f"{where}.sensor")
        if stype not in SENSORS:
            d.fail(f"{where}.sensor", f"sensor_type must be one of {SENSORS}, got {stype!r}")
        att = d.fields(raw["attitude_model"], f"{where}.attitude_model", set(ATTITUDE_KEYS), set(ATTITUDE_KEYS))
        res = d.fields(raw["resource_model"], f"{where}.resource_model", set(RESOURCE_KEYS), set(RESOURCE_KEYS))
        for key in ATTITUDE_KEYS:
            cols[key].append(d.number(att, key, f"{where}.attitude_model"))
        for key in RESOURCE_KEYS:
            cols[key].append(d.number(res, key, f"{where}.resource_model"))
        norad = d.integer(raw, "norad_catalog_id", where)
        if not 0 <= norad <= NORAD_MAX:
            d.fail(where, f"norad_catalog_id must lie in [0, {NORAD_MAX}], got {norad}")
        cols["id"].append(sid)
        cols["sensor"].append(stype)
        cols["l1"].append(l1)
        cols["l2"].append(l2)
        cols["norad"].append(norad)
    f = {k: np.asarray(v, dtype=float) for k, v in cols.items() if k in ATTITUDE_KEYS or k in RESOURCE_KEYS}
    sats = Satellites(
        ids=strings(cols["id"]), sensor=strings(cols["sensor"]),
        tle=Tles(strings(cols["l1"]), strings(cols["l2"]), np.asarray(cols["norad"], dtype=np.int64)),
        attitude=Attitude(f["max_off_nadir_deg"], f["max_slew_velocity_deg_per_s"],
                          f["max_slew_acceleration_deg_per_s2"], f["settling_time_s"]),
        battery=Battery(f["battery_capacity_wh"], f["initial_battery_wh"], f["idle_power_w"],
                        f["imaging_power_w"], f["slew_power_w"], f["sunlit_charge_power_w"]),
    )
    fault = satellite_fault(sats)  # the ranges every fleet's satellites share (eosp.fleet.model)
    if fault is not None:
        r, key, reason = fault
        part = ".attitude_model" if key in ATTITUDE_KEYS else ".resource_model" if key in RESOURCE_KEYS else ""
        d.fail(f"satellite {cols['id'][r]!r} (satellites[{r}]){part}", f"{key} {reason}")
    return sats


def _read_tasks(path: Path, horizon: Horizon) -> Tasks:
    d = _Doc(path)
    rows = d.items(d.load("tasks"), "tasks")
    if not rows:
        d.fail("tasks", "the list is empty (a fleet needs a task)")
    seen: dict[str, int] = {}
    cols: dict[str, list] = {k: [] for k in ("id", "name", "lat", "lon", "alt", "rel", "due", "dur", "w", "sensor")}
    step = horizon.action_step_s
    for i, raw in enumerate(rows):
        where = f"tasks[{i}]"
        if isinstance(raw, dict) and isinstance(raw.get("task_id"), str):
            where = f"task {raw['task_id']!r} (tasks[{i}])"
        d.fields(raw, where, TASK_KEYS, TASK_KEYS - {"weight"})
        tid = d.string(raw, "task_id", where)
        if tid in seen:
            d.fail(where, f"duplicate task_id {tid!r} (first at tasks[{seen[tid]}])")
        seen[tid] = i
        rel, due = d.time(raw, "release_time", where), d.time(raw, "due_time", where)
        dur = d.integer(raw, "required_duration_s", where)
        w = raw.get("weight", 1.0)
        if not isinstance(w, (int, float)) or isinstance(w, bool) or not np.isfinite(w):
            d.fail(where, f"weight must be a finite number, got {w!r}")
        for key, t in (("release_time", rel), ("due_time", due)):
            if t < horizon.start or t > horizon.end:
                d.fail(where, f"{key} {iso_z(t)} lies outside the horizon [{iso_z(horizon.start)}, "
                              f"{iso_z(horizon.end)}]")
        if due <= rel:
            d.fail(where, "due_time must be after release_time")
        if dur <= 0:
            d.fail(where, f"required_duration_s must be > 0, got {dur}")
        if w <= 0:
            d.fail(where, f"weight must be > 0, got {w}")
        rel_s, due_s = (rel - horizon.start).total_seconds(), (due - horizon.start).total_seconds()
        for key, s in (("release_time", rel_s), ("due_time", due_s), ("required_duration_s", float(dur))):
            if not _aligned(s, step):
                d.fail(where, f"{key} is off the {step} s action grid")
        if dur > int((due - rel).total_seconds()):
            d.fail(where, f"required_duration_s {dur} is longer than the window ({due_s - rel_s:g} s)")
        stype = d.string(raw, "required_sensor_type", where)
        if stype not in SENSORS:
            d.fail(where, f"required_sensor_type must be one of {SENSORS}, got {stype!r}")
        cols["id"].append(tid)
        cols["name"].append(d.string(raw, "name", where))
        cols["lat"].append(d.number(raw, "latitude_deg", where))
        cols["lon"].append(d.number(raw, "longitude_deg", where))
        cols["alt"].append(d.number(raw, "altitude_m", where))
        cols["rel"].append(rel_s)
        cols["due"].append(due_s)
        cols["dur"].append(float(dur))
        cols["w"].append(float(w))
        cols["sensor"].append(stype)
    fl = {k: np.asarray(cols[k], dtype=float) for k in ("lat", "lon", "alt", "rel", "due", "dur", "w")}
    tasks = Tasks(strings(cols["id"]), strings(cols["name"]), fl["lat"], fl["lon"], fl["alt"], fl["rel"],
                  fl["due"], fl["dur"], fl["w"], strings(cols["sensor"]))
    fault = task_fault(tasks, horizon)  # the ranges every fleet's tasks share (eosp.fleet.model)
    if fault is not None:
        r, key, reason = fault
        key = {"release_s": "release_time", "due_s": "due_time", "duration_s": "required_duration_s",
               "sensor_type": "required_sensor_type"}.get(key, key)
        d.fail(f"task {cols['id'][r]!r} (tasks[{r}])", f"{key} {reason}")
    return tasks


def is_case_dir(path: str | os.PathLike) -> bool:
    """A directory holding the three files of an aeossp case."""
    p = Path(path)
    return p.is_dir() and all((p / f).is_file() for f in CASE_FILES)


EVALUATION_SPLITS = ("test", "test_easy", "test_hard", "test_horizon_2022")  # aeossp_standard's held-out cases


def refuse_evaluation_case(path: str | os.PathLike, flag: str) -> None:
    """An InputError when `path` is an aeossp case of an evaluation split (its folder ``cases/<split>/``): what
    trains or tunes never reads them (a fleet directory imported from one cannot be told apart: the user's to
    keep out)."""
    p = Path(path).resolve()
    if is_case_dir(p) and p.parent.name in EVALUATION_SPLITS and p.parent.parent.name == "cases":
        raise InputError(f"{flag} {path}", f"an aeossp case of the evaluation split {p.parent.name!r}: training data "
                                           "never comes from the evaluation splits (use the train split)")


def read_case(case_dir: str | os.PathLike) -> Fleet:
    """The fleet of an aeossp_standard case directory (InputError on any bad entry)."""
    root = Path(case_dir)
    if not root.is_dir():
        raise InputError(root, "not a directory (an aeossp case directory holds " + ", ".join(CASE_FILES) + ")")
    horizon, case_id = _read_mission(root / "mission.yaml")
    sats = _read_satellites(root / "satellites.yaml")
    tasks = _read_tasks(root / "tasks.yaml", horizon)
    return Fleet(horizon, sats, tasks, source=SOURCE, source_commit=SOURCE_COMMIT, case_id=case_id)


def _offset_us(t: datetime, start: datetime) -> int:
    return (t - start) // timedelta(microseconds=1)


def read_solution(path: str | os.PathLike, horizon: Horizon) -> Schedule:
    """The observation actions of an aeossp ``solution.json`` (times as microsecond offsets)."""
    path = Path(path)
    try:
        payload = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(path, f"not valid JSON: {exc}") from None
    if not isinstance(payload, dict) or "actions" not in payload:
        raise InputError(path, "must be a JSON object with the key 'actions' (an aeossp solution; an empty schedule "
                               "is {\"actions\": []})")
    actions = payload["actions"]
    if not isinstance(actions, list):
        raise InputError(path, "'actions' must be a list")
    sat, task, st, en = [], [], [], []
    for i, a in enumerate(actions):
        where = f"actions[{i}]"
        if not isinstance(a, dict):
            raise InputError(path, f"{where}: expected an object")
        if a.get("type") != "observation":
            raise InputError(path, f"{where}: type {a.get('type')!r} is unsupported (only 'observation')")
        for key in ("satellite_id", "task_id", "start_time", "end_time"):
            if not isinstance(a.get(key), str) or not a.get(key):
                raise InputError(path, f"{where}: {key} must be a non-empty string")
        try:
            s, e = parse_utc(a["start_time"]), parse_utc(a["end_time"])
        except ValueError as exc:
            raise InputError(path, f"{where}: {exc}") from None
        sat.append(a["satellite_id"])
        task.append(a["task_id"])
        st.append(_offset_us(s, horizon.start))
        en.append(_offset_us(e, horizon.start))
    return Schedule(strings(sat), strings(task), np.asarray(st, dtype=np.int64), np.asarray(en, dtype=np.int64))


def solution_payload(schedule: Schedule, horizon: Horizon) -> dict:
    """The aeossp solution object of a schedule."""
    return {"actions": [
        {"type": "observation", "satellite_id": str(s), "task_id": str(t),
         "start_time": iso_z(horizon.utc(a)), "end_time": iso_z(horizon.utc(b))}
        for s, t, a, b in zip(schedule.satellite.tolist(), schedule.task.tolist(),
                              schedule.start_us.tolist(), schedule.end_us.tolist())]}


def write_solution(schedule: Schedule, horizon: Horizon, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Write an aeossp ``solution.json`` atomically; an existing file is replaced only with `overwrite`."""
    from eosp.atomic import atomic_path
    from eosp.ownership import check_output, json_mark

    path = check_output(path, "fleet-solution", overwrite=overwrite, suffixes=(".json",))
    with atomic_path(path) as tmp:
        payload = {**json_mark("fleet-solution"), **solution_payload(schedule, horizon)}  # the verifier ignores "eosp"
        tmp.write_text(json.dumps(payload, indent=2) + "\n", encoding="utf-8")
    return path
