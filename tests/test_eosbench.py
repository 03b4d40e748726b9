"""The EOS-Bench kind on small scenarios the tests write in their format: the streaming reader, both transition
readings, the checker against an independent replay of their rules, the solver (valid, bound above a brute-force
optimum), the command line and its one-line refusals."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eosp.budget import UNLIMITED
from eosp.cli import main
from eosp.eosbench.check import check, metrics
from eosp.eosbench.model import Schedule
from eosp.eosbench.read import read_scenario
from eosp.eosbench.schedules import read_schedule, schedule_json
from eosp.errors import InputError
from eosp.eosbench.transition import C_SMALL, Rules, documented_s, to_us, transition_s
from eosp.kinds.eosbench import solve as eosbench_solve
from eosp.kinds.eosbench.passes import build_passes, graph
from eosp.kinds.eosbench.dual import PriceLP
from eosp.kinds.eosbench.solve import (EosBenchConfig, State, _cap_term, bound_round, pack, solve, solve_pass,
                                       to_schedule)

T0 = datetime(2025, 11, 18, 12, 0, 0)


def iso(s: float) -> str:
    return (T0 + timedelta(seconds=s)).isoformat()


def scenario_json(windows: list[dict], n_sat: int = 2, n_task: int = 4, prio=None, dur=None, power: float = 50.0,
                  max_power: float = 500.0, agile: bool = True, duration: float = 21600.0) -> dict:
    """A scenario as their generator writes it.  `windows`: dicts (task, sat, start, length, orbit, pitch0, roll)
    with a pitch that turns 0.5 deg/s from pitch0."""
    prio = prio or [float(i % 10 + 1) for i in range(n_task)]
    dur = dur or [5.0 + (i % 3) * 5 for i in range(n_task)]
    sats = [{"id": f"SAT{s}", "orbital_type": "LEO", "satellite_specs": {
        "max_data_storage_GB": 1000.0, "max_operation_time_s": 4500.0, "max_power_W": max_power},
        "observation_capability": {"sensors": [{"sensor_id": f"SAT{s}_sensor", "data_rate_Mbps": 0.1,
                                                "power_consumption_W": power}]},
        "maneuverability_capability": {"maneuverability_type": "agile" if agile else "non_agile"}}
        for s in range(n_sat)]
    missions = [{"id": f"M{i:03d}", "priority": prio[i], "observation_requirement": {"duration_s": dur[i]}}
                for i in range(n_task)]
    obs = []
    for w in windows:
        n = int(w["length"])
        pitch = [w.get("pitch0", 0.0) + 0.5 * j for j in range(n)]
        tw = {"start_time": iso(w["start"]), "end_time": iso(w["start"] + n), "orbit_number": w.get("orbit", 1),
              "agile_data": {"pitch_angles": pitch, "yaw_angles": [0.1 * j for j in range(n)],
                             "roll_angles": [w.get("roll", 0.0)] * n},
              "non_agile_data": {"pitch_angle": pitch[n // 2], "yaw_angle": 0.0, "roll_angle": w.get("roll", 0.0)}}
        obs.append({"satellite_id": f"SAT{w['sat']}", "sensor_id": f"SAT{w['sat']}_sensor",
                    "mission_id": f"M{w['task']:03d}", "time_windows": [tw]})
    return {"scenario_id": "Scenario_T", "scenario_type": "basic",
            "metadata": {"name": "Scenario_T", "creation_time": T0.isoformat(), "duration": duration, "time_step": 1.0},
            "satellites": sats, "missions": missions, "observation_windows": obs}


def write(tmp_path: Path, data: dict, name: str = "scen.json") -> str:
    p = tmp_path / name
    p.write_text(json.dumps(data))
    return str(p)


# ---------------------------------------------------------------------------------------------- an independent replay


def replay(scen_data: dict, sched_data: dict, reading: str) -> tuple[int, dict]:
    """Their rules as plain Python over the JSON (datetimes, every pair, sums in order): the first assignment
    refused (-1 none) and TP, TCR, TM, BD."""
    dur = {m["id"]: m["observation_requirement"]["duration_s"] for m in scen_data["missions"]}
    prio = {m["id"]: m["priority"] for m in scen_data["missions"]}
    caps = {s["id"]: s["satellite_specs"] for s in scen_data["satellites"]}
    t = datetime.fromisoformat
    kept: list[dict] = []
    first = -1
    for i, a in enumerate(sched_data["assignments"]):
        s, e = t(a["sat_start_time"]), t(a["sat_end_time"])
        ok = all(b["task_id"] != a["task_id"] for b in kept) and (e - s).total_seconds() + 1e-6 >= dur[a["task_id"]]
        for b in (b for b in kept if b["satellite_id"] == a["satellite_id"]) if ok else ():
            bs, be = t(b["sat_start_time"]), t(b["sat_end_time"])
            prev, nxt = (b, a) if s >= bs else (a, b)
            if reading == "code":
                need = 11.66
            else:
                la = {k: prev["sat_angles"][k + "_angles"][-1] for k in ("pitch", "yaw", "roll")}
                fa = {k: nxt["sat_angles"][k + "_angles"][0] for k in ("pitch", "yaw", "roll")}
                dg = abs(fa["roll"] - la["roll"]) + abs(fa["pitch"] - la["pitch"]) + abs(fa["yaw"] - la["yaw"])
                v = (1.5, 2.0, 2.5, 3.0)
                need = 11.66 if dg <= 10 else 5 + dg / v[0] if dg <= 30 else 10 + dg / v[1] if dg <= 60 else \
                    16 + dg / v[2] if dg <= 90 else 22 + dg / v[3]
            if t(prev["sat_end_time"]) + timedelta(seconds=need) > t(nxt["sat_start_time"]) or not (e <= bs or s >= be):
                ok = False
                break
        if ok:
            cap = caps[a["satellite_id"]]
            same = [b for b in kept if b["satellite_id"] == a["satellite_id"] and b["orbit_number"] == a["orbit_number"]]
            pw = 0.0
            for b in same:
                pw += b["power_cost_W"]
            pw += a["power_cost_W"]
            ok = pw - cap["max_power_W"] <= 1e-9
        if not ok and first < 0:
            first = i
        kept.append(a)
    tasks = [m["id"] for m in scen_data["missions"]]
    assigned = {a["task_id"] for a in sched_data["assignments"]}
    horizon = scen_data["metadata"]["duration"]
    last = {a["task_id"]: a for a in sched_data["assignments"]}
    num = 0.0
    for tid in tasks:
        num += max(0.0, (t(last[tid]["sat_start_time"]) - T0).total_seconds()) if tid in last else horizon
    loads = {s["id"]: 0.0 for s in scen_data["satellites"]}
    for a in sched_data["assignments"]:
        loads[a["satellite_id"]] += (t(a["sat_end_time"]) - t(a["sat_start_time"])).total_seconds()
    mu = sum(loads.values()) / len(loads)
    bd = 1.0 - sum(abs(x - mu) for x in loads.values()) / (2.0 * sum(dur.values()))
    tp = 0.0
    for tid in tasks:
        tp += prio[tid] if tid in assigned else 0.0
    return first, {"TP": tp, "TCR": len(assigned) / len(tasks), "TM": num / (horizon * len(tasks)),
                   "BD": min(1.0, max(0.0, bd))}


def dense(n_task: int = 6, n_sat: int = 2, seed: int = 0, orbits: int = 2) -> dict:
    rng = np.random.default_rng(seed)
    wins = []
    for task in range(n_task):
        for sat in range(n_sat):
            for _ in range(int(rng.integers(1, 3))):
                wins.append({"task": task, "sat": sat, "start": float(rng.integers(0, 400)),
                             "length": int(rng.integers(20, 60)), "orbit": int(rng.integers(1, orbits + 1)),
                             "pitch0": float(rng.uniform(-30, 10)), "roll": float(rng.uniform(-20, 20))})
    return scenario_json(wins, n_sat=n_sat, n_task=n_task)


def candidates(scen) -> list[tuple[int, int]]:
    w = scen.windows
    out = []
    for r in range(len(w)):
        total = (w.end_us[r] - w.start_us[r]) / 1e6 - scen.tasks.duration_s[w.task[r]]
        out += [(r, k) for k in range(0, int(total) + 1, 3)]
    return out


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 10_000), picks=st.lists(st.integers(0, 10_000), min_size=1, max_size=14),
       reading=st.sampled_from(["code", "documented"]))
def test_the_checker_agrees_with_a_replay_of_their_rules(tmp_path, seed, picks, reading):
    data = dense(seed=seed)
    scen = read_scenario(write(tmp_path, data))
    cand = candidates(scen)
    sched = Schedule.build(scen, [cand[p % len(cand)] for p in picks])
    sdata = json.loads(json.dumps(schedule_json(sched, scen)))
    first, want = replay(data, sdata, reading)
    rep = check(scen, read_schedule(write(tmp_path, sdata, "s.json"), scen), Rules(reading))
    assert rep.their_first == first
    for k, v in want.items():
        assert rep.metrics[k] == pytest.approx(v, abs=1e-12), k
    assert rep.first == first  # the schedule comes from their candidates: the generator's rules all hold


def test_the_readings_differ_only_one_way(tmp_path):
    # two tasks 15 s apart on one satellite: 11.66 s is enough, a 40 deg attitude change is not (10 + 40/2 = 30 s)
    data = scenario_json([{"task": 0, "sat": 0, "start": 0, "length": 20, "pitch0": -20.0},
                          {"task": 1, "sat": 0, "start": 20, "length": 30, "pitch0": 35.0}], n_sat=1, n_task=2,
                         dur=[5.0, 5.0])
    scen = read_scenario(write(tmp_path, data))
    sched = Schedule.build(scen, [(0, 0), (1, 0)])  # 0-5 s, then 20-25 s: a 15 s gap
    code, doc = check(scen, sched, Rules("code")), check(scen, sched, Rules("documented"))
    assert code.valid and not doc.valid
    assert "needs" in doc.reason and "has 15 s" in doc.reason
    assert documented_s(np.array([10.0, 10.5, 30.0, 45.0, 90.0, 200.0])).tolist() == pytest.approx(
        [C_SMALL, 5 + 10.5 / 1.5, 5 + 20.0, 10 + 45 / 2, 16 + 90 / 2.5, 22 + 200 / 3])
    assert (documented_s(np.linspace(0, 270, 500)) >= C_SMALL).all()  # the code reading is the minimum


@given(st.floats(0, 200, allow_nan=False))
def test_transitions_round_as_their_datetime_arithmetic(x):
    assert to_us(np.array([x]))[0] == timedelta(seconds=x) // timedelta(microseconds=1)


def test_the_generator_rules_their_checker_trusts(tmp_path):
    data = scenario_json([{"task": 0, "sat": 0, "start": 0, "length": 40, "orbit": 2},
                          {"task": 1, "sat": 1, "start": 0, "length": 40}], n_task=2, dur=[5.0, 5.0])
    scen = read_scenario(write(tmp_path, data))
    good = schedule_json(Schedule.build(scen, [(0, 3), (1, 0)]), scen)
    assert check(scen, read_schedule(write(tmp_path, good, "g.json"), scen)).valid
    bad = {"orbit_number": (0, 1, "orbit number 1, its window's is 2"),
           "power_cost_W": (0, 10.0, "power cost 10 W, its sensor's is 50 W"),
           "sat_start_time": (0, iso(3.5), "off its window's 1 s grid")}
    for key, (i, value, why) in bad.items():
        data2 = json.loads(json.dumps(good))
        data2["assignments"][i][key] = value
        if key == "sat_start_time":
            data2["assignments"][i]["sat_end_time"] = iso(8.5)
        rep = check(scen, read_schedule(write(tmp_path, data2, f"{key}.json"), scen))
        assert rep.their_first < 0 and rep.first == i and why in rep.reason
    data2 = json.loads(json.dumps(good))
    data2["assignments"][1]["sat_angles"]["pitch_angles"][0] += 1.0
    assert "attitude" in check(scen, read_schedule(write(tmp_path, data2, "a.json"), scen)).reason
    data2["assignments"][1].update(sat_start_time=iso(100), sat_end_time=iso(105))
    assert "not inside an observation window" in check(scen, read_schedule(write(tmp_path, data2, "w.json"),
                                                                           scen)).reason
    for huge in (1e30, float("inf")):  # out of machine range: refused naming the entry (a traceback before)
        data3 = json.loads(json.dumps(good))
        data3["assignments"][0]["orbit_number"] = huge
        with pytest.raises(InputError, match=r"assignments\[0\]\.orbit_number: expected an integer of at most"):
            read_schedule(write(tmp_path, data3, "h.json"), scen)


def test_the_orbit_power_cap_counts_in_file_order(tmp_path):
    wins = [{"task": i, "sat": 0, "start": 20 * i, "length": 18, "orbit": 1} for i in range(12)]
    data = scenario_json(wins, n_sat=1, n_task=12, dur=[5.0] * 12)
    scen = read_scenario(write(tmp_path, data))
    sched = Schedule.build(scen, [(i, 0) for i in range(12)])
    rep = check(scen, sched, Rules("code"))
    assert rep.their_first == 10 and "power of orbit 1 would be 550 W, over 500 W" in rep.reason
    res = solve(scen, EosBenchConfig(time_limit=None, rounds=3, transition="code"))
    assert len(res.schedule) == 10 and check(scen, res.schedule, Rules("code")).valid
    top10 = np.sort(scen.tasks.priority)[::-1][:10].sum()
    assert res.value == top10 and res.bound == pytest.approx(top10)  # the cap's term is exact here


def brute_force(scen, rules: Rules) -> float:
    """The best profit over every set of candidate observations (all grid starts), by exhaustive search."""
    w = scen.windows
    cands = []
    for r in range(len(w)):
        total = (w.end_us[r] - w.start_us[r]) / 1e6 - scen.tasks.duration_s[w.task[r]]
        cands += [(r, k) for k in range(int(math.floor(total + 1e-9)) + 1)]
    best = 0.0

    def extend(chosen: list, start: int, tasks: set, value: float) -> None:
        nonlocal best
        best = max(best, value)
        for c in range(start, len(cands)):
            t = int(w.task[cands[c][0]])
            if t in tasks:
                continue
            trial = chosen + [cands[c]]
            if check(scen, Schedule.build(scen, trial), rules).their_first >= 0:
                continue
            extend(trial, c + 1, tasks | {t}, value + float(scen.tasks.priority[t]))

    extend([], 0, set(), 0.0)
    return best


@pytest.mark.parametrize("reading", ["code", "documented"])
def test_the_solver_is_valid_and_its_bound_holds_against_brute_force(tmp_path, reading):
    wins = [{"task": 0, "sat": 0, "start": 0, "length": 12, "pitch0": -30.0},
            {"task": 1, "sat": 0, "start": 10, "length": 12, "pitch0": 20.0},
            {"task": 2, "sat": 0, "start": 14, "length": 14, "pitch0": -10.0},
            {"task": 3, "sat": 0, "start": 30, "length": 10, "pitch0": 10.0},
            {"task": 1, "sat": 1, "start": 0, "length": 10},
            {"task": 3, "sat": 1, "start": 5, "length": 10}]
    data = scenario_json(wins, n_sat=2, n_task=4, prio=[3.0, 5.0, 4.0, 2.0], dur=[5.0, 5.0, 5.0, 5.0])
    scen = read_scenario(write(tmp_path, data))
    rules = Rules(reading)
    opt = brute_force(scen, rules)
    res = solve(scen, EosBenchConfig(time_limit=None, rounds=5, transition=reading))
    assert check(scen, res.schedule, rules).valid
    if reading == "documented":
        assert check(scen, res.schedule, Rules("code")).valid  # documented-valid is valid for both
    assert res.value <= opt + 1e-9 <= res.bound + 1e-9
    assert res.value == opt  # two satellites, four tasks: the passes are solved exactly
    again = solve(scen, EosBenchConfig(time_limit=None, rounds=5, transition=reading))
    assert schedule_json(again.schedule, scen) == schedule_json(res.schedule, scen)


def reference_arcs(p, rules: Rules, agile: bool, allowed: np.ndarray, release: int) -> list[list[int]]:
    """The pass graph's arcs by their definition, node by node: from the source, each acquisition's first allowed
    node starting at or after the release; from each allowed node u, for every other acquisition, its earliest
    allowed node x with start[x] >= end[u] + the transition from u to x (their checker's rule)."""
    out = [[] for _ in range(p.n_nodes)]
    k = len(p.acq_ptr) - 1
    for u in range(p.n_nodes):
        if not allowed[u]:
            continue
        for b in range(k):
            if u and b == p.node_acq[u]:
                continue
            for x in range(p.acq_ptr[b], p.acq_ptr[b + 1]):
                if not allowed[x]:
                    continue
                if u == 0:
                    ok = p.start_us[x] >= release
                else:
                    need = to_us(transition_s(rules, agile, p.last[u], p.first[x]))[0]
                    ok = p.start_us[x] >= p.end_us[u] + need
                if ok:
                    out[u].append(x)
                    break
    return out


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 10_000), reading=st.sampled_from(["code", "documented"]), agile=st.booleans(),
       share=st.floats(0.0, 1.0))
