"""Batched policy rollouts, sampling and policy-guided beam search, as a small library.

Like :mod:`eosp.search.mcts`: no Ray, no torch.  The caller gives an environment
with cheap ``snapshot`` / ``restore`` and an ``evaluate(list of obs) -> (logits
[B, N], values [B])`` function; many states advance in lockstep so that each
step costs ONE network call for all of them.

* :func:`sample`: K episodes from the policy (the first one greedy, so the result
  is never worse than the plain policy), best kept; repeated in rounds of K until
  the deadline (anytime).
* :func:`beam`: keep the W best partial schedules; each is extended by the
  policy's top-k actions, and each child is scored by its reward so far plus a
  greedy policy rollout from it (whose complete schedule is a candidate answer);
  the W best children go on.  Anytime: the best complete schedule met is returned
  when the deadline comes.

Both return actions (to replay) and the return in reward units, or, given ``improve``
(e.g. :meth:`eosp.search.polish.Polisher.actions`), every complete episode is improved
before it is compared and the return is the improved schedule's objective value.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

EvaluateMany = Callable[[list], tuple[np.ndarray, np.ndarray]]


@dataclass
class Best:
    """The best complete episode met so far.  `improve(actions) -> (value, actions)`: applied to every episode
    offered (then `ret` is in the improver's units, not in reward units).  Past `deadline`
    (``time.perf_counter()``), episodes are no longer taken once one is: at 1000 acquisitions polishing one costs
    ~0.2 s, and the 16 episodes of a sampling round, all finished at about the same time, would overrun the
    search's share of the time limit by seconds, taken from the refinement after it."""

    ret: float = -math.inf
    actions: list = field(default_factory=list)
    episodes: int = 0
    evaluations: int = 0
    improve: Callable[[list], tuple[float, list]] | None = None
    deadline: float | None = None
    on_best: Callable[[list], None] | None = None  # told of each new best episode's actions (a solver's incumbent)

    def offer(self, ret: float, actions: list) -> None:
        if self.actions and self.deadline is not None and time.perf_counter() > self.deadline:
            return
        self.episodes += 1
        if self.improve is not None:
            ret, actions = self.improve(actions)
        if not self.actions and self.ret == -math.inf or ret > self.ret + 1e-12 * max(1.0, abs(self.ret)):
            self.ret, self.actions = ret, list(actions)
            if self.on_best is not None:
                self.on_best(self.actions)


@dataclass
class _State:
    snap: object
    obs: dict
    ret: float
    actions: list
    done: bool


def choose(logits: np.ndarray, mask: np.ndarray, rng: np.random.Generator | None, temperature: float) -> int:
    """The allowed action of largest logit (`rng` None), or one drawn from the softmax of logits / temperature."""
    allowed = np.flatnonzero(mask)
    if rng is None:
        return int(allowed[np.argmax(logits[allowed])])
    z = (logits[allowed] - logits[allowed].max()) / max(temperature, 1e-6)
    p = np.exp(z)
    return int(rng.choice(allowed, p=p / p.sum()))


def rollout_many(env, starts: list[_State], evaluate: EvaluateMany, best: Best, *,
                 rng: np.random.Generator | None = None, temperature: float = 1.0,
                 deadline: float | None = None) -> list[float]:
    """Finish every start state with the policy (greedy, or sampled with `rng`), in lockstep.

    Returns each episode's return (states cut by the deadline count as their return so far
    and are not offered as complete).  Every finished episode is offered to `best`.
    """
    live = [_State(s.snap, s.obs, s.ret, list(s.actions), s.done) for s in starts]
    while True:
        todo = [i for i, s in enumerate(live) if not s.done]
        if not todo or (deadline is not None and time.perf_counter() > deadline):
            break
        logits, _ = evaluate([live[i].obs for i in todo])
        best.evaluations += 1
        for j, i in enumerate(todo):
            s = live[i]
            a = choose(logits[j], s.obs["action_mask"], rng, temperature)
            env.restore(s.snap)
            obs, r, done, _, _ = env.step(a)
            s.obs, s.ret, s.done = obs, s.ret + r, done or not obs["action_mask"].any()
            s.actions.append(a)
            s.snap = env.snapshot()
    for s in live:
        if s.done:
            best.offer(s.ret, s.actions)
    return [s.ret for s in live]


def root_state(env, seed: int = 0) -> _State:
    obs, _ = env.reset(seed=seed)
    return _State(env.snapshot(), obs, 0.0, [], not obs["action_mask"].any())


def sample(env, evaluate: EvaluateMany, *, samples: int = 16, temperature: float = 1.0, seed: int = 0,
           time_limit: float | None = None, max_rounds: int | None = None,
           improve: Callable[[list], tuple[float, list]] | None = None,
           on_best: Callable[[list], None] | None = None) -> Best:
    """Best of K episodes (the first greedy, always finished: the floor), then rounds of K sampled
    ones until the time limit.  With no time limit, one round (or `max_rounds`).  `samples` >= 1.
    """
    if samples < 1:
        raise ValueError(f"samples must be at least 1, got {samples}")
    t0 = time.perf_counter()
    deadline = None if time_limit is None else t0 + time_limit
    rng = np.random.default_rng(seed)
    root = root_state(env, seed)
    best = Best(improve=improve, deadline=deadline, on_best=on_best)
    if root.done:
        best.offer(0.0, [])
        return best
    rollout_many(env, [root], evaluate, best)  # the greedy episode, whatever the deadline: the anytime floor
    rounds, first = 0, samples - 1
    while True:
        if first > 0:
            rollout_many(env, [root] * first, evaluate, best, rng=rng, temperature=temperature, deadline=deadline)
        rounds, first = rounds + 1, samples
        if deadline is None and rounds >= (max_rounds or 1):
            break
        if deadline is not None and (time.perf_counter() > deadline or (max_rounds and rounds >= max_rounds)):
            break
    return best


def beam(env, evaluate: EvaluateMany, *, width: int = 4, expand: int = 4, seed: int = 0,
         time_limit: float | None = None, improve: Callable[[list], tuple[float, list]] | None = None,
         on_best: Callable[[list], None] | None = None) -> Best:
    """Policy-guided beam search scored by greedy rollouts (see the module docstring)."""
    if width < 1 or expand < 1:
        raise ValueError(f"beam width and expansion must be at least 1, got {width} and {expand}")
    t0 = time.perf_counter()
    deadline = None if time_limit is None else t0 + time_limit
    root = root_state(env, seed)
    best = Best(improve=improve, deadline=deadline, on_best=on_best)
    if root.done:
        best.offer(0.0, [])
        return best
    rollout_many(env, [root], evaluate, best)  # the plain policy first: beam never does worse
    beams = [root]
    while beams and (deadline is None or time.perf_counter() < deadline):
        logits, _ = evaluate([b.obs for b in beams])
        best.evaluations += 1
        children = []
        for b, lg in zip(beams, logits):
            allowed = np.flatnonzero(b.obs["action_mask"])
            top = allowed[np.argsort(-lg[allowed], kind="stable")[:expand]]
            for a in top:
                env.restore(b.snap)
                obs, r, done, _, _ = env.step(int(a))
                children.append(_State(env.snapshot(), obs, b.ret + r, b.actions + [int(a)],
                                       done or not obs["action_mask"].any()))
        scores = rollout_many(env, children, evaluate, best, deadline=deadline)
        order = np.argsort(-np.asarray(scores), kind="stable")
        beams = [children[i] for i in order if not children[i].done][:width]
    return best


def replay(env, actions: list, seed: int = 0) -> tuple[np.ndarray, float]:
    """Play `actions` from the reset state; the scheduled nodes and the return."""
    env.reset(seed=seed)
    total = 0.0
    for a in actions:
        _, r, _, _, _ = env.step(int(a))
        total += r
    return env.path(), total
