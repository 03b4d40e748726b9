"""Observation horizon: policy quality and time per decision against the horizon H, by size.

    python benchmarks/bench_horizon.py --sizes 100 300 1000 1500 --horizons 0 600 1200 2400 --instances 4 2 1 1

The shipped model of each mode (or --checkpoint) decodes unseen generated instances
greedily with ``EnvConfig.obs_horizon_s = H`` (0: the whole graph).  Prints, per size and
H, the mean value relative to H = 0 and the mean time per decision (network + environment
step), and the smallest H whose value stays within 0.5% of H = 0 on every size.
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace

os.environ.setdefault("OMP_NUM_THREADS", "1")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[100, 300, 1000, 1500])
    p.add_argument("--instances", type=int, nargs="+", default=[4, 2, 1, 1], help="per size")
    p.add_argument("--horizons", type=float, nargs="+", default=[0, 600, 1200, 2400])
    p.add_argument("--modes", nargs="+", default=["unitary", "utility"])
    p.add_argument("--checkpoint", default="")
    a = p.parse_args()

    import numpy as np
    import torch

    from eosp.config import family_config
    from eosp.envs.sources import prepare_instance
    from eosp.instances.generator import generate
    from eosp.solvers.policy import evaluate, make_env_for, resolve_agent

    torch.set_num_threads(1)
    agents = {m: resolve_agent("policy", a.checkpoint, None, m) for m in a.modes}
    rows = []
    for size, count in zip(a.sizes, a.instances + [a.instances[-1]] * len(a.sizes)):
        for k in range(count):
            inst = generate(family_config("uniform" if k % 2 == 0 else "conflict", size, 700_000 + 100 * size + k,
                                          graph={"step_s": 2.0}))
            prepared = prepare_instance(inst)
            for mode, (agent, env_cfg, _) in agents.items():
                w = np.ones(inst.n_acq) if mode == "unitary" else inst.acqs.utility
                for h in a.horizons:
                    env = make_env_for(prepared, replace(env_cfg, obs_horizon_s=float(h)))
                    obs, _ = env.reset()
                    steps, t0, done = 0, time.perf_counter(), not obs["action_mask"].any()
                    while not done:
                        logits, _ = evaluate(agent, obs)
                        obs, _, done, _, _ = env.step(int(np.argmax(logits)))
                        steps += 1
                    dt = (time.perf_counter() - t0) / max(steps, 1)
                    value = float(w[prepared.eg.node_acq[env.path()]].sum())
                    rows.append((size, inst.name, mode, h, value, dt * 1000, int(obs["n_edges"][0])))
                    print(f"[horizon] {inst.name} {mode} H={h:g}: value {value:.6g}, {dt * 1000:.1f} ms per decision",
                          flush=True)
    import pandas as pd

    df = pd.DataFrame(rows, columns=["size", "instance", "mode", "H", "value", "ms_per_decision", "last_edges"])
    base = df[df.H == 0].set_index(["instance", "mode"])["value"]
    df["ratio"] = [v / base[(i, m)] for i, m, v in zip(df.instance, df["mode"], df.value)]
    table = df.groupby(["size", "mode", "H"]).agg(ratio=("ratio", "mean"), worst=("ratio", "min"),
                                                   ms=("ms_per_decision", "mean")).round(4)
    print(table.to_markdown())
    ok = df.groupby("H")["ratio"].apply(lambda r: (r.groupby(df["mode"]).mean() >= 0.995).all())
    good = [h for h in sorted(df.H.unique()) if h > 0 and ok[h]]
    print(f"smallest horizon within 0.5% of the whole graph on average, every size and mode: "
          f"{good[0] if good else 'none'}")


if __name__ == "__main__":
    main()
