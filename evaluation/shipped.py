"""What the shipped model does on a handful of instances: its value against Greedy, RAMP and the proven optimum.

The demo ends with it (``jobs/train.py --demo``): a few minutes of PPO from scratch say little, the model that
imitation of the exact solver produced says what the project can do.  Each instance is solved by the operational
Greedy, RAMP, the exact solver and the shipped policy solver of the objective mode (its defaults); ratios are
per instance, then averaged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eosp.instances.instance import Instance


@dataclass
class Comparison:
    """Per-instance values of one set (rows: instances) and the shipped policy's mean ratios to each baseline."""

    name: str
    values: dict[str, np.ndarray]
    proven: int

    def ratio(self, baseline: str) -> float:
        return float(np.mean(self.values["policy"] / np.maximum(self.values[baseline], 1e-12)))

    def line(self) -> str:
        return (f"  {self.name:28s} policy/greedy {self.ratio('greedy'):.4f}  policy/ramp {self.ratio('ramp'):.4f}  "
                f"policy/optimum {self.ratio('exact'):.4f}  ({len(self.values['policy'])} instances, "
                f"{self.proven} optima proven)")


def compare(name: str, instances: list[Instance], mode: str, exact_limit: float = 30.0) -> Comparison:
    """Greedy, RAMP, exact (time-limited: its status says whether the optimum is proven) and the shipped policy."""
    from eosp.solvers.base import run_solver
    from eosp.solvers.policy import PolicyConfig, resolve_agent
    from eosp.solvers.policy import solve as policy

    agent = resolve_agent("policy", "", None, mode)  # the shipped model, loaded once for every instance
    values = {s: np.zeros(len(instances)) for s in ("greedy", "ramp", "exact", "policy")}
    proven = 0
    for i, inst in enumerate(instances):
        for s in values:
            if s == "policy":
                sol = policy(inst, PolicyConfig(mode=mode), agent=agent)
            else:
                sol = run_solver(s, inst, mode=mode, **({"time_limit": exact_limit} if s == "exact" else {}))
            values[s][i] = sol.value
            proven += s == "exact" and sol.info.get("status") == "optimal"
    return Comparison(name, values, proven)


def reading(comps: list[Comparison]) -> str:
    """One line a newcomer can read: where Greedy is weak and how close the shipped model is to the optimum."""
    worst = min(comps, key=lambda c: c.ratio("exact"))
    weakest = min(comps, key=lambda c: float(np.mean(c.values["greedy"] / np.maximum(c.values["exact"], 1e-12))))
    greedy_gap = 1 - float(np.mean(weakest.values["greedy"] / np.maximum(weakest.values["exact"], 1e-12)))
    model = ("reaches the proven optimum on every instance shown" if all(
        np.all(c.values["policy"] >= c.values["exact"] * (1 - 1e-9)) for c in comps)
        else f"is within {100 * (1 - worst.ratio('exact')):.2f}% of it on average on every set shown")
    return (f"Reading: on {weakest.name} the operational Greedy leaves {100 * greedy_gap:.1f}% of the optimum "
            f"unserved; the shipped model {model}.")
