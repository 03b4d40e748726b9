"""Monte Carlo tree search with the learned policy and value (PUCT), as a small library.

No Ray here: :func:`search` takes an environment (for its cheap ``snapshot`` /
``restore``) and an ``evaluate(list of obs) -> (logits [B, N], values [B])``
function, and returns the action to play; :func:`solve` plays a whole episode.

* Selection: PUCT, ``argmax_a Q(s, a) + c_puct P(s, a) sqrt(N(s)) / (1 + N(s, a))``,
  with Q normalized to [0, 1] by the smallest and largest values seen in the tree
  (returns are in reward units: tens of acquisitions, or normalized utility).
* Expansion: a new node gets the network's priors and its value estimate; no
  random rollouts.  Terminal nodes are worth 0 to go.
* Unexplored children take their parent's value estimate as Q (the paper's choice:
  an infinite value would force visiting every child of a 100-way node first).
* Backup: along the path, G = reward + G; visit counts and value sums.
* Batched evaluation: ``batch`` descents are made one after the other with a
  *virtual loss* (each edge on the way counts one more visit worth the lowest
  value seen), then their new leaves are evaluated in one network call, then the
  virtual losses are replaced by the real backups.  ``batch=1`` is plain
  sequential MCTS; a batch of 8 amortizes the per-call overhead of a small GNN.
* Decision: the most visited root action (ties: the higher Q, then the lower
  index).  The subtree under it is kept for the next decision.
* The best complete episode met during the search is remembered; :func:`solve`
  returns it if it beats the episode actually played.

Deterministic: nothing is random (Gumbel root selection, :func:`gumbel_search`, draws from a
generator seeded by ``seed``), the same inputs give the same schedule.
With ``num_simulations=0`` the search returns the policy's argmax.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

EvaluateMany = Callable[[list], tuple[np.ndarray, np.ndarray]]


@dataclass
class Node:
    snapshot: object
    actions: np.ndarray  # allowed actions
    terminal: bool
    path_reward: float = 0.0  # rewards from the start of the episode to here
    parent: "Node | None" = None
    action: int = -1  # the action leading here from the parent
    prior: np.ndarray | None = None  # P(s, a) over `actions`; None until evaluated
    value: float = 0.0  # network estimate of the return to go
    obs: dict | None = None  # kept until evaluated
    visits: np.ndarray = field(default=None)  # N(s, a)
    value_sum: np.ndarray = field(default=None)  # W(s, a): sum of (reward + return below)
    reward: np.ndarray = field(default=None)  # r(s, a) once expanded
    children: dict = field(default_factory=dict)  # action index -> Node

    def __post_init__(self):
        k = len(self.actions)
        self.visits = np.zeros(k, dtype=np.int64)
        self.value_sum = np.zeros(k)
        self.reward = np.zeros(k)
        if self.terminal:
            self.prior = np.zeros(0)

    @property
    def pending(self) -> bool:
        return self.prior is None


@dataclass
class SearchStats:
    simulations: int = 0
    expansions: int = 0
    evaluations: int = 0  # network calls
    best_return: float = -math.inf
    best_actions: list = field(default_factory=list)  # the best complete episode met, from the episode start
    played: list = field(default_factory=list)  # actions played before the current root
    on_best: Callable[[list], None] | None = None  # told of each new best complete episode (a solver's incumbent)

    def record(self, leaf: Node) -> None:
        """Remember a terminal leaf's episode as an action list (no reference to the tree is kept)."""
        if leaf.path_reward > self.best_return:
            tail, node = [], leaf
            while node.parent is not None:
                tail.append(node.action)
                node = node.parent
            self.best_return, self.best_actions = leaf.path_reward, self.played + tail[::-1]
            if self.on_best is not None:
                self.on_best(self.best_actions)


class MinMax:
    def __init__(self):
        self.lo, self.hi = math.inf, -math.inf

    def update(self, q: float) -> None:
        self.lo, self.hi = min(self.lo, q), max(self.hi, q)

    def norm(self, q: np.ndarray) -> np.ndarray:
        if self.hi > self.lo:
            return (q - self.lo) / (self.hi - self.lo)
        return np.zeros_like(q)


def new_node(env, obs: dict, path_reward: float, terminal: bool, parent: Node | None = None,
             action: int = -1) -> Node:
    actions = np.flatnonzero(obs["action_mask"])
    terminal = terminal or actions.size == 0
    return Node(env.snapshot(), actions, terminal, path_reward, parent, action, obs=None if terminal else obs)


def evaluate_nodes(nodes: list[Node], evaluate: EvaluateMany, stats: SearchStats) -> None:
    """Priors and values of pending nodes (each once), in one network call."""
    todo = list({id(n): n for n in nodes if n.pending}.values())
    if not todo:
        return
    logits, values = evaluate([n.obs for n in todo])
    stats.evaluations += 1
    for n, lg, v in zip(todo, logits, values):
        z = lg[n.actions] - lg[n.actions].max()
        p = np.exp(z)
        n.prior, n.value, n.obs = p / p.sum(), float(v), None


