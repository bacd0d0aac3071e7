"""Compiled loops of the fitter (numba): evaluation of every trace's strokes and eq. 22.

The refinement's loops are in :mod:`tagbot.gesture.refine_kernels`.

A fit repeats small steps (a few thousand instants, tens of strokes) many times, where numpy's
per-call cost would dominate; these loops do each step in one call, with a cost linear in the
(instant, active stroke) pairs. Arrays follow :class:`~tagbot.gesture.strokes.Strokes`: strokes
flattened over traces, stroke ``j`` of trace ``k`` leaving target ``j + k``; samples grouped by
trace (``sample_first[k]:sample_first[k + 1]``) and sorted by time within each. Every trace is
computed on its own, so it comes out the same alone or among others.
"""

from __future__ import annotations

import math

import numpy as np

from tagbot.model.kernels import (
    N_CONSTANTS,
    TINY,
    compiled,
    lognormal_at,
    segment_constants,
    segment_point,
    stroke_window,
    unit_stroke,
)


@compiled
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
    t_on: np.ndarray,
    t_off: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Positions and velocities at the samples; per stroke its active samples ``begin..stop``
    (global indices); per active (sample, stroke) pair, grouped by stroke, ``(w, gx, gy, ux,
    uy)``: the CDF, the unit shape's point and the unit shape's velocity ``dg/dt``.
    """
    n = onsets.size
    begin, stop = np.empty(n, np.intp), np.empty(n, np.intp)
    for k in range(first_stroke.size - 1):
        lo, hi = sample_first[k], sample_first[k + 1]
        for j in range(first_stroke[k], first_stroke[k + 1]):
            begin[j] = lo + np.searchsorted(t[lo:hi], t_on[j], side="left")
            stop[j] = lo + np.searchsorted(t[lo:hi], t_off[j], side="right")
    xy, v = np.empty((t.size, 2)), np.empty((t.size, 2))
    pairs = np.empty((int(np.sum(stop - begin)), 5))
    p = 0
    for k in range(first_stroke.size - 1):
        lo, hi = sample_first[k], sample_first[k + 1]
        j0, j1 = first_stroke[k], first_stroke[k + 1]
        count = int(np.sum(stop[j0:j1] - begin[j0:j1]))
        evaluate_trace(
            t[lo:hi],
            targets[j0 + k : j1 + k + 1],
            onsets[j0:j1],
            mu[j0:j1],
            sigma[j0:j1],
            shapes[j0:j1],
            unit_length[j0:j1],
            begin[j0:j1] - lo,
            stop[j0:j1] - lo,
            xy[lo:hi],
            v[lo:hi],
            pairs[p : p + count],
            True,
        )
        p += count
    return xy, v, begin, stop, pairs


@compiled
def evaluate_trace(
    t: np.ndarray,
    targets: np.ndarray,
    onsets: np.ndarray,
    mu: np.ndarray,
    sigma: np.ndarray,
    shapes: np.ndarray,
    unit_length: np.ndarray,
    begin: np.ndarray,
    stop: np.ndarray,
    xy: np.ndarray,
    v: np.ndarray,
    pairs: np.ndarray,
    keep_pairs: bool,
) -> None:
    """One trace's positions and velocities into ``xy`` and ``v`` (and its pairs, if wanted):
    its first target, plus every completed stroke's chord, plus each active stroke's chord times
    its unit shape at ``W``, summed in stroke order."""
    done = np.zeros((t.size + 1, 2))  # completed chords, at the first sample after each window
    for j in range(onsets.size):
        done[stop[j], 0] += targets[j + 1, 0] - targets[j, 0]
        done[stop[j], 1] += targets[j + 1, 1] - targets[j, 1]
    x, y = targets[0, 0], targets[0, 1]
    for i in range(t.size):
        x += done[i, 0]
        y += done[i, 1]
        xy[i, 0], xy[i, 1] = x, y
        v[i, 0], v[i, 1] = 0.0, 0.0
    p = 0
    for j in range(onsets.size):
        cx, cy = targets[j + 1, 0] - targets[j, 0], targets[j + 1, 1] - targets[j, 1]
        length = unit_length[j]
        for i in range(begin[j], stop[j]):
            w, density = lognormal_at(t[i], onsets[j], mu[j], sigma[j])
            gx, gy, tx, ty = segment_point(shapes[j], length * w)
            ux, uy = tx * length * density, ty * length * density
            xy[i, 0] += cx * gx - cy * gy
            xy[i, 1] += cx * gy + cy * gx
            v[i, 0] += cx * ux - cy * uy
            v[i, 1] += cx * uy + cy * ux
            if keep_pairs:
                pairs[p, 0], pairs[p, 1], pairs[p, 2], pairs[p, 3], pairs[p, 4] = w, gx, gy, ux, uy
                p += 1


# --- eq. 22 -------------------------------------------------------------------------------------

CROSSING_STEPS = 8
"""Safeguarded Newton steps for the speed-profile crossings (quadratic once close)."""


@compiled
def crossing(a: int, b: int, onsets, mu, sigma, lengths, steps: int) -> float:  # type: ignore[no-untyped-def]
    """When the speed profiles of strokes ``a`` and ``b`` cross between their peaks, or the
    later peak if they do not: safeguarded Newton's method on the log-speeds."""
    onset_a, mu_a, sigma_a = onsets[a], mu[a], sigma[a]
    onset_b, mu_b, sigma_b = onsets[b], mu[b], sigma[b]
    # log(D Λ(t)) = log D − log σ − ℓ − (ℓ − μ)²/2σ², ℓ = log(t − t0).
    offset = math.log(lengths[a] / sigma_a) - math.log(lengths[b] / sigma_b)
    peak_a = onset_a + math.exp(mu_a - sigma_a * sigma_a)
    peak_b = onset_b + math.exp(mu_b - sigma_b * sigma_b)
    lo, hi = min(peak_a, peak_b), max(peak_a, peak_b)
    if not (_excess(lo, onset_a, mu_a, sigma_a, onset_b, mu_b, sigma_b, offset)[0] > 0.0):
        return hi
    if not (_excess(hi, onset_a, mu_a, sigma_a, onset_b, mu_b, sigma_b, offset)[0] < 0.0):
        return hi
    t = 0.5 * (lo + hi)
    for _ in range(steps):
        value, slope = _excess(t, onset_a, mu_a, sigma_a, onset_b, mu_b, sigma_b, offset)
        if value > 0.0:
            lo = t
        else:
            hi = t
        step = t - value / slope
        # Near an onset the slope overflows: the Newton step is then refused and we bisect.
        t = step if lo < step < hi else 0.5 * (lo + hi)
    return t


