"""The fleet solver's time limit is strict (issue 48): ``time_limit`` bounds the whole solve after the fleet is
read (pass graphs, rounds, battery repairs, the final check), and when it is below the time of the first
schedule, that schedule is returned as soon as it exists, and the result says so.

Wall times are measured around the call, from the instant the solver counts from (`t0`); the slack covers a
loaded machine (the suite runs two workers beside other jobs)."""

import time
from types import SimpleNamespace

import pytest

from eosp.fleet.check import validate
from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.opportunities import compute
from eosp.kinds.fleet.config import FleetConfig
from eosp.kinds.fleet.solve import solve, solve_fleet

SLACK_S = 2.0  # a loaded machine; the promise is T + 1 s


@pytest.fixture(scope="module")
def data():
    fleet = generate(FleetGenConfig(satellites=6, tasks=1000, hours=4.0, seed=5))
    return SimpleNamespace(fleet=fleet, opps=compute(fleet), geo=None)


def test_the_limit_bounds_the_whole_solve_and_the_schedule_is_valid(data):
    T = 3.0
    t0 = time.perf_counter()
    sol = solve(data.fleet, data.opps, FleetConfig(time_limit=T), t0=t0)
    wall = time.perf_counter() - t0
    assert sol.info["first_schedule_s"] < T and not sol.info["first_after_limit"]
    assert wall <= T + 1.0 + SLACK_S, (wall, sol.info["first_schedule_s"], sol.info["check_reserve_s"])
    assert wall >= 0.5 * T  # the rounds used the time (the search does not end by itself on this fleet)
    assert sol.check.valid and validate(data.fleet, sol.schedule).valid
    assert sol.bound >= sol.value


def test_a_limit_below_the_first_schedule_returns_it_as_soon_as_it_exists(data):
    t0 = time.perf_counter()
    res = solve_fleet(data, FleetConfig(time_limit=0.01))
    wall = time.perf_counter() - t0
    assert res.status == "first_schedule" and res.info["first_after_limit"]
    assert res.info["rounds"] == 0
    first = res.info["first_schedule_s"]
    assert first > 0.01 and wall <= first + res.info["check_reserve_s"] + SLACK_S
    assert res.verdict.valid and validate(data.fleet, res.schedule).valid
