"""Agent checkpoints: weights as a plain tensor state dict, configuration as JSON.

``agent.pt`` holds only tensors and is read with ``torch.load(weights_only=True)``;
``agent.json`` holds the model and environment configurations the weights were
trained with.  Nothing is ever unpickled.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import torch

from eosp.atomic import atomic_path
from eosp.config import EnvConfig, ModelConfig, from_dict, to_dict
from eosp.errors import InputError
from eosp.envs.observation import LOSES, N_NODE_FEATURES, PLAN
from eosp.models.agent import EOSPAgent

WEIGHTS, CONFIG = "agent.pt", "agent.json"


def save_agent(agent: EOSPAgent, directory: str | Path, env_cfg: EnvConfig, extra: dict[str, Any] | None = None) -> Path:
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu().clone() for k, v in agent.state_dict().items()}
    with atomic_path(d / WEIGHTS) as tmp:
        torch.save(state, tmp)
    meta = {"format": "eosp-agent", "version": 1, "model": to_dict(agent.cfg), "env": to_dict(env_cfg),
            **(extra or {})}
    meta["env"]["shards"] = []
    with atomic_path(d / CONFIG) as tmp:
        tmp.write_text(json.dumps(meta, indent=1))
    return d


def load_agent(directory: str | Path) -> tuple[EOSPAgent, EnvConfig, dict[str, Any]]:
    """The agent (eval mode), the env configuration it was trained with, and the metadata."""
    given = Path(directory)
    if not given.exists():
        raise InputError(given, "checkpoint not found")
    d = given.parent if given.is_file() else given
    if not (d / WEIGHTS).exists() or not (d / CONFIG).exists():
        where = "this directory" if given.is_dir() else f"its directory {d}"
        raise InputError(given, f"not an agent checkpoint: expected {WEIGHTS} and {CONFIG} in {where}")
    try:
        meta = json.loads((d / CONFIG).read_text())
    except json.JSONDecodeError as exc:
        raise InputError(d / CONFIG, f"not valid JSON: {exc}") from None
    if meta.get("format") != "eosp-agent":
        raise InputError(d / CONFIG, "not an EOSP agent checkpoint (missing format 'eosp-agent')")
    agent = EOSPAgent(from_dict(ModelConfig, meta["model"]))
    try:
        state = torch.load(d / WEIGHTS, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated or foreign file
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(d / WEIGHTS, f"cannot read the weights: {first}") from None  # one line: torch's are long
    try:
        agent.load_state_dict(with_lookahead_columns(state))
    except RuntimeError as exc:
        raise InputError(d / WEIGHTS, f"weights do not match the model configuration: {exc}") from None
    agent.eval()
    return agent, from_dict(EnvConfig, meta["env"]), meta


def with_lookahead_columns(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """`state` with zero input weights for the node features added after it was saved.

    The lookahead features (:data:`eosp.envs.observation.LOSES` on), then the plan features
    (:data:`eosp.envs.observation.PLAN` on, the rollout ones from PLAN + 3), were appended as the last node
    features: a checkpoint saved before them has 12, 6 or 3 input columns fewer in the first node layer.
    Zero weights there make the agent compute exactly what it computed before, and let training start
    from it."""
    key = "node_embed.0.weight"
    w = state.get(key)
    if w is not None and w.ndim == 2 and w.shape[1] in (LOSES, PLAN, PLAN + 3):
        w = torch.as_tensor(w)
        state = dict(state)
        state[key] = torch.cat([w, torch.zeros(w.shape[0], N_NODE_FEATURES - w.shape[1], dtype=w.dtype)], dim=1)
    return state


def agent_from_rllib_weights(weights: dict[str, Any], model_cfg: ModelConfig) -> EOSPAgent:
    """An agent from the learner's module state (keys 'agent.*', numpy arrays or tensors)."""
    agent = EOSPAgent(model_cfg)
    state = {k[len("agent."):]: torch.as_tensor(v) for k, v in weights.items() if k.startswith("agent.")}
    agent.load_state_dict(state)
    agent.eval()
    return agent


def rllib_weights_from_agent(agent: EOSPAgent) -> dict[str, Any]:
    return {f"agent.{k}": v.detach().cpu().numpy() for k, v in agent.state_dict().items()}


def load_start(directory: str | Path, reward: str, job: str) -> EOSPAgent:
    """The agent a training job starts from (`--train.init-checkpoint`, `--imitation.init-checkpoint`): its
    architecture and value scale come with the weights; a different reward is worth a warning, not a refusal."""
    agent, env, _ = load_agent(directory)
    if env.reward != reward:
        print(f"[{job}] warning: {directory} was trained with reward {env.reward!r}, this run uses {reward!r}",
              file=sys.stderr)
    print(f"[{job}] starting from {directory}", flush=True)
    return agent
