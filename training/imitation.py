"""Imitation of the exact solver: behaviour cloning on expert demos, then DAgger.

The learner is the same :class:`eosp.models.agent.EOSPAgent` that PPO trains (same
observation, same checkpoint format), so an imitation checkpoint serves
``eosp solve --solver policy|mcts`` and ``jobs/train.py --train.init-checkpoint``.

Loss per state s with expert-optimal action set A*(s) (see :mod:`eosp.solvers.expert`):

* policy: ``-log sum_{a in A*} pi(a | s)``: the probability of choosing *an* optimal
  action (plain cross-entropy when A* has one element);
* value: squared error between the value head and the expert's remaining return in
  the environment's reward units (per class for the lexicographic heads), divided by
  ``value_scale`` squared like PPO's.

DAgger: behaviour cloning only sees the expert's states; the first mistake of the
learner leads it to states no demo covers.  Every ``dagger_every`` epochs the current
policy (sampling) plays training instances and every state it visits is labelled by
the expert (values of all allowed actions from the residual problem) as parallel
Ray tasks; the new states join the data set (aggregation).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from eosp.config import EnvConfig, ImitationConfig
from eosp.models.agent import EOSPAgent, batch_from_padded
from eosp.reward import objective_mode, reward
from eosp.training.samples import Sample


def samples_along(env, prepared, actions: np.ndarray, optimal: list[np.ndarray], values: np.ndarray,
                  q: list[tuple[np.ndarray, np.ndarray]] | None = None, scale: float = 1.0,
                  tolerance: float = 0.0) -> list[Sample]:
    """Replay `actions` and record the observation of every state before its action.

    `q`: per step, (allowed actions, their values) or empty arrays; when known, the optimal set is
    every action whose regret (Q* - Q(a)) / `scale` is at most `tolerance`, and the regrets are kept
    for the expected-regret loss."""
    obs, _ = env.reset(options={"instance": prepared})
    n = prepared.inst.n_acq
    out = []
    for t, a in enumerate(actions):
        m = int(obs["n_edges"][0])
        opt = optimal[t] if len(optimal[t]) else np.array([a], np.int32)
        allowed = regret = None
        if q is not None and len(q[t][0]):
            allowed, qv = q[t]
            regret = ((qv.max() - qv) / max(scale, 1e-300)).astype(np.float32)
            opt = allowed[regret <= tolerance + 1e-12]
        out.append(Sample(obs["x"][:n].copy(), obs["edge_index"][:, :m].copy(), obs["edge_attr"][:m].copy(),
                          obs["action_mask"][:n].copy(), np.asarray(opt, np.int32),
                          np.asarray(values[t], np.float32), allowed, regret))
        obs, *_ = env.step(int(a))
    return out


def collate(samples: list[Sample]) -> tuple[dict[str, torch.Tensor], torch.Tensor, torch.Tensor, torch.Tensor]:
    """Padded observation batch, optimal-action mask [B, N], value targets [B, V] and regrets [B, N]
    (NaN rows: regret unknown)."""
    b = len(samples)
    n = max(s.x.shape[0] for s in samples)
    m = max(1, max(s.edge_index.shape[1] for s in samples))
    f = samples[0].x.shape[1]
    x = np.zeros((b, n, f), np.float32)
    ei = np.zeros((b, 2, m), np.int32)
    ea = np.zeros((b, m, samples[0].edge_attr.shape[1]), np.float32)
    mask = np.zeros((b, n), np.int8)
    opt = np.zeros((b, n), bool)
    regret = np.full((b, n), np.nan, np.float32)
    for i, s in enumerate(samples):
        k, e = s.x.shape[0], s.edge_index.shape[1]
        x[i, :k], ei[i, :, :e], ea[i, :e], mask[i, :k] = s.x, s.edge_index, s.edge_attr, s.mask
        opt[i, s.optimal] = True
        if s.regret is not None:
            regret[i] = 0.0
            regret[i, s.allowed] = s.regret
    obs = {"x": torch.from_numpy(x), "edge_index": torch.from_numpy(ei), "edge_attr": torch.from_numpy(ea),
           "n_nodes": torch.tensor([[s.x.shape[0]] for s in samples], dtype=torch.int32),
           "n_edges": torch.tensor([[s.edge_index.shape[1]] for s in samples], dtype=torch.int32),
           "action_mask": torch.from_numpy(mask)}
    return obs, torch.from_numpy(opt), torch.from_numpy(np.stack([s.value for s in samples])), torch.from_numpy(regret)


def losses(agent: EOSPAgent, obs, opt, target, regret=None) -> dict[str, torch.Tensor]:
    """Policy loss (-log P(an optimal action)), value loss, expected regret under the policy (states with
    known action values), and the accuracy of the argmax, of one batch."""
    gb, valid = batch_from_padded(obs)
    logits, values = agent(gb)
    padded = agent.padded_logits(logits, valid)
    log_z = torch.logsumexp(padded, dim=-1)
    log_opt = torch.logsumexp(padded.masked_fill(~opt, float("-inf")), dim=-1)
    out = {"policy_loss": (log_z - log_opt).mean()}
    scale = agent.cfg.value_scale or 1.0
    known = ~torch.isnan(target)
    diff = torch.where(known, (values - torch.nan_to_num(target)) / scale, torch.zeros_like(values))
    out["value_loss"] = (diff ** 2).sum() / known.sum().clamp(min=1)
    out["regret"] = padded.new_zeros(())
    if regret is not None:
        rows = ~torch.isnan(regret[:, 0])
        if rows.any():
            p = torch.softmax(padded[rows], dim=-1)
            out["regret"] = (p * regret[rows]).sum(-1).mean()
    out["accuracy"] = opt.gather(1, padded.argmax(dim=-1, keepdim=True)).float().mean()
    return out


def label_states(shard: str, index: int, mode: str, actions: list[int], beam: int, prune: bool,
                 sets: bool = True):
    """Expert labels of the states along `actions` (a Ray task): optimal actions and best remaining values.

    With `sets`, every allowed action is valued (ties kept: unitary mode); without, the first action of
    the best continuation found by RAMP's beam search (one search per state instead of one per action:
    utility mode, where ties are rare).
    """
    from eosp.config import EnvConfig as _Env
    from eosp.envs.eosp_env import EOSPEnv
    from eosp.envs.sources import FixedSource, prepare_instance
    from eosp.shards.io import ShardReader
    from eosp.solvers import expert

    prepared = prepare_instance(ShardReader(shard).read(index, unpruned=not prune), prune)
    env = EOSPEnv(_Env(max_acquisitions=0, prune=prune), source=FixedSource(prepared))
    env.reset()
    w = expert.objective(prepared.inst, mode)
    labels, best = [], []
    for a in actions:
        if sets:
            allowed, q = expert.action_values(env, w, beam)
            labels.append(allowed[expert.optimal_set(q, mode == "unitary")])
            best.append(float(q.max()))
        else:
            path, value = expert.beam_path(expert.state_residual(env), w, beam)
            labels.append(path[:1])
            best.append(value)
        env.step(int(a))
    return labels, best


class DemoData:
    """Training instances with their demos, and the labelled states built from them."""

    def __init__(self, paths: tuple[str, ...], env_cfg: EnvConfig, n_values: int, set_tolerance: float = 0.0):
        from eosp.envs.eosp_env import EOSPEnv
        from eosp.envs.sources import FixedSource, expand_shards, prepare_instance
        from eosp.shards.io import ShardReader
        from eosp.training.demos import read_demos

        self.env_cfg, self.n_values = env_cfg, n_values
        self.mode = objective_mode(env_cfg)
        self.reward = reward(env_cfg.reward)
        self.instances: list[tuple[Path, int, object]] = []  # (shard, index, prepared)
        self.samples: list[Sample] = []
        self.start_values: list[float] = []
        self.optimal_values: list[float] = []
        demos = []
        for shard in expand_shards(list(paths)):
            reader = ShardReader(shard)
            unpruned = not env_cfg.prune or bool(env_cfg.plan)  # the plan features need the unpruned arcs
            prepared = [prepare_instance(reader.read(k, unpruned=unpruned), env_cfg.prune) for k in range(len(reader))]
            for d in read_demos(shard, self.mode, prepared):
                self.instances.append((shard, d.index, prepared[d.index]))
                self.optimal_values.append(d.value)
                demos.append(d)
        if not demos:
            raise ValueError(f"no demonstrations in {', '.join(paths)}")
        n_max = max(p.inst.n_acq for _, _, p in self.instances)
        self.env = EOSPEnv(replace(env_cfg, max_acquisitions=n_max, shards=()), source=FixedSource(self.instances[0][2]))
        for (_, _, p), d in zip(self.instances, demos):
            targets = self.reward.returns_to_go(p, d.actions, n_values)
            self.start_values.append(float(targets[0].max()) if len(targets) else 0.0)
            q = [(al, qv) for al, qv in zip(d.allowed, d.q)]
            self.samples += samples_along(self.env, p, d.actions, d.optimal, targets, q, d.value, set_tolerance)

    def add_policy_states(self, agent: EOSPAgent, n: int, beam: int, rng: np.random.Generator) -> dict:
        """One DAgger round: the policy samples episodes on `n` training instances, the expert labels them."""
        import ray

        from eosp.solvers.policy import rollout

        t0 = time.perf_counter()
        picks = rng.choice(len(self.instances), size=min(n, len(self.instances)), replace=False)
        trajectories = []
        for i in picks:
            shard, k, p = self.instances[i]
            nodes, _ = rollout(agent, p, self.env_cfg, sample=True, seed=int(rng.integers(1 << 30)))
            trajectories.append((i, p.eg.node_acq[nodes].astype(np.int32)))
        t_roll = time.perf_counter() - t0
        args = [(str(self.instances[i][0]), self.instances[i][1], self.mode, acts.tolist(), beam, self.env_cfg.prune,
                 self.mode == "unitary") for i, acts in trajectories]
        if ray.is_initialized():  # the labels are the expensive part: one Ray task per episode
            task = ray.remote(num_cpus=1)(label_states)
            labels = ray.get([task.remote(*x) for x in args])
        else:
            labels = [label_states(*x) for x in args]
        added, regret = 0, []
        for (i, acts), (sets, best) in zip(trajectories, labels):
            p = self.instances[i][2]
            values = np.stack([self.reward.to_units(v, p, self.n_values) for v in best]) if best else []
            self.samples += samples_along(self.env, p, acts, sets, values)
            added += len(acts)
            w = np.ones(p.inst.n_acq) if self.mode == "unitary" else p.inst.acqs.utility
            regret.append(float(w[acts].sum()) / max(best[0], 1e-300) if best else 1.0)
        return {"dagger/states_added": added, "dagger/sampled_ratio_to_expert": float(np.mean(regret)),
                "dagger/rollout_s": t_roll, "dagger/label_s": time.perf_counter() - t0 - t_roll,
                "dagger/dataset_states": len(self.samples)}


class WeightAverage:
    """Exponential moving average of a model's parameters and buffers (Polyak averaging): `model` holds it."""

    def __init__(self, agent: EOSPAgent, decay: float):
        import copy

        self.decay = decay
        self.model = copy.deepcopy(agent).eval()
        self.updates = 0

    @torch.no_grad()
    def update(self, agent: EOSPAgent) -> None:
        self.updates += 1
        d = min(self.decay, (1 + self.updates) / (10 + self.updates))  # short warm-up: early weights fade fast
        for avg, cur in zip(self.model.state_dict().values(), agent.state_dict().values()):
            if avg.dtype.is_floating_point:
                avg.mul_(d).add_(cur, alpha=1 - d)
            else:
                avg.copy_(cur)


