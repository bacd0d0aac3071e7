"""The brush: a round brush swept along a motion, thinner where the pen is fast, and paint drips.

Everything here is geometry in the tag's own units; :mod:`.raster` and :mod:`.svg` turn it into
pixels or vector paths. Only pen-down samples are painted, each pen-down run on its own.

**Width law** (paper §5: "an inverse function of the velocity")::

    w(v) = w_min + (w_max − w_min) · exp(−v / v_ref)
    w_max = Brush.width × S       S: the tag's size, the diagonal of its pen-down bounding box
    w_min = Brush.thin × w_max
    v_ref = Brush.speed_ref × v̄   v̄: the mean pen-down speed (pen-down path length / time)

Scaling a tag's positions or its clock scales the widths with the tag: the picture is the same.

**Drips** (paper §5: "a random drip effect where the velocity is under a certain threshold"):
a pen-down sample is *slow* when its speed is below ``v_drip = Brush.drip_speed × v̄``; its
slowness is ``s = 1 − v / v_drip`` in (0, 1]. Each maximal run of consecutive slow samples (an
episode, where the pen lingers: run starts and ends, cusps) holds the ink
``q = 1 − exp(−Σ s·Δt / Brush.drip_time)``. With a generator seeded by ``seed``, each episode drips
with probability ``Brush.drip_chance × q``, from its slowest sample (shifted sideways by
``(U' − 0.5) × 0.3 × w(sample)``), straight down (−y):

    length = Brush.drip_length × S × q × (0.5 + 0.5·U)      U, U' uniform in [0, 1)
    width  = w(sample) × (0.15 + 0.25·q), tapering to 0.8 of that, ending in a round bulb of
             radius 0.75 × width

so slower and longer lingering gives longer, wider drips, and nothing drips under fast samples.
``drip_time`` is in seconds on purpose: a pen that really lingers longer drips more.
The same seed gives the same drips; the random draws per episode are fixed in number, so the
drips do not depend on the texture or the output format.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
from numpy.typing import NDArray

from tagbot.errors import TagbotError
from tagbot.io.motionfile import MotionLike

__all__ = [
    "Brush",
    "Drip",
    "MotionLike",
    "Painting",
    "RenderError",
    "Run",
    "disc",
    "paint",
]

Array = NDArray[np.float64]

DISC_VERTICES = 24
"""Vertices of the polygons standing for round brush tips and drip bulbs."""


class RenderError(TagbotError, ValueError):
    """A rendering or plotting request is invalid (size, format, brush parameter, colour...)."""


@dataclass(frozen=True)
class Brush:
    """The brush's parameters; see the module docstring for the laws they enter."""

    width: float = 0.022
    """Widest brush (at rest), as a fraction of the tag's size."""
    thin: float = 0.2
    """Narrowest brush (at full speed), as a fraction of the widest."""
    speed_ref: float = 1.0
    """``v_ref``: the speed scale of the width law, as a fraction of the mean pen-down speed."""
    drip_speed: float = 0.15
    """Samples slower than this fraction of the mean pen-down speed may drip."""
    drip_chance: float = 0.7
    """Probability that an episode holding the most ink (q → 1) drips."""
    drip_length: float = 0.12
    """Longest drip, as a fraction of the tag's size."""
    drip_time: float = 0.25
    """Seconds of lingering (weighted by slowness) that load a drip with 63% of the most ink."""
    drip_grow: float = 0.4
    """Seconds (tag clock) a drip takes to run down to its full length in animations."""
    texture: float = 0.7
    """Strength of the textured brush in [0, 1]: how much bristle streaks and grain remove."""
    bristles: int = 11
    """Bristle streaks across the brush in the textured brush."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, int | float) and math.isfinite(value)):
                raise RenderError(f"brush.{f.name}: must be a finite number, got {value!r}")
        positive = ("width", "speed_ref", "drip_speed", "drip_length", "drip_time", "drip_grow")
        for name in positive:
            if getattr(self, name) <= 0:
                raise RenderError(f"brush.{name}: must be > 0, got {getattr(self, name)!r}")
        for name in ("thin", "drip_chance", "texture"):
            if not 0 <= getattr(self, name) <= 1:
                raise RenderError(f"brush.{name}: must be in [0, 1], got {getattr(self, name)!r}")
        if int(self.bristles) != self.bristles or self.bristles < 1:
            raise RenderError(f"brush.bristles: must be a whole number >= 1, got {self.bristles!r}")

    def widths(self, speed: Array, size: float, mean_speed: float) -> Array:
        """The width law ``w(v)`` for speeds ``speed`` (see the module docstring)."""
        w_max = self.width * size
        w_min = self.thin * w_max
        v_ref = self.speed_ref * mean_speed
        return w_min + (w_max - w_min) * np.exp(-np.asarray(speed, dtype=float) / v_ref)


@dataclass(frozen=True, eq=False)
class Run:
    """One pen-down run's samples and the brush along it."""

    rows: slice
    """The run's samples in the motion."""
    t: Array
    xy: Array
    speed: Array
    width: Array
    """Brush width at each sample, tag units."""
    normal: Array
    """Unit normal (left of the direction of travel) at each sample, ``(N, 2)``."""

    def __len__(self) -> int:
        return len(self.t)

    def pieces(self, start: int = 0, stop: int | None = None) -> list[Array]:
        """The brush swept over samples ``start..stop`` as counter-clockwise polygons whose union
        is the sweep of a round brush: a disc at every sample and, between consecutive samples,
        the quadrilateral joining the two discs' outer common tangents (zero-area where one disc
        holds the other). Returns ``[quads (k − 1, 4, 2), discs (k, V, 2)]``."""
        stop = len(self) if stop is None else min(stop, len(self))
        xy, r = self.xy[start:stop], 0.5 * self.width[start:stop]
        if len(xy) < 2:
            return [disc(xy, r)]
        c1, c2, r1, r2 = xy[:-1], xy[1:], r[:-1], r[1:]
        chord = c2 - c1
        d = np.hypot(chord[:, 0], chord[:, 1])
        ok = d > np.abs(r1 - r2) * (1 + 1e-9)
        safe = np.where(ok, d, 1.0)
        u = chord / safe[:, None]
        n = np.column_stack([-u[:, 1], u[:, 0]])
        sin = np.where(ok, (r1 - r2) / safe, 0.0)
        cos = np.sqrt(np.clip(1.0 - sin * sin, 0.0, 1.0))
        left = sin[:, None] * u + cos[:, None] * n
        right = sin[:, None] * u - cos[:, None] * n
        quads = np.stack(
            [
                c1 + r1[:, None] * right,
                c2 + r2[:, None] * right,
                c2 + r2[:, None] * left,
                c1 + r1[:, None] * left,
            ],
            axis=1,
        )
        quads[~ok] = c1[~ok, None, :]
        return [quads, disc(xy, r)]


