"""The single-pass kind: one satellite's pass as the paper's discrete graph (an interchange directory, or one
instance of a Parquet shard), checked by the independent checker, solved by the solvers of eosp.solvers."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from eosp.errors import InputError
from eosp.kinds.base import OVERWRITE_HELP, KindBase
from eosp.problem import Detection, Generator, Result, Solver, Source, Verdict

GRAPH_FILES = ("acquisitions.parquet", "nodes.parquet", "arcs.parquet")
SOLVER_NAMES = "random, greedy, ramp, exact, lns, policy, sample, beam, mcts"


def is_instance(path: str) -> Detection:
    """An interchange directory (one of its graph files in it) or ``SHARD.parquet#INDEX``."""
    if "#" in path:
        return Detection(True, "a shard's instance")
    p = Path(path)
    if not p.is_dir():
        return Detection(False, "no such directory" if not p.exists() else "not a directory")
    if any((p / f).exists() for f in GRAPH_FILES):
        return Detection(True, "an instance directory")
    return Detection(False, f"no {', '.join(GRAPH_FILES)} in it")


def load_instance(path: str):
    """An instance from an interchange directory, or `SHARD.parquet#INDEX` from a shard."""
    from eosp.instances.interchange import read_instance

    if "#" in path:
        from eosp.shards.io import ShardReader

        file, _, idx = path.rpartition("#")
        if not idx.isdigit():
            raise InputError(path, f"expected SHARD.parquet#INDEX with INDEX a number >= 0, got {idx!r}")
        return ShardReader(file).read(int(idx))
    return read_instance(path)


def import_dirs(paths: list[str], out: str, overwrite: bool = False, pruned_only: bool = False) -> str:
    """Interchange directories into one Parquet shard."""
    from eosp.instances.interchange import read_instance
    from eosp.shards.io import check_shard_out, write_shard

    check_shard_out(out, overwrite)
    insts, first = [], {}
    for d in paths:
        inst = read_instance(d)
        if inst.name in first:  # a shard's instances are told apart by their names
            raise InputError(d, f"instance name {inst.name!r} already given by {first[inst.name]}: a shard holds "
                                "distinct instances (rename one in its meta.json)")
        first[inst.name] = d
        insts.append(inst)
    write_shard(out, insts, include_unpruned=not pruned_only, overwrite=overwrite)
    return f"{out}: {len(insts)} instance(s)"


def generate(cfg, out: str, overwrite: bool = False) -> str:
    """Draw one instance and write it as an interchange directory."""
    import time

    from eosp.instances.generator import generate as draw
    from eosp.instances.generator import require_generate_memory
    from eosp.instances.interchange import check_instance_out, write_instance

    check_instance_out(out, overwrite=overwrite)
    require_generate_memory(cfg, "--n-acquisitions")  # from the request, before minutes of generation
    t0 = time.perf_counter()
    inst = draw(cfg)
    write_instance(inst, out, overwrite=overwrite)
    return (f"{out}: {inst.n_acq} acquisitions, {inst.n_nodes} nodes, {inst.unpruned().n_arcs} arcs "
            f"({time.perf_counter() - t0:.2f} s)")


def solve(inst, cfg) -> Result:
    """Solver ``cfg.NAME`` of :mod:`eosp.solvers` on `inst`; its path as an interchange schedule.  The searches
    report their improving schedules to :data:`eosp.solvers.base.INCUMBENT` (what Ctrl-C writes)."""
    import time
    from dataclasses import fields

    from eosp.instances.schedule import from_internal_nodes
    from eosp.solvers import base

    t0 = time.perf_counter()
    sol = base.run_solver(cfg.NAME, inst, **{f.name: getattr(cfg, f.name) for f in fields(cfg)})
    bound = sol.info.get("bound")
    return Result(from_internal_nodes(inst, sol.nodes), sol.value, bound, None if bound is None else "exact",
                  sol.info.get("status", "done"), {"solve": time.perf_counter() - t0}, sol.info)


