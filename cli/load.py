"""Reading the instance a command names: an interchange directory, or ``SHARD.parquet#INDEX`` (info, solve, plot,
report)."""

from __future__ import annotations

from eosp.errors import InputError


def load_instance(path: str):
    """An instance from an interchange directory, or `SHARD.parquet#INDEX` from a shard."""
    from eosp.instances.interchange import read_instance

    if "#" in path:
        from eosp.shards.io import ShardReader

        file, _, idx = path.rpartition("#")
        if not idx.isdigit():
            raise InputError(path, f"expected SHARD.parquet#INDEX with INDEX a number >= 0, got {idx!r}")
        return ShardReader(file).read(int(idx))
    return read_instance(path)
