"""jobs/warmup.py (run by `make demo`): it runs the first commands' code paths and leaves their kernels compiled."""

import numba

from eosp.jobs.warmup import main


def test_warmup_compiles_the_interchange_reader_and_the_solvers(capsys):
    from eosp.instances import interchange

    assert main(["--solvers", "greedy", "ramp"]) == 0
    assert "[warmup] kernels compiled and cached" in capsys.readouterr().out
    kernels = [f for f in vars(interchange).values() if isinstance(f, numba.core.registry.CPUDispatcher)]
    assert kernels and all(k.signatures for k in kernels)  # every reader kernel compiled for its arguments


def test_warmup_refuses_an_unknown_solver(capsys):
    assert main(["--solvers", "greedy", "nope"]) == 2
    assert capsys.readouterr().err.strip() == ("warmup.py: error: --solvers: unknown solver 'nope'; one of beam, "
                                                "exact, greedy, lns, mcts, policy, ramp, random, sample")
