"""The fleet solver at scale: a generated 200-satellite, 24 h, 20,000-task fleet solved with 1 and 2 workers.

    python benchmarks/bench_fleet_scale.py --out runs/scale --time-limit 600 --workers 1 2

Generates the fleet (``eosp generate --fleet`` settings below, seed 0) unless ``--fleet-dir`` is given, then for
each worker count runs ``jobs/solve_fleet.py`` in a child process (Ray actors when workers > 1) and reads its
result.json: time to the first schedule, value and gap at 60 s and at the time limit (from the run's history,
seconds counted from the job's start, the pass-graph build included), price-round times and their speed-up,
the memory of the job's processes (driver, Ray's actors and the rest of Ray: PSS summed, sampled every 2 s,
its peak in each step; the series in ``RUN-memory.csv``), and per-pass solve times by pass size (from the actors'
pass_times.csv).  Prints Markdown tables and writes ``scale.json``.
"""

from __future__ import annotations

import argparse
import csv
import json
import resource
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SIZES = [(1, 10), (11, 30), (31, 100), (101, 300), (301, 10 ** 9)]


def generate(out: Path, satellites: int, tasks: int, hours: float) -> tuple[Path, float, float]:
    """The fleet dir, its generation seconds and the generating process's peak memory (GB)."""
    fleet = out / f"fleet-{satellites}x{tasks}-{hours:g}h"
    if (fleet / "meta.json").exists():
        return fleet, 0.0, 0.0
    code = ("import resource, sys, time\nfrom eosp.cli import main\nt = time.perf_counter()\n"
            f"rc = main(['generate', '--fleet', '--satellites', '{satellites}', '--tasks', '{tasks}', '--hours', "
            f"'{hours}', '--out', {str(fleet)!r}])\n"
            "print('RESULT', time.perf_counter() - t, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6)\n"
            "sys.exit(rc)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    line = next(x for x in r.stdout.splitlines() if x.startswith("RESULT"))
    _, secs, gb = line.split()
    print(r.stdout.strip().splitlines()[0])
    return fleet, float(secs), float(gb)


def at(history: list, t: float) -> tuple[float, float] | None:
    """(value, bound) of the last history entry at or before `t` seconds."""
    last = None
    for ts, v, b in history:
        if ts <= t:
            last = (v, b)
    return last


def size_table(path: Path) -> list[dict]:
    if not path.exists():
        return []
    rows = list(csv.DictReader(path.open()))
    out = []
    for lo, hi in SIZES:
        secs = sorted(float(r["seconds"]) for r in rows if lo <= int(r["opportunities"]) <= hi)
        if secs:
            out.append({"opportunities": f"{lo}-{hi}" if hi < 10 ** 9 else f">{lo - 1}", "solves": len(secs),
                        "median_ms": round(1000 * secs[len(secs) // 2], 3),
                        "p95_ms": round(1000 * secs[int(0.95 * (len(secs) - 1))], 3),
                        "total_s": round(sum(secs), 2)})
    return out


class TreeMemory:
    """The job's memory while it runs: every `every` seconds the proportional set size of its process tree (the
    driver; under it, with workers > 1, Ray's raylet, GCS, object store and actors), summed (each shared page once)
    and split into driver, actors (``ray::`` processes) and the rest of Ray; kept as a time series (seconds from
    the job's start) for the step-by-step peaks."""

    def __init__(self, pid: int, every: float = 2.0):
        from eosp.memory import tree_pss

        self.samples: list[tuple[float, float, float, float]] = []  # (s, driver GB, actors GB, other GB)
        self._stop = threading.Event()
        t0 = time.perf_counter()

        def loop() -> None:
            while not self._stop.is_set():
                by = tree_pss(pid)
                driver = by.pop(_comm(pid), 0) if by else 0
                actors = sum(v for k, v in by.items() if k.startswith("ray::"))
                other = sum(v for k, v in by.items() if not k.startswith("ray::"))
                self.samples.append((time.perf_counter() - t0, driver / 1e9, actors / 1e9, other / 1e9))
                self._stop.wait(every)

        self._thread = threading.Thread(target=loop, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def peak(self, t_from: float = 0.0, t_to: float = 1e18) -> dict | None:
        """The sample of the largest total between two instants (seconds from the start), GB."""
        inside = [s for s in self.samples if t_from <= s[0] <= t_to]
        if not inside:
            return None
        s = max(inside, key=lambda x: x[1] + x[2] + x[3])
        return {"at_s": round(s[0], 1), "total": round(s[1] + s[2] + s[3], 2), "driver": round(s[1], 2),
                "actors": round(s[2], 2), "ray_other": round(s[3], 2)}


def _comm(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("runs/scale"))
    ap.add_argument("--fleet-dir", type=Path, default=None)
    ap.add_argument("--satellites", type=int, default=200)
    ap.add_argument("--tasks", type=int, default=20000)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--time-limit", type=float, default=600.0)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--warm-start", default="heuristic", choices=["none", "heuristic", "learned"],
                    help="where the prices start (the fleet solver's --warm-start)")
    ap.add_argument("--lean-driver", default="auto", choices=["auto", "yes", "no"],
                    help="the job's --lean-driver (with workers > 1: the driver without the pass graphs' arcs)")
    ap.add_argument("--rounds", type=int, default=0, help="a fixed number of price rounds instead of the time limit "
                                                          "(deterministic: the runs must give the same schedule)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    gen_s = gen_gb = 0.0
    fleet = args.fleet_dir
    if fleet is None:
        fleet, gen_s, gen_gb = generate(args.out, args.satellites, args.tasks, args.hours)
    meta = json.loads((fleet / "meta.json").read_text())
    results = {"fleet": str(fleet), "satellites": meta["satellites"], "tasks": meta["tasks"],
               "opportunities": meta["opportunities"], "passes": meta["passes"], "generate_s": round(gen_s, 1),
               "generate_peak_gb": round(gen_gb, 2), "runs": []}
    for w in args.workers:
        tag = f"{args.rounds}r" if args.rounds else f"{args.time_limit:g}s"
        run_dir = args.out / f"run-w{w}-{tag}-{time.strftime('%H%M%S')}"
        cmd = [sys.executable, str(ROOT / "jobs/solve_fleet.py"), "--fleet-dir", str(fleet), "--run-dir", str(run_dir),
               "--fleet.workers", str(w), "--fleet.time-limit", "0" if args.rounds else str(args.time_limit),
               "--ray.num-cpus", str(max(w, 2)),
               *(["--fleet.rounds", str(args.rounds)] if args.rounds else []),
               "--fleet.warm-start", args.warm_start, "--lean-driver", args.lean_driver,
               "--mlflow-uri", f"sqlite:///{(args.out / 'mlflow.db').resolve()}"]
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        t0 = time.perf_counter()
        with open(args.out / f"{run_dir.name}.log", "w") as log:
            child = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, text=True)
            mem = TreeMemory(child.pid)
            rc = child.wait()
            mem.stop()
        wall = time.perf_counter() - t0
        with open(args.out / f"{run_dir.name}-memory.csv", "w") as fh:
            fh.write("seconds,driver_gb,actors_gb,ray_other_gb\n")
            fh.writelines(f"{s:.1f},{d:.3f},{a:.3f},{o:.3f}\n" for s, d, a, o in mem.samples)
        if rc != 0:
            print((args.out / f"{run_dir.name}.log").read_text()[-2000:])
            raise SystemExit(f"workers {w}: exit {rc}")
        res = json.loads((run_dir / "result.json").read_text())
        hist = res["history"]
        v60, v_end = at(hist, 60.0), at(hist, 1e18)
        rounds = res["price_round_s"]
        phases = res.get("round_phases_s") or []
        v600 = at(hist, 600.0)
        row = {"workers": w, "lean_driver": res.get("lean_driver"), "first_schedule_s": res["first_schedule_s"],
               "build_s": res["build_s"], "actor_graph_mb": res.get("actor_graph_mb"), "graph_mb": res.get("graph_mb"),
               "pool_s": res["pool_s"], "value_60s": v60 and v60[0], "gap_60s": v60 and (v60[1] - v60[0]) / v60[1],
               "value_600s": v600 and v600[0], "gap_600s": v600 and (v600[1] - v600[0]) / v600[1],
               "value": res["value"], "bound": res["bound"], "gap": res["gap"], "rounds": res["rounds"],
               # where a price round's time went: the median of each phase over the price rounds (seconds)
               "round_phases_median_s": {k: round(statistics.median(ph[k] for ph in phases), 2)
                                         for k in phases[0]} if phases else None,
               "price_round_median_s": sorted(rounds)[len(rounds) // 2] if rounds else None,
               # rounds a minute after the first schedule (a round sent ahead is only waited for: its own median
               # is what was left to wait, not what it cost)
               "rounds_per_min": round(res["rounds"] / max(1e-9, res["wall_s"] - (res["first_schedule_s"] or 0))
                                       * 60, 3),
               "wall_s": round(wall, 1), "driver_peak_gb": round(max(before, resource.getrusage(
                   resource.RUSAGE_CHILDREN).ru_maxrss) / 1e6, 2), "faults": res["faults"],
               "pass_sizes": size_table(run_dir / "pass_times.csv"), "end": v_end,
               # the tree's memory (driver + Ray's processes, PSS) at its peak in each step, seconds from the start
               "memory_gb": {"graphs": mem.peak(0, res["build_s"]),
                             "actors started": mem.peak(res["build_s"], res["build_s"] + res["pool_s"]),
                             "first schedule": mem.peak(res["build_s"] + res["pool_s"], res["first_schedule_s"] or 0),
                             "rounds": mem.peak(res["first_schedule_s"] or 0), "whole run": mem.peak()}}
        results["runs"].append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "pass_sizes"}), flush=True)
    base = next((r for r in results["runs"] if r["workers"] == 1), None)
    for r in results["runs"]:
        if base and r["rounds_per_min"] and base["rounds_per_min"]:
            r["rounds_speedup"] = round(r["rounds_per_min"] / base["rounds_per_min"], 2)
    (args.out / "scale.json").write_text(json.dumps(results, indent=1))
    f = lambda x, d=4: "-" if x is None else f"{x:.{d}f}"  # noqa: E731  (a cell of the tables below)
    print(f"\n{results['satellites']} satellites, {results['tasks']} tasks, {results['opportunities']} opportunities, "
          f"{results['passes']} passes; generated in {results['generate_s']} s (peak {results['generate_peak_gb']} GB)\n")
    print("| workers | first schedule (s) | WCR at 60 s | gap at 60 s | WCR at end | bound | gap at end | rounds | "
          "price round (s) | rounds a minute | speed-up | driver peak (GB) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in results["runs"]:
        print(f"| {r['workers']} | {r['first_schedule_s']} | {f(r['value_60s'])} | {f(r['gap_60s'])} | "
              f"{f(r['value'])} | {f(r['bound'])} | {f(r['gap'])} | {r['rounds']} | {f(r['price_round_median_s'], 2)} | "
              f"{r['rounds_per_min']} | {r.get('rounds_speedup', '-')} | {r['driver_peak_gb']} |")
    print("\nMemory of the job's processes at the peak of each step (GB, PSS summed: total = driver + actors + "
          "rest of Ray):\n")
    print("| workers | step | total | driver | actors | rest of Ray |\n|---|---|---|---|---|---|")
    for r in results["runs"]:
        for step, m in r["memory_gb"].items():
            if m is not None:
                print(f"| {r['workers']} | {step} | {m['total']} | {m['driver']} | {m['actors']} | {m['ray_other']} |")
    print("\nWhere a price round's time went (median seconds over the price rounds: waiting for its passes, the "
          "master LP and price step, the recovery, its battery repair, the moves; pool: of these, waiting for "
          "sweeps and waves on the workers):\n")
    print("| workers | WCR at 600 s | gap at 600 s | round | prices | recover | repair | moves | pool | pool calls |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in results["runs"]:
        m = r["round_phases_median_s"] or {}
        cells = [str(m.get(k, "-")) for k in ("round", "prices", "recover", "repair", "moves", "pool", "pool_calls")]
        print(f"| {r['workers']} | {f(r['value_600s'])} | {f(r['gap_600s'])} | " + " | ".join(cells) + " |")
    for r in results["runs"]:
        if r["pass_sizes"]:
            print(f"\nPass solve times on the actors ({r['workers']} workers):\n")
            print("| opportunities | solves | median (ms) | p95 (ms) | total (s) |\n|---|---|---|---|---|")
            for s in r["pass_sizes"]:
                print(f"| {s['opportunities']} | {s['solves']} | {s['median_ms']} | {s['p95_ms']} | {s['total_s']} |")


if __name__ == "__main__":
    main()
