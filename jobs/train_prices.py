"""Train the price network (``--warm-start learned`` of the fleet solver) on Ray, tracked in MLflow.

    python jobs/train_prices.py --fleets CASE_OR_FLEET_DIR ... --data DATA_DIR --out MODEL_DIR
    ray job submit --working-dir . -- python jobs/train_prices.py --fleets ... --data ... --out ...

1. Data, one Ray task per fleet (an aeossp case or a fleet directory): its task-opportunity graph
   (:func:`eosp.kinds.fleet.warmstart.task_graph`) and the reference prices, those of the best Lagrangian bound
   of ``--rounds`` price rounds of the fleet solver (from its default start, the ceiling prices included),
   written to ``DATA/<name>/`` as Parquet (tasks.parquet with the target, passes.parquet, edges.parquet) with
   record.json last; a rerun keeps every fleet that has its record (resumable).  Dual optima are not unique:
   the target is one good point, and the model is judged by the bound its prices give (L(lam), below), not by
   its distance to that point.
2. Training: the network of :mod:`eosp.models.prices`, full batch per fleet, weighted squared error between the
   predicted and reference price fractions (weights: the task weights, since an error on a heavy task moves
   L most); then, with ``--dual-epochs``, descent on the dual itself: L is convex in the prices with subgradient
   1 - (times served), one price round per fleet gives it, and the network follows it through the prices it
   predicts.  The last ``--val`` fleets are held out; MLflow logs the losses and L/W per epoch.
3. Judged on the held-out fleets by the dual itself: L(lam)/W for the learned, heuristic and zero prices, one
   price round each (the pass solves of :func:`eosp.kinds.fleet.problem.solve_round_pass`), logged to MLflow.
The model is written to ``--out`` (prices.pt + prices.json).
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from eosp.args import Parser, add_config_args, config_from_args, run_job
from eosp.config import RayConfig, ranged
from eosp.models.prices import PriceModelConfig

KIND = "price-data"
DATA_VERSION = 2  # 1 (unversioned): the task weights' column overwrote the "weight" feature (w / mean w)


@dataclass
class PriceTrainConfig:
    """Training of the price network (``jobs/train_prices.py``)."""

    fleets: tuple[str, ...] = ()
    """aeossp case directories or fleet directories to learn from (never an evaluation split)."""
    data: str = ""
    """Directory of the training data (created; resumed when it holds fleets already)."""
    out: str = ""
    """Directory the model is written to (prices.pt, prices.json); must not hold another model."""
    rounds: int = ranged(40, 1, 100_000)
    """Price rounds of the reference run of each fleet (its best-bound prices are the target)."""
    epochs: int = ranged(300, 1, 100_000)
    """Passes over the training fleets."""
    lr: float = ranged(3e-3, 0.0, 1.0, lo_open=True)
    """Adam's learning rate."""
    dual_epochs: int = ranged(0, 0, 100_000)
    """Epochs of descent on the dual itself after the fit: each prices every training fleet with the network, one
    price round per fleet (Ray actors holding the fleets) gives L's subgradient 1 - served, and the network's
    weights follow it (the best epoch by the training fleets' mean L/W is kept)."""
    dual_lr: float = ranged(1e-3, 0.0, 1.0, lo_open=True)
    """Adam's learning rate of the dual epochs."""
    val: int = ranged(1, 0)
    """Fleets held out (the last ones of --fleets) to judge the model by the bound its prices give."""
    seed: int = ranged(0, 0)
    model: PriceModelConfig = field(default_factory=PriceModelConfig)
    ray: RayConfig = field(default_factory=RayConfig)
    mlflow_uri: str = ""
    """MLflow tracking URI (empty: mlflow.db in the working directory)."""


def read_problem(path: str):
    """The fleet solver's Problem of an aeossp case or a fleet directory."""
    from eosp.fleet.aeossp import is_case_dir, read_case
    from eosp.fleet.io import read_fleet
    from eosp.fleet.opportunities import compute
    from eosp.kinds.fleet.problem import Problem

    if is_case_dir(path):
        fleet = read_case(path)
        return Problem.build(fleet, compute(fleet))
    fleet, opps = read_fleet(path)
    return Problem.build(fleet, opps)


def reference_prices(prob, rounds: int):
    """The prices of the best proven Lagrangian bound of a fleet solve of `rounds` price rounds (its default start;
    the ceiling prices of its round 0 count too), the bound, the best value and the time."""
    import numpy as np

    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.loop import run

    t0 = time.perf_counter()
    coord = Coordinator(prob, FleetConfig(rounds=rounds, time_limit=None))
    run(coord)
    best = {"L": np.inf, "lam": np.zeros(len(prob.weight))}
    if coord.bound_source == "lagrangian":  # the prices where the kept bound was proven (dual._bound_from)
        best["L"], best["lam"] = coord.best_bound, coord.bound_lam
    return best["lam"], float(best["L"]), float(coord.best.value), time.perf_counter() - t0


