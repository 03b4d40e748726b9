"""Environment benchmark: steps per second and full-episode time with random valid actions,
observation building included, on generated instances of several sizes.

    python benchmarks/bench_env.py --sizes 100 300 1000 --episodes 20

One core; instance preparation (pruning, reverse arcs) is done once per instance
and reported separately.  Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from eosp.envs.eosp_env import EOSPEnv
from eosp.envs.sources import FixedSource
from eosp.config import EnvConfig, family_config
from eosp.instances.generator import generate


def run(n: int, family: str, episodes: int, obs_edges: str, snapshot: bool, plan: str = "") -> dict:
    inst = generate(family_config(family, n, 1))
    t0 = time.perf_counter()
    src = FixedSource(inst)
    t_prep = time.perf_counter() - t0
    env = EOSPEnv(EnvConfig(max_acquisitions=0, obs_edges=obs_edges, max_edges=n * 200, plan=plan), source=src)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    ep_times, steps = [], 0
    snaps = 0
    t_snap = 0.0
    for ep in range(episodes):
        t0 = time.perf_counter()
        obs, _ = env.reset(seed=ep)
        done = False
        while not done:
            if snapshot:
                ts = time.perf_counter()
                env.restore(env.snapshot())
                t_snap += time.perf_counter() - ts
                snaps += 1
            a = int(rng.choice(np.flatnonzero(obs["action_mask"])))
            obs, _, done, _, _ = env.step(a)
            steps += 1
        ep_times.append(time.perf_counter() - t0)
    return {"n": n, "family": family, "prep": t_prep, "episode_ms": 1000 * float(np.mean(ep_times)),
            "episode_ms_max": 1000 * float(np.max(ep_times)), "steps_per_ep": steps / episodes,
            "steps_per_s": steps / float(np.sum(ep_times)), "nodes": inst.n_nodes,
            "pruned_arcs": inst.pruned().n_arcs, "snap_us": 1e6 * t_snap / snaps if snaps else float("nan")}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[100, 300, 1000])
    p.add_argument("--families", nargs="+", default=["uniform", "clusters"])
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--obs-edges", default="earliest", choices=["earliest", "full"])
    p.add_argument("--plan", default="", choices=["", "greedy", "greedy2", "label"],
                   help="the plan features each step computes (EnvConfig.plan; the shipped unitary model: label)")
    a = p.parse_args()
    run(20, "uniform", 2, a.obs_edges, True, a.plan)  # JIT warm-up
    print(f"obs_edges={a.obs_edges} plan={a.plan or 'none'}\n")
    print("| family | acq | nodes | pruned arcs | prepare (s) | steps/episode | episode (ms, mean / max) "
          "| steps/s | snapshot+restore (us) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for fam in a.families:
        for n in a.sizes:
            r = run(n, fam, a.episodes, a.obs_edges, True, a.plan)
            print(f"| {fam} | {n} | {r['nodes']:,} | {r['pruned_arcs']:,} | {r['prep']:.2f} | "
                  f"{r['steps_per_ep']:.1f} | {r['episode_ms']:.1f} / {r['episode_ms_max']:.1f} | "
                  f"{r['steps_per_s']:,.0f} | {r['snap_us']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
