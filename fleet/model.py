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
