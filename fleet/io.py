"""Fleet interchange directory and fleet schedule files (Parquet), plus CSV export.

A fleet directory holds ``satellites.parquet``, ``tasks.parquet``, ``opportunities.parquet``,
``meta.json`` and, for other sources, ``extra_<name>.parquet`` tables; it round-trips losslessly.
``meta.json`` carries a fingerprint of the fleet's content (satellites, tasks, horizon, grids,
extras), which a schedule file records so that a schedule is never checked against another fleet.
Everything is written through :mod:`eosp.atomic`: no reader sees a half-written file, and an
existing output is only replaced when asked (and, for a directory, when it is a fleet directory).
docs/formats.md ("Fleets") is the reference.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from eosp.errors import InputError
from eosp.fleet.model import (US, Attitude, Battery, Fleet, Horizon, Satellites, Schedule, Tasks, Tles, iso_z,
                              parse_utc, strings)
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
SCHEDULE_COLUMNS = ("satellite", "task", "start_utc", "end_utc", "start_s", "end_s")


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
    }
    with atomic_dir(out, overwrite=overwrite, owned=is_fleet_dir) as tmp:
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


def read_columns(path: Path, expected: dict) -> dict:
    """Columns of a Parquet file, checked: present, nothing unexpected, right kind, no nulls/NaN."""
    import pyarrow as pa

    table = read_parquet(path)  # the project's checked reader: one line for a missing or unreadable file
    names = set(table.column_names)
    for c in expected:
        if c not in names:
            raise InputError(path, "missing column", column=c)
    for c in table.column_names:
        if c not in expected:
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
            out[c] = col.to_numpy().astype(np.int64)
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
    return meta


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
    except (ValueError, TypeError) as exc:
        raise InputError(root / "meta.json", f"bad horizon: {exc}") from None
    sp = root / "satellites.parquet"
    s = read_columns(sp, {k: kind for k, (kind, _) in SAT_COLUMNS.items()})
    _unique(sp, s["satellite_id"], "satellite_id")
    sats = Satellites(
        s["satellite_id"], s["sensor_type"], Tles(s["tle_line1"], s["tle_line2"], s["norad_catalog_id"]),
        Attitude(s["max_off_nadir_deg"], s["max_slew_velocity_deg_per_s"], s["max_slew_acceleration_deg_per_s2"],
                 s["settling_time_s"]),
        Battery(s["battery_capacity_wh"], s["initial_battery_wh"], s["idle_power_w"], s["imaging_power_w"],
                s["slew_power_w"], s["sunlit_charge_power_w"]))
    tp = root / "tasks.parquet"
    t = read_columns(tp, {k: kind for k, (kind, _) in TASK_COLUMNS.items()})
    _unique(tp, t["task_id"], "task_id")
    tasks = Tasks(t["task_id"], t["name"], t["latitude_deg"], t["longitude_deg"], t["altitude_m"], t["release_s"],
                  t["due_s"], t["duration_s"], t["weight"], t["sensor_type"])
    extras = {}
    for name in meta.get("extras", []):
        import pyarrow.parquet as pq

        tab = pq.read_table(root / f"extra_{name}.parquet")
        extras[name] = {c: (strings(tab.column(c).to_pylist()) if tab.column(c).type == "string"
                            else tab.column(c).to_numpy()) for c in tab.column_names}
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


def read_schedule_table(path: Path, kind: bytes, fleet_fingerprint: str, columns, what: str):
    """The Parquet table of a schedule eosp wrote (`what`: "a fleet schedule"), checked: its `kind` mark, the
    fingerprint of the fleet it was written for, and `columns` present without nulls; with its metadata as text."""
    table = read_parquet(path)
    md = table.schema.metadata or {}
    if md.get(b"kind") != kind:
        raise InputError(path, f"not {what} (no {kind.decode()} metadata)")
    if md.get(b"fleet_fingerprint", b"").decode() != fleet_fingerprint:
        raise InputError(path, "written for another fleet (fingerprint differs)")
    for c in columns:
        if c not in table.column_names:
            raise InputError(path, "missing column", column=c)
        if table.column(c).null_count:
            raise InputError(path, "null value", column=c)
    return table, {k.decode(): v.decode() for k, v in md.items()}


def read_schedule(path: str | os.PathLike, fleet: Fleet) -> tuple[Schedule, dict]:
    """A schedule from a fleet schedule (Parquet, checked against the fleet's fingerprint) or an aeossp
    ``solution.json``; returns it with its metadata."""
    path = Path(path)
    if path.suffix.lower() == ".json":
        from eosp.fleet.aeossp import read_solution

        return read_solution(path, fleet.horizon), {}
    if path.suffix.lower() != ".parquet":
        raise InputError(path, "unknown extension: a schedule is a .parquet (fleet schedule) or .json (aeossp solution)")
    table, info = read_schedule_table(path, SCHEDULE_KIND, fingerprint(fleet), SCHEDULE_COLUMNS, "a fleet schedule")
    start = np.datetime64(fleet.horizon.start.replace(tzinfo=None), "us")
    st = (table.column("start_utc").to_numpy().astype("datetime64[us]") - start).astype(np.int64)
    en = (table.column("end_utc").to_numpy().astype("datetime64[us]") - start).astype(np.int64)
    return Schedule(strings(table.column("satellite").to_pylist()), strings(table.column("task").to_pylist()),
                    st, en), info


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
