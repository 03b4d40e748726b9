"""The price network: the fleet solver's task prices predicted from the task-opportunity graph.

Input (:class:`TaskGraph`, built by :func:`eosp.kinds.fleet.warmstart.task_graph`): a node per task and per pass,
an edge per (task, pass) pair.  Task and pass nodes are embedded by their own MLPs; each layer sends the mean of
the tasks' embeddings (with the edge features) to their passes and the mean and max of the passes' back to their
tasks, residually; the output is a fraction sigma in (0, 1) per task, the price being ``sigma * weight`` (a
price above the weight never pays: the task would be left by every pass).

Saved as ``prices.pt`` (a tensor state dict, read with ``weights_only=True``) and ``prices.json`` (the layer sizes
and the feature layout it was trained on; a model for another layout is refused in one line).  Nothing is ever
unpickled.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from eosp.atomic import atomic_path
from eosp.config import apply_overrides, ranged
from eosp.errors import InputError

TASK_FEATURES = ("weight", "duration_min", "log_window_h", "log_passes", "log_satellites", "contested_sat",
                 "contested_pass")
PASS_FEATURES = ("log_tasks", "demand", "density", "log_span_min")
EDGE_FEATURES = ("log_opportunities", "log_conflicts", "weight_share", "position")
LAYOUT = {"task": list(TASK_FEATURES), "pass": list(PASS_FEATURES), "edge": list(EDGE_FEATURES)}
WEIGHTS, CONFIG = "prices.pt", "prices.json"
SHIPPED = Path(__file__).resolve().parent / "pretrained-prices"


@dataclass
class TaskGraph:
    """The task-opportunity graph of a fleet, arrays only.

    x_task float32 [n, len(TASK_FEATURES)], x_pass float32 [P, len(PASS_FEATURES)], edge_task int64 [E],
    edge_pass int64 [E], x_edge float32 [E, len(EDGE_FEATURES)], weight float64 [n], contested bool [n] (held by
    two passes or more: the only tasks a price is predicted for)."""

    x_task: np.ndarray
    x_pass: np.ndarray
    edge_task: np.ndarray
    edge_pass: np.ndarray
    x_edge: np.ndarray
    weight: np.ndarray
    contested: np.ndarray


@dataclass
class PriceModelConfig:
    hidden: int = ranged(64, 1, 1024)
    """Width of the task and pass embeddings."""
    layers: int = ranged(2, 1, 16)
    """Rounds of task -> pass -> task messages."""


def mlp(i: int, o: int, h: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(i, h), nn.ReLU(), nn.Linear(h, o))


def scatter_mean(src: torch.Tensor, index: torch.Tensor, n: int) -> torch.Tensor:
    out = torch.zeros(n, src.shape[1], dtype=src.dtype).index_add_(0, index, src)
    cnt = torch.zeros(n, dtype=src.dtype).index_add_(0, index, torch.ones(len(index), dtype=src.dtype))
    return out / cnt.clamp(min=1.0)[:, None]


def scatter_max(src: torch.Tensor, index: torch.Tensor, n: int) -> torch.Tensor:
    out = torch.zeros(n, src.shape[1], dtype=src.dtype)
    return out.scatter_reduce(0, index[:, None].expand_as(src), src, reduce="amax", include_self=False)


class PriceNet(nn.Module):
    """sigma per task from the task-opportunity graph (see the module docstring)."""

    def __init__(self, cfg: PriceModelConfig):
        super().__init__()
        self.cfg = cfg
        h = cfg.hidden
        self.task_in = mlp(len(TASK_FEATURES), h, h)
        self.pass_in = mlp(len(PASS_FEATURES), h, h)
        self.to_pass = nn.ModuleList(mlp(2 * h + len(EDGE_FEATURES), h, h) for _ in range(cfg.layers))
        self.pass_up = nn.ModuleList(mlp(2 * h, h, h) for _ in range(cfg.layers))
        self.to_task = nn.ModuleList(mlp(2 * h + len(EDGE_FEATURES), h, h) for _ in range(cfg.layers))
        self.task_up = nn.ModuleList(mlp(3 * h, h, h) for _ in range(cfg.layers))
        self.out = mlp(h, 1, h)

    def forward(self, g: dict[str, torch.Tensor]) -> torch.Tensor:
        """Logits per task (sigma = sigmoid(logits)); `g` holds the TaskGraph's arrays as tensors."""
        ht, hp = self.task_in(g["x_task"]), self.pass_in(g["x_pass"])
        et, ep, xe = g["edge_task"], g["edge_pass"], g["x_edge"]
        n, P = ht.shape[0], hp.shape[0]
        for k in range(self.cfg.layers):
            m = self.to_pass[k](torch.cat([ht[et], hp[ep], xe], 1))
            hp = hp + self.pass_up[k](torch.cat([hp, scatter_mean(m, ep, P)], 1))
            m = self.to_task[k](torch.cat([hp[ep], ht[et], xe], 1))
            ht = ht + self.task_up[k](torch.cat([ht, scatter_mean(m, et, n), scatter_max(m, et, n)], 1))
        return self.out(ht).squeeze(1)


