"""The regional_coverage checker: the benchmark's verifier re-implemented, its rules in its order.

A solution is judged as the verifier judges it (benchmarks/regional_coverage/verifier.py of astro-reason):

1. the action budget (`max_actions_total`), then each ``strip_observation`` (other types are ignored): its
   fields, a known satellite, |roll| -/+ half the field of view inside the off-nadir band (1e-6 deg), a duration
   within the sensor's bounds (1e-6 s) and positive, inside the horizon, start and duration on the time grid;
2. the strip of each action that passed 1: sampled at its start, every sample step, its end; each edge and
   centre ray must hit the ellipsoid, each segment (inner_a, outer_a, outer_b, inner_b) in longitude/latitude
   must have an area above 1e-9; the grid samples each segment covers (boundary included) are covered;
3. per satellite, its actions by start: no overlap, and a gap of at least the slew time of the roll change plus
   the settling time (1e-6 s); the slew occupies the required gap just before the later action;
4. the imaging duty limit per orbital period, over every window ending at an action's start or end;
5. the battery per satellite on the sample-step mesh plus every action and slew boundary, loads at each
   interval's midpoint (idle, imaging, slew), charge when sunlit there (cylindrical shadow), clamped at the
   capacity, invalid below -1e-9;
6. the minimum coverage of each region that states one.

Metrics as the verifier reports them: coverage_ratio (the region-weighted mean of per-region ratios, each against
the region's total weight as the grid file states it), weighted_coverage_ratio, num_actions (every
strip_observation entry, rejected ones included), min_battery_wh.  Times are integer microseconds where the
verifier uses datetimes (its timedeltas round to the microsecond), floats where it uses floats.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import timedelta

import numba
import numpy as np

from eosp.problem import Verdict
from eosp.regional.geometry import Track, axes, hits, sample_offsets
from eosp.regional.model import Case, Plan, Satellite
from eosp.regional.read import parse_time

US = 1_000_000
TOL = 1.0e-6


@dataclass
class Parsed:
    index: int
    sat: int
    start_us: int
    duration_s: float
    roll: float
    ok: bool = False  # accepted for the schedule (rule 1)
    covered: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    polygons: list = field(default_factory=list)  # the strip's segments (rule 2), kept for the page

    @property
    def end_us(self) -> int:
        return self.start_us + _us(self.duration_s)


def _us(seconds: float) -> int:
    return timedelta(seconds=seconds) // timedelta(microseconds=1)


@numba.njit(cache=True)
def slew_s(delta_deg, rate, acc):
    """The benchmark's roll slew time, settling excluded: bang-coast-bang, its float operations as its verifier
    writes them (2 sqrt(d / a) while d <= rate^2 / a, else d / rate + rate / a; nothing below 1e-9 deg)."""
    d = abs(delta_deg)
    if d <= 1.0e-9:
        return 0.0
    if rate <= 0.0 or acc <= 0.0:
        return np.inf
    if d <= (rate * rate) / acc:
        return 2.0 * np.sqrt(d / acc)
    return d / rate + rate / acc


def slew_time_s(delta_deg: float, sat: Satellite) -> float:
    """:func:`slew_s` of a satellite."""
    return float(slew_s(float(delta_deg), sat.max_roll_rate_deg_per_s, sat.max_roll_acceleration_deg_per_s2))


def _aligned(seconds: float, step: float) -> bool:
    q = seconds / step
    return abs(q - round(q)) <= 1.0e-6


def _field_errors(a: dict, prefix: str) -> str | None:
    for key in ("satellite_id", "start_time"):
        if key not in a:
            return f"{prefix}: missing {key}"
        if not isinstance(a[key], str):
            return f"{prefix}: {key} must be a string"
    for key in ("duration_s", "roll_deg"):
        if key not in a:
            return f"{prefix}: missing {key}"
        if not isinstance(a[key], (int, float)):
            return f"{prefix}: {key} must be a number"
    return None


def parse(case: Case, plan: Plan) -> tuple[list[Parsed], list[str], int]:
    """Rule 1: the actions accepted for the schedule, the violations in the verifier's order, and the count of
    strip_observation entries."""
    out: list[Parsed] = []
    bad: list[str] = []
    per: list[list[str]] = []
    if case.max_actions is not None and len(plan.actions) > case.max_actions:
        bad.append(f"solution.actions has {len(plan.actions)} entries but the case allows at most {case.max_actions}")
    index = case.sat_index()
    h0 = case.horizon_start
    count = 0
    for i, a in enumerate(plan.actions):
        if a.get("type") != "strip_observation":
            continue
        count += 1
        prefix = f"actions[{i}]"
        err = _field_errors(a, prefix)
        if err is None:
            try:
                start = parse_time(case.path, f"{prefix}.start_time", a["start_time"])
            except ValueError:
                err = f"{prefix}.start_time: invalid ISO 8601 timestamp {a['start_time']!r}"
        if err is not None:
            bad.append(err)
            continue
        dur, roll = float(a["duration_s"]), float(a["roll_deg"])
        v: list[str] = []
        s = index.get(a["satellite_id"], -1)
        if s < 0:
            v.append(f"{prefix}: unknown satellite_id {a['satellite_id']!r}")
        else:
            sat = case.satellites[s]
            inner, outer = abs(roll) - 0.5 * sat.cross_track_fov_deg, abs(roll) + 0.5 * sat.cross_track_fov_deg
            if inner < sat.min_edge_off_nadir_deg - TOL:
                v.append(f"{prefix}: theta_inner_deg={inner:.6f} below min_edge_off_nadir_deg="
                         f"{sat.min_edge_off_nadir_deg:.6f}")
            if outer > sat.max_edge_off_nadir_deg + TOL:
                v.append(f"{prefix}: theta_outer_deg={outer:.6f} above max_edge_off_nadir_deg="
                         f"{sat.max_edge_off_nadir_deg:.6f}")
            if dur < sat.min_strip_duration_s - TOL:
                v.append(f"{prefix}: duration_s={dur:.6f} below min_strip_duration_s={sat.min_strip_duration_s:.6f}")
            if dur > sat.max_strip_duration_s + TOL:
                v.append(f"{prefix}: duration_s={dur:.6f} above max_strip_duration_s={sat.max_strip_duration_s:.6f}")
        start_us = (start - h0) // timedelta(microseconds=1)
        end = start + timedelta(seconds=dur)
        if dur <= 0.0:
            v.append(f"{prefix}: duration_s must be positive")
        if end <= start:
            v.append(f"{prefix}: end_time must be after start_time")
        if start < h0 or end > case.horizon_end:
            v.append(f"{prefix}: action lies outside the mission horizon")
        if not _aligned((start - h0).total_seconds(), float(case.time_step_s)):
            v.append(f"{prefix}: start_time must align to the {case.time_step_s}s time grid")
        if not _aligned(dur, float(case.time_step_s)):
            v.append(f"{prefix}: duration_s must be an integer multiple of {case.time_step_s}s")
        out.append(Parsed(i, s, start_us, dur, roll, ok=not v))
        per.append(v)
    for v in per:
        bad.extend(v)
    return out, bad, count


def strip_polygons(case: Case, track: Track, p: Parsed) -> tuple[list, str | None]:
    """Rule 2: the segments of an accepted action as shapely polygons, or the violation that stops it."""
    import shapely

    from eosp.fleet.geometry import brahe_module

    bh = brahe_module()
    sat = case.satellites[p.sat]
    offs = sample_offsets(case, p.start_us / US, p.duration_s)
    prefix = f"actions[{p.index}]"
    if len(offs) < 2:
        return [], f"{prefix}: action sampling produced fewer than two time points"
    st = np.array([track.state_at(p.sat, t) for t in offs])
    nadir, across = axes(st[:, :3], st[:, 3:])
    half = 0.5 * sat.cross_track_fov_deg
    inner = math.copysign(abs(p.roll) - half, p.roll)
    outer = math.copysign(abs(p.roll) + half, p.roll)
    pts = []
    for look in (inner, p.roll, outer):
        h, ok = hits(st[:, :3], nadir, across, look)
        if not ok.all():
            t = case.at(offs[int(np.flatnonzero(~ok)[0])])
            return [], f"{prefix}: strip rays do not intersect Earth at {t.strftime('%Y-%m-%dT%H:%M:%SZ')}"
        pts.append(h)
    ll = [[tuple(float(x) for x in bh.position_ecef_to_geodetic(q, bh.AngleFormat.DEGREES)[:2]) for q in h]
          for h in (pts[0], pts[2])]
    polys = []
    for k in range(len(offs) - 1):
        poly = shapely.Polygon([ll[0][k], ll[1][k], ll[1][k + 1], ll[0][k + 1]])
        if poly.is_empty or poly.area <= 1.0e-9:
            return [], f"{prefix}: derived strip segment collapsed to zero area"
        polys.append(poly)
    return polys, None


def covered_samples(case: Case, polys: list) -> np.ndarray:
    """Indices of the grid samples the polygons cover (boundary included)."""
    import shapely

    found = []
    for poly in polys:
        x0, y0, x1, y1 = poly.bounds
        idx = np.flatnonzero((case.lon >= x0) & (case.lon <= x1) & (case.lat >= y0) & (case.lat <= y1))
        if len(idx):
            shapely.prepare(poly)
            found.append(idx[shapely.covers(poly, shapely.points(case.lon[idx], case.lat[idx]))])
    return np.unique(np.concatenate(found)) if found else np.zeros(0, np.int64)


def _by_satellite(acts: list[Parsed]) -> dict[int, list[Parsed]]:
    """The accepted actions per satellite, satellites in the order of their first action (the verifier's)."""
    by: dict[int, list[Parsed]] = {}
    for p in acts:
        if p.ok:
            by.setdefault(p.sat, []).append(p)
    return by


def sequence(case: Case, acts: list[Parsed]) -> tuple[list[tuple[int, int, int]], list[str]]:
    """Rule 3: the slew windows (satellite, start us, end us) and the violations."""
    bad, man = [], []
    for s, lst in _by_satellite(acts).items():
        sat = case.satellites[s]
        lst.sort(key=lambda p: (p.start_us, p.end_us))
        for prev, cur in zip(lst, lst[1:]):
            if cur.start_us < prev.end_us:
                bad.append(f"satellite {sat.id}: overlapping strip observations (actions[{prev.index}] and "
                           f"actions[{cur.index}])")
                continue
            delta = abs(cur.roll - prev.roll)
            need = slew_time_s(delta, sat) + sat.settling_time_s
            gap = (cur.start_us - prev.end_us) / US
            if gap + TOL < need:
                bad.append(f"actions[{cur.index}]: insufficient slew/settle time on satellite {sat.id} "
                           f"(need {need:.3f}s, gap {gap:.3f}s, delta {delta:.4f}deg)")
                continue
            man.append((s, cur.start_us - _us(need), cur.start_us))
    return man, bad


def duty(case: Case, acts: list[Parsed]) -> list[str]:
    """Rule 4: the imaging duty limit over every window of one orbital period ending at an action boundary."""
    bad = []
    for s, lst in _by_satellite(acts).items():
        sat = case.satellites[s]
        limit = sat.imaging_duty_limit_s_per_orbit
        if limit is None:
            continue
        period_us = _us(sat.orbit_period_s) if math.isfinite(sat.orbit_period_s) else 10 ** 18
        for b in sorted({t for p in lst for t in (p.start_us, p.end_us)}):
            w0 = b - period_us
            used = sum((min(b, p.end_us) - max(w0, p.start_us)) / US for p in lst if min(b, p.end_us) > max(w0, p.start_us))
            if used > limit + TOL:
                bad.append(f"satellite {sat.id}: imaging duty limit exceeded over one orbit (used {used:.3f}s, "
                           f"limit {limit:.3f}s)")
                break
    return bad


@dataclass
class Report:
    valid: bool
    violations: list[str]
    metrics: dict
    acts: list[Parsed]
    slews: list[tuple[int, int, int]]
    battery: dict


def check(case: Case, plan: Plan, track: Track | None = None) -> Report:
    """Judge `plan` on `case` (see the module docstring)."""
    from eosp.regional.power import simulate

    track = track or Track(case)
    acts, bad, count = parse(case, plan)
    covered = np.zeros(len(case.lon), dtype=bool)
    for p in acts:
        if not p.ok:
            continue
        polys, err = strip_polygons(case, track, p)
        if err is not None:
            bad.append(err)
            continue
        p.polygons = polys
        p.covered = covered_samples(case, polys)
        covered[p.covered] = True
    slews, seq_bad = sequence(case, acts)
    bad += seq_bad
    bad += duty(case, acts)
    battery, power_bad = simulate(case, track, acts, slews)
    bad += power_bad
    metrics = metrics_of(case, covered)
    metrics["num_actions"] = count
    metrics["min_battery_wh"] = min((b["min_battery_wh"] for b in battery.values()), default=0.0)
    for k in case.grid_order:
        r = case.regions[k]
        ratio = metrics["region_coverages"][r.id]["coverage_ratio"]
        if r.min_required_coverage_ratio is not None and ratio + 1.0e-9 < r.min_required_coverage_ratio:
            bad.append(f"region {r.id}: coverage_ratio={ratio:.6f} below min_required_coverage_ratio="
                       f"{r.min_required_coverage_ratio:.6f}")
    return Report(not bad, bad, metrics, acts, slews, battery)


def metrics_of(case: Case, covered: np.ndarray) -> dict:
    """The coverage metrics of a covered-sample mask, summed in the verifier's order."""
    per, wsum, ratio_sum, cov_tot, grid_tot = {}, 0.0, 0.0, 0.0, 0.0
    for k in case.grid_order:
        r = case.regions[k]
        mine = case.region == k
        cw = float(case.weight[mine][covered[mine]].sum())
        tot = float(case.region_total_m2[k])
        ratio = 0.0 if tot <= 0.0 else cw / tot
        per[r.id] = {"covered_weight_m2_equivalent": cw, "total_weight_m2": tot, "coverage_ratio": ratio,
                     "weight": r.weight}
        wsum += r.weight
        ratio_sum += r.weight * ratio
        cov_tot += cw
        grid_tot += tot
    return {"coverage_ratio": 0.0 if wsum <= 0.0 else ratio_sum / wsum,
            "weighted_coverage_ratio": 0.0 if grid_tot <= 0.0 else cov_tot / grid_tot, "region_coverages": per}


def verdict(case: Case, plan: Plan, track: Track | None = None) -> Verdict:
    """The kind's verdict: valid, the ranking metrics by name (per-region ratios as coverage:<region>), the first
    violation, the line ``eosp validate`` prints."""
    return verdict_of(check(case, plan, track))


def verdict_of(rep: Report) -> Verdict:
    """:func:`verdict` of a report already made."""
    m = rep.metrics
    mt = {"value": m["coverage_ratio"], "coverage_ratio": m["coverage_ratio"],
          "weighted_coverage_ratio": m["weighted_coverage_ratio"], "num_actions": m["num_actions"],
          "min_battery_wh": m["min_battery_wh"], "violations": len(rep.violations)}
    mt.update({f"coverage:{rid}": v["coverage_ratio"] for rid, v in m["region_coverages"].items()})
    figures = (f"coverage_ratio {m['coverage_ratio']:.6f}, weighted_coverage_ratio {m['weighted_coverage_ratio']:.6f}, "
               f"{m['num_actions']} actions, min battery {m['min_battery_wh']:.3f} Wh")
    first = rep.violations[0] if rep.violations else None
    line = f"valid: {figures}" if rep.valid else f"invalid: {first} ({len(rep.violations)} violations; {figures})"
    return Verdict(rep.valid, mt, first, line)
