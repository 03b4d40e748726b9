"""The EOS-Bench checker: their constraint model's verdict, the checks it leaves to its candidate generator, and
their metrics, re-implemented (``schedulers/constraint_model.py``, ``evaluation_metrics.py``, ``balance_utils.py``,
``timeliness_utils.py``).

Their rules.  Every scheduler of theirs keeps an assignment only when ``ConstraintModel.is_feasible_assignment``
accepts it against the assignments kept before, so a schedule file is judged by replaying its assignments in file
order; the first one refused is the first violation, named with the rule and, for a pair, the earlier assignment.
For assignment i, in their order:

1. its task has no earlier assignment;
2. it lasts at least the task's duration (1e-6 s tolerance);
3. with ground stations: it has a downlink that starts after the observation ends;
4. against every earlier assignment j of its satellite (all of them, not only the neighbours): the one that
   starts first ends at least a transition time (:mod:`eosp.eosbench.transition`, added as their datetime
   arithmetic does, in microseconds) before the other starts; observations and downlinks do not overlap (their
   checks, including their asymmetry: i's downlink against j's observation only when j has a downlink);
5. its downlink does not overlap another downlink at the same station;
6. the data volumes and power costs the assignments state, summed per (satellite, orbit number) in file order,
   stay within the satellite's ``max_data_storage_GB`` and ``max_power_W`` (1e-9 tolerance; a limit of 0 is none).

The generator's rules (what their model trusts its candidates for, checked after theirs): the observation lies in
an observation window of its task on its satellite, starts on the window's time grid (a non-agile satellite: at
the window's centre, as their generator places it) and lasts exactly the task's duration; its orbit number and
sensor are the window's, its data volume (rate x duration / 8192) and power cost its sensor's, its attitude the
window's samples from its start (ceil(duration / step) of them; a non-agile satellite: the window's fixed
attitude); a downlink lies in a communication window of its satellite and station, after the observation ends,
and lasts the ratio times the task's duration.

Metrics, as their code computes them on any schedule (valid or not): TP (priorities of the tasks assigned), TCR
(tasks assigned / tasks), TM (mean start offset of each task's last assignment, an unassigned task counting the
horizon, over the horizon), BD (1 - sum |workload - mean| / (2 x the tasks' total duration), workloads the
observation seconds per satellite, clamped to [0, 1]); sums in their order, so that the figures agree to the
last digit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eosp.eosbench.model import US, Scenario, Schedule, attitude_slice
from eosp.eosbench.transition import Rules, to_us, transition_s
from eosp.problem import Verdict

BLOCK = 256  # assignments per block of the pair checks (memory: satellite's assignments x BLOCK)


@dataclass
class Report:
    """A schedule judged: the first violation (index into the schedule, -1 when valid) under their rules alone
    and under theirs plus the generator's, each in words, and the metrics."""

    rules: Rules
    their_first: int
    their_reason: str | None
    first: int
    reason: str | None
    metrics: dict = field(default_factory=dict)

    @property
    def valid(self) -> bool:
        return self.first < 0


def _seq(values: np.ndarray) -> float:
    """A sum in order, one addition after another (their loops'; numpy's sum is pairwise)."""
    return float(np.cumsum(values)[-1]) if len(values) else 0.0


def metrics(scenario: Scenario, schedule: Schedule) -> dict:
    """TP, TCR, TM, BD as their evaluation_metrics computes them (see the module docstring)."""
    tasks, n = scenario.tasks, len(scenario.tasks)
    assigned = np.zeros(n, dtype=bool)
    assigned[schedule.task] = True
    tp = _seq(np.where(assigned, tasks.priority, 0.0)) if n else 0.0
    tcr = float(assigned.sum()) / n if n else 0.0
    horizon = scenario.horizon_us / US
    last = np.full(n, -1, dtype=np.int64)
    last[schedule.task] = np.arange(len(schedule))  # fancy assignment: the last write wins, as their dict does
    start_of_last = schedule.start_us[np.maximum(last, 0)] / US if len(schedule) else np.zeros(n)
    dt = np.where(last >= 0, np.maximum(0.0, start_of_last), horizon)
    tm = _seq(dt) / (horizon * n) if n and horizon > 0 else 0.0
    n_sat = len(scenario.satellites)
    load = np.zeros(n_sat)
    np.add.at(load, schedule.satellite, (schedule.end_us - schedule.start_us) / US)  # in file order
    required = _seq(tasks.duration_s)
    bd = 0.0
    if n_sat and required > 0:
        mu = _seq(load) / n_sat
        bd = min(1.0, max(0.0, 1.0 - _seq(np.abs(load - mu)) / (2.0 * required)))
    return {"TP": tp, "TCR": tcr, "TM": tm, "BD": bd}


