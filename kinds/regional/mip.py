"""The MIP baseline: budgeted maximum coverage over the candidate strips, solved by HiGHS.

Variables: x_c in {0, 1} per candidate strip; y_a in [0, 1] per *atom*, the grid samples covered by exactly the
same candidates (merged, their values summed: the model's rows shrink from samples to atoms without changing
it).  Maximise sum_a value_a y_a subject to y_a <= sum of x_c over the candidates covering a, sum_c x_c <= B, and
per satellite, for every two of its candidates that cannot both be flown (they overlap, or the later one starts
before the earlier one's end plus the slew time of their roll change plus the settling time), x_c + x_d <= 1;
overlaps are grouped into one row per candidate's start (every candidate in the air then).  The pairwise slew
rows are stronger than the verifier's rule (which tests consecutive strips only), so the model may miss a
schedule a strip between two others would allow: a baseline, not a bound.  The duty limit and the battery are
not rows; the schedule is judged by the checker like every other (the solve says when they broke it).
HiGHS's own dual bound is over this model's candidates with the pairwise rows, so it is reported as
information, not as the kind's bound.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from eosp.config import WEEK_S, ranged
from eosp.kinds.lagrange import quiet_highs
from eosp.regional.check import slew_s
from eosp.kinds.regional.solve import Search, _result, arrays, prepare
from eosp.problem import Result
from eosp.regional.model import Case
from eosp.solvers.base import UtilityConfig


@dataclass
class MipConfig(UtilityConfig):
    """Options of ``eosp solve CASE --solver mip``."""

    time_limit: float | None = ranged(60.0, 0, WEEK_S, lo_open=True, zero_unsets=True)
    roll_step: float = ranged(0.25, 0.05, 2.0)
    """Spacing of the candidate rolls, in fields of view of the satellite's sensor."""

    NAME = "mip"


