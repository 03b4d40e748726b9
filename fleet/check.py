"""The schedule checker: the aeossp_standard verifier's rules, checks and metrics, reproduced.

Stages run in the benchmark's order and each action is judged by the first rule it breaks:

1. structure, per action in file order: unknown satellite, unknown task, end not after start,
   outside the horizon, start/end off the action grid, outside the task window, duration not the
   required one, sensor mismatch;
2. geometry, per remaining action: at its start, end and every geometry-grid instant inside,
   the target must be visible (above its local horizontal plane) and the off-nadir angle within
   the limit (+1e-6 deg);
3. slew, per satellite in order of first appearance, actions by (start, end, index): an overlap
   with the previously accepted action, or a gap shorter than the slew (bang-coast-bang on the
   angle between the inertial lines of sight at the previous end and this start; from geocentric
   nadir, counting from the horizon start, for the first action) plus settling, minus 1e-9 s;
   each accepted action reserves a maneuver window [start - slew - settle, start];
4. battery, per satellite in fleet order (see :mod:`eosp.fleet.battery`).

The checker is the verifier re-implemented, on purpose independent of the solvers' code: its lines of sight come
from brahe's GCRF states (:class:`Inertial`), not the grid tables of :mod:`eosp.fleet.slew`, and it derives the
maneuver windows itself; it shares with them only the battery simulation (the verifier's recurrence, written
once in :mod:`eosp.fleet.battery`) and the slew formula (:func:`eosp.sim.slew.bang_coast_bang`).

Any violation makes the schedule invalid and every metric zero (TAT None).  Otherwise a task is
complete when at least one action observes it (duplicates count once, the earliest end is its
completion): CR = completed / tasks, WCR = completed weight / total weight, TAT = mean of
(completion - release) in seconds (None when nothing completes), PC = gross Wh consumed.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timedelta

import numpy as np

from eosp.fleet.battery import Intervals, SunCache, simulate
from eosp.fleet.geometry import (NUMERICAL_EPS, Geometry, angle_deg, brahe_module, epochs, pointing_ok,
                                 slew_time_s)
from eosp.fleet.model import US, Fleet, Schedule, iso_z
from eosp.problem import Verdict


@dataclass(frozen=True)
class Violation:
    """One broken rule: the action (index in the schedule, -1 when none), where and when."""

    action: int
    satellite: str
    task: str
    time: datetime | None
    stage: str
    reason: str

    def __str__(self) -> str:
        when = f" at {iso_z(self.time)}" if self.time is not None else ""
        what = f"action {self.action}" if self.action >= 0 else "no action"
        task = f", task {self.task}" if self.task else ""
        return f"{self.stage}: {what} (satellite {self.satellite}{task}){when}: {self.reason}"


@dataclass(frozen=True)
class CheckResult:
    valid: bool
    metrics: dict
    violations: tuple[Violation, ...]

    @property
    def first(self) -> Violation | None:
        return self.violations[0] if self.violations else None

    def verdict(self) -> Verdict:
        """The contract's verdict (:class:`eosp.problem.Verdict`), with the line ``eosp validate`` prints."""
        m = self.metrics
        if not self.valid:
            return Verdict(False, m, str(self.first), f"invalid: {self.first}")
        tat = "null" if m["TAT"] is None else repr(m["TAT"])
        return Verdict(True, m, None, f"valid: WCR {m['WCR']!r} CR {m['CR']!r} TAT {tat} PC {m['PC']!r}")


def zero_metrics() -> dict:
    return {"CR": 0.0, "WCR": 0.0, "TAT": None, "PC": 0.0}


def timedelta_us(seconds: float) -> int:
    """``timedelta(seconds=x)`` in microseconds (Python's rounding of a float to microseconds)."""
    return timedelta(seconds=float(seconds)) // timedelta(microseconds=1)


