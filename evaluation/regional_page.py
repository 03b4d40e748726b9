"""The page of a regional_coverage case: regions, strips and covered samples on a map, one map per solution.

One offline HTML file (inline SVG, no script, no network): per solution, the checker's verdict line, the
regions' outlines, every grid sample (covered: filled, by the colour of its satellite's first strip over it;
not covered: grey), every strip's footprint (the verifier's segments: its inner and outer edge hits), and a
table of the strips (satellite, start, duration, roll, samples it covers, violations named by the checker).
The map is an equirectangular view of the regions' bounding box; every region is drawn in its own panel when
they lie far apart.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from eosp.atomic import atomic_path
from eosp.ownership import check_output, html_mark
from eosp.regional.check import Report, check
from eosp.regional.geometry import Track
from eosp.regional.model import Case

REPORT_KIND = "report"
PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2", "#bcbd22",
           "#7f7f7f", "#393b79", "#637939"]
W = 520  # pixels per panel


def _panel(case: Case, k: int, rep: Report, polys: dict[int, list], owner: np.ndarray) -> str:
    r = case.regions[k]
    ring = np.array(r.ring)
    x0, y0 = ring.min(0) - 0.3
    x1, y1 = ring.max(0) + 0.3
    kx = np.cos(np.radians((y0 + y1) / 2))
    scale = W / max((x1 - x0) * kx, 1e-9)
    h = max(60.0, (y1 - y0) * scale)

    def xy(lon, lat):
        return (lon - x0) * kx * scale, (y1 - lat) * scale

    parts = [f"<svg width='{W}' height='{h:.0f}' viewBox='0 0 {W} {h:.0f}' style='border:1px solid #ccc'>"]
    for p in rep.acts:
        for poly in polys.get(p.index, []):
            pts = " ".join(f"{a:.1f},{b:.1f}" for a, b in (xy(*c) for c in poly.exterior.coords))
            col = PALETTE[p.sat % len(PALETTE)]
            parts.append(f"<polygon points='{pts}' fill='{col}' fill-opacity='0.12' stroke='{col}' "
                         "stroke-opacity='0.35' stroke-width='0.5'/>")
    mine = np.flatnonzero(case.region == k)
    for i in mine.tolist():
        a, b = xy(case.lon[i], case.lat[i])
        col = "#bbb" if owner[i] < 0 else PALETTE[owner[i] % len(PALETTE)]
        parts.append(f"<circle cx='{a:.1f}' cy='{b:.1f}' r='1.3' fill='{col}'/>")
    pts = " ".join(f"{a:.1f},{b:.1f}" for a, b in (xy(*c) for c in r.ring))
    parts.append(f"<polygon points='{pts}' fill='none' stroke='#000' stroke-width='1.2'/></svg>")
    ratio = rep.metrics["region_coverages"][r.id]["coverage_ratio"]
    return (f"<div class='panel'><h3>{html.escape(r.id)}: {ratio:.4f} covered (weight {r.weight:g})</h3>"
            + "".join(parts) + "</div>")


def _section(case: Case, label: str, plan, track: Track) -> str:
    rep = check(case, plan, track)
    polys = {}
    owner = np.full(len(case.lon), -1, np.int64)
    for p in sorted((p for p in rep.acts if p.polygons), key=lambda p: p.start_us):  # the checker's segments
        polys[p.index] = p.polygons
        fresh = p.covered[owner[p.covered] < 0]
        owner[fresh] = p.sat
    m = rep.metrics
    verdict = "valid" if rep.valid else f"invalid: {rep.violations[0]} ({len(rep.violations)} violations)"
    rows = []
    for p in rep.acts:
        sat = case.satellites[p.sat].id if p.sat >= 0 else "?"
        start = case.at(p.start_us / 1e6).strftime("%Y-%m-%d %H:%M:%S")
        rows.append(f"<tr><td>{p.index}</td><td style='color:{PALETTE[max(p.sat, 0) % len(PALETTE)]}'>"
                    f"{html.escape(sat)}</td><td>{start}</td><td>{p.duration_s:g}</td><td>{p.roll:+.2f}</td>"
                    f"<td>{len(p.covered)}</td><td>{'' if p.ok else 'rejected'}</td></tr>")
    panels = "".join(_panel(case, k, rep, polys, owner) for k in case.grid_order)
    return (f"<section><h2>{html.escape(label)}</h2><p><b>{verdict}</b>: coverage_ratio "
            f"{m['coverage_ratio']:.6f}, weighted_coverage_ratio {m['weighted_coverage_ratio']:.6f}, "
            f"{m['num_actions']} actions, min battery {m['min_battery_wh']:.3f} Wh</p>"
            f"<div class='panels'>{panels}</div><details><summary>strips</summary><table><tr><th>#</th>"
            "<th>satellite</th><th>start (UTC)</th><th>s</th><th>roll</th><th>samples</th><th></th></tr>"
            + "".join(rows) + "</table></details></section>")


def build_page(case: Case, plans: dict, title: str = "") -> str:
    track = Track(case)
    title = title or f"regional_coverage {case.case_id}"
    body = "".join(_section(case, label, plan, track) for label, plan in plans.items())
    legend = " ".join(f"<span style='color:{PALETTE[s % len(PALETTE)]}'>&#9632; {html.escape(sat.id)}</span>"
                      for s, sat in enumerate(case.satellites))
    return ("<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>" + html_mark(REPORT_KIND) +
            f"<title>{html.escape(title)}</title><style>body{{font:14px sans-serif;margin:20px}}"
            ".panels{display:flex;flex-wrap:wrap;gap:12px}.panel h3{font-size:13px;margin:4px 0}"
            "td,th{padding:2px 8px;text-align:right}</style></head><body>"
            f"<h1>{html.escape(title)}</h1><p>{len(case.satellites)} satellites, {len(case.regions)} regions, "
            f"{len(case.lon)} grid samples; {case.horizon_start:%Y-%m-%d %H:%M} to {case.horizon_end:%Y-%m-%d %H:%M} "
            f"UTC. Samples are coloured by the satellite whose strip covered them first, grey when uncovered; strips "
            f"are the verifier's segments.</p><p>{legend}</p>{body}</body></html>")


def write_page(case: Case, paths: list[str], out: str, title: str = "", overwrite: bool = False) -> str:
    """`eosp report CASE S1 [S2 ...] --out page.html`: the page written atomically, and the line to print."""
    from eosp.regional.read import read_solution

    dest = check_output(out, REPORT_KIND, overwrite, suffixes=(".html", ".htm"))
    plans = {}
    for path in paths:  # labelled by file name, a prime added to a repeated one
        label = Path(path).stem
        while label in plans:
            label += "'"
        plans[label] = read_solution(path)
    text = build_page(case, plans, title)
    with atomic_path(dest, suffix=".html") as tmp:
        tmp.write_text(text, encoding="utf-8")
    return f"{Path(dest)}: {len(plans)} solution(s) of {case.case_id} ({len(text) / 1e6:.2f} MB)"
