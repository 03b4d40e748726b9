"""Fleet schedules decoded in the constellation environment: by the fleet policy's network, or by a hand rule over
the same observation features (the ablation without a network).

Decoding plays a fleet through :class:`eosp.envs.constellation_team.TeamEnv` (the event clock of the multi-agent
environment; each decision the acting satellite's) with a scorer ``evaluate(list of observations) -> (logits [B,
N], values [B])``: the network's (:func:`network_scorer`) or a rule's (:func:`rule_scorer`).  Greedy decoding
takes the admissible slot of largest score; sampling draws from the softmax (:func:`eosp.search.rollouts.sample`:
many episodes in lockstep, one network call per step for all of them, the greedy one first, best kept).  Every
schedule the environment builds is valid by construction (slews, windows, battery: the checker's rules); the
solvers check it with the fleet checker before it is written.

The rules: a linear score over named node features (:data:`FEATURE_RULES`), the skip slot scored like any other
(its ``skip`` feature is 1), bridges (zero reward) penalized.  ``earliest`` (the task the satellite can start
soonest, weight breaking ties) is the best of them on the training fleets (docs/results.md, "The learned fleet
scheduler"), hence the features-only decoder's default.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from eosp.config import FleetEnvConfig
from eosp.envs.constellation_data import PreparedFleet
from eosp.envs.constellation_obs import FLEET_NODE_FEATURES
from eosp.envs.constellation_team import TeamEnv
from eosp.fleet.model import Schedule
from eosp.search.rollouts import EvaluateMany, choose

MASKED = -1e9  # the score of an inadmissible slot (eosp.models.agent.MASKED)
SKIP_LAST = {"skip": -100.0, "bridge": -1000.0}  # skip only when nothing else is admissible; bridges after skips
FEATURE_RULES: dict[str, dict[str, float]] = {
    # the task that can start soonest (weight breaks ties): the most observations per pass
    "earliest": {"earliest_start": -1.0, "weight": 0.01, **SKIP_LAST},
    # the heaviest task, then the soonest
    "weight": {"weight": 1.0, "earliest_start": -0.01, **SKIP_LAST},
    # soonest, traded against weight (a weight point = 0.2 x 300 s of delay / 5)
    "earliest_weight": {"earliest_start": -1.0, "weight": 1.0, **SKIP_LAST},
    # soonest, with tasks no other pass can still observe first among near-equals
    "earliest_scarce": {"earliest_start": -1.0, "weight": 0.2, "other_passes_rel": -0.2, **SKIP_LAST},
    # soonest, with the task's share of the pass's weight
    "earliest_share": {"earliest_start": -1.0, "weight_share": 1.0, **SKIP_LAST},
}

DEFAULT_RULE = "earliest_scarce"  # the best rule on the first training fleets (experiments/fleet_rules.py)


@dataclass
class Decoded:
    """One decoded schedule: its return (the WCR the environment credited), decisions and seconds."""

    schedule: Schedule
    value: float
    decisions: int
    seconds: float
    info: dict = field(default_factory=dict)


def rule_scorer(rule: dict[str, float]) -> EvaluateMany:
    """The scorer of a linear rule over named node features (``{feature: coefficient}``); values are zeros."""
    unknown = sorted(set(rule) - set(FLEET_NODE_FEATURES))
    if unknown:
        raise ValueError(f"unknown node feature(s) {', '.join(unknown)}; known: {', '.join(FLEET_NODE_FEATURES)}")
    coef = np.zeros(len(FLEET_NODE_FEATURES), dtype=np.float64)
    for name, c in rule.items():
        coef[FLEET_NODE_FEATURES.index(name)] += c

    def evaluate(obss: list[dict]) -> tuple[np.ndarray, np.ndarray]:
        x = np.stack([o["x"] for o in obss]).astype(np.float64)
        mask = np.stack([o["action_mask"] for o in obss]) > 0
        return np.where(mask, x @ coef, MASKED), np.zeros(len(obss))

    return evaluate


def network_scorer(agent) -> EvaluateMany:
    """The scorer of a fleet policy (an :class:`eosp.models.agent.EOSPAgent` over the constellation features)."""
    from eosp.solvers.policy import evaluate_batch

    return lambda obss: evaluate_batch(agent, obss)


def scorer_of(agent_or_scorer) -> EvaluateMany:
    """A scorer (a plain function) as it is; an agent (an EOSPAgent: a module with a ``cfg``) by its network."""
    return agent_or_scorer if callable(agent_or_scorer) and not hasattr(agent_or_scorer, "cfg") \
        else network_scorer(agent_or_scorer)


def sized(env_cfg: FleetEnvConfig, prepared: PreparedFleet) -> FleetEnvConfig:
    """`env_cfg` for this fleet alone: its satellites as the agent slots, and observations padded to its largest
    pass (the network reads graphs of any size: the padding is no part of the model)."""
    from dataclasses import replace

    return replace(env_cfg, fleets=(), max_satellites=0, max_edges=0,
                   max_nodes=max(env_cfg.max_nodes, prepared.max_pass_tasks + 1))


def decode(agent_or_scorer, prepared: PreparedFleet, env_cfg: FleetEnvConfig, sample: bool = False, seed: int = 0,
           temperature: float = 1.0) -> Decoded:
    """One episode: the argmax of every decision, or (`sample`) a draw from the softmax of the scores."""
    evaluate = scorer_of(agent_or_scorer)
    env = TeamEnv(sized(env_cfg, prepared), prepared)
    rng = np.random.default_rng(seed) if sample else None
    t0 = time.perf_counter()
    obs, _ = env.reset(seed=seed)
    n = 0
    while obs["action_mask"].any():
        logits, _ = evaluate([obs])
        obs, _, done, _, _ = env.step(choose(logits[0], obs["action_mask"], rng, temperature))
        n += 1
        if done:
            break
    return Decoded(env.schedule(), env.value, n, time.perf_counter() - t0)


def sample_best(agent_or_scorer, prepared: PreparedFleet, env_cfg: FleetEnvConfig, *, samples: int,
                temperature: float, seed: int, time_limit: float | None) -> Decoded:
    """The best of batched sampled episodes (:func:`eosp.search.rollouts.sample`: the greedy one first, then
    rounds of `samples` until `time_limit` seconds, one round without it)."""
    from eosp.search.rollouts import replay, sample

    env = TeamEnv(sized(env_cfg, prepared), prepared)
    t0 = time.perf_counter()
    kept: list[list] = []  # the best episode's actions so far: what Ctrl-C leaves (the greedy one at least)
    try:
        best = sample(env, scorer_of(agent_or_scorer), samples=samples, temperature=temperature, seed=seed,
                      time_limit=time_limit, on_best=lambda actions: kept.append(list(actions)))
        actions, info = best.actions, {"episodes": best.episodes, "network_calls": best.evaluations}
    except KeyboardInterrupt:
        if not kept:
            raise  # Ctrl-C before the first episode ended: nothing to write
        actions, info = kept[-1], {"interrupted": True}
    schedule, ret = replay(env, actions, seed)
    return Decoded(schedule, ret, len(actions), time.perf_counter() - t0, info)
