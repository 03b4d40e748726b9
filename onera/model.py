"""The ONERA constellation benchmark (ssquilla/Earth_Observing_Satellites_benchmarks): reader, model, files.

ONERA instances have no orbits: a satellite is only an id, and each observation already carries its
visibility window (integer seconds since 0 h), its duration, its target's lat/lon and a weather score.
So the model is its own typed bundle of arrays (:class:`OneraFleet`), not an aeossp :class:`Fleet`:
requests (four kinds), their observations, and the mandatory downloads.

Semantics (as the authors' solver ssquilla/EOSSP implements them, see docs/formats.md "ONERA"):

* an observation's value is the class of its score: <=0.5 -> 0.05, <=0.6 -> 0.1, <=0.7 -> 0.4,
  <=0.8 -> 0.7, <=0.9 -> 0.95, else 1; a video (``LONG_MONO``) observation is worth 4 x its class;
* a download lasts ``min(180, 0.95 x window)`` s and is placed at the ground station's coordinates;
* the transition between two activities is ``min(sqrt(dlat^2 + dlon^2), 90)`` s (degrees), 0 between
  two observations of the same request (they share a target).

A fleet directory holds ``requests.parquet``, ``observations.parquet``, ``downloads.parquet`` and a
``meta.json`` whose fingerprint a schedule records, written with :mod:`eosp.fleet.io`'s helpers.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eosp.errors import InputError

KIND = "eosp-onera-fleet"
SCHEMA_VERSION = 1
SCHEDULE_KIND = b"eosp-onera-schedule"

ONE_SHOT, VIDEO, STEREO, PERIODIC = 0, 1, 2, 3
KIND_NAMES = ("ONE_SHOT_MONO", "LONG_MONO", "ONE_SHOT_STEREO", "PERIODIC")
KIND_SHORT = ("one-shot", "video", "stereo", "periodic")
VIDEO_FACTOR = 4.0
PERIODIC_ALPHA = 0.5
DOWNLOAD_S = 180.0
TAU_MAX_S = 90.0
TIME_MAX_S = 10 ** 9  # window times and durations: seconds since 0 h (an instance spans a day; 1e9 s is 31 years)
SLOT_MAX = 2 ** 31 - 1  # pair ids and time slots are int32
INT64 = (-(2 ** 63), 2 ** 63 - 1)
CLASS_BOUNDS = np.array([0.5, 0.6, 0.7, 0.8, 0.9, 1.0])
CLASS_VALUES = np.array([0.05, 0.1, 0.4, 0.7, 0.95, 1.0])


def score_class(score: np.ndarray) -> np.ndarray:
    """The class value of weather scores in [0, 1] (the first bound a score does not exceed)."""
    return CLASS_VALUES[np.searchsorted(CLASS_BOUNDS, np.asarray(score, dtype=np.float64), side="left")]


@dataclass(frozen=True, eq=False)
class Requests:
    """One row per request; its observations are rows ``first[r] : first[r + 1]`` of :class:`Observations`."""

    id: np.ndarray  # int64, as in the file
    kind: np.ndarray  # int8: ONE_SHOT, VIDEO, STEREO, PERIODIC
    first: np.ndarray  # int64, len = n + 1 (CSR offsets into the observations)
    line: np.ndarray  # int64, 1-based line of the request in the source file (0 if unknown)

    def __len__(self) -> int:
        return len(self.id)


@dataclass(frozen=True, eq=False)
class Observations:
    """One row per observation opportunity, grouped by request (file order)."""

    id: np.ndarray  # int64
    request: np.ndarray  # int32, row in Requests
    satellite: np.ndarray  # int32, row in OneraFleet.satellites
    slot: np.ndarray  # int32: stereo pair id, periodic time slot, 0 otherwise
    start: np.ndarray  # int64, window start (s since 0 h)
    end: np.ndarray  # int64, window end
    duration: np.ndarray  # int64
    lat: np.ndarray  # float64, degrees
    lon: np.ndarray
    alt: np.ndarray
    score: np.ndarray  # float64, the file's weather score
    value: np.ndarray  # float64, class (x 4 for a video)

    def __len__(self) -> int:
        return len(self.id)


@dataclass(frozen=True, eq=False)
class Downloads:
    """One row per mandatory download (a ground-station visibility window of a satellite)."""

    id: np.ndarray  # int64 (disjoint from observation ids)
    satellite: np.ndarray  # int32, row in OneraFleet.satellites
    start: np.ndarray  # int64
    end: np.ndarray  # int64
    lat: np.ndarray
    lon: np.ndarray
    alt: np.ndarray

    @property
    def duration(self) -> np.ndarray:
        return np.minimum(DOWNLOAD_S, 0.95 * (self.end - self.start))

    def __len__(self) -> int:
        return len(self.id)


@dataclass(frozen=True, eq=False)
class OneraFleet:
    satellites: np.ndarray  # int64 satellite ids, sorted
    requests: Requests
    observations: Observations
    downloads: Downloads
    name: str = ""

    def slots(self, r: int) -> np.ndarray:
        """The distinct time slots (periodic) or pair ids (stereo) of request `r`, sorted."""
        a, b = self.requests.first[r], self.requests.first[r + 1]
        return np.unique(self.observations.slot[a:b])


@dataclass(frozen=True, eq=False)
class OneraSchedule:
    """A plan: one row per scheduled activity (observation or download), starts in seconds since 0 h."""

    satellite: np.ndarray  # int64 satellite id
    activity: np.ndarray  # int64 observation or download id
    start: np.ndarray  # float64 (the solver's are whole milliseconds)

    def __len__(self) -> int:
        return len(self.activity)


# --------------------------------------------------------------------------- the .pb reader

def is_onera_file(path) -> bool:
    """A ``.pb`` file, or a text file whose first two lines look like an ONERA instance."""
    p = Path(path)
    if not p.is_file():
        return False
    if p.suffix.lower() == ".pb":
        return True
    try:
        with open(p, "r", errors="replace") as f:
            head = [f.readline().strip() for _ in range(2)]
    except OSError:
        return False
    parts = head[1].split(",")
    return head[0].isdigit() and len(parts) == 3 and parts[2].strip() in KIND_NAMES


def _int(path, ln: int, text: str, what: str, lo: int = INT64[0], hi: int = INT64[1]) -> int:
    try:
        value = int(text)
    except ValueError:
        raise InputError(path, f"line {ln}: {what}: {text.strip()!r} is not an integer") from None
    if not lo <= value <= hi:
        raise InputError(path, f"line {ln}: {what}: {value} is out of range [{lo}, {hi}]")
    return value


def read_pb(path: str | os.PathLike) -> OneraFleet:
    """Parse an ONERA ``.pb`` file; one-line :class:`InputError` (file, line, reason) on bad input."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read: {exc}") from None
    n = len(lines)
    if n == 0:
        raise InputError(path, "line 1: empty file (expected the number of requests)")
    n_req = _int(path, 1, lines[0], "number of requests")
    i = 1
    r_id, r_kind, r_first, r_line = [], [], [0], []
    obs_rows: list[list[str]] = []
    obs_line: list[int] = []
    obs_slot: list[int] = []
    obs_req: list[int] = []
    for r in range(n_req):
        if i >= n:
            raise InputError(path, f"line {i + 1}: file ends after {r} of {n_req} requests")
        ln = i + 1
        parts = lines[i].split(",")
        if len(parts) != 3 or parts[2].strip() not in KIND_NAMES:
            raise InputError(path, f"line {ln}: request line does not parse (expected ID,N_OBSERVATIONS,TYPE with "
                                   f"TYPE one of {', '.join(KIND_NAMES)}): {lines[i].strip()!r}")
        rid = _int(path, ln, parts[0], "request id")
        nobs = _int(path, ln, parts[1], "number of observations")
        kind = KIND_NAMES.index(parts[2].strip())
        if nobs < 0:
            raise InputError(path, f"line {ln}: negative number of observations")
        if kind == PERIODIC and nobs == 0:
            raise InputError(path, f"line {ln}: periodic request {rid} without slots (no observation)")
        i += 1
        width = 10 if kind in (STEREO, PERIODIC) else 9
        for _ in range(nobs):
            if i >= n:
                raise InputError(path, f"line {i + 1}: file ends inside request {rid} (expected {nobs} observations)")
            parts = lines[i].split(",")
            if len(parts) != width:
                raise InputError(path, f"line {i + 1}: observation of a {KIND_NAMES[kind]} request needs {width} "
                                       f"fields, got {len(parts)}")
            if width == 10:
                obs_slot.append(_int(path, i + 1, parts[0], "pair id" if kind == STEREO else "time slot", 0, SLOT_MAX))
                parts = parts[1:]
            else:
                obs_slot.append(0)
            obs_rows.append(parts)
            obs_line.append(i + 1)
            obs_req.append(r)
            i += 1
        r_id.append(rid)
        r_kind.append(kind)
        r_first.append(len(obs_rows))
        r_line.append(ln)
    if i >= n:
        raise InputError(path, f"line {i + 1}: file ends before the number of downloads")
    n_dl = _int(path, i + 1, lines[i], "number of downloads")
    i += 1
    dl_rows, dl_line = [], []
    for _ in range(n_dl):
        if i >= n:
            raise InputError(path, f"line {i + 1}: file ends after {len(dl_rows)} of {n_dl} downloads")
        parts = lines[i].split(",")
        if len(parts) != 7:
            raise InputError(path, f"line {i + 1}: download needs 7 fields (ID,SATELLITE,START,END,LAT,LON,ALT), "
                                   f"got {len(parts)}")
        dl_rows.append(parts)
        dl_line.append(i + 1)
        i += 1
    for j in range(i, n):
        if lines[j].strip():
            raise InputError(path, f"line {j + 1}: unexpected content after the {n_dl} downloads")
    if n_req <= 0:
        raise InputError(path, "line 1: no request (an instance needs one)")
    if n_dl <= 0:
        raise InputError(path, f"line {i}: no download (the satellites are those the downloads name)")

    ocols = _columns(path, obs_rows, obs_line, (int, int, int, int, int, float, float, float, float),
                     ("observation id", "satellite", "window start", "window end", "duration", "latitude",
                      "longitude", "altitude", "score"))
    dcols = _columns(path, dl_rows, dl_line, (int, int, int, int, float, float, float),
                     ("download id", "satellite", "window start", "window end", "latitude", "longitude", "altitude"))
    obs_line_a = np.asarray(obs_line, dtype=np.int64)
    _require_ranges(path, ocols, dcols, obs_line, dl_line)
    sats = np.unique(dcols[1])
    o_sat = np.searchsorted(sats, ocols[1])
    unknown = np.flatnonzero((o_sat >= len(sats)) | (sats[np.minimum(o_sat, max(len(sats) - 1, 0))] != ocols[1])
                             if len(sats) else np.ones(len(o_sat), bool))
    if len(unknown):
        k = unknown[0]
        raise InputError(path, f"line {obs_line[k]}: observation {ocols[0][k]} names satellite {ocols[1][k]}, which "
                               "has no download (unknown satellite)")
    for what, (a, b, d, lines_) in (("observation", (ocols[2], ocols[3], ocols[4], obs_line_a)),
                                    ("download", (dcols[2], dcols[3], np.zeros(len(dcols[2]), np.int64),
                                                  np.asarray(dl_line)))):
        bad = np.flatnonzero(b - a < d)
        if len(bad):
            k = bad[0]
            raise InputError(path, f"line {lines_[k]}: {what} window [{a[k]}, {b[k]}] is shorter than its duration "
                                   f"{d[k]}")
    bad = np.flatnonzero(ocols[4] < 0)
    if len(bad):
        raise InputError(path, f"line {obs_line[bad[0]]}: negative duration")
    bad = np.flatnonzero((ocols[8] < 0) | (ocols[8] > 1) | ~np.isfinite(ocols[8]))
    if len(bad):
        raise InputError(path, f"line {obs_line[bad[0]]}: score {ocols[8][bad[0]]} is outside [0, 1]")
    _require_unique_ids(path, np.concatenate([ocols[0], dcols[0]]),
                        np.concatenate([obs_line_a, np.asarray(dl_line, dtype=np.int64)]), r_id, r_line)
    o_req = np.asarray(obs_req, dtype=np.int32)
    slot = np.asarray(obs_slot, dtype=np.int32)
    kind_a = np.asarray(r_kind, dtype=np.int8)
    _check_pairs(path, kind_a, o_req, slot, o_sat, obs_line_a)
    value = score_class(ocols[8]) * np.where(kind_a[o_req] == VIDEO, VIDEO_FACTOR, 1.0)
    requests = Requests(np.asarray(r_id, np.int64), kind_a, np.asarray(r_first, np.int64), np.asarray(r_line, np.int64))
    observations = Observations(ocols[0], o_req, o_sat.astype(np.int32), slot, ocols[2], ocols[3], ocols[4], ocols[5],
                                ocols[6], ocols[7], ocols[8], value)
    d_sat = np.searchsorted(sats, dcols[1]).astype(np.int32)
    downloads = Downloads(dcols[0], d_sat, dcols[2], dcols[3], dcols[4], dcols[5], dcols[6])
    return OneraFleet(sats.astype(np.int64), requests, observations, downloads, name=path.stem)


