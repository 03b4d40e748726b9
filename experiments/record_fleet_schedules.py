"""Record the fleet solvers' schedules under deterministic budgets, to show that a change of the solver's code
leaves them byte-identical (or to show where it does not).

    python experiments/record_fleet_schedules.py --astro ASTRO --work /tmp/rec --out before.jsonl
    ... change the code ...
    python experiments/record_fleet_schedules.py --astro ASTRO --work /tmp/rec --out after.jsonl
    python experiments/record_fleet_schedules.py --compare before.jsonl after.jsonl

ASTRO is a checkout of astro-reason (its benchmarks/aeossp_standard/dataset/cases).  Every solve runs with a budget
that does not depend on the clock (``--rounds``, ``--moves``, seeds, ``--time-limit 0``), through the command line
(``eosp.cli.main`` in this process, or the Ray job in a process of its own), and is recorded as one JSON line: the
run's name, a SHA-256 of the schedule's rows (satellite, task, start and end in microseconds, in the file's
order), its value, bound and rounds.  The set covers the solver's risky paths: the 30 aeossp cases with
``--rounds 6``; three generated fleets; uniform and lp price steps; ``--energy-bound``; ``--warm-start`` none,
heuristic and learned; ``--init`` with ``--freeze-until``; the Ray job with one and two workers, its driver lean or
not; four ONERA instances (generated here, seeded) with ``--moves``.  Inputs are made once under ``--work`` and
reused.  ``--ray-fleet DIR`` records the Ray job's three runs alone, on another fleet (a 200-satellite day).
``--compare`` prints the runs whose hashes differ and exits 1 when any does.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

SPLITS = {"test": 5, "test_easy": 5, "test_hard": 5, "test_horizon_2022": 5, "train": 10}
VARIANT_CASES = ("test-case_0001", "test_hard-case_0005", "test_horizon_2022-case_0001")
VARIANTS = {"uniform": ["--price-step", "uniform"], "energy-bound": ["--energy-bound", "true"],
            "warm-none": ["--warm-start", "none"], "warm-learned": ["--warm-start", "learned"]}
GENERATED = {"gen-land-12": ["--satellites", "12", "--tasks", "1500", "--hours", "12", "--placement", "land",
                             "--seed", "1"],
             "gen-cities-24": ["--satellites", "24", "--tasks", "3000", "--hours", "12", "--placement", "cities",
                               "--seed", "2"],
             "gen-clusters-6": ["--satellites", "6", "--tasks", "800", "--hours", "24", "--placement", "clusters",
                                "--seed", "3"]}
ROUNDS = ["--time-limit", "0", "--rounds", "6"]


def cli(argv: list) -> str:
    """`eosp ARGV` in this process; its stdout (a failure is an error naming the command)."""
    from eosp.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main([str(a) for a in argv])
    if rc != 0:
        raise RuntimeError(f"`eosp {' '.join(map(str, argv))}` exited {rc}: {err.getvalue().strip()[-400:]}")
    return out.getvalue()


def digest(fleet_dir: Path, schedule: Path) -> dict:
    """The schedule's rows hashed, with what its file says of value, bound and rounds."""
    from eosp.kinds import detect

    kind = detect(str(fleet_dir))
    problem = kind.read(str(fleet_dir), solving=False)
    if kind.name == "fleet":
        from eosp.fleet.io import read_schedule

        s, md = read_schedule(schedule, problem.fleet)
        cols = [np.asarray(s.satellite).astype(str), np.asarray(s.task).astype(str), s.start_us, s.end_us]
    else:
        from eosp.onera.model import read_schedule

        s, md = read_schedule(schedule, problem)
        cols = [np.asarray(s.satellite), np.asarray(s.activity), np.asarray(s.start, np.float64)]
    h = hashlib.sha256()
    for c in cols:
        if c.dtype.kind in "OU":  # ids: their text
            h.update("\x1f".join(map(str, c.tolist())).encode() + b"\x1e")
        else:
            h.update(str(c.dtype).encode() + np.ascontiguousarray(c).tobytes() + b"\x1e")
    info = {k: json.loads(md[k]) for k in ("value", "bound", "rounds") if k in md}
    return {"rows": int(len(cols[0])), "sha256": h.hexdigest(), **info}


def prepare(astro: Path, work: Path) -> dict[str, Path]:
    """The fleet directories and ONERA instances of the record, made under `work` once (so that another version of
    the code, on the import path, reads the same inputs)."""
    dirs = {}
    cases = astro / "benchmarks" / "aeossp_standard" / "dataset" / "cases"
    for split, n in SPLITS.items():
        for i in range(1, n + 1):
            name = f"{split}-case_{i:04d}"
            d = work / "fleets" / name
            if not d.exists():
                cli(["import", cases / split / f"case_{i:04d}", "--out", d])
            dirs[name] = d
    for name, args in GENERATED.items():
        d = work / "fleets" / name
        if not d.exists():
            cli(["generate", "--fleet", *args, "--out", d])
        dirs[name] = d
    for seed, n in enumerate((200, 400, 800, 1500)):
        name = f"onera-{n}"
        d = work / "fleets" / name
        if not d.exists():
            from eosp.cli.warmup import onera_instance

            pb = work / f"{name}.pb"
            pb.write_text(onera_instance(n, seed))
            cli(["import", pb, "--out", d])
        dirs[name] = d
    return dirs


def runs(dirs: dict[str, Path]) -> list[tuple[str, str, list]]:
    """(run name, fleet name, eosp solve options) of every in-process solve, in order."""
    out = []
    for name in dirs:
        if name.startswith("onera-"):
            out.append((f"{name}/onera-moves-40", name, ["--solver", "onera", "--time-limit", "0", "--moves", "40"]))
        else:
            out.append((f"{name}/fleet-rounds-6", name, ["--solver", "fleet", *ROUNDS]))
    for case in VARIANT_CASES:
        for v, args in VARIANTS.items():
            out.append((f"{case}/{v}", case, ["--solver", "fleet", *ROUNDS, *args]))
    return out


