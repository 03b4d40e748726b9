"""A proven upper bound for ONERA instances: a time-capacity LP relaxation, tightened by cutting planes.

Relaxation (every integer plan is a point of it, so its optimum bounds the best plan):

* a column per observation of a one-shot, video or periodic request (value: its class), per stereo pair
  (value: its two classes) and per periodic request (value: 0.5 x its slots, i.e. a max gap of 0);
  all in [0, 1];
* a request is served at most once (one-shot, video: one observation; stereo: one pair); a periodic
  slot holds at most one observation and the periodic column is at most the sum of its observations;
* time capacity of a satellite over an interval [a, b] of at most ``L`` seconds: the parts of the chosen
  observations' executions that must lie in [a, b] (an execution stays in its window: at least
  ``d - (a - ws)+ - (we - b)+`` of it), plus, for an observation whose window is inside [a, b], the least
  transition ``mt`` that can lead into it, plus the same least overlaps of the mandatory downloads, fit
  in ``b - a`` (plus the largest ``mt`` of the interval: the first activity's transition may lie before a).

Intervals are added by separation: after each LP solve the most violated intervals between the window
starts and ends of the chosen observations are added, until none is violated or the round or time cap
is hit.  The bound is certified from the LP duals y >= 0 of the last solve (weak duality:
``b.y + sum_j max(0, c_j - A_j.y)``), so it does not depend on the LP solver's tolerances.
"""

from __future__ import annotations

import time

import numpy as np

from eosp.onera.model import PERIODIC, PERIODIC_ALPHA, STEREO, OneraFleet, transition

L_MAX = 1200.0  # longest capacity interval (s)


def _min_transitions(f: OneraFleet) -> np.ndarray:
    """Per observation, the least transition from any activity that can precede it within L_MAX."""
    o, d = f.observations, f.downloads
    mt = np.full(len(o), 90.0)
    kind = f.requests.kind[o.request]
    for s in range(len(f.satellites)):
        orow = np.flatnonzero(o.satellite == s)
        drow = np.flatnonzero(d.satellite == s)
        ws = np.r_[o.start[orow], d.start[drow]].astype(np.float64)
        we = np.r_[o.end[orow], d.end[drow]].astype(np.float64)
        lat, lon = np.r_[o.lat[orow], d.lat[drow]], np.r_[o.lon[orow], d.lon[drow]]
        req = np.r_[o.request[orow], np.full(len(drow), -1)]
        order = np.argsort(ws, kind="stable")
        ws_s = ws[order]
        for i, g in enumerate(orow.tolist()):
            lo, hi = np.searchsorted(ws_s, [ws[i] - L_MAX - 300, we[i]])
            cand = order[lo:hi]
            cand = cand[(cand != i) & (we[cand] > ws[i] - L_MAX) & (ws[cand] < we[i])]
            if kind[g] in (STEREO, PERIODIC):  # two observations of one request (a pair, two slots) may follow
                tau = transition(lat[i], lon[i], lat[cand], lon[cand], same_request=req[cand] == req[i])
            else:  # one observation per request: the predecessor is of another request
                cand = cand[req[cand] != req[i]]
                tau = transition(lat[i], lon[i], lat[cand], lon[cand])
            mt[g] = tau.min() if len(tau) else 0.0
    return mt


def incompatible(o, rows_a: np.ndarray, rows_b: np.ndarray) -> np.ndarray:
    """Matrix: observation rows_a[i] and rows_b[j] of `o` (one satellite's) fit in neither order (same request:
    False)."""
    ws_a, ws_b = o.start[rows_a][:, None], o.start[rows_b][None, :]
    ls_a = (o.end[rows_a] - o.duration[rows_a])[:, None]
    ls_b = (o.end[rows_b] - o.duration[rows_b])[None, :]
    same = o.request[rows_a][:, None] == o.request[rows_b][None, :]
    tau = np.where(same, 0.0, transition(o.lat[rows_a][:, None], o.lon[rows_a][:, None], o.lat[rows_b][None, :],
                                         o.lon[rows_b][None, :]))
    a_first = ws_a + o.duration[rows_a][:, None] + tau <= ls_b
    b_first = ws_b + o.duration[rows_b][None, :] + tau <= ls_a
    return ~(a_first | b_first) & ~same