class SinglePass(KindBase):
    name = "single-pass"
    title = "an instance directory (interchange format) or SHARD.parquet#INDEX"
    schedule_suffixes = (".parquet", ".jsonl", ".json")
    sources = (Source("instance directories (interchange format) into a Parquet shard",
                      "eosp.kinds.single.kind:is_instance", "eosp.kinds.single.kind:import_dirs"),)
    generators = (Generator(None, "eosp.config:InstanceConfig", "eosp.kinds.single.kind:generate"),)
    extra_commands = ("export", "plot", "build-shards")

    @property
    def solvers(self) -> dict[str, Solver]:
        from eosp.solvers.base import REGISTRY

        return {name: Solver(name, entry.config, "eosp.kinds.single.kind:solve") for name, entry in REGISTRY.items()}

    def detect(self, path: str) -> Detection:
        return is_instance(path)

    def read(self, path: str, solving: bool = True) -> Any:
        return load_instance(path)

    def read_schedule(self, path: str, problem: Any) -> Any:
        from eosp.instances.schedule import read_schedule

        return read_schedule(path)

    def write_schedule(self, schedule: Any, problem: Any, path: str, overwrite: bool = False,
                       info: dict | None = None) -> Path:
        from eosp.instances.schedule import write_schedule

        return write_schedule(schedule, path, overwrite=overwrite)

    def check(self, problem: Any, schedule: Any) -> Verdict:
        from eosp.instances.schedule import check

        v = check(problem, schedule)
        line = f"feasible: {v.n} acquisitions, value {v.value:.6f}" if v.feasible else f"infeasible: {v.reason}"
        return Verdict(v.feasible, {"acquisitions": v.n, "value": v.value}, v.reason or None, line)

    def describe(self, problem: Any, path: str) -> str:
        from eosp.graphs.continuous import continuous_graph

        inst = problem
        pg = inst.pruned()
        cs, _ = continuous_graph(pg)
        out = {"name": inst.name, "acquisitions": inst.n_acq, "nodes": inst.n_nodes,
               "arcs_unpruned": None if inst.unpruned_graph is None else inst.unpruned_graph.n_arcs,
               "arcs_pruned": pg.n_arcs, "continuous_arcs_pruned": int(cs.size), "family": inst.meta.get("family")}
        return json.dumps(out, indent=1)

    def report(self, path: str, schedules: list[str], out: str, ns: argparse.Namespace) -> str:
        from eosp.evaluation.html_report import check_report_out, write_report
        from eosp.instances.schedule import read_schedule

        check_report_out(out, ns.overwrite)
        inst = load_instance(path)
        scheds = {}
        for s in schedules:
            label = Path(s).stem
            if label in scheds:  # same file name in two folders: tell them apart by the folder
                label = f"{Path(s).parent.name}/{label}"
            while label in scheds:
                label += "'"
            scheds[label] = read_schedule(s)
        try:
            page = write_report(inst, scheds, out, title=ns.title or None, overwrite=ns.overwrite,
                                reference=ns.reference or None)
        except InputError as exc:  # the label is the file's stem: name the file the user gave
            named = next((p for p, lab in zip(schedules, scheds) if lab == exc.file), exc.file)
            raise InputError(named, exc.message) from None
        return f"{page}: {len(scheds)} schedule(s) of {inst.name} ({page.stat().st_size / 1e6:.1f} MB)"

    # ------------------------------------------------------------------ the command line
    def generator_config(self, gen: Generator, ns: argparse.Namespace) -> Any:
        """The family's settings first, then every flag given."""
        from eosp.args import config_from_args
        from eosp.config import InstanceConfig, family_config

        return config_from_args(InstanceConfig, ns, base=family_config(getattr(ns, "family", "uniform"), 100, 0))

    def import_paths(self, ns: argparse.Namespace) -> list[str]:
        return ns.instance_dirs

    def import_options(self, ns: argparse.Namespace) -> dict:
        return {"pruned_only": ns.pruned_only}

    def schedule_out(self, out: str, overwrite: bool) -> Path:
        from eosp.instances.schedule import check_schedule_out

        return check_schedule_out(out, overwrite)

    def before_read(self, solver: str, cfg: Any) -> None:
        from eosp.models.pretrained import PREFIX, pretrained_dir

        ck = getattr(cfg, "checkpoint", "") or ""
        if ck.startswith(PREFIX):
            pretrained_dir(ck[len(PREFIX):])  # a shipped model by name: refused in one line if there is none
        elif ck and not Path(ck).exists():
            raise InputError(ck, "checkpoint not found")

    def before_solve(self, problem: Any, path: str) -> None:
        """A one-line InputError when solving the instance cannot fit (estimated from its arcs and nodes)."""
        from eosp.memory import require_memory

        inst = problem
        arcs = inst.unpruned_graph.n_arcs if inst.unpruned_graph is not None else inst.pruned().n_arcs
        require_memory(path, SOLVE_BYTES_PER_ARC * arcs + SOLVE_BYTES_PER_NODE * inst.n_nodes,
                       f"solving {inst.n_acq:,} acquisitions ({inst.n_nodes:,} nodes, {arcs:,} arcs)")

    def incumbent(self, problem: Any) -> Any | None:
        from eosp.instances.schedule import from_internal_nodes
        from eosp.solvers.base import INCUMBENT

        nodes = INCUMBENT.take(problem)
        return None if nodes is None else from_internal_nodes(problem, nodes)

    def solved(self, out: Path, solver: str, cfg: Any, res: Result, seconds: float) -> tuple[dict, str]:
        extra = "".join(f", {k} {v}" for k, v in res.info.items() if k in ("bound", "gap", "status"))
        n, value = len(res.schedule), res.verdict.metrics["value"]
        if cfg.mode == "unitary":  # the objective is the count; the utility sum is shown for reference
            said = f"value {n} (acquisitions, unitary), utility sum {value:.6f}"
        else:
            said = f"{n} acquisitions, value {value:.6f}"
        return {}, f"{out}: {solver}, {said}{extra} ({seconds:.2f} s)"

    def arguments(self, command: str, p: argparse.ArgumentParser, solver: str | None) -> None:
        from eosp.args import add_config_args, add_memory_arg
        from eosp.config import InstanceConfig

        if command == "generate":
            p.add_argument("out", help="instance directory to create")
            p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
            add_memory_arg(p)
            add_config_args(p, InstanceConfig)
        elif command == "import":
            p.add_argument("instance_dirs", nargs="+")
            p.add_argument("--out", required=True, help="shard file to write")
            p.add_argument("--pruned-only", action="store_true", help="do not store the unpruned arcs")
            p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
            add_memory_arg(p)
        elif command == "export":
            p.add_argument("shard")
            p.add_argument("--index", type=int, default=0)
            p.add_argument("--out", required=True)
            p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
            add_memory_arg(p)
        elif command == "info":
            p.add_argument("problem", metavar="instance")
            add_memory_arg(p)
        elif command == "validate":
            p.add_argument("problem", metavar="instance_dir")
            p.add_argument("schedule")
            add_memory_arg(p)
        elif command == "solve":
            p.epilog = "Each solver has its own options: eosp solve --solver NAME --help lists them."
            p.add_argument("problem", metavar="instance_dir", help="instance directory (or SHARD#INDEX)")
            p.add_argument("--solver", required=True, help=SOLVER_NAMES)
            p.add_argument("--out", required=True, help="schedule file (.parquet, or .jsonl)")
            p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
            add_memory_arg(p)
            if solver is not None:
                add_config_args(p, self.solver_config(solver))
        elif command == "plot":
            p.add_argument("problem", metavar="instance_dir")
            p.add_argument("schedules", nargs="+")
            p.add_argument("--out", required=True, help="output path without extension (PNG and SVG are written)")
            p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
            add_memory_arg(p)
        elif command == "report":
            p.add_argument("problem", metavar="instance_dir", help="instance directory (or SHARD#INDEX)")
            p.add_argument("schedules", nargs="+",
                           help="schedule files (.parquet or .jsonl); infeasible ones are drawn too")
            p.add_argument("--out", required=True, help="HTML file to write")
            p.add_argument("--title", default="", help="page title (default: the instance name)")
            p.add_argument("--reference", default="", help="the schedule (its label: the file name without suffix) "
                                                           "the others are compared with and whose missed acquisitions "
                                                           "are explained (default: the best feasible one)")
            p.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
            add_memory_arg(p)


SOLVE_BYTES_PER_ARC = 24  # the solvers' copies of the graph (pruning, the polisher's and the environment's arrays)
SOLVE_BYTES_PER_NODE = 512

KIND = SinglePass()
