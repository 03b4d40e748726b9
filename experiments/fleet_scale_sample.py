"""What a large constellation's passes look like and cost, from a sample of its satellites.

    python experiments/fleet_scale_sample.py --satellites 1000 --tasks 100000 --hours 24 --every 20 --solve 5

Generates the fleet (``eosp generate --fleet`` settings, seed 0), scans the opportunities of every
``--every``-th satellite (a whole fleet of 1,000 satellites and 100,000 tasks is about 19 million
opportunities: the sample gives its per-satellite figures without holding it), splits them into passes, and
for the first ``--solve`` sampled satellites builds every pass graph and solves each pass with the exact
solver (5 s limit a pass, as the fleet solver does) at the tasks' weights: pass sizes and solve seconds by
size, and the bytes of those pass graphs per opportunity (arrays of the graph and of its bound graph), the
inputs of the cluster-sizing table in docs/results/fleet-scale.md.
"""

from __future__ import annotations

import argparse
import json
import resource
import time

import numpy as np

SIZES = [(1, 30), (31, 100), (101, 300), (301, 1000), (1001, 10 ** 9)]


def main() -> None:
    from eosp.fleet.generate import FleetGenConfig, generate
    from eosp.fleet.geometry import Geometry
    from eosp.fleet.opportunities import Opportunities, passes, satellite_opportunities
    from eosp.fleet.passgraph import build_pass
    from eosp.fleet.slew import LineOfSight
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.problem import PassSpec, solve_pass_graph

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--satellites", type=int, default=1000)
    ap.add_argument("--tasks", type=int, default=100000)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--every", type=int, default=20, help="scan every k-th satellite")
    ap.add_argument("--solve", type=int, default=5, help="solve the passes of this many sampled satellites")
    args = ap.parse_args()
    t0 = time.perf_counter()
    fleet = generate(FleetGenConfig(satellites=args.satellites, tasks=args.tasks, hours=args.hours))
    t_gen = time.perf_counter() - t0
    geo = Geometry(fleet)
    los = LineOfSight(fleet, geo)
    sample = list(range(0, args.satellites, args.every))
    n_opp, sizes, timings, graph_bytes, graph_opps, arcs = 0, [], [], 0, 0, 0
    t1 = time.perf_counter()
    cfg = FleetConfig(pass_solver="exact")
    for i, k in enumerate(sample):
        task, start = satellite_opportunities(fleet, geo, k)
        order = np.lexsort((task, start))
        task, start = task[order], start[order]
        sat = np.full(len(task), k, dtype=np.int64)
        pid = passes(fleet, sat, task, start)
        sizes += np.bincount(pid).tolist() if len(pid) else []
        n_opp += len(task)
        if i < args.solve and len(task):
            opps = Opportunities(task.astype(np.int32), sat.astype(np.int32), start.astype(np.int32),
                                 pid.astype(np.int32))
            off = opps.pass_offsets()
            for p in range(opps.n_passes):
                pg = build_pass(fleet, opps, los, p, off)
                graph_bytes += pg.nbytes
                graph_opps += len(pg.rows)
                arcs += pg.graph.n_arcs + (pg.bound_graph.n_arcs if pg.bound_graph is not None else 0)
                s = time.perf_counter()
                solve_pass_graph(pg, fleet.tasks.weight[pg.tasks].astype(np.float64), PassSpec.of(cfg))
                timings.append((len(pg.rows), time.perf_counter() - s))
    t_scan = time.perf_counter() - t1
    sizes = np.asarray(sizes)
    per_sat = n_opp / len(sample)
    print(json.dumps({"satellites": args.satellites, "tasks": args.tasks, "hours": args.hours, "generate_s":
                      round(t_gen, 1), "sampled": len(sample), "scan_and_solve_s": round(t_scan, 1),
                      "opportunities_per_satellite": round(per_sat, 1),
                      "passes_per_satellite": round(len(sizes) / len(sample), 2),
                      "estimated_opportunities": int(per_sat * args.satellites),
                      "estimated_passes": int(len(sizes) / len(sample) * args.satellites),
                      "pass_size_median": float(np.median(sizes)), "pass_size_p95": float(np.percentile(sizes, 95)),
                      "pass_size_max": int(sizes.max()),
                      "graph_bytes_per_opportunity": round(graph_bytes / max(1, graph_opps), 1),
                      "arcs_per_opportunity": round(arcs / max(1, graph_opps), 1),
                      "estimated_graph_gb": round(graph_bytes / max(1, graph_opps) * per_sat * args.satellites / 1e9,
                                                  2),
                      "peak_gb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6, 2)}))
    print("\n| pass opportunities | passes solved | median s | p95 s | max s | total s |\n|---|---|---|---|---|---|")
    for lo, hi in SIZES:
        secs = sorted(t for n, t in timings if lo <= n <= hi)
        if secs:
            label = f"{lo}-{hi}" if hi < 10 ** 9 else f">{lo - 1}"
            print(f"| {label} | {len(secs)} | {secs[len(secs) // 2]:.4f} | {secs[int(0.95 * (len(secs) - 1))]:.4f} | "
                  f"{secs[-1]:.3f} | {sum(secs):.1f} |")
    if timings:
        total = sum(t for _, t in timings)
        solved_sats = min(args.solve, len(sample))
        print(f"\none price round, every pass solved once: about {total / solved_sats * args.satellites:.0f} "
              f"core-seconds for {args.satellites} satellites ({total / solved_sats:.2f} s a satellite)")


if __name__ == "__main__":
    main()
