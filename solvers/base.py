"""What every solver takes and returns, and the registry behind ``eosp solve --solver NAME``.

Each solver module defines a config dataclass (a subclass of :class:`SolverConfig`,
or of :class:`LearnedConfig` for the solvers that play a trained agent) and one entry
``solve(inst, cfg) -> Solution``.  :func:`run_solver` builds the config from keyword
options, so a misspelled option is an error naming the valid ones, never ignored; the
CLI builds its flags from the same config (:func:`eosp.args.add_config_args`).

Time limits mean the same for every solver of every problem kind (:class:`SolverConfig`): the searching
solvers (ramp, exact, lns, sample, beam, mcts; the fleet and ONERA searches) honour ``time_limit``, wall-clock
seconds of the solve after the problem is read; the one-shot constructions (random, greedy, policy; the fleet
and ONERA greedy) always finish in one pass and refuse a limit (``ONE_SHOT``), so a caller never believes it
bounded them; the anytime searches, which do not end by themselves, need a limit or their deterministic budget
(``BUDGET``: the fleet's rounds, the ONERA search's moves).
"""

from __future__ import annotations

import functools
import importlib
import numbers
import typing
from dataclasses import dataclass, field, fields
from typing import Any, Callable, ClassVar

import numpy as np

from eosp.config import WEEK_S, check_value, choice, ranged
from eosp.instances.instance import Instance


@dataclass
class Solution:
    """A path in the discrete graph: canonical node indices in execution order (source excluded)."""

    nodes: np.ndarray
    value: float
    info: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_path(cls, inst: Instance, nodes: np.ndarray, mode: str, info: dict[str, Any] | None = None) -> Solution:
        """The solution of a path, valued with the objective of `mode` (:func:`objective_weights`)."""
        nodes = np.asarray(nodes)
        value = float(objective_weights(inst, mode)[inst.node_acq[nodes]].sum()) if len(nodes) else 0.0
        return cls(nodes, value, info or {})


def objective_weights(inst: Instance, mode: str) -> np.ndarray:
    """Per-acquisition weight: the utility, or 1 per acquisition in unitary mode."""
    if mode == "utility":
        return inst.acqs.utility
    if mode == "unitary":
        return np.ones(inst.n_acq)
    raise ValueError(f"unknown objective mode {mode!r} (utility, unitary)")


