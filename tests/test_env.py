"""The EOSP environment: the gymnasium checker, the paper's update rules, masks, rewards, snapshots."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st

import eosp.envs  # noqa: F401  (registers EOSP-v0)
from eosp.envs.eosp_env import EOSPEnv, InvalidAction
from eosp.envs.sources import FixedSource
from eosp.envs.observation import LOOKAHEAD_S, LOSES, N_NODE_FEATURES, SELECTABLE
from eosp.config import EnvConfig
from eosp.instances.schedule import check
from tests.conftest import generated
from tests.synthetic import synthetic_instance


def make_env(inst, **cfg):
    return EOSPEnv(EnvConfig(max_acquisitions=0, **cfg), source=FixedSource(inst))


def test_gymnasium_checker_passes():
    """The checker's step-determinism check samples an action after a step and plays it after a reset;
    in the unpruned graph every acquisition is allowed first, so any sampled action is valid there."""
    env = EOSPEnv(EnvConfig(max_acquisitions=0, prune=False), source=FixedSource(generated("uniform", 12, 0),
                                                                                  prune=False))
    check_env(env, skip_render_check=True)
    check_env(gym.make("EOSP-v0", config=EnvConfig(prune=False)).unwrapped, skip_render_check=True)


def test_checker_parts_on_the_default_pruned_env():
    """Every part of the checker on the default (pruned) env; the step-determinism check is run with an
    action allowed after the reset it is played from (the checker itself samples it one state earlier)."""
    from gymnasium.utils import env_checker as ec
    from gymnasium.utils import passive_env_checker as pc

    env = gym.make("EOSP-v0").unwrapped
    ec.check_action_space(env.action_space)
    ec.check_observation_space(env.observation_space)
    ec.check_reset_return_type(env)
    ec.check_reset_seed_determinism(env)
    ec.check_reset_options(env)
    pc.env_reset_passive_checker(env)
    pc.env_step_passive_checker(env, env.action_space.sample())
    env.reset(seed=123)
    ec.check_step_determinism(env)


class Reference:
    """The paper's update rules on Python sets, written independently of envs.core."""

    def __init__(self, inst):
        g = inst.pruned()
        self.g = g
        self.succ = [set(g.dst[g.indptr[u]:g.indptr[u + 1]].tolist()) for u in range(g.n_nodes)]
        self.last = 0
        self.alive = self._reachable(0, set(range(1, g.n_nodes)))

    def _reachable(self, root, allowed):
        seen, stack = set(), [root]
        while stack:
            u = stack.pop()
            for v in self.succ[u]:
                if v in allowed and v not in seen:
                    seen.add(v)
                    stack.append(v)
        return seen

    def mask(self, n):
        m = np.zeros(n, dtype=np.int8)
        for v in self.succ[self.last]:
            if v in self.alive:
                m[self.g.node_acq[v]] = 1
        return m

    def step(self, a):
        (w,) = [v for v in self.succ[self.last] if v in self.alive and self.g.node_acq[v] == a]
        allowed = {v for v in self.alive if self.g.node_acq[v] != a}  # (2) other nodes of a deleted
        self.alive = self._reachable(w, allowed)  # (1) + (3): only what w reaches stays
        self.last = w
        return w


@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 9), seed=st.integers(0, 10_000), walk=st.integers(0, 2**31 - 1))
def test_mask_matches_the_paper_rules_and_every_insertion_is_feasible(n, seed, walk):
    inst = synthetic_instance(n, seed)
    env = make_env(inst, reward="utility")
    ref = Reference(inst)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(walk)
    total = 0.0
    while True:
        mask = obs["action_mask"][:n]
        # never hides a feasible successor the graph still has, never allows one it does not have
        np.testing.assert_array_equal(mask, ref.mask(n))
        assert np.array_equal(env.state.ep.alive.nonzero()[0], np.array(sorted(ref.alive), dtype=np.int64))
        if not mask.any():
            break
        a = int(rng.choice(np.flatnonzero(mask)))
        w = ref.step(a)
        obs, r, done, trunc, info = env.step(a)
        total += r
        assert info["start"] == inst.node_time[w]
        # the schedule so far is feasible for the independent checker (unpruned arcs)
        assert check(inst, env.schedule()).feasible
        assert done == (not ref.mask(n).any()) and not trunc
    v = check(inst, env.schedule())
    assert v.feasible and total == pytest.approx(v.value, rel=1e-12)


