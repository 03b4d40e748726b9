"""The regional_coverage kind: a case directory of astro-reason's regional_coverage benchmark (polygon regions
covered by SAR strips over 72 h, at most `max_actions_total` strips), read where it lies
(:mod:`eosp.regional.read`), judged by :mod:`eosp.regional.check` (the verifier's rules and metrics), solved by
:mod:`eosp.kinds.regional.solve`.

``eosp info CASE``, ``eosp solve CASE --solver coverage|greedy --out solution.json`` (their solution format),
``eosp validate CASE solution.json`` (exit 1 naming the first violation), ``eosp report CASE solution.json
--out page.html`` (regions, strips and covered samples on a map).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from eosp.kinds.base import KindBase, Words
from eosp.problem import Detection, Result, Solver, Verdict

HERE = "eosp.kinds.regional"


class RegionalKind(KindBase):
    name = "regional-coverage"
    title = "a regional_coverage case directory (astro-reason)"
    words = Words(problem="case", schedule="solution file (.json, the benchmark's format)",
                  schedules="solution files (.json)", out="solution file to write (.json, the benchmark's format)")
    schedule_suffixes = (".json",)
    schedule_mark = "regional-coverage-solution"
    solvers = {
        "coverage": Solver("coverage", f"{HERE}.solve:CoverageConfig", f"{HERE}.solve:solve",
                           "greedy, then ruin-and-recreate moves; a Lagrangian bound over the candidate grid"),
        "mip": Solver("mip", f"{HERE}.mip:MipConfig", f"{HERE}.mip:solve_mip",
                      "HiGHS over the candidate strips (a baseline: pairwise slew rows, no duty or battery rows)"),
        "greedy": Solver("greedy", f"{HERE}.solve:GreedyConfig", f"{HERE}.solve:solve_greedy",
                         "the strip of largest marginal coverage that fits, until the action budget"),
    }

    def detect(self, path: str) -> Detection:
        from eosp.regional.read import looks_like_case

        return Detection(*looks_like_case(path))

    def read(self, path: str, solving: bool = True) -> Any:
        from eosp.regional.read import read_case

        return read_case(path)

    def read_schedule(self, path: str, problem: Any) -> Any:
        from eosp.regional.read import read_solution

        return read_solution(path)

    def write_schedule(self, schedule: Any, problem: Any, path: str, overwrite: bool = False,
                       info: dict | None = None) -> Path:
        from eosp.regional.read import write_solution

        return write_solution(schedule, path, overwrite=overwrite, info=info)

    def check(self, problem: Any, schedule: Any) -> Verdict:
        from eosp.regional.check import verdict

        return verdict(problem, schedule)

    def describe(self, problem: Any, path: str) -> str:
        import numpy as np

        c = problem
        lines = [f"regional_coverage case: {path} ({c.case_id})",
                 f"horizon {c.horizon_start.isoformat()} to {c.horizon_end.isoformat()} ({c.horizon_s / 3600:g} h), "
                 f"time grid {c.time_step_s} s, strips sampled every {c.sample_step_s} s",
                 f"actions allowed: {c.max_actions if c.max_actions is not None else 'no limit'}",
                 f"satellites: {len(c.satellites)}"]
        for s in c.satellites:
            lo, hi = s.roll_band
            duty = "none" if s.imaging_duty_limit_s_per_orbit is None else f"{s.imaging_duty_limit_s_per_orbit:g} s"
            lines.append(f"  {s.id}: |roll| {lo:g}-{hi:g} deg (fov {s.cross_track_fov_deg:g}), strips "
                         f"{s.min_strip_duration_s:g}-{s.max_strip_duration_s:g} s, duty limit {duty} per orbit")
        lines.append(f"regions: {len(c.regions)}, grid samples: {len(c.lon)}")
        for k, r in enumerate(c.regions):
            need = "" if r.min_required_coverage_ratio is None else f", at least {r.min_required_coverage_ratio:g}"
            lines.append(f"  {r.id}: weight {r.weight:g}, {int(np.sum(c.region == k))} samples, "
                         f"{c.region_total_m2[k] / 1e6:,.0f} km2{need}")
        return "\n".join(lines)

    def report(self, problem: Any, schedules: list[str], out: str, ns: argparse.Namespace) -> str:
        from eosp.evaluation.regional_page import write_page
        from eosp.ownership import check_output

        check_output(out, "report", ns.overwrite, suffixes=(".html", ".htm"))  # before any reading
        return write_page(self.read(problem), schedules, out, title=ns.title, overwrite=ns.overwrite)

    def solved(self, out: Path, solver: str, cfg: Any, res: Result, seconds: float) -> tuple[dict, str]:
        m = res.verdict.metrics if res.verdict is not None else {}
        info = {"value": res.value, "solver": solver, "bound": res.bound, "gap": res.gap,
                "bound_source": res.bound_kind, "seconds": round(seconds, 3), "candidates": res.info.get("candidates"),
                "moves": res.info.get("moves")}
        bound = "" if res.bound is None else f", bound {res.bound:.6f} ({res.bound_kind}), gap {res.gap:.4%}"
        return info, (f"{out}: {solver}, coverage_ratio {res.value:.6f}{bound}; weighted_coverage_ratio "
                      f"{m.get('weighted_coverage_ratio', 0.0):.6f}, {m.get('num_actions', 0)} actions "
                      f"({res.info.get('candidates')} candidate strips, {seconds:.2f} s)")


KIND = RegionalKind()
