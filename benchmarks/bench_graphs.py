"""Graph-building benchmark: time to generate an instance and build its pruned discrete graph,
nodes and arcs before/after pruning, continuous-graph arcs, shard size on disk.

    python benchmarks/bench_graphs.py --sizes 100 300 1000 1500 --families uniform clusters

Runs on one core (numba is single-threaded here); the first, tiny instance only
warms up the JIT.  Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from eosp.config import family_config
from eosp.graphs.build import build_arcs
from eosp.graphs.continuous import continuous_graph
from eosp.graphs.prune import prune
from eosp.instances.generator import generate, scenario_of
from eosp.shards.io import write_shard


def bench(family: str, n: int, seed: int, step: float) -> dict:
    cfg = family_config(family, n, seed, graph={"step_s": step})
    t0 = time.perf_counter()
    inst = generate(cfg)
    t_gen = time.perf_counter() - t0
    g = inst.unpruned()
    t0 = time.perf_counter()
    build_arcs(g.node_acq, g.node_time, inst.node_attitude.astype(np.float64), inst.acqs.duration, g.acq_ptr,
               scenario_of(inst).slew_model, scenario_of(inst).max_slew())
    t_arcs = time.perf_counter() - t0
    t0 = time.perf_counter()
    pg = prune(g, inst.acqs.duration)
    t_prune = time.perf_counter() - t0
    inst.pruned_graph = pg
    cs, _ = continuous_graph(pg)
    cu, _ = continuous_graph(g)
    with tempfile.TemporaryDirectory() as d:
        full = write_shard(Path(d) / "full.parquet", [inst])
        pruned_only = write_shard(Path(d) / "pruned.parquet", [inst], include_unpruned=False)
        size_full, size_pruned = os.path.getsize(full), os.path.getsize(pruned_only)
    return {"family": family, "n": n, "nodes": g.n_nodes, "arcs": g.n_arcs, "pruned": pg.n_arcs,
            "cont_unpruned": int(cu.size), "cont_pruned": int(cs.size), "t_gen": t_gen, "t_arcs": t_arcs,
            "t_prune": t_prune, "mb_full": size_full / 1e6, "mb_pruned": size_pruned / 1e6}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[100, 300, 1000, 1500])
    p.add_argument("--families", nargs="+", default=["uniform", "clusters"])
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--step", type=float, default=1.0)
    a = p.parse_args()
    bench("uniform", 10, 0, a.step)  # JIT warm-up
    print("| family | acq | nodes | arcs unpruned | arcs pruned | kept | cont. arcs (unpruned / pruned) "
          "| generate (s) | of which arcs (s) | prune (s) | generate + prune (s) | shard MB (all / pruned only) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for fam in a.families:
        for n in a.sizes:
            r = bench(fam, n, a.seed, a.step)
            print(f"| {fam} | {n} | {r['nodes']:,} | {r['arcs']:,} | {r['pruned']:,} | "
                  f"{r['pruned'] / r['arcs']:.1%} | {r['cont_unpruned']:,} / {r['cont_pruned']:,} | "
                  f"{r['t_gen']:.2f} | {r['t_arcs']:.2f} | {r['t_prune']:.2f} | {r['t_gen'] + r['t_prune']:.2f} | "
                  f"{r['mb_full']:.1f} / {r['mb_pruned']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