@pytest.mark.parametrize("reward", ["normalized", "unitary", "utility", "lexicographic"])
def test_rewards_add_up_to_the_schedule_value(reward):
    inst = generated("uniform", 30, 1)
    env = make_env(inst, reward=reward)
    obs, _ = env.reset(seed=3)
    rewards, vectors, done = [], [], False
    while not done:
        obs, r, done, _, info = env.step(env.action_space.sample())
        rewards.append(r)
        vectors.append(info.get("reward_vector"))
    v = check(inst, env.schedule())
    assert v.feasible
    total = sum(rewards)
    if reward == "unitary":
        assert total == v.n
    elif reward == "utility":
        assert total == pytest.approx(v.value, rel=1e-12)
    else:
        assert total * np.mean(inst.acqs.utility) == pytest.approx(v.value, rel=1e-9)
    if reward == "lexicographic":
        vec = np.sum(vectors, axis=0)
        counts = np.bincount(inst.acqs.priority[env.schedule().acq], minlength=7)
        np.testing.assert_allclose(vec, counts, rtol=2e-3)


def test_invalid_action_raises_and_leaves_state_unchanged():
    env = make_env(generated("uniform", 30, 1))
    obs, _ = env.reset(seed=0)
    before = env.snapshot()
    masked = int(np.flatnonzero(obs["action_mask"] == 0)[0])
    for bad in (masked, -1, 10_000):
        with pytest.raises(InvalidAction, match="not allowed"):
            env.step(bad)
    after = env.snapshot()
    for f in before.ep._fields:  # every array of the episode state
        np.testing.assert_array_equal(getattr(before.ep, f), getattr(after.ep, f), err_msg=f)


def test_snapshot_restore_replays_identically():
    env = make_env(generated("clusters", 30, 2))
    obs, _ = env.reset(seed=0)
    for _ in range(3):
        obs, *_ = env.step(env.action_space.sample())
    snap = env.snapshot()
    runs = []
    for _ in range(2):
        env.restore(snap)
        local = np.random.default_rng(7)
        seq, done = [], False
        while not done:
            m = env.action_mask()
            a = int(local.choice(np.flatnonzero(m)))
            obs, r, done, _, _ = env.step(a)
            seq.append((a, r, obs["x"].sum()))
        runs.append(seq)
    assert runs[0] == runs[1]
    env.restore(snap)
    assert len(env.path()) == 3


@pytest.mark.parametrize("family,n,seed", [("conflict", 60, 3), ("clusters", 50, 4), ("uniform", 80, 5)])
def test_the_bounded_sweep_kills_what_the_whole_orbit_sweep_kills(family, n, seed):
    """A step's sweep stops past the latest death plus that node's longest arc; from every state of random
    walks and for every allowed action, it leaves exactly the alive nodes of a sweep to the end of the orbit
    (and does stop early somewhere, or the bound would go untested)."""
    from eosp.envs import core

    env = make_env(generated(family, n, seed))
    rng = np.random.default_rng(seed)
    stopped_early = 0
    for _ in range(3):
        env.reset(seed=0)
        while env.action_mask().any():
            g, ep = env.state.prepared.eg, env.state.ep
            for a in np.flatnonzero(env.action_mask()):
                bounded = ep.copy()
                w = core.apply_action(g, bounded, int(a))
                alive, count = ep.alive.copy(), ep.alive_count.copy()
                core.kill(g, alive, count, int(a))
                core.sweep(g, alive, count, g.pos[w], ep.last_pos[0])
                np.testing.assert_array_equal(bounded.alive, alive)
                np.testing.assert_array_equal(bounded.alive_count, count)
                h = core.sweep_horizon(g, ep.alive, ep.last[0], int(a))
                stopped_early += bool(h < g.node_time.max())
            env.step(int(rng.choice(np.flatnonzero(env.action_mask()))))
    assert stopped_early > 0