class _Model:
    def __init__(self, f: OneraFleet):
        o, r = f.observations, f.requests
        self.f = f
        kind = r.kind[o.request]
        n_obs = len(o)
        col = np.full(n_obs, -1, np.int64)
        c: list[float] = []
        rows_i, rows_j, rows_v, rhs = [], [], [], []  # static rows
        row = 0
        # one-shot / video / periodic observations: a column each
        plain = np.flatnonzero(kind != STEREO)
        col[plain] = np.arange(len(plain))
        c += o.value[plain].tolist()
        nxt = len(plain)
        # stereo pairs: one column for both images
        st = np.flatnonzero(kind == STEREO)
        key = o.request[st].astype(np.int64) * (1 << 32) + o.slot[st]
        uk, inv = np.unique(key, return_inverse=True)
        col[st] = nxt + inv
        pv = np.zeros(len(uk))
        np.add.at(pv, inv, o.value[st])
        c += pv.tolist()
        pair_req = (uk >> 32).astype(np.int64)
        nxt += len(uk)
        # periodic requests: the 0.5 x slots column
        per = np.flatnonzero(r.kind == PERIODIC)
        zcol = nxt + np.arange(len(per))
        nslots = np.array([len(f.slots(k)) for k in per.tolist()], dtype=np.float64)
        c += (PERIODIC_ALPHA * nslots).tolist()
        nxt += len(per)
        self.n_col = nxt
        self.c = np.asarray(c)
        # at most once: one-shot / video requests
        for k in np.flatnonzero(r.kind < STEREO).tolist():
            cols = col[r.first[k]:r.first[k + 1]]
            rows_i += [row] * len(cols)
            rows_j += cols.tolist()
            rows_v += [1.0] * len(cols)
            rhs.append(1.0)
            row += 1
        # stereo: one pair
        for k in np.unique(pair_req).tolist():
            cols = nxt_cols = np.flatnonzero(pair_req == k) + len(plain)
            rows_i += [row] * len(nxt_cols)
            rows_j += cols.tolist()
            rows_v += [1.0] * len(cols)
            rhs.append(1.0)
            row += 1
        # periodic: one per slot; z <= sum x
        for zi, k in enumerate(per.tolist()):
            a, b = r.first[k], r.first[k + 1]
            slots = o.slot[a:b]
            for sl in np.unique(slots).tolist():
                cols = col[a:b][slots == sl]
                rows_i += [row] * len(cols)
                rows_j += cols.tolist()
                rows_v += [1.0] * len(cols)
                rhs.append(1.0)
                row += 1
            # N z <= sum_k (N - k) x(slot k): the bonus 0.5 (N - max gap) is at most 0.5 (N - k) when k is
            # the first served slot (the leading run of unserved slots is a gap)
            uniq = np.unique(slots)
            n_sl = len(uniq)
            rank = np.searchsorted(uniq, slots)
            rows_i += [row] * (b - a + 1)
            rows_j += [int(zcol[zi])] + col[a:b].tolist()
            rows_v += [float(n_sl)] + (-(n_sl - rank)).astype(np.float64).tolist()
            rhs.append(0.0)
            row += 1
        self.static = (np.asarray(rows_i), np.asarray(rows_j), np.asarray(rows_v), np.asarray(rhs), row)
        self.col = col
        self.mt = _min_transitions(f)
        # per satellite: observations by window start, downloads
        self.sat_obs = []
        for s in range(len(f.satellites)):
            rows = np.flatnonzero(o.satellite == s)
            self.sat_obs.append(rows[np.argsort(o.start[rows], kind="stable")])
        d = f.downloads
        self.sat_dl = [np.flatnonzero(d.satellite == s) for s in range(len(f.satellites))]
        self.cuts: list[tuple[np.ndarray, np.ndarray, float]] = []
        self.cut_keys: set = set()

    def download_load(self, s: int, a: np.ndarray | float, b: np.ndarray | float) -> np.ndarray:
        d = self.f.downloads
        rows = self.sat_dl[s]
        a, b = np.atleast_1d(np.asarray(a, np.float64)), np.atleast_1d(np.asarray(b, np.float64))
        dur = d.duration[rows][None, :]
        ov = dur - np.maximum(0, a[:, None] - d.start[rows][None, :]) - np.maximum(0, d.end[rows][None, :] - b[:, None])
        return np.maximum(ov, 0).sum(axis=1)

    def cut(self, s: int, a: float, b: float):
        """The capacity row of satellite `s` over [a, b]: (columns, coefficients, right-hand side)."""
        o = self.f.observations
        rows = self.sat_obs[s]
        hi = np.searchsorted(o.start[rows], b, side="left")
        rows = rows[:hi]
        rows = rows[o.end[rows] > a]
        d = o.duration[rows].astype(np.float64)
        ov = d - np.maximum(0, a - o.start[rows]) - np.maximum(0, o.end[rows] - b)
        inside = (o.start[rows] >= a) & (o.end[rows] <= b)
        coef = np.maximum(ov, 0) + np.where(inside, self.mt[rows], 0.0)
        keep = coef > 0
        cols, coef = self.col[rows[keep]], coef[keep]
        uc, inv = np.unique(cols, return_inverse=True)
        agg = np.zeros(len(uc))
        np.add.at(agg, inv, coef)
        extra = self.mt[rows[inside]].max() if inside.any() else 0.0
        rhs = (b - a) - float(self.download_load(s, a, b)[0]) + extra
        return uc, agg, rhs

    def initial_cuts(self, widths=(300.0, 450.0, 600.0, 900.0, 1200.0)) -> None:
        """Capacity rows over a tiling of each satellite's busy time at widths from a window length up (step: a quarter of the
        width), keeping only the rows whose load can exceed their capacity."""
        o = self.f.observations
        for s in range(len(self.f.satellites)):
            rows = self.sat_obs[s]
            if not len(rows):
                continue
            busy = np.unique(np.floor(o.start[rows] / 60.0))
            for w in widths:
                step = w / 4
                starts = np.unique(np.concatenate([np.arange(b * 60 - w, b * 60 + 60, step) for b in busy]))
                starts = np.floor(starts / step) * step
                for a in np.unique(starts).tolist():
                    cols, coef, rhs = self.cut(s, a, a + w)
                    if len(cols) and coef.sum() > rhs + 1e-6:
                        self.cuts.append((cols, coef, rhs))
                        self.cut_keys.add((s, a, a + w))

    def separate(self, x: np.ndarray, per_sat: int = 40) -> int:
        """Add the most violated capacity intervals of each satellite for the LP point `x`; how many."""
        o = self.f.observations
        added = 0
        for s in range(len(self.f.satellites)):
            rows = self.sat_obs[s]
            xv = x[self.col[rows]]
            rows = rows[xv > 1e-7]
            if not len(rows):
                continue
            xv = x[self.col[rows]]
            ws, we = o.start[rows].astype(np.float64), o.end[rows].astype(np.float64)
            load = xv * (o.duration[rows] + self.mt[rows])
            found = []
            ends = np.unique(we)
            for a in np.unique(ws).tolist():
                sel = ws >= a
                bs = ends[(ends > a) & (ends <= a + L_MAX)]
                if not len(bs):
                    continue
                w_sel, l_sel = we[sel], load[sel]
                order = np.argsort(w_sel)
                cum = np.r_[0.0, np.cumsum(l_sel[order])]
                dem = cum[np.searchsorted(w_sel[order], bs, side="right")]
                viol = dem + self.download_load(s, a, bs) - (bs - a)  # a candidate: its cut is checked exactly below
                k = int(np.argmax(viol))
                if viol[k] > 1e-6:
                    found.append((viol[k], a, float(bs[k])))
            found.sort(reverse=True)
            for _, a, b in found[:per_sat]:
                if (s, a, b) in self.cut_keys:
                    continue
                cols, coef, rhs = self.cut(s, a, b)
                if float(coef @ x[cols]) > rhs + 1e-6:
                    self.cuts.append((cols, coef, rhs))
                    self.cut_keys.add((s, a, b))
                    added += 1
        return added

    def separate_cliques(self, x: np.ndarray, per_sat: int = 60) -> int:
        """Add violated clique rows (observations of one satellite pairwise impossible together: at most
        one of them), grown greedily from the LP point's observations and lifted with the others."""
        o = self.f.observations
        added = 0
        for s in range(len(self.f.satellites)):
            allrows = self.sat_obs[s]
            xv_all = x[self.col[allrows]]
            pos = allrows[xv_all > 1e-7]
            if len(pos) < 2:
                continue
            xv = x[self.col[pos]]
            inc = incompatible(o, pos, pos)
            found = []
            for i in np.argsort(-xv).tolist():
                members = [i]
                cand = inc[i].copy()
                while cand.any():
                    j = int(np.flatnonzero(cand)[np.argmax(xv[cand])])
                    members.append(j)
                    cand &= inc[j]
                tot = float(xv[members].sum())
                if tot > 1 + 1e-6:
                    key = tuple(sorted(int(pos[m]) for m in members))
                    if key not in self.cut_keys:
                        self.cut_keys.add(key)
                        found.append((tot, key))
            found.sort(reverse=True)
            starts = o.start[allrows]
            for _, key in found[:per_sat]:
                mem = np.asarray(key)
                lo, hi = np.searchsorted(starts, [o.start[mem].min() - 400, o.end[mem].max()])
                others = allrows[lo:hi]
                others = others[~np.isin(others, mem)]
                if len(others):
                    lift = others[incompatible(o, mem, others).all(axis=0)]
                    mem = np.r_[mem, lift[np.argsort(-x[self.col[lift]])]]
                    # keep the lifted set a clique: add one at a time
                    keep = list(range(len(key)))
                    for t in range(len(key), len(mem)):
                        if incompatible(o, mem[keep], mem[t:t + 1]).all():
                            keep.append(t)
                    mem = mem[keep]
                cols = np.unique(self.col[mem])
                self.cuts.append((cols, np.ones(len(cols)), 1.0))
                added += 1
        return added

    def fits(self, rows: np.ndarray, s: int) -> bool:
        """Can observations `rows` of satellite `s` all be done, with the downloads whose windows are near them
        (mandatory, so always there)?  Depth-first over orders, real-valued starts."""
        o, d = self.f.observations, self.f.downloads
        lo, hi = o.start[rows].min() - 400, o.end[rows].max() + 400
        dl = self.sat_dl[s]
        dl = dl[(d.end[dl] > lo) & (d.start[dl] < hi)]
        ws = np.r_[o.start[rows], d.start[dl]].astype(np.float64).tolist()
        dur = np.r_[o.duration[rows].astype(np.float64), d.duration[dl]].tolist()
        ls = (np.r_[o.end[rows], d.end[dl]] - np.asarray(dur)).tolist()
        lat, lon = np.r_[o.lat[rows], d.lat[dl]], np.r_[o.lon[rows], d.lon[dl]]
        req = np.r_[o.request[rows], -1 - np.arange(len(dl))]
        tau = transition(lat[:, None], lon[:, None], lat[None, :], lon[None, :],
                         same_request=req[:, None] == req[None, :]).tolist()
        n = len(ws)

        def dfs(done: int, last: int, t: float) -> bool:
            if done == (1 << n) - 1:
                return True
            for i in range(n):
                if not done >> i & 1 and ls[i] < t - 1e-9:
                    return False  # an activity left can no longer start
            for i in sorted((i for i in range(n) if not done >> i & 1), key=lambda i: ws[i]):
                st = ws[i] if last < 0 else max(ws[i], t + tau[last][i])
                if st <= ls[i] + 1e-9 and dfs(done | 1 << i, i, st + dur[i]):
                    return True
            return False

        return dfs(0, -1, -1e18)

    def separate_nogoods(self, x: np.ndarray, k_max: int = 6, per_sat: int = 80) -> int:
        """Add ``sum x <= |S| - 1`` for runs S of consecutive (by window start) chosen observations of one
        satellite that cannot all be done (with the mandatory downloads) while the LP point takes them all."""
        o = self.f.observations
        added = 0
        for s in range(len(self.f.satellites)):
            rows = self.sat_obs[s]
            rows = rows[x[self.col[rows]] > 1e-7]
            xv = x[self.col[rows]]
            n_add = 0
            for i in range(len(rows)):
                for k in range(2, k_max + 1):
                    if i + k > len(rows) or n_add >= per_sat:
                        break
                    S = rows[i:i + k]
                    if o.start[S[-1]] - o.end[S[0]] > 300:
                        break
                    if xv[i:i + k].sum() <= k - 1 + 1e-6:
                        continue
                    key = ("ng", *S.tolist())
                    if key in self.cut_keys or self.fits(S, s):
                        continue
                    self.cut_keys.add(key)
                    cols, inv = np.unique(self.col[S], return_inverse=True)
                    self.cuts.append((cols, np.bincount(inv).astype(np.float64), float(k - 1)))
                    n_add += 1
                    break
            added += n_add
        return added

    def matrix(self):
        from scipy.sparse import csr_matrix

        ri, rj, rv, rhs, n = self.static
        ci = [ri] + [np.full(len(cols), n + k) for k, (cols, _, _) in enumerate(self.cuts)]
        cj = [rj] + [cols for cols, _, _ in self.cuts]
        cv = [rv] + [coef for _, coef, _ in self.cuts]
        b = np.r_[rhs, [r for _, _, r in self.cuts]]
        A = csr_matrix((np.concatenate(cv), (np.concatenate(ci), np.concatenate(cj))),
                       shape=(n + len(self.cuts), self.n_col))
        return A, b


