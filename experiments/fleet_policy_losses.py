"""Where a fleet schedule loses weight against a reference schedule of the same fleet (the fleet policy's decode
against the fleet solver's): the tasks only one of them serves, by weight, by how many passes could observe them
(contention) and by satellite.

    eosp import AEOSSP_CASE --out CASE
    eosp solve CASE --solver fleet-policy --polish none --out policy.parquet
    eosp solve CASE --solver fleet --time-limit 30 --out fleet.parquet
    python experiments/fleet_policy_losses.py CASE policy.parquet fleet.parquet

CASE: a fleet directory or an aeossp case directory (its opportunities computed); the schedules: fleet schedules
(.parquet) or aeossp solutions (.json).
"""

from __future__ import annotations

import argparse

import numpy as np


def served(schedule, index: dict[str, int]) -> np.ndarray:
    """Rows of the fleet's tasks that `schedule` observes."""
    return np.unique([index[t] for t in schedule.task.tolist()]).astype(np.int64)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("fleet")
    p.add_argument("schedule")
    p.add_argument("reference")
    a = p.parse_args()
    from eosp.envs.constellation import read_fleet_dir
    from eosp.fleet.io import read_schedule

    from eosp.errors import InputError

    try:
        fleet, opps = read_fleet_dir(a.fleet)
        sched, ref = (read_schedule(x, fleet)[0] for x in (a.schedule, a.reference))
    except InputError as exc:
        raise SystemExit(f"error: {exc}") from None
    w = fleet.tasks.weight.astype(float)
    total = w.sum()
    index = fleet.task_index()
    mine, theirs = served(sched, index), served(ref, index)
    only_ref, only_mine = np.setdiff1d(theirs, mine), np.setdiff1d(mine, theirs)
    passes = np.zeros(len(w), np.int64)  # passes that can observe each task: its contention
    pairs = np.unique(np.stack([opps.task, opps.pass_id]), axis=1)
    np.add.at(passes, pairs[0], 1)
    print(f"WCR {w[mine].sum() / total:.4f} against {w[theirs].sum() / total:.4f}: {len(only_ref)} tasks only in the "
          f"reference ({w[only_ref].sum() / total:.4f} of the weight), {len(only_mine)} only in the schedule "
          f"({w[only_mine].sum() / total:.4f})")
    print("| passes that can observe the task | tasks | served by both | only reference (weight) | only schedule "
          "(weight) |\n|---|---|---|---|---|")
    for lo, hi in ((1, 1), (2, 3), (4, 7), (8, 10**9)):
        sel = lambda rows: rows[(passes[rows] >= lo) & (passes[rows] <= hi)]  # noqa: E731
        n = int(((passes >= lo) & (passes <= hi)).sum())
        both = sel(np.intersect1d(mine, theirs))
        r, m = sel(only_ref), sel(only_mine)
        label = f"{lo}" if lo == hi else f"{lo}-{hi}" if hi < 10**9 else f">= {lo}"
        print(f"| {label} | {n} | {len(both)} | {len(r)} ({w[r].sum() / total:.4f}) | {len(m)} ({w[m].sum() / total:.4f}) |")
    wq = np.quantile(w, [0.5, 0.9])
    print(f"weight of the tasks only in the reference: median {np.median(w[only_ref]) if len(only_ref) else 0:.2f} "
          f"(all tasks: median {wq[0]:.2f}, 90th percentile {wq[1]:.2f}); only in the schedule: median "
          f"{np.median(w[only_mine]) if len(only_mine) else 0:.2f}")
    sats = fleet.satellite_index()
    by_sat = np.zeros((2, len(sats)))
    for k, s in enumerate((sched, ref)):
        np.add.at(by_sat[k], [sats[x] for x in s.satellite.tolist()],
                  [w[index[t]] / total for t in s.task.tolist()])
    worst = np.argsort(by_sat[0] - by_sat[1])[:5]
    print("satellites where the schedule serves least against the reference (weight share, schedule / reference): "
          + ", ".join(f"{fleet.satellites.ids[i]} {by_sat[0, i]:.4f} / {by_sat[1, i]:.4f}" for i in worst))


if __name__ == "__main__":
    main()
