"""EOS-Bench: their published per-scenario results (Scenario_Level_Results.xlsx, in their repository) as a table of
anchors by size, for the sizes this machine cannot generate.

Usage::

    python experiments/eosbench_workbook.py THEIR_REPO/Scenario_Level_Results.xlsx [--sheets st-s10-t500 ...]
        [--horizons 12H ...]

Each sheet of their workbook is one scenario family (``st-s10-t500``: agile, standard, 10 satellites, 500 tasks;
``n-`` the non-agile twin; ``sp-co-s200`` constellation configurations; ``sp-re``/``sp-ma`` resource and
manoeuvrability variants), its rows one (size, distribution, horizon, configuration) block per method: TP, TCR, BD,
TM, RT, averaged over their scenarios where the values are fractional.  Prints one Markdown row per block with the
best TP of their methods and who reached it, and SA's, GA's, ACO's, RL's (PPO) and MIP's TP and runtime (the
``_profit`` objective for those run under three); blocks with no figure are left out.

Read with the standard library (an .xlsx is a zip of XML): no spreadsheet package, nothing unpickled.
"""

from __future__ import annotations

import argparse
import sys
import xml.etree.ElementTree as ET
import zipfile

NS = {"m": "http://schemas.openxmlformats.org/spreadsheetml/2006/main",
      "r": "http://schemas.openxmlformats.org/officeDocument/2006/relationships"}
REL = "{http://schemas.openxmlformats.org/package/2006/relationships}"
SHOWN = {"SA": "11-sa_profit", "GA": "08-ga_profit", "ACO": "14-aco_profit", "RL (PPO)": "17-RL",
         "MIP": "01-mip_profit"}
KEY_COLUMNS = ("sat", "task", "distribution", "horizon", "configuration", "Task", "H", "Sat")


def sheets(path: str) -> dict[str, list[dict[str, str]]]:
    """Every sheet of the workbook as rows of {header: cell text}."""
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
        shared = []
        if "xl/sharedStrings.xml" in names:
            shared = ["".join(si.itertext()) for si in ET.fromstring(z.read("xl/sharedStrings.xml")).findall("m:si", NS)]
        rels = {r.get("Id"): r.get("Target") for r in ET.fromstring(z.read("xl/_rels/workbook.xml.rels"))
                if r.tag == REL + "Relationship"}
        out = {}
        for s in ET.fromstring(z.read("xl/workbook.xml")).find("m:sheets", NS):
            target = rels[s.get("{%s}id" % NS["r"])].lstrip("/")
            target = target if target.startswith("xl/") else "xl/" + target
            grid = []
            for row in ET.fromstring(z.read(target)).find("m:sheetData", NS):
                cells = {}
                for c in row:
                    v = c.find("m:v", NS)
                    text = v.text if v is not None and v.text is not None else ""
                    if c.get("t") == "s" and text:
                        text = shared[int(text)]
                    cells["".join(ch for ch in c.get("r") if ch.isalpha())] = text.strip()
                grid.append(cells)
            if not grid:
                continue
            header = grid[0]
            out[s.get("name")] = [{header[col]: val for col, val in r.items() if header.get(col)} for r in grid[1:]]
    return out


def blocks(rows: list[dict[str, str]]) -> list[tuple[dict[str, str], dict[str, dict[str, str]]]]:
    """The sheet's rows grouped by block: the key cells carried down (a block names them on its first row only)."""
    out, key = [], {}
    for r in rows:
        alg = r.get("alg") or r.get("Alg")
        if not alg:
            continue
        if any(r.get(k) for k in KEY_COLUMNS):
            key = {**key, **{k: r[k] for k in KEY_COLUMNS if r.get(k)}}
            out.append((dict(key), {}))
        if out:
            out[-1][1][alg] = r
    return out


def family(alg: str) -> str:
    """A method's name without its number and objective (``11-sa_profit`` -> ``sa``; ``17-RL`` -> ``RL``)."""
    name = alg.split("-", 1)[-1]
    for suffix in ("_profit", "_completion", "_all"):
        if name.endswith(suffix) and not name.endswith("_first" + suffix):
            return name[: -len(suffix)]
    return name


def fmt(x: str, digits: int) -> str:
    try:
        return f"{float(x):,.{digits}f}"
    except ValueError:
        return ""


def table(book: dict[str, list[dict[str, str]]], names: list[str], horizons: list[str] | None = None) -> list[str]:
    lines = ["| family | satellites x tasks, distribution, horizon, configuration | best TP (who) | "
             + " | ".join(f"{m} TP (s)" for m in SHOWN) + " |",
             "|---|---|---|" + "---|" * len(SHOWN)]
    for name in names:
        for key, algs in blocks(book[name]):
            if horizons and (key.get("horizon") or key.get("H")) not in horizons:
                continue
            tp = {a: float(r["TP"]) for a, r in algs.items() if fmt(r.get("TP", ""), 1)}
            if not tp:
                continue
            best = max(tp.values())
            who = sorted({family(a) for a, v in tp.items() if v == best})
            who = ", ".join(who) if len(who) <= 3 else f"{len(who)} methods"
            size = f"{key.get('sat') or key.get('Sat')} x {key.get('task') or key.get('Task')}"
            where = ", ".join(x for x in (key.get("distribution"), key.get("horizon") or key.get("H"),
                                          key.get("configuration")) if x)
            cells = []
            for alg in SHOWN.values():
                r = algs.get(alg, {})
                cells.append(f"{fmt(r.get('TP', ''), 1)} ({fmt(r.get('RT', ''), 0)})" if fmt(r.get("TP", ""), 1)
                             else "")
            lines.append(f"| {name} | {size}, {where} | {best:,.1f} ({who}) | " + " | ".join(cells) + " |")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("workbook", help="their Scenario_Level_Results.xlsx")
    ap.add_argument("--sheets", nargs="*", default=None, help="sheets to print (default: every sheet but Total)")
    ap.add_argument("--horizons", nargs="*", default=None, help="horizons to print (default: all), e.g. 12H 24H")
    ns = ap.parse_args(argv)
    try:
        book = sheets(ns.workbook)
    except (OSError, zipfile.BadZipFile, ET.ParseError, KeyError) as e:
        print(f"{ns.workbook}: not a readable .xlsx workbook ({e})", file=sys.stderr)
        return 2
    names = ns.sheets or [n for n in book if n != "Total"]
    unknown = [n for n in names if n not in book]
    if unknown:
        print(f"{ns.workbook}: no sheet {', '.join(unknown)} (it has {', '.join(book)})", file=sys.stderr)
        return 2
    print("\n".join(table(book, names, ns.horizons)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
