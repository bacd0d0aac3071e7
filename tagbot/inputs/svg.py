"""Read SVG drawings: every subpath of every shape becomes an untimed trace, in millimetres.

The SVG is first parsed with defusedxml (entity declarations refused, nothing fetched), and
``<use>`` references are expanded on paper: a file whose ``<use>`` elements refer to themselves or
would expand to more than :data:`MAX_SVG_ELEMENTS` elements (a "use bomb") is refused. Only then
does svgelements interpret it: paths (lines, quadratic and cubic Béziers, elliptical arcs),
polylines, polygons, rectangles, circles, ellipses and lines, through nested transforms,
``viewBox`` and units (user units are CSS pixels, 96 per inch). Text and images are ignored, and
so are shapes inside ``<defs>``, ``<clipPath>`` and ``<pattern>`` unless a ``<use>`` draws them;
svgelements does draw shapes inside a ``<symbol>``, ``<marker>`` or ``<mask>`` placed outside
``<defs>`` (drawing programs put those inside ``<defs>``).

Curves are flattened to polylines whose distance from the true curve is at most
:data:`SVG_FLATNESS_MM`: Béziers with Wang's bound on the number of uniform steps
(``n = √(max‖second difference‖ · d(d−1) / (8 · tolerance))`` for degree d), arcs with the
sagitta bound of the ellipse's major semi-axis. Coordinates are converted from pixels to
millimetres (25.4 / 96) and y is negated, so y points up and the drawing lies below the x axis
when the SVG's origin is its top-left corner. A subpath that only moves is dropped; a closed one
ends on its first point.
"""

from __future__ import annotations

import io
import math
from typing import Any

import numpy as np

from tagbot.errors import InputError
from tagbot.inputs._common import (
    MAX_MAGNITUDE,
    Node,
    XmlDocument,
    check_size,
    make_trace,
    parse_xml,
)
from tagbot.inputs.trace import Trace

__all__ = [
    "MAX_SVG_ELEMENTS",
    "MAX_SVG_POINTS",
    "MM_PER_PX",
    "SVG_FLATNESS_MM",
    "read_svg",
    "read_svg_document",
]

SVG_FLATNESS_MM = 0.05
"""Largest distance (mm) between a flattened curve and the true one."""

MM_PER_PX = 25.4 / 96
"""Millimetres per SVG user unit (CSS pixel at 96 per inch)."""

MAX_SVG_ELEMENTS = 1_000_000
"""Most elements an SVG may have once its ``<use>`` references are expanded."""

MAX_SVG_POINTS = 5_000_000
"""Most points flattening may produce (a bound on memory for huge or absurdly scaled curves)."""


def read_svg(data: bytes, name: str = "<svg>") -> list[Trace]:
    """Read an SVG file into untimed traces in millimetres, y up; see the module doc."""
    check_size(data, name)
    return read_svg_document(data, parse_xml(data, name), name)


def read_svg_document(data: bytes, doc: XmlDocument, name: str) -> list[Trace]:
    """Read SVG whose bytes ``data`` were already parsed safely into ``doc``."""
    if doc.truncated:
        raise InputError(f"{name}: SVG is cut off ({doc.truncated})")
    if doc.root is None or doc.root.name != "svg":
        root = "no root element" if doc.root is None else f"the XML root is <{doc.root.name}>"
        raise InputError(f"{name}: not SVG ({root})")
    _check_use_expansion(doc.root, name)
    shapes = _shape_segments(data, name)
    flattener = _Flattener(SVG_FLATNESS_MM / MM_PER_PX, name)
    polylines: list[np.ndarray] = []
    try:
        for segments in shapes:
            polylines.extend(flattener.subpaths(segments))
    except _OutOfRange:
        raise InputError(
            f"{name}: SVG coordinates are not finite or beyond {MAX_MAGNITUDE:g} pixels"
        ) from None
    if not polylines:
        raise InputError(f"{name}: no points (no drawable shapes)")
    scale = [MM_PER_PX, -MM_PER_PX]
    return [make_trace(name, p * scale + 0.0, None) for p in polylines]  # + 0.0: no -0.0


def _shape_segments(data: bytes, name: str) -> list[list[Any]]:
    """Every shape's path segments, transformed into document pixels, by svgelements."""
    import svgelements

    try:
        svg = svgelements.SVG.parse(io.BytesIO(data), reify=True, ppi=96.0)
        return [
            list(svgelements.Path(e).segments(transformed=True))
            for e in svg.elements()
            if isinstance(e, svgelements.Shape)
        ]
    except RecursionError as e:
        raise InputError(f"{name}: SVG is nested too deeply") from e
    except Exception as e:  # svgelements raises many kinds on malformed attributes
        raise InputError(f"{name}: unreadable SVG ({type(e).__name__}: {e})") from e


