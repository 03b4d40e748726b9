"""Train the onboard policy (issue 76, item 2): which candidate a satellite that sees its next target cloudy takes
in its place, learned over recorded ground plans, against the classical rule tuned on the same scenarios.

    python jobs/train_onboard.py --scenarios SCEN... --work W --out models/pretrained-agents/onboard

Stages, each resumable from WORK (a rerun keeps what is there):

1. record: each training scenario's realizations flown once with the ground planner (``ev-replan``, looking
   ahead, ``--candidates`` per primary), its plans written (:mod:`eosp.ops.plan_cache`); one Ray task per
   scenario and share of realizations.  The last ``--validation`` realizations of each scenario are held out.
2. tune: the classical chooser (:class:`eosp.ops.onboard.ScoreRule`) on a grid of (beta, gamma), each point
   replayed over the training recordings (a Ray task a point); the best is the rule the policy must beat.
3. imitate: the states the tuned rule visits, each labelled with the candidate that pays in hindsight (the
   realized clouds: :meth:`eosp.envs.onboard.OnboardEnv.hindsight`), cross-entropy on the network.
4. PPO on RLlib's multi-agent env runners (:mod:`eosp.training.onboard`) from the imitation's weights; after each
   iteration the policy is replayed over the validation recordings and the best so far is kept
   (WORK/ppo.pt, WORK/ppo.json: a Ctrl-C keeps it and a rerun resumes from it).

Evaluation scenarios are refused (:func:`eosp.ops.evaluation.refuse_evaluation_scenario`).  MLflow: the options,
every stage's figures as metrics (imitation loss per epoch; PPO's return and the validation served weight per
iteration), the policy as an artifact.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from eosp.args import Parser, add_config_args, config_from_args, run_job
from eosp.config import RayConfig, flatten, ranged

GRID = ((0.0, 0.0), (0.5, 0.0), (1.0, 0.0), (0.0, 1.0), (0.5, 1.0), (1.0, 1.0))  # (beta, gamma) of the rule


@dataclass
class OnboardTrainJob:
    """Train the onboard policy (``jobs/train_onboard.py``)."""

    scenarios: tuple[str, ...] = ()
    """Training scenario directories (eosp scenario; never an evaluation scenario)."""
    work: str = ""
    """Working directory: recordings, the rule's grid, the PPO state (resumed)."""
    out: str = ""
    """Where the policy is written (onboard.pt, onboard.json)."""
    realizations: int = ranged(8, 2, 10_000)
    """Realizations recorded per scenario (0 to this, less one)."""
    validation: int = ranged(2, 1, 10_000)
    """Of those, the last this many per scenario are held out: the policy is chosen on them, never trained."""
    time_limit: float = ranged(3.0, 0.0, 3600.0, lo_open=True)
    """Seconds of the ground planner per planning call in the recordings."""
    candidates: int = ranged(3, 1, 3)
    """Candidates the ground plans send per primary."""
    epochs: int = ranged(40, 0, 10_000)
    """Imitation epochs."""
    iterations: int = ranged(8, 0, 10_000)
    """PPO iterations."""
    lr: float = ranged(3e-4, 0.0, 1.0, lo_open=True)
    """PPO's learning rate (the imitation's is 3e-3)."""
    train_batch_size: int = ranged(2000, 16)
    """PPO decisions per iteration."""
    entropy_coeff: float = ranged(0.003, 0.0, 1.0)
    """PPO's entropy bonus."""
    runners: int = ranged(2, 0, 64)
    """RLlib env runners."""
    seed: int = ranged(0, 0)
    """Seed of the draws, the network and PPO."""
    ray: RayConfig = field(default_factory=RayConfig)
    mlflow_uri: str = ""
    """MLflow tracking URI (empty: sqlite mlflow.db in the working directory)."""
    experiment: str = "eosp-onboard"
    """MLflow experiment."""