@dataclass
class SolverConfig:
    """Options every solver takes."""

    mode: str = choice("utility", "utility", "unitary")
    """'utility' (sum of utilities) or 'unitary' (count acquisitions)."""
    time_limit: float | None = ranged(None, 0, WEEK_S, zero_unsets=True)
    """Wall-clock seconds of the solve after the problem is read; unset: no limit, for a search that ends by
    itself (0 on a command line means unset).  The anytime searches (fleet, onera) default to a number and stop
    at it or at their deterministic budget (--rounds, --moves), whichever comes first; the one-pass
    constructions (random, greedy, policy, the fleet and ONERA greedy) refuse it."""
    seed: int = ranged(0, 0)
    """Seed of the random choices (random walk, sampled policy, sample, beam, mcts)."""

    NAME: ClassVar[str] = ""
    ONE_SHOT: ClassVar[bool] = False  # one pass, no search: a time limit is refused, not ignored
    BUDGET: ClassVar[str] = ""  # an anytime search's deterministic budget (a field): it needs this or a time limit

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Every field of the right type and within its limits (:func:`eosp.config.check_value`); a
        one-shot solver given a time limit is refused.  A one-line ValueError otherwise."""
        cls = type(self)
        # the type is part of the key: True == 1 == 1.0 as dictionary keys, yet only one of them is an int
        values = tuple((name, type(v), v) for name in field_names(cls) for v in (getattr(self, name),))
        try:
            _check_fields(cls, values)  # the same values were checked before: a fleet solves 100,000s of passes
        except TypeError:  # an unhashable value (a wrong type): checked directly, for its message
            _check_fields.__wrapped__(cls, values)
        if self.ONE_SHOT and self.time_limit is not None:
            raise ValueError(f"solver {self.NAME!r} takes no time_limit: it builds its schedule in one pass and "
                             f"always finishes (got {self.time_limit!r}; leave it unset)")
        if self.BUDGET and self.time_limit is None and getattr(self, self.BUDGET) is None:
            flag = "--" + self.BUDGET.replace("_", "-")
            raise ValueError(f"solver {self.NAME!r} needs a time_limit or {self.BUDGET} (--time-limit or {flag}): "
                             "it searches until one of them ends it")


@dataclass
class UtilityConfig(SolverConfig):
    """Options of the solvers of the kinds that maximise the value served alone (fleets: the weight served,
    WCR; ONERA: the plan's value)."""

    mode: str = choice("utility", "utility")
    """'utility' only: the value served (a fleet's weight, WCR; an ONERA plan's value)."""


@dataclass
class LearnedConfig(SolverConfig):
    """Options of the solvers that play a trained agent (policy, sample, beam, mcts).  An agent already
    loaded is passed to ``solve(inst, cfg, agent=...)`` instead, as an (agent, env config, metadata) tuple."""

    checkpoint: str = ""
    """Trained agent: a checkpoint directory, or pretrained:NAME for another shipped model (utility-fast: no plan
    features, cheaper decisions at 1000+ acquisitions, lower values); empty: the shipped pretrained model of
    --mode (for the searches with a time limit on more than 500 acquisitions, utility-fast)."""
    guard: float = ranged(0.3, 0, 1)
    """Rollout guard of the decisions, for models that read Greedy's plan (--env.plan): an allowed action whose
    Greedy rollout value is below (1 - guard) times the best allowed action's is never chosen (the best never
    is, so an action always remains); 1: off; 0: only actions of the best rollout value (the rollout of Greedy,
    the network breaking ties).  Relative, so it means the same on any utility scale.  Why: the
    policy's rare costliest errors give up a top acquisition that Greedy's rollout shows another action keeps."""


@dataclass
class SearchConfig(LearnedConfig):
    """Options of the learned searches (sample, beam, mcts)."""

    polish: bool = True
    """Improve every complete schedule the search meets by insert and swap moves before comparing them
    (eosp.search.polish; milliseconds per schedule); --polish false: the search's own schedules only."""
    refine: float = ranged(0.75, 0.0, 1.0)
    """With polish and a time limit: the share of the time limit spent refining the best schedule found by ruin
    and recreate (drop a few consecutive acquisitions, refill, keep when not worse) and windows; 0: search until
    the limit.  0.75: at 1000-1500 acquisitions the windows need 3-4 s to reach RAMP's value (0.5 was short)."""
    windows: bool = True
    """While refining, also re-plan windows of consecutive acquisitions by a label sweep over the time between
    their neighbours (eosp.planning.windows: up to 16 with 4 labels per node, or up to the whole schedule with 1,
    2, 4, ... 16 labels per node, doubled after each round), for up to three times as long as the ruin and recreate."""
    window_graph: str = choice("pruned", "pruned", "unpruned")
    """The arcs a window's label sweep looks at: the pruned graph's (RAMP's: 6-170 arcs per node against 50-770
    unpruned from 100 to 1500 acquisitions, so many more windows per second where schedules are long) or the
    unpruned graph's (every arc; windows there mostly exceed their work bound from ~500 acquisitions on).  The
    schedule itself may keep using every arc."""


@functools.lru_cache(maxsize=None)
def _type_hints(cls: type) -> dict[str, Any]:
    """A config class's resolved annotations, once per class: resolving them is most of a small solve's cost
    (the fleet solver solves hundreds of small passes a round)."""
    return typing.get_type_hints(cls)


@functools.cache
def field_names(cls: type) -> tuple[str, ...]:
    """The names of a solver config class's fields, once (``dataclasses.fields`` costs microseconds a call, and a
    fleet's sweeps build and check a config for every pass they solve)."""
    return tuple(f.name for f in fields(cls))


@functools.lru_cache(maxsize=4096)
def _check_fields(cls: type, values: tuple) -> None:
    """Type and range of each (field, value) of a config (cached: identical configs are checked once; a
    failing one raises every time, as lru_cache keeps no exception)."""
    hints = _type_hints(cls)
    for name, _, value in values:
        _check_type(cls.__name__, name, hints[name], value)
        check_value(cls, name, value)


def _check_type(owner: str, name: str, hint: Any, value: Any) -> None:
    args = typing.get_args(hint)
    if value is None and type(None) in args:
        return
    base = next((a for a in args if a is not type(None)), hint) if args else hint
    ok = {bool: lambda v: isinstance(v, (bool, np.bool_)),
          int: lambda v: isinstance(v, numbers.Integral) and not isinstance(v, (bool, np.bool_)),
          float: lambda v: isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_)),
          str: lambda v: isinstance(v, str)}.get(base)
    if ok is not None and not ok(value):
        kind = {bool: "true/false", int: "an integer", float: "a number", str: "a string"}[base]
        raise ValueError(f"{owner}.{name}: expected {kind}{' or None' if type(None) in args else ''}, got {value!r}")


