"""Compile the kernels of every kind's first commands, so that a planner's first solve answers in its time limit.

    python -m eosp.cli.warmup                 # make demo runs it; a container image can run it at build time
    python -m eosp.cli.warmup --kinds fleet   # one kind only

The project's hot loops are numba kernels compiled on first use and cached beside the package (``__pycache__``);
on a fresh install the first constellation solve spent 12 s of a 10 s limit compiling, and the first learned
solve most of a minute.  This job runs, for every registered problem kind, what a user's first commands run, on
tiny data it makes in a temporary directory and through the command line itself (``eosp.cli.main``, so that the
kernels compiled are the ones the commands call, with the same argument types): ``eosp generate`` or ``import``,
``info``, ``solve`` with each registered solver of the kind (short limits), ``validate``, ``report`` and
``export-schedule``; then an episode of the constellation environment (the fleet policy's training env).  It prints
how long each kind took; a second run finds the cache and takes seconds.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import tempfile
import time
from dataclasses import dataclass, fields
from pathlib import Path

from eosp.args import Parser, add_config_args, config_from_args, run_job

KINDS = ("single-pass", "fleet", "onera", "eosbench", "regional-coverage")

# per solver, the options that keep its warm-up short (a time limit where the config has one, few samples)
SHORT = {"fleet": ["--time-limit", "20", "--rounds", "3"], "fleet-sample": ["--samples", "2", "--time-limit", "3"],
         "sample": ["--samples", "4"], "onera": ["--time-limit", "3", "--bound-time-limit", "2"],
         "coverage": ["--time-limit", "2"], "mip": ["--time-limit", "2"]}


@dataclass
class WarmupConfig:
    """What to compile."""

    kinds: tuple[str, ...] = KINDS
    """Problem kinds whose commands and solvers to run once (every registered solver of each, on tiny data)."""


def cli(argv: list) -> None:
    """One ``eosp`` command in this process, its output kept; a failure is an error naming the command."""
    from eosp.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main([str(a) for a in argv])
    if rc != 0:
        raise RuntimeError(f"warm-up command `eosp {' '.join(map(str, argv))}` exited {rc}: "
                           f"{(err.getvalue() or out.getvalue()).strip()[-500:]}")


def solve_all(kind_name: str, problem: Path, d: Path, suffix: str) -> list[Path]:
    """Each registered solver of the kind once on `problem`, with a short limit; the schedules written."""
    from eosp.kinds import get

    kind = get(kind_name)
    written = []
    for name in kind.solvers:
        limited = any(f.name == "time_limit" and f.default is not None for f in fields(kind.solver_config(name)))
        extra = SHORT.get(name, ["--time-limit", "1"] if limited else [])  # a solver without a limit always ends
        out = d / f"{name}{suffix}"
        cli(["solve", problem, "--solver", name, *extra, "--out", out])
        written.append(out)
    return written


def warm_single_pass(d: Path) -> None:
    cli(["generate", d / "inst", "--n-acquisitions", "30", "--seed", "0"])
    cli(["info", d / "inst"])
    scheds = solve_all("single-pass", d / "inst", d, ".parquet")
    cli(["validate", d / "inst", scheds[0]])
    cli(["report", d / "inst", *scheds[:2], "--out", d / "report.html"])


def warm_fleet(d: Path) -> None:
    """A small generated fleet with conflicts (so that the solver runs price rounds and its Lagrangian bound), every
    fleet solver, the checker, the page, an export; then the constellation environment's episode."""
    cli(["generate", "--fleet", "--satellites", "3", "--tasks", "400", "--hours", "6", "--placement", "clusters",
         "--clusters", "6", "--seed", "0", "--out", d / "fleet"])
    cli(["info", d / "fleet"])
    scheds = solve_all("fleet", d / "fleet", d, ".parquet")
    cli(["solve", d / "fleet", "--solver", "fleet", "--warm-start", "none", "--price-step", "uniform",
         "--energy-bound", "true", "--time-limit", "10", "--rounds", "2", "--out", d / "other.parquet"])
    cli(["validate", d / "fleet", scheds[0]])
    cli(["report", d / "fleet", *scheds[:2], "--out", d / "day.html"])
    cli(["export-schedule", d / "fleet", scheds[0], "--format", "aeossp", "--out", d / "solution.json"])
    episode(d / "fleet")


def episode(fleet_dir: Path) -> None:
    """An episode of the constellation environment, each satellite acting in turn (its first valid observation)."""
    import numpy as np

    from eosp.config import FleetEnvConfig
    from eosp.envs.constellation import ConstellationEnv, prepare_fleet
    from eosp.fleet.geometry import Geometry
    from eosp.fleet.io import read_fleet

    fleet, opps = read_fleet(fleet_dir)
    geo = Geometry(fleet)
    env = ConstellationEnv(FleetEnvConfig(), source=prepare_fleet(fleet, opps, geo=geo))
    obs, _ = env.reset(seed=0)
    while obs:
        (agent, o), = obs.items()
        allowed = np.flatnonzero(o["action_mask"])
        obs, _, term, _, _ = env.step({agent: int(allowed[1] if len(allowed) > 1 else allowed[0])})
        if term["__all__"]:
            break


ONERA_STATION = "43.6,1.44,0.0"


