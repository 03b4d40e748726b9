"""Is a fleet inside the fleet policy's training range?  The node features the shipped (or a given) fleet policy
sees along its greedy decode, as median / 99th percentile / maximum over the admissible slots of the first N
decisions, one column per fleet, and how often the policy chose to skip (one decode of the whole day a fleet).

    python experiments/fleet_policy_features.py --decisions 3000 TRAIN_FLEET fleet-200-s7

A feature far outside the training fleets' range (a task seen by many more other passes, more passes left) is
where a network's scores stop meaning what they meant in training (docs/results.md, "The learned fleet
scheduler": the 200-satellite day).  With ``--clip FEATURE=MAX ...`` each fleet is decoded once more with those
features capped in every observation the network reads, and the raw WCR printed beside the plain decode's.
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
    from eosp.models.pretrained import load_fleet_pretrained
    from eosp.solvers.fleet_policy import decode, network_scorer

    caps = {}
    for item in a.clip:
        name, _, value = item.partition("=")
        if name not in FLEET_NODE_FEATURES:
            raise SystemExit(f"error: --clip {item}: unknown feature (known: {', '.join(FLEET_NODE_FEATURES)})")
        caps[FLEET_NODE_FEATURES.index(name)] = float(value)
    torch.set_num_threads(1)
    agent, env_cfg, _ = load_fleet_pretrained(a.checkpoint)
    evaluate = network_scorer(agent)

    def capped(obss: list[dict]) -> tuple:
        out = []
        for o in obss:
            x = o["x"].copy()
            for j, v in caps.items():
                np.minimum(x[:, j], v, out=x[:, j])
            out.append({**o, "x": x})
        return evaluate(out)

    seen, lines = {}, []
    for path in a.fleets:
        xs, skips = [], []

        def recording(obss: list[dict]) -> tuple:
            """The network's scores, the admissible slots' features and whether skip wins, first decisions only."""
            logits, values = evaluate(obss)
            if len(xs) < a.decisions:
                mask = obss[0]["action_mask"] > 0
                xs.append(obss[0]["x"][mask])
                skips.append(int(np.argmax(np.where(mask, logits[0], -np.inf))) == 0)
            return logits, values

        prepared = load_fleet(path)
        plain = decode(recording, prepared, env_cfg)
        seen[path] = np.concatenate(xs)
        print(f"{path}: raw decode WCR {plain.value:.4f}; of its first {len(xs)} decisions skip chosen {sum(skips)} "
              f"({sum(skips) / max(1, len(xs)):.1%}), {len(seen[path])} admissible slots", flush=True)
        if caps:
            clipped = decode(capped, prepared, env_cfg)
            lines.append(f"{path}: raw decode WCR {plain.value:.4f} ({plain.decisions} decisions), with "
                         f"{' '.join(a.clip)} {clipped.value:.4f} ({clipped.decisions} decisions)")
    print("feature (median / p99 / max)".ljust(30) + "".join(f"{str(k)[-26:]:>28s}" for k in seen))
    for j, name in enumerate(FLEET_NODE_FEATURES):
        cells = [f"{np.median(x[:, j]):8.2f}{np.percentile(x[:, j], 99):8.2f}{x[:, j].max():8.2f}    "
                 for x in seen.values()]
        print(name.ljust(30) + "".join(cells))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
