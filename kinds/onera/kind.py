"""The ONERA kind: the ONERA constellation benchmark (requests of four kinds, observations with their windows,
mandatory downloads; :mod:`eosp.onera.model`), checked by :mod:`eosp.onera.check`, solved by a greedy plan or by
large-neighbourhood search with a proven bound (:mod:`eosp.kinds.onera.search`).

``eosp import FILE.pb --out DIR``, ``eosp info|solve|validate|report DIR ...``, ``eosp export-schedule DIR S --format
onera --out PLAN.txt``.  User mistakes raise :class:`~eosp.errors.InputError` (one line, exit 2).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from eosp.kinds.base import KindBase, Words, labelled
from eosp.problem import Detection, Export, Result, Solver, Source, Verdict

HERE = "eosp.kinds.onera.kind"


def is_pb(path: str) -> Detection:
    from eosp.onera.model import is_onera_file

    if is_onera_file(path):
        return Detection(True, "an ONERA .pb file")
    return Detection(False, "not an ONERA benchmark instance (.pb)")


def import_pb(paths: list[str], out: str, overwrite: bool = False) -> str:
    """Read an ONERA ``.pb`` instance and write its fleet directory."""
    from eosp.atomic import check_output_dir
    from eosp.onera.model import KIND_SHORT, TABLE_FILES, is_onera_dir, read_pb, write_onera

    (pb_file,) = paths
    check_output_dir(out, overwrite=overwrite, owned=is_onera_dir, what="ONERA fleet directory",
                     names=lambda _: TABLE_FILES)
    t0 = time.perf_counter()
    f = read_pb(pb_file)
    write_onera(f, out, overwrite=overwrite, source=Path(pb_file).name)
    kinds = ", ".join(f"{KIND_SHORT[k]} {int((f.requests.kind == k).sum())}" for k in range(4))
    return (f"{out}: {len(f.satellites)} satellites, {len(f.requests)} requests ({kinds}), {len(f.observations)} "
            f"observations, {len(f.downloads)} downloads ({time.perf_counter() - t0:.1f} s)")


def export_plan(problem, schedule, out: str, overwrite: bool = False) -> str:
    """The ONERA text plan (docs/formats.md, "ONERA plan")."""
    from eosp.onera.model import write_plan

    return f"{Path(write_plan(schedule, problem, out, overwrite=overwrite))}: {len(schedule)} activities"


class OneraKind(KindBase):
    name = "onera"
    title = "an ONERA fleet directory (eosp import FILE.pb)"
    words = Words(problem="fleet_dir", schedule="ONERA schedule (.parquet) or text plan (.txt)",
                  schedules="ONERA schedules (.parquet) or text plans (.txt)",
                  solver="greedy (requests by value, each at its best fitting observations) or onera (greedy, then "
                         "large-neighbourhood search, with a proven bound)",
                  out="ONERA schedule file (.parquet)", overwrite=None, formats="the ONERA text plan",
                  export_out="text plan to write (.txt)", source="pb_file", written="ONERA fleet directory to write",
                  overwrite_written="replace an ONERA fleet directory eosp wrote")
    schedule_mark = "onera-schedule"
    solvers = {"greedy": Solver("greedy", "eosp.kinds.onera.search:GreedyConfig",
                                "eosp.kinds.onera.search:solve_greedy",
                                "requests by value, each at its best fitting observations"),
               "onera": Solver("onera", "eosp.kinds.onera.search:OneraConfig", "eosp.kinds.onera.search:solve_onera",
                               "greedy, then large-neighbourhood search, with a proven bound")}
    sources = (Source("an ONERA benchmark instance (.pb)", f"{HERE}:is_pb", f"{HERE}:import_pb"),)
    exports = {"onera": Export("onera", "the ONERA text plan", f"{HERE}:export_plan")}

    def detect(self, path: str) -> Detection:
        from eosp.onera.model import KIND, is_onera_dir

        if is_onera_dir(path):
            return Detection(True, "an ONERA fleet directory")
        return Detection(False, f"not an ONERA fleet directory (no meta.json of kind {KIND!r})")

    def read(self, path: str, solving: bool = True) -> Any:
        from eosp.onera.model import read_onera

        return read_onera(path)

    def read_schedule(self, path: str, problem: Any) -> Any:
        from eosp.onera.model import read_schedule

        return read_schedule(path, problem)[0]

    def write_schedule(self, schedule: Any, problem: Any, path: str, overwrite: bool = False,
                       info: dict | None = None) -> Path:
        from eosp.onera.model import write_schedule

        return write_schedule(schedule, problem, path, overwrite=overwrite, info=info)

    def check(self, problem: Any, schedule: Any) -> Verdict:
        from eosp.onera.check import validate

        return validate(problem, schedule).verdict()

    def describe(self, problem: Any, path: str) -> str:
        """Sizes, opportunities per request and the conflict-free upper bound."""
        import numpy as np

        from eosp.onera.check import best_values
        from eosp.onera.model import KIND_SHORT

        f = problem
        per = np.diff(f.requests.first)
        lines = [f"ONERA fleet: {path} ({f.name})",
                 f"satellites: {len(f.satellites)}; downloads: {len(f.downloads)} (mandatory)"]
        for k in range(4):
            sel = f.requests.kind == k
            if sel.any():
                lines.append(f"{KIND_SHORT[k]}: {int(sel.sum())} requests, {int(per[sel].sum())} observations")
        lines.append(f"requests without opportunity: {int((per == 0).sum())}")
        lines.append(f"conflict-free upper bound: {best_values(f).sum():.6g}")
        return "\n".join(lines)

    def report(self, path: str, schedules: list[str], out: str, ns: argparse.Namespace) -> str:
        """The fleet page (:mod:`eosp.evaluation.fleet_report`) of an ONERA fleet: its own model and plans, no
        orbits."""
        from eosp.evaluation.fleet_report import check_report_out, report_page
        from eosp.onera.model import read_schedule

        check_report_out(out, ns.overwrite)
        t0 = time.perf_counter()
        f = self.read(path)
        return report_page(f, None, labelled(schedules, lambda s: read_schedule(s, f)), out, ns, t0)

    # ------------------------------------------------------------------ the command line
    def solver_config(self, solver: str | None) -> type:
        from eosp.kinds.onera.search import OneraConfig

        return super().solver_config(solver) if solver in self.solvers else OneraConfig

    def solved(self, out: Path, solver: str, cfg: Any, res: Result, seconds: float) -> tuple[dict, str]:
        from eosp.onera.model import KIND_SHORT

        info = {"value": res.value, "solver": solver, "bound": res.bound, "gap": res.gap,
                "bound_source": res.bound_kind, "seconds": round(res.timings["solve"], 3),
                "time_limit": getattr(cfg, "time_limit", None)}
        served = ", ".join(f"{k} {res.verdict.metrics[k]}" for k in KIND_SHORT)
        bound = "" if res.bound is None else f", bound {res.bound:.4f} ({res.bound_kind}), gap {res.gap:.2%}"
        return info, (f"{out}: value {res.value:.4f}{bound}; served {served}; {res.info['moves']} moves "
                      f"({res.timings['solve']:.1f} s)")

    def arguments(self, command: str, p: argparse.ArgumentParser, solver: str | None) -> None:
        if command == "report":
            from eosp.evaluation.fleet_report import PAGE

            p.description = PAGE
        super().arguments(command, p, solver)


KIND = OneraKind()
