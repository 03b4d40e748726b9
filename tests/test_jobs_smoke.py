"""One subprocess smoke run per jobs/ entry point, on tiny settings with a local Ray."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_job(script, *args, timeout=600):
    r = subprocess.run([sys.executable, str(ROOT / "jobs" / script), *map(str, args)], capture_output=True,
                       text=True, timeout=timeout, cwd=ROOT)
    assert r.returncode == 0, f"{script} failed\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    return r


def test_build_shards(tmp_path):
    out = tmp_path / "ds"
    r = run_job("build_shards.py", "--out", out, "--n-acquisitions", 10, "--n-instances", 3, "--per-shard", 2,
                "--seed", 5, "--ray.num-cpus", 2)
    assert "shard 2/2" in r.stdout
    manifest = json.loads((out / "manifest.json").read_text())
    assert [s["file"] for s in manifest["shards"]] == ["shard-00000.parquet", "shard-00001.parquet"]
    from shards.io import read_instances

    insts = read_instances(sorted(out.glob("*.parquet")))
    assert [i.meta["seed"] for i in insts] == [5, 6, 7]
