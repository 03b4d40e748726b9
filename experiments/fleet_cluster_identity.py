"""The fleet job on a local multi-node Ray cluster: for fixed rounds, the same schedule with any number of actors.

    python experiments/fleet_cluster_identity.py --fleet-dir fleet-200 --out runs/identity --nodes 2 \
        --cpus-per-node 2 --workers 1 2 4 --rounds 6

Starts a Ray cluster of ``--nodes`` nodes on this machine (``ray.cluster_utils.Cluster``, ``--cpus-per-node``
logical CPUs each: more actors than this machine has cores, so the times say nothing, only the schedule counts),
runs ``jobs/solve_fleet.py``'s job on it once per worker count (1: in this process, no Ray; more: Ray actors, the
driver lean when ``--lean-driver yes``) with ``--rounds`` fixed price rounds, and compares every schedule row for
row, and the value, bound and pass-solve count, with the first.  Prints one line per run and whether all agree;
exits 1 when one differs.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def main() -> int:
    import ray
    from ray.cluster_utils import Cluster

    from eosp.fleet.io import read_fleet, read_schedule
    from eosp.jobs import solve_fleet as job_mod
    from eosp.kinds.fleet.config import FleetConfig

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fleet-dir", required=True)
    ap.add_argument("--out", required=True, help="a new directory for the run dirs")
    ap.add_argument("--nodes", type=int, default=2)
    ap.add_argument("--cpus-per-node", type=int, default=2)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--warm-start", default="none")
    ap.add_argument("--lean-driver", default="yes", choices=["auto", "yes", "no"])
    args = ap.parse_args()
    out = Path(args.out)
    if out.exists():
        print(f"{out}: exists; give a new directory", file=sys.stderr)
        return 2
    out.mkdir(parents=True)
    fleet, _ = read_fleet(args.fleet_dir, with_opportunities=False)

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": args.cpus_per_node})
    for _ in range(args.nodes - 1):
        cluster.add_node(num_cpus=args.cpus_per_node)
    cluster.wait_for_nodes()
    runs = []
    try:
        for w in args.workers:
            run_dir = out / f"w{w}"
            job = job_mod.SolveFleetJob(
                fleet_dir=args.fleet_dir, run_dir=str(run_dir), lean_driver=args.lean_driver,
                fleet=FleetConfig(rounds=args.rounds, time_limit=None, workers=w, seed=0, warm_start=args.warm_start),
                mlflow_uri=f"sqlite:///{out.resolve()}/mlflow.db",
                ray=job_mod.RayConfig(address=cluster.address if w > 1 else ""))
            t = time.perf_counter()
            res = job_mod.run(job)
            s, _ = read_schedule(run_dir / "schedule.parquet", fleet)
            rows = list(zip(s.satellite.tolist(), s.task.tolist(), s.start_us.tolist(), s.end_us.tolist()))
            runs.append((w, rows, res))
            print(json.dumps({"workers": w, "nodes": res.get("nodes"), "lean_driver": res.get("lean_driver"),
                              "rows": len(rows), "value": res["value"], "bound": res["bound"],
                              "pass_solves": res["pass_solves"], "faults": res.get("faults"),
                              "wall_s": round(time.perf_counter() - t, 1)}), flush=True)
            if ray.is_initialized():
                ray.shutdown()
    finally:
        cluster.shutdown()
    _, rows0, res0 = runs[0]
    same = all(rows == rows0 and (r["value"], r["bound"], r["pass_solves"]) ==
               (res0["value"], res0["bound"], res0["pass_solves"]) for _, rows, r in runs[1:])
    print(f"the same schedule, value, bound and pass solves with {', '.join(str(w) for w, _, _ in runs)} workers: "
          f"{'yes' if same else 'NO'}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