@compiled
def _excess(
    t: float, onset_a: float, mu_a: float, sigma_a: float, onset_b: float, mu_b: float,
    sigma_b: float, offset: float,
) -> tuple[float, float]:  # fmt: skip
    """The log-speed difference of strokes ``a`` and ``b`` at ``t`` (``offset`` the difference
    of their ``log(D/σ)``), and its derivative in ``t``."""
    ea = max(t - onset_a, TINY)
    eb = max(t - onset_b, TINY)
    la, lb = math.log(ea), math.log(eb)
    za = (la - mu_a) / sigma_a
    zb = (lb - mu_b) / sigma_b
    value = offset - la - 0.5 * za * za + lb + 0.5 * zb * zb
    slope = (1.0 + zb / sigma_b) / eb - (1.0 + za / sigma_a) / ea
    return value, slope


@compiled
def crossings(onsets, mu, sigma, lengths, a, b, steps: int) -> np.ndarray:  # type: ignore[no-untyped-def]
    """:func:`crossing` for each pair ``(a[i], b[i])``."""
    out = np.empty(a.size)
    for i in range(a.size):
        out[i] = crossing(a[i], b[i], onsets, mu, sigma, lengths, steps)
    return out


@compiled
def critical_points(
    targets: np.ndarray,
    onsets: np.ndarray,
    mu: np.ndarray,
    sigma: np.ndarray,
    shapes: np.ndarray,
    unit_length: np.ndarray,
    size: float,
    end_tolerance: float,
    steps: int,
    out: np.ndarray,
) -> None:
    """One trace's position at the critical instant of each interior target, into ``out``:
    where the speed profiles of the strokes meeting there cross (§6.4)."""
    n = onsets.size
    lengths = np.empty(n)
    t_on, t_off = np.empty(n), np.empty(n)
    for j in range(n):
        lengths[j] = unit_length[j] * math.hypot(
            targets[j + 1, 0] - targets[j, 0], targets[j + 1, 1] - targets[j, 1]
        )
        t_on[j], t_off[j] = stroke_window(
            onsets[j], mu[j], sigma[j], end_tolerance * size / (n * lengths[j])
        )
    times = np.empty(n - 1)
    for i in range(n - 1):
        times[i] = crossing(i, i + 1, onsets, mu, sigma, lengths, steps)
    order = np.argsort(times)
    sorted_times = times[order]
    begin, stop = np.empty(n, np.intp), np.empty(n, np.intp)
    for j in range(n):
        begin[j] = np.searchsorted(sorted_times, t_on[j], side="left")
        stop[j] = np.searchsorted(sorted_times, t_off[j], side="right")
    xy, v = np.empty((n - 1, 2)), np.empty((n - 1, 2))
    evaluate_trace(
        sorted_times, targets, onsets, mu, sigma, shapes, unit_length, begin, stop, xy, v,
        np.empty((0, 5)), False,
    )  # fmt: skip
    for i in range(n - 1):
        out[order[i], 0], out[order[i], 1] = xy[i, 0], xy[i, 1]


