"""Contour analysis for reconstruction (paper §6.1–6.3): resampling, smoothing, turning angles,
dominant points, inflections, circular-segment angles (eq. 19) and contour sharpness (eq. 20).

Every function works on one polyline ``(N, 2)`` with vectorised numpy; lengths are in the trace's
units. Per-section quantities come for all sections at once (:func:`inflections`,
:func:`section_deviations`, :func:`sharpnesses`, :func:`segment_angles`), in a fixed number of numpy
calls however many sections there are; :func:`inflection`, :func:`arc_deviation`,
:func:`sharpness` and :func:`segment_angle` are the one-section versions.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks

from tagbot.model.euler import wrap_angle

Array = NDArray[np.float64]
Indices = NDArray[np.intp]

_EPS = float(np.finfo(float).eps)


def arc_length(xy: Array) -> Array:
    """Cumulative length along the polyline, starting at 0."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])


def decimate(xy: Array, radius: float) -> Array:
    """Keep a point only once it is at least ``radius`` from the last kept one (and the last).

    Removes jitter below ``radius`` that would otherwise inflate the arc length of a densely
    captured trace. A point less than ``radius`` of path beyond the last kept one is nearer than
    ``radius``, so the search for the next kept point starts that far along the path; the first
    candidate of every point is checked at once, and only where it is too near (a bend, or a
    stretch of jitter) does a kept point search further on its own.
    """
    n = len(xy)
    if n < 3 or radius <= 0:
        return xy
    s = arc_length(xy)
    if not np.isfinite(s[-1]):
        unknown = np.full(n, -1, dtype=np.intp)
        return xy[_decimate_from(xy, radius, unknown, np.arange(1, n + 1))]
    # Rounding in the path length and the distances stays far below this margin.
    margin = 8.0 * n * _EPS * (s[-1] + radius)
    later = np.arange(1, n + 1)
    start = np.maximum(np.searchsorted(s, s + (radius - margin)), later)
    # Every point's first candidate at once: ``found`` is the next kept index (n: none), -1 where
    # the candidate is too near (the search goes on from the next one).
    far = np.hypot(*(xy[np.minimum(start, n - 1)] - xy).T) >= radius
    found = np.where(start >= n, n, np.where(far, start, -1))
    if (found[:-1] == later[:-1]).all():  # every point is kept
        return xy.copy()
    return xy[_decimate_from(xy, radius, found, start + 1)]


def _decimate_from(xy: Array, radius: float, found: Indices, start: Indices) -> list[int]:
    """The kept indices, from each point's next kept index (``found``, or -1 if not yet known:
    then the first at or after ``start`` at least ``radius`` away)."""
    n = len(xy)
    found_list, start_list = found.tolist(), start.tolist()
    kept = [0]
    i = 0
    while True:
        j = found_list[i]
        if j < 0:
            j = _next_far(xy, i, start_list[i], radius)
        if j >= n:
            break
        kept.append(j)
        i = j
    if kept[-1] != n - 1:
        kept.append(n - 1)
    return kept


def _next_far(xy: Array, i: int, start: int, radius: float) -> int:
    """The first index from ``start`` on at least ``radius`` from ``xy[i]``, or ``len(xy)``."""
    n = len(xy)
    chunk = 64
    while start < n:
        block = xy[start : start + chunk]
        far = np.flatnonzero(np.hypot(*(block - xy[i]).T) >= radius)
        if far.size:
            return start + int(far[0])
        start += chunk
        chunk *= 2  # a long stretch of jitter: look further at once
    return n


def prefilter(xy: Array, step: float) -> Array:
    """Average points captured much more densely than ``step`` over about one step of path.

    Jitter on a dense capture inflates its arc length (each tiny zig-zag counts), which would
    drown the shape. The density is estimated on a coarse decimation (points 5 steps apart), which
    jitter barely lengthens; with more than two points per step, the points are averaged with a
    Gaussian half a step wide (in points). Sparser captures are returned unchanged.
    """
    coarse_length = arc_length(decimate(xy, 5.0 * step))[-1]
    if coarse_length <= 0:
        return xy
    per_step = len(xy) * step / coarse_length
    return smooth(xy, 0.5 * per_step) if per_step > 2.0 else xy