def _check_use_expansion(root: Node, name: str) -> None:
    """Refuse ``<use>`` cycles and files that would expand beyond MAX_SVG_ELEMENTS."""
    ids: dict[str, Node] = {}
    for node in root.iter():
        if "id" in node.attrs:
            ids[node.attrs["id"]] = node  # svgelements keeps the last of duplicate ids

    def target(node: Node) -> Node | None:
        href = node.attrs.get("href") if node.name == "use" else None
        return ids.get(href[1:]) if href else None

    in_progress = -1
    size: dict[int, int] = {}
    stack: list[tuple[Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        ref = target(node)
        if done:
            total = 1 + sum(size[id(c)] for c in node.children)
            size[key] = min(total + (size[id(ref)] if ref is not None else 0), MAX_SVG_ELEMENTS + 1)
            continue
        if key in size:
            if size[key] == in_progress:
                raise InputError(f"{name}: SVG <use> elements refer to themselves")
            continue
        size[key] = in_progress
        stack.append((node, True))
        stack.extend((c, False) for c in node.children)
        if ref is not None:
            stack.append((ref, False))
    if size[id(root)] > MAX_SVG_ELEMENTS:
        raise InputError(
            f"{name}: SVG expands to more than {MAX_SVG_ELEMENTS} elements through <use> "
            "(refused as untrusted input)"
        )


class _Flattener:
    """Turns svgelements path segments into polylines (pixels), within ``tol`` of the curves."""

    def __init__(self, tol: float, name: str) -> None:
        self.tol = tol
        self.name = name
        self.budget = MAX_SVG_POINTS

    def subpaths(self, segments: list[Any]) -> list[np.ndarray]:
        import svgelements as se

        out: list[np.ndarray] = []
        current: list[np.ndarray] | None = None
        for seg in segments:
            if isinstance(seg, se.Move):
                self._flush(current, out)
                current = None
                continue
            if seg.start is None or seg.end is None:
                continue  # path data in error (no initial moveto): draws nothing
            if isinstance(seg, se.Close):
                if current is not None:
                    end = _xy(seg.end)
                    if not np.array_equal(end, current[-1][-1]):
                        current.append(end[None, :])
                self._flush(current, out)
                current = None
                continue
            if current is None:
                current = [_xy(seg.start)[None, :]]
            if isinstance(seg, se.CubicBezier):
                pts = self._bezier([seg.start, seg.control1, seg.control2, seg.end])
            elif isinstance(seg, se.QuadraticBezier):
                pts = self._bezier([seg.start, seg.control, seg.end])
            elif isinstance(seg, se.Arc):
                pts = self._arc(seg)
            else:  # Line, and any straight segment kind
                pts = _xy(seg.end)[None, :]
            current.append(pts)
        self._flush(current, out)
        return out

    def _flush(self, current: list[np.ndarray] | None, out: list[np.ndarray]) -> None:
        if current is None or len(current) < 2:
            return  # nothing, or a subpath that only moved
        out.append(np.concatenate(current))

    def _steps(self, n: float) -> int:
        if not math.isfinite(n) or n > self.budget:
            raise InputError(
                f"{self.name}: SVG curves need more than {MAX_SVG_POINTS} points to flatten"
            )
        steps = max(1, math.ceil(n))
        self.budget -= steps
        return steps

    def _bezier(self, control: list[Any]) -> np.ndarray:
        p = np.array([_xy(c) for c in control])
        d = len(p) - 1
        second = p[2:] - 2 * p[1:-1] + p[:-2]
        m = float(np.max(np.hypot(second[:, 0], second[:, 1])))
        n = self._steps(math.sqrt(m * d * (d - 1) / (8 * self.tol)) if m > 0 else 1)
        s = np.arange(1, n + 1)[:, None] / n
        coef = [math.comb(d, k) * s**k * (1 - s) ** (d - k) for k in range(d + 1)]
        return sum(c * pk for c, pk in zip(coef, p, strict=True))

    def _arc(self, arc: Any) -> np.ndarray:
        center, prx, pry = _xy(arc.center), _xy(arc.prx), _xy(arc.pry)
        axes = np.column_stack([prx - center, pry - center])  # conjugate semi-diameters
        sweep = abs(float(arc.sweep))
        if not math.isfinite(sweep):
            raise _OutOfRange
        radius = float(np.linalg.norm(axes, 2))  # the ellipse's major semi-axis
        # The sagitta r·(1 − cos(step / 2)) = 2r·sin²(step / 4) stays within the tolerance.
        step = 4 * math.asin(math.sqrt(min(1.0, self.tol / (2 * radius)))) if radius > 0 else 4.0
        n = self._steps(sweep / step if step > 0 else math.inf)
        pts = np.asarray(arc.npoint(np.arange(1, n + 1) / n), dtype=np.float64)
        pts[-1] = _xy(arc.end)
        if not np.all(np.isfinite(pts)):
            raise _OutOfRange
        return pts


def _xy(point: Any) -> np.ndarray:
    """A point as an array; non-finite or huge coordinates are refused (no overflow later)."""
    p = np.array([float(point[0]), float(point[1])], dtype=np.float64)
    if not (np.all(np.isfinite(p)) and np.all(np.abs(p) <= MAX_MAGNITUDE)):
        raise _OutOfRange
    return p


class _OutOfRange(Exception):
    """A coordinate is not finite or beyond MAX_MAGNITUDE (turned into an InputError)."""
