"""Read GML (Graffiti Markup Language) tags: XML, and #000000book's JSON and JSONP.

GML as found in the wild varies a lot; this reader copes with it by the rules below, all decided
from the file's content (never from the client's name).

**Parsing.** XML is untrusted input: it is parsed with defusedxml, which refuses entity
declarations (so billion-laughs and external-entity files fail at once) and never fetches
anything. Element and attribute names are matched case-insensitively and without namespaces. The
root is ``<gml>`` (any case). ``<environment>`` may be inside ``<header>`` or beside it. A file may
hold several ``<tag>`` elements, each with several ``<drawing>`` elements: every ``<stroke>`` in
the file becomes one trace, in document order, except pen-up moves (``isDrawing="false"``, as an
attribute or a child), which are skipped. A point is a ``<pt>`` with ``<x>`` and ``<y>``; ``<z>``
is not pressure and is ignored, as are pressure, thickness and brush data. Numbers may use a
decimal comma (``0,532``); a point without numeric ``x`` and ``y`` (missing, empty or text) is
skipped, but a coordinate or time that is a number no reader can use (``NaN``, ``inf``, or of
magnitude above 10¹⁵, e.g. ``1e308``) is refused with an error naming the stroke and point, as
the point-file reader refuses it. A stroke with a single usable point is kept (a dot); a file
without any usable point is an error.

**#000000book JSON.** ``{"gml": {"tag": ...}}`` mirrors the XML, objects for elements, lists for
repeated elements (a one-element list may collapse into a bare object: both read the same), and
values may be numbers or strings. ``{"tag": {"gml": "<GML ...>"}}`` holds the XML as a string,
which is parsed as above. Either may be wrapped as JSONP, ``callback(...)``.

**Truncated files.** Old dumps hold files cut off (e.g. at 65,535 bytes). When the XML is
well-formed up to an abrupt end, the points completed before the cut are kept (a ``<pt>`` whose
end tag was not reached is dropped). XML malformed before its end is an error, except junk after
a complete root element, which is ignored. Truncated JSON is an error.

**Orientation.** Coordinates are nominally 0..1 on a screen with y growing downwards; the
``<environment>``'s ``<up>`` vector (default (0, −1), i.e. screen-up) says which way is up when
the tag was drawn. tagbot snaps it to the nearest axis (a quarter turn; accelerometer jitter
must not tilt the drawing) and turns the drawing so that this direction points up: the unit
square is rotated about its centre, so up = (0, −1) gives ``(x, 1 − y)`` and up = (1, 0) (phones
held sideways, e.g. Graffiti Analysis DustTag, Fat Tag) gives ``(y, x)``. This matches Graffiti
Analysis 3's own loader and reads the letters upright on every development capture. Without an
``<up>``, y values above 1 also mark a sideways phone capture (the long screen side is the data's
y, normalised by the short side) and are turned as up = (1, 0).

**Aspect and scale.** One normalised unit becomes :data:`SCALE_MM` = 100 mm, so a tag comes out
about 10 to 15 cm wide. Clients normalise in three ways, told apart by the points themselves:

* coordinates beyond 0..1 (by more than 0.001): both axes were divided by the same length (the
  short screen side; DustTag's y reaches 1.5): kept as they are;
* an ``<environment>`` ``<screenScale>`` (GML4U) is the one length both axes were divided by:
  kept as they are;
* an axis spanning exactly 0..1: the drawing was normalised to its own bounding box (EyeWriter,
  GML4U): kept as it is (when both axes span 0..1 the true aspect is lost);
* otherwise each axis was divided by its own screen side (the GML convention, e.g. Fat Tag):
  with a ``<screenBounds>`` of unequal sides, read as the upright drawing's width × height, the
  axes are stretched to that aspect, the short side staying at one unit (a 480 × 320 screen
  stretches the horizontal axis by 1.5).

Coordinates far outside 0..1 (beyond ±4: not normalised at all, e.g. pixels) are not turned by
the y-above-1 rule; the drawing is moved to start at (0, 0) and scaled so that its longer side is
100 mm.

**Timing.** A point's time is ``<t>`` (GML 1.0) or ``<time>`` (older files), nominally in
seconds. Each trace's ``t`` is on the file's clock, zero at the file's first point, so pen lifts
keep their durations. The rules, in order:

* no time anywhere → ``t`` is None for every trace;
* points without a time before the file's first timed point read as 0 (GML4U omits the zero
  time of the first point); a point without a time after it, or with an unreadable one, makes
  the file untimed;
* times of 10¹¹ or more are unix epoch milliseconds (divided by 1000); 10⁸ or more, unix epoch
  seconds. Every time in such a file must be one: a missing or small one makes the file untimed;
* a stroke whose first time is earlier than the previous stroke's last time restarted the clock
  (EyeWriter restarts it at every ``<drawing>``): it and every later stroke are shifted to start
  when the previous stroke ended; the real pen-lift duration is unknown and becomes zero;
* a time that decreases inside a stroke cannot be repaired: the file is untimed;
* equal consecutive times (zero dt) and long stalls are kept as they are;
* if all times are equal (e.g. all zero) the file is untimed;
* **clock unit**: files are not always in seconds (eyeSaver/EyeWriter files count milliseconds:
  ``<time>`` running 0…2828 is a 2.8 s tag, not a 47-minute one). The unit is read from the
  point rate: the median positive interval between consecutive points of a stroke (zero
  intervals, duplicated times, do not count) must be a plausible sampling interval for a pen,
  touch screen, camera or eye tracker, between :data:`SAMPLE_INTERVAL_MIN` (2 ms, 500 Hz) and
  :data:`SAMPLE_INTERVAL_MAX` (200 ms, 5 Hz), and the whole span at most :data:`SPAN_MAX`
  (one hour). Seconds, milliseconds and microseconds are tried in that order and the first
  plausible one is used; when none is, the times stay in seconds. Epoch times are not
  rescaled (their magnitude fixes the unit). Each trace's ``clock`` says which unit was
  chosen and why, and fit reports repeat it.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from tagbot.errors import InputError
from tagbot.inputs._common import (
    MAX_MAGNITUDE,
    Node,
    XmlDocument,
    check_size,
    cut,
    decode_text,
    json_to_node,
    make_trace,
    number_problem,
    parse_json,
    parse_number,
    parse_xml,
    paused_gc,
)
from tagbot.inputs.trace import Trace

__all__ = [
    "CLOCK_UNITS",
    "EPOCH_MS_MIN",
    "EPOCH_SECONDS_MIN",
    "SAMPLE_INTERVAL_MAX",
    "SAMPLE_INTERVAL_MIN",
    "SCALE_MM",
    "SPAN_MAX",
    "read_gml",
    "read_gml_document",
    "read_gml_json",
]

SCALE_MM = 100.0
"""Millimetres per normalised GML unit (GML coordinates are nominally 0..1)."""

EPOCH_SECONDS_MIN = 1e8
"""Times at or above this (about 3 years in seconds) are unix epoch seconds."""

EPOCH_MS_MIN = 1e11
"""Times at or above this are unix epoch milliseconds."""

SAMPLE_INTERVAL_MIN = 2e-3
"""Shortest plausible median sampling interval, seconds (500 Hz: pen digitisers and touch screens
sample at 60-240 Hz; an integer millisecond clock ticking once per sample is not this fast)."""

SAMPLE_INTERVAL_MAX = 0.2
"""Longest plausible median sampling interval, seconds (5 Hz, e.g. sparse eye-tracker points)."""

SPAN_MAX = 3600.0
"""Longest plausible capture, seconds (stalls included)."""

CLOCK_UNITS = (("seconds", 1.0), ("milliseconds", 1e-3), ("microseconds", 1e-6))
"""Clock units tried, in order, for times that are not epoch times."""

_BEYOND = 1e-3
"""How far past 0..1 a coordinate must lie to show the file was not normalised per axis."""

_SPAN = 1e-4
"""Tolerance for an axis spanning exactly 0..1 (normalised to the drawing's bounding box)."""

_UNNORMALISED = 4.0
"""Coordinates beyond ±this are not normalised at all (e.g. pixels)."""

_PEN_UP = ("false", "0", "no")


def read_gml(data: bytes, name: str = "<gml>") -> list[Trace]:
    """Read a GML file (XML, or #000000book JSON/JSONP) into traces in millimetres, y up.

    ``name`` is used in error messages. Every problem raises :class:`~tagbot.errors.InputError`.
    """
    check_size(data, name)
    head = data[:64].lstrip(b"\xef\xbb\xbf \t\r\n")
    if head.startswith(b"<") or head[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return _read_xml(data, name)
    return read_gml_json(parse_json(decode_text(data, name, "GML file"), name), name)


def _read_xml(data: bytes | str, name: str) -> list[Trace]:
    return read_gml_document(parse_xml(data, name), name)


def read_gml_document(doc: XmlDocument, name: str) -> list[Trace]:
    """Read GML from an XML document already parsed by :func:`~tagbot.inputs._common.parse_xml`."""
    cut = f"; XML truncated: {doc.truncated}" if doc.truncated else ""
    if doc.root is None:
        raise InputError(f"{name}: no points (the XML ends before its root element{cut})")
    if doc.root.name != "gml":
        raise InputError(f"{name}: not GML (the XML root is <{doc.root.name}>, not <gml>)")
    return _interpret(doc.root, name, cut)


def read_gml_json(obj: object, name: str) -> list[Trace]:
    """Read parsed #000000book JSON: ``{"gml": {...}}``, ``{"tag": {"gml": "<GML ...>"}}``."""
    if isinstance(obj, dict):
        fields = {str(k).lower(): v for k, v in obj.items()}
        gml = fields.get("gml")
        if isinstance(gml, str):
            return _read_xml(gml, name)
        if isinstance(gml, dict | list):
            return _interpret(json_to_node("gml", gml), name, "")
        tag = fields.get("tag")
        if isinstance(tag, dict):
            inner = {str(k).lower(): v for k, v in tag.items()}.get("gml")
            if isinstance(inner, str):
                return _read_xml(inner, name)
            return _interpret(json_to_node("gml", obj), name, "")
    raise InputError(f'{name}: JSON but not #000000book GML (no "gml" or "tag" field)')


# --------------------------------------------------------------------------- structure


def _interpret(root: Node, name: str, cut: str) -> list[Trace]:
    """Turn a GML tree into traces."""
    with paused_gc():
        return _traces(root, name, cut)


def _strokes(root: Node) -> Iterator[Node]:
    """The ``<stroke>`` elements in document order (not looking inside them)."""
    stack = [root]
    while stack:
        node = stack.pop()
        if node.name == "stroke":
            yield node
        elif node.children:
            stack.extend(reversed(node.children))


def _traces(root: Node, name: str, cut: str) -> list[Trace]:
    xy: list[tuple[float, float]] = []
    times: list[float | None] = []
    lengths: list[int] = []
    n_pt = n_pen_up = 0
    for k, stroke in enumerate(_strokes(root), start=1):
        if (_field(stroke, "isdrawing") or "").strip().lower() in _PEN_UP:
            n_pen_up += 1
            continue
        before = len(xy)
        i = 0
        for pt in stroke.children:
            if pt.name != "pt":
                continue
            n_pt += 1
            i += 1
            if not pt.closed:
                continue
            fields = _point_fields(pt)
            _refuse_unusable(fields, name, k, i)
            x = parse_number(fields.get("x"))
            y = parse_number(fields.get("y"))
            if x is None or y is None or abs(x) > MAX_MAGNITUDE or abs(y) > MAX_MAGNITUDE:
                continue
            xy.append((x, y))
            times.append(_time(fields))
        if len(xy) > before:
            lengths.append(len(xy) - before)
    if not xy:
        if n_pt:
            why = f"{n_pt} <pt> element{'s' * (n_pt != 1)}, none with numeric <x> and <y>"
        elif n_pen_up:
            why = "only pen-up strokes"
        else:
            why = "no <pt> elements"
        raise InputError(f"{name}: no points ({why}{cut})")
    up, bounds, uniform = _environment(root)
    points = _to_mm(np.array(xy, dtype=np.float64), up, None if uniform else bounds)
    t, clock = _clock(times, lengths)
    traces = []
    start = 0
    for n in lengths:
        rows = slice(start, start + n)
        traces.append(make_trace(name, points[rows], None if t is None else t[rows], clock))
        start += n
    return traces


def _refuse_unusable(fields: dict[str, str | None], name: str, stroke: int, point: int) -> None:
    """Raise InputError if a point's x, y or time is NaN, infinite or beyond MAX_MAGNITUDE."""
    for key in ("x", "y", "t", "time"):
        text = fields.get(key)
        problem = number_problem(text)
        if problem is not None:
            limit = f"; at most {MAX_MAGNITUDE:g} in magnitude" if problem == "out of range" else ""
            raise InputError(
                f"{name}: <stroke> {stroke}, <pt> {point}: {key} is {problem} ({cut(text)}{limit})"
            )


def _field(node: Node, name: str) -> str | None:
    """Text of the child element ``name``, else of the attribute ``name``, else None."""
    child = node.child(name)
    if child is not None:
        return child.text if child.closed else None
    return node.attrs.get(name)


_POINT_FIELDS = frozenset({"x", "y", "t", "time"})


def _point_fields(pt: Node) -> dict[str, str | None]:
    """A point's x, y, t and time: the first child element of each name, else the attribute."""
    fields: dict[str, str | None] = {}
    for c in pt.children:
        if c.name in _POINT_FIELDS and c.name not in fields:
            fields[c.name] = c.text if c.closed else None
    for key, value in pt.attrs.items():
        if key in _POINT_FIELDS and key not in fields:
            fields[key] = value
    return fields


def _time(fields: dict[str, str | None]) -> float | None:
    """A point's time: a number, None if it has none, NaN if it has an unreadable one."""
    text = fields.get("t")
    if text is None:
        text = fields.get("time")
    if text is None or not text.strip():
        return None
    value = parse_number(text)
    return float("nan") if value is None or abs(value) > MAX_MAGNITUDE else value


_Vector = tuple[float, float]


def _environment(root: Node) -> tuple[_Vector | None, _Vector | None, bool]:
    """The first ``up`` and ``screenBounds`` (x, y) found in any ``<environment>``, and whether
    one has a ``screenScale`` (a single length both axes were divided by)."""
    up = bounds = None
    uniform = False
    for env in _environments(root):
        for c in env.children:
            if c.name == "up" and up is None:
                up = _vector(c)
            elif c.name == "screenbounds" and bounds is None:
                bounds = _vector(c)
            elif c.name == "screenscale":
                uniform = uniform or (parse_number(c.text) or 0) > 0
    if bounds is not None and not (
        0 < bounds[0] <= MAX_MAGNITUDE
        and 0 < bounds[1] <= MAX_MAGNITUDE
        and max(bounds) <= MAX_ASPECT * min(bounds)
    ):
        bounds = None  # absurd: a screen is not 10^308 pixels wide, nor a thousand times longer
    return up, bounds, uniform


def _environments(root: Node) -> Iterator[Node]:
    """The ``<environment>`` elements in document order (not looking inside drawings)."""
    stack = [root]
    while stack:
        node = stack.pop()
        if node.name == "environment":
            yield node
        elif node.children and node.name not in ("drawing", "stroke"):
            stack.extend(reversed(node.children))


def _vector(node: Node) -> _Vector | None:
    x = parse_number(_field(node, "x"))
    y = parse_number(_field(node, "y"))
    return None if x is None or y is None else (x, y)


# --------------------------------------------------------------------------- geometry

MAX_ASPECT = 1000.0
"""Largest ``screenBounds`` aspect ratio used to restore a per-axis normalised drawing; a file
with a more elongated (or non-finite, or non-positive) screen is read without stretching."""


def _to_mm(p: np.ndarray, up: _Vector | None, bounds: _Vector | None) -> np.ndarray:
    """Normalised screen coordinates (y down) → upright millimetres (y up); see module doc."""
    lo, hi = p.min(axis=0), p.max(axis=0)
    normalised = bool(np.all(lo >= -_UNNORMALISED) and np.all(hi <= _UNNORMALISED))
    ux, uy = _snap(up) or ((1.0, 0.0) if normalised and hi[1] > 1 + _BEYOND else (0.0, -1.0))
    q = p - 0.5
    h = q[:, 0] * -uy + q[:, 1] * ux + 0.5
    v = q[:, 0] * ux + q[:, 1] * uy + 0.5
    if not normalised:  # e.g. pixels: longer side to one unit, lower-left corner at 0
        h, v = h - h.min(), v - v.min()
        extent = max(float(h.max()), float(v.max()))
        scale = 1.0 / extent if extent > 0 else 1.0
        return np.column_stack([h * scale, v * scale]) * SCALE_MM
    sh, sv = _stretch(lo, hi, bounds)
    return np.column_stack([h * sh, v * sv]) * SCALE_MM


def _snap(up: _Vector | None) -> _Vector | None:
    """The axis direction nearest to ``up`` (x, y), None without a usable vector."""
    if up is None or (up[0] == 0 and up[1] == 0):
        return None
    if abs(up[0]) > abs(up[1]):
        return (float(np.sign(up[0])), 0.0)
    return (0.0, float(np.sign(up[1])))


def _stretch(lo: np.ndarray, hi: np.ndarray, bounds: _Vector | None) -> _Vector:
    """Horizontal and vertical stretch restoring the aspect of per-axis normalised files."""
    if np.any(lo < -_BEYOND) or np.any(hi > 1 + _BEYOND):
        return 1.0, 1.0  # both axes divided by the same (short) side
    if np.any((lo <= _SPAN) & (hi >= 1 - _SPAN)):
        return 1.0, 1.0  # normalised to the drawing's own bounding box
    if bounds is None or bounds[0] == bounds[1]:
        return 1.0, 1.0
    short = min(bounds)
    return bounds[0] / short, bounds[1] / short


# --------------------------------------------------------------------------- timing


def _clock(times: list[float | None], lengths: list[int]) -> tuple[np.ndarray | None, str | None]:
    """Times in seconds on the file's clock, zero at the first point, and how the unit was
    chosen; (None, None) when the file is untimed. See the module doc."""
    first = next((i for i, v in enumerate(times) if v is not None), None)
    if first is None or any(v is None for v in times[first:]):
        return None, None
    t = np.array([0.0 if v is None else v for v in times], dtype=np.float64)
    if not np.all(np.isfinite(t)):
        return None, None
    largest = float(np.max(np.abs(t)))
    epoch = None
    if largest >= EPOCH_MS_MIN:
        if np.min(t) < EPOCH_MS_MIN:
            return None, None
        epoch = ("epoch milliseconds", 1e-3)
    elif largest >= EPOCH_SECONDS_MIN:
        if np.min(t) < EPOCH_SECONDS_MIN:
            return None, None
        epoch = ("epoch seconds", 1.0)
    t = t - t[0]  # differences first: exact for epoch times
    end = None
    offset = 0.0
    start = 0
    for n in lengths:
        seg = t[start : start + n]  # a view: shifted in place
        if np.any(np.diff(seg) < 0):
            return None, None
        seg += offset
        if end is not None and seg[0] < end:  # the clock restarted: shift this and later strokes
            offset += end - seg[0]
            seg[:] = (seg - seg[0]) + end  # starts exactly at ``end`` despite rounding
        end = seg[-1]
        start += n
    t -= t[0]
    if t[-1] <= 0:
        return None, None
    if epoch is not None:
        return t * epoch[1], f"{epoch[0]} (by magnitude)"
    unit, clock = _unit(t, lengths)
    return t * unit, clock


def _unit(t: np.ndarray, lengths: list[int]) -> tuple[float, str]:
    """The clock unit (seconds per tick) read from the point rate and span, and why."""
    inside = np.ones(t.size - 1, dtype=bool)  # intervals between points of the same stroke
    inside[np.cumsum(lengths)[:-1] - 1] = False
    dt = np.diff(t)
    steps = dt[inside & (dt > 0)]
    if steps.size == 0:
        steps = dt[dt > 0]
    tick = float(np.median(steps))
    span = float(t[-1])
    for name, unit in CLOCK_UNITS:
        interval = tick * unit
        if SAMPLE_INTERVAL_MIN <= interval <= SAMPLE_INTERVAL_MAX and span * unit <= SPAN_MAX:
            return unit, (
                f"{name}: median sample interval {tick:.4g} = {interval * 1e3:.3g} ms "
                f"({1 / interval:.3g} Hz), span {span * unit:.3g} s"
            )
    return 1.0, (
        f"seconds (no unit gives a plausible rate: median sample interval {tick:.4g}, "
        f"span {span:.4g}; plausible is {SAMPLE_INTERVAL_MIN * 1e3:g} to "
        f"{SAMPLE_INTERVAL_MAX * 1e3:g} ms and at most {SPAN_MAX:g} s)"
    )
