"""Compiled loops of the fitter (numba): evaluation of every trace's strokes, eq. 22, and the
refinement's normal equations.

A fit repeats small steps (a few thousand instants, tens of strokes) many times, where numpy's
per-call cost would dominate; these loops do each step in one call, with a cost linear in the
(instant, active stroke) pairs. Arrays follow :class:`~tagbot.gesture.strokes.Strokes`: strokes
flattened over traces, stroke ``j`` leaving target ``j + trace[j]``; samples grouped by trace
(``sample_first[k]:sample_first[k + 1]``) and sorted by time within each.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tagbot.model.euler_kernels import segment_point

_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
_INV_SQRT_2 = 1.0 / math.sqrt(2.0)
_TINY = np.finfo(np.float64).tiny


@njit(cache=True)
def lognormal_at(t: float, onset: float, mu: float, sigma: float) -> tuple[float, float]:
    """A lognormal stroke's CDF ``W`` and density ``Λ`` at ``t``."""
    elapsed = max(t - onset, _TINY)
    z = (math.log(elapsed) - mu) / sigma
    return 0.5 * math.erfc(-z * _INV_SQRT_2), math.exp(-0.5 * z * z) * _INV_SQRT_2PI / (
        sigma * elapsed
    )


@njit(cache=True)
def active_ranges(
    t: np.ndarray,
    sample_first: np.ndarray,
    stroke_trace: np.ndarray,
    t_on: np.ndarray,
    t_off: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per stroke, its active samples ``begin..stop`` (global indices) within its trace's."""
    n = stroke_trace.size
    begin, stop = np.empty(n, np.intp), np.empty(n, np.intp)
    for j in range(n):
        k = stroke_trace[j]
        lo, hi = sample_first[k], sample_first[k + 1]
        times = t[lo:hi]
        begin[j] = lo + np.searchsorted(times, t_on[j], side="left")
        stop[j] = lo + np.searchsorted(times, t_off[j], side="right")
    return begin, stop


@njit(cache=True)
def evaluate(
    t: np.ndarray,
    sample_first: np.ndarray,
    first_stroke: np.ndarray,
    targets: np.ndarray,
    onsets: np.ndarray,
    mu: np.ndarray,
    sigma: np.ndarray,
    shapes: np.ndarray,
    unit_length: np.ndarray,
    begin: np.ndarray,
    stop: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions and velocities at the samples, and per active (sample, stroke) pair, grouped
    by stroke, ``(w, gx, gy, ux, uy)``: the CDF, the unit shape's point, and the unit shape's
    velocity (``d g / dt``).

    A trace's position is its first target plus every completed stroke's chord plus each active
    stroke's chord times its unit shape at ``W``; the sums run in stroke order within the trace,
    so a trace evaluates the same alone or among others.
    """
    count = t.size
    xy = np.zeros((count, 2))
    v = np.zeros((count, 2))
    pairs = np.empty((int(np.sum(stop - begin)), 5))
    traces = first_stroke.size - 1
    p = 0
    for k in range(traces):
        lo, hi = sample_first[k], sample_first[k + 1]
        start = first_stroke[k] + k  # the trace's first target
        # Completed strokes: a difference array over the trace's samples, summed in order.
        done = np.zeros((hi - lo + 1, 2))
        for j in range(first_stroke[k], first_stroke[k + 1]):
            a = j + k
            done[stop[j] - lo, 0] += targets[a + 1, 0] - targets[a, 0]
            done[stop[j] - lo, 1] += targets[a + 1, 1] - targets[a, 1]
        x, y = targets[start, 0], targets[start, 1]
        for i in range(lo, hi):
            x += done[i - lo, 0]
            y += done[i - lo, 1]
            xy[i, 0], xy[i, 1] = x, y
        for j in range(first_stroke[k], first_stroke[k + 1]):
            a = j + k
            cx, cy = targets[a + 1, 0] - targets[a, 0], targets[a + 1, 1] - targets[a, 1]
            length = unit_length[j]
            for i in range(begin[j], stop[j]):
                w, density = lognormal_at(t[i], onsets[j], mu[j], sigma[j])
                gx, gy, tx, ty = segment_point(shapes[j], length * w)
                ux, uy = tx * length * density, ty * length * density
                xy[i, 0] += cx * gx - cy * gy
                xy[i, 1] += cx * gy + cy * gx
                v[i, 0] += cx * ux - cy * uy
                v[i, 1] += cx * uy + cy * ux
                pairs[p, 0], pairs[p, 1], pairs[p, 2], pairs[p, 3], pairs[p, 4] = w, gx, gy, ux, uy
                p += 1
    return xy, v, pairs
