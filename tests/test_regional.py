"""The regional_coverage kind on tiny cases the tests write in the benchmark's format (one real TLE, a small
region placed under its pass): the checker's rules, the solvers' schedules, the bound against brute force,
the candidate strips against the checker's own geometry, bad inputs."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from eosp.errors import InputError

from eosp.regional.tiny import L1, L2, box, satellite, tiny, under_pass, write_case


@pytest.fixture(scope="module")
def case_dir(tmp_path_factory) -> Path:
    """One satellite, a 0.4 x 2 degree region under its pass at roll 25 deg, 2 actions allowed, 2 h."""
    return tiny(tmp_path_factory.mktemp("regional") / "case")


def solution(path: Path, actions: list[dict]) -> Path:
    path.write_text(json.dumps({"actions": actions}))
    return path


def eosp(*args: str) -> subprocess.CompletedProcess:
    """The command line in its own process (what a user runs)."""
    return subprocess.run([sys.executable, "-m", "eosp.cli", *args], capture_output=True, text=True, timeout=300)


def cli(*args: str):
    """The command line in this process (rc, out, err), for the many small cases."""
    from tests.test_bad_inputs import run_cli

    return run_cli(list(args))


def strips_of(case_dir: Path, roll_step: float = 0.5):
    from eosp.kinds.regional.strips import build
    from eosp.regional.geometry import Track
    from eosp.regional.read import read_case

    case = read_case(str(case_dir))
    track = Track(case)
    return case, track, build(case, track, roll_step)


def test_the_solvers_schedules_are_valid_and_the_search_is_at_least_the_greedy(case_dir, tmp_path):
    from eosp.kinds.regional.solve import CoverageConfig, GreedyConfig, solve, solve_greedy
    from eosp.regional.check import check
    from eosp.regional.read import read_case

    case = read_case(str(case_dir))
    g = solve_greedy(case, GreedyConfig())
    s = solve(case, CoverageConfig(time_limit=None, moves=30, bound_share=0.5))
    for r in (g, s):
        rep = check(case, r.schedule)
        assert rep.valid, rep.violations
        assert rep.metrics["coverage_ratio"] == pytest.approx(r.value, abs=1e-12)
        assert 0 < len(r.schedule.actions) <= 2
    assert s.value >= g.value - 1e-12 > 0
    assert s.bound is not None and s.bound >= s.value


def test_the_candidate_strips_cover_what_the_checker_finds(case_dir):
    """Each candidate's samples, from the vectorised geometry, equal the checker's (brahe's conversion, shapely's
    covers) for the same strip."""
    from eosp.regional.check import Parsed, covered_samples, strip_polygons

    case, track, strips = strips_of(case_dir)
    assert len(strips) > 10
    rng = np.random.default_rng(0)
    for c in rng.choice(len(strips), size=min(12, len(strips)), replace=False).tolist():
        p = Parsed(0, int(strips.track_sat[strips.cand_track[c]]), int(strips.start_s[c]) * 1_000_000,
                   float(strips.cand_n[c] * strips.step_s), float(strips.track_roll[strips.cand_track[c]]), ok=True)
        polys, err = strip_polygons(case, track, p)
        assert err is None
        assert np.array_equal(covered_samples(case, polys), strips.samples_of(c))


def _grid_schedules(case, strips):
    """Every strip of the candidate grid whose first step covers a sample, with every duration the sensor
    allows: (satellite, start s, end s, roll, samples)."""
    per = 2
    out = []
    for c in range(len(strips)):
        s = int(strips.track_sat[strips.cand_track[c]])
        sat = case.satellites[s]
        for n in range(int(sat.min_strip_duration_s // 5), int(sat.max_strip_duration_s // 5) + 1, per):
            k = int(strips.cand_k[c])
            if (k + n) * 5 > case.horizon_s:
                continue
            segs = strips.run_seg[strips.cand_seg0[c]:strips.cand_seg0[c] + n] if n <= strips.cand_n[c] else \
                strips.run_seg[strips.cand_seg0[c]:strips.cand_seg0[c] + strips.cand_n[c]]
            cov = set()
            for g in segs[segs >= 0].tolist():
                cov |= set(strips.cov_idx[strips.cov_ptr[g]:strips.cov_ptr[g + 1]].tolist())
            out.append((s, k * 5.0, (k + n) * 5.0, float(strips.track_roll[strips.cand_track[c]]), cov))
    return out


def test_the_bound_holds_against_brute_force_over_every_grid_schedule(tmp_path):
    """Two satellites on one orbit over one region, 2 actions: the best of every pair of grid strips the verifier's rules
    allow (overlap, slew plus settling between consecutive strips of a satellite) is at most the bound, and the
    search reaches it."""
    from eosp.kinds.regional.bound import lagrangian
    from eosp.kinds.regional.solve import CoverageConfig, solve
    from eosp.regional.check import slew_time_s

    sats = [satellite("sat_a", L1, L2), satellite("sat_b", L1, L2)]  # one orbit: their strips compete
    lon, lat = under_pass(tmp_path / "probe", sats[0])
    d = write_case(tmp_path / "case", sats, [("r1", box(lon, lat, 0.4, 0.6), 0.05)])
    case, track, strips = strips_of(d, roll_step=1.0)
    v = case.sample_value()
    grid = _grid_schedules(case, strips)
    assert len(grid) > 20

    def ok(a, b):
        if a[0] != b[0]:
            return True
        a, b = sorted((a, b), key=lambda x: x[1])
        sat = case.satellites[a[0]]
        return b[1] >= a[2] and b[1] - a[2] + 1e-6 >= slew_time_s(b[3] - a[3], sat) + sat.settling_time_s

    best = max(max(v[list(x[4])].sum() for x in grid),
               max(v[list(a[4] | b[4])].sum() for a, b in itertools.combinations(grid, 2) if ok(a, b)))
    bound, _ = lagrangian(case, strips, 0.0, seconds=20, iterations=300)
    assert bound >= best - 1e-12
    res = solve(case, CoverageConfig(time_limit=None, moves=40, roll_step=1.0, bound_share=0.0))
    assert res.value <= best + 1e-12
    assert res.value >= 0.9 * best


def test_the_checker_names_each_broken_rule(case_dir, tmp_path):
    lon_start = "2025-07-17T00:40:00Z"
    base = {"type": "strip_observation", "satellite_id": "sat_a", "start_time": lon_start, "duration_s": 20,
            "roll_deg": 25.0}
    cases = {
        "unknown satellite_id": [{**base, "satellite_id": "nope"}],
        "align to the 10s time grid": [{**base, "start_time": "2025-07-17T00:40:05Z"}],
        "integer multiple of 10s": [{**base, "duration_s": 25}],
        "below min_edge_off_nadir_deg": [{**base, "roll_deg": 18.5}],
        "above max_edge_off_nadir_deg": [{**base, "roll_deg": -33.5}],
        "above max_strip_duration_s": [{**base, "duration_s": 60}],
        "outside the mission horizon": [{**base, "start_time": "2025-07-17T01:59:50Z"}],
        "overlapping strip observations": [base, {**base, "start_time": "2025-07-17T00:40:10Z"}],
        "insufficient slew/settle time": [base, {**base, "start_time": "2025-07-17T00:40:20Z", "roll_deg": -25.0}],
        "allows at most 2": [base, {**base, "start_time": "2025-07-17T00:50:00Z"},
                             {**base, "start_time": "2025-07-17T01:00:00Z"}],
    }
    for why, acts in cases.items():
        r = cli("validate", str(case_dir), str(solution(tmp_path / "s.json", acts)))
        assert r.rc == 1, (why, r.out, r.err)
        assert why in r.out, (why, r.out)
    r = eosp("validate", str(case_dir), str(solution(tmp_path / "s.json", cases["unknown satellite_id"])))
    assert r.returncode == 1 and "unknown satellite_id 'nope'" in r.stdout
    r = eosp("validate", str(case_dir), str(solution(tmp_path / "s.json", [base])))
    assert r.returncode == 0 and r.stdout.startswith("valid: coverage_ratio"), r.stdout + r.stderr


def test_duty_limit_and_battery_are_checked_and_respected(tmp_path):
    from eosp.kinds.regional.mip import MipConfig, solve_mip
    from eosp.kinds.regional.solve import CoverageConfig, solve
    from eosp.regional.check import check
    from eosp.regional.model import Plan
    from eosp.regional.read import read_case

    lon, lat = under_pass(tmp_path / "probe", satellite("sat_a", L1, L2))
    tight = satellite("sat_a", L1, L2, imaging_duty_limit_s_per_orbit=30, battery_capacity_wh=3.0,
                      initial_battery_wh=2.9, idle_power_w=1.0, imaging_power_w=400.0, sunlit_charge_power_w=1.0)
    d = write_case(tmp_path / "case", [tight], [("r1", box(lon, lat, 0.15, 0.12), 0.03)], budget=4)
    case = read_case(str(d))
    two = Plan([{"type": "strip_observation", "satellite_id": "sat_a", "start_time": t, "duration_s": 20,
                 "roll_deg": 25.0} for t in ("2025-07-17T00:40:00Z", "2025-07-17T00:41:00Z")])
    rep = check(case, two)
    assert any("imaging duty limit exceeded" in v for v in rep.violations)
    assert any("battery depletes below zero" in v for v in rep.violations)
    res = solve(case, CoverageConfig(time_limit=None, moves=10, bound_share=0.0))
    assert check(case, res.schedule).valid
    assert len(res.schedule.actions) <= 1
    mip = solve_mip(case, MipConfig(time_limit=5))  # no duty or battery rows: mended after the solve
    assert check(case, mip.schedule).valid and len(mip.schedule.actions) <= 1


def test_sunlight_from_the_coarse_frames_matches_brahe_at_every_instant(case_dir):
    from eosp.regional.geometry import Track
    from eosp.regional.power import Sun
    from eosp.regional.read import read_case

    case = read_case(str(case_dir))
    sun = Sun(case, Track(case))
    t = np.arange(0, int(case.horizon_s) * 1_000_000, 2_500_000, dtype=np.int64)
    lit = sun.lit(0, t)
    assert lit.any() and not lit.all()  # the horizon holds an eclipse
    assert np.array_equal(lit, sun.exact(0, t))


def test_solve_writes_their_format_and_refuses_to_overwrite(case_dir, tmp_path):
    out = tmp_path / "sol.json"
    r = eosp("solve", str(case_dir), "--solver", "coverage", "--time-limit", "3", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert "coverage_ratio" in r.stdout and "bound" in r.stdout
    body = json.loads(out.read_text())
    assert body["actions"] and all(a["type"] == "strip_observation" for a in body["actions"])
    assert eosp("validate", str(case_dir), str(out)).returncode == 0
    r = eosp("solve", str(case_dir), "--solver", "greedy", "--out", str(out))
    assert r.returncode == 2 and "--overwrite" in r.stderr
    mine = tmp_path / "mine.json"
    mine.write_text("{}")
    r = eosp("solve", str(case_dir), "--solver", "greedy", "--out", str(mine), "--overwrite")
    assert r.returncode == 2 and mine.read_text() == "{}"


def _mutate(src: Path, dst: Path, name: str, edit) -> Path:
    import shutil

    shutil.copytree(src, dst)
    p = dst / name
    if edit is None:
        p.unlink()
    else:
        p.write_text(edit(p.read_text()))
    return dst


def _geo(fn):
    def edit(text):
        g = json.loads(text)
        fn(g)
        return json.dumps(g)
    return edit


@pytest.mark.parametrize("name,edit,words", [
    ("regions.geojson", None, "regions.geojson: missing"),
    ("regions.geojson", _geo(lambda g: g["features"][0]["geometry"].update(type="Point")), "expected 'Polygon'"),
    ("regions.geojson", _geo(lambda g: g["features"][0]["geometry"]["coordinates"][0].pop()), "the ring is open"),
    ("regions.geojson", _geo(lambda g: g["features"][0]["geometry"]["coordinates"][0][1].__setitem__(1, 95.0)),
     "off the globe"),
    ("coverage_grid.json", _geo(lambda g: g["regions"][0].update(region_id="elsewhere")),
     "'elsewhere' is not a region of regions.geojson"),
    ("manifest.json", _geo(lambda g: g.update(horizon_start="2025-07-17T00:00:00")), "has no time zone"),
    ("manifest.json", lambda t: t[:-3], "not valid JSON"),
    ("satellites.yaml", lambda t: t.replace("cross_track_fov_deg: 2.8", "cross_track_fov_deg: 20.0"),
     "no strip fits"),
    ("satellites.yaml", lambda t: t.replace("max_roll_rate_deg_per_s: 1.2", "max_roll_rate_deg_per_s: fast"),
     "expected a finite number"),
])
def test_a_malformed_case_is_refused_in_one_line(case_dir, tmp_path, name, edit, words):
    from eosp.regional.read import read_case

    bad = _mutate(case_dir, tmp_path / "bad", name, edit)
    with pytest.raises(InputError) as err:
        read_case(str(bad))
    assert words in str(err.value) and "\n" not in str(err.value)
    r = cli("info", str(bad))
    assert r.rc == 2 and words in r.err and "Traceback" not in r.err
    assert len(r.err.strip().splitlines()) == 1


def test_the_page_draws_regions_strips_and_samples_in_a_browser(case_dir, tmp_path, chromium):
    from tests.browser import Browser

    sol = tmp_path / "s.json"
    r = cli("solve", str(case_dir), "--solver", "greedy", "--out", str(sol))
    assert r.rc == 0, r.err
    page = tmp_path / "page.html"
    r = cli("report", str(case_dir), str(sol), "--out", str(page))
    assert r.rc == 0 and "1 solution(s)" in r.out, r.err
    text = page.read_text()
    assert text.count("<svg") == 1 and "r1:" in text and "<polygon" in text and "#bbb" in text
    with Browser(chromium, str(tmp_path / "chromium.log")) as b:
        b.open(str(page))
        assert b.evaluate("document.querySelectorAll('svg polygon').length") > 2
        assert b.evaluate("document.querySelectorAll('svg circle').length") == text.count("<circle")
        assert b.errors() == []
