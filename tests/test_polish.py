"""Polishing complete schedules: feasible for the independent checker, never worse, replayable in the env."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eosp.config import EnvConfig
from eosp.envs.eosp_env import EOSPEnv
from eosp.envs.sources import FixedSource, prepare_instance
from eosp.instances.schedule import check, from_internal_nodes
from eosp.search.polish import Polisher
from eosp.solvers.base import objective_weights, run_solver
from tests.conftest import generated


def _random_episode(prepared, rng) -> np.ndarray:
    """A random complete episode of the environment (uniform over allowed actions)."""
    env = EOSPEnv(EnvConfig(max_acquisitions=0), source=FixedSource(prepared))
    obs, _ = env.reset(seed=0)
    done = not obs["action_mask"].any()
    while not done:
        a = int(rng.choice(np.flatnonzero(obs["action_mask"])))
        obs, _, done, _, _ = env.step(a)
        done = done or not obs["action_mask"].any()
    return env.path()


def _replay(prepared, actions) -> np.ndarray:
    env = EOSPEnv(EnvConfig(max_acquisitions=0), source=FixedSource(prepared))
    env.reset(seed=0)
    for a in actions:
        assert env.action_mask()[a], "a polished action the environment does not allow"
        env.step(int(a))
    return env.path()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(family=st.sampled_from(["uniform", "clusters", "conflict"]), seed=st.integers(0, 3),
       walk=st.integers(0, 10_000), mode=st.sampled_from(["unitary", "utility"]))
def test_polished_random_schedules_are_feasible_never_worse_and_replay(family, seed, walk, mode):
    inst = generated(family, 40, seed)
    prepared = prepare_instance(inst, True)
    weights = objective_weights(inst, mode)
    pol = Polisher(prepared.eg, weights)
    nodes = _random_episode(prepared, np.random.default_rng(walk))
    out = pol(nodes)
    verdict = check(inst, from_internal_nodes(inst, out))
    assert verdict.feasible, verdict.reason
    assert pol.value(out) >= pol.value(nodes) - 1e-9
    assert len(set(inst.node_acq[out].tolist())) == len(out)
    value, actions = pol.actions(inst.node_acq[nodes].tolist())
    assert value == pytest.approx(pol.value(out))
    assert list(_replay(prepared, actions)) == list(out)  # the env plays exactly the polished path
    assert pol.value(pol(out)) == pytest.approx(pol.value(out))  # a second polish finds nothing more


@pytest.mark.parametrize("family,seed", [("uniform", 1), ("conflict", 2)])
def test_a_schedule_missing_one_acquisition_gets_it_back(family, seed):
    inst = generated(family, 60, seed)
    prepared = prepare_instance(inst, True)
    ramp = run_solver("ramp", inst, mode="unitary")
    pol = Polisher(prepared.eg, objective_weights(inst, "unitary"))
    tried = 0
    for k in range(len(ramp.nodes)):
        try:  # the rest re-reached without it, as a search would have played it (the pruned graph may lack an arc)
            nodes = pol.nodes_of(np.delete(inst.node_acq[ramp.nodes], k))
        except ValueError:
            continue
        assert pol.value(pol(nodes)) >= ramp.value
        tried += 1
    assert tried >= len(ramp.nodes) // 2


def test_the_swap_move_trades_one_low_utility_acquisition_for_a_higher_one():
    inst = generated("conflict", 60, 4)
    prepared = prepare_instance(inst, True)
    w = objective_weights(inst, "utility")
    pol = Polisher(prepared.eg, w)
    ramp = run_solver("ramp", inst, mode="utility")
    gains = 0
    for k in range(len(ramp.nodes)):
        # replace acquisition k by every other one that fits there alone and is worth less: the swap restores it
        rest = np.delete(ramp.nodes, k)
        for j in np.argsort(w)[: inst.n_acq // 2]:
            if j in set(inst.node_acq[ramp.nodes].tolist()) or w[j] >= w[inst.node_acq[ramp.nodes[k]]]:
                continue
            try:
                cand = pol.nodes_of(np.insert(inst.node_acq[rest], k, j))
            except ValueError:
                continue
            if not check(inst, from_internal_nodes(inst, cand)).feasible:
                continue
            assert pol.value(pol(cand)) > pol.value(cand)
            gains += 1
            break
    assert gains > 0


def test_on_the_unpruned_graph_the_polish_escapes_a_pruned_dead_end():
    """A pruned path can end at a node whose kept arcs all lead to acquisitions already scheduled (the pruning
    ignores the exclusion); the unpruned arcs continue it, and the result is feasible for the checker."""
    inst = generated("uniform", 60, 5)
    prepared = prepare_instance(inst, True)
    w = objective_weights(inst, "utility")
    pruned, full = Polisher(prepared.eg, w), Polisher(inst.unpruned(), w)
    ramp = run_solver("ramp", inst, mode="utility")
    for cut in (1, 2, len(ramp.nodes) // 3):
        head = ramp.nodes[:cut]  # a schedule stopped early, as a dead end leaves it
        out = full(head)
        assert check(inst, from_internal_nodes(inst, out)).feasible
        assert full.value(out) >= pruned.value(pruned(head)) - 1e-9
        assert full.value(out) >= 0.9 * ramp.value


@pytest.mark.parametrize("mode", ["unitary", "utility"])
def test_refine_is_never_worse_feasible_and_deterministic(mode):
    inst = generated("conflict", 60, 6)
    pol = Polisher(inst.unpruned(), objective_weights(inst, mode))
    greedy = run_solver("greedy", inst, mode=mode)
    a = pol.refine(greedy.nodes, iterations=640, seed=3)
    b = pol.refine(greedy.nodes, iterations=640, seed=3)
    assert list(a) == list(b)
    assert pol.value(a) >= greedy.value - 1e-9
    assert check(inst, from_internal_nodes(inst, a)).feasible


def test_lns_solver_beats_greedy_within_its_time_limit():
    import time

    inst = generated("conflict", 80, 7)
    greedy = run_solver("greedy", inst, mode="unitary")
    run_solver("lns", inst, mode="unitary", iterations=64)  # numba's compilation is set-up, not search time
    t0 = time.perf_counter()
    sol = run_solver("lns", inst, mode="unitary", time_limit=1.0)
    assert time.perf_counter() - t0 < 1.0 + 1.0
    assert check(inst, from_internal_nodes(inst, sol.nodes)).feasible
    assert sol.value >= greedy.value and sol.info["rounds"] > 0
    exact = run_solver("exact", inst, mode="unitary")
    assert sol.value <= exact.value


def test_learned_searches_refine_within_the_time_limit():
    """With a time limit the searches leave `refine` of it to ruin and recreate: the answer is feasible, at
    least the unrefined search's, and the limit holds."""
    import time

    import torch

    from eosp.config import ModelConfig
    from eosp.models.agent import EOSPAgent

    torch.manual_seed(0)
    agent = EOSPAgent(ModelConfig(hidden_dim=8, n_layers=2, heads=1)), EnvConfig(reward="unitary"), {}
    inst = generated("uniform", 60, 8)
    for name in ("sample", "beam", "mcts"):
        run_solver(name, inst, mode="unitary", agent=agent, time_limit=0.05)  # compilation: set-up, not search
        t0 = time.perf_counter()
        sol = run_solver(name, inst, mode="unitary", agent=agent, time_limit=1.0)
        assert time.perf_counter() - t0 < 1.0 + 1.5
        assert check(inst, from_internal_nodes(inst, sol.nodes)).feasible
        plain = run_solver(name, inst, mode="unitary", agent=agent, time_limit=1.0, refine=0.0)
        assert sol.value >= plain.value - 1  # another search time, but refining rarely loses what it had
