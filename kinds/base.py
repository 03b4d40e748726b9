"""What a problem kind needs beyond the contract to run on the command line, with defaults.

:class:`KindBase` gives a kind the command lines of ``eosp info|validate|solve|import|generate|export-schedule|
report`` (:meth:`KindBase.arguments`), the line ``eosp solve`` prints and the information a schedule file
keeps (:meth:`KindBase.solved`), and the output check of ``--out``.  A new kind subclasses it, sets its
members (:class:`eosp.problem.ProblemKind`) and overrides only what it words differently.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from eosp.problem import Detection, Export, Generator, Result, Solver, Source, Verdict, load

OVERWRITE_HELP = "replace an existing output that eosp wrote (a file or directory eosp did not write is never replaced)"
PROBLEM_COMMANDS = ("info", "validate", "solve")


@dataclass(frozen=True)
class Words:
    """How a kind's command lines word their arguments (None: no help text)."""

    problem: str = "problem"  # the problem's positional argument
    schedule: str | None = None  # a schedule file the kind reads
    schedules: str | None = None  # report's schedule files
    solver: str | None = None  # --solver (default: each solver with its help)
    out: str | None = "schedule file to write"  # a solve's --out
    overwrite: str | None = OVERWRITE_HELP
    formats: str | None = None  # export-schedule's --format (default: each format with its help)
    export_out: str | None = None  # export-schedule's --out
    source: str = "source"  # import's positional argument
    written: str | None = None  # the --out of import and generate
    overwrite_written: str | None = OVERWRITE_HELP
    generate_flag: str | None = None


