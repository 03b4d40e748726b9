"""Pretrained agents shipped with the package: one call away, no download.

``models/pretrained/<mode>/`` holds ``agent.pt`` (weights, read with
``weights_only=True``), ``agent.json`` (model and environment configuration) and
``MODEL.md`` (the command, data seeds and validation figures that produced it).
``eosp solve --solver policy|mcts --mode M`` without ``--checkpoint`` uses the one
of mode M, and so do ``jobs/evaluate.py`` and the MLflow model.  Other shipped models
(:data:`VARIANTS`, e.g. ``utility-plan``, which reads Greedy's plan: better schedules,
~20x the decision cost at 1000 acquisitions) are one flag away:
``--checkpoint pretrained:utility-plan``.
"""

from __future__ import annotations

from pathlib import Path

from eosp.errors import InputError

ROOT = Path(__file__).resolve().parent / "pretrained"
MODES = ("unitary", "utility")
VARIANTS = ("utility-plan",)
PREFIX = "pretrained:"


def pretrained_dir(mode: str) -> Path:
    """The shipped checkpoint directory of an objective mode ('unitary' or 'utility') or of a variant."""
    if mode not in MODES + VARIANTS:
        raise InputError("--mode", f"no pretrained model {mode!r}; shipped: {', '.join(MODES + VARIANTS)}")
    d = ROOT / mode
    if not (d / "agent.pt").is_file() or not (d / "agent.json").is_file():
        raise InputError(d, "the shipped pretrained model is missing (agent.pt and agent.json expected): reinstall "
                            "the package, or pass --checkpoint")
    return d


def load_pretrained(mode: str):
    """(agent, env config, metadata) of the shipped model of `mode` (or variant); one clear line if it is missing or
    corrupt."""
    from eosp.models.checkpoint import load_agent

    return load_agent(pretrained_dir(mode))