def record(scen_path: str, indices: list[int], time_limit: float, candidates: int, work: str) -> list[str]:
    """Ray task: realizations `indices` of a scenario recorded (those already on disk kept)."""
    import os

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from eosp.kinds.fleet.operations import SimulateConfig, Simulation, record_plans
    from eosp.ops import scenario

    out = [Path(work) / "recordings" / f"{Path(scen_path).name}-r{i}.npz" for i in indices]
    if all(p.exists() for p in out):
        return [str(p) for p in out]
    sim = Simulation.of(scenario.read(scen_path), SimulateConfig(
        planner="ev-replan", onboard="lookahead", candidates=candidates, time_limit=time_limit))
    for i, p in zip(indices, out):
        if not p.exists():
            record_plans(sim, str(Path(scen_path).resolve()), i, p)
    sim.close()
    return [str(p) for p in out]


def replay(recordings: list[str], chooser: tuple) -> list[float]:
    """Ray task: each recording flown with a chooser (("score", beta, gamma), ("policy", state dict, hidden) or
    ("oracle",): the realized clouds' choice); the served-weight fractions."""
    import torch

    from eosp.envs.onboard import OnboardEnv, OnboardEnvConfig
    from eosp.models.onboard import OnboardNet, OnboardPolicy
    from eosp.ops.onboard import ScoreRule

    torch.set_num_threads(1)
    env = OnboardEnv(OnboardEnvConfig(recordings))
    if chooser[0] == "oracle":  # the candidate that pays in hindsight, else the first: what no chooser exceeds
        make = lambda ctx: lambda d: int(np.argmax(env.hindsight()))  # noqa: E731
    elif chooser[0] == "score":
        make = lambda ctx: ScoreRule(ctx, chooser[1], chooser[2])  # noqa: E731
    else:
        net = OnboardNet(chooser[2])
        net.load_state_dict(chooser[1])
        make = OnboardPolicy(net).chooser
    return [env.play(i, make) for i in range(len(recordings))]


