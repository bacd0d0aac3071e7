"""Compiled loops of the contour analysis (numba), behind :mod:`tagbot.gesture.contour`.

A trace's analysis runs many small steps on a few hundred points, where numpy's per-call cost
was most of the time; each step here is one loop. The loops repeat the arithmetic of the numpy
and scipy code they replaced operation for operation, so the results are the same to the bit:
the same sums in the same order (numpy's pairwise summation where numpy summed, scipy's
symmetric correlation for the Gaussian, ``np.interp``'s slopes), and scipy's ``find_peaks``
(local maxima, distance, prominence) line by line.

Arctangents and arccosines whose last bit can decide an integer result (the turning angles,
heading changes and inflections, the sharpness's inscribed angle) are left to numpy, whose
vectorised versions round differently from the C library's: the loops return their arguments,
and take the angles back. Only the turn of salient candidates (:func:`chord_turn`, compared with
each other and a threshold, never near a tie on real traces), and eq. 19's logarithm and the
tangents of :func:`section_deviations` (floats only) use the C library's, within an ulp of numpy's.

Small helpers that take arrays are inlined where they run per sample; ``line[i - k]`` style
indices are avoided in the inner loops (numba's wraparound of negative indices stops
vectorisation: views are indexed instead).
"""

from __future__ import annotations

import math

import numpy as np

from tagbot.model.kernels import compiled, inlined

_PAIRWISE_BLOCK = 128
"""numpy's block for pairwise summation (``PW_BLOCKSIZE``)."""
FULL_TURN = 2.0 * np.pi - 1e-9
"""The largest central angle of a circular segment (the whole circle but a sliver)."""
_TWO_PI = 2.0 * np.pi


# --- sums and small helpers ---------------------------------------------------------------------


@compiled
def pairwise_sum(values, lo, n):  # type: ignore[no-untyped-def]
    """``values[lo : lo + n]`` summed as numpy's ``add.reduce`` does: halves (cut at a multiple
    of 8) summed recursively down to blocks of :data:`_PAIRWISE_BLOCK`, each block with 8
    accumulators. The recursion runs on a stack of its own (numba cannot cache recursion)."""
    if n <= _PAIRWISE_BLOCK:
        return _block_sum(values, lo, n)
    # Per pending range: where it starts, its length, its left half's sum once known.
    starts, counts = np.empty(64, np.intp), np.empty(64, np.intp)
    lefts, left_done = np.empty(64), np.zeros(64, np.bool_)
    starts[0], counts[0], left_done[0] = lo, n, False
    top = 1
    while True:
        count = counts[top - 1]
        if count > _PAIRWISE_BLOCK:  # the left half first
            half = count // 2 - (count // 2) % 8
            starts[top], counts[top], left_done[top] = starts[top - 1], half, False
            top += 1
            continue
        value = _block_sum(values, starts[top - 1], count)
        top -= 1
        while top:  # hand the sum up: a left half's, then the right half is next
            f = top - 1
            if not left_done[f]:
                half = counts[f] // 2 - (counts[f] // 2) % 8
                lefts[f], left_done[f] = value, True
                starts[top], counts[top], left_done[top] = starts[f] + half, counts[f] - half, False
                top += 1
                break
            value = lefts[f] + value
            top -= 1
        if not top:
            return value


@compiled
def _block_sum(values, lo, n):  # type: ignore[no-untyped-def]
    """numpy's pairwise summation of at most :data:`_PAIRWISE_BLOCK` values."""
    if n < 8:
        total = 0.0
        for i in range(lo, lo + n):
            total += values[i]
        return total
    r0, r1, r2, r3 = values[lo], values[lo + 1], values[lo + 2], values[lo + 3]
    r4, r5, r6, r7 = values[lo + 4], values[lo + 5], values[lo + 6], values[lo + 7]
    i = 8
    while i < n - n % 8:
        j = lo + i
        r0 += values[j]
        r1 += values[j + 1]
        r2 += values[j + 2]
        r3 += values[j + 3]
        r4 += values[j + 4]
        r5 += values[j + 5]
        r6 += values[j + 6]
        r7 += values[j + 7]
        i += 8
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for j in range(lo + i, lo + n):
        total += values[j]
    return total


