"""Compiled loops of the shape error (numba): each query point's exact distance to a set of
polylines, found through a uniform grid of their samples (see :func:`tagbot.metrics.shape_error`).

The polylines are given as samples ``points`` (N, 2) with, per sample, the indices of the
samples before and after it on its polyline (itself at a polyline's ends); the segments between
consecutive samples are the polylines' own, cut at the samples, each at most ``spacing`` long.
"""

from __future__ import annotations

import math

import numpy as np

from tagbot.gesture.refine_kernels import buckets
from tagbot.model.kernels import compiled

__all__ = ["COARSE", "distances", "grid_of"]

COARSE = 16
"""Coarse cells are this many fine cells wide."""


@compiled
def grid_of(points: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The uniform grid of ``cell``-wide cells over ``points`` (one group of
    :func:`tagbot.gesture.refine_kernels.buckets`)."""
    first = np.array([0, points.shape[0]], dtype=np.intp)
    return buckets(points, first, cell)


@compiled
def _segment_d2(qx: float, qy: float, ax: float, ay: float, bx: float, by: float) -> float:
    """Squared distance from ``(qx, qy)`` to the segment from a to b."""
    ux, uy = bx - ax, by - ay
    length2 = ux * ux + uy * uy
    u = 0.0
    if length2 > 0.0:
        u = min(max(((qx - ax) * ux + (qy - ay) * uy) / length2, 0.0), 1.0)
    dx, dy = qx - ax - u * ux, qy - ay - u * uy
    return dx * dx + dy * dy


@compiled
def _search(
    x: float,
    y: float,
    best: float,
    points: np.ndarray,
    before: np.ndarray,
    after: np.ndarray,
    header: np.ndarray,
    start: np.ndarray,
    order: np.ndarray,
    cell: float,
    spacing: float,
    rings: int,
) -> tuple[float, bool]:
    """Improve ``best``, the distance from ``(x, y)`` to the polylines, over the cells of one
    grid, ring by ring outwards, at most ``rings`` rings; and whether no segment left can be
    nearer. Every point of a segment (at most ``spacing`` long) is within ``spacing / 2`` of one
    of its end samples, so a ring farther than the best distance plus that ends the search."""
    x0, y0 = header[0, 0], header[0, 1]
    nx, ny = int(header[0, 2]), int(header[0, 3])
    cx = min(max(math.floor((x - x0) / cell), 0), nx - 1)
    cy = min(max(math.floor((y - y0) / cell), 0), ny - 1)
    for ring in range(min(max(nx, ny), rings) + 1):
        for iy in range(max(cy - ring, 0), min(cy + ring, ny - 1) + 1):
            edge = iy == cy - ring or iy == cy + ring
            ix = cx - ring
            while ix <= cx + ring:
                if 0 <= ix < nx:
                    dx = max(x0 + ix * cell - x, 0.0, x - x0 - (ix + 1) * cell)
                    dy = max(y0 + iy * cell - y, 0.0, y - y0 - (iy + 1) * cell)
                    reach = best + 0.5 * spacing
                    if dx * dx + dy * dy < reach * reach:
                        c = iy * nx + ix
                        for e in range(start[c], start[c + 1]):
                            i = order[e]
                            px, py = points[i, 0], points[i, 1]
                            for j in (before[i], after[i]):
                                d2 = _segment_d2(x, y, px, py, points[j, 0], points[j, 1])
                                if d2 < best * best:
                                    best = math.sqrt(d2)
                ix += 1 if edge else max(2 * ring, 1)
        # Cells beyond this ring are at least ``ring`` cells away from the query.
        if ring * cell >= best + 0.5 * spacing:
            return best, True
    return best, max(nx, ny) <= rings


@compiled
def distances(
    query: np.ndarray,
    points: np.ndarray,
    before: np.ndarray,
    after: np.ndarray,
    fine: tuple[np.ndarray, np.ndarray, np.ndarray],
    fine_cell: float,
    coarse: tuple[np.ndarray, np.ndarray, np.ndarray],
    coarse_cell: float,
    spacing: float,
    fine_rings: int,
) -> np.ndarray:
    """Each query point's exact distance to the polylines: searched in the fine grid for
    ``fine_rings`` rings (enough for points near the polylines, the usual case), then, if that
    could not settle it, in the coarse one (far points cost a few coarse rings, not thousands of
    fine ones)."""
    out = np.empty(query.shape[0])
    for q in range(query.shape[0]):
        x, y = query[q, 0], query[q, 1]
        best, done = _search(x, y, np.inf, points, before, after, fine[0], fine[1], fine[2],
                             fine_cell, spacing, fine_rings)  # fmt: skip
        if not done:
            best, done = _search(x, y, best, points, before, after, coarse[0], coarse[1],
                                 coarse[2], coarse_cell, spacing, 1 << 30)  # fmt: skip
        out[q] = best
    return out
