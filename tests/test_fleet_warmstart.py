"""Where the fleet solver's prices start (none, heuristic, learned): any start keeps the bound a bound, the price
network's files are read without unpickling and refused in one line when they do not fit, and training on the
reference prices lowers its error."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eosp.errors import InputError
from eosp.fleet.check import validate
from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.opportunities import compute
from eosp.kinds.fleet.config import FleetConfig
from eosp.kinds.fleet.problem import Problem
from eosp.kinds.fleet.solve import solve
from eosp.kinds.fleet.warmstart import dual_value, heuristic_prices, start_prices, task_graph
from eosp.models.prices import (EDGE_FEATURES, PASS_FEATURES, TASK_FEATURES, PriceModelConfig, PriceNet,
                                load_price_model, predict, save_price_model)


@pytest.fixture(scope="module")
def prob():
    f = generate(FleetGenConfig(satellites=6, tasks=600, hours=4.0, window_min_h=1.0, window_max_h=4.0,
                                placement="cities", seed=11))
    return Problem.build(f, compute(f))


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory):
    import torch

    torch.manual_seed(0)
    return save_price_model(PriceNet(PriceModelConfig(hidden=8, layers=1)), tmp_path_factory.mktemp("m") / "model")


@pytest.fixture(scope="module")
def best_value(prob):
    sol = solve(prob.fleet, prob.opps, FleetConfig(rounds=6, time_limit=None), problem=prob)
    assert sol.check.valid
    return sol.value


def test_the_graph_is_the_fleets(prob):
    g = task_graph(prob)
    n, P = len(prob.weight), len(prob.passes)
    assert g.x_task.shape == (n, len(TASK_FEATURES)) and g.x_pass.shape == (P, len(PASS_FEATURES))
    assert g.x_edge.shape == (len(g.edge_task), len(EDGE_FEATURES)) and np.isfinite(g.x_edge).all()
    # an edge per (task, pass) pair a pass can serve, no other
    pairs = {(int(t), int(p)) for t, p in zip(g.edge_task, g.edge_pass)}
    assert pairs == {(t, p) for t, h in enumerate(prob.task_passes) for p in h.tolist()}
    assert g.contested.sum() > 10  # the fleet has contested tasks to price
    assert (g.contested == np.array([len(h) > 1 for h in prob.task_passes])).all()


@pytest.mark.parametrize("kind", ["none", "heuristic", "learned"])
def test_every_start_bounds_the_best_schedule(prob, model_dir, best_value, kind):
    lam = start_prices(prob, kind, str(model_dir))
    assert (lam >= 0).all() and (lam <= prob.weight + 1e-12).all()
    assert (lam[[len(h) <= 1 for h in prob.task_passes]] == 0).all()  # an uncontested task is never priced
    assert dual_value(prob, lam) >= best_value - 1e-9


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.integers(0, 2 ** 31 - 1), st.floats(0.0, 2.0))
def test_any_nonnegative_prices_bound_the_best_schedule(prob, best_value, seed, scale):
    lam = np.random.default_rng(seed).uniform(0, scale, len(prob.weight)) * prob.weight
    assert dual_value(prob, lam) >= best_value - 1e-9


@pytest.mark.parametrize("share", [0.2, 1.0])
def test_passes_without_a_provable_bound_problem_keep_the_bound_finite_and_valid(prob, best_value, share):
    """A pass whose bound graph is not FIFO has no provable bound problem: its term becomes the sum of its tasks'
    positive values, so the fleet keeps a finite bound, above every schedule, and not below the bound with
    those passes' own terms."""
    import dataclasses

    rng = np.random.default_rng(0)
    lam = heuristic_prices(prob)
    marked = rng.uniform(size=len(prob.passes)) < share
    passes = [dataclasses.replace(pg, bound_graph=pg.graph, bound_provable=False) if m else pg
              for pg, m in zip(prob.passes, marked)]
    hurt = dataclasses.replace(prob, passes=passes)
    assert hurt.unprovable == int(marked.sum()) > 0
    value = dual_value(hurt, lam)
    assert np.isfinite(value) and value >= best_value - 1e-9 and value >= dual_value(prob, lam) - 1e-9


