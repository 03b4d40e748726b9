"""Reading a regional_coverage case directory where it lies, and its solution files.

A case is four files (manifest.json, satellites.yaml, regions.geojson, coverage_grid.json).  Everything the
benchmark's verifier reads is read here with the verifier's meaning (only a polygon's first ring; a region's
weight defaults to 1; a sample's weight as written; the region totals as the grid file states them), and
everything it would trip on, or silently accept although it makes no sense, is refused in one line naming the
file, the entry and the reason (:class:`~eosp.errors.InputError`): a missing file, a wrong type, a naive
timestamp, a non-polygon or open ring, coordinates off the globe, a grid region the GeoJSON lacks, a sensor band
no strip fits in, a battery above its capacity.
"""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from eosp.errors import InputError
from eosp.regional.model import Case, Plan, Region, Satellite

FILES = ("manifest.json", "satellites.yaml", "regions.geojson", "coverage_grid.json")
MARK = "regional-coverage-solution"
SENSOR = ("min_edge_off_nadir_deg", "max_edge_off_nadir_deg", "cross_track_fov_deg", "min_strip_duration_s",
          "max_strip_duration_s")
AGILITY = ("max_roll_rate_deg_per_s", "max_roll_acceleration_deg_per_s2", "settling_time_s")
POWER = ("battery_capacity_wh", "initial_battery_wh", "idle_power_w", "imaging_power_w", "slew_power_w",
         "sunlit_charge_power_w")


def looks_like_case(path: str) -> tuple[bool, str]:
    """Whether `path` is a regional_coverage case directory (its manifest names the benchmark), and why not."""
    p = Path(path)
    if not p.is_dir():
        return False, "not a directory"
    m = p / "manifest.json"
    if not m.is_file():
        return False, "no manifest.json"
    try:
        head = m.read_text(encoding="utf-8", errors="replace")[:65536]
    except OSError as exc:
        return False, f"cannot read manifest.json ({exc.strerror})"
    if '"regional_coverage"' not in head:
        return False, "manifest.json does not name the regional_coverage benchmark"
    return True, "a regional_coverage case"


def _load_json(path: Path) -> Any:
    if not path.is_file():
        raise InputError(path, "missing (a regional_coverage case has " + ", ".join(FILES) + ")")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise InputError(path, "not UTF-8 text") from None
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None


def _mapping(path: Path, where: str, value: Any) -> dict:
    if not isinstance(value, dict):
        raise InputError(path, f"{where}: expected an object, got {type(value).__name__}")
    return value


def _list(path: Path, where: str, value: Any) -> list:
    if not isinstance(value, list):
        raise InputError(path, f"{where}: expected a list, got {type(value).__name__}")
    return value


def _str(path: Path, where: str, obj: dict, key: str) -> str:
    if key not in obj:
        raise InputError(path, f"{where}: missing {key}")
    if not isinstance(obj[key], str) or not obj[key].strip():
        raise InputError(path, f"{where}.{key}: expected a non-empty string, got {obj[key]!r}")
    return obj[key]