@compiled
def signed_area(xy, start, end, terms):  # type: ignore[no-untyped-def]
    """The signed area of ``xy[start : end + 1]`` closed by its chord, summed relative to its
    start as ``np.add.reduceat`` did (the first term, then the rest pairwise); ``terms`` is
    scratch space."""
    count = end - start
    if count <= 0:
        return 0.0
    ox, oy = xy[start, 0], xy[start, 1]
    for k in range(count):
        ux, uy = xy[start + k, 0] - ox, xy[start + k, 1] - oy
        vx, vy = xy[start + k + 1, 0] - ox, xy[start + k + 1, 1] - oy
        terms[k] = ux * vy - uy * vx
    return 0.5 * (terms[0] + pairwise_sum(terms, 1, count - 1))


@compiled
def _sign(value):  # type: ignore[no-untyped-def]
    """``np.sign``."""
    if value > 0.0:
        return 1.0
    if value < 0.0:
        return -1.0
    return 0.0 if value == 0.0 else value  # nan stays


@compiled
def _maximum(a, b):  # type: ignore[no-untyped-def]
    """``np.maximum`` (nan if either is)."""
    if a != a or b != b:
        return a + b
    return a if a >= b else b


@compiled
def _clip(i, lo, hi):  # type: ignore[no-untyped-def]
    return lo if i < lo else (hi if i > hi else i)


# --- polylines ----------------------------------------------------------------------------------


@compiled
def arc_length(xy: np.ndarray) -> np.ndarray:
    """Cumulative length along the polyline, starting at 0."""
    n = xy.shape[0]
    s = np.empty(max(n, 1))
    s[0] = 0.0
    for i in range(1, n):
        s[i] = s[i - 1] + math.hypot(xy[i, 0] - xy[i - 1, 0], xy[i, 1] - xy[i - 1, 1])
    return s


@compiled
def decimate(xy: np.ndarray, radius: float) -> tuple[np.ndarray, float]:
    """The points kept at least ``radius`` from the last kept one (and the last), and their
    path length. Fewer than 3 points or ``radius <= 0``: all of them."""
    n = xy.shape[0]
    kept = np.empty(n, np.intp)
    m = 0
    if n < 3 or radius <= 0.0:
        for i in range(n):
            kept[i] = i
        m = n
    else:
        kept[0] = 0
        m = 1
        i = 0
        for j in range(1, n):
            if math.hypot(xy[j, 0] - xy[i, 0], xy[j, 1] - xy[i, 1]) >= radius:
                kept[m] = j
                m += 1
                i = j
        if kept[m - 1] != n - 1:
            kept[m] = n - 1
            m += 1
    out = np.empty((m, 2))
    length = 0.0
    for k in range(m):
        out[k, 0], out[k, 1] = xy[kept[k], 0], xy[kept[k], 1]
        if k:
            length += math.hypot(out[k, 0] - out[k - 1, 0], out[k, 1] - out[k - 1, 1])
    return out, length


