"""The planner's HTML report: contents, bad input, and rendering in a real headless browser."""

import dataclasses
import html.parser
import subprocess
import sys

import numpy as np
import pytest

from eosp.evaluation.html_report import build_report, coastlines, ground_track, write_report
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
    assert "<td>1.0000</td>" in text
    assert f"infeasible: {verdict.reason}" in text.replace("&#x27;", "'")
    assert text.count("class='ok'>feasible") == 2
    # self-contained: plotly.js inline, nothing fetched, a few MB
    r = resources(text)
    assert r.urls == [] and r.scripts >= 3
    assert "cdn.plot.ly/plotly" not in text and 1e6 < len(text.encode()) < 8e6


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
             "--out", tmp_path / "out" / "report.html")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out" / "report.html").stat().st_size > 1e6 and "2 schedule(s)" in r.stdout
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

@pytest.fixture(scope="session")
def chromium():
    from tests.browser import ensure_chromium

    path, why = ensure_chromium()
    if path is None:
        pytest.skip(why)
    return path


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
