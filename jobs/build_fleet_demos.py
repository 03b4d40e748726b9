"""Demonstrations for the fleet policy: the fleet solver's schedules of training fleets, one Ray task per fleet.

    python jobs/build_fleet_demos.py --fleets data/fleets/gen-train data/fleets/aeossp-train --out data/demos/train \\
        --time-limit 60
    ray job submit --working-dir . -- python jobs/build_fleet_demos.py --fleets /shared/fleets --out /shared/demos

Each fleet (a fleet directory, ``eosp generate --fleet`` or ``eosp import CASE``; an aeossp case directory; or a
directory holding them) is solved by the fleet solver (``--time-limit`` seconds of search after its pass graphs)
in its own Ray task; its schedule is written to ``OUT/<fingerprint>.parquet`` (a fleet schedule: the fleet's
fingerprint inside, so a schedule is never replayed on another fleet), then its record ``OUT/<fingerprint>.json``
(the fleet's path, the solver's WCR, bound and settings); ``OUT/manifest.json`` last.  A rerun with the same
settings keeps every fleet that has its record (resumable); a record of other settings is refused.  The
imitation job (jobs/pretrain_fleet.py) replays each schedule in the constellation environment
(:class:`eosp.envs.constellation.ScheduleFollower`): the actions and states it learns from
(:mod:`eosp.training.fleet_demos`).
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from eosp.args import Parser, add_config_args, config_from_args, run_job
from eosp.config import WEEK_S, RayConfig, choice, ranged, to_dict

KIND = "fleet-demos"


@dataclass
class FleetDemoConfig:
    """Demonstrations of the fleet solver (``jobs/build_fleet_demos.py``)."""

    fleets: tuple[str, ...] = ()
    """Fleet directories, aeossp case directories, or directories holding them (never the evaluation splits)."""
    out: str = ""
    """Directory of the demonstrations (created; resumed when it holds demos of the same settings)."""
    time_limit: float = ranged(60.0, 0, WEEK_S, lo_open=True)
    """Seconds of fleet-solver search per fleet, after its pass graphs are built."""
    pass_solver: str = choice("exact", "greedy", "ramp", "exact")
    """The fleet solver's pass solver (exact: its best schedules, and a proven bound)."""
    seed: int = ranged(0, 0)
    ray: RayConfig = field(default_factory=RayConfig)


def solve_fleet_demo(path: str, time_limit: float, pass_solver: str, seed: int, out: str) -> dict:
    """One fleet solved by the fleet solver, its schedule written to `out` (a Ray task); returns its record."""
    from eosp.envs.constellation import read_fleet_dir
    from eosp.fleet.io import fingerprint, write_schedule
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import solve

    t0 = time.perf_counter()
    fleet, opps = read_fleet_dir(path)
    sol = solve(fleet, opps, FleetConfig(pass_solver=pass_solver, time_limit=time_limit, seed=seed))
    info = {"value": sol.value, "bound": sol.bound, "solver": "fleet", "pass_solver": pass_solver,
            "time_limit": time_limit}
    write_schedule(sol.schedule, fleet, out, overwrite=True, info=info)
    return {"fleet": str(Path(path).resolve()), "fingerprint": fingerprint(fleet), "schedule": Path(out).name,
            "satellites": len(fleet.satellites), "tasks": len(fleet.tasks), "observations": len(sol.schedule),
            "wcr": sol.value, "bound": sol.bound, "rounds": sol.info["rounds"], "settings": settings_of(time_limit,
                                                                                                       pass_solver, seed),
            "seconds": round(time.perf_counter() - t0, 2)}


def complete_day(fleet_path: str, part, freeze_s: float, time_limit: float):
    """The fleet solver's completion of a partial schedule `part` (a Ray task of the DAgger rounds of
    jobs/pretrain_fleet.py): the passes that start before `freeze_s` keep `part`'s observations, the rest of the day
    is solved again (`time_limit` seconds after the fleet is read)."""
    from eosp.envs.constellation import read_fleet_dir
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.solve import solve

    t0 = time.perf_counter()
    fleet, opps = read_fleet_dir(fleet_path)
    return solve(fleet, opps, FleetConfig(time_limit=time_limit), initial=part, freeze_until_s=freeze_s,
                 t0=t0).schedule