def resample(xy: Array, step: float) -> Array:
    """Points equally spaced along the polyline, at most ``step`` apart, both ends kept."""
    s = arc_length(xy)
    count = max(2, int(np.ceil(s[-1] / step)) + 1)
    keep = np.concatenate([[True], np.diff(s) > 0])  # drop repeated points
    s, xy = s[keep], xy[keep]
    u = np.linspace(0.0, s[-1], count)
    return np.column_stack([np.interp(u, s, xy[:, 0]), np.interp(u, s, xy[:, 1])])


def smooth(xy: Array, width: float) -> Array:
    """Gaussian-weighted averaging over ``width`` samples (standard deviation); ends kept.

    The curve is extended past each end by its point reflection there, so straight ends stay
    straight and the end points do not move.
    """
    if width <= 0 or len(xy) < 3:
        return xy.copy()
    pad = min(len(xy) - 1, int(np.ceil(4 * width)))
    head = 2 * xy[0] - xy[pad:0:-1]
    tail = 2 * xy[-1] - xy[-2 : -pad - 2 : -1]
    extended = np.concatenate([head, xy, tail])
    smoothed = gaussian_filter1d(extended, width, axis=0, mode="nearest")[pad : pad + len(xy)]
    smoothed[0], smoothed[-1] = xy[0], xy[-1]
    return smoothed


def turning(xy: Array, support: int = 1) -> Array:
    """Signed turning angle at each point between the chords to ``support`` samples either side.

    Counter-clockwise positive; 0 at the ends (and where the support reaches past them, the
    chords are shortened to the ends).
    """
    before = xy - _shifted(xy, -support)
    after = _shifted(xy, support) - xy
    angle = _angles(before[:, 0], before[:, 1], after[:, 0], after[:, 1])
    angle[[0, -1]] = 0.0
    return angle


def _turning_at(xy: Array, i: Indices, support: Indices, lo: Indices, hi: Indices) -> Array:
    """:func:`turning` at the points ``i`` only, each with its own ``support``, the chords
    shortened so as not to reach past ``lo`` and ``hi``."""
    x, y = xy[:, 0], xy[:, 1]
    prev, nxt = np.maximum(i - support, lo), np.minimum(i + support, hi)
    here_x, here_y = x[i], y[i]
    return _angles(here_x - x[prev], here_y - y[prev], x[nxt] - here_x, y[nxt] - here_y)


def _angles(before_x: Array, before_y: Array, after_x: Array, after_y: Array) -> Array:
    """Signed angles from the vectors ``before`` to the vectors ``after``, in (−π, π]."""
    cross = before_x * after_y - before_y * after_x
    # As einsum's dot product, which starts from +0 (so that −0 + −0 is +0: atan2(0, +0) = 0).
    dot = before_x * after_x + before_y * after_y + 0.0
    return np.arctan2(cross, dot)


def _shifted(xy: Array, k: int) -> Array:
    """``xy[clip(i + k, 0, n − 1)]`` for every ``i``: the points ``k`` samples on, held at the
    ends (slices, not a gather)."""
    n = len(xy)
    out = np.empty_like(xy)
    if k >= 0:
        k = min(k, n)
        out[: n - k], out[n - k :] = xy[k:], xy[-1]
    else:
        k = min(-k, n)
        out[:k], out[k:] = xy[0], xy[: n - k]
    return out


def heading_changes(xy: Array, support: int = 1) -> Array:
    """Per sample, the change of direction of the chord ``support`` samples long centred there.

    Summing their absolute values gives the total absolute turning at that scale.
    """
    half = support // 2
    chords = _shifted(xy, support - half) - _shifted(xy, -half)
    heading = np.arctan2(chords[:, 1], chords[:, 0])
    change = np.zeros(len(xy))
    change[1:] = np.angle(np.exp(1j * np.diff(heading)))
    return change


def chord_turn(xy: Array, prev: Indices, here: Indices, nxt: Indices) -> Array:
    """Absolute turning angle at ``xy[here]`` between the chords from ``xy[prev]`` and to
    ``xy[nxt]`` (the angle between a salient point and its two neighbours)."""
    a = xy[here] - xy[prev]
    b = xy[nxt] - xy[here]
    return np.abs(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], np.einsum("ij,ij->i", a, b)))


