"""Contour analysis for reconstruction (paper §6.1–6.3): resampling, smoothing, turning angles,
dominant points, inflections, circular-segment angles (eq. 19) and contour sharpness (eq. 20).

Every function works on one polyline ``(N, 2)``; lengths are in the trace's units. The work is
done by the compiled loops of :mod:`tagbot.gesture.contour_kernels`, a few calls per function
however many points and sections there are, with the same results as the numpy and scipy code
they replaced. Per-section quantities come for all sections at once (:func:`inflections`,
:func:`section_deviations`, :func:`sharpnesses`, :func:`segment_angles`); :func:`inflection`,
:func:`arc_deviation`, :func:`sharpness` and :func:`segment_angle` are the one-section versions.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tagbot.gesture import contour_kernels as kernels

Array = NDArray[np.float64]
Indices = NDArray[np.intp]


def _points(xy: ArrayLike) -> Array:
    """``xy`` as the kernels take it: C-contiguous float64."""
    return np.ascontiguousarray(xy, dtype=np.float64)


def _indices(k: ArrayLike) -> Indices:
    return np.ascontiguousarray(k, dtype=np.intp)


def arc_length(xy: Array) -> Array:
    """Cumulative length along the polyline, starting at 0."""
    return kernels.arc_length(_points(xy))


def decimate(xy: Array, radius: float) -> Array:
    """Keep a point only once it is at least ``radius`` from the last kept one (and the last).

    Removes jitter below ``radius`` that would otherwise inflate the arc length of a densely
    captured trace. Fewer than 3 points, or ``radius <= 0``: ``xy`` itself.
    """
    if len(xy) < 3 or radius <= 0:
        return xy
    return kernels.decimate(_points(xy), float(radius))[0]


def prefilter(xy: Array, step: float) -> Array:
    """Average points captured much more densely than ``step`` over about one step of path.

    Jitter on a dense capture inflates its arc length (each tiny zig-zag counts), which would
    drown the shape. The density is estimated on a coarse decimation (points 5 steps apart), which
    jitter barely lengthens; with more than two points per step, the points are averaged with a
    Gaussian half a step wide (in points). Sparser captures are returned unchanged.
    """
    coarse_length = kernels.decimate(_points(xy), 5.0 * step)[1]
    if coarse_length <= 0:
        return xy
    per_step = len(xy) * step / coarse_length
    return smooth(xy, 0.5 * per_step) if per_step > 2.0 else xy


def resample(xy: Array, step: float) -> Array:
    """Points equally spaced along the polyline, at most ``step`` apart, both ends kept."""
    return kernels.resample(_points(xy), float(step))


def smooth(xy: Array, width: float) -> Array:
    """Gaussian-weighted averaging over ``width`` samples (standard deviation); ends kept.

    The curve is extended past each end by its point reflection there, so straight ends stay
    straight and the end points do not move. The Gaussian is scipy's ``gaussian_filter1d``'s
    (truncated at 4 widths, mode ``nearest``), to the bit.
    """
    xy = _points(xy)
    if width <= 0 or len(xy) < 3:
        return xy.copy()
    # Wider than the curve averages it all the same: the weights stay as long as the curve.
    width = min(float(width), float(len(xy)))
    pad = min(len(xy) - 1, math.ceil(4 * width))
    return kernels.smooth(xy, _gaussian_weights(float(width)), pad)


@functools.lru_cache(maxsize=32)
def _gaussian_weights(width: float) -> Array:
    """The centre and right half of scipy's Gaussian kernel of standard deviation ``width``
    (computed as scipy does: numpy's ``exp`` and pairwise sum)."""
    radius = int(4.0 * width + 0.5)
    x = np.arange(-radius, radius + 1)
    phi = np.exp(-0.5 / (width * width) * x**2)
    return np.ascontiguousarray((phi / phi.sum())[radius:])


def turning(xy: Array, support: int = 1) -> Array:
    """Signed turning angle at each point between the chords to ``support`` samples either side.

    Counter-clockwise positive; 0 at the ends (and where the support reaches past them, the
    chords are shortened to the ends).
    """
    parts = kernels.turning_parts(_points(xy), int(support))
    return np.arctan2(parts[0], parts[1])


def heading_changes(xy: Array, support: int = 1) -> Array:
    """Per sample, the change of direction of the chord ``support`` samples long centred there.

    Summing their absolute values gives the total absolute turning at that scale.
    """
    chords = kernels.heading_chords(_points(xy), int(support))
    steps = kernels.heading_steps(np.arctan2(chords[0], chords[1]))
    return np.arctan2(steps[0], steps[1])


def chord_turn(xy: Array, prev: Indices, here: Indices, nxt: Indices) -> Array:
    """Absolute turning angle at ``xy[here]`` between the chords from ``xy[prev]`` and to
    ``xy[nxt]`` (the angle between a salient point and its two neighbours)."""
    return kernels.chord_turn(_points(xy), _indices(prev), _indices(here), _indices(nxt))


def salient_points(
    xy: Array, support: int, threshold: float, prominence: float, reach: float = 3.0
) -> Indices:
    """Indices of salient points: the ends, plus curvature extrema that turn enough.

    Candidates are the peaks of ``|turning(xy, support)|`` standing out by ``prominence`` (rad)
    from their surroundings (de Winter & Wagemans, as in the paper), at least ``support`` apart
    (scipy's ``find_peaks``, reproduced; the tallest first); then, while some candidate turns
    less than ``threshold`` (rad) between its two neighbouring candidates, the weakest one is
    dropped. The turn is also measured with chords reaching at most ``reach`` supports, and the
    larger of the two counts: on a long smooth stretch the next candidate can be far away, and a
    chord that long no longer sees a sharp corner.
    """
    if support < 1:
        raise ValueError("support: must be at least 1")
    xy = _points(xy)
    height, peaks, priority = kernels.local_maxima(turning(xy, support))
    order = np.argsort(priority)  # as find_peaks: equal heights come in numpy's order
    return kernels.salient_points(
        xy,
        height,
        peaks,
        order,
        int(support),
        float(threshold),
        float(prominence),
        int(reach * support),
    )


def add_turning_points(
    xy: Array, points: Indices, max_turn: float = np.pi, support: int = 1
) -> Indices:
    """Add ⌊θ̂ / max_turn⌋ points equally spaced along each section turning θ̂ > ``max_turn``.

    θ̂ is the section's total absolute turning, measured on chords ``support`` samples long (so
    that jitter below that scale does not add up), leaving out half a support at each interior
    salient point: a corner's own turning is the corner's.
    """
    xy = _points(xy)
    change = heading_changes(xy, support)
    return kernels.add_turning_points(xy, _indices(points), change, float(max_turn), int(support))


def inflection(xy: Array, a: int, b: int, support: int, min_turn: float) -> int | None:
    """The most significant inflection strictly inside section ``a..b``, or None.

    An inflection is a sign change of the turning (at ``support`` samples) where the section
    turns at least ``min_turn`` (rad) on each side, in opposite directions; among several, the
    one that splits the turning most evenly.
    """
    cut = int(inflections(xy, np.array([a, b], dtype=np.intp), support, min_turn)[0])
    return None if cut < 0 else cut


def inflections(xy: Array, dominant: Indices, support: int, min_turn: float) -> Indices:
    """:func:`inflection` of every section ``dominant[i]..dominant[i + 1]``, -1 where none.

    The turning is measured within the section: its chords stop at the section's ends, so the
    corner at a dominant point (rounded by the smoothing) does not count as the section turning
    one way before it turns the other. Sections shorter than 4 supports measure their turning
    with a quarter of their length.
    """
    dominant = _indices(dominant)
    parts = kernels.inflection_parts(_points(xy), dominant, int(support))
    return kernels.inflections(np.arctan2(parts[0], parts[1]), dominant, float(min_turn))


def signed_area(xy: Array) -> float:
    """Signed area enclosed by the polyline closed by its chord (counter-clockwise positive)."""
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


_FULL_TURN = kernels.FULL_TURN
"""The largest central angle of a circular segment (the whole circle but a sliver)."""


def segment_angle(chord: float, area: float) -> float:
    """The central angle θ of the circular segment with this chord and (absolute) area (eq. 19).

    See :func:`segment_angles`.
    """
    return float(segment_angles(np.array([chord], dtype=float), np.array([area], dtype=float))[0])


def segment_angles(chord: ArrayLike, area: ArrayLike) -> Array:
    """Eq. 19 for arrays: central angles θ in [0, 2π) of the circular segments with these chords
    and (absolute) areas; 0 where either is not positive.

    Solves ``½ (c / (2 sin(θ/2)))² (θ − sin θ) = A``, i.e. the monotone ratio
    ``A / c² = (θ − sin θ) / (8 sin²(θ/2))``, with a table of cubics in ``log(A / c²)`` (good to
    about 1e-14); below it (θ < 1e-4) from the ratio's series, above it the whole circle (less
    the sliver of 1e-9).
    """
    chord, area = np.broadcast_arrays(np.asarray(chord, dtype=float), np.asarray(area, dtype=float))
    # NaN is not positive (θ = 0), +inf the largest area (the whole circle): finite for the kernel.
    big = np.finfo(float).max
    chord, area = (np.nan_to_num(x, nan=0.0, posinf=big, neginf=-big) for x in (chord, area))
    start, cubics = _segment_table()
    theta = kernels.segment_angles(
        _points(chord).ravel(), _points(area).ravel(), start, _TABLE_STEP, cubics
    )
    return theta.reshape(chord.shape)


def _segment_ratio(theta: Array) -> tuple[Array, Array]:
    """``(θ − sin θ) / (8 sin²(θ/2))`` and its derivative in θ (below θ = ¼, ``θ − sin θ`` from
    its series, free of cancellation)."""
    sin, cos = np.sin(0.5 * theta), np.cos(0.5 * theta)
    t2 = theta * theta
    # θ − sin θ = θ³/6 (1 − θ²/20 (1 − θ²/42 (1 − θ²/72 (1 − θ²/110 (1 − θ²/156)))))
    series = 1.0 - t2 / 156.0
    for k in (110.0, 72.0, 42.0, 20.0):
        series = 1.0 - t2 / k * series
    excess = np.where(theta < 0.25, theta * t2 / 6.0 * series, theta - 2.0 * sin * cos)
    square = 8.0 * sin * sin
    return excess / square, 0.25 - excess * cos / (square * sin)


_TABLE_STEP = 2e-3
"""Spacing of :func:`_segment_table` in ``log(A / c²)``."""


@functools.cache
def _segment_table() -> tuple[float, Array]:
    """For :func:`segment_angles`: the first ``log(A / c²)`` (θ = 1e-4) and, per step of
    :data:`_TABLE_STEP` from there to past θ = 2π − 1e-9, the cubic in the fraction of the step
    through θ there (Hermite, from θ and dθ/d log(A / c²) at both ends)."""
    # θ on an even grid of log(A / c²): a first guess from a dense grid of θ, then Newton.
    w = np.arange(np.log(1e-4 / (2.0 * np.pi)), np.log(2.0 * np.pi / 1e-10), 1e-3)
    guess = 2.0 * np.pi / (1.0 + np.exp(-w))
    guess_x = np.log(_segment_ratio(guess)[0])
    top = np.log(_segment_ratio(np.array(_FULL_TURN))[0])
    x = guess_x[0] + _TABLE_STEP * np.arange(int((top - guess_x[0]) / _TABLE_STEP) + 3)
    theta = np.interp(x, guess_x, guess)
    for _ in range(3):
        value, slope = _segment_ratio(theta)
        theta = theta - (value - np.exp(x)) / slope
    value, slope = _segment_ratio(theta)
    step = _TABLE_STEP * value / slope  # dθ per table step
    rise = np.diff(theta)
    cubics = np.column_stack(
        [
            theta[:-1],
            step[:-1],
            3.0 * rise - 2.0 * step[:-1] - step[1:],
            step[:-1] + step[1:] - 2.0 * rise,
        ]
    )
    return float(x[0]), cubics


def arc_deviation(xy: Array) -> float:
    """The ΣΛ* deviation ``phi`` of the circular arc fitted to a section by its area.

    ``phi = sign(A)·θ/2``: the arc leaves at ``alpha − phi`` from the chord direction ``alpha``;
    a positive signed area (the contour right of the chord, turning left) gives ``phi > 0``.
    """
    area = signed_area(xy)
    chord = float(np.hypot(*(xy[-1] - xy[0])))
    return float(np.sign(area)) * 0.5 * segment_angle(chord, abs(area))


def section_deviations(
    curve: Array, dominant: Indices, cuts: Sequence[int | None] | Indices | None = None
) -> tuple[Array, Array]:
    """``(phi1, phi2)`` of every section ``dominant[i]..dominant[i + 1]`` (eq. 19).

    One circular arc by the section's area: ``(-phi, phi)``, as :func:`arc_deviation`. With an
    inflection at ``curve[cuts[i]]`` strictly inside (None or -1: none), one arc on each side; the
    first's start tangent and the second's end tangent, measured from the section's chord.
    """
    dominant = _indices(dominant)
    m = max(len(dominant) - 1, 0)
    if cuts is None:
        q = np.full(m, -1, dtype=np.intp)
    elif isinstance(cuts, np.ndarray):
        q = _indices(cuts)
    else:
        q = np.array([-1 if c is None else c for c in cuts], dtype=np.intp)
    start, cubics = _segment_table()
    return kernels.section_deviations(_points(curve), dominant, q, start, _TABLE_STEP, cubics)


def sharpness(xy: Array, a: int, z: int, b: int) -> float:
    """Eq. 20: how close the contour ``a..b`` around ``z`` is to a corner (1) or an arc (0).

    Compares its area ``A_Z`` (closed by the chord ``ab``) with the triangle ``(a, z, b)``
    (``A_t``, sharpest) and the circular segment through ``a, z, b`` (``A_s``, roundest).
    """
    return float(sharpnesses(xy, np.array([a]), np.array([z]), np.array([b]))[0])


def sharpnesses(xy: Array, a: Indices, z: Indices, b: Indices) -> Array:
    """:func:`sharpness` of the contours ``xy[a[i]..b[i]]`` around ``xy[z[i]]``."""
    xy = _points(xy)
    a, z, b = _indices(a), _indices(z), _indices(b)
    if not z.size:
        return np.zeros(z.shape)
    # The inscribed angle at z from numpy's arccos (the kernels' C library rounds differently).
    gamma = np.arccos(np.clip(kernels.sharpness_cosines(xy, a, z, b), -1.0, 1.0))
    # NaN where a side has no length: the sharpness is 0 there whatever the angle, so π stands in
    # (kernels only ever see finite values).
    return kernels.sharpnesses(xy, a, z, b, np.nan_to_num(gamma, nan=np.pi))
