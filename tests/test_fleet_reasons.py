"""Reasons for missed fleet tasks (eosp.fleet.reasons): every verdict confirmed by the checker on the changed schedule."""

import dataclasses

import numpy as np
import pytest

from eosp.fleet.check import validate
from eosp.fleet.geometry import Geometry
from eosp.fleet.greedy import solve
from eosp.fleet.model import US, Schedule, strings
from eosp.fleet.opportunities import compute
from eosp.fleet.reasons import (BLOCKED, BLOCKED_NONE, ENERGY, INSERTABLE, KINDS, NO_OPP, SENSOR, describe,
                                explain)
from tests.test_fleet import synthetic_fleet


def with_row(s: Schedule, sat: str, task: str, st_s: float, dur_s: float, drop=None) -> Schedule:
    keep = np.ones(len(s), dtype=bool) if drop is None else ~drop
    return Schedule(np.r_[s.satellite[keep], strings([sat])], np.r_[s.task[keep], strings([task])],
                    np.r_[s.start_us[keep], [round(st_s * US)]].astype(np.int64),
                    np.r_[s.end_us[keep], [round((st_s + dur_s) * US)]].astype(np.int64))


def thinned(fleet, geo, opps, every: int) -> Schedule:
    """Greedy's schedule with every `every`-th observation dropped, when the checker still accepts it (value left
    on the table for the reasons to find)."""
    s = solve(fleet, opps, geo)
    keep = np.arange(len(s)) % every != 1
    out = Schedule(s.satellite[keep], s.task[keep], s.start_us[keep], s.end_us[keep])
    return out if validate(fleet, out, geo).valid else s


def odd_tasks(fleet):
    """Task 0 needs a sensor nobody carries, task 1 lies far from every track."""
    tk = fleet.tasks
    sensor = tk.sensor.copy()
    sensor[0] = "infrared"
    lat = tk.lat_deg.copy()
    lat[1] = -lat[1] if abs(lat[1]) > 30 else lat[1] + 60.0
    return dataclasses.replace(fleet, tasks=dataclasses.replace(tk, sensor=strings(sensor.tolist()), lat_deg=lat))


def weak(fleet):
    b = fleet.satellites.battery
    w = dataclasses.replace(b, initial_wh=np.array([6.0, 6.0]), capacity_wh=np.array([6.0, 6.0]),
                            idle_w=np.array([1.0, 1.0]), imaging_w=np.array([600.0, 600.0]), sunlit_w=np.zeros(2))
    return dataclasses.replace(fleet, satellites=dataclasses.replace(fleet.satellites, battery=w))


CASES = {"thinned": lambda: odd_tasks(synthetic_fleet(40, seed=5)), "weak battery": lambda: weak(synthetic_fleet(40, 5))}


@pytest.mark.parametrize("name", list(CASES))
def test_reasons_agree_with_the_checker(name):
    fleet = CASES[name]()
    geo = Geometry(fleet)
    opps = compute(fleet, geo)
    s = thinned(fleet, geo, opps, 3) if name == "thinned" else solve(fleet, opps, geo)
    assert validate(fleet, s, geo).valid
    r = explain(fleet, opps, s, geo)
    tk, sats = fleet.tasks, fleet.satellites
    served = set(s.task.tolist())
    assert sorted(tk.ids[r.task].tolist()) == sorted(set(tk.ids.tolist()) - served)
    per_task = opps.per_task(len(tk))
    seen = set()
    for i in range(len(r)):
        t, k = int(r.task[i]), int(r.kind[i])
        seen.add(k)
        text = describe(fleet, r, i)
        assert text.startswith(KINDS[k].split(",")[0]), text
        if k == SENSOR:
            assert tk.sensor[t] not in set(sats.sensor.tolist())
            continue
        if k == NO_OPP:
            assert per_task[t] == 0
            continue
        if k == BLOCKED_NONE:
            assert per_task[t] > 0
            continue
        sat, st = str(sats.ids[r.satellite[i]]), float(r.start_s[i])
        assert (st / fleet.horizon.action_step_s) in set(opps.start[(opps.task == t) &
                                                                     (opps.satellite == r.satellite[i])].tolist())
        plain = validate(fleet, with_row(s, sat, str(tk.ids[t]), st, float(tk.duration_s[t])), geo)
        if k == INSERTABLE:
            assert plain.valid, (text, plain.first)
            assert "value left on the table" in text
        elif k == ENERGY:
            assert not plain.valid and {v.stage for v in plain.violations} == {"battery"}, (text, plain.violations)
        else:
            assert k == BLOCKED
            names = [str(tk.ids[b]) for b in r.blockers[i] if b >= 0]
            assert 1 <= len(names) <= 3 and all(n in text for n in names)
            assert not plain.valid and "battery" not in {v.stage for v in plain.violations}
            drop = (s.satellite == sat) & np.isin(s.task, names)
            assert drop.sum() == len(names)
            freed = validate(fleet, with_row(s, sat, str(tk.ids[t]), st, float(tk.duration_s[t]), drop), geo)
            assert freed.valid, (text, freed.first)
    if name == "thinned":
        assert {SENSOR, NO_OPP, INSERTABLE, BLOCKED} <= seen, seen
    else:
        assert ENERGY in seen, seen


def test_reasons_of_an_empty_schedule_are_all_insertable_or_not_servable():
    fleet = synthetic_fleet(12, seed=2)
    geo = Geometry(fleet)
    opps = compute(fleet, geo)
    r = explain(fleet, opps, Schedule.empty(), geo)
    assert len(r) == 12
    per_task = opps.per_task(12)
    assert np.all((r.kind == INSERTABLE) == (per_task[r.task] > 0))


def test_a_schedule_missing_nothing_has_no_reasons():
    fleet = synthetic_fleet(1, seed=2)
    geo = Geometry(fleet)
    opps = compute(fleet, geo)
    s = solve(fleet, opps, geo)
    assert len(s) == 1 and len(explain(fleet, opps, s, geo)) == 0
