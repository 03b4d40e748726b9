"""Generate synthetic fleets with their opportunities, one Ray task per fleet (resumable).

    python jobs/generate_fleets.py --out /shared/fleets --count 8 --gen.satellites 200 --gen.tasks 20000 --gen.hours 24
    ray job submit --working-dir . -- python jobs/generate_fleets.py --out /shared/fleets ...

Fleet k is ``eosp generate --fleet`` with seed ``gen.seed + k``, written to ``OUT/fleet-KKKKK`` (a fleet
directory), then its record ``OUT/fleet-KKKKK.json`` (the generator settings, the fingerprint, the counts and
times); ``OUT/manifest.json`` is written last.  A rerun with the same settings keeps every fleet that has its
record and builds the others (a fleet directory without a record is from a killed run and is rebuilt); a
record of other settings in ``--out`` is refused, not replaced.  The memory of one fleet is estimated before
any work and checked against this machine times the fleets built at once.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from eosp.args import Parser, add_config_args, add_memory_arg, config_from_args, run_job  # noqa: E402
from eosp.config import RayConfig, ranged, to_dict  # noqa: E402
from eosp.fleet.generate import FleetGenConfig  # noqa: E402

KIND = "fleet-set"


@dataclass
class FleetSetConfig:
    """A set of synthetic fleets (``jobs/generate_fleets.py``)."""

    out: str = ""
    """Directory of the fleets (created; resumed when it holds fleets of the same settings)."""
    count: int = ranged(1, 1, 100_000)
    """Fleets to generate; fleet k uses seed gen.seed + k."""
    gen: FleetGenConfig = field(default_factory=FleetGenConfig)
    ray: RayConfig = field(default_factory=RayConfig)


def build_fleet(gen: FleetGenConfig, path: str) -> dict:
    """Generate one fleet, compute its opportunities, write it; returns its record."""
    from eosp.fleet.generate import generate
    from eosp.fleet.io import fingerprint, write_fleet
    from eosp.fleet.opportunities import compute, require_scan_memory

    t0 = time.perf_counter()
    fleet = generate(gen)
    opps = compute(fleet, *require_scan_memory(fleet, "--gen.satellites/--gen.tasks/--gen.hours"))
    write_fleet(fleet, opps, path, overwrite=True)
    return {"fleet": Path(path).name, "case_id": fleet.case_id, "fingerprint": fingerprint(fleet),
            "generator": to_dict(gen), "satellites": len(fleet.satellites), "tasks": len(fleet.tasks),
            "opportunities": len(opps), "passes": opps.n_passes, "seconds": round(time.perf_counter() - t0, 2)}


def existing(cfg: FleetSetConfig, k: int) -> dict | None:
    """The record of fleet k when it is complete and of these settings; None when it must be built."""
    from eosp.errors import InputError

    rec_path = Path(cfg.out) / f"fleet-{k:05d}.json"
    if not rec_path.exists():
        return None
    try:
        rec = json.loads(rec_path.read_text())
    except ValueError:
        raise InputError(rec_path, "not readable JSON: not a fleet record eosp wrote (use another --out)") from None
    want = to_dict(replace(cfg.gen, seed=cfg.gen.seed + k))
    if not isinstance(rec, dict) or rec.get("generator") != want:
        raise InputError(rec_path, "a fleet of other settings: use another --out")
    if rec.get("fleet") != f"fleet-{k:05d}":  # a record eosp wrote names its own fleet directory, nothing else
        raise InputError(rec_path, f"names fleet {rec.get('fleet')!r}, not fleet-{k:05d}: not a fleet record eosp "
                                   "wrote (use another --out)")
    from eosp.fleet.io import is_fleet_dir

    return rec if is_fleet_dir(Path(cfg.out) / rec["fleet"]) else None


def run(cfg: FleetSetConfig) -> dict:
    import ray

    from eosp.atomic import atomic_path
    from eosp.errors import InputError
    from eosp.fleet.generate import check, estimate_bytes
    from eosp.jobs.ray_init import init_ray
    from eosp.memory import require_memory
    from eosp.ownership import check_output, json_mark, kind_of, mark_dir

    try:
        out = check_output(cfg.out, KIND, directory=True, reuse=True)
    except InputError as exc:
        raise InputError(f"--out {cfg.out}", exc.message) from None
    try:
        check(cfg.gen)  # the request as a whole (start, windows, planes), before anything is created
    except ValueError as exc:  # "FleetGenConfig.start: reason" -> "--gen.start: reason"
        name, _, reason = str(exc).partition(": ")
        raise InputError("--gen." + name.rpartition(".")[2].replace("_", "-"), reason) from None
    parallel = max(1, min(cfg.count, cfg.ray.num_cpus))
    require_memory("--gen.satellites/--gen.tasks/--gen.hours", estimate_bytes(cfg.gen) * parallel,
                   f"{parallel} fleet(s) of {cfg.gen.satellites} satellites and {cfg.gen.tasks} tasks over "
                   f"{cfg.gen.hours:g} h at once")
    out.mkdir(parents=True, exist_ok=True)
    if kind_of(out) != KIND:
        mark_dir(out, KIND)
    done = {k: rec for k in range(cfg.count) if (rec := existing(cfg, k)) is not None}
    if done:
        print(f"[generate_fleets] resuming: {len(done)} of {cfg.count} fleets already complete", flush=True)
    init_ray(cfg.ray.address, cfg.ray.num_cpus)
    task = ray.remote(num_cpus=1)(build_fleet)
    pending = {task.remote(replace(cfg.gen, seed=cfg.gen.seed + k), str(out / f"fleet-{k:05d}")): k
               for k in range(cfg.count) if k not in done}
    t0 = time.perf_counter()
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        k = pending.pop(ready[0])
        rec = ray.get(ready[0])
        with atomic_path(out / f"fleet-{k:05d}.json") as tmp:
            tmp.write_text(json.dumps(rec, indent=1))
        done[k] = rec
        print(f"[generate_fleets] fleet {len(done)}/{cfg.count}: {rec['case_id']}, {rec['opportunities']} "
              f"opportunities, {rec['passes']} passes ({rec['seconds']:.1f} s)", flush=True)
    manifest = {**json_mark(KIND), "settings": to_dict(cfg), "fleets": [done[k] for k in range(cfg.count)],
                "wall_seconds": round(time.perf_counter() - t0, 2)}
    with atomic_path(out / "manifest.json") as tmp:
        tmp.write_text(json.dumps(manifest, indent=1))
    return manifest


def main(argv: list[str] | None = None, prog: str = "generate_fleets.py") -> int:
    return run_job(_main, argv, prog)


def _main(argv: list[str] | None) -> int:
    from eosp import errors
    from eosp.errors import InputError
    from eosp.jobs.preflight import require_findable

    p = Parser(prog=errors.PROG, description=__doc__.splitlines()[0])
    add_config_args(p, FleetSetConfig)
    add_memory_arg(p)
    ns = p.parse_args(argv)
    cfg = config_from_args(FleetSetConfig, ns)
    if not cfg.out:
        raise InputError("--out", "required")
    require_findable(cfg.out, "--out")
    from eosp.memory import memory_ceiling

    with memory_ceiling(ns.max_memory_gb):
        m = run(cfg)
    print(f"[generate_fleets] {len(m['fleets'])} fleets -> {cfg.out} ({m['wall_seconds']:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
