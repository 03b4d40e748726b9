"""The exact solver as a teacher: residual problems, demos that replay exactly, imitation that learns."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from eosp.config import EnvConfig, ImitationConfig, ModelConfig
from eosp.envs.eosp_env import EOSPEnv
from eosp.envs.sources import FixedSource, prepare_instance
from eosp.errors import InputError
from eosp.shards.io import ShardReader, write_shard
from eosp.solvers import expert
from tests.conftest import generated
from tests.synthetic import synthetic_instance

ROOT = Path(__file__).resolve().parents[1]


def brute_best(env, w) -> float:
    """Best remaining objective from the env's state, by trying every action sequence (independent of the DP)."""
    allowed = np.flatnonzero(env.state.ep.mask)
    best = 0.0
    for a in allowed:
        snap = env.snapshot()
        env.step(int(a))
        best = max(best, w[a] + brute_best(env, w))
        env.restore(snap)
    return best


@pytest.mark.parametrize("mode", ["unitary", "utility"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_residual_optimum_and_optimal_sets_match_brute_force(mode, seed):
    inst = synthetic_instance(9, seed)
    env = EOSPEnv(EnvConfig(max_acquisitions=0), source=FixedSource(inst))
    env.reset()
    w = expert.objective(inst, mode)
    rng = np.random.default_rng(seed)
    for _ in range(3):  # the initial state and two states further down a random path
        if not env.state.ep.mask.any():
            break
        best = brute_best(env, w)
        path = expert.optimal_path(expert.state_residual(env), w, unitary=mode == "unitary", time_limit=30)
        assert path.status == "optimal" and path.value == pytest.approx(best, rel=1e-12)
        allowed, q = expert.action_values(env, w, beam=64)
        truth = []
        for a in allowed:
            snap = env.snapshot()
            env.step(int(a))
            truth.append(w[a] + brute_best(env, w))
            env.restore(snap)
        np.testing.assert_allclose(q, truth, rtol=1e-12)
        assert set(allowed[expert.optimal_set(q, mode == "unitary")]) == set(
            allowed[np.asarray(truth) >= max(truth) * (1 - 1e-9) - (0.5 if mode == "unitary" else 0)])
        env.step(int(rng.choice(allowed)))


@pytest.fixture(scope="module")
def demo_shard(tmp_path_factory):
    from eosp.training.demos import demo_file, solve_shard

    d = tmp_path_factory.mktemp("demos")
    shard = d / "train" / "shard-00000.parquet"
    write_shard(shard, [generated("conflict", 20, 1), generated("uniform", 20, 2, 1.0, "bang_coast_bang")])
    for mode in ("unitary", "utility"):
        solve_shard(shard, mode, time_limit=30, action_sets=True, beam=4, prune=True, out=demo_file(shard, mode))
    return shard


@pytest.mark.parametrize("mode", ["unitary", "utility"])
def test_demos_replay_to_the_expert_value_with_allowed_actions(demo_shard, mode):
    from eosp.solvers.exact import ExactConfig
    from eosp.solvers.exact import solve as exact
    from eosp.training.demos import read_demos

    reader = ShardReader(demo_shard)
    prepared = [prepare_instance(reader.read(k)) for k in range(len(reader))]
    demos = read_demos(demo_shard, mode, prepared)
    assert [d.index for d in demos] == [0, 1]
    for d, p in zip(demos, prepared):
        env = EOSPEnv(EnvConfig(max_acquisitions=0), source=FixedSource(p))
        env.reset()
        w = expert.objective(p.inst, mode)
        for t, a in enumerate(d.actions):
            assert env.state.ep.mask[a], (d.name, t, a)
            assert a in d.optimal[t]
            assert d.return_to_go[t] == pytest.approx(w[d.actions[t:]].sum(), rel=1e-12)
            env.step(int(a))
        got = env.state.value if mode == "utility" else float(env.state.ep.n_scheduled[0])
        assert got == pytest.approx(d.value, rel=1e-12, abs=0)
        assert d.status == "optimal" and d.bound == d.value
        # the environment's graph is pruned: its optimum can only be below the unpruned one (here equal)
        assert d.value <= exact(p.inst, ExactConfig(mode=mode, time_limit=60)).value * (1 + 1e-12)


def test_demos_of_another_shard_or_with_a_forbidden_action_are_refused(demo_shard, tmp_path):
    from eosp.training.demos import demo_file, read_demos, replay

    reader = ShardReader(demo_shard)
    prepared = [prepare_instance(reader.read(k)) for k in range(len(reader))]
    # another shard: same file name, other instances
    other = tmp_path / "other" / demo_shard.name
    write_shard(other, [generated("uniform", 20, 7), generated("uniform", 20, 8)])
    (other.parent / "demos").symlink_to(demo_shard.parent / "demos")
    other_prepared = [prepare_instance(ShardReader(other).read(k)) for k in range(2)]
    with pytest.raises(InputError, match="another graph|is '"):
        read_demos(other, "unitary", other_prepared)
    # an action the environment does not allow
    f = demo_file(demo_shard, "unitary")
    t = pq.read_table(f)
    acts = t.column("action").to_pylist()
    d0 = read_demos(demo_shard, "unitary", prepared)[0]
    env = EOSPEnv(EnvConfig(max_acquisitions=0), source=FixedSource(prepared[0]))
    env.reset()
    bad = int(np.flatnonzero(env.state.ep.mask == 0)[0])
    d0.actions = np.array([bad] + acts[1:len(d0.actions)], np.int32)
    with pytest.raises(InputError, match="step 0: action .* is not allowed"):
        list(replay(env, prepared[0], d0, f))
    # a corrupt file
    broken = tmp_path / "broken" / demo_shard.name
    (broken.parent / "demos" / "unitary").mkdir(parents=True)
    (broken.parent / "demos" / "unitary" / demo_shard.name).write_bytes(b"not parquet")
    with pytest.raises(InputError, match="not a readable Parquet file"):
        read_demos(broken, "unitary", prepared)


def test_imitation_learns_the_expert_on_a_tiny_set(demo_shard):
    import torch

    from eosp.models.agent import EOSPAgent
    from eosp.solvers.policy import rollout
    from eosp.training.imitation import DemoData, train_epoch

    torch.manual_seed(0)
    env_cfg = EnvConfig(reward="unitary", max_acquisitions=32)
    data = DemoData((str(demo_shard),), env_cfg, 1)
    agent = EOSPAgent(ModelConfig(hidden_dim=16, n_layers=2, heads=2, value_scale=float(np.mean(data.start_values))))
    opt = torch.optim.Adam(agent.parameters(), lr=3e-3)
    rng = np.random.default_rng(0)

    def score():
        return sum(len(rollout(agent, p, env_cfg)[0]) for _, _, p in data.instances)

    before = score()
    im = ImitationConfig(batch_size=16, value_coeff=0.5, grad_clip=1.0)
    first = train_epoch(agent, opt, data.samples, im, rng)
    for _ in range(30):
        last = train_epoch(agent, opt, data.samples, im, rng)
    assert last["train/policy_loss"] < 0.2 * first["train/policy_loss"]
    assert last["train/accuracy"] > 0.95
    cloned = score()
    assert cloned > before
    # DAgger: the policy's own states, labelled by the expert (in-process without Ray), lift the cloned
    # policy to the optimum or within one acquisition of it in 3 rounds (seeds 0-5 reached the optimum
    # after 1 to 3 rounds; which round depends on the initialization)
    optimum = sum(data.optimal_values)
    scores = []
    for _ in range(3):
        info = data.add_policy_states(agent, 2, 4, rng)
        assert info["dagger/states_added"] > 0 and len(data.samples) == info["dagger/dataset_states"]
        for _ in range(15):
            train_epoch(agent, opt, data.samples, im, rng)
        scores.append(score())
        if scores[-1] == optimum:
            break
    assert (max(scores) > cloned or cloned == optimum) and max(scores) >= optimum - 1, (cloned, scores, optimum)


def test_build_demos_job_is_resumable_and_refuses_bad_options(demo_shard, capsys):
    import ray

    from eosp.jobs.build_demos import main

    # both files exist: nothing to do
    assert main(["--data", str(demo_shard.parent), "--ray.num-cpus", "1"]) == 0
    assert "0 (shard, mode) tasks, 2 already done" in capsys.readouterr().out
    assert main(["--data", str(demo_shard.parent), "--modes", "lexical"]) == 2
    assert "unknown mode 'lexical'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # the typed config refuses it while parsing
        main(["--data", str(demo_shard.parent), "--time-limit", "-1"])
    assert exc.value.code == 2 and "--time-limit" in capsys.readouterr().err
    ray.shutdown()  # the job started a local Ray in this process


@pytest.mark.parametrize("mode", ["unitary", "utility"])
def test_shipped_models_solve_without_a_checkpoint(tmp_path, mode):
    """`eosp solve --solver policy|mcts --mode M` with no --checkpoint uses the shipped model of M."""
    from eosp.cli import main
    from eosp.instances.interchange import write_instance
    from eosp.instances.schedule import check, read_schedule
    from eosp.models.pretrained import load_pretrained

    agent, env_cfg, meta = load_pretrained(mode)
    assert (env_cfg.reward == "unitary") == (mode == "unitary") and agent.cfg.n_values == 1
    inst = generated("clusters", 30, 4)
    write_instance(inst, tmp_path / "inst")
    for solver, extra in (("policy", []), ("mcts", ["--budget", "4"])):
        out = tmp_path / f"{solver}.parquet"
        assert main(["solve", str(tmp_path / "inst"), "--solver", solver, "--mode", mode, "--out", str(out),
                     *extra]) == 0
        assert check(inst, read_schedule(out)).feasible


def test_the_fast_variant_and_the_old_name_are_one_flag_away_and_an_unknown_name_is_one_line(tmp_path, capsys):
    """The utility model reads plan features; `--checkpoint pretrained:utility-fast` (no plan features) and the
    plan model's former name `pretrained:utility-plan` solve too (the plan model's schedule is at least Greedy's
    here); a name that is not shipped is refused in one line, nothing written."""
    from eosp.cli import main
    from eosp.instances.interchange import write_instance
    from eosp.instances.schedule import check, read_schedule
    from eosp.models.pretrained import load_pretrained, pretrained_dir
    from eosp.solvers.base import run_solver

    _, env_cfg, _ = load_pretrained("utility")
    assert env_cfg.plan in ("greedy", "greedy2", "label") and env_cfg.reward == "normalized"
    assert load_pretrained("utility-fast")[1].plan == ""
    assert pretrained_dir("utility-plan") == pretrained_dir("utility")
    inst = generated("conflict", 30, 5)
    write_instance(inst, tmp_path / "inst")
    greedy = run_solver("greedy", inst, mode="utility").value
    for name in ("utility-plan", "utility-fast"):
        out = tmp_path / f"{name}.parquet"
        assert main(["solve", str(tmp_path / "inst"), "--solver", "policy", "--mode", "utility", "--checkpoint",
                     f"pretrained:{name}", "--out", str(out)]) == 0
        v = check(inst, read_schedule(out))
        assert v.feasible and (name == "utility-fast" or v.value >= greedy * (1 - 1e-9))
    capsys.readouterr()
    assert main(["solve", str(tmp_path / "inst"), "--solver", "policy", "--mode", "utility", "--checkpoint",
                 "pretrained:nope", "--out", str(tmp_path / "x.parquet")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "no pretrained model 'nope'" in err and not (tmp_path / "x.parquet").exists()


def test_time_limited_searches_on_large_instances_default_to_the_fast_model():
    """The plan features cost grows with allowed actions x acquisitions left: without --checkpoint, a search with a
    time limit on more than FAST_ABOVE acquisitions gets the fast utility model; the one-shot policy, smaller
    instances and the unitary mode keep the mode's model."""
    from eosp.models.pretrained import FAST_ABOVE, default_name
    from eosp.solvers.policy import resolve_agent

    assert default_name("utility", FAST_ABOVE + 1, time_limited=True) == "utility-fast"
    assert default_name("utility", FAST_ABOVE + 1, time_limited=False) == "utility"
    assert default_name("utility", FAST_ABOVE, time_limited=True) == "utility"
    assert default_name("unitary", 10 * FAST_ABOVE, time_limited=True) == "unitary"
    big = resolve_agent("sample", "", None, "utility", n_acquisitions=FAST_ABOVE + 1, time_limited=True)
    small = resolve_agent("sample", "", None, "utility", n_acquisitions=FAST_ABOVE, time_limited=True)
    assert big[1].plan == "" and small[1].plan != ""
    forced = resolve_agent("sample", "pretrained:utility", None, "utility", n_acquisitions=10_000, time_limited=True)
    assert forced[1].plan != ""  # an explicit checkpoint is never replaced


def test_missing_or_corrupt_shipped_model_is_one_line(tmp_path, monkeypatch, capsys):
    import eosp.models.pretrained as pretrained
    from eosp.cli import main
    from eosp.instances.interchange import write_instance

    write_instance(generated("uniform", 12, 0), tmp_path / "inst")
    monkeypatch.setattr(pretrained, "ROOT", tmp_path / "nowhere")
    assert main(["solve", str(tmp_path / "inst"), "--solver", "policy", "--mode", "unitary",
                 "--out", str(tmp_path / "s.parquet")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "shipped pretrained model is missing" in err
    broken = tmp_path / "broken" / "unitary"
    broken.mkdir(parents=True)
    shipped = pretrained.Path(__file__).parents[1] / "models" / "pretrained-agents" / "unitary"
    (broken / "agent.json").write_text((shipped / "agent.json").read_text())
    (broken / "agent.pt").write_bytes(b"\x00garbage")
    monkeypatch.setattr(pretrained, "ROOT", tmp_path / "broken")
    assert main(["solve", str(tmp_path / "inst"), "--solver", "policy", "--mode", "unitary",
                 "--out", str(tmp_path / "s.parquet")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "agent.pt: not a torch weights file" in err
    assert not (tmp_path / "s.parquet").exists()


def test_pretrain_continues_a_shipped_model_and_refuses_a_missing_one(demo_shard, tmp_path, capsys):
    import ray

    from eosp.jobs.pretrain import main
    from eosp.models.checkpoint import load_agent
    from eosp.models.pretrained import pretrained_dir

    common = ["--imitation.train-data", str(demo_shard.parent), "--imitation.val-data", "", "--env.reward", "unitary",
              "--imitation.epochs", "1", "--imitation.run-dir", str(tmp_path / "runs"), "--imitation.mlflow-uri",
              f"sqlite:///{tmp_path / 'mlflow.db'}", "--ray.num-cpus", "1", "--env.max-acquisitions", "32"]
    shipped = pretrained_dir("unitary")
    assert main([*common, "--imitation.init-checkpoint", str(shipped), "--imitation.run-name", "more"]) == 0
    assert f"starting from {shipped}" in capsys.readouterr().out
    agent, _, _ = load_agent(tmp_path / "runs" / "more" / "checkpoints" / "last")
    assert agent.cfg == load_agent(shipped)[0].cfg  # architecture and value scale came with the weights
    assert main([*common, "--imitation.init-checkpoint", str(tmp_path / "none"), "--imitation.run-name", "x"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "checkpoint not found" in err
    ray.shutdown()


def test_pretrain_saves_the_weight_average_and_decays_the_learning_rate(demo_shard, tmp_path):
    import json

    import ray
    import torch

    from eosp.jobs.pretrain import main
    from eosp.models.checkpoint import load_agent
    from eosp.training.imitation import WeightAverage, cosine_lr

    assert cosine_lr(1e-3, 0.0) == pytest.approx(1e-3) and cosine_lr(1e-3, 0.5) == pytest.approx(5e-4)
    assert cosine_lr(1e-3, 1.0) == pytest.approx(0.0, abs=1e-12) and cosine_lr(1e-3, 3.0) == pytest.approx(0.0, abs=1e-12)
    # the average of a parameter that moves from 0 to 1 and stays there follows it with lag, and converges
    lin = torch.nn.Linear(1, 1, bias=False)
    with torch.no_grad():
        lin.weight.zero_()
    avg = WeightAverage(lin, 0.9)
    with torch.no_grad():
        lin.weight.fill_(1.0)
    seen = []
    for _ in range(200):
        avg.update(lin)
        seen.append(float(avg.model.weight))
    assert 0 < seen[0] < seen[10] < seen[-1] and seen[-1] == pytest.approx(1.0, abs=1e-6)
    assert all(a <= b for a, b in zip(seen, seen[1:]))

    run_dir = tmp_path / "runs"
    common = ["--imitation.train-data", str(demo_shard.parent), "--imitation.val-data", "", "--env.reward", "unitary",
              "--imitation.epochs", "3", "--imitation.run-dir", str(run_dir), "--imitation.mlflow-uri",
              f"sqlite:///{tmp_path / 'mlflow.db'}", "--ray.num-cpus", "1", "--env.max-acquisitions", "32",
              "--model.hidden-dim", "8", "--model.n-layers", "1"]
    assert main([*common, "--imitation.run-name", "plain"]) == 0
    assert main([*common, "--imitation.run-name", "avg", "--imitation.ema", "0.99", "--imitation.lr-schedule",
                 "cosine"]) == 0
    ray.shutdown()
    history = json.loads((run_dir / "avg" / "history.json").read_text())["history"]
    lrs = [h["train/lr"] for h in history]
    assert lrs[0] <= 1e-3 and all(a > b for a, b in zip(lrs, lrs[1:])) and lrs[-1] < 0.3e-3  # 1, 0.75, 0.25 e-3
    assert [h["train/lr"] for h in json.loads((run_dir / "plain" / "history.json").read_text())["history"]] == [1e-3] * 3
    # same seed, same data: the two runs differ only by the schedule and what is saved (the average)
    plain = load_agent(run_dir / "plain" / "checkpoints" / "last")[0].state_dict()
    averaged = load_agent(run_dir / "avg" / "checkpoints" / "last")[0].state_dict()
    assert any(not torch.equal(plain[k], averaged[k]) for k in plain)


def test_the_rollout_guard_never_takes_an_action_greedys_rollout_values_far_below_the_best():
    """With the guard (the default of every learned solver), each decision of the shipped utility model is an
    allowed action whose rollout value is at least (1 - guard) x the best allowed action's (after_ratio); the
    guard only ever removes actions (1: the plain argmax), and the best-rollout action is never removed."""
    from eosp.envs.observation import PLAN
    from eosp.models.pretrained import load_pretrained
    from eosp.solvers.base import LearnedConfig
    from eosp.solvers.policy import evaluate, guarded, make_env_for

    guard = LearnedConfig().guard
    assert 0 < guard < 1
    agent, env_cfg, _ = load_pretrained("utility")
    checked = 0
    for family, n, seed in (("conflict", 40, 5), ("clusters", 40, 3)):
        env = make_env_for(prepare_instance(generated(family, n, seed, step=1.0), env_cfg.prune), env_cfg)
        obs, _ = env.reset(seed=0)
        while obs["action_mask"].any():
            plain, _ = evaluate(agent, obs)
            logits, _ = evaluate(agent, obs, guard)
            allowed = np.flatnonzero(obs["action_mask"])
            ratio = obs["x"][allowed, PLAN + 5]
            kept = allowed[logits[allowed] > -1e8]
            np.testing.assert_array_equal(kept, allowed[ratio >= 1 - guard])
            assert set(allowed[obs["x"][allowed, PLAN + 4] == 1]) <= set(kept) and len(kept)
            np.testing.assert_array_equal(logits[kept], plain[kept])
            a = int(np.argmax(logits))
            assert obs["x"][a, PLAN + 5] >= 1 - guard
            checked += 1
            obs, *_ = env.step(a)
    assert checked > 20
    # the kernel on a hand-made row: only the allowed actions below (1 - guard) x the best go; 1 leaves all; a
    # model without plan features (ratios 0) is untouched
    x = np.zeros((1, 4, PLAN + 6), dtype=np.float32)
    x[0, :, PLAN + 5] = [1.0, 0.5, 0.95, 0.89]
    out = guarded(np.zeros((1, 4)), x, 0.1)
    assert list(out[0] < -1e8) == [False, True, False, True]
    assert not (guarded(np.zeros((1, 4)), x, 1.0) < -1e8).any()
    assert not (guarded(np.zeros((1, 4)), np.zeros_like(x), 0.1) < -1e8).any()


@pytest.mark.parametrize("plan", ["greedy2", ""])
@pytest.mark.parametrize("mode,reward", [("utility", "normalized"), ("unitary", "unitary")])
def test_the_incumbent_is_never_below_greedy_nor_the_episode_and_is_feasible(mode, reward, plan):
    """With `incumbent` (the policy solver's default), the schedule returned is the best of the states' Greedy
    completions: an untrained agent (with or without plan features) that ends below Greedy comes back at least
    at Greedy's value and at its own episode's, feasible for the independent checker, its value the sum of its
    acquisitions' utilities."""
    import torch

    from eosp.instances.schedule import check, from_internal_nodes
    from eosp.models.agent import EOSPAgent
    from eosp.solvers import policy
    from eosp.solvers.base import run_solver

    torch.manual_seed(0)
    agent = (EOSPAgent(ModelConfig(hidden_dim=8, n_layers=1, heads=1)).eval(),
             EnvConfig(reward=reward, plan=plan), {})
    below = 0
    for family, n, seed in (("conflict", 40, 5), ("clusters", 40, 3), ("uniform", 30, 7)):
        inst = generated(family, n, seed, step=1.0)
        greedy = run_solver("greedy", inst, mode=mode).value
        raw = policy.solve(inst, policy.PolicyConfig(mode=mode, guard=1.0, incumbent=False, polish=False),
                           agent=agent)
        kept = policy.solve(inst, policy.PolicyConfig(mode=mode, guard=1.0, polish=False), agent=agent)
        below += raw.value < greedy * (1 - 1e-9)
        assert kept.value >= greedy * (1 - 1e-12) and kept.value >= raw.value * (1 - 1e-12)
        verdict = check(inst, from_internal_nodes(inst, kept.nodes))
        assert verdict.feasible
        nodes, value = policy.rollout(agent[0], prepare_instance(inst), agent[1], incumbent=True)
        np.testing.assert_array_equal(nodes, kept.nodes)
        assert value == pytest.approx(verdict.value, rel=1e-12)
    assert below >= 2  # the untrained agent does end below Greedy: the incumbent had work to do


@pytest.mark.parametrize("mode", ["utility", "unitary"])
def test_the_polished_policy_is_feasible_and_never_worse(mode):
    """`polish` (the policy solver's default) improves the decoded schedule by local moves: with an untrained
    agent, never below the unpolished schedule, strictly above it on some instance, feasible for the independent
    checker, its value the checker's; with the incumbent too, never below the polished episode."""
    import torch

    from eosp.instances.schedule import check, from_internal_nodes
    from eosp.models.agent import EOSPAgent
    from eosp.solvers import policy

    torch.manual_seed(0)
    agent = (EOSPAgent(ModelConfig(hidden_dim=8, n_layers=1, heads=1)).eval(),
             EnvConfig(reward="unitary" if mode == "unitary" else "normalized"), {})
    gained = 0
    for family, n, seed in (("conflict", 40, 5), ("clusters", 40, 3), ("uniform", 30, 7)):
        inst = generated(family, n, seed, step=1.0)
        plain = policy.solve(inst, policy.PolicyConfig(mode=mode, incumbent=False, polish=False), agent=agent)
        polished = policy.solve(inst, policy.PolicyConfig(mode=mode, incumbent=False), agent=agent)
        assert polished.info["polish"] and polished.value >= plain.value * (1 - 1e-12)
        # with the incumbent, its schedule and the episode are both polished: never below the episode polished
        both = policy.solve(inst, policy.PolicyConfig(mode=mode), agent=agent)
        assert both.value >= polished.value * (1 - 1e-12)
        assert check(inst, from_internal_nodes(inst, both.nodes)).feasible
        gained += polished.value > plain.value * (1 + 1e-9)
        verdict = check(inst, from_internal_nodes(inst, polished.nodes))
        assert verdict.feasible
        util = inst.acqs.utility[inst.node_acq[polished.nodes]].sum()
        assert verdict.value == pytest.approx(util, rel=1e-12)
        if mode == "unitary":
            assert polished.value == len(polished.nodes)
    assert gained >= 1
