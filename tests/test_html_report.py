"""The planner's HTML report: contents, bad input, and rendering in a real headless browser."""

import dataclasses
import html.parser
import subprocess
import sys

import numpy as np
import pytest

from eosp.errors import InputError
from eosp.evaluation.html_report import (build_report, coastlines, exact, ground_track, lon_origin, map_extent,
                                          missed_reasons, wrap_lon, write_report)
from eosp.planning.insertion import earliest_path, first_insertion
from eosp.instances.interchange import write_instance
from eosp.instances.schedule import Schedule, check, from_internal_nodes, write_schedule
from eosp.solvers.greedy import solve as greedy
from eosp.solvers.random_walk import RandomConfig
from eosp.solvers.random_walk import solve as random_walk
from tests.conftest import generated
from tests.synthetic import synthetic_instance


class Resources(html.parser.HTMLParser):
    """Every URL a tag of the page would load (script/img/iframe src, link href, ...)."""

    def __init__(self):
        super().__init__()
        self.urls, self.scripts = [], 0

    def handle_starttag(self, tag, attrs):
        self.scripts += tag == "script"
        for k, v in attrs:
            if k in ("src", "href", "data", "poster", "srcset") and v:
                self.urls.append(v)


def resources(text: str) -> Resources:
    p = Resources()
    p.feed(text)
    return p


def infeasible(inst, sched: Schedule) -> Schedule:
    """The same rows with the first two swapped: every row still names this instance's nodes."""
    order = np.r_[1, 0, np.arange(2, len(sched))]
    return Schedule(sched.acq[order], sched.node[order], sched.start[order])


@pytest.fixture(scope="module")
def case():
    inst = generated("uniform", 30, 3)
    g = from_internal_nodes(inst, greedy(inst).nodes)
    scheds = {"greedy": g, "walk": from_internal_nodes(inst, random_walk(inst, RandomConfig(seed=1)).nodes),
              "swapped": infeasible(inst, g)}
    assert not check(inst, scheds["swapped"]).feasible and len(g) >= 3
    return inst, scheds


def section_attrs(text: str, div_id: str) -> dict:
    i = text.index(f"id='{div_id}-section'")
    tag = text[text.rindex("<section", 0, i):text.index(">", i)]
    return dict((k, int(v)) for k, v in
                (a.split("=") for a in tag.replace("'", "").split() if a.startswith("data-")))


def test_report_contents(case, tmp_path):
    inst, scheds = case
    out = write_report(inst, scheds, tmp_path / "r.html")
    text = out.read_text()
    taken = sum(len(s) for s in scheds.values())
    assert section_attrs(text, "map") == {"data-candidates": 30, "data-taken": taken, "data-track-points":
                                          section_attrs(text, "map")["data-track-points"]}
    assert section_attrs(text, "map")["data-track-points"] > 100
    assert section_attrs(text, "timeline") == {"data-windows": 30, "data-taken": taken}
    assert section_attrs(text, "attitude") == {"data-segments": taken}
    # summary: one row per schedule, the best at ratio 1, the infeasible one named with its first violation
    verdict = check(inst, scheds["swapped"])
    assert text.count("<tr data-schedule=") == 3
    assert "<td>1.000000</td>" in text
    assert f"infeasible: {verdict.reason}" in text.replace("&#x27;", "'")
    assert text.count("class='ok'>feasible") == 2
    # self-contained: plotly.js inline, nothing fetched, a few MB
    r = resources(text)
    assert r.urls == [] and r.scripts >= 3
    assert "cdn.plot.ly/plotly" not in text and 1e6 < len(text.encode()) < 8e6


def test_exact_values_and_difference_to_the_reference(case):
    """Values print exactly (issue 41: 6 significant figures made schedules 221 apart read the same), with the
    exact difference to the chosen reference schedule."""
    inst, scheds = case
    text = build_report(inst, scheds, reference="walk")
    values = {k: check(inst, s).value for k, s in scheds.items()}
    for k, v in values.items():
        row = text[text.index(f"<tr data-schedule='{k}'"):]
        row = row[:row.index("</tr>")]
        assert f"<td class='value'>{exact(v)}</td>" in row
        assert float(row.split("data-value='")[1].split("'")[0]) == v  # the float itself, read back exactly
        d = v - values["walk"]
        assert f"<td class='diff'>{'0' if d == 0 else ('+' if d > 0 else '-') + exact(abs(d))}</td>" in row
    assert "walk <small>(reference)</small>" in text and "Why walk misses what it misses" in text
    assert exact(201265221.0) == "201,265,221" and exact(201265000.5) == "201,265,000.5"
    assert exact(201265221.0) != exact(201265000.0)
    with pytest.raises(InputError, match="no schedule of that name"):
        build_report(inst, scheds, reference="nope")


