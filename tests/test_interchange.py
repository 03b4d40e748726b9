"""The interchange contract: lossless round trips, foreign numbering, and one clear error per bad input."""

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eosp.errors import InputError
from eosp.instances.interchange import read_instance, write_instance
from eosp.instances.schedule import Schedule, check, from_internal_nodes, read_schedule, write_schedule
from eosp.solvers.random_walk import RandomConfig
from eosp.solvers.random_walk import solve as random_solve
from tests.conftest import generated
from tests.synthetic import synthetic_instance


def assert_same_instance(a, b):
    for f in ("duration", "vtw_start", "vtw_end", "utility", "priority", "lat", "lon", "attitude"):
        x, y = getattr(a.acqs, f), getattr(b.acqs, f)
        assert (x is None) == (y is None), f
        if x is not None:
            np.testing.assert_array_equal(x, y, err_msg=f)
    for f in ("node_acq", "node_time", "indptr", "dst", "acq_ptr"):
        np.testing.assert_array_equal(getattr(a.unpruned(), f), getattr(b.unpruned(), f), err_msg=f)
    np.testing.assert_array_equal(a.node_ids, b.node_ids)


def test_export_import_export_identical(tmp_path):
    inst = generated("uniform", 12, 0)
    write_instance(inst, tmp_path / "a")
    back = read_instance(tmp_path / "a")
    assert_same_instance(inst, back)
    assert back.meta["seed"] == 0
    write_instance(back, tmp_path / "b")
    for f in ("acquisitions.parquet", "nodes.parquet", "arcs.parquet"):
        assert pq.read_table(tmp_path / "a" / f).equals(pq.read_table(tmp_path / "b" / f))


def _write_foreign(inst, d, seed=0):
    """Write an instance the way another tool might: shuffled node ids and rows, int64 ids."""
    rng = np.random.default_rng(seed)
    g = inst.unpruned()
    big_n = g.n_nodes
    new_id = np.concatenate([[0], 1 + rng.permutation(big_n - 1)])
    d.mkdir()
    a = inst.acqs
    order = rng.permutation(inst.n_acq)
    pq.write_table(pa.table({"acq": order.astype(np.int64), "duration": a.duration[order],
                             "vtw_start": a.vtw_start[order], "vtw_end": a.vtw_end[order],
                             "utility": a.utility[order]}), d / "acquisitions.parquet")
    rows = rng.permutation(big_n)
    pq.write_table(pa.table({"node": new_id[rows], "acq": g.node_acq[rows].astype(np.int64),
                             "time": g.node_time[rows]}), d / "nodes.parquet")
    arcs = rng.permutation(g.n_arcs)
    pq.write_table(pa.table({"src": new_id[g.src()][arcs].astype(np.int32),
                             "dst": new_id[g.dst][arcs].astype(np.int32)}), d / "arcs.parquet")
    return new_id


@settings(max_examples=15, deadline=None)
@given(n=st.integers(1, 7), seed=st.integers(0, 1000))
def test_foreign_numbering_and_row_order_is_canonicalized(tmp_path_factory, n, seed):
    inst = synthetic_instance(n, seed)
    d = tmp_path_factory.mktemp("foreign") / "inst"
    new_id = _write_foreign(inst, d, seed)
    back = read_instance(d)
    for f in ("node_acq", "node_time", "indptr", "dst"):
        np.testing.assert_array_equal(getattr(inst.unpruned(), f), getattr(back.unpruned(), f))
    np.testing.assert_array_equal(back.node_ids, new_id)
    # a schedule found on the imported instance refers to the file's own node ids and validates
    sol = random_solve(back, RandomConfig(seed=seed))
    sched = from_internal_nodes(back, sol.nodes)
    assert check(back, sched).feasible
    # the same path, written with the original ids, is feasible for the original instance
    assert check(inst, Schedule(sched.acq, np.argsort(new_id)[sched.node].astype(np.int32), sched.start)).feasible


def test_schedule_files_parquet_and_jsonl(tmp_path):
    inst = generated("uniform", 12, 0)
    sched = from_internal_nodes(inst, random_solve(inst, RandomConfig(seed=3)).nodes)
    for name in ("s.parquet", "s.jsonl"):
        write_schedule(sched, tmp_path / name)
        back = read_schedule(tmp_path / name)
        np.testing.assert_array_equal(back.node, sched.node)
        np.testing.assert_array_equal(back.start, sched.start)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(2, 8), seed=st.integers(0, 10_000))
