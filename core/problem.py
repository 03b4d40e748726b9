"""The contract of a problem kind: what every problem the platform reads offers, whatever its model.

A problem kind (a single pass, an aeossp fleet, an ONERA fleet, ...) is one folder of ``kinds/`` holding an
object that satisfies :class:`ProblemKind`, and one line of the registry (:mod:`eosp.kinds`).  The command line
detects the kind of the path it is given once and runs the same commands on every kind: ``eosp import``,
``generate``, ``info``, ``solve``, ``validate``, ``report`` and ``export-schedule``.

The words are one vocabulary across kinds: a kind *reads* a problem, *checks* a schedule of it (a
:class:`Verdict`: valid, metrics by name, the first violation), and its solvers (:class:`Solver`) *solve* it
(a :class:`Result`: the schedule, its value, a bound or None with what kind of bound it is, a status and the
timings).  Every solver's config is a ``SolverConfig`` (:mod:`eosp.solvers.base`): ``time_limit`` means the
same on every kind.

The members that run code are named as ``"module:attribute"`` strings and imported when used (:func:`load`),
so that reading the registry costs nothing (``eosp --help`` stays fast) and the contract, in the bottom layer,
imports no layer above it.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, NamedTuple, Protocol, Sequence, runtime_checkable


def load(ref: str) -> Any:
    """The attribute a ``"module:attribute"`` string names."""
    module, _, name = ref.partition(":")
    return getattr(importlib.import_module(module), name)


class Detection(NamedTuple):
    """Whether a kind reads a path, and why not (or what it found), in a few words."""

    ok: bool
    reason: str


@dataclass(frozen=True)
class Verdict:
    """A checker's judgement of a schedule: valid or not, its metrics by name (all of a kind's metrics, also
    when invalid: zero then, as the benchmarks' verifiers report), the first violation in words (None when
    valid), and the one line ``eosp validate`` prints."""

    valid: bool
    metrics: Mapping[str, float | int | None]
    first: str | None = None
    line: str = ""


@dataclass
class Result:
    """What a solver returns, on every kind.

    `value` is the objective the kind reports (a pass's utility sum, a fleet's WCR, an ONERA plan's value);
    `bound` an upper bound of the best value or None, `bound_kind` what proves it ("lagrangian",
    "conflict-free", "lp", "exact", ...); `status` how the solve ended ("optimal", "time_limit", "budget",
    "done", "interrupted", "first_schedule": the first schedule of an anytime search, found after the limit); `timings` seconds by phase; `info` the solver's own figures; `verdict` the
    checker's verdict when the solver ran the checker itself (the command line then does not run it again)."""

    schedule: Any
    value: float
    bound: float | None = None
    bound_kind: str | None = None
    status: str = "done"
    timings: dict[str, float] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    verdict: Verdict | None = None

    @property
    def gap(self) -> float | None:
        """(bound - value) / bound, None without a bound (0 when the bound is 0)."""
        if self.bound is None:
            return None
        return 0.0 if self.bound <= 0 else max(0.0, (self.bound - self.value) / self.bound)


@dataclass(frozen=True)
class Solver:
    """A solver of a kind: ``solve(problem, cfg, **inputs) -> Result``, `cfg` an instance of `config` (a
    SolverConfig); `inputs` the kind's own solve inputs (a fleet's initial schedule), none by default."""

    name: str
    config: str  # "module:Class"
    solve: str  # "module:function"
    help: str = ""


@dataclass(frozen=True)
class Source:
    """A format a kind imports (``eosp import PATH --out OUT``): `detect(path) -> Detection`,
    `convert(path, out, overwrite) -> str` (the line to print)."""

    what: str
    detect: str  # "module:function"
    convert: str  # "module:function"


@dataclass(frozen=True)
class Generator:
    """How a kind draws problems (``eosp generate [FLAG] ...``): `generate(cfg, out, overwrite) -> str` (the
    line to print), `cfg` an instance of `config`; `flag` selects the kind on the command line (None: the
    default generator)."""

    flag: str | None
    config: str  # "module:Class"
    generate: str  # "module:function"


@dataclass(frozen=True)
class Export:
    """A format a kind writes a schedule in (``eosp export-schedule P S --format NAME``):
    `write(problem, schedule, out, overwrite) -> str` (the line to print)."""

    format: str
    help: str
    write: str  # "module:function"


@runtime_checkable
class ProblemKind(Protocol):
    """What every problem kind offers (see the module docstring).  `read(path, solving=False)` may leave out
    what only solvers need (a fleet's opportunities); `describe` is what ``eosp info`` prints.  The command line
    words and runs a kind through the hooks of :class:`eosp.kinds.base.KindBase`, which a kind subclasses."""

    name: str
    title: str  # what `detect` accepts, in words ("an aeossp fleet directory")
    commands: frozenset[str]  # the commands of ``eosp`` it offers
    solvers: Mapping[str, Solver]
    sources: Sequence[Source]
    generators: Sequence[Generator]
    exports: Mapping[str, Export]

    def detect(self, path: str) -> Detection: ...

    def read(self, path: str, solving: bool = True) -> Any: ...

    def read_schedule(self, path: str, problem: Any) -> Any: ...

    def write_schedule(self, schedule: Any, problem: Any, path: str, overwrite: bool = False,
                       info: dict | None = None) -> Path: ...

    def check(self, problem: Any, schedule: Any) -> Verdict: ...

    def describe(self, problem: Any, path: str) -> str: ...
