"""The eosp command as users run it (subprocesses)."""

import dataclasses
import subprocess
import sys

import pyarrow as pa
import pyarrow.parquet as pq


def eosp(*args, check=True):
    r = subprocess.run([sys.executable, "-m", "eosp.cli", *map(str, args)], capture_output=True, text=True,
                       timeout=300)
    if check and r.returncode != 0:
        raise AssertionError(f"eosp {args} -> {r.returncode}\n{r.stdout}\n{r.stderr}")
    return r


def test_generate_solve_validate(tmp_path):
    inst = tmp_path / "inst"
    eosp("generate", inst, "--n-acquisitions", 15, "--seed", 4, "--graph.step-s", 2)
    eosp("solve", inst, "--solver", "random", "--out", tmp_path / "s.parquet", "--seed", 1)
    r = eosp("validate", inst, tmp_path / "s.parquet")
    assert r.stdout.startswith("feasible:") and "value" in r.stdout
    # a broken schedule: exit 1 and the reason
    t = pq.read_table(tmp_path / "s.parquet")
    start = t.column("start").to_numpy().copy()
    start[0] += 0.5
    pq.write_table(t.set_column(2, "start", pa.array(start)), tmp_path / "bad.parquet")
    r = eosp("validate", inst, tmp_path / "bad.parquet", check=False)
    assert r.returncode == 1 and "infeasible: row 0" in r.stdout


def test_bad_input_is_one_line_exit_2(tmp_path):
    inst = tmp_path / "inst"
    eosp("generate", inst, "--n-acquisitions", 8, "--seed", 1, "--graph.step-s", 4)
    (inst / "nodes.parquet").write_bytes(b"garbage")
    r = eosp("solve", inst, "--solver", "random", "--out", tmp_path / "s.parquet", check=False)
    assert r.returncode == 2
    assert "nodes.parquet" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "s.parquet").exists()


def test_import_export_info(tmp_path):
    inst = tmp_path / "inst"
    eosp("generate", inst, "--n-acquisitions", 10, "--seed", 2, "--graph.step-s", 4, "--family", "clusters")
    eosp("import", inst, "--out", tmp_path / "shard.parquet")
    eosp("export", tmp_path / "shard.parquet", "--index", 0, "--out", tmp_path / "again")
    for f in ("acquisitions.parquet", "nodes.parquet", "arcs.parquet"):
        assert pq.read_table(inst / f).equals(pq.read_table(tmp_path / "again" / f))
    r = eosp("info", f"{tmp_path / 'shard.parquet'}#0")
    assert '"acquisitions": 10' in r.stdout


def test_unknown_solver(tmp_path):
    inst = tmp_path / "inst"
    eosp("generate", inst, "--n-acquisitions", 5, "--seed", 2, "--graph.step-s", 4)
    r = eosp("solve", inst, "--solver", "nope", "--out", tmp_path / "x.parquet", check=False)
    assert r.returncode == 2 and "unknown solver" in r.stderr


def test_corrupt_arcs_row_group_is_one_line_exit_2(tmp_path):
    inst = tmp_path / "inst"
    eosp("generate", inst, "--n-acquisitions", 8, "--seed", 1, "--graph.step-s", 4)
    pq.write_table(pq.read_table(inst / "arcs.parquet"), inst / "arcs.parquet", row_group_size=50)
    cc = pq.ParquetFile(inst / "arcs.parquet").metadata.row_group(1).column(0)
    raw = bytearray((inst / "arcs.parquet").read_bytes())
    raw[cc.data_page_offset:cc.data_page_offset + cc.total_compressed_size] = b"\xff" * cc.total_compressed_size
    (inst / "arcs.parquet").write_bytes(bytes(raw))
    r = eosp("info", inst, check=False)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "arcs.parquet" in r.stderr and "row group 1" in r.stderr


@dataclasses.dataclass
class Percent:
    share: float = 0.5
    """Share of the time (50% by default; '%(prog)s' printed as is)."""


def test_every_config_renders_its_help_with_docstrings_as_written():
    """Field docstrings are the --help; argparse %-formats help strings, so a '%' in one must not break it."""
    import argparse
    import inspect

    import eosp.config as config
    from eosp.args import add_config_args

    classes = [c for _, c in inspect.getmembers(config, inspect.isclass)
               if dataclasses.is_dataclass(c) and c.__module__ == config.__name__]
    assert len(classes) >= 10
    for cls in [*classes, Percent]:
        p = argparse.ArgumentParser(prog="x")
        add_config_args(p, cls)
        text = p.format_help()
        assert all("--" + f.name.replace("_", "-") in text for f in dataclasses.fields(cls)), cls
    assert "50% by default; '%(prog)s' printed as is" in " ".join(text.split())


def test_every_job_prints_its_help():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    for job in ("build_shards", "build_demos", "pretrain", "train", "tune", "evaluate"):
        r = subprocess.run([sys.executable, str(root / "jobs" / f"{job}.py"), "--help"], capture_output=True,
                           text=True, timeout=120)
        assert r.returncode == 0 and "usage:" in r.stdout and not r.stderr.strip(), (job, r.stderr[-2000:])
        if job == "train":
            assert "--train.rollout-values" in r.stdout and "GAE's values come from" in r.stdout


def test_the_plain_commands_import_neither_torch_ray_nor_mlflow(tmp_path):
    """--help, info, validate, generate, import, export and the classical solvers start in a blink: one process
    runs them all, then reports which heavy packages it imported."""
    script = f"""
import contextlib, io, sys
from eosp.cli import main
d = {str(tmp_path)!r}
calls = [["generate", d + "/inst", "--n-acquisitions", "10", "--seed", "2"], ["info", d + "/inst"],
         ["import", d + "/inst", "--out", d + "/s.parquet"], ["export", d + "/s.parquet", "--out", d + "/again"]]
for solver in ("random", "greedy", "ramp", "exact", "lns"):
    extra = ["--time-limit", "1"] if solver in ("exact", "lns") else []
    calls += [["solve", d + "/inst", "--solver", solver, "--out", f"{{d}}/{{solver}}.parquet", *extra],
              ["validate", d + "/inst", f"{{d}}/{{solver}}.parquet"]]
with contextlib.redirect_stdout(io.StringIO()):
    for argv in calls:
        assert main(argv) == 0, argv
    try:
        main(["--help"])
    except SystemExit:
        pass
print(sorted(m for m in ("torch", "ray", "mlflow") if m in sys.modules))
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "[]", r.stdout
    r = eosp("solve", tmp_path / "inst", "--solver", "greedy", "--mode", "unitary", "--out", tmp_path / "u.parquet")
    n = len(pq.read_table(tmp_path / "u.parquet"))
    assert f"value {n} (acquisitions, unitary), utility sum" in r.stdout  # the count is the value
