"""Schedules: the interchange schedule file and the independent feasibility check.

A schedule is a list of rows (acq, node, start) in execution order, with node
ids as written in the instance's own ``nodes.parquet``.  :func:`check` applies
the contract's rules directly on the unpruned arcs with plain numpy; it shares
no code with the environment or the solvers, so it can judge them.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from eosp.atomic import atomic_path
from eosp.errors import InputError
from eosp.ownership import check_output, json_mark, parquet_mark
from eosp.instances.instance import Instance
from eosp.instances.interchange import TIME_TOL, check_columns, column, read_parquet

SCHEDULE_COLUMNS = {"acq": "int", "node": "int", "start": "float"}


@dataclass
class Schedule:
    acq: np.ndarray  # int32 [k]
    node: np.ndarray  # int32 [k], ids of the instance's nodes.parquet
    start: np.ndarray  # float64 [k]

    def __len__(self) -> int:
        return int(self.acq.shape[0])


def from_internal_nodes(inst: Instance, nodes: np.ndarray | list[int]) -> Schedule:
    """Schedule of a path given as canonical node indices (source excluded)."""
    nodes = np.asarray(nodes, dtype=np.int64)
    g = inst.node_graph
    return Schedule(acq=g.node_acq[nodes].astype(np.int32), node=inst.node_ids[nodes].astype(np.int32),
                    start=g.node_time[nodes].astype(np.float64))


def to_internal_nodes(inst: Instance, schedule: Schedule) -> np.ndarray:
    inv = np.empty(inst.n_nodes, dtype=np.int64)
    inv[inst.node_ids] = np.arange(inst.n_nodes)
    return inv[schedule.node]


def value(inst: Instance, schedule: Schedule) -> float:
    return math.fsum(inst.acqs.utility[schedule.acq].tolist())


SCHEDULE_SUFFIXES = (".parquet", ".jsonl", ".json")


SCHEDULE_KIND = "schedule"  # the mark (eosp.ownership) of the schedule files eosp writes


def check_schedule_out(path: str | Path, overwrite: bool = False) -> Path:
    """Refuse, before any work, a schedule output path that is a directory, has an unknown extension, or is an
    existing file that eosp did not write (or did, without `overwrite`): :func:`eosp.ownership.check_output`."""
    return check_output(path, SCHEDULE_KIND, overwrite, suffixes=SCHEDULE_SUFFIXES)


def _column(values: np.ndarray, dtype: type) -> pa.Array:
    """A numeric Arrow column over a numpy array's buffer: unlike ``pa.array``, it does not import pandas to ask
    whether the array is a pandas object (a third of the command line's start-up)."""
    values = np.ascontiguousarray(values, dtype=dtype)
    return pa.Array.from_buffers(pa.from_numpy_dtype(values.dtype), len(values), [None, pa.py_buffer(values)])


def write_schedule(schedule: Schedule, path: str | Path, overwrite: bool = False) -> Path:
    """Write a schedule as Parquet, or as JSON lines when the name ends in .jsonl/.json (atomically), marked as
    eosp's (Parquet metadata; the key "eosp" of the first JSON line, alone on its line for an empty schedule).
    An existing file is replaced only when eosp wrote it and `overwrite` is given."""
    path = check_schedule_out(path, overwrite)
    mark = json_mark(SCHEDULE_KIND)
    with atomic_path(path) as tmp:
        if path.suffix.lower() in (".jsonl", ".json"):
            with open(tmp, "w") as fh:
                rows = zip(schedule.acq.tolist(), schedule.node.tolist(), schedule.start.tolist())
                for k, (a, n, s) in enumerate(rows):
                    fh.write(json.dumps({"acq": a, "node": n, "start": s, **(mark if k == 0 else {})}) + "\n")
                if len(schedule) == 0:
                    fh.write(json.dumps(mark) + "\n")
        else:
            table = pa.table({"acq": _column(schedule.acq, np.int32), "node": _column(schedule.node, np.int32),
                              "start": _column(schedule.start, np.float64)})
            pq.write_table(table.replace_schema_metadata(parquet_mark(SCHEDULE_KIND)), tmp)
    return path


def read_schedule(path: str | Path) -> Schedule:
    """A schedule file (.parquet, or JSON lines .jsonl/.json); other extensions are refused."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "file not found")
    if path.is_dir():
        raise InputError(path, "is a directory, expected a schedule file (.parquet or .jsonl)")
    if path.suffix.lower() not in SCHEDULE_SUFFIXES:
        raise InputError(path, f"unknown extension {path.suffix or '(none)'!r} for a schedule: use .parquet or .jsonl"
                               " (CSV is not read: convert it)")
    if path.suffix.lower() in (".jsonl", ".json"):
        rows = []
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError as exc:
            raise InputError(path, f"not UTF-8 text (JSON lines expected): byte {exc.start} cannot be read") from None
        for k, line in enumerate(text.splitlines()):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError as exc:
                raise InputError(path, f"not valid JSON: {exc}", row=k) from None
            if isinstance(row, dict):
                row.pop("eosp", None)  # the mark of a file eosp wrote (eosp.ownership), not a column
                if not row:
                    continue
            if not isinstance(row, dict) or set(row) != set(SCHEDULE_COLUMNS):
                raise InputError(path, f"each line must be an object with keys {sorted(SCHEDULE_COLUMNS)}", row=k)
            for key in ("acq", "node"):
                if not isinstance(row[key], int) or isinstance(row[key], bool):
                    raise InputError(path, "must be an integer", column=key, row=k)
            if not isinstance(row["start"], (int, float)) or isinstance(row["start"], bool):
                raise InputError(path, "must be a number", column="start", row=k)
            try:
                finite = math.isfinite(row["start"])
            except OverflowError:
                finite = False
            if not finite:
                raise InputError(path, "NaN or infinite start", column="start", row=k)
            rows.append(row)
        for key in ("acq", "node"):
            for k, r in enumerate(rows):
                if not 0 <= r[key] <= np.iinfo(np.int32).max:
                    raise InputError(path, "id out of range (0 .. 2**31-1)", column=key, row=k)
        sched = Schedule(acq=np.array([r["acq"] for r in rows], dtype=np.int32),
                         node=np.array([r["node"] for r in rows], dtype=np.int32),
                         start=np.array([r["start"] for r in rows], dtype=np.float64))
        _check_starts(path, sched.start)
        return sched
    table = read_parquet(path)
    check_columns(path, table, SCHEDULE_COLUMNS, {})
    ids = {}
    for key in ("acq", "node"):
        v = column(path, table, key, "int")  # int64: check before narrowing
        bad = (v < 0) | (v > np.iinfo(np.int32).max)
        if bad.any():
            raise InputError(path, "id out of range (0 .. 2**31-1)", column=key, row=int(np.flatnonzero(bad)[0]))
        ids[key] = v.astype(np.int32)
    start = column(path, table, "start", "float")
    _check_starts(path, start)
    return Schedule(acq=ids["acq"], node=ids["node"], start=start)


def _check_starts(path: Path, start: np.ndarray) -> None:
    bad = ~np.isfinite(start)
    if bad.any():
        raise InputError(path, "NaN or infinite start", column="start", row=int(np.flatnonzero(bad)[0]))


@dataclass
class Verdict:
    feasible: bool
    value: float
    n: int
    reason: str = ""


def check(inst: Instance, schedule: Schedule) -> Verdict:
    """Apply the contract's feasibility rules; the value is the float64 sum of the utilities."""
    g = inst.unpruned("checking a schedule")
    acqs = inst.acqs
    n_acq = len(acqs)
    n_nodes = g.n_nodes
    inv = np.full(int(max(n_nodes, int(inst.node_ids.max()) + 1)), -1, dtype=np.int64)
    inv[inst.node_ids] = np.arange(n_nodes)
    used = set()
    prev = 0  # canonical index of the source
    k = len(schedule)

    def bad(row: int, why: str) -> Verdict:
        return Verdict(False, value(inst, schedule) if k and _ids_ok(schedule, n_acq) else float("nan"), k,
                       f"row {row}: {why}")

    for r in range(k):
        a, node_id, start = int(schedule.acq[r]), int(schedule.node[r]), float(schedule.start[r])
        if not 0 <= a < n_acq:
            return bad(r, f"unknown acquisition {a}")
        if a in used:
            return bad(r, f"acquisition {a} appears twice")
        used.add(a)
        if not 0 <= node_id < inv.shape[0] or inv[node_id] < 0:
            return bad(r, f"unknown node {node_id}")
        u = int(inv[node_id])
        if int(g.node_acq[u]) != a:
            return bad(r, f"node {node_id} belongs to acquisition {int(g.node_acq[u])}, not {a}")
        if not math.isfinite(start) or abs(start - float(g.node_time[u])) > TIME_TOL:
            return bad(r, f"start {start} differs from the node's time {float(g.node_time[u])}")
        if start < acqs.vtw_start[a] - TIME_TOL or start > acqs.vtw_end[a] - acqs.duration[a] + TIME_TOL:
            return bad(r, f"start {start} outside the window [{acqs.vtw_start[a]}, "
                          f"{acqs.vtw_end[a] - acqs.duration[a]}] of acquisition {a}")
        row = g.dst[g.indptr[prev]:g.indptr[prev + 1]]
        hit = row[g.node_acq[row] == a]
        what = "the source" if prev == 0 else f"node {int(inst.node_ids[prev])}"
        if hit.size == 0:
            return bad(r, f"no arc from {what} to acquisition {a}: the maneuver cannot reach it")
        if float(g.node_time[hit[0]]) > start + TIME_TOL:
            return bad(r, f"the arc from {what} reaches acquisition {a} at {float(g.node_time[hit[0]])}, "
                          f"after the scheduled start {start}")
        prev = u
    return Verdict(True, value(inst, schedule), k)


def _ids_ok(schedule: Schedule, n_acq: int) -> bool:
    return bool(np.all((schedule.acq >= 0) & (schedule.acq < n_acq)))
