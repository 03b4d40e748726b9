"""Generate a data set of Parquet shards, one Ray task per shard.

    python jobs/build_shards.py --out data/train --family uniform --n-acquisitions 100 --n-instances 128
    ray job submit --working-dir . -- python jobs/build_shards.py --out /shared/data/train ...

Instance k of the data set is generated from seed ``seed + k``; every shard is
written atomically and the manifest (``manifest.json``) last, so a data set
with a manifest is complete.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from eosp.args import add_config_args, config_from_args, prefixed_config  # noqa: E402
from eosp.config import DatasetConfig, InstanceConfig, RayConfig, changed, family_config, to_dict  # noqa: E402


def build_shard(cfg: DatasetConfig, shard: int) -> dict:
    """Generate the instances of one shard and write it; returns its manifest entry."""
    from eosp.instances.generator import generate
    from eosp.shards.io import write_shard

    t0 = time.perf_counter()
    first = shard * cfg.per_shard
    seeds = range(cfg.seed + first, cfg.seed + min(cfg.n_instances, first + cfg.per_shard))
    extra = {k: v for k, v in changed(cfg.instance, InstanceConfig()).items()
             if k not in ("n_acquisitions", "seed", "family")}
    insts = [generate(family_config(cfg.family, cfg.n_acquisitions, s, **extra)) for s in seeds]
    path = Path(cfg.out) / f"shard-{shard:05d}.parquet"
    write_shard(path, insts, include_unpruned=cfg.include_unpruned, extra_meta={"dataset": to_dict(cfg)})
    return {"file": path.name, "instances": [i.name for i in insts], "seconds": round(time.perf_counter() - t0, 3),
            "nodes": int(sum(i.n_nodes for i in insts)), "arcs": int(sum(i.unpruned().n_arcs for i in insts)),
            "pruned_arcs": int(sum(i.pruned().n_arcs for i in insts)), "bytes": path.stat().st_size}


def run(cfg: DatasetConfig, ray_cfg: RayConfig) -> dict:
    import ray

    from eosp.atomic import atomic_path
    from eosp.jobs.ray_init import init_ray

    init_ray(ray_cfg.address, ray_cfg.num_cpus)
    Path(cfg.out).mkdir(parents=True, exist_ok=True)
    n_shards = (cfg.n_instances + cfg.per_shard - 1) // cfg.per_shard
    task = ray.remote(num_cpus=1)(build_shard)
    pending = {task.remote(cfg, s): s for s in range(n_shards)}
    done: dict[int, dict] = {}
    t0 = time.perf_counter()
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        s = pending.pop(ready[0])
        done[s] = ray.get(ready[0])
        print(f"[build_shards] shard {len(done)}/{n_shards} ({done[s]['file']}, {len(done[s]['instances'])} "
              f"instances, {done[s]['seconds']:.1f} s)", flush=True)
    manifest = {"dataset": to_dict(cfg), "shards": [done[s] for s in range(n_shards)],
                "wall_seconds": round(time.perf_counter() - t0, 3)}
    with atomic_path(Path(cfg.out) / "manifest.json") as tmp:
        tmp.write_text(json.dumps(manifest, indent=1))
    return manifest


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_config_args(p, DatasetConfig)
    add_config_args(p, RayConfig, prefix="ray.")
    ns = p.parse_args(argv)
    cfg = config_from_args(DatasetConfig, ns)
    ray_cfg = prefixed_config(RayConfig, ns, "ray.")
    m = run(cfg, ray_cfg)
    tot = sum(s["bytes"] for s in m["shards"])
    print(f"[build_shards] {cfg.n_instances} instances in {len(m['shards'])} shards, {tot / 1e6:.1f} MB, "
          f"{m['wall_seconds']:.1f} s -> {cfg.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
