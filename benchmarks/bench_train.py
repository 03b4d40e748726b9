"""PPO training throughput: the real loop of jobs/train.py, with the split of an iteration.

    python benchmarks/bench_train.py                          # 100 acquisitions, cpu preset, defaults
    python benchmarks/bench_train.py --acquisitions 300

The algorithm is built by ``eosp.training.ppo.ppo_config`` from a ``RunConfig``
(the path of jobs/train.py: same env, model preset, PPO settings), on a local
Ray with 2 CPUs, on generated uniform instances (built once under
``data/bench/``).  After ``--warmup`` iterations (numba compilation, Ray
start-up), ``--iterations`` are timed.  Printed per iteration and in total:

* sampling (timed by wrapping the env runners' methods in their processes):
  env step (and the share of it spent building observations, measured apart in
  this process), module inference, RLlib connectors, the rest (episode
  bookkeeping, resets, transfers);
* learning (the local learner, timed by wrapping its methods in this process):
  learner connectors (batch building and GAE, whose value pass is shown apart),
  forward, loss, backward, optimizer, the rest (minibatch slicing, metrics);
* weight sync and what is left of the iteration;
* peak RSS of the driver and of the env runners;

and as the last line ``train_env_steps_per_s=<x>`` (env steps sampled per second
of ``algo.train()`` over the timed iterations).
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import resource
import sys
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Args:
    acquisitions: int = 100
    """Acquisitions per training instance (any size works)."""
    instances: int = 32
    """Training instances (generated once under data/bench/, uniform family)."""
    iterations: int = 5
    """Timed PPO iterations."""
    warmup: int = 1
    """Untimed iterations first (compilation, start-up)."""
    preset: str = "cpu"
    """Model preset (eosp.config.MODEL_PRESETS)."""
    reward: str = "unitary"
    num_env_runners: int = 1
    num_envs_per_env_runner: int = 0
    """0: the default of TrainConfig."""
    overlap_sampling: bool = True
    """Sample the next batch while learning (eosp.config.TrainConfig.overlap_sampling, on by default)."""
    num_gpus_per_learner: float = 0.0
    """GPU learner (refused in one line where Ray sees no GPU)."""
    json_out: str = ""
    """Write the figures of this run as JSON here."""


def parse(argv: list[str] | None) -> Args:
    from eosp.args import add_config_args, config_from_args

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    add_config_args(p, Args)
    return config_from_args(Args, p.parse_args(argv))


def data_set(a: Args) -> Path:
    """The benchmark's training set, generated on first use (seed fixed: every run trains on the same)."""
    from eosp.config import DatasetConfig, RayConfig
    from eosp.jobs.build_shards import run as build

    out = ROOT / "data" / "bench" / f"train-{a.acquisitions}-{a.instances}"
    if not (out / "manifest.json").exists():
        print(f"[bench] generating {a.instances} instances of {a.acquisitions} acquisitions in {out}", flush=True)
        build(DatasetConfig(out=str(out), family="uniform", n_acquisitions=a.acquisitions, n_instances=a.instances,
                            per_shard=8, seed=770_000), RayConfig())
    return out


class Clock:
    """Seconds spent in wrapped callables, by name."""

    def __init__(self):
        self.total: dict[str, float] = {}

    def wrap(self, obj, attr: str, name: str) -> None:
        """Time calls of ``obj.attr``: a method gets a timing function, a callable object (an RLlib connector
        pipeline, whose other attributes RLlib uses) a proxy that times ``__call__`` and forwards the rest."""
        inner = getattr(obj, attr)
        clock = self

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                clock.total[name] = clock.total.get(name, 0.0) + time.perf_counter() - t0

        if inspect.ismethod(inner) or inspect.isfunction(inner):
            setattr(obj, attr, timed)
            return

        class Timed:
            def __call__(self, *args, **kwargs):
                return timed(*args, **kwargs)

            def __getattr__(self, item):
                return getattr(inner, item)

        setattr(obj, attr, Timed())

    def take(self) -> dict[str, float]:
        out, self.total = self.total, {}
        return out


