"""``eosp scenario`` (eosp.ops.scenario): a fleet's day in operation written as a directory and read back, the
same for the same seed; bad station files and silent satellites refused in one line with nothing written."""

from __future__ import annotations

import json

import numpy as np
import pytest

from eosp.cli import main
from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.geometry import Geometry
from eosp.fleet.io import write_fleet
from eosp.fleet.opportunities import compute
from eosp.ops import scenario
from eosp.ops.stations import Stations, contacts


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory):
    f = generate(FleetGenConfig(satellites=8, tasks=25, hours=8.0, placement="cities", seed=6))
    out = tmp_path_factory.mktemp("ops") / "fleet"
    write_fleet(f, compute(f, Geometry(f)), out)
    return out


def test_a_scenario_is_written_read_back_and_reproducible(fleet_dir, tmp_path, capsys):
    out = tmp_path / "scen"
    argv = ["scenario", str(fleet_dir), "--out", str(out), "--urgent-per-hour", "6", "--hours", "6", "--seed", "4"]
    assert main(argv) == 0
    line = capsys.readouterr().out
    assert "urgent requests" in line and "contacts over 6 h" in line
    scen = scenario.read(out)
    assert scen.fleet.horizon.seconds == 6 * 3600
    n_cat = json.loads((out / "meta.json").read_text())["catalogue_tasks"]
    assert (~scen.urgent[:n_cat]).all() and scen.urgent[n_cat:].all() and scen.urgent.sum() > 0
    assert np.all(scen.arrival_s[:n_cat] == 0) and np.all(np.diff(scen.arrival_s[n_cat:]) >= 0)
    t = scen.fleet.tasks
    assert np.all(t.release_s[n_cat:] >= scen.arrival_s[n_cat:]) and np.all(t.due_s <= 6 * 3600)
    assert scen.config.urgent_per_hour == 6.0 and scen.config.seed == 4
    want = contacts(Geometry(scen.fleet), Stations.default())  # the contacts of the day's own geometry
    assert np.array_equal(want.start_s, scen.contacts.start_s) and np.array_equal(want.station, scen.contacts.station)
    assert set(scen.opps.task.tolist()) & set(range(n_cat, len(t)))  # urgent requests have opportunities
    again = tmp_path / "again"
    assert main([*argv[:3], str(again), *argv[4:]]) == 0
    for name in ("requests.parquet", "contacts.parquet", "stations.csv", "day/tasks.parquet"):
        assert (out / name).read_bytes() == (again / name).read_bytes(), name
    assert main(argv) == 2  # exists: --overwrite replaces a scenario eosp wrote
    assert "already exists" in capsys.readouterr().err
    assert main([*argv, "--overwrite"]) == 0


def test_bad_station_lists_are_refused_and_nothing_is_written(fleet_dir, tmp_path, capsys):
    bad = tmp_path / "stations.csv"
    bad.write_text("name,lat_deg,lon_deg\nNorth,95,0\n")
    out = tmp_path / "scen"
    assert main(["scenario", str(fleet_dir), "--out", str(out), "--stations", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "stations.csv: column 'lat_deg', row 0" in err and not out.exists()
    blind = tmp_path / "blind.csv"
    blind.write_text("name,lat_deg,lon_deg,min_elevation_deg\nPit,0,0,89.9\n")  # sees nothing overhead enough
    assert main(["scenario", str(fleet_dir), "--out", str(out), "--stations", str(blind)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "has no contact in the horizon" in err and not out.exists()
    with pytest.raises(SystemExit) as e:  # an option's value: refused by the parser, before anything is read
        main(["scenario", str(fleet_dir), "--out", str(out), "--cloud-threshold", "2"])
    assert e.value.code == 2 and "--cloud-threshold: must be in (0, 1]" in capsys.readouterr().err
    assert not out.exists()
    with pytest.raises(Exception, match="not an operations scenario"):
        scenario.read(fleet_dir)
