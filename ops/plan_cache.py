"""Ground plans recorded once, replayed many times: what an onboard chooser's training rollouts fly.

A file per (scenario, realization), ``.npz`` of plain arrays (read with ``allow_pickle=False``): each planning
call's primaries and candidates (with their primaries) and compute, the passes' start times the simulation ran
with, and a JSON description (scenario, realization, planner, compute budget, candidates per primary) so that a
replay is the recorded run's world and uploads.  :class:`eosp.ops.simulate.Replayed` answers the calls from it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eosp.atomic import atomic_path
from eosp.errors import InputError
from eosp.ops.simulate import Plan

FORMAT = "eosp-plan-cache"


@dataclass
class Recorded:
    """One realization's recorded plans (call -> :class:`Plan`), the pass starts and the description."""

    answers: dict[int, Plan]
    pass_start: np.ndarray
    meta: dict


def write(path: str | Path, answers: list[tuple[int, Plan]], pass_start: np.ndarray, meta: dict) -> Path:
    """Write a recording (atomically: a file is whole or absent)."""
    arrays = {"pass_start": np.asarray(pass_start, dtype=np.float64),
              "meta": np.array(json.dumps({"format": FORMAT, **meta})),
              "calls": np.array([c for c, _ in answers], dtype=np.int64),
              "compute_s": np.array([p.compute_s for _, p in answers], dtype=np.float64)}
    for c, p in answers:
        arrays[f"rows_{c}"] = np.asarray(p.rows, dtype=np.int64)
        arrays[f"alt_{c}"] = np.asarray(p.alternates, dtype=np.int64)
        arrays[f"alt_of_{c}"] = np.asarray(p.alternate_of, dtype=np.int64)
    path = Path(path)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)
    return path


def read(path: str | Path) -> Recorded:
    """A recording; one line naming the file for anything that is not one."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("format") != FORMAT:
                raise ValueError(f"format {meta.get('format')!r}, not {FORMAT!r}")
            answers = {int(c): Plan(z[f"rows_{c}"], float(s), {}, z[f"alt_{c}"], z[f"alt_of_{c}"])
                       for c, s in zip(z["calls"].tolist(), z["compute_s"].tolist())}
            return Recorded(answers, z["pass_start"].copy(), meta)
    except FileNotFoundError:
        raise InputError(path, "no such plan recording") from None
    except (OSError, ValueError, KeyError) as e:
        raise InputError(path, f"not a plan recording ({e})") from None
