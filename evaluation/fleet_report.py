"""A planner's view of a constellation day: one self-contained, offline HTML page for fleet schedules.

Sections, top to bottom:

* a summary per schedule (the checker's verdict and metrics, observations) and, with two or more,
  what differs from the first: tasks only one of them serves, observations per satellite;
* a Gantt chart, one row per satellite over the horizon in UTC: observations (bars), slews and
  settling before each (thin bars), eclipses (grey band; sunlit is the pale band), the battery
  charge as a line across the row (0 at its bottom, the capacity at its top) and each checker
  violation as a red mark; a menu picks the schedule drawn;
* a world map zoomed to the targets: coastlines, each satellite's ground track, every target
  coloured by status (observed: green, missed: red), hover naming who observed it and when, or
  why it was missed;
* a sortable, paged table of every task: window, weight, who observed it when, or its reason
  (:mod:`eosp.fleet.reasons`, for the first schedule when the checker accepts it);
* a summary per satellite (observations, busy time, lowest charge, time in eclipse) and per weight
  (tasks, observed, missed by reason).

Scale: everything is drawn on canvases by a small inline script from one JSON block (no plotly:
its SVG bars are too slow at 20,000 observations).  Tracks are sampled every
:data:`TRACK_STEP_S` seconds, coarser when the fleet is large (:func:`track_step`), battery curves
are reduced to the minimum and maximum of each pixel-wide time bin, and the task table is
rendered a page at a time: 200 satellites and 20,000 tasks give a page of a few MB that a
headless Chromium draws in about a second (docs/results.md).

What cannot be drawn is said on the page: a fleet whose orbits do not propagate gets no tracks,
sunlight, battery or reasons (and no checker verdict); a fleet without ground stations has no
downloads to draw.
"""

from __future__ import annotations

import html
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from eosp.atomic import atomic_path
from eosp.fleet.model import US, Fleet, Schedule, iso_z
from eosp.ownership import check_output, html_mark

REPORT_KIND = "report"
PAGE = ("One self-contained HTML page of a constellation day: Gantt per satellite (UTC), map with tracks and "
        "targets, every task with the reason it was missed, summaries, differences.")  # eosp report's description
TRACK_STEP_S = 60
MAX_TRACK_POINTS = 400_000  # over all satellites
BATTERY_BINS = 700
MAX_LISTED = 1000  # violations listed in words per schedule


@dataclass
class View:
    """One schedule on the page: its label, the checker's verdict, and what is drawn of it."""

    label: str
    schedule: Schedule
    info: dict = field(default_factory=dict)  # how it was made: the schedule file's metadata (provenance_cells)
    valid: bool | None = None  # None: not checked (no geometry)
    metrics: dict = field(default_factory=dict)
    violations: list = field(default_factory=list)


def track_step(geo, n_sat: int) -> int:
    """Seconds between track samples: :data:`TRACK_STEP_S`, coarser when all tracks would exceed
    :data:`MAX_TRACK_POINTS` points."""
    per = MAX_TRACK_POINTS / max(1, n_sat)
    step = TRACK_STEP_S
    while geo.fleet.horizon.seconds / step > per:
        step *= 2
    return step


def _r(v, nd: int) -> list:
    """Rounded floats for JSON (NaN -> None)."""
    a = np.round(np.asarray(v, dtype=np.float64), nd)
    out = a.tolist()
    if np.isnan(a).any():
        out = [None if x != x else x for x in out]
    return out


def _geometry(fleet: Fleet):
    """The fleet's geometry, or why its orbits cannot be propagated."""
    from eosp.fleet.geometry import Geometry

    try:
        geo = Geometry(fleet)
        for k in range(len(fleet.satellites)):
            pos = geo.grid_positions(k)
            if not np.isfinite(pos).all():
                raise ValueError(f"satellite {fleet.satellites.ids[k]}: propagation gives non-finite positions")
        return geo, None
    except Exception as exc:  # noqa: BLE001 - brahe raises its own types for bad TLEs; the page says why
        return None, f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}".rstrip(": ")