def certified(A, b: np.ndarray, c: np.ndarray, y: np.ndarray) -> float:
    """Weak-duality bound of max c.x, A x <= b, 0 <= x <= 1 from any multipliers y (clipped at 0)."""
    y = np.maximum(y, 0.0)
    return float(b @ y + np.maximum(c - A.T @ y, 0.0).sum())


def lp_bound(f: OneraFleet, rounds: int = 40, time_limit: float = 60.0, info: dict | None = None,
             finish_first: bool = False) -> float:
    """The certified LP bound (see the module's docstring), within `time_limit` seconds (but for the model's build);
    `finish_first`: the first solve runs to its end whatever the limit (benchmarks/bench_onera.py's bound: the
    tightest one, at its price in time)."""
    from scipy.optimize import linprog

    t0 = time.perf_counter()
    m = _Model(f)
    m.initial_cuts()
    best = float("inf")
    n_rounds = 0
    for n_rounds in range(1, rounds + 1):
        A, b = m.matrix()
        # every solve within the time limit (the caller's time limit covers the bound): one cut short keeps the
        # last finished round's bound, or the conflict-free bound when none finished
        left = time_limit - (time.perf_counter() - t0)
        if left <= 0 and not (finish_first and n_rounds == 1):
            break
        if finish_first:  # the benchmark's rule: the first solve to its end, a later one at least 5 s
            options = {} if n_rounds == 1 else {"time_limit": max(5.0, left)}
        else:
            options = {"time_limit": left}
        res = linprog(-m.c, A_ub=A, b_ub=b, bounds=(0, 1), method="highs", options=options)
        if res.status != 0:
            break
        y = -np.asarray(res.ineqlin.marginals)
        best = min(best, certified(A, b, m.c, y))
        if time.perf_counter() - t0 > time_limit:
            break
        if not (m.separate(res.x) + m.separate_cliques(res.x) + m.separate_nogoods(res.x)):
            break
    if info is not None:
        info.update(rounds=n_rounds, cuts=len(m.cuts), seconds=time.perf_counter() - t0)
    if not np.isfinite(best):  # no LP solve finished: the conflict-free bound is still proven
        from eosp.onera.check import best_values

        best = float(best_values(f).sum())
    return best