def lookahead_reference(env, inst):
    """What each allowed action would remove, from the environment's own step on a copy of the state:
    {action: (lost acquisitions, the highest log-utility feature among them, their utility share)}, counting
    an acquisition only when its last alive node starts within LOOKAHEAD_S of the end of the action's node."""
    from eosp.envs.core import step, target_node

    ep, eg = env.state.ep, env.state.prepared.eg
    static = env.state.prepared.cand.static
    out = {}
    for a in np.flatnonzero(ep.mask):
        w = target_node(eg, ep.alive, ep.last[0], a)
        limit = eg.node_finish[w] + LOOKAHEAD_S
        before = ep.alive_count > 0
        last_start = np.array([inst.node_time[np.flatnonzero(ep.alive[eg.acq_ptr[i]:eg.acq_ptr[i + 1]])[-1]
                                              + eg.acq_ptr[i]] if before[i] else np.inf for i in range(inst.n_acq)])
        copy = ep.copy()
        step(eg, copy, a)
        lost = before & (copy.alive_count == 0) & (last_start <= limit)
        lost[a] = False
        out[int(a)] = (int(lost.sum()), float(static[lost, 1].max()) if lost.any() else 0.0,
                       float(static[lost, 2].sum()))
    return out


@settings(max_examples=30, deadline=None)
@given(n=st.integers(2, 12), seed=st.integers(0, 10_000), walk=st.integers(0, 2**31 - 1))
def test_lookahead_features_are_what_the_step_would_remove(n, seed, walk):
    inst = synthetic_instance(n, seed)
    env = make_env(inst, reward="utility", lookahead=True)
    off = make_env(inst, reward="utility")
    obs, _ = env.reset(seed=0)
    obs_off, _ = off.reset(seed=0)
    rng = np.random.default_rng(walk)
    while obs["action_mask"][:n].any():
        # off (the default): zeros there, everything else the same
        assert np.all(obs_off["x"][:, LOSES:] == 0)
        np.testing.assert_array_equal(obs_off["x"][:, :LOSES], obs["x"][:, :LOSES])
        ref = lookahead_reference(env, inst)
        x = obs["x"][:n]
        least = np.min([[c / 10, t, s] for c, t, s in ref.values()], axis=0)
        for a in range(n):
            count, top, share = ref.get(a, (0, 0.0, 0.0))
            assert x[a, LOSES] == pytest.approx(count / 10, abs=1e-6)
            assert x[a, LOSES + 1] == pytest.approx(top, abs=1e-6) and x[a, LOSES + 2] == pytest.approx(share, abs=1e-6)
            # in excess of the allowed action that loses the least; nothing for a forbidden one
            excess = np.array([count / 10, top, share]) - least if a in ref else np.zeros(3)
            np.testing.assert_allclose(x[a, LOSES + 3:LOSES + 6], excess, atol=1e-6)
        a = int(rng.choice(np.flatnonzero(obs["action_mask"][:n])))
        obs, *_ = env.step(a)
        obs_off, *_ = off.step(a)


def test_lookahead_features_on_a_generated_instance_and_an_action_that_removes_something():
    inst = generated("clusters", 40, 3, step=1.0)
    env = make_env(inst, lookahead=True)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    seen = 0
    while obs["action_mask"].any():
        ref = lookahead_reference(env, inst)
        np.testing.assert_allclose(obs["x"][:, LOSES], [ref.get(a, (0,))[0] / 10 for a in range(inst.n_acq)],
                                   atol=1e-6)
        seen += sum(c > 0 for c, _, _ in ref.values())
        obs, *_ = env.step(int(rng.choice(np.flatnonzero(obs["action_mask"]))))
    assert seen > 0  # the features were tested on actions that do remove acquisitions