def onera_instance(n: int = 120, seed: int = 0) -> str:
    """An ONERA instance (its .pb text): `n` one-shot requests on 2 satellites over 2 h, a download window each."""
    import numpy as np

    rng = np.random.default_rng(seed)
    lines = [str(n)]
    for r in range(n):
        lines.append(f"{r},2,ONE_SHOT_MONO")
        for k in range(2):
            t = int(rng.integers(0, 7000))
            lines.append(f"{1000 + 2 * r + k},{k},{t},{t + 120},{int(rng.integers(20, 60))},"
                         f"{rng.uniform(-40, 40):.3f},{rng.uniform(-40, 40):.3f},0.0,{rng.uniform(0, 1):.3f}")
    lines += ["2", f"1,0,7300,7500,{ONERA_STATION}", f"2,1,7300,7500,{ONERA_STATION}"]
    return "\n".join(lines) + "\n"


def warm_onera(d: Path) -> None:
    (d / "i.pb").write_text(onera_instance())
    cli(["import", d / "i.pb", "--out", d / "onera"])
    cli(["info", d / "onera"])
    scheds = solve_all("onera", d / "onera", d, ".parquet")
    cli(["validate", d / "onera", scheds[0]])
    cli(["report", d / "onera", *scheds, "--out", d / "onera.html"])


def eosbench_scenario(n_sat: int = 2, n_task: int = 12, seed: int = 0) -> dict:
    """A scenario in EOS-Bench's generator's JSON: agile satellites, tasks with one to two windows per satellite,
    pitch turning 0.5 deg/s through each window."""
    from datetime import datetime, timedelta

    import numpy as np

    rng = np.random.default_rng(seed)
    t0 = datetime(2025, 11, 18, 12, 0, 0)
    sats = [{"id": f"SAT{s}", "orbital_type": "LEO", "satellite_specs": {
        "max_data_storage_GB": 1000.0, "max_operation_time_s": 4500.0, "max_power_W": 500.0},
        "observation_capability": {"sensors": [{"sensor_id": f"SAT{s}_sensor", "data_rate_Mbps": 0.1,
                                                "power_consumption_W": 50.0}]},
        "maneuverability_capability": {"maneuverability_type": "agile"}} for s in range(n_sat)]
    missions = [{"id": f"M{i:03d}", "priority": float(i % 10 + 1),
                 "observation_requirement": {"duration_s": 5.0 + (i % 3) * 5}} for i in range(n_task)]
    obs = []
    for task in range(n_task):
        for sat in range(n_sat):
            for _ in range(int(rng.integers(1, 3))):
                start, n = float(rng.integers(0, 400)), int(rng.integers(20, 60))
                pitch0, roll = float(rng.uniform(-30, 10)), float(rng.uniform(-20, 20))
                pitch = [pitch0 + 0.5 * j for j in range(n)]
                tw = {"start_time": (t0 + timedelta(seconds=start)).isoformat(),
                      "end_time": (t0 + timedelta(seconds=start + n)).isoformat(),
                      "orbit_number": int(rng.integers(1, 3)),
                      "agile_data": {"pitch_angles": pitch, "yaw_angles": [0.1 * j for j in range(n)],
                                     "roll_angles": [roll] * n},
                      "non_agile_data": {"pitch_angle": pitch[n // 2], "yaw_angle": 0.0, "roll_angle": roll}}
                obs.append({"satellite_id": f"SAT{sat}", "sensor_id": f"SAT{sat}_sensor",
                            "mission_id": f"M{task:03d}", "time_windows": [tw]})
    return {"scenario_id": "Scenario_W", "scenario_type": "basic",
            "metadata": {"name": "Scenario_W", "creation_time": t0.isoformat(), "duration": 21600.0, "time_step": 1.0},
            "satellites": sats, "missions": missions, "observation_windows": obs}


def warm_eosbench(d: Path) -> None:
    scen = d / "scenario.json"
    scen.write_text(json.dumps(eosbench_scenario()))
    cli(["info", scen])
    scheds = solve_all("eosbench", scen, d, ".json")
    cli(["solve", scen, "--solver", "eosbench", "--transition", "code", "--time-limit", "1", "--out", d / "c.json"])
    cli(["validate", scen, scheds[0]])


def warm_regional(d: Path) -> None:
    from eosp.regional.tiny import tiny

    case = tiny(d / "case")
    cli(["info", case])
    scheds = solve_all("regional-coverage", case, d, ".json")
    cli(["validate", case, scheds[0]])
    cli(["report", case, *scheds, "--out", d / "page.html"])


WARM = {"single-pass": warm_single_pass, "fleet": warm_fleet, "onera": warm_onera, "eosbench": warm_eosbench,
        "regional-coverage": warm_regional}


def run(cfg: WarmupConfig) -> dict[str, float]:
    """Seconds per kind of the warm-up."""
    from eosp.errors import InputError

    unknown = [k for k in cfg.kinds if k not in WARM]
    if unknown:
        raise InputError("--kinds", f"unknown kind {unknown[0]!r}; one of {', '.join(WARM)}")
    times = {}
    for name in cfg.kinds:
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            WARM[name](Path(tmp))
        times[name] = time.perf_counter() - t0
    return times


def main(argv: list[str] | None = None) -> int:
    return run_job(_main, argv, "warmup")


def _main(argv: list[str] | None) -> int:
    p = Parser(prog="python -m eosp.cli.warmup", description=__doc__.splitlines()[0])
    add_config_args(p, WarmupConfig)
    cfg = config_from_args(WarmupConfig, p.parse_args(argv))
    t0 = time.perf_counter()
    times = run(cfg)
    steps = ", ".join(f"{k} {v:.1f} s" for k, v in times.items())
    print(f"[warmup] kernels of every kind compiled and cached in {time.perf_counter() - t0:.0f} s ({steps})",
          flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
