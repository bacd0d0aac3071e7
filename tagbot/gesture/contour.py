"""Contour analysis for reconstruction (paper §6.1–6.3): resampling, smoothing, turning angles,
dominant points, inflections, circular-segment angles (eq. 19) and contour sharpness (eq. 20).

Every function works on one polyline ``(N, 2)`` with vectorised numpy; lengths are in the trace's
units.
"""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks

Array = NDArray[np.float64]
Indices = NDArray[np.intp]


def arc_length(xy: Array) -> Array:
    """Cumulative length along the polyline, starting at 0."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])


def decimate(xy: Array, radius: float) -> Array:
    """Keep a point only once it is at least ``radius`` from the last kept one (and the last).

    Removes jitter below ``radius`` that would otherwise inflate the arc length of a densely
    captured trace. Works through the points in vectorised chunks, so its cost is about
    (points + kept points) numpy steps of a few dozen points.
    """
    n = len(xy)
    if n < 3 or radius <= 0:
        return xy
    kept = [0]
    i = 0
    chunk = 64
    while True:
        block = xy[i + 1 : i + 1 + chunk]
        if not len(block):
            break
        far = np.flatnonzero(np.hypot(*(block - xy[i]).T) >= radius)
        if far.size:
            i = i + 1 + int(far[0])
            kept.append(i)
            chunk = 64
        elif i + 1 + chunk >= n:
            break
        else:
            chunk *= 2  # a long stretch of jitter: look further at once
    if kept[-1] != n - 1:
        kept.append(n - 1)
    return xy[kept]


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
    n = len(xy)
    i = np.arange(n)
    before = xy[i] - xy[np.maximum(i - support, 0)]
    after = xy[np.minimum(i + support, n - 1)] - xy[i]
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    dot = np.einsum("ij,ij->i", before, after)
    angle = np.arctan2(cross, dot)
    angle[[0, -1]] = 0.0
    return angle


def heading_changes(xy: Array, support: int = 1) -> Array:
    """Per sample, the change of direction of the chord ``support`` samples long centred there.

    Summing their absolute values gives the total absolute turning at that scale.
    """
    n = len(xy)
    half = support // 2
    i = np.arange(n)
    chords = xy[np.minimum(i + support - half, n - 1)] - xy[np.maximum(i - half, 0)]
    heading = np.arctan2(chords[:, 1], chords[:, 0])
    change = np.zeros(n)
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
    while len(points) > 2:
        idx = np.asarray(points)
        span = int(reach * support)
        here = idx[1:-1]
        near = chord_turn(
            xy, np.maximum(idx[:-2], here - span), here, np.minimum(idx[2:], here + span)
        )
        turns = np.maximum(chord_turn(xy, idx[:-2], here, idx[2:]), near)
        weakest = int(np.argmin(turns))
        if turns[weakest] >= threshold:
            break
        del points[weakest + 1]
    return np.asarray(points, dtype=np.intp)


def add_turning_points(
    xy: Array, points: Indices, max_turn: float = np.pi, support: int = 1
) -> Indices:
    """Add ⌊θ̂ / max_turn⌋ points equally spaced along each section turning θ̂ > ``max_turn``.

    θ̂ is the section's total absolute turning, measured on chords ``support`` samples long (so
    that jitter below that scale does not add up), leaving out half a support at each interior
    salient point: a corner's own turning is the corner's.
    """
    step_turn = np.abs(heading_changes(xy, support))
    margin = support // 2
    s = arc_length(xy)
    last = len(xy) - 1
    out = [int(points[0])]
    for a, b in itertools.pairwise(points):
        lo = a + 1 + (margin if a > 0 else 0)
        hi = b - (margin if b < last else 0)
        total = float(np.sum(step_turn[lo:hi]))
        extra = int(total // max_turn)
        if extra:
            targets = np.linspace(s[a], s[b], extra + 2)[1:-1]
            inner = np.clip(np.searchsorted(s, targets), a + 1, b - 1)
            out.extend(sorted(set(inner.tolist())))
        out.append(int(b))
    return np.asarray(sorted(set(out)), dtype=np.intp)


def inflection(xy: Array, a: int, b: int, support: int, min_turn: float) -> int | None:
    """The most significant inflection strictly inside section ``a..b``, or None.

    An inflection is a sign change of the turning (at ``support`` samples) where the section
    turns at least ``min_turn`` (rad) on each side, in opposite directions; among several, the
    one that splits the turning most evenly.
    """
    if b - a < 4:
        return None
    theta = turning(xy, max(1, min(support, (b - a) // 4)))[a + 1 : b]
    left = np.cumsum(theta)  # turning from a to each candidate
    right = left[-1] - left
    # Sign changes between consecutive non-zero turnings (a zero can sit exactly on one).
    nonzero = np.flatnonzero(theta != 0)
    flips = np.flatnonzero(np.sign(theta[nonzero[:-1]]) != np.sign(theta[nonzero[1:]]))
    change = (nonzero[flips] + nonzero[flips + 1]) // 2
    if not change.size:
        return None
    score = np.minimum(np.abs(left[change]), np.abs(right[change]))
    opposite = np.sign(left[change]) * np.sign(right[change]) < 0
    score = np.where(opposite, score, 0.0)
    best = int(np.argmax(score))
    if score[best] < min_turn:
        return None
    return a + 1 + int(change[best]) + 1


def signed_area(xy: Array) -> float:
    """Signed area enclosed by the polyline closed by its chord (counter-clockwise positive)."""
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def segment_angle(chord: float, area: float) -> float:
    """The central angle θ of the circular segment with this chord and (absolute) area (eq. 19).

    Solves ``½ (c / (2 sin(θ/2)))² (θ − sin θ) = A`` for θ in [0, 2π) by bisection on the
    monotone ratio ``A / c² = (θ − sin θ) / (8 sin²(θ/2))``.
    """
    if chord <= 0 or area <= 0:
        return 0.0
    ratio = area / (chord * chord)
    lo, hi = 0.0, 2.0 * np.pi - 1e-9
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        value = (mid - np.sin(mid)) / (8.0 * np.sin(0.5 * mid) ** 2)
        if value < ratio:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def arc_deviation(xy: Array) -> float:
    """The ΣΛ* deviation ``phi`` of the circular arc fitted to a section by its area.

    ``phi = sign(A)·θ/2``: the arc leaves at ``alpha − phi`` from the chord direction ``alpha``;
    a positive signed area (the contour right of the chord, turning left) gives ``phi > 0``.
    """
    area = signed_area(xy)
    chord = float(np.hypot(*(xy[-1] - xy[0])))
    return float(np.sign(area)) * 0.5 * segment_angle(chord, abs(area))


def sharpness(xy: Array, a: int, z: int, b: int) -> float:
    """Eq. 20: how close the contour ``a..b`` around ``z`` is to a corner (1) or an arc (0).

    Compares its area ``A_Z`` (closed by the chord ``ab``) with the triangle ``(a, z, b)``
    (``A_t``, sharpest) and the circular segment through ``a, z, b`` (``A_s``, roundest).
    """
    pa, pz, pb = xy[a], xy[z], xy[b]
    u, w = pa - pz, pb - pz
    lengths = float(np.hypot(*u) * np.hypot(*w))
    if lengths <= 0:
        return 0.0
    # The inscribed angle at z; the arc through z subtends 2π − 2γ at the centre.
    gamma = float(np.arccos(np.clip(np.dot(u, w) / lengths, -1.0, 1.0)))
    if gamma < 1e-6:  # a cusp (a and b on one ray from z): as sharp as it gets
        return 1.0
    chord = float(np.hypot(*(pb - pa)))
    triangle = 0.5 * abs(float(u[0] * w[1] - u[1] * w[0]))
    if chord <= 0 or triangle <= 0 or np.pi - gamma < 1e-9:  # straight through
        return 0.0
    radius = chord / (2.0 * np.sin(gamma))
    theta = 2.0 * np.pi - 2.0 * gamma
    circle = 0.5 * radius * radius * (theta - np.sin(theta))
    contour = abs(signed_area(xy[a : b + 1]))
    if not circle > max(contour, triangle):
        return 0.0
    return (circle - contour) / (circle - triangle)