def record_ray(work: Path, fleet_dir: Path, name: str) -> list[dict]:
    """The Ray job (jobs/solve_fleet.py) on one fleet, 6 rounds: one worker; two with the driver lean and not."""
    rows = []
    for label, extra in (("ray-1", ["--fleet.workers", "1"]),
                         ("ray-2", ["--fleet.workers", "2", "--lean-driver", "no"]),
                         ("ray-2-lean", ["--fleet.workers", "2", "--lean-driver", "yes"])):
        run = work / "ray" / f"{name}-{label}"
        if run.exists():
            import shutil

            shutil.rmtree(run)
        argv = [sys.executable, "-m", "eosp.jobs.solve_fleet", "--fleet-dir", str(fleet_dir), "--run-dir",
                str(run), "--fleet.time-limit", "0", "--fleet.rounds", "6", "--mlflow-uri",
                f"sqlite:///{work / 'mlflow.db'}", "--ray.num-cpus", "2", *extra]
        t0 = time.perf_counter()
        r = subprocess.run(argv, capture_output=True, text=True, timeout=3600)
        if r.returncode != 0:
            raise RuntimeError(f"{label}: exit {r.returncode}: {r.stderr[-600:]}")
        rows.append({"run": f"{name}/{label}", **digest(fleet_dir, run / "schedule.parquet"),
                     "seconds": round(time.perf_counter() - t0, 1)})
    return rows


def record(args) -> int:
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    dirs = prepare(Path(args.astro), work)
    out = Path(args.out)
    lines = []
    sched_dir = work / "schedules"
    sched_dir.mkdir(exist_ok=True)
    plan = runs(dirs)
    for run, fleet_name, opts in plan:
        s = sched_dir / (run.replace("/", "__") + ".parquet")
        s.unlink(missing_ok=True)
        t0 = time.perf_counter()
        cli(["solve", dirs[fleet_name], *opts, "--out", s])
        lines.append({"run": run, **digest(dirs[fleet_name], s), "seconds": round(time.perf_counter() - t0, 1)})
        print(json.dumps(lines[-1]), flush=True)
    # --init with --freeze-until: each variant case from its 6-round schedule, its first half kept
    for case in VARIANT_CASES:
        init = sched_dir / f"{case}__fleet-rounds-6.parquet"
        meta = json.loads((dirs[case] / "meta.json").read_text())
        start, end = (np.datetime64(meta[k].replace("Z", "")) for k in ("horizon_start", "horizon_end"))
        mid = str(start + (end - start) // 2) + "Z"
        s = sched_dir / f"{case}__init-freeze.parquet"
        s.unlink(missing_ok=True)
        t0 = time.perf_counter()
        cli(["solve", dirs[case], "--solver", "fleet", *ROUNDS, "--init", init, "--freeze-until", mid, "--out", s])
        lines.append({"run": f"{case}/init-freeze", **digest(dirs[case], s),
                      "seconds": round(time.perf_counter() - t0, 1)})
        print(json.dumps(lines[-1]), flush=True)
    if not args.no_ray:
        for row in record_ray(work, dirs["gen-cities-24"], "gen-cities-24"):
            lines.append(row)
            print(json.dumps(row), flush=True)
    out.write_text("".join(json.dumps(x) + "\n" for x in lines))
    print(f"{len(lines)} runs recorded in {out}")
    return 0


def compare(a: Path, b: Path) -> int:
    ra = {x["run"]: x for x in map(json.loads, a.read_text().splitlines())}
    rb = {x["run"]: x for x in map(json.loads, b.read_text().splitlines())}
    differ = [r for r in ra if r in rb and ra[r]["sha256"] != rb[r]["sha256"]]
    only = sorted(set(ra) ^ set(rb))
    for r in differ:
        print(f"differs: {r}: value {ra[r].get('value')} -> {rb[r].get('value')}, "
              f"bound {ra[r].get('bound')} -> {rb[r].get('bound')}")
    for r in only:
        print(f"in one record only: {r}")
    same = sum(1 for r in ra if r in rb and ra[r]["sha256"] == rb[r]["sha256"])
    print(f"{same} of {len(set(ra) | set(rb))} runs byte-identical, {len(differ)} differ, {len(only)} in one only")
    return 1 if differ or only else 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--astro", help="astro-reason checkout")
    p.add_argument("--work", default="/tmp/fleet-record", help="where the inputs and schedules are kept")
    p.add_argument("--out", help="the record (JSON lines)")
    p.add_argument("--no-ray", action="store_true", help="skip the Ray job's runs")
    p.add_argument("--ray-fleet", help="record only the Ray job's three runs, on this fleet directory (e.g. a "
                                       "generated 200-satellite day)")
    p.add_argument("--compare", nargs=2, metavar=("A", "B"), help="compare two records")
    args = p.parse_args()
    if args.compare:
        return compare(Path(args.compare[0]), Path(args.compare[1]))
    if args.ray_fleet and args.out:
        fleet_dir = Path(args.ray_fleet)
        rows = record_ray(Path(args.work), fleet_dir, fleet_dir.name)
        Path(args.out).write_text("".join(json.dumps(r) + "\n" for r in rows))
        for r in rows:
            print(json.dumps(r))
        return 0
    if not args.astro or not args.out:
        p.error("--astro and --out are needed to record")
    return record(args)


if __name__ == "__main__":
    sys.exit(main())