def test_checker_accepts_walks_and_rejects_broken_ones(n, seed):
    inst = synthetic_instance(n, seed)
    nodes = random_solve(inst, RandomConfig(seed=seed)).nodes
    sched = from_internal_nodes(inst, nodes)
    v = check(inst, sched)
    assert v.feasible and v.value == pytest.approx(inst.acqs.utility[sched.acq].sum(), rel=1e-12)
    if len(sched) >= 2:
        dup = Schedule(np.r_[sched.acq, sched.acq[:1]], np.r_[sched.node, sched.node[:1]],
                       np.r_[sched.start, sched.start[:1]])
        assert not check(inst, dup).feasible
        rev = Schedule(sched.acq[::-1].copy(), sched.node[::-1].copy(), sched.start[::-1].copy())
        assert not check(inst, rev).feasible
    if len(sched) >= 1:
        # starting earlier than the node reached by the arc is infeasible
        g = inst.unpruned()
        last = int(nodes[-1])
        if last - 1 >= g.acq_ptr[g.node_acq[last]]:
            prev_nodes = nodes.copy()
            prev_nodes[-1] = last - 1
            early = from_internal_nodes(inst, prev_nodes)
            row = g.dst[g.indptr[nodes[-2] if len(nodes) > 1 else 0]:g.indptr[(nodes[-2] if len(nodes) > 1 else 0) + 1]]
            reached = row[g.node_acq[row] == g.node_acq[last]]
            if reached.size and reached[0] == last:
                assert not check(inst, early).feasible


# --------------------------------------------------------------------------- bad inputs

@pytest.fixture
def inst_dir(tmp_path):
    return write_instance(generated("uniform", 12, 0), tmp_path / "inst")


def _edit(d, name, fn):
    t = pq.read_table(d / name)
    pq.write_table(fn(t), d / name)


def _set(table, col, row, value):
    arr = table.column(col).to_numpy().copy()
    arr[row] = value
    return table.set_column(table.column_names.index(col), col, pa.array(arr, table.schema.field(col).type))


BAD = [
    ("missing column", "acquisitions.parquet", lambda t: t.drop_columns(["utility"]), "utility", None,
     "missing required column"),
    ("extra column", "acquisitions.parquet", lambda t: t.append_column("colour", pa.array(["x"] * t.num_rows)),
     "colour", None, "unexpected column"),
    ("wrong dtype", "nodes.parquet", lambda t: t.set_column(1, "acq", pa.array(t.column("acq").to_numpy()
                                                                               .astype(float))),
     "acq", None, "wrong type"),
    ("NaN utility", "acquisitions.parquet", lambda t: _set(t, "utility", 4, np.nan), "utility", 4, "NaN"),
    ("zero utility", "acquisitions.parquet", lambda t: _set(t, "utility", 3, 0.0), "utility", 3, "> 0"),
    ("negative duration", "acquisitions.parquet", lambda t: _set(t, "duration", 2, -1.0), "duration", 2, "> 0"),
    ("window end before start", "acquisitions.parquet",
     lambda t: _set(t, "vtw_end", 5, t.column("vtw_start")[5].as_py() - 1.0), "vtw_end", 5, "ends before it starts"),
    ("node outside window", "nodes.parquet", lambda t: _set(t, "time", 7, 1e7), "time", 7, "outside its window"),
    ("dangling acquisition", "nodes.parquet", lambda t: _set(t, "acq", 9, 999), "acq", 9, "dangling"),
    ("dangling node", "arcs.parquet", lambda t: _set(t, "dst", 11, 10 ** 8), "dst", 11, "dangling"),
]


@pytest.mark.parametrize("label,file,edit,col,row,msg", BAD, ids=[b[0] for b in BAD])
def test_bad_input_names_file_column_row(inst_dir, label, file, edit, col, row, msg):
    _edit(inst_dir, file, edit)
    with pytest.raises(InputError) as info:
        read_instance(inst_dir)
    err = info.value
    assert err.file.endswith(file) and err.column == col and msg in err.message
    if row is not None:
        assert err.row == row
    assert file in str(err) and f"'{col}'" in str(err)


def test_arc_back_in_time(inst_dir):
    nodes = pq.read_table(inst_dir / "nodes.parquet")
    time = nodes.column("time").to_numpy()
    acq = nodes.column("acq").to_numpy()
    late = int(np.argmax(time))
    early = int(np.flatnonzero((acq >= 0) & (acq != acq[late]))[np.argmin(time[(acq >= 0) & (acq != acq[late])])])
    arcs = pq.read_table(inst_dir / "arcs.parquet")
    src = arcs.column("src").to_numpy().copy()
    dst = arcs.column("dst").to_numpy().copy()
    src[20], dst[20] = late, early
    pq.write_table(pa.table({"src": pa.array(src, pa.int32()), "dst": pa.array(dst, pa.int32())}),
                   inst_dir / "arcs.parquet")
    with pytest.raises(InputError, match="back in time") as info:
        read_instance(inst_dir)
    assert info.value.row == 20 and info.value.column == "dst"