def _slews(fleet: Fleet, los, sched_idx: tuple) -> np.ndarray:
    """Slew + settling start of each observation (s), from the one before on its satellite (nadir first)."""
    sat, task, st, en = sched_idx
    out = np.full(len(st), np.nan)
    for k in np.unique(sat[sat >= 0]).tolist():
        m = np.flatnonzero(sat == k)
        m = m[np.argsort(st[m], kind="stable")]
        l0 = los.los(k, task[m], st[m])
        l1 = los.los(k, task[m], en[m])
        frm = np.concatenate([los.nadir(k, st[m[:1]]), l1[:-1]]) if len(m) else l1
        out[m] = st[m] - los.need_s(k, frm, l0)
    return out


def _battery(fleet: Fleet, sun, los, k: int, st: np.ndarray, en: np.ndarray, need0: np.ndarray):
    """(times s, charge Wh) of satellite k's battery, min and max per time bin."""
    from eosp.fleet.battery import Intervals
    from eosp.fleet.battery import levels

    o = np.argsort(st, kind="stable")
    s_us = np.round(st[o] * US).astype(np.int64)
    e_us = np.round(en[o] * US).astype(np.int64)
    w_us = np.round(need0[o] * US).astype(np.int64)
    ends, lv = levels(fleet, sun, k, Intervals(s_us, e_us), Intervals(np.minimum(w_us, s_us), s_us))
    h = fleet.horizon.seconds
    b = np.minimum((ends / US / h * BATTERY_BINS).astype(np.int64), BATTERY_BINS - 1)
    first = np.r_[True, b[1:] != b[:-1]]
    idx = np.flatnonzero(first)
    lo, hi = np.minimum.reduceat(lv, idx), np.maximum.reduceat(lv, idx)
    t = (b[idx] + 0.5) * h / BATTERY_BINS
    tt = np.r_[0.0, np.repeat(t, 2)]
    vv = np.r_[float(fleet.satellites.battery.initial_wh[k]), np.column_stack([hi, lo]).ravel()]
    return tt, vv, float(lv.min()) if len(lv) else float(fleet.satellites.battery.initial_wh[k])


def build_data(fleet: Fleet, opps, views: list[View], name: str = "") -> tuple[dict, list[str]]:
    """Everything the page draws, as JSON-ready arrays, and the notes on what could not be drawn."""
    from eosp.fleet.check import validate

    notes = []
    h, tk, sats = fleet.horizon, fleet.tasks, fleet.satellites
    n_sat = len(sats)
    si, ti = fleet.satellite_index(), fleet.task_index()
    geo, why = _geometry(fleet)
    if geo is None:
        notes.append(f"The orbits of this fleet cannot be propagated ({why}): no ground tracks, sunlight, battery "
                     "curves, slews, checker verdicts or reasons are drawn; the observations, targets and the task "
                     "table are.")
    if not any(k in fleet.extras for k in ("stations", "ground_stations", "downloads")):
        notes.append("This fleet has no ground stations, so there are no downloads to draw.")
    data: dict = {"name": name, "start": iso_z(h.start), "seconds": h.seconds, "sats": sats.ids.tolist(),
                  "sensor": sats.sensor.tolist(), "capacity": _r(sats.battery.capacity_wh, 3),
                  "tasks": {"id": tk.ids.tolist(), "lat": _r(tk.lat_deg, 4), "lon": _r(tk.lon_deg, 4),
                            "w": _r(tk.weight, 4), "rel": _r(tk.release_s, 1), "due": _r(tk.due_s, 1),
                            "dur": _r(tk.duration_s, 1), "sensor": tk.sensor.tolist()},
                  "views": [], "kinds": []}
    los = sun = None
    if geo is not None:
        from eosp.fleet.battery import SunCache
        from eosp.fleet.slew import LineOfSight
        from eosp.fleet.tracks import eclipses, ground_track, sample_times

        los, sun = LineOfSight(fleet, geo), SunCache(geo)
        t_s = sample_times(geo, track_step(geo, n_sat))
        tr, ecl = [], []
        for k in range(n_sat):
            lat, lon, _ = ground_track(geo, k, t_s)
            tr.append([_r(lat, 2), _r(lon, 2)])
            e0, e1 = eclipses(sun, k, sample_times(geo, 30))
            ecl.append([_r(e0, 0), _r(e1, 0)])
        data.update(track_t=_r(t_s, 0), tracks=tr, eclipses=ecl)
    for v_i, v in enumerate(views):
        s = v.schedule
        sat = np.asarray([si.get(x, -1) for x in s.satellite.tolist()], dtype=np.int64)
        task = np.asarray([ti.get(x, -1) for x in s.task.tolist()], dtype=np.int64)
        st, en = s.start_us / US, s.end_us / US
        vd: dict = {"label": v.label, "sat": sat.tolist(), "task": task.tolist(), "st": _r(st, 3), "en": _r(en, 3)}
        if geo is not None:
            res = validate(fleet, s, geo)
            v.valid, v.metrics, v.violations = res.valid, res.metrics, list(res.violations)
            ok = (sat >= 0) & (task >= 0)
            slew0 = np.full(len(s), np.nan)
            if ok.any():
                slew0[ok] = _slews(fleet, los, (sat[ok], task[ok], st[ok], en[ok]))
            vd["slew"] = _r(slew0, 3)
            bat, low = [], []
            for k in range(n_sat):
                m = np.flatnonzero((sat == k) & ok)
                tt, vv, lo = _battery(fleet, sun, los, k, st[m], en[m], slew0[m])
                bat.append([_r(tt, 0), _r(vv, 3)])
                low.append(round(lo, 3))
            vd["battery"], vd["low"] = bat, low
            vd["viol"] = [[si.get(x.satellite, -1), None if x.time is None else
                           round((x.time - h.start).total_seconds(), 3), str(x)] for x in v.violations]
        vd["valid"], vd["metrics"] = v.valid, v.metrics
        data["views"].append(vd)
        if v_i == 0:
            data["reasons"] = _reasons(fleet, opps, v, geo, los, sun, notes)
    return data, notes


