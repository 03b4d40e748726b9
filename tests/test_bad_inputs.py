"""Bad inputs across every subcommand, as a new user would give them.

A table of cases (every Parquet file of an instance, a shard and a schedule, each
corrupted in every way: dropped or renamed column, wrong type, NaN/inf, ids out of
range, truncated bytes; plus bad paths and options) run in-process through
``eosp.cli.main``; then hypothesis varies the corruptions.  Every bad input must give
exit 2, one line naming the file (and the column when there is one), no traceback,
and leave nothing behind.  ``python tests/test_bad_inputs.py`` prints the counts that
docs/formats.md reports.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.conftest import generated  # noqa: E402

FILES = {"acquisitions.parquet": {"int": ["acq"], "float": ["duration", "vtw_start", "vtw_end", "utility"],
                                  "ids": ["acq"], "optional": ["priority", "lat", "lon"]},
         "nodes.parquet": {"int": ["node", "acq"], "float": ["time"], "ids": ["node", "acq"], "optional": []},
         "arcs.parquet": {"int": ["src", "dst"], "float": [], "ids": ["src", "dst"], "optional": []}}
SCHEDULE = {"int": ["acq", "node"], "float": ["start"], "ids": ["acq", "node"]}
KINDS = ("drop", "rename", "dtype", "nan", "inf", "id_range", "truncate")


# --------------------------------------------------------------------------- the pristine inputs

def make_base(root: Path) -> Path:
    """An instance directory, a shard of it and a feasible schedule (Parquet and JSON lines) under `root`."""
    from eosp.instances.interchange import write_instance
    from eosp.instances.schedule import from_internal_nodes, write_schedule
    from eosp.shards.io import write_shard
    from eosp.solvers.base import run_solver

    inst = generated("uniform", 12, 0, 2.0)
    write_instance(inst, root / "inst")
    write_shard(root / "shard.parquet", [inst])
    sched = from_internal_nodes(inst, run_solver("greedy", inst, mode="utility").nodes)
    assert len(sched) >= 2
    write_schedule(sched, root / "sched.parquet")
    write_schedule(sched, root / "sched.jsonl")
    return root


# --------------------------------------------------------------------------- corruptions

def corrupt_table(t: pa.Table, kind: str, col: str, row: int, value: float | int | None = None) -> pa.Table:
    i = t.column_names.index(col)
    if kind == "drop":
        return t.remove_column(i)
    if kind == "rename":
        return t.rename_columns([("bogus_" + c) if c == col else c for c in t.column_names])
    if kind == "dtype":
        return t.set_column(i, col, pa.array([str(x) for x in t.column(col).to_pylist()]))
    arr = t.column(col).to_numpy().copy()
    if kind in ("nan", "inf"):
        arr = arr.astype(np.float64)
        arr[row % len(arr)] = np.nan if kind == "nan" else (value if value is not None else np.inf)
        return t.set_column(i, col, pa.array(arr, pa.float64()))
    if kind == "id_range":
        arr = arr.astype(np.int64)
        arr[row % len(arr)] = value if value is not None else len(arr) + 7
        return t.set_column(i, col, pa.array(arr, t.schema.field(col).type if -2**31 <= arr.min() and arr.max()
                                             < 2**31 else pa.int64()))
    raise ValueError(kind)


def corrupt_file(path: Path, kind: str, col: str, row: int = 0, value=None, cut: float = 0.5) -> None:
    if kind == "truncate":
        data = path.read_bytes()
        path.write_bytes(data[:int(len(data) * cut)])
        return
    if path.suffix == ".jsonl":
        lines = [json.loads(x) for x in path.read_text().splitlines()]
        r = lines[row % len(lines)]
        if kind == "drop":
            del r[col]
        elif kind == "rename":
            r["bogus_" + col] = r.pop(col)
        elif kind == "dtype":
            r[col] = str(r[col])
        elif kind in ("nan", "inf"):
            r[col] = float("nan") if kind == "nan" else float("inf")
        elif kind == "id_range":
            r[col] = value if value is not None else -1
        path.write_text("".join(json.dumps(x) + "\n" for x in lines))
        return
    pq.write_table(corrupt_table(pq.read_table(path), kind, col, row, value), path)


def corrupt_shard(path: Path, kind: str, col: str, row: int = 0, value=None, cut: float = 0.5) -> None:
    if kind == "truncate":
        data = path.read_bytes()
        path.write_bytes(data[:int(len(data) * cut)])
        return
    t = pq.read_table(path)
    meta = t.schema.metadata
    i = t.column_names.index(col)
    if kind == "drop":
        t = t.remove_column(i)
    elif kind == "rename":
        t = t.rename_columns([("bogus_" + c) if c == col else c for c in t.column_names])
    elif kind == "dtype":
        t = t.set_column(i, col, pa.array([str(x) for x in t.column(col).to_pylist()]))
    else:
        typ = t.schema.field(col).type
        lists = t.column(col).to_pylist()
        vals = lists[0]
        if kind in ("nan", "inf"):
            vals[row % len(vals)] = float("nan") if kind == "nan" else float("inf")
        else:  # id_range
            vals[row % len(vals)] = value if value is not None else 10**6
        t = t.set_column(i, col, pa.array([vals], typ))
    pq.write_table(t.replace_schema_metadata(meta), path)


# --------------------------------------------------------------------------- running the CLI in-process

@dataclass
class Outcome:
    rc: int
    out: str
    err: str


def run_cli(argv: list[str]) -> Outcome:
    from eosp.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse
            rc = exc.code if isinstance(exc.code, int) else 2
        except Exception as exc:  # noqa: BLE001 - a traceback is exactly what we look for
            import traceback

            traceback.print_exc(file=err)
            rc = f"exception {type(exc).__name__}"
    return Outcome(rc, out.getvalue(), err.getvalue())


def listing(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")}


@dataclass
class Case:
    name: str
    setup: Callable[[Path], list]  # corrupts the copy under the folder given, returns argv
    names: tuple[str, ...] = ()  # what the one line must name (file, column, row)
    rc: int = 2
    tags: list = field(default_factory=list)


def clean_error(case: Case, root: Path) -> tuple[bool, str]:
    """Run `case` on a fresh copy of the inputs in `root`; (clean, why not)."""
    argv = case.setup(root)
    before = listing(root)
    res = run_cli(argv)
    after = listing(root)
    lines = [x for x in res.err.strip().splitlines() if x.strip()]
    errors = [x for x in lines if "error" in x]
    problems = []
    if res.rc != case.rc:
        problems.append(f"exit {res.rc}, expected {case.rc}")
    if "Traceback" in res.err:
        problems.append("traceback")
    if case.rc == 2:
        # one line; argparse adds its usage line above its one error line
        if len(errors) != 1 or (len(lines) > 1 and not lines[0].startswith("usage:")):
            problems.append(f"not one error line: {lines!r}")
        for s in case.names:
            if s not in res.err:
                problems.append(f"does not name {s!r}: {res.err.strip()!r}")
    new = set(after) - set(before)
    changed = {k for k in before if k in after and after[k] != before[k]}
    if case.rc == 2 and (new or changed or set(before) - set(after)):
        problems.append(f"touched files: new {sorted(new)}, changed {sorted(changed)}")
    return not problems, "; ".join(problems) + f" [{res.err.strip()[-300:]}]"


# --------------------------------------------------------------------------- the table

def file_cases() -> list[Case]:
    """Every Parquet file of the instance, every corruption, every subcommand that reads it."""
    cases = []
    for fname, spec in FILES.items():
        for kind in KINDS:
            cols = {"drop": spec["int"][:1] + spec["float"][:1], "rename": spec["int"][:1],
                    "dtype": spec["int"] + spec["float"][:1], "nan": spec["float"] + spec["int"][:1],
                    "inf": spec["float"], "id_range": spec["ids"], "truncate": [spec["int"][0]]}[kind]
            for col in cols:
                for cmd in ("validate", "solve", "info", "import"):
                    def setup(root, fname=fname, kind=kind, col=col, cmd=cmd):
                        corrupt_file(root / "inst" / fname, kind, col, row=3)
                        return {"validate": ["validate", root / "inst", root / "sched.parquet"],
                                "solve": ["solve", root / "inst", "--solver", "greedy", "--out", root / "o.parquet"],
                                "info": ["info", root / "inst"],
                                "import": ["import", root / "inst", "--out", root / "o.parquet"]}[cmd]
                    names = (fname,) if kind == "truncate" else (fname, col)
                    cases.append(Case(f"{cmd}-{fname}-{kind}-{col}", setup, names))
    for kind in KINDS:  # schedules, Parquet and JSON lines
        for ext in ("parquet", "jsonl"):
            cols = SCHEDULE["ids"] if kind == "id_range" else (["start"] if kind in ("nan", "inf") else ["acq"])
            for col in cols:
                def setup(root, kind=kind, ext=ext, col=col):
                    corrupt_file(root / f"sched.{ext}", kind, col, row=1, value=-1 if kind == "id_range" else None)
                    return ["validate", root / "inst", root / f"sched.{ext}"]
                names = (f"sched.{ext}",) if kind == "truncate" or ext == "jsonl" and kind in ("drop", "rename") \
                    else (f"sched.{ext}", col)
                if kind == "truncate" and ext == "jsonl":
                    continue  # a cut JSON line is caught, but a cut at a line end is a valid shorter schedule
                cases.append(Case(f"validate-sched.{ext}-{kind}-{col}", setup, names))
    shard_cols = {"drop": ["utility", "node_time"], "rename": ["arc_dst"], "dtype": ["n_acq", "duration"],
                  "nan": ["utility", "node_time", "vtw_start"], "inf": ["duration"],
                  "id_range": ["node_acq", "pruned_dst", "arc_dst"], "truncate": ["name"]}
    for kind, cols in shard_cols.items():
        for col in cols:
            for cmd in ("info", "export", "solve"):
                def setup(root, kind=kind, col=col, cmd=cmd):
                    corrupt_shard(root / "shard.parquet", kind, col, row=2)
                    s = f"{root / 'shard.parquet'}#0"
                    return {"info": ["info", s], "export": ["export", root / "shard.parquet", "--out", root / "o"],
                            "solve": ["solve", s, "--solver", "greedy", "--out", root / "o.parquet"]}[cmd]
                names = ("shard.parquet",) if kind == "truncate" else ("shard.parquet", col)
                cases.append(Case(f"{cmd}-shard-{kind}-{col}", setup, names))
    return cases


def _big_utilities(root):
    t = pq.read_table(root / "inst" / "acquisitions.parquet")
    pq.write_table(t.set_column(t.column_names.index("utility"), "utility",
                                pa.array(np.full(t.num_rows, 1e308))), root / "inst" / "acquisitions.parquet")


def _no_arc_from_source(root):
    nodes = pq.read_table(root / "inst" / "nodes.parquet")
    src_id = int(nodes.column("node").to_numpy()[nodes.column("acq").to_numpy() == -1][0])
    arcs = pq.read_table(root / "inst" / "arcs.parquet")
    a = nodes.column("acq").to_numpy()[np.argsort(nodes.column("node").to_numpy())]
    src, dst = arcs.column("src").to_numpy(), arcs.column("dst").to_numpy()
    keep = ~((src == src_id) & (a[dst] == a[dst[src == src_id][0]]))
    pq.write_table(arcs.filter(pa.array(keep)), root / "inst" / "arcs.parquet")


def _user_dir(root):
    (root / "mine").mkdir()
    (root / "mine" / "thesis.tex").write_text("precious")
    return root / "mine"


def path_cases() -> list[Case]:
    """Bad paths and options (the classes of issue 15)."""
    I, S = "inst", "sched.parquet"  # noqa: N806
    c = [
        Case("export-overwrite-user-dir", lambda r: ["export", r / "shard.parquet", "--out", _user_dir(r),
                                                     "--overwrite"], ("mine", "not a instance directory")),
        Case("export-overwrite-file", lambda r: (r / "f.txt").write_text("x") and
             ["export", r / "shard.parquet", "--out", r / "f.txt", "--overwrite"], ("f.txt", "not a directory")),
        Case("export-exists", lambda r: ["export", r / "shard.parquet", "--out", r / I], ("inst", "already exists")),
        Case("generate-overwrite-user-dir", lambda r: ["generate", _user_dir(r), "--overwrite", "--n-acquisitions",
                                                       "5"], ("mine",)),
        Case("generate-n0", lambda r: ["generate", r / "g", "--n-acquisitions", "0"], ("--n-acquisitions",)),
        Case("generate-nan", lambda r: ["generate", r / "g", "--orbit.altitude-km", "nan"], ("altitude-km",)),
        Case("validate-overflow", lambda r: _big_utilities(r) or ["validate", r / I, r / S],
             ("acquisitions.parquet", "utility")),
        Case("solve-overflow", lambda r: _big_utilities(r) or ["solve", r / I, "--solver", "greedy", "--out",
                                                                r / "o.parquet"], ("acquisitions.parquet", "utility")),
        Case("solve-out-dir", lambda r: (r / "d").mkdir() or ["solve", r / I, "--solver", "greedy", "--out", r / "d"],
             ("is a directory",)),
        Case("import-out-dir", lambda r: (r / "d").mkdir() or ["import", r / I, "--out", r / "d"],
             ("is a directory",)),
        Case("import-out-foreign", lambda r: ["import", r / I, "--out", r / S], ("sched.parquet", "not a shard")),
        Case("import-out-csv", lambda r: ["import", r / I, "--out", r / "o.csv"], ("o.csv", "extension")),
        Case("import-twice", lambda r: ["import", r / I, r / I, "--out", r / "o.parquet"], ("inst", "already given")),
        Case("solve-out-csv", lambda r: ["solve", r / I, "--solver", "greedy", "--out", r / "o.csv"],
             ("o.csv", "extension")),
        Case("solve-out-parent-file", lambda r: ["solve", r / I, "--solver", "greedy", "--out",
                                                 r / S / "o.parquet"], ("is a file",)),
        Case("validate-sched-csv", lambda r: (r / "s.csv").write_text("acq,node,start\n") and
             ["validate", r / I, r / "s.csv"], ("s.csv", "extension")),
        Case("validate-sched-dir", lambda r: (r / "sd").mkdir() or ["validate", r / I, r / "sd"],
             ("sd", "is a directory")),
        Case("validate-sched-missing", lambda r: ["validate", r / I, r / "nope.parquet"], ("nope.parquet",)),
        Case("validate-inst-missing", lambda r: ["validate", r / "nope", r / S], ("nope",)),
        Case("solve-no-source-arc", lambda r: _no_arc_from_source(r) or ["solve", r / I, "--solver", "greedy",
                                                                          "--out", r / "o.parquet"],
             ("arcs.parquet", "source")),
        Case("solve-time-limit-neg", lambda r: ["solve", r / I, "--solver", "ramp", "--time-limit", "-1", "--out",
                                                r / "o.parquet"], ("--time-limit",)),
        Case("solve-time-limit-nan", lambda r: ["solve", r / I, "--solver", "ramp", "--time-limit", "nan", "--out",
                                                r / "o.parquet"], ("--time-limit", "finite")),
        Case("solve-time-limit-inf", lambda r: ["solve", r / I, "--solver", "ramp", "--time-limit", "inf", "--out",
                                                r / "o.parquet"], ("--time-limit",)),
        Case("solve-budget-neg", lambda r: ["solve", r / I, "--solver", "mcts", "--budget", "-5", "--out",
                                            r / "o.parquet"], ("--budget",)),
        Case("solve-mode", lambda r: ["solve", r / I, "--solver", "greedy", "--mode", "fast", "--out",
                                      r / "o.parquet"], ("--mode",)),
        Case("solve-checkpoint-file", lambda r: ["solve", r / I, "--solver", "policy", "--checkpoint", r / S,
                                                 "--out", r / "o.parquet"], ("sched.parquet",)),
        Case("solve-checkpoint-missing", lambda r: ["solve", r / I, "--solver", "policy", "--checkpoint",
                                                    r / "ck", "--out", r / "o.parquet"], ("ck", "not found")),
        Case("solve-unknown-solver", lambda r: ["solve", r / I, "--solver", "nope", "--out", r / "o.parquet"],
             ("nope",)),
        Case("info-shard-abc", lambda r: ["info", f"{r / 'shard.parquet'}#abc"], ("#abc", "INDEX")),
        Case("info-shard-index", lambda r: ["info", f"{r / 'shard.parquet'}#9"], ("shard.parquet", "9")),
        Case("info-shard-neg", lambda r: ["info", f"{r / 'shard.parquet'}#-1"], ("#-1",)),
        Case("export-index", lambda r: ["export", r / "shard.parquet", "--index", "5", "--out", r / "o"],
             ("shard.parquet",)),
        Case("info-foreign-parquet", lambda r: ["info", f"{r / S}#0"], ("sched.parquet", "not an EOSP shard")),
        Case("report-out-txt", lambda r: ["report", r / I, r / S, "--out", r / "o.txt"], ("o.txt", "extension")),
        Case("report-out-dir", lambda r: (r / "d.html").mkdir() or ["report", r / I, r / S, "--out", r / "d.html"],
             ("is a directory",)),
        Case("report-sched-nan", lambda r: corrupt_file(r / S, "nan", "start", 0) or
             ["report", r / I, r / S, "--out", r / "o.html"], ("sched.parquet", "start", "row 0")),
        Case("plot-out-dir", lambda r: (r / "p.png").mkdir() or ["plot", r / I, r / S, "--out", r / "p"],
             ("is a directory",)),
        Case("plot-sched-csv", lambda r: (r / "s.csv").write_text("") or ["plot", r / I, r / "s.csv", "--out",
                                                                          r / "p"], ("s.csv",)),
        Case("meta-json-bad", lambda r: (r / I / "meta.json").write_text("{oops") and
             ["info", r / I], ("meta.json", "JSON")),
    ]
    return c


CASES = file_cases() + path_cases()


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return make_base(tmp_path_factory.mktemp("base"))


def fresh(base: Path, tmp: Path) -> Path:
    root = tmp / "w"
    shutil.copytree(base, root)
    return root


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_bad_input(case, base, tmp_path):
    ok, why = clean_error(case, fresh(base, tmp_path))
    assert ok, why


def test_good_inputs_still_work(base, tmp_path):
    """The controls: the pristine inputs pass, and --overwrite replaces what eosp wrote."""
    r = fresh(base, tmp_path)
    assert run_cli(["validate", r / "inst", r / "sched.parquet"]).rc == 0
    assert run_cli(["validate", r / "inst", r / "sched.jsonl"]).rc == 0
    assert run_cli(["export", r / "shard.parquet", "--out", r / "inst", "--overwrite"]).rc == 0
    assert run_cli(["import", r / "inst", "--out", r / "shard.parquet"]).rc == 0  # replaces our own shard
    res = run_cli(["solve", f"{r / 'shard.parquet'}#0", "--solver", "ramp", "--time-limit", "5", "--out",
                   r / "o.jsonl"])
    assert res.rc == 0, res.err
    # shuffled rows are a valid file (ids, not positions, matter)
    t = pq.read_table(r / "inst" / "acquisitions.parquet")
    pq.write_table(t.take(pa.array(np.random.default_rng(0).permutation(t.num_rows))),
                   r / "inst" / "acquisitions.parquet")
    assert run_cli(["validate", r / "inst", r / "sched.parquet"]).rc == 0


def test_outputs_follow_the_umask(base, tmp_path):
    r = fresh(base, tmp_path)
    old = os.umask(0o002)
    try:
        assert run_cli(["export", r / "shard.parquet", "--out", r / "e"]).rc == 0
        assert run_cli(["import", r / "e", "--out", r / "s2.parquet"]).rc == 0
        assert run_cli(["solve", r / "e", "--solver", "greedy", "--out", r / "o.parquet"]).rc == 0
    finally:
        os.umask(old)
    assert (r / "e").stat().st_mode & 0o777 == 0o775
    assert {(p.stat().st_mode & 0o777) for p in (r / "e").iterdir()} == {0o664}
    assert (r / "s2.parquet").stat().st_mode & 0o777 == 0o664
    assert (r / "o.parquet").stat().st_mode & 0o777 == 0o664


def test_broken_pipe_is_quiet(base, tmp_path):
    import subprocess

    r = subprocess.run(f"'{sys.executable}' -m eosp.cli info '{base / 'inst'}' | head -c 10", shell=True,
                       capture_output=True, text=True, timeout=120)
    assert len(r.stdout) == 10 and r.stderr == "", r.stderr


# --------------------------------------------------------------------------- hypothesis: varied corruptions

HSET = settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                       HealthCheck.too_slow])


@HSET
@given(fname=st.sampled_from(sorted(FILES)), kind=st.sampled_from(KINDS), row=st.integers(0, 400),
       cut=st.floats(0.0, 0.98), big=st.sampled_from([-1, -2**31, 2**31 + 5, 10**6]),
       inf=st.sampled_from([np.inf, -np.inf, 1e309]), cmd=st.sampled_from(["validate", "solve", "info", "import"]),
       pick=st.integers(0, 10))
def test_hypothesis_instance_corruption(base, tmp_path_factory, fname, kind, row, cut, big, inf, cmd, pick):
    spec = FILES[fname]
    cols = {"drop": spec["int"] + spec["float"], "rename": spec["int"] + spec["float"],
            "dtype": spec["int"] + spec["float"], "nan": spec["float"] + spec["int"], "inf": spec["float"] or None,
            "id_range": spec["ids"], "truncate": [spec["int"][0]]}[kind]
    if not cols:
        return
    col = cols[pick % len(cols)]
    root = fresh(base, tmp_path_factory.mktemp("h"))

    def setup(r):
        value = big if kind == "id_range" else (inf if kind == "inf" else None)
        corrupt_file(r / "inst" / fname, kind, col, row=row, value=value, cut=cut)
        return {"validate": ["validate", r / "inst", r / "sched.parquet"],
                "solve": ["solve", r / "inst", "--solver", "greedy", "--out", r / "o.parquet"],
                "info": ["info", r / "inst"], "import": ["import", r / "inst", "--out", r / "o.parquet"]}[cmd]
    ok, why = clean_error(Case("h", setup, (fname,)), root)
    assert ok, why


@HSET
@given(ext=st.sampled_from(["parquet", "jsonl"]), kind=st.sampled_from(KINDS), col=st.sampled_from(["acq", "node",
                                                                                                   "start"]),
       row=st.integers(0, 50), cut=st.floats(0.05, 0.95), big=st.sampled_from([-1, -2**40, 2**31, 2**63 - 1]))
def test_hypothesis_schedule_corruption(base, tmp_path_factory, ext, kind, col, row, cut, big):
    root = fresh(base, tmp_path_factory.mktemp("h"))
    if kind in ("nan", "inf"):
        col = "start"
    if kind == "id_range" and col == "start":
        col = "acq"

    def setup(r):
        corrupt_file(r / f"sched.{ext}", kind, col, row=row, value=big if kind == "id_range" else None, cut=cut)
        return ["validate", r / "inst", r / f"sched.{ext}"]
    res_case = Case("h", setup, (f"sched.{ext}",))
    if kind == "truncate" and ext == "jsonl":
        # a cut JSON-lines file may be a valid shorter schedule: any verdict, but never a traceback
        argv = setup(root)
        out = run_cli(argv)
        assert out.rc in (0, 1, 2) and "Traceback" not in out.err
        return
    ok, why = clean_error(res_case, root)
    assert ok, why


def count() -> tuple[int, int, list[str]]:
    """(bad inputs tried, clean errors, the names of the others) over the table."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        base_dir = make_base(Path(d) / "base")
        bad = []
        for k, case in enumerate(CASES):
            ok, why = clean_error(case, fresh(base_dir, Path(d) / f"c{k}"))
            if not ok:
                bad.append(f"{case.name}: {why}")
            shutil.rmtree(Path(d) / f"c{k}")
    return len(CASES), len(CASES) - len(bad), bad


if __name__ == "__main__":
    n, clean, bad = count()
    print(f"{n} bad inputs tried, {clean} give a clean error (exit 2, one line naming file/column/row, "
          f"nothing written)")
    for b in bad:
        print("  not clean:", b)