def test_two_arcs_to_the_same_acquisition(inst_dir):
    arcs = pq.read_table(inst_dir / "arcs.parquet")
    dup = pa.concat_tables([arcs, arcs.slice(40, 1)])
    pq.write_table(dup, inst_dir / "arcs.parquet")
    with pytest.raises(InputError, match="same acquisition") as info:
        read_instance(inst_dir)
    assert info.value.row == arcs.num_rows


def test_truncated_parquet(inst_dir):
    raw = (inst_dir / "arcs.parquet").read_bytes()
    (inst_dir / "arcs.parquet").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(InputError, match="not a readable Parquet file") as info:
        read_instance(inst_dir)
    assert info.value.file.endswith("arcs.parquet")


def test_bad_meta_json(inst_dir):
    (inst_dir / "meta.json").write_text("{not json")
    with pytest.raises(InputError, match="not valid JSON"):
        read_instance(inst_dir)


def test_export_leaves_nothing_half_written(tmp_path, monkeypatch):
    import eosp.instances.interchange as ic

    inst = generated("uniform", 12, 0)

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(ic, "acquisitions_table", boom)
    with pytest.raises(RuntimeError):
        write_instance(inst, tmp_path / "out")
    assert list(tmp_path.iterdir()) == []


def test_meta_json_round_trip(tmp_path):
    inst = generated("uniform", 12, 0)
    write_instance(inst, tmp_path / "a")
    meta = json.loads((tmp_path / "a" / "meta.json").read_text())
    assert meta["generator"] == "eosp-open-sim" and meta["family"] == "uniform"


def test_acquisition_without_node(inst_dir):
    nodes = pq.read_table(inst_dir / "nodes.parquet")
    acq = nodes.column("acq").to_numpy()
    keep = acq != 5
    # drop acquisition 5's nodes and the arcs touching them; keep the ids dense
    ids = nodes.column("node").to_numpy()
    new = np.full(ids.max() + 1, -1)
    new[ids[keep]] = np.arange(keep.sum())
    pq.write_table(pa.table({"node": new[ids[keep]].astype(np.int32), "acq": acq[keep],
                             "time": nodes.column("time").to_numpy()[keep]}), inst_dir / "nodes.parquet")
    arcs = pq.read_table(inst_dir / "arcs.parquet")
    src, dst = new[arcs.column("src").to_numpy()], new[arcs.column("dst").to_numpy()]
    ok = (src >= 0) & (dst >= 0)
    pq.write_table(pa.table({"src": src[ok].astype(np.int32), "dst": dst[ok].astype(np.int32)}),
                   inst_dir / "arcs.parquet")
    with pytest.raises(InputError, match="acquisition 5 has no node"):
        read_instance(inst_dir)


def test_schedule_ids_out_of_int32_range(tmp_path):
    from eosp.errors import InputError as IE

    pq.write_table(pa.table({"acq": pa.array([2**32], pa.int64()), "node": pa.array([1], pa.int64()),
                             "start": [0.0]}), tmp_path / "s.parquet")
    with pytest.raises(IE, match="out of range") as info:
        read_schedule(tmp_path / "s.parquet")
    assert info.value.column == "acq" and info.value.row == 0
    (tmp_path / "s.jsonl").write_text('{"acq": 1, "node": 36893488147419103232, "start": 0.0}\n')
    with pytest.raises(IE, match="out of range"):
        read_schedule(tmp_path / "s.jsonl")


def test_input_error_survives_pickling():
    """Ray sends exceptions between processes (by __reduce__): the message must come through intact."""
    cls, args = InputError("x.parquet", "bad value", column="utility", row=4).__reduce__()
    err = cls(*args)
    assert str(err) == "x.parquet: column 'utility', row 4: bad value" and err.row == 4


# --------------------------------------------------------------------------- streamed arcs

def _reference_csr(inst_dir):
    """The arcs as the whole-file reader built them: all arcs in memory, lexsorted (reference)."""
    nodes = pq.read_table(inst_dir / "nodes.parquet")
    ids, acq, time = (nodes.column(c).to_numpy() for c in ("node", "acq", "time"))
    perm = np.lexsort((time, np.where(ids == 0, -1, acq)))
    canon = np.empty(len(ids), dtype=np.int64)
    canon[ids[perm]] = np.arange(len(ids))
    arcs = pq.read_table(inst_dir / "arcs.parquet")
    s, d = canon[arcs.column("src").to_numpy()], canon[arcs.column("dst").to_numpy()]
    order = np.lexsort((d, s))
    indptr = np.zeros(len(ids) + 1, dtype=np.int64)
    np.cumsum(np.bincount(s, minlength=len(ids)), out=indptr[1:])
    return indptr, d[order].astype(np.int32)