def _select(node: Node, c_puct: float, minmax: MinMax) -> int:
    n = node.visits
    q = np.where(n > 0, node.value_sum / np.maximum(n, 1), node.value)  # unexplored: the parent's value
    score = minmax.norm(q) + c_puct * node.prior * math.sqrt(max(1, n.sum())) / (1 + n)
    return int(np.argmax(score))  # first maximum: deterministic


def _descend(env, root: Node, c_puct: float, minmax: MinMax, stats: SearchStats,
             forced: int | None = None) -> tuple[list, Node]:
    """Select down to a new (or terminal, or still pending) node; expand a new one with one env step.
    `forced`: the root's action (index) to take first (Gumbel root selection)."""
    node, path = root, []
    while True:
        k = forced if forced is not None and node is root else _select(node, c_puct, minmax)
        path.append((node, k))
        child = node.children.get(k)
        if child is None:
            env.restore(node.snapshot)
            obs, r, done, _, _ = env.step(int(node.actions[k]))
            node.reward[k] = r
            child = new_node(env, obs, node.path_reward + r, done, node, int(node.actions[k]))
            node.children[k] = child
            stats.expansions += 1
            return path, child
        if child.terminal or child.pending:
            return path, child
        node = child


def search(env, root: Node, evaluate: EvaluateMany, *, num_simulations: int, c_puct: float = 1.25,
           batch: int = 8, stats: SearchStats | None = None, deadline: float | None = None) -> int:
    """Run `num_simulations` simulations from `root` (the env's current state), fewer if the clock
    passes `deadline` (``time.perf_counter()``); return an index into ``root.actions``.  The
    environment is left in the root's state."""
    stats = stats or SearchStats()
    evaluate_nodes([root], evaluate, stats)
    if num_simulations <= 0 or root.terminal or root.actions.size == 1:  # nothing to search
        return int(np.argmax(root.prior)) if root.actions.size else -1
    minmax = MinMax()
    done = 0
    while done < num_simulations and (deadline is None or time.perf_counter() < deadline):
        descents = []
        for _ in range(min(batch, num_simulations - done)):
            path, leaf = _descend(env, root, c_puct, minmax, stats)
            loss = minmax.lo if minmax.lo < math.inf else 0.0
            for parent, k in path:  # virtual loss: steer the next descents elsewhere
                parent.visits[k] += 1
                parent.value_sum[k] += loss
            descents.append((path, leaf, loss))
        evaluate_nodes([leaf for _, leaf, _ in descents], evaluate, stats)
        for path, leaf, loss in descents:
            if leaf.terminal:
                stats.record(leaf)
            g = leaf.value
            for parent, k in reversed(path):
                g = parent.reward[k] + g
                parent.value_sum[k] += g - loss  # the real value replaces the virtual one
                minmax.update(parent.value_sum[k] / parent.visits[k])
            stats.simulations += 1
            done += 1
    env.restore(root.snapshot)
    n = root.visits
    q = np.where(n > 0, root.value_sum / np.maximum(n, 1), -np.inf)
    best = np.flatnonzero(n == n.max())
    return int(best[np.argmax(q[best])])


def _backup(path: list, leaf: Node, loss: float, minmax: MinMax, stats: SearchStats) -> None:
    if leaf.terminal:
        stats.record(leaf)
    g = leaf.value
    for parent, k in reversed(path):
        g = parent.reward[k] + g
        parent.value_sum[k] += g - loss
        minmax.update(parent.value_sum[k] / parent.visits[k])
    stats.simulations += 1


@dataclass(frozen=True)
class SearchParams:
    """How one decision is searched (mctx's search arguments as one value): the simulations per decision, the PUCT
    constant, the leaves evaluated per network call (PUCT), and whether the root is chosen by Gumbel-top-k with
    sequential halving (:func:`gumbel_search`) over at most `max_considered` actions, with its sigma constants."""

    num_simulations: int
    c_puct: float = 1.25
    batch: int = 8
    gumbel: bool = False
    max_considered: int = 16
    c_visit: float = 50.0
    c_scale: float = 1.0


