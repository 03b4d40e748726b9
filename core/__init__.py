"""EOSP: agile Earth-observation satellite scheduling with GNNs, RL and tree search.

One package: ``eosp.config``, ``eosp.errors``, ``eosp.atomic`` and ``eosp.args`` (the
bottom layer, in the folder core/) and the subpackages that carry the data flow,
instances -> graphs -> shards -> envs -> models -> search/solvers -> training ->
evaluation -> jobs -> cli (each in the repository folder of the same name; the
simulator's geometry and slew models in sim/).  docs/architecture.md has the layers
and their rule: a module imports only from its own layer or the layers below.
"""

__version__ = "0.1.0"
