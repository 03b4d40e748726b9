"""Does the pruned graph lose schedules?  The lossless rule (eosp.graphs.prune.prune) against the paper's
(paper_prune) on many small generated instances.

    python benchmarks/bench_prune.py --count 1000 --seed 0            # 10-60 acquisitions, every family
    python benchmarks/bench_prune.py --count 1000 --seed 900000 --sizes 50 --families uniform

For each instance and rule, in both objectives: the best schedule of the MDP on the pruned graph (the exact
label DP over nodes and open acquisitions, which is the MDP's optimum) against the unpruned optimum; RAMP
(beam 4) on the pruned graph against RAMP on the unpruned one and against Greedy.  Prints the counts and the
arc ratios as a Markdown table.  Instances alternate the families given and the two slew models; sizes are
drawn uniformly from --sizes' range (one size: all that size).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from eosp.config import family_config
from eosp.graphs.prune import fifo_violations, paper_prune, prune
from eosp.instances.generator import generate
from eosp.planning.labels import label_search
from eosp.solvers.base import objective_weights
from eosp.solvers.greedy import GreedyConfig
from eosp.solvers.greedy import solve as greedy

SLEWS = ("piecewise", "bang_coast_bang")
MODES = ("utility", "unitary")


def below(a: float, b: float) -> bool:
    return a < b - 1e-9 * max(1.0, abs(b))


def run(args: argparse.Namespace) -> dict:
    lo, hi = (args.sizes[0], args.sizes[-1])
    rng = np.random.default_rng(args.seed)
    rules = {"paper": paper_prune, "lossless": prune}
    count = {r: {k: 0 for k in ("mdp_below_opt", "ramp_below_unpruned", "ramp_below_greedy", "arcs")} for r in rules}
    total = {"instances": 0, "checks": 0, "arcs": 0, "fifo_violating": 0, "ramp_unpruned_below_greedy": 0}
    worst = {r: 1.0 for r in rules}
    for i in range(args.count):
        seed = args.seed + i
        n = int(rng.integers(lo, hi + 1))
        fam = args.families[i % len(args.families)]
        slew = SLEWS[(i // len(args.families)) % 2] if args.slew == "both" else args.slew
        inst = generate(family_config(fam, n, seed, **{"satellite.slew_model": slew}))
        g, d = inst.unpruned(), inst.acqs.duration
        graphs = {r: f(g, d) for r, f in rules.items()}
        total["instances"] += 1
        total["arcs"] += g.n_arcs
        total["fifo_violating"] += fifo_violations(g) > 0
        for r, pg in graphs.items():
            count[r]["arcs"] += pg.n_arcs
        for mode in MODES:
            total["checks"] += 1
            w = objective_weights(inst, mode)
            opt = label_search(g, w, beam=0).value
            ramp_u = label_search(g, w, beam=args.beam).value
            gr = greedy(inst, GreedyConfig(mode=mode)).value
            total["ramp_unpruned_below_greedy"] += below(ramp_u, gr)
            for r, pg in graphs.items():
                best = label_search(pg, w, beam=0).value
                ramp = label_search(pg, w, beam=args.beam).value
                count[r]["mdp_below_opt"] += below(best, opt)
                count[r]["ramp_below_unpruned"] += below(ramp, ramp_u)
                count[r]["ramp_below_greedy"] += below(ramp, gr)
                if opt > 0:
                    worst[r] = min(worst[r], best / opt)
                if below(best, opt) and args.verbose:
                    print(f"  {r}: seed {seed} n {n} {fam} {slew} {mode}: MDP best {best:.6g} < optimum {opt:.6g}")
    return {"count": count, "total": total, "worst": worst}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=1000, help="instances")
    p.add_argument("--seed", type=int, default=0, help="seed of the first instance (the others follow)")
    p.add_argument("--sizes", type=int, nargs="+", default=[10, 60], help="acquisitions: one size or a range lo hi")
    p.add_argument("--families", nargs="+", default=["uniform", "clusters", "conflict"])
    p.add_argument("--slew", choices=[*SLEWS, "both"], default="both")
    p.add_argument("--beam", type=int, default=4, help="RAMP's labels per node")
    p.add_argument("--verbose", action="store_true", help="print every instance where a rule loses")
    a = p.parse_args()
    t0 = time.perf_counter()
    res = run(a)
    t, c = res["total"], res["count"]
    print(f"{t['instances']} instances ({a.sizes[0]}-{a.sizes[-1]} acquisitions, {', '.join(a.families)}, "
          f"slew {a.slew}, seeds {a.seed}-{a.seed + a.count - 1}), {t['checks']} instance x objective checks, "
          f"{t['fifo_violating']} with FIFO violations, {time.perf_counter() - t0:.0f} s")
    print(f"RAMP (beam {a.beam}) on the unpruned graph below Greedy: {t['ramp_unpruned_below_greedy']}")
    print("| rule | arcs kept | MDP best < unpruned optimum | worst MDP best / optimum | "
          "RAMP < RAMP unpruned | RAMP < Greedy |")
    print("|---|---|---|---|---|---|")
    for r, k in c.items():
        print(f"| {r} | {k['arcs'] / t['arcs']:.1%} | {k['mdp_below_opt']} | {res['worst'][r]:.4f} | "
              f"{k['ramp_below_unpruned']} | {k['ramp_below_greedy']} |")


if __name__ == "__main__":
    main()