@dataclass(frozen=True)
class Drip:
    """A run of paint hanging straight down from a slow sample."""

    x: float
    y: float
    """Where it starts (the top, inside the stroke), tag units."""
    length: float
    """From the top to the centre of the bulb at full length."""
    width: float
    """Width at the top."""
    t: float
    """When its sample was painted, seconds on the motion's clock."""
    sample: int
    """Its slowest sample, an index into the motion."""
    ink: float
    """The episode's ink ``q`` in (0, 1)."""

    @property
    def bulb(self) -> float:
        """Radius of the bulb at the bottom."""
        return 0.75 * self.width

    def shapes(self, fraction: float = 1.0) -> tuple[Array, Array]:
        """The body (a counter-clockwise quadrilateral ``(4, 2)``) and the bulb (a disc polygon
        ``(V, 2)``) when ``fraction`` of its length has run down."""
        length = self.length * min(max(fraction, 0.0), 1.0)
        top, bottom = 0.5 * self.width, 0.4 * self.width
        y_end = self.y - length
        body = np.array(
            [
                [self.x - top, self.y],
                [self.x - bottom, y_end],
                [self.x + bottom, y_end],
                [self.x + top, self.y],
            ]
        )
        radius = self.bulb * (0.7 + 0.3 * min(max(fraction, 0.0), 1.0))
        return body, disc(np.array([[self.x, y_end]]), np.array([radius]))[0]