@pytest.mark.parametrize("seed", [0, 1])
def test_streamed_arcs_equal_whole_file_reading(tmp_path, monkeypatch, seed):
    """Many row groups, tiny batches, shuffled foreign ids: the same CSR as reading everything at once."""
    import eosp.instances.interchange as ic

    inst = synthetic_instance(7, seed)
    d = tmp_path / "inst"
    _write_foreign(inst, d, seed)
    pq.write_table(pq.read_table(d / "arcs.parquet"), d / "arcs.parquet", row_group_size=13)
    assert pq.ParquetFile(d / "arcs.parquet").metadata.num_row_groups > 2
    monkeypatch.setattr(ic, "BATCH_ROWS", 5)
    back = read_instance(d)
    indptr, dst = _reference_csr(d)
    assert back.unpruned().indptr.dtype == np.int64 and back.unpruned().dst.dtype == np.int32
    np.testing.assert_array_equal(back.unpruned().indptr, indptr)
    np.testing.assert_array_equal(back.unpruned().dst, dst)
    np.testing.assert_array_equal(back.unpruned().dst, inst.unpruned().dst)


def test_streamed_error_names_the_file_row_in_a_later_batch(inst_dir, monkeypatch):
    import eosp.instances.interchange as ic

    arcs = pq.read_table(inst_dir / "arcs.parquet")
    row = arcs.num_rows - 3
    pq.write_table(_set(arcs, "src", row, -5), inst_dir / "arcs.parquet", row_group_size=100)
    monkeypatch.setattr(ic, "BATCH_ROWS", 17)
    with pytest.raises(InputError, match="dangling") as info:
        read_instance(inst_dir)
    assert info.value.row == row and info.value.column == "src"


def test_first_rule_broken_is_reported_whatever_the_batch(inst_dir, monkeypatch):
    """A later row breaking an earlier rule wins over an earlier row breaking a later rule (as before)."""
    import eosp.instances.interchange as ic

    arcs = pq.read_table(inst_dir / "arcs.parquet")
    arcs = _set(arcs, "dst", 2, 0)  # arc into the source (rule 3)
    arcs = _set(arcs, "dst", arcs.num_rows - 1, 10 ** 6)  # dangling (rule 2), in the last batch
    pq.write_table(arcs, inst_dir / "arcs.parquet", row_group_size=50)
    monkeypatch.setattr(ic, "BATCH_ROWS", 7)
    with pytest.raises(InputError, match="dangling") as info:
        read_instance(inst_dir)
    assert info.value.row == arcs.num_rows - 1


def test_null_arc_is_reported_with_its_row(inst_dir):
    arcs = pq.read_table(inst_dir / "arcs.parquet")
    dst = arcs.column("dst").to_pylist()
    dst[33] = None
    pq.write_table(pa.table({"src": arcs.column("src"), "dst": pa.array(dst, pa.int32())}),
                   inst_dir / "arcs.parquet", row_group_size=20)
    with pytest.raises(InputError, match="null") as info:
        read_instance(inst_dir)
    assert info.value.row == 33 and info.value.column == "dst"


def test_corrupt_row_group_is_reported_with_its_index(inst_dir):
    pq.write_table(pq.read_table(inst_dir / "arcs.parquet"), inst_dir / "arcs.parquet", row_group_size=100)
    md = pq.ParquetFile(inst_dir / "arcs.parquet").metadata
    assert md.num_row_groups > 3
    cc = md.row_group(2).column(1)
    raw = bytearray((inst_dir / "arcs.parquet").read_bytes())
    raw[cc.data_page_offset:cc.data_page_offset + cc.total_compressed_size] = b"\xff" * cc.total_compressed_size
    (inst_dir / "arcs.parquet").write_bytes(bytes(raw))
    with pytest.raises(InputError, match=f"row group 2 of {md.num_row_groups}") as info:
        read_instance(inst_dir)
    assert info.value.file.endswith("arcs.parquet") and "\n" not in str(info.value)


def test_arcs_too_large_for_memory_fail_before_allocating(inst_dir, monkeypatch):
    import eosp.memory

    monkeypatch.setattr(eosp.memory, "available_bytes", lambda: 1000)
    with pytest.raises(InputError, match="too large for the memory available") as info:
        read_instance(inst_dir)
    msg = str(info.value)
    assert "arcs.parquet" in msg and "needs about" in msg and "GiB available" in msg and "\n" not in msg


def test_available_memory_is_known_here():
    from eosp.memory import available_bytes

    have = available_bytes()
    assert have is None or have > 0
