"""Who wrote an output path: eosp marks what it writes, and replaces only what it marked.

The rule, for every command and job (and every writer added later): an existing file or
directory that eosp did not write is never replaced, modified or written into; one that
eosp wrote is replaced only with ``--overwrite``.  The mark travels with the file, in
the file's own format, so that a copy keeps it and a user's file of the same name is
never mistaken for eosp's:

===================  ======================================================  ==================
format               mark                                                    helper
===================  ======================================================  ==================
Parquet              key-value metadata ``eosp.kind = KIND``                 :func:`parquet_mark`
JSON / JSON lines    a key ``"eosp": KIND`` in the (first) object            :func:`json_mark`
CZML                 2nd packet: id ``eosp``, properties ``{"eosp": KIND}``  (by hand)
HTML                 ``<meta name="eosp" content="KIND">`` in the head       :func:`html_mark`
PNG                  a text chunk ``eosp = KIND``                            :func:`png_mark`
SVG, KML, XML        a comment ``<!-- eosp: KIND -->`` after the first line  :func:`comment_mark`
CSV, text            a first line ``# eosp: KIND``                           :func:`comment_mark`
directory            a manifest ``.eosp.json`` holding ``{"eosp": KIND}``    :func:`mark_dir`
===================  ======================================================  ==================

(An interchange instance directory holds exactly its four files: its mark is the key
``"eosp"`` of its ``meta.json``.)

A writer calls :func:`check_output` before any work (the path, ``--overwrite``, its
KIND), writes under a temporary name with :func:`eosp.atomic.atomic_path` /
:func:`eosp.atomic.atomic_dir` and puts the mark in what it writes::

    from eosp.ownership import check_output, json_mark
    out = check_output(ns.out, "fleet-schedule", overwrite=ns.overwrite, suffixes=(".json",))
    with atomic_path(out) as tmp:
        tmp.write_text(json.dumps({**json_mark("fleet-schedule"), "actions": ...}))

:func:`kind_of` reads the mark back (None: not eosp's).  Refusals are one-line
:class:`~eosp.errors.InputError` naming the path.  Standard library only (bottom layer).
"""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path
from typing import Sequence

from eosp.atomic import _check_parent, check_output_file
from eosp.errors import InputError

KEY = "eosp"
MANIFEST = ".eosp.json"
PARQUET_KEY = b"eosp.kind"
HEAD_BYTES = 8192  # where a text format's mark must be

# how refusals name each kind
WHAT = {"schedule": "schedule file", "report": "HTML report", "plot": "plot", "instance": "instance directory",
        "eosp-instance-shard": "shard", "dataset": "data set directory", "evaluation": "evaluation directory",
        "run": "run directory", "sweep": "sweep directory"}


def what(kind: str) -> str:
    """How a refusal names a `kind` ('schedule' -> 'schedule file')."""
    return WHAT.get(kind, kind)


def _a(noun: str) -> str:
    return ("an " if noun[:1].lower() in "aeiou" or noun.startswith(("HTML", "SVG")) else "a ") + noun


# --------------------------------------------------------------------------- marks, one per format

def parquet_mark(kind: str) -> dict[bytes, bytes]:
    """Key-value metadata to add to a Parquet schema (``schema.with_metadata({**old, **parquet_mark(k)})``)."""
    return {PARQUET_KEY: kind.encode()}


def json_mark(kind: str) -> dict[str, str]:
    """The key to add to a JSON object (readers of the format ignore extra keys)."""
    return {KEY: kind}


def html_mark(kind: str) -> str:
    """A tag to put in an HTML page's head."""
    return f'<meta name="{KEY}" content="{kind}">'


def png_mark(kind: str) -> dict[str, str]:
    """Matplotlib's ``savefig(metadata=...)`` for a PNG: a tEXt chunk ``eosp``."""
    return {KEY: kind}


def comment_mark(kind: str, xml: bool = False) -> str:
    """A comment line: ``<!-- eosp: KIND -->`` for SVG/KML/XML (after the XML declaration), else ``# eosp: KIND``
    (first line of a CSV or text file; readers skip it as a comment)."""
    return f"<!-- {KEY}: {kind} -->" if xml else f"# {KEY}: {kind}"


def mark_svg(path: str | os.PathLike, kind: str) -> None:
    """Insert :func:`comment_mark` after the first line (the XML declaration) of an SVG file being written."""
    p = Path(path)
    text = p.read_text(encoding="utf-8")
    head, nl, rest = text.partition("\n")
    p.write_text(head + nl + comment_mark(kind, xml=True) + "\n" + rest, encoding="utf-8")


def mark_dir(path: str | os.PathLike, kind: str, **extra: object) -> Path:
    """Write the manifest that marks a directory as eosp's (`extra`: more keys for it)."""
    p = Path(path) / MANIFEST
    p.write_text(json.dumps({**json_mark(kind), **extra}, indent=1, sort_keys=True) + "\n")
    return p


# --------------------------------------------------------------------------- reading a mark back

def _head(path: Path, n: int = HEAD_BYTES) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(n)
    except OSError:
        return b""


def _json_kind(data: bytes) -> str | None:
    """The mark of the first JSON object (a JSON file, or the first line of JSON lines)."""
    text = data.decode("utf-8", errors="replace").lstrip()
    for candidate in (text, text.partition("\n")[0]):
        try:
            obj = json.loads(candidate)
        except ValueError:
            continue
        if isinstance(obj, dict) and isinstance(obj.get(KEY), str):
            return obj[KEY]
        return None
    return None