def cosine_lr(lr: float, progress: float) -> float:
    """Half-cosine decay from `lr` at progress 0 to 0 at progress 1."""
    return 0.5 * lr * (1.0 + math.cos(math.pi * min(max(progress, 0.0), 1.0)))


def train_epoch(agent: EOSPAgent, opt: torch.optim.Optimizer, samples: list[Sample], im: ImitationConfig,
                rng: np.random.Generator, deadline: float | None = None, average: WeightAverage | None = None,
                lr_at=None) -> dict[str, float]:
    """One pass over `samples`, in batches of ``im.batch_size``, the loss weighted by ``im.value_coeff`` and
    ``im.regret_coeff``, gradients clipped at ``im.grad_clip``.  `lr_at(fraction of this epoch done)`: the
    learning rate of each batch (None: the optimizer's as it is); `average`: updated after every step."""
    batch_size, value_coeff, grad_clip, regret_coeff = im.batch_size, im.value_coeff, im.grad_clip, im.regret_coeff
    agent.train()
    order = rng.permutation(len(samples))
    tot = {"policy_loss": 0.0, "value_loss": 0.0, "regret": 0.0, "accuracy": 0.0}
    batches = 0
    for start in range(0, len(order), batch_size):
        if lr_at is not None:
            for g in opt.param_groups:
                g["lr"] = lr_at(start / len(order))
        obs, optm, target, regret = collate([samples[i] for i in order[start:start + batch_size]])
        parts = losses(agent, obs, optm, target, regret if regret_coeff > 0 else None)
        loss = parts["policy_loss"] + value_coeff * parts["value_loss"] + regret_coeff * parts["regret"]
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(agent.parameters(), grad_clip)
        opt.step()
        if average is not None:
            average.update(agent)
        for k in tot:
            tot[k] += parts[k].item()
        batches += 1
        if deadline is not None and time.perf_counter() > deadline:
            break
    agent.eval()
    return {f"train/{k}": v / max(batches, 1) for k, v in tot.items()} | {"train/batches": batches}


