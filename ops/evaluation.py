"""The operations scenarios that evaluate learned planners, fixed before any of them was trained or tuned
(``evaluation_scenarios.json`` beside this module; docs/operations.md, "Evaluation scenarios").

What trains or tunes a planner calls :func:`refuse_evaluation_scenario` on every scenario it reads: a scenario made
with one of these seeds is refused, whatever its fleet, so that evaluation data never reaches training (the seeds
are 31-bit draws: another scenario meets one only by copying it).  The file's fingerprint is held by a test: a
change to it is a deliberate, visible act.
"""

from __future__ import annotations

import json
from functools import lru_cache

from eosp.errors import InputError


@lru_cache(maxsize=1)
def evaluation_scenarios() -> dict:
    """The file's content: scenarios (name, fleet, hours, seed, realizations) and the perturbed cloud models."""
    from importlib.resources import files

    return json.loads(files("eosp.ops").joinpath("evaluation_scenarios.json").read_text(encoding="utf-8"))


def evaluation_seeds() -> frozenset[int]:
    return frozenset(int(s["seed"]) for s in evaluation_scenarios()["scenarios"])


def refuse_evaluation_scenario(scen, flag: str) -> None:
    """An InputError naming `flag` when `scen` (:class:`eosp.ops.scenario.Scenario`) was made with an evaluation
    scenario's seed."""
    if int(scen.config.seed) in evaluation_seeds():
        raise InputError(f"{flag} {scen.path}", f"made with seed {scen.config.seed}, an evaluation scenario's "
                                                "(eosp/ops/evaluation_scenarios.json): training and tuning never read "
                                                "evaluation scenarios")
