"""The checker of ONERA plans: names the first violated rule, and scores a valid plan.

Rules (docs/formats.md, "ONERA"), in the order they are checked:

1. every activity id is an observation or download of the fleet, on its own satellite, at most once;
2. each activity starts in ``[window_start, window_end - duration]``;
3. every download is scheduled (downloads are mandatory);
4. one activity at a time per satellite: the next start is ``>= start + duration + tau``
   (tau of :func:`eosp.onera.model.transition`);
5. request rules: one-shot and video at most one observation; stereo none or both images of one pair;
   periodic at most one observation per time slot.

The value of a plan is the sum over satisfied requests: one-shot the class, video 4 x class, stereo the
two classes, periodic the classes plus ``0.5 x (slots - max gap)``, where, as in the authors' code
(EOSSP ``PeriodicRequest.scoreActivityList``), the max gap is the longest run of unserved slots that
is followed by a served slot (a trailing run is not counted).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eosp.onera.model import (KIND_SHORT, ONE_SHOT, PERIODIC, PERIODIC_ALPHA, STEREO, VIDEO, OneraFleet,
                              OneraSchedule, transition)
from eosp.problem import Verdict

EPS = 1e-6  # seconds: transitions are irrational, starts are integers


@dataclass
class Result:
    valid: bool
    first: str | None = None
    value: float = 0.0
    served: dict = field(default_factory=dict)  # kind name -> requests satisfied
    value_by_kind: dict = field(default_factory=dict)

    def verdict(self) -> Verdict:
        """The contract's verdict (:class:`eosp.problem.Verdict`): the value and the requests served by request
        kind (zero when invalid), with the line ``eosp validate`` prints."""
        metrics = {"value": self.value, **{k: self.served.get(k, 0) for k in KIND_SHORT}}
        if not self.valid:
            return Verdict(False, metrics, self.first, f"invalid: {self.first}")
        served = ", ".join(f"{k} {v}" for k, v in self.served.items())
        return Verdict(True, metrics, None, f"valid: value {self.value!r}; served {served}")


def periodic_value(classes_by_slot: np.ndarray, served: np.ndarray) -> float:
    """Value of a periodic request: `classes_by_slot[k]` is the class of the observation served in the
    request's k-th slot (slots in increasing order), `served[k]` whether one is; 0 when none is."""
    if not served.any():
        return 0.0
    max_gap, gap = 0, 0
    for s in served.tolist():
        if s:
            max_gap, gap = max(max_gap, gap), 0
        else:
            gap += 1
    return float(classes_by_slot[served].sum()) + PERIODIC_ALPHA * (len(served) - max_gap)


def request_values(f: OneraFleet, sel: np.ndarray) -> tuple[str | None, np.ndarray]:
    """(first request-rule violation or None, value per request) for the observation rows `sel`."""
    o, r = f.observations, f.requests
    n = len(r)
    val = np.zeros(n)
    req = o.request[sel]
    count = np.bincount(req, minlength=n)
    np.add.at(val, req, o.value[sel])
    kind = r.kind
    bad = np.flatnonzero(((kind == ONE_SHOT) | (kind == VIDEO)) & (count > 1))
    if len(bad):
        k = bad[0]
        return f"{KIND_SHORT[kind[k]]} request {r.id[k]} has {count[k]} observations (at most 1)", val
    st = np.flatnonzero((kind == STEREO) & (count > 0))
    for k in st.tolist():
        rows = sel[req == k]
        if len(rows) != 2 or o.slot[rows[0]] != o.slot[rows[1]]:
            return (f"stereo request {r.id[k]} has observations {o.id[rows].tolist()}: expected none or both "
                    "images of one pair"), val
    for k in np.flatnonzero((kind == PERIODIC) & (count > 0)).tolist():
        rows = sel[req == k]
        slots = o.slot[rows]
        if len(np.unique(slots)) != len(slots):
            return f"periodic request {r.id[k]} has two observations in one time slot", val
        all_slots = f.slots(k)
        served = np.isin(all_slots, slots)
        classes = np.zeros(len(all_slots))
        classes[np.searchsorted(all_slots, slots)] = o.value[rows]
        val[k] = periodic_value(classes, served)
    return None, val


