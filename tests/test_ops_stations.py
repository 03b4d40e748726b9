"""Ground stations and contacts (eosp.ops.stations): contacts from the fleet's own geometry, every grid instant of
a contact above the station's minimum elevation and the instants around it below; polar stations see a polar
orbit more often; bad station files refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

from eosp.errors import InputError
from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.geometry import Geometry
from eosp.ops.stations import Stations, contacts, elevation_deg, read_stations


@pytest.fixture(scope="module")
def geo():
    fleet = generate(FleetGenConfig(satellites=2, tasks=10, hours=12.0, placement="cities", seed=3))
    return Geometry(fleet)


def test_contacts_are_the_runs_above_the_minimum_elevation(geo):
    st = Stations.default()
    c = contacts(geo, st)
    assert len(c) > 0
    assert np.all(np.diff(c.satellite) >= 0)
    step = geo.base_step_s
    last = (geo.n_base - 1) * step
    for k in range(len(geo.fleet.satellites)):
        pos = geo.grid_positions(k)
        starts, ends = c.of(k)
        assert np.all(np.diff(starts) >= 0)
        for j in range(len(st)):
            el = elevation_deg(pos, st.lat_deg[j], st.lon_deg[j], st.alt_m[j])
            up = el >= st.min_elevation_deg[j]
            mine = (c.satellite == k) & (c.station == j)
            want = np.zeros(len(up), dtype=bool)
            for a, b in zip(c.start_s[mine], c.end_s[mine]):
                i0, i1 = int(round(a / step)), int(round(b / step))
                want[i0:i1 + 1] = True
                assert i0 == 0 or not up[i0 - 1]  # a contact starts where the station first sees the satellite
                assert b == last or not up[i1 + 1]
            assert np.array_equal(up, want), (k, j)


def test_polar_stations_see_a_polar_orbit_more_often(geo):
    st = Stations.default()
    c = contacts(geo, st)
    names = list(st.name)
    per = {n: int((c.station == names.index(n)).sum()) for n in ("Svalbard", "Kourou")}
    assert per["Svalbard"] > per["Kourou"] >= 0
    assert per["Svalbard"] >= 4  # two satellites, 12 hours: most of their orbits


def test_next_contact(geo):
    c = contacts(geo, Stations.default())
    starts, ends = c.of(0)
    assert c.next_contact(0, 0.0) == max(0.0, starts[0])
    mid = 0.5 * (starts[0] + ends[0])
    assert c.next_contact(0, mid) == mid  # in contact: now
    if len(starts) > 1:
        assert c.next_contact(0, ends[0] + 1.0) == pytest.approx(max(starts[1], ends[0] + 1.0))
    assert c.next_contact(0, ends[-1] + 1.0) is None


@pytest.mark.parametrize("text, where", [
    ("name,lat_deg\nA,1\n", "column 'lon_deg'"),
    ("name,lat_deg,lon_deg,height\nA,1,2,3\n", "column 'height'"),
    ("name,lat_deg,lon_deg\nA,91,2\n", "column 'lat_deg', row 0: 91 outside"),
    ("name,lat_deg,lon_deg\nA,1,x\n", "column 'lon_deg', row 0: not a number"),
    ("name,lat_deg,lon_deg\nA,1,2\nA,3,4\n", "column 'name', row 1: station 'A' listed twice"),
    ("name,lat_deg,lon_deg,min_elevation_deg\nA,1,2,95\n", "column 'min_elevation_deg', row 0"),
    ("name,lat_deg,lon_deg\n", "no station"),
    ("name,lat_deg,lon_deg\nA,1\n", "row 0: wrong number of fields"),
])
def test_bad_station_files_are_refused_in_one_line(tmp_path, text, where):
    f = tmp_path / "stations.csv"
    f.write_text(text)
    with pytest.raises(InputError) as e:
        read_stations(f)
    assert str(e.value).startswith(str(f)) and where in str(e.value) and "\n" not in str(e.value)


def test_a_station_file_is_read(tmp_path):
    path = tmp_path / "s.csv"
    path.write_text("name,lat_deg,lon_deg,min_elevation_deg\nHere,10.5,-20,7\nThere,-5,170,\n")
    st = read_stations(path)
    assert list(st.name) == ["Here", "There"] and st.min_elevation_deg.tolist() == [7.0, 5.0]
    assert st.lat_deg.tolist() == [10.5, -5.0] and st.alt_m.tolist() == [0.0, 0.0]


def test_elevation_is_measured_from_the_local_horizontal():
    """Straight overhead: 90 deg; along the station's horizontal plane: 0; below it: negative (WGS84 normal)."""
    from eosp.fleet.geometry import target_ecef

    for lat, lon in ((0.0, 0.0), (60.0, 30.0), (-45.0, -120.0)):
        st = target_ecef(np.array([lat]), np.array([lon]), np.zeros(1))[0]
        la, lo = np.radians(lat), np.radians(lon)
        up = np.array([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)])
        east = np.array([-np.sin(lo), np.cos(lo), 0.0])
        sats = np.array([st + 7e5 * up, st + 7e5 * east, st + 7e5 * (east - 0.1 * up), st + 7e5 * (east + up)])
        el = elevation_deg(sats, lat, lon)
        assert el == pytest.approx([90.0, 0.0, -np.degrees(np.arctan(0.1)), 45.0], abs=1e-6)
