"""Wall time of the command line as a user meets it: ``eosp --help`` and ``eosp solve --solver ramp`` on a
100-acquisition instance, end to end (process start, imports, reading, solving, writing).

The first solve of a fresh numba cache compiles the kernels; it is reported apart ("first call"), then the
median of the warm calls.  Targets on a quiet machine: --help <= 0.3 s, warm solve <= 1.5 s.

    python benchmarks/bench_cli.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def timed(args: list[str], env: dict) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "eosp.cli", *args], check=True, capture_output=True, env=env)
    return time.perf_counter() - t0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5, help="warm calls of each command")
    p.add_argument("--n-acquisitions", type=int, default=100)
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(tmp) / "numba")}  # a cold cache of its own
        inst = Path(tmp) / "inst"
        timed(["generate", str(inst), "--n-acquisitions", str(a.n_acquisitions), "--seed", "1"], env)
        def solve(i: int) -> list[str]:
            return ["solve", str(inst), "--solver", "ramp", "--out", str(Path(tmp) / f"s{i}.parquet")]

        first = timed(solve(0), env)
        warm = [timed(solve(i + 1), env) for i in range(a.repeats)]
        helps = [timed(["--help"], env) for _ in range(a.repeats)]
    print(f"eosp --help: median {statistics.median(helps):.2f} s (min {min(helps):.2f}, target <= 0.3 s)")
    print(f"eosp solve --solver ramp, {a.n_acquisitions} acquisitions: median {statistics.median(warm):.2f} s "
          f"(min {min(warm):.2f}, target <= 1.5 s); first call with a cold numba cache {first:.2f} s")


if __name__ == "__main__":
    main()
