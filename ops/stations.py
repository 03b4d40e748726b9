"""Ground stations and their contacts with a fleet's satellites: when a plan can be uploaded and an outcome
downlinked.

A plan reaches a satellite only while a ground station sees it (elevation at least the station's minimum); between
contacts the satellite runs what was uploaded.  Contacts are computed from the fleet's own SGP4 geometry
(:class:`eosp.fleet.geometry.Geometry`, the positions the checker uses) on its base grid: a contact is a run of
grid instants at or above the minimum elevation, from its first instant to its last (so a contact is known to
within one grid step, 5-60 s on the aeossp cases; a pass over a station lasts minutes).

The default stations (:data:`DEFAULT_STATIONS`) are public ground stations of the kind polar-orbiting
Earth-observation missions use: polar ones that see a sun-synchronous satellite on most orbits (Svalbard,
Kiruna, Inuvik, Fairbanks, Troll) and mid-latitude ones that see it a few times a day (Toulouse, Matera, Kourou,
Hartebeesthoek); coordinates rounded to 0.01 deg (the sites' published locations), minimum elevation 5 deg.
A user list is a CSV file with the columns ``name,lat_deg,lon_deg[,alt_m][,min_elevation_deg]``
(:func:`read_stations`).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eosp.errors import InputError

DEFAULT_MIN_ELEVATION_DEG = 5.0

# name, latitude, longitude (deg): the sites' published locations, rounded
DEFAULT_STATIONS = (
    ("Svalbard", 78.23, 15.39),
    ("Kiruna", 67.86, 20.96),
    ("Inuvik", 68.32, -133.55),
    ("Fairbanks", 64.86, -147.85),
    ("Troll", -72.01, 2.54),
    ("Toulouse", 43.56, 1.48),
    ("Matera", 40.65, 16.70),
    ("Kourou", 5.25, -52.80),
    ("Hartebeesthoek", -25.89, 27.69),
)


@dataclass(frozen=True, eq=False)
class Stations:
    """Ground stations, one row each."""

    name: np.ndarray  # str
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    min_elevation_deg: np.ndarray

    def __len__(self) -> int:
        return len(self.name)

    @classmethod
    def default(cls) -> Stations:
        n = len(DEFAULT_STATIONS)
        return cls(np.array([s[0] for s in DEFAULT_STATIONS], dtype=object),
                   np.array([s[1] for s in DEFAULT_STATIONS], dtype=np.float64),
                   np.array([s[2] for s in DEFAULT_STATIONS], dtype=np.float64), np.zeros(n),
                   np.full(n, DEFAULT_MIN_ELEVATION_DEG))


@dataclass(frozen=True, eq=False)
class Contacts:
    """Contact windows, one row each, sorted by (satellite, start): satellite and station rows, first and last
    instant in view (seconds from the horizon start)."""

    satellite: np.ndarray  # int64
    station: np.ndarray  # int64
    start_s: np.ndarray  # float64
    end_s: np.ndarray  # float64

    def __len__(self) -> int:
        return len(self.satellite)

    def of(self, sat: int) -> tuple[np.ndarray, np.ndarray]:
        """The (start, end) seconds of satellite `sat`'s contacts, in time order."""
        mine = self.satellite == sat
        return self.start_s[mine], self.end_s[mine]

    def next_contact(self, sat: int, t: float) -> float | None:
        """The first instant at or after `t` at which satellite `sat` is in contact (`t` itself when it is in
        one); None when no contact is left in the horizon."""
        got = float(self.next_contacts(np.array([sat]), np.array([t]))[0])
        return None if math.isinf(got) else got

    def next_contacts(self, sat: np.ndarray, t: np.ndarray) -> np.ndarray:
        """:meth:`next_contact` of many (satellite, time) pairs at once (inf: no contact left): uploads and
        downlinks in the simulator (:mod:`eosp.ops.simulate`)."""
        sat, t = np.asarray(sat, dtype=np.int64), np.asarray(t, dtype=np.float64)
        out = np.full(len(sat), math.inf)
        for k in np.unique(sat).tolist():
            mine = sat == k
            st, en = self.of(k)
            i = np.searchsorted(en, t[mine], side="left")  # the first contact not over at t (ends ascend with starts)
            ok = i < len(en)
            got = np.full(int(mine.sum()), math.inf)
            got[ok] = np.maximum(st[i[ok]], t[mine][ok])
            out[mine] = got
        return out


