"""An operations scenario: a fleet's day in operation, seeded and reproducible, written as a directory
(docs/formats.md, "Operations scenario"; made by ``eosp scenario FLEET --out SCEN/``).

It holds what a planner and the simulator need and nothing drawn per realization: the day's fleet (the catalogue
and the urgent requests as one fleet directory, their opportunities computed by the fleet's own geometry), when
each request arrives, the ground stations and every contact, the cloud model's parameters and the seed.  The
clouds themselves are drawn per realization from the seed (:mod:`eosp.ops.clouds`), so that every planner meets
the same ones (common random numbers).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eosp.config import choice, ranged
from eosp.errors import InputError
from eosp.ops.clouds import CloudModel, default_climatology
from eosp.ops.requests import RequestConfig, urgent_requests, with_urgent
from eosp.ops.stations import Contacts, Stations, contacts, read_stations

KIND = "eosp-operations-scenario"
SCHEMA_VERSION = 1
FILES = ("meta.json", "day", "requests.parquet", "stations.csv", "contacts.parquet")


@dataclass
class ScenarioConfig:
    """An operations scenario (``eosp scenario FLEET --out SCEN/``)."""

    hours: float = ranged(0.0, 0.0, 168.0)
    """Hours of operation from the fleet's horizon start (0: the fleet's whole horizon)."""
    urgent_per_hour: float = ranged(2.0, 0.0, 1000.0)
    """Urgent requests arriving per hour (a Poisson process)."""
    urgent_placement: str = choice("cities", "cities", "land")
    """Where urgent requests are: cities (by population) or anywhere on land."""
    stations: str = ""
    """A CSV of ground stations (name,lat_deg,lon_deg[,alt_m][,min_elevation_deg]); empty: the public default list."""
    cadence_h: float = ranged(3.0, 0.0, 168.0, lo_open=True)
    """Hours between planning calls."""
    cloud_length_km: float = ranged(300.0, 1.0, 20000.0)
    """Correlation length of the cloud field."""
    cloud_tau_h: float = ranged(6.0, 0.01, 1000.0)
    """Correlation time of the cloud field (hours)."""
    cloud_threshold: float = ranged(0.2, 0.0, 1.0, lo_open=True)
    """An acquisition succeeds when the cloud fraction at its target and start is below this."""
    forecast_sigma_day: float = ranged(1.0, 0.0)
    """Forecast error a day ahead (latent units; 0: perfect forecasts)."""
    seed: int = ranged(0, 0)
    """Seed of the requests and of every realization's clouds."""

    def clouds(self) -> CloudModel:
        return CloudModel(self.cloud_length_km, self.cloud_tau_h, self.cloud_threshold, self.forecast_sigma_day)


@dataclass(frozen=True, eq=False)
class Scenario:
    """A scenario read back: the day's fleet and opportunities, each task's arrival (0 for the catalogue),
    whether it is urgent, the stations, the contacts, the config it was made with."""

    fleet: object
    opps: object
    arrival_s: np.ndarray
    urgent: np.ndarray
    stations: Stations
    contacts: Contacts
    config: ScenarioConfig
    path: Path


def cut(fleet, hours: float):
    """The fleet over its first `hours` (0: as it is): the horizon ends then, tasks keep what of their window
    falls before it (those left with less than their duration are dropped)."""
    from datetime import timedelta

    from eosp.fleet.model import Tasks

    h = fleet.horizon
    if hours <= 0 or hours * 3600.0 >= h.seconds:
        return fleet
    end_s = math.floor(hours * 3600.0 / h.action_step_s) * h.action_step_s
    t = fleet.tasks
    due = np.minimum(t.due_s, end_s)
    keep = due - t.release_s >= t.duration_s
    cols = {f.name: np.asarray(getattr(t, f.name))[keep] for f in dataclasses.fields(Tasks)}
    cols["due_s"] = due[keep]
    horizon = dataclasses.replace(h, end=h.start + timedelta(seconds=end_s))
    return dataclasses.replace(fleet, horizon=horizon, tasks=Tasks(**cols))


