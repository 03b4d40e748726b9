"""The fleet model: a constellation, its imaging tasks and a horizon, as typed bundles of arrays.

One row per satellite or task, one numpy array per field, so that geometry and scheduling code
works on whole columns instead of looping over Python objects.  Times are kept as offsets from
the horizon start: seconds (float64) for task windows, integer microseconds for schedules (the
resolution of the UTC timestamps they are read from), so nothing is lost on a round trip.

Sources other than ``aeossp_standard`` (ground stations, downloads, stereo, periodic or video
requests, a value per opportunity) go into :attr:`Fleet.extras`: named tables (column name ->
array) carried through the interchange directory untouched.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import Mapping

import numpy as np

US = 1_000_000  # microseconds per second


@dataclass(frozen=True)
class Horizon:
    """The planning horizon in UTC and its three public time grids (steps in whole seconds)."""

    start: datetime
    end: datetime
    action_step_s: int
    geometry_step_s: int
    resource_step_s: int

    @property
    def seconds(self) -> int:
        return int(round((self.end - self.start).total_seconds()))

    @property
    def n_action(self) -> int:
        """Number of action-grid instants, both horizon ends included."""
        return self.seconds // self.action_step_s + 1

    def utc(self, offset_us: int) -> datetime:
        """The UTC instant `offset_us` microseconds after the horizon start."""
        return self.start + timedelta(microseconds=int(offset_us))


@dataclass(frozen=True, eq=False)
class Tles:
    """Two-line element sets, propagated with SGP4."""

    line1: np.ndarray  # str
    line2: np.ndarray  # str
    norad: np.ndarray  # int64


@dataclass(frozen=True, eq=False)
class Attitude:
    """Pointing limits and the bang-coast-bang slew model (degrees, seconds)."""

    max_off_nadir_deg: np.ndarray
    max_rate_deg_s: np.ndarray
    max_acc_deg_s2: np.ndarray
    settling_s: np.ndarray


@dataclass(frozen=True, eq=False)
class Battery:
    """Energy model: capacity and initial charge (Wh), loads and sunlit charging (W)."""

    capacity_wh: np.ndarray
    initial_wh: np.ndarray
    idle_w: np.ndarray
    imaging_w: np.ndarray
    slew_w: np.ndarray
    sunlit_w: np.ndarray


@dataclass(frozen=True, eq=False)
class Satellites:
    """The constellation, one row per satellite."""

    ids: np.ndarray  # str
    sensor: np.ndarray  # str
    tle: Tles
    attitude: Attitude
    battery: Battery

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True, eq=False)
class Tasks:
    """Point-imaging tasks, one row per task; times in seconds from the horizon start."""

    ids: np.ndarray  # str
    names: np.ndarray  # str
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    release_s: np.ndarray
    due_s: np.ndarray
    duration_s: np.ndarray
    weight: np.ndarray
    sensor: np.ndarray  # str

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True, eq=False)
class Fleet:
    """A scheduling problem over a constellation.

    `source` names where it came from (``aeossp_standard``), `source_commit` the data version,
    `case_id` the case; `extras` holds tables of other kinds of demand (see the module docstring).
    """

    horizon: Horizon
    satellites: Satellites
    tasks: Tasks
    source: str = ""
    source_commit: str = ""
    case_id: str = ""
    extras: Mapping[str, Mapping[str, np.ndarray]] = field(default_factory=dict)

    def satellite_index(self) -> dict[str, int]:
        return {s: i for i, s in enumerate(self.satellites.ids)}

    def task_index(self) -> dict[str, int]:
        return {t: i for i, t in enumerate(self.tasks.ids)}


@dataclass(frozen=True, eq=False)
class Schedule:
    """Observation actions: satellite and task ids as given, times in microseconds from the horizon start.

    Ids are kept as strings so that a schedule naming an unknown satellite or task can still be
    checked (and rejected with the verifier's reason) rather than refused on reading.
    """

    satellite: np.ndarray  # str
    task: np.ndarray  # str
    start_us: np.ndarray  # int64
    end_us: np.ndarray  # int64

    def __len__(self) -> int:
        return len(self.task)

    @staticmethod
    def empty() -> "Schedule":
        return Schedule(np.array([], dtype=object), np.array([], dtype=object),
                        np.zeros(0, np.int64), np.zeros(0, np.int64))


SENSORS = ("visible", "infrared")
NORAD_MAX = 999_999_999  # the largest catalog number kept (int64 column; TLEs' alpha-5 numbers reach 339,999)
EPS = 1.0e-9  # the benchmark's tolerance on values that must not be negative
ALTITUDE_M = (-11_000.0, 100_000.0)  # a target on (or above) the Earth's surface: the ocean floor to the Karman line


def satellite_fault(sats: Satellites) -> tuple[int, str, str] | None:
    """The first satellite whose parameters are out of range: (row, field, reason), fields named as the fleet
    directory's columns (= the aeossp keys); None when all are in range.  Checked where a fleet enters (the aeossp
    reader, the fleet directory reader), so that no solver divides by a zero slew rate or looks past the horizon."""
    a, b = sats.attitude, sats.battery
    return _first_fault((
        ("norad_catalog_id", sats.tle.norad, lambda v: (v >= 0) & (v <= NORAD_MAX), f"must lie in [0, {NORAD_MAX}]"),
        ("max_off_nadir_deg", a.max_off_nadir_deg, lambda v: (v >= -EPS) & (v <= 90), "must lie in [0, 90]"),
        ("max_slew_velocity_deg_per_s", a.max_rate_deg_s, lambda v: v > 0, "must be > 0"),
        ("max_slew_acceleration_deg_per_s2", a.max_acc_deg_s2, lambda v: v > 0, "must be > 0"),
        ("settling_time_s", a.settling_s, lambda v: v >= -EPS, "must be >= 0"),
        ("battery_capacity_wh", b.capacity_wh, lambda v: v > 0, "must be > 0"),
        ("initial_battery_wh", b.initial_wh, lambda v: (v >= -EPS) & (v <= b.capacity_wh + EPS),
         "must lie within [0, battery_capacity_wh]"),
        ("idle_power_w", b.idle_w, lambda v: v >= -EPS, "must be >= 0"),
        ("imaging_power_w", b.imaging_w, lambda v: v >= -EPS, "must be >= 0"),
        ("slew_power_w", b.slew_w, lambda v: v >= -EPS, "must be >= 0"),
        ("sunlit_charge_power_w", b.sunlit_w, lambda v: v >= -EPS, "must be >= 0"),
        ("sensor_type", sats.sensor, lambda v: np.isin(v.astype(str), SENSORS),
         f"must be one of {', '.join(SENSORS)}"),
    ))


def task_fault(tasks: Tasks, horizon: Horizon) -> tuple[int, str, str] | None:
    """The first task out of range (place, window inside the horizon and on the action grid, duration, weight,
    sensor), as :func:`satellite_fault`; also the sum of the weights must be finite (two weights of 1e308 are
    each finite, their sum is not, and every metric is that sum's fraction)."""
    step, h = horizon.action_step_s, horizon.seconds

    def on_grid(v: np.ndarray) -> np.ndarray:
        return np.abs(v / step - np.round(v / step)) <= 1e-9

    fault = _first_fault((
        ("latitude_deg", tasks.lat_deg, lambda v: (v >= -90) & (v <= 90), "must lie in [-90, 90]"),
        ("longitude_deg", tasks.lon_deg, lambda v: (v >= -180) & (v <= 180), "must lie in [-180, 180]"),
        ("altitude_m", tasks.alt_m, lambda v: (v >= ALTITUDE_M[0]) & (v <= ALTITUDE_M[1]),
         f"must lie in [{ALTITUDE_M[0]:g}, {ALTITUDE_M[1]:g}] (a place on the Earth)"),
        ("release_s", tasks.release_s, lambda v: (v >= 0) & (v <= h) & on_grid(v),
         f"must lie in the horizon [0, {h}] on the {step} s action grid"),
        ("due_s", tasks.due_s, lambda v: (v > tasks.release_s) & (v <= h) & on_grid(v),
         f"must lie after release_s, in the horizon [0, {h}], on the {step} s action grid"),
        ("duration_s", tasks.duration_s, lambda v: (v > 0) & (v <= tasks.due_s - tasks.release_s) & on_grid(v),
         f"must be > 0, a multiple of {step} s and fit in the window"),
        ("weight", tasks.weight, lambda v: v > 0, "must be > 0"),
        ("sensor_type", tasks.sensor, lambda v: np.isin(v.astype(str), SENSORS),
         f"must be one of {', '.join(SENSORS)}"),
    ))
    with np.errstate(over="ignore"):
        running = np.cumsum(np.asarray(tasks.weight, dtype=np.float64))
    if fault is None and len(tasks) and not np.isfinite(running[-1]):  # the row where the sum first overflows
        return int(np.flatnonzero(~np.isfinite(running))[0]), "weight", \
            "makes the sum of the weights overflow (every metric divides by it)"
    return fault


def _first_fault(checks) -> tuple[int, str, str] | None:
    """The first (row, name, reason) of `checks`, each (name, values, ok(values) -> bool mask, reason)."""
    with np.errstate(invalid="ignore", over="ignore"):
        for name, values, ok, reason in checks:
            rows = np.flatnonzero(~ok(values))
            if len(rows):
                r = int(rows[0])
                got = values[r]
                return r, name, f"{reason}, got {got.item() if hasattr(got, 'item') else got!r}"
    return None


def strings(values) -> np.ndarray:
    """A 1-D object array of Python strings (numpy's fixed-width unicode would truncate nothing but
    pads and compares differently)."""
    out = np.empty(len(values), dtype=object)
    out[:] = [str(v) for v in values]
    return out


def iso_z(value: datetime) -> str:
    """ISO 8601 in UTC with a ``Z`` suffix (microseconds only when nonzero), as the benchmark writes it."""
    return value.astimezone(UTC).isoformat().replace("+00:00", "Z")


def parse_utc(value: str) -> datetime:
    """An ISO 8601 timestamp with a time zone, as an aware UTC datetime; ValueError otherwise."""
    if not isinstance(value, str):
        raise ValueError(f"expected an ISO 8601 timestamp string, got {value!r}")
    parsed = datetime.fromisoformat(value.replace("Z", "+00:00"))
    if parsed.tzinfo is None:
        raise ValueError(f"timestamp {value!r} has no time zone")
    return parsed.astimezone(UTC)
