"""Agreement of eosp's fleet checker with the astro-reason aeossp_standard verifier.

Usage::

    python experiments/verifier_agreement.py SOURCE [--splits test,test_easy] [--broken 20] [--log FILE]

SOURCE is a checkout of astro-reason, or a bare mirror of it (its HEAD is unpacked with
``git archive`` into a temporary directory).  The benchmark's verifier is imported from there
(as a package loaded from its files), and run on:

* its 8 fixtures (solution.json given);
* the greedy schedule of every case of the chosen splits;
* for the evaluation splits, ``--broken`` deliberately broken schedules per case, derived from
  the greedy one: overlaps, short slews, off-grid and wrong-duration actions, wrong sensors,
  actions outside their window, off-nadir starts, unknown ids, and battery drains (the case
  copied with one satellite's initial charge and sunlit charging lowered);
* two random sub-schedules of the greedy one per evaluation case (50 % and 90 % of its actions),
  usually valid, so that the metrics are compared on more than the greedy schedules.

For each schedule it compares the verdict, the metrics (WCR, CR, TAT, PC, to 1e-9) and the
first violation (stage, action, time), prints one line per schedule and a summary table, and
appends one JSON line per schedule to ``--log``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from eosp.fleet.aeossp import read_case, read_solution, write_solution
from eosp.fleet.check import validate
from eosp.fleet.geometry import Geometry
from eosp.fleet.greedy import solve
from eosp.fleet.model import US, Schedule
from eosp.fleet.opportunities import compute

BENCH = "benchmarks/aeossp_standard"
FIXTURES = "tests/fixtures/aeossp_standard"
EVAL_SPLITS = ("test", "test_easy", "test_hard", "test_horizon_2022")
TOL = 1e-9


def checkout(source: Path, tmp: Path) -> Path:
    """A directory holding the benchmark's files: `source` itself, or HEAD of a bare mirror."""
    if (source / BENCH).is_dir():
        return source
    root = tmp / "astro-reason"
    root.mkdir()
    archive = subprocess.run(["git", "-C", str(source), "archive", "HEAD", BENCH, FIXTURES],
                             check=True, capture_output=True).stdout
    subprocess.run(["tar", "x", "-C", str(root)], input=archive, check=True)
    return root


def load_verifier(root: Path):
    """The verifier package, loaded from its files under a private name."""
    d = root / BENCH / "verifier"
    spec = importlib.util.spec_from_file_location("ar_aeossp_verifier", d / "__init__.py",
                                                  submodule_search_locations=[str(d)])
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def compare(ours, theirs) -> dict:
    row = {"valid_ours": ours.valid, "valid_theirs": bool(theirs.valid)}
    same = ours.valid == theirs.valid
    for k in ("WCR", "CR", "TAT", "PC"):
        a, b = ours.metrics[k], theirs.metrics[k]
        ok = (a is None and b is None) or (a is not None and b is not None and abs(a - b) <= TOL)
        row[k] = [a, b]
        same &= ok
    fails = theirs.diagnostics.get("action_failures", [])
    f_ours = ours.first
    if fails and f_ours is not None:
        t = fails[0]
        ours_t = f_ours.time.isoformat().replace("+00:00", "Z") if f_ours.time else None
        row["first_same"] = (t["stage"] == f_ours.stage and t["action_index"] == f_ours.action
                             and t["time"] == ours_t and t["satellite_id"] == f_ours.satellite)
        row["first"] = [str(f_ours), t]
    else:
        row["first_same"] = not fails and f_ours is None
    row["agree"] = bool(same)
    return row


def subset(s: Schedule, keep) -> Schedule:
    keep = np.asarray(keep, dtype=np.int64)
    return Schedule(s.satellite[keep], s.task[keep], s.start_us[keep], s.end_us[keep])


def with_rows(s: Schedule, rows: list[tuple]) -> Schedule:
    sat = np.concatenate([s.satellite, np.asarray([r[0] for r in rows], dtype=object)])
    task = np.concatenate([s.task, np.asarray([r[1] for r in rows], dtype=object)])
    st = np.concatenate([s.start_us, np.asarray([r[2] for r in rows], dtype=np.int64)])
    en = np.concatenate([s.end_us, np.asarray([r[3] for r in rows], dtype=np.int64)])
    return Schedule(sat, task, st, en)


def edited(s: Schedule, i: int, sat=None, start=None, end=None) -> Schedule:
    sats, st, en = s.satellite.copy(), s.start_us.copy(), s.end_us.copy()
    if sat is not None:
        sats[i] = sat
    if start is not None:
        st[i] = start
    if end is not None:
        en[i] = end
    return Schedule(sats, s.task.copy(), st, en)