def _czml_kind(data: bytes) -> str | None:
    """The mark of a CZML file (a JSON array of packets): the second packet, ``{"id": "eosp", "properties":
    {"eosp": KIND}}`` (the document packet may not carry properties), read on its own with the one before it
    (the file may be far longer than the head read)."""
    text = data.decode("utf-8", errors="replace")
    dec, at = json.JSONDecoder(), text.find("[") + 1
    if at <= 0 or text[:at - 1].strip():
        return None
    for _ in range(2):
        while at < len(text) and text[at] in " \t\r\n,":
            at += 1
        try:
            obj, at = dec.raw_decode(text, at)
        except ValueError:
            return None
        props = obj.get("properties") if isinstance(obj, dict) and obj.get("id") == KEY else None
        if isinstance(props, dict) and isinstance(props.get(KEY), str):
            return props[KEY]
    return None


def _png_kind(path: Path) -> str | None:
    """The ``eosp`` tEXt chunk of a PNG file (chunks read up to the image data)."""
    try:
        with open(path, "rb") as fh:
            if fh.read(8) != b"\x89PNG\r\n\x1a\n":
                return None
            while True:
                head = fh.read(8)
                if len(head) < 8:
                    return None
                size, ctype = struct.unpack(">I4s", head)
                if ctype in (b"IDAT", b"IEND") or size > 1 << 20:
                    return None
                body = fh.read(size)
                fh.read(4)  # CRC
                if ctype == b"tEXt":
                    key, _, value = body.partition(b"\0")
                    if key == KEY.encode():
                        return value.decode("latin-1")
    except OSError:
        return None


def _parquet_kind(path: Path) -> str | None:
    try:
        import pyarrow.parquet as pq

        md = pq.read_schema(path).metadata or {}
    except Exception:  # noqa: BLE001 - not Parquet, unreadable: not ours
        return None
    value = md.get(PARQUET_KEY)
    return value.decode(errors="replace") if value else None


def _text_kind(data: bytes, suffix: str) -> str | None:
    """The mark of a text format: the head's meta tag (HTML), the comment after the first line (SVG, KML,
    XML), the first line (CSV, text)."""
    text = data.decode("utf-8", errors="replace")
    if suffix in (".html", ".htm"):
        opening, closing = f'<meta name="{KEY}" content="', '">'
    elif suffix in (".svg", ".kml", ".xml"):
        opening, closing = f"<!-- {KEY}: ", " -->"
        text = text.partition("\n")[2].partition("\n")[0]
    else:
        opening, closing = f"# {KEY}: ", "\n"
        text = text.partition("\n")[0] + "\n"
    at = text.find(opening)
    if suffix not in (".html", ".htm") and at != 0:  # the comment opens its line: a mark, not a mention
        return None
    if at >= 0:
        end = text.find(closing, at + len(opening))
        if end > at:
            return text[at + len(opening):end].strip()
    return None


def kind_of(path: str | os.PathLike) -> str | None:
    """The KIND eosp marked `path` with, or None when it bears no mark (not eosp's, or not there)."""
    p = Path(path)
    if p.is_dir():
        for name in (MANIFEST, "meta.json"):  # an instance directory's mark is in its meta.json
            if (p / name).is_file():
                kind = _json_kind(_head(p / name, 1 << 20))
                if kind:
                    return kind
        return None
    if not p.is_file():
        return None
    suffix = p.suffix.lower()
    if suffix == ".parquet":
        return _parquet_kind(p)
    if suffix == ".png":
        return _png_kind(p)
    if suffix in (".json", ".jsonl"):
        return _json_kind(_head(p, 1 << 20))
    if suffix == ".czml":
        return _czml_kind(_head(p))
    return _text_kind(_head(p), suffix)


# --------------------------------------------------------------------------- the one check every writer makes

def check_output(path: str | os.PathLike, kind: str, overwrite: bool = False, *, suffixes: Sequence[str] = (),
                 directory: bool = False, reuse: bool = False) -> Path:
    """Refuse, before any work, an output path that eosp must not write; the path otherwise.

    An existing path is replaced only when eosp marked it with `kind` and `overwrite` is given.
    `directory`: the output is a directory (else a file with one of `suffixes`).  `reuse`: a job that
    resumes may write into an existing directory of its `kind`, or into an empty directory, without
    `overwrite`.  One-line :class:`InputError` naming the path otherwise.
    """
    p = Path(path)
    noun = what(kind)
    if not directory:
        check_output_file(p, suffixes, what=noun)  # directory, extension, not a regular file, parent
    elif p.exists() or p.is_symlink():
        if not p.is_dir():
            raise InputError(p, f"exists and is not a directory: refusing to replace it with {_a(noun)}")
        if reuse and not any(p.iterdir()):
            return p
    if not (p.exists() or p.is_symlink()):
        _check_parent(p)
        return p
    if kind_of(p) != kind:
        into = " or write into it" if directory else ""
        raise InputError(p, f"exists and is not {_a(noun)} written by eosp: refusing to replace it{into} "
                            "(choose another path)")
    if reuse:
        return p
    if not overwrite:
        raise InputError(p, "already exists (use --overwrite to replace it)")
    return p