def test_pass_arcs_follow_their_definition_under_any_mask(tmp_path, seed, reading, agile, share):
    if reading == "code" and not agile:
        reading = "documented"  # the code reading has no non-agile rule
    rng = np.random.default_rng(seed)
    wins = [{"task": t % 5, "sat": 0, "start": float(rng.integers(0, 90)), "length": int(rng.integers(6, 40)),
             "pitch0": float(rng.uniform(-60, 40)), "roll": float(rng.uniform(-45, 45))} for t in range(8)]
    scen = read_scenario(write(tmp_path, scenario_json(wins, n_sat=1, n_task=5, agile=agile)))
    rules = Rules(reading)
    for p in build_passes(scen):
        allowed = rng.random(p.n_nodes) >= share
        allowed[0] = True
        release = int(rng.integers(0, 40)) * 1_000_000 + int(p.start_us[1:].min())
        g = graph(p, rules, agile, allowed, release)
        got = [sorted(g.dst[g.indptr[u]:g.indptr[u + 1]].tolist()) for u in range(p.n_nodes)]
        assert got == [sorted(x) for x in reference_arcs(p, rules, agile, allowed, release)]


def best_capped_path(p, pos: np.ndarray, cap: int) -> float:
    """The most utility a path of at most `cap` observations collects in pass p under the code reading, by
    enumeration (each observation starting 11.66 s or more after the previous one ends, distinct acquisitions)."""
    gap = to_us(np.array([C_SMALL]))[0]
    order = np.argsort(p.start_us[1:], kind="stable") + 1
    best = 0.0

    def extend(last: int, used: frozenset, value: float, left: int) -> None:
        nonlocal best
        best = max(best, value)
        if not left:
            return
        for x in order.tolist():
            a = int(p.node_acq[x])
            if a in used or pos[a] <= 0 or (last and p.start_us[x] < p.end_us[last] + gap):
                continue
            extend(x, used | {a}, value + float(pos[a]), left - 1)

    extend(0, frozenset(), 0.0, cap)
    return best


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 10_000), cap=st.integers(1, 3))
def test_the_capped_pass_term_bounds_every_capped_path(tmp_path, seed, cap):
    rng = np.random.default_rng(seed)
    wins = [{"task": t, "sat": 0, "start": float(rng.integers(0, 80)), "length": int(rng.integers(6, 12)),
             "pitch0": float(rng.uniform(-30, 30))} for t in range(5)]
    scen = read_scenario(write(tmp_path, scenario_json(wins, n_sat=1, n_task=5, dur=[5.0] * 5)))
    for p in build_passes(scen):
        p = dataclasses.replace(p, cap=cap)
        pos = np.round(rng.uniform(-1, 5, len(p.tasks)), 1)
        pos = np.maximum(pos, 0.0)
        if not (pos > 0).any():
            continue
        term, nodes, proven, fit = _cap_term(p, pos, lambda allowed: graph(p, Rules("code"), True, allowed), 10.0)
        assert len(fit) <= cap and float(pos[p.node_acq[fit]].sum()) <= best_capped_path(p, pos, cap) + 1e-9
        assert proven
        assert best_capped_path(p, pos, cap) <= term + 1e-9  # a bound on every path the cap allows
        assert term <= best_capped_path(p, pos, len(p.tasks)) + 1e-9  # never looser than the cap dropped