def _number(path: Path, row: int, column: str, text: str, lo: float, hi: float) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InputError(path, f"not a number: {text!r}", column, row) from None
    if not (math.isfinite(v) and lo <= v <= hi):
        raise InputError(path, f"{v:g} outside [{lo:g}, {hi:g}]", column, row)
    return v


def read_stations(path: str | Path) -> Stations:
    """Stations from a CSV file with a header: ``name,lat_deg,lon_deg`` and optionally ``alt_m`` (default 0) and
    ``min_elevation_deg`` (default :data:`DEFAULT_MIN_ELEVATION_DEG`); an InputError naming the file, the row and
    the column at fault otherwise (an empty list, a repeated name, a value out of range, an unknown column)."""
    path = Path(path)
    try:
        with path.open(newline="") as fh:
            rows = list(csv.DictReader(fh))
            header = rows and list(rows[0]) or []
    except OSError as e:
        raise InputError(path, f"cannot read: {e.strerror or e}") from None
    except (UnicodeDecodeError, csv.Error) as e:
        raise InputError(path, f"not a CSV text file: {e}") from None
    known = {"name", "lat_deg", "lon_deg", "alt_m", "min_elevation_deg"}
    for col in header:
        if col not in known:
            raise InputError(path, f"unknown column (known: {', '.join(sorted(known))})", col)
    for col in ("name", "lat_deg", "lon_deg"):
        if rows and col not in header:
            raise InputError(path, "missing", col)
    if not rows:
        raise InputError(path, "no station (a header line and one station a line)")
    names, lat, lon, alt, el = [], [], [], [], []
    for i, r in enumerate(rows):
        if None in r or any(v is None for v in r.values()):
            raise InputError(path, "wrong number of fields", row=i)
        name = r["name"].strip()
        if not name:
            raise InputError(path, "empty", "name", i)
        if name in names:
            raise InputError(path, f"station {name!r} listed twice", "name", i)
        names.append(name)
        lat.append(_number(path, i, "lat_deg", r["lat_deg"], -90.0, 90.0))
        lon.append(_number(path, i, "lon_deg", r["lon_deg"], -180.0, 180.0))
        alt.append(_number(path, i, "alt_m", r.get("alt_m") or "0", -500.0, 9000.0))
        el.append(_number(path, i, "min_elevation_deg", r.get("min_elevation_deg") or str(DEFAULT_MIN_ELEVATION_DEG),
                          0.0, 90.0))
    return Stations(np.array(names, dtype=object), *(np.asarray(v, dtype=np.float64) for v in (lat, lon, alt, el)))


def elevation_deg(sat_ecef: np.ndarray, lat_deg: float, lon_deg: float, alt_m: float = 0.0) -> np.ndarray:
    """Elevation (deg) of satellite positions `sat_ecef` (n, 3; ITRF, m) above a station's local horizontal plane
    (the WGS84 ellipsoid's normal at the station)."""
    from eosp.fleet.geometry import target_ecef

    st = target_ecef(np.array([lat_deg]), np.array([lon_deg]), np.array([alt_m]))[0]
    la, lo = math.radians(lat_deg), math.radians(lon_deg)
    up = np.array([math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)])
    d = sat_ecef - st
    r = np.sqrt(np.einsum("ij,ij->i", d, d))
    return np.degrees(np.arcsin(np.clip(d @ up / np.maximum(r, 1e-9), -1.0, 1.0)))


def contacts(geo, stations: Stations) -> Contacts:
    """Every contact of every satellite of `geo`'s fleet (:class:`eosp.fleet.geometry.Geometry`) with `stations`,
    on the geometry's base grid (see the module docstring)."""
    step = float(geo.base_step_s)
    rows = []
    for k in range(len(geo.fleet.satellites)):
        pos = geo.grid_positions(k)
        for j in range(len(stations)):
            up = elevation_deg(pos, float(stations.lat_deg[j]), float(stations.lon_deg[j]),
                               float(stations.alt_m[j])) >= stations.min_elevation_deg[j]
            edges = np.diff(np.r_[0, up.astype(np.int8), 0])
            for a, b in zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()):
                rows.append((k, j, a * step, (b - 1) * step))
    rows.sort(key=lambda r: (r[0], r[2], r[1]))
    cols = list(zip(*rows)) if rows else [(), (), (), ()]
    return Contacts(np.asarray(cols[0], dtype=np.int64), np.asarray(cols[1], dtype=np.int64),
                    np.asarray(cols[2], dtype=np.float64), np.asarray(cols[3], dtype=np.float64))
