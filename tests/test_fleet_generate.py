"""The fleet generator: reproducible fleets whose orbits, places and windows are what the config says, and
opportunities whose reach filter loses nothing against a full scan of every window."""

from __future__ import annotations

import numpy as np
import pytest

from eosp.fleet import opportunities as opp_mod
from eosp.fleet.generate import FleetGenConfig, default_planes, generate
from eosp.fleet.geometry import Geometry, brahe_module
from eosp.fleet.io import fingerprint

SMALL = dict(satellites=6, tasks=150, hours=3.0, window_min_h=0.5, window_max_h=2.0)


def test_same_seed_same_fleet_other_seed_other_fleet():
    a, b = generate(FleetGenConfig(**SMALL)), generate(FleetGenConfig(**SMALL))
    c = generate(FleetGenConfig(**SMALL, seed=1))
    assert fingerprint(a) == fingerprint(b)
    assert fingerprint(a) != fingerprint(c)


def test_walker_orbits_are_valid_tles_at_the_altitude_and_planes_asked():
    cfg = FleetGenConfig(satellites=12, planes=4, phasing=1, altitude_km=600.0, inclination_deg=53.0, tasks=10)
    f = generate(cfg)
    bh = brahe_module()
    raans = set()
    for l1, l2 in zip(f.satellites.tle.line1, f.satellites.tle.line2):
        assert bh.validate_tle_lines(l1, l2)
        assert float(l2[8:16]) == pytest.approx(53.0)
        raans.add(float(l2[17:25]))
    assert sorted(raans) == [0.0, 90.0, 180.0, 270.0]
    geo = Geometry(f)
    r = np.sqrt((geo.grid_positions(0) ** 2).sum(axis=1))
    # circular orbit 600 km above the equatorial radius; SGP4's mean elements and J2 move it by a few km
    assert np.all(np.abs(r - (6378137.0 + 600e3)) < 25e3)
    assert default_planes(12) in (3, 4) and default_planes(7) in (1, 7)


@pytest.mark.parametrize("placement", ["land", "clusters", "cities"])
def test_tasks_are_on_land_with_windows_on_the_grid_inside_the_horizon(placement):
    from global_land_mask import globe

    cfg = FleetGenConfig(**SMALL, placement=placement)
    f = generate(cfg)
    t = f.tasks
    assert len(t) == cfg.tasks
    if placement != "cities":  # city centres may sit on a coastline cell the 1 km mask calls sea
        assert globe.is_land(t.lat_deg, t.lon_deg).all()
    assert np.all(np.abs(t.lat_deg) <= 80.0)
    assert np.all(t.release_s >= 0) and np.all(t.due_s <= f.horizon.seconds)
    assert np.all(t.release_s % 5 == 0) and np.all(t.due_s % 5 == 0) and np.all(t.duration_s % 5 == 0)
    length = t.due_s - t.release_s
    assert np.all(length >= 0.5 * 3600 - 5) and np.all(length <= 2.0 * 3600 + 5)
    assert np.all(t.duration_s <= length)
    assert set(np.unique(t.weight)) <= {1.0, 2.0, 3.0, 4.0, 5.0}
    assert set(t.sensor) <= {"visible", "infrared"} and set(f.satellites.sensor) <= {"visible", "infrared"}


def test_reach_filter_finds_every_opportunity_of_a_full_window_scan(monkeypatch):
    """The reach filter only narrows the instants scanned: the opportunities equal those of scanning
    every instant of every window (what the scan did before the filter)."""
    f = generate(FleetGenConfig(satellites=4, tasks=400, hours=4.0, window_min_h=1.0, window_max_h=3.0,
                                placement="clusters", clusters=4, cluster_km=800.0, seed=3))
    geo = Geometry(f)
    fast = opp_mod.compute(f, geo)
    assert len(fast) > 100  # the case is not vacuous

    def full_windows(fleet, geo, sat, tasks, lo, hi):
        return np.arange(len(tasks)), lo, hi

    monkeypatch.setattr(opp_mod, "reach_segments", full_windows)
    full = opp_mod.compute(f, geo)
    for k in ("task", "satellite", "start", "pass_id"):
        assert np.array_equal(getattr(fast, k), getattr(full, k))


def test_generate_cli_writes_a_fleet_and_refuses_bad_requests(tmp_path, capsys):
    from eosp.cli import main

    out = tmp_path / "fleet"
    assert main(["generate", "--fleet", "--satellites", "4", "--tasks", "60", "--hours", "2", "--out", str(out)]) == 0
    assert "4 satellites, 60 tasks" in capsys.readouterr().out
    assert main(["info", str(out)]) == 0
    capsys.readouterr()
    cases = [
        (["--satellites", "6", "--planes", "4"], "--planes: 4 planes do not divide 6 satellites"),
        (["--satellites", "1000", "--tasks", "1000000", "--hours", "168"], "too large for the memory available"),
        (["--placement", "moon"], "--placement: must be one of land, cities, clusters"),
        (["--window-min-h", "3", "--window-max-h", "1"], "--window-min-h: must not exceed window_max_h"),
        (["--start", "yesterday"], "--start: not an ISO 8601 UTC time"),
    ]
    for extra, message in cases:
        with pytest.raises(SystemExit) as exc:
            rc = main(["generate", "--fleet", "--out", str(tmp_path / "other"), *extra])
            raise SystemExit(rc)
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1
        assert not (tmp_path / "other").exists()
    assert main(["generate", "--fleet", "--out", str(out)]) == 2  # never over an existing directory silently
    assert "already exists" in capsys.readouterr().err


def test_the_opportunities_estimated_from_a_sample_cover_the_scan_and_are_not_scanned_twice(monkeypatch):
    """The memory check scans a few satellites per sensor (fleet.opportunities.sample_scan) and scales them up with
    a margin: on a 24-satellite fleet the estimate lies between the real count and three times it, and compute()
    scans only the satellites the sample did not."""
    from eosp.fleet import opportunities as op
    from eosp.fleet.geometry import Geometry

    cfg = FleetGenConfig(satellites=24, tasks=1500, hours=6.0, infrared_fraction=0.25)
    fleet = generate(cfg)
    geo = Geometry(fleet)
    sample = op.sample_scan(fleet, geo)
    assert 2 <= len(sample) <= op.SAMPLE_SATELLITES + 1
    assert set(fleet.satellites.sensor[list(sample)].tolist()) == set(fleet.satellites.sensor.tolist())
    scanned = []
    real = op.satellite_opportunities
    monkeypatch.setattr(op, "satellite_opportunities", lambda f, g, k: scanned.append(k) or real(f, g, k))
    opps = op.compute(fleet, geo, sample)
    assert sorted(scanned + list(sample)) == list(range(24))
    expected = op.expected_opportunities(fleet, sample)
    assert len(opps) <= expected <= 3 * len(opps), (expected, len(opps))
    from eosp.fleet.generate import config_opportunities  # the estimate before the draw, from the config alone

    assert len(opps) <= config_opportunities(cfg) <= 3 * len(opps), (config_opportunities(cfg), len(opps))
    assert len(op.compute(fleet, geo)) == len(opps)  # the sample's arrays are the scan's own
