"""The fleet kind's learned solvers, as contract entries (:mod:`eosp.kinds.fleet.kind`): the fleet policy decoded
greedily (``fleet-policy``), sampled in batches with the best kept (``fleet-sample``), and the same decoder scored
by a hand rule over the same features, no network (``fleet-features``: the ablation).

Each decodes in the constellation environment (:mod:`eosp.solvers.fleet_policy`), applies its post-processing
(``polish``: ``fill``, :func:`eosp.fleet.greedy.fill`, kept only when it serves more weight; or ``none``), checks
the result with the fleet checker (the command line writes nothing the checker refuses) and reports the raw
decode's WCR beside it (``info['raw_wcr']``).  They give no bound.  ``time_limit`` (fleet-sample) counts from the
entry, the problem read: pass graphs, the environment's arrays, sampling and the polish fit in it (the sampling
stops early enough to leave the polish the time it took on the greedy episode, at least one second).
"""

from __future__ import annotations

import time

from eosp.kinds.fleet.config import FleetFeaturesConfig, FleetPolicyConfig, FleetSampleConfig
from eosp.problem import Result


def agent_of(cfg, agent: tuple | None) -> tuple:
    """The (agent, env config, metadata) given, or loaded from ``cfg.checkpoint`` (the shipped model when empty);
    torch on one thread (two threads make a small graph's forward pass ~100x slower on two cores)."""
    import torch

    from eosp.models.pretrained import load_fleet_pretrained

    torch.set_num_threads(1)
    return agent or load_fleet_pretrained(cfg.checkpoint)


def prepared_of(data, t0: float):
    """The fleet's environment arrays (pass graphs included) and the seconds they took."""
    from eosp.envs.constellation_data import prepare_fleet
    from eosp.fleet.geometry import Geometry

    pf = prepare_fleet(data.fleet, data.opps, geo=data.geo or Geometry(data.fleet))  # the kind's checks built one
    return pf, time.perf_counter() - t0


def finish(pf, decoded, polish: str, timings: dict, info: dict) -> Result:
    """The decoded schedule post-processed (`polish`) and checked: a Result whose value is the checker's WCR, with
    the raw decode's beside it."""
    from eosp.fleet.check import validate
    from eosp.fleet.greedy import fill

    t0 = time.perf_counter()
    schedule, res = decoded.schedule, validate(pf.fleet, decoded.schedule, pf.geo)
    raw = float(res.metrics["WCR"])
    if polish == "fill":
        filled = fill(pf.fleet, pf.opps, schedule, pf.geo)
        check = validate(pf.fleet, filled, pf.geo)
        if check.valid and check.metrics["WCR"] > raw:
            schedule, res = filled, check
    timings["polish"] = time.perf_counter() - t0
    seconds = max(decoded.seconds, 1e-9)
    info = {"raw_wcr": raw, "polish": polish, "decisions": decoded.decisions,
            "decisions_per_s": decoded.decisions / seconds, **decoded.info, **info}
    return Result(schedule, float(res.metrics.get("WCR", 0.0)), None, None, "done", timings, info, res.verdict())


def solve_policy(data, cfg: FleetPolicyConfig, agent: tuple | None = None) -> Result:
    """``--solver fleet-policy``: the greedy decode of the fleet policy (`agent`: an already loaded (agent, env
    config, metadata); default: ``cfg.checkpoint``, or the shipped model)."""
    from eosp.solvers.fleet_policy import decode

    net, env_cfg, meta = agent_of(cfg, agent)
    t0 = time.perf_counter()
    pf, t_prep = prepared_of(data, t0)
    decoded = decode(net, pf, env_cfg)
    return finish(pf, decoded, cfg.polish, {"prepare": t_prep, "decode": decoded.seconds},
                  {"solver": "fleet-policy", "model": meta.get("source", "")})


def solve_sample(data, cfg: FleetSampleConfig, agent: tuple | None = None) -> Result:
    """``--solver fleet-sample``: the best of batched samples of the fleet policy within ``cfg.time_limit``."""
    from eosp.solvers.fleet_policy import sample_best

    net, env_cfg, meta = agent_of(cfg, agent)
    t0 = time.perf_counter()
    pf, t_prep = prepared_of(data, t0)
    limit = None
    if cfg.time_limit is not None:  # what is left once the arrays are built, less a share for the polish
        reserve = 0.0 if cfg.polish == "none" else max(1.0, 0.05 * cfg.time_limit)
        limit = max(0.0, cfg.time_limit - (time.perf_counter() - t0) - reserve)
    decoded = sample_best(net, pf, env_cfg, samples=cfg.samples, temperature=cfg.temperature, seed=cfg.seed,
                          time_limit=limit)
    stopped = decoded.info.get("interrupted", False)  # Ctrl-C: the best episode so far, written at once
    res = finish(pf, decoded, "none" if stopped else cfg.polish, {"prepare": t_prep, "sample": decoded.seconds},
                 {"solver": "fleet-sample", "model": meta.get("source", "")})
    if stopped:
        res.status = "interrupted"
    return res


def solve_features(data, cfg: FleetFeaturesConfig) -> Result:
    """``--solver fleet-features``: the decoder with the hand rule ``cfg.rule`` over the observation features."""
    from eosp.config import FleetEnvConfig
    from eosp.solvers.fleet_policy import FEATURE_RULES, decode, rule_scorer

    t0 = time.perf_counter()
    pf, t_prep = prepared_of(data, t0)
    decoded = decode(rule_scorer(FEATURE_RULES[cfg.rule]), pf, FleetEnvConfig())
    return finish(pf, decoded, cfg.polish, {"prepare": t_prep, "decode": decoded.seconds},
                  {"solver": "fleet-features", "rule": cfg.rule})
