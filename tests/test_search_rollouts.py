"""Batched sampling and beam search: never below the policy, anytime, deterministic, feasible."""

from __future__ import annotations

import time

import pytest
import torch

from eosp.config import EnvConfig, ModelConfig
from eosp.instances.schedule import check, from_internal_nodes
from eosp.models.agent import EOSPAgent
from eosp.solvers.base import run_solver
from tests.conftest import generated


@pytest.fixture(scope="module")
def agent():
    torch.manual_seed(3)
    return EOSPAgent(ModelConfig(hidden_dim=8, n_layers=2, heads=1, value_scale=10.0)), EnvConfig(reward="unitary"), {}


@pytest.mark.parametrize("family,n,seed", [("uniform", 30, 1), ("conflict", 30, 2)])
def test_sample_and_beam_never_below_the_policy_and_feasible(agent, family, n, seed):
    inst = generated(family, n, seed)
    policy = run_solver("policy", inst, mode="unitary", agent=agent, incumbent=False,
                        polish=False)  # the greedy episode itself
    one = run_solver("sample", inst, mode="unitary", agent=agent, samples=1, polish=False)
    assert one.value == policy.value and list(one.nodes) == list(policy.nodes)  # the first episode is greedy
    polished = run_solver("sample", inst, mode="unitary", agent=agent, samples=1)
    assert polished.value >= policy.value
    many = run_solver("sample", inst, mode="unitary", agent=agent, samples=16, seed=5)
    again = run_solver("sample", inst, mode="unitary", agent=agent, samples=16, seed=5)
    assert list(many.nodes) == list(again.nodes) and many.info["episodes"] == 16
    bm = run_solver("beam", inst, mode="unitary", agent=agent, beam_width=3)
    ramp = run_solver("ramp", inst, mode="unitary")
    for sol in (polished, many, bm):
        assert policy.value <= sol.value <= ramp.value + 1  # pruned-graph optimum is what RAMP finds here
        verdict = check(inst, from_internal_nodes(inst, sol.nodes))
        assert verdict.feasible and verdict.n == len(sol.nodes) == sol.value  # unitary: the value is the count


def test_time_limits_are_honoured_and_the_answer_is_complete(agent):
    inst = generated("clusters", 60, 3)
    for name, kw in (("sample", {"samples": 8}), ("beam", {"beam_width": 8}), ("mcts", {})):
        t0 = time.perf_counter()
        sol = run_solver(name, inst, mode="unitary", agent=agent, time_limit=0.5, **kw)
        assert time.perf_counter() - t0 < 0.5 + 1.5  # one batched step past the deadline at most (+ set-up)
        assert check(inst, from_internal_nodes(inst, sol.nodes)).feasible and len(sol.nodes) > 0


def test_bad_search_sizes_are_refused(agent, tmp_path, capsys):
    from eosp.cli import main
    from eosp.instances.interchange import write_instance

    inst = generated("uniform", 12, 0)
    with pytest.raises(ValueError, match=r"SampleConfig.samples: must be >= 1, got 0"):
        run_solver("sample", inst, mode="unitary", agent=agent, samples=0)
    with pytest.raises(ValueError, match=r"BeamConfig.beam_width: must be >= 1"):
        run_solver("beam", inst, mode="unitary", agent=agent, beam_width=0)
    with pytest.raises(ValueError, match=r"MctsConfig.budget: must be >= 0"):
        run_solver("mcts", inst, mode="unitary", agent=agent, budget=-1)
    write_instance(inst, tmp_path / "inst")
    with pytest.raises(SystemExit) as exc:  # the flag's own check (argparse): exit status 2, one line
        main(["solve", str(tmp_path / "inst"), "--solver", "sample", "--samples", "0", "--out",
              str(tmp_path / "s.parquet")])
    assert exc.value.code == 2
    assert "--samples: must be >= 1, got 0" in capsys.readouterr().err
    assert not (tmp_path / "s.parquet").exists()


def test_every_search_takes_a_lexicographic_model():
    """Per-class value heads are weighed by the class utilities: MCTS no longer refuses them."""
    torch.manual_seed(4)
    lex = (EOSPAgent(ModelConfig(hidden_dim=8, n_layers=1, heads=1, n_values=7, value_scale=5.0)),
           EnvConfig(reward="lexicographic"), {})
    inst = generated("conflict", 30, 6)
    policy = run_solver("policy", inst, mode="utility", agent=lex, polish=False)
    for name, kw in (("mcts", {"budget": 8}), ("sample", {"samples": 4}), ("beam", {"beam_width": 2})):
        sol = run_solver(name, inst, mode="utility", agent=lex, **kw)
        assert check(inst, from_internal_nodes(inst, sol.nodes)).feasible
        assert sol.value >= policy.value * (1 - 1e-12)


def test_the_policy_refuses_a_time_limit_and_the_searches_take_one(agent):
    """policy is one episode (one pass): a time limit is refused, never silently ignored."""
    inst = generated("uniform", 12, 0)
    with pytest.raises(ValueError, match="solver 'policy' takes no time_limit"):
        run_solver("policy", inst, agent=agent, time_limit=1.0)
    for name in ("sample", "beam", "mcts"):
        assert run_solver(name, inst, mode="unitary", agent=agent, time_limit=5.0).nodes.size > 0
    with pytest.raises(ValueError, match="solver 'beam' has no option 'samples'; its options: .*beam_width"):
        run_solver("beam", inst, agent=agent, samples=4)


def test_past_its_deadline_the_best_episode_takes_no_more_episodes():
    """Improving an episode can be slow (polishing one costs ~0.2 s at 1000 acquisitions) and the episodes of a
    sampling round finish together: past the deadline they are neither improved nor taken, so the round does not
    overrun the search's time; the first one is always taken (the anytime floor)."""
    from eosp.search.rollouts import Best

    improved = []

    def improve(actions):
        improved.append(list(actions))
        return float(len(actions)), list(actions)

    late = Best(improve=improve, deadline=time.perf_counter() - 1.0)
    late.offer(1.0, [3])
    late.offer(5.0, [1, 2, 4, 5, 6])
    assert late.actions == [3] and late.episodes == 1 and improved == [[3]]
    improved.clear()
    early = Best(improve=improve, deadline=time.perf_counter() + 60.0)
    early.offer(1.0, [3])
    early.offer(5.0, [1, 2, 4, 5, 6])
    assert early.actions == [1, 2, 4, 5, 6] and early.episodes == 2 and len(improved) == 2
