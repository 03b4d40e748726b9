"""MCTS benchmark: full MCTS(budget) episode time and time per simulation by instance size.

    python benchmarks/bench_mcts.py --checkpoint runs/NAME/checkpoints/best --sizes 100 300 1000 --budget 100

One core (torch and numba single-threaded).  Without --checkpoint a freshly
initialized agent of the cpu preset is used (same cost, different choices).
The first instance size's episode is the headline figure (the paper: ~13
thread-minutes per instance for MCTS(100)).
"""

from __future__ import annotations

import argparse
import time

import torch

from eosp.envs.sources import prepare_instance
from eosp.config import MODEL_PRESETS, EnvConfig, ModelConfig, family_config
from eosp.instances.generator import generate
from eosp.models.agent import EOSPAgent
from eosp.solvers.mcts import MctsConfig, solve


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--checkpoint", default="")
    p.add_argument("--sizes", type=int, nargs="+", default=[100, 300, 1000])
    p.add_argument("--budget", type=int, default=100)
    p.add_argument("--seed", type=int, default=7)
    a = p.parse_args()
    torch.set_num_threads(1)
    if a.checkpoint:
        from eosp.models.checkpoint import load_agent

        agent = load_agent(a.checkpoint)
    else:
        torch.manual_seed(0)
        agent = (EOSPAgent(ModelConfig(**MODEL_PRESETS["cpu"])).eval(), EnvConfig(), {})
    solve(generate(family_config("uniform", 20, 0)), MctsConfig(budget=5), agent=agent)  # warm-up
    print("| acq | budget | decisions | simulations | expansions | episode (s) | ms / simulation | "
          "ms / expansion |\n|---|---|---|---|---|---|---|---|")
    for n in a.sizes:
        inst = generate(family_config("uniform", n, a.seed))
        prepare_instance(inst)  # pruning outside the timing (done once per instance)
        t0 = time.perf_counter()
        sol = solve(inst, MctsConfig(budget=a.budget, mode="utility"), agent=agent)
        dt = time.perf_counter() - t0
        i = sol.info
        print(f"| {n} | {a.budget} | {len(sol.nodes)} | {i['simulations']} | {i['expansions']} | {dt:.1f} | "
              f"{1e3 * dt / max(1, i['simulations']):.2f} | {1e3 * dt / max(1, i['expansions']):.2f} |", flush=True)


if __name__ == "__main__":
    main()
