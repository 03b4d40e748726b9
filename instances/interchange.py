"""Import and export of the instance interchange format (docs/formats.md).

An instance directory holds ``acquisitions.parquet``, ``nodes.parquet``,
``arcs.parquet`` (the UNPRUNED discrete graph) and optionally ``meta.json``.
Import checks every rule of the contract and stops at the first violation with
an :class:`~eosp.errors.InputError` naming the file, the column and the row.
Export writes the same files into a temporary directory renamed into place, so
export -> import gives back identical arrays.
"""

from __future__ import annotations

import json
from pathlib import Path

import numba
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from eosp.atomic import atomic_dir
from eosp.ownership import check_output, json_mark, kind_of
from eosp.errors import InputError
from eosp.memory import require_memory
from eosp.graphs.discrete import DiscreteGraph, acq_ptr_from_node_acq
from eosp.instances.instance import ATTITUDE_COLUMNS, Acquisitions, Instance

TIME_TOL = 1e-6

ACQ_REQUIRED = {"acq": "int", "duration": "float", "vtw_start": "float", "vtw_end": "float", "utility": "float"}
ACQ_OPTIONAL = {"priority": "int", "lat": "float", "lon": "float", **{c: "float" for c in ATTITUDE_COLUMNS}}
NODE_COLUMNS = {"node": "int", "acq": "int", "time": "float"}
ARC_COLUMNS = {"src": "int", "dst": "int"}


# --------------------------------------------------------------------------- reading helpers

def read_parquet(path: Path) -> pa.Table:
    if not path.exists():
        raise InputError(path, "file not found")
    if path.is_dir():
        raise InputError(path, "is a directory, expected a Parquet file")
    try:
        with pq.ParquetFile(path) as f:  # not pq.read_table: its dataset layer imports pandas (0.3 s a call)
            return f.read()
    except (pa.ArrowException, OSError) as exc:
        raise InputError(path, f"not a readable Parquet file (truncated or not Parquet?): {exc}") from None


def check_columns(path: Path, table: pa.Table | pa.Schema, required: dict[str, str],
                  optional: dict[str, str]) -> None:
    names = table.column_names if isinstance(table, pa.Table) else table.names
    for name in required:
        if name not in names:
            raise InputError(path, f"missing required column (found: {', '.join(names) or 'none'})", column=name)
    allowed = set(required) | set(optional)
    for name in names:
        if name not in allowed:
            raise InputError(path, f"unexpected column (allowed: {', '.join(sorted(allowed))})", column=name)
    if len(set(names)) != len(names):
        raise InputError(path, "duplicate column names")


def column(path: Path, table: pa.Table, name: str, kind: str) -> np.ndarray:
    """A column as numpy: 'int' must be an integer type, 'float' a float or integer type; no nulls."""
    col = table.column(name)
    check_type(path, name, col.type, kind)
    if col.null_count:
        row = int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0])
        raise InputError(path, "null value", column=name, row=row)
    arr = col.to_numpy()
    return arr.astype(np.int64) if kind == "int" else arr.astype(np.float64)


def check_type(path: Path, name: str, t: pa.DataType, kind: str) -> None:
    if kind == "int" and not pa.types.is_integer(t):
        raise InputError(path, f"wrong type {t}, expected an integer type", column=name)
    if kind == "float" and not (pa.types.is_floating(t) or pa.types.is_integer(t)):
        raise InputError(path, f"wrong type {t}, expected a floating-point type", column=name)


def _fail_rows(path: Path, bad: np.ndarray, column_name: str, message: str, rows: np.ndarray | None = None) -> None:
    if np.any(bad):
        r = int(np.flatnonzero(bad)[0])
        raise InputError(path, message, column=column_name, row=int(rows[r]) if rows is not None else r)


# --------------------------------------------------------------------------- arcs, streamed

# the rules checked on every arc, in the order in which they are reported
ARC_RULES = (
    ("src", "dangling node id (not in nodes.parquet)"),
    ("dst", "dangling node id (not in nodes.parquet)"),
    ("dst", "arc into the source node 0"),
    ("dst", "arc between two nodes of the same acquisition"),
    ("dst", "arc goes back in time (dst time < src time)"),
    ("dst", "arc starts its destination before the source acquisition ends (time < src time + duration)"),
)
BATCH_ROWS = 1 << 20  # arcs decoded at a time


