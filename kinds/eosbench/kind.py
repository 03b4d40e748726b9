"""The EOS-Bench kind: a scenario JSON of Ethan19YQ/EOS-Bench's generator (:mod:`eosp.eosbench.read`, read as a
stream), checked by :mod:`eosp.eosbench.check` (their rules, their generator's, their metrics), solved by
:mod:`eosp.kinds.eosbench.solve` (passes per satellite and orbit, task prices, a Lagrangian bound).

``eosp info SCENARIO.json``, ``eosp solve SCENARIO.json --solver eosbench --out S.json``, ``eosp validate
SCENARIO.json S.json`` (their schedule files too).  The verdict holds their rules under the documented transition
model (the default of the solver too) and says beside it what the code reading (11.66 s) gives.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from eosp.kinds.base import KindBase, Words
from eosp.problem import Detection, Result, Solver, Verdict

HERE = "eosp.kinds.eosbench"


class EosBenchKind(KindBase):
    name = "eosbench"
    title = "an EOS-Bench scenario (their generator's JSON)"
    words = Words(problem="scenario", schedule="EOS-Bench schedule (.json, theirs or eosp's)",
                  solver="eosbench (passes per satellite and orbit, task prices, a Lagrangian bound)",
                  out="schedule file to write (.json, their format)")
    schedule_suffixes = (".json",)
    schedule_mark = "eosbench-schedule"
    solvers = {"eosbench": Solver("eosbench", f"{HERE}.solve:EosBenchConfig", f"{HERE}.solve:solve",
                                  "passes per satellite and orbit, task prices, a Lagrangian bound")}

    def detect(self, path: str) -> Detection:
        from eosp.eosbench.read import looks_like_scenario

        return Detection(*looks_like_scenario(path))

    def read(self, path: str, solving: bool = True) -> Any:
        from eosp.eosbench.read import read_scenario

        return read_scenario(path)

    def read_schedule(self, path: str, problem: Any) -> Any:
        from eosp.eosbench.schedules import read_schedule

        return read_schedule(path, problem)

    def write_schedule(self, schedule: Any, problem: Any, path: str, overwrite: bool = False,
                       info: dict | None = None) -> Path:
        from eosp.eosbench.check import metrics
        from eosp.eosbench.schedules import write_schedule

        m = metrics(problem, schedule)
        rt = (info or {}).get("seconds")
        out = {"TP": m["TP"], "TCR": m["TCR"], "BD": m["BD"], "TM": m["TM"], "RT": rt, "RV": None}
        return write_schedule(schedule, problem, path, overwrite=overwrite, metrics=out, info=info)

    def check(self, problem: Any, schedule: Any) -> Verdict:
        from eosp.eosbench.check import verdict

        return verdict(problem, schedule)

    def describe(self, problem: Any, path: str) -> str:
        import numpy as np

        s = problem
        w = s.windows
        agile = int(s.satellites.agile.sum())
        lines = [f"EOS-Bench scenario: {path} ({s.name})",
                 f"start {s.start.isoformat()}, horizon {s.duration_s:g} s, time step {s.time_step:g} s",
                 f"satellites: {len(s.satellites)} ({agile} agile, {len(s.satellites) - agile} non-agile); "
                 f"ground stations: {len(s.stations)}, communication windows: {len(s.comm)}",
                 f"tasks: {len(s.tasks)}, priority sum {s.tasks.priority.sum():g}; observation windows: {len(w)}, "
                 f"attitude samples: {int(w.att_ptr[-1])}",
                 f"tasks without a window: {int((np.bincount(w.task, minlength=len(s.tasks)) == 0).sum())}; "
                 f"orbits with windows: {len({(int(a), int(b)) for a, b in zip(w.satellite, w.orbit)})}"]
        lines += [f"not a constraint of their model: {k} ({why})" for k, why in s.ignored.items()]
        return "\n".join(lines)

    def solved(self, out: Path, solver: str, cfg: Any, res: Result, seconds: float) -> tuple[dict, str]:
        m = res.info["metrics"]
        info = {"value": res.value, "solver": solver, "bound": res.bound, "gap": res.gap,
                "bound_source": res.bound_kind, "seconds": round(seconds, 3), "transition": cfg.transition,
                "agility": cfg.agility, "rounds": res.info["rounds"]}
        bound = "" if res.bound is None else f", bound {res.bound:.6g} ({res.bound_kind}), gap {res.gap:.4%}"
        return info, (f"{out}: TP {m['TP']:.6g}{bound}; TCR {m['TCR']:.4f}, TM {m['TM']:.4f}, BD {m['BD']:.4f} "
                      f"({res.info['rounds']} price rounds, {seconds:.2f} s)")


KIND = EosBenchKind()