def _aligned(us: np.ndarray, step_s: int) -> np.ndarray:
    q = (us / 1e6) / step_s
    return np.abs(q - np.round(q)) <= 1.0e-9


class _Ctx:
    """What the stages share: the fleet, its geometry, the schedule and index maps."""

    def __init__(self, fleet: Fleet, schedule: Schedule, geo: Geometry):
        self.fleet, self.schedule, self.geo = fleet, schedule, geo
        si, ti = fleet.satellite_index(), fleet.task_index()
        self.sat = np.asarray([si.get(s, -1) for s in schedule.satellite.tolist()], dtype=np.int64)
        self.task = np.asarray([ti.get(t, -1) for t in schedule.task.tolist()], dtype=np.int64)
        self.violations: list[Violation] = []

    def fail(self, i: int, t_us: int | None, stage: str, reason: str) -> None:
        s = self.schedule
        when = self.fleet.horizon.utc(t_us) if t_us is not None else None
        self.violations.append(Violation(i, str(s.satellite[i]), str(s.task[i]), when, stage, reason))


def _structure(c: _Ctx) -> np.ndarray:
    """Indices of the actions that pass the structural rules."""
    f, s = c.fleet, c.schedule
    n = len(s)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    h, tk = f.horizon, f.tasks
    step = h.action_step_s
    ti = np.maximum(c.task, 0)
    start_ok, end_ok = _aligned(s.start_us, step), _aligned(s.end_us, step)
    rel_us = np.round(tk.release_s[ti] * US).astype(np.int64)
    due_us = np.round(tk.due_s[ti] * US).astype(np.int64)
    dur_s = np.round((s.end_us - s.start_us) / 1e6)
    sensor_ok = np.asarray([c.sat[i] < 0 or f.satellites.sensor[c.sat[i]] == tk.sensor[ti[i]] for i in range(n)])
    checks = [
        (c.sat < 0, "unknown satellite_id", "start"),
        (c.task < 0, "unknown task_id", "start"),
        (s.end_us <= s.start_us, "end_time must be after start_time", "start"),
        ((s.start_us < 0) | (s.end_us > h.seconds * US), "action lies outside the mission horizon", "start"),
        (~start_ok, f"start_time must align to the {step}s action grid", "start"),
        (~end_ok, f"end_time must align to the {step}s action grid", "end"),
        ((s.start_us < rel_us) | (s.end_us > due_us), "action lies outside the task window", "start"),
        (dur_s != tk.duration_s[ti], None, "start"),
        (~sensor_ok, "satellite sensor_type does not match task required_sensor_type", "start"),
    ]
    bad = np.zeros(n, dtype=bool)
    first = np.full(n, -1)
    for k, (mask, _, _) in enumerate(checks):
        hit = mask & ~bad
        first[hit] = k
        bad |= mask
    for i in np.flatnonzero(bad).tolist():
        mask, reason, at = checks[first[i]]
        if reason is None:
            reason = f"action duration must equal required_duration_s ({int(tk.duration_s[ti[i]])}s)"
        c.fail(i, int(s.start_us[i] if at == "start" else s.end_us[i]), "structure", reason)
    return np.flatnonzero(~bad)


