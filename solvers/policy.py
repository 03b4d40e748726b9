"""Decode a schedule with the trained agent: greedy (argmax) or sampled with a seed.

    eosp solve INSTANCE_DIR --solver policy --checkpoint runs/NAME/checkpoints/best --out s.parquet
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from eosp.envs.eosp_env import EOSPEnv
from eosp.envs.sources import FixedSource, PreparedInstance, prepare_instance
from eosp.config import CLASS_UTILITIES, EnvConfig
from eosp.instances.instance import Instance
from eosp.envs.observation import PLAN
from eosp.models.agent import MASKED, EOSPAgent, batch_from_padded
from eosp.solvers.base import INCUMBENT, LearnedConfig, SearchConfig, Solution, objective_weights


def to_batch(obs: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
    return {k: torch.as_tensor(v)[None] for k, v in obs.items()}


def guarded(logits: np.ndarray, x: np.ndarray, guard: float) -> np.ndarray:
    """`logits` [..., N] with the actions whose Greedy rollout value is below ``(1 - guard)`` times the best
    allowed action's (the after_ratio plan feature, x[..., PLAN + 5] = V(a) / max V) forbidden (set to MASKED), in
    place; `guard` 1: unchanged.  The action of largest rollout value has ratio 1, so an allowed action always
    remains; without plan features every ratio is 0 and nothing is forbidden."""
    if guard < 1.0:
        ratio = x[..., :logits.shape[-1], PLAN + 5]
        logits[(ratio > 0.0) & (ratio < 1.0 - guard)] = MASKED
    return logits


@torch.no_grad()
def evaluate(agent: EOSPAgent, obs: dict[str, np.ndarray], guard: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Per-acquisition logits (forbidden: very negative; with `guard`, see :func:`guarded`) and the value head of
    one observation."""
    gb, valid = batch_from_padded(to_batch(obs))
    logits, values = agent(gb)
    return guarded(agent.padded_logits(logits, valid)[0].numpy(), obs["x"], guard), values[0].numpy()


