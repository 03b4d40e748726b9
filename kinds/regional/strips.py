"""The candidate strips of a case: which grid samples each 5 s piece of each roll's strip covers.

The discretisation (what the solver can choose; the bound is over the same set):

* rolls: per satellite and side, |roll| from the band's inner end (min edge + half the field of view) to its outer
  end (max edge - half the field of view) in steps of `roll_step` fields of view, both ends included; a *track* is one (satellite, signed roll);
* times: starts on the public time grid, durations multiples of it within the sensor's bounds; a strip sampled
  every `coverage_sample_step_s` is a run of consecutive *segments* (the verifier's quadrilaterals between two
  sample instants), so a segment is computed once per track and grid instant and a candidate is a run of them;
* candidates: per track, every start on the time grid whose first step covers a sample, lasting as long as the
  sensor allows but trimmed to its last segment that covers one (a longer strip covers a superset, so the bound
  over these candidates holds for every duration of the same start and roll); a strip that would cross the
  horizon's end is cut to fit.

What it leaves out: rolls between the grid's (a finer `roll_step` adds them), strips whose first step covers
nothing (dominated by the later start), regions crossing the antimeridian (the verifier's longitude/latitude
polygons do not handle them either).  Segments are found only where the band of the side (inner to outer edge)
touches a region's bounding box, so the work follows the regions, not the horizon.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from eosp.regional.geometry import Track, axes, geodetic, hits
from eosp.regional.model import Case


@dataclass
class Strips:
    """Tracks, their segments' coverage (CSR) and the candidates, as arrays."""

    track_sat: np.ndarray  # (T,) satellite of each track
    track_roll: np.ndarray  # (T,) signed roll, degrees
    seg_track: np.ndarray  # (S,) track of each segment
    seg_k: np.ndarray  # (S,) grid index of the segment's first instant
    cov_ptr: np.ndarray  # (S + 1,) CSR over samples
    cov_idx: np.ndarray
    # candidates
    cand_track: np.ndarray  # (C,)
    cand_k: np.ndarray  # (C,) first grid index
    cand_n: np.ndarray  # (C,) segments (duration / sample step)
    cand_seg0: np.ndarray  # (C,) index into `run_seg` where the candidate's segment slots begin
    run_seg: np.ndarray  # per track, one slot per grid index of its span: the segment there or -1
    cand_usable: np.ndarray  # (C,) within the sensor's durations (False: cut by the horizon's end, for the bound)
    step_s: float

    @property
    def start_s(self) -> np.ndarray:
        return self.cand_k * self.step_s

    @property
    def end_s(self) -> np.ndarray:
        return (self.cand_k + self.cand_n) * self.step_s

    def __len__(self) -> int:
        return len(self.cand_track)

    def samples_of(self, c: int) -> np.ndarray:
        """The grid samples candidate `c` covers, sorted."""
        n = int(self.cov_idx.max()) + 1 if len(self.cov_idx) else 0
        buf = np.empty(n, np.int64)
        m = strip_samples(self.cand_seg0[c], self.cand_n[c], self.run_seg, self.cov_ptr, self.cov_idx,
                          np.zeros(n, np.int64), 1, buf)
        return np.sort(buf[:m])


def roll_grid(lo: float, hi: float, step: float) -> np.ndarray:
    """|roll| values from lo to hi in steps of `step`, both ends included."""
    if hi - lo <= 1e-9:
        return np.array([lo])
    n = int(np.ceil((hi - lo) / step - 1e-9))
    return np.linspace(lo, hi, n + 1)


def _boxes(case: Case, pad_deg: float) -> np.ndarray:
    out = []
    for k in range(len(case.regions)):
        m = case.region == k
        out.append((case.lon[m].min() - pad_deg, case.lat[m].min() - pad_deg, case.lon[m].max() + pad_deg,
                    case.lat[m].max() + pad_deg))
    return np.array(out)