def instrument(algo) -> Clock:
    """Wrap the local learner's steps (this process) so that their time is measured."""
    clock = Clock()
    learner = algo.learner_group._learner
    if learner is None:
        raise SystemExit("bench_train: the learner must be local (num_learners=0) to be timed")
    module = learner.module["default_policy"]
    clock.wrap(learner, "_learner_connector", "learn/connectors")
    clock.wrap(module, "compute_values", "learn/connectors: of which value pass (GAE)")
    clock.wrap(module, "forward_train", "learn/forward")
    clock.wrap(learner, "compute_losses", "learn/loss")
    clock.wrap(learner, "compute_gradients", "learn/backward")
    clock.wrap(learner, "postprocess_gradients", "learn/optimizer")  # gradient clipping
    clock.wrap(learner, "apply_gradients", "learn/optimizer")
    clock.wrap(algo.learner_group, "update", "learn/total")
    clock.wrap(algo.env_runner_group, "sync_weights", "sync weights")
    return clock


def runner_rss_mb(algo) -> list[float]:
    def peak(_runner):
        import resource as r

        return r.getrusage(r.RUSAGE_SELF).ru_maxrss / 1024

    return [float(x) for x in algo.env_runner_group.foreach_env_runner(peak, local_env_runner=False)]


def instrument_runners(algo) -> None:
    """Wrap each env runner's env step, module inference and connectors (in the runner's process)."""
    def setup(runner):
        clock = Clock()
        clock.wrap(runner.env, "step", "sample/env step (with observation)")
        clock.wrap(runner.module, "forward_exploration", "sample/inference")
        clock.wrap(runner, "_env_to_module", "sample/connectors")
        clock.wrap(runner, "_module_to_env", "sample/connectors")
        runner.bench_clock = clock
        return True

    algo.env_runner_group.foreach_env_runner(setup, local_env_runner=False)


def sampling_split(algo) -> dict[str, float]:
    """Seconds of the last iteration's sampling by part, averaged over the env runners (they run in parallel)."""
    per_runner = algo.env_runner_group.foreach_env_runner(lambda r: r.bench_clock.take(), local_env_runner=False)
    keys = {k for d in per_runner for k in d}
    return {k: sum(d.get(k, 0.0) for d in per_runner) / len(per_runner) for k in keys}


def observation_share(data: Path, cfg, steps: int = 600) -> float:
    """Fraction of an env step spent building the observation (both in numba), measured in this process."""
    import numpy as np

    from eosp.envs.eosp_env import EOSPEnv
    from eosp.envs.observation import build_observation
    from eosp.envs.sources import ShardSource, expand_shards

    env = EOSPEnv(cfg, source=ShardSource(expand_shards([str(data)]), max_cached=8, prune=cfg.prune))
    rng = np.random.default_rng(0)
    t_step = t_obs = 0.0
    obs, _ = env.reset(seed=0)
    for i in range(steps + 50):
        a = int(rng.choice(np.flatnonzero(obs["action_mask"])))
        t0 = time.perf_counter()
        obs, _, done, _, _ = env.step(a)
        t1 = time.perf_counter()
        s = env.state
        bufs = env._buffers()
        t2 = time.perf_counter()
        build_observation(s.prepared.eg, s.ep, s.prepared.cand, env._obs_options()[:5] + (0,), (*bufs, None))
        t3 = time.perf_counter()
        if i >= 50:  # compiled by then
            t_step, t_obs = t_step + t1 - t0, t_obs + t3 - t2
        if done:
            obs, _ = env.reset(seed=i)
    return t_obs / t_step


