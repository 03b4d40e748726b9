"""What each plan sends besides its primaries for the satellites' own decisions (:mod:`eosp.ops.onboard`):
alternates after a primary (the onboard rule), replacements in its place (the rule that looks ahead, and the
candidates a chooser picks among), and the onboard test of the problem's fleet."""

from __future__ import annotations

import numpy as np

from eosp.kinds.fleet.problem import Problem


def _times(prob: Problem) -> tuple[np.ndarray, np.ndarray]:
    """Each opportunity's start and end (seconds from the horizon's start)."""
    o = prob.opps
    start = o.start.astype(np.float64) * float(prob.fleet.horizon.action_step_s)
    return start, start + prob.fleet.tasks.duration_s[o.task]


def _open_candidates(prob: Problem, rows: np.ndarray, frozen: np.ndarray, value: np.ndarray, taken: np.ndarray):
    """For each satellite with primaries (`rows`) in passes the plan may change: (satellite, its primaries in time
    order, its opportunities worth something (`value` > 0) in those passes of a task not `taken`, the primaries'
    timeline, where each candidate would go in it).  `taken` is read per satellite: what the caller marks taken
    while it handles one satellite is no candidate of the next."""
    from eosp.fleet.timeline import Arrays, timeline

    o, los = prob.opps, prob.los
    start, end = _times(prob)
    task = o.task.astype(np.int64)
    live = ~frozen[o.pass_id] & (value > 0)
    for k in np.unique(o.satellite[rows[~frozen[o.pass_id[rows]]]]).tolist():
        mine = rows[o.satellite[rows] == k]
        mine = mine[np.lexsort((end[mine], start[mine]))]
        cand = np.flatnonzero(live & (o.satellite == k) & ~taken[task])
        if not len(cand):
            continue
        tl = Arrays.of(timeline(los, k, task[mine], start[mine], end[mine]))
        yield k, mine, cand, tl, np.searchsorted(tl.start, start[cand], side="right")


