"""Pixels: the brush geometry filled anti-aliased by matplotlib's Agg renderer, textured, composed.

The strokes are filled as one compound path of counter-clockwise polygons (``Run.pieces``) with
the non-zero rule, which Agg rasterises as their exact union with anti-aliased edges (no
hand-written rasteriser, no seams inside the stroke). Drips are filled the same way on their own
layer.

**Textured brush** (``texture=True``): the ink's opacity is multiplied by ``T`` in [0, 1]::

    T = 1 − Brush.texture × clip(0.8·M + 0.12·N, 0, 1)
    M = clip((1 − L) + 0.6·D·G + B, 0, 1)  ink missing from the felt under the pixel
    L ~ U(0.88, 1)                         each felt streak's ink load (per run, per streak)
    D = Brush.dry · clip((v/v̄ − 1.3) / 2.5, 0, 1)   dryness: only a fast pen runs dry
    G = (½ + ½ sin(2π f s / 4 + φ))²       streaks along the stroke (s in nib widths)
    B = clip(3·(D − n(s)), 0, 1)           dry-brush breaks: gaps where the streak's smooth noise
                                           n(s) in [0, 1] falls under the dryness
    N ~ U(0, 1)                            per-pixel grain

A pixel's streak is found from its nearest centreline sample (a Euclidean distance transform of
the samples' pixels): its offset across the stroke, over the half width there, split into
``Brush.bristles`` bands, so the streaks follow the stroke's direction. Drips are textured the same
way along their own (vertical) centrelines, never dry. All random numbers come from the seed.

**Spray** (``Brush.soft``, ``Brush.overspray``): the coverage is blurred by a Gaussian of
standard deviation ``soft × nib / 2`` (soft edges), and fine seeded dots of overspray are
sprinkled around the strokes with a density falling off over about a nib.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import PathPatch
from matplotlib.path import Path as MplPath
from numpy.typing import NDArray
from scipy.ndimage import distance_transform_edt

from tagbot.render.brush import Painting, RenderError

__all__ = [
    "DEFAULT_LONG_SIDE",
    "MAX_PIXELS",
    "UNITS_PER_INCH",
    "Rasteriser",
    "View",
    "compose",
    "compound",
    "coverage",
    "make_view",
    "texture_field",
    "write_png",
]

Array = NDArray[np.float64]

UNITS_PER_INCH = {"mm": 25.4, "cm": 2.54, "in": 1.0, "pt": 72.0, "px": 96.0}
"""Units a tag can be in for ``dpi`` to give it its physical size (any other unit counts as mm)."""

DEFAULT_LONG_SIDE = 1200
"""Pixels along the picture's longer side when neither a size nor a dpi is given."""

DEFAULT_DPI = 96.0
"""The resolution written into a PNG when none is given."""

MAX_PIXELS = 36_000_000
"""Refuse pictures with more pixels than this (6000 by 6000; an A3 sheet at 300 dpi is 17.4 M)."""


@dataclass(frozen=True)
class View:
    """A window on the tag's plane mapped onto a pixel grid (y up, rows down)."""

    xmin: float
    ymin: float
    xmax: float
    ymax: float
    width: int
    height: int
    dpi: float = DEFAULT_DPI

    @property
    def scale(self) -> float:
        """Pixels per tag unit."""
        return self.width / (self.xmax - self.xmin)

    def to_pixels(self, xy: Array) -> Array:
        """Tag coordinates to continuous pixel coordinates ``(column, row)``; pixel ``(r, c)``
        covers ``[c, c + 1) × [r, r + 1)``."""
        xy = np.asarray(xy, dtype=float)
        return np.stack(
            [(xy[..., 0] - self.xmin) * self.scale, (self.ymax - xy[..., 1]) * self.scale], axis=-1
        )

    def centres(self) -> tuple[Array, Array]:
        """Tag coordinates of the pixel centres: ``x`` per column and ``y`` per row."""
        x = self.xmin + (np.arange(self.width) + 0.5) / self.scale
        y = self.ymax - (np.arange(self.height) + 0.5) / self.scale
        return x, y