@pytest.mark.parametrize("seed", range(12))
def test_the_packing_of_paths_met_is_the_best_packing(tmp_path, monkeypatch, seed):
    """pack: the best choice of one committed path (or none) a pass, each task once, by enumeration over the
    columns (its fill left out: one orbit a satellite, no neighbouring passes, so the packing is the schedule);
    with the fill, a valid schedule at least as good."""
    data = dense(n_task=8, n_sat=3, seed=seed, orbits=1)
    rng = np.random.default_rng(seed)
    for m in data["missions"]:  # profits far apart: the most tasks is not the most profit
        m["priority"] = float(rng.choice([1.0, 2.0, 9.0, 20.0]))
    for sat in data["satellites"]:  # three observations an orbit: the passes contend for the tasks
        sat["satellite_specs"]["max_power_W"] = 150.0
    scen = read_scenario(write(tmp_path, data))
    rules = Rules("code")
    st = State(scen, rules, build_passes(scen), EosBenchConfig(transition="code"))
    for _ in range(6):  # paths of every pass under random utilities: the columns
        for k, p in enumerate(st.passes):
            st.commit(k, solve_pass(st, k, rng.uniform(0.1, 1.0, len(p.tasks)), UNLIMITED))
        for k in range(len(st.passes)):
            st.commit(k, np.zeros(0, np.int64))
    by_pass = [[np.frombuffer(t, dtype=np.int32) for (q, t) in st.columns if q == k] for k in range(len(st.passes))]
    best = 0.0
    for pick in itertools.product(*[[None, *cols] for cols in by_pass]):
        tasks = np.concatenate([c for c in pick if c is not None] or [np.zeros(0, np.int32)])
        if len(np.unique(tasks)) == len(tasks):
            best = max(best, float(st.prio[tasks].sum()))
    empty = (list(st.paths), st.served.copy())
    with monkeypatch.context() as m:
        m.setattr(eosbench_solve, "polish", lambda st: None)
        assert best > 0 and pack(st, None)
        assert st.value == pytest.approx(best)
    st.paths, st.served = empty
    assert pack(st, None) and st.value >= best - 1e-9
    assert check(scen, to_schedule(st), rules).valid


