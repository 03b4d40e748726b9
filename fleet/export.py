"""A fleet schedule for globe viewers: CZML (Cesium) and KML (Google Earth and GIS tools).

Both are built with registry libraries made for them (czml3, fastkml), so their structure is the
formats' own.  What they hold (docs/formats.md, "Fleet schedule exports"):

* CZML: a document packet (name, version, the horizon as the clock interval); one packet per
  satellite (``sat/<id>``) with its ITRF positions sampled every :data:`TRACK_STEP_S` seconds
  (Lagrange interpolation, ``referenceFrame: FIXED``), a point, a label and a path; one packet per
  task (``task/<id>``) at its target, available over its window, green when observed, red when
  not; one packet per observation (``obs/<n>``), available exactly over [start, end] (UTC, to the
  microsecond), a line from the satellite to the target, with the satellite and task in its
  properties.  The second packet, ``{"id": "eosp", "properties": {"eosp": "fleet-czml"}}``, is the ownership
  mark (:mod:`eosp.ownership`; it draws nothing).
* KML: a folder of ground tracks (one LineString per satellite and antimeridian crossing, in a
  MultiGeometry), a folder of targets (one Point per task, its status in the name), and a folder
  of observations (one Point at the target per observation, with a TimeSpan [start, end]).
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path

import numpy as np

from eosp.fleet.geometry import Geometry
from eosp.fleet.model import US, Fleet, Schedule, iso_z
from eosp.fleet.tracks import ground_track, positions, sample_times

TRACK_STEP_S = 60
CZML_KIND = "fleet-czml"
KML_KIND = "fleet-kml"
SERVED_RGBA = [46, 160, 67, 255]
MISSED_RGBA = [214, 39, 40, 255]
SAT_RGBA = [31, 119, 180, 255]


def _served(fleet: Fleet, schedule: Schedule) -> np.ndarray:
    return np.isin(fleet.tasks.ids, np.unique(schedule.task))


def czml_document(fleet: Fleet, schedule: Schedule, geo: Geometry, name: str = "") -> list[dict]:
    """The CZML packets (JSON-ready), built and validated by czml3."""
    from czml3 import Clock, Document, Label, Packet, Path, Point, Polyline, Position, PositionList
    from czml3.properties import Color, PolylineMaterial, SolidColorMaterial
    from czml3.types import TimeInterval

    h = fleet.horizon
    t0, t1 = iso_z(h.start), iso_z(h.end)
    horizon = TimeInterval(start=t0, end=t1)
    packets = [Packet(id="document", name=name or f"eosp fleet schedule {fleet.case_id}".strip(), version="1.0",
                      clock=Clock(interval=horizon, currentTime=t0, multiplier=60)),
               Packet(id="eosp", properties={"eosp": CZML_KIND})]
    t_s = sample_times(geo, TRACK_STEP_S)
    for k, sid in enumerate(fleet.satellites.ids.tolist()):
        pos = np.round(positions(geo, k, t_s), 1)  # decimetres: far below what a globe shows
        samples = np.column_stack([t_s.astype(np.float64), pos]).ravel().tolist()
        packets.append(Packet(
            id=f"sat/{sid}", name=str(sid), availability=horizon,
            position=Position(epoch=t0, cartesian=samples, referenceFrame="FIXED", interpolationAlgorithm="LAGRANGE",
                              interpolationDegree=5),
            point=Point(pixelSize=8, color=Color(rgba=SAT_RGBA)),
            label=Label(text=str(sid), show=True),
            path=Path(leadTime=0, trailTime=3000, width=1, resolution=TRACK_STEP_S)))
    tk = fleet.tasks
    served = _served(fleet, schedule)
    for i, tid in enumerate(tk.ids.tolist()):
        packets.append(Packet(
            id=f"task/{tid}", name=str(tk.names[i]) or str(tid),
            availability=TimeInterval(start=iso_z(h.utc(round(tk.release_s[i] * US))),
                                      end=iso_z(h.utc(round(tk.due_s[i] * US)))),
            description=f"task {tid}: weight {tk.weight[i]:g}, {tk.duration_s[i]:g} s, sensor {tk.sensor[i]}, "
                        + ("observed" if served[i] else "missed"),
            position=Position(cartographicDegrees=[float(tk.lon_deg[i]), float(tk.lat_deg[i]), float(tk.alt_m[i])]),
            point=Point(pixelSize=6, color=Color(rgba=SERVED_RGBA if served[i] else MISSED_RGBA))))
    for n, (sid, tid, a, b) in enumerate(zip(schedule.satellite.tolist(), schedule.task.tolist(),
                                             schedule.start_us.tolist(), schedule.end_us.tolist())):
        packets.append(Packet(
            id=f"obs/{n}", name=f"{sid} observes {tid}",
            availability=TimeInterval(start=iso_z(h.utc(a)), end=iso_z(h.utc(b))),
            properties={"satellite": sid, "task": tid, "duration_s": (b - a) / US},
            polyline=Polyline(positions=PositionList(references=[f"sat/{sid}#position", f"task/{tid}#position"]),
                              width=2, material=PolylineMaterial(solidColor=SolidColorMaterial(
                                  color=Color(rgba=[255, 200, 0, 255]))))))
    return json.loads(Document(packets=packets).dumps())


def _quiet_fastkml():
    """fastkml, imported without its warning that lxml (pretty printing only) is missing."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        import fastkml
    return fastkml


