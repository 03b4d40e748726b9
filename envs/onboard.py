"""The operations simulator as a multi-agent environment of onboard decisions: one agent per satellite.

An episode is one realization of an operations scenario flown with the ground plans recorded for it
(:mod:`eosp.ops.plan_cache`; the ground planner is not re-run), the satellites looking ahead
(:class:`eosp.ops.onboard.Onboard` with ``ahead``).  The simulator (:func:`eosp.ops.simulate.running`) runs
until a satellite finds its next primary cloudy and has candidates it can fly; that satellite is the agent to act,
and it observes what the simulator says it knows (:func:`eosp.ops.onboard.features`: its last upload's
forecasts and plan, the outcomes it met, the candidates it can fly).  Its action is a candidate slot or
:data:`NONE` (fly the primary as sent); an action naming an empty slot is taken as none.

Rewards: each acquisition that serves a request (the first to succeed) earns its request's weight over the
scenario's total to the satellite that made it, paid at that satellite's next observation or at the end.  The
rewards of an episode sum to the simulator's served-weight fraction of the same realization and decisions
(``info["served"]`` at the end; :attr:`OnboardEnv.returns` per satellite, satellites that never act included).

The dict API is RLlib's multi-agent one (reset -> obs, infos; step(actions) -> obs, rewards, terminateds,
truncateds, infos); :mod:`eosp.training.onboard_env` puts it under RLlib's base class.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eosp.ops.onboard import CANDIDATES, FEATURES, Context, Onboard, features, fly_test

NONE = CANDIDATES  # the action that takes no candidate


@dataclass
class OnboardEnvConfig:
    """The episodes of an onboard environment: recordings (:mod:`eosp.ops.plan_cache` files), each naming its
    scenario directory and realization."""

    recordings: list[str] = field(default_factory=list)
    """Plan recordings (.npz); an episode draws one at random."""
    seed: int = 0
    """Seed of the draws (with the reset's seed, when given)."""


def agent_id(k: int) -> str:
    return f"sat{k}"


class _Source:
    """A scenario read once per environment: its day, fly test and forecasts' shapes (per scenario path)."""

    def __init__(self, scen_path: str, pass_start: np.ndarray):
        from eosp.fleet.battery import SunCache
        from eosp.fleet.geometry import Geometry
        from eosp.fleet.slew import LineOfSight
        from eosp.ops import scenario
        from eosp.ops.clouds import surface_km
        from eosp.ops.simulate import Day

        self.scen = scenario.read(scen_path)
        f = self.scen.fleet
        geo = Geometry(f)
        self.day = Day.of(self.scen, pass_start)
        self.test = fly_test(f, self.scen.opps, LineOfSight(f, geo), SunCache(geo), slews=True)
        self.xyz = surface_km(f.tasks.lat_deg, f.tasks.lon_deg)

    def context(self, world) -> Context:
        m = self.scen.config
        return Context(self.day.weight, self.xyz, self.day.task, self.day.start_s, world.forecast,
                       float(m.cloud_length_km), float(m.cloud_tau_h) * 3600.0)


class OnboardEnv:
    """See the module docstring."""

    def __init__(self, cfg: OnboardEnvConfig):
        from eosp.ops import plan_cache

        if not cfg.recordings:
            raise ValueError("an onboard environment needs at least one plan recording")
        self.cfg = cfg
        self.recorded = [plan_cache.read(p) for p in cfg.recordings]
        self.sources: dict[str, _Source] = {}
        self.rng = np.random.default_rng(cfg.seed)
        n = max(self._source(r).day.satellites for r in self.recorded)
        self.possible_agents = [agent_id(k) for k in range(n)]
        self.obs_shape = (CANDIDATES, len(FEATURES))

    def _source(self, rec) -> _Source:
        path = rec.meta["scenario"]
        if path not in self.sources:
            self.sources[path] = _Source(path, rec.pass_start)
        return self.sources[path]

    def reset(self, seed: int | None = None, episode: int | None = None) -> tuple[dict, dict]:
        """A new episode: recording `episode` (default: drawn at random, again while a draw asks no decision, so
        that the first observation names an agent; an error when none of the recordings asks one)."""
        if seed is not None:
            self.rng = np.random.default_rng([self.cfg.seed, seed])
        if episode is not None:
            return self._start(episode)
        for i in self.rng.permutation(len(self.recorded)).tolist():
            obs, info = self._start(i)
            if obs:
                return obs, info
        raise ValueError("no recording of this onboard environment asks a decision (no cloudy primary with a "
                         "candidate the satellite can fly)")

    def _start(self, i: int) -> tuple[dict, dict]:
        from eosp.ops.simulate import Replayed, Sent, running
        from eosp.ops.world import realize

        rec = self.recorded[i]
        src = self._source(rec)
        self.day, self.world = src.day, realize(src.scen, int(rec.meta["realization"]))
        self.ctx = src.context(self.world)
        onboard = Onboard(src.test, ahead=True, choose=_asked)
        self.sent = Sent(ahead=True)
        self.gen = running(self.day, self.world, Replayed(self.day, rec.answers), float(rec.meta["time_limit"]),
                           None, onboard, self.sent)
        self.paid = 0
        self.served = np.zeros(len(self.day.weight), dtype=bool)
        self.returns = np.zeros(self.day.satellites)
        self.pending = np.zeros(self.day.satellites)
        self.acted: set[int] = set()
        self.run = None
        return self._advance(None)[0], {}

    def step(self, actions: dict) -> tuple[dict, dict, dict, dict, dict]:
        (a,) = actions.values()
        a = int(a)
        n = len(self.decision.cands)
        return self._advance(a if 0 <= a < min(n, CANDIDATES) else -1)

    def _advance(self, answer: int | None):
        """Run the simulator to the next decision (or the end); the observation and what is paid."""
        try:
            d = next(self.gen) if answer is None else self.gen.send(answer)
        except StopIteration as stop:
            self.run = stop.value
            self._pay(self.run.rows)
            agents = sorted(self.acted)
            obs = {agent_id(k): self._blank() for k in agents}
            rew = {agent_id(k): float(self.pending[k]) for k in agents}
            done = {agent_id(k): True for k in agents} | {"__all__": True}
            info = {agent_id(k): {} for k in agents}
            if agents:
                info[agent_id(agents[0])] = {"served": self.run.figures["served"], "returns": self.returns.copy()}
            return obs, rew, done, {"__all__": False}, info
        self.decision = d
        self._pay(np.asarray(self.sent.done, dtype=np.int64))
        k = d.sat
        self.acted.add(k)
        x, mask = features(self.ctx, d)
        r, self.pending[k] = float(self.pending[k]), 0.0
        aid = agent_id(k)
        return ({aid: {"x": x, "mask": mask.astype(np.int8)}}, {aid: r}, {"__all__": False}, {"__all__": False},
                {aid: {}})

    def hindsight(self) -> np.ndarray:
        """Per candidate slot of the current decision, what taking it earns in hindsight (the realized clouds):
        its request's weight over the total when it is clear, not served yet, and no primary sent after it
        serves it (clear); 0 otherwise and in empty slots.  The labels of an imitation start, never an
        observation."""
        d, day = self.decision, self.day
        out = np.zeros(CANDIDATES)
        prim = self.sent.prim
        total = float(day.weight.sum())
        for i, c in enumerate(d.cands[:CANDIDATES].tolist()):
            t = day.task[c]
            later = prim[(day.task[prim] == t) & (day.start_s[prim] > day.start_s[c])]
            if self.world.clear[c] and not self.served[t] and not self.world.clear[later].any():
                out[i] = day.weight[t] / total
        return out

    def play(self, episode: int, choose) -> float:
        """Recording `episode` flown with chooser `choose` (:data:`eosp.ops.onboard.Chooser`, built by
        ``choose(context)``); the served-weight fraction."""
        self.reset(episode=episode)
        pick = choose(self.ctx)
        while self.run is None:
            a = pick(self.decision)
            self.step({agent_id(self.decision.sat): NONE if a < 0 else a})
        return float(self.run.figures["served"])

    def _pay(self, done: np.ndarray) -> None:
        """Pay the acquisitions done since the last payment that serve a request first."""
        w, total = self.day.weight, float(self.day.weight.sum())
        for r in done[self.paid:].tolist():
            t = self.day.task[r]
            if self.world.clear[r] and not self.served[t]:
                self.served[t] = True
                k = self.day.sat[r]
                self.pending[k] += w[t] / total
                self.returns[k] += w[t] / total
        self.paid = len(done)

    def _blank(self) -> dict:
        return {"x": np.zeros(self.obs_shape, np.float32), "mask": np.zeros(CANDIDATES, np.int8)}


def _asked(d):  # noqa: ARG001 - the environment answers the simulator's decisions itself
    raise RuntimeError("the onboard environment answers its decisions through step()")