def alternates(prob: Problem, rows: np.ndarray, frozen: np.ndarray, value: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Alternates for the onboard rule (:func:`eosp.ops.simulate.execute`) of a plan's primaries `rows` in the
    passes it may change (not `frozen`): after each primary, the most valuable opportunity (`value`, per
    opportunity; 0: never) of the same satellite and pass that fits between it and the next primary (the slew and
    settling from it and to the next, no overlap: the checker's rules, :func:`eosp.fleet.timeline.fits`), of a
    task no primary holds and no other alternate took; then, per satellite, alternates dropped from the least
    valuable until its battery holds with all of them.  Why one per gap: taken or not, every sequence the
    satellite can then fly (a primary, perhaps its alternate, the next primary) is one the checker accepts, and
    with every alternate in, the battery held on the ground.  Returns the alternates and their primaries."""
    from eosp.fleet.battery import SunCache
    from eosp.fleet.battery import simulate as battery
    from eosp.fleet.timeline import Candidates, fits, intervals, timeline

    o, los = prob.opps, prob.los
    start, end = _times(prob)
    task = o.task.astype(np.int64)
    sun = prob.sun or SunCache(prob.geo)
    taken = np.zeros(len(prob.weight), dtype=bool)
    taken[task[rows]] = True
    out_alt, out_of = [], []
    for k, mine, cand, tl, pos in _open_candidates(prob, rows, frozen, value, taken):
        prev = mine[np.maximum(pos - 1, 0)]
        ok = (pos > 0) & (o.pass_id[prev] == o.pass_id[cand]) & ~frozen[o.pass_id[prev]]
        cand, pos, prev = cand[ok], pos[ok], prev[ok]
        if not len(cand):
            continue
        c = Candidates(start[cand], end[cand], los.los(k, task[cand], start[cand]), los.los(k, task[cand], end[cand]))
        ok = fits(los, k, tl, c, pos)
        cand, prev = cand[ok], prev[ok]
        got: dict[int, int] = {}
        for i in np.argsort(-value[cand], kind="stable").tolist():  # the most valuable first, one per gap and task
            if prev[i] not in got and not taken[task[cand[i]]]:
                got[int(prev[i])] = int(cand[i])
                taken[task[cand[i]]] = True
        alt = sorted(got.items(), key=lambda kv: value[kv[1]])  # the least valuable first: dropped first
        while alt:
            both = np.concatenate([mine, [a for _, a in alt]])
            both = both[np.lexsort((end[both], start[both]))]
            tlb = timeline(los, k, task[both], start[both], end[both])
            if battery(prob.fleet, sun, k, *intervals(los, tlb, k)).ok:
                break
            alt = alt[1:]
        out_of += [p for p, _ in alt]
        out_alt += [a for _, a in alt]
    return np.asarray(out_alt, dtype=np.int64), np.asarray(out_of, dtype=np.int64)


def onboard_test(prob: Problem, slews: bool = False):
    """The onboard test of the problem's fleet (:func:`eosp.ops.onboard.fly_test`)."""
    from eosp.fleet.battery import SunCache
    from eosp.ops.onboard import fly_test

    return fly_test(prob.fleet, prob.opps, prob.los, prob.sun or SunCache(prob.geo), slews)


def replacements(prob: Problem, rows: np.ndarray, frozen: np.ndarray, value: np.ndarray,
                 per_primary: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Replacements for the onboard rule that looks ahead (:class:`eosp.ops.onboard.Onboard`) of a plan's
    primaries `rows` in the passes it may change (not `frozen`): for each primary, the most valuable opportunity
    (`value`, per opportunity; 0: never) of the same satellite and pass that fits in its place, between the
    primaries before and after it (slews and settling, no overlap: :func:`eosp.fleet.timeline.fits` with the
    primary removed), of a task no primary holds and no other replacement took.  With `per_primary` > 1, up to
    that many per primary, the most valuable first, each of another task and each row for one primary (a task
    may then be a candidate of several primaries: the satellite's chooser decides).  The battery is the satellite's to test when it decides
    (a replacement changes the slews around it).  Returns the replacements and their primaries, each primary's
    in the order sent."""
    from eosp.fleet.timeline import Candidates, fits

    o, los = prob.opps, prob.los
    start, end = _times(prob)
    task = o.task.astype(np.int64)
    taken = np.zeros(len(prob.weight), dtype=bool)
    taken[task[rows]] = True
    out_alt, out_of = [], []
    for k, mine, cand, tl, pos in _open_candidates(prob, rows, frozen, value, taken):
        c = Candidates(start[cand], end[cand], los.los(k, task[cand], start[cand]), los.los(k, task[cand], end[cand]))
        # the primary replaced: the one after the insertion point (b=1) or the one before it (a=1)
        got: dict[int, list[int]] = {}
        used: set[int] = set()
        for a, b, at in ((0, 1, pos), (1, 0, pos - 1)):
            inside = (at >= 0) & (at < len(mine))
            prim = mine[np.clip(at, 0, len(mine) - 1)]
            ok = inside & (o.pass_id[prim] == o.pass_id[cand]) & ~frozen[o.pass_id[prim]]
            ok &= fits(los, k, tl, c, pos, a, b)
            for i in np.flatnonzero(ok)[np.argsort(-value[cand[ok]], kind="stable")].tolist():
                p_, r_ = int(prim[i]), int(cand[i])
                if per_primary > 1:  # each row for one primary (the ground reads a taken row's primary back)
                    have = got.setdefault(p_, [])
                    if r_ not in used and task[r_] not in task[have] and len(have) < per_primary:
                        have.append(r_)
                        used.add(r_)
                elif not taken[task[r_]] and (p_ not in got or value[r_] > value[got[p_][0]]):
                    if p_ in got:
                        taken[task[got[p_][0]]] = False
                    got[p_] = [r_]
                    taken[task[r_]] = True
        for p_, have in got.items():
            have = sorted(have, key=lambda r_: -value[r_])
            out_of += [p_] * len(have)
            out_alt += have
    return np.asarray(out_alt, dtype=np.int64), np.asarray(out_of, dtype=np.int64)