@pytest.mark.parametrize("seed", [0, 5])
def test_no_prices_bound_below_the_lp_of_the_relaxed_paths(tmp_path, seed):
    """dual.PriceLP: its LP over relaxed pass paths (those of the bound rounds) is a lower bound on L(lam) for every
    lam, and its smoothed duals give an L no lower than it either."""
    data = dense(n_task=8, n_sat=3, seed=seed, orbits=2)
    for sat in data["satellites"]:
        sat["satellite_specs"]["max_power_W"] = 150.0
    scen = read_scenario(write(tmp_path, data))
    st = State(scen, Rules("code"), build_passes(scen), EosBenchConfig(transition="code"))
    lp = PriceLP(st.prio, len(st.passes))
    rng = np.random.default_rng(seed)
    lam = np.zeros(len(scen.tasks))
    for _ in range(8):
        cols: list = []
        value, _, proven = bound_round(st, lam, cols)
        for k, tasks in cols:
            assert len(tasks) <= st.passes[k].cap
            lp.add(k, tasks)
        lam = lp.next_prices(lam, value if proven else math.inf, UNLIMITED)
    lp_value = lp._h.getInfo().objective_function_value
    assert lp_value > 0
    for _ in range(20):
        assert bound_round(st, rng.uniform(0, 12, len(scen.tasks)))[0] >= lp_value - 1e-6
    assert bound_round(st, lam)[0] >= lp_value - 1e-6


