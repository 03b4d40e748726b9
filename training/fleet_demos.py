"""Imitation data of the fleet policy: the fleet solver's schedules replayed in the constellation environment.

A demo set (jobs/build_fleet_demos.py) is a directory of fleet schedules, one per training fleet, with a
``manifest.json`` naming each one's fleet.  :func:`samples_along` plays a schedule through the environment with
:class:`eosp.envs.constellation.ScheduleFollower` (each satellite takes the next observation of its part of the
schedule, or skips to its next pass) and labels the observation of every decision with the follower's action:
the same :class:`eosp.training.imitation.Sample` the single pass learns from, so that batching, the loss and the
training loop are the single pass's (:func:`eosp.training.imitation.train_epoch`).

Value target: the fleet's return still to come from the decision on (the WCR the whole fleet gains after it), not
the acting satellite's own: a search over the team's return (:mod:`eosp.envs.constellation_team`) reads it, and it
is what an agent's return is with ``team_reward`` 1.

:class:`FleetDemoData` also adds states the policy reaches (DAgger-style): the policy plays a training fleet up to
a random instant, the fleet solver completes the day from that partial schedule (the passes before the instant
frozen), and the decisions from that instant on are labelled by the follower of the completed schedule.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from eosp.config import FleetEnvConfig
from eosp.envs.constellation import ConstellationEnv, ScheduleFollower
from eosp.envs.constellation_data import PreparedFleet
from eosp.errors import InputError
from eosp.fleet.model import Schedule
from eosp.training.samples import Sample


def trimmed(obs: dict[str, np.ndarray], action: int, value: float) -> Sample:
    """One labelled decision, its observation cut to its slots and edges (padding is added per batch)."""
    n, m = int(obs["n_nodes"][0]), int(obs["n_edges"][0])
    return Sample(obs["x"][:n].copy(), obs["edge_index"][:, :m].copy(), obs["edge_attr"][:m].copy(),
                  obs["action_mask"][:n].copy(), np.array([action], np.int32), np.array([value], np.float32))


def samples_along(env: ConstellationEnv, prepared: PreparedFleet, schedule: Schedule,
                  after_s: float = 0.0) -> tuple[list[Sample], dict]:
    """Play `schedule` on `prepared` and label every decision taken at or after `after_s` (seconds from the
    horizon start: the acting satellite's clock); returns the samples and what the replay did (its return, the
    observations it could not play)."""
    follower = ScheduleFollower(prepared, schedule)
    obs, _ = env.reset(options={"fleet": prepared})
    states, actions, before = [], [], []
    after_us = after_s * 1e6
    while env.acting_agent is not None:
        agent = env.acting_agent
        a = follower.action(env)
        if env.ep.sat_clock[env.actor] >= after_us:
            states.append(obs[agent])
            actions.append(a)
            before.append(env.value)
        obs, _, term, _, _ = env.step({agent: a})
        if term.get("__all__"):
            break
    final = env.value
    samples = [trimmed(o, a, final - v) for o, a, v in zip(states, actions, before)]
    return samples, {"return": final, "decisions": len(samples), "dropped": follower.dropped}


def read_demo_set(path: str | Path) -> list[dict]:
    """The records of a demo set (jobs/build_fleet_demos.py's manifest), each with the absolute schedule path."""
    root = Path(path)
    manifest = root / "manifest.json"
    if not manifest.is_file():
        raise InputError(root, "not a demo set of the fleet policy (no manifest.json: run jobs/build_fleet_demos.py)")
    try:
        data = json.loads(manifest.read_text())
    except ValueError:
        raise InputError(manifest, "not readable JSON") from None
    demos = data.get("demos") if isinstance(data, dict) else None
    if not isinstance(demos, list) or not all(isinstance(d, dict) and {"fleet", "schedule"} <= set(d) for d in demos):
        raise InputError(manifest, "no 'demos' list of fleet and schedule entries: not written by build_fleet_demos")
    if not demos:
        raise InputError(manifest, "'demos' is empty: no demonstration to learn from or to validate on")
    from eosp.fleet.aeossp import is_case_dir
    from eosp.fleet.io import is_fleet_dir

    for i, d in enumerate(demos):  # every fleet and schedule there before any job starts on them
        if not isinstance(d["fleet"], str) or not (is_fleet_dir(d["fleet"]) or is_case_dir(d["fleet"])):
            raise InputError(manifest, f"demos[{i}]: fleet {d['fleet']!r} is not a fleet or aeossp case directory")
        if not isinstance(d["schedule"], str) or not (root / d["schedule"]).is_file():
            raise InputError(manifest, f"demos[{i}]: schedule {d['schedule']!r} not found in {root}")
    return [{**d, "schedule": str(root / d["schedule"])} for d in demos]


class FleetDemoData:
    """The training fleets, their demonstrations and the labelled decisions built from them (``samples``)."""

    def __init__(self, demo_sets: tuple[str, ...] | list[str], env_cfg: FleetEnvConfig):
        from eosp.envs.constellation import load_fleet
        from eosp.fleet.io import read_schedule

        self.env_cfg = env_cfg
        self.fleets: list[PreparedFleet] = []
        self.records: list[dict] = []
        self.samples: list[Sample] = []
        self.start_values: list[float] = []
        self.replays: list[dict] = []
        for ds in demo_sets:
            for rec in read_demo_set(ds):
                prepared = load_fleet(rec["fleet"])
                schedule, _ = read_schedule(rec["schedule"], prepared.fleet)
                self.fleets.append(prepared)
                self.records.append(rec)
                env = self.env_for(prepared)
                samples, info = samples_along(env, prepared, schedule)
                self.samples += samples
                self.start_values.append(info["return"])
                self.replays.append({"fleet": rec["fleet"], "expert_wcr": rec.get("wcr"), **info})
        if not self.fleets:
            raise InputError(", ".join(map(str, demo_sets)), "no demonstrations")
        self.k_slots = max(f.n_satellites for f in self.fleets)

    def env_for(self, prepared: PreparedFleet) -> ConstellationEnv:
        from dataclasses import replace

        return ConstellationEnv(replace(self.env_cfg, fleets=(), max_satellites=0), source=prepared)

    def add_policy_states(self, agent, n: int, complete, time_limit: float, rng: np.random.Generator) -> dict:
        """One DAgger round: on `n` training fleets the policy samples a partial day up to a random instant, the
        expert completes it (``complete(fleet path, partial schedule, instant s, time_limit) -> schedule``: the
        fleet solver, jobs/build_fleet_demos.complete_day; as Ray tasks when Ray runs), and the decisions from that
        instant on are added."""
        import ray

        from eosp.solvers.fleet_policy import decode

        t0 = time.perf_counter()
        picks = rng.choice(len(self.fleets), size=min(n, len(self.fleets)), replace=False)
        jobs = []
        for i in picks.tolist():
            p = self.fleets[i]
            cut_s = float(rng.uniform(0.1, 0.7)) * p.fleet.horizon.seconds
            ep = decode(agent, p, self.env_cfg, sample=True, seed=int(rng.integers(1 << 30)))
            keep = ep.schedule.start_us < cut_s * 1e6
            part = Schedule(ep.schedule.satellite[keep], ep.schedule.task[keep], ep.schedule.start_us[keep],
                            ep.schedule.end_us[keep])
            jobs.append((i, cut_s, part))
        t_roll = time.perf_counter() - t0
        args = [(self.records[i]["fleet"], part, cut_s, time_limit) for i, cut_s, part in jobs]
        if ray.is_initialized():
            task = ray.remote(num_cpus=1)(complete)
            done = ray.get([task.remote(*a) for a in args])
        else:
            done = [complete(*a) for a in args]
        added, ratio = 0, []
        for (i, cut_s, _), sched in zip(jobs, done):
            p = self.fleets[i]
            samples, info = samples_along(self.env_for(p), p, sched, after_s=cut_s)
            self.samples += samples
            added += len(samples)
            if self.records[i].get("wcr"):
                ratio.append(info["return"] / self.records[i]["wcr"])
        return {"dagger/states_added": added, "dagger/completed_ratio_to_expert": float(np.mean(ratio)) if ratio
                else float("nan"), "dagger/rollout_s": t_roll, "dagger/label_s": time.perf_counter() - t0 - t_roll,
                "dagger/dataset_states": len(self.samples)}