def _require_ranges(path: Path, ocols: list, dcols: list, obs_line: list, dl_line: list) -> None:
    """Observations' and downloads' times, durations and coordinates within their ranges (one line naming the first
    value out of range)."""
    for what, cols, lines_, ranges in (
            ("observation", ocols, obs_line, ((2, "window start", 0, TIME_MAX_S), (3, "window end", 0, TIME_MAX_S),
                                              (4, "duration", 0, TIME_MAX_S), (5, "latitude", -90, 90),
                                              (6, "longitude", -180, 180))),
            ("download", dcols, dl_line, ((2, "window start", 0, TIME_MAX_S), (3, "window end", 0, TIME_MAX_S),
                                          (4, "latitude", -90, 90), (5, "longitude", -180, 180)))):
        for c, name, lo, hi in ranges:
            bad = np.flatnonzero((cols[c] < lo) | (cols[c] > hi))
            if len(bad):
                k = bad[0]
                raise InputError(path, f"line {lines_[k]}: {what} {name} {cols[c][k]} is out of range [{lo}, {hi}]")


def _require_unique_ids(path: Path, all_ids: np.ndarray, all_lines: np.ndarray, r_id: list, r_line: list) -> None:
    """Observation and download ids (`all_ids`, read at `all_lines`) unique among themselves, request ids among
    themselves (one line naming the second use and the first)."""
    order = np.argsort(all_ids, kind="stable")
    dup = np.flatnonzero(np.diff(all_ids[order]) == 0)
    if len(dup):
        first, second = order[dup[0]], order[dup[0] + 1]
        raise InputError(path, f"line {all_lines[second]}: id {all_ids[second]} already used at line "
                               f"{all_lines[first]}")
    if len(set(r_id)) != len(r_id):
        seen: dict[int, int] = {}
        for rid, ln in zip(r_id, r_line):
            if rid in seen:
                raise InputError(path, f"line {ln}: request id {rid} already used at line {seen[rid]}")
            seen[rid] = ln


