"""EOS-Bench: their algorithms' schedules beside eosp's solver on one scenario, every schedule judged by eosp's
checker under both transition readings and, where their environment is given, by their own checker.

Usage::

    python experiments/eosbench_compare.py SCENARIO.json --schedules DIR [--time-limit 30]
        [--their-python PY --their-repo REPO] [--log FILE]

DIR holds the schedule files their ``main_scheduler.py`` wrote for SCENARIO (``scheduler_<scenario>_c<class>_<algo>
_<objective>.json``, their metrics and runtime inside).  With ``--their-python`` and ``--their-repo`` the same files
(and eosp's) are replayed through their ``ConstraintModel`` and metrics by ``experiments/eosbench_theirs.py check``,
and the verdicts and metrics compared (to 1e-9).  eosp's solver runs once per transition reading at the time limit
(none with ``--time-limit 0``).

Prints one Markdown row per schedule: source, TP, TCR, TM, BD, runtime, valid (documented / code reading, eosp's
checker), their checker's verdict and whether its metrics agree, the bound and gap (eosp's rows); appends one JSON
line per row to ``--log``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from eosp.eosbench.check import check
from eosp.eosbench.read import read_scenario
from eosp.eosbench.schedules import read_schedule, write_schedule
from eosp.eosbench.transition import Rules
from eosp.kinds.eosbench.solve import EosBenchConfig, solve

TOL = 1e-9
KEYS = ("TP", "TCR", "TM", "BD")


def theirs(ns: argparse.Namespace, paths: list[str]) -> dict[str, dict]:
    """Their checker's row for each schedule file (empty without their environment)."""
    if not ns.their_python:
        return {}
    script = Path(__file__).with_name("eosbench_theirs.py").resolve()
    env = {**os.environ, "PYTHONPATH": str(Path(ns.their_repo).resolve()), "MPLBACKEND": "Agg"}
    r = subprocess.run([ns.their_python, str(script), "check", str(Path(ns.scenario).resolve()), *paths],
                       cwd=ns.their_repo, env=env, capture_output=True, text=True, check=True)
    rows = [json.loads(line) for line in r.stdout.splitlines() if line.startswith("{")]
    return {row["schedule"]: row for row in rows}


def judge(scen, path: str, their: dict) -> dict:
    sched = read_schedule(path, scen)
    doc, code = check(scen, sched, Rules("documented")), check(scen, sched, Rules("code"))
    row = {**{k: doc.metrics[k] for k in KEYS}, "valid_documented": doc.valid, "valid_code": code.valid,
           "first_documented": doc.reason}
    t = their.get(path)
    if t is not None:
        row["their_first"] = t.get("first", t.get("error"))
        row["their_agree"] = ("error" not in t and t["first"] == code.their_first
                              and all(abs(t[k] - doc.metrics[k]) <= TOL for k in KEYS))
    return row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scenario")
    p.add_argument("--schedules", required=True, help="folder of their schedule files for this scenario")
    p.add_argument("--time-limit", type=float, default=30.0,
                   help="seconds of eosp's solver per reading (0: not run, their schedules judged alone)")
    p.add_argument("--their-python", help="interpreter of their environment (enables their checker)")
    p.add_argument("--their-repo", help="their repository (with --their-python)")
    p.add_argument("--log", help="JSON lines appended here")
    ns = p.parse_args()
    t0 = time.perf_counter()
    scen = read_scenario(ns.scenario)
    read_s = time.perf_counter() - t0
    stem = Path(ns.scenario).stem
    files = sorted(str(f) for f in Path(ns.schedules).glob(f"scheduler_{stem}_*.json"))
    rows = []
    for f in files:
        meta = json.loads(Path(f).read_text()).get("metrics", {})
        rows.append({"source": Path(f).stem.removeprefix(f"scheduler_{stem}_"), "path": f,
                     "runtime_s": meta.get("RT"), "bound": None, "gap": None})
    with tempfile.TemporaryDirectory() as tmp:
        for reading in ("documented", "code") if ns.time_limit > 0 else ():
            t1 = time.perf_counter()
            res = solve(scen, EosBenchConfig(time_limit=ns.time_limit, transition=reading))
            secs = time.perf_counter() - t1
            out = write_schedule(res.schedule, scen, str(Path(tmp) / f"eosp_{reading}.json"))
            rows.append({"source": f"eosp ({reading} reading)", "path": str(out), "runtime_s": secs,
                         "bound": res.bound, "gap": res.gap, "rounds": res.info["rounds"]})
        their = theirs(ns, [r["path"] for r in rows])
        for r in rows:
            r.update(judge(scen, r["path"], their))
    name = f"{stem} ({len(scen.satellites)} sat., {len(scen.tasks)} tasks, read in {read_s:.1f} s)"
    print("| scenario | schedule | TP | TCR | TM | BD | runtime s | valid doc./code | their checker | bound | gap |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        tc = "-" if "their_first" not in r else \
            (f"{'valid' if r['their_first'] == -1 else r['their_first']}, metrics {'=' if r['their_agree'] else '!='}")
        fmt = (lambda x, d: "-" if x is None else f"{x:.{d}f}")
        pct = (lambda x: "-" if x is None else f"{x:.2%}")
        print(f"| {name} | {r['source']} | {r['TP']:.1f} | {r['TCR']:.3f} | {r['TM']:.4f} | {r['BD']:.4f} | "
              f"{fmt(r['runtime_s'], 1)} | {'yes' if r['valid_documented'] else 'no'}/"
              f"{'yes' if r['valid_code'] else 'no'} | {tc} | {fmt(r['bound'], 1)} | "
              f"{pct(r['gap'])} |")
        if ns.log:
            with open(ns.log, "a") as fh:
                fh.write(json.dumps({"scenario": ns.scenario, **{k: v for k, v in r.items()}}, default=str) + "\n")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