def make_view(
    bounds: tuple[float, float, float, float],
    *,
    size: int | tuple[int, int] | None = None,
    dpi: float | None = None,
    units: str = "mm",
    even: bool = False,
) -> View:
    """The view showing ``bounds`` whole and centred, aspect kept.

    ``size``: ``(width, height)`` in pixels, or one number for the longer side. Without it,
    ``dpi`` gives the tag its physical size (``units`` per inch from :data:`UNITS_PER_INCH`),
    else the longer side is :data:`DEFAULT_LONG_SIDE`. ``dpi`` is also written into PNG files.
    ``even`` rounds the pixel size up to even numbers (for video encoders).
    """
    xmin, ymin, xmax, ymax = (float(b) for b in bounds)
    if dpi is not None and not (math.isfinite(dpi) and dpi > 0):
        raise RenderError(f"dpi: must be a positive number, got {dpi!r}")
    bw, bh = xmax - xmin, ymax - ymin
    if not (bw > 0 and bh > 0 and math.isfinite(bw) and math.isfinite(bh)):
        raise RenderError(f"bounds: need a positive, finite extent, got {bounds!r}")
    if size is None:
        if dpi is not None:
            scale = dpi / UNITS_PER_INCH.get(units, 25.4)
        else:
            scale = DEFAULT_LONG_SIDE / max(bw, bh)
        pixels = (max(1, math.ceil(bw * scale - 1e-6)), max(1, math.ceil(bh * scale - 1e-6)))
    elif isinstance(size, int | np.integer):
        long = _pixels("size", size)
        scale = long / max(bw, bh)
        pixels = (max(1, round(bw * scale)), max(1, round(bh * scale)))
    else:
        if len(size) != 2:
            raise RenderError(f"size: expected (width, height) in pixels, got {size!r}")
        pixels = (_pixels("size width", size[0]), _pixels("size height", size[1]))
    if even:
        pixels = (pixels[0] + pixels[0] % 2, pixels[1] + pixels[1] % 2)
    if pixels[0] * pixels[1] > MAX_PIXELS:
        raise RenderError(
            f"size: {pixels[0]}x{pixels[1]} pixels is more than {MAX_PIXELS:,} (lower --dpi or"
            " --size)"
        )
    scale = min(pixels[0] / bw, pixels[1] / bh)
    cx, cy = 0.5 * (xmin + xmax), 0.5 * (ymin + ymax)
    half_w, half_h = 0.5 * pixels[0] / scale, 0.5 * pixels[1] / scale
    return View(
        cx - half_w,
        cy - half_h,
        cx + half_w,
        cy + half_h,
        pixels[0],
        pixels[1],
        float(dpi) if dpi is not None else DEFAULT_DPI,
    )


def _pixels(name: str, value: object) -> int:
    if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < 1:
        raise RenderError(f"{name}: must be a whole number of pixels >= 1, got {value!r}")
    return int(value)


def compound(*groups: Array) -> MplPath:
    """One path made of closed polygons; each group is an array ``(k, V, 2)``."""
    vertices, codes = [], []
    for polygons in groups:
        polygons = np.asarray(polygons, dtype=float)
        if polygons.size == 0:
            continue
        k, v = polygons.shape[:2]
        vertices.append(np.concatenate([polygons, polygons[:, :1]], axis=1).reshape(-1, 2))
        code = np.full((k, v + 1), MplPath.LINETO, dtype=MplPath.code_type)
        code[:, 0] = MplPath.MOVETO
        code[:, -1] = MplPath.CLOSEPOLY
        codes.append(code.reshape(-1))
    if not vertices:
        return MplPath(np.zeros((0, 2)), np.zeros(0, dtype=MplPath.code_type))
    return MplPath(np.concatenate(vertices), np.concatenate(codes))


class Rasteriser:
    """Fills compound paths in a view and returns their anti-aliased coverage in [0, 1]."""

    def __init__(self, view: View) -> None:
        self.view = view
        # One figure "inch" per pixel: the canvas is exactly width × height pixels.
        self._figure = Figure(figsize=(view.width, view.height), dpi=1, frameon=False)
        self._canvas = FigureCanvasAgg(self._figure)
        axes = self._figure.add_axes((0.0, 0.0, 1.0, 1.0))
        axes.set_axis_off()
        axes.set_xlim(view.xmin, view.xmax)
        axes.set_ylim(view.ymin, view.ymax)
        axes.patch.set_visible(False)
        self._patch = PathPatch(
            compound(), facecolor="black", edgecolor="none", linewidth=0.0, antialiased=True
        )
        self._patch.set_snap(False)
        axes.add_patch(self._patch)

    def coverage(self, path: MplPath) -> NDArray[np.float32]:
        """The fraction of each pixel ``(height, width)`` covered by ``path`` (non-zero rule)."""
        if len(path.vertices) == 0:
            return np.zeros((self.view.height, self.view.width), dtype=np.float32)
        self._patch.set_path(path)
        self._canvas.draw()
        rgba = np.asarray(self._canvas.buffer_rgba())
        if rgba.shape[:2] != (self.view.height, self.view.width):  # pragma: no cover - guard
            raise RuntimeError(f"canvas is {rgba.shape[:2]}, expected {self.view}")
        return rgba[..., 3].astype(np.float32) / np.float32(255.0)


def stroke_path(painting: Painting) -> MplPath:
    """Every pen-down run as one compound path (see :meth:`.brush.Run.pieces`)."""
    return compound(*(piece for run in painting.runs for piece in run.pieces()))