def broken_schedules(fleet, opps, sched: Schedule, rng) -> list[tuple[str, Schedule]]:
    """Deliberately broken variants of a (valid) schedule: (kind, schedule)."""
    step = fleet.horizon.action_step_s * US
    ti = fleet.task_index()
    n = len(sched)
    out = []
    pick = lambda: int(rng.integers(n))  # noqa: E731
    for _ in range(2):  # an exact duplicate, and a copy one step later
        i = pick()
        out.append(("overlap", with_rows(sched, [(sched.satellite[i], sched.task[i], sched.start_us[i], sched.end_us[i])])))
    order = np.lexsort((sched.start_us, sched.satellite))
    pairs = [(int(order[k]), int(order[k + 1])) for k in range(n - 1)
             if sched.satellite[order[k]] == sched.satellite[order[k + 1]]]
    for _ in range(3):  # the later action moved to start right after (or one step after) the earlier one
        a, b = pairs[int(rng.integers(len(pairs)))]
        shift = int(rng.integers(2)) * step
        dur = sched.end_us[b] - sched.start_us[b]
        out.append(("short_slew", edited(sched, b, start=sched.end_us[a] + shift, end=sched.end_us[a] + shift + dur)))
    for k in range(2):
        i = pick()
        off = US if k == 0 else US // 2
        out.append(("off_grid", edited(sched, i, start=sched.start_us[i] + off, end=sched.end_us[i] + off)))
    for k in range(2):
        i = pick()
        out.append(("wrong_duration", edited(sched, i, end=sched.end_us[i] + (step if k == 0 else -step))))
    sens = fleet.satellites.sensor
    for _ in range(2):
        i = pick()
        k = fleet.satellite_index()[sched.satellite[i]]
        other = np.flatnonzero(sens != sens[k])
        if len(other):
            out.append(("wrong_sensor", edited(sched, i, sat=fleet.satellites.ids[int(rng.choice(other))])))
    for k in range(2):
        i = pick()
        t = ti[sched.task[i]]
        dur = sched.end_us[i] - sched.start_us[i]
        if k == 0 and fleet.tasks.release_s[t] * US - step >= 0:
            s0 = int(fleet.tasks.release_s[t] * US) - step
        else:
            s0 = int(fleet.tasks.due_s[t] * US) - dur + step
        out.append(("off_window", edited(sched, i, start=s0, end=s0 + dur)))
    for _ in range(3):  # an in-window start that is not an opportunity: fails geometry
        for _try in range(50):
            i = pick()
            t, k = ti[sched.task[i]], fleet.satellite_index()[sched.satellite[i]]
            good = set(opps.start[(opps.task == t) & (opps.satellite == k)].tolist())
            a_step = fleet.horizon.action_step_s
            lo = int(fleet.tasks.release_s[t]) // a_step
            hi = int(fleet.tasks.due_s[t] - fleet.tasks.duration_s[t]) // a_step
            cand = [g for g in range(lo, hi + 1) if g not in good]
            if cand:
                g = int(rng.choice(cand))
                dur = sched.end_us[i] - sched.start_us[i]
                out.append(("off_nadir", edited(sched, i, start=g * step, end=g * step + dur)))
                break
    i = pick()
    out.append(("unknown_id", Schedule(sched.satellite, np.where(np.arange(n) == i, "no_such_task", sched.task),
                                       sched.start_us, sched.end_us)))
    i = pick()
    out.append(("unknown_id", edited(sched, i, sat="no_such_satellite")))
    for frac in (0.5, 0.9):  # not broken: random sub-schedules (usually valid) compare the metrics
        out.append(("subset", subset(sched, np.sort(rng.choice(n, int(frac * n), replace=False)))))
    return out


