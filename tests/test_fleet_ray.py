"""The fleet solver on Ray (jobs/solve_fleet.py): two nodes give the one-process result, a killed actor and a
killed driver are survived, and bad run dirs or addresses are refused in one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.geometry import Geometry
from eosp.fleet.io import read_fleet, read_schedule, write_fleet
from eosp.fleet.opportunities import compute
from eosp.jobs import solve_fleet as job_mod
from eosp.budget import UNLIMITED
from eosp.kinds.fleet.config import FleetConfig
from eosp.kinds.fleet.problem import PassSpec
from eosp.kinds.fleet.raypool import RayPassPool

ROUNDS = 2


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory):
    f = generate(FleetGenConfig(satellites=6, tasks=400, hours=4.0, window_min_h=1.0, window_max_h=3.0, seed=5))
    out = tmp_path_factory.mktemp("fleet") / "fleet"
    write_fleet(f, compute(f, Geometry(f)), out)
    return out


@pytest.fixture(scope="module")
def clustered_fleet_dir(tmp_path_factory):
    """A fleet whose solve is not proven optimal in 3 rounds (the one above is, at round 0, by the ceiling
    prices' bound: a resumed run would have nothing left to do)."""
    f = generate(FleetGenConfig(satellites=6, tasks=400, hours=4.0, window_min_h=1.0, window_max_h=3.0, seed=5,
                                placement="clusters"))
    out = tmp_path_factory.mktemp("fleet") / "clustered"
    write_fleet(f, compute(f, Geometry(f)), out)
    return out


@pytest.fixture(scope="module")
def two_nodes():
    """A Ray cluster of two nodes on this machine (one CPU each), the driver attached to it."""
    import ray
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    yield cluster
    ray.shutdown()
    cluster.shutdown()


def job(fleet_dir, run_dir, workers=1, address="", rounds=ROUNDS, mlflow_dir=None, lean="auto"):
    return job_mod.SolveFleetJob(
        fleet_dir=str(fleet_dir), run_dir=str(run_dir), lean_driver=lean,
        fleet=FleetConfig(pass_solver="exact", rounds=rounds, time_limit=None, workers=workers, seed=0),
        mlflow_uri=f"sqlite:///{mlflow_dir or run_dir.parent}/mlflow.db",
        ray=job_mod.RayConfig(address=address, num_cpus=2))


def schedule_rows(fleet_dir, path):
    fleet, _ = read_fleet(fleet_dir, with_opportunities=False)
    s, _ = read_schedule(path, fleet)
    return sorted(zip(s.satellite.tolist(), s.task.tolist(), s.start_us.tolist()))


@pytest.mark.parametrize("lean", ["no", "yes"])
def test_two_nodes_give_the_single_process_schedule_and_a_killed_actor_costs_nothing(fleet_dir, two_nodes,
                                                                                    tmp_path, monkeypatch, lean):
    """With the driver holding every graph, and lean (the actors' graphs only, every solve theirs)."""
    alone = job_mod.run(job(fleet_dir, tmp_path / "alone"))
    spread = job_mod.run(job(fleet_dir, tmp_path / "spread", workers=2, address=two_nodes.address, lean=lean))
    assert spread["nodes"] == 2  # one actor on each node
    assert spread["lean_driver"] == (lean == "yes") and spread["actor_graph_mb"] > 0
    assert spread["bound_graphs"] == alone["bound_graphs"]
    assert spread["faults"] == 0
    assert (spread["value"], spread["bound"]) == (alone["value"], alone["bound"])
    assert alone["value"] > 0 and alone["bound"] >= alone["value"]
    assert schedule_rows(fleet_dir, tmp_path / "spread/schedule.parquet") == \
        schedule_rows(fleet_dir, tmp_path / "alone/schedule.parquet")
    times = (tmp_path / "spread/pass_times.csv").read_text().splitlines()
    assert times[0] == "pass,opportunities,seconds,worker" and len(times) > 10

    monkeypatch.setenv("EOSP_FAULT_KILL_ACTOR_ROUND", "1")  # actor 0 killed as the first round is sent
    hurt = job_mod.run(job(fleet_dir, tmp_path / "hurt", workers=2, address=two_nodes.address, lean=lean))
    assert hurt["faults"] >= 1
    assert (hurt["value"], hurt["bound"]) == (alone["value"], alone["bound"])
    assert schedule_rows(fleet_dir, tmp_path / "hurt/schedule.parquet") == \
        schedule_rows(fleet_dir, tmp_path / "alone/schedule.parquet")


@pytest.mark.parametrize("lean", [False, True])
def test_ray_sweeps_with_one_and_two_actors_give_the_in_process_schedule(clustered_fleet_dir, two_nodes,
                                                                         monkeypatch, lean):
    """The coordinate descent's sweeps and the battery repairs on Ray actors (one actor, then one on each node,
    then with actor 0 killed in the first sweep, then in the first repair sent to them): for fixed rounds and seed
    the schedule, value, bound and solve count of this process alone, the second price round sent to the actors
    before the first round's recovery.  Every sweep of 2 passes or more and every repair goes to the pool (this
    fleet's are smaller than the default thresholds).  Lean: the driver holds no arc (every sweep and wave of the
    construction on the actors, paths re-walked from the geometry) and builds none while no actor is lost."""
    import ray

    from eosp.kinds.fleet import construct as coord_mod
    from eosp.kinds.fleet.problem import Problem
    from eosp.kinds.fleet.solve import solve

    from eosp.kinds.fleet import battery

    monkeypatch.setattr(coord_mod, "SWEEP_IN_PROCESS", 2)
    monkeypatch.setattr(battery, "REPAIR_AWAY", 1)
    fleet, opps = read_fleet(clustered_fleet_dir)
    full = Problem.build(fleet, opps)
    driver = Problem.build(fleet, opps, full.geo, lean=True) if lean else full

    def run(workers, pool=True):
        cfg = FleetConfig(pass_solver="exact", rounds=ROUNDS, time_limit=None, workers=workers, seed=4)
        ray_pool = RayPassPool(driver, cfg) if pool else None
        prob = driver if pool else full
        try:
            sol = solve(fleet, opps, cfg, problem=prob, pool=ray_pool)
        finally:
            if ray_pool is not None:
                ray_pool.close()
        rows = sorted(zip(sol.schedule.satellite.tolist(), sol.schedule.task.tolist(), sol.schedule.start_us.tolist()))
        run.prefetched = sol.info["prefetched_rounds"]
        return (rows, sol.value, sol.bound, sol.info["pass_solves"]), ray_pool

    if not ray.is_initialized():
        ray.init(address=two_nodes.address)
    alone, _ = run(1, pool=False)
    for workers in (1, 2):
        got, pool = run(workers)
        assert pool.sweeps >= 1 and pool.repairs >= 1 and pool.faults == 0
        assert got == alone, workers
        assert not driver.built
        assert run.prefetched >= 1  # round 2 was sent to the actors before round 1's recovery, and taken
    for fault in ("SWEEP", "REPAIR"):
        monkeypatch.setenv(f"EOSP_FAULT_KILL_ACTOR_{fault}", "1")
        hurt, pool = run(2)
        assert pool.faults >= 1, fault
        assert hurt == alone, fault
        monkeypatch.delenv(f"EOSP_FAULT_KILL_ACTOR_{fault}")


def test_a_replan_on_actors_sees_each_revaluation(clustered_fleet_dir, two_nodes):
    """A Replanner over two actors (the driver lean) and one in this process, the values changed between calls
    (the actors built with none; each round carries the new ones, a restarted actor included): the same schedules,
    values and bounds, call by call, as in this process."""
    import ray

    from eosp.kinds.fleet.problem import Problem, opportunity_values
    from eosp.kinds.fleet.replan import Replanner
    from eosp.kinds.fleet.solve import Start

    fleet, opps = read_fleet(clustered_fleet_dir)
    full = Problem.build(fleet, opps)
    driver = Problem.build(fleet, opps, full.geo, lean=True)
    if not ray.is_initialized():
        ray.init(address=two_nodes.address)

    def calls(prob, pool, workers):
        planner = Replanner(prob, FleetConfig(pass_solver="exact", rounds=ROUNDS, time_limit=None,
                                              workers=workers, seed=4), pool=pool)
        out = []
        for seed in (1, 2):
            share = np.random.default_rng(seed).uniform(0.1, 1.0, len(opps))
            planner.revalue(opportunity_values(prob, fleet.tasks.weight[opps.task] * share))
            sol = planner.solve(Start())
            out.append((sol.schedule.task.tolist(), sol.schedule.start_us.tolist(), sol.value, sol.bound,
                        sol.info["objective_value"]))
        return out

    alone = calls(full, None, 1)
    pool = RayPassPool(driver, FleetConfig(pass_solver="exact", workers=2))
    try:
        assert calls(driver, pool, 2) == alone
        assert pool.faults == 0 and pool.calls >= 2
    finally:
        pool.close()


def test_four_actors_on_four_nodes_give_the_in_process_schedule(clustered_fleet_dir, two_nodes, monkeypatch):
    """Two more nodes join (four CPUs in all) and four actors, the driver lean, solve with fixed rounds: every sweep
    of 2 passes or more on the actors, filled batches included (the descent's batches change with the worker count
    nowhere), and every battery repair; the schedule, value, bound and solve count of this process alone.  The nodes leave afterwards."""
    import ray

    from eosp.kinds.fleet import construct as coord_mod
    from eosp.kinds.fleet.problem import Problem
    from eosp.kinds.fleet.solve import solve

    monkeypatch.setattr(coord_mod, "SWEEP_IN_PROCESS", 2)
    fleet, opps = read_fleet(clustered_fleet_dir)
    full = Problem.build(fleet, opps)
    driver = Problem.build(fleet, opps, full.geo, lean=True)

    def result(sol):
        rows = sorted(zip(sol.schedule.satellite.tolist(), sol.schedule.task.tolist(), sol.schedule.start_us.tolist()))
        return rows, sol.value, sol.bound, sol.info["pass_solves"]

    from eosp.kinds.fleet import battery

    monkeypatch.setattr(battery, "REPAIR_AWAY", 1)
    cfg = FleetConfig(pass_solver="exact", rounds=ROUNDS, time_limit=None, workers=4, seed=4)
    alone = result(solve(fleet, opps, FleetConfig(pass_solver="exact", rounds=ROUNDS, time_limit=None, workers=1,
                                                  seed=4), problem=full))
    if not ray.is_initialized():
        ray.init(address=two_nodes.address)
    added = [two_nodes.add_node(num_cpus=1) for _ in range(2)]
    two_nodes.wait_for_nodes()
    pool = None
    try:
        pool = RayPassPool(driver, cfg)
        assert len(set(pool.nodes)) == 4  # one actor on each node
        assert result(solve(fleet, opps, cfg, problem=driver, pool=pool)) == alone
        assert pool.sweeps >= 1 and pool.repairs >= 1 and pool.faults == 0 and not driver.built
    finally:
        if pool is not None:
            pool.close()
        for node in added:
            two_nodes.remove_node(node)


def test_actors_repair_the_batteries_of_their_satellites_as_the_driver_does(two_nodes, monkeypatch):
    """A battery repair sent to the actors (each repairs the satellites whose passes it owns) keeps what the
    driver's own repair keeps, and with actor 0 killed as the repair is sent (its satellites then repaired on the
    driver; its first repair computes its sunlight, long enough for the kill to land), the same again; weak
    batteries make the repair drop observations."""
    import dataclasses

    import ray

    from eosp.fleet.battery import SunCache
    from eosp.fleet.greedy import solve
    from eosp.fleet.reasons import schedule_timelines
    from eosp.fleet.timeline import Rows, repair_rows
    from eosp.kinds.fleet.problem import Problem

    fleet = generate(FleetGenConfig(satellites=5, tasks=300, hours=4.0, window_min_h=1.0, window_max_h=3.0, seed=2))
    opps = compute(fleet, Geometry(fleet))
    b = fleet.satellites.battery
    weak = dataclasses.replace(b, initial_wh=0.05 * b.capacity_wh, sunlit_w=0.3 * b.sunlit_w)
    weak = dataclasses.replace(fleet, satellites=dataclasses.replace(fleet.satellites, battery=weak))
    prob = Problem.build(weak, opps)
    rows = Rows.of(schedule_timelines(weak, solve(fleet, opps), prob.los))
    here = repair_rows(weak, prob.los, rows, SunCache(prob.geo))
    assert 0 < int((~here).sum()) < len(here)
    guarded = rows._replace(kept_until=np.full(len(rows.sats), 0.4 * weak.horizon.seconds))  # a frozen prefix
    kept_here = repair_rows(weak, prob.los, guarded, SunCache(prob.geo))
    assert not np.array_equal(kept_here, here)  # the guard changes what goes: the actors must honour it too
    if not ray.is_initialized():
        ray.init(address=two_nodes.address)
    for fault in ("", "1"):
        monkeypatch.setenv("EOSP_FAULT_KILL_ACTOR_REPAIR", fault)
        pool = RayPassPool(prob, FleetConfig(pass_solver="exact", workers=2))
        try:
            assert len({int(pool.owner[p]) for p in range(len(prob.passes))}) == 2
            assert np.array_equal(pool.repair_rows(rows, UNLIMITED), here)
            assert pool.faults == (1 if fault else 0)
            assert np.array_equal(pool.repair_rows(rows, UNLIMITED), here)  # and once more, the actor back or not
            assert np.array_equal(pool.repair_rows(guarded, UNLIMITED), kept_here)
        finally:
            pool.close()


def test_a_killed_driver_resumes_from_its_run_dir(clustered_fleet_dir, tmp_path):
    import os
    import subprocess
    import sys
    from pathlib import Path

    run_dir = tmp_path / "run"
    args = [sys.executable, str(Path(job_mod.__file__)), "--fleet-dir", str(clustered_fleet_dir),
            "--run-dir", str(run_dir), "--fleet.rounds", "3", "--fleet.time-limit", "0",
            "--mlflow-uri", f"sqlite:///{tmp_path}/mlflow.db"]
    killed = subprocess.run(args, env={**os.environ, "EOSP_FAULT_KILL_AFTER": "1"}, capture_output=True, text=True)
    assert killed.returncode == -9  # SIGKILL once round 1 was saved
    with np.load(run_dir / "state.npz", allow_pickle=False) as z:
        assert int(z["rounds_done"]) == 1 and z["lam"].shape == (400,) and z["lam"].max() > 0
    fleet, _ = read_fleet(clustered_fleet_dir, with_opportunities=False)
    saved_value = float(read_schedule(run_dir / "best.parquet", fleet)[1]["value"])
    again = subprocess.run(args, capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    result = json.loads((run_dir / "result.json").read_text())
    assert result["resumed_from_round"] == 1 and result["rounds"] == 3 and result["gap"] > 0
    assert result["value"] >= saved_value - 1e-9
    full = job_mod.run(job(clustered_fleet_dir, tmp_path / "whole", rounds=3))
    assert result["bound"] <= full["bound"] * 1.05  # the resumed prices went on from where they were


def test_bad_run_dirs_and_addresses_are_refused_in_one_line(fleet_dir, tmp_path, capsys):
    other = generate(FleetGenConfig(satellites=2, tasks=30, hours=2.0, seed=9))
    other_dir = tmp_path / "other"
    write_fleet(other, compute(other, Geometry(other)), other_dir)
    run_dir = tmp_path / "run"
    job_mod.run(job(other_dir, run_dir, rounds=1))
    stranger = tmp_path / "stranger"
    stranger.mkdir()
    (stranger / "notes.txt").write_text("mine")
    cases = [
        (["--run-dir", str(run_dir)], "a run dir of another fleet"),
        (["--run-dir", str(stranger)], "is not a fleet run dir eosp wrote"),
        (["--run-dir", str(tmp_path / "new"), "--fleet.workers", "2", "--ray.address", "127.0.0.1:1"], "unreachable"),
        (["--run-dir", str(tmp_path / "new"), "--fleet.pass-solver", "policy"], "no model trained on fleet passes"),
        (["--run-dir", str(tmp_path / "new"), "--fleet.rounds", "0"], "--fleet.rounds"),
        (["--run-dir", str(tmp_path / "new"), "--fleet.workers", "256"], "more than the"),
    ]
    for extra, message in cases:
        try:
            rc = job_mod.main(["--fleet-dir", str(fleet_dir), "--mlflow-uri", f"sqlite:///{tmp_path}/m.db", *extra])
        except SystemExit as exc:  # flags are refused by the parser itself
            rc = exc.code
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and message in err[0], (extra, err)
    assert (stranger / "notes.txt").read_text() == "mine" and not (tmp_path / "new").exists()


def test_generated_fleet_sets_resume_and_refuse_other_settings(two_nodes, tmp_path, capsys):
    from eosp.jobs import generate_fleets

    out = tmp_path / "fleets"
    small = ["--gen.satellites", "2", "--gen.tasks", "40", "--gen.hours", "1", "--out", str(out)]
    assert generate_fleets.main([*small, "--count", "2"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert [f["fleet"] for f in manifest["fleets"]] == ["fleet-00000", "fleet-00001"]
    assert manifest["fleets"][0]["fingerprint"] != manifest["fleets"][1]["fingerprint"]  # seeds 0 and 1
    fleet, opps = read_fleet(out / "fleet-00001")
    assert len(fleet.satellites) == 2 and len(fleet.tasks) == 40 and len(opps) == manifest["fleets"][1]["opportunities"]
    capsys.readouterr()
    assert generate_fleets.main([*small, "--count", "3"]) == 0
    printed = capsys.readouterr().out
    assert "resuming: 2 of 3 fleets already complete" in printed and printed.count("[generate_fleets] fleet ") == 1
    rc = generate_fleets.main([*small[:-2], "--gen.seed", "7", "--out", str(out), "--count", "3"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "a fleet of other settings" in err[0]


@pytest.mark.parametrize("workers", [2, 3])
def test_a_lost_node_costs_at_most_time(fleet_dir, two_nodes, monkeypatch, workers):
    """A third node joins, the pool spreads its actors, and the node of one of them (not the driver's) is removed as
    the first price round is sent.  With 2 workers a CPU is left: Ray restarts the actor there and it builds its
    graphs again; with 3 none is: the actor is given up (at once: ``EOSP_REVIVE_S=0``) and its passes go to the
    live ones, which build their graphs and solve them for the rest of the solve.  Either way the
    schedule, value, bound and solve count are those of one process, and afterwards the pool's actors answer a
    round of every pass as one process does."""
    import time
    from dataclasses import replace

    import ray

    from eosp.kinds.fleet.pool import solve_priced_pass
    from eosp.kinds.fleet.problem import Problem
    from eosp.kinds.fleet.solve import solve

    if not ray.is_initialized():
        ray.init(address=two_nodes.address)
    fleet, opps = read_fleet(fleet_dir)
    prob = Problem.build(fleet, opps)
    cfg = FleetConfig(pass_solver="exact", rounds=ROUNDS, time_limit=None, workers=workers, seed=4)

    def result(sol):
        rows = sorted(zip(sol.schedule.satellite.tolist(), sol.schedule.task.tolist(), sol.schedule.start_us.tolist()))
        return rows, sol.value, sol.bound, sol.info["pass_solves"]

    alone = result(solve(fleet, opps, replace(cfg, workers=1), problem=prob))  # this process alone (never forked)
    two_nodes.add_node(num_cpus=1)
    two_nodes.wait_for_nodes()
    monkeypatch.setenv("EOSP_REVIVE_S", "60" if workers == 2 else "0")
    pool = RayPassPool(prob, cfg)
    try:
        head = two_nodes.head_node.node_id
        victim = next(n for n in two_nodes.list_all_nodes() if n.node_id != head and n.node_id in pool.nodes)
        lost = pool.nodes.index(victim.node_id)
        pool.on_sent = lambda kind, count: two_nodes.remove_node(victim) if (kind, count) == ("round", 1) else None
        assert result(solve(fleet, opps, cfg, problem=prob, pool=pool)) == alone
        assert pool.faults >= 1
        if workers == 2:  # restarted on the CPU left, its graphs built again
            until = time.monotonic() + 120
            while lost not in pool.live() and time.monotonic() < until:
                time.sleep(0.5)
            assert lost in pool.live() and pool.nodes[lost] != victim.node_id
            assert pool.given_up == 0
        else:  # no CPU left: its passes moved to the others
            assert pool.given_up == 1 and pool.actors[lost] is None and lost not in pool.owner
        faults = pool.faults
        every = list(range(len(prob.passes)))
        rng = np.random.default_rng(0)
        lam, pi = rng.uniform(0, 1, len(fleet.tasks)) * prob.weight, np.zeros(len(prob.passes))
        got = pool.solve_priced(every, lam, pi, UNLIMITED)
        for p in every:
            want = solve_priced_pass(prob, p, lam, pi, PassSpec.of(cfg), UNLIMITED)
            assert np.array_equal(got[p].nodes, want.nodes) and got[p].value == want.value
        assert pool.faults == faults
    finally:
        pool.close()