@compiled
def resample(xy: np.ndarray, step: float) -> np.ndarray:
    """Points equally spaced along the polyline (``np.linspace`` of the length, ``np.interp``
    along it, repeated points left out), at most ``step`` apart, both ends kept."""
    s = arc_length(xy)
    total = s[s.size - 1]
    count = max(2, math.ceil(total / step) + 1)
    # The distinct points: the first, and each one further along than the one before.
    along, points = np.empty(s.size), np.empty((s.size, 2))
    m = 0
    for i in range(s.size):
        if i == 0 or s[i] - s[i - 1] > 0.0:
            along[m], points[m, 0], points[m, 1] = s[i], xy[i, 0], xy[i, 1]
            m += 1
    out = np.empty((count, 2))
    div = count - 1
    step_ = total / div
    j = 0  # the last distinct point at or before u (np.interp's search)
    for i in range(count):
        if i == div:
            u = total
        elif step_ == 0.0:
            u = i / div * total + 0.0
        else:
            u = i * step_ + 0.0
        while j + 1 < m and along[j + 1] <= u:
            j += 1
        # np.interp, inline (a helper taking arrays costs more than the work here).
        for c in range(2):
            if u != u:
                value = u
            elif u < along[0]:
                value = points[0, c]
            elif u > along[m - 1] or j == m - 1:
                value = points[m - 1, c]
            elif along[j] == u:
                value = points[j, c]
            else:
                slope = (points[j + 1, c] - points[j, c]) / (along[j + 1] - along[j])
                value = slope * (u - along[j]) + points[j, c]
                if value != value:  # nan one way: try the other
                    value = slope * (u - along[j + 1]) + points[j + 1, c]
                    if value != value and points[j, c] == points[j + 1, c]:
                        value = points[j, c]
            out[i, c] = value
    return out


@compiled
def smooth(xy: np.ndarray, weights: np.ndarray, pad: int) -> np.ndarray:
    """The Gaussian average of :func:`tagbot.gesture.contour.smooth`: the curve extended by
    ``pad`` point reflections at each end, correlated with the symmetric kernel whose centre
    and right half are ``weights`` (scipy's ``correlate1d``, mode ``nearest``); ends kept."""
    n = xy.shape[0]
    radius = weights.size - 1
    size = n + 2 * pad
    origin = radius + pad  # where xy[0] sits in the extended line
    line = np.empty(size + 2 * radius)
    out = np.empty((n, 2))
    total = np.empty(n)
    for c in range(2):
        for i in range(pad):
            line[radius + i] = 2.0 * xy[0, c] - xy[pad - i, c]
            line[origin + n + i] = 2.0 * xy[n - 1, c] - xy[n - 2 - i, c]
        for i in range(n):
            line[origin + i] = xy[i, c]
        for i in range(radius):  # scipy's "nearest" beyond the reflections
            line[i] = line[radius]
            line[radius + size + i] = line[radius + size - 1]
        # Each output sums its terms in scipy's order, the outermost pair first; the loop over
        # the outputs is the inner one.
        centre = line[origin:]
        for i in range(n):
            total[i] = centre[i] * weights[0]
        for k in range(radius, 0, -1):
            weight, before, after = weights[k], line[origin - k :], line[origin + k :]
            for i in range(n):
                total[i] += (before[i] + after[i]) * weight
        for i in range(n):
            out[i, c] = total[i]
        out[0, c], out[n - 1, c] = xy[0, c], xy[n - 1, c]
    return out


# --- turning ------------------------------------------------------------------------------------


@compiled
def turning_parts(xy: np.ndarray, support: int) -> np.ndarray:
    """Cross and dot products ``(2, N)`` of the chords ``support`` samples before and after each
    point (held at the ends); 0 at the first and last point. Their ``arctan2`` is the turning."""
    n = xy.shape[0]
    parts = np.zeros((2, n))
    for i in range(1, n - 1):
        p, q = _clip(i - support, 0, n - 1), _clip(i + support, 0, n - 1)
        bx, by = xy[i, 0] - xy[p, 0], xy[i, 1] - xy[p, 1]
        ax, ay = xy[q, 0] - xy[i, 0], xy[q, 1] - xy[i, 1]
        parts[0, i] = bx * ay - by * ax
        parts[1, i] = bx * ax + by * ay + 0.0  # +0, never −0 (atan2(0, −0) = π)
    return parts


@compiled
def heading_chords(xy: np.ndarray, support: int) -> np.ndarray:
    """Per sample, the chord ``support`` samples long centred there, ``(2, N)``: y, then x."""
    n = xy.shape[0]
    half = support // 2
    chords = np.empty((2, n))
    for i in range(n):
        p, q = _clip(i - half, 0, n - 1), _clip(i + support - half, 0, n - 1)
        chords[0, i] = xy[q, 1] - xy[p, 1]
        chords[1, i] = xy[q, 0] - xy[p, 0]
    return chords


