"""Cost of the plan features (``--env.plan``): environment steps with and without them, one instance.

    python benchmarks/bench_plan.py --family uniform --n 1000 --plans "" greedy greedy2

Each episode follows the rollout of Greedy (the allowed action of largest V(a), column after_ratio;
the first allowed action when the features are off), so every configuration plays a long,
realistic episode; the first episode of each configuration is a warm-up (numba's compilation or
cache load) and is not counted.  Prints, per configuration: steps, mean allowed actions, value
reached, seconds per episode and milliseconds per step (observation included).  One core.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from eosp.config import EnvConfig, family_config
from eosp.envs.eosp_env import EOSPEnv
from eosp.envs.observation import PLAN
from eosp.envs.sources import FixedSource, prepare_instance
from eosp.instances.generator import generate


def episode(env: EOSPEnv, n: int, follow: bool) -> tuple[int, float, float, float]:
    obs, _ = env.reset(seed=0)
    steps = allowed_total = 0
    value, t0 = 0.0, time.perf_counter()
    while obs["action_mask"][:n].any():
        allowed = np.flatnonzero(obs["action_mask"][:n])
        allowed_total += len(allowed)
        a = int(allowed[np.argmax(obs["x"][allowed, PLAN + 5])]) if follow else int(allowed[0])
        obs, r, done, _, _ = env.step(a)
        value += r
        steps += 1
        if done:
            break
    return steps, allowed_total / max(steps, 1), value, time.perf_counter() - t0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--family", default="uniform")
    p.add_argument("--n", type=int, default=1000)
    p.add_argument("--seed", type=int, default=990001)
    p.add_argument("--mode", choices=["utility", "unitary"], default="utility")
    p.add_argument("--plans", nargs="+", default=["", "greedy", "greedy2"], help="'' = features off")
    p.add_argument("--episodes", type=int, default=2, help="timed episodes per configuration")
    a = p.parse_args()
    inst = generate(family_config(a.family, a.n, a.seed))
    t0 = time.perf_counter()
    prepared = prepare_instance(inst, True)
    print(f"{a.family} {a.n} acquisitions: {prepared.eg.node_time.shape[0]} nodes, {prepared.eg.dst.shape[0]} "
          f"pruned arcs, prepared in {time.perf_counter() - t0:.1f} s")
    print("| plan | steps | allowed / step | value | s / episode | ms / step |")
    print("|---|---|---|---|---|---|")
    reward = "unitary" if a.mode == "unitary" else "utility"
    for plan in a.plans:
        env = EOSPEnv(EnvConfig(max_acquisitions=0, plan=plan, reward=reward), source=FixedSource(prepared))
        episode(env, a.n, bool(plan))  # warm-up
        runs = [episode(env, a.n, bool(plan)) for _ in range(a.episodes)]
        steps, allowed, value, _ = runs[0]
        dt = float(np.mean([r[3] for r in runs]))
        print(f"| {plan or 'off'} | {steps} | {allowed:.1f} | {value:.6g} | {dt:.2f} | {1000 * dt / steps:.2f} |",
              flush=True)


if __name__ == "__main__":
    main()
