"""The replay of a simulated day (``eosp simulate ... --replay N``): the fleet page of the day as executed (its Gantt,
map, task table and checker verdict, :mod:`eosp.evaluation.fleet_report`) with the replay as sections of its own,
one offline HTML page per realization.

What the replay shows, from the simulator's own record (:class:`eosp.ops.simulate.Run`) and the realization: per satellite,
its ground contacts, the uploads of each planning call, every acquisition it flew (served, found cloudy, an
alternate the onboard rule took); per contact, what the satellite reported there and whether a plan reached it;
every urgent request with its arrival and when it was served (or that it never was, tried or not).  The page is
self-contained (its data as JSON, its script from ``replay_page.js``), so it opens from a file with no network.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np


_STYLE = ("#replay svg{border:1px solid #ccc}#replay .legend span{display:inline-block;width:12px;height:10px;"
          "margin:0 4px 0 12px}#replay td.l,#replay th.l{text-align:left}")


def replay_data(day, world, run, scen) -> dict:
    """The page's data: satellites, contacts, uploads, acquisitions flown with their outcomes and reports,
    requests with their arrival and service (seconds from the horizon start)."""
    f = scen.fleet
    rows = np.asarray(run.rows, dtype=np.int64)
    ok = world.clear[rows]
    report = day.next_contact(day.sat[rows], day.end_s[rows])
    taken = set(int(a) for a in run.alternates_taken)
    served_at = np.full(len(day.weight), np.inf)
    np.minimum.at(served_at, day.task[rows[ok]], day.end_s[rows[ok]])
    tries = np.bincount(day.task[rows], minlength=len(day.weight))
    uploads = [{"t": float(t), "at": [None if not np.isfinite(u) else float(u) for u in at]} for t, at in run.uploads]
    return {
        "start": f.horizon.start.isoformat().replace("+00:00", "Z"), "horizon": float(day.horizon_s),
        "sats": [str(s) for s in f.satellites.ids],
        "contacts": [[[float(a), float(b)] for a, b in zip(*day.contacts.of(k))] for k in range(day.satellites)],
        "uploads": uploads,
        "acq": {"sat": day.sat[rows].tolist(), "task": [str(f.tasks.ids[t]) for t in day.task[rows]],
                "start": day.start_s[rows].tolist(), "end": day.end_s[rows].tolist(), "ok": ok.tolist(),
                "alt": [int(r) in taken for r in rows.tolist()],
                "report": [None if not np.isfinite(x) else float(x) for x in report]},
        "urgent": [{"id": str(f.tasks.ids[j]), "weight": float(day.weight[j]), "arrival": float(world.arrival_s[j]),
                    "served": None if not np.isfinite(served_at[j]) else float(served_at[j]),
                    "tries": int(tries[j])} for j in np.flatnonzero(day.urgent).tolist()],
        "catalogue": {"tasks": int((~day.urgent).sum()),
                      "served": int(np.isfinite(served_at[~day.urgent]).sum()),
                      "tried_never_served": int(((tries > 0) & ~np.isfinite(served_at) & ~day.urgent).sum())},
    }


def replay_section(data: dict, figures: dict) -> str:
    """The replay's sections of the page (its style, data and script inline; the element ids are its own)."""
    from importlib.resources import files

    script = files("eosp.evaluation").joinpath("replay_page.js").read_text(encoding="utf-8")
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    urgent = "-" if figures.get("served_urgent") is None else f"{figures['served_urgent']:.4f}"
    meta = (f"served {figures['served']:.4f} of the weight (catalogue {figures['served_catalogue']:.4f}, urgent "
            f"{urgent}); clairvoyant bound {figures['bound']:.4f} ({html.escape(str(figures.get('bound_source', '')))})"
            f", regret {figures['regret']:.4f}; {figures['acquisitions']} acquisitions, {figures['failed']} found "
            f"cloudy, {figures.get('alternates_taken', 0)} alternates taken; executions "
            f"{'valid' if figures.get('valid') else 'INVALID'} by the checker")
    legend = ("<p class='legend'>acquisitions:<span style='background:#2a2'></span>served"
              "<span style='background:#d33'></span>found cloudy<span style='background:#36c'></span>an alternate "
              "(onboard rule)<span style='background:#ddd'></span>ground contact<span style='background:#f90'>"
              "</span>upload</p>")
    return (f"<style>{_STYLE}</style><section id='replay'>\n<h2>Replay: the day in operation</h2>"
            f"<p class='meta'>{meta}.  The schedule above is every acquisition flown, those found cloudy included "
            f"(they serve nothing); here they are told apart.</p>{legend}\n"
            "<svg id='timeline'></svg>\n<h2>Contacts</h2><p class='meta'>What each satellite reported at each contact "
            "(the acquisitions since its last one) and whether a plan reached it.</p><table id='contacts'></table>\n"
            "<h2>Urgent requests</h2><table id='urgent'></table>\n<h2>Catalogue</h2><p id='catalogue'></p>\n"
            f"<script type='application/json' id='replay-data'>{payload}</script>\n<script>{script}</script>\n"
            "</section>\n")


def replay_page(fleet, opps, executed, data: dict, figures: dict, title: str, info: dict) -> str:
    """The page: the fleet page of the `executed` schedule (every acquisition flown; `info`: how it was planned,
    for the page's summary) and the replay's sections."""
    from eosp.evaluation.fleet_report import build_page

    return build_page(fleet, opps, {"executed": executed}, title, {"executed": info},
                      appendix=replay_section(data, figures))


def write_replay(path: Path, page: str) -> Path:
    """The page written atomically to `path` (a page of a run directory eosp writes)."""
    from eosp.atomic import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_text(page, encoding="utf-8")
    return path