def settings_of(time_limit: float, pass_solver: str, seed: int) -> dict:
    return {"time_limit": time_limit, "pass_solver": pass_solver, "seed": seed}


def run(cfg: FleetDemoConfig) -> dict:
    import ray

    from eosp.atomic import atomic_path
    from eosp.envs.constellation import expand_fleets, read_fleet_dir
    from eosp.errors import InputError
    from eosp.fleet.io import fingerprint
    from eosp.jobs.ray_init import init_ray
    from eosp.ownership import check_output, json_mark, kind_of, mark_dir

    try:
        out = check_output(cfg.out, KIND, directory=True, reuse=True)
    except InputError as exc:
        raise InputError(f"--out {cfg.out}", exc.message) from None
    paths = expand_fleets(cfg.fleets)
    from eosp.fleet.aeossp import refuse_evaluation_case

    for path in paths:
        refuse_evaluation_case(path, "--fleets")
    out.mkdir(parents=True, exist_ok=True)
    if kind_of(out) != KIND:
        mark_dir(out, KIND)
    want = settings_of(cfg.time_limit, cfg.pass_solver, cfg.seed)
    done, todo = {}, []
    for p in paths:
        key = fingerprint(read_fleet_dir(p, with_opportunities=False)[0])[:16]
        rec_path = out / f"{key}.json"
        if rec_path.exists():
            try:
                rec = json.loads(rec_path.read_text())
            except ValueError:
                raise InputError(rec_path, "not readable JSON: not a demo record eosp wrote (use another --out)") \
                    from None
            if not isinstance(rec, dict) or rec.get("settings") != want:
                raise InputError(rec_path, "demonstrations of other settings: use another --out")
            if (out / rec["schedule"]).exists():
                done[key] = rec
                continue
        todo.append((p, key))
    if done:
        print(f"[build_fleet_demos] resuming: {len(done)} of {len(paths)} fleets already solved", flush=True)
    init_ray(cfg.ray.address, cfg.ray.num_cpus)
    task = ray.remote(num_cpus=1)(solve_fleet_demo)
    pending = {task.remote(str(p), cfg.time_limit, cfg.pass_solver, cfg.seed, str(out / f"{key}.parquet")): key
               for p, key in todo}
    t0 = time.perf_counter()
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        key = pending.pop(ready[0])
        rec = ray.get(ready[0])
        with atomic_path(out / f"{key}.json") as tmp:
            tmp.write_text(json.dumps(rec, indent=1))
        done[key] = rec
        print(f"[build_fleet_demos] {len(done)}/{len(paths)} {rec['fleet']}: {rec['satellites']} satellites, "
              f"{rec['observations']} observations, WCR {rec['wcr']:.4f} (bound {rec['bound']:.4f}), "
              f"{rec['seconds']:.0f} s", flush=True)
    manifest = {**json_mark(KIND), "settings": to_dict(cfg), "demos": sorted(done.values(), key=lambda r: r["fleet"]),
                "wall_seconds": round(time.perf_counter() - t0, 2)}
    with atomic_path(out / "manifest.json") as tmp:
        tmp.write_text(json.dumps(manifest, indent=1))
    return manifest


def main(argv: list[str] | None = None) -> int:
    """The job; user errors are one line ``build_fleet_demos.py: error: ...`` and exit 2 before Ray starts."""
    return run_job(_main, argv, "build_fleet_demos.py")


def _main(argv: list[str] | None) -> int:
    from eosp.errors import InputError
    from eosp.jobs.preflight import require_findable

    p = Parser(prog="build_fleet_demos.py", description=__doc__.splitlines()[0])
    add_config_args(p, FleetDemoConfig)
    cfg = config_from_args(FleetDemoConfig, p.parse_args(argv))
    if not cfg.out:
        raise InputError("--out", "required")
    if not cfg.fleets:
        raise InputError("--fleets", "required: fleet directories, aeossp case directories, or directories of them")
    require_findable(cfg.out, "--out")
    m = run(cfg)
    wcr = [d["wcr"] for d in m["demos"]]
    print(f"[build_fleet_demos] {len(m['demos'])} fleets -> {cfg.out}, mean WCR {sum(wcr) / max(len(wcr), 1):.4f} "
          f"({m['wall_seconds']:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
