"""EOSP: agile Earth-observation satellite scheduling with GNNs, RL and tree search.

This package holds what every step shares: the typed configuration, the CLI and
the user-facing errors.  The data flow lives in the sibling packages:
instances -> graphs -> shards -> envs -> models -> solvers/search -> evaluation.
"""

__version__ = "0.1.0"
