"""Requests of a day in operation: the fleet's tasks as the standing catalogue, known from the start, and urgent
requests that arrive during the day.

Urgent requests arrive as a Poisson process of rate :attr:`RequestConfig.per_hour` over the horizon (seeded):
each at a place on land or in a city (drawn as the fleet generator draws its tasks,
:func:`eosp.fleet.generate.land_points`, :func:`~eosp.fleet.generate.city_points`), observable from its arrival
(rounded up to the action grid) until 2-12 hours after it (uniform; cut at the horizon's end), its duration,
weight and sensor drawn from the catalogue's own (so an urgent request is one more task of the same kind); one
that arrives too near the horizon's end for its duration is dropped (nothing could observe it).  They
are appended to the catalogue as tasks ``urgent_000001``, ... with their arrival times beside them, so that their
opportunities are computed by the fleet's own geometry with the catalogue's (:func:`with_urgent`).  A request is
served by its first acquisition that succeeds within its window.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from eosp.fleet.model import Fleet, Tasks, strings

PLACEMENTS = ("cities", "land")


@dataclass(frozen=True)
class RequestConfig:
    """The urgent requests of a day (see the module docstring)."""

    per_hour: float = 2.0  # arrivals per hour
    placement: str = "cities"  # where they are: cities (by population) or anywhere on land
    window_min_h: float = 2.0  # each observable from its arrival for between these many hours ...
    window_max_h: float = 12.0  # ... and these

    def validate(self) -> None:
        if not (self.per_hour >= 0 and 0 < self.window_min_h <= self.window_max_h
                and self.placement in PLACEMENTS):
            raise ValueError(f"requests: per_hour >= 0, 0 < window_min_h <= window_max_h, placement one of "
                             f"{', '.join(PLACEMENTS)} ({self})")


def arrival_times(horizon_s: float, per_hour: float, rng: np.random.Generator) -> np.ndarray:
    """A Poisson process of rate `per_hour` over ``[0, horizon_s]``: its count Poisson, its times uniform given the
    count, sorted."""
    n = int(rng.poisson(per_hour * horizon_s / 3600.0))
    return np.sort(rng.uniform(0.0, horizon_s, n))


def urgent_requests(fleet: Fleet, cfg: RequestConfig, rng: np.random.Generator) -> tuple[Tasks, np.ndarray]:
    """The urgent requests of one day and their arrival times (seconds from the horizon start), in arrival order."""
    from eosp.fleet.generate import city_points, land_points

    cfg.validate()
    h = fleet.horizon
    step = h.action_step_s
    arrival = arrival_times(h.seconds, cfg.per_hour, rng)
    n = len(arrival)
    release = np.minimum(np.ceil(arrival / step) * step, h.seconds)
    due = np.minimum(release + rng.uniform(cfg.window_min_h, cfg.window_max_h, n) * 3600.0, h.seconds)
    due = np.floor(due / step) * step
    cat = fleet.tasks
    if not len(cat):
        raise ValueError("urgent requests: the fleet has no task to draw their durations, weights and sensors from")
    pick = rng.integers(0, len(cat), n)
    duration = cat.duration_s[pick]
    max_lat = reach_deg(fleet)
    lat, lon, names = np.zeros(0), np.zeros(0), None
    if n and cfg.placement == "cities":
        lat, lon, names = city_points(rng, n, max_lat)
    elif n:
        lat, lon = land_points(rng, n, max_lat)
    fits = due - release >= duration  # one arriving too near the horizon's end cannot be observed: none
    arrival, release, due, duration, pick, lat, lon = (a[fits] for a in (arrival, release, due, duration, pick,
                                                                         np.asarray(lat), np.asarray(lon)))
    names = None if names is None else [x for x, f in zip(names, fits) if f]
    n = len(arrival)
    ids = [f"urgent_{i + 1:06d}" for i in range(n)]
    tasks = Tasks(strings(ids), strings(names if names is not None else ids), np.asarray(lat, dtype=np.float64),
                  np.asarray(lon, dtype=np.float64), np.zeros(n), release, due, duration,
                  cat.weight[pick].astype(np.float64), strings(list(cat.sensor[pick])))
    return tasks, arrival


def reach_deg(fleet: Fleet) -> float:
    """The latitudes the fleet's ground tracks reach, with 5 deg beside them (at most 80): where a request can be
    seen at all (the inclinations of its TLEs, columns 9-16 of line 2)."""
    incl = [float(line[8:16]) for line in fleet.satellites.tle.line2.tolist()]
    top = max((i if i <= 90.0 else 180.0 - i for i in incl), default=80.0)
    return min(80.0, top + 5.0)


def with_urgent(fleet: Fleet, urgent: Tasks) -> Fleet:
    """The fleet with the urgent requests appended to its tasks (the catalogue first, in its order)."""
    cat = fleet.tasks
    cols = {f.name: np.concatenate([np.asarray(getattr(cat, f.name)), np.asarray(getattr(urgent, f.name))])
            for f in dataclasses.fields(Tasks)}
    for name in ("ids", "names", "sensor"):
        cols[name] = strings(list(cols[name]))
    return dataclasses.replace(fleet, tasks=Tasks(**cols))
