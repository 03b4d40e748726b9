"""The operations simulator (eosp.ops.simulate) with the fleet solver's planners (eosp.kinds.fleet.operations) and
``eosp simulate``: every executed timeline valid by the checker, nothing served above the clairvoyant bound, the
same run for the same realization, plans that use nothing known only later (non-anticipativity), and the command's
run directory, Ctrl-C and resume."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eosp.cli import main
from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.geometry import Geometry
from eosp.fleet.io import write_fleet
from eosp.fleet.opportunities import compute
from eosp.kinds.fleet.operations import PLANNERS, SimulateConfig, Simulation
from eosp.ops import scenario
from eosp.ops.scenario import ScenarioConfig, make
from eosp.ops.simulate import Plan, clairvoyant_bound, simulate
from eosp.ops.world import realize


@pytest.fixture(scope="module")
def scen_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("sim")
    f = generate(FleetGenConfig(satellites=12, tasks=80, hours=6.0, placement="cities", seed=6))
    write_fleet(f, compute(f, Geometry(f)), root / "fleet")
    make(str(root / "fleet"), ScenarioConfig(urgent_per_hour=6, cadence_h=1, seed=3), str(root / "scen"))
    return root / "scen"


@pytest.fixture(scope="module")
def scen(scen_dir):
    return scenario.read(scen_dir)


@pytest.mark.parametrize("planner", PLANNERS)
def test_every_execution_is_valid_and_below_the_clairvoyant_bound(scen, planner):
    """Three realizations: the checker accepts every executed timeline (failed acquisitions included), what is
    served never exceeds the clairvoyant bound, some acquisitions fail (clouds) and a planner that re-plans makes
    more than one call; a realization run twice gives the same run."""
    sim = Simulation.of(scen, SimulateConfig(planner=planner, rounds=3, time_limit=60.0))
    try:
        got = [sim.run(i) for i in range(3)]
        again = sim.run(1)
    finally:
        sim.close()
    for r in got:
        assert r["valid"] is True and r["violation"] is None
        assert 0 < r["served"] <= r["bound"] + 1e-12 and r["regret"] >= -1e-12
        assert r["clairvoyant_schedule"] <= r["bound"] + 1e-12 and r["bound"] <= r["conflict_free_bound"]
        assert len(r["calls"]) == (1 if planner == "plan-once" else len(realize(scen, 0).calls_s))
    assert sum(r["failed"] for r in got) > 0
    timed = ("calls", "compute_s")
    assert {k: v for k, v in again.items() if k not in timed} == {k: v for k, v in got[1].items() if k not in timed}


def test_the_clairvoyant_bound_is_the_weight_of_requests_with_a_clear_opportunity(scen):
    """Recomputed request by request, each opportunity's outcome from the world."""
    day = Simulation.of(scen, SimulateConfig(rounds=1)).day
    w = realize(scen, 0)
    want = sum(day.weight[j] for j in range(len(day.weight))
               if any(w.clear[r] and day.start_s[r] >= w.arrival_s[j] for r in np.flatnonzero(day.task == j)))
    assert clairvoyant_bound(day, w) == pytest.approx(want, abs=1e-9)


def clairvoyant_optimum(prob, values) -> float:
    """The most any day of pass paths serves under per-(pass, task) `values`, each task credited once at a pass
    where its value is positive, the battery left out: every task set of every pass enumerated along its graph's
    arcs, then an exact integer program over them (scipy's milp; nothing of the solver)."""
    from scipy.optimize import Bounds, LinearConstraint, milp

    from tests.test_fleet_master import every_task_set

    cols = []  # (pass, the tasks it credits)
    for p, pg in enumerate(prob.passes):
        v = dict(zip(pg.tasks.tolist(), values[prob.task_ptr[p]:prob.task_ptr[p + 1]].tolist()))
        credit = {frozenset(t for t in c if v[t] > 0) for c in every_task_set(prob, p)}
        cols += [(p, c) for c in credit if c]
    n, P, C = len(prob.weight), len(prob.passes), len(cols)
    # variables: x_c (a pass's task set), then y_j (task j credited)
    cover = np.zeros((n, C + n))  # y_j <= sum of the x_c crediting j
    one = np.zeros((P, C + n))  # a pass takes one set
    for i, (p, c) in enumerate(cols):
        one[p, i] = 1
        for t in c:
            cover[t, i] = -1
    cover[np.arange(n), C + np.arange(n)] = 1
    cost = np.r_[np.zeros(C), -prob.weight]
    res = milp(cost, integrality=np.ones(C + n), bounds=Bounds(0, 1),
               constraints=[LinearConstraint(cover, -np.inf, 0), LinearConstraint(one, 0, 1)])
    assert res.success
    return -res.fun / prob.weight.sum()