def _reasons(fleet, opps, v: View, geo, los, sun, notes: list) -> dict | None:
    from eosp.fleet.reasons import KINDS, explain

    if geo is None:
        return None
    if opps is None:
        notes.append("The fleet's opportunities were not given, so missed tasks get no reasons.")
        return None
    if not v.valid:
        notes.append(f"{v.label} is not valid (each violation is marked on the Gantt chart), so its missed tasks get "
                     "no reasons: insertion is judged against a valid timeline.")
        return None
    r = explain(fleet, opps, v.schedule, geo, los, sun)
    return {"kinds": list(KINDS), "task": r.task.tolist(), "kind": r.kind.tolist(), "sat": r.satellite.tolist(),
            "st": _r(r.start_s, 1), "blk": [[int(b) for b in row if b >= 0] for row in r.blockers],
            "cand": r.candidates.tolist()}


# what a schedule file says of how it was made (written at solve time, docs/formats.md): the page's columns
PROVENANCE = (("solver", "solver"), ("time_limit", "time limit (s)"), ("rounds", "rounds"),
              ("warm_start", "warm start"), ("bound", "bound"), ("gap", "gap"))
_PROVENANCE_HEAD = "".join(f"<th>{h}</th>" for _, h in PROVENANCE)


def schedule_info(metadata: dict) -> dict:
    """A schedule file's metadata (text values, each written as JSON) as values; what is not JSON stays text."""
    out = {}
    for k, v in metadata.items():
        try:
            out[k] = json.loads(v)
        except (TypeError, ValueError):
            out[k] = v
    return out


def provenance_cells(info: dict) -> str:
    """The summary's cells of how a schedule was made: solver, its time limit, rounds, warm start, bound and gap
    ("-" where the file does not say: a schedule written by another tool, or a solver without that notion)."""
    def cell(key: str) -> str:
        x = info.get(key)
        if x is None or x == "":
            return "<td class='na'>-</td>"
        if key == "gap" and isinstance(x, (int, float)):
            text = f"{x:.2%}"
        elif key == "bound" and isinstance(x, float):
            text = f"{x:.6f}"
        elif key == "time_limit" and isinstance(x, (int, float)):
            text = f"{x:g}"
        else:
            text = str(x)
        return f"<td data-k='{key}'>{html.escape(text)}</td>"
    return "".join(cell(k) for k, _ in PROVENANCE)