def _columns(path, rows, lines, types, names) -> list[np.ndarray]:
    """Columns of comma-separated rows, parsed by numpy; the first bad field is reported with its line."""
    out = []
    for c, (t, name) in enumerate(zip(types, names)):
        col = [row[c] for row in rows]
        try:
            out.append(np.array(col, dtype=np.float64 if t is float else np.int64) if col
                       else np.zeros(0, np.float64 if t is float else np.int64))
        except (ValueError, OverflowError):
            for k, v in enumerate(col):
                try:
                    x = t(v)
                except ValueError:
                    kind = "a number" if t is float else "an integer"
                    raise InputError(path, f"line {lines[k]}: {name}: {v.strip()!r} is not {kind}") from None
                if t is int and not INT64[0] <= x <= INT64[1]:
                    raise InputError(path, f"line {lines[k]}: {name}: {x} does not fit a 64-bit integer") from None
            raise
        if t is float and len(out[-1]) and not np.all(np.isfinite(out[-1])):
            k = int(np.flatnonzero(~np.isfinite(out[-1]))[0])
            raise InputError(path, f"line {lines[k]}: {name}: not a finite number")
    return out


def _check_pairs(path, kind, o_req, slot, o_sat, lines) -> None:
    """A stereo pair is exactly two images on one satellite."""
    st = np.flatnonzero(kind[o_req] == STEREO)
    if not len(st):
        return
    key = o_req[st].astype(np.int64) * (1 << 32) + slot[st].astype(np.int64)
    order = np.argsort(key, kind="stable")
    k_sorted = key[order]
    starts = np.flatnonzero(np.r_[True, k_sorted[1:] != k_sorted[:-1]])
    counts = np.diff(np.r_[starts, len(k_sorted)])
    bad = np.flatnonzero(counts != 2)
    if len(bad):
        row = st[order[starts[bad[0]]]]
        raise InputError(path, f"line {lines[row]}: stereo pair {slot[row]} has {counts[bad[0]]} image(s), "
                               "expected 2")
    a, b = st[order[starts]], st[order[starts + 1]]
    bad = np.flatnonzero(o_sat[a] != o_sat[b])
    if len(bad):
        raise InputError(path, f"line {lines[b[bad[0]]]}: the two images of stereo pair {slot[b[bad[0]]]} are on "
                               "two satellites")