def sample_offsets(start_s: int, end_s: int, geometry_step_s: int) -> list[int]:
    """The instants (seconds from the horizon start) at which an action's geometry is checked."""
    pts = [start_s]
    g = (start_s // geometry_step_s + 1) * geometry_step_s
    while g < end_s:
        pts.append(g)
        g += geometry_step_s
    if pts[-1] != end_s:
        pts.append(end_s)
    return pts


def _geometry(c: _Ctx, idx: np.ndarray) -> np.ndarray:
    """Indices (of `idx`) whose target is visible and within the off-nadir limit throughout."""
    f, s, geo = c.fleet, c.schedule, c.geo
    if len(idx) == 0:
        return idx
    base = geo.base_step_s
    owner, t_s = [], []
    for i in idx.tolist():
        pts = sample_offsets(int(round(s.start_us[i] / US)), int(round(s.end_us[i] / US)), f.horizon.geometry_step_s)
        owner.extend([i] * len(pts))
        t_s.extend(pts)
    owner, t_s = np.asarray(owner), np.asarray(t_s, dtype=np.int64)
    sat = c.sat[owner]
    pos = np.empty((len(owner), 3))
    for k in np.unique(sat).tolist():
        m = sat == k
        pos[m] = geo.grid_positions(k)[t_s[m] // base]
    vis, on = pointing_ok(pos, geo.target_ecef[c.task[owner]], f.satellites.attitude.max_off_nadir_deg[sat])
    bad = ~(vis & on)
    accepted = []
    bounds = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
    for lo, hi in zip(bounds.tolist(), np.r_[bounds[1:], len(owner)].tolist()):
        i = int(owner[lo])
        if not bad[lo:hi].any():
            accepted.append(i)
            continue
        j = lo + int(np.argmax(bad[lo:hi]))
        why = "target is not continuously visible" if not vis[j] else "required pointing exceeds max_off_nadir_deg"
        when = f.horizon.utc(int(t_s[j]) * US)
        c.fail(i, int(t_s[j]) * US, "geometry", f"{why} at {iso_z(when)}")
    return np.asarray(accepted, dtype=np.int64)


class Inertial:
    """GCRF lines of sight computed exactly as the benchmark does (brahe's GCRF satellite state,
    brahe's ITRF->GCRF transform of the target), cached per instant."""

    def __init__(self, fleet: Fleet, geo: Geometry):
        self.fleet, self.geo = fleet, geo
        self._sat: dict[tuple[int, int], np.ndarray] = {}
        self._tgt: dict[tuple[int, int], np.ndarray] = {}

    def _epoch(self, t_us: int):
        return epochs(self.fleet.horizon.start, [t_us])[0]

    def sat_eci(self, sat: int, t_us: int) -> np.ndarray:
        key = (sat, t_us)
        if key not in self._sat:
            self._sat[key] = self.geo.positions_eci(sat, [self._epoch(t_us)])[0]
        return self._sat[key]

    def los(self, sat: int, task: int, t_us: int) -> np.ndarray:
        key = (task, t_us)
        if key not in self._tgt:
            bh = brahe_module()
            self._tgt[key] = np.asarray(bh.position_ecef_to_eci(self._epoch(t_us), self.geo.target_ecef[task]),
                                        dtype=float).reshape(3)
        return self._tgt[key] - self.sat_eci(sat, t_us)


def _slew(c: _Ctx, idx: np.ndarray) -> tuple[dict[int, list[int]], dict[int, Intervals]]:
    """Per satellite: accepted actions in time order, and their maneuver windows."""
    f, s = c.fleet, c.schedule
    att = f.satellites.attitude
    inertial = Inertial(f, c.geo)
    by_sat: dict[int, list[int]] = {}
    for i in idx.tolist():
        by_sat.setdefault(int(c.sat[i]), []).append(i)
    accepted: dict[int, list[int]] = {}
    windows: dict[int, Intervals] = {}
    for k, acts in by_sat.items():
        acts.sort(key=lambda i: (int(s.start_us[i]), int(s.end_us[i]), i))
        prev = None
        keep, w0, w1 = [], [], []
        for i in acts:
            st = int(s.start_us[i])
            if prev is not None and int(s.end_us[prev]) > st:
                c.fail(i, st, "slew", "observation actions overlap on the same satellite")
                continue
            to = inertial.los(k, int(c.task[i]), st)
            if prev is None:
                frm = -inertial.sat_eci(k, st)
                gap = st / 1e6
            else:
                frm = inertial.los(k, int(c.task[prev]), int(s.end_us[prev]))
                gap = (st - int(s.end_us[prev])) / 1e6
            angle = float(angle_deg(frm, to))
            need = float(slew_time_s(angle, att.max_rate_deg_s[k], att.max_acc_deg_s2[k])) + float(att.settling_s[k])
            if gap + NUMERICAL_EPS < need:
                c.fail(i, st, "slew", f"insufficient slew/settle time before observation "
                                      f"(need {need:.3f}s, have {gap:.3f}s)")
                continue
            if need > NUMERICAL_EPS:
                w0.append(st - timedelta_us(need))
                w1.append(st)
            keep.append(i)
            prev = i
        accepted[k] = keep
        windows[k] = Intervals(np.asarray(w0, dtype=np.int64), np.asarray(w1, dtype=np.int64))
    return accepted, windows


def _battery(c: _Ctx, accepted: dict[int, list[int]], windows: dict[int, Intervals]) -> float:
    f, s = c.fleet, c.schedule
    sun = SunCache(c.geo)
    empty = Intervals(np.zeros(0, np.int64), np.zeros(0, np.int64))
    total = 0.0
    for k in range(len(f.satellites)):
        acts = accepted.get(k, [])
        obs = Intervals(s.start_us[acts].astype(np.int64), s.end_us[acts].astype(np.int64)) if acts else empty
        run = simulate(f, sun, k, obs, windows.get(k, empty))
        if run.ok:
            total += run.gross_wh
            continue
        i = acts[run.fail_action] if run.fail_action >= 0 else -1
        when = f.horizon.utc(run.fail_us)
        reason = f"battery depletes below zero around {iso_z(when)}"
        c.violations.append(Violation(i, str(f.satellites.ids[k]), str(s.task[i]) if i >= 0 else "", when,
                                      "battery", reason))
    return total


def metrics(fleet: Fleet, schedule: Schedule, accepted: list[int], pc_wh: float) -> dict:
    """CR, WCR, TAT and PC of the accepted actions (the verifier's sums, in its order)."""
    tk = fleet.tasks
    ti = fleet.task_index()
    done: dict[int, int] = {}
    for i in accepted:
        t, e = ti[schedule.task[i]], int(schedule.end_us[i])
        if t not in done or e < done[t]:
            done[t] = e
    n = len(tk)
    completed = [t for t in range(n) if t in done]
    total_w = sum(tk.weight.tolist())
    done_w = sum(float(tk.weight[t]) for t in completed)
    rel_us = np.round(tk.release_s * US).astype(np.int64)
    tat = [(done[t] - int(rel_us[t])) / 1e6 for t in completed]
    return {"CR": len(completed) / n if n else 0.0,
            "WCR": done_w / total_w if total_w > 0.0 else 0.0,
            "TAT": sum(tat) / len(tat) if tat else None,
            "PC": pc_wh}


def validate(fleet: Fleet, schedule: Schedule, geo: Geometry | None = None) -> CheckResult:
    """Check `schedule` against `fleet` with the benchmark's rules; see the module docstring."""
    geo = geo or Geometry(fleet)
    c = _Ctx(fleet, schedule, geo)
    idx = _structure(c)
    idx = _geometry(c, idx)
    accepted, windows = _slew(c, idx)
    pc = _battery(c, accepted, windows)
    if c.violations:
        return CheckResult(False, zero_metrics(), tuple(c.violations))
    all_acc = [i for k in sorted(accepted) for i in accepted[k]]
    return CheckResult(True, metrics(fleet, schedule, all_acc, pc), ())


def require_feasible(fleet: Fleet, where: object, geo: Geometry | None = None) -> None:
    """Refuse (one-line InputError) a fleet that has no valid schedule at all, not even the empty one (a battery that
    idling alone runs dry within the horizon), instead of solvers that cannot succeed."""
    from eosp.errors import InputError

    res = validate(fleet, Schedule.empty(), geo)
    if not res.valid:
        raise InputError(where, f"no schedule of this fleet is valid, not even the empty one: {res.first}")