def test_observation_shapes_dtypes_and_edges():
    inst = generated("uniform", 30, 1)
    for mode in ("earliest", "full"):
        env = EOSPEnv(EnvConfig(max_acquisitions=64, obs_edges=mode), source=FixedSource(inst))
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        assert obs["x"].shape == (64, N_NODE_FEATURES) == (64, 37) and obs["edge_index"].dtype == np.int32
        m = int(obs["n_edges"][0])
        assert m > 0 and np.all(obs["edge_index"][:, m:] == 0)
        src, dst = obs["edge_index"][:, :m]
        assert np.all(src < 30) and np.all(dst < 30) and np.all(src != dst)
        assert np.all(obs["x"][30:] == 0)
        # every selectable acquisition is flagged
        np.testing.assert_array_equal(obs["x"][:30, SELECTABLE], obs["action_mask"][:30])
    # the full graph at reset is the continuous graph of the alive part
    from eosp.graphs.continuous import continuous_graph

    env = EOSPEnv(EnvConfig(max_acquisitions=30, obs_edges="full", max_edges=5000), source=FixedSource(inst))
    obs, _ = env.reset(seed=0)
    m = int(obs["n_edges"][0])
    s, t = continuous_graph(inst.pruned(), env.state.ep.alive.astype(bool))
    assert set(zip(*obs["edge_index"][:, :m].tolist())) == set(zip(s.tolist(), t.tolist()))


def test_shard_source_splits_shards_between_workers(tmp_path):
    from ray.rllib.env.env_context import EnvContext

    from eosp.shards.io import write_shard

    for k in range(4):
        write_shard(tmp_path / f"shard-{k}.parquet", [generated("uniform", 12, 10 + k)])
    seen = {}
    for w in (1, 2):
        ctx = EnvContext({"shards": [str(tmp_path)], "max_acquisitions": 16, "seed": 0}, worker_index=w,
                         num_workers=2)
        env = EOSPEnv(ctx)
        names = set()
        for ep in range(12):
            env.reset()
            names.add(env.instance.name)
        seen[w] = names
    assert seen[1] and seen[2] and not (seen[1] & seen[2])
    assert len(seen[1] | seen[2]) == 4
    # same seed, same draws
    ctx = EnvContext({"shards": [str(tmp_path)], "max_acquisitions": 16, "seed": 0}, worker_index=1, num_workers=2)
    a, b = EOSPEnv(ctx), EOSPEnv(ctx)
    assert [a.reset()[1]["instance"] for _ in range(5)] == [b.reset()[1]["instance"] for _ in range(5)]


def test_observation_horizon_keeps_the_selectable_and_drops_the_far_future():
    """With obs_horizon_s, far acquisitions leave the graph: no edge touches them, every allowed action stays."""
    from eosp.envs.observation import LAST, REMOVED, SCHEDULED, SELECTABLE
    from eosp.envs.sources import FixedSource

    inst = generated("uniform", 60, 3)
    full = EOSPEnv(EnvConfig(max_acquisitions=0), source=FixedSource(inst))
    near = EOSPEnv(EnvConfig(max_acquisitions=0, obs_horizon_s=300.0), source=FixedSource(inst))
    o_full, _ = full.reset(seed=1)
    o_near, _ = near.reset(seed=1)
    rng = np.random.default_rng(0)
    dropped_any = False
    while o_full["action_mask"].any():
        x = o_near["x"]
        active = (x[:, REMOVED] == 0) & ((x[:, SCHEDULED] == 0) | (x[:, LAST] == 1))
        m = int(o_near["n_edges"][0])
        assert active[o_near["edge_index"][:, :m]].all()  # no edge to or from a node left out
        assert (active | (o_near["action_mask"] == 0)).all() and (x[:, SELECTABLE] == o_near["action_mask"]).all()
        np.testing.assert_array_equal(o_near["action_mask"], o_full["action_mask"])
        assert m <= int(o_full["n_edges"][0])
        dropped_any |= bool((~active & (o_full["x"][:, REMOVED] == 0) & (o_full["x"][:, SCHEDULED] == 0)).any())
        a = int(rng.choice(np.flatnonzero(o_full["action_mask"])))
        o_full, *_ = full.step(a)
        o_near, *_ = near.step(a)
    assert dropped_any


