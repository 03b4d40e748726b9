"""EOS-Bench (Ethan19YQ/EOS-Bench) scenarios and schedules as typed bundles of arrays.

A scenario is what their generator writes (``main_generate.py`` -> ``Scenario.export_to_json``): satellites with
their sensors and per-orbit limits (``satellite_specs.max_power_W``, ``max_data_storage_GB``), missions (tasks:
a priority, the profit TP sums, and a required duration), observation windows per (mission, satellite) with an
orbit number and the attitude (pitch, yaw, roll in degrees) sampled every ``time_step`` seconds inside the window,
and, when ground stations exist, communication windows.  A schedule is their scheduler's output
(``schedulers/schedule_output.py``): assignments (task, satellite, observation start and end, sensor, orbit number,
data volume, power cost, the attitude slice, and a downlink when ground stations exist).

Times are integer microseconds since the scenario's start (their times are ISO strings; a downlink their
schedulers place at random carries microseconds).  Windows keep file order: their ``window_id`` is the row + 1.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime, timedelta

import numpy as np

US = 1_000_000  # microseconds per second
ONE_US = timedelta(microseconds=1)


@dataclass(frozen=True, eq=False)
class Satellites:
    """One row per satellite; its sensors are rows ``sensor_ptr[s] : sensor_ptr[s + 1]`` of the sensor arrays."""

    ids: list[str]
    agile: np.ndarray  # bool: maneuverability type "agile" (their default) or "non_agile"
    max_storage_gb: np.ndarray  # float64, per orbit; 0 = no limit (their rule: both 0 = no resource check)
    max_power_w: np.ndarray  # float64, per orbit
    sensor_ptr: np.ndarray  # int64 [n + 1]
    sensor_ids: list[str]
    sensor_rate_mbps: np.ndarray  # float64
    sensor_power_w: np.ndarray  # float64

    def __len__(self) -> int:
        return len(self.ids)

    def sensor_of(self, sat: int, sensor_id: str) -> int:
        """The sensor row of `sensor_id` on satellite `sat`, -1 when it has none of that id."""
        for r in range(int(self.sensor_ptr[sat]), int(self.sensor_ptr[sat + 1])):
            if self.sensor_ids[r] == sensor_id:
                return r
        return -1


@dataclass(frozen=True, eq=False)
class Tasks:
    """One row per mission."""

    ids: list[str]
    priority: np.ndarray  # float64: the profit TP sums
    duration_s: np.ndarray  # float64: observation_requirement.duration_s

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True, eq=False)
class Windows:
    """Observation windows, one row per time window in file order.  The agile attitude samples of window w are
    ``pitch[att_ptr[w]:att_ptr[w + 1]]`` (and yaw, roll), one per ``step_s`` from its start; ``fixed[w]`` is its
    non-agile attitude (pitch, yaw, roll), NaN where the file has none."""

    task: np.ndarray  # int32
    satellite: np.ndarray  # int32
    sensor: np.ndarray  # int32: sensor row, -1 when the satellite has no sensor of the window's sensor_id
    sensor_id: list[str]
    orbit: np.ndarray  # int64: orbit number (1 = the orbit holding the scenario start)
    start_us: np.ndarray  # int64
    end_us: np.ndarray  # int64
    step_s: np.ndarray  # float64
    att_ptr: np.ndarray  # int64 [n + 1]
    pitch: np.ndarray  # float64 [samples]
    yaw: np.ndarray
    roll: np.ndarray
    fixed: np.ndarray  # float64 [n, 3]

    def __len__(self) -> int:
        return len(self.task)


@dataclass(frozen=True, eq=False)
class CommWindows:
    """Satellite-ground station communication windows, one row per time window."""

    satellite: np.ndarray  # int32
    station: np.ndarray  # int32
    start_us: np.ndarray  # int64
    end_us: np.ndarray  # int64

    def __len__(self) -> int:
        return len(self.satellite)


@dataclass(eq=False)
class Scenario:
    """One EOS-Bench scenario (see the module docstring)."""

    path: str
    name: str  # scenario_id
    start: datetime  # naive UTC (metadata.creation_time)
    duration_s: float
    time_step: float
    satellites: Satellites
    tasks: Tasks
    windows: Windows
    stations: list[str]
    comm: CommWindows
    ignored: dict[str, str] = field(default_factory=dict)  # fields read and not constraints of their model: why

    @property
    def horizon_us(self) -> int:
        return int(round(self.duration_s * US))

    def time_of(self, us: int) -> datetime:
        return self.start + timedelta(microseconds=int(us))

    def iso(self, us: int) -> str:
        """A time as their schedules write it (``datetime.isoformat``: seconds, microseconds only when not 0)."""
        return self.time_of(us).isoformat()

    def windows_of(self) -> dict[tuple[int, int], np.ndarray]:
        """Window rows by (task, satellite), each in file order."""
        w = self.windows
        order = np.lexsort((np.arange(len(w)), w.satellite, w.task))
        keys = np.stack([w.task[order], w.satellite[order]], axis=1)
        cuts = np.flatnonzero(np.any(np.diff(keys, axis=0) != 0, axis=1)) + 1
        return {(int(g[0, 0]), int(g[0, 1])): order[lo:lo + len(g)]
                for lo, g in zip(np.r_[0, cuts], np.split(keys, cuts))} if len(order) else {}


@dataclass(eq=False)
class Schedule:
    """Assignments in file order (their checker replays them in this order).  ``att_ptr`` indexes the attitude
    slice each carries (agile: per-sample pitch, yaw, roll; ``fixed``: one non-agile set, NaN when absent);
    downlink columns are -1 (station) and 0 (times) where there is none."""

    task: np.ndarray  # int32
    satellite: np.ndarray  # int32
    start_us: np.ndarray  # int64
    end_us: np.ndarray  # int64
    sensor_id: list[str]
    orbit: np.ndarray  # int64
    data_gb: np.ndarray  # float64, as the file states it (their checker sums these)
    power_w: np.ndarray  # float64
    att_ptr: np.ndarray  # int64 [m + 1]
    pitch: np.ndarray
    yaw: np.ndarray
    roll: np.ndarray
    fixed: np.ndarray  # float64 [m, 3]
    station: np.ndarray  # int32, -1: no downlink
    gs_start_us: np.ndarray  # int64
    gs_end_us: np.ndarray  # int64
    info: dict = field(default_factory=dict)  # the file's "metrics" and what eosp adds

    def __len__(self) -> int:
        return len(self.task)

    def has_angles(self, i: int) -> bool:
        return self.att_ptr[i + 1] > self.att_ptr[i]

    @classmethod
    def build(cls, scenario: Scenario, rows: list[tuple[int, int]], info: dict | None = None) -> Schedule:
        """A schedule of observations (window row, start offset k on its grid), in the given order, as their
        candidate generator makes them: end = start + duration, the window's sensor, orbit and attitude slice,
        data volume and power from the sensor; no downlinks."""
        w, sats, tasks = scenario.windows, scenario.satellites, scenario.tasks
        m = len(rows)
        win = np.asarray([r for r, _ in rows], dtype=np.int64)
        k = np.asarray([k for _, k in rows], dtype=np.int64)
        task = w.task[win] if m else np.zeros(0, np.int32)
        dur = tasks.duration_s[task]
        start = w.start_us[win] + np.round(k * w.step_s[win] * US).astype(np.int64)
        end = start + np.round(dur * US).astype(np.int64)
        sensor = w.sensor[win]
        rate = np.where(sensor >= 0, sats.sensor_rate_mbps[np.maximum(sensor, 0)], 0.0) if m else np.zeros(0)
        power = np.where(sensor >= 0, sats.sensor_power_w[np.maximum(sensor, 0)], 0.0) if m else np.zeros(0)
        data = rate * ((end - start) / US) / (8.0 * 1024.0)
        ptr, pitch, yaw, roll, fixed = [0], [], [], [], np.full((m, 3), np.nan)
        for i in range(m):
            r = int(win[i])
            if sats.agile[w.satellite[r]]:
                lo, n = attitude_slice(scenario, r, int(k[i]))
                pitch.append(w.pitch[lo:lo + n])
                yaw.append(w.yaw[lo:lo + n])
                roll.append(w.roll[lo:lo + n])
                ptr.append(ptr[-1] + n)
            else:
                fixed[i] = w.fixed[r]
                ptr.append(ptr[-1])
        cat = (lambda xs: np.concatenate(xs) if xs else np.zeros(0))
        none = np.full(m, -1, dtype=np.int32)
        return cls(task.astype(np.int32), w.satellite[win].astype(np.int32), start, end,
                   [w.sensor_id[r] for r in win.tolist()], w.orbit[win].astype(np.int64), data, power,
                   np.asarray(ptr, dtype=np.int64), cat(pitch), cat(yaw), cat(roll), fixed, none,
                   np.zeros(m, np.int64), np.zeros(m, np.int64), dict(info or {}))


def attitude_slice(scenario: Scenario, window: int, k: int) -> tuple[int, int]:
    """Where the attitude of an observation starting k steps into `window` lies in the window samples: (first
    sample, count), count = ceil(duration / step) as their candidate generator slices it (cut at the window's
    last sample, as a Python slice is)."""
    w = scenario.windows
    dur = float(scenario.tasks.duration_s[w.task[window]])
    step = float(w.step_s[window])
    n = max(1, int(np.ceil(dur / step - 1e-9)))
    lo, hi = int(w.att_ptr[window]), int(w.att_ptr[window + 1])
    first = min(lo + k, hi)
    return first, max(0, min(n, hi - first))