def salient_points(
    xy: Array, support: int, threshold: float, prominence: float, reach: float = 3.0
) -> Indices:
    """Indices of salient points: the ends, plus curvature extrema that turn enough.

    Candidates are the peaks of ``|turning(xy, support)|`` standing out by ``prominence`` (rad)
    from their surroundings (de Winter & Wagemans, as in the paper); then, while some candidate
    turns less than ``threshold`` (rad) between its two neighbouring candidates, the weakest one
    is dropped. The turn is also measured with chords reaching at most ``reach`` supports, and the
    larger of the two counts: on a long smooth stretch the next candidate can be far away, and a
    chord that long no longer sees a sharp corner.
    """
    n = len(xy)
    peaks, _ = find_peaks(np.abs(turning(xy, support)), prominence=prominence, distance=support)
    # Within one support of an end the chords are cut short: no reliable extremum there.
    peaks = peaks[(peaks >= support) & (peaks <= n - 1 - support)]
    points = [0, *peaks.tolist(), n - 1]
    span = int(reach * support)
    turns = _salient_turns(xy, points[:-2], points[1:-1], points[2:], span).tolist()
    while turns:
        weakest = int(np.argmin(turns))
        if turns[weakest] >= threshold:
            break
        del points[weakest + 1], turns[weakest]
        # Only the dropped point's neighbours turn differently now.
        moved = [k for k in (weakest - 1, weakest) if 0 <= k < len(turns)]
        if moved:
            new = _salient_turns(
                xy,
                [points[k] for k in moved],
                [points[k + 1] for k in moved],
                [points[k + 2] for k in moved],
                span,
            )
            for k, turn in zip(moved, new.tolist(), strict=True):
                turns[k] = turn
    return np.asarray(points, dtype=np.intp)


def _salient_turns(xy: Array, prev: list[int], here: list[int], nxt: list[int], span: int) -> Array:
    """The turn of candidates ``here`` between ``prev`` and ``nxt`` (:func:`salient_points`)."""
    p, h, q = (np.asarray(k, dtype=np.intp) for k in (prev, here, nxt))
    near = chord_turn(xy, np.maximum(p, h - span), h, np.minimum(q, h + span))
    return np.maximum(chord_turn(xy, p, h, q), near)


def add_turning_points(
    xy: Array, points: Indices, max_turn: float = np.pi, support: int = 1
) -> Indices:
    """Add ⌊θ̂ / max_turn⌋ points equally spaced along each section turning θ̂ > ``max_turn``.

    θ̂ is the section's total absolute turning, measured on chords ``support`` samples long (so
    that jitter below that scale does not add up), leaving out half a support at each interior
    salient point: a corner's own turning is the corner's.
    """
    points = np.asarray(points, dtype=np.intp)
    step_turn = np.abs(heading_changes(xy, support))
    margin = support // 2
    last = len(xy) - 1
    a, b = points[:-1], points[1:]
    lo = a + 1 + np.where(a > 0, margin, 0)
    hi = b - np.where(b < last, margin, 0)
    extra = _whole_turns(step_turn, lo, hi, max_turn)
    more = np.flatnonzero(extra > 0)
    if not more.size:
        return np.unique(points)
    # ⌊θ̂ / max_turn⌋ targets per section, as np.linspace(s[a], s[b], extra + 2)[1:-1].
    s = arc_length(xy)
    count = extra[more]
    first = np.repeat(np.cumsum(count) - count, count)
    k = (np.arange(int(count.sum())) - first + 1).astype(float)
    start, span = s[a[more]], s[b[more]] - s[a[more]]
    div = (count + 1).astype(float)
    step = np.repeat(span / div, count)
    offset = np.where(step == 0, k / np.repeat(div, count) * np.repeat(span, count), k * step)
    targets = offset + np.repeat(start, count)
    inner = np.minimum(
        np.maximum(np.searchsorted(s, targets), np.repeat(a[more] + 1, count)),
        np.repeat(b[more] - 1, count),
    )
    return np.unique(np.concatenate([points, inner]))


