"""The onboard policy against the classical rules on the hidden evaluation scenarios (issue 76, items 2 and 7):
``ev-replan`` re-planning on the ground, the satellites looking ahead, and three ways to choose the candidate that
replaces a primary found cloudy, paired on the same realizations:

* ``rule``: one replacement per primary, the most valuable (``--onboard lookahead``, the rule of issue 75);
* ``tuned rule``: three candidates per primary, the score rule with the (beta, gamma) the training job tuned on
  the training scenarios (read from the policy's onboard.json);
* ``policy``: three candidates per primary, the learned policy.

    python experiments/onboard_table.py --scenarios SCEN... --policy models/pretrained-agents/onboard \\
        --realizations 20 --time-limit 3 --work W

Each (scenario, variant, realization) is one simulation, run on Ray (one task each, resumable: WORK keeps a JSON
per finished one).  Prints per scenario the means and the paired differences with 95% Student t intervals, and
the policy's decision time (features and forward pass, one thread).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from operations_table import interval  # experiments/, beside this script

VARIANTS = ("rule", "tuned rule", "policy")


def options(variant: str, policy: str, time_limit: float) -> dict:
    meta = json.loads((Path(policy) / "onboard.json").read_text())
    base = {"planner": "ev-replan", "onboard": "lookahead", "time_limit": time_limit, "bound_time_limit": 0.0}
    if variant == "rule":
        return {**base, "candidates": 1}
    if variant == "tuned rule":
        return {**base, "candidates": 3, "choose": "score", "beta": meta["rule/beta"], "gamma": meta["rule/gamma"]}
    return {**base, "candidates": 3, "choose": "policy", "policy": str(Path(policy).resolve())}


def simulate(scen: str, opts: dict, indices: list[int], out: str) -> list[dict]:
    """Ray task: realizations of one scenario with one variant, each written to OUT/<index>.json."""
    import os

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)
    from eosp.kinds.fleet.operations import SimulateConfig, Simulation
    from eosp.ops import scenario

    sim = Simulation.of(scenario.read(scen), SimulateConfig(**opts))
    got = []
    for i in indices:
        rec = sim.run(i)
        rec.pop("calls", None)
        Path(out, f"{i}.json").write_text(json.dumps(rec))
        got.append(rec)
    sim.close()
    return got


def decision_time(policy: str, scen: str, n: int = 2000) -> float:
    """Mean milliseconds of one decision of the policy (features and forward pass, one thread) on decisions
    made up of the scenario's opportunities."""
    import numpy as np
    import torch

    from eosp.kinds.fleet.operations import onboard_context
    from eosp.models.onboard import load_policy
    from eosp.ops import scenario
    from eosp.ops.onboard import Decision
    from eosp.ops.simulate import Day
    from eosp.ops.world import realize

    torch.set_num_threads(1)
    s = scenario.read(scen)
    day = Day.of(s)
    choose = load_policy(policy).chooser(onboard_context(s, day, realize(s, 0)))
    rng = np.random.default_rng(0)
    rows = rng.integers(len(day.task), size=(n, 4))
    ds = [Decision(int(day.sat[r[0]]), int(r[0]), r[1:], 1, rng.random(3), rng.random(5) < 0.5, 3600.0) for r in rows]
    t = time.perf_counter()
    for d in ds:
        choose(d)
    return (time.perf_counter() - t) / n * 1000.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenarios", nargs="+", required=True)
    ap.add_argument("--policy", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--realizations", type=int, default=20)
    ap.add_argument("--time-limit", type=float, default=3.0)
    ap.add_argument("--chunk", type=int, default=5, help="realizations a Ray task runs (the problem built once)")
    ap.add_argument("--report-only", action="store_true")
    args = ap.parse_args()
    work = Path(args.work)
    if not args.report_only:
        import ray

        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        task = ray.remote(num_cpus=1)(simulate)
        refs = []
        for scen in args.scenarios:
            for v in VARIANTS:
                out = work / Path(scen).name / v.replace(" ", "-")
                out.mkdir(parents=True, exist_ok=True)
                todo = [i for i in range(args.realizations) if not (out / f"{i}.json").exists()]
                for a in range(0, len(todo), args.chunk):
                    refs.append(task.remote(scen, options(v, args.policy, args.time_limit), todo[a:a + args.chunk],
                                            str(out)))
        while refs:
            done, refs = ray.wait(refs, num_returns=1)
            ray.get(done)
            print(f"{len(refs)} tasks left", flush=True)
        ray.shutdown()
    print("\n| scenario | variant | realizations | served | valid | replacements taken |\n|---|---|---|---|---|---|")
    pairs = []
    for scen in args.scenarios:
        got = {}
        for v in VARIANTS:
            d = work / Path(scen).name / v.replace(" ", "-")
            got[v] = {int(p.stem): json.loads(p.read_text()) for p in d.glob("*.json")}
            recs = list(got[v].values())
            if recs:
                print(f"| {Path(scen).name} | {v} | {len(recs)} | {sum(r['served'] for r in recs) / len(recs):.4f} | "
                      f"{sum(bool(r['valid']) for r in recs)} | "
                      f"{sum(r['alternates_taken'] for r in recs) / len(recs):.1f} |")
        for a, b in (("tuned rule", "rule"), ("policy", "rule"), ("policy", "tuned rule")):
            common = sorted(set(got[a]) & set(got[b]))
            if common:
                m, h = interval([got[a][i]["served"] - got[b][i]["served"] for i in common])
                pairs.append(f"| {Path(scen).name} | {a} - {b} | {len(common)} | {m:+.5f} | [{m - h:+.5f}, {m + h:+.5f}] |")
    print("\n| scenario | pair | realizations | served, mean difference | 95% interval |\n|---|---|---|---|---|")
    print("\n".join(pairs))
    print(f"\npolicy decision: {decision_time(args.policy, args.scenarios[0]):.3f} ms (one thread, features included)")


if __name__ == "__main__":
    main()
