"""Parquet shards: many instances with their graphs, one row (and one row group) each.

Layout of a shard (schema version :data:`SCHEMA_VERSION`, stored in the file's
key-value metadata under ``eosp.schema_version``):

* scalars: ``name``, ``meta_json``, ``n_acq``, ``n_nodes``;
* per acquisition (lists of length n): ``duration``, ``vtw_start``, ``vtw_end``,
  ``utility``, ``priority`` (int8), ``lat``, ``lon``, ``attitude`` (6n, row-major
  in the order of :data:`instances.instance.ATTITUDE_COLUMNS`); optional ones null;
* per node (lists of length N, canonical order): ``node_acq`` (int32),
  ``node_time`` (float64), ``node_ids`` (int32), ``node_attitude`` (float32, 4N, optional);
* CSR arcs: ``pruned_indptr``/``pruned_dst`` (the graph the environment uses) and,
  optionally, ``arc_indptr``/``arc_dst`` (the unpruned graph, needed by the
  solvers that insert acquisitions and by the schedule check).

Reading a row group gives numpy arrays by zero-copy views of Arrow buffers; no
per-node Python object is created.  Every read checks the schema version, the
columns and the structural invariants, and reports a violation with the file,
the column and the instance row.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from eosp.atomic import atomic_path
from eosp.ownership import check_output
from eosp.errors import InputError
from eosp.memory import require_memory
from eosp.graphs.discrete import DiscreteGraph, first_backward_arc
from eosp.instances.instance import Acquisitions, Instance

SCHEMA_VERSION = 2  # 2: pruned arcs by the lossless rule (eosp.graphs.prune); 1 had the paper's rule
KIND = "eosp-instance-shard"

_F64, _F32, _I32, _I64, _I8 = pa.float64(), pa.float32(), pa.int32(), pa.int64(), pa.int8()
SCHEMA = pa.schema([
    ("name", pa.string()), ("meta_json", pa.string()), ("n_acq", _I32), ("n_nodes", _I32),
    ("duration", pa.list_(_F64)), ("vtw_start", pa.list_(_F64)), ("vtw_end", pa.list_(_F64)),
    ("utility", pa.list_(_F64)), ("priority", pa.list_(_I8)), ("lat", pa.list_(_F64)), ("lon", pa.list_(_F64)),
    ("attitude", pa.list_(_F64)),
    ("node_acq", pa.list_(_I32)), ("node_time", pa.list_(_F64)), ("node_ids", pa.list_(_I32)),
    ("node_attitude", pa.list_(_F32)),
    ("pruned_indptr", pa.list_(_I64)), ("pruned_dst", pa.list_(_I32)),
    ("arc_indptr", pa.list_(_I64)), ("arc_dst", pa.list_(_I32)),
])
TRANSIENT_META = ("source",)  # added on read, never stored


def _row(inst: Instance, include_unpruned: bool) -> dict:
    a = inst.acqs
    pg = inst.pruned()
    g = inst.unpruned_graph if include_unpruned else None  # None: not stored (or not known)

    def opt(x):
        return None if x is None else np.ascontiguousarray(x).reshape(-1)

    return {
        "name": inst.name, "meta_json": json.dumps({k: v for k, v in inst.meta.items() if k not in TRANSIENT_META},
                                                   sort_keys=True), "n_acq": inst.n_acq,
        "n_nodes": inst.n_nodes, "duration": a.duration, "vtw_start": a.vtw_start, "vtw_end": a.vtw_end,
        "utility": a.utility, "priority": opt(a.priority), "lat": opt(a.lat), "lon": opt(a.lon),
        "attitude": opt(a.attitude), "node_acq": inst.node_acq, "node_time": inst.node_time,
        "node_ids": inst.node_ids, "node_attitude": opt(inst.node_attitude),
        "pruned_indptr": pg.indptr, "pruned_dst": pg.dst,
        "arc_indptr": None if g is None else g.indptr, "arc_dst": None if g is None else g.dst,
    }


def _to_table(rows: list[dict]) -> pa.Table:
    arrays = []
    for f in SCHEMA:
        vals = [r[f.name] for r in rows]
        if pa.types.is_list(f.type):
            arrays.append(_list_array(vals, f.type))
        else:
            arrays.append(pa.array(vals, f.type))
    return pa.Table.from_arrays(arrays, schema=SCHEMA)


def _list_array(vals: list, typ: pa.ListType) -> pa.Array:
    """A list array built from numpy buffers in one go (no Python-level element loop)."""
    vt = typ.value_type
    np_t = vt.to_pandas_dtype()
    lengths = np.array([0 if v is None else len(v) for v in vals], dtype=np.int32)
    offsets = np.zeros(len(vals) + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    present = [np.asarray(v, dtype=np_t).reshape(-1) for v in vals if v is not None]
    # one instance per row group: its array goes in as it is (no copy of a large arc array)
    flat = present[0] if len(present) == 1 else np.concatenate(present) if offsets[-1] else np.zeros(0, dtype=np_t)
    mask = np.array([v is None for v in vals])
    return pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat, vt), mask=pa.array(mask) if mask.any() else None)


def is_shard(path: str | Path) -> bool:
    """Whether `path` is a Parquet file written by :func:`write_shard` (its key-value metadata says so)."""
    try:
        md = pq.read_schema(path).metadata or {}
    except (pa.ArrowException, OSError):
        return False
    return md.get(b"eosp.kind") == KIND.encode()


def check_shard_out(path: str | Path, overwrite: bool = False) -> Path:
    """Refuse, before any work, a shard output path: a directory, not .parquet, an existing file that is not a
    shard eosp wrote, or one that is without `overwrite` (:func:`eosp.ownership.check_output`; the mark is the
    metadata key ``eosp.kind``)."""
    return check_output(path, KIND, overwrite, suffixes=(".parquet",))


def write_shard(path: str | Path, instances: list[Instance], include_unpruned: bool = True,
                extra_meta: dict | None = None, overwrite: bool = False) -> Path:
    """Write instances (with their pruned graphs) to one Parquet shard, atomically; an existing shard is replaced
    only with `overwrite`."""
    path = check_shard_out(path, overwrite)
    meta = {b"eosp.kind": KIND.encode(), b"eosp.schema_version": str(SCHEMA_VERSION).encode(),
            b"eosp.n_instances": str(len(instances)).encode(),
            b"eosp.extra": json.dumps(extra_meta or {}, sort_keys=True).encode()}
    with atomic_path(path, suffix=".parquet") as tmp:
        writer = pq.ParquetWriter(tmp, SCHEMA.with_metadata(meta), compression="zstd",
                                  use_dictionary=["name", "meta_json"], write_statistics=False)
        try:
            for inst in instances:
                writer.write_table(_to_table([_row(inst, include_unpruned)]))
        finally:
            writer.close()
    return path


class ShardReader:
    """Random access to the instances of one shard (one row group per instance)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if not self.path.exists():
            raise InputError(self.path, "shard not found")
        try:
            self._file = pq.ParquetFile(self.path)
        except (pa.ArrowException, OSError) as exc:
            raise InputError(self.path, f"not a readable Parquet file (truncated or not a shard?): {exc}") from None
        md = self._file.schema_arrow.metadata or {}
        if md.get(b"eosp.kind") != KIND.encode():
            raise InputError(self.path, "not an EOSP shard (no 'eosp.kind' metadata): a foreign Parquet file?")
        version = md.get(b"eosp.schema_version", b"?").decode()
        if version == "1":
            raise InputError(self.path, "shard of schema version 1, whose pruned graphs can lose schedules (the "
                                        "paper's pruning rule): build it again with jobs/build_shards.py")
        if version != str(SCHEMA_VERSION):
            raise InputError(self.path, f"unknown shard schema version {version!r} "
                                        f"(this version of eosp reads version {SCHEMA_VERSION})")
        names = set(self._file.schema_arrow.names)
        for col in SCHEMA.names:
            if col not in names:
                raise InputError(self.path, "missing column", column=col)
        for f in SCHEMA:
            got = self._file.schema_arrow.field(f.name).type
            if got != f.type:
                raise InputError(self.path, f"wrong type {got}, expected {f.type}", column=f.name)
        self.extra = json.loads(md.get(b"eosp.extra", b"{}").decode())

    def __len__(self) -> int:
        return self._file.num_row_groups

    def names(self) -> list[str]:
        return self._file.read(columns=["name"]).column("name").to_pylist()

    def read(self, index: int, unpruned: bool = True) -> Instance:
        if not 0 <= index < len(self):
            raise IndexError(f"{self.path}: instance {index} out of range (shard holds {len(self)})")
        columns = [c for c in SCHEMA.names if unpruned or c != "arc_dst"]
        require_memory(self.path, self._bytes_needed(index, columns), f"instance {index}")
        try:
            t = self._file.read_row_group(index, columns=columns, use_threads=False)
        except (pa.ArrowException, OSError) as exc:
            raise InputError(self.path, f"cannot read instance row group {index} (truncated file?): {exc}",
                             row=index) from None
        return _instance_from_row(self.path, index, t, unpruned)

    def _bytes_needed(self, index: int, columns: list[str]) -> int:
        """Peak memory of decoding one instance: its arrays, plus the Parquet reader's levels and buffers.

        Measured: a list column of k values of b bytes peaks near k * (b + 4) * 1.5 while decoded.
        """
        rg = self._file.metadata.row_group(index)
        need = 0
        for c in range(rg.num_columns):
            cc = rg.column(c)
            name = cc.path_in_schema.split(".")[0]
            if name in columns:
                width = {"INT32": 4, "FLOAT": 4, "INT64": 8, "DOUBLE": 8}.get(cc.physical_type, 8)
                need += int(cc.num_values * (width + 4) * 1.5)
        return need

    def __iter__(self):
        for i in range(len(self)):
            yield self.read(i)


