"""The problem kinds the platform reads, one folder each, and their registry.

A kind is an object satisfying :class:`eosp.problem.ProblemKind` (usually a :class:`eosp.kinds.base.KindBase`);
adding one is a folder under ``kinds/`` and one line in :data:`REGISTRY` (or :func:`register` at run time, as the
tests do).  The command line asks :func:`detect` once which kind a path is, then runs the same command on it.
"""

from __future__ import annotations

from typing import Any

from eosp.errors import InputError
from eosp.problem import Detection, ProblemKind, load

REGISTRY: dict[str, Any] = {  # name -> "module:attribute" of the kind (loaded when first needed), or the kind
    "single-pass": "eosp.kinds.single.kind:KIND",
    "fleet": "eosp.kinds.fleet.kind:KIND",
    "onera": "eosp.kinds.onera.kind:KIND",
    "eosbench": "eosp.kinds.eosbench.kind:KIND",
    "regional-coverage": "eosp.kinds.regional.kind:KIND",
}


def register(kind: Any, name: str | None = None) -> None:
    """Add a kind (an object, or its "module:attribute") under `name` (default: the kind's own name)."""
    REGISTRY[name or kind.name] = kind


def unregister(name: str) -> None:
    REGISTRY.pop(name, None)


def get(name: str) -> ProblemKind:
    """The kind registered as `name` (loaded on first use)."""
    kind = REGISTRY[name]
    if isinstance(kind, str):
        kind = REGISTRY[name] = load(kind)
    return kind


def kinds() -> list[ProblemKind]:
    """Every registered kind, in registry order."""
    return [get(name) for name in list(REGISTRY)]


def offering(command: str) -> ProblemKind:
    """The first kind that offers `command` (the kind of a command line that names no problem)."""
    return next(k for k in kinds() if command in k.commands)


def _refusal(path: str, tried: list[tuple[str, Detection]], what: str) -> InputError:
    reasons = "; ".join(f"{name}: {d.reason}" for name, d in tried)
    return InputError(path, f"not {what} of any kind this eosp reads ({reasons})")


def detect(path: str) -> ProblemKind:
    """The kind whose problem `path` is (the first in registry order that accepts it); an InputError naming
    every kind tried and why it refused otherwise."""
    tried = []
    for kind in kinds():
        d = kind.detect(str(path))
        if d.ok:
            return kind
        tried.append((kind.name, d))
    raise _refusal(str(path), tried, "a problem")


def detect_source(path: str) -> tuple[ProblemKind, Any]:
    """The kind and the import source (:class:`eosp.problem.Source`) that read `path`; an InputError naming every
    source tried and why it refused otherwise."""
    tried = []
    for kind in kinds():
        for src in kind.sources:
            d = load(src.detect)(str(path))
            if d.ok:
                return kind, src
            tried.append((f"{kind.name} ({src.what})", d))
    raise _refusal(str(path), tried, "an import source")


def generator_kind(argv: list[str]) -> tuple[ProblemKind, Any] | None:
    """The kind and generator an ``eosp generate`` command line selects: the one whose flag it gives, else
    the first default generator (None when no kind generates)."""
    default = None
    for kind in kinds():
        for gen in kind.generators:
            if gen.flag is not None and gen.flag in argv:
                return kind, gen
            if gen.flag is None and default is None:
                default = (kind, gen)
    return default
