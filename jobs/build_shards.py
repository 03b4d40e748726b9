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

from eosp.args import Parser, add_config_args, add_memory_arg, config_from_args, prefixed_config, run_job  # noqa: E402
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

    InputError (one line) when the file is not a readable shard of this very data set: never replaced.
    """
    from eosp.errors import InputError
    from eosp.shards.io import ShardReader, is_shard

    if not path.exists():
        return None
    if not is_shard(path):
        raise InputError(path, "exists and is not a shard written by eosp: refusing to replace it (use another --out)")
    first = shard * cfg.per_shard
    expected = min(cfg.n_instances, first + cfg.per_shard) - first
    try:
        reader = ShardReader(path)
        if not _same_dataset(reader.extra.get("dataset", {}), to_dict(cfg)):
            raise InputError(path, "belongs to a data set with other settings: use another --out")
        if len(reader) != expected:
            raise InputError(path, f"holds {len(reader)} instances, expected {expected}")
        insts = list(reader)
    except InputError as exc:
        if "other settings" in exc.message:
            raise
        raise InputError(path, f"{exc.message} (not a complete shard of this data set: use another --out)") from None
    return {"file": path.name, "instances": [i.name for i in insts], "seconds": 0.0, "resumed": True,
            "nodes": int(sum(i.n_nodes for i in insts)), "arcs": int(sum(i.unpruned().n_arcs for i in insts)),
            "pruned_arcs": int(sum(i.pruned().n_arcs for i in insts)), "bytes": path.stat().st_size}


DATASET_KIND = "dataset"  # the mark (eosp.ownership) of a data set directory: its .eosp.json and manifest.json


def check_dataset_out(cfg: DatasetConfig) -> Path:
    """Refuse, before Ray starts or anything is written, an --out that is a file or a directory eosp did not write
    (a user's files are never written beside); an empty directory or one of eosp's data sets (resumed) is kept."""
    from eosp.errors import InputError
    from eosp.ownership import check_output

    try:
        return check_output(cfg.out, DATASET_KIND, directory=True, reuse=True)
    except InputError as exc:
        raise InputError(f"--out {cfg.out}", exc.message) from None


def run(cfg: DatasetConfig, ray_cfg: RayConfig) -> dict:
    import ray

    from eosp.atomic import atomic_path
    from eosp.jobs.ray_init import init_ray
    from eosp.ownership import json_mark, kind_of, mark_dir

    out = check_dataset_out(cfg)
    n_shards = (cfg.n_instances + cfg.per_shard - 1) // cfg.per_shard
    from eosp.instances.generator import require_generate_memory

    extra = {k: v for k, v in changed(cfg.instance, InstanceConfig()).items()
             if k not in ("n_acquisitions", "seed", "family")}
    require_generate_memory(family_config(cfg.family, cfg.n_acquisitions, cfg.seed, **extra), "--n-acquisitions",
                            parallel=max(1, min(n_shards, ray_cfg.num_cpus or 1)))
    out.mkdir(parents=True, exist_ok=True)
    if kind_of(out) != DATASET_KIND:
        mark_dir(out, DATASET_KIND)  # from now on eosp's: a rerun resumes in it
    for stale in out.glob(".shard-*.parquet.*"):  # temporaries of a killed run, never renamed into place
        stale.unlink(missing_ok=True)
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
    manifest = {**json_mark(DATASET_KIND), "dataset": to_dict(cfg), "shards": [done[s] for s in range(n_shards)],
                "wall_seconds": round(time.perf_counter() - t0, 3)}
    with atomic_path(Path(cfg.out) / "manifest.json") as tmp:
        tmp.write_text(json.dumps(manifest, indent=1))
    return manifest


def main(argv: list[str] | None = None, prog: str = "build_shards.py") -> int:
    """The job (`prog`: how errors name it, e.g. ``eosp build-shards``); user errors are one line, exit 2."""
    return run_job(_main, argv, prog)


def _main(argv: list[str] | None) -> int:
    from eosp import errors

    p = Parser(prog=errors.PROG, description=__doc__.splitlines()[0])
    add_config_args(p, DatasetConfig)  # (--max-memory-gb is not a setting of the data set: not in its config)
    add_config_args(p, RayConfig, prefix="ray.")
    add_memory_arg(p)
    ns = p.parse_args(argv)
    from eosp.memory import memory_ceiling

    with memory_ceiling(ns.max_memory_gb):
        return _build(ns)


def _build(ns: argparse.Namespace) -> int:
    cfg = config_from_args(DatasetConfig, ns)
    ray_cfg = prefixed_config(RayConfig, ns, "ray.")
    from eosp.jobs.preflight import require_findable

    require_findable(cfg.out, "--out")
    from eosp.errors import InputError

    for flag, path in (("--instance.orbit.tle", cfg.instance.orbit.tle),
                       ("--instance.targets.csv-path", cfg.instance.targets.csv_path)):
        if path and not Path(path).is_file():  # read by every Ray task: checked here, before Ray starts
            raise InputError(f"{flag} {path}", "file not found")
    m = run(cfg, ray_cfg)
    tot = sum(s["bytes"] for s in m["shards"])
    print(f"[build_shards] {cfg.n_instances} instances in {len(m['shards'])} shards, {tot / 1e6:.1f} MB, "
          f"{m['wall_seconds']:.1f} s -> {cfg.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