@numba.njit(cache=True)
def _check_batch(src, dst, offset, canon, node_acq, node_time, dur, deg, first_bad):
    """Check one batch of arcs (file ids) and count the valid ones per canonical source.

    ``first_bad[r]`` keeps the smallest file row breaking rule r (ARC_RULES), so the
    error reported is the one a whole-file check would report.
    """
    big_n = canon.shape[0]
    for k in range(src.shape[0]):
        s = src[k]
        d = dst[k]
        row = offset + k
        bad = False
        if s < 0 or s >= big_n:
            if row < first_bad[0]:
                first_bad[0] = row
            bad = True
        if d < 0 or d >= big_n:
            if row < first_bad[1]:
                first_bad[1] = row
            bad = True
        if bad:
            continue
        if d == 0 and row < first_bad[2]:
            first_bad[2] = row
        cs = canon[s]
        cd = canon[d]
        sa = node_acq[cs]
        if sa == node_acq[cd] and row < first_bad[3]:
            first_bad[3] = row
        ts = node_time[cs]
        td = node_time[cd]
        if td < ts and row < first_bad[4]:
            first_bad[4] = row
        fin = ts + (dur[sa] if sa >= 0 else 0.0)
        if td < fin - 1e-6 and row < first_bad[5]:
            first_bad[5] = row
        deg[cs] += 1


@numba.njit(cache=True)
def _scatter_batch(src, dst, canon, cursor, out):
    """Place one batch of (already checked) arcs into the CSR rows of their canonical sources."""
    for k in range(src.shape[0]):
        cs = canon[src[k]]
        out[cursor[cs]] = canon[dst[k]]
        cursor[cs] += 1


@numba.njit(cache=True)
def _sort_rows(indptr, dst, node_acq, dup_src):
    """Sort every CSR row; flag sources with two arcs to one acquisition. Returns the number flagged."""
    n_dup = 0
    for u in range(indptr.shape[0] - 1):
        lo = indptr[u]
        hi = indptr[u + 1]
        if hi - lo > 1:
            dst[lo:hi].sort()
            for k in range(lo + 1, hi):
                if node_acq[dst[k]] == node_acq[dst[k - 1]]:
                    dup_src[u] = True
                    n_dup += 1
                    break
    return n_dup


class _ArcBatches:
    """The (src, dst) batches of an arcs file, row group by row group, with their file offsets."""

    def __init__(self, path: Path):
        self.path = path
        if not path.exists():
            raise InputError(path, "file not found")
        try:
            self.file = pq.ParquetFile(path)
        except (pa.ArrowException, OSError) as exc:
            raise InputError(path, f"not a readable Parquet file (truncated or not Parquet?): {exc}") from None
        schema = self.file.schema_arrow
        check_columns(path, schema, ARC_COLUMNS, {})
        for name in ARC_COLUMNS:
            check_type(path, name, schema.field(name).type, "int")
        md = self.file.metadata
        self.n_rows = md.num_rows
        size = path.stat().st_size
        for i in range(md.num_row_groups):
            rg = md.row_group(i)
            for c in range(rg.num_columns):
                cc = rg.column(c)
                start = cc.dictionary_page_offset if cc.has_dictionary_page else cc.data_page_offset
                if start is not None and start + cc.total_compressed_size > size:
                    raise InputError(path, f"row group {i} of {md.num_row_groups} is truncated (its data ends "
                                           f"past the end of the file)", column=cc.path_in_schema)

    def __iter__(self):
        offset = 0
        n_groups = self.file.metadata.num_row_groups
        for i in range(n_groups):
            try:
                for batch in self.file.iter_batches(batch_size=BATCH_ROWS, row_groups=[i],
                                                    columns=list(ARC_COLUMNS), use_threads=False):
                    cols = []
                    for name in ARC_COLUMNS:
                        col = batch.column(name)
                        if col.null_count:
                            r = int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0])
                            raise InputError(self.path, "null value", column=name, row=offset + r)
                        cols.append(col.to_numpy())
                    yield offset, cols[0], cols[1]
                    offset += batch.num_rows
            except (pa.ArrowException, OSError) as exc:
                raise InputError(self.path, f"row group {i} of {n_groups} unreadable (truncated or corrupt): "
                                            f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}",
                                 row=offset) from None


