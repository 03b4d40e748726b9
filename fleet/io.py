"""Fleet interchange directory and fleet schedule files (Parquet), plus CSV export.

A fleet directory holds ``satellites.parquet``, ``tasks.parquet``, ``opportunities.parquet``,
``meta.json`` and, for other sources, ``extra_<name>.parquet`` tables; it round-trips losslessly.
``meta.json`` carries a fingerprint of the fleet's content (satellites, tasks, horizon, grids,
extras), which a schedule file records so that a schedule is never checked against another fleet, and one of
the opportunities (every table of the directory is thus covered: an edited opportunities.parquet is refused,
not solved).  Values are checked where they enter (:func:`eosp.fleet.model.satellite_fault`,
:func:`eosp.fleet.model.task_fault`), as the aeossp reader checks them.
Everything is written through :mod:`eosp.atomic`: no reader sees a half-written file, and an
existing output is only replaced when asked (and, for a directory, when it is a fleet directory).
docs/formats.md ("Fleets") is the reference.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path

import numpy as np

from eosp.errors import InputError
from eosp.fleet.model import (US, Attitude, Battery, Fleet, Horizon, Satellites, Schedule, Tasks, Tles, iso_z,
                              parse_utc, satellite_fault, strings, task_fault)
from eosp.fleet.opportunities import Opportunities
from eosp.instances.interchange import read_parquet

SCHEMA_VERSION = 1
KIND = "eosp-fleet"
SCHEDULE_KIND = b"eosp-fleet-schedule"

SAT_COLUMNS = {  # column -> (dtype kind, getter)
    "satellite_id": ("str", lambda s: s.ids), "norad_catalog_id": ("int", lambda s: s.tle.norad),
    "tle_line1": ("str", lambda s: s.tle.line1), "tle_line2": ("str", lambda s: s.tle.line2),
    "sensor_type": ("str", lambda s: s.sensor),
    "max_off_nadir_deg": ("float", lambda s: s.attitude.max_off_nadir_deg),
    "max_slew_velocity_deg_per_s": ("float", lambda s: s.attitude.max_rate_deg_s),
    "max_slew_acceleration_deg_per_s2": ("float", lambda s: s.attitude.max_acc_deg_s2),
    "settling_time_s": ("float", lambda s: s.attitude.settling_s),
    "battery_capacity_wh": ("float", lambda s: s.battery.capacity_wh),
    "initial_battery_wh": ("float", lambda s: s.battery.initial_wh),
    "idle_power_w": ("float", lambda s: s.battery.idle_w),
    "imaging_power_w": ("float", lambda s: s.battery.imaging_w),
    "slew_power_w": ("float", lambda s: s.battery.slew_w),
    "sunlit_charge_power_w": ("float", lambda s: s.battery.sunlit_w),
}
TASK_COLUMNS = {
    "task_id": ("str", lambda t: t.ids), "name": ("str", lambda t: t.names),
    "latitude_deg": ("float", lambda t: t.lat_deg), "longitude_deg": ("float", lambda t: t.lon_deg),
    "altitude_m": ("float", lambda t: t.alt_m), "release_s": ("float", lambda t: t.release_s),
    "due_s": ("float", lambda t: t.due_s), "duration_s": ("float", lambda t: t.duration_s),
    "weight": ("float", lambda t: t.weight), "sensor_type": ("str", lambda t: t.sensor),
}
OPP_COLUMNS = ("task", "satellite", "start", "pass")
SCHEDULE_COLUMNS = {"satellite": "str", "task": "str", "start_utc": "timestamp", "end_utc": "timestamp",
                    "start_s": "float", "end_s": "float"}
EXTRA_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")  # an extra table's name: a file name part, never a path


def _canon(v):
    return v.tolist() if isinstance(v, np.ndarray) else v


def fingerprint(fleet: Fleet) -> str:
    """sha256 of the fleet's content: horizon, grids, every satellite and task field, extras."""
    h = fleet.horizon
    doc = {
        "horizon": [iso_z(h.start), iso_z(h.end), h.action_step_s, h.geometry_step_s, h.resource_step_s],
        "satellites": {k: _canon(get(fleet.satellites)) for k, (_, get) in SAT_COLUMNS.items()},
        "tasks": {k: _canon(get(fleet.tasks)) for k, (_, get) in TASK_COLUMNS.items()},
        "extras": {name: {c: _canon(v) for c, v in sorted(t.items())} for name, t in sorted(fleet.extras.items())},
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def opportunities_fingerprint(opps: Opportunities) -> str:
    """sha256 of the opportunity columns (int32 bytes, in file order)."""
    h = hashlib.sha256()
    for c in (opps.task, opps.satellite, opps.start, opps.pass_id):
        h.update(np.ascontiguousarray(c, dtype=np.int32).tobytes())
    return h.hexdigest()


def written_names(path: str | os.PathLike) -> set[str]:
    """The entries :func:`write_fleet` wrote in an existing fleet directory (the fixed tables, meta.json and the
    extra tables its meta.json lists): what ``--overwrite`` may replace."""
    names = {"meta.json", "satellites.parquet", "tasks.parquet", "opportunities.parquet"}
    try:
        extras = json.loads((Path(path) / "meta.json").read_text()).get("extras", [])
    except (OSError, ValueError, AttributeError):
        extras = []
    if isinstance(extras, list):
        names |= {f"extra_{e}.parquet" for e in extras if isinstance(e, str) and EXTRA_NAME.fullmatch(e)}
    return names


def is_fleet_dir(path: str | os.PathLike) -> bool:
    """A directory written by :func:`write_fleet` (its meta.json says so)."""
    p = Path(path)
    try:
        meta = json.loads((p / "meta.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(meta, dict) and meta.get("kind") == KIND and (p / "satellites.parquet").is_file()


def arrow_table(columns: dict):
    """An Arrow table of named numpy columns (object arrays as strings): the tables of the fleet files."""
    import pyarrow as pa

    arrays = {}
    for name, v in columns.items():
        v = np.asarray(v)
        if v.dtype == object:
            arrays[name] = pa.array(v.tolist(), type=pa.string())
        else:
            arrays[name] = pa.array(v)
    return pa.table(arrays)


def write_fleet(fleet: Fleet, opps: Opportunities, out: str | os.PathLike, overwrite: bool = False) -> Path:
    """Write the fleet interchange directory `out` (atomically)."""
    import pyarrow.parquet as pq
    from eosp.atomic import atomic_dir

    h = fleet.horizon
    meta = {
        "kind": KIND, "schema_version": SCHEMA_VERSION, "source": fleet.source, "source_commit": fleet.source_commit,
        "case_id": fleet.case_id, "horizon_start": iso_z(h.start), "horizon_end": iso_z(h.end),
        "action_step_s": h.action_step_s, "geometry_step_s": h.geometry_step_s, "resource_step_s": h.resource_step_s,
        "fingerprint": fingerprint(fleet), "satellites": len(fleet.satellites), "tasks": len(fleet.tasks),
        "opportunities": len(opps), "passes": opps.n_passes, "extras": sorted(fleet.extras),
        "opportunities_fingerprint": opportunities_fingerprint(opps),
    }
    bad = next((e for e in fleet.extras if not EXTRA_NAME.fullmatch(e)), None)
    if bad is not None:
        raise ValueError(f"extra table name {bad!r}: letters, digits, '_' and '-' only")
    with atomic_dir(out, overwrite=overwrite, owned=is_fleet_dir, names=written_names) as tmp:
        pq.write_table(arrow_table({k: get(fleet.satellites) for k, (_, get) in SAT_COLUMNS.items()}),
                       tmp / "satellites.parquet")
        pq.write_table(arrow_table({k: get(fleet.tasks) for k, (_, get) in TASK_COLUMNS.items()}),
                       tmp / "tasks.parquet")
        pq.write_table(arrow_table({"task": opps.task, "satellite": opps.satellite, "start": opps.start,
                                    "pass": opps.pass_id}), tmp / "opportunities.parquet")
        for name, cols in fleet.extras.items():
            pq.write_table(arrow_table(dict(cols)), tmp / f"extra_{name}.parquet")
        (tmp / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    return Path(out)


def read_columns(path: Path, expected: dict, table=None, extra_ok: bool = False) -> dict:
    """Columns of a Parquet file, checked: present, nothing unexpected (unless `extra_ok`), right kind ("str", "int",
    "float": a finite number, "timestamp"), no nulls/NaN.  `table`: already read."""
    import pyarrow as pa

    if table is None:
        table = read_parquet(path)  # the project's checked reader: one line for a missing or unreadable file
    names = set(table.column_names)
    for c in expected:
        if c not in names:
            raise InputError(path, "missing column", column=c)
    for c in table.column_names:
        if c not in expected and not extra_ok:
            raise InputError(path, "unexpected column", column=c)
    out = {}
    for c, kind in expected.items():
        col = table.column(c)
        if col.null_count:
            raise InputError(path, "null value", column=c, row=int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0]))
        t = col.type
        if kind == "str":
            if not (pa.types.is_string(t) or pa.types.is_large_string(t)):
                raise InputError(path, f"expected strings, got {t}", column=c)
            out[c] = strings(col.to_pylist())
        elif kind == "int":
            if not pa.types.is_integer(t):
                raise InputError(path, f"expected integers, got {t}", column=c)
            v = col.to_numpy()
            if v.dtype == np.uint64 and len(v) and v.max() > np.iinfo(np.int64).max:
                raise InputError(path, "integer too large", column=c, row=int(np.argmax(v)))
            out[c] = v.astype(np.int64)
        elif kind == "timestamp":
            if not pa.types.is_timestamp(t):
                raise InputError(path, f"expected UTC timestamps, got {t}", column=c)
            out[c] = col.to_numpy().astype("datetime64[us]")
        else:
            if not (pa.types.is_floating(t) or pa.types.is_integer(t)):
                raise InputError(path, f"expected numbers, got {t}", column=c)
            v = col.to_numpy().astype(np.float64)
            bad = np.flatnonzero(~np.isfinite(v))
            if len(bad):
                raise InputError(path, "not a finite number", column=c, row=int(bad[0]))
            out[c] = v
    return out


def _unique(path: Path, ids: np.ndarray, column: str) -> None:
    seen: dict[str, int] = {}
    for r, v in enumerate(ids.tolist()):
        if v in seen:
            raise InputError(path, f"duplicate id {v!r} (first at row {seen[v]})", column=column, row=r)
        seen[v] = r


def read_meta_json(root: Path, kind: str, version: int, what: str) -> dict:
    """The meta.json of a directory eosp wrote (`what`: "a fleet directory"), its kind and schema version checked."""
    path = root / "meta.json"
    try:
        meta = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(path, f"file not found (not {what})") from None
    except (OSError, ValueError) as exc:
        raise InputError(path, f"not valid JSON: {exc}") from None
    if not isinstance(meta, dict) or meta.get("kind") != kind:
        raise InputError(path, f"not {what}'s meta.json (kind must be {kind!r})")
    if meta.get("schema_version") != version:
        raise InputError(path, f"schema_version {meta.get('schema_version')!r} is not supported (expected {version})")
    return meta


def read_meta(root: Path) -> dict:
    path = root / "meta.json"
    meta = read_meta_json(root, KIND, SCHEMA_VERSION, "a fleet directory")
    need = ("horizon_start", "horizon_end", "action_step_s", "geometry_step_s", "resource_step_s", "fingerprint")
    for k in need:
        if k not in meta:
            raise InputError(path, f"missing key {k!r}")
    extras = meta.get("extras", [])
    if not isinstance(extras, list) or not all(isinstance(e, str) and EXTRA_NAME.fullmatch(e) for e in extras):
        raise InputError(path, f"extras must be a list of table names (letters, digits, '_', '-'), got {extras!r}")
    if len(set(extras)) != len(extras):
        raise InputError(path, f"extras names a table twice: {extras!r}")
    return meta


def _read_extra(path: Path) -> dict[str, np.ndarray]:
    """An extra table (carried untouched): its columns as strings or numbers, no nulls."""
    import pyarrow as pa

    table = read_parquet(path)
    kinds = {}
    for c in table.column_names:
        t = table.schema.field(c).type
        if pa.types.is_string(t) or pa.types.is_large_string(t):
            kinds[c] = "str"
        elif pa.types.is_integer(t):
            kinds[c] = "int"
        elif pa.types.is_floating(t):
            kinds[c] = "number"
        else:
            raise InputError(path, f"unsupported column type {t} (strings and numbers only)", column=c)
    for c, kind in kinds.items():
        col = table.column(c)
        if col.null_count:
            raise InputError(path, "null value", column=c,
                             row=int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0]))
    return {c: (strings(table.column(c).to_pylist()) if kind == "str" else table.column(c).to_numpy())
            for c, kind in kinds.items()}


