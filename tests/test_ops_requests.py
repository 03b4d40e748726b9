"""Urgent requests (eosp.ops.requests): a Poisson process of arrivals, each observable from its arrival for 2-12
hours on the action grid, drawn like the catalogue's tasks, appended to it with their opportunities."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.geometry import Geometry
from eosp.fleet.opportunities import compute
from eosp.ops.requests import RequestConfig, arrival_times, reach_deg, urgent_requests, with_urgent


def test_arrivals_are_a_poisson_process():
    rng = np.random.default_rng(0)
    runs = [arrival_times(12 * 3600.0, 3.0, rng) for _ in range(2000)]
    counts = np.array([len(r) for r in runs])
    assert counts.mean() == pytest.approx(36.0, abs=0.6) and counts.var() == pytest.approx(36.0, rel=0.15)
    quarters = np.array([np.histogram(r, bins=4, range=(0.0, 12 * 3600.0))[0] for r in runs])  # 3 h each
    assert quarters.mean(axis=0) == pytest.approx(np.full(4, 9.0), abs=0.4)  # Poisson counts of rate x length
    assert quarters.var(axis=0) == pytest.approx(np.full(4, 9.0), rel=0.2)
    assert np.abs(np.corrcoef(quarters.T)[np.triu_indices(4, 1)]).max() < 0.08  # independent in disjoint spans
    first = np.array([r[0] / 3600.0 for r in runs if len(r)])  # the first arrival: exponential
    assert stats.kstest(first[first < 12.0], stats.truncexpon(b=36.0, scale=1 / 3.0).cdf).pvalue > 1e-3
    assert all(np.all(np.diff(r) >= 0) and (r >= 0).all() and (r <= 12 * 3600.0).all() for r in runs)


def test_urgent_requests_are_tasks_of_the_fleet_seen_by_its_geometry():
    fleet = generate(FleetGenConfig(satellites=3, tasks=30, hours=12.0, placement="cities", seed=4))
    cfg = RequestConfig(per_hour=2.0, placement="cities")
    tasks, arrival = urgent_requests(fleet, cfg, np.random.default_rng(7))
    again, _ = urgent_requests(fleet, cfg, np.random.default_rng(7))
    assert list(tasks.ids) == list(again.ids) and np.array_equal(tasks.lat_deg, again.lat_deg)  # seeded
    n = len(tasks)
    assert n > 5 and len(set(tasks.ids)) == n
    step, end = fleet.horizon.action_step_s, fleet.horizon.seconds
    assert np.all(tasks.release_s >= arrival) and np.all(tasks.release_s - arrival < step)
    assert np.all(tasks.release_s % step == 0) and np.all(tasks.due_s % step == 0)
    length = tasks.due_s - tasks.release_s
    cut = tasks.due_s >= end - step
    assert np.all((length >= 2 * 3600.0 - step) | cut) and np.all(length <= 12 * 3600.0)
    assert np.all(tasks.duration_s <= np.maximum(length, 0.0))
    assert set(tasks.weight.tolist()) <= set(fleet.tasks.weight.tolist())
    assert np.all(np.abs(tasks.lat_deg) <= reach_deg(fleet))
    day = with_urgent(fleet, tasks)
    assert list(day.tasks.ids[:len(fleet.tasks)]) == list(fleet.tasks.ids)
    assert list(day.tasks.ids[len(fleet.tasks):]) == list(tasks.ids)
    opps = compute(day, Geometry(day))
    urgent_seen = np.unique(opps.task[opps.task >= len(fleet.tasks)])
    assert len(urgent_seen) > 0  # some urgent request is observable
    with pytest.raises(ValueError, match="placement"):
        RequestConfig(placement="sea").validate()