def _who(scenario: Scenario, schedule: Schedule, i: int) -> str:
    return (f"assignment {i} (task {scenario.tasks.ids[schedule.task[i]]} on "
            f"{scenario.satellites.ids[schedule.satellite[i]]} at {scenario.iso(schedule.start_us[i])})")


def _ends(schedule: Schedule) -> tuple[np.ndarray, np.ndarray]:
    """The first and last attitude (pitch, yaw, roll) of each assignment's agile slice; NaN without one."""
    m = len(schedule)
    first = np.full((m, 3), np.nan)
    last = np.full((m, 3), np.nan)
    has = schedule.att_ptr[1:] > schedule.att_ptr[:-1]
    lo, hi = schedule.att_ptr[:-1][has], schedule.att_ptr[1:][has] - 1
    for col, arr in enumerate((schedule.pitch, schedule.yaw, schedule.roll)):
        first[has, col] = arr[lo]
        last[has, col] = arr[hi]
    return first, last


def _overlap(a0, a1, b0, b1):
    return ~((a1 <= b0) | (a0 >= b1))


def _pair_reasons(scenario: Scenario, schedule: Schedule, rules: Rules) -> dict[int, str]:
    """Rule 4 (see the module docstring): for each assignment refused, why, naming the first earlier assignment
    (in file order) it conflicts with."""
    out: dict[int, str] = {}
    first, last = _ends(schedule)
    s0, s1 = schedule.start_us, schedule.end_us
    g0, g1, has_g = schedule.gs_start_us, schedule.gs_end_us, schedule.station >= 0
    for sat in np.unique(schedule.satellite).tolist():
        idx = np.flatnonzero(schedule.satellite == sat)
        agile = bool(scenario.satellites.agile[sat])
        if len(idx) < 2:
            continue
        if not agile and rules.transition == "code":
            i = int(idx[1])
            out[i] = ("their checker has no transition rule for a non-agile satellite (its ConstraintModel never "
                      "stores non_agile_transition_s: AttributeError at a satellite's second assignment)")
            continue
        for lo in range(0, len(idx), BLOCK):
            col = idx[lo:lo + BLOCK]  # the later assignments i of the pairs, against every j of the satellite
            J, I = idx[:, None], col[None, :]
            shape = (len(idx), len(col))
            JJ, II = np.broadcast_to(J, shape).ravel(), np.broadcast_to(I, shape).ravel()
            earlier = J < I
            i_after = s0[I] >= s0[J]  # their test: i starting at or after j comes after j
            t_ji = to_us(transition_s(rules, agile, last[JJ], first[II])).reshape(shape)
            t_ij = to_us(transition_s(rules, agile, last[II], first[JJ])).reshape(shape)
            trans = np.where(i_after, s1[J] + t_ji > s0[I], s1[I] + t_ij > s0[J])
            obs = _overlap(s0[I], s1[I], s0[J], s1[J])
            gj = has_g[J]
            obs_gs = gj & _overlap(s0[I], s1[I], g0[J], g1[J])
            gs_gs = gj & has_g[I] & _overlap(g0[I], g1[I], g0[J], g1[J])
            gs_obs = gj & has_g[I] & _overlap(g0[I], g1[I], s0[J], s1[J])
            bad = earlier & (trans | obs | obs_gs | gs_gs | gs_obs)
            for c in np.flatnonzero(bad.any(axis=0)).tolist():
                r = int(np.flatnonzero(bad[:, c])[0])
                i, j = int(col[c]), int(idx[r])
                if trans[r, c]:
                    a, b = (j, i) if i_after[r, c] else (i, j)
                    gap = (s0[b] - s1[a]) / US
                    need = (t_ji[r, c] if i_after[r, c] else t_ij[r, c]) / US
                    why = (f"transition from task {scenario.tasks.ids[schedule.task[a]]} to task "
                           f"{scenario.tasks.ids[schedule.task[b]]} needs {need:.6g} s, has {gap:.6g} s")
                elif obs[r, c]:
                    why = "observation overlaps it"
                elif obs_gs[r, c]:
                    why = "observation overlaps its downlink"
                elif gs_gs[r, c]:
                    why = "downlink overlaps its downlink"
                else:
                    why = "downlink overlaps its observation"
                out[i] = f"against assignment {j}: {why}"
    return out


