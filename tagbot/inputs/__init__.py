"""Input traces: pen-down polylines read from captured tags, drawings and point lists.

:func:`load_traces` reads a file and returns its :class:`Trace` list (millimetres for GML and
SVG, the file's own unit for point files; y up; times in seconds when the file has usable
timing). The format is told from the content, never from the file name, since ``.gml`` and
``.json`` are shared with other formats:

* XML whose root is ``<gml>``: GML (:mod:`tagbot.inputs.gml`);
* XML whose root is ``<svg>``: SVG (:mod:`tagbot.inputs.svg`);
* JSON or JSONP with a ``"gml"`` or ``"tag"`` field: #000000book GML (:mod:`tagbot.inputs.gml`);
* other JSON (a list, or ``{"traces": ...}``), and CSV: point files (:mod:`tagbot.inputs.points`);
* text whose first line is a ``.KEYWORD``: UNIPEN (:mod:`tagbot.inputs.unipen`).

Files larger than :data:`MAX_INPUT_BYTES` are refused before being read. Every problem raises
:class:`~tagbot.errors.InputError` with one line naming the file and the problem, e.g.
``tag.gml: not a GML, SVG, point or UNIPEN file (starts with '%PDF-1.4')`` or
``points.csv: line 7: y is not a number ('abc')``.
"""

from __future__ import annotations

import os

from tagbot.errors import InputError
from tagbot.inputs._common import (
    MAX_INPUT_BYTES,
    XmlDocument,
    check_size,
    parse_json,
    parse_xml,
    preview,
    read_input,
    unwrap_jsonp,
)
from tagbot.inputs.gml import SCALE_MM, read_gml, read_gml_document, read_gml_json
from tagbot.inputs.points import (
    looks_like_csv,
    read_points_csv,
    read_points_json,
    read_points_json_object,
)
from tagbot.inputs.svg import read_svg, read_svg_document
from tagbot.inputs.trace import Trace
from tagbot.inputs.unipen import load_unipen, looks_like_unipen, read_unipen

__all__ = [
    "FORMATS",
    "MAX_INPUT_BYTES",
    "SCALE_MM",
    "Trace",
    "detect_format",
    "load_traces",
    "load_unipen",
    "read_gml",
    "read_points_csv",
    "read_points_json",
    "read_svg",
    "read_traces_bytes",
    "read_unipen",
]

FORMATS = ("gml", "svg", "csv", "json", "unipen")
"""What :func:`detect_format` returns: GML (XML or #000000book JSON), SVG, point CSV, point JSON,
UNIPEN."""


def load_traces(path: str | os.PathLike[str]) -> list[Trace]:
    """Read the traces of a GML, SVG, point or UNIPEN file, whatever its extension."""
    return read_traces_bytes(read_input(path), os.fsdecode(path))


def read_traces_bytes(data: bytes, name: str = "<input>") -> list[Trace]:
    """Read the traces held in ``data`` (a whole file's bytes); ``name`` is used in errors."""
    fmt, parsed = _sniff(data, name)
    if fmt == "svg":
        assert isinstance(parsed, XmlDocument)
        return read_svg_document(data, parsed, name)
    if fmt == "gml":
        if isinstance(parsed, XmlDocument):
            return read_gml_document(parsed, name)
        return read_gml_json(parsed, name)
    if fmt == "json":
        return read_points_json_object(parsed, name)
    if fmt == "unipen":
        return read_unipen(data, name)
    return read_points_csv(data, name)


def detect_format(data: bytes, name: str = "<input>") -> str:
    """Tell the format of ``data`` from its content: one of :data:`FORMATS`.

    XML is told apart by its root element, JSON by its top-level fields (both are parsed, the
    XML safely); anything else raises InputError.
    """
    return _sniff(data, name)[0]


def _sniff(data: bytes, name: str) -> tuple[str, object]:
    """The format of ``data`` and its parsed form (XmlDocument, JSON value, or None for CSV)."""
    check_size(data, name)
    first = _first_char(data)
    if not first:
        raise InputError(f"{name}: empty file")
    if first == "<":
        doc = parse_xml(data, name)
        kind = doc.root.name if doc.root is not None else None
        if kind in ("gml", "svg"):
            return kind, doc
        what = f"the XML root is <{kind}>" if kind else "XML without a root element"
        raise InputError(f"{name}: not a GML, SVG, point or UNIPEN file ({what})")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(
            f"{name}: not a GML, SVG, point or UNIPEN file (not UTF-8 text at byte {e.start}; "
            f"starts with {preview(data)})"
        ) from e
    if first in "{[" or unwrap_jsonp(text) is not None:
        obj = parse_json(text, name)
        if isinstance(obj, dict) and {str(k).lower() for k in obj} & {"gml", "tag"}:
            return "gml", obj
        if isinstance(obj, list) or (isinstance(obj, dict) and "traces" in obj):
            return "json", obj
        if isinstance(obj, dict) and "plans" in obj:
            raise InputError(
                f"{name}: a tagbot plan file, not a recording (GML, SVG or points); plans are"
                " drawn, sampled or rendered as they are, not fitted"
            )
        keys = ", ".join(sorted(str(k) for k in obj)[:5]) if isinstance(obj, dict) else ""
        what = f"top-level fields: {keys}" if keys else f"a {type(obj).__name__}"
        raise InputError(f"{name}: JSON, but neither #000000book GML nor points ({what})")
    if first == "." and looks_like_unipen(text):  # before CSV: ".COORD X Y" names x and y
        return "unipen", None
    if looks_like_csv(text):
        return "csv", None
    raise InputError(f"{name}: not a GML, SVG, point or UNIPEN file (starts with {preview(data)})")


def _first_char(data: bytes) -> str:
    """The first non-blank character (after any byte-order mark), '' if none; '<' for UTF-16."""
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        try:
            return data.decode("utf-16").lstrip("\ufeff \t\r\n")[:1]
        except UnicodeDecodeError:
            return "?"
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    return data.lstrip(b" \t\r\n")[:1].decode("latin-1")