def atoms(strips, usable: np.ndarray, n_samples: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """(atom of each sample, -1: covered by no usable candidate; the candidates covering each atom)."""
    cands, samples = [], []
    for c in np.flatnonzero(usable).tolist():
        s = strips.samples_of(c)
        cands.append(np.full(len(s), c, np.int64))
        samples.append(s)
    cand = np.concatenate(cands) if cands else np.zeros(0, np.int64)
    samp = np.concatenate(samples) if samples else np.zeros(0, np.int64)
    key = np.random.default_rng(12345).integers(1, 2 ** 62, size=len(usable), dtype=np.int64)
    h = np.zeros(n_samples, np.uint64)
    np.add.at(h, samp, key[cand].astype(np.uint64))
    cnt = np.bincount(samp, minlength=n_samples)
    sig = np.stack([h.astype(np.int64), cnt], axis=1)
    covered = cnt > 0
    uniq, inv = np.unique(sig[covered], axis=0, return_inverse=True)
    atom = np.full(n_samples, -1, np.int64)
    atom[covered] = inv.ravel()
    order = np.argsort(samp, kind="stable")
    first = np.full(len(uniq), -1, np.int64)  # one sample standing for each atom
    idx = np.flatnonzero(covered)
    first[inv.ravel()[::-1]] = idx[::-1]
    by_sample = np.split(cand[order], np.cumsum(np.bincount(samp[order], minlength=n_samples))[:-1])
    return atom, [by_sample[i] for i in first.tolist()]


def solve_mip(case: Case, cfg: MipConfig) -> Result:
    """The MIP baseline (see the module docstring)."""
    import highspy

    t0 = time.perf_counter()
    track, strips, timings = prepare(case, cfg.roll_step)
    search = Search(case, strips, cfg.seed)
    cd, st = arrays(case, strips)
    usable = strips.cand_usable
    cols = np.flatnonzero(usable)
    col_of = np.full(len(usable), -1, np.int64)
    col_of[cols] = np.arange(len(cols))
    atom, members = atoms(strips, usable, len(case.lon))
    v = case.sample_value()
    na = len(members)
    val = np.bincount(atom[atom >= 0], weights=v[atom >= 0], minlength=na)
    h = quiet_highs()
    h.setOptionValue("threads", 1)
    h.setOptionValue("mip_rel_gap", 0.0)  # HiGHS stops at a 1e-4 relative gap by default: ties matter here
    h.setOptionValue("mip_abs_gap", 1e-12)
    inf = highspy.kHighsInf
    nx = len(cols)
    h.addVars(nx, np.zeros(nx), np.ones(nx))
    h.changeColsIntegrality(nx, np.arange(nx, dtype=np.int32), np.full(nx, highspy.HighsVarType.kInteger))
    # a strip costs 1e-7 (the benchmark ranks fewer actions after coverage; a sample is worth > 1e-6 of it)
    h.changeColsCost(nx, np.arange(nx, dtype=np.int32), np.full(nx, 1e-7))
    h.addVars(na, np.zeros(na), np.ones(na))
    h.changeColsCost(na, np.arange(nx, nx + na, dtype=np.int32), -val)
    for a in range(na):  # y_a - sum x_c <= 0
        idx = np.r_[nx + a, col_of[members[a]]].astype(np.int32)
        h.addRow(-inf, 0.0, len(idx), idx, np.r_[1.0, -np.ones(len(members[a]))])
    B = case.max_actions if case.max_actions is not None else nx
    h.addRow(-inf, float(B), nx, np.arange(nx, dtype=np.int32), np.ones(nx))
    rows = 0
    for s in range(len(case.satellites)):
        mine = cols[cd.sat[cols] == s]
        if not len(mine):
            continue
        mine = mine[np.argsort(cd.start[mine], kind="stable")]
        a, b, r = cd.start[mine], cd.end[mine], cd.roll[mine]
        for i in range(len(mine)):  # every candidate in the air at this one's start: one row
            air = np.flatnonzero((a <= a[i]) & (b > a[i]))
            if len(air) > 1:
                h.addRow(-inf, 1.0, len(air), col_of[mine[air]].astype(np.int32), np.ones(len(air)))
                rows += 1
        reach = st.settle[s] + slew_s(180.0, st.rate[s], st.acc[s])
        for i in range(len(mine)):  # later starts too soon after this one's end for the slew
            later = np.flatnonzero((a >= b[i]) & (a < b[i] + reach))
            for j in later.tolist():
                if a[j] - b[i] < slew_s(r[j] - r[i], st.rate[s], st.acc[s]) + st.settle[s]:
                    h.addRow(-inf, 1.0, 2, col_of[[mine[i], mine[j]]].astype(np.int32), np.ones(2))
                    rows += 1
    timings["model"] = time.perf_counter() - t0 - timings["candidates"]
    left = (cfg.time_limit or 0.0) - (time.perf_counter() - t0) - 0.5 if cfg.time_limit else None
    if left is not None:
        h.setOptionValue("time_limit", max(0.1, left))
    # a start: the greedy's strips (HiGHS keeps it when nothing better is found in time)
    search.fill()
    start = np.zeros(nx + na)
    start[col_of[np.flatnonzero(search.chosen)]] = 1.0
    cov = np.zeros(len(case.lon), bool)
    for c in np.flatnonzero(search.chosen).tolist():
        cov[strips.samples_of(c)] = True
    start[nx:] = np.bincount(atom[cov & (atom >= 0)], minlength=na) > 0
    sol = highspy.HighsSolution()
    sol.col_value = start.tolist()
    sol.value_valid = True
    h.setSolution(sol)
    t = time.perf_counter()
    h.run()
    timings["mip"] = time.perf_counter() - t
    x = np.asarray(h.getSolution().col_value[:nx]) > 0.5
    if x.any():
        chosen = np.zeros(len(usable), bool)
        chosen[cols[x]] = True
        search.set(chosen)
    info = h.getInfo()
    dual = -float(info.mip_dual_bound) if np.isfinite(info.mip_dual_bound) else None
    return _result(case, track, search, timings, None,
                   {"atoms": na, "conflict_rows": rows, "highs_status": h.modelStatusToString(h.getModelStatus()),
                    "highs_dual_bound": dual})
