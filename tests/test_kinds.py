"""The problem-kind contract: a kind registered from this module runs through the command line untouched (info,
solve, validate), a path of no kind is refused naming every kind tried, and the three shipped kinds satisfy it."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pytest

from eosp import kinds
from eosp.cli import main
from eosp.config import apply_overrides, ranged
from eosp.kinds.base import KindBase
from eosp.problem import Detection, ProblemKind, Result, Solver, Verdict
from eosp.solvers.base import SolverConfig

HERE = "tests.test_kinds"


@dataclass
class FillConfig(SolverConfig):
    """Options of the toy solver."""

    limit: int = ranged(100, 0)
    """Items taken at most."""

    NAME = "fill"
    ONE_SHOT = True


def fill(problem: dict, cfg: FillConfig) -> Result:
    """Items by decreasing value while they fit in the capacity: a knapsack's greedy."""
    taken, load = [], 0.0
    for i in sorted(range(len(problem["values"])), key=lambda i: -problem["values"][i])[:cfg.limit]:
        if load + problem["weights"][i] <= problem["capacity"]:
            taken.append(i)
            load += problem["weights"][i]
    return Result(sorted(taken), float(sum(problem["values"][i] for i in taken)))


class Knapsack(KindBase):
    """A knapsack in a directory holding knapsack.json; a schedule is the JSON list of the items taken."""

    name = "toy-knapsack"
    title = "a knapsack directory (knapsack.json)"
    schedule_suffixes = (".json",)
    solvers = {"fill": Solver("fill", f"{HERE}:FillConfig", f"{HERE}:fill", "by value while it fits")}

    def detect(self, path: str) -> Detection:
        ok = (Path(path) / "knapsack.json").is_file()
        return Detection(ok, "a knapsack" if ok else "no knapsack.json in it")

    def read(self, path: str, solving: bool = True) -> dict:
        return json.loads((Path(path) / "knapsack.json").read_text())

    def read_schedule(self, path: str, problem: dict) -> list[int]:
        return json.loads(Path(path).read_text())

    def write_schedule(self, schedule, problem, path, overwrite=False, info=None) -> Path:
        Path(path).write_text(json.dumps(schedule))
        return Path(path)

    def check(self, problem: dict, schedule: list[int]) -> Verdict:
        load = sum(problem["weights"][i] for i in schedule)
        value = float(sum(problem["values"][i] for i in schedule))
        if load > problem["capacity"]:
            return Verdict(False, {"value": 0.0}, f"load {load} over the capacity", "invalid: over the capacity")
        return Verdict(True, {"value": value}, None, f"valid: value {value:g}")

    def describe(self, problem: dict, path: str) -> str:
        return f"{path}: {len(problem['values'])} items, capacity {problem['capacity']:g}"


@pytest.fixture
def knapsack(tmp_path):
    kinds.register(Knapsack())
    d = tmp_path / "k"
    d.mkdir()
    (d / "knapsack.json").write_text(json.dumps({"values": [5, 4, 3, 1], "weights": [4, 3, 2, 1], "capacity": 6}))
    yield d
    kinds.unregister("toy-knapsack")


def test_a_kind_registered_here_runs_through_the_command_line(knapsack, tmp_path, capsys):
    assert main(["info", str(knapsack)]) == 0
    assert capsys.readouterr().out.strip() == f"{knapsack}: 4 items, capacity 6"
    out = tmp_path / "s.json"
    assert main(["solve", str(knapsack), "--solver", "fill", "--out", str(out)]) == 0
    assert json.loads(out.read_text()) == [0, 2]  # 5 (weight 4), then 3 (weight 2): 4 and 1 no longer fit
    assert "value 8.000000" in capsys.readouterr().out
    assert main(["validate", str(knapsack), str(out)]) == 0
    assert capsys.readouterr().out.strip() == "valid: value 8"
    out.write_text("[0, 1]")
    assert main(["validate", str(knapsack), str(out)]) == 1
    # its solver's config is its command line, and the shared rules hold: a one-pass solver refuses a time limit
    assert main(["solve", str(knapsack), "--solver", "fill", "--limit", "1", "--out", str(tmp_path / "t.json")]) == 0
    assert json.loads((tmp_path / "t.json").read_text()) == [0]
    capsys.readouterr()
    assert main(["solve", str(knapsack), "--solver", "fill", "--time-limit", "3", "--out",
                 str(tmp_path / "u.json")]) == 2
    assert "takes no time_limit" in capsys.readouterr().err and not (tmp_path / "u.json").exists()
    assert main(["solve", str(knapsack), "--solver", "fill", "--beam", "3", "--out", str(tmp_path / "u.json")]) == 2
    assert "has no option --beam" in capsys.readouterr().err


def test_a_path_of_no_kind_names_every_kind_tried(knapsack, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    for command in (["info"], ["validate", "-"], ["solve", "--solver", "greedy", "--out", str(tmp_path / "o")]):
        argv = [command[0], str(tmp_path / "empty"), *command[1:]]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"eosp {command[0]}: error: {tmp_path / 'empty'}: ")
        for k in kinds.kinds():
            assert f"{k.name}: " in err
        assert "no knapsack.json" in err and "no acquisitions.parquet" in err


def test_the_shipped_kinds_satisfy_the_contract():
    names = {k.name for k in kinds.kinds()}
    assert {"single-pass", "fleet", "onera"} <= names
    for k in kinds.kinds():
        assert isinstance(k, ProblemKind)
        for s in k.solvers.values():
            assert issubclass(k.solver_config(s.name), SolverConfig)
        assert {"info", "validate", "solve"} <= k.commands


def test_time_limit_means_the_same_on_every_kind():
    """One meaning: one-pass constructions refuse it; the anytime searches need it or their deterministic budget."""
    from eosp.kinds.fleet.config import FleetConfig, GreedyConfig
    from eosp.kinds.onera.search import GreedyConfig as OneraGreedy
    from eosp.kinds.onera.search import OneraConfig

    for one_pass in (GreedyConfig, OneraGreedy):
        with pytest.raises(ValueError, match="takes no time_limit"):
            one_pass(time_limit=5.0)
    for anytime, budget in ((FleetConfig, "rounds"), (OneraConfig, "moves")):
        assert anytime().time_limit > 0  # a numeric default
        with pytest.raises(ValueError, match=f"--{budget}"):
            anytime(time_limit=None)
        assert anytime(time_limit=None, **{budget: 2}).time_limit is None
        cfg = apply_overrides(anytime(), {"time_limit": None})  # set one field at a time, as the jobs' flags are
        with pytest.raises(ValueError, match=f"--{budget}"):
            cfg.validate()  # what the solvers and the job check before any work