def read_arcs(path: Path, canon: np.ndarray, node_acq: np.ndarray, node_time: np.ndarray,
              duration: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The arcs file as canonical CSR (int64 indptr, int32 dst, rows sorted), checked batch by batch.

    Two streaming passes: the first checks every arc and counts the arcs of each
    source, the second places them; memory is the CSR arrays plus one batch.
    """
    batches = _ArcBatches(path)
    n_arcs = batches.n_rows
    big_n = canon.shape[0]
    # the CSR (4 bytes per arc), then pruning (a mask and the kept arcs, at most 5 bytes per arc)
    require_memory(path, 9 * n_arcs + 48 * big_n + 64 * BATCH_ROWS,
                   f"reading and pruning {n_arcs:,} arcs")
    deg = np.zeros(big_n, dtype=np.int64)
    first_bad = np.full(len(ARC_RULES), np.iinfo(np.int64).max, dtype=np.int64)
    for offset, src, dst in batches:
        _check_batch(src, dst, offset, canon, node_acq, node_time, duration, deg, first_bad)
    for r, (col, message) in enumerate(ARC_RULES):
        if first_bad[r] != np.iinfo(np.int64).max:
            raise InputError(path, message, column=col, row=int(first_bad[r]))
    indptr = np.zeros(big_n + 1, dtype=np.int64)
    np.cumsum(deg, out=indptr[1:])
    del deg
    out = np.empty(n_arcs, dtype=np.int32)
    cursor = indptr[:-1].copy()
    for _, src, dst in batches:
        _scatter_batch(src, dst, canon, cursor, out)
    if not np.array_equal(cursor, indptr[1:]):  # the file changed between the two passes
        raise InputError(path, "file changed while being read")
    del cursor
    dup_src = np.zeros(big_n, dtype=np.bool_)
    if _sort_rows(indptr, out, node_acq, dup_src):
        raise InputError(path, "second arc from the same node to the same acquisition", column="dst",
                         row=_first_duplicate_row(batches, canon, node_acq, dup_src))
    n_acq = int(node_acq.max()) + 1 if node_acq.size else 0
    from_source = np.zeros(n_acq, dtype=bool)
    from_source[node_acq[out[indptr[0]:indptr[1]]]] = True
    if not from_source.all():
        raise InputError(path, f"no arc from the source (node 0) to acquisition {int(np.flatnonzero(~from_source)[0])}:"
                               " the format requires one to the earliest node of every acquisition", column="src")
    return indptr, out


def _first_duplicate_row(batches: _ArcBatches, canon: np.ndarray, node_acq: np.ndarray,
                         dup_src: np.ndarray) -> int:
    """File row of the first arc repeating an earlier (source, destination acquisition) pair."""
    rows, keys = [], []
    n = int(node_acq.max()) + 2
    for offset, src, dst in batches:
        cs = canon[src]
        sel = np.flatnonzero(dup_src[cs])
        rows.append(offset + sel)
        keys.append(cs[sel].astype(np.int64) * n + node_acq[canon[dst[sel]]] + 1)
    row, key = np.concatenate(rows), np.concatenate(keys)
    seen: set[int] = set()
    for r, k in zip(row.tolist(), key.tolist()):  # only the arcs of the flagged sources
        if k in seen:
            return r
        seen.add(k)
    return -1


# --------------------------------------------------------------------------- import

def read_acquisitions(path: Path) -> tuple[Acquisitions, np.ndarray]:
    """Acquisitions sorted by id, and the file row of each id."""
    table = read_parquet(path)
    check_columns(path, table, ACQ_REQUIRED, ACQ_OPTIONAL)
    cols = {name: column(path, table, name, kind) for name, kind in {**ACQ_REQUIRED, **ACQ_OPTIONAL}.items()
            if name in table.column_names}
    acq = cols["acq"]
    n = acq.shape[0]
    if n == 0:
        raise InputError(path, "no acquisition")
    _fail_rows(path, (acq < 0) | (acq >= n), "acq", f"id out of range: ids must be dense 0..{n - 1}")
    seen = np.zeros(n, dtype=np.int64)
    np.add.at(seen, acq, 1)
    if np.any(seen != 1):
        dup = int(np.flatnonzero(seen > 1)[0])
        rows = np.flatnonzero(acq == dup)
        raise InputError(path, f"duplicate acquisition id {dup}", column="acq", row=int(rows[1]))
    for name in ("duration", "vtw_start", "vtw_end", "utility", "lat", "lon", *ATTITUDE_COLUMNS):
        if name in cols:
            _fail_rows(path, ~np.isfinite(cols[name]), name, "NaN or infinite value")
    _fail_rows(path, cols["duration"] <= 0, "duration", "duration must be > 0")
    _fail_rows(path, cols["utility"] <= 0, "utility", "utility must be > 0")
    with np.errstate(over="ignore"):
        running = np.cumsum(cols["utility"])
    _fail_rows(path, ~np.isfinite(running), "utility",
               "the utilities add up past the largest float (1.8e308): scale them down")
    _fail_rows(path, cols["vtw_end"] < cols["vtw_start"], "vtw_end", "window ends before it starts")
    _fail_rows(path, cols["vtw_end"] - cols["duration"] < cols["vtw_start"] - TIME_TOL, "duration",
               "window [vtw_start, vtw_end] is shorter than the duration")
    if "priority" in cols:
        _fail_rows(path, (cols["priority"] < 0) | (cols["priority"] > 127), "priority",
                   "priority must be in 0..127 (0 = highest)")
    order = np.argsort(acq, kind="stable")

    def get(name: str) -> np.ndarray | None:
        return cols[name][order] if name in cols else None

    att = None
    if all(c in cols for c in ATTITUDE_COLUMNS):
        att = np.stack([cols[c][order] for c in ATTITUDE_COLUMNS], axis=1)
    elif any(c in cols for c in ATTITUDE_COLUMNS):
        missing = [c for c in ATTITUDE_COLUMNS if c not in cols]
        raise InputError(path, "attitude statistics must come all six together", column=missing[0])
    prio = get("priority")
    acqs = Acquisitions(duration=get("duration"), vtw_start=get("vtw_start"), vtw_end=get("vtw_end"),
                        utility=get("utility"), priority=None if prio is None else prio.astype(np.int8),
                        lat=get("lat"), lon=get("lon"), attitude=att)
    return acqs, order


def read_instance(directory: str | Path, name: str | None = None) -> Instance:
    """Read and check an instance directory; nodes are brought to canonical order."""
    d = Path(directory)
    if not d.is_dir():
        raise InputError(d, "not an instance directory")
    acqs, _ = read_acquisitions(d / "acquisitions.parquet")
    n = len(acqs)

    npath = d / "nodes.parquet"
    table = read_parquet(npath)
    check_columns(npath, table, NODE_COLUMNS, {})
    node = column(npath, table, "node", "int")
    nacq = column(npath, table, "acq", "int")
    ntime = column(npath, table, "time", "float")
    big_n = node.shape[0]
    if big_n == 0:
        raise InputError(npath, "no node (node 0, the source, is required)")
    _fail_rows(npath, (node < 0) | (node >= big_n), "node", f"node id out of range: ids must be dense 0..{big_n - 1}")
    pos = np.full(big_n, -1, dtype=np.int64)  # file row of each node id
    seen = np.zeros(big_n, dtype=np.int64)
    np.add.at(seen, node, 1)
    if np.any(seen != 1):
        dup = int(np.flatnonzero(seen > 1)[0])
        raise InputError(npath, f"duplicate node id {dup}", column="node", row=int(np.flatnonzero(node == dup)[1]))
    pos[node] = np.arange(big_n)
    _fail_rows(npath, ~np.isfinite(ntime), "time", "NaN or infinite time")
    src_row = int(pos[0])
    if nacq[src_row] != -1:
        raise InputError(npath, "node 0 is the source and must have acq = -1", column="acq", row=src_row)
    bad_acq = ((nacq < 0) | (nacq >= n)) & (node != 0)
    _fail_rows(npath, bad_acq, "acq", f"unknown acquisition id (dangling): must be in 0..{n - 1}")
    real = node != 0
    a = np.where(real, nacq, 0)
    lo = acqs.vtw_start[a]
    hi = acqs.vtw_end[a] - acqs.duration[a]
    _fail_rows(npath, real & ((ntime < lo - TIME_TOL) | (ntime > hi + TIME_TOL)), "time",
               "node time outside its window [vtw_start, vtw_end - duration]")

    per_acq = np.bincount(nacq[real], minlength=n)
    if np.any(per_acq == 0):
        raise InputError(npath, f"acquisition {int(np.flatnonzero(per_acq == 0)[0])} has no node: every "
                                "acquisition needs at least one candidate start", column="acq")

    # canonical order: source, then by (acq, time)
    key_acq = np.where(node == 0, -1, nacq)
    perm = np.lexsort((ntime, key_acq))  # file rows in canonical order
    if perm[0] != src_row:
        perm = np.concatenate([[src_row], perm[perm != src_row]])
    new_of_row = np.empty(big_n, dtype=np.int64)
    new_of_row[perm] = np.arange(big_n)
    node_acq = nacq[perm].astype(np.int32)
    node_time = ntime[perm]
    node_ids = node[perm].astype(np.int32)
    canon = np.empty(big_n, dtype=np.int32)  # canonical index of each file node id
    canon[node] = new_of_row
    del pos, seen, new_of_row, perm, key_acq, a, lo, hi, real
    acq_ptr = acq_ptr_from_node_acq(node_acq, n)
    indptr, dst = read_arcs(d / "arcs.parquet", canon, node_acq, node_time, acqs.duration)
    graph = DiscreteGraph(node_acq=node_acq, node_time=node_time, indptr=indptr, dst=dst, acq_ptr=acq_ptr)

    meta: dict = {}
    mpath = d / "meta.json"
    if mpath.exists():
        try:
            meta = json.loads(mpath.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(mpath, f"not valid JSON: {exc}") from None
        if not isinstance(meta, dict):
            raise InputError(mpath, "must hold a JSON object")
        meta.pop("eosp", None)  # the mark of a directory eosp wrote (eosp.ownership): about the files, not the instance
    return Instance(name=name or str(meta.get("name", d.name)), acqs=acqs, unpruned_graph=graph, node_ids=node_ids,
                    meta=meta)


# --------------------------------------------------------------------------- export

def acquisitions_table(acqs: Acquisitions) -> pa.Table:
    n = len(acqs)
    cols = {
        "acq": pa.array(np.arange(n, dtype=np.int32)),
        "duration": pa.array(acqs.duration, pa.float64()),
        "vtw_start": pa.array(acqs.vtw_start, pa.float64()),
        "vtw_end": pa.array(acqs.vtw_end, pa.float64()),
        "utility": pa.array(acqs.utility, pa.float64()),
    }
    if acqs.priority is not None:
        cols["priority"] = pa.array(acqs.priority.astype(np.int8))
    if acqs.lat is not None:
        cols["lat"] = pa.array(acqs.lat, pa.float64())
    if acqs.lon is not None:
        cols["lon"] = pa.array(acqs.lon, pa.float64())
    if acqs.attitude is not None:
        for k, c in enumerate(ATTITUDE_COLUMNS):
            cols[c] = pa.array(acqs.attitude[:, k], pa.float64())
    return pa.table(cols)


INSTANCE_FILES = ("acquisitions.parquet", "nodes.parquet", "arcs.parquet", "meta.json")


INSTANCE_KIND = "instance"  # the mark (eosp.ownership) of the directories write_instance writes, in meta.json


def is_instance_dir(directory: str | Path) -> bool:
    """Whether `directory` was written by :func:`write_instance`: its four files, nothing else, and the mark
    ``"eosp": "instance"`` in its meta.json (a user's directory of the same files is not eosp's)."""
    d = Path(directory)
    try:
        names = {p.name for p in d.iterdir()}
    except OSError:
        return False
    return (names == set(INSTANCE_FILES) and all((d / f).is_file() for f in INSTANCE_FILES)
            and kind_of(d) == INSTANCE_KIND)


def check_instance_out(directory: str | Path, overwrite: bool = False) -> Path:
    """Refuse, before any work, an output directory that :func:`write_instance` must not write
    (:func:`eosp.ownership.check_output`)."""
    d = check_output(directory, INSTANCE_KIND, overwrite, directory=True)
    if d.exists() and not is_instance_dir(d):
        raise InputError(d, "exists and is not an instance directory written by eosp: refusing to replace it "
                            "(it holds other files)")
    return d


def write_instance(inst: Instance, directory: str | Path, overwrite: bool = False) -> Path:
    """Write `inst` as an interchange directory (atomically); `overwrite` replaces only an instance directory."""
    g = inst.unpruned("the interchange format")
    ids = inst.node_ids
    check_instance_out(directory, overwrite)
    with atomic_dir(directory, overwrite=overwrite, owned=is_instance_dir) as tmp:
        pq.write_table(acquisitions_table(inst.acqs), tmp / "acquisitions.parquet")
        pq.write_table(pa.table({"node": pa.array(ids, pa.int32()), "acq": pa.array(g.node_acq, pa.int32()),
                                 "time": pa.array(g.node_time, pa.float64())}), tmp / "nodes.parquet")
        pq.write_table(pa.table({"src": pa.array(ids[g.src()], pa.int32()), "dst": pa.array(ids[g.dst], pa.int32())}),
                       tmp / "arcs.parquet")
        meta = {"name": inst.name, **inst.meta, **json_mark(INSTANCE_KIND)}
        (tmp / "meta.json").write_text(json.dumps(meta, indent=1, sort_keys=True))
    return Path(directory)
