"""CZML and KML exports of a fleet schedule: parsed back with czml3 and fastkml, intervals checked against the schedule."""

import json
import warnings
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest

from eosp.cli import main
from eosp.fleet.io import read_fleet, read_schedule
from eosp.fleet.model import US, iso_z, parse_utc

FIXTURES = Path(__file__).parent / "fixtures" / "aeossp"


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet")
    assert main(["import", str(FIXTURES / "duplicate_observation_no_bonus_valid"), "--out", str(d / "fl")]) == 0
    assert main(["solve", str(d / "fl"), "--solver", "greedy", "--out", str(d / "s.parquet")]) == 0
    fleet, _ = read_fleet(d / "fl", with_opportunities=False)
    sched, _ = read_schedule(d / "s.parquet", fleet)
    assert len(sched) >= 1
    return d / "fl", d / "s.parquet", fleet, sched


def test_czml_parses_back_with_czml3(solved, tmp_path, capsys):
    from czml3 import Document

    fleet_dir, s, fleet, sched = solved
    out = tmp_path / "day.czml"
    assert main(["export-schedule", str(fleet_dir), str(s), "--format", "czml", "--out", str(out)]) == 0
    raw = json.loads(out.read_text())
    doc = Document.model_validate(raw)  # czml3's own model of the format
    ids = [p.id for p in doc.packets]
    assert ids[0] == "document" and raw[1] == {"id": "eosp", "properties": {"eosp": "fleet-czml"}}
    h = fleet.horizon
    assert raw[0]["clock"]["interval"] == f"{iso_z(h.start)}/{iso_z(h.end)}"
    sats = [p for p in raw if p["id"].startswith("sat/")]
    assert [p["id"] for p in sats] == [f"sat/{x}" for x in fleet.satellites.ids]
    for p in sats:  # positions over the whole horizon: time, x, y, z samples in the fixed frame, about 7,000 km out
        c = np.asarray(p["position"]["cartesian"]).reshape(-1, 4)
        assert c[0, 0] == 0 and c[-1, 0] == h.seconds and p["position"]["referenceFrame"] == "FIXED"
        assert np.all(np.abs(np.linalg.norm(c[:, 1:], axis=1) - 7.0e6) < 0.6e6)
    tasks = {p["id"]: p for p in raw if p["id"].startswith("task/")}
    assert set(tasks) == {f"task/{t}" for t in fleet.tasks.ids}
    obs = [p for p in raw if p["id"].startswith("obs/")]
    assert len(obs) == len(sched)
    for p, sat, task, a, b in zip(obs, sched.satellite, sched.task, sched.start_us, sched.end_us):
        start, end = (parse_utc(x) for x in p["availability"].split("/"))
        assert start == h.start + timedelta(microseconds=int(a)) and end == h.start + timedelta(microseconds=int(b))
        assert p["properties"]["satellite"] == sat and p["properties"]["task"] == task
        assert p["polyline"]["positions"]["references"] == [f"sat/{sat}#position", f"task/{task}#position"]
        assert "observed" in tasks[f"task/{task}"]["description"]
    # a second write needs --overwrite; a file eosp did not write is never replaced
    capsys.readouterr()
    assert main(["export-schedule", str(fleet_dir), str(s), "--format", "czml", "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(["export-schedule", str(fleet_dir), str(s), "--format", "czml", "--out", str(out), "--overwrite"]) == 0
    mine = tmp_path / "mine.czml"
    mine.write_text("[]")
    assert main(["export-schedule", str(fleet_dir), str(s), "--format", "czml", "--out", str(mine),
                 "--overwrite"]) == 2
    assert mine.read_text() == "[]"


def test_kml_parses_back_with_fastkml(solved, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        from fastkml import KML

    fleet_dir, s, fleet, sched = solved
    out = tmp_path / "day.kml"
    assert main(["export-schedule", str(fleet_dir), str(s), "--format", "kml", "--out", str(out)]) == 0
    text = out.read_text()
    assert text.splitlines()[1] == "<!-- eosp: fleet-kml -->" and "<kml xmlns=" in text
    k = KML.from_string(text.encode())
    doc = list(k.features)[0]
    folders = {f.name: list(f.features) for f in doc.features}
    assert list(folders) == ["ground tracks", "targets", "observations"]
    assert len(folders["ground tracks"]) == len(fleet.satellites)
    for pm in folders["ground tracks"]:
        lines = list(pm.kml_geometry.kml_geometries)
        assert lines and sum(len(ln.kml_coordinates.coords) for ln in lines) > 5
    assert len(folders["targets"]) == len(fleet.tasks)
    assert {pm.name.split(" (")[0] for pm in folders["targets"]} == set(fleet.tasks.ids.tolist())
    h = fleet.horizon
    obs = folders["observations"]
    assert len(obs) == len(sched)
    for pm, sat, task, a, b in zip(obs, sched.satellite, sched.task, sched.start_us, sched.end_us):
        assert pm.name == f"{sat} observes {task}"
        assert pm.times.begin.dt == h.start + timedelta(microseconds=int(a))
        assert pm.times.end.dt == h.start + timedelta(microseconds=int(b))
        i = fleet.task_index()[task]
        (lon, lat), = [c[:2] for c in pm.kml_geometry.kml_coordinates.coords]
        assert (lon, lat) == pytest.approx((fleet.tasks.lon_deg[i], fleet.tasks.lat_deg[i]), abs=1e-6)
    assert (int((b - a) // US) for a, b in zip(sched.start_us, sched.end_us))


def test_export_of_another_fleets_schedule_is_refused(solved, tmp_path, capsys):
    fleet_dir, _, _, _ = solved
    other = tmp_path / "other"
    assert main(["import", str(FIXTURES / "full_completion_valid"), "--out", str(other)]) == 0
    s = tmp_path / "s.parquet"
    assert main(["solve", str(other), "--solver", "greedy", "--out", str(s)]) == 0
    capsys.readouterr()
    for fmt in ("czml", "kml"):
        assert main(["export-schedule", str(fleet_dir), str(s), "--format", fmt, "--out",
                     str(tmp_path / f"x.{fmt}")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "another fleet" in err and not (tmp_path / f"x.{fmt}").exists()