def build_one(path: str, out: str, rounds: int) -> dict:
    """One fleet's training data (see the module docstring); returns its record."""
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq
    import torch

    from eosp.kinds.fleet.warmstart import task_graph
    from eosp.models.prices import EDGE_FEATURES, PASS_FEATURES, TASK_FEATURES

    torch.set_num_threads(1)
    t0 = time.perf_counter()
    prob = read_problem(path)
    g = task_graph(prob)
    lam, L, value, ref_s = reference_prices(prob, rounds)
    target = np.where(g.contested, np.clip(lam / np.maximum(g.weight, 1e-12), 0.0, 1.0), 0.0)
    d = Path(out)
    d.mkdir(parents=True, exist_ok=True)
    tasks = {n: g.x_task[:, i] for i, n in enumerate(TASK_FEATURES)}
    pq.write_table(pa.table({**tasks, "task_weight": g.weight, "contested": g.contested, "target": target}),
                   d / "tasks.parquet")
    pq.write_table(pa.table({n: g.x_pass[:, i] for i, n in enumerate(PASS_FEATURES)}), d / "passes.parquet")
    pq.write_table(pa.table({"task": g.edge_task, "pass": g.edge_pass,
                             **{n: g.x_edge[:, i] for i, n in enumerate(EDGE_FEATURES)}}), d / "edges.parquet")
    W = prob.total_weight
    rec = {"data_version": DATA_VERSION, "fleet": str(path), "tasks": len(g.weight), "passes": len(g.x_pass),
           "edges": len(g.edge_task), "contested": int(g.contested.sum()), "rounds": rounds,
           "bound_over_weight": L / W if np.isfinite(L) else None,
           "value_over_weight": value / W, "reference_s": round(ref_s, 2), "seconds": round(time.perf_counter() - t0, 2)}
    (d / "record.json").write_text(json.dumps(rec, indent=1))
    return rec


def read_graph(d: Path):
    """A fleet's training data as a TaskGraph and its target fractions."""
    import numpy as np
    import pyarrow.parquet as pq

    from eosp.errors import InputError
    from eosp.models.prices import EDGE_FEATURES, PASS_FEATURES, TASK_FEATURES, TaskGraph

    try:
        version = json.loads((d / "record.json").read_text()).get("data_version")
    except (OSError, ValueError, AttributeError) as exc:
        raise InputError(d / "record.json", f"unreadable ({type(exc).__name__}): build it again") from None
    if version != DATA_VERSION:
        raise InputError(d, f"training data of version {version}, this eosp reads version {DATA_VERSION}: "
                            "build it again (another --data directory)")
    try:
        t, p, e = (pq.read_table(d / f).to_pydict() for f in ("tasks.parquet", "passes.parquet", "edges.parquet"))
        cols = lambda tab, names: np.column_stack([np.asarray(tab[n], np.float32) for n in names])  # noqa: E731
        g = TaskGraph(cols(t, TASK_FEATURES), cols(p, PASS_FEATURES).reshape(-1, len(PASS_FEATURES)),
                      np.asarray(e["task"], np.int64), np.asarray(e["pass"], np.int64), cols(e, EDGE_FEATURES),
                      np.asarray(t["task_weight"], np.float64), np.asarray(t["contested"], bool))
    except (OSError, KeyError, ValueError) as exc:
        raise InputError(d, f"not training data of this eosp ({type(exc).__name__}: {exc}): build it again") from None
    return g, np.asarray(t["target"], np.float64)


def dual_ratio(path: str, lams: dict) -> dict:
    """L(lam)/W of a fleet for each named start: a fraction per task (sigma; the price is sigma * weight) or the
    name of a start of :mod:`eosp.kinds.fleet.warmstart` ('heuristic', 'none')."""
    import numpy as np

    from eosp.kinds.fleet.warmstart import dual_value, start_prices

    prob = read_problem(path)
    return {name: dual_value(prob, start_prices(prob, sigma) if isinstance(sigma, str)
                             else np.asarray(sigma) * prob.weight) for name, sigma in lams.items()}


