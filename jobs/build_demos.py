"""Expert demonstrations for a data set: the exact solver's schedules as environment actions.

    python jobs/build_demos.py --data data/train data/val --modes unitary utility --time-limit 30
    ray job submit --working-dir . -- python jobs/build_demos.py --data /shared/data/train ...

One Ray task per (shard, mode) solves every instance of the shard exactly (time
limit per instance; at the limit the best schedule found is kept and its gap
recorded), replays it in the environment (an action the mask forbids is a bug,
never written) and labels each step with the set of optimal actions.  Files go
to ``<data>/demos/<mode>/`` beside the shards (format: eosp.training.demos),
each written atomically, the manifest last; a rerun skips the files already
written (resumable).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from eosp.args import Parser, add_config_args, config_from_args, prefixed_config, run_job
from eosp.config import DemoConfig, RayConfig, to_dict
from eosp.errors import InputError


def run(cfg: DemoConfig, ray_cfg: RayConfig) -> dict:
    import ray

    from eosp.atomic import atomic_path
    from eosp.jobs.ray_init import init_ray
    from eosp.shards.io import dataset_shards
    from eosp.training.demos import MODES, demo_file, is_complete, solve_shard

    for m in cfg.modes:
        if m not in MODES:
            raise InputError("--modes", f"unknown mode {m!r}; one of {', '.join(MODES)}")
    if not cfg.time_limit > 0:
        raise InputError("--time-limit", f"must be a positive number of seconds, got {cfg.time_limit}")
    jobs, skipped = [], 0
    for data in cfg.data:
        for shard in dataset_shards(data):
            for mode in cfg.modes:
                if is_complete(demo_file(Path(shard), mode), mode, cfg.action_sets):
                    skipped += 1
                else:
                    jobs.append((Path(shard), mode))
    init_ray(ray_cfg.address, ray_cfg.num_cpus)
    task = ray.remote(num_cpus=1)(solve_shard)
    pending = {task.remote(str(s), m, time_limit=cfg.time_limit, action_sets=cfg.action_sets, beam=cfg.beam,
                           prune=cfg.prune, out=str(demo_file(s, m)),
                           sets_max_acquisitions=cfg.sets_max_acquisitions): (s, m) for s, m in jobs}
    print(f"[build_demos] {len(jobs)} (shard, mode) tasks, {skipped} already done", flush=True)
    done: list[dict] = []
    t0 = time.perf_counter()
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        s, m = pending.pop(ready[0])
        r = ray.get(ready[0])
        done.append({"data": str(s.parent), "mode": m, **r})
        print(f"[build_demos] {len(done)}/{len(jobs)} {s.parent.name}/{s.name} {m}: {r['instances']} instances, "
              f"{r['steps']} steps, {r['optimal']}/{r['instances']} proven optimal (max gap {r['max_gap']:.2e}), "
              f"solve {r['solve_s']:.1f} s, task {r['seconds']:.1f} s", flush=True)
    wall = time.perf_counter() - t0
    for data in cfg.data:
        for m in cfg.modes:
            d = Path(data) / "demos" / m
            entries = [x for x in done if x["data"] == str(Path(data)) and x["mode"] == m]
            manifest = {"config": to_dict(cfg), "mode": m, "written_this_run": entries,
                        "files": sorted(p.name for p in d.glob("*.parquet"))}
            with atomic_path(d / "manifest.json") as tmp:
                tmp.write_text(json.dumps(manifest, indent=1))
    return {"tasks": done, "skipped": skipped, "wall_seconds": round(wall, 3)}


def main(argv: list[str] | None = None) -> int:
    """The job; user errors are one line ``build_demos.py: error: ...`` and exit 2 before Ray starts."""
    return run_job(_main, argv, "build_demos.py")


def _main(argv: list[str] | None) -> int:
    p = Parser(prog="build_demos.py", description=__doc__.splitlines()[0])
    add_config_args(p, DemoConfig)
    add_config_args(p, RayConfig, prefix="ray.")
    ns = p.parse_args(argv)
    cfg = config_from_args(DemoConfig, ns)
    from eosp.jobs.preflight import require_data, require_findable

    for data in cfg.data:  # the demos are written under <data>/demos/
        require_findable(data, "--data")
    require_data(cfg.data, "--data")
    out = run(cfg, prefixed_config(RayConfig, ns, "ray."))
    steps = sum(t["steps"] for t in out["tasks"])
    n = sum(t["instances"] for t in out["tasks"])
    opt = sum(t["optimal"] for t in out["tasks"])
    print(f"[build_demos] {n} (instance, mode) solved, {opt} proven optimal, {steps} steps, "
          f"{out['wall_seconds']:.1f} s wall ({out['skipped']} files skipped as already done)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