@pytest.fixture(scope="module")
def sims(scen):
    out = [Simulation.of(scen, SimulateConfig(planner=p, rounds=4, time_limit=60.0)) for p in PLANNERS]
    yield out
    for s in out:
        s.close()


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(index=st.integers(0, 1_000_000))
def test_the_clairvoyant_bound_against_an_exact_optimum(scen, sims, index):
    """Realizations drawn by hypothesis: what every planner serves <= the clairvoyant optimum (an exact integer
    program over every pass's task sets, battery left out) <= the clairvoyant bound the fleet solver proves; the
    clairvoyant schedule executed serves at most the optimum."""
    from eosp.kinds.fleet.operations import clairvoyant_values

    w = realize(scen, index)
    runs = [s.run(index) for s in sims]
    prob = sims[0].planner.prob
    best = clairvoyant_optimum(prob, clairvoyant_values(prob, w))
    for r in runs:
        assert r["served"] <= best + 1e-12 <= r["bound"] + 2e-12, (index, r["served"], best, r["bound"])
        assert r["clairvoyant_schedule"] <= best + 1e-12
    assert runs[0]["bound"] == runs[1]["bound"] == runs[2]["bound"]  # the realization's, whoever planned


class Peeking:
    """A planner that reads the realized clouds (what no planner may know): it keeps only the opportunities that
    will succeed.  The non-anticipativity check must catch it."""

    name = "peeking"

    def __init__(self, inner, world):
        self.inner, self.world = inner, world

    def plan(self, know):
        got = self.inner.plan(know)
        return Plan(got.rows[self.world.clear[got.rows]], got.compute_s, got.info)


def plans_before(run, world, t: float) -> list:
    return [(call, rows.tolist()) for call, rows in run.plans if world.calls_s[call] <= t]


@pytest.mark.parametrize("planner", ["replan", "ev-replan"])
def test_plans_use_nothing_known_only_later(scen, planner):
    """Non-anticipativity: clouds, forecasts and arrivals redrawn after a time t leave every plan made up to t
    (every plan uploaded up to t among them) unchanged, for three times t; the runs do differ after t (the test
    can fail), and a planner that peeks at the realized clouds is caught."""
    sim = Simulation.of(scen, SimulateConfig(planner=planner, rounds=3, time_limit=60.0))
    w = realize(scen, 2)
    base = sim.simulate(w)
    rng = np.random.default_rng(0)
    differ = 0
    for t in w.calls_s[1:4] + 600.0:
        other = w.perturbed_after(float(t), rng, sim.day.start_s)
        run = sim.simulate(other)
        assert plans_before(run, other, t) == plans_before(base, w, t), t
        differ += [r.tolist() for _, r in run.plans] != [r.tolist() for _, r in base.plans]
    assert differ > 0
    t = float(w.calls_s[2] + 600.0)
    other = w.perturbed_after(t, rng, sim.day.start_s)
    a = simulate(sim.day, w, Peeking(sim.planner, w), 60.0)
    sim.planner.reset()
    b = simulate(sim.day, other, Peeking(sim.planner, other), 60.0)
    assert plans_before(a, w, t) != plans_before(b, other, t)
    sim.close()


