"""Generate a data set of Parquet shards, one Ray task per shard.

    python jobs/build_shards.py --out data/train --family uniform --n-acquisitions 100 --n-instances 128
    ray job submit --working-dir . -- python jobs/build_shards.py --out /shared/data/train ...

Instance k of the data set is generated from seed ``seed + k``; every shard is
written atomically and the manifest (``manifest.json``) last, so a data set
with a manifest is complete.

A rerun with the same settings resumes: complete shards of the same data set are
checked (every instance read) and kept, temporaries of a killed run are removed, and
only the missing shards are built.  A shard of another configuration in ``--out``
is refused, not replaced.  (Tests kill the driver after N shards with the
environment variable ``EOSP_FAULT_KILL_AFTER=N``.)
"""

from __future__ import annotations

import argparse
import json
import os
import signal
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


def _same_dataset(a: dict, b: dict) -> bool:
    """Two data set configurations (to_dict) that differ at most in where they are written."""
    strip = lambda d: {k: v for k, v in json.loads(json.dumps(d)).items() if k != "out"}  # noqa: E731
    return strip(a) == strip(b)


def existing_shard(cfg: DatasetConfig, shard: int, path: Path) -> dict | None:
    """The manifest entry of a complete shard `path` of this data set, None when it is not there yet.

    SystemExit (one line) when the file is not a readable shard of this very data set: it is the user's to remove.
    """
    from eosp.errors import InputError
    from eosp.shards.io import ShardReader

    if not path.exists():
        return None
    first = shard * cfg.per_shard
    expected = min(cfg.n_instances, first + cfg.per_shard) - first
    try:
        reader = ShardReader(path)
        if not _same_dataset(reader.extra.get("dataset", {}), to_dict(cfg)):
            raise SystemExit(f"error: {path} belongs to a data set with other settings: use another --out, "
                             "or remove it")
        if len(reader) != expected:
            raise InputError(path, f"holds {len(reader)} instances, expected {expected}")
        insts = list(reader)
    except InputError as exc:
        raise SystemExit(f"error: {exc} (not a complete shard of this data set: remove it to rebuild it)") from None
    return {"file": path.name, "instances": [i.name for i in insts], "seconds": 0.0, "resumed": True,
            "nodes": int(sum(i.n_nodes for i in insts)), "arcs": int(sum(i.unpruned().n_arcs for i in insts)),
            "pruned_arcs": int(sum(i.pruned().n_arcs for i in insts)), "bytes": path.stat().st_size}


def run(cfg: DatasetConfig, ray_cfg: RayConfig) -> dict:
    import ray

    from eosp.atomic import atomic_path
    from eosp.jobs.ray_init import init_ray

    out = Path(cfg.out)
    if out.exists() and not out.is_dir():
        raise SystemExit(f"error: --out {out} is a file, not a directory")
    out.mkdir(parents=True, exist_ok=True)
    for stale in out.glob(".shard-*.parquet.*"):  # temporaries of a killed run, never renamed into place
        stale.unlink(missing_ok=True)
    n_shards = (cfg.n_instances + cfg.per_shard - 1) // cfg.per_shard
    done: dict[int, dict] = {}
    for s in range(n_shards):
        entry = existing_shard(cfg, s, out / f"shard-{s:05d}.parquet")
        if entry is not None:
            done[s] = entry
    if done:
        print(f"[build_shards] resuming: {len(done)} of {n_shards} shards already complete", flush=True)
    init_ray(ray_cfg.address, ray_cfg.num_cpus)
    task = ray.remote(num_cpus=1)(build_shard)
    pending = {task.remote(cfg, s): s for s in range(n_shards) if s not in done}
    kill_after = int(os.environ.get("EOSP_FAULT_KILL_AFTER", "0") or 0)
    built = 0
    t0 = time.perf_counter()
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        s = pending.pop(ready[0])
        done[s] = ray.get(ready[0])
        built += 1
        print(f"[build_shards] shard {len(done)}/{n_shards} ({done[s]['file']}, {len(done[s]['instances'])} "
              f"instances, {done[s]['seconds']:.1f} s)", flush=True)
        if built == kill_after:  # fault injection for the tests: die like a killed job
            os.kill(os.getpid(), signal.SIGKILL)
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
    from eosp.jobs.preflight import require_findable

    require_findable(cfg.out, "--out")
    m = run(cfg, ray_cfg)
    tot = sum(s["bytes"] for s in m["shards"])
    print(f"[build_shards] {cfg.n_instances} instances in {len(m['shards'])} shards, {tot / 1e6:.1f} MB, "
          f"{m['wall_seconds']:.1f} s -> {cfg.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