def _summary(views: list[View]) -> str:
    rows = []
    for v in views:
        m = v.metrics or {}
        verdict = ("<span class='na'>not checked</span>" if v.valid is None else "<span class='ok'>valid</span>"
                   if v.valid else f"<span class='bad'>invalid: {len(v.violations)} violation(s); first: "
                                   f"{html.escape(str(v.violations[0]))}</span>")

        def f(k, nd=6):
            x = m.get(k)
            return "-" if x is None or v.valid is None else f"{x:.{nd}f}"
        rows.append(f"<tr data-schedule='{html.escape(v.label, quote=True)}' data-valid='{str(v.valid).lower()}'>"
                    f"<td>{html.escape(v.label)}</td><td>{len(v.schedule)}</td><td>{f('WCR')}</td><td>{f('CR')}</td>"
                    f"<td>{f('TAT', 1)}</td><td>{f('PC', 1)}</td>{provenance_cells(v.info)}<td>{verdict}</td></tr>")
    lists = []
    for v in views:  # every violation in words (the Gantt marks those with a satellite and a time)
        if v.violations:
            items = "".join(f"<li>{html.escape(str(x))}</li>" for x in v.violations[:MAX_LISTED])
            more = f"<li>... and {len(v.violations) - MAX_LISTED} more</li>" if len(v.violations) > MAX_LISTED else ""
            lists.append(f"<details class='violations' data-schedule='{html.escape(v.label, quote=True)}' "
                         f"data-count='{len(v.violations)}'><summary>{html.escape(v.label)}: {len(v.violations)} "
                         f"violation(s)</summary><ol>{items}{more}</ol></details>")
    return ("<table class='summary'><thead><tr><th>schedule</th><th>observations</th><th>WCR</th><th>CR</th>"
            f"<th>TAT (s)</th><th>PC (Wh)</th>{_PROVENANCE_HEAD}<th>checker</th></tr></thead><tbody>" + "".join(rows) +
            "</tbody></table>" + "".join(lists))


def build_page(fleet: Fleet, opps, schedules: dict[str, Schedule], title: str | None = None,
               infos: dict[str, dict] | None = None, appendix: str = "") -> str:
    """The page as one HTML string (self-contained: the script, the data and the coastlines inline); `infos`: each
    schedule's metadata by label (:func:`schedule_info`), for the summary's solver, time limit, bound and gap;
    `appendix`: sections of the page's own after the fleet's (a simulated day's replay,
    :mod:`eosp.evaluation.replay_page`)."""
    views = [View(label, s, (infos or {}).get(label, {})) for label, s in schedules.items()]
    title = title or f"{fleet.case_id or 'fleet'}: a constellation day"
    data, notes = build_data(fleet, opps, views, title)
    h = fleet.horizon
    meta = (f"{len(fleet.satellites)} satellites, {len(fleet.tasks)} tasks, horizon {iso_z(h.start)} to "
            f"{iso_z(h.end)} (UTC); {len(views)} schedule(s), checked by the fleet checker")
    return _page(data, notes, _summary(views), title, meta, fleet.tasks.lat_deg, fleet.tasks.lon_deg, appendix)