class KindBase:
    """Defaults of a problem kind (see the module docstring)."""

    words = Words()

    name: str = ""
    title: str = ""
    solvers: Mapping[str, Solver] = {}
    sources: Sequence[Source] = ()
    generators: Sequence[Generator] = ()
    exports: Mapping[str, Export] = {}
    extra_commands: tuple[str, ...] = ()  # commands of this kind alone (a single pass: export, plot, build-shards)
    schedule_suffixes: tuple[str, ...] = (".parquet",)
    schedule_mark = "schedule"  # the ownership mark (eosp.ownership) of the schedule files this kind writes
    memory_checked: tuple[str, ...] = ()  # commands whose memory estimates --max-memory-gb caps (eosp.memory)

    @property
    def commands(self) -> frozenset[str]:
        """The commands this kind offers."""
        out = set(PROBLEM_COMMANDS) | set(self.extra_commands)
        out |= {"import"} if self.sources else set()
        out |= {"generate"} if self.generators else set()
        out |= {"export-schedule"} if self.exports else set()
        out |= {"report"} if type(self).report is not KindBase.report else set()
        return frozenset(out)

    # ------------------------------------------------------------------ the contract's defaults
    def detect(self, path: str) -> Detection:
        raise NotImplementedError

    def read(self, path: str, solving: bool = True) -> Any:
        raise NotImplementedError

    def read_schedule(self, path: str, problem: Any) -> Any:
        raise NotImplementedError

    def write_schedule(self, schedule: Any, problem: Any, path: str, overwrite: bool = False,
                       info: dict | None = None) -> Path:
        raise NotImplementedError

    def check(self, problem: Any, schedule: Any) -> Verdict:
        raise NotImplementedError

    def describe(self, problem: Any, path: str) -> str:
        return f"{path}: a problem of kind {self.name}"

    def report(self, problem: Any, schedules: list[str], out: str, ns: argparse.Namespace) -> str:
        """Write the HTML page of `schedules` (paths) of `problem` to `out`; the line to print."""
        raise NotImplementedError

    # ------------------------------------------------------------------ the command line
    def solver_config(self, solver: str | None) -> type:
        """The config class of `solver` (the shared SolverConfig when it is no solver of this kind)."""
        from eosp.solvers.base import SolverConfig

        return load(self.solvers[solver].config) if solver in self.solvers else SolverConfig

    def arguments(self, command: str, p: argparse.ArgumentParser, solver: str | None) -> None:
        """Add `command`'s arguments to its parser `p` (`solver`: the --solver given to a solve), worded by the
        kind's :class:`Words`."""
        from eosp.args import add_config_args, add_memory_arg

        w = self.words
        if command in self.memory_checked:
            add_memory_arg(p)
        if command in ("info", "validate", "solve", "export-schedule"):
            p.add_argument("problem", metavar=w.problem)
        if command == "validate":
            p.add_argument("schedule", help=w.schedule)
        elif command == "solve":
            p.add_argument("--solver", required=True, choices=tuple(self.solvers), help=w.solver or " or ".join(
                f"{k} ({s.help})" if s.help else k for k, s in self.solvers.items()))
            p.add_argument("--out", required=True, help=w.out)
            p.add_argument("--overwrite", action="store_true", help=w.overwrite)
            self.solve_arguments(p)
            add_config_args(p, self.solver_config(solver))
        elif command == "export-schedule":
            p.add_argument("schedule")
            p.add_argument("--format", required=True, choices=tuple(self.exports), help=w.formats or ", ".join(
                f"{k}: {e.help}" for k, e in self.exports.items()))
            p.add_argument("--out", required=True, help=w.export_out)
            p.add_argument("--overwrite", action="store_true", help=w.overwrite)
        elif command == "report":
            p.add_argument("problem", metavar=w.problem)
            p.add_argument("schedules", nargs="+", help=w.schedules)
            p.add_argument("--out", required=True, help="HTML file to write")
            p.add_argument("--title", default="")
            p.add_argument("--overwrite", action="store_true", help=w.overwrite)
        elif command == "import":
            p.add_argument("source", metavar=w.source, help=", ".join(s.what for s in self.sources))
            p.add_argument("--out", required=True, help=w.written)
            p.add_argument("--overwrite", action="store_true", help=w.overwrite_written)
        elif command == "generate":
            gen = self.generators[0]
            if gen.flag:
                p.add_argument(gen.flag, action="store_true", required=True, help=w.generate_flag)
            p.add_argument("--out", required=True, help=w.written)
            p.add_argument("--overwrite", action="store_true", help=w.overwrite_written)
            add_config_args(p, load(gen.config))

    def solve_arguments(self, p: argparse.ArgumentParser) -> None:
        """The kind's own solve arguments (:meth:`solve_inputs` reads them), after --overwrite."""

    def generator(self, ns: argparse.Namespace) -> Generator:
        """The generator a command line selects: the one whose flag it gives, else the one without a flag."""
        flagged = [g for g in self.generators if g.flag and getattr(ns, g.flag.lstrip("-").replace("-", "_"), False)]
        return (flagged or [g for g in self.generators if not g.flag] or list(self.generators))[0]

    def generator_config(self, gen: Generator, ns: argparse.Namespace) -> Any:
        """The generator's config from the command line."""
        from eosp.args import config_from_args

        return config_from_args(load(gen.config), ns)

    def import_options(self, ns: argparse.Namespace) -> dict:
        """Options of the import beyond its paths, output and --overwrite (keywords of the source's convert)."""
        return {}

    def import_paths(self, ns: argparse.Namespace) -> list[str]:
        """The paths an ``eosp import`` command line names (the source's detector picked this kind by the first)."""
        return [ns.source]

    def schedule_out(self, out: str, overwrite: bool) -> Path:
        """`out` checked as a schedule file this kind may write (before any work): the ownership rule and the
        suffixes it writes."""
        from eosp.ownership import check_output

        return check_output(out, self.schedule_mark, overwrite=overwrite, suffixes=self.schedule_suffixes)

    def before_read(self, solver: str, cfg: Any) -> None:
        """Checks of a solve's options that need no problem (a checkpoint that does not exist): refused before
        any file is read."""

    def before_solve(self, problem: Any, path: str) -> None:
        """Checks of a solve on the problem read, before solving (the memory a single pass needs)."""

    def solve_inputs(self, ns: argparse.Namespace, problem: Any) -> dict:
        """The kind's own inputs of a solve, from its command line (a fleet's --init): keywords of the solver."""
        return {}

    def incumbent(self, problem: Any) -> Any | None:
        """The best schedule a search of this kind had found when Ctrl-C stopped it (None: none kept)."""
        return None

    def solved(self, out: Path, solver: str, cfg: Any, res: Result, seconds: float) -> tuple[dict, str]:
        """What the schedule file keeps of a solve (Parquet metadata) and the line ``eosp solve`` prints."""
        bound = "" if res.bound is None else f", bound {res.bound:.6f} ({res.bound_kind}), gap {res.gap:.4%}"
        info = {"value": res.value, "solver": solver, "bound": res.bound, "gap": res.gap,
                "bound_source": res.bound_kind, "seconds": round(seconds, 3)}
        return info, f"{out}: {solver}, value {res.value:.6f}{bound} ({seconds:.2f} s)"


def labelled(paths: list[str], read: Callable[[str], Any]) -> dict[str, Any]:
    """The schedules of `paths` by label: the file name without suffix, a prime added to a repeated one."""
    out: dict[str, Any] = {}
    for path in paths:
        label = Path(path).stem
        while label in out:
            label += "'"
        out[label] = read(path)
    return out
