"""``render`` and ``render_array``: a tag or a motion to pixels, SVG, GIF or MP4."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from tagbot.model.plan import Tag
from tagbot.render.animate import (
    Progress,
    check_animation,
    check_frame_pixels,
    frame_times,
    paint_frames,
    write_animation,
)
from tagbot.render.brush import Brush, MotionLike, Painting, RenderError, paint
from tagbot.render.raster import UNITS_PER_INCH, View, compose, coverage, make_view, write_png
from tagbot.render.svg import svg_document, write_svg

if TYPE_CHECKING:
    from tagbot.model.motion import Motion

__all__ = [
    "DEFAULT_DT",
    "FORMATS",
    "MAX_PAINT_SAMPLES",
    "Rendered",
    "check_samples",
    "prepare",
    "render",
    "render_array",
]

DEFAULT_DT = 0.002
"""Seconds between the samples a tag is painted from (smooth outlines at any usual size)."""

MAX_PAINT_SAMPLES = 250_000
"""Most samples one picture or animation is painted from: each costs about 3.5 KB of brush
geometry while painting (so about 0.9 GB at most), 500 s of drawing at :data:`DEFAULT_DT`. A
longer tag is refused before it is sampled; a coarser ``dt`` paints it."""

FORMATS = ("png", "svg", "gif", "mp4")
"""What :func:`render` writes, told by the file's suffix."""

Size = int | tuple[int, int] | None


@dataclass(frozen=True)
class Rendered:
    """What :func:`render` wrote."""

    path: Path
    format: str
    width: int
    height: int
    """Pixels (the SVG's view in pixels)."""
    seed: int | None
    """The seed of the drips and texture (None when neither was asked for)."""
    drips: int
    frames: int | None = None
    """Frames in the animation file (a GIF merges identical consecutive frames)."""
    seconds: float | None = None
    """How long the animation plays."""
    physical: tuple[float, float, str] | None = None
    """An SVG's width and height in physical units, when it has them (else pixels)."""

    def summary(self) -> str:
        """One line for people, saying what the file holds."""
        if self.physical is not None:
            w, h, units = self.physical
            text = f"{w:.1f}x{h:.1f} {units} {self.format.upper()}"
        else:
            text = f"{self.width}x{self.height} {self.format.upper()}"
        if self.frames is not None and self.seconds is not None:
            text += f", {self.frames} frames, {self.seconds:.2f} s"
        if self.drips:
            text += f", {self.drips} drip{'s' * (self.drips != 1)}"
        return text


def format_of(path: str | os.PathLike[str]) -> str:
    """The output format told by the suffix of ``path``."""
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in FORMATS:
        shown = f"'.{suffix}'" if suffix else "no suffix"
        raise RenderError(
            f"{os.fspath(path)}: unknown picture format ({shown}); use .png, .svg, .gif or .mp4"
        )
    return suffix


def check_samples(source: Tag | Motion | MotionLike, dt: float = DEFAULT_DT) -> int:
    """The samples ``source`` is painted from (a tag's every ``dt`` seconds); refuses more than
    :data:`MAX_PAINT_SAMPLES` before any is made."""
    if not isinstance(source, Tag):
        samples = len(source.t)
        if samples > MAX_PAINT_SAMPLES:
            raise RenderError(
                f"the motion has {samples:,} samples to paint (max {MAX_PAINT_SAMPLES:,})"
            )
        return samples
    if not (isinstance(dt, int | float) and dt > 0 and np.isfinite(dt)):
        raise RenderError(f"dt: must be a positive number of seconds, got {dt!r}")
    duration = source.end - source.start
    samples = int(np.ceil(duration / dt)) + 1
    if samples > MAX_PAINT_SAMPLES:
        coarser = duration / (MAX_PAINT_SAMPLES - 1)
        raise RenderError(
            f"dt: {duration:.6g} s of drawing every {dt:g} s is {samples:,} samples to paint "
            f"(max {MAX_PAINT_SAMPLES:,}); a dt of {coarser:.2g} s or more paints it"
        )
    return samples