def _whole_turns(values: Array, lo: Indices, hi: Indices, unit: float) -> Indices:
    """``⌊sum(values[lo:hi]) / unit⌋`` per range (Python slices), exactly as with ``np.sum``.

    The sums come from one cumulative sum; the few that fall within rounding of a multiple of
    ``unit`` are summed again with ``np.sum`` so that the floor is the same.
    """
    n = len(values)
    cumulative = np.concatenate([[0.0], np.cumsum(values)])
    start, stop = np.minimum(lo, n), np.minimum(hi, n)
    total = np.where(stop > start, cumulative[stop] - cumulative[start], 0.0)
    whole = np.rint(total / unit)
    slack = 4.0 * (n + 1) * _EPS * (cumulative[-1] + abs(unit))
    again = (whole >= 1) & (np.abs(total - whole * unit) <= slack) | (lo < 0) | (hi < 0)
    for i in np.flatnonzero(again).tolist():
        total[i] = float(np.sum(values[lo[i] : hi[i]]))
    return np.floor_divide(total, unit).astype(np.intp)


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
    dominant = np.asarray(dominant, dtype=np.intp)
    a, b = dominant[:-1], dominant[1:]
    cuts = np.full(len(a), -1, dtype=np.intp)
    sections = np.flatnonzero(b - a >= 4)
    if not sections.size:
        return cuts
    a, b = a[sections], b[sections]
    count = b - a - 1  # turnings strictly inside
    scale = np.maximum(1, np.minimum(support, (b - a) // 4))
    # One row per section, zeros past its end: each row's cumulative sum is the section's own.
    width = int(count.max())
    inside = np.arange(width) < count[:, None]
    where = ((a + 1)[:, None] + np.arange(width))[inside]
    values = _turning_at(
        xy, where, np.repeat(scale, count), np.repeat(a, count), np.repeat(b, count)
    )
    theta = np.zeros((len(a), width))
    theta[inside] = values
    left = np.cumsum(theta, axis=1)  # turning from a to each candidate
    total = left[np.arange(len(a)), count - 1]
    # Sign changes between consecutive non-zero turnings (a zero can sit exactly on one).
    nonzero = np.flatnonzero(theta)
    rows, cols = np.divmod(nonzero, width)
    sign = np.sign(theta.ravel()[nonzero])
    flips = np.flatnonzero((rows[:-1] == rows[1:]) & (sign[:-1] != sign[1:]))
    if not flips.size:
        return cuts
    rows = rows[flips]
    change = (cols[flips] + cols[flips + 1]) // 2
    before = left.ravel()[rows * width + change]
    after = total[rows] - before
    score = np.minimum(np.abs(before), np.abs(after))
    score = np.where(np.sign(before) * np.sign(after) < 0, score, 0.0)
    # Per section the best score, the first of equals (lexsort is stable).
    order = np.lexsort((-score, rows))
    best = order[np.concatenate([[True], rows[order][1:] != rows[order][:-1]])]
    best = best[score[best] >= min_turn]
    cuts[sections[rows[best]]] = a[rows[best]] + 2 + change[best]
    return cuts


def signed_area(xy: Array) -> float:
    """Signed area enclosed by the polyline closed by its chord (counter-clockwise positive)."""
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _signed_areas(xy: Array, start: Indices, end: Indices) -> Array:
    """:func:`signed_area` of each ``xy[start[i] : end[i] + 1]``, summed relative to its start."""
    length = np.maximum(end - start, 0)
    offset = np.cumsum(length) - length
    area = np.zeros(len(length))
    count = int(offset[-1] + length[-1]) if len(length) else 0
    if count:
        edge = np.arange(count) - np.repeat(offset - start, length)
        x, y = xy[:, 0], xy[:, 1]
        origin_x, origin_y = np.repeat(x[start], length), np.repeat(y[start], length)
        ux, uy = x[edge] - origin_x, y[edge] - origin_y
        vx, vy = x[edge + 1] - origin_x, y[edge + 1] - origin_y
        filled = length > 0
        area[filled] = 0.5 * np.add.reduceat(ux * vy - uy * vx, offset[filled])
    return area


_FULL_TURN = 2.0 * np.pi - 1e-9
"""The largest central angle of a circular segment (the whole circle but a sliver)."""


def segment_angle(chord: float, area: float) -> float:
    """The central angle θ of the circular segment with this chord and (absolute) area (eq. 19).

    See :func:`segment_angles`.
    """
    return float(segment_angles(np.array([chord], dtype=float), np.array([area], dtype=float))[0])


def segment_angles(chord: Array, area: Array) -> Array:
    """Eq. 19 for arrays: central angles θ in [0, 2π) of the circular segments with these chords
    and (absolute) areas; 0 where either is not positive.

    Solves ``½ (c / (2 sin(θ/2)))² (θ − sin θ) = A``, i.e. the monotone ratio
    ``A / c² = (θ − sin θ) / (8 sin²(θ/2))``, with a table of cubics in ``log(A / c²)`` (good to
    about 1e-14); below it (θ < 1e-4) from the ratio's series, above it the whole circle (less
    the sliver of 1e-9).
    """
    chord, area = np.asarray(chord, dtype=float), np.asarray(area, dtype=float)
    start, cubics = _segment_table()
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        ratio = np.where((chord > 0) & (area > 0), area / (chord * chord), 0.0)
        at = np.minimum(np.maximum((np.log(ratio) - start) / _TABLE_STEP, 0.0), len(cubics))
        k = np.minimum(at.astype(np.intp), len(cubics) - 1)
        t = at - k
        c = cubics[k]
        theta = c[..., 0] + t * (c[..., 1] + t * (c[..., 2] + t * c[..., 3]))
        # Below the table, ratio = θ/12 (1 + θ²/30 + O(θ⁴)).
        small = 12.0 * ratio * (1.0 - 4.8 * ratio * ratio)
        return np.where(at > 0.0, np.minimum(theta, _FULL_TURN), small)


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
    dominant = np.asarray(dominant, dtype=np.intp)
    a, b = dominant[:-1], dominant[1:]
    m = len(a)
    if cuts is None:
        q = np.full(m, -1, dtype=np.intp)
    elif isinstance(cuts, np.ndarray):
        q = cuts.astype(np.intp)
    else:
        q = np.array([-1 if c is None else c for c in cuts], dtype=np.intp)
    split = np.flatnonzero((q > a) & (q < b))
    # The arcs: each section, or its part up to the inflection; then the parts after it.
    start, end = a, b
    if split.size:
        start = np.concatenate([a, q[split]])
        end = np.concatenate([b, b[split]])
        end[split] = q[split]
    area = _signed_areas(curve, start, end)
    chord = curve[end] - curve[start]
    phi = np.sign(area) * 0.5 * segment_angles(np.hypot(chord[:, 0], chord[:, 1]), np.abs(area))
    if not split.size:
        return -phi, phi
    # Two arcs: their chords' directions, and the section's chord's (alpha).
    vectors = np.concatenate([chord[split], chord[m:], curve[b[split]] - curve[a[split]]])
    direction = np.arctan2(vectors[:, 1], vectors[:, 0])
    n = len(split)
    alpha = direction[2 * n :]
    first, second = direction[:n] - phi[split] - alpha, direction[n : 2 * n] + phi[m:] - alpha
    tangents = wrap_angle(np.concatenate([first, second]))
    phi1, phi2 = -phi[:m], phi[:m]
    phi1[split], phi2[split] = tangents[:n], tangents[n:]
    return phi1, phi2


def sharpness(xy: Array, a: int, z: int, b: int) -> float:
    """Eq. 20: how close the contour ``a..b`` around ``z`` is to a corner (1) or an arc (0).

    Compares its area ``A_Z`` (closed by the chord ``ab``) with the triangle ``(a, z, b)``
    (``A_t``, sharpest) and the circular segment through ``a, z, b`` (``A_s``, roundest).
    """
    return float(sharpnesses(xy, np.array([a]), np.array([z]), np.array([b]))[0])


def sharpnesses(xy: Array, a: Indices, z: Indices, b: Indices) -> Array:
    """:func:`sharpness` of the contours ``xy[a[i]..b[i]]`` around ``xy[z[i]]``."""
    a, z, b = (np.asarray(k, dtype=np.intp) for k in (a, z, b))
    if not z.size:
        return np.zeros(z.shape)
    pa, pz, pb = xy[a], xy[z], xy[b]
    u, w = pa - pz, pb - pz
    lengths = np.hypot(u[:, 0], u[:, 1]) * np.hypot(w[:, 0], w[:, 1])
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        # The inscribed angle at z; the arc through z subtends 2π − 2γ at the centre.
        cosine = (u[:, 0] * w[:, 0] + u[:, 1] * w[:, 1]) / lengths
        gamma = np.arccos(np.minimum(np.maximum(cosine, -1.0), 1.0))
        chord = np.hypot(*(pb - pa).T)
        triangle = 0.5 * np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0])
        radius = chord / (2.0 * np.sin(gamma))
        theta = 2.0 * np.pi - 2.0 * gamma
        circle = 0.5 * radius * radius * (theta - np.sin(theta))
        contour = np.abs(_signed_areas(xy, a, b))
        sharp = (circle - contour) / (circle - triangle)
    rounded = ~(np.pi - gamma < 1e-9) & (circle > np.maximum(contour, triangle))
    sharp = np.where((chord > 0) & (triangle > 0) & rounded, sharp, 0.0)
    sharp = np.where(gamma < 1e-6, 1.0, sharp)  # a cusp (a and b on one ray from z)
    return np.where(lengths > 0, sharp, 0.0)