def _fits_by_checker(inst, seq: np.ndarray, a: int) -> bool:
    """`a` inserted where first_insertion says, each member at its earliest node: the independent checker agrees."""
    g = inst.unpruned_graph
    nodes = earliest_path(g.indptr, g.dst, g.acq_ptr, seq, 0)
    p = first_insertion(g.indptr, g.dst, g.acq_ptr, g.node_time, seq, nodes, 0, a)
    if p < 0:
        return False
    new = np.insert(seq, p, a)
    path = earliest_path(g.indptr, g.dst, g.acq_ptr, new, 0)
    assert path.min() >= 0
    return check(inst, from_internal_nodes(inst, path)).feasible


@pytest.mark.parametrize("solver", ["greedy", "walk"])
def test_missed_reasons_agree_with_the_checker(case, solver):
    """Every missed acquisition gets a reason; 'insertable' ones really fit, and removing a named blocker really
    frees a blocked one (both confirmed by the independent checker on the changed schedule)."""
    inst, scheds = case
    s = scheds[solver]
    reasons = missed_reasons(inst, s)
    missed = set(range(inst.n_acq)) - set(s.acq.tolist())
    assert {m.acq for m in reasons} == missed
    prio = inst.priorities()
    assert [prio[m.acq] for m in reasons] == sorted(prio[m.acq] for m in reasons)  # highest class first
    seq = s.acq.astype(np.int64)
    for m in reasons:
        if m.kind == "insertable":
            assert _fits_by_checker(inst, seq, m.acq) and "value left on the table" in m.text
        elif m.kind == "blocked":
            assert not _fits_by_checker(inst, seq, m.acq)
            assert 1 <= len(m.blockers) <= 3 or "no removal" in m.text
            if "any one of" in m.text or len(m.blockers) == 1:
                for b in m.blockers:
                    assert _fits_by_checker(inst, seq[seq != b], m.acq) and str(b) in m.text
            elif m.blockers:
                assert _fits_by_checker(inst, seq[~np.isin(seq, m.blockers)], m.acq)
    # the random walk leaves value on the table: some missed acquisitions fit as it is
    if solver == "walk":
        assert any(m.kind == "insertable" for m in reasons)


def test_infeasible_reference_gets_no_reasons(case):
    inst, scheds = case
    text = build_report(inst, scheds, reference="swapped")
    assert "No reasons" in text and "data-missed='0'" in text


def test_utc_when_the_instance_has_an_epoch(case):
    inst, scheds = case
    without = build_report(inst, {"greedy": scheds["greedy"]})
    assert "no UTC epoch" in without and " UTC" not in without.replace("no UTC epoch", "")
    dated = dataclasses.replace(inst, meta={**inst.meta, "epoch_utc": "2026-03-20T10:00:00Z"})
    text = build_report(dated, {"greedy": scheds["greedy"]})
    assert "t = 0 s is 2026-03-20 10:00:00.0 UTC" in text and "time (s after 2026-03-20 10:00:00.0 UTC)" in text
    t0 = float(scheds["greedy"].start[0])
    h, rest = divmod(t0, 3600)
    assert f"2026-03-20 {10 + int(h):02d}:{int(rest // 60):02d}:" in text


def test_map_extent_is_the_data():
    (x0, x1), (y0, y1) = map_extent(np.array([10.0, 12.0, 11.0]), np.array([40.0, 45.0, 41.0]))
    assert (x0, x1) == (8.5, 13.5) and (y0, y1) == (38.5, 46.5)
    lon = np.array([170.0, -175.0, 178.0])  # across the antimeridian: drawn from 170 east to 185
    west = lon_origin(lon)
    assert west == 170.0 and list(wrap_lon(lon, west)) == [170.0, 185.0, 178.0]
    assert map_extent(wrap_lon(lon, west), np.zeros(3))[0] == (168.5, 186.5)
    assert lon_origin(np.array([10.0, 12.0])) == 10.0 and list(wrap_lon(np.array([10.0, 12.0]), 10.0)) == [10, 12]


def test_ground_track_follows_the_targets():
    inst = generated("uniform", 30, 3)
    t, lat, lon = ground_track(inst)
    a = inst.acqs

    def unit(la, lo):
        la, lo = np.deg2rad(la), np.deg2rad(lo)
        return np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], -1)

    ang = np.rad2deg(np.arccos(np.clip(unit(a.lat, a.lon) @ unit(lat, lon).T, -1, 1)))
    assert ang.min(axis=1).max() < 10.0  # every target lies near the track (within the pointing reach)
    closest = t[ang.argmin(axis=1)]
    assert np.all((closest >= a.vtw_start - 120) & (closest <= a.vtw_end + 120))  # ... when it is visible