# --------------------------------------------------------------------------- transitions

def transition(lat1, lon1, lat2, lon2, same_request=False):
    """tau = min(sqrt(dlat^2 + dlon^2), 90) s (degrees); 0 between two observations of one request."""
    tau = np.minimum(np.hypot(np.asarray(lat1) - lat2, np.asarray(lon1) - lon2), TAU_MAX_S)
    return np.where(same_request, 0.0, tau)


# --------------------------------------------------------------------------- the fleet directory

REQ_COLUMNS = {"request_id": "int", "kind": "int", "first": "int", "line": "int"}
OBS_COLUMNS = {"observation_id": "int", "request": "int", "satellite": "int", "slot": "int", "window_start_s": "int",
               "window_end_s": "int", "duration_s": "int", "latitude_deg": "float", "longitude_deg": "float",
               "altitude": "float", "score": "float", "value": "float"}
DL_COLUMNS = {"download_id": "int", "satellite": "int", "window_start_s": "int", "window_end_s": "int",
              "latitude_deg": "float", "longitude_deg": "float", "altitude": "float"}
SAT_COLUMNS = {"satellite_id": "int"}
TABLE_FILES = ("meta.json", "satellites.parquet", "requests.parquet", "observations.parquet", "downloads.parquet")


def _tables(f: OneraFleet) -> dict[str, dict[str, np.ndarray]]:
    r, o, d = f.requests, f.observations, f.downloads
    return {
        "satellites": {"satellite_id": f.satellites},
        "requests": {"request_id": r.id, "kind": r.kind.astype(np.int64), "first": r.first[:-1], "line": r.line},
        "observations": {"observation_id": o.id, "request": o.request.astype(np.int64),
                         "satellite": o.satellite.astype(np.int64), "slot": o.slot.astype(np.int64),
                         "window_start_s": o.start, "window_end_s": o.end, "duration_s": o.duration,
                         "latitude_deg": o.lat, "longitude_deg": o.lon, "altitude": o.alt, "score": o.score,
                         "value": o.value},
        "downloads": {"download_id": d.id, "satellite": d.satellite.astype(np.int64), "window_start_s": d.start,
                      "window_end_s": d.end, "latitude_deg": d.lat, "longitude_deg": d.lon, "altitude": d.alt},
    }