def bench(a: Args) -> dict:
    import ray
    import torch

    from eosp.config import MODEL_PRESETS, ModelConfig, RunConfig, from_dict
    from eosp.training.ppo import estimate_value_scale, ppo_config

    torch.set_num_threads(1)
    ray.init(address="local", num_cpus=max(2, a.num_env_runners + 1), include_dashboard=False,
             log_to_driver=False)
    data = data_set(a)
    cfg = RunConfig(model=from_dict(ModelConfig, MODEL_PRESETS[a.preset]))
    cfg.train.train_data, cfg.train.val_data = str(data), ""
    cfg.train.num_env_runners = a.num_env_runners
    if a.num_envs_per_env_runner:
        cfg.train.num_envs_per_env_runner = a.num_envs_per_env_runner
    cfg.env.reward = a.reward
    cfg.train.overlap_sampling = a.overlap_sampling
    cfg.train.num_gpus_per_learner = a.num_gpus_per_learner
    cfg.env.max_acquisitions = max(cfg.env.max_acquisitions, a.acquisitions)
    cfg.model.value_scale = estimate_value_scale(cfg)
    from eosp.jobs.preflight import ray_nodes, require_cluster_fits

    require_cluster_fits(cfg.train, ray_nodes(), torch.cuda.device_count() if a.num_gpus_per_learner > 0 else None)
    obs_share = observation_share(data, cfg.env)
    algo = ppo_config(cfg).build_algo()
    clock = instrument(algo)
    instrument_runners(algo)
    rows, steps_prev = [], 0
    for it in range(a.warmup + a.iterations):
        t0 = time.perf_counter()
        r = algo.train()
        wall = time.perf_counter() - t0
        steps = int(r.get("num_env_steps_sampled_lifetime", 0))
        learned, split = clock.take(), sampling_split(algo)
        n = steps - steps_prev
        steps_prev = steps
        if it < a.warmup:
            continue
        learn_total = learned.pop("learn/total", 0.0)
        sync = learned.pop("sync weights", 0.0)
        sample_total = max(0.0, wall - learn_total - sync)
        split["sample/other"] = max(0.0, sample_total - sum(split.values()))
        env_step = split.get("sample/env step (with observation)", 0.0)
        split["sample/env step: of which observation"] = obs_share * env_step
        inner = sum(v for k, v in learned.items() if ": of which" not in k)
        learned["learn/other"] = max(0.0, learn_total - inner)
        rows.append({"wall": wall, "steps": n, "sample": sample_total, "learn": learn_total, "sync": sync,
                     **split, **learned})
        print(f"[bench] iteration {it + 1 - a.warmup}: {n} env steps in {wall:.2f} s = {n / wall:.0f} steps/s "
              f"(sampling {sample_total:.2f} s, learning {learn_total:.2f} s)", flush=True)
    rss = {"driver": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "env runners": runner_rss_mb(algo)}
    algo.stop()
    ray.shutdown()
    wall = sum(r["wall"] for r in rows)
    keys = [k for k in rows[0] if k not in ("wall", "steps")]
    mean = {k: sum(r[k] for r in rows) / len(rows) for k in keys}
    import eosp

    return {"steps_per_s": sum(r["steps"] for r in rows) / wall, "iteration_s": wall / len(rows),
            "steps_per_iteration": rows[0]["steps"], "split": mean, "peak_rss_mb": rss,
            "package": str(Path(eosp.__file__).parent), "args": vars(a)}


def report(res: dict, title: str = "") -> None:
    s, it = res["split"], res["iteration_s"]
    print(f"\n{title}split of one iteration ({res['steps_per_iteration']} env steps, {it:.2f} s):")
    runner = sum(v for k, v in s.items() if k.startswith("sample/") and "of which" not in k)
    if runner > 1.5 * s["sample"] + 0.05:  # the runner worked longer than the driver waited: overlapped
        print("  (overlapped sampling: 'sample' is the driver's wait for the batch; the sample/* parts ran in the "
              "env runner during learning, percentages of the iteration)")
    for k in ("sample", *sorted(k for k in s if k.startswith("sample/")), "learn",
              *sorted(k for k in s if k.startswith("learn/")), "sync"):
        indent = "      " if ": of which" in k else "    " if "/" in k else "  "
        print(f"{indent}{k:42s} {s[k]:7.3f} s  {100 * s[k] / it:5.1f}%")
    rss = res["peak_rss_mb"]
    print(f"  peak RSS: driver {rss['driver']:.0f} MB, env runners "
          f"{', '.join(f'{x:.0f}' for x in rss['env runners'])} MB")


def main(argv: list[str] | None = None) -> int:
    a = parse(argv)
    res = bench(a)
    if a.json_out:
        Path(a.json_out).write_text(json.dumps(res))
    report(res)
    print(f"train_env_steps_per_s={res['steps_per_s']:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