def prepare(
    source: Tag | Motion | MotionLike,
    *,
    dt: float = DEFAULT_DT,
    drips: bool = False,
    seed: int | None = None,
    texture: bool = False,
    brush: Brush | str | None = None,
) -> Painting:
    """Sample a tag (every ``dt`` seconds) or take a motion as is, and paint it with ``brush`` (a
    :class:`Brush` or a preset's name, see :data:`.brush.PRESETS`). A seed is drawn when drips or
    texture need one and none is given (it is in ``painting.seed``)."""
    check_samples(source, dt)
    if isinstance(source, Tag):
        motion: MotionLike = source.sample(dt)
        units = source.units
    else:
        motion = source
        units = getattr(source, "units", "mm")
    if seed is None and (drips or texture):
        from tagbot.gesture import new_seed

        seed = new_seed()
    if seed is not None and (int(seed) != seed or seed < 0):
        raise RenderError(f"seed: must be a whole number >= 0, got {seed!r}")
    if isinstance(brush, str):
        brush = Brush.preset(brush)
    return paint(motion, brush, drips=drips, seed=seed, units=units)


def _view(
    painting: Painting,
    size: Size,
    dpi: float | None,
    bounds: tuple[float, float, float, float] | None,
    even: bool = False,
) -> View:
    return make_view(
        bounds or painting.bounds(), size=size, dpi=dpi, units=painting.units, even=even
    )


def render_array(
    source: Tag | Motion | MotionLike,
    *,
    size: Size = None,
    dpi: float | None = None,
    dt: float = DEFAULT_DT,
    drips: bool = False,
    seed: int | None = None,
    texture: bool = False,
    brush: Brush | str | None = None,
    color: object = "#111111",
    background: object = "white",
    bounds: tuple[float, float, float, float] | None = None,
) -> NDArray[np.uint8]:
    """The brush render as RGBA pixels ``(height, width, 4)``.

    ``bounds`` (tag units, ``(xmin, ymin, xmax, ymax)``) fixes the window, e.g. to compare renders
    pixel for pixel; by default it is the painting's own (:meth:`.brush.Painting.bounds`). Without
    a seed, drips and texture draw a random one (pass one to repeat a picture).
    """
    painting = prepare(source, dt=dt, drips=drips, seed=seed, texture=texture, brush=brush)
    view = _view(painting, size, dpi, bounds)
    alpha = coverage(painting, view, texture=texture, seed=painting.seed)
    return compose(alpha, color, background)


def render(
    source: Tag | Motion | MotionLike,
    path: str | os.PathLike[str],
    *,
    size: Size = None,
    dpi: float | None = None,
    dt: float = DEFAULT_DT,
    drips: bool = False,
    seed: int | None = None,
    texture: bool = False,
    brush: Brush | str | None = None,
    color: object = "#111111",
    background: object = "white",
    bounds: tuple[float, float, float, float] | None = None,
    fps: float = 25.0,
    speed: float = 1.0,
    hold: float = 1.0,
    progress: Progress | None = None,
) -> Rendered:
    """Paint ``source`` (a Tag, sampled every ``dt`` s, or a Motion) into ``path``.

    The format follows the suffix: ``.png`` (anti-aliased, ``dpi`` written in the file), ``.svg``
    (one outline per pen-down run), ``.gif`` or ``.mp4`` (drawn progressively: ``fps`` frames per
    second, ``speed`` times real time, the finished tag held ``hold`` seconds). ``size`` is
    ``(width, height)`` in pixels or the longer side; without it, ``dpi`` gives the tag its
    physical size, else the longer side is 1200 pixels.
    """
    fmt = format_of(path)
    if fmt in ("gif", "mp4"):
        check_animation(path, fps)
    painting = prepare(source, dt=dt, drips=drips, seed=seed, texture=texture, brush=brush)
    view = _view(painting, size, dpi, bounds, even=fmt == "mp4")
    seed = painting.seed
    common = {"path": Path(path), "format": fmt, "width": view.width, "height": view.height}
    common |= {"seed": seed, "drips": len(painting.drips)}
    if fmt == "png":
        alpha = coverage(painting, view, texture=texture, seed=seed)
        write_png(compose(alpha, color, background), path, view.dpi)
        return Rendered(**common)
    if fmt == "svg":
        text = svg_document(
            painting,
            view,
            texture=texture,
            seed=seed,
            color=color,
            background=background,
            pixels=size is not None,
        )
        write_svg(text, path)
        physical = None
        if size is None and painting.units in UNITS_PER_INCH:
            physical = (view.xmax - view.xmin, view.ymax - view.ymin, painting.units)
        return Rendered(**common, physical=physical)
    timing = frame_times(painting.t0, painting.duration, fps, speed, hold)
    check_frame_pixels(timing, view)
    frames = paint_frames(painting, view, timing, texture=texture, seed=seed, progress=progress)
    written = write_animation(frames, path, view, timing, color=color, background=background)
    return Rendered(**common, frames=written, seconds=timing.seconds)