def drip_path(painting: Painting, fractions: Sequence[float] | None = None) -> MplPath:
    """The drips (each ``fractions[k]`` of its length run down; default all of it)."""
    if not painting.drips:
        return compound()
    fractions = [1.0] * len(painting.drips) if fractions is None else list(fractions)
    shown = [(d, f) for d, f in zip(painting.drips, fractions, strict=True) if f > 0]
    if not shown:
        return compound()
    shapes = [d.shapes(f) for d, f in shown]
    return compound(*(group for s in shapes for group in s))


def coverage(
    painting: Painting, view: View, *, texture: bool = False, seed: int | None = None
) -> NDArray[np.float32]:
    """The ink's opacity per pixel ``(height, width)`` in [0, 1]: strokes under drips, textured
    when asked, sprayed by a spray brush."""
    raster = Rasteriser(view)
    alpha = raster.coverage(stroke_path(painting))
    drips = raster.coverage(drip_path(painting)) if painting.drips else None
    if drips is not None:
        alpha = np.maximum(alpha, drips)  # one ink: the drip's top lies inside the stroke
    if texture:
        if seed is None:
            raise RenderError("seed: the textured brush needs a seed")
        alpha = alpha * texture_field(painting, view, seed, where=alpha > 0)
    return spray(np.clip(alpha, 0.0, 1.0).astype(np.float32), painting, view, seed)


def spray(
    alpha: NDArray[np.float32], painting: Painting, view: View, seed: int | None
) -> NDArray[np.float32]:
    """Soft edges and overspray of a spray brush (see the module docstring); ``alpha`` as is
    for other brushes."""
    brush = painting.brush
    if brush.soft <= 0 and brush.overspray <= 0:
        return alpha
    from scipy.ndimage import gaussian_filter

    nib = brush.nib * painting.size * view.scale  # pixels
    out = alpha
    if brush.soft > 0:
        out = gaussian_filter(alpha, sigma=max(0.5 * brush.soft * nib, 0.3), mode="constant")
    if brush.overspray > 0:
        density = gaussian_filter(alpha, sigma=max(0.6 * nib, 1.0), mode="constant")
        rng = np.random.default_rng([0 if seed is None else seed, 3])
        chance = rng.random(alpha.shape, dtype=np.float32)
        dots = (chance < 0.35 * brush.overspray * density) * np.float32(0.55)
        out = out + dots - out * dots
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def _centrelines(painting: Painting) -> dict[str, Array]:
    """Every centreline sample the texture follows: pen-down samples, then drip stations."""
    runs = painting.runs
    nib = painting.brush.nib * painting.size
    parts: dict[str, list[Array]] = {k: [] for k in ("xy", "normal", "half", "line", "s", "v")}
    for k, r in enumerate(runs):
        parts["xy"].append(r.xy)
        parts["normal"].append(r.normal)
        parts["half"].append(0.5 * r.width)
        parts["line"].append(np.full(len(r), k, dtype=float))
        parts["s"].append(np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(r.xy, axis=0).T))]))
        parts["v"].append(r.speed / painting.mean_speed)
    for k, drip in enumerate(painting.drips):
        x, y, half = drip.outline()
        parts["xy"].append(np.column_stack([x, y]))
        parts["normal"].append(np.tile([1.0, 0.0], (len(x), 1)))
        parts["half"].append(half)
        parts["line"].append(np.full(len(x), len(runs) + k, dtype=float))
        parts["s"].append(drip.y - y)
        parts["v"].append(np.zeros(len(x)))
    out = {k: np.concatenate(v) for k, v in parts.items()}
    out["s"] = out["s"] / nib
    return out