def test_the_heuristic_start_is_below_the_cold_bound(prob):
    assert dual_value(prob, heuristic_prices(prob)) < dual_value(prob, np.zeros(len(prob.weight)))


@pytest.mark.parametrize("kind", ["heuristic", "learned"])
def test_a_warm_started_solve_is_valid_and_bounded(prob, model_dir, kind):
    model = str(model_dir) if kind == "learned" else ""  # a price model is refused with another start
    sol = solve(prob.fleet, prob.opps, FleetConfig(rounds=3, time_limit=None, warm_start=kind, price_model=model),
                problem=prob)
    assert validate(prob.fleet, sol.schedule, prob.geo).valid
    assert sol.bound >= sol.value - 1e-12 and sol.info["rounds"] >= 1


def test_training_lowers_the_error_to_the_reference(prob):
    from eosp.jobs.train_prices import PriceTrainConfig, train

    g = task_graph(prob)
    y = np.where(g.contested, heuristic_prices(prob) / prob.weight, 0.0) ** 2  # some smooth target of the graph
    logs = []
    cfg = PriceTrainConfig(epochs=60, val=0, model=PriceModelConfig(hidden=16, layers=1))
    model = train([g], [y], cfg, lambda step, m: logs.append(m["train_loss"]))
    assert logs[-1] < 0.3 * logs[0]
    err = np.abs(predict(model, g) - y)[g.contested]
    assert err.mean() < 0.05


def test_model_files_round_trip_and_refusals(tmp_path, prob, model_dir):
    import shutil

    import torch

    m = load_price_model(model_dir)
    g = task_graph(prob)
    assert np.allclose(predict(m, g), predict(load_price_model(model_dir), g))
    # another feature layout: one line naming what differs
    other = tmp_path / "other"
    shutil.copytree(model_dir, other)
    meta = json.loads((other / "prices.json").read_text())
    meta["features"]["edge"] = meta["features"]["edge"][:-1]
    (other / "prices.json").write_text(json.dumps(meta))
    with pytest.raises(InputError, match="another feature layout: its edge features differ"):
        load_price_model(other)
    # weights of another size
    shutil.copy(model_dir / "prices.json", other / "prices.json")
    torch.save({"out.0.weight": torch.zeros(3, 3)}, other / "prices.pt")
    with pytest.raises(InputError, match="do not match"):
        load_price_model(other)
    # corrupt, or a pickle of Python objects: never unpickled
    (other / "prices.pt").write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(InputError, match="unreadable or truncated"):
        load_price_model(other)
    torch.save({"w": torch.zeros(1), "evil": object()}, other / "prices.pt")
    with pytest.raises(InputError, match="never unpickled"):
        load_price_model(other)
    (other / "prices.json").write_text("{")
    with pytest.raises(InputError, match="not JSON"):
        load_price_model(other)
    with pytest.raises(InputError, match="no price model here"):
        load_price_model(tmp_path / "nothing")


def test_the_cli_refuses_a_model_that_does_not_fit_in_one_line(tmp_path, model_dir):
    import subprocess
    import sys

    from eosp.fleet.io import write_fleet

    f = generate(FleetGenConfig(satellites=2, tasks=40, hours=2.0, window_min_h=1.0, window_max_h=2.0,
                                placement="cities", seed=3))
    write_fleet(f, compute(f), tmp_path / "fleet")
    bad = tmp_path / "bad"
    bad.mkdir()
    meta = json.loads((model_dir / "prices.json").read_text())
    meta["features"]["task"] = ["weight"]
    (bad / "prices.json").write_text(json.dumps(meta))
    r = subprocess.run([sys.executable, "-m", "eosp.cli", "solve", str(tmp_path / "fleet"), "--solver", "fleet",
                        "--warm-start", "learned", "--price-model", str(bad), "--rounds", "1", "--time-limit", "0",
                        "--out", str(tmp_path / "s.parquet")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().count("\n") == 0 and "task features differ" in r.stderr
    assert not (tmp_path / "s.parquet").exists()


def test_the_shipped_model_prices_a_fleet(prob):
    lam = start_prices(prob, "learned")  # no directory: the shipped model
    assert np.isfinite(lam).all() and (lam >= 0).all() and (lam <= prob.weight + 1e-12).all()
    assert (lam > 0).sum() > 0
