"""eosp.cli.warmup (run by `make demo`): every kind's first commands, their kernels left compiled."""

import numba

from eosp.cli.warmup import WARM, main


def test_every_registered_kind_is_warmed():
    from eosp.kinds import REGISTRY

    assert set(WARM) == set(REGISTRY)  # a new kind adds its first commands to the warm-up


def test_warmup_compiles_the_kernels_of_the_kinds_it_runs(capsys):
    from eosp.kinds.eosbench import passes

    assert main(["--kinds", "eosbench", "onera"]) == 0
    assert "[warmup] kernels of every kind compiled and cached" in capsys.readouterr().out
    assert isinstance(passes._arcs, numba.core.registry.CPUDispatcher) and passes._arcs.signatures  # the pass arcs


def test_warmup_refuses_an_unknown_kind(capsys):
    assert main(["--kinds", "fleet", "nope"]) == 2
    assert capsys.readouterr().err.strip() == ("python -m eosp.cli.warmup: error: --kinds: unknown kind 'nope'; "
                                                "one of single-pass, fleet, onera, eosbench, regional-coverage")