def is_scenario_dir(path: str | Path) -> bool:
    try:
        meta = json.loads((Path(path) / "meta.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(meta, dict) and meta.get("kind") == KIND


def make(fleet_dir: str, cfg: ScenarioConfig, out: str, overwrite: bool = False) -> str:
    """Read the fleet at `fleet_dir`, draw the day's urgent requests, compute the day's opportunities and every
    contact, and write the scenario directory `out` (atomically: nothing is left half-written).  Returns a line
    saying what was written."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from eosp.atomic import atomic_dir, check_output_dir
    from eosp.fleet.geometry import Geometry
    from eosp.fleet.io import read_fleet, write_fleet
    from eosp.fleet.opportunities import compute

    check_output_dir(out, overwrite=overwrite, owned=is_scenario_dir, what="scenario directory",
                     names=lambda p: set(FILES))
    stations = read_stations(cfg.stations) if cfg.stations else Stations.default()
    fleet, _ = read_fleet(fleet_dir, with_opportunities=False)
    fleet = cut(fleet, cfg.hours)
    rng = np.random.default_rng([cfg.seed, 0])
    urgent, arrival = urgent_requests(fleet, RequestConfig(cfg.urgent_per_hour, cfg.urgent_placement), rng)
    day = with_urgent(fleet, urgent)
    geo = Geometry(day)
    opps = compute(day, geo)
    c = contacts(geo, stations)
    silent = sorted(set(range(len(day.satellites))) - set(c.satellite.tolist()))
    if silent:
        raise InputError(cfg.stations or "the default stations",
                         f"satellite {day.satellites.ids[silent[0]]} has no contact in the horizon "
                         f"({len(silent)} satellites without one)")
    n_cat = len(fleet.tasks)
    with atomic_dir(out, overwrite=overwrite, owned=is_scenario_dir, names=lambda p: set(FILES)) as tmp:
        write_fleet(day, opps, tmp / "day")
        pq.write_table(pa.table({"task": pa.array(list(day.tasks.ids), pa.string()),
                                 "arrival_s": pa.array(np.r_[np.zeros(n_cat), arrival], pa.float64()),
                                 "urgent": pa.array(np.arange(len(day.tasks)) >= n_cat)}), tmp / "requests.parquet")
        with (tmp / "stations.csv").open("w", newline="") as fh:
            out_csv = csv.writer(fh)
            out_csv.writerow(["name", "lat_deg", "lon_deg", "alt_m", "min_elevation_deg"])
            for row in zip(stations.name, stations.lat_deg, stations.lon_deg, stations.alt_m,
                           stations.min_elevation_deg):
                out_csv.writerow([row[0], *(repr(float(v)) for v in row[1:])])
        pq.write_table(pa.table({"satellite": pa.array([day.satellites.ids[k] for k in c.satellite], pa.string()),
                                 "station": pa.array([stations.name[j] for j in c.station], pa.string()),
                                 "start_s": pa.array(c.start_s, pa.float64()),
                                 "end_s": pa.array(c.end_s, pa.float64())}), tmp / "contacts.parquet")
        meta = {"kind": KIND, "schema_version": SCHEMA_VERSION, "config": dataclasses.asdict(cfg),
                "catalogue_tasks": n_cat, "urgent_tasks": len(urgent), "contacts": len(c),
                "climatology": default_climatology().source}
        (tmp / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")
    return (f"{out}: {n_cat} catalogue tasks, {len(urgent)} urgent requests, {len(opps)} opportunities, "
            f"{len(stations)} stations, {len(c)} contacts over {day.horizon.seconds / 3600:g} h")


def read(path: str | Path) -> Scenario:
    """A scenario directory read back and checked (an InputError naming the file and what is wrong)."""
    import pyarrow.parquet as pq

    from eosp.config import apply_overrides
    from eosp.fleet.io import read_fleet

    root = Path(path)
    if not is_scenario_dir(root):
        raise InputError(root, f"not an operations scenario (no meta.json of kind {KIND}; eosp scenario writes one)")
    meta = json.loads((root / "meta.json").read_text())
    if meta.get("schema_version") != SCHEMA_VERSION:
        raise InputError(root / "meta.json", f"schema_version {meta.get('schema_version')!r}, this eosp reads "
                                             f"{SCHEMA_VERSION}")
    try:
        cfg = apply_overrides(ScenarioConfig(), dict(meta.get("config") or {}))
    except (ValueError, TypeError) as e:
        raise InputError(root / "meta.json", f"config: {e}") from None
    fleet, opps = read_fleet(root / "day")
    req = pq.read_table(root / "requests.parquet").to_pydict()
    if req["task"] != list(fleet.tasks.ids):
        raise InputError(root / "requests.parquet", "its tasks are not the day's tasks, in order")
    stations = read_stations(root / "stations.csv")
    ct = pq.read_table(root / "contacts.parquet").to_pydict()
    si = {s: k for k, s in enumerate(fleet.satellites.ids)}
    ni = {n: j for j, n in enumerate(stations.name)}
    for col, index in (("satellite", si), ("station", ni)):
        bad = [i for i, v in enumerate(ct[col]) if v not in index]
        if bad:
            raise InputError(root / "contacts.parquet", f"unknown {col} {ct[col][bad[0]]!r}", col, bad[0])
    c = Contacts(np.array([si[s] for s in ct["satellite"]], dtype=np.int64),
                 np.array([ni[s] for s in ct["station"]], dtype=np.int64),
                 np.asarray(ct["start_s"], dtype=np.float64), np.asarray(ct["end_s"], dtype=np.float64))
    return Scenario(fleet, opps, np.asarray(req["arrival_s"], dtype=np.float64), np.asarray(req["urgent"], bool),
                    stations, c, cfg, root)
