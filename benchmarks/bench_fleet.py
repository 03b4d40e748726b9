"""The fleet solver on the astro-reason aeossp_standard cases, end to end, scored by the benchmark's own verifier.

For each case: read the case, compute opportunities and passes, build the pass graphs, solve with the fleet
solver (``--time-limit`` seconds after the fleet and its opportunities are read: pass graphs, rounds, repair and
final check all count), write solution.json, then run the astro-reason verifier on
it in a subprocess (``python -m benchmarks.aeossp_standard.verifier.run CASE SOLUTION`` in a checkout of
astro-reason at commit ffd1e89; make one from the fetched mirror with ``git -C MIRROR archive HEAD benchmarks
| tar x -C DIR``).  Prints one line per case and writes a CSV, a Markdown table and a plot of value and bound
against time per case; the anytime curve (seconds after reading, value, bound: WCR fractions) is kept in
history.json and sampled at ``--at`` seconds in the table (WCR and gap of the best schedule and bound then).
Wall time is end to end, verifier excluded.

    python benchmarks/bench_fleet.py --astro /path/to/astro-reason --splits test --time-limit 120 --out runs/bench-fleet
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import time
from pathlib import Path

# figures of the reference solvers (60 s search budget, 1 worker, scored by the verifier): WCR, wall seconds
REFERENCE = {
    "test/case_0001": {"greedy_lns": (0.6140, 432), "mwis_conflict_graph": (0.6854, 393)},
    "test/case_0002": {"greedy_lns": (0.6932, 483), "mwis_conflict_graph": (0.7523, 401)},
    "test/case_0003": {"greedy_lns": (0.6954, 335), "mwis_conflict_graph": (0.7694, 285)},
    "test/case_0004": {"greedy_lns": (0.6672, 252), "mwis_conflict_graph": (0.7212, 339)},
    "test/case_0005": {"greedy_lns": (0.7190, 422), "mwis_conflict_graph": (0.7692, 575)},
}


def run_case(case: Path, split: str, args: argparse.Namespace) -> dict:
    from eosp.fleet.aeossp import read_case, write_solution
    from eosp.fleet.opportunities import compute
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.problem import Problem
    from eosp.kinds.fleet.solve import solve

    t0 = time.perf_counter()
    fleet = read_case(case)
    opps = compute(fleet)
    t_read = time.perf_counter()
    t_opp = t_read - t0
    prob = Problem.build(fleet, opps)
    t_build = time.perf_counter() - t0
    cfg = FleetConfig(pass_solver=args.pass_solver, time_limit=args.time_limit, seed=args.seed,
                      warm_start=args.warm_start, price_step=args.price_step,
                      energy_bound=args.energy_bound, integer_energy=not args.no_integer_energy)
    sol = solve(fleet, opps, cfg, problem=prob, t0=t_read)
    solve_s = time.perf_counter() - t_read
    wall = time.perf_counter() - t0
    name = f"{split}/{case.name}"
    out = Path(args.out) / split / case.name
    out.mkdir(parents=True, exist_ok=True)
    sol_path = out / "solution.json"
    write_solution(sol.schedule, fleet.horizon, sol_path, overwrite=True)
    r = subprocess.run([sys.executable, "-m", "benchmarks.aeossp_standard.verifier.run", str(case.resolve()),
                        str(sol_path.resolve())], cwd=args.astro, capture_output=True, text=True)
    verdict = json.loads(r.stdout) if r.stdout.strip().startswith("{") else {"valid": False, "metrics": {}}
    (out / "verifier.json").write_text(json.dumps(verdict, indent=1))
    ref = REFERENCE.get(name, {})
    row = {"case": name, "satellites": len(fleet.satellites), "tasks": len(fleet.tasks), "passes": len(prob.passes),
           "opportunities": len(opps), "valid": verdict.get("valid"), "WCR": verdict["metrics"].get("WCR"),
           "CR": verdict["metrics"].get("CR"), "our_WCR": sol.value, "bound": sol.bound, "gap": sol.gap,
           "opportunities_s": round(t_opp, 1), "build_s": round(t_build, 1), "wall_s": round(wall, 1),
           "solve_s": round(solve_s, 2), "first_schedule_s": sol.info["first_schedule_s"],
           "check_reserve_s": sol.info["check_reserve_s"], "final_check_s": sol.info["final_check_s"],
           "rounds": sol.info["rounds"], "battery_barred": sol.info["battery_barred"],
           "repair_removed": sol.info["repair_removed"], "repair_first": sol.info["repair_first"],
           "energy_windows": sol.info["energy_windows"],
           "bound_source": sol.info["bound_source"], "bound_graphs": sol.info["bound_graphs"],
           "bound_refused": len(sol.info["bound_refused"]),
           "ref_greedy_lns": ref.get("greedy_lns", (None,))[0], "ref_mwis": ref.get("mwis_conflict_graph", (None,))[0]}
    for t in args.at:
        v, b = at_time(sol.history, t)
        row[f"WCR@{t:g}"], row[f"gap@{t:g}"] = v, None if v is None or not b else (b - v) / b
    (out / "history.json").write_text(json.dumps(sol.history))
    plot_history(sol.history, out / "value_bound.png", name)
    return row


def at_time(history: list, t: float) -> tuple[float | None, float | None]:
    """The best value and bound of an anytime curve at `t` seconds: its last point at or before t (a run that
    ended earlier keeps its last point); None before its first schedule."""
    before = [(v, b) for ti, v, b in history if ti <= t]
    return before[-1] if before else (None, None)


def plot_history(history: list, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not history:
        return
    t, v, b = zip(*history)
    fig, ax = plt.subplots(figsize=(5, 3))
    ax.step(t, v, where="post", label="schedule (WCR)")
    finite = [(ti, bi) for ti, bi in zip(t, b) if bi < 1e9]
    if finite:
        ax.step(*zip(*finite), where="post", label="bound")
    ax.set_xlabel("seconds after the fleet is read")
    ax.set_ylabel("weighted completion")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--astro", required=True, help="a checkout of astro-reason (commit ffd1e89)")
    p.add_argument("--splits", nargs="+", default=["test", "test_easy", "test_hard", "test_horizon_2022"])
    p.add_argument("--cases", nargs="*", default=[], help="only these case names (e.g. case_0001)")
    p.add_argument("--pass-solver", default="exact")
    p.add_argument("--time-limit", type=float, default=120.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--warm-start", default="heuristic", choices=["none", "heuristic", "learned"],
                   help="where the prices start (the fleet solver's --warm-start)")
    p.add_argument("--price-step", default="lp", choices=["uniform", "weighted", "lp"],
                   help="the fleet solver's --price-step")
    p.add_argument("--energy-bound", action="store_true", help="the fleet solver's --energy-bound")
    p.add_argument("--no-integer-energy", action="store_true",
                   help="the fleet solver's --integer-energy false (the integer round without energy rows)")
    p.add_argument("--at", type=float, nargs="*", default=[5.0, 10.0, 30.0, 120.0],
                   help="seconds after reading at which the anytime curve is sampled")
    p.add_argument("--out", default="runs/bench-fleet")
    a = p.parse_args()
    rows = []
    root = Path(a.astro) / "benchmarks" / "aeossp_standard" / "dataset" / "cases"
    Path(a.out).mkdir(parents=True, exist_ok=True)
    for split in a.splits:
        for case in sorted((root / split).glob("case_*")):
            if a.cases and case.name not in a.cases:
                continue
            row = run_case(case, split, a)
            rows.append(row)
            print(json.dumps(row), flush=True)
            with open(Path(a.out) / "results.csv", "w", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=list(rows[0]))
                w.writeheader()
                w.writerows(rows)
    at = [t for t in a.at if t <= a.time_limit]
    lines = ["| case | sat / tasks | valid | WCR (verifier) | CR | bound | gap | "
             + "".join(f"WCR / gap @{t:g} s | " for t in at)
             + "repair removed | first s | solve s | wall s | greedy_lns | mwis |",
             "|---|---|---|---|---|---|---|" + "---|" * len(at) + "---|---|---|---|---|---|"]
    for r in rows:
        f = (lambda x: "-" if x is None else f"{x:.4f}")
        g = (lambda x: "-" if x is None else f"{x:.2%}")
        lines.append(f"| {r['case']} | {r['satellites']} / {r['tasks']} | {r['valid']} | {f(r['WCR'])} | {f(r['CR'])} | "
                     f"{f(r['bound'])} | {g(r['gap'])} | "
                     + "".join(f"{f(r[f'WCR@{t:g}'])} / {g(r[f'gap@{t:g}'])} | " for t in at)
                     + f"{r['repair_removed']} | {r['first_schedule_s']} | {r['solve_s']} | {r['wall_s']} | "
                     f"{f(r['ref_greedy_lns'])} | {f(r['ref_mwis'])} |")
    refused = sum(r["bound_refused"] > 0 for r in rows)
    lines.append(f"\nLagrangian bound refused (below a schedule found) on {refused} of {len(rows)} cases; passes whose "
                 f"bound term needed their bound problem (bridges, repeats, loose arcs): "
                 f"{sum(r['bound_graphs'] for r in rows)}; bound kinds: "
                 f"{', '.join(sorted({r['bound_source'] for r in rows}))}.")
    (Path(a.out) / "results.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