def tiny(seed: int) -> dict:
    """Four 5 s tasks, each seen by each of two satellites through one 6-8 s window in the first 40 s (2-4 starts)
    on one of two orbits, one observation an orbit (50 W cap, 50 W each): few enough candidates for the
    exhaustive search, crowded enough for transitions and the cap to bind."""
    rng = np.random.default_rng(seed)
    wins = [{"task": task, "sat": sat, "start": float(rng.integers(0, 40)), "length": int(rng.integers(6, 9)),
             "orbit": int(rng.integers(1, 3)), "pitch0": float(rng.uniform(-30, 10)), "roll": float(rng.uniform(-20, 20))}
            for task in range(4) for sat in range(2)]
    return scenario_json(wins, n_sat=2, n_task=4, dur=[5.0] * 4, max_power=50.0)


@pytest.mark.parametrize("seed", [1, 2, 4, 7])
@pytest.mark.parametrize("reading", ["code", "documented"])
@pytest.mark.parametrize("price_step", ["uniform", "lp"])
def test_the_bound_holds_on_random_scenarios(tmp_path, seed, reading, price_step):
    scen = read_scenario(write(tmp_path, tiny(seed)))
    res = solve(scen, EosBenchConfig(time_limit=None, rounds=4, transition=reading, price_step=price_step))
    assert check(scen, res.schedule, Rules(reading)).valid
    assert res.bound + 1e-9 >= brute_force(scen, Rules(reading)) >= res.value - 1e-9