def fit(agent: EOSPAgent, data, validator, im: ImitationConfig, env_cfg, run_dir: Path, record: dict,
        dagger=None, job: str = "pretrain") -> list[dict]:
    """The imitation loop every imitation job shares (jobs/pretrain.py: the single pass; jobs/pretrain_fleet.py:
    fleets), inside an active MLflow run: epochs over ``data.samples`` (:func:`train_epoch`; cosine learning rate
    and weight averaging as `im` says), validation every ``im.validate_every`` epochs (``validator.run(policy)``,
    the checkpoint of the best :func:`eosp.training.validation.selection_score` saved as ``checkpoints/best``),
    ``dagger(policy, rng) -> metrics`` every ``im.dagger_every`` epochs (states added to ``data.samples``), until
    ``im.epochs`` or the time budget; then ``checkpoints/last``, the learning curve and ``history.json``.
    `env_cfg`: the environment configuration saved with the checkpoints; `record`: the run's whole configuration
    (a dict), kept in history.json with the history.  Returns the history."""
    import json

    import mlflow

    from eosp.atomic import atomic_path
    from eosp.models.checkpoint import save_agent
    from eosp.training.plots import imitation_curve
    from eosp.training.validation import primary_metric, selection_score

    rng = np.random.default_rng(im.seed)
    ckpt = run_dir / "checkpoints"
    opt = torch.optim.Adam(agent.parameters(), lr=im.lr, weight_decay=im.weight_decay)
    history, best = [], float("-inf")
    average = WeightAverage(agent, im.ema) if im.ema > 0 else None
    t0 = time.perf_counter()
    deadline = t0 + im.time_budget if im.time_budget > 0 else None
    for epoch in range(1, im.epochs + 1):
        lr_at = None
        if im.lr_schedule == "cosine":
            def lr_at(done: float, epoch: int = epoch) -> float:
                by_epochs = (epoch - 1 + done) / im.epochs
                by_time = (time.perf_counter() - t0) / im.time_budget if deadline is not None else 0.0
                return cosine_lr(im.lr, max(by_epochs, by_time))
        metrics = train_epoch(agent, opt, data.samples, im, rng, deadline, average, lr_at)
        metrics["train/lr"] = opt.param_groups[0]["lr"]
        policy = average.model if average is not None else agent  # what is validated, saved and rolled out
        out_of_time = deadline is not None and time.perf_counter() > deadline
        last = epoch == im.epochs or out_of_time
        if validator is not None and (epoch % im.validate_every == 0 or last):
            metrics.update(validator.run(policy).metrics)
            if selection_score(metrics) > best:
                best = selection_score(metrics)
                save_agent(policy, ckpt / "best", env_cfg, {"epoch": epoch, "val": metrics, "source": "imitation"})
        if dagger is not None and im.dagger_every and epoch % im.dagger_every == 0 and not last:
            metrics.update(dagger(policy, rng))
        metrics["wall_s"] = time.perf_counter() - t0
        history.append({"epoch": epoch, **metrics})
        mlflow.log_metrics(metrics, step=epoch)
        val = primary_metric(metrics) if "val/policy_mean" in metrics else None
        print(f"[{job}] epoch {epoch}: loss {metrics['train/policy_loss']:.4f} accuracy "
              f"{metrics['train/accuracy']:.4f} value {metrics['train/value_loss']:.4f}"
              + (f"  {val} {metrics[val]:.4f}" if val else "")
              + "".join(f" /{b} {metrics[f'val/ratio_to_{b}']:.4f}" for b in ("exact", "fleet", "ramp", "features",
                                                                               "greedy") if f"val/ratio_to_{b}" in metrics)
              + (f"  dagger +{metrics['dagger/states_added']:.0f} states" if "dagger/states_added" in metrics else "")
              + f"  ({metrics['wall_s']:.0f} s)", flush=True)
        if out_of_time:
            print(f"[{job}] time budget of {im.time_budget:.0f} s reached", flush=True)
            break
    policy = average.model if average is not None else agent
    save_agent(policy, ckpt / "last", env_cfg, {"epoch": history[-1]["epoch"], "source": "imitation"})
    if validator is None:
        save_agent(policy, ckpt / "best", env_cfg, {"epoch": history[-1]["epoch"], "source": "imitation"})
    png = imitation_curve(history, run_dir / "learning_curve")
    mlflow.log_artifact(str(png))
    mlflow.log_artifact(str(png.with_suffix(".svg")))
    with atomic_path(run_dir / "history.json") as tmp:
        tmp.write_text(json.dumps({"config": record, "history": history}, indent=1))
    mlflow.log_metric("perf/train_wall_s", time.perf_counter() - t0)
    return history
