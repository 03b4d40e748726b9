"""Periodic validation on held-out shards: greedy decoding vs the Greedy and RAMP baselines.

Baseline values are computed once per data set, as parallel Ray tasks, and cached
next to the shards (``baselines.json``, keyed by instance, solver and mode), so
repeated runs do not pay for them again.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eosp.atomic import atomic_path
from eosp.config import EnvConfig
from eosp.reward import objective_mode

BASELINES = ("greedy", "ramp")


def _solve_task(shard: str, index: int, solver: str, mode: str, time_limit: float) -> tuple[str, float, float]:
    from eosp.shards.io import ShardReader
    from eosp.solvers.base import run_solver, takes_time_limit

    inst = ShardReader(shard).read(index)
    t0 = time.perf_counter()
    limit = {"time_limit": time_limit} if takes_time_limit(solver) else {}  # greedy is one pass: no limit
    sol = run_solver(solver, inst, mode=mode, **limit)
    return inst.name, float(sol.value), time.perf_counter() - t0


def baseline_values(val_path: str | Path, mode: str, solvers=BASELINES, time_limit: float = 60.0) -> dict:
    """{solver: {instance name: value}} for every instance of the data set, cached in baselines.json."""
    import ray

    from eosp.envs.sources import expand_shards
    from eosp.shards.io import ShardReader

    shards = expand_shards([str(val_path)])
    cache_file = (Path(val_path) if Path(val_path).is_dir() else Path(val_path).parent) / "baselines.json"
    cache = json.loads(cache_file.read_text()) if cache_file.exists() else {}

    def key(shard: Path, i: int) -> str:
        # the shard's identity is part of the key: a regenerated data set is not served stale values
        st = shard.stat()
        return f"{shard.name}:{st.st_size}:{int(st.st_mtime)}#{i}"

    todo, names = [], {}
    for shard in shards:
        for i, name in enumerate(ShardReader(shard).names()):
            names[key(shard, i)] = name
            for s in solvers:
                if key(shard, i) not in cache.get(f"{s}/{mode}/{time_limit:g}", {}):
                    todo.append((shard, i, s))
    if todo:
        task = ray.remote(num_cpus=1)(_solve_task)
        refs = [task.remote(str(sh), i, s, mode, time_limit) for sh, i, s in todo]
        for (sh, i, s), (_, value, _) in zip(todo, ray.get(refs)):
            cache.setdefault(f"{s}/{mode}/{time_limit:g}", {})[key(sh, i)] = value
        with atomic_path(cache_file) as tmp:
            tmp.write_text(json.dumps(cache, indent=1, sort_keys=True))
    return {s: {names[k]: v for k, v in cache[f"{s}/{mode}/{time_limit:g}"].items() if k in names} for s in solvers}


@dataclass
class ValidationResult:
    metrics: dict[str, float]
    names: list[str]
    policy: np.ndarray
    baselines: dict[str, np.ndarray]


def compare(policy: np.ndarray, baselines: dict[str, np.ndarray], prefix: str = "val") -> dict[str, float]:
    """Mean scores, ratios of the means (the paper's table), means of the per-instance ratios, and
    win/tie/loss counts."""
    out = {f"{prefix}/policy_mean": float(np.mean(policy))}
    for s, b in baselines.items():
        out[f"{prefix}/{s}_mean"] = float(np.mean(b))
        out[f"{prefix}/ratio_to_{s}"] = float(np.mean(policy) / np.mean(b)) if np.mean(b) > 0 else float("nan")
        pos = b > 0
        out[f"{prefix}/mean_ratio_to_{s}"] = float(np.mean(policy[pos] / b[pos])) if pos.any() else float("nan")
        tie = np.isclose(policy, b, rtol=1e-9, atol=1e-9)
        out[f"{prefix}/wins_vs_{s}"] = float(np.sum((policy > b) & ~tie))
        out[f"{prefix}/ties_vs_{s}"] = float(np.sum(tie))
        out[f"{prefix}/losses_vs_{s}"] = float(np.sum((policy < b) & ~tie))
    return out


SELECTION_KEY = "val/selection_score"  # the primary validation metric, logged under this name too


def primary_metric(metrics: dict[str, float]) -> str:
    """The key of the metric that picks a run's `best` checkpoint: the mean per-instance ratio to the strongest
    baseline validated (exact, then RAMP, then Greedy), else the mean value.

    Why not the mean value: in utility mode it is the sum over instances of values spanning eight orders
    of magnitude (a class-0 acquisition is worth 1e8), so it only sees the instances with top-class
    acquisitions; a policy that loses two class-3 acquisitions on an instance without classes 0-2 (0.92
    x its optimum) moves it by 1e-5.  Nor the ratio of the means (``val/ratio_to_X``), for the same reason:
    it can rise while this falls.  The targets are means of per-instance ratios too."""
    for s in ("exact", "fleet", "ramp", "greedy"):  # fleet: the fleet solver (fleet policies, FleetValidator)
        v = metrics.get(f"val/mean_ratio_to_{s}")
        if v is not None and np.isfinite(v):
            return f"val/mean_ratio_to_{s}"
    return "val/policy_mean"


def selection_score(metrics: dict[str, float]) -> float:
    """The value of :func:`primary_metric`: what picks a run's `best` checkpoint (higher is better)."""
    return float(metrics[primary_metric(metrics)])


def describe_metric(key: str) -> str:
    """A plot label for a validation metric key, naming which mean it is."""
    names = {"exact": "optimum", "ramp": "RAMP", "greedy": "Greedy", "fleet": "fleet solver",
             "features": "features-only decoder"}
    if key.startswith("val/mean_ratio_to_"):
        return f"mean of per-instance ratios, policy / {names.get(key[18:], key[18:])}"
    if key.startswith("val/ratio_to_"):
        return f"ratio of means, policy / {names.get(key[13:], key[13:])}"
    return key


def instance_rows(result: "ValidationResult") -> list[dict]:
    """One row per validation instance: the policy's value, each baseline's and the policy / baseline ratio
    (NaN where the baseline is 0): the figures behind the means, logged as a table."""
    rows = []
    for i, name in enumerate(result.names):
        row = {"instance": name, "policy": float(result.policy[i])}
        for s, b in result.baselines.items():
            row[s] = float(b[i])
            row[f"policy/{s}"] = float(result.policy[i] / b[i]) if b[i] > 0 else float("nan")
        rows.append(row)
    return rows


def write_instance_table(result: "ValidationResult", out: str | Path) -> Path:
    """:func:`instance_rows` as a CSV file (written atomically); returns its path."""
    import csv
    import io

    rows = instance_rows(result)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]) if rows else ["instance", "policy"])
    w.writeheader()
    for r in rows:
        w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        tmp.write_text(buf.getvalue())
    return out


