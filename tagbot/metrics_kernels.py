"""Compiled loops of the metrics (numba): each query point's exact distance to a set of
polylines, found through a uniform grid of their segments (see
:func:`tagbot.metrics.shape_error`), and the velocity SNR's recorded velocity and search (see
:func:`tagbot.metrics.velocity_snr`).

The polylines are given as their segments ``(ax, ay, bx − ax, by − ay, 1 / length²)`` (K, 5; 0
for a point), the polylines' own cut at their samples, each at most ``spacing`` long (a polyline
of one point: one segment of length 0); the fine grid holds each segment in every cell its
bounding box meets, the coarse one (for queries far from the polylines) in the cell of its
midpoint.
"""

from __future__ import annotations

import math

import numpy as np

from tagbot.gesture.refine_kernels import buckets
from tagbot.inputs import stamps_kernels
from tagbot.model.kernels import compiled, inlined

__all__ = [
    "COARSE",
    "DIRECT",
    "arc_lengths",
    "arc_samples",
    "best_mapping",
    "crossing_grid",
    "densified",
    "distances",
    "extent",
    "farthest",
    "fft",
    "filter_reach",
    "fine_rings",
    "grid_of",
    "grid_velocity",
    "grids_of",
    "low_pass_into",
    "midpoint_grid",
    "path_length",
    "recording_velocity",
    "refinement",
    "rising",
    "sampled",
    "shape_error_of",
    "spacing_of",
    "turning",
    "twiddles",
    "unbuilt",
    "velocity_snr_of",
    "velocity_snrs",
]

COARSE = 16
"""Coarse cells are this many fine cells wide."""
CELL = 4.0
"""Fine cells are at most this many sample spacings wide (along a curve a cell then holds 6-7
segments; at 2 spacings, 3-4, but four times the cells to build and twice as many queries
reading a neighbour: 14-26 % more for the whole shape error on mocap letters and synthetic
tags)."""


@compiled
def grid_of(points: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The uniform grid of ``cell``-wide cells over ``points`` (one group of
    :func:`tagbot.gesture.refine_kernels.buckets`)."""
    first = np.array([0, points.shape[0]], dtype=np.intp)
    return buckets(points, first, cell)


@compiled
def extent(points: np.ndarray) -> tuple[float, float]:
    """The width and height of the points' bounding box (numpy's reductions along the short
    axis of ``(N, 2)`` cost more than the points)."""
    x0 = x1 = points[0, 0]
    y0 = y1 = points[0, 1]
    for i in range(1, points.shape[0]):
        x0, x1 = min(x0, points[i, 0]), max(x1, points[i, 0])
        y0, y1 = min(y0, points[i, 1]), max(y1, points[i, 1])
    return x1 - x0, y1 - y0


@compiled
def path_length(points: np.ndarray, ends: np.ndarray) -> float:
    """The total length of the polylines ``points[ends[k − 1]:ends[k]]``."""
    total = 0.0
    begin = 0
    for k in range(ends.size):
        for i in range(begin, ends[k] - 1):
            dx, dy = points[i + 1, 0] - points[i, 0], points[i + 1, 1] - points[i, 1]
            total += math.sqrt(dx * dx + dy * dy)
        begin = ends[k]
    return total


@compiled
def turning(points: np.ndarray, ends: np.ndarray) -> float:
    """The total absolute turning (radians) of the polylines ``points[ends[k − 1]:ends[k]]``:
    between each step and the next of non-zero length, on each polyline."""
    total = 0.0
    begin = 0
    for k in range(ends.size):
        px = py = 0.0
        have = False
        for i in range(begin, ends[k] - 1):
            dx, dy = points[i + 1, 0] - points[i, 0], points[i + 1, 1] - points[i, 1]
            if dx == 0.0 and dy == 0.0:
                continue
            if have:
                total += abs(math.atan2(px * dy - py * dx, px * dx + py * dy))
            px, py, have = dx, dy, True
        begin = ends[k]
    return total


@compiled
def densified(
    points: np.ndarray, ends: np.ndarray, spacing: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The polylines ``points[ends[k − 1]:ends[k]]`` (each non-empty) with points inserted so
    that consecutive ones are at most ``spacing`` apart (:func:`tagbot.metrics.densify`), and
    per sample the previous and next sample on its polyline (itself at its ends); then the
    segments (as the module describes them) between distinct consecutive samples (a polyline
    at rest in one place: one of length 0 there)."""
    pieces = np.ones(points.shape[0], np.intp)  # samples from each point to the next
    begin = 0
    for k in range(ends.size):
        for i in range(begin, ends[k] - 1):
            gap = math.hypot(points[i + 1, 0] - points[i, 0], points[i + 1, 1] - points[i, 1])
            pieces[i] = max(1, math.ceil(gap / spacing))
        begin = ends[k]
    total = int(pieces.sum())
    samples = np.empty((total, 2))
    before = np.arange(-1, total - 1)
    after = np.arange(1, total + 1)
    moving = np.zeros(total, np.bool_)
    row = begin = 0
    for k in range(ends.size):
        first = row
        for i in range(begin, ends[k] - 1):
            dx = (points[i + 1, 0] - points[i, 0]) / pieces[i]
            dy = (points[i + 1, 1] - points[i, 1]) / pieces[i]
            for j in range(pieces[i]):
                samples[row, 0], samples[row, 1] = points[i, 0] + dx * j, points[i, 1] + dy * j
                row += 1
        samples[row] = points[ends[k] - 1]
        before[first], after[row] = first, row
        row += 1
        for i in range(first, row - 1):
            moving[i] = samples[i + 1, 0] != samples[i, 0] or samples[i + 1, 1] != samples[i, 1]
        if not moving[first:row].any():
            moving[first] = True
        begin = ends[k]
    segments = np.empty((int(moving.sum()), 5))
    e = 0
    for i in range(total):
        if moving[i]:
            j = after[i]
            ux, uy = samples[j, 0] - samples[i, 0], samples[j, 1] - samples[i, 1]
            length2 = ux * ux + uy * uy
            segments[e, 0], segments[e, 1] = samples[i, 0], samples[i, 1]
            segments[e, 2], segments[e, 3] = ux, uy
            segments[e, 4] = 1.0 / length2 if length2 > 0.0 else 0.0
            e += 1
    return samples, before, after, segments