def train(graphs: list, targets: list, cfg: PriceTrainConfig, log) -> object:
    """The network fitted to the reference fractions (see the module docstring); `log(step, metrics)`."""
    import numpy as np
    import torch

    from eosp.models.prices import PriceNet, tensors

    torch.manual_seed(cfg.seed)
    model = PriceNet(cfg.model)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    data = [(tensors(g), torch.from_numpy(y), torch.from_numpy(np.where(g.contested, g.weight / g.weight.mean(), 0.0)))
            for g, y in zip(graphs, targets)]
    n_train = len(data) - cfg.val if len(data) > cfg.val else len(data)
    rng = np.random.default_rng(cfg.seed)

    def loss_of(x, y, wt):
        sigma = torch.sigmoid(model(x)).double()
        return (wt * (sigma - y) ** 2).sum() / wt.sum().clamp(min=1e-12)

    for epoch in range(cfg.epochs):
        model.train()
        total = 0.0
        for k in rng.permutation(n_train).tolist():
            opt.zero_grad()
            loss = loss_of(*data[k])
            loss.backward()
            opt.step()
            total += loss.item()
        if epoch % 10 == 9 or epoch == cfg.epochs - 1:
            model.eval()
            with torch.no_grad():
                val = [float(loss_of(*data[k])) for k in range(n_train, len(data))]
            log(epoch + 1, {"train_loss": total / max(n_train, 1),
                            **({"val_loss": float(np.mean(val))} if val else {})})
    return model


class DualRound:
    """A Ray actor holding some fleets' Problems: for each, L(lam)/W and the tasks' serve counts of one price
    round (a fleet per CPU would leave actors waiting for CPUs the others hold: the fleets are dealt out)."""

    def __init__(self, paths: list[str]):
        import torch

        torch.set_num_threads(1)
        self.probs = [read_problem(p) for p in paths]

    def rounds(self, lams: list) -> list:
        from eosp.kinds.fleet.warmstart import dual_round

        return [dual_round(prob, lam) for prob, lam in zip(self.probs, lams)]