def test_eosp_simulate_writes_a_summary_resumes_and_keeps_what_ctrl_c_leaves(scen_dir, tmp_path, capsys,
                                                                             monkeypatch):
    out = tmp_path / "run"
    argv = ["simulate", str(scen_dir), "--planner", "replan", "--rounds", "2", "--time-limit", "60", "--out",
            str(out)]
    real_run = Simulation.run
    calls = []

    def stop_at_second(self, index):
        calls.append(index)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real_run(self, index)

    monkeypatch.setattr(Simulation, "run", stop_at_second)
    assert main([*argv, "--realizations", "3"]) == 130
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "interrupted" in err and "over 1 realizations" in err
    assert len(json.loads((out / "summary.json").read_text())["realizations"]) == 1
    monkeypatch.setattr(Simulation, "run", real_run)
    assert main([*argv, "--realizations", "3"]) == 2  # exists: --resume or --overwrite
    assert "already exists" in capsys.readouterr().err
    assert main([*argv, "--realizations", "3", "--resume"]) == 0
    line = capsys.readouterr().out
    assert line.count("\n") == 1 and "replan over 3 realizations" in line and "3 of 3 executions valid" in line
    body = json.loads((out / "summary.json").read_text())
    assert [r["realization"] for r in body["realizations"]] == [0, 1, 2]
    assert body["means"]["served"] == pytest.approx(np.mean([r["served"] for r in body["realizations"]]))
    assert main([*argv, "--realizations", "3", "--resume", "--seed", "5"]) == 2  # other options
    assert "another scenario or other options" in capsys.readouterr().err