def _touching(lon_a, lat_a, lon_b, lat_b, boxes) -> np.ndarray:
    """Grid indices k whose band quadrilateral (points a at k and k+1, points b at k and k+1) meets a box."""
    x = np.stack([lon_a[:-1], lon_a[1:], lon_b[:-1], lon_b[1:]])
    y = np.stack([lat_a[:-1], lat_a[1:], lat_b[:-1], lat_b[1:]])
    x0, x1, y0, y1 = x.min(0), x.max(0), y.min(0), y.max(0)
    ok = (x1 - x0) < 180.0  # a quadrilateral across the antimeridian is not one in longitude/latitude
    hit = np.zeros(len(x0), dtype=bool)
    for bx0, by0, bx1, by1 in boxes:
        hit |= (x0 <= bx1) & (x1 >= bx0) & (y0 <= by1) & (y1 >= by0)
    return np.flatnonzero(hit & ok)


@numba.njit(cache=True)
def strip_samples(seg0, n, run_seg, cov_ptr, cov_idx, stamp, tag, buf):
    """The samples a strip covers (its segments' slots seg0 .. seg0 + n), each once, into `buf`; how many.
    `stamp` marks the samples met under `tag` (a fresh tag per call)."""
    m = 0
    for j in range(seg0, seg0 + n):
        s = run_seg[j]
        if s < 0:
            continue
        for q in range(cov_ptr[s], cov_ptr[s + 1]):
            i = cov_idx[q]
            if stamp[i] != tag:
                stamp[i] = tag
                buf[m] = i
                m += 1
    return m


@numba.njit(cache=True)
def _quad_cover(qx, qy, slon, slat, sorder):
    """For each quadrilateral (q, 4) the sorted-by-longitude samples inside it, boundary included (CSR)."""
    nq = qx.shape[0]
    ptr = np.zeros(nq + 1, np.int64)
    out = np.empty(16, np.int64)
    m = 0
    for q in range(nq):
        x0, x1 = qx[q].min(), qx[q].max()
        y0, y1 = qy[q].min(), qy[q].max()
        lo = np.searchsorted(slon, x0, side="left")
        hi = np.searchsorted(slon, x1, side="right")
        for j in range(lo, hi):
            y = slat[j]
            if y < y0 or y > y1:
                continue
            x = slon[j]
            pos = False
            neg = False
            for e in range(4):
                f = (e + 1) % 4
                cr = (qx[q, f] - qx[q, e]) * (y - qy[q, e]) - (qy[q, f] - qy[q, e]) * (x - qx[q, e])
                if cr > 0:
                    pos = True
                elif cr < 0:
                    neg = True
            if pos and neg:
                continue
            if m == len(out):
                bigger = np.empty(2 * len(out), np.int64)
                bigger[:m] = out[:m]
                out = bigger
            out[m] = sorder[j]
            m += 1
        ptr[q + 1] = m
    return ptr, out[:m]