@compiled
def correct_targets(
    targets: np.ndarray,
    onsets: np.ndarray,
    mu: np.ndarray,
    sigma: np.ndarray,
    shapes: np.ndarray,
    unit_length: np.ndarray,
    first_stroke: np.ndarray,
    size: float,
    end_tolerance: float,
    tolerance: np.ndarray,
    iterations: int,
    steps: int,
) -> np.ndarray:
    """Eq. 22 trace by trace: the targets after moving each interior one by ``p(z_j) − c_j``
    (its starting point minus the trajectory's at its critical instant), all of a trace at
    once, by the largest of 1, ½, ¼ or ⅛ of that move that lowers the trace's largest error,
    until that error is below ``tolerance[k]``, no step lowers it, or after ``iterations``."""
    out = targets.copy()
    for k in range(first_stroke.size - 1):
        j0, j1 = first_stroke[k], first_stroke[k + 1]
        if j1 - j0 < 2:
            continue
        _correct_trace(
            out[j0 + k : j1 + k + 1], onsets[j0:j1], mu[j0:j1], sigma[j0:j1], shapes[j0:j1],
            unit_length[j0:j1], size, end_tolerance, tolerance[k], iterations, steps,
        )  # fmt: skip
    return out


@compiled
def _correct_trace(
    targets,
    onsets,
    mu,
    sigma,
    shapes,
    unit_length,
    size,
    end_tolerance,
    tolerance,
    iterations,
    steps,
) -> None:  # type: ignore[no-untyped-def]
    """:func:`correct_targets` for one trace, in place."""
    inner = targets.shape[0] - 2
    wanted = targets[1:-1].copy()
    reached = np.empty((inner, 2))
    error = np.empty((inner, 2))
    critical_points(
        targets, onsets, mu, sigma, shapes, unit_length, size, end_tolerance, steps, reached
    )
    worst = _errors(wanted, reached, error)
    trial = targets.copy()
    trial_error = np.empty((inner, 2))
    for _ in range(iterations):
        if worst < tolerance:
            return
        moved = False
        step = 1.0
        while step > 0.1 and not moved:  # 1, ½, ¼, ⅛
            for i in range(inner):
                trial[i + 1, 0] = targets[i + 1, 0] + step * error[i, 0]
                trial[i + 1, 1] = targets[i + 1, 1] + step * error[i, 1]
            step *= 0.5
            if collapsed(trial, 1e-9 * size):
                continue
            critical_points(
                trial, onsets, mu, sigma, shapes, unit_length, size, end_tolerance, steps, reached
            )
            trial_worst = _errors(wanted, reached, trial_error)
            if trial_worst < worst:
                targets[1:-1] = trial[1:-1]
                error[:] = trial_error
                worst = trial_worst
                moved = True
        if not moved:
            return


@compiled
def _errors(wanted: np.ndarray, reached: np.ndarray, error: np.ndarray) -> float:
    """``error = wanted − reached``; returns the largest distance."""
    worst = 0.0
    for i in range(wanted.shape[0]):
        error[i, 0] = wanted[i, 0] - reached[i, 0]
        error[i, 1] = wanted[i, 1] - reached[i, 1]
        worst = max(worst, math.hypot(error[i, 0], error[i, 1]))
    return worst


@compiled
def collapsed(targets: np.ndarray, limit: float) -> bool:
    """Whether two consecutive targets are within ``limit`` of each other."""
    for j in range(targets.shape[0] - 1):
        if (
            math.hypot(targets[j + 1, 0] - targets[j, 0], targets[j + 1, 1] - targets[j, 1])
            <= limit
        ):
            return True
    return False


@compiled
def shapes_of(phi1: np.ndarray, phi2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each stroke's unit-chord shape: its evaluation constants and its length."""
    constants = np.empty((phi1.size, N_CONSTANTS))
    length = np.empty(phi1.size)
    for j in range(phi1.size):
        theta0, kappa0, dkappa, length[j] = unit_stroke(phi1[j], phi2[j])
        segment_constants(theta0, kappa0, dkappa, length[j], constants[j])
    return constants, length


@compiled
def windows_of(
    targets, onsets, mu, sigma, unit_length, first_stroke, size, end_tolerance
) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """Each stroke's active window, as :meth:`tagbot.model.plan.Plan.windows` with ``size``."""
    t_on, t_off = np.empty(onsets.size), np.empty(onsets.size)
    for k in range(first_stroke.size - 1):
        count = first_stroke[k + 1] - first_stroke[k]
        for j in range(first_stroke[k], first_stroke[k + 1]):
            a = j + k
            chord = math.hypot(targets[a + 1, 0] - targets[a, 0], targets[a + 1, 1] - targets[a, 1])
            budget = end_tolerance * size / (count * unit_length[j] * chord)
            t_on[j], t_off[j] = stroke_window(onsets[j], mu[j], sigma[j], budget)
    return t_on, t_off