def _values(path: Path, row: int, t: pa.Table, name: str, np_type, required: bool = True) -> np.ndarray | None:
    col = t.column(name)
    chunk = col.chunk(0) if col.num_chunks == 1 else pa.concat_arrays(col.chunks)
    if chunk.null_count:
        if required:
            raise InputError(path, "null where a list is required", column=name, row=row)
        return None
    vals = chunk.values
    if vals.null_count:
        raise InputError(path, "null element", column=name, row=row)
    return vals.to_numpy(zero_copy_only=False).astype(np_type, copy=False)


def _instance_from_row(path: Path, row: int, t: pa.Table, unpruned: bool) -> Instance:
    def need(name, typ):
        return _values(path, row, t, name, typ)

    def maybe(name, typ):
        return _values(path, row, t, name, typ, required=False)

    n = t.column("n_acq")[0].as_py()
    big_n = t.column("n_nodes")[0].as_py()
    if n is None or big_n is None or n < 1 or big_n < 1:
        raise InputError(path, "n_acq and n_nodes must be positive", column="n_acq", row=row)
    for name in ("duration", "vtw_start", "vtw_end", "utility"):
        if len(need(name, np.float64)) != n:
            raise InputError(path, f"length differs from n_acq={n}", column=name, row=row)
    node_acq, node_time = need("node_acq", np.int32), need("node_time", np.float64)
    node_ids = need("node_ids", np.int32)
    for name, arr in (("node_acq", node_acq), ("node_time", node_time), ("node_ids", node_ids)):
        if len(arr) != big_n:
            raise InputError(path, f"length differs from n_nodes={big_n}", column=name, row=row)
    dur = need("duration", np.float64)
    acqs = Acquisitions(duration=dur, vtw_start=need("vtw_start", np.float64), vtw_end=need("vtw_end", np.float64),
                        utility=need("utility", np.float64), priority=maybe("priority", np.int8),
                        lat=maybe("lat", np.float64), lon=maybe("lon", np.float64),
                        attitude=None)
    _check_values(path, row, acqs, node_time, node_ids)
    att = maybe("attitude", np.float64)
    if att is not None:
        if len(att) != 6 * n:
            raise InputError(path, f"length differs from 6 * n_acq = {6 * n}", column="attitude", row=row)
        acqs.attitude = att.reshape(n, 6)
    if big_n < 1 or node_acq[0] != -1 or np.any(node_acq[1:] < 0) or np.any(node_acq[1:] >= n) \
            or np.any(np.diff(node_acq[1:]) < 0):
        raise InputError(path, "nodes not in canonical order (source, then by acquisition)", column="node_acq",
                         row=row)
    from eosp.graphs.discrete import acq_ptr_from_node_acq

    acq_ptr = acq_ptr_from_node_acq(node_acq, n)
    if np.any(np.diff(acq_ptr) == 0):
        raise InputError(path, "an acquisition has no node", column="node_acq", row=row)
    pindptr, pdst = need("pruned_indptr", np.int64), need("pruned_dst", np.int32)
    _check_csr(path, row, "pruned", pindptr, pdst, node_acq, node_time, dur)
    unpruned_graph = None  # not stored, or not asked for
    if unpruned and "arc_dst" in t.column_names and t.column("arc_indptr").null_count == 0:
        aindptr, adst = need("arc_indptr", np.int64), need("arc_dst", np.int32)
        _check_csr(path, row, "arc", aindptr, adst, node_acq, node_time, dur)
        unpruned_graph = DiscreteGraph(node_acq, node_time, aindptr, adst, acq_ptr)
    node_att = maybe("node_attitude", np.float32)
    try:
        meta = json.loads(t.column("meta_json")[0].as_py() or "{}")
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc}", column="meta_json", row=row) from None
    meta["source"] = f"{path}#{row}"
    return Instance(name=t.column("name")[0].as_py(), acqs=acqs, unpruned_graph=unpruned_graph, node_ids=node_ids,
                    meta=meta, node_attitude=None if node_att is None else node_att.reshape(big_n, 4),
                    pruned_graph=DiscreteGraph(node_acq, node_time, pindptr, pdst, acq_ptr))