def build(case: Case, track: Track, roll_step: float = 0.25) -> Strips:
    """The candidate strips of `case` (see the module docstring)."""
    boxes = _boxes(case, pad_deg=0.05)
    order = np.argsort(case.lon, kind="stable")
    slon, slat = case.lon[order], case.lat[order]
    t_sat, t_roll, segs_track, segs_k, ptrs, idxs = [], [], [], [], [np.zeros(1, np.int64)], []
    nseg = 0
    for s, sat in enumerate(case.satellites):
        st = track.states(s)
        nadir, across = axes(st[:, :3], st[:, 3:])
        lo, hi = sat.roll_band
        half = 0.5 * sat.cross_track_fov_deg
        for side in (1.0, -1.0):
            ha, _ = hits(st[:, :3], nadir, across, side * sat.min_edge_off_nadir_deg)
            hb, _ = hits(st[:, :3], nadir, across, side * sat.max_edge_off_nadir_deg)
            lon_a, lat_a = geodetic(ha)
            lon_b, lat_b = geodetic(hb)
            ks = _touching(lon_a, lat_a, lon_b, lat_b, boxes)
            if not len(ks):
                continue
            kk = np.unique(np.r_[ks, ks + 1])
            pos = {int(k): i for i, k in enumerate(kk.tolist())}
            i0 = np.array([pos[int(k)] for k in ks])
            i1 = np.array([pos[int(k) + 1] for k in ks])
            for r in roll_grid(lo, hi, roll_step * sat.cross_track_fov_deg):
                hin, ok_in = hits(st[kk, :3], nadir[kk], across[kk], side * (r - half))
                hout, ok_out = hits(st[kk, :3], nadir[kk], across[kk], side * (r + half))
                good = ok_in[i0] & ok_in[i1] & ok_out[i0] & ok_out[i1]
                xin, yin = geodetic(hin)
                xout, yout = geodetic(hout)
                qx = np.stack([xin[i0], xout[i0], xout[i1], xin[i1]], axis=1)[good]
                qy = np.stack([yin[i0], yout[i0], yout[i1], yin[i1]], axis=1)[good]
                ptr, idx = _quad_cover(np.ascontiguousarray(qx), np.ascontiguousarray(qy), slon, slat, order)
                keep = np.flatnonzero(np.diff(ptr) > 0)
                if not len(keep):
                    continue
                tid = len(t_sat)
                t_sat.append(s)
                t_roll.append(side * r)
                segs_track.append(np.full(len(keep), tid))
                segs_k.append(ks[good][keep])
                sizes = (ptr[keep + 1] - ptr[keep])
                ptrs.append(ptrs[-1][-1] + np.cumsum(sizes))
                idxs.append(np.concatenate([idx[ptr[q]:ptr[q + 1]] for q in keep]))
                nseg += len(keep)
    seg_track = np.concatenate(segs_track) if segs_track else np.zeros(0, np.int64)
    seg_k = np.concatenate(segs_k) if segs_k else np.zeros(0, np.int64)
    cov_ptr = np.concatenate(ptrs)
    cov_idx = np.concatenate(idxs) if idxs else np.zeros(0, np.int64)
    strips = Strips(np.array(t_sat, np.int64), np.array(t_roll), seg_track.astype(np.int64), seg_k.astype(np.int64),
                    cov_ptr.astype(np.int64), cov_idx.astype(np.int64), *_candidates(case, track, seg_track, seg_k,
                                                                                     np.array(t_sat, np.int64)),
                    step_s=float(track.step_s))
    return strips


def _candidates(case: Case, track: Track, seg_track: np.ndarray, seg_k: np.ndarray, t_sat: np.ndarray):
    """(cand_track, cand_k, cand_n, cand_seg0, run_seg, cand_usable): per track, the slots of its span and its
    candidates."""
    per = int(round(case.time_step_s / track.step_s))  # grid instants per public time step
    last_k = track.n - 1
    c_track, c_k, c_n, c_seg0, c_ok, runs = [], [], [], [], [], []
    base = 0
    for t in range(len(t_sat)):
        mine_all = np.flatnonzero(seg_track == t)
        sat = case.satellites[int(t_sat[t])]
        n_max = int(np.floor(sat.max_strip_duration_s / case.time_step_s + 1e-9)) * per
        n_min = max(per, int(np.ceil(sat.min_strip_duration_s / case.time_step_s - 1e-9)) * per)
        if n_max < n_min or n_max <= 0:
            continue
        ks_all = seg_k[mine_all]
        cuts = np.flatnonzero(np.diff(ks_all) > n_max + per) + 1  # one run per pass: no strip spans two
        for mine in np.split(mine_all, cuts):
            ks = seg_k[mine]
            k0 = max(0, (int(ks.min()) - n_max) // per * per)
            k1 = min(last_k, int(ks.max()) + n_max + per)
            run = np.full(k1 - k0 + 1, -1, np.int64)
            run[ks - k0] = mine
            nonempty = run >= 0
            for a in range(k0, k1 - n_min + 1, per):
                if not nonempty[a - k0:a - k0 + per].any():
                    continue
                top = min(a + n_max, last_k)  # the strip's last instant
                inside = np.flatnonzero(nonempty[a - k0:top - k0])
                if not len(inside):
                    continue
                n = int(inside.max()) + 1
                n = min(max(n_min, -(-n // per) * per), (last_k - a) // per * per)  # the horizon cuts it
                if n < per or a + n > k1 + 1:
                    continue
                c_ok.append(n >= n_min)
                c_track.append(t)
                c_k.append(a)
                c_n.append(n)
                c_seg0.append(base + a - k0)
            runs.append(run)
            base += len(run)
    run_seg = np.concatenate(runs) if runs else np.zeros(0, np.int64)
    return (np.array(c_track, np.int64), np.array(c_k, np.int64), np.array(c_n, np.int64),
            np.array(c_seg0, np.int64), run_seg, np.array(c_ok, dtype=bool))