def test_coastlines_are_embedded_data():
    lon, lat = coastlines()
    ok = np.isfinite(lon)
    assert 5000 < ok.sum() < 30000 and np.nanmax(np.abs(lon)) <= 180 and np.nanmax(np.abs(lat)) <= 90
    assert np.all(np.abs(np.diff(lon)[np.isfinite(np.diff(lon))]) <= 180)  # no line across the whole map


def test_instance_without_lat_lon_gets_timeline_and_table():
    inst = synthetic_instance(8, 2)
    s = from_internal_nodes(inst, random_walk(inst, RandomConfig(seed=0)).nodes)
    text = build_report(inst, {"walk": s})
    assert "id='map-section'" not in text and "no latitude/longitude" in text
    assert section_attrs(text, "timeline") == {"data-windows": 8, "data-taken": len(s)}
    assert "attitudes of this instance are unknown" in text and text.count("<tr data-schedule=") == 1


def test_imported_instance_has_no_track():
    inst = dataclasses.replace(generated("uniform", 30, 3), meta={"horizon_s": 6000.0}, node_attitude=None)
    text = build_report(inst, {"greedy": from_internal_nodes(inst, greedy(inst).nodes)})
    assert section_attrs(text, "map")["data-track-points"] == 0
    assert "orbit of this instance is unknown" in text and "ground track of the pass" not in text
    # attitudes fall back on the acquisitions' mean roll and pitch
    assert "mean attitude of each window" in text