class Validator:
    def __init__(self, val_path: str | Path, env_cfg: EnvConfig, max_instances: int = 0,
                 baselines: tuple[str, ...] = BASELINES):
        from eosp.envs.sources import expand_shards, prepare_instance
        from eosp.shards.io import read_instances

        self.env_cfg = env_cfg
        self.mode = objective_mode(env_cfg)
        insts = read_instances(expand_shards([str(val_path)]), unpruned=not env_cfg.prune or bool(env_cfg.plan))
        if max_instances:
            insts = insts[:max_instances]
        self.prepared = [prepare_instance(i, env_cfg.prune) for i in insts]
        self.names = [i.name for i in insts]
        base = baseline_values(val_path, self.mode, baselines)
        self.baselines = {s: np.array([base[s][n] for n in self.names]) for s in baselines}

    def score(self, inst, nodes: np.ndarray) -> float:
        from eosp.solvers.base import objective_weights

        return float(objective_weights(inst, self.mode)[inst.node_acq[nodes]].sum()) if len(nodes) else 0.0

    def run(self, agent) -> ValidationResult:
        from eosp.solvers.policy import rollout

        values = []
        for p in self.prepared:
            nodes, _ = rollout(agent, p, self.env_cfg)
            values.append(self.score(p.inst, nodes))
        policy = np.asarray(values)
        metrics = compare(policy, self.baselines)
        metrics[SELECTION_KEY] = selection_score(metrics)
        return ValidationResult(metrics, self.names, policy, self.baselines)


class FleetValidator:
    """Greedy decoding of a fleet policy on held-out fleets (a demo set of jobs/build_fleet_demos.py) against the
    fleet solver's schedules there (``fleet``), the fleet greedy (``greedy``) and the features-only decoder
    (``features``, :data:`eosp.solvers.fleet_policy.DEFAULT_RULE`); values are WCRs, the baselines computed once."""

    def __init__(self, demo_set: str | Path, env_cfg, max_fleets: int = 0):
        from dataclasses import replace

        from eosp.envs.constellation import load_fleet
        from eosp.fleet.check import validate
        from eosp.fleet.greedy import solve as fleet_greedy
        from eosp.solvers.fleet_policy import DEFAULT_RULE, FEATURE_RULES, decode, rule_scorer
        from eosp.training.fleet_demos import read_demo_set

        self.env_cfg = replace(env_cfg, fleets=(), max_satellites=0)
        records = read_demo_set(demo_set)
        if max_fleets:
            records = records[:max_fleets]
        self.fleets = [load_fleet(r["fleet"]) for r in records]
        self.names = [r["fleet"] for r in records]
        rule = rule_scorer(FEATURE_RULES[DEFAULT_RULE])
        self.baselines = {
            "fleet": np.array([float(r["wcr"]) for r in records]),
            "greedy": np.array([validate(p.fleet, fleet_greedy(p.fleet, p.opps, p.geo), p.geo).metrics["WCR"]
                                for p in self.fleets]),
            "features": np.array([decode(rule, p, self.env_cfg).value for p in self.fleets])}

    def run(self, agent) -> ValidationResult:
        from eosp.solvers.fleet_policy import decode

        policy = np.array([decode(agent, p, self.env_cfg).value for p in self.fleets])
        metrics = compare(policy, self.baselines)
        metrics[SELECTION_KEY] = selection_score(metrics)
        return ValidationResult(metrics, self.names, policy, self.baselines)
