"""Open agile-satellite instance generator.

One satellite, one orbit (the planning horizon is one orbital period), a set of
ground targets, and for each the visibility window that follows from the
geometry: the target must be within the roll and pitch limits and in daylight.
The discrete graph is then built from the attitudes at every candidate start
time (see :mod:`graphs.build`).

Determinism: everything is drawn from one ``numpy.random.Generator`` seeded by
``InstanceConfig.seed``, with the draws in a fixed order, so the same
configuration gives the same arrays (and the same bytes on disk).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eosp.config import CLASS_UTILITIES, InstanceConfig, to_dict
from eosp.graphs.build import build_arcs
from eosp.graphs.discrete import DiscreteGraph, acq_ptr_from_node_acq
from eosp.sim.geometry import R_EARTH, Orbit, pointing, rotation_angle_deg, sun_direction, target_ecef
from eosp.instances.instance import Acquisitions, Instance
from eosp.sim.slew import pack_slew_model, slew_times

GENERATOR_NAME = "eosp-open-sim"
GENERATOR_VERSION = 1
_FINE_STEP = 1.0  # s, grid on which windows are located before their edges are interpolated
_HALF_SPAN = 150.0  # s searched on each side of the closest approach


@dataclass
class Scenario:
    """The physical set-up of an instance: orbit, Sun, satellite agility."""

    orbit: Orbit
    sun: np.ndarray
    horizon: float
    day_of_year: int
    roll_max: float
    pitch_max: float
    min_sun_elevation: float
    slew_model: np.ndarray

    def max_slew(self) -> float:
        """Upper bound of every slew between two attitudes within the pointing limits."""
        ang = rotation_angle_deg(np.array([2 * self.roll_max]), np.array([2 * self.pitch_max]))
        return float(slew_times(ang + 1e-6, self.slew_model)[0]) + 1e-6

    def attitude(self, lat: np.ndarray, lon: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = pointing(self.orbit, self.sun, lat, lon, t)
        return p.roll, p.pitch


def make_scenario(cfg: InstanceConfig, rng: np.random.Generator) -> Scenario:
    doy = cfg.orbit.day_of_year or int(rng.integers(1, 366))
    gmst0 = float(rng.uniform(0.0, 2.0 * np.pi))
    sun = sun_direction(doy)
    if cfg.orbit.tle:
        lines = [ln.rstrip() for ln in Path(cfg.orbit.tle).read_text().splitlines() if ln.strip()]
        l1 = next((ln for ln in lines if ln.startswith("1 ")), None)
        l2 = next((ln for ln in lines if ln.startswith("2 ")), None)
        if l1 is None or l2 is None:
            raise ValueError(f"{cfg.orbit.tle}: no TLE lines starting with '1 ' and '2 '")
        orbit = Orbit.from_tle(l1, l2, start_offset_s=float(rng.uniform(0, 86400.0)))
    else:
        orbit = Orbit.circular_sso(cfg.orbit.altitude_km, cfg.orbit.ltan_hours, sun, gmst0)
    orbit = orbit.shifted(_daylight_entry(orbit, sun))
    return Scenario(orbit, sun, orbit.period_s, doy, cfg.satellite.roll_max_deg, cfg.satellite.pitch_max_deg,
                    cfg.orbit.min_sun_elevation_deg, pack_slew_model(cfg.satellite))


def _daylight_entry(orbit: Orbit, sun: np.ndarray) -> float:
    """Time (s) shortly before the sub-satellite point enters daylight, so that the
    horizon (one orbit from there) holds the whole day side in one piece."""
    t = np.arange(0.0, orbit.period_s, 10.0)
    r, _ = orbit.state(t)
    el = (r / np.linalg.norm(r, axis=1, keepdims=True)) @ sun
    up = np.flatnonzero((el[:-1] < 0) & (el[1:] >= 0))
    return float(t[up[0]] - 120.0) if up.size else 0.0


# --------------------------------------------------------------------------- targets

def _reach_angle(scn: Scenario) -> float:
    """Largest Earth central angle (rad) between the sub-satellite point and a reachable target."""
    r, _ = scn.orbit.state(np.array([0.0]))
    a = float(np.linalg.norm(r[0]))
    b = np.array([np.sin(np.deg2rad(scn.pitch_max)), np.sin(np.deg2rad(scn.roll_max)), 0.0])
    b[2] = np.cos(np.deg2rad(scn.roll_max)) * np.cos(np.deg2rad(scn.pitch_max))
    eta = np.arccos(b[2] / np.linalg.norm(b))
    return float(np.arcsin(min(1.0, a / R_EARTH * np.sin(eta))) - eta)


def _ground_track(scn: Scenario, step: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """Earth-fixed unit vectors of the sub-satellite point, and their times."""
    t = np.arange(0.0, scn.horizon, step)
    r, _ = scn.orbit.state(t)
    g = scn.orbit.gmst(t)
    c, s = np.cos(-g), np.sin(-g)
    x = c * r[:, 0] - s * r[:, 1]
    y = s * r[:, 0] + c * r[:, 1]
    u = np.stack([x, y, r[:, 2]], axis=-1)
    return u / np.linalg.norm(u, axis=-1, keepdims=True), t


def _windows(scn: Scenario, lat: np.ndarray, lon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Visibility window [start, end] of each target (NaN when never visible in daylight)."""
    n = lat.shape[0]
    start = np.full(n, np.nan)
    end = np.full(n, np.nan)
    if n == 0:
        return start, end
    track, tt = _ground_track(scn, 10.0)
    p = target_ecef(lat, lon) / R_EARTH
    closest = tt[np.argmax(p @ track.T, axis=1)]
    offs = np.arange(-_HALF_SPAN, _HALF_SPAN + 1e-9, _FINE_STEP)
    for lo in range(0, n, 256):
        hi = min(n, lo + 256)
        t = np.clip(closest[lo:hi, None] + offs[None, :], 0.0, scn.horizon)
        pt = pointing(scn.orbit, scn.sun, lat[lo:hi, None], lon[lo:hi, None], t)
        margin = np.minimum.reduce([
            scn.roll_max - np.abs(pt.roll), scn.pitch_max - np.abs(pt.pitch),
            pt.sun_elevation - scn.min_sun_elevation, np.where(pt.boresight_z > 0, 90.0, -90.0)])
        ok = margin >= 0
        for r in range(hi - lo):
            idx = np.flatnonzero(ok[r])
            if idx.size == 0:
                continue
            # the contiguous run containing the best margin
            best = idx[np.argmax(margin[r, idx])]
            a = best
            while a > 0 and ok[r, a - 1]:
                a -= 1
            b = best
            while b + 1 < ok.shape[1] and ok[r, b + 1]:
                b += 1
            ts, te = t[r, a], t[r, b]
            if a > 0:  # interpolate the crossing of the margin through zero
                m0, m1 = margin[r, a - 1], margin[r, a]
                ts = t[r, a - 1] + (t[r, a] - t[r, a - 1]) * (-m0) / (m1 - m0)
            if b + 1 < ok.shape[1]:
                m0, m1 = margin[r, b], margin[r, b + 1]
                te = t[r, b] + (t[r, b + 1] - t[r, b]) * m0 / (m0 - m1)
            # a hair inside the interpolated crossings, so every attitude is within the limits
            start[lo + r], end[lo + r] = ts + 0.02, te - 0.02
    return start, end