def _page(data: dict, notes: list[str], summary: str, title: str, meta: str, lat, lon, appendix: str = "") -> str:
    from importlib.resources import files

    script = files("eosp.evaluation").joinpath("fleet_page.js").read_text(encoding="utf-8")
    from eosp.evaluation.html_report import coastlines, lon_origin, map_extent, wrap_lon

    clon, clat = coastlines()
    data["coast"] = [_r(clon, 2), _r(clat, 2)]
    west = lon_origin(lon) if len(lon) else -180.0
    (x0, x1), (y0, y1) = map_extent(wrap_lon(lon, west), lat) if len(lon) else ((-180.0, 180.0), (-90.0, 90.0))
    data["map"] = {"west": west, "x": [x0, x1], "y": [y0, y1]}
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    note_html = "".join(f"<p class='note'>{html.escape(n)}</p>" for n in notes)
    return ("<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>" + html_mark(REPORT_KIND) +
            f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head>\n"
            f"<body data-satellites='{len(data['sats'])}' data-tasks='{len(data['tasks']['id'])}' "
            f"data-schedules='{len(data['views'])}'>\n<h1>{html.escape(title)}</h1><p class='meta'>{meta}</p>"
            f"{note_html}\n{summary}<div id='diff'></div>\n{_BODY}\n"
            f"<script type='application/json' id='fleet-data'>{payload}</script>\n<script>{script}</script>\n"
            f"{appendix}</body></html>\n")


# --------------------------------------------------------------------------- ONERA fleets (no orbits, downloads)

def build_onera_page(f, schedules: dict, title: str | None = None, infos: dict[str, dict] | None = None) -> str:
    """The page of an ONERA fleet (:mod:`eosp.onera.model`): a task row per request (at its first observation's
    target, worth its best value alone, its kind as the group), observations and the mandatory downloads on
    the Gantt with the transition before each, no tracks, sunlight, battery or reasons (the instances have no
    orbits); times are seconds since 0 h, as the instances give them."""
    from eosp.onera.model import KIND_SHORT, activity_durations, transition
    from eosp.onera.check import best_values, request_values, validate

    o, d, r = f.observations, f.downloads, f.requests
    first = r.first[:-1]
    has = r.first[1:] > first
    fo = np.where(has, first, 0)
    rel = np.asarray([o.start[a:b].min() if b > a else 0 for a, b in zip(r.first[:-1], r.first[1:])], dtype=float)
    due = np.asarray([o.end[a:b].max() if b > a else 0 for a, b in zip(r.first[:-1], r.first[1:])], dtype=float)
    horizon = float(max(o.end.max() if len(o) else 0, d.end.max() if len(d) else 0, 1))
    kinds = [KIND_SHORT[k] for k in r.kind.tolist()]
    data: dict = {"name": title or "", "start": "1970-01-01T00:00:00Z", "relative": True, "seconds": horizon,
                  "sats": [str(x) for x in f.satellites.tolist()], "sensor": ["-"] * len(f.satellites),
                  "capacity": None, "views": [], "reasons": None,
                  "tasks": {"id": [str(x) for x in r.id.tolist()], "lat": _r(o.lat[fo], 4), "lon": _r(o.lon[fo], 4),
                            "w": _r(best_values(f), 4), "rel": _r(rel, 0), "due": _r(due, 0),
                            "dur": _r(o.duration[fo], 0), "sensor": kinds},
                  "groups": {"name": "request kind", "of": kinds}}
    obs_pos = {int(x): i for i, x in enumerate(o.id.tolist())}
    dl_pos = {int(x): i for i, x in enumerate(d.id.tolist())}
    sat_pos = {int(x): i for i, x in enumerate(f.satellites.tolist())}
    rows = []
    for label, s in schedules.items():
        res = validate(f, s)
        act = s.activity.astype(np.int64)
        dur = activity_durations(f, act)
        sat = np.asarray([sat_pos.get(int(x), -1) for x in s.satellite.tolist()], dtype=np.int64)
        oi = np.asarray([obs_pos.get(int(a), -1) for a in act.tolist()], dtype=np.int64)
        di = np.asarray([dl_pos.get(int(a), -1) for a in act.tolist()], dtype=np.int64)
        st = s.start.astype(np.float64)
        en = st + np.nan_to_num(dur)
        lat = np.where(oi >= 0, o.lat[np.maximum(oi, 0)], d.lat[np.maximum(di, 0)] if len(d) else 0.0)
        lon = np.where(oi >= 0, o.lon[np.maximum(oi, 0)], d.lon[np.maximum(di, 0)] if len(d) else 0.0)
        req = np.where(oi >= 0, o.request[np.maximum(oi, 0)], -1)
        slew = np.full(len(s), np.nan)  # the transition before each activity, from the one before on its satellite
        for k in np.unique(sat[sat >= 0]).tolist():
            m = np.flatnonzero(sat == k)
            m = m[np.argsort(st[m], kind="stable")]
            if len(m) > 1:
                a, b = m[:-1], m[1:]
                slew[b] = st[b] - transition(lat[a], lon[a], lat[b], lon[b], (req[a] == req[b]) & (req[a] >= 0))
        is_obs = oi >= 0
        vd = {"label": label, "sat": sat[is_obs].tolist(), "task": req[is_obs].tolist(), "st": _r(st[is_obs], 3),
              "en": _r(en[is_obs], 3), "slew": _r(slew[is_obs], 3), "valid": res.valid,
              "metrics": {"value": res.value}, "viol": [],
              "dl": {"sat": sat[di >= 0].tolist(), "st": _r(st[di >= 0], 3), "en": _r(en[di >= 0], 3),
                     "id": act[di >= 0].tolist(), "slew": _r(slew[di >= 0], 3)}}
        why, val = request_values(f, oi[is_obs])
        if why is None:
            vd["credit"] = (val > 0).tolist()  # a request counts only when its rules are met (stereo pairs, ...)
        data["views"].append(vd)
        verdict = ("<span class='ok'>valid</span>" if res.valid else
                   f"<span class='bad'>invalid: {html.escape(str(res.first))}</span>")
        served = ", ".join(f"{k} {v}" for k, v in res.served.items()) if res.valid else "-"
        rows.append(f"<tr data-schedule='{html.escape(label, quote=True)}' data-valid='{str(res.valid).lower()}'>"
                    f"<td>{html.escape(label)}</td><td>{int(is_obs.sum())}</td><td>{int((di >= 0).sum())}</td>"
                    f"<td>{res.value:.4f}</td><td>{served}</td>{provenance_cells((infos or {}).get(label, {}))}"
                    f"<td>{verdict}</td></tr>")
    summary = ("<table class='summary'><thead><tr><th>schedule</th><th>observations</th><th>downloads</th>"
               f"<th>value</th><th>requests served by kind</th>{_PROVENANCE_HEAD}<th>checker</th></tr></thead><tbody>"
               + "".join(rows) +
               "</tbody></table>")
    notes = ["ONERA instances have no orbits (a satellite is an id; each observation carries its own window): no "
             "ground tracks, sunlight or battery are drawn, and missed requests get no reasons (the insertion "
             "procedure needs the orbit and attitude model of aeossp fleets).  Times are seconds since 0 h, as the "
             "instance gives them; thin bars are the transitions (min(angular distance, 90) s) before each "
             "activity; a checker violation is named in the summary (the ONERA checker names the first)."]
    title = title or f"{f.name or 'ONERA fleet'}: a constellation day"
    meta = (f"{len(f.satellites)} satellites, {len(r)} requests ({len(o)} observations), {len(d)} mandatory "
            f"downloads; {len(schedules)} schedule(s), checked by the ONERA checker")
    return _page(data, notes, summary, title, meta, o.lat[fo], o.lon[fo])