@compiled
def heading_steps(heading: np.ndarray) -> np.ndarray:
    """``exp(i·Δheading)`` per sample as ``(2, N)`` sines and cosines (``(0, 1)`` at the
    first); their ``arctan2`` is the change of heading wrapped into (−π, π]."""
    n = heading.size
    steps = np.empty((2, n))
    for i in range(n):
        if i == 0:
            steps[0, i], steps[1, i] = 0.0, 1.0
        else:
            change = 0.0 + (heading[i] - heading[i - 1])  # as the imaginary part of 1j·Δ
            steps[0, i], steps[1, i] = math.sin(change), math.cos(change)
    return steps


@inlined
def chord_turn_at(xy, prev, here, nxt):  # type: ignore[no-untyped-def]
    """Absolute turning angle at ``xy[here]`` between the chords from ``xy[prev]`` and to
    ``xy[nxt]``."""
    ax, ay = xy[here, 0] - xy[prev, 0], xy[here, 1] - xy[prev, 1]
    bx, by = xy[nxt, 0] - xy[here, 0], xy[nxt, 1] - xy[here, 1]
    return abs(math.atan2(ax * by - ay * bx, ax * bx + ay * by + 0.0))


@compiled
def chord_turn(xy: np.ndarray, prev: np.ndarray, here: np.ndarray, nxt: np.ndarray) -> np.ndarray:
    """:func:`chord_turn_at` of each triple."""
    out = np.empty(here.size)
    for k in range(here.size):
        out[k] = chord_turn_at(xy, prev[k], here[k], nxt[k])
    return out


# --- salient and turning points -----------------------------------------------------------------