@dataclass(frozen=True, eq=False)
class Painting:
    """A motion as brush geometry: pen-down runs, their widths, and the drips."""

    runs: tuple[Run, ...]
    drips: tuple[Drip, ...]
    brush: Brush
    size: float
    """The tag's size ``S`` (pen-down bounding-box diagonal), tag units."""
    mean_speed: float
    """``v̄``, tag units per second."""
    t0: float
    """The motion's first sample time."""
    t1: float
    """The motion's last sample time."""
    seed: int | None = None
    units: str = "mm"
    samples: int = field(default=0)
    """Pen-down samples painted."""

    @property
    def duration(self) -> float:
        return self.t1 - self.t0

    def bounds(self, pad: float = 0.02) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` holding every brush position and drip, padded by
        ``pad × size``."""
        lo = np.min([(r.xy - r.width[:, None] / 2).min(axis=0) for r in self.runs], axis=0)
        hi = np.max([(r.xy + r.width[:, None] / 2).max(axis=0) for r in self.runs], axis=0)
        for drip in self.drips:
            body, bulb = drip.shapes()
            shape = np.concatenate([body, bulb])
            lo, hi = np.minimum(lo, shape.min(axis=0)), np.maximum(hi, shape.max(axis=0))
        margin = pad * self.size
        return (
            float(lo[0] - margin),
            float(lo[1] - margin),
            float(hi[0] + margin),
            float(hi[1] + margin),
        )


def disc(centres: Array, radii: Array, vertices: int = DISC_VERTICES) -> Array:
    """Counter-clockwise polygons ``(k, vertices, 2)`` circumscribing discs (so that a chain of
    them never shows the polygon's flats inside the true circle)."""
    angle = np.linspace(0.0, 2.0 * np.pi, vertices, endpoint=False)
    ring = np.column_stack([np.cos(angle), np.sin(angle)]) / math.cos(math.pi / vertices)
    return centres[:, None, :] + np.asarray(radii, dtype=float)[:, None, None] * ring[None]


def _pen_down_runs(pen: np.ndarray) -> list[slice]:
    """Slices of the maximal runs of ``pen != 0``."""
    down = np.concatenate([[0], (np.asarray(pen) != 0).astype(np.int8), [0]])
    edges = np.flatnonzero(np.diff(down))
    return [slice(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _directions(xy: Array, v: Array) -> Array:
    """Unit directions of travel: the velocity's, else the path's, else the nearest known one."""
    speed = np.hypot(v[:, 0], v[:, 1])
    scale = float(speed.max(initial=0.0))
    direction = np.full_like(xy, np.nan)
    ok = speed > 1e-9 * scale if scale > 0 else np.zeros(len(xy), dtype=bool)
    direction[ok] = v[ok] / speed[ok, None]
    if len(xy) > 1:
        d = np.gradient(xy, axis=0)
        norm = np.hypot(d[:, 0], d[:, 1])
        extent = float(np.ptp(xy, axis=0).max())
        fill = ~ok & (norm > 1e-12 * max(extent, 1e-300))
        direction[fill] = d[fill] / norm[fill, None]
        ok |= fill
    if not ok.any():
        direction[:] = (1.0, 0.0)
        return direction
    index = np.arange(len(xy))
    previous = np.maximum.accumulate(np.where(ok, index, -1))
    following = np.minimum.accumulate(np.where(ok, index, len(xy))[::-1])[::-1]
    nearest = np.where(previous >= 0, previous, following)
    use_next = (following < len(xy)) & ((previous < 0) | (following - index < index - previous))
    nearest = np.where(use_next, following, nearest)
    return direction[nearest]


def paint(
    motion: MotionLike,
    brush: Brush | None = None,
    *,
    drips: bool = False,
    seed: int | None = None,
    units: str = "mm",
) -> Painting:
    """The brush geometry of ``motion``'s pen-down samples, with drips when asked (seeded)."""
    brush = brush or Brush()
    t = np.asarray(motion.t, dtype=float)
    xy = np.asarray(motion.xy, dtype=float)
    v = np.asarray(motion.v, dtype=float)
    pen = np.asarray(motion.pen)
    if t.ndim != 1 or xy.shape != (len(t), 2) or v.shape != (len(t), 2) or pen.shape != t.shape:
        raise RenderError("motion: t, xy, v and pen must hold the same number of samples")
    slices = _pen_down_runs(pen)
    if not slices:
        raise RenderError("motion: no pen-down samples to paint")
    down = np.concatenate([xy[s] for s in slices])
    if not np.all(np.isfinite(down)) or not np.all(np.isfinite(t)):
        raise RenderError("motion: positions and times must be finite")
    size = float(np.hypot(*np.ptp(down, axis=0)))
    if not size > 0:
        raise RenderError("motion: the pen-down samples have no extent to paint")
    path = sum(float(np.hypot(*np.diff(xy[s], axis=0).T).sum()) for s in slices)
    time = sum(float(t[s][-1] - t[s][0]) for s in slices)
    mean_speed = path / time if time > 0 else 1.0
    if not mean_speed > 0:
        mean_speed = 1.0
    runs = []
    for rows in slices:
        run_speed = np.hypot(v[rows, 0], v[rows, 1])
        direction = _directions(xy[rows], v[rows])
        runs.append(
            Run(
                rows=rows,
                t=t[rows],
                xy=xy[rows],
                speed=run_speed,
                width=brush.widths(run_speed, size, mean_speed),
                normal=np.column_stack([-direction[:, 1], direction[:, 0]]),
            )
        )
    painting = Painting(
        runs=tuple(runs),
        drips=(),
        brush=brush,
        size=size,
        mean_speed=mean_speed,
        t0=float(t[0]),
        t1=float(t[-1]),
        seed=seed,
        units=units,
        samples=len(down),
    )
    if not drips:
        return painting
    if seed is None:
        raise RenderError("seed: drips need a seed (pass one, or let render() draw it)")
    return Painting(**{**painting.__dict__, "drips": _drips(painting, seed)})


def _drips(painting: Painting, seed: int) -> tuple[Drip, ...]:
    """The drips of ``painting`` (see the module docstring), reproducible for ``seed``."""
    brush = painting.brush
    v_drip = brush.drip_speed * painting.mean_speed
    t = np.concatenate([r.t for r in painting.runs])
    xy = np.concatenate([r.xy for r in painting.runs])
    speed = np.concatenate([r.speed for r in painting.runs])
    width = np.concatenate([r.width for r in painting.runs])
    offset = np.concatenate([[0], np.cumsum([len(r) for r in painting.runs])])
    index = np.concatenate([np.arange(r.rows.start, r.rows.stop) for r in painting.runs])
    step = np.concatenate([np.gradient(r.t) if len(r) > 1 else [0.0] for r in painting.runs])
    slow = speed < v_drip
    # Episodes: maximal runs of slow samples, never spanning two pen-down runs.
    first, last = np.zeros(len(t), dtype=bool), np.zeros(len(t), dtype=bool)
    first[offset[:-1]] = True
    last[offset[1:] - 1] = True
    slow_before = np.concatenate([[False], slow[:-1]]) & ~first
    slow_after = np.concatenate([slow[1:], [False]]) & ~last
    start_sample = np.flatnonzero(slow & ~slow_before)
    stop_sample = np.flatnonzero(slow & ~slow_after) + 1
    if not len(start_sample):
        return ()
    slowness = np.where(slow, 1.0 - speed / v_drip, 0.0)
    weighted = np.concatenate([[0.0], np.cumsum(slowness * step)])
    ink = 1.0 - np.exp(-(weighted[stop_sample] - weighted[start_sample]) / brush.drip_time)
    rng = np.random.default_rng([seed, 1])
    draws = rng.random((len(start_sample), 3))
    falls = draws[:, 0] < brush.drip_chance * ink
    result = []
    for k in np.flatnonzero(falls):
        a, b = int(start_sample[k]), int(stop_sample[k])
        i = a + int(np.argmin(speed[a:b]))
        q = float(ink[k])
        w = float(width[i]) * (0.15 + 0.25 * q)
        result.append(
            Drip(
                x=float(xy[i, 0] + (draws[k, 2] - 0.5) * 0.3 * width[i]),
                y=float(xy[i, 1]),
                length=brush.drip_length * painting.size * q * (0.5 + 0.5 * float(draws[k, 1])),
                width=w,
                t=float(t[i]),
                sample=int(index[i]),
                ink=q,
            )
        )
    return tuple(result)