def test_non_agile_satellites(tmp_path):
    wins = [{"task": 0, "sat": 0, "start": 0, "length": 21}, {"task": 1, "sat": 0, "start": 10, "length": 31}]
    data = scenario_json(wins, n_sat=1, n_task=2, dur=[5.0, 5.0], agile=False)
    path = write(tmp_path, data)
    scen = read_scenario(path)
    res = solve(scen, EosBenchConfig(time_limit=None, rounds=2))
    assert len(res.schedule) == 2 and check(scen, res.schedule).valid  # centred starts 8 and 23: 10 s apart
    rep = check(scen, res.schedule, Rules("code"))
    assert not rep.valid and "non-agile" in rep.reason
    assert main(["solve", path, "--solver", "eosbench", "--transition", "code", "--rounds", "1", "--out",
                 str(tmp_path / "o.json")]) == 2


def test_the_command_line(tmp_path, capsys):
    path = write(tmp_path, dense(seed=5))
    assert main(["info", path]) == 0
    assert "EOS-Bench scenario" in capsys.readouterr().out
    out = tmp_path / "s.json"
    assert main(["solve", path, "--solver", "eosbench", "--rounds", "2", "--time-limit", "0", "--out", str(out)]) == 0
    line = capsys.readouterr().out
    assert "TP" in line and "bound" in line
    assert main(["validate", path, str(out)]) == 0
    assert capsys.readouterr().out.startswith("valid: TP")
    # the code reading's schedule is judged under the code reading (the documented one may refuse it)
    code = tmp_path / "code.json"
    assert main(["solve", path, "--solver", "eosbench", "--transition", "code", "--rounds", "2", "--time-limit", "0",
                 "--out", str(code)]) == 0
    assert check(read_scenario(path), read_schedule(str(code), read_scenario(path)), Rules("code")).valid
    capsys.readouterr()
    data = json.loads(out.read_text())
    assert data["eosp"] == "eosbench-schedule" and set(data["metrics"]) == {"TP", "TCR", "BD", "TM", "RT", "RV"}
    data["assignments"].append(dict(data["assignments"][0]))
    bad = tmp_path / "dup.json"
    bad.write_text(json.dumps(data))
    assert main(["validate", path, str(bad)]) == 1
    assert "task already assigned" in capsys.readouterr().out
    assert main(["solve", path, "--solver", "eosbench", "--rounds", "1", "--out", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
    # the registry routes the path to this kind: its solvers and options, no other kind's
    for argv, words in ((["--solver", "greedy"], "invalid choice: 'greedy' (choose from 'eosbench')"),
                        (["--solver", "eosbench", "--moves", "3"], "no option --moves")):
        try:
            code = main(["solve", path, *argv, "--out", str(tmp_path / "g.json")])
        except SystemExit as exit_:  # the solver's own options are parsed once the solver is known
            code = exit_.code
        assert code == 2 and words in capsys.readouterr().err and not (tmp_path / "g.json").exists()


@pytest.mark.parametrize("mutate, words", [
    (lambda d: d["observation_windows"][0].update(mission_id="NOPE"), "observation_windows[0]: mission 'NOPE'"),
    (lambda d: d["observation_windows"][1]["time_windows"][0].update(end_time=iso(0)),
     "observation_windows[1].time_windows[0]: end_time"),
    (lambda d: d["missions"][2]["observation_requirement"].update(required_mode="sar"),
     "missions[2].observation_requirement.required_mode = 'sar': unsupported constraint"),
    (lambda d: d["satellites"][0]["satellite_specs"].update(max_power_W="lots"),
     "satellites[0].satellite_specs.max_power_W: expected a number"),
    (lambda d: d.update(constraints={"x": 1}), "unsupported top-level field 'constraints'"),
    (lambda d: d["observation_windows"][0]["time_windows"][0]["agile_data"].update(pitch_angles=[1.0]),
     "observation_windows[0].time_windows[0].agile_data: needs"),
    (lambda d: d["metadata"].pop("duration"), "metadata.duration missing"),
    # numbers out of machine range (robustness round 4, class 2): tracebacks or "TP": Infinity before
    (lambda d: d["observation_windows"][0]["time_windows"][0].update(orbit_number=1e30),
     "observation_windows[0].time_windows[0].orbit_number: expected an integer of at most"),
    (lambda d: d["metadata"].update(duration=1e300), "metadata.duration: 1e+300 is not in (0, 31,622,400]"),
    (lambda d: [m.update(priority=1e308) for m in d["missions"][:2]],
     "missions[1].priority: 1e+308 makes the priorities' sum overflow"),
    # class 10: a time step of 0 was taken as 1 s, attitudes of 1e300 made numpy warn
    (lambda d: d["metadata"].update(time_step=0), "metadata.time_step: 0 is not positive"),
    (lambda d: d["metadata"].update(time_step=-1), "metadata.time_step: -1 is not positive"),
    (lambda d: d["observation_windows"][0]["time_windows"][0]["agile_data"]["pitch_angles"].__setitem__(0, 1e300),
     "observation_windows[0].time_windows[0].agile_data.pitch_angles[0]: 1e+300 is not an angle"),
])
def test_a_malformed_scenario_is_one_line(tmp_path, capsys, mutate, words):
    data = dense(seed=7)
    mutate(data)
    path = write(tmp_path, data)
    assert main(["info", path]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and path in err and words in err, err


def test_a_scenario_with_a_byte_order_mark_is_named(tmp_path, capsys):
    path = tmp_path / "bom.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(dense(seed=8)).encode())
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "eosbench: starts with a UTF-8 byte-order mark" in err


def test_a_truncated_scenario_is_one_line(tmp_path, capsys):
    path = tmp_path / "cut.json"
    path.write_text(json.dumps(dense(seed=8))[:3000])
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not valid JSON" in err


def test_a_scenario_with_defaults_reads_as_their_loader(tmp_path):
    data = dense(seed=9)
    del data["missions"][0]["priority"]
    tw = data["observation_windows"][0]["time_windows"][0]
    del tw["orbit_number"]
    data["observation_windows"][0]["orbit_number"] = 4
    scen = read_scenario(write(tmp_path, data))
    assert scen.tasks.priority[0] == 1.0 and scen.windows.orbit[0] == 4
    assert scen.windows.att_ptr[-1] == sum(len(w["time_windows"][0]["agile_data"]["pitch_angles"])
                                           for w in data["observation_windows"])
    assert metrics(scen, Schedule.build(scen, []))["TM"] == 1.0
    assert list(itertools.islice(scen.ignored, 1)) == ["satellite_specs.max_operation_time_s"]


@pytest.mark.parametrize("change", ["end-9999", "time-step-tiny"])
def test_candidate_starts_are_bounded_by_the_attitude_samples(tmp_path, capsys, change):
    """A window stretched to the year 9999, or a time step of a microsecond, once asked for terabytes of candidate
    starts (issue 80, class 1): a start needs its attitude sample, so there are no more candidates than samples,
    and the solve ends with a schedule their checker accepts."""
    data = tiny(3)
    if change == "end-9999":
        data["observation_windows"][0]["time_windows"][0]["end_time"] = "9999-12-31T23:59:59+00:00"
    else:
        data["metadata"]["time_step"] = 1e-6
    path = write(tmp_path, data)
    out = tmp_path / "s.json"
    rc = main(["solve", path, "--solver", "eosbench", "--rounds", "2", "--time-limit", "0", "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    assert main(["validate", path, str(out)]) == 0


def test_ctrl_c_writes_the_best_schedule_so_far(tmp_path, capsys, monkeypatch):
    """Ctrl-C in the first price round (issue 80, class 8): the schedule built so far is checked and
    written, one line, exit 130 (before: "no feasible schedule found yet, nothing written")."""
    import eosp.kinds.eosbench.solve as eb

    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(eb, "bound_round", interrupt)
    path = write(tmp_path, dense(seed=5))
    out = tmp_path / "s.json"
    assert main(["solve", path, "--solver", "eosbench", "--rounds", "3", "--time-limit", "0", "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "wrote the best valid schedule so far" in err, err
    monkeypatch.undo()
    assert main(["validate", path, str(out)]) == 0