def imitation_data(recordings: list[str], beta: float, gamma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ray task: the decisions the rule (beta, gamma) meets where a candidate pays in hindsight, as features,
    masks and labels (the slot that pays most).  Where none pays every choice is worth the same (taking costs
    nothing the test has not checked), so those teach nothing and are left out: labelled "none", they teach the
    network to take nothing, which loses the candidates that do pay (measured: 95% of decisions are such)."""
    from eosp.envs.onboard import NONE, OnboardEnv, OnboardEnvConfig, agent_id
    from eosp.ops.onboard import CANDIDATES, FEATURES, ScoreRule, features

    env = OnboardEnv(OnboardEnvConfig(recordings))
    xs, ms, ys = [], [], []
    for i in range(len(recordings)):
        env.reset(episode=i)
        rule = ScoreRule(env.ctx, beta, gamma)
        while env.run is None:
            d = env.decision
            x, m = features(env.ctx, d)
            h = env.hindsight()
            if h.max() > 0:
                xs.append(x)
                ms.append(m)
                ys.append(int(np.argmax(h)))
            a = rule(d)
            env.step({agent_id(d.sat): NONE if a < 0 else a})
    if not ys:
        return np.zeros((0, CANDIDATES, len(FEATURES)), np.float32), np.zeros((0, CANDIDATES), bool), np.zeros(0, int)
    return np.stack(xs), np.stack(ms), np.asarray(ys)


def imitate(net, data, epochs: int, seed: int, log) -> None:
    """Cross-entropy of the network's choice on the hindsight labels (Adam, lr 3e-3, batches of 256)."""
    import torch

    x, m, y = (torch.from_numpy(a) for a in data)
    if not len(y):
        return
    g = torch.Generator().manual_seed(seed)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    for epoch in range(epochs):
        perm = torch.randperm(len(y), generator=g)
        total = 0.0
        for b in perm.split(256):
            logits, _ = net(x[b], m[b].bool())
            loss = torch.nn.functional.cross_entropy(logits, y[b])
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += loss.item() * len(b)
        log({"imitation/loss": total / len(y)}, epoch)


def run(job: OnboardTrainJob) -> int:
    import logging

    import mlflow
    import ray
    import torch

    from eosp.jobs.ray_init import init_ray
    from eosp.jobs.tracking import use_experiment
    from eosp.models.onboard import OnboardNet, save_policy
    from eosp.ops import scenario
    from eosp.ops.evaluation import refuse_evaluation_scenario

    for s in job.scenarios:
        refuse_evaluation_scenario(scenario.read(s), "--scenarios")
    work = Path(job.work)
    (work / "recordings").mkdir(parents=True, exist_ok=True)
    torch.manual_seed(job.seed)
    logging.getLogger("mlflow").setLevel(logging.WARNING)
    use_experiment(job.mlflow_uri, job.experiment)
    init_ray(job.ray.address, job.ray.num_cpus)
    say = lambda text: print(f"[train_onboard] {text}", flush=True)  # noqa: E731
    with mlflow.start_run(run_name="onboard-policy"):
        mlflow.log_params({k: str(v) for k, v in flatten(job).items() if not k.startswith("ray.")})
        log = lambda metrics, step: mlflow.log_metrics(metrics, step=step)  # noqa: E731
        # 1. record
        task = ray.remote(num_cpus=1)(record)
        half = job.realizations // 2
        shares = [(s, list(range(a, b))) for s in job.scenarios for a, b in ((0, half), (half, job.realizations))]
        recs = [r for got in ray.get([task.remote(s, ix, job.time_limit, job.candidates, str(work))
                                      for s, ix in shares]) for r in got]
        val = [r for r in recs if int(r.rsplit("-r", 1)[1][:-4]) >= job.realizations - job.validation]
        train = [r for r in recs if r not in val]
        say(f"recorded {len(train)} training and {len(val)} validation realizations")
        # 2. tune the rule (kept in WORK/rule.json)
        rep = ray.remote(num_cpus=1)(replay)
        rule_path = work / "rule.json"
        if rule_path.exists():
            figures = json.loads(rule_path.read_text())
        else:
            grid = ray.get([rep.remote(train, ("score", b, g)) for b, g in GRID])
            means = [float(np.mean(v)) for v in grid]
            for (b, g), v in zip(GRID, means):
                say(f"rule beta {b} gamma {g}: training served {v:.5f}")
            beta, gamma = GRID[int(np.argmax(means))]
            rule_val = ray.get([rep.remote(val, ("score", beta, gamma)), rep.remote(val, ("score", 0.0, 0.0))])
            figures = {"rule/beta": beta, "rule/gamma": gamma, "rule/train_served": max(means),
                       "rule/validation_served": float(np.mean(rule_val[0])),
                       "first/validation_served": float(np.mean(rule_val[1]))}
            rule_path.write_text(json.dumps(figures))
        beta, gamma = figures["rule/beta"], figures["rule/gamma"]
        if "oracle/validation_served" not in figures:
            figures["oracle/validation_served"] = float(np.mean(ray.get(rep.remote(val, ("oracle",)))))
            rule_path.write_text(json.dumps(figures))
        mlflow.log_metrics(figures)
        say(f"tuned rule beta {beta} gamma {gamma}: validation served {figures['rule/validation_served']:.5f} "
            f"(first: {figures['first/validation_served']:.5f}; hindsight's choice "
            f"{figures['oracle/validation_served']:.5f})")
        # 3. imitation
        net = OnboardNet()
        state_path = work / "ppo.pt"
        meta_path = work / "ppo.json"
        if meta_path.exists():
            prior = json.loads(meta_path.read_text())
            net.load_state_dict(torch.load(state_path, weights_only=True))
            say(f"resuming after PPO iteration {prior['iteration']} (validation {prior['best']:.5f})")
        else:
            parts = ray.get([ray.remote(num_cpus=1)(imitation_data).remote(train[i::2], beta, gamma)
                             for i in range(min(2, len(train)))])
            data = tuple(np.concatenate([p[j] for p in parts]) for j in range(3))
            say(f"imitation: {len(data[2])} decisions with a candidate that pays in hindsight")
            imitate(net, data, job.epochs, job.seed, log)
            prior = {"iteration": 0, "best": float(np.mean(replay(val, ("policy", net.state_dict(), net.hidden))))}
            torch.save(net.state_dict(), state_path)
            meta_path.write_text(json.dumps(prior))
            say(f"imitation: validation served {prior['best']:.5f}")
        mlflow.log_metric("policy/validation_served", prior["best"], step=prior["iteration"])
        # 4. PPO
        best, best_state = prior["best"], {k: v.clone() for k, v in net.state_dict().items()}
        if job.iterations > prior["iteration"]:
            best, best_state = ppo(job, train, val, net, prior, log, say)
        net.load_state_dict(best_state)
        save_policy(net, job.out, {"trained_on": [str(Path(s).resolve()) for s in job.scenarios],
                                   "validation_served": best, **figures})
        mlflow.log_artifacts(job.out, "policy")
        say(f"policy written to {job.out}: validation served {best:.5f} (tuned rule "
            f"{figures['rule/validation_served']:.5f}, first {figures['first/validation_served']:.5f})")
    return 0


def ppo(job: OnboardTrainJob, train: list[str], val: list[str], net, prior: dict, log, say):
    """PPO iterations from `net`'s weights; after each, the validation replay; the best kept in WORK."""
    import torch

    from eosp.training.onboard import SHARED_MODULE, ppo_config

    pc = ppo_config(train, job.seed, job.runners, {
        "lr": job.lr, "train_batch_size": job.train_batch_size, "minibatch_size": min(256, job.train_batch_size),
        "num_epochs": 4, "entropy_coeff": job.entropy_coeff, "gamma": 0.99, "hidden": net.hidden})
    algo = pc.build_algo()
    learner = algo.learner_group._learner  # num_learners=0: the learner is local
    learner.module[SHARED_MODULE].net.load_state_dict(net.state_dict())
    algo.env_runner_group.sync_weights(from_worker_or_learner_group=algo.learner_group)
    best, best_state = prior["best"], {k: v.clone() for k, v in net.state_dict().items()}
    try:
        for it in range(prior["iteration"] + 1, job.iterations + 1):
            res = algo.train()
            state = {k: v.detach().clone() for k, v in learner.module[SHARED_MODULE].net.state_dict().items()}
            served = float(np.mean(replay(val, ("policy", state, net.hidden))))  # here: the runners hold the CPUs
            ret = res.get("env_runners", {}).get("episode_return_mean")
            log({"ppo/episode_return_mean": float(ret or 0.0), "policy/validation_served": served}, it)
            say(f"PPO iteration {it}: return {ret}, validation served {served:.5f}")
            if served > best:
                best, best_state = served, state
                torch.save(state, Path(job.work) / "ppo.pt")
            (Path(job.work) / "ppo.json").write_text(json.dumps({"iteration": it, "best": best}))
    finally:
        algo.stop()
    return best, best_state


def main(argv: list[str] | None = None, prog: str = "train_onboard.py") -> int:
    return run_job(_main, argv, prog)


def _main(argv: list[str] | None) -> int:
    from eosp import errors
    from eosp.errors import InputError
    from eosp.jobs.preflight import check_mlflow, require_findable

    p = Parser(prog=errors.PROG, description=__doc__.splitlines()[0])
    add_config_args(p, OnboardTrainJob)
    job = config_from_args(OnboardTrainJob, p.parse_args(argv))
    for flag, value in (("--scenarios", job.scenarios), ("--work", job.work), ("--out", job.out)):
        if not value:
            raise InputError(flag, "required")
    if job.validation >= job.realizations:
        raise InputError("--validation", f"{job.validation} leaves no training realization of {job.realizations}")
    for s in job.scenarios:
        require_findable(s, "--scenarios")
    check_mlflow(job.mlflow_uri)
    return run(job)


if __name__ == "__main__":
    sys.exit(main())