@torch.no_grad()
def evaluate_batch(agent: EOSPAgent, obss: list[dict[str, np.ndarray]],
                   value_weights: np.ndarray | None = None, guard: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Logits [B, N] and scalar values [B] of several observations of one instance, in one call.

    The value is the first head's, or with `value_weights` the heads' weighted sum (a lexicographic
    model's per-class values turned into the normalized reward's units, see :func:`value_weights`).
    `guard`: see :func:`guarded`.
    """
    batch = {k: torch.as_tensor(np.stack([o[k] for o in obss])) for k in obss[0]}
    gb, valid = batch_from_padded(batch)
    logits, values = agent(gb)
    v = values.numpy()
    logits = guarded(agent.padded_logits(logits, valid).numpy(), batch["x"].numpy(), guard)
    return logits, (v[:, 0] if value_weights is None else v @ value_weights)


def value_weights(agent: EOSPAgent, prepared: PreparedInstance) -> np.ndarray | None:
    """For a model with one value head per priority class (lexicographic reward): the class utilities over
    the instance's mean utility, so that searches compare values in the normalized reward's units."""
    n = agent.cfg.n_values
    if n == 1:
        return None
    return np.asarray(CLASS_UTILITIES[:n], dtype=np.float64) / prepared.mean_utility


def make_env_for(prepared: PreparedInstance, env_cfg: EnvConfig) -> EOSPEnv:
    """An environment sized to this (already prepared) instance, with the agent's env settings."""
    return EOSPEnv(replace(env_cfg, max_acquisitions=0, shards=()), source=FixedSource(prepared))


def rollout(agent: EOSPAgent, prepared: PreparedInstance, env_cfg: EnvConfig, sample: bool = False,
            seed: int = 0, guard: float = 1.0, incumbent: bool = False) -> tuple[np.ndarray, float]:
    """Play one episode with the agent (`guard`: see :func:`guarded`); returns the scheduled nodes and the
    schedule's utility.

    `incumbent` (instances with their unpruned graph): every state's partial schedule completed by Greedy (the
    plan the plan features show, or Greedy's two orders for models without them, :meth:`EOSPEnv.completion`)
    is a complete feasible schedule; the best of them, in the plan's worth, is returned, the episode's own
    when tied.  The state at reset completes into Greedy's own schedule (or the better of two orders), so the
    result is never below Greedy's, and never below the episode's.  (Label plan features: the completions are
    the label sweep's chains, so never below the episode's; Greedy is not among them.)"""
    episode, value, best = play(agent, prepared, env_cfg, sample, seed, guard, incumbent)
    return best if best is not None else (episode, value)


def play(agent: EOSPAgent, prepared: PreparedInstance, env_cfg: EnvConfig, sample: bool = False, seed: int = 0,
         guard: float = 1.0, incumbent: bool = False) -> tuple[np.ndarray, float, tuple[np.ndarray, float] | None]:
    """One episode (see :func:`rollout`): its nodes and utility, and with `incumbent` the best completed state's
    (nodes, utility), or None."""
    env = make_env_for(prepared, env_cfg)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    best = None  # (worth, prefix nodes, completion nodes, utility) of the best completed state; ties: the later
    done = not obs["action_mask"].any()
    while True:
        completed = env.completion() if incumbent else None  # None: no unpruned graph, and so at every state
        if completed is not None and (best is None or completed[2] >= best[0] * (1.0 - 1e-12)):
            nodes, value, worth = completed
            best = (worth, env.path(), nodes, value)
        if done:
            break
        logits, _ = evaluate(agent, obs, guard)
        if sample:
            allowed = np.flatnonzero(obs["action_mask"])
            z = logits[allowed] - logits[allowed].max()
            p = np.exp(z) / np.exp(z).sum()
            a = int(rng.choice(allowed, p=p))
        else:
            a = int(np.argmax(logits))
        obs, _, done, _, info = env.step(a)
    # the last state's completion is the episode's own schedule (completed if the plan fits more)
    kept = None if best is None else (np.concatenate([best[1], best[2]]), best[3])
    return env.path(), env.state.value, kept


def resolve_agent(solver: str, checkpoint: str, agent: tuple | None, mode: str = "utility", *,
                  n_acquisitions: int = 0, time_limited: bool = False) -> tuple:
    """The (agent, env config, metadata) given, loaded from `checkpoint` (a directory, or ``pretrained:NAME`` for a
    shipped model by name, eosp.models.pretrained), or the shipped model that serves `mode` (for a time-limited
    search on a large instance, the mode's fast model: eosp.models.pretrained.default_name)."""
    if agent is not None:
        return agent
    torch.set_num_threads(1)
    from eosp.models.pretrained import PREFIX, default_name, load_pretrained

    if not checkpoint or checkpoint.startswith(PREFIX):  # pretrained:NAME, a shipped model by name
        return load_pretrained(checkpoint[len(PREFIX):] if checkpoint
                               else default_name(mode, n_acquisitions, time_limited))
    from eosp.models.checkpoint import load_agent

    return load_agent(checkpoint)


@dataclass
class PolicyConfig(LearnedConfig):
    """One episode of the trained agent; one pass, so no time limit."""

    sample: bool = False
    """Sample actions (seeded by --seed) instead of taking the argmax."""

    incumbent: bool = True
    """Keep the best complete schedule seen: every state's partial schedule completed by Greedy is one, the first
    of them Greedy's own; the best is returned when it beats the episode's.  Never below Greedy nor below the
    policy's own episode, at the cost of one Greedy completion a step (two orders for models without plan
    features).  Needs the instance's unpruned graph (loaded by every generator and interchange import).  A model
    reading the label plan (--env.plan label) completes each state by the label sweep's chain instead (no
    unpruned graph needed): never below its own episode, and usually at or above Greedy, though not by
    construction."""

    polish: bool = True
    """Improve the returned schedule by local moves (eosp.search.polish, milliseconds at 100-1000 acquisitions):
    insert an unscheduled acquisition where it fits, or drop one for others worth more (in unitary mode: two for
    one), until no move improves; with the incumbent, both it and the episode are polished and the better kept.
    Never worse than the episode (or the incumbent).  Needs nothing but the instance's graph (the unpruned one when
    the instance has it); --polish false: the decoded schedule as is."""

    NAME = "policy"
    ONE_SHOT = True


def polisher_for(prepared: PreparedInstance, cfg: SearchConfig):
    """The search's improver of complete episodes, or None with ``polish`` off: a
    :class:`eosp.search.polish.Polisher` for the objective of cfg.mode on the unpruned graph when the instance has
    it (more moves: the pruned graph lacks the arc that skips a dropped acquisition, and a pruned path can end
    in a node whose pruned arcs all lead to acquisitions already scheduled), its windows sweeping the pruned graph's
    arcs (cfg.window_graph), else on the environment's graph."""
    if not cfg.polish:
        return None
    from eosp.search.polish import Polisher

    inst = prepared.inst
    if inst.unpruned_graph is None:  # the environment's (pruned) graph for everything
        return Polisher(prepared.eg, objective_weights(inst, cfg.mode))
    return Polisher(inst.unpruned_graph, objective_weights(inst, cfg.mode),
                    window_graph=inst.pruned() if cfg.window_graph == "pruned" else None)


def incumbent_reporter(prepared: PreparedInstance, mode: str):
    """`on_best(actions)` for the searches: a complete episode's path in the environment's graph, reported to the
    solvers' :data:`eosp.solvers.base.INCUMBENT` with its objective value (what Ctrl-C writes)."""
    from eosp.planning.chain import walk

    eg, weights = prepared.eg, objective_weights(prepared.inst, mode)

    def report(actions: list) -> None:
        nodes = walk(eg, actions)
        if not isinstance(nodes, int):
            INCUMBENT.offer(nodes, float(weights[eg.node_acq[nodes]].sum()) if len(nodes) else 0.0)

    return report


def search_time(cfg: SearchConfig) -> float | None:
    """The part of cfg.time_limit the learned search itself gets: the rest goes to refining (cfg.refine)."""
    if cfg.time_limit is None or not cfg.polish:
        return cfg.time_limit
    return cfg.time_limit * (1.0 - cfg.refine)


def finish(polisher, nodes: np.ndarray, cfg: SearchConfig, t0: float) -> np.ndarray:
    """The search's best schedule, refined (ruin and recreate, and window re-planning with cfg.windows) until
    t0 + cfg.time_limit when refining."""
    if polisher is None or cfg.time_limit is None or cfg.refine <= 0:
        return nodes
    return polisher.refine(nodes, deadline=t0 + cfg.time_limit, seed=cfg.seed, windows=cfg.windows)


def run_search(name: str, inst: Instance, cfg: SearchConfig, agent: tuple | None, search, **info) -> Solution:
    """The frame every rollout search shares: the agent (given, from cfg.checkpoint, or the shipped model of the
    mode), an environment sized to the instance, ``search(env, evaluate, improve, time_limit, on_best) -> Best``
    (the time limit less the refining share; `on_best` reports each better episode to the solvers' incumbent,
    what Ctrl-C writes), its best episode replayed and scored (:mod:`eosp.search.rollouts`), then refined for the
    rest of the time (:func:`finish`)."""
    import time

    from eosp.search.rollouts import replay

    model, env_cfg, _ = resolve_agent(name, cfg.checkpoint, agent, cfg.mode, n_acquisitions=inst.n_acq,
                                      time_limited=cfg.time_limit is not None)
    prepared = prepare_instance(inst, env_cfg.prune)
    env = make_env_for(prepared, env_cfg)
    polisher = polisher_for(prepared, cfg)  # set-up (kernels compiled), before the clock starts
    if polisher is not None:  # every polished schedule the search meets is its incumbent (Ctrl-C writes it)
        polisher.on_improve = INCUMBENT.offer
    t0 = time.perf_counter()
    best = search(env, lambda obss: evaluate_batch(model, obss, guard=cfg.guard),
                  None if polisher is None else polisher.actions,
                  search_time(cfg), incumbent_reporter(prepared, cfg.mode))
    # polished actions may use arcs the environment's (pruned) graph lacks: their nodes come from the polisher
    nodes = replay(env, best.actions, cfg.seed)[0] if polisher is None else polisher.nodes_of(best.actions)
    nodes = finish(polisher, nodes, cfg, t0)
    return Solution.from_path(inst, nodes, cfg.mode, {"solver": name, **info, "polish": cfg.polish,
                                                      "refine": cfg.refine, "windows": cfg.windows,
                                                      "window_graph": cfg.window_graph,
                                                      "episodes": best.episodes,
                                                      "evaluations": best.evaluations,
                                                      "seconds": time.perf_counter() - t0})


def solve(inst: Instance, cfg: PolicyConfig | None = None, *, agent: tuple | None = None) -> Solution:
    """`agent`: an already loaded (agent, env config, metadata) from models.checkpoint.load_agent."""
    cfg = cfg or PolicyConfig()
    cfg.validate()
    agent, env_cfg, _ = resolve_agent("policy", cfg.checkpoint, agent, cfg.mode)
    prepared = prepare_instance(inst, env_cfg.prune)
    episode, _, kept = play(agent, prepared, env_cfg, sample=cfg.sample, seed=cfg.seed, guard=cfg.guard,
                            incumbent=cfg.incumbent)
    nodes = episode if kept is None else kept[0]
    if cfg.polish:  # the moves only (no refining: a one-shot solver has no time limit to fill)
        # both the incumbent and the episode: local moves from two schedules of equal worth can end far apart
        # (a conflict instance at 100 acquisitions: 0.86 from one, the optimum from the other)
        polisher = polisher_for(prepared, SearchConfig(mode=cfg.mode, polish=True, window_graph="unpruned"))
        tried = [polisher(n) for n in ([nodes] if kept is None else [nodes, episode])]
        nodes = max(tried, key=polisher.value)  # ties: the first (the incumbent's)
    return Solution.from_path(inst, nodes, cfg.mode, {"solver": "policy", "sample": cfg.sample,
                                                      "incumbent": cfg.incumbent, "polish": cfg.polish})