def greedy_plan_at_start(inst, mode, plan):
    """The acquisitions of the Greedy solver's schedule; with 'greedy2', of the better of it and Greedy in the
    second order (utility: by class then window start; unitary: by latest start), ties to the first."""
    from eosp.planning.insertion import greedy_insert
    from eosp.solvers.base import run_solver

    first = inst.node_acq[run_solver("greedy", inst, mode=mode).nodes]
    if plan == "greedy":
        return first
    if mode == "unitary":
        second = inst.node_acq[run_solver("greedy", inst, mode=mode, order="deadline").nodes]
        return second if len(second) > len(first) else first
    g = inst.unpruned()
    order = np.lexsort((np.arange(inst.n_acq), g.node_time[g.acq_ptr[:-1]], inst.acqs.priority)).astype(np.int32)
    second, *_ = greedy_insert(g.indptr, g.dst, g.acq_ptr, g.node_time, order, 0, np.zeros(inst.n_acq, np.uint8))
    u = inst.acqs.utility
    return second if u[second].sum() > u[first].sum() * (1 + 1e-12) else first


@pytest.mark.parametrize("plan", ["greedy", "greedy2"])
@pytest.mark.parametrize("reward,mode", [("normalized", "utility"), ("unitary", "unitary")])
def test_plan_features_are_greedys_feasible_completion_of_the_partial_schedule(reward, mode, plan):
    """With --env.plan greedy: at the start the plan is the Greedy solver's schedule (greedy2: the better of two
    orders); at every state of a random walk the plan's acquisitions, in the order of their plan starts,
    complete the partial schedule into one the independent checker accepts, with those starts; off, the
    columns are zeros."""
    from eosp.envs.observation import PLAN, TIME_SCALE, plan_completion
    from eosp.graphs.discrete import arc_to_acq
    from eosp.instances.schedule import Schedule

    for family, n, seed in (("clusters", 40, 3), ("conflict", 30, 5)):
        inst = generated(family, n, seed, step=1.0)
        env, off = make_env(inst, reward=reward, plan=plan), make_env(inst, reward=reward)
        obs, _ = env.reset(seed=0)
        obs_off, _ = off.reset(seed=0)
        assert sorted(np.flatnonzero(obs["x"][:, PLAN])) == sorted(greedy_plan_at_start(inst, mode, plan))
        g = inst.unpruned()
        rng = np.random.default_rng(seed)
        while obs["action_mask"].any():
            assert np.all(obs_off["x"][:, PLAN:] == 0)
            np.testing.assert_array_equal(obs_off["x"][:, :PLAN], obs["x"][:, :PLAN])
            x = obs["x"]
            members = np.flatnonzero(x[:, PLAN])
            members = members[np.argsort(x[members, PLAN + 2], kind="stable")]
            assert x[:, PLAN + 1].sum() == (1 if len(members) else 0)
            if len(members):
                assert x[members[0], PLAN + 1] == 1
            path = list(env.path())
            t_now = inst.node_time[path[-1]] + inst.acqs.duration[inst.node_acq[path[-1]]] if path else 0.0
            prev = path[-1] if path else 0
            for a in members:  # each starts as early as the arc from its predecessor allows
                prev = arc_to_acq(g.indptr, g.dst, g.acq_ptr, prev, a)
                assert prev >= 0
                assert x[a, PLAN + 2] == pytest.approx(min(10.0, (inst.node_time[prev] - t_now) / TIME_SCALE), abs=1e-5)
                path.append(prev)
            nodes = np.array(path, dtype=np.int64)
            sched = Schedule(acq=inst.node_acq[nodes].astype(np.int32), node=inst.node_ids[nodes].astype(np.int32),
                             start=inst.node_time[nodes].astype(np.float64))
            assert check(inst, sched).feasible
            st = env.state  # the incumbent's completion is the plan the observation computed, read back
            np.testing.assert_array_equal(env.completion()[0],
                                          plan_completion(st.prepared.eg, st.ep, st.prepared.cand, env._plan)[1])
            a = int(rng.choice(np.flatnonzero(obs["action_mask"])))
            obs, *_ = env.step(a)
            obs_off, *_ = off.step(a)


