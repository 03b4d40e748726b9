"""Agent checkpoints: weights as a plain tensor state dict, configuration as JSON.

``agent.pt`` holds only tensors and is read with ``torch.load(weights_only=True)``;
``agent.json`` holds the model and environment configurations the weights were
trained with.  Nothing is ever unpickled.

Two environments train the same agent: the single pass (``EnvConfig``) and the constellation
(``FleetEnvConfig``, one agent per satellite).  A constellation checkpoint says so in ``agent.json``
(``"env_kind": "fleet"``) and lists the node features it was trained on (``"features"``), so that
:func:`load_fleet_agent` refuses, in one line naming what differs, a single-pass checkpoint, a fleet
checkpoint of another observation layout, or one trained for another objective; :func:`load_agent` (the
single pass) refuses a fleet checkpoint likewise.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import torch

from eosp.atomic import atomic_path
from eosp.config import EnvConfig, FleetEnvConfig, ModelConfig, from_dict, to_dict
from eosp.errors import InputError
from eosp.envs.constellation_obs import FLEET_NODE_FEATURES
from eosp.envs.observation import LOSES, N_NODE_FEATURES, PLAN
from eosp.models.agent import EOSPAgent

WEIGHTS, CONFIG = "agent.pt", "agent.json"
FLEET = "fleet"  # agent.json's "env_kind" of a constellation checkpoint (absent: the single pass)


def save_agent(agent: EOSPAgent, directory: str | Path, env_cfg: EnvConfig | FleetEnvConfig,
               extra: dict[str, Any] | None = None) -> Path:
    """Weights and agent.json; a constellation agent (`env_cfg` a FleetEnvConfig) is marked as one, with the
    node features it reads."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu().clone() for k, v in agent.state_dict().items()}
    with atomic_path(d / WEIGHTS) as tmp:
        torch.save(state, tmp)
    meta = {"format": "eosp-agent", "version": 1, "model": to_dict(agent.cfg), "env": to_dict(env_cfg)}
    if isinstance(env_cfg, FleetEnvConfig):
        meta |= {"env_kind": FLEET, "features": list(FLEET_NODE_FEATURES)}
        meta["env"]["fleets"] = []
    else:
        meta["env"]["shards"] = []
    meta |= extra or {}
    with atomic_path(d / CONFIG) as tmp:
        tmp.write_text(json.dumps(meta, indent=1))
    return d


def _checkpoint_dir(directory: str | Path) -> Path:
    given = Path(directory)
    if not given.exists():
        raise InputError(given, "checkpoint not found")
    d = given.parent if given.is_file() else given
    if not (d / WEIGHTS).exists() or not (d / CONFIG).exists():
        where = "this directory" if given.is_dir() else f"its directory {d}"
        raise InputError(given, f"not an agent checkpoint: expected {WEIGHTS} and {CONFIG} in {where}")
    return d


def _build(d: Path, model_cfg: ModelConfig, n_features: int) -> EOSPAgent:
    try:
        agent = EOSPAgent(model_cfg, n_features)
    except (ValueError, TypeError, RuntimeError) as exc:
        raise InputError(d / CONFIG, f"'model' cannot build the agent: {one_line(exc)}") from None
    load_weights(agent, read_weights(d / WEIGHTS), d / WEIGHTS, lookahead=n_features == N_NODE_FEATURES)
    agent.eval()
    return agent


def load_agent(directory: str | Path) -> tuple[EOSPAgent, EnvConfig, dict[str, Any]]:
    """The single-pass agent (eval mode), the env configuration it was trained with, and the metadata."""
    d = _checkpoint_dir(directory)
    meta, model_cfg, env_cfg = read_agent_json(d / CONFIG)
    if isinstance(env_cfg, FleetEnvConfig):
        raise InputError(d, "a fleet policy (trained in the constellation environment), not a single-pass agent: "
                            "use it on a fleet (--solver fleet-policy)")
    return _build(d, model_cfg, N_NODE_FEATURES), env_cfg, meta


def load_fleet_agent(directory: str | Path, reward: str = "wcr") -> tuple[EOSPAgent, FleetEnvConfig, dict[str, Any]]:
    """A constellation agent (eval mode), its FleetEnvConfig and the metadata; a single-pass checkpoint, one of
    another observation layout (node features) or one trained for another reward than `reward` is refused in
    one line naming what differs."""
    d = _checkpoint_dir(directory)
    meta, model_cfg, env_cfg = read_agent_json(d / CONFIG)
    if not isinstance(env_cfg, FleetEnvConfig):
        raise InputError(d, "a single-pass agent (EnvConfig, one pass of one satellite), not a fleet policy: "
                            "no 'env_kind': 'fleet' in agent.json")
    features = meta.get("features")
    if features != list(FLEET_NODE_FEATURES):
        if not isinstance(features, list):
            raise InputError(d / CONFIG, "no 'features' list: the observation layout it was trained on is unknown")
        ours = list(FLEET_NODE_FEATURES)
        i = next((i for i, (a, b) in enumerate(zip(features, ours)) if a != b), min(len(features), len(ours)))
        differ = (f"column {i} is {features[i]!r} there, {ours[i]!r} here" if i < min(len(features), len(ours))
                  else f"{len(features)} node features there, {len(ours)} here")
        raise InputError(d / CONFIG, f"trained on another observation layout of the constellation environment "
                                     f"({differ})")
    if env_cfg.reward != reward:
        raise InputError(d / CONFIG, f"trained for reward {env_cfg.reward!r}, not {reward!r} (the objective "
                                     f"{'WCR' if reward == 'wcr' else 'CR'} this solver maximizes)")
    return _build(d, model_cfg, len(FLEET_NODE_FEATURES)), env_cfg, meta


