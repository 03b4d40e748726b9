"""The satellite simulator's physics: orbit and pointing geometry, slew-time models.

Below ``eosp.graphs`` (which turns windows and slew times into the discrete graph)
and above nothing but ``eosp.config``.
"""
