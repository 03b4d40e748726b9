"""Expert demonstrations in Parquet, beside the shards they were solved from.

Layout: ``<data set>/demos/<mode>/shard-XXXXX.parquet`` (one file per shard and
objective mode) and ``manifest.json`` written last.  One row per environment step:

==================  ============  ====================================================
column              type          meaning
==================  ============  ====================================================
``instance``        int32         index of the instance in its shard
``name``            string        instance name (checked against the shard)
``step``            int32         0, 1, ... within the instance's trajectory
``action``          int32         the expert's action (an acquisition)
``reward``          float64       objective weight of the action (1, or its utility)
``return_to_go``    float64       objective collected from this step on (this step included)
``optimal``         list<int32>   actions of this state whose value is the best (empty: not computed)
``n_allowed``       int16         number of allowed actions in this state
``allowed``         list<int32>   the allowed actions (empty: not computed)
``q``               list<float64> their values Q(s, a) (objective units; empty: not computed)
``value``           float64       the expert schedule's value (per instance)
``bound``           float64       upper bound of the instance's optimum (= value when proven)
``status``          string        'optimal' or 'time_limit'
==================  ============  ====================================================

File metadata: ``eosp.demos.schema_version``, ``eosp.demos.mode``, ``eosp.demos.shard``
(file name) and ``eosp.demos.graph`` (nodes/arcs of every instance's environment graph, so
that demos of another shard or another pruning are refused).  An instance whose initial
state allows no action has no row.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from eosp.atomic import atomic_path
from eosp.errors import InputError

SCHEMA_VERSION = 2  # 2: columns allowed and q (files of version 1 are still read)
READABLE = (b"1", b"2")
MODES = ("unitary", "utility")
SCHEMA = pa.schema([("instance", pa.int32()), ("name", pa.string()), ("step", pa.int32()), ("action", pa.int32()),
                    ("reward", pa.float64()), ("return_to_go", pa.float64()), ("optimal", pa.list_(pa.int32())),
                    ("n_allowed", pa.int16()), ("allowed", pa.list_(pa.int32())), ("q", pa.list_(pa.float64())),
                    ("value", pa.float64()), ("bound", pa.float64()),
                    ("status", pa.string())])


def demo_dir(data: str | Path, mode: str) -> Path:
    return Path(data) / "demos" / mode


def graph_signature(prepared) -> list[int]:
    eg = prepared.eg
    return [int(eg.node_acq.shape[0]), int(eg.dst.shape[0])]


def solve_shard(shard: str | Path, mode: str, *, time_limit: float, action_sets: bool, beam: int,
                prune: bool, out: str | Path, sets_max_acquisitions: int = 0) -> dict:
    """Solve every instance of a shard in `mode`, replay it in the environment, write the demos file."""
    from eosp.config import EnvConfig
    from eosp.envs.eosp_env import EOSPEnv
    from eosp.envs.sources import FixedSource, prepare_instance
    from eosp.shards.io import ShardReader
    from eosp.solvers import expert

    t0 = time.perf_counter()
    reader = ShardReader(shard)
    unitary = mode == "unitary"
    cols: dict[str, list] = {f.name: [] for f in SCHEMA}
    sigs, stats = [], {"instances": 0, "steps": 0, "optimal": 0, "max_gap": 0.0, "solve_s": 0.0}
    env = None
    for k in range(len(reader)):
        prepared = prepare_instance(reader.read(k, unpruned=not prune), prune)
        sigs.append(graph_signature(prepared))
        if env is None or prepared.inst.n_acq > env.n_max:
            env = EOSPEnv(EnvConfig(max_acquisitions=0, prune=prune), source=FixedSource(prepared))
        env.reset(options={"instance": prepared})
        w = expert.objective(prepared.inst, mode)
        path = expert.optimal_path(expert.state_residual(env), w, unitary=unitary, time_limit=time_limit)
        stats["solve_s"] += path.seconds
        rewards = w[path.actions]
        togo = np.cumsum(rewards[::-1])[::-1] if rewards.size else rewards
        sets = action_sets and (not sets_max_acquisitions or prepared.inst.n_acq <= sets_max_acquisitions)
        for step, a in enumerate(path.actions):
            opt: list[int] = []
            allowed_l: list[int] = []
            q_l: list[float] = []
            n_allowed = int(env.state.ep.mask.sum())
            if sets:
                allowed, q = expert.action_values(env, w, beam)
                q[allowed == a] = np.maximum(q[allowed == a], togo[step])  # the expert's value is exact
                opt = allowed[expert.optimal_set(q, unitary)].tolist()
                allowed_l, q_l = allowed.tolist(), q.tolist()
            env.step(int(a))  # raises if the expert's action is not allowed: never written
            for c, v in (("instance", k), ("name", prepared.inst.name), ("step", step), ("action", int(a)),
                         ("reward", float(rewards[step])), ("return_to_go", float(togo[step])), ("optimal", opt),
                         ("n_allowed", n_allowed), ("allowed", allowed_l), ("q", q_l), ("value", path.value),
                         ("bound", path.bound),
                         ("status", path.status)):
                cols[c].append(v)
        replayed = float(np.sum(w[[int(x) for x in path.actions]])) if path.actions.size else 0.0
        if not np.isclose(replayed, path.value, rtol=1e-12, atol=1e-9):
            raise AssertionError(f"{shard}#{k}: replay gives {replayed}, the expert {path.value}")
        stats["instances"] += 1
        stats["steps"] += int(path.actions.size)
        stats["optimal"] += path.status == "optimal"
        stats["max_gap"] = max(stats["max_gap"], path.gap)
    table = pa.table(cols, schema=SCHEMA)
    meta = {b"eosp.demos.schema_version": str(SCHEMA_VERSION).encode(), b"eosp.demos.mode": mode.encode(),
            b"eosp.demos.shard": Path(shard).name.encode(), b"eosp.demos.graph": json.dumps(sigs).encode(),
            b"eosp.demos.prune": str(prune).encode(), b"eosp.demos.sets": str(bool(action_sets)).lower().encode()}
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        pq.write_table(table.replace_schema_metadata(meta), tmp)
    return {"file": out.name, "shard": Path(shard).name, **stats, "seconds": round(time.perf_counter() - t0, 3)}


@dataclass
class Demo:
    """One instance's expert trajectory."""

    shard: Path
    index: int
    name: str
    actions: np.ndarray  # int32 [T]
    rewards: np.ndarray  # float64 [T]
    return_to_go: np.ndarray  # float64 [T]
    optimal: list[np.ndarray]  # per step; empty arrays when not computed
    allowed: list[np.ndarray]  # per step: the allowed actions (empty when not computed)
    q: list[np.ndarray]  # per step: their values (objective units)
    value: float
    bound: float
    status: str