def _num(path: Path, where: str, obj: dict, key: str, lo: float | None = None, hi: float | None = None,
         optional: bool = False, default: float | None = None) -> float | None:
    if key not in obj or obj[key] is None:
        if optional:
            return default
        raise InputError(path, f"{where}: missing {key}")
    v = obj[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise InputError(path, f"{where}.{key}: expected a finite number, got {v!r}")
    v = float(v)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        span = f"[{lo:g}, {hi:g}]" if lo is not None and hi is not None else (f">= {lo:g}" if lo is not None
                                                                               else f"<= {hi:g}")
        raise InputError(path, f"{where}.{key}: {v:g} is out of range ({span})")
    return v


def parse_time(path: Path, where: str, text: Any) -> datetime:
    """An ISO 8601 time with a Z or an explicit offset (a naive time is refused: the benchmark's rule)."""
    if not isinstance(text, str) or not text.strip():
        raise InputError(path, f"{where}: expected an ISO 8601 time, got {text!r}")
    t = text.strip()
    t = t[:-1] + "+00:00" if t.endswith(("Z", "z")) else t
    try:
        v = datetime.fromisoformat(t)
    except ValueError:
        raise InputError(path, f"{where}: not an ISO 8601 time: {text!r}") from None
    if v.tzinfo is None:
        raise InputError(path, f"{where}: {text!r} has no time zone (end it with Z or give an offset)")
    return v.astimezone(UTC)


def _manifest(d: Path) -> dict:
    p = d / "manifest.json"
    raw = _mapping(p, "manifest", _load_json(p))
    if raw.get("benchmark") != "regional_coverage":
        raise InputError(p, f"benchmark: expected 'regional_coverage', got {raw.get('benchmark')!r}")
    earth = _mapping(p, "earth_model", raw.get("earth_model"))
    if str(earth.get("shape", "")).lower() != "wgs84":
        raise InputError(p, f"earth_model.shape: only 'wgs84' is defined, got {earth.get('shape')!r}")
    grid = _mapping(p, "grid_parameters", raw.get("grid_parameters"))
    scoring = _mapping(p, "scoring", raw.get("scoring"))
    out = {"case_id": _str(p, "manifest", raw, "case_id"),
           "start": parse_time(p, "horizon_start", raw.get("horizon_start")),
           "end": parse_time(p, "horizon_end", raw.get("horizon_end")),
           "time_step_s": _num(p, "manifest", raw, "time_step_s", lo=1),
           "sample_step_s": _num(p, "manifest", raw, "coverage_sample_step_s", lo=1),
           "spacing": _num(p, "grid_parameters", grid, "sample_spacing_m", lo=0),
           "alpha": _num(p, "scoring", scoring, "revisit_bonus_alpha", optional=True, default=0.0),
           "max_actions": _num(p, "scoring", scoring, "max_actions_total", lo=0, optional=True)}
    for key in ("time_step_s", "sample_step_s"):
        if not float(out[key]).is_integer():
            raise InputError(p, f"{key}: expected whole seconds, got {out[key]:g}")
    if out["end"] <= out["start"]:
        raise InputError(p, "horizon_end: not after horizon_start")
    if out["alpha"] != 0.0:
        raise InputError(p, f"scoring.revisit_bonus_alpha: {out['alpha']:g} (the verifier scores first coverage "
                            "only; only 0 is defined)")
    primary = scoring.get("primary_metric", "coverage_ratio")
    if primary != "coverage_ratio":
        raise InputError(p, f"scoring.primary_metric: only 'coverage_ratio' is defined, got {primary!r}")
    out["raw"] = raw
    return out


def _satellites(d: Path) -> list[Satellite]:
    import yaml

    p = d / "satellites.yaml"
    if not p.is_file():
        raise InputError(p, "missing (a regional_coverage case has " + ", ".join(FILES) + ")")
    try:
        rows = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" (line {mark.line + 1})" if mark is not None else ""
        raise InputError(p, f"not valid YAML{at}") from None
    rows = _list(p, "satellites", rows)
    if not rows:
        raise InputError(p, "no satellites")
    sats, seen = [], set()
    for i, row in enumerate(rows):
        w = f"satellites[{i}]"
        e = _mapping(p, w, row)
        sid = _str(p, w, e, "satellite_id")
        w = f"satellites[{i}] ({sid})"
        if sid in seen:
            raise InputError(p, f"{w}: duplicate satellite_id")
        seen.add(sid)
        sen, agi, pw = (_mapping(p, f"{w}.{k}", e.get(k)) for k in ("sensor", "agility", "power"))
        vals = {k: _num(p, f"{w}.sensor", sen, k, lo=0, hi=90 if k.endswith("_deg") else None) for k in SENSOR}
        vals.update({k: _num(p, f"{w}.agility", agi, k, lo=0) for k in AGILITY})
        vals.update({k: _num(p, f"{w}.power", pw, k, lo=0) for k in POWER})
        duty = _num(p, f"{w}.power", pw, "imaging_duty_limit_s_per_orbit", lo=0, optional=True)
        if vals["cross_track_fov_deg"] <= 0:
            raise InputError(p, f"{w}.sensor.cross_track_fov_deg: must be positive")
        if vals["max_edge_off_nadir_deg"] - vals["min_edge_off_nadir_deg"] < vals["cross_track_fov_deg"] - 1e-6:
            raise InputError(p, f"{w}.sensor: the off-nadir band [{vals['min_edge_off_nadir_deg']:g}, "
                                f"{vals['max_edge_off_nadir_deg']:g}] deg is narrower than the field of view "
                                f"{vals['cross_track_fov_deg']:g} deg: no strip fits")
        if vals["min_strip_duration_s"] > vals["max_strip_duration_s"] or vals["max_strip_duration_s"] <= 0:
            raise InputError(p, f"{w}.sensor: min_strip_duration_s {vals['min_strip_duration_s']:g} > "
                                f"max_strip_duration_s {vals['max_strip_duration_s']:g}")
        if vals["max_roll_rate_deg_per_s"] <= 0 or vals["max_roll_acceleration_deg_per_s2"] <= 0:
            raise InputError(p, f"{w}.agility: roll rate and acceleration must be positive")
        if vals["initial_battery_wh"] > vals["battery_capacity_wh"]:
            raise InputError(p, f"{w}.power.initial_battery_wh: {vals['initial_battery_wh']:g} above "
                                f"battery_capacity_wh {vals['battery_capacity_wh']:g}")
        l1, l2 = _str(p, w, e, "tle_line1"), _str(p, w, e, "tle_line2")
        parse_time(p, f"{w}.tle_epoch", e.get("tle_epoch"))  # validated; the state comes from the TLE lines
        _check_tle(p, w, l1, l2)
        sats.append(Satellite(sid, l1, l2, e["tle_epoch"], **vals, imaging_duty_limit_s_per_orbit=duty))
    return sats


def _check_tle(p: Path, w: str, l1: str, l2: str) -> None:
    from eosp.fleet.geometry import brahe_module

    if not (l1.startswith("1 ") and l2.startswith("2 ")) or len(l2.split()) < 8:
        raise InputError(p, f"{w}: tle_line1/tle_line2 are not the two lines of a TLE")
    try:
        float(l2.split()[-2])
        brahe_module().SGPPropagator.from_tle(l1, l2, 5.0)
    except Exception as exc:  # brahe raises its own error types for a TLE it cannot parse
        raise InputError(p, f"{w}: the TLE does not parse ({str(exc).splitlines()[0] if str(exc) else exc!r})") \
            from None


def _regions(d: Path) -> list[Region]:
    p = d / "regions.geojson"
    raw = _mapping(p, "regions", _load_json(p))
    if raw.get("type") != "FeatureCollection":
        raise InputError(p, f"type: expected 'FeatureCollection', got {raw.get('type')!r}")
    feats = _list(p, "features", raw.get("features"))
    if not feats:
        raise InputError(p, "features: no region")
    out, seen = [], set()
    for i, f in enumerate(feats):
        w = f"features[{i}]"
        f = _mapping(p, w, f)
        props = _mapping(p, f"{w}.properties", f.get("properties"))
        rid = _str(p, f"{w}.properties", props, "region_id")
        w = f"features[{i}] ({rid})"
        if rid in seen:
            raise InputError(p, f"{w}: duplicate region_id")
        seen.add(rid)
        geom = _mapping(p, f"{w}.geometry", f.get("geometry"))
        if geom.get("type") != "Polygon":
            raise InputError(p, f"{w}.geometry.type: expected 'Polygon', got {geom.get('type')!r}")
        rings = _list(p, f"{w}.geometry.coordinates", geom.get("coordinates"))
        if not rings:
            raise InputError(p, f"{w}.geometry.coordinates: no ring")
        ring = _list(p, f"{w}.geometry.coordinates[0]", rings[0])
        pts = []
        for j, c in enumerate(ring):
            if (not isinstance(c, list) or len(c) < 2 or any(isinstance(x, bool) or not isinstance(x, (int, float))
                                                           for x in c[:2])):
                raise InputError(p, f"{w}.geometry.coordinates[0][{j}]: expected [lon, lat], got {c!r}")
            lon, lat = float(c[0]), float(c[1])
            if not (-180.0 <= lon <= 180.0 and -90.0 <= lat <= 90.0):
                raise InputError(p, f"{w}.geometry.coordinates[0][{j}]: [{lon:g}, {lat:g}] is off the globe "
                                    "(longitude in [-180, 180], latitude in [-90, 90])")
            pts.append((lon, lat))
        if len(pts) < 4:
            raise InputError(p, f"{w}: a polygon ring needs at least 4 positions, got {len(pts)}")
        if pts[0] != pts[-1]:
            raise InputError(p, f"{w}: the ring is open (its first and last positions differ)")
        weight = _num(p, f"{w}.properties", props, "weight", lo=0, optional=True, default=1.0)
        need = _num(p, f"{w}.properties", props, "min_required_coverage_ratio", lo=0, hi=1, optional=True)
        out.append(Region(rid, float(weight), need, tuple(pts)))
    return out


def _grid(d: Path, regions: list[Region]) -> tuple[np.ndarray, list[str], list[np.ndarray], list[int]]:
    p = d / "coverage_grid.json"
    raw = _mapping(p, "coverage grid", _load_json(p))
    if raw.get("grid_version") != 1:
        raise InputError(p, f"grid_version: only 1 is defined, got {raw.get('grid_version')!r}")
    rows = _list(p, "regions", raw.get("regions"))
    index = {r.id: k for k, r in enumerate(regions)}
    totals = np.zeros(len(regions))
    found: dict[int, tuple[list, np.ndarray]] = {}
    for i, row in enumerate(rows):
        w = f"regions[{i}]"
        row = _mapping(p, w, row)
        rid = _str(p, w, row, "region_id")
        if rid not in index:
            raise InputError(p, f"{w}: region_id {rid!r} is not a region of regions.geojson")
        k = index[rid]
        if k in found:
            raise InputError(p, f"{w}: region {rid!r} listed twice")
        totals[k] = _num(p, w, row, "total_weight_m2", lo=0)
        samples = _list(p, f"{w}.samples", row.get("samples"))
        ids, arr = [], np.empty((len(samples), 3))
        for j, s in enumerate(samples):
            sw = f"{w}.samples[{j}]"
            s = _mapping(p, sw, s)
            ids.append(_str(p, sw, s, "sample_id"))
            arr[j] = (_num(p, sw, s, "longitude_deg", lo=-180, hi=180), _num(p, sw, s, "latitude_deg", lo=-90, hi=90),
                      _num(p, sw, s, "weight_m2", lo=0))
        found[k] = (ids, arr)
    missing = [r.id for k, r in enumerate(regions) if k not in found]
    if missing:
        raise InputError(p, f"regions: no samples listed for region {missing[0]!r} of regions.geojson")
    return (totals, [sid for k in range(len(regions)) for sid in found[k][0]], [found[k][1] for k in range(len(regions))],
            list(found))


def read_case(path: str) -> Case:
    """Read and validate the case directory `path` (see the module docstring)."""
    d = Path(path)
    if not d.is_dir():
        raise InputError(path, "not a directory (a regional_coverage case is a directory of " + ", ".join(FILES) + ")")
    m = _manifest(d)
    sats = _satellites(d)
    regions = _regions(d)
    totals, ids, arrs, order = _grid(d, regions)
    if len(set(ids)) != len(ids):
        dup = next(s for s in ids if ids.count(s) > 1)
        raise InputError(d / "coverage_grid.json", f"sample_id {dup!r} appears twice")
    lens = [len(a) for a in arrs]
    all_ = np.concatenate(arrs) if arrs else np.zeros((0, 3))
    return Case(path=str(d), case_id=m["case_id"], horizon_start=m["start"], horizon_end=m["end"],
                time_step_s=int(m["time_step_s"]), sample_step_s=int(m["sample_step_s"]), sample_spacing_m=m["spacing"],
                max_actions=None if m["max_actions"] is None else int(m["max_actions"]),
                revisit_bonus_alpha=m["alpha"], satellites=sats, regions=regions, region_total_m2=totals,
                sample_ids=ids, lon=all_[:, 0].copy(), lat=all_[:, 1].copy(), weight=all_[:, 2].copy(),
                region=np.repeat(np.arange(len(regions)), lens).astype(np.int64), grid_order=order,
                manifest=m["raw"])


def read_solution(path: str) -> Plan:
    """A solution file: a JSON object with an "actions" list of objects (what an action holds is the checker's
    to judge, as the verifier does; a file that is not such an object is refused)."""
    p = Path(path)
    raw = _load_json(p)
    raw = _mapping(p, "solution", raw)
    acts = _list(p, "actions", raw.get("actions"))
    for i, a in enumerate(acts):
        _mapping(p, f"actions[{i}]", a)
    return Plan(list(acts))


def write_solution(plan: Plan, path: str, overwrite: bool = False, info: dict | None = None) -> Path:
    """Write `plan` in the benchmark's solution format (eosp's mark and info beside "actions"; the verifier
    reads only "actions"), atomically, under the ownership rule."""
    from eosp.atomic import atomic_path
    from eosp.ownership import check_output

    out = check_output(path, MARK, overwrite=overwrite, suffixes=(".json",))
    body = {"eosp": MARK, "actions": plan.actions}
    if info:
        body["eosp_info"] = info
    with atomic_path(out) as tmp:
        tmp.write_text(json.dumps(body, indent=1), encoding="utf-8")
    return out
