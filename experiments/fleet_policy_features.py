"""Is a fleet inside the fleet policy's training range?  The node features the shipped (or a given) fleet policy
sees along its greedy decode, as median / 99th percentile / maximum over the admissible slots of the first N
decisions, one column per fleet, and how often the policy chose to skip.

    python experiments/fleet_policy_features.py --decisions 3000 TRAIN_FLEET fleet-200-s7

A feature far outside the training fleets' range (a task seen by many more other passes, more passes left) is
where a network's scores stop meaning what they meant in training (docs/results.md, "The learned fleet
scheduler": the 200-satellite day).  With ``--clip FEATURE=MAX ...`` each fleet is then decoded to the end with
those features capped in every observation the network reads, and the raw WCR printed beside the plain decode's.
"""

from __future__ import annotations

import argparse


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("fleets", nargs="+", help="fleet directories")
    p.add_argument("--decisions", type=int, default=3000, help="decisions of each decode to look at")
    p.add_argument("--checkpoint", default="", help="a fleet policy checkpoint; empty: the shipped one")
    p.add_argument("--clip", nargs="*", default=[], metavar="FEATURE=MAX",
                   help="also decode each fleet with these node features capped (in feature units)")
    a = p.parse_args()
    import numpy as np
    import torch

    from eosp.envs.constellation import load_fleet
    from eosp.envs.constellation_obs import FLEET_NODE_FEATURES
    from eosp.envs.constellation_team import TeamEnv
    from eosp.models.pretrained import load_fleet_pretrained
    from eosp.search.rollouts import choose
    from eosp.solvers.fleet_policy import network_scorer, sized

    torch.set_num_threads(1)
    agent, env_cfg, _ = load_fleet_pretrained(a.checkpoint)
    evaluate = network_scorer(agent)
    seen = {}
    for path in a.fleets:
        prepared = load_fleet(path)
        env = TeamEnv(sized(env_cfg, prepared), prepared)
        obs, _ = env.reset(seed=0)
        xs, skips, n = [], 0, 0
        while obs["action_mask"].any() and n < a.decisions:
            logits, _ = evaluate([obs])
            action = choose(logits[0], obs["action_mask"], None, 1.0)
            xs.append(obs["x"][obs["action_mask"] > 0])
            skips, n = skips + int(action == 0), n + 1
            obs, _, done, _, _ = env.step(action)
            if done:
                break
        seen[path] = np.concatenate(xs)
        print(f"{path}: {n} decisions, skip chosen {skips} ({skips / max(1, n):.1%}), {len(seen[path])} admissible "
              "slots", flush=True)
    print("feature (median / p99 / max)".ljust(30) + "".join(f"{str(k)[-26:]:>28s}" for k in seen))
    for j, name in enumerate(FLEET_NODE_FEATURES):
        cells = [f"{np.median(x[:, j]):8.2f}{np.percentile(x[:, j], 99):8.2f}{x[:, j].max():8.2f}    "
                 for x in seen.values()]
        print(name.ljust(30) + "".join(cells))
    if a.clip:
        from eosp.solvers.fleet_policy import decode

        caps = {}
        for item in a.clip:
            name, _, value = item.partition("=")
            if name not in FLEET_NODE_FEATURES:
                raise SystemExit(f"error: --clip {item}: unknown feature (known: {', '.join(FLEET_NODE_FEATURES)})")
            caps[FLEET_NODE_FEATURES.index(name)] = float(value)

        def capped(obss: list[dict]) -> tuple:
            out = []
            for o in obss:
                x = o["x"].copy()
                for j, v in caps.items():
                    np.minimum(x[:, j], v, out=x[:, j])
                out.append({**o, "x": x})
            return evaluate(out)

        for path in a.fleets:
            prepared = load_fleet(path)
            plain, clipped = decode(evaluate, prepared, env_cfg), decode(capped, prepared, env_cfg)
            print(f"{path}: raw decode WCR {plain.value:.4f} ({plain.decisions} decisions), with {' '.join(a.clip)} "
                  f"{clipped.value:.4f} ({clipped.decisions} decisions)", flush=True)


if __name__ == "__main__":
    main()