def check_report_out(out, overwrite: bool = False) -> Path:
    return check_output(out, REPORT_KIND, overwrite, suffixes=(".html", ".htm"))


def write_page(fleet, opps, schedules: dict, out, overwrite: bool = False, title: str | None = None,
               infos: dict[str, dict] | None = None) -> Path:
    """Build the page (of an aeossp fleet, or of an ONERA fleet when `opps` is None and `fleet` is one) and
    write it atomically; an existing page is replaced only when eosp wrote it and `overwrite` is given."""
    out = check_report_out(out, overwrite)
    text = build_page(fleet, opps, schedules, title, infos) if isinstance(fleet, Fleet) else \
        build_onera_page(fleet, schedules, title, infos)
    with atomic_path(out, suffix=".html") as tmp:
        tmp.write_text(text, encoding="utf-8")
    return out


def report_page(fleet, opps, schedules: dict, out: str, ns, t0: float) -> str:
    """`eosp report` of a constellation day (an aeossp or an ONERA fleet): `schedules` by label, each a
    (schedule, the file's metadata) pair; the page written, and the command's line.  `t0`: when the command
    started reading."""
    import time

    scheds = {label: s for label, (s, _) in schedules.items()}
    infos = {label: schedule_info(md) for label, (_, md) in schedules.items()}
    page = write_page(fleet, opps, scheds, out, overwrite=ns.overwrite, title=ns.title or None, infos=infos)
    n_tasks = len(fleet.tasks) if hasattr(fleet, "tasks") else len(fleet.requests)
    return (f"{page}: {len(schedules)} schedule(s) of {len(fleet.satellites)} satellites and {n_tasks} tasks "
            f"({page.stat().st_size / 1e6:.1f} MB, {time.perf_counter() - t0:.1f} s)")


