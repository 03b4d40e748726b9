"""The README's command-line block runs as written (small sizes), so that it cannot go stale.

Substitutions: ``--n-acquisitions 20``, ``--time-limit 2``, ``--n-instances 2``; the TLE file is written by
the test; ``runs/demo/checkpoints/best`` (the demo's agent) is a copy of the shipped model.
"""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def readme_block(heading: str) -> list[str]:
    """The command lines of the first ```bash block after `heading` (comments stripped)."""
    text = (ROOT / "README.md").read_text()
    section = text[text.index(heading):]
    block = section[section.index("```bash") + len("```bash"):]
    block = block[:block.index("```")]
    lines = [line.split("#", 1)[0].strip() for line in block.strip().splitlines()]
    return [line for line in lines if line]


def small(line: str) -> str:
    line = re.sub(r"--n-acquisitions \d+", "--n-acquisitions 20", line)
    line = re.sub(r"--time-limit \d+", "--time-limit 2", line)
    return re.sub(r"--n-instances \d+", "--n-instances 2", line)


def write_tle(path: Path) -> None:
    from sgp4.api import WGS72, Satrec
    from sgp4.exporter import export_tle

    sat = Satrec()  # a sun-synchronous orbit at ~690 km
    sat.sgp4init(WGS72, "i", 1, 27911.0, 0.0, 0.0, 0.0, 0.0001, 0.0, np.deg2rad(98.2), 0.0,
                 14.31 * 2 * np.pi / 1440.0, np.deg2rad(20.0))
    path.write_text("\n".join(export_tle(sat)) + "\n")


def test_the_readme_command_line_block_runs(tmp_path, monkeypatch, capsys):
    """Each line through ``eosp.cli.main`` in this process (torch and numba load once), except the lines that
    start Ray, which run as the user runs them, in a process of their own."""
    from eosp.cli import main

    lines = readme_block("## The command line: `eosp`")
    assert len(lines) >= 15 and all(line.startswith("eosp ") for line in lines)
    write_tle(tmp_path / "sat.tle")
    best = tmp_path / "runs" / "demo" / "checkpoints" / "best"
    shutil.copytree(ROOT / "models" / "pretrained-agents" / "utility", best)
    monkeypatch.chdir(tmp_path)
    for line in lines:
        args = small(line).split()[1:]
        if args[0] == "build-shards":
            r = subprocess.run([sys.executable, "-m", "eosp.cli", *args], cwd=tmp_path, capture_output=True,
                               text=True, timeout=300)
            assert r.returncode == 0, f"{line}\n{r.stdout}\n{r.stderr}"
            continue
        try:
            code = main(args)
        except SystemExit as exc:  # --help exits through argparse
            code = exc.code
        out = capsys.readouterr()
        assert code == 0, f"{line}\n{out.out}\n{out.err}"
    assert (tmp_path / "report.html").stat().st_size > 0 and (tmp_path / "again" / "meta.json").exists()


def test_the_readme_fleet_block_runs(tmp_path):
    """The fleet commands, on a verifier fixture (the case directory) with 2 s of search."""
    lines = readme_block("## Fleets")
    assert len(lines) >= 5 and all(line.startswith("eosp ") for line in lines)
    case = ROOT / "tests" / "fixtures" / "aeossp" / "duplicate_observation_no_bonus_valid"
    for line in lines:
        line = small(line).replace("CASE_DIR", str(case))
        line = re.sub(r"--freeze-until \S+", "--freeze-until 2025-07-17T04:15:00Z", line)
        r = subprocess.run([sys.executable, "-m", "eosp.cli", *line.split()[1:]], cwd=tmp_path, capture_output=True,
                           text=True, timeout=300)
        assert r.returncode == 0, f"{line}\n{r.stdout}\n{r.stderr}"
    assert (tmp_path / "solution.json").exists() and (tmp_path / "again.parquet").exists()
