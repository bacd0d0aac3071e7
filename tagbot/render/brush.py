"""The brush: ink laid along a motion, spreading where the pen lingers, and drips of excess ink.

Everything here is geometry in the tag's own units; :mod:`.raster` and :mod:`.svg` turn it into
pixels or vector paths. Only pen-down samples are painted, each pen-down run on its own.

**Ink model** (paper §5: width "an inverse function of the velocity", made physical). A nib of
width ``w_nib = Brush.nib × S`` (S: the tag's size, the diagonal of its pen-down bounding box)
lets ink flow while it touches the wall; the ink laid per unit length where the pen passes is
the time the pen spends there. At each sample that is the *dwell*: the time the pen spends
within half a nib width of it along the path (``h = w_nib / 2``), over the length of that
window::

    u = (t(s + h) − t(s − h)) / (min(s + h, L) − max(s − h, 0))    seconds per unit length
    r = u · v̂                v̂: the line's speed, so r = 1 at that speed (≈ v̂ / v)
    e = Brush.flow · r       ink laid, in units that fill the nib once

The line's speed ``v̂ = Σ d² / Δt / Σ d`` over the pen-down path's segments (length ``d``, time
``Δt``) is the mean speed at which the line was drawn, each stretch weighted by its length: where
a pen creeps or rests it lays almost no line, so it cannot pull ``v̂`` down. (The mean over time,
path over time, could: a fitted capture whose lognormal tails creep for a second made every real
stroke "fast", so thin, and the ends where the pen does slow down reached the cap: beads 2-3 times
the stroke's width.)

A pen passing at speed v has ``u = 1/v``; one that stops stays in its window and ``u`` grows
with the time it stays. The width follows the laid ink and saturates: the nib fills, then the
ink spreads a little beyond it, then stops::

    w = w_nib · (thin + (1 + spread − thin) · (1 − exp(−e))) · k(θ)

``thin`` is a starved line (a very fast pen) as a fraction of the nib, ``spread`` how far
pooled ink spreads beyond the nib (the cap ``w_nib · (1 + spread)`` for a pen at rest: a
lingering pen pools a little, never a disc), and ``k(θ) = aspect + (1 − aspect)·|sin(θ − angle)|``
the chisel's calligraphic width for direction of travel θ (1 for a round nib). Measuring time
relative to ``v̂`` makes the picture independent of the tag's units and clock.

**Drips** (paper §5: drips "where the velocity is under a certain threshold"): ink beyond
``Brush.drip_ink`` is excess that the wall cannot hold. Each maximal run of consecutive samples
with ``e > drip_ink`` (a pool: a run's start or end, a cusp, a stop) holds the excess
``x = max(e) − drip_ink`` and the load ``q = 1 − exp(−x / drip_ink)``. With a generator seeded by
``seed``, a pool drips with probability ``Brush.drip_chance × q``, from its most loaded sample,
straight down (gravity: −y, down the wall)::

    length = Brush.drip_length × S × q × exp(0.5·Z)     Z ~ N(0, 1), clipped to [−2, 1.5]
    width  = w(sample) × (0.4 + 0.3·q)

its width irregular along its length (seeded smooth wobble), tapering, and ending in a rounded
bead. ``Run.ink`` keeps ``e`` per sample. Each pool's random draws come from a generator keyed by
``seed``, its pen-down run and its place along the run (to two nib widths): the drips do not
depend on the texture or the output format, and a plan and its execution drip alike where they
pool alike.

**Presets** (:data:`PRESETS`, ``Brush.preset(name)``): ``marker`` (the default, a round felt
marker), ``fineliner`` (thin, quickly saturated, hardly spreads, rarely drips), ``chisel`` (a
broad chisel nib at 40°), ``spray`` (a wide soft-edged cone with overspray, drips easily).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
from numpy.typing import NDArray

from tagbot.errors import TagbotError
from tagbot.io.motionfile import MotionLike

__all__ = [
    "PRESETS",
    "Brush",
    "Drip",
    "MotionLike",
    "Painting",
    "RenderError",
    "Run",
    "disc",
    "dwell",
    "paint",
]

Array = NDArray[np.float64]

DISC_VERTICES = 24
"""Vertices of the polygons standing for round brush tips and drip bulbs."""


class RenderError(TagbotError, ValueError):
    """A rendering or plotting request is invalid (size, format, brush parameter, colour...)."""


@dataclass(frozen=True)
class Brush:
    """The pen's physical parameters; see the module docstring for the laws they enter."""

    nib: float = 0.011
    """Nib width, as a fraction of the tag's size: the line a fully inked nib lays."""
    flow: float = 1.0
    """Ink flow: the ink laid while the nib crosses its own width at the line's speed (1 fills
    the nib)."""
    thin: float = 0.3
    """Width of a starved line (a very fast pen), as a fraction of the nib."""
    spread: float = 0.5
    """How far pooled ink spreads beyond the nib, as a fraction of it (the cap at rest)."""
    aspect: float = 1.0
    """Chisel nib: its thin side over its broad side (1 is a round nib)."""
    angle: float = 40.0
    """Chisel nib: the angle of its broad side, degrees from the x axis."""
    soft: float = 0.0
    """Soft edges (spray): blur of the edge, as a fraction of the nib."""
    overspray: float = 0.0
    """Overspray (spray): density of the fine dots around the stroke, in [0, 1]."""
    drip_ink: float = 4.0
    """Ink ``e`` beyond which pooled ink is excess that may drip (4 ≈ a pen 4 times slower than
    the line's speed)."""
    drip_chance: float = 0.8
    """Probability that a pool holding the most excess (q → 1) drips."""
    drip_length: float = 0.1
    """Typical longest drip, as a fraction of the tag's size (a lucky one runs twice as far)."""
    drip_grow: float = 0.4
    """Seconds (tag clock) a drip takes to run down to its full length in animations."""
    texture: float = 0.7
    """Strength of the textured brush in [0, 1]: how much felt streaks, dry breaks and grain
    remove."""
    bristles: int = 11
    """Felt streaks across the nib in the textured brush."""
    dry: float = 0.5
    """Dry-brush breaks in the textured brush: how much ink a fast pen leaves out, in [0, 1]."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, int | float) and math.isfinite(value)):
                raise RenderError(f"brush.{f.name}: must be a finite number, got {value!r}")
        for name in ("nib", "flow", "drip_ink", "drip_length", "drip_grow"):
            if getattr(self, name) <= 0:
                raise RenderError(f"brush.{name}: must be > 0, got {getattr(self, name)!r}")
        if self.spread < 0:
            raise RenderError(f"brush.spread: must be >= 0, got {self.spread!r}")
        for name in ("thin", "aspect", "soft", "overspray", "drip_chance", "texture", "dry"):
            if not 0 <= getattr(self, name) <= 1:
                raise RenderError(f"brush.{name}: must be in [0, 1], got {getattr(self, name)!r}")
        if self.aspect == 0:
            raise RenderError("brush.aspect: must be > 0")
        if int(self.bristles) != self.bristles or self.bristles < 1:
            raise RenderError(f"brush.bristles: must be a whole number >= 1, got {self.bristles!r}")

    @classmethod
    def preset(cls, name: str) -> Brush:
        """One of :data:`PRESETS` by name."""
        try:
            return PRESETS[name]
        except KeyError:
            known = ", ".join(PRESETS)
            raise RenderError(f"brush: unknown preset {name!r} (one of {known})") from None

    @property
    def cap(self) -> float:
        """The widest line (a pen at rest), as a fraction of the tag's size."""
        return self.nib * (1.0 + self.spread)

    def widths(self, ink: Array, size: float, direction: Array | None = None) -> Array:
        """The width ``w`` for laid ink ``ink`` (``e``) and unit directions of travel
        ``direction`` ``(N, 2)`` (see the module docstring)."""
        e = np.maximum(np.asarray(ink, dtype=float), 0.0)
        w = self.nib * size * (self.thin + (1.0 + self.spread - self.thin) * -np.expm1(-e))
        if self.aspect < 1.0 and direction is not None:
            a = math.radians(self.angle)
            across = np.abs(direction[:, 0] * math.sin(a) - direction[:, 1] * math.cos(a))
            w = w * (self.aspect + (1.0 - self.aspect) * across)
        return w


