"""Learned policies on freshly generated instances, against Greedy and a reference (RAMP or the exact solver).

    python experiments/fresh_eval.py --mode utility --n 100 --families uniform conflict clusters --count 30 \
        --seed 970000 --reference exact --checkpoints pretrained:utility pretrained:utility-fast

Instance k of each family uses seed + k (the generator's defaults, or --step, --slew and --set), so a draw is
reproducible and disjoint from the training seeds (100000-639999) when the seed is chosen so.
Prints, per family and policy: the mean of per-instance ratios to the reference, the worst ratio, how many
instances end below Greedy, and the decision time; with ``--out``, one CSV row per instance and solver.
Greedy decoding (the shipped models' figures are of the argmax policy).  ``--rollouts label`` adds the rollout
of the plan features alone (no network), what a model reading them starts from.
"""

from __future__ import annotations

import argparse
import csv
import time

import numpy as np

from eosp.config import family_config
from eosp.instances.generator import generate
from eosp.solvers import exact, greedy, policy, ramp
from eosp.solvers.policy import PolicyConfig, resolve_agent


def plan_rollout(inst, mode: str, plan: str) -> float:
    """The objective value of the rollout of the plan features alone: at every step the first allowed action
    of largest V(a) (column after_best)."""
    from eosp.config import EnvConfig
    from eosp.envs.observation import PLAN
    from eosp.envs.sources import prepare_instance
    from eosp.solvers.policy import make_env_for

    env = make_env_for(prepare_instance(inst), EnvConfig(reward="unitary" if mode == "unitary" else "normalized",
                                                         plan=plan))
    obs, _ = env.reset(seed=0)
    done = not obs["action_mask"].any()
    while not done:
        obs, _, done, _, _ = env.step(int(np.flatnonzero(obs["x"][:, PLAN + 4] == 1)[0]))
    nodes = env.path()
    return float(len(nodes)) if mode == "unitary" else float(inst.acqs.utility[inst.node_acq[nodes]].sum())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mode", choices=["utility", "unitary"], required=True)
    p.add_argument("--n", type=int, required=True, help="acquisitions per instance")
    p.add_argument("--families", nargs="+", default=["uniform", "conflict", "clusters"])
    p.add_argument("--count", type=int, default=10, help="instances per family")
    p.add_argument("--seed", type=int, required=True, help="instance k of a family uses seed + k")
    p.add_argument("--reference", choices=["ramp", "exact"], default="ramp")
    p.add_argument("--time-limit", type=float, default=60.0, help="of the exact solver (its best if hit)")
    p.add_argument("--checkpoints", nargs="+", required=True, help="checkpoint directories or pretrained:NAME")
    p.add_argument("--step", type=float, default=0.0, help="time step of the discrete graph (s); 0: the default")
    p.add_argument("--slew", default="", help="slew model (piecewise, bang_coast_bang); empty: the default")
    p.add_argument("--set", nargs="*", default=[], metavar="SECTION.FIELD=VALUE",
                   help="other generator settings, e.g. orbit.altitude_km=550 satellite.roll_max_deg=40")
    p.add_argument("--guard", type=float, nargs="+", default=[PolicyConfig().guard],
                   help="rollout guard(s) of the decisions (eosp.solvers.base.LearnedConfig.guard); 1: off")
    p.add_argument("--incumbent", nargs="+", choices=["on", "off"], default=["on"],
                   help="keep the best Greedy-completed state (eosp.solvers.policy.PolicyConfig.incumbent); both: "
                        "`on off`")
    p.add_argument("--polish", nargs="+", choices=["on", "off"], default=["on"],
                   help="improve the decoded schedule by local moves (eosp.solvers.policy.PolicyConfig.polish); "
                        "both: `on off`")
    p.add_argument("--rollouts", nargs="*", default=[], choices=["greedy", "greedy2", "label"],
                   help="also the rollout of these plan features alone (the allowed action of largest V(a) at every "
                        "step, no network): what the features know by themselves")
    p.add_argument("--known", default="", help="CSV of an earlier run of the same draw (--out): its greedy and "
                   "reference columns are taken instead of solving")
    p.add_argument("--out", default="", help="CSV of every (instance, solver) result")
    a = p.parse_args()
    agents = {ck: resolve_agent("policy", ck, None, a.mode) for ck in a.checkpoints}
    variants = [(g, inc == "on", pol == "on") for g in a.guard for inc in a.incumbent for pol in a.polish]

    def label(ck: str, guard: float, incumbent: bool, polish: bool) -> str:
        return ck + ("" if len(a.guard) == 1 else f" guard {guard:g}") + (
            "" if len(a.incumbent) == 1 else " incumbent" if incumbent else " raw") + (
            "" if len(a.polish) == 1 else " polish" if polish else "")

    names = [label(ck, *v) for ck in a.checkpoints for v in variants] + [f"rollout:{r}" for r in a.rollouts]
    overrides: dict = {}
    given = [*([f"graph.step_s={a.step}"] if a.step else []), *([f"satellite.slew_model={a.slew}"] if a.slew else [])]
    for item in [*given, *a.set]:
        key, _, value = item.partition("=")
        section, _, name = key.partition(".")
        if not value or not name:
            p.error(f"--set {item!r}: SECTION.FIELD=VALUE expected")
        number = value.lstrip("-")
        parsed = int(value) if number.isdigit() else float(value) if number.replace(".", "", 1).isdigit() else value
        overrides.setdefault(section, {})[name] = parsed
    known = {}
    if a.known:
        with open(a.known, newline="") as f:
            for r in csv.DictReader(f):
                if a.reference not in r:
                    p.error(f"--known {a.known}: no {a.reference!r} column")
                known[(r["family"], int(r["seed"]))] = (float(r["greedy"]), float(r[a.reference]))
    rows = []
    for family in a.families:
        for k in range(a.count):
            inst = generate(family_config(family, a.n, a.seed + k, **overrides))
            if known:
                if (family, a.seed + k) not in known:
                    p.error(f"--known {a.known}: no row for {family} {a.seed + k}")
                g, ref = known[(family, a.seed + k)]
            else:
                g = greedy.solve(inst, greedy.GreedyConfig(mode=a.mode)).value
                ref = (exact.solve(inst, exact.ExactConfig(mode=a.mode, time_limit=a.time_limit)).value
                       if a.reference == "exact" else ramp.solve(inst, ramp.RampConfig(mode=a.mode)).value)
            row = {"family": family, "seed": a.seed + k, "greedy": g, a.reference: ref}
            for ck, agent in agents.items():
                for guard, incumbent, polish in variants:
                    name = label(ck, guard, incumbent, polish)
                    t0 = time.perf_counter()
                    cfg = policy.PolicyConfig(mode=a.mode, guard=guard, incumbent=incumbent, polish=polish)
                    row[name] = policy.solve(inst, cfg, agent=agent).value
                    row[name + " s"] = time.perf_counter() - t0
            for plan in a.rollouts:
                t0 = time.perf_counter()
                row[f"rollout:{plan}"] = plan_rollout(inst, a.mode, plan)
                row[f"rollout:{plan} s"] = time.perf_counter() - t0
            rows.append(row)
            print(f"[fresh_eval] {family} {a.seed + k}: greedy {g / ref:.4f} "
                  + " ".join(f"{name} {row[name] / ref:.4f}" for name in names), flush=True)
    print(f"\n{a.mode}, {a.n} acquisitions, x {a.reference} (mean of per-instance ratios; worst; below Greedy; "
          f"s per instance)")
    for family in [*a.families, "all"]:
        sel = [r for r in rows if family in ("all", r["family"])]
        ref = np.array([r[a.reference] for r in sel])
        parts = [f"greedy {np.mean([r['greedy'] for r in sel] / ref):.4f}"]
        for name in names:
            v = np.array([r[name] for r in sel])
            below = sum(r[name] < r["greedy"] * (1 - 1e-9) for r in sel)
            parts.append(f"{name} {np.mean(v / ref):.4f} (worst {np.min(v / ref):.4f}; "
                         f"below Greedy {below}/{len(sel)}; "
                         f"{np.mean([r[name + ' s'] for r in sel]):.2f} s)")
        print(f"  {family:9s} " + " | ".join(parts))
    if a.out:
        with open(a.out, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


if __name__ == "__main__":
    main()