def drained_case(case_dir: Path, tmp: Path, sat_id: str, initial: float, charge: float) -> Path:
    """A copy of a case with one satellite's initial charge and sunlit charging lowered."""
    import yaml

    dst = tmp / f"drain_{case_dir.parent.name}_{case_dir.name}_{initial:g}"
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(case_dir, dst)
    doc = yaml.safe_load((dst / "satellites.yaml").read_text())
    for s in doc["satellites"]:
        if s["satellite_id"] == sat_id:
            s["resource_model"]["initial_battery_wh"] = initial
            s["resource_model"]["sunlit_charge_power_w"] = charge
    (dst / "satellites.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return dst


class Runner:
    def __init__(self, verifier, tmp: Path, log: Path | None):
        self.v, self.tmp, self.log = verifier, tmp, log
        self.rows: list[dict] = []

    def check(self, label: str, kind: str, case_dir: Path, fleet, geo, sched: Schedule, vcase=None) -> None:
        path = self.tmp / "solution.json"
        write_solution(sched, fleet.horizon, path, overwrite=True)
        t0 = time.perf_counter()
        ours = validate(fleet, read_solution(path, fleet.horizon), geo)
        t_ours = time.perf_counter() - t0
        t0 = time.perf_counter()
        vcase = vcase or self.v.io.load_case(case_dir)
        theirs = self.v.verify(vcase, self.v.io.load_solution(path))
        t_theirs = time.perf_counter() - t0
        row = {"case": label, "kind": kind, "actions": len(sched), **compare(ours, theirs),
               "t_ours_s": round(t_ours, 2), "t_verifier_s": round(t_theirs, 2)}
        self.rows.append(row)
        print(f"{label:32s} {kind:15s} n={len(sched):5d} valid={ours.valid!s:5s}/{bool(theirs.valid)!s:5s} "
              f"WCR={ours.metrics['WCR']:.6f} agree={row['agree']} first={row['first_same']} "
              f"({t_ours:.1f} s / {t_theirs:.1f} s)", flush=True)
        if self.log:
            with self.log.open("a") as fh:
                fh.write(json.dumps(row, default=str) + "\n")


def run_fixtures(r: Runner, root: Path) -> None:
    for d in sorted((root / FIXTURES).iterdir()):
        if not d.is_dir():
            continue
        fleet = read_case(d)
        r.check(f"fixture/{d.name}", "fixture", d, fleet, Geometry(fleet), read_solution(d / "solution.json", fleet.horizon))


def run_case(r: Runner, case_dir: Path, n_broken: int, seed: int) -> None:
    label = f"{case_dir.parent.name}/{case_dir.name}"
    fleet = read_case(case_dir)
    geo = Geometry(fleet)
    opps = compute(fleet, geo)
    t0 = time.perf_counter()
    sched = solve(fleet, opps, geo)
    print(f"{label}: greedy {len(sched)} actions in {time.perf_counter() - t0:.1f} s", flush=True)
    vcase = r.v.io.load_case(case_dir)
    r.check(label, "greedy", case_dir, fleet, geo, sched, vcase)
    if n_broken <= 0 or case_dir.parent.name not in EVAL_SPLITS or len(sched) < 2:
        return
    rng = np.random.default_rng(seed)
    variants = broken_schedules(fleet, opps, sched, rng)
    sats, cnt = np.unique(sched.satellite, return_counts=True)
    busiest = str(sats[int(np.argmax(cnt))])
    for kind, s in variants[: max(0, n_broken - 2)]:
        r.check(label, kind, case_dir, fleet, geo, s, vcase)
    for initial, charge in [(30.0, 0.0), (200.0, 5.0)][: min(2, n_broken)]:
        d = drained_case(case_dir, r.tmp, busiest, initial, charge)
        f2 = read_case(d)
        r.check(label, "battery_drain", d, f2, Geometry(f2), sched)


def summary(rows: list[dict]) -> None:
    print("\n| group | schedules | verdict agrees | metrics agree (1e-9) | first violation agrees |")
    print("|---|---|---|---|---|")
    groups: dict[str, list[dict]] = {}
    for row in rows:
        groups.setdefault(row["kind"], []).append(row)
    for name, rs in sorted(groups.items()) + [("all", rows)]:
        v = sum(r["valid_ours"] == r["valid_theirs"] for r in rs)
        a = sum(r["agree"] for r in rs)
        f = sum(r["first_same"] for r in rs)
        print(f"| {name} | {len(rs)} | {v} | {a} | {f} |")
    if rows:
        print(f"\nagreement rate: {sum(r['agree'] for r in rows)}/{len(rows)} = "
              f"{sum(r['agree'] for r in rows) / len(rows):.4f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("source", type=Path, help="astro-reason checkout or bare mirror")
    ap.add_argument("--splits", default="test,test_easy,test_horizon_2022,test_hard,train")
    ap.add_argument("--broken", type=int, default=22, help="variants per evaluation case (20 broken, 2 sub-schedules)")
    ap.add_argument("--no-fixtures", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--log", type=Path, default=None, help="append one JSON line per schedule")
    ns = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="eosp_agree_") as t:
        tmp = Path(t)
        root = checkout(ns.source, tmp)
        r = Runner(load_verifier(root), tmp, ns.log)
        if not ns.no_fixtures:
            run_fixtures(r, root)
        for split in [s for s in ns.splits.split(",") if s]:
            for case_dir in sorted((root / BENCH / "dataset" / "cases" / split).glob("case_*")):
                run_case(r, case_dir, ns.broken, ns.seed)
        summary(r.rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