def fingerprint(f: OneraFleet) -> str:
    """sha256 of every column's bytes (name, dtype, values) of the four tables."""
    h = hashlib.sha256()
    for name, cols in _tables(f).items():
        for c, v in cols.items():
            v = np.ascontiguousarray(v)
            h.update(f"{name}.{c}:{v.dtype.str}:{len(v)};".encode())
            h.update(v.tobytes())
    return h.hexdigest()


def is_onera_dir(path) -> bool:
    p = Path(path)
    try:
        meta = json.loads((p / "meta.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(meta, dict) and meta.get("kind") == KIND


def write_onera(f: OneraFleet, out, overwrite: bool = False, source: str = "") -> Path:
    """Write the ONERA fleet directory `out` atomically (Parquet tables + meta.json)."""
    import pyarrow.parquet as pq

    from eosp.atomic import atomic_dir
    from eosp.fleet.io import arrow_table

    o = f.observations
    meta = {"kind": KIND, "schema_version": SCHEMA_VERSION, "source": source, "name": f.name,
            "fingerprint": fingerprint(f), "satellites": len(f.satellites), "requests": len(f.requests),
            "requests_by_kind": {KIND_SHORT[k]: int((f.requests.kind == k).sum()) for k in range(4)},
            "observations": len(o), "downloads": len(f.downloads)}
    with atomic_dir(out, overwrite=overwrite, owned=is_onera_dir, names=lambda _: TABLE_FILES) as tmp:
        for name, cols in _tables(f).items():
            pq.write_table(arrow_table(cols), tmp / f"{name}.parquet")
        (tmp / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    return Path(out)


def read_onera(path) -> OneraFleet:
    """An ONERA fleet directory, its columns checked (kinds, ranges) and its fingerprint verified."""
    from eosp.fleet.io import read_columns, read_meta_json

    root = Path(path)
    meta = read_meta_json(root, KIND, SCHEMA_VERSION, "an ONERA fleet directory")
    s = read_columns(root / "satellites.parquet", SAT_COLUMNS)
    r = read_columns(root / "requests.parquet", REQ_COLUMNS)
    o = read_columns(root / "observations.parquet", OBS_COLUMNS)
    d = read_columns(root / "downloads.parquet", DL_COLUMNS)
    n_sat, n_req = len(s["satellite_id"]), len(r["request_id"])
    for file, cols, c, hi in (("observations", o, "request", n_req), ("observations", o, "satellite", n_sat),
                              ("downloads", d, "satellite", n_sat), ("requests", r, "kind", 4),
                              ("requests", r, "first", len(o["observation_id"]) + 1)):
        bad = np.flatnonzero((cols[c] < 0) | (cols[c] >= hi))
        if len(bad):
            raise InputError(root / f"{file}.parquet", f"out of range [0, {hi})", column=c, row=int(bad[0]))
    f = OneraFleet(
        s["satellite_id"],
        Requests(r["request_id"], r["kind"].astype(np.int8), np.r_[r["first"], len(o["observation_id"])].astype(np.int64),
                 r["line"]),
        Observations(o["observation_id"], o["request"].astype(np.int32), o["satellite"].astype(np.int32),
                     o["slot"].astype(np.int32), o["window_start_s"], o["window_end_s"], o["duration_s"],
                     o["latitude_deg"], o["longitude_deg"], o["altitude"], o["score"], o["value"]),
        Downloads(d["download_id"], d["satellite"].astype(np.int32), d["window_start_s"], d["window_end_s"],
                  d["latitude_deg"], d["longitude_deg"], d["altitude"]),
        name=str(meta.get("name", "")))
    if fingerprint(f) != meta.get("fingerprint"):
        raise InputError(root / "meta.json", "fingerprint does not match the fleet's content (files edited or mixed)")
    return f


# --------------------------------------------------------------------------- schedules

def write_schedule(s: OneraSchedule, f: OneraFleet, path, overwrite: bool = False, info: dict | None = None) -> Path:
    """A plan as Parquet (satellite, activity, start, end), marked and tied to the fleet's fingerprint."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from eosp.atomic import atomic_path
    from eosp.ownership import check_output, parquet_mark

    path = check_output(path, "onera-schedule", overwrite=overwrite, suffixes=(".parquet",))
    end = s.start + activity_durations(f, s.activity)
    table = pa.table({"satellite": pa.array(s.satellite, pa.int64()), "activity": pa.array(s.activity, pa.int64()),
                      "start": pa.array(np.asarray(s.start, np.float64), pa.float64()),
                      "end": pa.array(end, pa.float64())})
    md = {b"kind": SCHEDULE_KIND, b"fleet_fingerprint": fingerprint(f).encode(), **parquet_mark("onera-schedule")}
    for k, v in (info or {}).items():
        md[k.encode()] = json.dumps(v).encode()
    with atomic_path(path, suffix=".parquet") as tmp:
        pq.write_table(table.replace_schema_metadata(md), tmp)
    return path


def activity_durations(f: OneraFleet, activity: np.ndarray) -> np.ndarray:
    """Durations of activities by id (observations: their duration; downloads: min(180, 0.95 x window));
    NaN for an unknown id."""
    o, d = f.observations, f.downloads
    ids = np.concatenate([o.id, d.id])
    dur = np.concatenate([o.duration.astype(np.float64), d.duration])
    order = np.argsort(ids)
    pos = np.searchsorted(ids[order], activity)
    pos = np.minimum(pos, len(ids) - 1)
    ok = ids[order][pos] == activity
    return np.where(ok, dur[order][pos], np.nan)


def read_schedule(path, f: OneraFleet) -> tuple[OneraSchedule, dict]:
    """A plan from a Parquet schedule of this fleet or from a text plan (docs/formats.md, "ONERA plan")."""
    from eosp.fleet.io import read_schedule_table

    path = Path(path)
    if path.suffix.lower() != ".parquet":
        return read_plan(path), {}
    columns = {"satellite": "int", "activity": "int", "start": "float"}
    cols, info = read_schedule_table(path, SCHEDULE_KIND, fingerprint(f), columns, "an ONERA schedule")
    return OneraSchedule(cols["satellite"], cols["activity"], cols["start"]), info


PLAN_HEADER = "satellite activity start end"


def write_plan(s: OneraSchedule, f: OneraFleet, path, overwrite: bool = False) -> Path:
    """The text plan: a mark line, a header, then ``SATELLITE ACTIVITY START END`` per activity, sorted by
    satellite then start (seconds since 0 h, to the millisecond)."""
    from eosp.atomic import atomic_path
    from eosp.ownership import check_output, comment_mark

    path = check_output(path, "onera-plan", overwrite=overwrite, suffixes=(".txt",))
    end = s.start + activity_durations(f, s.activity)
    order = np.lexsort((s.start, s.satellite))
    out = [comment_mark("onera-plan"), PLAN_HEADER]
    out += [f"{a} {b} {_sec(c)} {_sec(e)}" for a, b, c, e in zip(s.satellite[order].tolist(), s.activity[order].tolist(),
                                                                  s.start[order].tolist(), end[order].tolist())]
    with atomic_path(path, suffix=".txt") as tmp:
        tmp.write_text("\n".join(out) + "\n")
    return path


def _sec(t: float) -> str:
    """Seconds to the millisecond, without trailing zeros (a solver's starts are whole milliseconds)."""
    return f"{t:.3f}".rstrip("0").rstrip(".")


def read_plan(path) -> OneraSchedule:
    """Parse a text plan (lines starting with # and the header are skipped; END is not trusted: the checker
    recomputes it)."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read: {exc}") from None
    rows = []
    for k, line in enumerate(lines, 1):
        t = line.strip()
        if not t or t.startswith("#") or t == PLAN_HEADER:
            continue
        parts = t.split()
        if len(parts) not in (3, 4):
            raise InputError(path, f"line {k}: expected SATELLITE ACTIVITY START END")
        try:
            sat, act, start = int(parts[0]), int(parts[1]), float(parts[2])
        except ValueError:
            raise InputError(path, f"line {k}: satellite and activity must be integers, start a number") from None
        if not (INT64[0] <= sat <= INT64[1] and INT64[0] <= act <= INT64[1] and math.isfinite(start)):
            raise InputError(path, f"line {k}: satellite and activity must fit 64-bit integers, start be finite")
        rows.append((sat, act, start))
    return OneraSchedule(np.array([r[0] for r in rows], dtype=np.int64), np.array([r[1] for r in rows], dtype=np.int64),
                         np.array([r[2] for r in rows], dtype=np.float64))
