"""The command line on fleets: import, info, solve (greedy and fleet), validate, export; bad input is one line."""

import json
import shutil
from pathlib import Path

import pytest

from eosp.cli import main

FIXTURES = Path(__file__).parent / "fixtures" / "aeossp"


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet")
    assert main(["import", str(FIXTURES / "duplicate_observation_no_bonus_valid"), "--out", str(d / "fl")]) == 0
    return d / "fl"


def test_solve_validate_export(fleet_dir, tmp_path, capsys):
    out = tmp_path / "s.parquet"
    assert main(["solve", str(fleet_dir), "--solver", "fleet", "--rounds", "2", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "WCR 1.000000, bound 1.000000" in said and "gap 0.0000%" in said
    assert main(["validate", str(fleet_dir), str(out)]) == 0
    assert capsys.readouterr().out.startswith("valid: WCR 1.0")
    sol = tmp_path / "solution.json"
    assert main(["export-schedule", str(fleet_dir), str(out), "--format", "aeossp", "--out", str(sol)]) == 0
    assert len(json.loads(sol.read_text())["actions"]) == 1
    # re-planning from it, with its first pass kept
    again = tmp_path / "again.parquet"
    assert main(["solve", str(fleet_dir), "--solver", "fleet", "--rounds", "1", "--init", str(out),
                 "--freeze-until", "2025-07-17T04:15:00Z", "--out", str(again)]) == 0
    # a second write of the same path needs --overwrite
    capsys.readouterr()
    assert main(["solve", str(fleet_dir), "--solver", "greedy", "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(["solve", str(fleet_dir), "--solver", "greedy", "--out", str(out), "--overwrite"]) == 0


def test_a_first_schedule_after_the_limit_says_why(fleet_dir, tmp_path, capsys):
    """A limit shorter than the first schedule: the line says when it came and where the time went (compiling kernels
    not yet cached, building the pass graphs, reading)."""
    import re

    from eosp.cli.solve import CompileClock
    from eosp.kinds.fleet.kind import late_because
    from eosp.problem import Result

    out = tmp_path / "s.parquet"
    assert main(["solve", str(fleet_dir), "--solver", "fleet", "--time-limit", "0.0001", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert re.search(r"\(the first schedule, found after the time limit at [\d.]+ s: [\d.]+ s of it compiling "
                     r"kernels[^,]*, [\d.]+ s building the pass graphs; reading took [\d.]+ s before\)", said), said
    r = Result(None, 0.0, timings={"compile": 12.3, "build": 0.5, "read": 2.0}, info={"first_schedule_s": 14.0})
    assert late_because(r) == ("12.3 s of it compiling kernels (python -m eosp.cli.warmup compiles them once), 0.5 s building "
                               "the pass graphs; reading took 2.0 s before")
    import numba

    @numba.njit
    def fresh(x):  # not cached: compiled in the block
        return x + 1

    with CompileClock() as c:
        fresh(1)
    assert c.seconds > 0


@pytest.mark.parametrize("args,why", [
    (["--time-limit", "0"], "--time-limit"),
    (["--time-limit", "1e9"], "--time-limit"),
    (["--rounds", "0"], "--rounds"),
    (["--pass-solver", "bogus"], "--pass-solver"),
    (["--pass-solver", "policy"], "--pass-solver"),
    (["--freeze-until", "2030-01-01T00:00:00Z", "--init", "X"], "--freeze-until"),
    (["--workers", "256"], "more than this machine's"),
])
def test_bad_fleet_solve_options_are_one_line(fleet_dir, tmp_path, capsys, args, why):
    init = tmp_path / "s.parquet"
    assert main(["solve", str(fleet_dir), "--solver", "greedy", "--out", str(init)]) == 0
    capsys.readouterr()
    args = [str(init) if a == "X" else a for a in args]
    with pytest.raises(SystemExit) as e:
        code = main(["solve", str(fleet_dir), "--solver", "fleet", "--out", str(tmp_path / "o.parquet"), *args])
        raise SystemExit(code)
    err = capsys.readouterr().err.strip()
    assert e.value.code == 2 and err.count("\n") == 0 and why in err and "Traceback" not in err
    assert not (tmp_path / "o.parquet").exists()


def test_init_of_another_fleet_is_refused(fleet_dir, tmp_path, capsys):
    other = tmp_path / "other"
    assert main(["import", str(FIXTURES / "full_completion_valid"), "--out", str(other)]) == 0
    s = tmp_path / "s.parquet"
    assert main(["solve", str(other), "--solver", "greedy", "--out", str(s)]) == 0
    capsys.readouterr()
    assert main(["solve", str(fleet_dir), "--solver", "fleet", "--rounds", "1", "--init", str(s),
                 "--out", str(tmp_path / "o.parquet")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(s) in err
    shutil.rmtree(other)
