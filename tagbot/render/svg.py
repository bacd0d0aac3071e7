"""SVG: the brush as variable-width outlines, one ``<path>`` per pen-down run.

Each run's outline is the union (by GEOS, through shapely) of the same polygons the raster fills
(:meth:`.brush.Run.pieces`), simplified to within ``SIMPLIFY × size`` of the exact outline: a few
hundred vertices per run, editable in any vector editor. Loops of a letter are holes of the outline
(``fill-rule="evenodd"``). Drips are one ``<path>`` each in their own group.

Coordinates are the tag's, shifted so that the view's top-left corner is the origin and y points
down (``viewBox`` in tag units). The document's ``width`` and ``height`` are its physical size when
the tag's unit is known (mm, cm, in, pt, px) and no pixel size was asked for, else pixels.

The textured brush (``texture=True``) becomes an SVG filter: seeded fractal noise
(``feTurbulence``, its ``seed`` from the render's seed) removing up to ``Brush.texture × 0.6`` of
the ink's opacity, on strokes and drips alike. A spray's soft edges are a Gaussian blur
(``feGaussianBlur``). SVG has no felt streaks, dry breaks or overspray; the PNG does.
"""

from __future__ import annotations

import math
import os
from xml.sax.saxutils import escape

import numpy as np
import shapely

from tagbot.render.brush import Painting, RenderError
from tagbot.render.raster import UNITS_PER_INCH, View, parse_color

__all__ = ["SIMPLIFY", "outlines", "svg_document", "write_svg"]

SIMPLIFY = 1e-4
"""Outlines are simplified to within this fraction of the tag's size."""


def _union(pieces: list[np.ndarray], tolerance: float) -> shapely.Geometry:
    polygons = np.concatenate([shapely.polygons(p) for p in pieces if len(p)])
    polygons = polygons[shapely.area(polygons) > 0]
    union = shapely.union_all(shapely.make_valid(polygons))
    return shapely.simplify(union, tolerance)


def outlines(painting: Painting) -> tuple[list[shapely.Geometry], list[shapely.Geometry]]:
    """The outline of each pen-down run and of each drip, as shapely (multi)polygons."""
    tolerance = SIMPLIFY * painting.size
    runs = [_union(run.pieces(), tolerance) for run in painting.runs]
    drips = []
    for drip in painting.drips:
        drips.append(_union(drip.shapes(), tolerance))
    return runs, drips


def _number(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _path_data(geometry: shapely.Geometry, view: View, decimals: int) -> str:
    """SVG path data of every ring of ``geometry`` in view coordinates (y down)."""
    parts = []
    for polygon in getattr(geometry, "geoms", [geometry]):
        if polygon.is_empty or polygon.geom_type != "Polygon":
            continue
        for ring in [polygon.exterior, *polygon.interiors]:
            xy = np.asarray(ring.coords)[:-1]
            x = xy[:, 0] - view.xmin
            y = view.ymax - xy[:, 1]
            points = " ".join(
                f"{_number(a, decimals)},{_number(b, decimals)}"
                for a, b in zip(x.tolist(), y.tolist(), strict=True)
            )
            parts.append(f"M{points}Z")
    return "".join(parts)


def _paint(color: object, name: str) -> str:
    rgba = parse_color(color, name)
    if rgba is None:
        return 'fill="none"'
    hex_ = "#{:02x}{:02x}{:02x}".format(*(round(c * 255) for c in rgba[:3]))
    opacity = f' fill-opacity="{_number(rgba[3], 3)}"' if rgba[3] < 1 else ""
    return f'fill="{hex_}"{opacity}'


def svg_document(
    painting: Painting,
    view: View,
    *,
    texture: bool = False,
    seed: int | None = None,
    color: object = "#111111",
    background: object = "white",
    pixels: bool = False,
) -> str:
    """The SVG text of ``painting`` in ``view`` (``pixels``: give width and height in pixels)."""
    if parse_color(color, "color") is None:
        raise RenderError("color: the ink needs a colour, got 'none'")
    runs, drips = outlines(painting)
    width, height = view.xmax - view.xmin, view.ymax - view.ymin
    decimals = max(0, math.ceil(-math.log10(painting.size * 1e-5)))
    units = painting.units if painting.units in UNITS_PER_INCH else None
    if pixels or units is None:
        size = f'width="{view.width}" height="{view.height}"'
    else:
        size = f'width="{_number(width, 3)}{units}" height="{_number(height, 3)}{units}"'
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" version="1.1" {size}'
        f' viewBox="0 0 {_number(width, decimals)} {_number(height, decimals)}">',
        "<title>tagbot</title>",
        f"<desc>{_description(painting, texture, seed)}</desc>",
    ]
    brush_filter = ""
    if texture:
        if seed is None:
            raise RenderError("seed: the textured brush needs a seed")
        frequency = 1.0 / (0.5 * painting.brush.nib * painting.size)
        k = 0.6 * painting.brush.texture
        lines += [
            "<defs>",
            '<filter id="texture" x="0" y="0" width="1" height="1">',
            f'<feTurbulence type="fractalNoise" baseFrequency="{_number(frequency, 6)}"'
            f' numOctaves="2" seed="{seed % 2**31}" result="noise"/>',
            '<feColorMatrix in="noise" type="matrix" result="grain"'
            f' values="0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 {_number(-k, 4)} 0 0 0 1"/>',
            '<feComposite in="SourceGraphic" in2="grain" operator="in"/>',
            "</filter>",
            "</defs>",
        ]
        brush_filter = ' filter="url(#texture)"'
    if painting.brush.soft > 0:
        blur = 0.5 * painting.brush.soft * painting.brush.nib * painting.size
        lines += [
            "<defs>",
            '<filter id="soft" x="-10%" y="-10%" width="120%" height="120%">',
            f'<feGaussianBlur stdDeviation="{_number(blur, decimals)}"/>',
            "</filter>",
            "</defs>",
        ]
    if parse_color(background, "background") is not None:
        lines.append(
            f'<rect id="background" width="100%" height="100%" {_paint(background, "background")}/>'
        )
    if painting.brush.soft > 0:
        lines.append('<g id="ink" filter="url(#soft)">')
    lines.append(f'<g id="strokes" {_paint(color, "color")} fill-rule="evenodd"{brush_filter}>')
    for k, geometry in enumerate(runs):
        lines.append(f'<path id="run-{k}" d="{_path_data(geometry, view, decimals)}"/>')
    lines.append("</g>")
    if drips:
        lines.append(f'<g id="drips" {_paint(color, "color")}{brush_filter}>')
        for k, geometry in enumerate(drips):
            lines.append(f'<path id="drip-{k}" d="{_path_data(geometry, view, decimals)}"/>')
        lines.append("</g>")
    if painting.brush.soft > 0:
        lines.append("</g>")
    lines.append("</svg>")
    return "\n".join(lines) + "\n"


def _description(painting: Painting, texture: bool, seed: int | None) -> str:
    brush = painting.brush
    text = (
        f"{len(painting.runs)} pen-down runs, {len(painting.drips)} drips; brush nib"
        f" {brush.nib:g}, flow {brush.flow:g}, thin {brush.thin:g}, spread {brush.spread:g}"
        f"{'; textured' if texture else ''}{f'; seed {seed}' if seed is not None else ''}"
    )
    return escape(text)


def write_svg(text: str, path: str | os.PathLike[str]) -> None:
    """Write SVG text as UTF-8."""
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(text)
