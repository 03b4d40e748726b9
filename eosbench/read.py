"""Reading an EOS-Bench scenario JSON as a stream (ijson), never as one document in memory.

Their scenarios store every window's attitude once per second (about 11 MB for 10 satellites x 200 tasks x 12 h,
gigabytes at 100 satellites and more), so the reader walks the parser's events: the small sections (metadata,
satellites, missions, ground stations, communication windows) are built as objects, and the observation windows'
attitude samples go straight into growing float arrays.

What it accepts is what their loader (``schedulers/scenario_loader.py``) reads, with its defaults (a missing
priority is 1, a missing duration 0, a window's orbit number, time step and attitude fall back to the
observation-window entry, then to the metadata's time step), and it refuses what their loader drops without a
word: a window naming an unknown mission or satellite, a window that does not end after it starts.  Fields their
scheduler never reads are kept in :attr:`Scenario.ignored` with the reason; a field that states a constraint
their model does not check (a required resolution, sensor mode or elevation on a mission) is refused, naming it
(:class:`Unsupported`).  Every refusal is one :class:`~eosp.errors.InputError` line: the file, the entry, why.
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from eosp.eosbench.model import ONE_US, CommWindows, Satellites, Scenario, Tasks, Windows
from eosp.errors import InputError

TOP_KEYS = {"scenario_id", "scenario_type", "metadata", "satellites", "missions", "ground_stations",
            "observation_windows", "communication_windows"}
OW_KEYS = {"satellite_id", "sensor_id", "mission_id", "time_windows", "orbit_number", "time_step", "agile_data",
           "non_agile_data"}
TW_KEYS = {"start_time", "end_time", "orbit_number", "time_step", "agile_data", "non_agile_data"}
AGILE_KEYS = ("pitch_angles", "yaw_angles", "roll_angles")
FIXED_KEYS = ("pitch_angle", "yaw_angle", "roll_angle")
# fields their scheduler reads nowhere (schedulers/, algorithms/): kept, reported by `eosp info`, never checked
NOT_CONSTRAINTS = {
    "satellite_specs.max_operation_time_s": "stored by their generator, read by no scheduler",
    "satellite_specs.max_battery_capacity_Wh": "stored by their generator, read by no scheduler",
    "satellite_specs.max_fuel_kg": "stored by their generator, read by no scheduler",
    "maneuverability_capability.slew_rate_deg_per_s": "their transition model ignores it (a piecewise function of "
                                                      "the attitude change, or 11.66 s)",
    "maneuverability_capability.stabilization_time_s": "their transition model ignores it",
    "maneuverability_capability.max_*_angle_deg": "applied by their generator (windows end where the attitude "
                                                  "exceeds it), not by their checker",
}
# requirements a mission may state that their constraint model does not check: refused when set
UNSUPPORTED_REQUIREMENTS = ("required_resolution", "required_mode", "min_elevation_angle_deg")


class Unsupported(InputError):
    """A scenario states a constraint this kind does not check (one line naming it; exit 2 like any bad input)."""


def looks_like_scenario(path: str) -> tuple[bool, str]:
    """Whether `path` is an EOS-Bench scenario JSON, judged from its first bytes (a JSON object with a
    "scenario_id" or "metadata" key and "satellites" or "missions"), and why not."""
    p = Path(path)
    if not p.is_file():
        return False, "not a file"
    if p.suffix.lower() != ".json":
        return False, "not a .json file"
    try:
        with open(p, "rb") as fh:
            head = fh.read(65536)
    except OSError as exc:
        return False, f"cannot read ({exc.strerror})"
    if head.startswith(BOM):
        return False, "starts with a UTF-8 byte-order mark, which JSON readers (theirs included) refuse: save it without"
    text = head.lstrip()
    if not text.startswith(b"{"):
        return False, "not a JSON object"
    if b'"eosp"' in head[:200]:
        return False, "a file eosp wrote (a schedule), not a scenario"
    if (b'"scenario_id"' in head or b'"metadata"' in head) and (b'"satellites"' in head or b'"missions"' in head):
        return True, "an EOS-Bench scenario"
    return False, "no EOS-Bench scenario keys (scenario_id/metadata, satellites/missions) in its first 64 KiB"


def parse_time(path: str, where: str, text: Any) -> datetime:
    """An ISO time as their loader reads it: naive UTC ("Z" or an offset converted to UTC)."""
    if not isinstance(text, str):
        raise InputError(path, f"{where}: expected an ISO time string, got {text!r}")
    s = text.strip()
    try:
        dt = datetime.fromisoformat(s[:-1] + "+00:00" if s.endswith("Z") else s)
    except ValueError:
        raise InputError(path, f"{where}: {text!r} is not an ISO time") from None
    return dt.astimezone(timezone.utc).replace(tzinfo=None) if dt.tzinfo is not None else dt


BOM = b"\xef\xbb\xbf"
MAX_ANGLE_DEG = 360.0  # an attitude angle beyond a turn is no attitude (1e300 made numpy warn in the checks)
MAX_ORBIT = 2**31 - 1  # an orbit number held as int32 by their schema's readers; beyond it no orbit of a year
MAX_DURATION_S = 366 * 86400  # a scenario's horizon at most a year (theirs: hours to a day)


def _angles(path: str, where: str, values: list) -> None:
    """Attitude samples (degrees): finite and within a turn, else an InputError naming the first bad one."""
    a = np.asarray(values, dtype=np.float64)
    bad = ~np.isfinite(a) | (np.abs(a) > MAX_ANGLE_DEG)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(path, f"{where}[{i}]: {values[i]!r} is not an angle in [-{MAX_ANGLE_DEG:g}, "
                               f"{MAX_ANGLE_DEG:g}] degrees")


def _num(path: str, where: str, value: Any, default: float | None = None) -> float:
    if value is None and default is not None:
        return default
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(path, f"{where}: expected a number, got {value!r}")
    out = float(value)
    if not np.isfinite(out):
        raise InputError(path, f"{where}: {value!r} is not a finite number")
    return out


def _obj(path: str, where: str, value: Any) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise InputError(path, f"{where}: expected an object, got {type(value).__name__}")
    return value


def _list(path: str, where: str, value: Any) -> list:
    if value is None:
        return []
    if not isinstance(value, list):
        raise InputError(path, f"{where}: expected a list, got {type(value).__name__}")
    return value


def _agility(sat: dict) -> bool:
    """Their _infer_maneuverability_type: the first type found (maneuverability_capability, the top level, the
    attributes, a payload or payloads), "non" in it meaning non-agile; agile by default."""
    def norm(v: Any) -> bool | None:
        if isinstance(v, str):
            s = v.strip().lower()
            if "non" in s:
                return False
            if "agile" in s:
                return True
        return None

    places: list[Any] = []
    mcap = sat.get("maneuverability_capability")
    if isinstance(mcap, dict):
        places.append(mcap.get("maneuverability_type") or mcap.get("type"))
    places.append(sat.get("maneuverability_type"))
    if isinstance(sat.get("attributes"), dict):
        places.append(sat["attributes"].get("maneuverability_type"))
    payloads = [sat["payload"]] if isinstance(sat.get("payload"), dict) else []
    payloads += [p for p in sat.get("payloads") or [] if isinstance(p, dict)] if isinstance(sat.get("payloads"),
                                                                                            list) else []
    for p in payloads:
        places.append(p.get("maneuverability_type"))
        if isinstance(p.get("attributes"), dict):
            places.append(p["attributes"].get("maneuverability_type"))
    for v in places:
        got = norm(v)
        if got is not None:
            return got
    return True


class _WindowStream:
    """The observation windows, fed event by event (see the module docstring)."""

    def __init__(self, path: str):
        self.path = path
        self.rows: list[tuple] = []  # (ow index, tw index, sat id, mission id, sensor id, fields of the tw)
        self.pitch: list[float] = []
        self.yaw: list[float] = []
        self.roll: list[float] = []
        self.att_ptr = [0]
        self.ow = -1
        self.ow_fields: dict = {}
        self.tw: dict | None = None
        self.tw_index = -1
        self.pending: list[dict] = []
        self.target: list[float] | None = None

    def where(self) -> str:
        return f"observation_windows[{self.ow}]" + ("" if self.tw is None else f".time_windows[{self.tw_index}]")

    def event(self, prefix: str, event: str, value: Any) -> None:
        if prefix == "observation_windows":
            if event not in ("start_array", "end_array"):
                raise InputError(self.path, "observation_windows: expected a list")
            return
        rest = prefix[len("observation_windows.item"):]
        if rest == "":
            if event == "start_map":
                self.ow, self.ow_fields, self.pending, self.tw_index = self.ow + 1, {}, [], -1
            elif event == "end_map":
                self._end_ow()
            elif event != "map_key":
                raise InputError(self.path, f"observation_windows[{self.ow + 1}]: expected an object")
            elif value not in OW_KEYS:
                raise InputError(self.path, f"observation_windows[{self.ow}]: unsupported field {value!r} (known: "
                                            f"{', '.join(sorted(OW_KEYS))})")
            return
        if rest.startswith(".time_windows.item"):
            self._tw_event(rest[len(".time_windows.item"):], event, value)
            return
        if rest == ".time_windows":
            if event not in ("start_array", "end_array"):
                raise InputError(self.path, f"observation_windows[{self.ow}].time_windows: expected a list")
            return
        self._field(self.ow_fields, rest[1:], event, value, f"observation_windows[{self.ow}]")

    def _field(self, fields: dict, key: str, event: str, value: Any, where: str) -> None:
        """A scalar field, or the number lists of agile_data / the numbers of non_agile_data."""
        if key.endswith(".item") and event == "number" and self.target is not None:  # the bulk: one sample
            self.target.append(value)
            return
        head, _, tail = key.partition(".")
        if head in ("agile_data", "non_agile_data"):
            names = AGILE_KEYS if head == "agile_data" else FIXED_KEYS
            bad = f"{where}.{key}: unexpected {event} {value!r} (expected an object of " + \
                  (f"lists {', '.join(names)} of numbers)" if head == "agile_data" else f"numbers {', '.join(names)})")
            if not tail:
                if event == "null":
                    fields[head] = None
                elif event == "start_map":
                    fields[head] = {}
                elif event == "map_key" and value not in names:
                    raise InputError(self.path, f"{where}.{head}: unsupported field {value!r}")
                elif event not in ("map_key", "end_map"):
                    raise InputError(self.path, bad)
            elif head == "agile_data" and tail in names and event == "start_array":
                self.target = fields[head][tail] = []
            elif head == "agile_data" and tail in names and event == "end_array":
                self.target = None
            elif head == "non_agile_data" and tail in names and event == "number":
                fields[head][tail] = value
            else:
                raise InputError(self.path, bad)
            return
        if tail or event in ("start_map", "start_array", "end_map", "end_array", "map_key"):
            raise InputError(self.path, f"{where}.{head}: expected a string or a number")
        fields[head] = value

    def _tw_event(self, rest: str, event: str, value: Any) -> None:
        if rest == "":
            if event == "start_map":
                self.tw_index += 1
                self.tw = {}
            elif event == "end_map":
                self.pending.append(self.tw)
                self.tw = None
            elif event != "map_key":
                raise InputError(self.path, f"observation_windows[{self.ow}].time_windows[{self.tw_index + 1}]: "
                                            "expected an object")
            elif value not in TW_KEYS:
                raise InputError(self.path, f"{self.where()}: unsupported field {value!r} (known: "
                                            f"{', '.join(sorted(TW_KEYS))})")
            return
        self._field(self.tw, rest[1:], event, value, self.where())

    def _end_ow(self) -> None:
        f = self.ow_fields
        where = f"observation_windows[{self.ow}]"
        for key in ("satellite_id", "mission_id"):
            if not isinstance(f.get(key), str):
                raise InputError(self.path, f"{where}: {key} missing or not a string")
        for j, tw in enumerate(self.pending):
            w = f"{where}.time_windows[{j}]"
            for key in ("start_time", "end_time"):
                if key not in tw:
                    raise InputError(self.path, f"{w}: {key} missing")
            agile = tw.get("agile_data", f.get("agile_data"))
            fixed = tw.get("non_agile_data", f.get("non_agile_data"))
            n = 0
            if agile:
                lists = [agile.get(k) for k in AGILE_KEYS]
                if any(x is None for x in lists) or len({len(x) for x in lists}) != 1:
                    raise InputError(self.path, f"{w}.agile_data: needs {', '.join(AGILE_KEYS)} of one length")
                n = len(lists[0])
                for k, x in zip(AGILE_KEYS, lists):
                    _angles(self.path, f"{w}.agile_data.{k}", x)
                self.pitch += lists[0]
                self.yaw += lists[1]
                self.roll += lists[2]
            self.att_ptr.append(self.att_ptr[-1] + n)
            fixed_row = (np.nan, np.nan, np.nan)
            if fixed:
                if any(k not in fixed for k in FIXED_KEYS):
                    raise InputError(self.path, f"{w}.non_agile_data: needs {', '.join(FIXED_KEYS)}")
                fixed_row = tuple(float(fixed[k]) for k in FIXED_KEYS)
                for k, v in zip(FIXED_KEYS, fixed_row):
                    _angles(self.path, f"{w}.non_agile_data.{k}", [v])
            orbit = tw.get("orbit_number", f.get("orbit_number", 0))
            step = tw.get("time_step", f.get("time_step"))
            self.rows.append((self.ow, j, f["satellite_id"], f["mission_id"], str(f.get("sensor_id", "")),
                              tw["start_time"], tw["end_time"], orbit, step, fixed_row))


def _events(path: str):
    import ijson

    try:
        with open(path, "rb") as fh:
            yield from ijson.parse(fh, use_float=True)
    except ijson.JSONError as exc:
        raise InputError(path, f"not valid JSON: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") \
            from None
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror}") from None


def read_scenario(path: str) -> Scenario:
    """The scenario at `path` (see the module docstring)."""
    import ijson

    path = str(path)
    sections: dict[str, Any] = {}
    stream = _WindowStream(path)
    key, builder = None, None
    for prefix, event, value in _events(path):
        if prefix == "":
            if event == "map_key":
                if builder is not None:
                    sections[key] = builder.value
                key = value
                if key not in TOP_KEYS:
                    raise InputError(path, f"unsupported top-level field {key!r} (known: {', '.join(sorted(TOP_KEYS))})")
                builder = None if key == "observation_windows" else ijson.ObjectBuilder()
            elif event == "end_map":
                if builder is not None:
                    sections[key] = builder.value
                builder = None
            elif event != "start_map":
                raise InputError(path, "not a JSON object at the top level")
            continue
        if key == "observation_windows":
            stream.event(prefix, event, value)
        else:
            builder.event(event, value)
    return _assemble(path, sections, stream)


def _satellites(path: str, raw: list) -> tuple[Satellites, dict]:
    ids, agile, storage, power, ptr = [], [], [], [], [0]
    s_ids, s_rate, s_power = [], [], []
    ignored: dict[str, str] = {}
    for i, sat in enumerate(raw):
        where = f"satellites[{i}]"
        sat = _obj(path, where, sat)
        if not isinstance(sat.get("id"), str):
            raise InputError(path, f"{where}: id missing or not a string")
        if sat["id"] in ids:
            raise InputError(path, f"{where}: satellite id {sat['id']!r} repeats satellites[{ids.index(sat['id'])}]")
        ids.append(sat["id"])
        specs = _obj(path, f"{where}.satellite_specs", sat.get("satellite_specs"))
        storage.append(_num(path, f"{where}.satellite_specs.max_data_storage_GB", specs.get("max_data_storage_GB"), 0.0))
        power.append(_num(path, f"{where}.satellite_specs.max_power_W", specs.get("max_power_W"), 0.0))
        for k in ("max_operation_time_s", "max_battery_capacity_Wh", "max_fuel_kg"):
            if specs.get(k) is not None:
                ignored[f"satellite_specs.{k}"] = NOT_CONSTRAINTS[f"satellite_specs.{k}"]
        man = _obj(path, f"{where}.maneuverability_capability", sat.get("maneuverability_capability"))
        for k in ("slew_rate_deg_per_s", "stabilization_time_s"):
            if man.get(k) is not None:
                ignored[f"maneuverability_capability.{k}"] = NOT_CONSTRAINTS[f"maneuverability_capability.{k}"]
        if any(man.get(f"max_{a}_angle_deg") is not None for a in ("pitch", "yaw", "roll")):
            ignored["maneuverability_capability.max_*_angle_deg"] = \
                NOT_CONSTRAINTS["maneuverability_capability.max_*_angle_deg"]
        agile.append(_agility(sat))
        obs = _obj(path, f"{where}.observation_capability", sat.get("observation_capability"))
        for j, s in enumerate(_list(path, f"{where}.observation_capability.sensors", obs.get("sensors"))):
            s = _obj(path, f"{where}.observation_capability.sensors[{j}]", s)
            if not s.get("sensor_id"):
                continue  # their loader skips a sensor without an id: it can serve no window
            s_ids.append(str(s["sensor_id"]))
            sw = f"{where}.observation_capability.sensors[{j}]"
            s_rate.append(_num(path, f"{sw}.data_rate_Mbps", s.get("data_rate_Mbps"), 0.0))
            s_power.append(_num(path, f"{sw}.power_consumption_W", s.get("power_consumption_W"), 0.0))
        ptr.append(len(s_ids))
    sats = Satellites(ids, np.asarray(agile, dtype=bool), np.asarray(storage), np.asarray(power),
                      np.asarray(ptr, dtype=np.int64), s_ids, np.asarray(s_rate), np.asarray(s_power))
    return sats, ignored


def _tasks(path: str, raw: list) -> Tasks:
    ids, prio, dur = [], [], []
    seen: dict[str, int] = {}
    for i, m in enumerate(raw):
        where = f"missions[{i}]"
        m = _obj(path, where, m)
        if not isinstance(m.get("id"), str):
            raise InputError(path, f"{where}: id missing or not a string")
        if m["id"] in seen:
            raise InputError(path, f"{where}: mission id {m['id']!r} repeats missions[{seen[m['id']]}]")
        seen[m["id"]] = i
        ids.append(m["id"])
        prio.append(_num(path, f"{where}.priority", m.get("priority", 1.0)))
        req = _obj(path, f"{where}.observation_requirement", m.get("observation_requirement"))
        dur.append(_num(path, f"{where}.observation_requirement.duration_s", req.get("duration_s", 0.0)))
        for k in UNSUPPORTED_REQUIREMENTS:
            if req.get(k) is not None:
                raise Unsupported(path, f"{where}.observation_requirement.{k} = {req[k]!r}: unsupported constraint "
                                        "(EOS-Bench's constraint model does not check it, nor does this kind)")
    prio_arr = np.asarray(prio, dtype=np.float64)
    with np.errstate(over="ignore"):
        total = np.cumsum(prio_arr)
    if len(total) and not np.isfinite(total[-1]):  # each one finite, their sum (the TP they can reach) not
        i = int(np.flatnonzero(~np.isfinite(total))[0])
        raise InputError(path, f"missions[{i}].priority: {prio[i]!r} makes the priorities' sum overflow "
                               "(the total profit would not be a number)")
    return Tasks(ids, prio_arr, np.asarray(dur))


def _us(path: str, where: str, text: Any, start: datetime) -> int:
    return (parse_time(path, where, text) - start) // ONE_US


def _windows(path: str, stream: _WindowStream, sats: Satellites, tasks: Tasks, start: datetime,
             step0: float) -> Windows:
    sat_of = {s: i for i, s in enumerate(sats.ids)}
    task_of = {t: i for i, t in enumerate(tasks.ids)}
    n = len(stream.rows)
    task = np.empty(n, np.int32)
    sat = np.empty(n, np.int32)
    sensor = np.empty(n, np.int32)
    orbit = np.empty(n, np.int64)
    t0 = np.empty(n, np.int64)
    t1 = np.empty(n, np.int64)
    step = np.empty(n, np.float64)
    fixed = np.empty((n, 3))
    sensor_ids = []
    for r, (ow, j, sid, mid, sensor_id, ts, te, orb, st, fx) in enumerate(stream.rows):
        where = f"observation_windows[{ow}].time_windows[{j}]"
        if sid not in sat_of:
            raise InputError(path, f"observation_windows[{ow}]: satellite {sid!r} is not in satellites")
        if mid not in task_of:
            raise InputError(path, f"observation_windows[{ow}]: mission {mid!r} is not in missions")
        sat[r], task[r] = sat_of[sid], task_of[mid]
        sensor[r] = sats.sensor_of(sat[r], sensor_id)
        sensor_ids.append(sensor_id)
        t0[r] = _us(path, f"{where}.start_time", ts, start)
        t1[r] = _us(path, f"{where}.end_time", te, start)
        if t1[r] <= t0[r]:
            raise InputError(path, f"{where}: end_time {te} is not after start_time {ts}")
        if isinstance(orb, bool) or not isinstance(orb, (int, float, type(None))) or (orb is not None and (
                not np.isfinite(orb) or orb != int(orb) or abs(orb) > MAX_ORBIT)):
            raise InputError(path, f"{where}.orbit_number: expected an integer of at most {MAX_ORBIT:,} in size, "
                                   f"got {orb!r}")
        orbit[r] = int(orb or 0)
        step[r] = _num(path, f"{where}.time_step", st, step0) if st is not None else step0
        if step[r] <= 0:
            raise InputError(path, f"{where}.time_step: {st!r} is not positive")
        fixed[r] = fx
    return Windows(task, sat, sensor, sensor_ids, orbit, t0, t1, step, np.asarray(stream.att_ptr, dtype=np.int64),
                   np.asarray(stream.pitch, dtype=np.float64), np.asarray(stream.yaw, dtype=np.float64),
                   np.asarray(stream.roll, dtype=np.float64), fixed)


def _comm(path: str, raw: list, sats: Satellites, stations: list[str], start: datetime) -> CommWindows:
    sat_of = {s: i for i, s in enumerate(sats.ids)}
    gs_of = {g: i for i, g in enumerate(stations)}
    rows = []
    for i, cw in enumerate(raw):
        where = f"communication_windows[{i}]"
        cw = _obj(path, where, cw)
        if cw.get("satellite_id") not in sat_of:
            raise InputError(path, f"{where}: satellite {cw.get('satellite_id')!r} is not in satellites")
        if cw.get("ground_station_id") not in gs_of:
            raise InputError(path, f"{where}: ground station {cw.get('ground_station_id')!r} is not in "
                                   "ground_stations")
        for j, tw in enumerate(_list(path, f"{where}.time_windows", cw.get("time_windows"))):
            tw = _obj(path, f"{where}.time_windows[{j}]", tw)
            a = _us(path, f"{where}.time_windows[{j}].start_time", tw.get("start_time"), start)
            b = _us(path, f"{where}.time_windows[{j}].end_time", tw.get("end_time"), start)
            if b <= a:
                raise InputError(path, f"{where}.time_windows[{j}]: end_time is not after start_time")
            rows.append((sat_of[cw["satellite_id"]], gs_of[cw["ground_station_id"]], a, b))
    arr = np.asarray(rows, dtype=np.int64).reshape(-1, 4)
    return CommWindows(arr[:, 0].astype(np.int32), arr[:, 1].astype(np.int32), arr[:, 2].copy(), arr[:, 3].copy())


def _assemble(path: str, sections: dict, stream: _WindowStream) -> Scenario:
    meta = _obj(path, "metadata", sections.get("metadata"))
    if "metadata" not in sections:
        raise InputError(path, "metadata missing (creation_time and duration are needed)")
    for k in ("creation_time", "duration"):
        if k not in meta:
            raise InputError(path, f"metadata.{k} missing")
    start = parse_time(path, "metadata.creation_time", meta["creation_time"])
    duration = _num(path, "metadata.duration", meta["duration"])
    if not 0 < duration <= MAX_DURATION_S:
        raise InputError(path, f"metadata.duration: {meta['duration']!r} is not in (0, {MAX_DURATION_S:,}] seconds "
                               "(a scenario of at most a year)")
    step0 = _num(path, "metadata.time_step", meta.get("time_step"), 1.0)
    if step0 <= 0:  # 0 was taken as 1 s without a word, -1 refused naming a window's step
        raise InputError(path, f"metadata.time_step: {meta.get('time_step')!r} is not positive")
    sats, ignored = _satellites(path, _list(path, "satellites", sections.get("satellites")))
    tasks = _tasks(path, _list(path, "missions", sections.get("missions")))
    stations = []
    for i, gs in enumerate(_list(path, "ground_stations", sections.get("ground_stations"))):
        gs = _obj(path, f"ground_stations[{i}]", gs)
        if not isinstance(gs.get("id"), str):
            raise InputError(path, f"ground_stations[{i}]: id missing or not a string")
        stations.append(gs["id"])
    windows = _windows(path, stream, sats, tasks, start, step0)
    comm = _comm(path, _list(path, "communication_windows", sections.get("communication_windows")), sats,
                 stations, start)
    name = sections.get("scenario_id") if isinstance(sections.get("scenario_id"), str) else Path(path).stem
    return Scenario(path, name, start, duration, step0, sats, tasks, windows, stations, comm, ignored)
