"""Re-planning after an event inside one process (issue 75, item 7): how close a short warm re-plan comes to a long
cold solve of the same state, against keeping the plan as it is.

    python experiments/replan_speed.py --scenario SCEN --realization 0 --call 2 --call-limit 10 --warm 5 --cold 120

The simulator runs `ev-replan` (``--call-limit`` seconds a call) through planning call ``--call`` and stops at the
next one: its plan sent, the planner's prices and master columns where that call left them.  The base state is
what the ground knew at that call (arrivals, reported outcomes, forecasts) with the timelines after its plan and
the next call's upload times.  Four events change it: an **arrival** (the requests arrived since), an **outcome**
(the acquisitions reported since), a **forecast** (the next call's), a **contact** (each satellite's upload moved to
its first contact 30 minutes later: more of its plan frozen).  For each, on the value of what is not frozen (the
planner's objective):

* keep: the plan as sent, valued under the event's values (each task once);
* warm: the planner re-plans from its state within ``--warm`` seconds;
* cold: a fresh planner (prices at their start, no columns) within ``--cold`` seconds.

Prints one row per event: the three values, warm / cold and keep / cold.  Each event starts again from a fresh run
to the base state (the planner's state cannot be copied), so the base plans of the events differ a little.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import time


class Stop(Exception):
    pass


class UpTo:
    """A planner that plans through `inner` up to call `call` and stops the simulation at the next call, with the
    knowledge of both."""

    def __init__(self, inner, call: int):
        self.inner, self.call, self.name = inner, call, inner.name
        self.before = self.after = None

    def plan(self, know):
        if know.call > self.call:
            self.after = know
            raise Stop
        if know.call == self.call:
            self.before = know
        return self.inner.plan(know)


def base_state(before, after, day):
    """The timelines and upload times of `after`, what the ground knew at `before`: arrivals, outcomes reported
    by then, its forecast."""
    import numpy as np

    report = day.next_contact(day.sat[after.rows], day.end_s[after.rows])
    known = (day.start_s[after.rows] < before.t) & (report <= before.t)
    return dataclasses.replace(after, arrived=before.arrived, forecast=before.forecast,
                               outcome=np.where(known, after.outcome, -1))


def kept_value(planner, know, rows) -> float:
    """The value under `know` of the plan `rows` in the passes not frozen (each task once, at its best pass)."""
    import numpy as np

    _, frozen, _, values = planner.values(know)
    prob, o = planner.prob, planner.prob.opps
    best = np.zeros(len(prob.weight))
    for r in rows.tolist():
        p, t = int(o.pass_id[r]), int(o.task[r])
        if frozen[p]:
            continue
        pos = prob.task_ptr[p] + int(np.flatnonzero(prob.passes[p].tasks == t)[0])
        best[t] = max(best[t], values[pos])
    return float(best.sum())


def event(kind: str, base, after, day):
    """The base state changed by one event (see the module docstring)."""
    import numpy as np

    if kind == "arrival":
        return dataclasses.replace(base, arrived=after.arrived)
    if kind == "outcome":
        return dataclasses.replace(base, outcome=after.outcome)
    if kind == "forecast":
        return dataclasses.replace(base, forecast=after.forecast)
    n = len(base.upload_s)
    later = day.next_contact(np.arange(n), np.maximum(base.upload_s, base.t) + 1800.0)
    return dataclasses.replace(base, upload_s=np.where(np.isfinite(base.upload_s), later, base.upload_s))


def main() -> None:
    from eosp.kinds.fleet.operations import FleetPlanner, SimulateConfig, Simulation
    from eosp.ops import scenario
    from eosp.ops.simulate import simulate
    from eosp.ops.world import realize

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", required=True)
    ap.add_argument("--realization", type=int, default=0)
    ap.add_argument("--call", type=int, default=2)
    ap.add_argument("--call-limit", type=float, default=10.0)
    ap.add_argument("--warm", type=float, default=5.0)
    ap.add_argument("--cold", type=float, default=120.0)
    ap.add_argument("--events", nargs="+", default=["arrival", "outcome", "forecast", "contact"])
    ap.add_argument("--call-rounds", type=int, default=None,
                    help="price rounds of each call up to the base state instead of --call-limit seconds (the same "
                         "base state in every run; uploads still wait for --call-limit)")
    ap.add_argument("--carry", nargs="+", default=["scale"], choices=["scale", "keep"],
                    help="how the warm re-plan carries its prices to the new values (each from the same state: "
                         "the prices restored, or with master columns a run again, the same with --call-rounds)")
    args = ap.parse_args()
    scen = scenario.read(args.scenario)
    world = realize(scen, args.realization)
    print("| event | keep | warm | cold | warm / cold | keep / cold | warm s | cold s |\n|---|---|---|---|---|---|---|---|")
    for kind in args.events:
        warms, sim = [], None
        for carry in args.carry:
            if sim is None or sim.planner.replanner.master is not None:  # a master LP cannot be copied: run again
                if sim is not None:
                    sim.close()
                sim = Simulation.of(scen, SimulateConfig(planner="ev-replan", time_limit=args.call_limit,
                                                         rounds=args.call_rounds))
                stop = UpTo(sim.planner, args.call)
                try:
                    simulate(sim.day, world, stop, args.call_limit)
                except Stop:
                    pass
                know = event(kind, base_state(stop.before, stop.after, sim.day), stop.after, sim.day)
                W = sim.planner.prob.total_weight
                keep = kept_value(sim.planner, know, know.rows[~know.alternate])
                rp = sim.planner.replanner
                rp.cfg = dataclasses.replace(rp.cfg, time_limit=args.warm, rounds=None)
                base = (copy.deepcopy(rp.prices), rp._cap, rp.calls)
            else:  # the same state again: the prices as the base left them (no master columns)
                rp.prices, rp._cap, rp.calls = copy.deepcopy(base[0]), *base[1:]
            rp.carry = carry
            t = time.perf_counter()
            warms.append((carry, sim.planner.plan(know).info["objective"] * W, time.perf_counter() - t))
        _, warm, warm_s = warms[-1]
        if len(warms) > 1:
            print(f"| {kind}, warm by carry | " + " | ".join(f"{c}: {v:.2f} ({s_:.1f} s)" for c, v, s_ in warms) + " |",
                  flush=True)
        if args.cold <= 0:  # the warm ones only
            sim.close()
            continue
        cold_planner = FleetPlanner("ev-replan", sim.planner.prob, dataclasses.replace(sim.planner.cfg,
                                                                                      time_limit=args.cold, rounds=None))
        t = time.perf_counter()
        cold = cold_planner.plan(know).info["objective"] * W
        cold_s = time.perf_counter() - t
        cold = cold or float("nan")  # nothing left to serve
        print(f"| {kind} | {keep:.2f} | {warm:.2f} | {cold:.2f} | {warm / cold:.4f} | {keep / cold:.4f} | "
              f"{warm_s:.1f} | {cold_s:.1f} |", flush=True)
        cold_planner.close()
        sim.close()

if __name__ == "__main__":
    main()
