"""``eosp report INSTANCE_DIR SCHEDULE... --out PAGE.html``: one self-contained HTML page of schedules of one
instance (fleets: :mod:`eosp.cli.fleet`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from eosp.cli.load import load_instance
from eosp.errors import InputError


def cmd_report(ns: argparse.Namespace) -> int:
    from eosp.evaluation.html_report import check_report_out, write_report
    from eosp.instances.schedule import read_schedule

    check_report_out(ns.out, ns.overwrite)
    inst = load_instance(ns.instance_dir)
    schedules = {}
    for path in ns.schedules:
        label = Path(path).stem
        if label in schedules:  # same file name in two folders: tell them apart by the folder
            label = f"{Path(path).parent.name}/{label}"
        while label in schedules:
            label += "'"
        schedules[label] = read_schedule(path)
    try:
        out = write_report(inst, schedules, ns.out, title=ns.title or None, overwrite=ns.overwrite,
                           reference=ns.reference or None)
    except InputError as exc:  # the label is the file's stem: name the file the user gave
        path = next((p for p, lab in zip(ns.schedules, schedules) if lab == exc.file), exc.file)
        raise InputError(path, exc.message) from None
    print(f"{out}: {len(schedules)} schedule(s) of {inst.name} ({out.stat().st_size / 1e6:.1f} MB)")
    return 0
