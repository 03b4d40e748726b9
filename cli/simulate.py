"""``eosp simulate SCEN --planner NAME --realizations N --out RUN/``: a planner run through realizations of an
operations scenario (:mod:`eosp.ops.simulate`, the fleet solver's planners in :mod:`eosp.kinds.fleet.operations`).

RUN/summary.json is written after every realization (replaced whole), so Ctrl-C keeps the realizations finished
so far, says so in one line and exits 130; ``--resume`` goes on from them (the same scenario and options)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def cmd_simulate(kind, ns: argparse.Namespace) -> int:  # noqa: ARG001 - the fleet kind, the one offering it
    from eosp.args import config_from_args
    from eosp.kinds.fleet.operations import (SimulateConfig, Simulation, prior_realizations, summary_line,
                                             write_summary)
    from eosp.ops import scenario

    cfg = config_from_args(SimulateConfig, ns)
    out = Path(ns.out)
    scen = scenario.read(ns.problem)  # a bad scenario is refused before anything is written
    done = prior_realizations(out, ns.problem, cfg, resume=ns.resume, overwrite=ns.overwrite)
    sim = Simulation.of(scen, cfg)  # a bad onboard policy is refused here, before anything is written
    out.mkdir(parents=True, exist_ok=True)
    have = {r["realization"] for r in done}
    try:
        for index in range(cfg.realizations):
            if index not in have:
                done.append(sim.run(index))
                write_summary(out, ns.problem, cfg, done)
                if index < ns.replay:
                    replay(sim, done[-1], out / f"replay-{index:04d}.html")
    except KeyboardInterrupt:
        if done:
            m = write_summary(out, ns.problem, cfg, done)
            print(f"eosp simulate: interrupted: {summary_line(out / 'summary.json', cfg, m)}", file=sys.stderr)
        else:
            print("eosp simulate: interrupted: no realization finished, nothing written", file=sys.stderr)
        return 130
    finally:
        sim.close()
    m = write_summary(out, ns.problem, cfg, done)
    print(summary_line(out / "summary.json", cfg, m))
    if m["valid"] < m["realizations"]:
        bad = next(r for r in done if not r["valid"])
        print(f"eosp simulate: an executed timeline is invalid (a defect; realization {bad['realization']}): "
              f"{bad['violation']}", file=sys.stderr)
        return 1
    return 0


def replay(sim, figures: dict, path: Path) -> None:
    """The replay page of the realization `sim` ran last: the fleet page of the day as executed with the replay's
    sections (:mod:`eosp.evaluation.replay_page`)."""
    import numpy as np

    from eosp.evaluation.replay_page import replay_data, replay_page, write_replay

    world, run = sim.last
    planner = f"{sim.cfg.planner}{' + onboard rule' if sim.cfg.onboard == 'rule' else ''}"
    title = f"{planner}: {sim.scen.path.name}, realization {world.index}"
    executed = sim.planner.schedule(np.asarray(run.rows, dtype=np.int64))
    info = {"solver": planner, "time_limit": sim.cfg.time_limit}
    write_replay(path, replay_page(sim.scen.fleet, sim.scen.opps, executed, replay_data(sim.day, world, run, sim.scen),
                                   figures, title, info))
