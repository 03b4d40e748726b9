"""Tiny regional_coverage cases in the benchmark's format, written where asked: a region placed under a real
satellite's pass (its look at a roll, a given minute into the horizon), samples on a lattice inside it.  The
warm-up and the tests make their cases with it; nothing here is a reference result."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

L1 = "1 63255U 25052AX  25198.17518200  .00001597  00000-0  15702-3 0  9994"  # a public case's satellite
L2 = "2 63255  97.7253  91.1881 0000724 209.0702 151.0478 14.93504225 18614"


def satellite(sid: str, l1: str = L1, l2: str = L2, **over) -> dict:
    """A satellite entry (the public cases' narrow SAR class, strips of 20-40 s); `over` replaces fields."""
    s = {"satellite_id": sid, "tle_line1": l1, "tle_line2": l2, "tle_epoch": "2025-07-17T04:12:15.724Z",
         "sensor": {"min_edge_off_nadir_deg": 18.0, "max_edge_off_nadir_deg": 34.0, "cross_track_fov_deg": 2.8,
                    "min_strip_duration_s": 20, "max_strip_duration_s": 40},
         "agility": {"max_roll_rate_deg_per_s": 1.2, "max_roll_acceleration_deg_per_s2": 0.4, "settling_time_s": 2.0},
         "power": {"battery_capacity_wh": 900, "initial_battery_wh": 540, "idle_power_w": 85, "imaging_power_w": 290,
                   "slew_power_w": 35, "sunlit_charge_power_w": 170, "imaging_duty_limit_s_per_orbit": 900}}
    for k, v in over.items():
        for part in ("sensor", "agility", "power"):
            if k in s[part]:
                s[part][k] = v
    return s


def write_case(d: Path, sats: list[dict], regions: list[tuple[str, list, float]], budget: int = 2,
               hours: float = 2.0) -> Path:
    """A case directory: `regions` as (id, ring, spacing in degrees) with samples on that lattice inside."""
    import yaml
    from shapely.geometry import Point, Polygon

    d.mkdir(parents=True, exist_ok=True)
    (d / "manifest.json").write_text(json.dumps({
        "case_id": "tiny", "benchmark": "regional_coverage", "spec_version": "v1", "seed": 1,
        "horizon_start": "2025-07-17T00:00:00Z", "horizon_end": f"2025-07-17T{int(hours):02d}:00:00Z",
        "time_step_s": 10, "coverage_sample_step_s": 5, "earth_model": {"shape": "wgs84"},
        "grid_parameters": {"sample_spacing_m": 5000.0},
        "scoring": {"primary_metric": "coverage_ratio", "revisit_bonus_alpha": 0.0, "max_actions_total": budget}}))
    (d / "satellites.yaml").write_text(yaml.safe_dump(sats, sort_keys=False))
    feats, grid = [], []
    for rid, ring, step in regions:
        feats.append({"type": "Feature", "properties": {"region_id": rid, "weight": 1.0},
                      "geometry": {"type": "Polygon", "coordinates": [ring]}})
        poly = Polygon(ring)
        x0, y0, x1, y1 = poly.bounds
        samples = []
        for x in np.arange(x0 + step / 2, x1, step):
            for y in np.arange(y0 + step / 2, y1, step):
                if poly.covers(Point(x, y)):
                    samples.append({"sample_id": f"{rid}_s{len(samples):06d}", "longitude_deg": float(x),
                                    "latitude_deg": float(y), "weight_m2": 25e6})
        grid.append({"region_id": rid, "total_weight_m2": 25e6 * len(samples), "samples": samples})
    (d / "regions.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    (d / "coverage_grid.json").write_text(json.dumps({"grid_version": 1, "sample_spacing_m": 5000.0, "regions": grid}))
    return d


def box(lon: float, lat: float, dlon: float, dlat: float) -> list:
    return [[lon - dlon, lat - dlat], [lon + dlon, lat - dlat], [lon + dlon, lat + dlat], [lon - dlon, lat + dlat],
            [lon - dlon, lat - dlat]]


def under_pass(d: Path, sat: dict, roll: float = 25.0, minute: int = 40) -> tuple[float, float]:
    """Where the look at `roll` of `sat` hits the ground `minute` minutes into the horizon."""
    from eosp.regional.geometry import Track, axes, geodetic, hits
    from eosp.regional.read import read_case

    write_case(d, [sat], [("far", box(0.0, 0.0, 0.1, 0.1), 0.05)])
    case = read_case(str(d))
    st = Track(case).states(0)[minute * 12]
    nadir, across = axes(st[None, :3], st[None, 3:])
    h, _ = hits(st[None, :3], nadir, across, roll)
    lon, lat = geodetic(h)
    return float(lon[0]), float(lat[0])




def tiny(d: Path, budget: int = 2) -> Path:
    """One satellite, a 0.4 x 2 degree region under its pass at roll 25 deg, `budget` actions, 2 h."""
    sat = satellite("sat_a")
    lon, lat = under_pass(d, sat)
    return write_case(d, [sat], [("r1", box(lon, lat, 0.2, 1.0), 0.05)], budget=budget)
