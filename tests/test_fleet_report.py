"""The fleet page (eosp report FLEET_DIR S...): contents, bad input, and rendering in a real headless browser."""

import dataclasses
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from eosp.cli import main
from eosp.evaluation.fleet_report import build_page, write_page
from eosp.fleet.check import validate
from eosp.fleet.geometry import Geometry
from eosp.fleet.greedy import solve
from eosp.fleet.model import Schedule, strings
from eosp.fleet.opportunities import compute
from tests.test_fleet import synthetic_fleet
from tests.test_html_report import resources

FIXTURES = Path(__file__).parent / "fixtures" / "aeossp"


@pytest.fixture(scope="module")
def day():
    fleet = synthetic_fleet(30, seed=4)
    geo = Geometry(fleet)
    opps = compute(fleet, geo)
    s = solve(fleet, opps, geo)
    half = Schedule(s.satellite[::2], s.task[::2], s.start_us[::2], s.end_us[::2])
    assert validate(fleet, s, geo).valid and len(s) >= 6
    return fleet, opps, {"greedy": s, "half": half}


def overlapping(s: Schedule) -> Schedule:
    """The schedule with its first observation again, 5 s later on the same satellite: an overlap."""
    return Schedule(np.r_[s.satellite, s.satellite[:1]], np.r_[s.task, s.task[1:2]], np.r_[s.start_us, s.start_us[:1] + 5_000_000],
                    np.r_[s.end_us, s.end_us[:1] + 5_000_000])


def test_page_contents(day):
    fleet, opps, scheds = day
    text = build_page(fleet, opps, scheds)
    r = resources(text)
    assert r.urls == [] and "http" not in text.split("<script type='application/json'")[0].lower()
    assert text.count("<tr data-schedule=") == 2 and text.count("class='ok'>valid") == 2
    assert "no ground stations" in text and f"data-tasks='{len(fleet.tasks)}'" in text
    assert len(text.encode()) < 2e6


def test_invalid_schedule_and_no_geometry(day):
    fleet, opps, scheds = day
    bad = overlapping(scheds["greedy"])
    res = validate(fleet, bad)
    assert not res.valid
    text = build_page(fleet, opps, {"bad": bad})
    assert "class='bad'>invalid: " in text and "is not valid (each violation is marked" in text
    assert f"data-count='{len(res.violations)}'" in text and text.count("<li>") == len(res.violations)
    broken = dataclasses.replace(fleet, satellites=dataclasses.replace(
        fleet.satellites, tle=dataclasses.replace(fleet.satellites.tle, line2=strings(["2 garbage"] * 2))))
    text = build_page(broken, opps, {"greedy": scheds["greedy"]})
    assert "cannot be propagated" in text and "not checked" in text


