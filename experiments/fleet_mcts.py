"""Does MCTS pay at inference on fleets?  The fleet policy's greedy episode, batched sampling and MCTS (PUCT and
Gumbel, the project's search.mcts over the team view of the constellation environment) at equal time.

    python experiments/fleet_mcts.py --checkpoint runs/fleet-bc/checkpoints/best --fleets data/demos/val \\
        --time-limit 30 --simulations 4 16 --out runs/fleet-mcts.csv

MCTS gets the time limit for the whole episode (each decision an equal share of what the greedy episode says is
left, at most ``--simulations`` each); sampling gets the same limit (rounds of 16 episodes).  Prints one row per
fleet and search: WCR, seconds, network calls, and the number of decisions.  In-process (one core): a
simulation costs one network call on a batch of leaves, far below a Ray task's overhead, so batching simulations
per Ray task only pays where one process cannot spend the time a decision is given.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--fleets", nargs="+", required=True, help="demo sets (their fleets) or fleet directories")
    p.add_argument("--time-limit", type=float, default=30.0)
    p.add_argument("--simulations", type=int, nargs="+", default=[4, 16])
    p.add_argument("--out", default="runs/fleet-mcts.csv")
    a = p.parse_args()
    import torch

    from eosp.config import FleetEnvConfig
    from eosp.envs.constellation import expand_fleets, load_fleet
    from eosp.envs.constellation_team import TeamEnv
    from eosp.fleet.check import validate
    from eosp.models.checkpoint import load_fleet_agent
    from eosp.search.mcts import SearchParams, solve
    from eosp.solvers.fleet_policy import decode, network_scorer, sample_best
    from eosp.training.fleet_demos import read_demo_set

    torch.set_num_threads(1)
    agent, env_cfg, _ = load_fleet_agent(a.checkpoint)
    env_cfg = FleetEnvConfig(**{**env_cfg.__dict__, "fleets": ()})
    paths = []
    for f in a.fleets:
        manifest = Path(f) / "manifest.json"
        is_demo_set = manifest.exists() and "demos" in json.loads(manifest.read_text())
        paths += [r["fleet"] for r in read_demo_set(f)] if is_demo_set else [str(x) for x in expand_fleets([f])]
    rows = []
    for path in paths:
        pf = load_fleet(path)
        evaluate = network_scorer(agent)
        g = decode(agent, pf, env_cfg)
        rows.append({"fleet": path, "search": "greedy", "wcr": g.value, "seconds": g.seconds,
                     "decisions": g.decisions, "network_calls": g.decisions})
        s = sample_best(agent, pf, env_cfg, samples=16, temperature=1.0, seed=0, time_limit=a.time_limit)
        rows.append({"fleet": path, "search": f"sample 16 x rounds, {a.time_limit:g} s", "wcr": s.value,
                     "seconds": s.seconds, "decisions": s.decisions, "network_calls": s.info["network_calls"]})
        for gumbel in (False, True):
            for n in a.simulations:
                env = TeamEnv(env_cfg, pf)
                t0 = time.perf_counter()
                sched, ret, stats = solve(env, evaluate, SearchParams(num_simulations=n, gumbel=gumbel),
                                          time_limit=a.time_limit)
                dt = time.perf_counter() - t0
                assert validate(pf.fleet, sched, pf.geo).valid
                rows.append({"fleet": path, "search": f"mcts {'gumbel' if gumbel else 'puct'} {n} sims",
                             "wcr": ret, "seconds": dt, "decisions": len(stats.played),
                             "network_calls": stats.evaluations})
        for r in rows[-2 - 2 * len(a.simulations):]:
            print(f"{Path(r['fleet']).name:28s} {r['search']:28s} WCR {r['wcr']:.4f}  {r['seconds']:6.1f} s  "
                  f"{r['network_calls']} network calls, {r['decisions']} decisions", flush=True)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    with open(a.out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
