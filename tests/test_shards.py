"""Parquet shards: round trip, schema checks, truncated and foreign files."""

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from eosp.errors import InputError
from eosp.shards.io import SCHEMA_VERSION, ShardReader, read_instances, write_shard
from eosp.solvers.greedy import solve as greedy
from tests.conftest import generated
from tests.test_interchange import assert_same_instance


@pytest.fixture
def shard(tmp_path):
    insts = [generated("uniform", 12, s) for s in range(3)]
    return write_shard(tmp_path / "s.parquet", insts), insts


def test_round_trip(shard):
    path, insts = shard
    reader = ShardReader(path)
    assert len(reader) == 3 and reader.names() == [i.name for i in insts]
    for a, b in zip(insts, read_instances([path])):
        assert_same_instance(a, b)
        np.testing.assert_array_equal(a.pruned().dst, b.pruned().dst)
        np.testing.assert_array_equal(a.pruned().indptr, b.pruned().indptr)
        np.testing.assert_array_equal(a.node_attitude, b.node_attitude)
        assert b.meta["family"] == "uniform"


def test_pruned_only_shard(tmp_path):
    inst = generated("uniform", 12, 0)
    path = write_shard(tmp_path / "p.parquet", [inst], include_unpruned=False)
    back = ShardReader(path).read(0)
    assert back.unpruned_graph is None
    np.testing.assert_array_equal(back.pruned().dst, inst.pruned().dst)
    np.testing.assert_array_equal(back.node_acq, inst.node_acq)
    # written again asking for the unpruned arcs: the pruned ones never stand in for them
    again = ShardReader(write_shard(tmp_path / "q.parquet", [back], include_unpruned=True)).read(0)
    assert again.unpruned_graph is None
    np.testing.assert_array_equal(again.pruned().dst, inst.pruned().dst)


def test_truncated_shard(shard, tmp_path):
    path, _ = shard
    bad = tmp_path / "cut.parquet"
    bad.write_bytes(path.read_bytes()[:-100])
    with pytest.raises(InputError, match="truncated"):
        ShardReader(bad)


def test_foreign_parquet(tmp_path):
    p = tmp_path / "f.parquet"
    pq.write_table(pa.table({"x": [1, 2]}), p)
    with pytest.raises(InputError, match="not an EOSP shard"):
        ShardReader(p)


def test_unknown_schema_version(shard, tmp_path):
    path, _ = shard
    t = pq.read_table(path)
    md = dict(t.schema.metadata)
    md[b"eosp.schema_version"] = str(SCHEMA_VERSION + 1).encode()
    p = tmp_path / "v.parquet"
    pq.write_table(t.replace_schema_metadata(md), p)
    with pytest.raises(InputError, match="unknown shard schema version"):
        ShardReader(p)


def test_corrupted_arcs_name_column_and_row(shard, tmp_path):
    path, _ = shard
    t = pq.read_table(path)
    col = t.column("pruned_dst").to_pylist()
    col[1] = [v if k else 10 ** 7 for k, v in enumerate(col[1])]
    t = t.set_column(t.schema.get_field_index("pruned_dst"), "pruned_dst", pa.array(col, pa.list_(pa.int32())))
    p = tmp_path / "c.parquet"
    pq.write_table(t, p, row_group_size=1)
    with pytest.raises(InputError) as info:
        ShardReader(p).read(1)
    assert info.value.column == "pruned_dst" and info.value.row == 1 and "dangling" in info.value.message


def test_reading_without_unpruned_arcs_skips_them(shard):
    path, insts = shard
    back = ShardReader(path).read(1, unpruned=False)
    assert back.unpruned_graph is None
    np.testing.assert_array_equal(back.pruned().dst, insts[1].pruned().dst)
    with pytest.raises(InputError, match="the greedy solver needs the unpruned arcs"):
        back.unpruned("the greedy solver")
    with pytest.raises(InputError, match="unpruned"):
        greedy(back)


def test_shard_too_large_for_memory_fails_in_one_line(shard, monkeypatch):
    import eosp.memory

    monkeypatch.setattr(eosp.memory, "available_bytes", lambda: 1000)
    with pytest.raises(InputError, match="too large for the memory available") as info:
        ShardReader(shard[0]).read(0)
    assert "needs about" in str(info.value) and "\n" not in str(info.value)


def test_shards_pruned_by_the_papers_rule_are_refused(shard, tmp_path):
    path, _ = shard
    t = pq.read_table(path)
    md = dict(t.schema.metadata)
    md[b"eosp.schema_version"] = b"1"
    p = tmp_path / "v1.parquet"
    pq.write_table(t.replace_schema_metadata(md), p)
    with pytest.raises(InputError, match="schema version 1.*build it again"):
        ShardReader(p)
