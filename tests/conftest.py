import functools
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest  # noqa: E402

from eosp.config import family_config  # noqa: E402


@functools.lru_cache(maxsize=None)
def generated(family: str = "uniform", n: int = 12, seed: int = 0, step: float = 2.0, slew: str = "piecewise"):
    """A small generated instance (cached: tests must not modify it)."""
    from eosp.instances.generator import generate

    return generate(family_config(family, n, seed, graph={"step_s": step}, satellite={"slew_model": slew}))


@pytest.fixture
def tiny():
    return generated("uniform", 12, 0, 2.0)