PRESETS: dict[str, Brush] = {
    "marker": Brush(),
    "fineliner": Brush(
        nib=0.004, flow=4.0, thin=0.6, spread=0.15, drip_ink=12.0, drip_chance=0.3, texture=0.3
    ),
    "chisel": Brush(nib=0.022, flow=1.8, thin=0.4, spread=0.3, aspect=0.25, angle=40.0),
    "spray": Brush(
        nib=0.024,
        flow=0.8,
        thin=0.35,
        spread=0.9,
        soft=0.25,
        overspray=0.5,
        drip_ink=2.5,
        drip_chance=0.9,
        drip_length=0.16,
        texture=0.35,
        dry=0.3,
    ),
}
"""Named brushes: a felt marker (the default), a fineliner, a chisel marker, a spray can."""


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
    ink: Array = field(default_factory=lambda: np.zeros(0))
    """Ink laid at each sample (``e``, see the module docstring)."""

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


DRIP_STATIONS = 18
"""Cross-sections along a drip's body."""


@dataclass(frozen=True)
class Drip:
    """A run of excess ink hanging straight down (−y) from a pool."""

    x: float
    y: float
    """Where it starts (the top, inside the stroke), tag units."""
    length: float
    """From the top to the centre of the bead at full length."""
    width: float
    """Width at the top."""
    t: float
    """When its sample was painted, seconds on the motion's clock."""
    sample: int
    """Its most loaded sample, an index into the motion."""
    ink: float
    """The pool's load ``q`` in (0, 1)."""
    wobble: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    """Seeded phases of its irregular width and sideways wander, in [0, 1)."""

    @property
    def bulb(self) -> float:
        """Radius of the bead at the bottom."""
        return 0.42 * self.width

    def outline(self, fraction: float = 1.0) -> tuple[Array, Array, Array]:
        """Centre ``x``, ``y`` and half width of its cross-sections when ``fraction`` of its
        length has run down."""
        f = min(max(fraction, 0.0), 1.0)
        u = np.linspace(0.0, 1.0, DRIP_STATIONS)
        p = 2.0 * np.pi * np.asarray(self.wobble)
        # A smooth irregular width (two incommensurate waves) over a taper to 0.55 of the top.
        waves = 0.6 * np.sin(2.0 * np.pi * 1.7 * u + p[0]) + 0.4 * np.sin(
            2.0 * np.pi * 3.1 * u + p[1]
        )
        half = 0.5 * self.width * (1.0 - 0.45 * u) * (1.0 + 0.18 * waves)
        half[0] = 0.5 * self.width
        x = self.x + 0.12 * self.width * (np.sin(np.pi * u + p[2]) - np.sin(p[2]))
        x += 0.05 * self.width * np.sin(2.0 * np.pi * 2.3 * u + p[3]) * u
        return x, self.y - f * self.length * u, half

    def shapes(self, fraction: float = 1.0) -> list[Array]:
        """Counter-clockwise polygons whose union is the drip: its body as quadrilaterals
        between cross-sections ``(DRIP_STATIONS − 1, 4, 2)`` and the bead ``(1, V, 2)``."""
        x, y, half = self.outline(fraction)
        left, right = np.column_stack([x - half, y]), np.column_stack([x + half, y])
        body = np.stack([left[:-1], left[1:], right[1:], right[:-1]], axis=1)
        f = min(max(fraction, 0.0), 1.0)
        radius = self.bulb * (0.75 + 0.25 * f)
        bead = disc(np.array([[x[-1], y[-1] - 0.3 * radius]]), np.array([radius]))
        return [body, bead]


