"""``eosp plot INSTANCE_DIR SCHEDULE... --out PATH``: the trajectory plot (roll against time) of feasible
schedules of one instance, PNG and SVG."""

from __future__ import annotations

import argparse
from pathlib import Path

from eosp.errors import InputError


def cmd_plot(kind, ns: argparse.Namespace) -> int:
    from eosp.evaluation.plots import check_plot_out, plot_trajectories
    from eosp.instances.schedule import check, read_schedule

    check_plot_out(ns.out, ns.overwrite)
    inst = kind.read(ns.problem)
    schedules = {Path(s).stem: read_schedule(s) for s in ns.schedules}
    for name, sched in zip(ns.schedules, schedules.values()):
        verdict = check(inst, sched)  # plot only schedules that make sense for this instance
        if not verdict.feasible:
            raise InputError(name, f"not a feasible schedule of this instance: {verdict.reason}")
    written = plot_trajectories(inst, schedules, ns.out, overwrite=ns.overwrite)
    print("wrote " + ", ".join(str(p) for p in written))
    return 0
