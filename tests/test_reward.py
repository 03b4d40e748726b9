"""The reward variants (eosp.reward): the targets imitation learns are the returns the environment pays."""

import numpy as np
import pytest

from eosp.config import EnvConfig
from eosp.envs.eosp_env import EOSPEnv
from eosp.envs.sources import FixedSource
from eosp.reward import REWARDS, objective_mode, reward
from tests.conftest import generated


def test_an_unknown_name_is_one_line_naming_the_variants():
    with pytest.raises(ValueError) as e:
        reward("normalised")
    assert str(e.value) == "unknown reward 'normalised'; one of normalized, utility, unitary, lexicographic"
    with pytest.raises(ValueError, match="unknown reward 'normalised'"):
        EOSPEnv(EnvConfig(reward="normalised"))


def test_objective_modes():
    assert {n: objective_mode(EnvConfig(reward=n)) for n in REWARDS} == {
        "normalized": "utility", "utility": "utility", "unitary": "unitary", "lexicographic": "utility"}


@pytest.mark.parametrize("name", list(REWARDS))
def test_returns_to_go_are_the_environments_rewards_summed_from_each_step(name):
    inst = generated("clusters", 30, 3)
    env = EOSPEnv(EnvConfig(max_acquisitions=0, reward=name), source=FixedSource(inst))
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    actions, scalars, vectors, done = [], [], [], False
    while not done:
        a = int(rng.choice(np.flatnonzero(env.action_mask())))
        _, r, done, _, info = env.step(a)
        actions.append(a)
        scalars.append(r)
        vectors.append(info.get("reward_vector"))
    rew, prepared = env.reward, env.state.prepared
    n_values = rew.n_values
    togo = rew.returns_to_go(prepared, np.asarray(actions), n_values)
    paid = np.stack(vectors).astype(np.float64) if rew.per_class else np.asarray(scalars)[:, None]
    np.testing.assert_allclose(togo, np.cumsum(paid[::-1], axis=0)[::-1], rtol=1e-6)
    assert togo.shape == (len(actions), n_values)
    # the objective's value of the whole schedule, in reward units, is the first return to go (not split by class
    # for the lexicographic reward)
    value = len(actions) if rew.objective == "unitary" else float(inst.acqs.utility[actions].sum())
    units = rew.to_units(value, prepared, n_values)
    if rew.per_class:
        assert np.isnan(units).all() and units.shape == (n_values,)
        assert rew.episode_return(sum(scalars), togo[0]) == pytest.approx(float(np.max(togo[0])))
    else:
        assert units[0] == pytest.approx(togo[0, 0], rel=1e-6)
        assert rew.episode_return(sum(scalars), None) == sum(scalars)


def test_the_config_offers_exactly_the_rewards_there_are():
    """An unknown reward is refused by the command line in one line: EnvConfig.reward's choices are the rewards."""
    from dataclasses import fields

    from eosp.config import EnvConfig
    from eosp.reward import REWARDS

    (f,) = [f for f in fields(EnvConfig) if f.name == "reward"]
    assert set(f.metadata["choices"]) == set(REWARDS)