def test_plan_features_without_the_unpruned_arcs_are_refused_in_one_line():
    from eosp.errors import InputError

    inst = generated("uniform", 20, 1)
    inst.pruned()
    inst.unpruned_graph = None
    with pytest.raises(InputError, match="the plan features .*needs the unpruned arcs"):
        make_env(inst, plan="greedy").reset(seed=0)


def assert_rollout_columns(x, v: dict, reward: str) -> float:
    """The loss, best and ratio plan columns of x for the allowed actions' values `v` (action -> V(a));
    returns the best value."""
    from eosp.envs.observation import PLAN

    best = max(v.values())
    for a, va in v.items():
        loss = best - va
        expect = np.log10(1 + loss) / 8 if reward != "unitary" else loss / 10
        assert x[a, PLAN + 3] == pytest.approx(expect, abs=1e-5)
        assert x[a, PLAN + 4] == (1.0 if loss <= 1e-9 * best else 0.0)
        assert x[a, PLAN + 5] == pytest.approx(va / best, rel=1e-5)
    return best


@pytest.mark.parametrize("reward", ["normalized", "unitary"])
def test_label_plan_values_each_action_by_a_chain_the_environment_can_play(reward):
    """With --env.plan label (no unpruned arcs needed): at every state of a random walk, each allowed action's
    value is the worth of the label sweep's chain from the node the step would start it at; that chain,
    played after the partial schedule, is allowed action by action and feasible for the independent checker;
    the loss, best and ratio columns compare the values; the plan shown is the best action's chain, and
    EOSPEnv.completion() returns it."""
    import copy

    from eosp.envs.observation import PLAN, _label_plan, plan_completion
    from eosp.graphs.discrete import arc_to_acq
    from eosp.instances.schedule import Schedule

    for family, n, seed in (("clusters", 40, 3), ("conflict", 30, 5), ("uniform", 40, 7)):
        ref = generated(family, n, seed, step=1.0)  # with its unpruned arcs, for the checker
        ref.pruned()
        inst = copy.copy(ref)
        inst.unpruned_graph = None  # the label sweep runs on the environment's own graph
        w = np.ones(n) if reward == "unitary" else inst.acqs.utility
        env = make_env(inst, reward=reward, plan="label")
        obs, _ = env.reset(seed=0)
        rng = np.random.default_rng(seed)
        while obs["action_mask"].any():
            s = env.state
            eg = s.prepared.eg
            togo, nxt, start = _label_plan(eg, s.ep, s.prepared.cand, env._plan)
            last, value = int(s.ep.last[0]), s.value  # (the steps below play on s.ep; restore() replaces it)
            allowed = np.flatnonzero(obs["action_mask"])
            x = obs["x"]
            v = {}
            for a in allowed:
                node = arc_to_acq(eg.indptr, eg.dst, eg.acq_ptr, last, int(a))
                chain = [node]
                while nxt[chain[-1]] >= 0:
                    chain.append(int(nxt[chain[-1]]))
                acqs = eg.node_acq[chain]
                v[a] = w[acqs].sum()
                assert togo[node] == pytest.approx(v[a], rel=1e-12) and acqs[0] == a
                snap = env.snapshot()
                for b in acqs:  # the environment plays the chain, node for node
                    o, *_ = env.step(int(b))
                assert list(env.path()[-len(chain):]) == chain
                nodes = env.path()
                sched = Schedule(acq=inst.node_acq[nodes].astype(np.int32), node=inst.node_ids[nodes].astype(np.int32),
                                 start=inst.node_time[nodes].astype(np.float64))
                assert check(ref, sched).feasible
                env.restore(snap)
            best = assert_rollout_columns(x, v, reward)
            nodes, total, worth = env.completion()  # the plan the observation computed, read back
            np.testing.assert_array_equal(nodes, plan_completion(eg, env.state.ep, s.prepared.cand, env._plan)[1])
            assert sorted(eg.node_acq[nodes]) == sorted(np.flatnonzero(x[:n, PLAN]))
            assert x[eg.node_acq[nodes[0]], PLAN + 1] == 1 and v[eg.node_acq[nodes[0]]] == pytest.approx(best, rel=1e-12)
            assert worth == pytest.approx(best + (len(env.path()) if reward == "unitary" else value), rel=1e-12)
            assert total == pytest.approx(value + inst.acqs.utility[eg.node_acq[nodes]].sum(), rel=1e-12)
            obs, *_ = env.step(int(rng.choice(allowed)))