def demo_file(shard: Path, mode: str) -> Path:
    return demo_dir(shard.parent, mode) / shard.name


def is_complete(path: Path, mode: str, action_sets: bool = False) -> bool:
    """A demos file that exists, is readable, is of `mode`, and has action sets when they are asked for
    (resuming skips it)."""
    try:
        md = pq.read_schema(path).metadata or {}
        if md.get(b"eosp.demos.schema_version") not in READABLE or md.get(b"eosp.demos.mode") != mode.encode():
            return False
        if not action_sets:
            return True
        if b"eosp.demos.sets" in md:
            return md[b"eosp.demos.sets"] == b"true"
        first = pq.ParquetFile(path).read_row_group(0, columns=["optimal"]).column(0)  # version 1: look
        return len(first) == 0 or len(first[0]) > 0
    except (OSError, pa.ArrowInvalid, IndexError):
        return False


def read_demos(shard: Path, mode: str, prepared: list) -> list[Demo]:
    """The demos of a shard, checked against its instances (`prepared`, in shard order).

    A file of another shard, another graph, or with an action the environment does not
    allow is refused with the file, the row and the reason (:class:`InputError`).
    """
    path = demo_file(shard, mode)
    if not path.exists():
        raise InputError(path, f"no {mode} demos for {shard.name}: run jobs/build_demos.py on {shard.parent}")
    try:
        pf = pq.ParquetFile(path)
        table = pf.read()
    except (OSError, pa.ArrowInvalid) as exc:
        raise InputError(path, f"not a readable Parquet file: {exc}") from None
    md = table.schema.metadata or {}
    if md.get(b"eosp.demos.schema_version") not in READABLE:
        raise InputError(path, f"not an expert demos file of schema version {', '.join(v.decode() for v in READABLE)}")
    if md.get(b"eosp.demos.shard", b"").decode() != shard.name:
        raise InputError(path, f"demos of shard {md.get(b'eosp.demos.shard', b'?').decode()}, not {shard.name}")
    sigs = json.loads(md.get(b"eosp.demos.graph", b"[]"))
    if len(sigs) != len(prepared):
        raise InputError(path, f"demos of {len(sigs)} instances, the shard has {len(prepared)}")
    for k, p in enumerate(prepared):
        if sigs[k] != graph_signature(p):
            raise InputError(path, f"instance {k}: demos solved on another graph ({sigs[k][0]} nodes, {sigs[k][1]} "
                                   f"arcs; the shard's environment graph has {graph_signature(p)})")
    optional = ("allowed", "q")  # version 2
    for c in SCHEMA.names:
        if c not in table.column_names and c not in optional:
            raise InputError(path, f"missing column {c!r}", column=c)
    d = {c: table.column(c).to_pylist() if c in table.column_names else [[]] * table.num_rows for c in SCHEMA.names}
    rows_of: dict[int, list[int]] = {}
    for r, k in enumerate(d["instance"]):
        if not 0 <= k < len(prepared):
            raise InputError(path, f"instance index {k} out of range", column="instance", row=r)
        rows_of.setdefault(k, []).append(r)
    out = []
    for k, rows in sorted(rows_of.items()):
        name = prepared[k].inst.name
        if d["name"][rows[0]] != name:
            raise InputError(path, f"instance {k} is {name!r} in the shard, {d['name'][rows[0]]!r} here",
                             column="name", row=rows[0])
        if [d["step"][r] for r in rows] != list(range(len(rows))):
            raise InputError(path, f"steps of instance {k} are not 0..{len(rows) - 1} in order", column="step",
                             row=rows[0])
        out.append(Demo(shard, k, name, np.array([d["action"][r] for r in rows], np.int32),
                        np.array([d["reward"][r] for r in rows]), np.array([d["return_to_go"][r] for r in rows]),
                        [np.array(d["optimal"][r], np.int32) for r in rows],
                        [np.array(d["allowed"][r], np.int32) for r in rows],
                        [np.array(d["q"][r], np.float64) for r in rows], float(d["value"][rows[0]]),
                        float(d["bound"][rows[0]]), d["status"][rows[0]]))
    return out


def replay(env, prepared, demo: Demo, path: Path | None = None):
    """Yield (observation, step index) along a demo; refuses an action the mask forbids."""
    obs, _ = env.reset(options={"instance": prepared})
    for t, a in enumerate(demo.actions):
        yield obs, t
        if not env.state.ep.mask[a]:
            raise InputError(path or demo.shard, f"instance {demo.index} step {t}: action {int(a)} is not allowed "
                                                 f"by the environment (allowed: "
                                                 f"{np.flatnonzero(env.state.ep.mask).tolist()})", column="action")
        obs, *_ = env.step(int(a))
