"""Baseline solver benchmark: greedy, RAMP and exact, values and times per size.

    python benchmarks/bench_solvers.py --sizes 100 300 1000 --families uniform conflict --seeds 0 1

For every instance and objective mode: the value and time of each solver, the
exact solver's status and gap (it runs up to ``--exact-max-size`` acquisitions,
with ``--exact-limit`` seconds), the ratios ramp/greedy, greedy/exact and
ramp/exact, and the time of the pruning (done once per instance and shared by
RAMP and the bound).  Runs single-threaded; a tiny instance warms up the JIT
first.  Prints a Markdown table and a summary of the ratios; ``--json FILE``
also writes the rows.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from eosp.config import family_config
from eosp.instances.generator import generate
from eosp.instances.schedule import check, from_internal_nodes
from eosp.solvers.base import run_solver

MODES = ("utility", "unitary")


def timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t0


def run_instance(family: str, n: int, seed: int, args: argparse.Namespace) -> list[dict]:
    inst, t_gen = timed(generate, family_config(family, n, seed))
    _, t_prune = timed(inst.pruned)
    rows = []
    for mode in args.modes:
        row = {"family": family, "n": n, "seed": seed, "mode": mode, "nodes": inst.n_nodes,
               "arcs": inst.unpruned().n_arcs, "pruned_arcs": inst.pruned().n_arcs, "t_generate": t_gen,
               "t_prune": t_prune}
        sols = {}
        sols["greedy"], row["t_greedy"] = timed(run_solver, "greedy", inst, mode=mode)
        sols["ramp"], row["t_ramp"] = timed(run_solver, "ramp", inst, mode=mode, beam=args.beam,
                                            time_limit=args.ramp_limit)
        if n <= args.exact_max_size:
            sols["exact"], row["t_exact"] = timed(run_solver, "exact", inst, mode=mode, time_limit=args.exact_limit)
            info = sols["exact"].info
            row.update(status=info["status"], gap=info["gap"], bound=info["bound"],
                       t_lagrangian=info.get("lagrangian_seconds", 0.0))  # none: the sweep alone proved it
        for name, sol in sols.items():
            verdict = check(inst, from_internal_nodes(inst, sol.nodes))
            if not verdict.feasible:
                raise SystemExit(f"{name} infeasible on {family}-{n}-{seed} ({mode}): {verdict.reason}")
            row[name] = sol.value
        rows.append(row)
        print(_line(row), flush=True)
    return rows


HEADER = ("| family | n | seed | mode | greedy | t (s) | ramp | t (s) | exact | t (s) | status | gap "
          "| ramp/greedy | greedy/exact | ramp/exact |\n" + "|---" * 15 + "|")


def _fmt(x: float) -> str:
    return f"{x:.0f}" if x == int(x) and abs(x) < 1e6 else f"{x:.6g}"


def _line(r: dict) -> str:
    has_exact = "exact" in r
    cells = [r["family"], str(r["n"]), str(r["seed"]), r["mode"], _fmt(r["greedy"]), f"{r['t_greedy']:.3f}",
             _fmt(r["ramp"]), f"{r['t_ramp']:.2f}",
             _fmt(r["exact"]) if has_exact else "-", f"{r['t_exact']:.1f}" if has_exact else "-",
             r.get("status", "-"), f"{r['gap']:.1e}" if has_exact else "-",
             f"{r['ramp'] / r['greedy']:.4f}",
             f"{r['greedy'] / r['exact']:.4f}" if has_exact else "-",
             f"{r['ramp'] / r['exact']:.6f}" if has_exact else "-"]
    return "| " + " | ".join(cells) + " |"


def summary(rows: list[dict]) -> str:
    out = ["", "| n | family | mode | instances | t greedy | t ramp | t exact (max) | proven | ramp/greedy "
           "| greedy/exact | ramp/exact (min) |", "|---" * 11 + "|"]
    keys = sorted({(r["n"], r["family"], r["mode"]) for r in rows})
    for n, fam, mode in keys:
        rs = [r for r in rows if (r["n"], r["family"], r["mode"]) == (n, fam, mode)]
        ex = [r for r in rs if "exact" in r]

        def mean(key, sub=rs):
            return float(np.mean([r[key] for r in sub]))

        cells = [str(n), fam, mode, str(len(rs)), f"{mean('t_greedy'):.3f}", f"{mean('t_ramp'):.2f}",
                 f"{mean('t_exact', ex):.1f} ({max(r['t_exact'] for r in ex):.1f})" if ex else "-",
                 f"{sum(r['status'] == 'optimal' for r in ex)}/{len(ex)}" if ex else "-",
                 f"{np.mean([r['ramp'] / r['greedy'] for r in rs]):.4f}",
                 f"{np.mean([r['greedy'] / r['exact'] for r in ex]):.4f}" if ex else "-",
                 (f"{np.mean([r['ramp'] / r['exact'] for r in ex]):.5f} "
                  f"({min(r['ramp'] / r['exact'] for r in ex):.5f})") if ex else "-"]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[100, 300, 1000])
    p.add_argument("--families", nargs="+", default=["uniform", "conflict"])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    p.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    p.add_argument("--beam", type=int, default=4, help="RAMP labels per node")
    p.add_argument("--ramp-limit", type=float, default=None, help="RAMP time limit (s)")
    p.add_argument("--exact-limit", type=float, default=300.0, help="exact solver time limit (s)")
    p.add_argument("--exact-max-size", type=int, default=1000, help="largest size the exact solver runs on")
    p.add_argument("--json", type=Path, default=None, help="also write the rows as JSON")
    args = p.parse_args(argv)

    # warm up the JIT on a tiny instance so that the first row is not compile time
    warm = generate(family_config("clusters", 12, 0, graph={"step_s": 5.0}))
    for mode in MODES:
        for name in ("greedy", "ramp", "exact"):
            run_solver(name, warm, mode=mode)

    print(HEADER, flush=True)
    rows = []
    for n in args.sizes:
        for family in args.families:
            for seed in args.seeds:
                rows.extend(run_instance(family, n, seed, args))
    print(summary(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