def eosp(*args):
    return subprocess.run([sys.executable, "-m", "eosp.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=300)


def test_cli_report_and_foreign_schedule(tmp_path):
    inst = generated("uniform", 30, 3)
    write_instance(inst, tmp_path / "inst")
    write_schedule(from_internal_nodes(inst, greedy(inst).nodes), tmp_path / "greedy.parquet")
    write_schedule(from_internal_nodes(inst, random_walk(inst, RandomConfig(seed=2)).nodes), tmp_path / "walk.jsonl")
    r = eosp("report", tmp_path / "inst", tmp_path / "greedy.parquet", tmp_path / "walk.jsonl",
             "--out", tmp_path / "out" / "report.html", "--reference", "walk")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out" / "report.html").stat().st_size > 1e6 and "2 schedule(s)" in r.stdout
    assert "walk <small>(reference)</small>" in (tmp_path / "out" / "report.html").read_text()
    # a schedule of another instance: one line, exit 2, nothing written
    other = generated("uniform", 12, 0)
    write_schedule(from_internal_nodes(other, greedy(other).nodes), tmp_path / "other.parquet")
    r = eosp("report", tmp_path / "inst", tmp_path / "greedy.parquet", tmp_path / "other.parquet",
             "--out", tmp_path / "bad.html")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert "other.parquet" in r.stderr and "not a schedule of this instance" in r.stderr
    assert not (tmp_path / "bad.html").exists() and not list(tmp_path.glob(".bad.html*"))


# --------------------------------------------------------------------------- real browser

COUNT_JS = """(async () => {
  await new Promise(r => setTimeout(r, 300));
  const out = {};
  for (const id of ['map', 'timeline', 'attitude']) {
    const gd = document.getElementById(id);
    out[id] = gd && {rendered: !!gd._fullLayout, width: gd.getBoundingClientRect().width,
                     markers: gd.querySelectorAll('.scatterlayer .point').length,
                     bars: gd.querySelectorAll('.barlayer .point').length,
                     lines: gd.querySelectorAll('.scatterlayer path.js-line').length,
                     legend: Array.from(gd.querySelectorAll('.legendtext')).map(e => e.textContent)};
  }
  out.rows = Array.from(document.querySelectorAll('table.summary tbody tr')).map(
      r => [r.dataset.schedule, r.dataset.feasible]);
  out.resources = performance.getEntriesByType('resource').map(e => e.name);
  return out;
})()"""


def test_report_renders_in_headless_chromium(case, tmp_path, chromium):
    from tests.browser import LOCAL_SCHEMES, Browser

    inst, scheds = case
    page = write_report(inst, scheds, tmp_path / "report.html")
    taken = sum(len(s) for s in scheds.values())
    with Browser(chromium, tmp_path / "chromium.log") as b:
        b.open(page)
        got = b.evaluate(COUNT_JS)
        shot = b.screenshot(tmp_path / "report.png")
        full = b.screenshot(tmp_path / "report-full.png", full_page=True)
        errors, requests = b.errors(), b.requests()
    print(f"screenshots: {shot} {full}")
    assert errors == []
    assert requests == [page.resolve().as_uri()] and got["resources"] == []
    assert all(u.startswith(LOCAL_SCHEMES) for u in requests)
    for fig in ("map", "timeline", "attitude"):
        assert got[fig]["rendered"] and got[fig]["width"] > 1000
    # map: one marker per candidate and one per taken target; a line for coastlines, track, slews
    assert got["map"]["markers"] == inst.n_acq + taken
    assert got["map"]["lines"] >= 3 + len(scheds)
    assert {"greedy", "walk", "swapped"} <= {t.split(" (")[0] for t in got["map"]["legend"]}
    # timeline: one bar per visibility window and one per taken acquisition
    assert got["timeline"]["bars"] == inst.n_acq + taken
    assert got["attitude"]["lines"] >= 4 * len(scheds)
    assert got["rows"] == [["greedy", "true"], ["walk", "true"], ["swapped", "false"]]
    assert shot.stat().st_size > 20000 and full.stat().st_size > shot.stat().st_size


HOVER_JS = """(async () => {
  const gd = document.getElementById('timeline');
  const out = {};
  for (const [name, curve] of [['window', 0], ['taken', 1]]) {
    Plotly.Fx.hover(gd, [{curveNumber: curve, pointNumber: 0}]);
    await new Promise(r => setTimeout(r, 150));
    out[name] = Array.from(gd.querySelectorAll('.hoverlayer .hovertext text')).map(e => e.textContent).join(' ');
    Plotly.Fx.unhover(gd);
  }
  const m = document.getElementById('map')._fullLayout;
  out.map = {x: m.xaxis.range, y: m.yaxis.range};
  out.values = Array.from(document.querySelectorAll('table.summary td.value')).map(e => e.textContent);
  out.diffs = Array.from(document.querySelectorAll('table.summary td.diff')).map(e => e.textContent);
  out.missed = Array.from(document.querySelectorAll('#missed-section tbody tr')).map(r => r.dataset.kind);
  return out;
})()"""


def test_report_hover_and_values_in_headless_chromium(case, tmp_path, chromium):
    """What a planner reads: the hover of a known window bar and of a known taken bar (length and duration are
    end - start, issue 41), exact values and differences, the map held to the data, the missed table."""
    import re

    from tests.browser import Browser

    inst, scheds = case
    page = write_report(inst, scheds, tmp_path / "report.html", reference="greedy")
    with Browser(chromium, tmp_path / "chromium.log") as b:
        b.open(page)
        got = b.evaluate(HOVER_JS)
        errors = b.errors()
    assert errors == []
    a = inst.acqs
    first = int(np.lexsort((np.arange(inst.n_acq), a.vtw_start))[0])  # row 0 of the timeline
    nums = lambda t, key: float(re.search(key + r" (-?[\d.]+) s", t).group(1))  # noqa: E731
    win = got["window"]
    assert f"acquisition {first} " in win
    assert nums(win, "length") == pytest.approx(a.vtw_end[first] - a.vtw_start[first], abs=0.051)
    assert nums(win, "length") == pytest.approx(nums(win, "to") - nums(win, "window"), abs=0.11)
    assert nums(win, "duration") == pytest.approx(a.duration[first], abs=0.051)
    g = scheds["greedy"]
    acq0 = int(g.acq[0])
    taken = got["taken"]
    assert f"greedy #1: acquisition {acq0}" in taken
    assert nums(taken, "start") == pytest.approx(g.start[0], abs=0.051)
    assert nums(taken, "end") == pytest.approx(g.start[0] + a.duration[acq0], abs=0.051)
    assert nums(taken, "duration") == pytest.approx(nums(taken, "end") - nums(taken, "start"), abs=0.11)
    values = {k: check(inst, s).value for k, s in scheds.items()}
    assert got["values"] == [exact(values[k]) for k in scheds]
    assert got["diffs"][0] == "0" and got["diffs"][1].startswith(("+", "-", "0"))
    (x0, x1), (y0, y1) = map_extent(wrap_lon(a.lon, lon_origin(a.lon)), a.lat)
    assert x1 - x0 < 200  # this pass crosses the south pole: not a world map (it spanned 316 degrees)
    assert got["map"]["x"] == pytest.approx([x0, x1]) and got["map"]["y"] == pytest.approx([y0, y1])
    assert len(got["missed"]) == inst.n_acq - len(set(g.acq.tolist()))


def test_browser_harness_sees_errors_and_fetches(tmp_path, chromium):
    """The checks above would catch a page that fetched something or failed: prove it on such a page."""
    from tests.browser import LOCAL_SCHEMES, Browser

    page = tmp_path / "bad.html"
    page.write_text("<html><body><img src='http://example.invalid/tile.png'>"
                    "<script>console.error('boom'); undefined_function();</script></body></html>")
    with Browser(chromium, tmp_path / "chromium.log") as b:
        b.open(page)
        errors, requests = b.errors(), b.requests()
    assert any("boom" in e for e in errors) and any("undefined_function" in e for e in errors)
    assert any(not u.startswith(LOCAL_SCHEMES) for u in requests)
    assert resources(page.read_text()).urls == ["http://example.invalid/tile.png"]