def _kdt(fleet: Fleet, us: int):
    from fastkml.times import KmlDateTime

    return KmlDateTime(fleet.horizon.utc(us))


def kml_document(fleet: Fleet, schedule: Schedule, geo: Geometry, name: str = "") -> str:
    """The KML text (fastkml), with the ownership comment after the XML declaration."""
    fk = _quiet_fastkml()
    from fastkml import Folder, Placemark, TimeSpan
    from fastkml.geometry import LineString, MultiGeometry, Point

    h = fleet.horizon
    tracks = []
    t_s = sample_times(geo, TRACK_STEP_S)
    for k, sid in enumerate(fleet.satellites.ids.tolist()):
        lat, lon, _ = ground_track(geo, k, t_s)
        cuts = np.flatnonzero(np.abs(np.diff(lon)) > 180.0) + 1
        parts = [p for p in zip(np.split(lon, cuts), np.split(lat, cuts)) if len(p[0]) >= 2]
        lines = [LineString(kml_coordinates=fk.Coordinates(coords=list(zip(x.tolist(), y.tolist()))))
                 for x, y in parts]
        tracks.append(Placemark(name=f"{sid} ground track", kml_geometry=MultiGeometry(kml_geometries=lines),
                                times=TimeSpan(begin=_kdt(fleet, 0), end=_kdt(fleet, h.seconds * US))))
    tk = fleet.tasks
    served = _served(fleet, schedule)
    targets = [Placemark(name=f"{tid} ({'observed' if served[i] else 'missed'})", id=f"task-{i}",
                         description=f"weight {tk.weight[i]:g}, window {iso_z(h.utc(round(tk.release_s[i] * US)))} "
                                     f"to {iso_z(h.utc(round(tk.due_s[i] * US)))}",
                         kml_geometry=Point(kml_coordinates=fk.Coordinates(
                             coords=[(float(tk.lon_deg[i]), float(tk.lat_deg[i]))])))
               for i, tid in enumerate(tk.ids.tolist())]
    ti = fleet.task_index()
    obs = []
    for n, (sid, tid, a, b) in enumerate(zip(schedule.satellite.tolist(), schedule.task.tolist(),
                                             schedule.start_us.tolist(), schedule.end_us.tolist())):
        i = ti[tid]
        obs.append(Placemark(name=f"{sid} observes {tid}", id=f"obs-{n}",
                             times=TimeSpan(begin=_kdt(fleet, a), end=_kdt(fleet, b)),
                             kml_geometry=Point(kml_coordinates=fk.Coordinates(
                                 coords=[(float(tk.lon_deg[i]), float(tk.lat_deg[i]))]))))
    doc = fk.Document(name=name or f"eosp fleet schedule {fleet.case_id}".strip(), features=[
        Folder(name="ground tracks", features=tracks), Folder(name="targets", features=targets),
        Folder(name="observations", features=obs)])
    import xml.etree.ElementTree as ET

    ET.register_namespace("", "http://www.opengis.net/kml/2.2")  # <kml xmlns=...>, not <kml:kml>: what viewers expect
    text = fk.KML(features=[doc]).to_string(prettyprint=False, precision=6)
    return _with_mark(text)


def _with_mark(text: str) -> str:
    from eosp.ownership import comment_mark

    if not text.startswith("<?xml"):
        text = '<?xml version="1.0" encoding="UTF-8"?>\n' + text
    head, _, rest = text.partition("\n")
    if not head.rstrip().endswith("?>"):  # the declaration and the document on one line
        cut = text.index("?>") + 2
        head, rest = text[:cut], text[cut:].lstrip("\n")
    return head + "\n" + comment_mark(KML_KIND, xml=True) + "\n" + rest


def write_export(fleet: Fleet, schedule: Schedule, fmt: str, out: str | os.PathLike, overwrite: bool = False,
                 geo: Geometry | None = None) -> Path:
    """Write `schedule` as CZML (fmt "czml", .czml) or KML (fmt "kml", .kml), atomically; an existing file is
    replaced only when eosp wrote it and `overwrite` is given."""
    from eosp.atomic import atomic_path
    from eosp.ownership import check_output

    kind, suffix = (CZML_KIND, ".czml") if fmt == "czml" else (KML_KIND, ".kml")
    path = check_output(out, kind, overwrite=overwrite, suffixes=(suffix,))
    geo = geo or Geometry(fleet)
    if fmt == "czml":
        doc = czml_document(fleet, schedule, geo)
        text = "[" + json.dumps(doc[0], separators=(",", ":")) + "".join(
            ",\n" + json.dumps(p, separators=(",", ":")) for p in doc[1:]) + "]\n"
    else:
        text = kml_document(fleet, schedule, geo)
    with atomic_path(path, suffix=suffix) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path