def gumbel_search(env, root: Node, evaluate: EvaluateMany, params: SearchParams, *,
                  rng: np.random.Generator | None = None, stats: SearchStats | None = None,
                  deadline: float | None = None) -> int:
    """Root selection by Gumbel-top-k and sequential halving (Danihelka et al., 2022).

    m = min(max_considered, allowed) root actions are drawn without replacement by
    Gumbel(0) + logit; the simulation budget is split over ceil(log2 m) phases, each
    giving the remaining candidates equal visits (the root action is forced, PUCT
    below), after which the better half by g + logit + sigma(q) stays, with
    sigma(q) = (c_visit + max visits) * c_scale * q normalized to [0, 1] over the tree
    (per-instance value normalization) and q completed by the root value for an unvisited
    candidate.  With a few simulations this still improves on the policy: a candidate
    is only dropped for a worse simulated value.  Returns an index into ``root.actions``.
    """
    num_simulations, c_puct, max_considered = params.num_simulations, params.c_puct, params.max_considered
    c_visit, c_scale = params.c_visit, params.c_scale
    stats = stats or SearchStats()
    rng = rng or np.random.default_rng(0)
    evaluate_nodes([root], evaluate, stats)
    k_all = root.actions.size
    if num_simulations <= 0 or root.terminal or k_all <= 1:
        return int(np.argmax(root.prior)) if k_all else -1
    logits = np.log(np.maximum(root.prior, 1e-30))
    g = rng.gumbel(size=k_all)
    m = min(max_considered, k_all)
    cands = list(np.argsort(-(g + logits), kind="stable")[:m])
    minmax = MinMax()
    phases = max(1, math.ceil(math.log2(m)))
    left = num_simulations

    def score(idx: list) -> np.ndarray:
        n = root.visits
        q = np.where(n > 0, root.value_sum / np.maximum(n, 1), root.value)
        sigma = (c_visit + n.max()) * c_scale * minmax.norm(q)
        return (g + logits + sigma)[idx]

    for phase in range(phases):
        if left <= 0 or len(cands) == 1 or (deadline is not None and time.perf_counter() > deadline):
            break
        per = max(1, left // ((phases - phase) * len(cands)))
        for _ in range(per):
            descents = []
            for c in cands:
                path, leaf = _descend(env, root, c_puct, minmax, stats, forced=int(c))
                for parent, kk in path:
                    parent.visits[kk] += 1
                descents.append((path, leaf))
            evaluate_nodes([leaf for _, leaf in descents], evaluate, stats)
            for path, leaf in descents:
                _backup(path, leaf, 0.0, minmax, stats)
            left -= len(cands)
            if deadline is not None and time.perf_counter() > deadline:
                break
        keep = max(1, len(cands) // 2)
        order = np.argsort(-score(cands), kind="stable")[:keep]
        cands = [cands[i] for i in order]
    env.restore(root.snapshot)
    return int(cands[int(np.argmax(score(cands)))])


def solve(env, evaluate: EvaluateMany, params: SearchParams, *, reuse_tree: bool = True, seed: int = 0,
          time_limit: float | None = None,
          on_best: Callable[[list], None] | None = None) -> tuple[np.ndarray, float, SearchStats]:
    """Play one episode from the env's reset state with MCTS before each decision (`params`: how each is searched).

    The greedy policy's episode is played first (one network call per decision): the answer is
    never worse than the policy's own, and it is the answer if time runs out.  With `time_limit`
    (seconds for the whole episode) the search is anytime: each decision gets an equal share of
    the time left over the decisions the greedy episode suggests remain (at most
    `params.num_simulations` simulations each).
    Returns the scheduled nodes, the episode's return in reward units, and search statistics.
    `on_best(actions)`: told of the greedy episode, then of each better complete episode met.
    """
    t0 = time.perf_counter()
    stats = SearchStats(on_best=on_best)
    # the greedy episode first: a floor for the answer, and the time plan of an anytime search
    obs, _ = env.reset(seed=seed)
    ret, acts, done = 0.0, [], not obs["action_mask"].any()
    while not done:
        logits, _ = evaluate([obs])
        stats.evaluations += 1
        allowed = np.flatnonzero(obs["action_mask"])
        a = int(allowed[np.argmax(logits[0][allowed])])
        obs, r, done, _, _ = env.step(a)
        ret, done = ret + r, done or not obs["action_mask"].any()
        acts.append(a)
    stats.best_return, stats.best_actions, expected_steps = ret, acts, max(1, len(acts))
    if on_best is not None:
        on_best(acts)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    root = new_node(env, obs, 0.0, False)
    while not root.terminal:
        deadline = None
        if time_limit is not None:
            left = time_limit - (time.perf_counter() - t0)
            deadline = time.perf_counter() + max(0.0, left) / max(1, expected_steps - len(stats.played))
        if params.gumbel:
            k = gumbel_search(env, root, evaluate, params, rng=rng, stats=stats, deadline=deadline)
        else:
            k = search(env, root, evaluate, num_simulations=params.num_simulations, c_puct=params.c_puct,
                       batch=params.batch, stats=stats, deadline=deadline)
        child = root.children.get(k) if reuse_tree else None
        obs, r, done, _, _ = env.step(int(root.actions[k]))
        if child is None:
            child = new_node(env, obs, root.path_reward + r, done, root, int(root.actions[k]))
        stats.played.append(int(root.actions[k]))
        root = child
        root.parent = None  # the rest of the old tree can go: memory stays one subtree
        env.restore(root.snapshot)
    nodes, total = env.path(), root.path_reward
    if stats.best_actions and stats.best_return > total + 1e-9 * max(1.0, abs(total)):
        # a complete episode met during the search beats the one played: that is the answer
        env.reset(seed=seed)
        for a in stats.best_actions:
            env.step(a)
        nodes, total = env.path(), stats.best_return
    return nodes, total, stats