@compiled
def crossing_grid(segments: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A uniform grid of ``cell``-wide cells over the segments, each segment in every cell its
    bounding box meets (the layout of :func:`grid_of`): a point of a segment lies in a cell
    that holds it."""
    x0 = y0 = np.inf
    x1 = y1 = -np.inf
    for e in range(segments.shape[0]):
        ax, ay = segments[e, 0], segments[e, 1]
        bx, by = ax + segments[e, 2], ay + segments[e, 3]
        x0, x1 = min(x0, ax, bx), max(x1, ax, bx)
        y0, y1 = min(y0, ay, by), max(y1, ay, by)
    inv = 1.0 / cell  # cells by products, as :func:`_search` finds them
    nx, ny = int((x1 - x0) * inv) + 1, int((y1 - y0) * inv) + 1
    header = np.empty((1, 5))
    header[0, 0], header[0, 1], header[0, 2], header[0, 3], header[0, 4] = x0, y0, nx, ny, 0
    box = np.empty((segments.shape[0], 4), np.intp)
    start = np.zeros(nx * ny + 1, np.intp)
    for e in range(segments.shape[0]):
        ax, ay = segments[e, 0], segments[e, 1]
        bx, by = ax + segments[e, 2], ay + segments[e, 3]
        box[e, 0] = min(int((min(ax, bx) - x0) * inv), nx - 1)
        box[e, 1] = min(int((max(ax, bx) - x0) * inv), nx - 1)
        box[e, 2] = min(int((min(ay, by) - y0) * inv), ny - 1)
        box[e, 3] = min(int((max(ay, by) - y0) * inv), ny - 1)
        for iy in range(box[e, 2], box[e, 3] + 1):
            for ix in range(box[e, 0], box[e, 1] + 1):
                start[iy * nx + ix + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(start[nx * ny], np.intp)
    for e in range(segments.shape[0]):
        for iy in range(box[e, 2], box[e, 3] + 1):
            for ix in range(box[e, 0], box[e, 1] + 1):
                c = iy * nx + ix
                order[fill[c]] = e
                fill[c] += 1
    return header, start, order


@compiled
def midpoint_grid(segments: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The coarse grid of the segments: each in the cell of its midpoint (:func:`grid_of`)."""
    middle = np.empty((segments.shape[0], 2))
    for e in range(segments.shape[0]):
        middle[e, 0] = segments[e, 0] + 0.5 * segments[e, 2]
        middle[e, 1] = segments[e, 1] + 0.5 * segments[e, 3]
    return grid_of(middle, cell)


@compiled
def unbuilt() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A coarse grid not built yet: :func:`distances` and :func:`farthest` build it
    (:func:`midpoint_grid`) only if some query is far enough to need it, which few are."""
    return np.empty((0, 5)), np.zeros(1, np.intp), np.empty(0, np.intp)


@compiled
def grids_of(
    segments: np.ndarray, cell: float, coarse_cell: float
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The fine grid of the segments (:func:`crossing_grid`) and the coarse one of their
    midpoints (:func:`midpoint_grid`)."""
    return crossing_grid(segments, cell), midpoint_grid(segments, coarse_cell)


@compiled
def arc_lengths(points: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Per point of the polylines ``points[ends[k − 1]:ends[k]]``, the arc length from its
    polyline's first point."""
    out = np.empty(points.shape[0])
    begin = 0
    for k in range(ends.size):
        total = 0.0
        out[begin] = 0.0
        for i in range(begin + 1, ends[k]):
            dx, dy = points[i, 0] - points[i - 1, 0], points[i, 1] - points[i - 1, 1]
            total += math.sqrt(dx * dx + dy * dy)
            out[i] = total
        begin = ends[k]
    return out


@inlined
def _point_along(
    points: np.ndarray, lengths: np.ndarray, last: int, s: float, i: int
) -> tuple[float, float, int]:
    """The point at arc length ``s`` of the polyline whose points run from ``i`` (or before)
    to ``last``, and the index of the segment it is on (a search from ``i``, so that rising
    ``s`` cost one pass)."""
    while i < last - 1 and lengths[i + 1] < s:
        i += 1
    if i >= last:
        return points[last, 0], points[last, 1], last
    gap = lengths[i + 1] - lengths[i]
    u = min(max((s - lengths[i]) / gap, 0.0), 1.0) if gap > 0 else 0.0
    x = points[i, 0] + u * (points[i + 1, 0] - points[i, 0])
    y = points[i, 1] + u * (points[i + 1, 1] - points[i, 1])
    return x, y, i


@compiled
def arc_samples(
    points: np.ndarray, ends: np.ndarray, lengths: np.ndarray, spacing: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The polylines ``points[ends[k − 1]:ends[k]]`` (each non-empty; ``lengths`` of
    :func:`arc_lengths`) sampled evenly along their arc length, both ends included, at most
    ``spacing`` apart: polyline ``k``'s samples are ``first[k]:first[k + 1]``, ``step[k]``
    apart along it (one sample, step 0, for a polyline of length 0)."""
    pieces = np.zeros(ends.size, np.intp)
    first = np.zeros(ends.size + 1, np.intp)
    step = np.zeros(ends.size)
    for k in range(ends.size):
        total = lengths[ends[k] - 1]
        if total > 0:
            pieces[k] = max(1, math.ceil(total / spacing))
            step[k] = total / pieces[k]
        first[k + 1] = first[k] + pieces[k] + 1
    out = np.empty((first[ends.size], 2))
    begin = 0
    for k in range(ends.size):
        last, i = ends[k] - 1, begin
        for j in range(pieces[k]):
            x, y, i = _point_along(points, lengths, last, j * step[k], i)
            out[first[k] + j, 0], out[first[k] + j, 1] = x, y
        out[first[k + 1] - 1] = points[last]
        begin = ends[k]
    return out, first, step


@inlined
def _could_exceed(
    points: np.ndarray,
    segments: np.ndarray,
    x0: float,
    y0: float,
    d0: float,
    e0: int,
    x1: float,
    y1: float,
    d1: float,
    e1: int,
    length: float,
    inside: int,
    until: int,
    largest: float,
    limit: float,
) -> bool:
    """Whether the distance to ``segments`` along a piece of path ``length`` long, from
    ``(x0, y0)`` (distance ``d0``, to segment ``e0``; -1: not known) through ``points[inside:
    until + 1]`` to ``(x1, y1)`` (``d1``, ``e1``), could exceed ``limit``, or for its ends'
    segments ``largest``: the distance changes no faster than the arc length (at most
    ``(d0 + d1 + length) / 2``), and it is at most the distance to any one segment, which is
    convex along each straight piece of the path (at most its largest at the ends and the
    points between)."""
    if 0.5 * (d0 + d1 + length) <= limit:
        return False
    bound = np.inf
    for e in (e0, e1):
        if e < 0:
            continue
        worst = max(_segment_d2(x0, y0, segments, e), _segment_d2(x1, y1, segments, e))
        for i in range(inside, until + 1):
            worst = max(worst, _segment_d2(points[i, 0], points[i, 1], segments, e))
        bound = min(bound, math.sqrt(worst))
    return bound > largest


@compiled
def _chosen(
    points: np.ndarray,
    ends: np.ndarray,
    lengths: np.ndarray,
    first: np.ndarray,
    step: np.ndarray,
    samples: np.ndarray,
    near: np.ndarray,
    nearest: np.ndarray,
    segments: np.ndarray,
    largest: float,
    fine: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The intervals between consecutive ``samples`` (:func:`arc_samples`: ``first``,
    ``step``; ``near``, their distances to ``segments``, ``nearest`` the segment each is to,
    -1: not known) where the distance could exceed ``largest`` (at least the samples'
    largest) by more than ``fine / 2`` (:func:`_could_exceed`, the bar ``fine / 2`` higher for
    the first bound): each one's first sample, its polyline, the pieces of path (points ``p``,
    ``p + 1``) its ends lie on, and their total length."""
    limit = largest + 0.5 * fine
    chosen = np.empty(near.size, np.intp)
    owner = np.empty(near.size, np.intp)
    pieces = np.empty((near.size, 2), np.intp)
    count = 0
    total = 0.0
    for k in range(ends.size):
        last = ends[k] - 1
        piece = ends[k - 1] if k > 0 else 0  # the piece sample j lies on
        for j in range(first[k], first[k + 1] - 1):
            after = piece
            while after < last - 1 and lengths[after + 1] < (j + 1 - first[k]) * step[k]:
                after += 1
            a, b = samples[j], samples[j + 1]
            if _could_exceed(points, segments, a[0], a[1], near[j], nearest[j], b[0], b[1],
                             near[j + 1], nearest[j + 1], step[k], piece + 1, after, largest,
                             limit):  # fmt: skip
                chosen[count], owner[count] = j, k
                pieces[count, 0], pieces[count, 1] = piece, after
                count += 1
                total += step[k]
            piece = after
    return chosen[:count], owner[:count], pieces[:count], total


@compiled
def refinement(
    points: np.ndarray,
    ends: np.ndarray,
    lengths: np.ndarray,
    first: np.ndarray,
    step: np.ndarray,
    samples: np.ndarray,
    near: np.ndarray,
    nearest: np.ndarray,
    segments: np.ndarray,
    fine: float,
    max_samples: int,
) -> np.ndarray:
    """Where the largest distance from the polylines to others could exceed the largest at
    their ``samples`` by more than ``fine / 2`` (:func:`_chosen`): those intervals resampled
    along the path every ``fine`` (coarser if that would give more than ``max_samples``
    points), for a search that gives no nearest segments (:func:`farthest` bisects
    instead)."""
    chosen, owner, _, total = _chosen(
        points, ends, lengths, first, step, samples, near, nearest, segments, near.max(), fine
    )
    fine = max(fine, total / max_samples)
    count = chosen.size
    pieces = np.empty(count, np.intp)
    for c in range(count):
        pieces[c] = max(1, math.ceil(step[owner[c]] / fine))
    out = np.empty((int(pieces.sum()), 2))
    row, i, k_last = 0, 0, -1
    for c in range(count):
        k = owner[c]
        if k != k_last:
            i, k_last = ends[k - 1] if k > 0 else 0, k
        start = (chosen[c] - first[k]) * step[k]
        for p in range(pieces[c]):
            s = start + p * step[k] / pieces[c]
            out[row, 0], out[row, 1], i = _point_along(points, lengths, ends[k] - 1, s, i)
            row += 1
    return out


@inlined
def _segment_d2(qx: float, qy: float, segments: np.ndarray, i: int) -> float:
    """Squared distance from ``(qx, qy)`` to segment ``i`` (the module's layout)."""
    px, py = qx - segments[i, 0], qy - segments[i, 1]
    ux, uy = segments[i, 2], segments[i, 3]
    u = min(max((px * ux + py * uy) * segments[i, 4], 0.0), 1.0)
    dx, dy = px - u * ux, py - u * uy
    return dx * dx + dy * dy


@inlined
def _cell_search(
    x: float,
    y: float,
    best2: float,
    nearest: int,
    slack: float,
    ix: int,
    iy: int,
    x0: float,
    y0: float,
    nx: int,
    start: np.ndarray,
    order: np.ndarray,
    cell: float,
    segments: np.ndarray,
) -> tuple[float, int]:
    """``best2`` (the squared distance to segment ``nearest``) improved over the segments of
    cell ``(ix, iy)`` of a grid (its corner ``(x0, y0)``, ``nx`` cells wide), if that cell is
    within the distance plus ``slack`` of ``(x, y)`` (:func:`_search`), and the segment it is
    to. Squares throughout: no square root in the search's chain."""
    dx = max(x0 + ix * cell - x, 0.0, x - x0 - (ix + 1) * cell)
    dy = max(y0 + iy * cell - y, 0.0, y - y0 - (iy + 1) * cell)
    if slack > 0.0:
        reach = math.sqrt(best2) + slack
        reach2 = reach * reach
    else:
        reach2 = best2
    if dx * dx + dy * dy < reach2:
        c = iy * nx + ix
        for e in range(start[c], start[c + 1]):
            d2 = _segment_d2(x, y, segments, order[e])
            if d2 < best2:
                best2, nearest = d2, order[e]
    return best2, nearest


@inlined
def _search(
    x: float,
    y: float,
    best2: float,
    nearest: int,
    segments: np.ndarray,
    header: np.ndarray,
    start: np.ndarray,
    order: np.ndarray,
    cell: float,
    slack: float,
    rings: int,
) -> tuple[float, int, bool]:
    """Improve ``best2``, the squared distance from ``(x, y)`` to the polylines (to their
    segment ``nearest``, -1 for none yet), over the cells of one grid: its own cell, then the
    cells within reach of what that found if they are few, else ring by ring outwards, at most
    ``rings`` rings; the segment it is to, and whether no segment left can be nearer.
    Every point of a segment is within ``slack`` of a cell that holds it (0 for
    :func:`crossing_grid`; half the segments' longest for a grid of their midpoints), so a
    ring farther than the best distance plus that ends the search."""
    x0, y0 = header[0, 0], header[0, 1]
    nx, ny = int(header[0, 2]), int(header[0, 3])
    inv = 1.0 / cell  # (out of the caller's loop: the grids' cells by products)
    cx = min(max(math.floor((x - x0) * inv), 0), nx - 1)
    cy = min(max(math.floor((y - y0) * inv), 0), ny - 1)
    # How far the query is inside its own cell: every cell beyond ring r is farther than
    # r cells plus this (0 for a query outside the grid).
    left, bottom = x - (x0 + cx * cell), y - (y0 + cy * cell)
    margin = max(min(left, cell - left, bottom, cell - bottom), 0.0)
    best2, nearest = _cell_search(
        x, y, best2, nearest, slack, cx, cy, x0, y0, nx, start, order, cell, segments
    )
    reach = math.sqrt(best2) + slack
    if reach <= margin:
        return best2, nearest, True
    if reach < cell:  # near the polylines, the usual case: the cells the disc within reach meets
        ix0, ix1 = math.floor((x - reach - x0) * inv), math.floor((x + reach - x0) * inv)
        iy0, iy1 = math.floor((y - reach - y0) * inv), math.floor((y + reach - y0) * inv)
        for iy in range(max(iy0, 0), min(iy1, ny - 1) + 1):
            for ix in range(max(ix0, 0), min(ix1, nx - 1) + 1):
                if ix != cx or iy != cy:
                    best2, nearest = _cell_search(x, y, best2, nearest, slack, ix, iy, x0, y0,
                                                 nx, start, order, cell, segments)  # fmt: skip
        return best2, nearest, True
    for ring in range(1, min(max(nx, ny), rings) + 1):
        for iy in range(max(cy - ring, 0), min(cy + ring, ny - 1) + 1):
            edge = iy == cy - ring or iy == cy + ring
            ix = cx - ring
            while ix <= cx + ring:
                if 0 <= ix < nx:
                    best2, nearest = _cell_search(x, y, best2, nearest, slack, ix, iy, x0, y0,
                                                 nx, start, order, cell, segments)  # fmt: skip
                ix += 1 if edge else max(2 * ring, 1)
        # Cells beyond this ring are farther than ``ring`` cells and the margin.
        if ring * cell + margin >= math.sqrt(best2) + slack:
            return best2, nearest, True
    return best2, nearest, max(nx, ny) <= rings


@compiled
def distances(
    query: np.ndarray,
    segments: np.ndarray,
    fine: tuple[np.ndarray, np.ndarray, np.ndarray],
    fine_cell: float,
    coarse: tuple[np.ndarray, np.ndarray, np.ndarray],
    coarse_cell: float,
    spacing: float,
    fine_rings: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Each query point's exact distance to the polylines, and the segment it is to: searched
    in the fine grid for ``fine_rings`` rings (enough for points near the polylines, the usual
    case), then, if that could not settle it, in the coarse one (far points cost a few coarse
    rings, not thousands of fine ones; built here at the first such point if ``coarse`` is
    :func:`unbuilt`). A point repeating the one before it (a pen at rest) has its distance."""
    out = np.empty(query.shape[0])
    nearest = np.full(query.shape[0], -1, np.intp)
    for q in range(query.shape[0]):
        x, y = query[q, 0], query[q, 1]
        if q > 0 and x == query[q - 1, 0] and y == query[q - 1, 1]:
            out[q], nearest[q] = out[q - 1], nearest[q - 1]
            continue
        best2, near, done = _search(x, y, np.inf, -1, segments, fine[0], fine[1], fine[2],
                                    fine_cell, 0.0, fine_rings)  # fmt: skip
        if not done:
            if not coarse[0].shape[0]:
                coarse = midpoint_grid(segments, coarse_cell)
            best2, near, done = _search(x, y, best2, near, segments, coarse[0], coarse[1],
                                        coarse[2], coarse_cell, 0.5 * spacing, 1 << 30)  # fmt: skip
        out[q], nearest[q] = math.sqrt(best2), near
    return out, nearest


@compiled
def farthest(
    points: np.ndarray,
    ends: np.ndarray,
    lengths: np.ndarray,
    first: np.ndarray,
    step: np.ndarray,
    samples: np.ndarray,
    near: np.ndarray,
    nearest: np.ndarray,
    largest: float,
    segments: np.ndarray,
    fine: tuple[np.ndarray, np.ndarray, np.ndarray],
    fine_cell: float,
    coarse: tuple[np.ndarray, np.ndarray, np.ndarray],
    coarse_cell: float,
    spacing: float,
    fine_rings: int,
    resolution: float,
    max_samples: int,
) -> float:
    """The largest distance from the polylines to the segments (their grids as
    :func:`distances`, the coarse one perhaps :func:`unbuilt`), or ``largest`` if that is
    larger, within ``resolution / 2`` (coarser if the intervals that could hold it are longer
    than ``max_samples`` of it): the ``samples``' distances are ``near``, to segments
    ``nearest``; each interval between them that :func:`_chosen` keeps is halved, its
    midpoint measured (from its ends' segments on), and each half kept while
    :func:`_could_exceed` says it could exceed the largest so far. A piece shorter than the
    resolution cannot exceed it by more than half of that."""
    largest = max(largest, near.max())
    chosen, owner, pieces, total = _chosen(
        points, ends, lengths, first, step, samples, near, nearest, segments, largest,
        resolution,
    )  # fmt: skip
    if not chosen.size:
        return largest
    resolution = max(resolution, total / max_samples)
    # Depth first: each halving takes one interval and leaves two.
    depth = max(math.ceil(math.log2(max(step.max() / resolution, 1.0))), 0) + 3
    real = np.empty((depth, 2, 4))  # per interval and end: arc length, x, y, distance
    whole = np.empty((depth, 2, 2), np.intp)  # per interval and end: its segment, its piece
    for c in range(chosen.size):
        j, k = chosen[c], owner[c]
        last = ends[k] - 1
        for end in range(2):
            i = j + end
            real[0, end, 0] = (i - first[k]) * step[k]
            real[0, end, 1], real[0, end, 2] = samples[i, 0], samples[i, 1]
            real[0, end, 3] = near[i]
            whole[0, end, 0], whole[0, end, 1] = nearest[i], pieces[c, end]
        top = 1
        while top > 0:
            top -= 1
            r, w = real[top], whole[top]
            if not _could_exceed(points, segments, r[0, 1], r[0, 2], r[0, 3], w[0, 0], r[1, 1],
                                 r[1, 2], r[1, 3], w[1, 0], r[1, 0] - r[0, 0], w[0, 1] + 1,
                                 w[1, 1], largest, largest + 0.5 * resolution):  # fmt: skip
                continue
            s = 0.5 * (r[0, 0] + r[1, 0])
            x, y, p = _point_along(points, lengths, last, s, w[0, 1])
            best2, e = np.inf, -1
            for end in range(2):
                if w[end, 0] >= 0:
                    d2 = _segment_d2(x, y, segments, w[end, 0])
                    if d2 < best2:
                        best2, e = d2, w[end, 0]
            # The fine grid, then if need be the coarse one, as :func:`distances` searches
            # (written out: a shared inlined helper made that loop 40 % slower).
            best2, e, done = _search(x, y, best2, e, segments, fine[0], fine[1], fine[2],
                                     fine_cell, 0.0, fine_rings)  # fmt: skip
            if not done:
                if not coarse[0].shape[0]:
                    coarse = midpoint_grid(segments, coarse_cell)
                best2, e, done = _search(x, y, best2, e, segments, coarse[0], coarse[1], coarse[2],
                                         coarse_cell, 0.5 * spacing, 1 << 30)  # fmt: skip
            best = math.sqrt(best2)
            largest = max(largest, best)
            # The halves: (midpoint, end 1) in the next row, (end 0, midpoint) in this one.
            for q in range(4):
                real[top + 1, 1, q] = r[1, q]
            whole[top + 1, 1, 0], whole[top + 1, 1, 1] = w[1, 0], w[1, 1]
            for row, end in ((top + 1, 0), (top, 1)):
                real[row, end, 0], real[row, end, 1] = s, x
                real[row, end, 2], real[row, end, 3] = y, best
                whole[row, end, 0], whole[row, end, 1] = e, p
            top += 2
    return largest


@compiled
def spacing_of(
    ref: np.ndarray,
    ref_ends: np.ndarray,
    cand: np.ndarray,
    cand_ends: np.ndarray,
    density: float,
    max_samples: int,
) -> tuple[float, float]:
    """The shape error's size (the reference's bounding-box diagonal, 1 if 0) and sample
    spacing: ``size / density``, or coarser for drawings longer than ``max_samples`` of it."""
    width, height = extent(ref)
    size = math.hypot(width, height) or 1.0
    longest = max(path_length(ref, ref_ends), path_length(cand, cand_ends))
    return size, max(size / density, longest / max_samples)


@compiled
def sampled(
    points: np.ndarray, ends: np.ndarray, spacing: float, crowded: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, bool]:
    """A drawing :func:`densified` at ``spacing``, its grids' cell, and whether it is crowded:
    more than ``crowded`` samples expected within half a spacing of a point. Cells
    :data:`CELL` spacings wide along a curve, narrower where the samples crowd an area (a
    scribble over itself), so that a cell holds a few samples whatever the drawing."""
    samples, before, after, segments = densified(points, ends, spacing)
    width, height = extent(samples)
    area = width * height
    count = samples.shape[0]
    typical = 2.0 * math.sqrt(area / count)
    cell = min(CELL * spacing, max(0.5 * spacing, typical)) if typical > 0 else spacing
    dense = area > 0 and count * math.pi * (0.5 * spacing) ** 2 > crowded * area
    return samples, before, after, segments, cell, dense


@compiled
def fine_rings(spacing: float, cell: float) -> int:
    """The fine grid's rings :func:`distances` searches before the coarse grid."""
    return math.ceil(0.5 * spacing / cell) + 2


@compiled
def shape_error_of(
    ref: np.ndarray,
    ref_ends: np.ndarray,
    cand: np.ndarray,
    cand_ends: np.ndarray,
    density: float,
    max_samples: int,
    max_density: float,
    crowded: float,
) -> tuple[float, float, float]:
    """:func:`tagbot.metrics.shape_error` of two drawings (non-empty polylines one after the
    other, and where each ends) in one call: mean and max over the size (samples ``density``
    per size, the max refined to ``size / max_density``), and the size; the mean NaN if either
    drawing is crowded (:func:`sampled`), for the caller's KD-tree."""
    size, spacing = spacing_of(ref, ref_ends, cand, cand_ends, density, max_samples)
    a = sampled(ref, ref_ends, spacing, crowded)
    b = sampled(cand, cand_ends, spacing, crowded)
    if a[5] or b[5]:
        return math.nan, math.nan, size
    a_fine, b_fine = crossing_grid(a[3], a[4]), crossing_grid(b[3], b[4])
    a_coarse, b_coarse = unbuilt(), unbuilt()  # built where a query needs them
    a_rings, b_rings = fine_rings(spacing, a[4]), fine_rings(spacing, b[4])
    # Each drawing's samples, evenly along its arc length, against the other's segments.
    ref_lengths, cand_lengths = arc_lengths(ref, ref_ends), arc_lengths(cand, cand_ends)
    qa, a_first, a_step = arc_samples(ref, ref_ends, ref_lengths, spacing)
    qb, b_first, b_step = arc_samples(cand, cand_ends, cand_lengths, spacing)
    a_to_b, a_near = distances(qa, b[3], b_fine, b[4], b_coarse, COARSE * b[4], spacing, b_rings)
    b_to_a, b_near = distances(qb, a[3], a_fine, a[4], a_coarse, COARSE * a[4], spacing, a_rings)
    mean = (a_to_b.sum() + b_to_a.sum()) / (a_to_b.size + b_to_a.size)
    # The maximum, refined where it could be (:func:`farthest`) each way.
    largest = max(a_to_b.max(), b_to_a.max())
    fine = size / max_density
    largest = farthest(ref, ref_ends, ref_lengths, a_first, a_step, qa, a_to_b, a_near, largest,
                       b[3], b_fine, b[4], b_coarse, COARSE * b[4], spacing, b_rings, fine,
                       max_samples)  # fmt: skip
    largest = farthest(cand, cand_ends, cand_lengths, b_first, b_step, qb, b_to_a, b_near,
                       largest, a[3], a_fine, a[4], a_coarse, COARSE * a[4], spacing, a_rings,
                       fine, max_samples)  # fmt: skip
    return mean / size, largest / size, size


# --- the velocity SNR ---------------------------------------------------------------------------


@compiled
def rising(t: np.ndarray) -> bool:
    """Whether the stamps ``t`` strictly rise (NaN does not)."""
    i = 0
    while i < t.size - 1 and t[i + 1] > t[i]:
        i += 1
    return i >= t.size - 1


@compiled
def twiddles(size: int) -> np.ndarray:
    """``exp(−2πik/size)`` for ``k < size/2``: the factors of :func:`fft` up to ``size`` (the
    second quarter turn from the first: ``−i`` times)."""
    table = np.empty(max(size // 2, 1), dtype=np.complex128)
    quarter = size // 4
    for k in range(table.size):
        if quarter and k >= quarter:
            table[k] = -1j * table[k - quarter]
        else:
            angle = -2.0 * math.pi * k / size
            table[k] = complex(math.cos(angle), math.sin(angle))
    return table


@compiled
def fft(x: np.ndarray, table: np.ndarray, inverse: bool) -> None:
    """In place, the discrete Fourier transform of ``x`` (a power of 2 long, at most twice
    ``table``'s length; radix 2), or its inverse unscaled (no division by the length)."""
    n = x.size
    j = 0
    for i in range(1, n):
        bit = n >> 1
        while j & bit:
            j ^= bit
            bit >>= 1
        j |= bit
        if i < j:
            x[i], x[j] = x[j], x[i]
    sign = -1.0 if inverse else 1.0  # the inverse's factors are the conjugates
    length = 2
    while length <= n:
        half = length >> 1
        stride = 2 * table.size // length
        if half <= n // length:  # more blocks than factors: each factor once, for every block
            for k in range(half):
                wr, wi = table[k * stride].real, sign * table[k * stride].imag
                for first in range(k, n, length):
                    _butterfly(x, first, first + half, wr, wi)
        else:
            for first in range(0, n, length):
                for k in range(half):
                    wr, wi = table[k * stride].real, sign * table[k * stride].imag
                    _butterfly(x, first + k, first + k + half, wr, wi)
        length <<= 1


@inlined
def _butterfly(x: np.ndarray, i: int, j: int, wr: float, wi: float) -> None:
    """``x[i], x[j] = x[i] + w·x[j], x[i] − w·x[j]`` with ``w = wr + i·wi``."""
    a, b = x[i], x[j]
    br = b.real * wr - b.imag * wi
    bi = b.real * wi + b.imag * wr
    x[i] = complex(a.real + br, a.imag + bi)
    x[j] = complex(a.real - br, a.imag - bi)


@compiled
def low_pass_into(x: np.ndarray, dt: float, cutoff: float, order: int, reach: int) -> None:
    """In place, the zero-phase low-pass of :func:`tagbot.metrics.low_pass` of the rows of
    ``x`` (n ≥ 4, c) (``min(reach, n − 1)`` rows of point reflection at each end), two columns
    per complex transform."""
    n, columns = x.shape
    pad = min(n - 1, reach)
    m = n + 2 * pad
    size = 1
    while size < 2 * m:
        size <<= 1
    table = twiddles(size)
    gain = np.empty(size)
    for k in range(size):
        f = min(k, size - k) / (size * dt) / cutoff
        gain[k] = 1.0 / (1.0 + f ** (2 * order))
    ext = np.empty(m)
    line = np.empty((m, 2))
    z = np.empty(size, dtype=np.complex128)
    for c0 in range(0, columns, 2):
        pair = min(2, columns - c0)
        for c in range(pair):
            col = c0 + c
            for k in range(pad):
                ext[k] = 2.0 * x[0, col] - x[pad - k, col]
                ext[pad + n + k] = 2.0 * x[n - 1, col] - x[n - 2 - k, col]
            ext[pad : pad + n] = x[:, col]
            for k in range(m):
                line[k, c] = ext[0] + (k / (m - 1)) * (ext[m - 1] - ext[0])
                if c == 0:
                    z[k] = ext[k] - line[k, 0]
                else:
                    z[k] += 1j * (ext[k] - line[k, 1])
        z[m:] = 0.0
        fft(z, table, False)
        for k in range(size):
            z[k] *= gain[k] / size
        fft(z, table, True)
        for k in range(n):
            x[k, c0] = z[pad + k].real + line[pad + k, 0]
            if pair == 2:
                x[k, c0 + 1] = z[pad + k].imag + line[pad + k, 1]


@compiled
def grid_velocity(
    t: np.ndarray,
    xy: np.ndarray,
    dt: float,
    count: int,
    cutoff: float,
    order: int,
    reach: int,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`tagbot.metrics.recorded_velocity` once its stamps are clean (distinct, rising):
    the grid ``t[0] + k·dt`` (``count`` steps, those within the recording), the positions
    interpolated linearly on it, low-passed by :func:`low_pass_into` unless ``reach`` is 0,
    and their central differences (one-sided at the ends)."""
    last = t[t.size - 1]
    grid = t[0] + dt * np.arange(count)
    while count > 0 and grid[count - 1] > last:
        count -= 1
    grid = grid[:count]
    rec = np.empty((count, 2))
    j = 0
    for k in range(count):
        while j + 2 < t.size and t[j + 1] <= grid[k]:
            j += 1
        if grid[k] >= last:
            rec[k, 0], rec[k, 1] = xy[t.size - 1, 0], xy[t.size - 1, 1]
            continue
        u = (grid[k] - t[j]) / (t[j + 1] - t[j])
        for c in range(2):
            rec[k, c] = xy[j, c] + u * (xy[j + 1, c] - xy[j, c])
    if reach > 0 and count >= 4:
        low_pass_into(rec, dt, cutoff, order, reach)
    v = np.empty((count, 2))
    for c in range(2):
        v[0, c] = (rec[1, c] - rec[0, c]) / dt
        v[count - 1, c] = (rec[count - 1, c] - rec[count - 2, c]) / dt
        for k in range(1, count - 1):
            v[k, c] = (rec[k + 1, c] - rec[k - 1, c]) / (2.0 * dt)
    return grid, v


UNIFORM = 1e-9
"""A model clock counts as evenly spaced when each time is within this many steps of its place
on the even grid (:func:`_uniform_step`)."""


@compiled
def _uniform_step(xp: np.ndarray) -> float:
    """``1 / step`` if the rising ``xp`` is evenly spaced, each point within :data:`UNIFORM` of
    a step of its place, else 0. Then ``(x − xp[0]) / step`` gives ``x``'s interval, or within
    that distance of a point the next one, whose line passes through the same point: the
    interpolated value is the same to rounding (relative ``UNIFORM``)."""
    last = xp.size - 1
    span = xp[last] - xp[0]
    if not span > 0:
        return 0.0
    inv_step = last / span
    for j in range(xp.size):
        if abs((xp[j] - xp[0]) * inv_step - j) > UNIFORM:
            return 0.0
    return inv_step


@inlined
def _bisect(x: float, xp: np.ndarray) -> int:
    """The interval ``j`` of the rising ``xp`` with ``xp[j] <= x < xp[j + 1]`` (the last one at
    its end), for ``x`` within them."""
    j, hi = 0, xp.size - 1
    while hi - j > 1:
        mid = (j + hi) >> 1
        if xp[mid] <= x:
            j = mid
        else:
            hi = mid
    return j


@inlined
def _interpolated(
    x: float, xp: np.ndarray, fp: np.ndarray, slope: np.ndarray, inv_step: float, outside: bool
) -> tuple[float, float]:
    """``fp`` (n, 2) at ``x``, linearly over the rising ``xp`` as ``np.interp`` (``slope``: the
    (n − 1, 2) slopes between points; beyond the ends 0 if ``outside``, else the end values;
    at the last point to rounding). The interval is ``x``'s place on the even spacing
    :func:`_uniform_step` finds (no search), or if it found none, found by bisection."""
    last = xp.size - 1
    if x < xp[0] or x > xp[last]:
        if outside:
            return 0.0, 0.0
        x = min(max(x, xp[0]), xp[last])
    j = int(min((x - xp[0]) * inv_step, last - 1.0)) if inv_step > 0 else _bisect(x, xp)
    u = x - xp[j]
    return fp[j, 0] + slope[j, 0] * u, fp[j, 1] + slope[j, 1] * u


@compiled
def _slopes(xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """The slopes of ``fp`` (n, 2) between consecutive points of the rising ``xp`` (0 between
    repeated points)."""
    slope = np.empty((xp.size - 1, 2))
    for j in range(xp.size - 1):
        gap = xp[j + 1] - xp[j]
        inv = 1.0 / gap if gap > 0 else 0.0
        slope[j, 0] = (fp[j + 1, 0] - fp[j, 0]) * inv
        slope[j, 1] = (fp[j + 1, 1] - fp[j, 1]) * inv
    return slope


@compiled
def _mapping_errors(
    grid: np.ndarray,
    vx: np.ndarray,
    vy: np.ndarray,
    model_t: np.ndarray,
    model_v: np.ndarray,
    slope: np.ndarray,
    inv_step: float,
    s: float,
    offsets: np.ndarray,
    bound: float,
    out: np.ndarray,
) -> None:
    """``Σ|v − v̂|²`` of scale ``s`` with each of ``offsets`` into ``out``: the model mapped as
    ``v̂(t) = model_v((t − o)/s) / s``, zero outside the model's span (``slope`` of
    :func:`_slopes`, ``inv_step`` of :func:`_uniform_step`, as :func:`_interpolated`, written
    out: the polish's inner loop), each sum over the recording in its order; or, for a sum that
    reaches ``bound``, the partial sum that did (its terms are not negative: the whole sum
    would not be below ``bound`` either)."""
    inv_s = 1.0 / s
    last = model_t.size - 1
    for b in range(offsets.size):
        total = 0.0
        for k in range(grid.size):
            x = (grid[k] - offsets[b]) * inv_s
            ex, ey = vx[k], vy[k]
            if model_t[0] <= x <= model_t[last]:
                if inv_step > 0:
                    j = int(min((x - model_t[0]) * inv_step, last - 1.0))
                else:
                    j = _bisect(x, model_t)
                u = x - model_t[j]
                ex -= (model_v[j, 0] + slope[j, 0] * u) * inv_s
                ey -= (model_v[j, 1] + slope[j, 1] * u) * inv_s
            total += ex * ex + ey * ey
            if total >= bound:
                break
        out[b] = total


@inlined
def _correlate_into(
    sums: np.ndarray, vx: np.ndarray, vy: np.ndarray, w: np.ndarray, length: int, lo: int, hi: int
) -> None:
    """``sums[m − lo] = Σ_k vx[k + m]·w[k, 0] + vy[k + m]·w[k, 1]`` for every offset ``lo ≤ m ≤
    hi`` at once, over the model's first ``length`` samples and the recording's: model sample by
    model sample, independent sums over consecutive recording samples (slices, so that the
    compiler vectorises them: no bound reloaded through a possible alias)."""
    n = vx.size
    sums[: hi - lo + 1] = 0.0
    for k in range(length):
        wx, wy = w[k, 0], w[k, 1]
        first, last = max(lo, -k), min(hi, n - 1 - k) + 1
        if last <= first:
            continue
        out = sums[first - lo : last - lo]
        xs, ys = vx[k + first : k + last], vy[k + first : k + last]
        for j in range(out.size):
            out[j] += xs[j] * wx + ys[j] * wy


@inlined
def _resampled(
    w: np.ndarray,
    cum: np.ndarray,
    length: int,
    dt: float,
    s: float,
    model_t: np.ndarray,
    model_v: np.ndarray,
    slope: np.ndarray,
    inv_step: float,
) -> None:
    """The model at scale ``s`` on the grid's spacing into ``w`` (``length`` samples: sample
    ``k`` the model at ``k·dt/s``, over ``s``; as :func:`_interpolated`, written out for an even
    model clock, with products for the divisions) and the prefix sums of ``|w|²`` into
    ``cum``."""
    cum[0] = 0.0
    last = model_t.size - 1
    inv_s, tick = 1.0 / s, dt / s
    for k in range(length):
        if inv_step > 0:
            x = min(max(k * tick, model_t[0]), model_t[last])
            j = int(min((x - model_t[0]) * inv_step, last - 1.0))
            u = x - model_t[j]
            wx, wy = model_v[j, 0] + slope[j, 0] * u, model_v[j, 1] + slope[j, 1] * u
        else:
            wx, wy = _interpolated(k * tick, model_t, model_v, slope, inv_step, False)
        w[k, 0], w[k, 1] = wx * inv_s, wy * inv_s
        cum[k + 1] = cum[k] + (w[k, 0] * w[k, 0] + w[k, 1] * w[k, 1])


DIRECT = 16.0
"""A scale's offsets are correlated by direct sums when these cost less than this many times
the transforms' ``N·log2 N``."""

SINGLE = 2.0**-24
"""The unit roundoff of single precision, in which the grid search's direct sums are taken
(twice as many products per vector instruction): each error is then known within a bound, and
recomputed in double precision, as :func:`_correlate_into` sums it, only if it could be the
smallest so far, so the pair found is the same..."""
SINGLE_WORK = 8192
"""... for scales of at least this many products (offsets by overlap; below, converting the model
costs more than it saves)..."""
SINGLE_RANGE = 1e15
"""... and a model that, scaled as the recording is (its RMS 1), has an RMS within this and its
inverse (no single-precision overflow, no underflow that could matter against the bound)."""

PRUNE = 1e-9
"""An offset is left out of the grid search when a lower bound on its error exceeds the best
error so far by more than this fraction of the recording's energy (rounding, many orders of
magnitude below it, cannot make a left-out offset the best)."""


@inlined
def _error_bound(
    m: int, length: int, n: int, energy: float, cv: np.ndarray, cum: np.ndarray
) -> float:
    """A lower bound on ``Σ|v − w|²`` at offset ``m`` (:func:`best_mapping`'s grid): over the
    overlap, ``|Σ v·w| ≤ √(V·W)`` (Cauchy–Schwarz; ``V`` and ``W`` the two energies there), so
    the error is at least ``energy − V + (√V − √W)²``. ``cv`` and ``cum`` are the prefix sums
    of ``|v|²`` and ``|w|²``."""
    first = min(max(-m, 0), length)
    last = max(min(max(n - m, 0), length), first)
    recorded = max(cv[last + m] - cv[first + m], 0.0) if last > first else 0.0
    model = max(cum[last] - cum[first], 0.0)
    gap = math.sqrt(recorded) - math.sqrt(model)
    return energy - recorded + gap * gap


@compiled
def _mapping_pass(
    grid: np.ndarray,
    vx: np.ndarray,
    vy: np.ndarray,
    model_t: np.ndarray,
    model_v: np.ndarray,
    slope: np.ndarray,
    inv_step: float,
    s: float,
    o: float,
    out: np.ndarray,
) -> None:
    """At the mapping ``(s, o)`` (:func:`_mapping_errors`), into ``out``: the error ``Σ|r|²``
    of the residuals ``r = v − v̂``, the gradient ``Jᵀr`` (scale, offset) and the Gauss-Newton
    matrix ``JᵀJ`` (ss, so, oo). With ``x = (t − o)/s`` and ``v̂ = m(x)/s`` (``m`` linear
    between the model's samples, slope ``m′``): ``∂r/∂s = (m′(x)·x + m(x))/s²`` and
    ``∂r/∂o = m′(x)/s²``; 0 outside the model's span."""
    inv_s = 1.0 / s
    f = inv_s * inv_s
    last = model_t.size - 1
    e = gs = go = hss = hso = hoo = 0.0
    for k in range(grid.size):
        x = (grid[k] - o) * inv_s
        ex, ey = vx[k], vy[k]
        if model_t[0] <= x <= model_t[last]:
            if inv_step > 0:
                j = int(min((x - model_t[0]) * inv_step, last - 1.0))
            else:
                j = _bisect(x, model_t)
            u = x - model_t[j]
            mx = model_v[j, 0] + slope[j, 0] * u
            my = model_v[j, 1] + slope[j, 1] * u
            ex -= mx * inv_s
            ey -= my * inv_s
            ox, oy = slope[j, 0] * f, slope[j, 1] * f
            sx, sy = (slope[j, 0] * x + mx) * f, (slope[j, 1] * x + my) * f
            gs += ex * sx + ey * sy
            go += ex * ox + ey * oy
            hss += sx * sx + sy * sy
            hso += sx * ox + sy * oy
            hoo += ox * ox + oy * oy
        e += ex * ex + ey * ey
    out[0], out[1], out[2], out[3], out[4], out[5] = e, gs, go, hss, hso, hoo


@compiled
def best_mapping(
    grid: np.ndarray,
    v: np.ndarray,
    model_t: np.ndarray,
    model_v: np.ndarray,
    scales: np.ndarray,
    shared: float,
    energy: float,
    steps: np.ndarray,
    widths: np.ndarray,
    iterations: int,
) -> tuple[float, float, float]:
    """The velocity SNR's search (:func:`tagbot.metrics.velocity_snr`): the error ``Σ|v − v̂|²``
    of the best (scale, offset), and that pair.

    Every offset on the grid of each of ``scales``, the model resampled on the grid's spacing
    and correlated with ``v`` by direct sums or by FFT (whichever is cheaper for that scale,
    the transform no longer than its own offsets need; long direct sums in single precision,
    see :data:`SINGLE`), the first smallest error kept; offsets
    that a lower bound (:func:`_error_bound`) shows cannot beat the best so far are skipped,
    the scales nearest the spans' ratio first so that the best is soon good. Then the polish
    from the better of that pair and the shared clock (scale 1, offset ``shared``): for each
    of ``widths`` every pair of ``steps`` around the best pair so far, then at most
    ``iterations`` Levenberg-Marquardt steps (each kept only if the error falls)."""
    n = grid.size
    dt = grid[1] - grid[0]
    span = grid[n - 1] - grid[0]
    model_span = model_t[model_t.size - 1]
    count = scales.size
    lengths = np.empty(count, np.intp)
    low = np.empty(count, np.intp)
    high = np.empty(count, np.intp)
    sizes = np.zeros(count, np.intp)
    top = 1
    # Scale i's model on the grid's spacing: sample k at model time k·dt/scale (``lengths[i]``
    # of them); an offset of m steps puts it on recording sample k + m. Each scale's offsets
    # stay within its own slack (the model inside the recording's span, or the recording
    # inside the model's), and a circular correlation of ``need`` samples has them unwrapped.
    for i in range(count):
        lengths[i] = int(model_span * scales[i] / dt) + 1
        slack = (span - scales[i] * model_span) / dt
        low[i], high[i] = math.floor(min(0.0, slack)), math.ceil(max(0.0, slack))
        overlap = min(n, lengths[i])
        need = max(n - low[i], high[i] + lengths[i])
        size = 1
        while size < need:
            size <<= 1
        if (high[i] - low[i] + 1) * overlap > DIRECT * size * math.log2(size):
            sizes[i] = size
            top = max(top, size)
    table = twiddles(top)
    spectra = np.zeros(2 * top, dtype=np.complex128)  # the recording's, the one of length N at N
    done = np.zeros(64, np.bool_)
    buffer = np.empty(top, dtype=np.complex128)
    w = np.empty((int(lengths.max()), 2))
    cum = np.empty(w.shape[0] + 1)
    cv = np.empty(n + 1)
    cv[0] = 0.0
    for k in range(n):
        cv[k + 1] = cv[k] + (v[k, 0] * v[k, 0] + v[k, 1] * v[k, 1])
    inv_step = _uniform_step(model_t)
    slope = _slopes(model_t, model_v)
    sums = np.empty(int((high - low).max()) + 1)
    errors_of = np.empty(sums.size)  # the errors of a scale correlated by FFT
    vx, vy = v[:, 0].copy(), v[:, 1].copy()
    unit = math.sqrt(n / energy)  # the recording's RMS 1 in single precision
    single = False  # whether any scale has the work for single precision
    for i in range(count):
        single |= (high[i] - low[i] + 1) * min(n, lengths[i]) >= SINGLE_WORK
    rows = n if single else 0
    vx32, vy32 = np.empty(rows, np.float32), np.empty(rows, np.float32)
    for k in range(rows):
        vx32[k], vy32[k] = vx[k] * unit, vy[k] * unit
    w32 = np.empty((w.shape[0] if single else 0, 2), np.float32)
    sums32 = np.empty(sums.size if single else 0, np.float32)
    best, pick, pick_scale, pick_offset = np.inf, count, 1.0, shared
    pick_m = 0
    margin = PRUNE * energy
    ratio = span / model_span if model_span > 0 else 1.0
    nearness = np.empty(count)
    for i in range(count):
        nearness[i] = abs(math.log(scales[i] / ratio)) if scales[i] > 0 else np.inf
    z = buffer[:1]
    for i in np.argsort(nearness, kind="mergesort"):
        length, s = lengths[i], scales[i]
        cum[0] = 0.0
        _resampled(w, cum, length, dt, s, model_t, model_v, slope, inv_step)
        # Left out: the offsets at either end whose bound shows they cannot beat the best.
        lo, hi = low[i], high[i]
        while lo <= hi and _error_bound(lo, length, n, energy, cv, cum) > best + margin:
            lo += 1
        while hi >= lo and _error_bound(hi, length, n, energy, cv, cum) > best + margin:
            hi -= 1
        if lo <= hi:
            tolerance = 0.0
            size = sizes[i]
            if size and (hi - lo + 1) * min(n, length) <= DIRECT * size * math.log2(size):
                size = 0  # few offsets: direct sums cost less
            if size:
                level = int(math.log2(size) + 0.5)
                spectrum = spectra[size : 2 * size]
                if not done[level]:
                    spectrum[:] = 0.0
                    for k in range(n):
                        spectrum[k] = complex(v[k, 0], v[k, 1])
                    fft(spectrum, table, False)
                    done[level] = True
                z = buffer[:size]
                z[:] = 0.0
                for k in range(length):
                    z[k] = complex(w[k, 0], w[k, 1])
                fft(z, table, False)
                for k in range(size):  # conjugated, so that the forward transform inverts it
                    z[k] = spectrum[k].conjugate() * z[k]
                fft(z, table, False)
            elif (hi - lo + 1) * min(n, length) >= SINGLE_WORK and (
                1.0 / SINGLE_RANGE < unit * math.sqrt(cum[length] / length) < SINGLE_RANGE
            ):
                for k in range(length):
                    w32[k, 0], w32[k, 1] = w[k, 0] * unit, w[k, 1] * unit
                _correlate_into(sums32, vx32, vy32, w32, length, lo, hi)
                # Each product within 5 units of its size (its factors' and its own rounding),
                # a sum of m terms within m − 1 units of theirs, and Σ|v||w| ≤ √(Σv²·Σw²): the
                # correlation within (m + 6)·u·√(energy·Σw²), the error within twice that; and
                # twice again, to spare.
                terms = min(n, length) + 6
                tolerance = 4.0 * terms * SINGLE * math.sqrt(energy * cum[length])
            else:
                _correlate_into(sums, vx, vy, w, length, lo, hi)
            # Σ|v − w|² over the overlap = Σ|v|² − 2·Re Σ v·conj(w) + Σ|w|² (outside: v or 0).
            # Single precision: offset by offset, each recomputed only if it could beat the best
            # so far (one pass with the other paths' two measured 5 % slower in all).
            if tolerance > 0:
                for mm in range(lo, hi + 1):
                    first = min(max(-mm, 0), length)
                    last = max(min(max(n - mm, 0), length), first)
                    err = energy - 2.0 * sums32[mm - lo] / (unit * unit) + (cum[last] - cum[first])
                    if err - tolerance > best:
                        continue  # not the smallest, even within its tolerance
                    cross = 0.0  # it could be: its double-precision sum, as _correlate_into's
                    for k in range(first, last):
                        cross += vx[k + mm] * w[k, 0] + vy[k + mm] * w[k, 1]
                    err = energy - 2.0 * cross + (cum[last] - cum[first])
                    # The first smallest in the scales' order, whatever order they are visited
                    # in.
                    if err < best or (err == best and (i < pick or (i == pick and mm < pick_m))):
                        best, pick, pick_m = err, i, mm
                        pick_scale, pick_offset = s, grid[0] + mm * dt
                continue
            # Every offset's error, then the first smallest of them (as offset by offset).
            errors = sums[: hi - lo + 1] if not size else errors_of[: hi - lo + 1]
            for mm in range(lo, hi + 1):
                first = min(max(-mm, 0), length)
                last = max(min(max(n - mm, 0), length), first)
                # (by FFT, conj(conj(·)) has the same real part)
                cross = z[mm % size].real / size if size else sums[mm - lo]
                errors[mm - lo] = energy - 2.0 * cross + (cum[last] - cum[first])
            at = -1
            for j in range(errors.size):  # (NaN, which no finite input gives, never picked)
                if errors[j] == errors[j] and (at < 0 or errors[j] < errors[at]):
                    at = j
            if at < 0:
                continue
            err, mm = errors[at], lo + at
            # The first smallest in the scales' order, whatever order they are visited in.
            if err < best or (err == best and (i < pick or (i == pick and mm < pick_m))):
                best, pick, pick_m = err, i, mm
                pick_scale, pick_offset = s, grid[0] + mm * dt
    # The polish starts from the better of the grid's pair and the shared clock, so that the
    # result is never below the shared clock's (a timed fit's own mapping).
    starts = np.array([pick_offset, shared])
    at = np.empty(2)
    _mapping_errors(grid, vx, vy, model_t, model_v, slope, inv_step, pick_scale, starts[:1],
                    np.inf, at[:1])  # fmt: skip
    _mapping_errors(grid, vx, vy, model_t, model_v, slope, inv_step, 1.0, starts[1:], np.inf,
                    at[1:])  # fmt: skip
    at_grid, at_clock = at[0], at[1]
    if at_clock < at_grid:
        best, scale, offset = at_clock, 1.0, shared
    else:
        best, scale, offset = at_grid, pick_scale, pick_offset
    reach = max(span, dt)
    o_try = np.empty(steps.size)
    errors = np.empty(steps.size)
    for width in widths:
        new_best, new_scale, new_offset = best, scale, offset
        for a in range(steps.size):
            s_try = scale * (1.0 + width * steps[a])
            for b in range(steps.size):
                o_try[b] = offset + steps[b] * width * reach
            _mapping_errors(
                grid, vx, vy, model_t, model_v, slope, inv_step, s_try, o_try, new_best, errors
            )
            for b in range(steps.size):
                if steps[a] == 0.0 and steps[b] == 0.0:
                    continue  # the best pair so far
                if errors[b] < new_best:
                    new_best, new_scale, new_offset = errors[b], s_try, o_try[b]
        best, scale, offset = new_best, new_scale, new_offset
    return _refined(grid, vx, vy, model_t, model_v, slope, inv_step, best, scale, offset,
                    reach, iterations)  # fmt: skip


LM_DAMPING = 1e-3
"""The Levenberg-Marquardt polish's first damping (relative to the matrix's diagonal)."""


@compiled
def _refined(
    grid: np.ndarray,
    vx: np.ndarray,
    vy: np.ndarray,
    model_t: np.ndarray,
    model_v: np.ndarray,
    slope: np.ndarray,
    inv_step: float,
    best: float,
    scale: float,
    offset: float,
    reach: float,
    iterations: int,
) -> tuple[float, float, float]:
    """The mapping ``(scale, offset)`` of error ``best`` improved by at most ``iterations``
    Levenberg-Marquardt steps (:func:`_mapping_pass`; a step is kept only if the error falls,
    the scale at most halves per step), until a step no longer moves it (1e-9 of the scale and
    of ``reach``) or gains less than 1e-12 of the error."""
    here = np.empty(6)
    trial = np.empty(6)
    if iterations <= 0:
        return best, scale, offset
    _mapping_pass(grid, vx, vy, model_t, model_v, slope, inv_step, scale, offset, here)
    damping = LM_DAMPING
    moved = False
    for _ in range(iterations):
        a, b, c = here[3] * (1.0 + damping), here[4], here[5] * (1.0 + damping)
        det = a * c - b * b
        if not det > 0:
            break
        s_try = max(scale - (c * here[1] - b * here[2]) / det, 0.5 * scale)
        o_try = offset - (a * here[2] - b * here[1]) / det
        _mapping_pass(grid, vx, vy, model_t, model_v, slope, inv_step, s_try, o_try, trial)
        if trial[0] < here[0]:
            still = abs(s_try - scale) <= 1e-9 * scale and abs(o_try - offset) <= 1e-9 * reach
            gain = here[0] - trial[0]
            scale, offset, moved = s_try, o_try, True
            here[:] = trial
            damping = max(0.1 * damping, 1e-9)
            if still or gain < 1e-12 * here[0]:
                break
        else:
            damping *= 10.0
            if damping > 1e8:
                break
    return (here[0] if moved else best), scale, offset


# --- the velocity SNR of a recording, whole -----------------------------------------------------

OK, SHORT_MODEL, SHORT_RECORDING, AT_REST = range(4)
"""What :func:`velocity_snr_of` found: a figure, or why there is none."""


@compiled
def filter_reach(dt: float, cutoff: float) -> int:
    """Rows of three cut-off periods every ``dt`` s, how far the low-pass reflects each end; 0
    where the grid is too coarse for the cut-off (see :func:`tagbot.metrics.low_pass`)."""
    if 0.0 < 2.0 * cutoff * dt < 1.0:
        return max(3, round(3.0 / (cutoff * dt)))
    return 0


@compiled
def recording_velocity(
    t: np.ndarray,
    xy: np.ndarray,
    dt: float,
    cutoff: float,
    filtered: bool,
    order: int,
    per_point: float,
    stamps: np.ndarray,
    blends: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, bool]:
    """:func:`tagbot.metrics.recorded_velocity` (low-passed at ``cutoff`` if ``filtered``;
    ``stamps``: the width, gap and steadiness of
    :func:`tagbot.inputs.stamps_kernels.sample_instants`), and False instead if the recording
    is too short (fewer than 3 samples, or over less than 3 grid steps)."""
    if filtered:
        t, _ = stamps_kernels.sample_instants(t, xy, stamps[0], stamps[1], stamps[2], blends)
    if not rising(t):
        keep = np.ones(t.size, np.bool_)
        for i in range(1, t.size):
            keep[i] = t[i] > t[i - 1]
        t, xy = t[keep], xy[keep]
    n = t.size
    if n >= 3:
        dt = max(dt, (t[n - 1] - t[0]) / (per_point * n))
    if n < 3 or t[n - 1] - t[0] < 3.0 * dt:
        return np.empty(0), np.empty((0, 2)), False
    count = int((t[n - 1] - t[0]) / dt) + 1
    reach = filter_reach(dt, cutoff) if filtered else 0
    grid, v = grid_velocity(t, xy, dt, count, cutoff if filtered else 0.0, order, reach)
    return grid, v, True


@compiled
def velocity_snr_of(
    t: np.ndarray,
    xy: np.ndarray,
    model_t: np.ndarray,
    model_v: np.ndarray,
    dt: float,
    cutoff: float,
    filtered: bool,
    order: int,
    per_point: float,
    stamps: np.ndarray,
    blends: np.ndarray,
    scales: np.ndarray,
    steps: np.ndarray,
    widths: np.ndarray,
    iterations: int,
) -> tuple[int, float, float, float, float]:
    """:func:`tagbot.metrics.velocity_snr` whole (:func:`recording_velocity`, then
    :func:`best_mapping` over ``scales`` times the spans' ratio and 1): ``(status, snr_db,
    scale, offset, energy)``, the status :data:`OK` or why there is no figure."""
    if model_t.size < 2:
        return SHORT_MODEL, 0.0, 1.0, 0.0, 0.0
    grid, v, ok = recording_velocity(t, xy, dt, cutoff, filtered, order, per_point, stamps, blends)
    if not ok:
        return SHORT_RECORDING, 0.0, 1.0, 0.0, 0.0
    energy = 0.0
    for k in range(v.shape[0]):
        energy += v[k, 0] * v[k, 0] + v[k, 1] * v[k, 1]
    if not energy > 0:
        return AT_REST, 0.0, 1.0, 0.0, 0.0
    shared = model_t[0]  # the offset of the shared clock
    own = model_t - shared  # the mapping's offset is from the model's first sample
    model_span = own[own.size - 1]
    span = grid[grid.size - 1] - grid[0]
    ratio = span / model_span if model_span > 0 else 1.0
    tried = np.empty(scales.size + 1)
    tried[: scales.size] = scales * ratio
    tried[scales.size] = 1.0  # the model on the recording's own clock, as a timed fit is
    best, scale, offset = best_mapping(
        grid, v, own, model_v, tried, shared, energy, steps, widths, iterations
    )
    return OK, 10.0 * math.log10(energy / max(best, 1e-300)), scale, offset, energy


@compiled
def velocity_snrs(
    t: np.ndarray,
    xy: np.ndarray,
    first: np.ndarray,
    model_t: np.ndarray,
    model_v: np.ndarray,
    model_first: np.ndarray,
    dt: float,
    cutoff: float,
    order: int,
    per_point: float,
    stamps: np.ndarray,
    blends: np.ndarray,
    scales: np.ndarray,
    steps: np.ndarray,
    widths: np.ndarray,
    iterations: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`velocity_snr_of` (low-passed) of recordings ``first[k]:first[k + 1]`` against
    models ``model_first[k]:model_first[k + 1]``: per recording its status, SNR (dB) and
    energy."""
    count = first.size - 1
    status = np.empty(count, np.intp)
    db = np.zeros(count)
    energy = np.zeros(count)
    filtered = cutoff > 0.0
    for k in range(count):
        a, b = first[k], first[k + 1]
        c, d = model_first[k], model_first[k + 1]
        # Contiguous copies and no literal flag: the signature Python calls velocity_snr_of
        # with, compiled once.
        status[k], db[k], _, _, energy[k] = velocity_snr_of(
            t[a:b].copy(), xy[a:b].copy(), model_t[c:d].copy(), model_v[c:d].copy(), dt, cutoff,
            filtered, order, per_point, stamps, blends, scales, steps, widths, iterations,
        )  # fmt: skip
    return status, db, energy
