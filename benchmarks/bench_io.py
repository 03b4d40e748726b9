"""Large instances: time and peak memory of generating, reading, importing and solving.

    nice -n 10 python benchmarks/bench_io.py --sizes 100 300 1000 1500 --work /tmp/bench_io
    nice -n 10 python benchmarks/bench_io.py --sizes 1500 3000 --heavy --work /tmp/bench_io

Every step runs as its own child process (the ``eosp`` command, or a short Python
snippet for the steps that have no command); its wall time and peak RSS come from
``os.wait4`` on that child alone.  Each child runs under an address-space limit
(``--cap-gb``, RLIMIT_AS) so that a runaway step fails instead of taking the
machine down.  Steps, per size (uniform family, seed 1):

* ``generate``: ``eosp generate DIR --n-acquisitions n``;
* ``info``: ``eosp info DIR`` (read and check the directory, prune, continuous graph);
* ``import``: ``eosp import DIR --out DIR.parquet`` (read, prune, write a shard);
* ``greedy dir`` / ``greedy shard``: ``eosp solve ... --solver greedy`` from the directory / ``DIR.parquet#0``;

and with ``--heavy``: ``read dir`` (read_instance alone), ``ramp``, ``exact``
(``--exact-limit`` seconds), ``policy`` (an untrained agent: memory and time do
not depend on the weights), and ``env`` (read, prune + environment preparation,
first observation, each phase's peak printed by the child).  Prints a Markdown
table; ``--json FILE`` also writes the rows.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PY = sys.executable

ENV_SNIPPET = """
import resource, sys, time, json
from eosp.instances.interchange import read_instance
from eosp.envs.sources import FixedSource
from eosp.envs.eosp_env import EOSPEnv
from eosp.config import EnvConfig
def rss(): return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
t = time.perf_counter(); inst = read_instance(sys.argv[1]); out = {"read_s": time.perf_counter() - t, "read_gb": rss()}
t = time.perf_counter(); inst.pruned(); out.update(prune_s=time.perf_counter() - t, prune_gb=rss())
t = time.perf_counter(); src = FixedSource(inst); out.update(prepare_s=time.perf_counter() - t, prepare_gb=rss())
env = EOSPEnv(EnvConfig(max_acquisitions=0), source=src)
t = time.perf_counter(); obs, _ = env.reset(seed=0); out.update(obs_s=time.perf_counter() - t, obs_gb=rss())
out["obs_mb"] = sum(v.nbytes for v in obs.values()) / 2**20
print(" ".join(f"{k} {v:.2f}" for k, v in out.items()))
"""

READ_SNIPPET = """
import sys
from eosp.instances.interchange import read_instance
inst = read_instance(sys.argv[1])
print(inst.unpruned().n_arcs)
"""

AGENT_SNIPPET = """
import sys
from eosp.config import EnvConfig
from eosp.models.agent import EOSPAgent
from eosp.models.checkpoint import save_agent
save_agent(EOSPAgent(), sys.argv[1], EnvConfig(max_acquisitions=0))
"""


def run_child(cmd: list[str], cap_gb: float, timeout: float) -> dict:
    """Wall time, peak RSS (GiB) and exit status of one child process."""
    cap = int(cap_gb * 2**30)

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
        os.nice(10)

    with tempfile.TemporaryFile() as out:
        t0 = time.perf_counter()
        p = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, preexec_fn=limit)
        deadline = t0 + timeout
        while True:
            pid, status, ru = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() > deadline:
                p.kill()
                pid, status, ru = os.wait4(p.pid, 0)
                break
            time.sleep(0.05)
        wall = time.perf_counter() - t0
        p.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        text = out.read().decode(errors="replace")
    return {"wall_s": round(wall, 2), "peak_gb": round(ru.ru_maxrss / 2**20, 2), "rc": p.returncode,
            "out": text.strip().splitlines()[-1][:200] if text.strip() else ""}


def eosp(*args: object) -> list[str]:
    return [PY, "-m", "eosp.cli", *map(str, args)]


def steps_for(n: int, work: Path, heavy: bool, exact_limit: float, agent: Path) -> list[tuple[str, list[str]]]:
    d = work / f"u{n}"
    shard = work / f"u{n}.parquet"
    s = work / f"sched{n}"
    steps = [
        ("generate", eosp("generate", d, "--n-acquisitions", n, "--seed", 1, "--overwrite")),
        ("info", eosp("info", d)),
        ("import", eosp("import", d, "--out", shard)),
        ("greedy dir", eosp("solve", d, "--solver", "greedy", "--out", f"{s}_g.parquet")),
        ("greedy shard", eosp("solve", f"{shard}#0", "--solver", "greedy", "--out", f"{s}_gs.parquet")),
    ]
    if heavy:
        steps += [
            ("read dir", [PY, "-c", READ_SNIPPET, str(d)]),
            ("ramp", eosp("solve", d, "--solver", "ramp", "--out", f"{s}_r.parquet")),
            ("exact", eosp("solve", d, "--solver", "exact", "--time-limit", exact_limit, "--out", f"{s}_e.parquet")),
            ("policy", eosp("solve", d, "--solver", "policy", "--checkpoint", agent, "--out", f"{s}_p.parquet")),
            ("env", [PY, "-c", ENV_SNIPPET, str(d)]),
        ]
    return steps


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 300, 1000, 1500])
    ap.add_argument("--work", default="/tmp/bench_io", help="directory for the instances and shards")
    ap.add_argument("--heavy", action="store_true", help="also RAMP, exact, policy, environment")
    ap.add_argument("--only", nargs="*", default=None, help="run only these steps (names as in the table)")
    ap.add_argument("--exact-limit", type=float, default=60.0)
    ap.add_argument("--cap-gb", type=float, default=12.0, help="address-space limit of each child (GiB)")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per step")
    ap.add_argument("--json", default="")
    args = ap.parse_args(argv)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    agent = work / "untrained-agent"
    if args.heavy and not (agent / "agent.pt").exists():
        r = run_child([PY, "-c", AGENT_SNIPPET, str(agent)], args.cap_gb, args.timeout)
        if r["rc"]:
            print(f"could not write the untrained agent: {r['out']}", file=sys.stderr)
            return 1
    rows = []
    print("| acq | step | wall (s) | peak RSS (GiB) | exit | last line of output |")
    print("|---|---|---|---|---|---|")
    for n in args.sizes:
        for name, cmd in steps_for(n, work, args.heavy, args.exact_limit, agent):
            if args.only is not None and name not in args.only:
                continue
            r = run_child(cmd, args.cap_gb, args.timeout)
            rows.append({"n": n, "step": name, **r})
            print(f"| {n} | {name} | {r['wall_s']:.2f} | {r['peak_gb']:.2f} | {r['rc']} | {r['out']} |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
