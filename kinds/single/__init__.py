"""The single-pass kind (kind.py): an interchange directory or a shard instance, the solvers of eosp.solvers."""