def _check_values(path: Path, row: int, acqs: Acquisitions, node_time: np.ndarray, node_ids: np.ndarray) -> None:
    for name in ("duration", "vtw_start", "vtw_end", "utility"):
        if not np.all(np.isfinite(getattr(acqs, name))):
            raise InputError(path, "NaN or infinite value", column=name, row=row)
    if not np.all(np.isfinite(node_time)):
        raise InputError(path, "NaN or infinite value", column="node_time", row=row)
    if np.any(acqs.duration <= 0) or np.any(acqs.utility <= 0):
        raise InputError(path, "durations and utilities must be > 0", column="utility" if np.any(acqs.utility <= 0)
                         else "duration", row=row)
    with np.errstate(over="ignore"):
        total = np.sum(acqs.utility)
    if not np.isfinite(total):
        raise InputError(path, "the utilities add up past the largest float (1.8e308)", column="utility", row=row)
    if node_ids.size and (node_ids.min() < 0 or np.unique(node_ids).size != node_ids.size):
        raise InputError(path, "node ids must be distinct and >= 0", column="node_ids", row=row)


def _check_csr(path: Path, row: int, prefix: str, indptr: np.ndarray, dst: np.ndarray, node_acq: np.ndarray,
               node_time: np.ndarray, dur: np.ndarray) -> None:
    big_n = node_acq.shape[0]
    if indptr.shape[0] != big_n + 1 or indptr[0] != 0 or indptr[-1] != dst.shape[0] or np.any(np.diff(indptr) < 0):
        raise InputError(path, "CSR offsets inconsistent with the arcs", column=f"{prefix}_indptr", row=row)
    if dst.size and (dst.min() < 1 or dst.max() >= big_n):
        raise InputError(path, "dangling node id in arcs", column=f"{prefix}_dst", row=row)
    if first_backward_arc(node_acq, node_time, indptr, dst, dur) >= 0:
        raise InputError(path, "arc goes back in time", column=f"{prefix}_dst", row=row)


def read_instances(paths: list[str | Path], unpruned: bool = True) -> list[Instance]:
    out = []
    for p in paths:
        reader = ShardReader(p)
        out.extend(reader.read(i, unpruned) for i in range(len(reader)))
    return out


def dataset_shards(path: str | Path) -> list[Path]:
    """The shard files of a data set directory (sorted), or the file itself."""
    p = Path(path)
    if p.is_file():
        return [p]
    files = sorted(p.glob("*.parquet"))
    if not files:
        raise InputError(p, "no shard (*.parquet) in this directory")
    return files