@pytest.mark.parametrize("plan", ["greedy", "greedy2"])
@pytest.mark.parametrize("reward", ["normalized", "unitary"])
def test_rollout_features_value_each_action_by_greedys_completion_after_it(reward, plan):
    """V(a), Greedy's rollout after an allowed action a, is a's worth plus the worth of the plan shown in the
    state the step to a leads to; the loss and ratio columns compare it with the best allowed action."""
    from eosp.envs.observation import PLAN

    for family, n, seed in (("clusters", 40, 3), ("conflict", 30, 5), ("uniform", 40, 7)):
        inst = generated(family, n, seed, step=1.0)
        w = np.ones(n) if reward == "unitary" else inst.acqs.utility
        env = make_env(inst, reward=reward, plan=plan)
        obs, _ = env.reset(seed=0)
        rng = np.random.default_rng(seed)
        while obs["action_mask"].any():
            allowed = np.flatnonzero(obs["action_mask"])
            snap = env.snapshot()
            v = {}
            for a in allowed:
                after, *_ = env.step(int(a))
                v[a] = w[a] + w[after["x"][:n, PLAN] > 0].sum()
                env.restore(snap)
            x = obs["x"]
            assert_rollout_columns(x, v, reward)
            assert np.all(x[np.setdiff1d(np.arange(n), allowed), PLAN + 3:] == 0)
            obs, *_ = env.step(int(rng.choice(allowed)))


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 100_000), synthetic=st.booleans())
def test_an_episode_never_ends_while_an_acquisition_is_still_insertable(seed, synthetic):
    """Random allowed actions on the pruned graph until the mask is empty: then no unscheduled acquisition has
    an arc of the unpruned graph from the last scheduled node (the pruning removes no way on)."""
    rng = np.random.default_rng(seed)
    inst = (synthetic_instance(int(rng.integers(3, 10)), seed, period=float(rng.choice([37.0, 2.0]))) if synthetic
            else generated(str(rng.choice(["uniform", "clusters", "conflict"])), int(rng.integers(10, 40)), seed % 50))
    env = make_env(inst)
    env.reset(seed=seed)
    terminated = False
    while not terminated:
        _, _, terminated, _, _ = env.step(int(rng.choice(np.flatnonzero(env.action_mask()))))
    g, path = inst.unpruned(), env.path()
    done = set(g.node_acq[path].tolist())
    after = g.node_acq[g.dst[g.indptr[path[-1]]:g.indptr[path[-1] + 1]]]
    assert not set(after.tolist()) - done
