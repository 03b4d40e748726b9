"""The constellation environment's speed: agent steps per second with random valid actions (the environment
alone, default features, one process) and the time to prepare and reset a fleet after its pass graphs are built.

Fleets: aeossp cases (``--astro``: a checkout of astro-reason, ``--cases`` split/case names), fleet or case
directories (``--env.fleets``, the environment's own option), or generated ones (``--generate SATELLITES TASKS
HOURS``, repeatable; seed ``--seed``, tasks in cities for at most 40 satellites as the aeossp cases, on land
above).  One warm-up episode
compiles the kernels; then ``--episodes`` random episodes are timed.  Prints one Markdown row per fleet.

``--replay SCHEDULE`` (one fleet; a fleet schedule .parquet or an aeossp solution.json, e.g. the fleet solver's
from bench_fleet.py) plays that schedule through the environment (:class:`eosp.envs.constellation.ScheduleFollower`)
and prints how many of its observations could not be played, the return and the schedule's WCR.

    python benchmarks/bench_fleet_env.py --astro ASTRO --cases test/case_0001 test_hard/case_0001 \
        --generate 20 2000 12 --generate 200 20000 24
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from eosp.args import Parser, add_config_args, prefixed_config, run_job
from eosp.config import FleetEnvConfig


def fleets(args, cfg: FleetEnvConfig):
    """(name, fleet, opportunities, geometry, seconds to read and compute opportunities) of every fleet asked."""
    from eosp.envs.constellation import expand_fleets
    from eosp.fleet.aeossp import is_case_dir, read_case
    from eosp.fleet.geometry import Geometry
    from eosp.fleet.io import read_fleet
    from eosp.fleet.opportunities import compute

    paths = [Path(args.astro) / "benchmarks" / "aeossp_standard" / "dataset" / "cases" / c for c in args.cases]
    for p in paths + (expand_fleets(cfg.fleets) if cfg.fleets else []):
        t0 = time.perf_counter()
        if is_case_dir(p):
            fleet = read_case(p)
            geo = Geometry(fleet)
            opps = compute(fleet, geo)
        else:
            fleet, opps = read_fleet(p)
            geo = Geometry(fleet)
        yield str(p), fleet, opps, geo, time.perf_counter() - t0
    for sats, tasks, hours in args.generate:
        from eosp.fleet.generate import FleetGenConfig, generate

        t0 = time.perf_counter()
        fleet = generate(FleetGenConfig(satellites=int(sats), tasks=int(tasks), hours=float(hours), seed=args.seed,
                                        placement="cities" if int(sats) <= 40 else "land"))
        geo = Geometry(fleet)
        opps = compute(fleet, geo)
        yield fleet.case_id, fleet, opps, geo, time.perf_counter() - t0


def replay(pf, cfg: FleetEnvConfig, path: str) -> str:
    """Play the schedule at `path` through the environment: one line of figures."""
    from eosp.envs.constellation import ConstellationEnv, ScheduleFollower
    from eosp.fleet.check import validate
    from eosp.fleet.io import read_schedule

    sched, _ = read_schedule(path, pf.fleet)
    given = validate(pf.fleet, sched, pf.geo)
    env = ConstellationEnv(cfg, source=pf)
    follower = ScheduleFollower(pf, sched)
    env.reset(seed=0)
    while True:
        _, _, term, _, _ = env.step({env.acting_agent: follower.action(env)})
        if term["__all__"]:
            break
    played = validate(pf.fleet, env.schedule(), pf.geo)
    return (f"replay of {path}: {len(sched)} observations (valid {given.valid}, WCR {given.metrics['WCR']:.6f}); "
            f"{follower.dropped} not playable; the environment's schedule: {len(env.schedule())} observations, "
            f"return {env.value:.6f}, valid {played.valid}, WCR {played.metrics['WCR']:.6f}")


def measure(name, fleet, opps, geo, cfg: FleetEnvConfig, episodes: int, seed: int):
    """(the row of figures, the prepared fleet)."""
    from eosp.envs.constellation import ConstellationEnv
    from eosp.envs.constellation_data import prepare_fleet
    from eosp.fleet.passgraph import build_passes
    from eosp.fleet.slew import LineOfSight

    t0 = time.perf_counter()
    passes = build_passes(fleet, opps, LineOfSight(fleet, geo))
    t_graphs = time.perf_counter() - t0
    pf = prepare_fleet(fleet, opps, passes=passes, geo=geo, name=name)
    env = ConstellationEnv(cfg, source=pf)
    rng = np.random.default_rng(seed)
    resets, steps, step_s = [], 0, 0.0
    served = []
    for ep in range(episodes + 1):  # the first one compiles the kernels (cached afterwards): not counted
        t = time.perf_counter()
        obs, _ = env.reset(seed=seed + ep)
        t_reset = time.perf_counter() - t
        n, t = 0, time.perf_counter()
        while obs:
            (agent, o), = obs.items()
            allowed = np.flatnonzero(o["action_mask"])
            obs, _, term, _, _ = env.step({agent: int(allowed[rng.integers(len(allowed))])})
            n += 1
            if term["__all__"]:
                break
        if ep:
            resets.append(t_reset)
            steps += n
            step_s += time.perf_counter() - t
            served.append(env.value)
    info = env.episode_info()
    return {"fleet": name, "satellites": len(fleet.satellites), "tasks": len(fleet.tasks),
            "opportunities": len(opps), "passes": len(passes), "max_pass_tasks": pf.max_pass_tasks,
            "fifo_violations": pf.fifo_violations, "pass_graphs_s": round(t_graphs, 2),
            "prepare_s": round(pf.prepare_s, 2), "reset_ms": round(1e3 * float(np.median(resets)), 2),
            "agent_steps": steps, "steps_per_s": round(steps / step_s), "random_wcr": round(float(np.mean(served)), 4),
            "battery_refusals_last": info["battery_refusals"]}, pf


def main(argv: list[str] | None = None) -> int:
    p = Parser(prog="bench_fleet_env.py", description=__doc__.splitlines()[0])
    p.add_argument("--astro", default="", help="a checkout of astro-reason (its aeossp_standard cases)")
    p.add_argument("--cases", nargs="*", default=[], help="aeossp cases under --astro, e.g. test/case_0001")
    p.add_argument("--generate", nargs=3, action="append", default=[], metavar=("SATELLITES", "TASKS", "HOURS"),
                   help="a generated fleet (repeatable)")
    p.add_argument("--episodes", type=int, default=3, help="timed episodes per fleet (after one warm-up)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--replay", default="", help="a schedule of the one fleet given, played through the environment")
    add_config_args(p, FleetEnvConfig, prefix="env.")
    args = p.parse_args(argv)
    if args.cases and not args.astro:
        p.error("--cases: needs --astro")
    cfg = prefixed_config(FleetEnvConfig, args, "env.")
    if args.replay and len(args.cases) + len(cfg.fleets) + len(args.generate) != 1:
        p.error("--replay: give exactly one fleet (--cases, --env.fleets or --generate)")
    print("| fleet | satellites / tasks | opportunities / passes | max tasks a pass | pass graphs s | prepare s | "
          "reset ms | agent steps/s | random WCR |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, fleet, opps, geo, _ in fleets(args, cfg):
        row, pf = measure(name, fleet, opps, geo, cfg, args.episodes, args.seed)
        print(f"| {row['fleet']} | {row['satellites']} / {row['tasks']:,} | {row['opportunities']:,} / "
              f"{row['passes']:,} | {row['max_pass_tasks']} | {row['pass_graphs_s']} | {row['prepare_s']} | "
              f"{row['reset_ms']} | {row['steps_per_s']:,} | {row['random_wcr']} |", flush=True)
        if args.replay:
            print(replay(pf, cfg, args.replay), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(run_job(main, None, "bench_fleet_env.py"))
