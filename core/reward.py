"""The reward variants as objects: what a step is worth, in which units values are learned and compared.

Why: the variant is configuration (``EnvConfig.reward``, a string, so that configs stay plain data), but what
it means was written as string branches in the environment, the imitation targets, validation, the PPO
set-up and the jobs; a new variant had to find all of them.  Here each variant is one small class, and
:func:`reward` turns the configured name into it at the boundary; the users call its methods.

The objective (what a schedule's value counts, the solvers' ``mode``) is 'unitary' (acquisitions) for the
unitary reward and 'utility' (the sum of utilities) for the others.  Reward units: the environment's per-step
rewards summed; a value in objective units divided by :meth:`Reward.scale` is in reward units.

`prepared` below is an :class:`eosp.envs.sources.PreparedInstance` (read for ``mean_utility`` and
``priority``, the class of each acquisition, 0 highest).
"""

from __future__ import annotations

import numpy as np

from eosp.config import CLASS_UTILITIES, N_CLASSES


class Reward:
    """A reward variant (stateless): subclasses set the names and override what differs."""

    name = ""
    objective = "utility"  # 'unitary' (count acquisitions) or 'utility' (sum utilities)
    per_class = False  # a vector reward, one component per priority class (info['reward_vector'])
    n_values = 1  # value heads a model needs at least for this reward

    def scale(self, prepared) -> float | None:
        """Objective units per reward unit (None: the reward does not follow from the objective's value)."""
        return 1.0

    def step(self, u: float, a: int, prepared, info: dict) -> float:
        """The scalar reward of scheduling acquisition `a` of utility `u`; vector rewards go to `info`."""
        return u

    def step_rewards(self, prepared, actions: np.ndarray) -> np.ndarray:
        """Per-step rewards of playing `actions` in order, one column per value they are learned as: [T, k]."""
        return (prepared.inst.acqs.utility[actions])[:, None]

    def returns_to_go(self, prepared, actions: np.ndarray, n_values: int) -> np.ndarray:
        """The remaining return from each step of `actions`, in reward units: [T, n_values or 1]."""
        per = self.step_rewards(prepared, actions)
        if self.per_class and n_values <= N_CLASSES:
            per = per[:, :n_values]
        return np.cumsum(per[::-1], axis=0)[::-1]

    def to_units(self, v_objective: float, prepared, n_values: int) -> np.ndarray:
        """A remaining objective value (count or utility) in reward units; NaN where it cannot be split."""
        return np.array([v_objective / self.scale(prepared)], np.float32)

    def episode_return(self, total: float, per_class) -> float:
        """The size of an episode's return that value targets are scaled by: the scalar rewards' sum `total`
        (`per_class`: the sum of the vector rewards, for a per-class reward)."""
        return total


class Normalized(Reward):
    """u_a over the instance's mean utility (the paper): returns of similar size on instances of any scale."""

    name = "normalized"

    def scale(self, prepared) -> float:
        return prepared.mean_utility

    def step(self, u: float, a: int, prepared, info: dict) -> float:
        return u / prepared.mean_utility

    def step_rewards(self, prepared, actions: np.ndarray) -> np.ndarray:
        return (prepared.inst.acqs.utility[actions] / prepared.mean_utility)[:, None]


class Lexicographic(Normalized):
    """The normalized reward as the scalar, and in info['reward_vector'] u_a / V_c in the component of a's
    class c: a learner compares returns class by class, highest first (training/lexicographic.py)."""

    name = "lexicographic"
    per_class = True
    n_values = N_CLASSES

    def scale(self, prepared) -> None:
        return None

    def step(self, u: float, a: int, prepared, info: dict) -> float:
        r = u / prepared.mean_utility
        vec = np.zeros(N_CLASSES, dtype=np.float32)
        c = int(prepared.priority[a])
        vec[min(c, N_CLASSES - 1)] = u / CLASS_UTILITIES[min(c, N_CLASSES - 1)]
        info["reward_vector"] = vec
        return r

    def step_rewards(self, prepared, actions: np.ndarray) -> np.ndarray:
        u = prepared.inst.acqs.utility[actions]
        c = np.minimum(prepared.priority[actions].astype(np.int64), N_CLASSES - 1)
        per = np.zeros((actions.shape[0], N_CLASSES))
        per[np.arange(actions.shape[0]), c] = u / np.asarray(CLASS_UTILITIES)[c]
        return per

    def to_units(self, v_objective: float, prepared, n_values: int) -> np.ndarray:
        return np.full(n_values, np.nan, np.float32)

    def episode_return(self, total: float, per_class) -> float:
        # the heads learn per-class counts: scaled by the largest one
        return float(np.max(per_class))


class Unitary(Reward):
    """1 per acquisition: the objective is the count."""

    name = "unitary"
    objective = "unitary"

    def step(self, u: float, a: int, prepared, info: dict) -> float:
        return 1.0

    def step_rewards(self, prepared, actions: np.ndarray) -> np.ndarray:
        return np.ones_like(prepared.inst.acqs.utility[actions])[:, None]


class Utility(Reward):
    """u_a, unscaled: returns in the instance's own utility units."""

    name = "utility"


REWARDS = {r.name: r for r in (Normalized(), Utility(), Unitary(), Lexicographic())}


def reward(name: str) -> Reward:
    """The reward variant of a configured name (``EnvConfig.reward``)."""
    try:
        return REWARDS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown reward {name!r}; one of {', '.join(REWARDS)}") from None


def objective_mode(env_cfg) -> str:
    """The objective (a solver's ``mode``: 'unitary' or 'utility') of an :class:`eosp.config.EnvConfig`'s reward."""
    return reward(env_cfg.reward).objective