def test_bad_scenarios_and_run_directories_are_refused_in_one_line(scen_dir, tmp_path, capsys):
    mine = tmp_path / "notes"
    mine.mkdir()
    (mine / "keep.txt").write_text("a user's file")
    assert main(["simulate", str(scen_dir), "--out", str(mine), "--rounds", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a run directory written by eosp simulate" in err
    assert sorted(p.name for p in mine.iterdir()) == ["keep.txt"]
    broken = tmp_path / "scen"
    broken.mkdir()
    (broken / "meta.json").write_text(json.dumps({"kind": "eosp-operations-scenario", "schema_version": 99}))
    out = tmp_path / "run"
    assert main(["simulate", str(broken), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "schema_version" in err and not out.exists()
    with pytest.raises(SystemExit) as stop:  # argparse's exit, as for every option
        main(["simulate", str(scen_dir), "--out", str(out), "--planner", "oracle"])
    assert stop.value.code == 2 and not out.exists()
    assert "--planner: must be one of plan-once, replan, ev-replan" in capsys.readouterr().err


@pytest.mark.ray
def test_the_ray_job_runs_realizations_resumes_and_logs_to_mlflow(scen, scen_dir, tmp_path, capsys):
    """jobs/simulate_operations.py on a local Ray (two actors): the same realizations as in this process, resumed
    by a rerun with more of them, each run in MLflow with its figures and summary.json."""
    import mlflow
    import ray

    from eosp.jobs import simulate_operations as job

    uri = f"sqlite:///{tmp_path}/mlflow.db"
    out = tmp_path / "run"
    argv = ["--scenario", str(scen_dir), "--out", str(out), "--sim.planner", "ev-replan", "--sim.rounds", "2",
            "--sim.time-limit", "60", "--mlflow-uri", uri, "--ray.num-cpus", "2"]
    try:
        assert job.main([*argv, "--sim.realizations", "2"]) == 0
        body = json.loads((out / "summary.json").read_text())
        assert [r["realization"] for r in body["realizations"]] == [0, 1] and body["means"]["valid"] == 2
        here = Simulation.of(scen, SimulateConfig(planner="ev-replan", rounds=2, time_limit=60.0)).run(1)
        timed = ("calls", "compute_s")
        assert {k: v for k, v in body["realizations"][1].items() if k not in timed} == \
            {k: v for k, v in here.items() if k not in timed}
        capsys.readouterr()
        assert job.main([*argv, "--sim.realizations", "3"]) == 0
        printed = capsys.readouterr().out
        assert "resuming: 2 of 3 realizations done" in printed and printed.count("] realization ") == 1
        mlflow.set_tracking_uri(uri)
        runs = mlflow.search_runs(experiment_names=["eosp-operations"])
        assert len(runs) == 2 and runs["metrics.mean/served"].notna().all()
        assert set(runs["params.sim.planner"]) == {"ev-replan"}
    finally:
        ray.shutdown()


@pytest.fixture(scope="module")
def clustered(tmp_path_factory):
    """Targets in four clusters: passes with several primaries, where a thinned plan leaves gaps to fill."""
    from tests.conftest import clustered_scenario

    return scenario.read(clustered_scenario(tmp_path_factory.mktemp("clustered")))


def test_the_onboard_rule_takes_alternates_that_keep_every_timeline_valid(clustered):
    """A plan thinned to leave gaps (every other primary of the first plan dropped), alternates chosen for it
    (one per gap, fitting there, battery held), then flown in two worlds: where every primary is cloudy each
    alternate whose task is still open is taken, where every primary is clear none is; both executions pass the
    checker, as does the plan with every alternate in."""
    import dataclasses

    from eosp.fleet.check import validate
    from eosp.kinds.fleet.candidates import alternates, onboard_test
    from eosp.ops.onboard import Onboard
    from eosp.ops.simulate import Sent, execute

    sim = Simulation.of(clustered, SimulateConfig(planner="replan", rounds=3, time_limit=60.0))
    prob, day = sim.planner.prob, sim.day
    w = realize(clustered, 0)
    first = sim.simulate(w).plans[0][1]
    first = first[np.lexsort((day.start_s[first], day.sat[first]))]
    thin = first[::2]
    frozen = np.zeros(len(prob.passes), dtype=bool)
    alt, alt_of = alternates(prob, thin, frozen, prob.weight[prob.opps.task])
    assert len(alt) >= 3 and set(alt_of.tolist()) <= set(thin.tolist())  # 4 here
    assert validate(prob.fleet, sim.planner.schedule(np.sort(np.r_[thin, alt])), prob.geo).valid
    for clear, expect in ((False, len(alt)), (True, 0)):
        world = dataclasses.replace(w, clear=np.where(np.isin(np.arange(len(w.clear)), thin), clear, True))
        sent = Sent(prim=np.sort(thin), alt=alt, alt_of=alt_of)
        execute(day, world, sent, math.inf, Onboard(onboard_test(prob)))
        done = np.asarray(sent.done)
        assert len(sent.taken) == expect and len(done) == len(thin) + expect
        assert validate(prob.fleet, sim.planner.schedule(np.sort(done)), prob.geo).valid
    sim.close()


def test_the_rule_that_looks_ahead_replaces_cloudy_primaries_where_it_can_fly_the_replacement(clustered):
    """Replacements for a plan (per primary, one that fits in its place), flown in two worlds: where every primary
    is cloudy, each is skipped for its replacement when the satellite can fly it (slews checked against what it
    really flew, the battery) and flown as sent otherwise; where every primary is clear, none is replaced; both
    executions pass the checker; a replacement never shares its primary's pass with another's task twice."""
    import dataclasses

    from eosp.fleet.check import validate
    from eosp.kinds.fleet.candidates import onboard_test, replacements
    from eosp.ops.onboard import Onboard
    from eosp.ops.simulate import Sent, execute

    sim = Simulation.of(clustered, SimulateConfig(planner="replan", rounds=3, time_limit=60.0))
    prob, day = sim.planner.prob, sim.day
    w = realize(clustered, 0)
    plan = np.sort(sim.simulate(w).plans[0][1])
    frozen = np.zeros(len(prob.passes), dtype=bool)
    rep, rep_of = replacements(prob, plan, frozen, prob.weight[prob.opps.task])
    o = prob.opps
    assert len(rep) >= 3 and set(rep_of.tolist()) <= set(plan.tolist()) and len(set(rep_of.tolist())) == len(rep)
    assert (o.pass_id[rep] == o.pass_id[rep_of]).all() and not np.isin(o.task[rep], o.task[plan]).any()
    assert len(set(o.task[rep].tolist())) == len(rep)
    for k in range(len(rep)):  # each fits in its primary's place (the rest of the plan as it is)
        swapped = np.sort(np.r_[plan[plan != rep_of[k]], rep[k]])
        assert validate(prob.fleet, sim.planner.schedule(swapped), prob.geo).valid
    for clear, replaced in ((False, True), (True, False)):
        world = dataclasses.replace(w, clear=np.where(np.isin(np.arange(len(w.clear)), plan), clear, True))
        sent = Sent(prim=plan, alt=rep, alt_of=rep_of)
        execute(day, world, sent, math.inf, Onboard(onboard_test(prob, slews=True), ahead=True))
        done = np.asarray(sent.done)
        assert (len(sent.taken) > 0) == replaced and len(done) == len(plan)
        skipped = set(plan.tolist()) - set(done.tolist())
        assert skipped == {int(rep_of[list(rep).index(a)]) for a in sent.taken}
        assert validate(prob.fleet, sim.planner.schedule(np.sort(done)), prob.geo).valid
    sim.close()


@pytest.mark.parametrize("onboard", ["none", "rule", "lookahead"])
def test_every_execution_is_valid_with_and_without_an_onboard_rule(clustered, onboard):
    sim = Simulation.of(clustered, SimulateConfig(planner="ev-replan", onboard=onboard, rounds=3, time_limit=60.0))
    for index in range(2):
        r = sim.run(index)
        assert r["valid"] is True and r["served"] <= r["bound"] + 1e-12
        assert onboard != "none" or r["alternates_taken"] == 0
    sim.close()


def test_the_replay_page_in_headless_chromium(clustered, tmp_path, chromium, capsys):
    """``eosp simulate --replay 1``: the fleet page of the day as executed with the replay's sections opens from its
    file with no request and no script error; the fleet page's Gantt draws every acquisition flown with no checker
    violation, the replay every acquisition (served, cloudy, alternates as the figures count them), every contact
    and upload, a row per contact where something was reported or uploaded, a row per urgent request."""
    from tests.browser import Browser

    out = tmp_path / "run"
    assert main(["simulate", str(clustered.path), "--planner", "ev-replan", "--onboard", "rule", "--rounds", "3",
                 "--realizations", "1", "--replay", "1", "--out", str(out)]) == 0
    capsys.readouterr()
    fig = json.loads((out / "summary.json").read_text())["realizations"][0]
    page = out / "replay-0000.html"
    with Browser(chromium, tmp_path / "chromium.log") as b:
        b.open(page)
        got = b.evaluate("window.replay")
        fleet = b.evaluate("[window.fleetPage.ready, window.fleetPage.drawn.gantt.bars, "
                           "window.fleetPage.drawn.gantt.violations, document.body.dataset.schedules]")
        counts = b.evaluate("[document.querySelectorAll('rect.acq').length, "
                            "document.querySelectorAll('tr.contact').length, "
                            "document.querySelectorAll('tr.request').length, "
                            "document.querySelectorAll('path.upload').length]")
        errors, requests = b.errors(), b.requests()
    assert errors == [] and requests == [page.resolve().as_uri()]
    assert fleet == [True, fig["acquisitions"], 0, "1"]
    d = got["drawn"]
    assert got["ready"] and d["acquisitions"] == fig["acquisitions"] == counts[0]
    assert d["cloudy"] == fig["failed"] and d["alternates"] == fig["alternates_taken"]
    assert d["contacts"] == len(clustered.contacts) and counts[1] == got["contactRows"] > 0
    assert counts[2] == int(clustered.urgent.sum()) and d["uploads"] == counts[3] > 0


@pytest.mark.ray
@pytest.mark.extended
def test_ctrl_c_of_the_ray_job_keeps_its_realizations(scen_dir, tmp_path):
    """SIGINT to the process group of jobs/simulate_operations.py once a realization is written: one line of the
    job's with the means of those kept, exit 130, no traceback; a rerun goes on from them."""
    import sys

    from eosp.jobs import simulate_operations as job
    from tests.test_bad_inputs import _interrupt

    out = tmp_path / "run"
    args = ["--scenario", str(scen_dir), "--out", str(out), "--sim.planner", "replan", "--sim.rounds", "3",
            "--sim.time-limit", "60", "--mlflow-uri", f"sqlite:///{tmp_path}/mlflow.db", "--ray.num-cpus", "2"]
    rc, err, took = _interrupt([sys.executable, "-m", "eosp.jobs.simulate_operations", *args,
                                "--sim.realizations", "200"], out / "summary.json", cwd=tmp_path)
    ours = [x for x in err.splitlines() if x.startswith("simulate_operations.py:")]
    assert rc == 130 and len(ours) == 1 and "Traceback" not in err, err
    assert "interrupted" in ours[0] and "executions valid" in ours[0] and took < 30.0, (ours, took)
    kept = json.loads((out / "summary.json").read_text())["realizations"]
    assert 1 <= len(kept) < 200
    n = len(kept) + 1
    try:
        assert job.main([*args, "--sim.realizations", str(n)]) == 0
    finally:
        import ray

        ray.shutdown()
    assert len(json.loads((out / "summary.json").read_text())["realizations"]) == n
