"""A regional_coverage case as data: the manifest, the satellites, the regions and the weighted grid samples.

Satellites are few (6-12 a case): one frozen dataclass each.  The grid (5,000-20,000 samples) is arrays: the
samples' longitudes, latitudes, weights and region index; what a sample is worth to the primary metric
(:meth:`Case.sample_value`) is its region's weight share times its share of the region's total weight, so
that the coverage ratio of a set of samples is the sum of their values.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime, timedelta

import numpy as np

US = 1_000_000


@dataclass(frozen=True)
class Satellite:
    """One satellite of a case, with the fields of satellites.yaml (units as named)."""

    id: str
    tle_line1: str
    tle_line2: str
    tle_epoch: str
    min_edge_off_nadir_deg: float
    max_edge_off_nadir_deg: float
    cross_track_fov_deg: float
    min_strip_duration_s: float
    max_strip_duration_s: float
    max_roll_rate_deg_per_s: float
    max_roll_acceleration_deg_per_s2: float
    settling_time_s: float
    battery_capacity_wh: float
    initial_battery_wh: float
    idle_power_w: float
    imaging_power_w: float
    slew_power_w: float
    sunlit_charge_power_w: float
    imaging_duty_limit_s_per_orbit: float | None

    @property
    def roll_band(self) -> tuple[float, float]:
        """The |roll| range whose strip edges stay inside the sensor's off-nadir band."""
        half = 0.5 * self.cross_track_fov_deg
        return self.min_edge_off_nadir_deg + half, self.max_edge_off_nadir_deg - half

    @property
    def orbit_period_s(self) -> float:
        """The period the duty limit's sliding window spans: 86,400 s over the TLE's mean motion (as the
        benchmark reads it: the second-to-last field of line 2)."""
        mean_motion = float(self.tle_line2.split()[-2])
        return 86_400.0 / mean_motion if mean_motion > 0.0 else float("inf")


@dataclass(frozen=True)
class Region:
    id: str
    weight: float
    min_required_coverage_ratio: float | None
    ring: tuple[tuple[float, float], ...]  # the polygon's first ring, (lon, lat) in degrees


@dataclass
class Case:
    """One case directory, read (:func:`eosp.regional.read.read_case`)."""

    path: str
    case_id: str
    horizon_start: datetime
    horizon_end: datetime
    time_step_s: int
    sample_step_s: int
    sample_spacing_m: float
    max_actions: int | None
    revisit_bonus_alpha: float
    satellites: list[Satellite]
    regions: list[Region]
    region_total_m2: np.ndarray  # per region, the total weight the grid file states
    sample_ids: list[str]
    lon: np.ndarray
    lat: np.ndarray
    weight: np.ndarray
    region: np.ndarray  # region index of each sample
    grid_order: list[int] = field(default_factory=list)  # region indices in the grid file's order (the metrics')
    manifest: dict = field(default_factory=dict)

    @property
    def horizon_s(self) -> float:
        return (self.horizon_end - self.horizon_start).total_seconds()

    def sat_index(self) -> dict[str, int]:
        return {s.id: i for i, s in enumerate(self.satellites)}

    def sample_value(self) -> np.ndarray:
        """Each sample's share of the coverage ratio (region weight / sum of region weights x sample weight /
        the region's total weight): the ratio of a covered set is the sum of its samples' values."""
        w = np.array([r.weight for r in self.regions], dtype=float)
        tot = float(w.sum())
        with np.errstate(divide="ignore", invalid="ignore"):
            per = np.where((self.region_total_m2 > 0) & (tot > 0), w / np.where(tot > 0, tot, 1.0)
                           / np.where(self.region_total_m2 > 0, self.region_total_m2, 1.0), 0.0)
        return per[self.region] * self.weight

    def at(self, offset_s: float) -> datetime:
        return self.horizon_start + timedelta(seconds=offset_s)


@dataclass
class Plan:
    """A solution: its actions as the solution file lists them (dicts; the checker parses them as the verifier
    does, so that a malformed action is a violation, not a refusal)."""

    actions: list[dict]

    @staticmethod
    def of(case: Case, sats: list[int], starts_s: list[float], durations_s: list[float], rolls: list[float]) -> "Plan":
        """A plan of strips given by satellite index, start offset from the horizon start, duration and roll."""
        acts = []
        for s, t, d, r in zip(sats, starts_s, durations_s, rolls):
            acts.append({"type": "strip_observation", "satellite_id": case.satellites[int(s)].id,
                         "start_time": iso_z(case.at(float(t))), "duration_s": int(round(d)) if float(d).is_integer()
                         else float(d), "roll_deg": float(r)})
        acts.sort(key=lambda a: (a["start_time"], a["satellite_id"]))
        return Plan(acts)


def iso_z(value: datetime) -> str:
    """A UTC time as the benchmark writes it (seconds resolution, a Z)."""
    from datetime import UTC

    return value.astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