_STYLE = """
body { font-family: system-ui, -apple-system, 'Segoe UI', sans-serif; margin: 20px; color: #222; }
h1 { font-size: 1.4em; margin-bottom: 0.2em; } h2 { font-size: 1.1em; margin-top: 28px; }
p.meta { color: #555; margin-top: 0; }
p.note { background: #fff7e0; border-left: 4px solid #e6a700; padding: 6px 10px; }
table { border-collapse: collapse; margin: 10px 0 20px; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 3px 7px; text-align: right; }
td:first-child, th:first-child { text-align: left; } td.reason, th[data-k='reason'] { text-align: left; }
td.status, th[data-k='status'], table.summary td:last-child { text-align: left; }
th { background: #f0f0f0; } th.sort { cursor: pointer; } th.sort:hover { background: #e2e8f0; }
.ok { color: #1a7f37; font-weight: 600; } .bad { color: #c62828; font-weight: 600; } .na { color: #777; }
#tip { position: fixed; pointer-events: none; background: rgba(255,255,255,0.96); border: 1px solid #888;
  padding: 4px 7px; font-size: 12px; display: none; max-width: 520px; z-index: 10; white-space: pre-line; }
.wrap { overflow-x: auto; } canvas { display: block; }
.legend span { display: inline-block; margin-right: 14px; font-size: 0.85em; }
.legend i { display: inline-block; width: 14px; height: 9px; margin-right: 4px; vertical-align: middle; }
"""

_BODY = """
<h2>Gantt: what each satellite does when (UTC)</h2>
<p>Schedule drawn: <select id='view'></select> <small>(drag across the chart to zoom in time, double-click to see
the whole horizon)</small></p>
<p class='legend'><span><i style='background:#1f77b4'></i>observation</span><span><i style='background:#ff9f1c'>
</i>slew and settling (transition)</span><span><i style='background:#9467bd'></i>download</span><span><i style='background:#d9d9d9'></i>eclipse</span><span><i style='background:#fffbe6;
border:1px solid #ddd'></i>sunlit</span><span><i style='background:#2ca02c;height:2px'></i>battery (0 to capacity)
</span><span><i style='background:#e00000'></i>checker violation</span></p>
<section id='gantt-section'><div class='wrap'><canvas id='gantt'></canvas></div></section>
<h2>Map: ground tracks and targets by status</h2>
<p class='legend'><span><i style='background:#2ca02c'></i>observed</span><span><i style='background:#d62728'></i>
missed</span><span><i style='background:rgba(31,119,180,0.5);height:2px'></i>ground track</span></p>
<section id='map-section'><canvas id='map'></canvas></section>
<h2>Tasks</h2>
<p><label><input type='checkbox' id='only-missed'> missed only</label> <span id='pager'></span></p>
<section id='tasks-section'><table id='tasks'><thead><tr><th class='sort' data-k='id'>task</th>
<th class='sort' data-k='w'>weight</th><th class='sort' data-k='rel'>window (UTC)</th>
<th class='sort' data-k='status'>status</th><th class='sort' data-k='reason'>reason</th></tr></thead><tbody></tbody>
</table></section>
<h2>Per satellite</h2><section id='sat-section'><table id='per-sat'></table></section>
<h2>Per weight</h2><section id='weight-section'><table id='per-weight'></table></section>
<div id='tip'></div>
"""

