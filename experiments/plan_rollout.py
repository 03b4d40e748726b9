"""How much the plan features know by themselves: two hand-written policies that read only them.

    python experiments/plan_rollout.py --mode utility \\
        --tests data/expert/parts/test-u100 data/expert/parts/test-c100 data/expert/parts/test-x100 \\
        --baselines experiments/records/ship-baselines-utility.csv

* ``follow``: take the plan's first acquisition (Greedy's completion of the partial schedule,
  ``--env.plan greedy``), or when it is not allowed (the pruned graph has no arc across a gap
  where something else fits) the allowed plan member that can start first: Greedy's schedule
  played in the environment.
* ``rollout``: take an action of largest V(a) (Greedy's completion after it), ties to the
  earliest start: the classic rollout of Greedy (``--plan label``: of the label sweep,
  eosp.planning.labels.label_togo).

Prints, per test set, the mean ratio to the recorded Greedy and exact values, the instances below
Greedy, and the seconds per instance (the features' cost: no network is run).
"""

from __future__ import annotations

import argparse
import csv
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")


def play(env, inst, policy: str) -> float:
    import numpy as np

    from eosp.envs.observation import EARLIEST_START, PLAN

    obs, _ = env.reset(options={"instance": inst})
    while obs["action_mask"].any():
        x, allowed = obs["x"], np.flatnonzero(obs["action_mask"])
        if policy == "rollout":
            top = x[allowed, PLAN + 5].max()
            cands = allowed[x[allowed, PLAN + 5] >= top - 1e-7]
        else:
            first = np.flatnonzero(x[:, PLAN + 1])
            cands = first if len(first) and obs["action_mask"][first[0]] else allowed[x[allowed, PLAN] > 0]
            cands = cands if len(cands) else allowed
        obs, *_ = env.step(int(cands[np.argmin(x[cands, EARLIEST_START])]))
    return float(env.state.value) if env.cfg.reward != "unitary" else float(len(env.path()))


def main() -> None:
    import numpy as np

    from eosp.config import EnvConfig
    from eosp.envs.eosp_env import EOSPEnv
    from eosp.envs.sources import FixedSource, expand_shards
    from eosp.shards.io import read_instances

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", choices=("utility", "unitary"), required=True)
    ap.add_argument("--tests", nargs="+", required=True, help="test set directories (shards with unpruned arcs)")
    ap.add_argument("--baselines", required=True, help="record of Greedy and exact values (experiments/records)")
    ap.add_argument("--policies", nargs="+", default=["follow", "rollout"], choices=("follow", "rollout"))
    ap.add_argument("--plan", default="greedy", choices=("greedy", "greedy2", "label"),
                    help="the features' --env.plan")
    args = ap.parse_args()
    base = {r["instance"]: r for r in csv.DictReader(open(args.baselines))}
    print("| test | policy | instances | / Greedy | / exact | below Greedy | s / instance |")
    print("|---|---|---|---|---|---|---|")
    for test in args.tests:
        insts = read_instances(expand_shards([test]))
        env = EOSPEnv(EnvConfig(reward="unitary" if args.mode == "unitary" else "normalized", plan=args.plan,
                                max_acquisitions=0), source=FixedSource(insts[0]))
        for policy in args.policies:
            rg, rx, t0 = [], [], time.perf_counter()
            for inst in insts:
                v = play(env, inst, policy)
                rg.append(v / float(base[inst.name]["greedy"]))
                rx.append(v / float(base[inst.name]["exact"]))
            dt = (time.perf_counter() - t0) / len(insts)
            below = sum(r < 1 - 1e-9 for r in rg)
            print(f"| {test.rstrip('/').split('/')[-1]} | {policy} | {len(insts)} | {np.mean(rg):.4f} | "
                  f"{np.mean(rx):.4f} | {below} | {dt:.3f} |", flush=True)


if __name__ == "__main__":
    main()