def one_line(exc: BaseException) -> str:
    """The first line of an exception's message (torch's run over dozens of lines)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def read_agent_json(path: Path) -> tuple[dict, ModelConfig, EnvConfig | FleetEnvConfig]:
    """The metadata of agent.json and the model and environment configurations it holds (a FleetEnvConfig for a
    constellation checkpoint); a one-line InputError naming the file and what is wrong otherwise."""
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise InputError(path, "not UTF-8 text (a JSON object expected)") from None
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc}") from None
    if not isinstance(meta, dict):
        raise InputError(path, f"must hold a JSON object, not a {type(meta).__name__}")
    if meta.get("format") != "eosp-agent":
        raise InputError(path, "not an EOSP agent checkpoint (missing format 'eosp-agent')")
    kind = meta.get("env_kind")
    if kind not in (None, FLEET):
        raise InputError(path, f"unknown 'env_kind' {kind!r} (none for the single pass, {FLEET!r})")
    cfgs = []
    for key, cls in (("model", ModelConfig), ("env", FleetEnvConfig if kind == FLEET else EnvConfig)):
        if not isinstance(meta.get(key), dict):
            raise InputError(path, f"no '{key}' entry (a JSON object of {cls.__name__})" if key not in meta
                             else f"'{key}' must be a JSON object of {cls.__name__}")
        try:
            cfgs.append(from_dict(cls, meta[key]))
        except (ValueError, TypeError) as exc:
            raise InputError(path, f"'{key}': {one_line(exc)}") from None
    return meta, cfgs[0], cfgs[1]


def read_weights(path: Path) -> dict[str, torch.Tensor]:
    """The tensor state dict of agent.pt, read without unpickling anything (``weights_only=True``); a one-line
    InputError otherwise (never torch's advice to load the file unsafely)."""
    with open(path, "rb") as fh:
        if fh.read(4) != b"PK\x03\x04":  # torch.save writes a zip archive
            raise InputError(path, "not a torch weights file (torch.save's zip archive of tensors expected)")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - truncated or foreign archives, pickled objects
        text = str(exc)
        if "Unsupported global" in text or "Unsupported operand" in text or "WeightsUnpickler" in text:
            why = "holds Python objects besides tensors, which are never unpickled"
        else:
            why = f"unreadable or truncated torch archive ({type(exc).__name__})"
        raise InputError(path, why) from None
    if not isinstance(state, dict) or not all(isinstance(k, str) and isinstance(v, torch.Tensor)
                                              for k, v in state.items()):
        raise InputError(path, f"must hold a state dict (parameter name -> tensor), not a {type(state).__name__}")
    return state


def load_weights(agent: EOSPAgent, state: dict[str, torch.Tensor], path: Path, lookahead: bool = True) -> None:
    """Load `state` into `agent`; a mismatch is one line: the first parameter at fault (and its two shapes).
    `lookahead`: a single-pass agent, whose older checkpoints lack the last node features' columns
    (:func:`with_lookahead_columns`)."""
    if lookahead:
        state = with_lookahead_columns(state)
    own = agent.state_dict()
    missing = [k for k in own if k not in state]
    extra = [k for k in state if k not in own]
    if missing or extra:
        parts = ([f"{len(missing)} parameter(s) missing, first {missing[0]!r}"] if missing else []) + \
                ([f"{len(extra)} unexpected, first {extra[0]!r}"] if extra else [])
        raise InputError(path, "weights do not match the model configuration of agent.json: " + "; ".join(parts))
    for k, v in own.items():
        if tuple(state[k].shape) != tuple(v.shape):
            raise InputError(path, f"weights do not match the model configuration of agent.json: {k!r} has shape "
                                   f"{tuple(state[k].shape)} in the file, {tuple(v.shape)} in the model")
    try:
        agent.load_state_dict(state)
    except RuntimeError as exc:
        raise InputError(path, f"weights do not match the model configuration: {one_line(exc)}") from None


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


def agent_from_rllib_weights(weights: dict[str, Any], model_cfg: ModelConfig,
                             n_node_features: int = N_NODE_FEATURES) -> EOSPAgent:
    """An agent from the learner's module state (keys 'agent.*', numpy arrays or tensors); `n_node_features`: the
    width of its environment's node features (the constellation's: len(FLEET_NODE_FEATURES))."""
    agent = EOSPAgent(model_cfg, n_node_features)
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