def _uniform_points(rng: np.random.Generator, m: int) -> tuple[np.ndarray, np.ndarray]:
    lat = np.rad2deg(np.arcsin(rng.uniform(-1.0, 1.0, m)))
    lon = rng.uniform(-180.0, 180.0, m)
    return lat, lon


def _reachable(scn: Scenario, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    track, _ = _ground_track(scn, 20.0)
    p = target_ecef(lat, lon) / R_EARTH
    return np.max(p @ track.T, axis=1) >= np.cos(_reach_angle(scn) + np.deg2rad(2.0))


def _sample_visible(scn: Scenario, rng: np.random.Generator, want: int) -> tuple[np.ndarray, ...]:
    """Worldwide uniform targets, kept when they have a daylight window."""
    lats, lons = [], []
    got = 0
    for _ in range(200):
        lat, lon = _uniform_points(rng, 20000)
        keep = _reachable(scn, lat, lon)
        lat, lon = lat[keep], lon[keep]
        lats.append(lat)
        lons.append(lon)
        got += lat.size
        if got >= 3 * want + 50:
            break
    lat, lon = np.concatenate(lats), np.concatenate(lons)
    return lat, lon


def _cluster_points(scn: Scenario, rng: np.random.Generator, want: int, n_clusters: int,
                    radius_km: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Targets around `n_clusters` visible centers; returns lat, lon and the cluster of each."""
    clat, clon = _sample_visible(scn, rng, 20 * n_clusters)
    clat, clon = clat[: 60 * n_clusters], clon[: 60 * n_clusters]
    ws, _ = _windows(scn, clat, clon)
    good = np.flatnonzero(np.isfinite(ws))
    if good.size < n_clusters:
        raise ValueError("could not place the requested number of visible clusters")
    centers = good[rng.permutation(good.size)[:n_clusters]]
    clat, clon = clat[centers], clon[centers]
    m = 4 * want + 100
    which = rng.integers(0, n_clusters, m)
    ang = np.abs(rng.normal(0.0, radius_km / R_EARTH, m))
    bearing = rng.uniform(0.0, 2 * np.pi, m)
    la0, lo0 = np.deg2rad(clat[which]), np.deg2rad(clon[which])
    la = np.arcsin(np.sin(la0) * np.cos(ang) + np.cos(la0) * np.sin(ang) * np.cos(bearing))
    lo = lo0 + np.arctan2(np.sin(bearing) * np.sin(ang) * np.cos(la0), np.cos(ang) - np.sin(la0) * np.sin(la))
    lon = (np.rad2deg(lo) + 180.0) % 360.0 - 180.0
    return np.rad2deg(la), lon, which


def _csv_points(path: str) -> tuple[np.ndarray, np.ndarray]:
    lat, lon = [], []
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        if reader.fieldnames is None or not {"lat", "lon"} <= set(reader.fieldnames):
            raise ValueError(f"{path}: a CSV with columns 'lat' and 'lon' is required "
                             f"(found {reader.fieldnames})")
        for row_no, row in enumerate(reader, start=2):
            try:
                la, lo = float(row["lat"]), float(row["lon"])
            except (TypeError, ValueError):
                raise ValueError(f"{path}: line {row_no}: lat/lon not numbers: {row}") from None
            if not (-90 <= la <= 90 and -180 <= lo <= 360) or not np.isfinite(la + lo):
                raise ValueError(f"{path}: line {row_no}: lat/lon out of range: {la}, {lo}")
            lat.append(la)
            lon.append(lo)
    return np.asarray(lat), np.asarray(lon)


# --------------------------------------------------------------------------- instance

# Sizes of a generated instance per acquisition, measured on the default orbit and agility (300 and 600
# acquisitions, steps of 1 and 2 s): ~109 nodes per acquisition at a 1 s step, ~54 n^2 unpruned arcs at a 1 s
# step (each acquisition reaches most later ones), 28-45 bytes per arc at the peak of generation and writing.
NODES_PER_ACQ_STEP = 110.0
ARCS_PER_ACQ2_STEP = 55.0
BYTES_PER_ARC = 48
BYTES_PER_NODE = 64
BASE_BYTES = 128 * 1024 ** 2


def estimate_size(cfg: InstanceConfig) -> tuple[int, int, int]:
    """(nodes, unpruned arcs, peak bytes) of generating `cfg`, from the request alone (no generation): what
    :func:`require_generate_memory` compares with the memory available before a long generation starts."""
    n, step = cfg.n_acquisitions, max(float(cfg.graph.step_s), 1e-3)
    nodes = int(NODES_PER_ACQ_STEP * n / step) + 1
    arcs = int(min(ARCS_PER_ACQ2_STEP * n * n / step, nodes * (nodes - 1) / 2))
    return nodes, arcs, BASE_BYTES + BYTES_PER_ARC * arcs + BYTES_PER_NODE * nodes


def require_generate_memory(cfg: InstanceConfig, where: object, parallel: int = 1) -> None:
    """A one-line InputError (naming `where`, e.g. ``--n-acquisitions``) when generating `cfg`, `parallel` at a
    time, cannot fit in the memory available or in --max-memory-gb (:func:`eosp.memory.require_memory`)."""
    from eosp.memory import require_memory

    nodes, arcs, need = estimate_size(cfg)
    times = f"{parallel} at a time, each " if parallel > 1 else ""
    require_memory(where, need * parallel, f"generating {times}{cfg.n_acquisitions:,} acquisitions (about "
                                          f"{nodes:,} nodes, {arcs:,} arcs)")


def generate(cfg: InstanceConfig, name: str | None = None) -> Instance:
    """Generate one instance (acquisitions and the unpruned discrete graph)."""
    rng = np.random.default_rng(cfg.seed)
    scn = make_scenario(cfg, rng)
    tc = cfg.targets
    n = cfg.n_acquisitions
    if n < 1:
        raise ValueError("n_acquisitions must be at least 1")
    cluster = None
    if tc.distribution == "uniform":
        lat, lon = _sample_visible(scn, rng, n)
    elif tc.distribution == "clusters":
        lat, lon, cluster = _cluster_points(scn, rng, n, tc.n_clusters, tc.cluster_radius_km)
    elif tc.distribution == "csv":
        if not tc.csv_path:
            raise ValueError("targets.distribution='csv' needs targets.csv_path")
        lat, lon = _csv_points(tc.csv_path)
    else:
        raise ValueError(f"unknown target distribution {tc.distribution!r} (uniform, clusters, csv)")

    dur_all = np.round(rng.uniform(tc.duration_min_s, tc.duration_max_s, lat.size), 1)
    step = cfg.graph.step_s
    # windows chunk by chunk until enough candidates fit (all of them for a user's list)
    ws = np.full(lat.size, np.nan)
    we = np.full(lat.size, np.nan)
    found = 0
    for lo in range(0, lat.size, 256):
        hi = min(lat.size, lo + 256)
        ws[lo:hi], we[lo:hi] = _windows(scn, lat[lo:hi], lon[lo:hi])
        found += int(np.sum(we[lo:hi] - ws[lo:hi] - dur_all[lo:hi] >= step))
        if found >= n and tc.distribution != "csv":
            break
    for _ in range(20):  # rare: too few candidates had a daylight window, draw more (same stream before)
        if found >= n or tc.distribution == "csv":
            break
        if tc.distribution == "uniform":
            la2, lo2 = _sample_visible(scn, rng, n - found)
        else:
            la2, lo2, c2 = _cluster_points(scn, rng, n - found, tc.n_clusters, tc.cluster_radius_km)
            cluster = np.concatenate([cluster, c2])
        d2 = np.round(rng.uniform(tc.duration_min_s, tc.duration_max_s, la2.size), 1)
        w2s, w2e = _windows(scn, la2, lo2)
        lat, lon, dur_all = np.concatenate([lat, la2]), np.concatenate([lon, lo2]), np.concatenate([dur_all, d2])
        ws, we = np.concatenate([ws, w2s]), np.concatenate([we, w2e])
        found += int(np.sum(w2e - w2s - d2 >= step))
    fits = np.isfinite(ws) & (we - ws - dur_all >= step)
    idx = np.flatnonzero(fits)
    if tc.distribution == "csv":
        idx = np.sort(rng.permutation(idx)[:n]) if idx.size > n else idx
    else:
        if idx.size < n:
            raise ValueError(f"only {idx.size} visible targets found for {n} acquisitions; "
                             "widen the clusters or the pointing limits")
        idx = idx[:n]
    if idx.size == 0:
        raise ValueError("no target is visible in daylight from this orbit")
    lat, lon, ws, we, dur = lat[idx], lon[idx], ws[idx], we[idx], dur_all[idx]
    n = idx.size

    # priority classes: a per-instance mix around the configured one, top classes sometimes absent
    base = np.asarray(tc.class_probs, dtype=np.float64)
    mix = rng.dirichlet(tc.class_mix_concentration * base / base.sum())
    if rng.uniform() < tc.drop_top_classes_prob:
        mix[: int(rng.integers(1, 3))] = 0.0
    mix /= mix.sum()
    prio = rng.choice(len(CLASS_UTILITIES), size=n, p=mix).astype(np.int8)
    if tc.high_priority_clustered and cluster is not None:
        # the highest classes go to the targets of one cluster, where they compete for the same pass
        members = np.flatnonzero(cluster[idx] == cluster[idx][0])
        rest = np.setdiff1d(np.arange(n), members)
        order = np.concatenate([rng.permutation(members), rng.permutation(rest)])
        prio[order] = np.sort(prio)
    cloud = rng.beta(0.7, 1.2, n)
    utility = np.asarray(CLASS_UTILITIES)[prio] * (1.0 + tc.cloud_weight * (1.0 - cloud))

    # chronological acquisition ids
    order = np.lexsort((lon, ws))
    lat, lon, ws, we, dur, prio, utility = (x[order] for x in (lat, lon, ws, we, dur, prio, utility))

    # nodes: every window discretized from its start with the configured step
    counts = np.floor((we - dur - ws) / step + 1e-9).astype(np.int64) + 1
    node_acq = np.concatenate([[-1], np.repeat(np.arange(n), counts)]).astype(np.int32)
    k = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    node_time = np.concatenate([[0.0], ws[node_acq[1:]] + k * step])
    a_lat, a_lon = lat[node_acq[1:]], lon[node_acq[1:]]
    r0, p0 = scn.attitude(a_lat, a_lon, node_time[1:])
    r1, p1 = scn.attitude(a_lat, a_lon, node_time[1:] + dur[node_acq[1:]])
    node_att = np.zeros((node_acq.size, 4))
    node_att[1:] = np.stack([r0, p0, r1, p1], axis=1)

    # attitude statistics over each window (start and end attitudes of every node)
    att = np.zeros((n, 6))
    owner = node_acq[1:]
    for col, (vals_a, vals_b) in enumerate(((r0, r1), (p0, p1))):
        vals = np.concatenate([vals_a, vals_b])
        who = np.concatenate([owner, owner])
        mn = np.full(n, np.inf)
        mx = np.full(n, -np.inf)
        np.minimum.at(mn, who, vals)
        np.maximum.at(mx, who, vals)
        mean = np.bincount(who, weights=vals, minlength=n) / np.bincount(who, minlength=n)
        att[:, 3 * col:3 * col + 3] = np.stack([mn, mx, mean], axis=1)

    acq_ptr = acq_ptr_from_node_acq(node_acq, n)
    indptr, dst = build_arcs(node_acq, node_time, node_att, dur, acq_ptr, scn.slew_model, scn.max_slew())
    graph = DiscreteGraph(node_acq, node_time, indptr, dst, acq_ptr)
    acqs = Acquisitions(duration=dur, vtw_start=ws, vtw_end=we, utility=utility, priority=prio,
                        lat=lat, lon=lon, attitude=att)
    meta = {
        "generator": GENERATOR_NAME, "generator_version": GENERATOR_VERSION, "family": cfg.family,
        "seed": cfg.seed, "horizon_s": scn.horizon, "day_of_year": scn.day_of_year,
        "max_slew_s": scn.max_slew(), "config": to_dict(cfg),
    }
    inst = Instance(name=name or f"{cfg.family}-n{cfg.n_acquisitions}-s{cfg.seed}", acqs=acqs, unpruned_graph=graph,
                    node_ids=np.arange(node_acq.size, dtype=np.int32), meta=meta,
                    node_attitude=node_att.astype(np.float32))
    return inst


def scenario_of(inst: Instance) -> Scenario:
    """Rebuild the scenario of a generated instance (for checks against the simulator)."""
    from eosp.config import from_dict

    cfg = from_dict(InstanceConfig, inst.meta["config"])
    return make_scenario(cfg, np.random.default_rng(cfg.seed))