@dataclass(frozen=True, eq=False)
class Painting:
    """A motion as brush geometry: pen-down runs, their widths and ink, and the drips."""

    runs: tuple[Run, ...]
    drips: tuple[Drip, ...]
    brush: Brush
    size: float
    """The tag's size ``S`` (pen-down bounding-box diagonal), tag units."""
    mean_speed: float
    """The mean pen-down speed (path over time), tag units per second: the texture's pace."""
    line_speed: float
    """``v̂``, the length-weighted mean speed the ink is laid relative to, units per second."""
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
        ``pad × size`` (and the soft edge and overspray of a spray)."""
        lo = np.min([(r.xy - r.width[:, None] / 2).min(axis=0) for r in self.runs], axis=0)
        hi = np.max([(r.xy + r.width[:, None] / 2).max(axis=0) for r in self.runs], axis=0)
        for drip in self.drips:
            shape = np.concatenate([s.reshape(-1, 2) for s in drip.shapes()])
            lo, hi = np.minimum(lo, shape.min(axis=0)), np.maximum(hi, shape.max(axis=0))
        margin = pad * self.size + self.halo
        return (
            float(lo[0] - margin),
            float(lo[1] - margin),
            float(hi[0] + margin),
            float(hi[1] + margin),
        )

    @property
    def halo(self) -> float:
        """How far soft edges and overspray reach beyond the brush, tag units."""
        b = self.brush
        return (b.soft + 1.5 * (b.overspray > 0)) * b.nib * self.size


def dwell(t: Array, xy: Array, h: float) -> Array:
    """Seconds per unit length the pen spends within ``h`` of each sample along its path (see
    the module docstring): ``1/v`` for a pen passing at speed v, growing while it stays."""
    step = np.hypot(*np.diff(xy, axis=0).T) if len(xy) > 1 else np.zeros(0)
    s = np.concatenate([[0.0], np.cumsum(step)])
    total = float(s[-1])
    lo_s, hi_s = np.maximum(s - h, 0.0), np.minimum(s + h, total)
    # Interpolated times (moving pen) and whole stays (samples where s does not advance).
    moving = np.interp(hi_s, s, t) - np.interp(lo_s, s, t)
    first = np.searchsorted(s, lo_s, side="left")
    last = np.searchsorted(s, hi_s, side="right") - 1
    staying = t[np.maximum(last, first)] - t[first]
    window = np.maximum(hi_s - lo_s, h)
    return np.maximum(moving, staying) / window


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


def _speeds(t: Array, xy: Array, slices: list[slice]) -> tuple[float, float]:
    """The pen-down path's mean speed over time and its line speed ``v̂`` (the module docstring),
    each 1.0 where it is not a positive number (a path that never moves)."""
    d = [np.hypot(*np.diff(xy[s], axis=0).T) for s in slices]
    dt = [np.diff(t[s]) for s in slices]
    path = sum(float(x.sum()) for x in d)
    time = sum(float(x.sum()) for x in dt)
    swept = sum(float(np.sum(x[y > 0] ** 2 / y[y > 0])) for x, y in zip(d, dt, strict=True))
    mean_speed = path / time if time > 0 else 1.0
    line_speed = swept / path if path > 0 else 1.0
    return (
        mean_speed if mean_speed > 0 and math.isfinite(mean_speed) else 1.0,
        line_speed if line_speed > 0 and math.isfinite(line_speed) else 1.0,
    )


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
    mean_speed, line_speed = _speeds(t, xy, slices)
    h = 0.5 * brush.nib * size
    runs = []
    for rows in slices:
        run_speed = np.hypot(v[rows, 0], v[rows, 1])
        direction = _directions(xy[rows], v[rows])
        ink = brush.flow * line_speed * dwell(t[rows], xy[rows], h)
        runs.append(
            Run(
                rows=rows,
                t=t[rows],
                xy=xy[rows],
                speed=run_speed,
                width=brush.widths(ink, size, direction),
                normal=np.column_stack([-direction[:, 1], direction[:, 0]]),
                ink=ink,
            )
        )
    painting = Painting(
        runs=tuple(runs),
        drips=(),
        brush=brush,
        size=size,
        mean_speed=mean_speed,
        line_speed=line_speed,
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
    runs = painting.runs
    t = np.concatenate([r.t for r in runs])
    xy = np.concatenate([r.xy for r in runs])
    ink = np.concatenate([r.ink for r in runs])
    width = np.concatenate([r.width for r in runs])
    offset = np.concatenate([[0], np.cumsum([len(r) for r in runs])])
    index = np.concatenate([np.arange(r.rows.start, r.rows.stop) for r in runs])
    pooled = ink > brush.drip_ink
    # Pools: maximal runs of pooled samples, never spanning two pen-down runs.
    first, last = np.zeros(len(t), dtype=bool), np.zeros(len(t), dtype=bool)
    first[offset[:-1]] = True
    last[offset[1:] - 1] = True
    before = np.concatenate([[False], pooled[:-1]]) & ~first
    after = np.concatenate([pooled[1:], [False]]) & ~last
    starts = np.flatnonzero(pooled & ~before)
    stops = np.flatnonzero(pooled & ~after) + 1
    if not len(starts):
        return ()
    # The most loaded sample of each pool (samples between pools do not count).
    peak = np.maximum.reduceat(np.where(pooled, ink, -np.inf), starts)
    excess = peak - brush.drip_ink
    load = -np.expm1(-excess / brush.drip_ink)
    # Each pool's draws come from its own generator, keyed by its run and where it lies along
    # the run (to two nib widths): the same pool drips alike in a plan and in its execution.
    run_of = np.searchsorted(offset, starts, side="right") - 1
    along = np.concatenate(
        [np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(r.xy, axis=0).T))]) for r in runs]
    )
    place = np.floor(along[starts] / (2.0 * brush.nib * painting.size)).astype(np.int64)
    draws = np.empty((len(starts), 8))
    for k, (run, where) in enumerate(zip(run_of.tolist(), place.tolist(), strict=True)):
        rng = np.random.default_rng([seed, 1, run, where])
        draws[k, :7] = rng.random(7)
        draws[k, 7] = rng.standard_normal()
    spread = np.clip(draws[:, 7], -2.0, 1.5)
    falls = draws[:, 0] < brush.drip_chance * load
    result = []
    for k in np.flatnonzero(falls):
        a, b = int(starts[k]), int(stops[k])
        i = a + int(np.argmax(ink[a:b]))
        q = float(load[k])
        result.append(
            Drip(
                x=float(xy[i, 0] + (draws[k, 2] - 0.5) * 0.3 * width[i]),
                y=float(xy[i, 1]),
                length=brush.drip_length * painting.size * q * math.exp(0.5 * spread[k]),
                width=float(width[i]) * (0.4 + 0.3 * q),
                t=float(t[i]),
                sample=int(index[i]),
                ink=q,
                wobble=tuple(float(d) for d in draws[k, 3:7]),  # type: ignore[arg-type]
            )
        )
    return tuple(result)