def dual_descent(model, graphs: list, actors: list, cfg: PriceTrainConfig, log) -> object:
    """The network's weights moved along L's subgradient (see --dual-epochs); the best epoch's weights kept."""
    import copy

    import numpy as np
    import ray
    import torch

    from eosp.models.prices import tensors

    opt = torch.optim.Adam(model.parameters(), lr=cfg.dual_lr)
    xs = [tensors(g) for g in graphs]
    best, best_state = np.inf, copy.deepcopy(model.state_dict())
    for epoch in range(cfg.dual_epochs + 1):
        model.train()
        sig = [torch.sigmoid(model(x)).double() * torch.from_numpy(g.contested.astype(np.float64))
               for x, g in zip(xs, graphs)]
        lams = [(s.detach().numpy() * g.weight) for s, g in zip(sig, graphs)]
        dealt = ray.get([a.rounds.remote(lams[k::len(actors)]) for k, a in enumerate(actors)])
        got = [dealt[i % len(actors)][i // len(actors)] for i in range(len(lams))]
        mean_L = float(np.mean([v for v, _ in got]))
        log(cfg.epochs + epoch, {"train_L_over_W": mean_L})
        if mean_L < best:
            best, best_state = mean_L, copy.deepcopy(model.state_dict())
        if epoch == cfg.dual_epochs:
            break
        opt.zero_grad()
        # dL/dlam = 1 - served: the surrogate sum(lam * (1 - served)) / W has L's subgradient in lam
        loss = sum((s * torch.from_numpy(g.weight) * torch.from_numpy(1.0 - c)).sum() / float(g.weight.sum())
                   for s, g, (_, c) in zip(sig, graphs, got)) / len(graphs)
        loss.backward()
        opt.step()
    model.load_state_dict(best_state)
    return model


def run(cfg: PriceTrainConfig) -> dict:
    import ray
    import torch

    torch.set_num_threads(1)  # one thread per process (a second one made the fit 10x slower on a loaded machine)

    from eosp.errors import InputError
    from eosp.jobs.ray_init import init_ray
    from eosp.jobs.tracking import use_experiment
    from eosp.models.prices import save_price_model
    from eosp.ownership import check_output, kind_of, mark_dir

    if not cfg.fleets:
        raise InputError("--fleets", "required: aeossp case or fleet directories to learn from")
    from eosp.fleet.aeossp import refuse_evaluation_case

    for f in cfg.fleets:
        if not Path(f).is_dir():
            raise InputError(f, "not a directory (an aeossp case or a fleet directory expected)")
        refuse_evaluation_case(f, "--fleets")
    for opt, val in (("--data", cfg.data), ("--out", cfg.out)):
        if not val:
            raise InputError(opt, "required")
    data = check_output(cfg.data, KIND, directory=True, reuse=True)
    out = Path(cfg.out)
    if out.is_symlink() or (out.exists() and (not out.is_dir() or any(out.iterdir()))):
        what = "holds a price model already" if (out / "prices.json").exists() else "exists and is not an empty directory"
        raise InputError(f"--out {cfg.out}", f"{what}: the model goes to a new or empty directory")
    data.mkdir(parents=True, exist_ok=True)
    if kind_of(data) != KIND:
        mark_dir(data, KIND)
    names = [f"{k:04d}-{Path(f).resolve().parent.name}-{Path(f).resolve().name}" for k, f in enumerate(cfg.fleets)]
    todo = [k for k, n in enumerate(names) if not (data / n / "record.json").exists()]
    if len(todo) < len(names):
        print(f"[train_prices] resuming: {len(names) - len(todo)} of {len(names)} fleets' data complete", flush=True)
    init_ray(cfg.ray.address, cfg.ray.num_cpus)
    task = ray.remote(num_cpus=1)(build_one)
    pending = {task.remote(str(Path(cfg.fleets[k]).resolve()), str(data / names[k]), cfg.rounds): k for k in todo}
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        k = pending.pop(ready[0])
        rec = ray.get(ready[0])
        print(f"[train_prices] data {len(names) - len(pending)}/{len(names)}: {names[k]}: {rec['contested']} "
              f"contested tasks, reference bound {rec['bound_over_weight'] or float('nan'):.4f} W after {rec['rounds']} "
              f"rounds "
              f"({rec['seconds']:.0f} s)", flush=True)
    import mlflow

    use_experiment(cfg.mlflow_uri, "eosp-prices")
    pairs = [read_graph(data / n) for n in names]
    with mlflow.start_run() as run_:
        mlflow.log_params({"fleets": len(names), "val": cfg.val, "rounds": cfg.rounds, "epochs": cfg.epochs,
                           "dual_epochs": cfg.dual_epochs, "dual_lr": cfg.dual_lr,
                           "lr": cfg.lr, "hidden": cfg.model.hidden, "layers": cfg.model.layers})
        t0 = time.perf_counter()
        model = train([g for g, _ in pairs], [y for _, y in pairs], cfg,
                      lambda step, m: mlflow.log_metrics(m, step=step))
        if cfg.dual_epochs:
            n_train = len(pairs) - cfg.val if len(pairs) > cfg.val else len(pairs)
            actor = ray.remote(num_cpus=1)(DualRound)
            paths = [str(Path(f).resolve()) for f in cfg.fleets[:n_train]]
            k = max(1, min(n_train, int(ray.available_resources().get("CPU", 1))))
            actors = [actor.remote(paths[i::k]) for i in range(k)]
            model = dual_descent(model, [g for g, _ in pairs[:n_train]], actors, cfg,
                                 lambda step, m: mlflow.log_metrics(m, step=step))
            for a in actors:
                ray.kill(a)
        train_s = time.perf_counter() - t0
        from eosp.models.prices import predict

        judged = {}
        held = list(range(len(names) - cfg.val, len(names))) if 0 < cfg.val < len(names) else []
        if held:
            dual = ray.remote(num_cpus=1)(dual_ratio)
            refs = {dual.remote(str(Path(cfg.fleets[k]).resolve()),
                                {"learned": predict(model, pairs[k][0]), "heuristic": "heuristic", "none": "none"}): k
                    for k in held}
            for ref, k in refs.items():
                judged[names[k]] = ray.get(ref)
                for name, v in judged[names[k]].items():
                    mlflow.log_metric(f"val_L_over_W_{name}", v, step=k)
                print(f"[train_prices] held out {names[k]}: L/W " + ", ".join(
                    f"{n} {v:.4f}" for n, v in judged[names[k]].items()), flush=True)
        save_price_model(model, cfg.out, {"trained_on": [str(f) for f in cfg.fleets[:len(names) - len(held)]],
                                          "held_out": judged, "train_seconds": round(train_s, 1)})
        mlflow.log_artifacts(cfg.out, "model")
        return {"run_id": run_.info.run_id, "held_out": judged, "train_seconds": train_s}


def main(argv: list[str] | None = None, prog: str = "train_prices.py") -> int:
    return run_job(_main, argv, prog)


def _main(argv: list[str] | None) -> int:
    from eosp import errors

    p = Parser(prog=errors.PROG, description=__doc__.splitlines()[0])
    add_config_args(p, PriceTrainConfig)
    cfg = config_from_args(PriceTrainConfig, p.parse_args(argv))
    from eosp.jobs.preflight import check_mlflow, require_findable

    for flag, value in (("--data", cfg.data), ("--out", cfg.out)):
        if value:
            require_findable(value, flag)
    check_mlflow(cfg.mlflow_uri)  # before any work: a tracking URI MLflow cannot use is refused now
    res = run(cfg)
    print(f"[train_prices] model -> {cfg.out} (MLflow run {res['run_id']}, {res['train_seconds']:.0f} s of training)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