def test_cli_report_and_another_fleets_schedule(tmp_path, capsys):
    fl = tmp_path / "fl"
    assert main(["import", str(FIXTURES / "duplicate_observation_no_bonus_valid"), "--out", str(fl)]) == 0
    s = tmp_path / "s.parquet"
    assert main(["solve", str(fl), "--solver", "greedy", "--out", str(s)]) == 0
    out = tmp_path / "out" / "day.html"
    assert main(["report", str(fl), str(s), "--out", str(out)]) == 0
    assert out.stat().st_size > 20000 and "1 schedule(s)" in capsys.readouterr().out
    assert main(["report", str(fl), str(s), "--out", str(out)]) == 2  # needs --overwrite
    other = tmp_path / "other"
    assert main(["import", str(FIXTURES / "full_completion_valid"), "--out", str(other)]) == 0
    s2 = tmp_path / "s2.parquet"
    assert main(["solve", str(other), "--solver", "greedy", "--out", str(s2)]) == 0
    r = subprocess.run([sys.executable, "-m", "eosp.cli", "report", str(fl), str(s), str(s2), "--out",
                        str(tmp_path / "bad.html")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "another fleet" in r.stderr
    assert str(s2) in r.stderr and not (tmp_path / "bad.html").exists()


# --------------------------------------------------------------------------- real browser

PROBE_JS = """(async () => {
  const p = window.fleetPage;
  const out = {ready: p.ready, drawn: p.drawn, ms: p.renderMs};
  const tip = document.getElementById('tip');
  const move = (el, at) => el.dispatchEvent(new MouseEvent('mousemove', {clientX: at.x, clientY: at.y, bubbles: true}));
  move(document.getElementById('gantt'), p.barAt(0));
  out.bar = tip.textContent;
  move(document.getElementById('map'), p.taskAt(OBSERVED_ROW));
  out.task = tip.textContent;
  out.rows = Array.from(document.querySelectorAll('#tasks tbody tr')).map(r => [r.dataset.task, r.dataset.status, r.dataset.kind]);
  out.reasons = Array.from(document.querySelectorAll('#tasks tbody td.reason')).map(e => e.textContent);
  out.sats = document.querySelectorAll('#per-sat tbody tr').length;
  out.weights = document.querySelectorAll('#per-weight tbody tr').length;
  out.diff = Array.from(document.querySelectorAll('.diffrow')).map(e => [e.dataset.onlyA, e.dataset.onlyB]);
  out.resources = performance.getEntriesByType('resource').map(e => e.name);
  const mr = document.getElementById('map').getBoundingClientRect();  // zoomed to the data: every target on the map
  out.outside = D_TASKS.filter(t => { const q = p.taskAt(t); return q.x < mr.left || q.x > mr.right || q.y < mr.top || q.y > mr.bottom; });
  out.map_box = [mr.width, mr.height];
  // zoom by dragging across the chart from a quarter to half of its width: the bar keeps its hover
  const g = document.getElementById('gantt'), r = g.getBoundingClientRect(), w = r.width - 92 - 12;
  const y = r.top + 40, xa = r.left + 92 + w / 4, xb = r.left + 92 + w / 2;
  g.dispatchEvent(new MouseEvent('mousedown', {clientX: xa, clientY: y, bubbles: true}));
  g.dispatchEvent(new MouseEvent('mouseup', {clientX: xb, clientY: y, bubbles: true}));
  out.dragged = p.view();
  out.view = [p.zoom(BAR_A, BAR_B)];
  move(g, p.barAt(0));
  out.bar_zoomed = tip.textContent;
  out.view.push(p.zoom());
  return out;
})()"""


def test_page_renders_in_headless_chromium(day, tmp_path, chromium):
    from tests.browser import Browser

    fleet, opps, scheds = day
    page = write_page(fleet, opps, scheds, tmp_path / "day.html")
    s = scheds["greedy"]
    missed = sorted(set(fleet.tasks.ids.tolist()) - set(s.task.tolist()))
    observed_task = int(fleet.task_index()[s.task[0]])
    with Browser(chromium, tmp_path / "chromium.log") as b:
        b.open(page)
        a0 = max(0.0, s.start_us[0] / 1e6 - 30)
        b0 = max(a0 + 60, min(fleet.horizon.seconds, s.end_us[0] / 1e6 + 30))
        got = b.evaluate(PROBE_JS.replace("OBSERVED_ROW", str(observed_task)).replace("D_TASKS", str(list(range(len(fleet.tasks))))).replace("BAR_A", str(a0))
                         .replace("BAR_B", str(b0)))
        shot = b.screenshot(tmp_path / "day.png", full_page=True)
        errors, requests = b.errors(), b.requests()
    print(f"screenshot: {shot}")
    assert errors == [] and requests == [page.resolve().as_uri()] and got["resources"] == []
    assert got["ready"]
    g = got["drawn"]["gantt"]
    assert g["bars"] == len(s) and g["slews"] == len(s) and g["violations"] == 0 and g["eclipses"] >= 0
    assert g["battery_points"] > 2 * len(fleet.satellites)
    m = got["drawn"]["map"]
    assert got["outside"] == [] and got["map_box"][0] > 1000 and got["map_box"][1] >= 300
    assert m["points"] == len(fleet.tasks) and m["observed"] == len(set(s.task.tolist())) and m["tracks"] == 2
    # the hover of the first observation: its satellite, task and UTC times
    h = fleet.horizon
    st = (h.start + (s.start_us[0] * 1e-6) * (h.end - h.start) / h.seconds).strftime("%Y-%m-%d %H:%M:%S")
    assert got["bar"].startswith(f"{s.satellite[0]}: task {s.task[0]} ") and f"{st} UTC to " in got["bar"]
    dur = (s.end_us[0] - s.start_us[0]) / 1e6
    assert re.search(rf", {dur:.1f} s", got["bar"]) and "slew and settling" in got["bar"]
    assert got["task"].startswith(f"task {s.task[0]} ") and "observed by" in got["task"]
    # the table: one row per task, every missed one with a reason
    assert len(got["rows"]) == len(fleet.tasks)
    assert sorted(r[0] for r in got["rows"] if r[1] == "missed") == missed
    assert all(r[2] for r in got["rows"] if r[1] == "missed") and all(got["reasons"][i] for i, r in
                                                                     enumerate(got["rows"]) if r[1] == "missed")
    # zoomed to a minute around the first observation: same hover, the horizon back on double-click
    hs = fleet.horizon.seconds
    assert got["dragged"] == pytest.approx([hs / 4, hs / 2], abs=hs / 500)
    assert got["view"][0] == pytest.approx([a0, b0]) and got["bar_zoomed"] == got["bar"]
    assert got["view"][1] == [0, fleet.horizon.seconds]
    assert got["sats"] == 2 and got["weights"] == len(set(fleet.tasks.weight.tolist()))
    half = scheds["half"]
    assert got["diff"] == [[str(len(set(s.task.tolist()) - set(half.task.tolist()))), "0"]]


def test_invalid_schedule_is_marked_in_headless_chromium(day, tmp_path, chromium):
    from tests.browser import Browser

    fleet, opps, scheds = day
    bad = overlapping(scheds["greedy"])
    violations = validate(fleet, bad).violations
    n_viol = sum(v.time is not None for v in violations)
    page = write_page(fleet, opps, {"bad": bad}, tmp_path / "bad.html")
    with Browser(chromium, tmp_path / "chromium.log") as b:
        b.open(page)
        got = b.evaluate("""(async () => {
          const p = window.fleetPage, g = document.getElementById('gantt'), at = p.violationAt(0);
          g.dispatchEvent(new MouseEvent('mousemove', {clientX: at.x, clientY: at.y, bubbles: true}));
          return {drawn: p.drawn.gantt, hover: document.getElementById('tip').textContent};
        })()""")
        errors = b.errors()
    assert errors == [] and n_viol >= 1 and got["drawn"]["violations"] == n_viol
    assert got["hover"] == f"violation: {violations[0]}"


# --------------------------------------------------------------------------- an ONERA fleet: no orbits, downloads

ONERA_JS = """(async () => {
  const p = window.fleetPage, tip = document.getElementById('tip'), g = document.getElementById('gantt');
  const at = p.barAt(0);
  g.dispatchEvent(new MouseEvent('mousemove', {clientX: at.x, clientY: at.y, bubbles: true}));
  return {drawn: p.drawn, bar: tip.textContent,
          rows: Array.from(document.querySelectorAll('#tasks tbody tr')).map(r => [r.dataset.task, r.dataset.status]),
          groups: Array.from(document.querySelectorAll('#per-weight tbody tr')).map(r => r.dataset.weight),
          heading: document.getElementById('weight-section').previousElementSibling.textContent};
})()"""


def test_onera_fleet_page_in_headless_chromium(tmp_path, chromium, capsys):
    """An ONERA fleet has no orbits but mandatory downloads: the page draws observations, downloads and
    transitions, requests by kind, and says what it cannot draw."""
    from eosp.onera.model import read_onera
    from eosp.onera.model import read_schedule as read_onera_schedule
    from eosp.onera.check import request_values
    from tests.browser import Browser
    from tests.test_onera import TINY

    (tmp_path / "t.pb").write_text(TINY)
    fl, s, out = tmp_path / "fl", tmp_path / "s.parquet", tmp_path / "o.html"
    assert main(["import", str(tmp_path / "t.pb"), "--out", str(fl)]) == 0
    assert main(["solve", str(fl), "--solver", "greedy", "--out", str(s)]) == 0
    assert main(["report", str(fl), str(s), "--out", str(out)]) == 0
    f = read_onera(fl)
    sched, _ = read_onera_schedule(s, f)
    is_dl = np.isin(sched.activity, f.downloads.id)
    assert is_dl.sum() == len(f.downloads) == 2
    text = out.read_text()
    assert "have no orbits" in text and "class='ok'>valid" in text
    with Browser(chromium, tmp_path / "chromium.log") as b:
        b.open(out)
        got = b.evaluate(ONERA_JS)
        errors = b.errors()
    assert errors == []
    g, m = got["drawn"]["gantt"], got["drawn"]["map"]
    assert g["downloads"] == 2 and g["bars"] == int((~is_dl).sum()) and g["battery_points"] == 0
    assert m["tracks"] == 0 and m["points"] == len(f.requests)
    assert "(since 0 h)" in got["bar"] and got["bar"].split(": ")[0] in {str(x) for x in f.satellites}
    # a request counts as observed only when it is worth something (a stereo request needs its pair)
    rows = set(np.flatnonzero(np.isin(f.observations.id, sched.activity)).tolist())
    _, val = request_values(f, np.asarray(sorted(rows), dtype=np.int64))
    assert sorted(r[0] for r in got["rows"] if r[1] == "observed") == sorted(str(f.requests.id[k])
                                                                             for k in np.flatnonzero(val > 0))
    assert got["heading"] == "Per request kind" and sorted(got["groups"]) == ["one-shot", "periodic", "stereo", "video"]


def test_the_page_says_how_each_schedule_was_made_in_headless_chromium(tmp_path, chromium, capsys):
    """`eosp solve` writes into the schedule file its solver, time limit, rounds, warm start, bound and gap; the page
    states them per schedule beside the checker's verdict (read back from the rendered page); a schedule file
    without them (an aeossp solution.json) shows '-'."""
    import json

    import pyarrow.parquet as pq

    from tests.browser import Browser

    fl = tmp_path / "fl"
    assert main(["import", str(FIXTURES / "full_completion_valid"), "--out", str(fl)]) == 0
    day, greedy = tmp_path / "day.parquet", tmp_path / "greedy.parquet"
    assert main(["solve", str(fl), "--solver", "fleet", "--time-limit", "20", "--rounds", "2", "--out", str(day)]) == 0
    assert main(["solve", str(fl), "--solver", "greedy", "--out", str(greedy)]) == 0
    sol = tmp_path / "sol.json"
    assert main(["export-schedule", str(fl), str(greedy), "--format", "aeossp", "--out", str(sol)]) == 0
    md = {k.decode(): json.loads(v) for k, v in pq.read_schema(day).metadata.items()
          if k.decode() in ("solver", "time_limit", "rounds", "warm_start", "bound", "gap")}
    assert md["solver"] == "fleet" and md["time_limit"] == 20 and md["rounds"] >= 0 and md["warm_start"]
    page = tmp_path / "page.html"
    assert main(["report", str(fl), str(day), str(greedy), str(sol), "--out", str(page)]) == 0
    capsys.readouterr()
    with Browser(chromium, tmp_path / "chromium.log") as b:
        b.open(page)
        got = b.evaluate("""(async () => Array.from(document.querySelectorAll('table.summary tbody tr')).map(r => ({
            label: r.dataset.schedule, valid: r.dataset.valid,
            cells: Object.fromEntries(Array.from(r.querySelectorAll('td[data-k]')).map(c => [c.dataset.k, c.textContent])),
            dashes: r.querySelectorAll('td.na').length,
            head: Array.from(r.closest('table').querySelectorAll('th')).map(h => h.textContent)})))()""")
        errors = b.errors()
    assert errors == [] and [r["label"] for r in got] == ["day", "greedy", "sol"]
    assert all(r["valid"] == "true" for r in got)
    assert got[0]["head"][-7:] == ["solver", "time limit (s)", "rounds", "warm start", "bound", "gap", "checker"]
    c = got[0]["cells"]
    assert c["solver"] == "fleet" and c["time_limit"] == "20" and c["rounds"] == str(md["rounds"])
    assert c["warm_start"] == md["warm_start"] and c["bound"] == f"{md['bound']:.6f}" and c["gap"] == f"{md['gap']:.2%}"
    assert got[1]["cells"] == {"solver": "greedy"} and got[1]["dashes"] == 5
    assert got[2]["cells"] == {} and got[2]["dashes"] == 6