def _check_values(path: Path, fault: tuple[int, str, str] | None) -> None:
    if fault is not None:
        row, column, reason = fault
        raise InputError(path, reason, column=column, row=row)


def read_fleet(path: str | os.PathLike, with_opportunities: bool = True) -> tuple[Fleet, Opportunities | None]:
    """A fleet directory's fleet (and opportunities), checked against its fingerprint."""
    root = Path(path)
    if not root.is_dir():
        raise InputError(root, "not a directory (a fleet directory holds satellites.parquet, tasks.parquet, "
                               "opportunities.parquet and meta.json)")
    meta = read_meta(root)
    try:
        h = Horizon(parse_utc(meta["horizon_start"]), parse_utc(meta["horizon_end"]), int(meta["action_step_s"]),
                    int(meta["geometry_step_s"]), int(meta["resource_step_s"]))
    except (ValueError, TypeError, OverflowError) as exc:
        raise InputError(root / "meta.json", f"bad horizon: {exc}") from None
    if min(h.action_step_s, h.geometry_step_s, h.resource_step_s) <= 0 or h.end <= h.start:
        raise InputError(root / "meta.json", "bad horizon: the steps must be > 0 and the end after the start")
    sp = root / "satellites.parquet"
    s = read_columns(sp, {k: kind for k, (kind, _) in SAT_COLUMNS.items()})
    if len(s["satellite_id"]) == 0:
        raise InputError(sp, "no satellite (a fleet needs one)")
    _unique(sp, s["satellite_id"], "satellite_id")
    sats = Satellites(
        s["satellite_id"], s["sensor_type"], Tles(s["tle_line1"], s["tle_line2"], s["norad_catalog_id"]),
        Attitude(s["max_off_nadir_deg"], s["max_slew_velocity_deg_per_s"], s["max_slew_acceleration_deg_per_s2"],
                 s["settling_time_s"]),
        Battery(s["battery_capacity_wh"], s["initial_battery_wh"], s["idle_power_w"], s["imaging_power_w"],
                s["slew_power_w"], s["sunlit_charge_power_w"]))
    _check_values(sp, satellite_fault(sats))
    tp = root / "tasks.parquet"
    t = read_columns(tp, {k: kind for k, (kind, _) in TASK_COLUMNS.items()})
    if len(t["task_id"]) == 0:
        raise InputError(tp, "no task (a fleet needs one)")
    _unique(tp, t["task_id"], "task_id")
    tasks = Tasks(t["task_id"], t["name"], t["latitude_deg"], t["longitude_deg"], t["altitude_m"], t["release_s"],
                  t["due_s"], t["duration_s"], t["weight"], t["sensor_type"])
    _check_values(tp, task_fault(tasks, h))
    extras = {name: _read_extra(root / f"extra_{name}.parquet") for name in meta.get("extras", [])}
    fleet = Fleet(h, sats, tasks, source=str(meta.get("source", "")), source_commit=str(meta.get("source_commit", "")),
                  case_id=str(meta.get("case_id", "")), extras=extras)
    if fingerprint(fleet) != meta["fingerprint"]:
        raise InputError(root / "meta.json", "fingerprint does not match the fleet's content (files edited or mixed)")
    if not with_opportunities:
        return fleet, None
    op = root / "opportunities.parquet"
    o = read_columns(op, {c: "int" for c in OPP_COLUMNS})
    for c, hi in (("task", len(tasks)), ("satellite", len(sats)), ("start", h.n_action)):
        bad = np.flatnonzero((o[c] < 0) | (o[c] >= hi))
        if len(bad):
            raise InputError(op, f"out of range [0, {hi})", column=c, row=int(bad[0]))
    if np.any(np.diff(o["pass"]) < 0):
        raise InputError(op, "rows must be sorted by pass", column="pass")
    opps = Opportunities(o["task"].astype(np.int32), o["satellite"].astype(np.int32), o["start"].astype(np.int32),
                         o["pass"].astype(np.int32))
    want = meta.get("opportunities_fingerprint")
    if want is None:
        raise InputError(root / "meta.json", "no opportunities_fingerprint (written by an older eosp): import or "
                                             "generate the fleet again")
    if opportunities_fingerprint(opps) != want:
        raise InputError(op, "does not match its fingerprint in meta.json (edited or mixed with another fleet's)")
    return fleet, opps


