"""Schedule algorithms on a discrete graph, as typed array kernels (numba): one home for what every solver,
search and the environment's plan features share.

* :mod:`eosp.planning.chain`: a schedule as a path of the graph, its edits (insert, replace, drop one position,
  re-chain the rest) and :class:`~eosp.planning.chain.GraphArrays`, the graph's arrays as one argument;
* :mod:`eosp.planning.insertion`: the operational Greedy's insertion kernel and its orders;
* :mod:`eosp.planning.moves`: insert, swap, ruin and recreate on a complete schedule;
* :mod:`eosp.planning.labels`: the label sweeps (RAMP's and the exact solver's, the window sweep, the backward
  one-label sweep), side by side, and why they differ;
* :mod:`eosp.planning.windows`: window re-planning, a stretch of a schedule swept again.

Directly above :mod:`eosp.graphs`; imports only numpy, numba and eosp.graphs (tests/test_architecture.py), so
that a pass of a constellation is planned with exactly these kernels.
"""