def _their_reasons(scenario: Scenario, schedule: Schedule, rules: Rules) -> dict[int, str]:
    """Why their checker refuses each assignment it refuses (the first rule of theirs that fails)."""
    m = len(schedule)
    has_gs = len(scenario.stations) > 0
    pairs = _pair_reasons(scenario, schedule, rules)
    out: dict[int, str] = {}
    seen: dict[int, int] = {}
    sats = scenario.satellites
    # rule 6: per-(satellite, orbit) sums in file order
    res: dict[int, str] = {}
    keys = schedule.satellite.astype(np.int64) * (1 << 32) + schedule.orbit
    for key in np.unique(keys).tolist():
        idx = np.flatnonzero(keys == key)
        sat, orbit = int(schedule.satellite[idx[0]]), int(schedule.orbit[idx[0]])
        cap_s, cap_p = float(sats.max_storage_gb[sat]), float(sats.max_power_w[sat])
        if cap_s <= 0 and cap_p <= 0:
            continue
        cum_s, cum_p = np.cumsum(schedule.data_gb[idx]), np.cumsum(schedule.power_w[idx])
        for n, i in enumerate(idx.tolist()):
            if cap_s > 0 and cum_s[n] - cap_s > 1e-9:
                res[i] = f"storage of orbit {orbit} would be {cum_s[n]:.9g} GB, over {cap_s:g} GB"
            elif cap_p > 0 and cum_p[n] - cap_p > 1e-9:
                res[i] = f"power of orbit {orbit} would be {cum_p[n]:.9g} W, over {cap_p:g} W"
    # rule 5: a station serves one downlink at a time
    station: dict[int, str] = {}
    for g in np.unique(schedule.station[schedule.station >= 0]).tolist():
        idx = np.flatnonzero(schedule.station == g)
        for n, i in enumerate(idx.tolist()):
            prior = idx[:n]
            hit = prior[_overlap(schedule.gs_start_us[i], schedule.gs_end_us[i], schedule.gs_start_us[prior],
                                 schedule.gs_end_us[prior])]
            if len(hit):
                station[i] = f"downlink overlaps assignment {int(hit[0])}'s at station {scenario.stations[g]}"
    for i in range(m):
        t = int(schedule.task[i])
        if t in seen:
            out[i] = f"task already assigned (assignment {seen[t]})"
        elif (schedule.end_us[i] - schedule.start_us[i]) / US + 1e-6 < scenario.tasks.duration_s[t]:
            out[i] = (f"lasts {(schedule.end_us[i] - schedule.start_us[i]) / US:g} s, the task needs "
                      f"{scenario.tasks.duration_s[t]:g} s")
        elif has_gs and schedule.station[i] < 0:
            out[i] = "no downlink (the scenario has ground stations)"
        elif has_gs and schedule.gs_start_us[i] <= schedule.end_us[i]:
            out[i] = "downlink does not start after the observation ends"
        elif i in pairs:
            out[i] = pairs[i]
        elif i in station:
            out[i] = station[i]
        elif i in res:
            out[i] = res[i]
        seen.setdefault(t, i)
    return out


def _generator_reason(scenario: Scenario, schedule: Schedule, i: int, windows: dict, rules: Rules) -> str | None:
    """The first of the generator's rules that assignment i breaks (see the module docstring), None if none."""
    w = scenario.windows
    t, s = int(schedule.task[i]), int(schedule.satellite[i])
    start, end = int(schedule.start_us[i]), int(schedule.end_us[i])
    rows = windows.get((t, s), np.zeros(0, np.int64))
    inside = [int(r) for r in rows if w.start_us[r] <= start and end <= w.end_us[r]]
    if not inside:
        return "not inside an observation window of its task on its satellite"
    # windows of one task and satellite may overlap: the assignment is the generator's if it is one of them
    same_orbit = [r for r in inside if w.orbit[r] == schedule.orbit[i]]
    ranked = same_orbit + [r for r in inside if r not in same_orbit]
    reasons = [_window_reason(scenario, schedule, i, r) for r in ranked]
    if all(why is not None for why in reasons):
        return reasons[0]
    g = int(schedule.station[i])
    if g >= 0:
        c = scenario.comm
        ok = (c.satellite == s) & (c.station == g) & (c.start_us <= schedule.gs_start_us[i]) & \
             (schedule.gs_end_us[i] <= c.end_us)
        if not ok.any():
            return "downlink not inside a communication window of its satellite and station"
        want = int(np.rint(scenario.tasks.duration_s[t] * rules.downlink_ratio * US))
        if abs(int(schedule.gs_end_us[i] - schedule.gs_start_us[i]) - want) > 1:
            return f"downlink lasts {(schedule.gs_end_us[i] - schedule.gs_start_us[i]) / US:g} s, not {want / US:g} s"
    return None