def builder_version() -> str:
    import eosp

    return f"eosp {eosp.__version__}"


def write_schedule(schedule: Schedule, fleet: Fleet, path: str | os.PathLike, overwrite: bool = False,
                   info: dict | None = None) -> Path:
    """Write a fleet schedule (Parquet); `info` may hold ``value`` (WCR), ``bound``, ``gap``, ``solver``."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from eosp.atomic import atomic_path
    from eosp.ownership import check_output

    path = check_output(path, "fleet-schedule", overwrite=overwrite, suffixes=(".parquet",))
    start = np.datetime64(fleet.horizon.start.replace(tzinfo=None), "us")
    table = pa.table({
        "satellite": pa.array(schedule.satellite.tolist(), type=pa.string()),
        "task": pa.array(schedule.task.tolist(), type=pa.string()),
        "start_utc": pa.array(start + schedule.start_us.astype("timedelta64[us]"), type=pa.timestamp("us", tz="UTC")),
        "end_utc": pa.array(start + schedule.end_us.astype("timedelta64[us]"), type=pa.timestamp("us", tz="UTC")),
        "start_s": pa.array(schedule.start_us / 1e6, type=pa.float64()),
        "end_s": pa.array(schedule.end_us / 1e6, type=pa.float64()),
    })
    from eosp.ownership import parquet_mark

    md = {b"kind": SCHEDULE_KIND, b"fleet_fingerprint": fingerprint(fleet).encode(),
          b"builder": builder_version().encode(), **parquet_mark("fleet-schedule")}
    for k, v in (info or {}).items():
        md[k.encode()] = json.dumps(v).encode()
    table = table.replace_schema_metadata(md)
    with atomic_path(path, suffix=".parquet") as tmp:
        pq.write_table(table, tmp)
    return path


def read_schedule_table(path: Path, kind: bytes, fleet_fingerprint: str, columns: dict, what: str):
    """The columns of a schedule eosp wrote (`what`: "a fleet schedule"), checked: its `kind` mark, the fingerprint of
    the fleet it was written for, and `columns` (name -> kind, as :func:`read_columns`) present, of their kind,
    without nulls; with its metadata as text."""
    table = read_parquet(path)
    md = table.schema.metadata or {}
    if md.get(b"kind") != kind:
        raise InputError(path, f"not {what} (no {kind.decode()} metadata)")
    if md.get(b"fleet_fingerprint", b"").decode(errors="replace") != fleet_fingerprint:
        raise InputError(path, "written for another fleet (fingerprint differs)")
    cols = read_columns(path, columns, table=table, extra_ok=True)
    return cols, {k.decode(errors="replace"): v.decode(errors="replace") for k, v in md.items()}


def read_schedule(path: str | os.PathLike, fleet: Fleet) -> tuple[Schedule, dict]:
    """A schedule from a fleet schedule (Parquet, checked against the fleet's fingerprint) or an aeossp
    ``solution.json``; returns it with its metadata."""
    path = Path(path)
    if path.suffix.lower() == ".json":
        from eosp.fleet.aeossp import read_solution

        return read_solution(path, fleet.horizon), {}
    if path.suffix.lower() != ".parquet":
        raise InputError(path, "unknown extension: a schedule is a .parquet (fleet schedule) or .json (aeossp solution)")
    cols, info = read_schedule_table(path, SCHEDULE_KIND, fingerprint(fleet), SCHEDULE_COLUMNS, "a fleet schedule")
    start = np.datetime64(fleet.horizon.start.replace(tzinfo=None), "us")
    st = (cols["start_utc"] - start).astype(np.int64)
    en = (cols["end_utc"] - start).astype(np.int64)
    return Schedule(cols["satellite"], cols["task"], st, en), info


def write_csv(schedule: Schedule, fleet: Fleet, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """One observation a line: satellite, task, start and end in UTC (ISO 8601), duration in seconds."""
    from eosp.atomic import atomic_path
    from eosp.ownership import check_output, comment_mark

    path = check_output(path, "fleet-csv", overwrite=overwrite, suffixes=(".csv",))
    import csv
    import io

    h = fleet.horizon
    buf = io.StringIO()
    buf.write(comment_mark("fleet-csv") + "\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["satellite_id", "task_id", "start_time", "end_time", "duration_s"])
    for s, t, a, b in zip(schedule.satellite.tolist(), schedule.task.tolist(), schedule.start_us.tolist(),
                          schedule.end_us.tolist()):
        w.writerow([s, t, iso_z(h.utc(a)), iso_z(h.utc(b)), f"{(b - a) / US:g}"])
    with atomic_path(path, suffix=".csv") as tmp:
        tmp.write_text(buf.getvalue())
    return path
