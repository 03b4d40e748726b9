"""Pretrained agents shipped with the package: one call away, no download.

``models/pretrained-agents/<name>/`` holds ``agent.pt`` (weights, read with
``weights_only=True``), ``agent.json`` (model and environment configuration) and
``MODEL.md`` (the command, data seeds and validation figures that produced it).
``eosp solve --solver policy|mcts --mode M`` without ``--checkpoint`` uses the model
of mode M, and so do ``jobs/evaluate.py`` and the MLflow model.  The utility model reads
Greedy's plan and Greedy's rollout after each allowed action (``--env.plan``), whose cost
per step grows with the allowed actions times the acquisitions left (2 ms at 300
acquisitions, 36-420 ms at 1000): the time-limited searches on instances of more than
:data:`FAST_ABOVE` acquisitions therefore default to the mode's fast model
(:data:`FAST`, ``utility-fast``: no plan features, the shipped utility model before it),
whose greedy episode fits their time share.  Any shipped model is one flag away:
``--checkpoint pretrained:NAME`` (``utility-plan``: the name the plan model had when it
was a variant, kept so that commands written then still work).  The unitary model reads
the label sweep's values instead (``--env.plan label``: one backward sweep a step, 45 ms at
1000 acquisitions on a conflict instance), so it serves searches of every size.

The fleet policy (``fleet``: the constellation environment's agent, one module for every satellite) serves
``eosp solve FLEET_DIR --solver fleet-policy|fleet-sample`` without ``--checkpoint`` (:func:`load_fleet_pretrained`).
"""

from __future__ import annotations

from pathlib import Path

from eosp.errors import InputError

ROOT = Path(__file__).resolve().parent / "pretrained-agents"
MODES = ("unitary", "utility")
VARIANTS = ("utility-fast",)
FLEET = "fleet"  # the shipped fleet policy (a constellation checkpoint: eosp.models.checkpoint.load_fleet_agent)
ALIASES = {"utility-plan": "utility"}
FAST = {"utility": "utility-fast"}
FAST_ABOVE = 500
PREFIX = "pretrained:"


def default_name(mode: str, n_acquisitions: int = 0, time_limited: bool = False) -> str:
    """The shipped model that serves `mode` when no checkpoint is given: the mode's own, or its fast model for a
    time-limited search on more than :data:`FAST_ABOVE` acquisitions (see the module docstring)."""
    if time_limited and n_acquisitions > FAST_ABOVE and mode in FAST:
        return FAST[mode]
    return mode


def pretrained_dir(mode: str) -> Path:
    """The shipped checkpoint directory of an objective mode ('unitary' or 'utility') or of a variant."""
    mode = ALIASES.get(mode, mode)
    if mode not in MODES + VARIANTS + (FLEET,):
        names = ", ".join(MODES + VARIANTS + tuple(ALIASES) + (FLEET,))
        raise InputError(f"--checkpoint {PREFIX}{mode}", f"no pretrained model {mode!r}; shipped: {names}")
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


def load_fleet_pretrained(checkpoint: str = ""):
    """(agent, FleetEnvConfig, metadata) of a fleet policy: the shipped one (`checkpoint` empty or
    ``pretrained:fleet``), or a checkpoint directory; refused in one line when it is another layout or objective."""
    from eosp.models.checkpoint import load_fleet_agent

    if not checkpoint or checkpoint.startswith(PREFIX):
        name = checkpoint[len(PREFIX):] if checkpoint else FLEET
        if name != FLEET:
            raise InputError(f"--checkpoint {checkpoint}", f"{name!r} is no fleet policy; shipped: {FLEET}")
        return load_fleet_agent(pretrained_dir(FLEET))
    return load_fleet_agent(checkpoint)