def tensors(g: TaskGraph) -> dict[str, torch.Tensor]:
    return {"x_task": torch.from_numpy(g.x_task), "x_pass": torch.from_numpy(g.x_pass),
            "edge_task": torch.from_numpy(g.edge_task), "edge_pass": torch.from_numpy(g.edge_pass),
            "x_edge": torch.from_numpy(g.x_edge)}


@torch.no_grad()
def predict(model: PriceNet, g: TaskGraph) -> np.ndarray:
    """sigma per task, float64 (0 for a task not contested)."""
    model.eval()
    sigma = torch.sigmoid(model(tensors(g))).double().numpy()
    return np.where(g.contested, sigma, 0.0)


def save_price_model(model: PriceNet, directory: str | Path, extra: dict | None = None) -> Path:
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    with atomic_path(d / WEIGHTS) as tmp:
        torch.save({k: v.detach().cpu().clone() for k, v in model.state_dict().items()}, tmp)
    meta = {"format": "eosp-prices", "version": 1, "model": asdict(model.cfg), "features": LAYOUT, **(extra or {})}
    with atomic_path(d / CONFIG) as tmp:
        tmp.write_text(json.dumps(meta, indent=1))
    return d


def load_price_model(directory: str | Path | None = None) -> PriceNet:
    """The price model of `directory` (None: the shipped one); a model for another feature layout, a corrupt or
    foreign file: one-line InputError naming the file and what differs."""
    from eosp.models.checkpoint import read_weights

    d = Path(directory) if directory is not None else SHIPPED
    cfg_path = d / CONFIG
    if not cfg_path.is_file():
        raise InputError(cfg_path, "no price model here (prices.json missing)")
    try:
        meta = json.loads(cfg_path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(cfg_path, f"not JSON ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != "eosp-prices":
        raise InputError(cfg_path, "not a price model configuration (format 'eosp-prices' expected)")
    feats = meta.get("features")
    if feats != LAYOUT:
        diff = [k for k in LAYOUT if not isinstance(feats, dict) or feats.get(k) != LAYOUT[k]]
        raise InputError(cfg_path, "trained on another feature layout: its " + ", ".join(diff) + " features differ "
                         "from this eosp's")
    try:  # every size checked before anything is built (a width of 40,000 would take gigabytes)
        if not isinstance(meta.get("model"), dict):
            raise TypeError("'model' is not an object")
        cfg = apply_overrides(PriceModelConfig(), dict(meta["model"]))
    except (TypeError, ValueError) as exc:
        raise InputError(cfg_path, f"model configuration: {exc}") from None
    model = PriceNet(cfg)
    state = read_weights(d / WEIGHTS)
    want = model.state_dict()
    if set(state) != set(want) or any(state[k].shape != want[k].shape for k in want):
        raise InputError(d / WEIGHTS, "weights do not match the model configuration of prices.json")
    model.load_state_dict(state)
    return model