def texture_field(
    painting: Painting, view: View, seed: int, where: NDArray[np.bool_] | None = None
) -> NDArray[np.float32]:
    """The textured brush's opacity factor ``T`` per pixel (see the module docstring), computed
    where ``where`` is true (default: everywhere) and 1 elsewhere."""
    brush = painting.brush
    h, w = view.height, view.width
    line = _centrelines(painting)
    pixel = view.to_pixels(line["xy"])  # float64 (column, row)
    cell = np.floor(pixel).astype(np.intp)
    inside = (cell[:, 0] >= 0) & (cell[:, 0] < w) & (cell[:, 1] >= 0) & (cell[:, 1] < h)
    factor = np.ones((h, w), dtype=np.float32)
    if not inside.any():
        return factor
    index = np.full((h, w), -1, dtype=np.int32)
    index[cell[inside, 1], cell[inside, 0]] = np.flatnonzero(inside)
    rows, cols = distance_transform_edt(index < 0, return_distances=False, return_indices=True)
    rng = np.random.default_rng([seed, 2])
    k = brush.bristles
    lines = len(painting.runs) + len(painting.drips)
    load = rng.uniform(0.88, 1.0, (lines, k))
    frequency = rng.uniform(0.5, 1.5, (lines, k, 3))
    phase = rng.uniform(0.0, 2.0 * np.pi, (lines, k, 3))
    grain = rng.random((h, w), dtype=np.float32)

    pick = np.ones((h, w), dtype=bool) if where is None else np.asarray(where, dtype=bool)
    pr, pc = np.nonzero(pick)
    nearest = index[rows[pr, pc], cols[pr, pc]]
    del rows, cols, index
    # Offset across the stroke, in half widths: the pixel's offset from its nearest sample along
    # the normal there (pixel rows point down, y up).
    normal = line["normal"][nearest]
    dx = pc + 0.5 - pixel[nearest, 0]
    dy = pixel[nearest, 1] - (pr + 0.5)
    half = np.maximum(line["half"][nearest] * view.scale, 1e-9)
    across = (dx * normal[:, 0] + dy * normal[:, 1]) / half
    streak = np.clip(np.floor((across + 1.0) * 0.5 * k), 0, k - 1).astype(np.intp)
    which = line["line"][nearest].astype(np.intp)
    s = line["s"][nearest]
    f, p = frequency[which, streak], phase[which, streak]
    # Along the stroke, in nib widths, between samples too (the direction is the normal's turn).
    s = s + (dx * normal[:, 1] - dy * normal[:, 0]) / (brush.nib * painting.size * view.scale)
    dryness = brush.dry * np.clip((line["v"][nearest] - 1.3) / 2.5, 0.0, 1.0)
    stripes = (0.5 + 0.5 * np.sin(2.0 * np.pi * f[:, 0] * s / 4.0 + p[:, 0])) ** 2
    noise = 0.5 + 0.25 * (
        np.sin(2.0 * np.pi * f[:, 1] * s / 3.0 + p[:, 1])
        + np.sin(2.0 * np.pi * f[:, 2] * s / 1.3 + p[:, 2])
    )
    breaks = np.clip(3.0 * (dryness - noise), 0.0, 1.0)
    missing = np.clip((1.0 - load[which, streak]) + 0.6 * dryness * stripes + breaks, 0.0, 1.0)
    value = 1.0 - brush.texture * np.clip(0.8 * missing + 0.12 * grain[pr, pc], 0.0, 1.0)
    factor[pr, pc] = value
    return factor


def parse_color(value: object, name: str) -> tuple[float, float, float, float] | None:
    """A matplotlib colour (name, ``#rrggbb``...) as RGBA floats; None for 'none' or
    'transparent'."""
    from matplotlib.colors import to_rgba

    if value is None or (isinstance(value, str) and value.lower() in ("none", "transparent")):
        return None
    try:
        rgba = to_rgba(value)  # type: ignore[arg-type]
    except ValueError:
        raise RenderError(f"{name}: not a colour: {value!r}") from None
    return (float(rgba[0]), float(rgba[1]), float(rgba[2]), float(rgba[3]))


def compose(
    alpha: NDArray[np.floating],
    color: object = "#111111",
    background: object = "white",
) -> NDArray[np.uint8]:
    """RGBA pixels ``(height, width, 4)``: ink of ``color`` with opacity ``alpha`` over
    ``background`` (None or 'none' for a transparent one)."""
    ink = parse_color(color, "color")
    if ink is None:
        raise RenderError("color: the ink needs a colour, got 'none'")
    paper = parse_color(background, "background")
    a = np.asarray(alpha, dtype=np.float32)[..., None] * np.float32(ink[3])
    rgb = np.asarray(ink[:3], dtype=np.float32)
    if paper is None:
        out = np.concatenate([np.broadcast_to(rgb, (*a.shape[:-1], 3)), a], axis=-1)
    elif paper[3] >= 1.0:  # opaque paper: a plain mix, no division
        under = np.asarray(paper[:3], dtype=np.float32)
        mixed = under + a * (rgb - under)
        out = np.concatenate([mixed, np.ones_like(a)], axis=-1)
    else:
        under = np.asarray(paper[:3], dtype=np.float32)
        top = a + np.float32(paper[3]) * (1 - a)
        mixed = (rgb * a + under * np.float32(paper[3]) * (1 - a)) / np.maximum(top, 1e-12)
        out = np.concatenate([mixed, top], axis=-1)
    return np.round(np.clip(out, 0.0, 1.0) * 255.0).astype(np.uint8)


def write_png(rgba: NDArray[np.uint8], path: str | os.PathLike[str], dpi: float) -> None:
    """Write RGBA pixels as a PNG with its resolution set (Pillow; the bytes are reproducible)."""
    from PIL import Image

    Image.fromarray(np.ascontiguousarray(rgba)).save(path, format="PNG", dpi=(dpi, dpi))
