"""One realization of an operations scenario: what happens that no planner chooses, drawn from the scenario's seed.

A realization holds the day's clouds as each opportunity would meet them (whether an acquisition starting there
succeeds), the forecasts issued at each planning time, and when each request arrives.  Every planner run on a
realization meets the same ones (common random numbers: paired comparisons), and a realization is the same
whatever planner asks for it, in whatever order.

Why per opportunity: an acquisition is an opportunity of the day's fleet (a task, a satellite, a start on the
action grid; :mod:`eosp.fleet.opportunities`) and its outcome is the cloud fraction at its target and start
(:mod:`eosp.ops.clouds`), so the latent field is evaluated once per opportunity and the simulator only looks
outcomes up.  The forecasts of one opportunity issued at successive planning times have nested errors (a later
forecast knows what an earlier one knew, :func:`eosp.ops.clouds.forecast_errors`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eosp.ops.clouds import (default_climatology, draw_field, forecast_errors, forecast_probability,
                             success_threshold, surface_km)


@dataclass(frozen=True, eq=False)
class World:
    """One realization: `clear` (bool per opportunity: an acquisition starting there succeeds), `forecast`
    (float64 (opportunities, calls): the success probability a forecast issued at each planning time gives it;
    the realized outcome for a forecast issued at or after its start), `arrival_s` (per task; the catalogue at 0)
    and the planning times `calls_s`."""

    index: int
    clear: np.ndarray
    forecast: np.ndarray
    arrival_s: np.ndarray
    calls_s: np.ndarray

    def perturbed_after(self, t: float, rng: np.random.Generator, opp_start_s: np.ndarray) -> World:
        """The same world up to time `t` and another after it: outcomes of opportunities starting after `t`
        redrawn, forecasts issued after `t` redrawn, requests arriving after `t` moved to other times after
        it.  What a planner may know at `t` is the same in both (the non-anticipativity test)."""
        late = opp_start_s > t
        clear = np.where(late, rng.random(len(self.clear)) < 0.5, self.clear)
        forecast = self.forecast.copy()
        later = self.calls_s > t
        forecast[:, later] = rng.random((len(forecast), int(later.sum())))
        arr = self.arrival_s.copy()
        moved = arr > t
        arr[moved] = t + (arr[moved] - t) * rng.uniform(0.2, 3.0, int(moved.sum()))
        return World(self.index, clear, forecast, arr, self.calls_s)


def planning_times(horizon_s: float, cadence_h: float) -> np.ndarray:
    """The planning calls: at the horizon's start and every `cadence_h` hours after it, within the horizon."""
    return np.arange(0.0, horizon_s, cadence_h * 3600.0)


def realize(scen, index: int) -> World:
    """Realization `index` of scenario `scen` (:class:`eosp.ops.scenario.Scenario`): the clouds drawn from
    ``(seed, 1, index)``, evaluated at every opportunity's target and start, and the forecasts at every planning
    time (:func:`planning_times`)."""
    fleet, opps, cfg = scen.fleet, scen.opps, scen.config
    model = cfg.clouds()
    h = fleet.horizon
    rng = np.random.default_rng([cfg.seed, 1, index])
    field = draw_field(model, h.seconds, rng)
    tasks = fleet.tasks
    month = np.full(len(tasks), h.start.month)
    alpha, beta = default_climatology().params(tasks.lat_deg, month)
    q = success_threshold(model, alpha, beta)  # per task: success when the latent value is below it
    start_s = opps.start.astype(np.float64) * h.action_step_s
    x = field.at(surface_km(tasks.lat_deg, tasks.lon_deg)[opps.task], start_s)
    calls = planning_times(h.seconds, cfg.cadence_h)
    leads = start_s[:, None] - calls[None, :]
    err = forecast_errors(model, leads, rng)
    forecast = forecast_probability(model, x[:, None], err, leads, q[opps.task][:, None])
    return World(index, x < q[opps.task], np.ascontiguousarray(forecast), scen.arrival_s.copy(), calls)