@compiled
def local_maxima(turning: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``|turning|``, its local maxima (the middle of flat ones) and their heights: scipy's
    ``_local_maxima_1d``."""
    n = turning.size
    height = np.empty(n)
    for i in range(n):
        height[i] = abs(turning[i])
    peaks = np.empty(n // 2, np.intp)
    m = 0
    i, last = 1, n - 1
    while i < last:
        if height[i - 1] < height[i]:
            ahead = i + 1
            while ahead < last and height[ahead] == height[i]:
                ahead += 1
            if height[ahead] < height[i]:
                peaks[m] = (i + ahead - 1) // 2
                m += 1
                i = ahead
        i += 1
    priority = np.empty(m)
    for k in range(m):
        priority[k] = height[peaks[k]]
    return height, peaks[:m].copy(), priority


@compiled
def _select_peaks(height, peaks, order, distance, prominence):  # type: ignore[no-untyped-def]
    """The ``peaks`` that scipy's ``find_peaks`` keeps for ``distance`` (``order``:
    ``np.argsort`` of their heights, highest first from the end) and then ``prominence``."""
    m = peaks.size
    keep = np.ones(m, np.bool_)
    for r in range(m - 1, -1, -1):
        j = order[r]
        if not keep[j]:
            continue
        k = j - 1
        while k >= 0 and peaks[j] - peaks[k] < distance:
            keep[k] = False
            k -= 1
        k = j + 1
        while k < m and peaks[k] - peaks[j] < distance:
            keep[k] = False
            k += 1
    out = np.empty(m, np.intp)
    count = 0
    last = height.size - 1
    for j in range(m):
        if not keep[j]:
            continue
        peak = peaks[j]
        top = height[peak]
        left = top
        i = peak
        while i >= 0 and height[i] <= top:
            if height[i] < left:
                left = height[i]
            i -= 1
        right = top
        i = peak
        while i <= last and height[i] <= top:
            if height[i] < right:
                right = height[i]
            i += 1
        if prominence <= top - max(left, right):
            out[count] = peak
            count += 1
    return out[:count]


@inlined
def _salient_turn(xy, prev, here, nxt, span):  # type: ignore[no-untyped-def]
    """The turn of a salient candidate (:func:`tagbot.gesture.contour.salient_points`)."""
    near = chord_turn_at(xy, max(prev, here - span), here, min(nxt, here + span))
    return _maximum(chord_turn_at(xy, prev, here, nxt), near)


@compiled
def salient_points(
    xy: np.ndarray,
    height: np.ndarray,
    peaks: np.ndarray,
    order: np.ndarray,
    support: int,
    threshold: float,
    prominence: float,
    span: int,
) -> np.ndarray:
    """The ends and the peaks of ``height`` that ``find_peaks`` keeps and that lie a support
    from the ends; then, while the weakest of them turns less than ``threshold`` between its
    neighbours, without it."""
    n = xy.shape[0]
    found = _select_peaks(height, peaks, order, support, prominence)
    points = np.empty(found.size + 2, np.intp)
    points[0] = 0
    m = 1
    for peak in found:
        if support <= peak <= n - 1 - support:
            points[m] = peak
            m += 1
    points[m] = n - 1
    m += 1
    return _drop_weak(xy, points[:m], threshold, span)


@compiled
def _drop_weak(xy, points, threshold, span):  # type: ignore[no-untyped-def]
    """``points`` without, repeatedly, the interior one turning least between its neighbours
    (``np.argmin``'s: the first nan, else the first of the smallest) while that is less than
    ``threshold``. A heap of the turns with stale entries skipped: O(m log m) for m points."""
    m = points.size
    before, after = np.arange(-1, m - 1), np.arange(1, m + 1)
    alive = np.ones(m, np.bool_)
    version = np.zeros(m, np.intp)
    # Heap entries: (turn, node, the node's version when pushed); at most one per point at first
    # and two per dropped point after.
    turn_of = np.empty(3 * m)
    node_of, version_of = np.empty(3 * m, np.intp), np.empty(3 * m, np.intp)
    size = 0
    for k in range(1, m - 1):
        turn = _salient_turn(xy, points[k - 1], points[k], points[k + 1], span)
        size = _push(turn_of, node_of, version_of, size, turn, k, 0)
    while size:
        turn, k, stamp = turn_of[0], node_of[0], version_of[0]
        size = _pop(turn_of, node_of, version_of, size)
        if not alive[k] or stamp != version[k]:
            continue  # dropped, or its turn changed since
        if turn >= threshold:
            break
        alive[k] = False
        p, q = before[k], after[k]
        after[p], before[q] = q, p
        # Only the dropped point's neighbours turn differently now.
        for j in (p, q):
            if 0 < j < m - 1:
                version[j] += 1
                turn = _salient_turn(xy, points[before[j]], points[j], points[after[j]], span)
                size = _push(turn_of, node_of, version_of, size, turn, j, version[j])
    return points[alive].copy()


@compiled
def _first(turn_a, node_a, turn_b, node_b):  # type: ignore[no-untyped-def]
    """Whether entry a comes before b: nan first, then the smaller turn, then the earlier."""
    if turn_a != turn_a or turn_b != turn_b:
        if turn_a == turn_a:
            return False
        if turn_b == turn_b:
            return True
        return node_a < node_b
    return turn_a < turn_b or (turn_a == turn_b and node_a < node_b)


@compiled
def _push(turn_of, node_of, version_of, size, turn, node, stamp):  # type: ignore[no-untyped-def]
    """Add an entry to the binary heap of the first ``size`` entries; returns the new size."""
    i = size
    while i > 0:
        parent = (i - 1) // 2
        if not _first(turn, node, turn_of[parent], node_of[parent]):
            break
        turn_of[i], node_of[i], version_of[i] = turn_of[parent], node_of[parent], version_of[parent]
        i = parent
    turn_of[i], node_of[i], version_of[i] = turn, node, stamp
    return size + 1


@compiled
def _pop(turn_of, node_of, version_of, size):  # type: ignore[no-untyped-def]
    """Remove the heap's first entry; returns the new size."""
    size -= 1
    turn, node, stamp = turn_of[size], node_of[size], version_of[size]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and _first(
            turn_of[child + 1], node_of[child + 1], turn_of[child], node_of[child]
        ):
            child += 1
        if not _first(turn_of[child], node_of[child], turn, node):
            break
        turn_of[i], node_of[i], version_of[i] = turn_of[child], node_of[child], version_of[child]
        i = child
    if size:
        turn_of[i], node_of[i], version_of[i] = turn, node, stamp
    return size


@compiled
def add_turning_points(
    xy: np.ndarray, points: np.ndarray, change: np.ndarray, max_turn: float, support: int
) -> np.ndarray:
    """``points`` with ⌊θ̂ / max_turn⌋ more equally spaced along each section (θ̂: the sum of
    ``|change|`` over the section less half a support at interior ends), sorted and unique."""
    n = xy.shape[0]
    values = np.empty(n)
    cumulative = np.empty(n + 1)
    cumulative[0] = 0.0
    for i in range(n):
        values[i] = abs(change[i])
        cumulative[i + 1] = cumulative[i] + values[i]
    margin = support // 2
    last = n - 1
    # Rounding in the cumulative sums stays far below this margin (else: summed as np.sum).
    slack = 4.0 * (n + 1) * 2.220446049250313e-16 * (cumulative[n] + abs(max_turn))
    extra = np.zeros(max(points.size - 1, 0), np.intp)
    for k in range(points.size - 1):
        a, b = points[k], points[k + 1]
        lo = a + 1 + (margin if a > 0 else 0)
        hi = b - (margin if b < last else 0)
        total, near = 0.0, False
        if lo >= 0 and hi >= 0:
            start, stop = min(lo, n), min(hi, n)
            if stop > start:
                total = cumulative[stop] - cumulative[start]
            whole = np.rint(total / max_turn)
            near = whole >= 1 and abs(total - whole * max_turn) <= slack
        if lo < 0 or hi < 0 or near:
            start, stop = _slice(lo, n), _slice(hi, n)
            total = pairwise_sum(values, start, stop - start) if stop > start else 0.0
        extra[k] = int(total // max_turn)
    more = 0
    for k in range(extra.size):
        more += max(extra[k], 0)
    out = np.empty(points.size + more, np.intp)
    out[: points.size] = points
    m = points.size
    s = arc_length(xy) if more else np.zeros(0)
    for k in range(points.size - 1):
        count = extra[k]
        if count <= 0:
            continue
        # As np.linspace(s[a], s[b], count + 2)[1:-1].
        a, b = points[k], points[k + 1]
        origin, span = s[a], s[b] - s[a]
        div = float(count + 1)
        step = span / div
        for j in range(1, count + 1):
            offset = j / div * span if step == 0.0 else j * step
            inner = np.searchsorted(s, offset + origin)
            out[m] = min(max(inner, a + 1), b - 1)
            m += 1
    return np.unique(out)


@compiled
def _slice(i, n):  # type: ignore[no-untyped-def]
    """A Python slice bound ``i`` into ``0..n``."""
    if i < 0:
        i += n
        return i if i > 0 else 0
    return i if i < n else n


# --- inflections --------------------------------------------------------------------------------


@compiled
def inflection_parts(xy: np.ndarray, dominant: np.ndarray, support: int) -> np.ndarray:
    """Cross and dot products ``(2, M)`` of the turning at every point strictly inside each
    section of at least 4 samples, measured within the section, sections one after another."""
    total = 0
    for k in range(dominant.size - 1):
        a, b = dominant[k], dominant[k + 1]
        if b - a >= 4:
            total += b - a - 1
    parts = np.empty((2, total))
    p = 0
    for k in range(dominant.size - 1):
        a, b = dominant[k], dominant[k + 1]
        if b - a < 4:
            continue
        scale = max(1, min(support, (b - a) // 4))
        for i in range(a + 1, b):
            prev, nxt = max(i - scale, a), min(i + scale, b)
            bx, by = xy[i, 0] - xy[prev, 0], xy[i, 1] - xy[prev, 1]
            ax, ay = xy[nxt, 0] - xy[i, 0], xy[nxt, 1] - xy[i, 1]
            parts[0, p] = bx * ay - by * ax
            parts[1, p] = bx * ax + by * ay + 0.0
            p += 1
    return parts


@compiled
def inflections(theta: np.ndarray, dominant: np.ndarray, min_turn: float) -> np.ndarray:
    """Per section, the inflection that splits the turning ``theta`` (from
    :func:`inflection_parts`) most evenly, if it turns at least ``min_turn`` either way; -1
    where none."""
    cuts = np.full(max(dominant.size - 1, 0), -1, np.intp)
    left = np.empty(theta.size)
    p = 0
    for k in range(dominant.size - 1):
        a, b = dominant[k], dominant[k + 1]
        if b - a < 4:
            continue
        count = b - a - 1
        left[0] = theta[p]
        for c in range(1, count):
            left[c] = left[c - 1] + theta[p + c]
        total = left[count - 1]
        best, best_score = -1, 0.0
        previous = -1  # the last non-zero turning
        for c in range(count):
            value = theta[p + c]
            if value == 0.0:
                continue
            if previous >= 0 and _sign(theta[p + previous]) != _sign(value):
                change = (previous + c) // 2
                before = left[change]
                after = total - before
                score = min(abs(before), abs(after))
                if not _sign(before) * _sign(after) < 0.0:
                    score = 0.0
                if best < 0 or score > best_score:
                    best, best_score = change, score
            previous = c
        if best >= 0 and best_score >= min_turn:
            cuts[k] = a + 2 + best
        p += count
    return cuts


# --- circular segments (eq. 19) and sharpness (eq. 20) ------------------------------------------


@inlined
def segment_angle(chord, area, start, step, cubics):  # type: ignore[no-untyped-def]
    """Eq. 19 for one segment, from the table of cubics of
    :func:`tagbot.gesture.contour._segment_table` (its first ``log(A / c²)`` is ``start``,
    its spacing ``step``)."""
    ratio = area / (chord * chord) if chord > 0.0 and area > 0.0 else 0.0
    size = cubics.shape[0]
    at = min(max((math.log(ratio) - start) / step, 0.0), float(size))
    k = min(int(at), size - 1)
    t = at - k
    if at > 0.0:
        theta = cubics[k, 0] + t * (cubics[k, 1] + t * (cubics[k, 2] + t * cubics[k, 3]))
        return min(theta, FULL_TURN)
    # Below the table, ratio = θ/12 (1 + θ²/30 + O(θ⁴)).
    return 12.0 * ratio * (1.0 - 4.8 * ratio * ratio)


@compiled
def segment_angles(
    chord: np.ndarray, area: np.ndarray, start: float, step: float, cubics: np.ndarray
) -> np.ndarray:
    """:func:`segment_angle` of each pair."""
    out = np.empty(chord.size)
    for k in range(chord.size):
        out[k] = segment_angle(chord[k], area[k], start, step, cubics)
    return out


@inlined
def _arc_deviation(xy, a, b, terms, start, step, cubics):  # type: ignore[no-untyped-def]
    """The ΣΛ* deviation ``sign(A)·θ/2`` of the arc fitted to ``xy[a : b + 1]`` by its area."""
    area = signed_area(xy, a, b, terms)
    chord = math.hypot(xy[b, 0] - xy[a, 0], xy[b, 1] - xy[a, 1])
    return _sign(area) * 0.5 * segment_angle(chord, abs(area), start, step, cubics)


@inlined
def _direction(xy, a, b):  # type: ignore[no-untyped-def]
    return math.atan2(xy[b, 1] - xy[a, 1], xy[b, 0] - xy[a, 0])


@compiled
def _wrap(angle):  # type: ignore[no-untyped-def]
    """:func:`tagbot.model.euler.wrap_angle`."""
    return np.pi - (np.pi - angle) % _TWO_PI


@compiled
def section_deviations(
    xy: np.ndarray,
    dominant: np.ndarray,
    cuts: np.ndarray,
    start: float,
    step: float,
    cubics: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``(phi1, phi2)`` of every section: one arc by its area, or one on each side of its cut
    where that is strictly inside (the first's start and the second's end tangent, from the
    section's chord)."""
    m = max(dominant.size - 1, 0)
    phi1, phi2 = np.empty(m), np.empty(m)
    terms = np.empty(max(xy.shape[0], 1))
    for k in range(m):
        a, b, q = dominant[k], dominant[k + 1], cuts[k]
        if a < q < b:
            alpha = _direction(xy, a, b)
            first = _arc_deviation(xy, a, q, terms, start, step, cubics)
            second = _arc_deviation(xy, q, b, terms, start, step, cubics)
            phi1[k] = _wrap(_direction(xy, a, q) - first - alpha)
            phi2[k] = _wrap(_direction(xy, q, b) + second - alpha)
        else:
            phi = _arc_deviation(xy, a, b, terms, start, step, cubics)
            phi1[k], phi2[k] = -phi, phi
    return phi1, phi2


@compiled
def sharpness_cosines(xy: np.ndarray, a: np.ndarray, z: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cosine of the angle ``(a, z, b)`` at ``z``, clipped to [−1, 1] (nan where a side has
    no length): its ``arccos`` is eq. 20's inscribed angle."""
    out = np.empty(z.size)
    for k in range(z.size):
        ux, uy = xy[a[k], 0] - xy[z[k], 0], xy[a[k], 1] - xy[z[k], 1]
        wx, wy = xy[b[k], 0] - xy[z[k], 0], xy[b[k], 1] - xy[z[k], 1]
        lengths = math.hypot(ux, uy) * math.hypot(wx, wy)
        cosine = (ux * wx + uy * wy) / lengths
        out[k] = -1.0 if cosine < -1.0 else (1.0 if cosine > 1.0 else cosine)
    return out


@compiled
def sharpnesses(
    xy: np.ndarray, a: np.ndarray, z: np.ndarray, b: np.ndarray, gamma: np.ndarray
) -> np.ndarray:
    """Eq. 20 for the contours ``xy[a..b]`` around ``xy[z]``, given their inscribed angles."""
    out = np.empty(z.size)
    terms = np.empty(max(xy.shape[0], 1))
    for k in range(z.size):
        ux, uy = xy[a[k], 0] - xy[z[k], 0], xy[a[k], 1] - xy[z[k], 1]
        wx, wy = xy[b[k], 0] - xy[z[k], 0], xy[b[k], 1] - xy[z[k], 1]
        lengths = math.hypot(ux, uy) * math.hypot(wx, wy)
        angle = gamma[k]
        # The arc through z subtends 2π − 2γ at the centre.
        chord = math.hypot(xy[b[k], 0] - xy[a[k], 0], xy[b[k], 1] - xy[a[k], 1])
        triangle = 0.5 * abs(ux * wy - uy * wx)
        radius = chord / (2.0 * math.sin(angle))
        theta = _TWO_PI - 2.0 * angle
        circle = 0.5 * radius * radius * (theta - math.sin(theta))
        contour = abs(signed_area(xy, a[k], b[k], terms))
        sharp = (circle - contour) / (circle - triangle)
        rounded = not (np.pi - angle < 1e-9) and circle > _maximum(contour, triangle)
        if not (chord > 0.0 and triangle > 0.0 and rounded):
            sharp = 0.0
        if angle < 1e-6:
            sharp = 1.0  # a cusp (a and b on one ray from z)
        out[k] = sharp if lengths > 0.0 else 0.0
    return out