def validate(f: OneraFleet, s: OneraSchedule) -> Result:
    """Check plan `s` against fleet `f`; the first violation in words, else the value and requests served."""
    o, d = f.observations, f.downloads
    n_obs = len(o)
    ids = np.concatenate([o.id, d.id])
    order = np.argsort(ids)
    act = np.asarray(s.activity, dtype=np.int64)
    pos = np.minimum(np.searchsorted(ids[order], act), len(ids) - 1)
    known = ids[order][pos] == act
    if not known.all():
        k = int(np.flatnonzero(~known)[0])
        return Result(False, f"row {k}: activity {act[k]} is not an observation or download of this fleet")
    row = order[pos]  # < n_obs: observation row; else download row + n_obs
    srt = np.sort(row)
    dup = np.flatnonzero(np.diff(srt) == 0)
    if len(dup):
        return Result(False, f"activity {ids[srt[dup[0]]]} is scheduled twice")
    is_obs = row < n_obs
    orow, drow = row[is_obs], row[~is_obs] - n_obs
    sat = np.empty(len(row), np.int64)
    sat[is_obs], sat[~is_obs] = f.satellites[o.satellite[orow]], f.satellites[d.satellite[drow]]
    bad = np.flatnonzero(sat != s.satellite)
    if len(bad):
        k = bad[0]
        return Result(False, f"row {k}: activity {act[k]} belongs to satellite {sat[k]}, not {s.satellite[k]}")
    ws, we, dur = (np.empty(len(row)) for _ in range(3))
    ws[is_obs], we[is_obs], dur[is_obs] = o.start[orow], o.end[orow], o.duration[orow]
    ws[~is_obs], we[~is_obs], dur[~is_obs] = d.start[drow], d.end[drow], d.duration[drow]
    start = np.asarray(s.start, dtype=np.float64)
    bad = np.flatnonzero((start < ws) | (start + dur > we + EPS))
    if len(bad):
        k = bad[0]
        return Result(False, f"activity {act[k]} starts at {start[k]:g}: outside [{ws[k]:g}, {we[k] - dur[k]:g}] "
                             f"(window [{ws[k]:g}, {we[k]:g}], duration {dur[k]:g})")
    missing = np.setdiff1d(np.arange(len(d)), drow)
    if len(missing):
        return Result(False, f"download {d.id[missing[0]]} (satellite {f.satellites[d.satellite[missing[0]]]}) is "
                             f"not scheduled: downloads are mandatory ({len(missing)} missing)")
    lat, lon, req = np.empty(len(row)), np.empty(len(row)), np.full(len(row), -1, np.int64)
    lat[is_obs], lon[is_obs], req[is_obs] = o.lat[orow], o.lon[orow], o.request[orow]
    lat[~is_obs], lon[~is_obs] = d.lat[drow], d.lon[drow]
    seq = np.lexsort((start, sat))
    a, b = seq[:-1], seq[1:]
    same_sat = sat[a] == sat[b]
    tau = transition(lat[a], lon[a], lat[b], lon[b], same_request=(req[a] == req[b]) & (req[a] >= 0))
    gap = start[b] - (start[a] + dur[a] + tau)
    bad = np.flatnonzero(same_sat & (gap < -EPS))
    if len(bad):
        i, j = a[bad[0]], b[bad[0]]
        return Result(False, f"satellite {sat[i]}: activity {act[j]} starts at {start[j]:g}, before the end of "
                             f"activity {act[i]} ({start[i] + dur[i]:g}) plus the transition {tau[bad[0]]:.3f} s")
    why, val = request_values(f, orow)
    if why is not None:
        return Result(False, why)
    return Result(True, None, float(val.sum()), *served_by_kind(f, val))


def served_by_kind(f: OneraFleet, val: np.ndarray) -> tuple[dict, dict]:
    kind = f.requests.kind
    served = {KIND_SHORT[k]: int(((kind == k) & (val > 0)).sum()) for k in range(4)}
    value = {KIND_SHORT[k]: float(val[kind == k].sum()) for k in range(4)}
    return served, value


def best_values(f: OneraFleet) -> np.ndarray:
    """Per request, the most it can be worth alone (every slot or pair at its best observation): the
    conflict-free upper bound is the sum."""
    o, r = f.observations, f.requests
    n = len(r)
    best = np.zeros(n)
    key = o.request.astype(np.int64) * (1 << 32) + o.slot.astype(np.int64)
    uk, inv = np.unique(key, return_inverse=True)
    per_slot_max = np.zeros(len(uk))
    np.maximum.at(per_slot_max, inv, o.value)
    per_slot_sum = np.zeros(len(uk))
    np.add.at(per_slot_sum, inv, o.value)
    slot_req = (uk >> 32).astype(np.int64)
    kind = r.kind[slot_req]
    # one-shot / video: best observation; stereo: best pair (sum of its two); periodic: sum of slot bests
    np.maximum.at(best, slot_req[(kind == ONE_SHOT) | (kind == VIDEO)], per_slot_max[(kind == ONE_SHOT) | (kind == VIDEO)])
    np.maximum.at(best, slot_req[kind == STEREO], per_slot_sum[kind == STEREO])
    per = kind == PERIODIC
    np.add.at(best, slot_req[per], per_slot_max[per])
    n_slots = np.bincount(slot_req[per], minlength=n)
    best += PERIODIC_ALPHA * n_slots * (r.kind == PERIODIC)
    return best
