"""The onboard policy: which candidate a satellite takes in place of a primary found cloudy (or none).

A small network over the features of :mod:`eosp.ops.onboard` (one row per candidate slot): the same MLP scores
each candidate (a logit), a second reads the candidates pooled and gives the logit of taking none and the value
of the state (for PPO's critic).  Sharing the scorer across slots makes the choice equivariant to the order the
candidates were sent in (the order is a feature, ``rank``, not a position), and keeps the network tiny: a
decision is one forward pass of a few thousand multiply-adds, well under a millisecond on one CPU thread.

Saved as ``onboard.pt`` (tensors only, read with ``torch.load(weights_only=True)``) and ``onboard.json`` (format,
sizes, the feature names and the candidate slots it was trained on); a directory that says anything else is
refused in one line (:class:`eosp.errors.InputError`), never unpickled.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from torch import nn

from eosp.errors import InputError
from eosp.ops.onboard import CANDIDATES, FEATURES, Context, Decision, features

FORMAT, VERSION = "eosp-onboard-policy", 1
WEIGHTS, CONFIG = "onboard.pt", "onboard.json"
SHIPPED = Path(__file__).resolve().parent / "pretrained-agents" / "onboard"


class OnboardNet(nn.Module):
    """Logits over (candidate slots..., none) and a value, from features (batch, slots, F) and a mask (batch,
    slots); an empty slot's logit is -inf."""

    def __init__(self, hidden: int = 32, n_features: int = len(FEATURES)):
        super().__init__()
        self.hidden = hidden
        self.score = nn.Sequential(nn.Linear(n_features, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh())
        self.logit = nn.Linear(hidden, 1)
        self.pooled = nn.Sequential(nn.Linear(hidden + 1, hidden), nn.Tanh(), nn.Linear(hidden, 2))

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = self.score(x)
        logits = self.logit(h).squeeze(-1).masked_fill(~mask, -1e9)
        m = mask.unsqueeze(-1).to(h.dtype)
        n = m.sum(1)
        pooled = torch.cat([(h * m).sum(1) / n.clamp(min=1.0), n / x.shape[1]], dim=1)
        none_value = self.pooled(pooled)
        return torch.cat([logits, none_value[:, :1]], dim=1), none_value[:, 1]


class OnboardPolicy:
    """The network as a chooser (:data:`eosp.ops.onboard.Chooser`): the most likely action, -1 for none."""

    def __init__(self, net: OnboardNet, slots: int = CANDIDATES):
        self.net, self.slots = net.eval(), slots

    def chooser(self, ctx: Context):
        def choose(d: Decision) -> int:
            x, mask = features(ctx, d, self.slots)
            with torch.no_grad():
                logits, _ = self.net(torch.from_numpy(x)[None], torch.from_numpy(mask)[None])
            i = int(torch.argmax(logits[0]))
            return -1 if i == self.slots else i

        return choose


def save_policy(net: OnboardNet, directory: str | Path, extra: dict | None = None) -> Path:
    """Weights and onboard.json in `directory` (made if missing)."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    torch.save({k: v.detach().clone() for k, v in net.state_dict().items()}, d / WEIGHTS)
    meta = {"format": FORMAT, "version": VERSION, "hidden": net.hidden, "features": list(FEATURES),
            "candidates": CANDIDATES, **(extra or {})}
    (d / CONFIG).write_text(json.dumps(meta, indent=1) + "\n")
    return d


def load_policy(directory: str | Path | None = None) -> OnboardPolicy:
    """The policy saved in `directory` (None: the shipped one); one line naming the file and what is wrong with
    it for anything else."""
    d = Path(directory) if directory else SHIPPED
    cfg = d / CONFIG
    try:
        meta = json.loads(cfg.read_text())
    except FileNotFoundError:
        raise InputError(cfg, f"no onboard policy here (expected {CONFIG} and {WEIGHTS})") from None
    except (OSError, ValueError) as e:
        raise InputError(cfg, f"not an onboard policy's description ({e})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT or meta.get("version") != VERSION:
        raise InputError(cfg, f"not an onboard policy (format {FORMAT!r} version {VERSION} expected)")
    if meta.get("features") != list(FEATURES) or meta.get("candidates") != CANDIDATES:
        raise InputError(cfg, f"trained on other features or candidate slots than this version reads "
                         f"({meta.get('features')}, {meta.get('candidates')})")
    hidden = meta.get("hidden")
    if not isinstance(hidden, int) or not 1 <= hidden <= 1024:
        raise InputError(cfg, f"hidden must be an integer in [1, 1024], not {hidden!r}")
    net = OnboardNet(hidden)
    try:
        state = torch.load(d / WEIGHTS, map_location="cpu", weights_only=True)
        net.load_state_dict(state)
    except FileNotFoundError:
        raise InputError(d / WEIGHTS, "missing") from None
    except Exception as e:  # noqa: BLE001 - any unreadable or mismatched file is the user's, said in one line
        raise InputError(d / WEIGHTS, f"not the weights {cfg.name} describes ({str(e).splitlines()[0]})") from None
    return OnboardPolicy(net)


def decision_batch(rows: list[tuple[np.ndarray, np.ndarray]]) -> tuple[torch.Tensor, torch.Tensor]:
    """Features and masks of several decisions as tensors (batch, slots, F), (batch, slots)."""
    return (torch.from_numpy(np.stack([x for x, _ in rows])), torch.from_numpy(np.stack([m for _, m in rows])))