def _window_reason(scenario: Scenario, schedule: Schedule, i: int, r: int) -> str | None:
    """What breaks assignment i being the generator's candidate in window row r, None if nothing."""
    w, sats = scenario.windows, scenario.satellites
    t, s = int(schedule.task[i]), int(schedule.satellite[i])
    start, end = int(schedule.start_us[i]), int(schedule.end_us[i])
    step_us = int(round(w.step_s[r] * US))
    k = int(round((start - w.start_us[r]) / step_us))
    if w.start_us[r] + int(np.rint(k * w.step_s[r] * US)) != start:
        return f"starts off its window's {w.step_s[r]:g} s grid"
    dur_us = int(np.rint(scenario.tasks.duration_s[t] * US))
    if end - start != dur_us:
        return f"lasts {(end - start) / US:g} s, not the task's {scenario.tasks.duration_s[t]:g} s"
    if not sats.agile[s]:
        max_off = (w.end_us[r] - w.start_us[r]) / US - scenario.tasks.duration_s[t]
        max_k = int(np.floor((max_off + 1e-9) / w.step_s[r]))
        centre = max(0, min(max_k, int(round((max_off / 2.0) / w.step_s[r]))))
        if k != centre:
            return f"a non-agile satellite observes at its window's centre (step {centre}), not step {k}"
    if w.orbit[r] != schedule.orbit[i]:
        return f"orbit number {schedule.orbit[i]}, its window's is {w.orbit[r]}"
    if w.sensor_id[r] != schedule.sensor_id[i]:
        return f"sensor {schedule.sensor_id[i]!r}, its window's is {w.sensor_id[r]!r}"
    sensor = int(w.sensor[r])
    rate = float(sats.sensor_rate_mbps[sensor]) if sensor >= 0 else 0.0
    power = float(sats.sensor_power_w[sensor]) if sensor >= 0 else 0.0
    data = rate * ((end - start) / US) / (8.0 * 1024.0)
    if not np.isclose(schedule.data_gb[i], data, rtol=1e-12, atol=0.0):
        return f"data volume {schedule.data_gb[i]:.12g} GB, its sensor's is {data:.12g} GB"
    if not np.isclose(schedule.power_w[i], power, rtol=1e-12, atol=0.0):
        return f"power cost {schedule.power_w[i]:.12g} W, its sensor's is {power:.12g} W"
    lo, hi = int(schedule.att_ptr[i]), int(schedule.att_ptr[i + 1])
    if sats.agile[s]:
        a, n = attitude_slice(scenario, r, k)
        mine = np.stack([schedule.pitch[lo:hi], schedule.yaw[lo:hi], schedule.roll[lo:hi]])
        theirs = np.stack([w.pitch[a:a + n], w.yaw[a:a + n], w.roll[a:a + n]])
        if mine.shape != theirs.shape or not np.allclose(mine, theirs, rtol=1e-12, atol=1e-12):
            return "attitude is not its window's samples from its start"
    elif not np.allclose(schedule.fixed[i], w.fixed[r], rtol=1e-12, atol=1e-12, equal_nan=True):
        return "attitude is not its window's fixed attitude"
    return None


def check(scenario: Scenario, schedule: Schedule, rules: Rules = Rules()) -> Report:
    """`schedule` judged under `rules` (see the module docstring)."""
    theirs = _their_reasons(scenario, schedule, rules)
    their_first = min(theirs) if theirs else -1
    windows = scenario.windows_of()
    first, reason = -1, None
    for i in range(len(schedule)):
        why = theirs.get(i) or _generator_reason(scenario, schedule, i, windows, rules)
        if why is not None:
            first, reason = i, f"{_who(scenario, schedule, i)}: {why}"
            break
    their_reason = None if their_first < 0 else f"{_who(scenario, schedule, their_first)}: {theirs[their_first]}"
    return Report(rules, their_first, their_reason, first, reason, metrics(scenario, schedule))


def verdict(scenario: Scenario, schedule: Schedule, rules: Rules = Rules()) -> Verdict:
    """The kind's verdict: valid under `rules` (the documented transitions by default, their rules and their
    generator's); the code reading's verdict beside it (``valid_code``), the metrics by name."""
    rep = check(scenario, schedule, rules)
    other = check(scenario, schedule, Rules("code" if rules.transition == "documented" else "documented",
                                            rules.agility, rules.non_agile_s, rules.downlink_ratio))
    code, doc = (other, rep) if rules.transition == "documented" else (rep, other)
    mt = {**rep.metrics, "value": rep.metrics["TP"], "assignments": len(schedule),
          "valid_documented": int(doc.valid), "valid_code": int(code.valid), "valid_their_rules": int(code.their_first < 0)}
    m = rep.metrics
    figures = f"TP {m['TP']:.6g}, TCR {m['TCR']:.6f}, TM {m['TM']:.6f}, BD {m['BD']:.6f}"
    readings = (f"transitions as documented ({rules.agility}): {'valid' if doc.valid else 'invalid'}; "
                f"as their code applies them (11.66 s): {'valid' if code.valid else 'invalid'}")
    line = f"valid: {figures} ({readings})" if rep.valid else f"invalid: {rep.reason} ({figures}; {readings})"
    return Verdict(rep.valid, mt, rep.reason, line)