@dataclass(frozen=True)
class SolverEntry:
    """Where a solver lives: its ``solve(inst, cfg)`` and its config class, as "module:name"."""

    function: str
    config: str

    def load(self, which: str) -> Any:
        module, name = getattr(self, which).split(":")
        return getattr(importlib.import_module(module), name)


REGISTRY: dict[str, SolverEntry] = {
    "random": SolverEntry("eosp.solvers.random_walk:solve", "eosp.solvers.random_walk:RandomConfig"),
    "policy": SolverEntry("eosp.solvers.policy:solve", "eosp.solvers.policy:PolicyConfig"),
    "mcts": SolverEntry("eosp.solvers.mcts:solve", "eosp.solvers.mcts:MctsConfig"),
    "sample": SolverEntry("eosp.solvers.sample:solve", "eosp.solvers.sample:SampleConfig"),
    "beam": SolverEntry("eosp.solvers.beam:solve", "eosp.solvers.beam:BeamConfig"),
    "greedy": SolverEntry("eosp.solvers.greedy:solve", "eosp.solvers.greedy:GreedyConfig"),
    "ramp": SolverEntry("eosp.solvers.ramp:solve", "eosp.solvers.ramp:RampConfig"),
    "exact": SolverEntry("eosp.solvers.exact:solve", "eosp.solvers.exact:ExactConfig"),
    "lns": SolverEntry("eosp.solvers.lns:solve", "eosp.solvers.lns:LnsConfig"),
}


def _entry(name: str) -> SolverEntry:
    if name not in REGISTRY:
        raise ValueError(f"unknown solver {name!r}; available: {', '.join(sorted(REGISTRY))}")
    return REGISTRY[name]


def solver_config_class(name: str) -> type[SolverConfig]:
    """The config dataclass of solver `name`."""
    return _entry(name).load("config")


def solver_function(name: str) -> Callable[..., Solution]:
    """The ``solve(inst, cfg)`` of solver `name`."""
    return _entry(name).load("function")


def is_learned(name: str) -> bool:
    return issubclass(solver_config_class(name), LearnedConfig)


def takes_time_limit(name: str) -> bool:
    """Whether solver `name` honours a time limit (the one-shot ones refuse it)."""
    return not solver_config_class(name).ONE_SHOT


def make_config(name: str, **options: Any) -> SolverConfig:
    """The config of solver `name` with `options` set; an unknown option is a one-line ValueError that
    names it and the valid ones, a bad value one that names the field."""
    cls = solver_config_class(name)
    valid = field_names(cls)
    unknown = [k for k in options if k not in valid]
    if unknown:
        raise ValueError(f"solver {name!r} has no option {', '.join(map(repr, unknown))}; "
                         f"its options: {', '.join(valid)}")
    return cls(**options)


class Incumbent:
    """The best feasible schedule a search of this process has met so far, for Ctrl-C.

    The searches with an incumbent (exact, lns, sample, beam, mcts; any later one) report each improved complete
    schedule with :meth:`offer` (canonical node indices of the instance, and its objective value); the command
    line's interrupt path takes the last one with :meth:`take`, checks it with the independent checker and
    writes it.  :func:`run_solver` clears it at the start of each solve."""

    def __init__(self) -> None:
        self.clear(None)

    def clear(self, inst: Instance | None) -> None:
        self.inst, self.nodes, self.value = inst, None, float("-inf")

    def offer(self, nodes: Any, value: float) -> None:
        """Keep `nodes` when its `value` is above the best kept (copied: the caller may reuse its buffer)."""
        if value > self.value:
            self.nodes, self.value = np.array(nodes, dtype=np.int64, copy=True), float(value)

    def take(self, inst: Instance) -> np.ndarray | None:
        """The best schedule kept for `inst` (None when there is none)."""
        return self.nodes if self.inst is inst else None


INCUMBENT = Incumbent()


def run_solver(name: str, inst: Instance, *, agent: tuple | None = None, **options: Any) -> Solution:
    """Solve `inst` with solver `name`, its config built from `options` (:func:`make_config`).

    `agent`: an already loaded (agent, env config, metadata) for the learned solvers.  The searches report their
    improving schedules to :data:`INCUMBENT` (what Ctrl-C writes)."""
    cfg = make_config(name, **options)
    INCUMBENT.clear(inst)
    if agent is not None:
        if not isinstance(cfg, LearnedConfig):
            raise ValueError(f"solver {name!r} plays no agent: agent= is only for "
                             f"{', '.join(n for n in sorted(REGISTRY) if is_learned(n))}")
        return solver_function(name)(inst, cfg, agent=agent)
    return solver_function(name)(inst, cfg)
