"""Compiled loops of the least-squares refinement (numba): residuals with nearest contour
samples, the Jacobian, banded normal equations with the instants eliminated, and the
Levenberg-Marquardt loop (see :mod:`tagbot.gesture.refine`). Array conventions as in
:mod:`tagbot.gesture.kernels`.
"""

from __future__ import annotations

import math

import numpy as np

from tagbot.gesture.kernels import collapsed, crossing, evaluate, shapes_of, windows_of
from tagbot.model.kernels import (
    SMALL_A,
    TAYLOR_B,
    compiled,
    generalized_fresnel_into,
    taylor,
    unit_stroke,
)

# --- the refinement's normal equations ----------------------------------------------------------


@compiled
def jacobian(
    begin: np.ndarray,
    stop: np.ndarray,
    pairs: np.ndarray,
    chords: np.ndarray,
    first_stroke: np.ndarray,
    phi1: np.ndarray,
    phi2: np.ndarray,
    arcs_only: bool,
    h: float,
    angle_col: np.ndarray,
    onset_col: np.ndarray,
    target_col: np.ndarray,
    rows: int,
    tail: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The trajectory's complex Jacobian in the plan's parameters, as rows (``indptr``, ``col``,
    ``value``) per evaluation row; where a stroke's CDF is within ``tail`` of 0 or 1 it counts
    as not started or complete (``tail = 0``: exact).

    Targets: ``x = Σ_i p_i (G_{i−1} − G_i)`` is complex-linear in each interior target. Onsets:
    moving one later moves its stroke's contribution back by its velocity. Tangents: the unit
    shape's point at the same CDF value moves with the spiral's ``(θ0, κ0, κ', L)``, whose
    partial derivatives are closed form (:func:`_shape_partials`) and whose derivatives in the
    angles are central differences (step ``h``) of the G1 fit, per stroke. Stroke ``j``'s columns
    are ``angle_col[j]`` (and the next), ``onset_col[j]`` and ``target_col[j]`` (x, then y) of
    the target it leaves, −1 where fixed.
    """
    n = begin.size
    offsets = np.zeros(n + 1, np.intp)
    for j in range(n):
        offsets[j + 1] = offsets[j] + stop[j] - begin[j]
    angles = 1 if arcs_only else 2
    # Per stroke its shape (θ0, κ0, κ', L) and, by central differences, their derivatives in
    # each angle parameter.
    shape = np.empty((n, 4))
    slope = np.empty((angles, n, 4))
    for j in range(n):
        shape[j, 0], shape[j, 1], shape[j, 2], shape[j, 3] = unit_stroke(phi1[j], phi2[j])
        for m in range(angles):
            d1, d2 = (-h, h) if arcs_only else ((h, 0.0) if m == 0 else (0.0, h))
            plus = unit_stroke(phi1[j] + d1, phi2[j] + d2)
            minus = unit_stroke(phi1[j] - d1, phi2[j] - d2)
            for q in range(4):
                slope[m, j, q] = (plus[q] - minus[q]) / (2.0 * h)
    # Each stroke's rows beyond its tails, ``first..last`` (within ``begin..stop``; w rises).
    first, last = begin.copy(), stop.copy()
    for j in range(n):
        while first[j] < stop[j] and pairs[offsets[j] + first[j] - begin[j], 0] < tail:
            first[j] += 1
        last[j] = first[j]
        while last[j] < stop[j] and pairs[offsets[j] + last[j] - begin[j], 0] <= 1.0 - tail:
            last[j] += 1
    for j in range(n):  # pair index of row i: offsets[j] + i − begin[j], with the new begin
        offsets[j] += first[j] - begin[j]
    begin, stop = first, last
    # Count the entries per row, then fill them in row order.
    count = np.zeros(rows + 1, np.intp)
    for j in range(n):
        per_pair = angles + (1 if onset_col[j] >= 0 else 0)
        for i in range(begin[j], stop[j]):
            count[i + 1] += per_pair
        if target_col[j] >= 0:
            lo, hi = min(begin[j - 1], begin[j]), max(stop[j - 1], stop[j])
            for i in range(lo, hi):
                count[i + 1] += 2
    indptr = np.cumsum(count)
    fill = indptr[:-1].copy()
    col = np.empty(indptr[-1], np.intp)
    value = np.empty(indptr[-1], np.complex128)
    for j in range(n):
        chord = complex(chords[j, 0], chords[j, 1])
        for i in range(begin[j], stop[j]):
            q = offsets[j] + i - begin[j]
            w, g = pairs[q, 0], complex(pairs[q, 1], pairs[q, 2])
            partial = _shape_partials(shape[j, 0], shape[j, 1], shape[j, 2], shape[j, 3], w, g)
            for m in range(angles):
                dg = 0j
                for p in range(4):
                    dg += partial[p] * slope[m, j, p]
                col[fill[i]] = angle_col[j] + m
                value[fill[i]] = chord * dg
                fill[i] += 1
            if onset_col[j] >= 0:
                col[fill[i]] = onset_col[j]
                value[fill[i]] = -chord * complex(pairs[q, 3], pairs[q, 4])
                fill[i] += 1
        if target_col[j] >= 0:
            a, b = j - 1, j
            lo, hi = min(begin[a], begin[b]), max(stop[a], stop[b])
            for i in range(lo, hi):
                # Each stroke's unit shape at row i: 0 before its window, 1 after.
                cx, cy = 0.0, 0.0
                if i >= stop[a]:
                    cx = 1.0
                elif i >= begin[a]:
                    q = offsets[a] + i - begin[a]
                    cx, cy = pairs[q, 1], pairs[q, 2]
                if i >= stop[b]:
                    cx -= 1.0
                elif i >= begin[b]:
                    q = offsets[b] + i - begin[b]
                    cx, cy = cx - pairs[q, 1], cy - pairs[q, 2]
                e = fill[i]
                col[e], value[e] = target_col[j], complex(cx, cy)
                col[e + 1], value[e + 1] = target_col[j] + 1, complex(-cy, cx)
                fill[i] = e + 2
    return indptr, col, value


@compiled
def _shape_partials(
    theta0: float, kappa0: float, dkappa: float, length: float, w: float, g: complex
) -> tuple[complex, complex, complex, complex]:
    """Derivatives of a unit shape's point ``g = P(L·w)`` in its ``(θ0, κ0, κ', L)``.

    With ``P(s) = s·e^{iθ0}·I_0(κ's², κ0 s)``: ``∂P/∂θ0 = iP``, ``∂P/∂κ0 = i s² e^{iθ0} I_1``,
    ``∂P/∂κ' = (i/2) s³ e^{iθ0} I_2`` and ``∂P/∂L = w·e^{iθ(s)}``.
    """
    s = length * w
    if s == 0.0:
        return 0j, 0j, 0j, 0j
    a, b = dkappa * s * s, kappa0 * s
    e0 = complex(math.cos(theta0), math.sin(theta0))
    i0 = g / (s * e0)
    i1, i2 = _higher_moments(a, b, i0)
    theta = theta0 + s * (kappa0 + 0.5 * dkappa * s)
    return (
        1j * g,
        1j * s * s * e0 * i1,
        0.5j * s * s * s * e0 * i2,
        w * complex(math.cos(theta), math.sin(theta)),
    )


@compiled
def _higher_moments(a: float, b: float, i0: complex) -> tuple[complex, complex]:
    """``I_1(a, b)`` and ``I_2(a, b)`` from ``I_0``: B&F's recurrence in ``k`` down to
    ``|a| = SMALL_A`` (enough for a derivative), the series below."""
    if abs(a) < SMALL_A and abs(b) <= TAYLOR_B:
        return taylor(a, b, 1e-12)[1:]  # a derivative: 1e-12 of the unit chord is plenty
    if abs(a) < SMALL_A:
        out = np.empty(3, np.complex128)
        generalized_fresnel_into(a, b, False, out)
        return out[1], out[2]
    psi = 0.5 * a + b
    e1 = complex(math.cos(psi), math.sin(psi))
    # a I_{k+1} + b I_k = −i (e^{iψ(1)} − [k = 0]) + i k I_{k−1}
    i1 = (-1j * (e1 - 1.0) - b * i0) / a
    i2 = (-1j * e1 - b * i1 + 1j * i0) / a
    return i1, i2


@compiled
def normal_equations(
    indptr: np.ndarray,
    col: np.ndarray,
    value: np.ndarray,
    residual: np.ndarray,
    velocity: np.ndarray,
    speed2: np.ndarray,
    forward: np.ndarray,
    params: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The real normal equations of the complex Jacobian rows, in band storage.

    Returns ``A = Re(CᴴC)`` and ``B = Σ u uᵀ / |v|²`` over the forward rows (lower bands, row
    by row: ``[c, d] = M[c, c − d]``), ``g = Re(Cᴴ r)``, and per row ``u = Re(conj(v)·C_row)``
    (aligned with ``value``) — the coupling of a forward row's own instant, whose column is its
    velocity ``v``, to the parameters.
    """
    rows = indptr.size - 1
    band = 0
    for i in range(rows):  # a row's columns come in increasing order (see jacobian)
        if indptr[i + 1] > indptr[i]:
            band = max(band, col[indptr[i + 1] - 1] - col[indptr[i]])
    a = np.zeros((params, band + 1))
    b = np.zeros((params, band + 1))
    g = np.zeros(params)
    u = np.zeros(value.size)
    re, im = value.real.copy(), value.imag.copy()
    for i in range(rows):
        rr, ri = residual[i].real, residual[i].imag
        lo, hi = indptr[i], indptr[i + 1]
        if forward[i]:
            vx, vy = velocity[i].real, velocity[i].imag
            for e in range(lo, hi):
                u[e] = vx * re[e] + vy * im[e]
        inverse = 1.0 / speed2[i] if forward[i] else 0.0
        for e in range(lo, hi):
            ce, xe, ye = col[e], re[e], im[e]
            g[ce] += xe * rr + ye * ri
            ue = u[e] * inverse
            row_a, row_b = a[ce], b[ce]
            for f in range(lo, e + 1):
                d = ce - col[f]
                row_a[d] += re[f] * xe + im[f] * ye
                row_b[d] += ue * u[f]
    return a, b, g, u


@compiled
def damped_step(
    a: np.ndarray,
    b: np.ndarray,
    scale: np.ndarray,
    g: np.ndarray,
    indptr: np.ndarray,
    col: np.ndarray,
    u: np.ndarray,
    g_t: np.ndarray,
    speed2: np.ndarray,
    forward: np.ndarray,
    damping: float,
) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """The Levenberg-Marquardt step at ``damping`` with the forward instants eliminated (a Schur
    complement, still banded): ``(step for the parameters, step per row's instant, the cost
    decrease the linear model predicts, whether the system was positive definite)``.

    With ``d = |v|²(1 + λ)`` per forward row: ``(A − B/(1 + λ) + λ·diag(scale)) δp =
    −g + Σ u g_t / d`` and ``δt = (−g_t − u·δp) / d``.
    """
    params = g.size
    band = a.shape[1] - 1
    factor = np.empty_like(a)
    shrink = 1.0 / (1.0 + damping)
    for c in range(params):
        for d in range(band + 1):
            factor[c, d] = a[c, d] - b[c, d] * shrink
        factor[c, 0] += damping * scale[c]
    rhs = -g.copy()
    rows = indptr.size - 1
    for i in range(rows):
        if forward[i]:
            weight = g_t[i] / (speed2[i] * (1.0 + damping))
            for e in range(indptr[i], indptr[i + 1]):
                rhs[col[e]] += u[e] * weight
    if not _band_cholesky(factor, band):
        return np.zeros(params), np.zeros(rows), 0.0, False
    step = _band_solve(factor, band, rhs)
    step_t = np.zeros(rows)
    predicted = 0.0
    for c in range(params):
        predicted += damping * scale[c] * step[c] * step[c] - step[c] * g[c]
    for i in range(rows):
        if forward[i]:
            coupled = 0.0
            for e in range(indptr[i], indptr[i + 1]):
                coupled += u[e] * step[col[e]]
            step_t[i] = (-g_t[i] - coupled) / (speed2[i] * (1.0 + damping))
            predicted += damping * speed2[i] * step_t[i] ** 2 - step_t[i] * g_t[i]
    return step, step_t, predicted, True


@compiled
def _band_cholesky(m: np.ndarray, band: int) -> bool:
    """In place: the lower band ``m`` (``m[i, d] = M[i, i − d]``) becomes its Cholesky factor
    ``L`` in the same storage, row by row. False if ``M`` is not positive definite."""
    n = m.shape[0]
    for i in range(n):
        first = max(0, i - band)
        for j in range(first, i + 1):
            s = m[i, i - j]
            for k in range(first, j):
                s -= m[i, i - k] * m[j, j - k]
            if j < i:
                m[i, i - j] = s / m[j, 0]
            elif s > 0.0:
                m[i, 0] = math.sqrt(s)
            else:
                return False
    return True


@compiled
def _band_solve(factor: np.ndarray, band: int, rhs: np.ndarray) -> np.ndarray:
    """Solve ``L Lᵀ x = rhs`` with the banded Cholesky factor of :func:`_band_cholesky`."""
    n = rhs.size
    y = rhs.copy()
    for i in range(n):
        s = y[i]
        for k in range(max(0, i - band), i):
            s -= factor[i, i - k] * y[k]
        y[i] = s / factor[i, 0]
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, min(n, i + band + 1)):
            s -= factor[k, k - i] * y[k]
        y[i] = s / factor[i, 0]
    return y


# --- nearest contour samples ------------------------------------------------------------------


OCCUPANCY = 2.0
"""Points per cell that :func:`path_buckets` aims at where the points fill their box."""
SPACINGS = 6.0
"""... and the widest cell it takes, in mean spacings between consecutive points."""
FINEST = 0.125
"""... and the finest, in points per cell where the points fill their box (cells 8x points)."""


@compiled
def buckets(
    points: np.ndarray, first: np.ndarray, cell: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A uniform grid of cells ``cell`` wide over each group ``first[k]:first[k + 1]`` of
    ``points``, for :func:`nearest`: per group ``(x0, y0, nx, ny, its first cell, cell)``, and
    the points of cell ``c``, ``order[start[c]:start[c + 1]]``."""
    return _buckets(points, first, np.full(first.size - 1, cell))


@compiled
def path_buckets(
    points: np.ndarray, first: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`buckets` with each group's own cell width, for a group of points along a path
    (consecutive points consecutive on it): :data:`SPACINGS` mean spacings, but no wider than
    holds :data:`OCCUPANCY` points per cell where the points fill their bounding box, nor finer
    than :data:`FINEST`. So a sparse curve gets cells a few samples long, and a path crossing
    its box over and over (random points: the contour's length grows with their number, its box
    does not) keeps a bounded number of points per cell: the cells (memory) and the work of a
    query near the points stay proportional to the points, and at most to their number.
    """
    groups = first.size - 1
    cells = np.empty(groups)
    for k in range(groups):
        lo, hi = first[k], first[k + 1]
        count = hi - lo
        width = np.max(points[lo:hi, 0]) - np.min(points[lo:hi, 0])
        height = np.max(points[lo:hi, 1]) - np.min(points[lo:hi, 1])
        length = 0.0
        for i in range(lo + 1, hi):
            length += math.hypot(points[i, 0] - points[i - 1, 0], points[i, 1] - points[i - 1, 1])
        spacing = length / max(count - 1, 1)
        cells[k] = max(
            min(SPACINGS * spacing, _fill_cell(width, height, count, OCCUPANCY)),
            _fill_cell(width, height, count, FINEST),
        )
        if not cells[k] > 0.0:  # all the points at one place: any width
            cells[k] = 1.0
    return _buckets(points, first, cells)


@compiled
def _fill_cell(width: float, height: float, count: int, occupancy: float) -> float:
    """The cell width giving at most about ``count / occupancy`` cells over a ``width`` x
    ``height`` box (three times that at most, where the box is a line)."""
    area_cell = math.sqrt(width * height * occupancy / count)
    return max(area_cell, max(width, height) * occupancy / count)


@compiled
def _buckets(
    points: np.ndarray, first: np.ndarray, cells: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`buckets` with cells ``cells[k]`` wide for group ``k``."""
    groups = first.size - 1
    header = np.empty((groups, 6))
    total = 0
    for k in range(groups):
        lo, hi, cell = first[k], first[k + 1], cells[k]
        x0, y0 = np.min(points[lo:hi, 0]), np.min(points[lo:hi, 1])
        nx = int((np.max(points[lo:hi, 0]) - x0) / cell) + 1
        ny = int((np.max(points[lo:hi, 1]) - y0) / cell) + 1
        header[k, 0], header[k, 1], header[k, 2], header[k, 3] = x0, y0, nx, ny
        header[k, 4], header[k, 5] = total, cell
        total += nx * ny
    which = np.empty(points.shape[0], np.intp)
    start = np.zeros(total + 1, np.intp)
    for k in range(groups):
        x0, y0, cell = header[k, 0], header[k, 1], header[k, 5]
        nx, ny, base = int(header[k, 2]), int(header[k, 3]), int(header[k, 4])
        for i in range(first[k], first[k + 1]):
            cx = min(int((points[i, 0] - x0) / cell), nx - 1)
            cy = min(int((points[i, 1] - y0) / cell), ny - 1)
            which[i] = base + cy * nx + cx
            start[which[i] + 1] += 1
    start = np.cumsum(start)
    fill = start[:-1].copy()
    order = np.empty(points.shape[0], np.intp)
    for i in range(points.shape[0]):
        order[fill[which[i]]] = i
        fill[which[i]] += 1
    return header, start, order


@compiled
def nearest(
    points: np.ndarray, header: np.ndarray, start: np.ndarray, order: np.ndarray, k: int,
    x: float, y: float, lo: int = 0, hi: int = -1,
) -> tuple[int, int]:  # fmt: skip
    """The point of group ``k`` nearest to ``(x, y)`` (:func:`buckets`) among points ``lo..hi``
    (``hi < 0``: all), and the work it took (cells and points looked at): cells ring by ring
    outwards, skipping those farther than the best so far, until no ring left can be nearer."""
    x0, y0, cell = header[k, 0], header[k, 1], header[k, 5]
    nx, ny, base = int(header[k, 2]), int(header[k, 3]), int(header[k, 4])
    cx = min(max(math.floor((x - x0) / cell), 0), nx - 1)
    cy = min(max(math.floor((y - y0) / cell), 0), ny - 1)
    best, best_d2 = -1, np.inf
    work = 0
    for ring in range(max(nx, ny) + 1):
        for iy in range(max(cy - ring, 0), min(cy + ring, ny - 1) + 1):
            edge = iy == cy - ring or iy == cy + ring
            step = 1 if edge else 2 * ring
            ix = cx - ring
            while ix <= cx + ring:
                if 0 <= ix < nx:
                    dx = max(x0 + ix * cell - x, 0.0, x - x0 - (ix + 1) * cell)
                    dy = max(y0 + iy * cell - y, 0.0, y - y0 - (iy + 1) * cell)
                    work += 1
                    if dx * dx + dy * dy < best_d2:
                        c = base + iy * nx + ix
                        work += start[c + 1] - start[c]
                        for e in range(start[c], start[c + 1]):
                            i = order[e]
                            if hi >= 0 and not lo <= i <= hi:
                                continue
                            px, py = points[i, 0] - x, points[i, 1] - y
                            if px * px + py * py < best_d2:
                                best, best_d2 = i, px * px + py * py
                ix += max(step, 1)
        # Cells beyond this ring are at least ``ring`` cells away.
        if (ring * cell) ** 2 >= best_d2:
            break
    return best, work


SCAN = 4096
"""A grid row's contour samples are scanned one by one when fewer than this (a few strokes'
worth; a dense grid cell holds samples of other parts of the contour, which a range skips but
still reads), else searched through the grid."""


@compiled
def _nearest_in(points: np.ndarray, lo: int, hi: int, x: float, y: float) -> int:
    """The first of ``points[lo..hi]`` nearest to ``(x, y)``."""
    best, best_d2 = lo, np.inf
    for i in range(lo, hi + 1):
        dx, dy = points[i, 0] - x, points[i, 1] - y
        if dx * dx + dy * dy < best_d2:
            best, best_d2 = i, dx * dx + dy * dy
    return best


# --- the refinement ---------------------------------------------------------------------------


@compiled
def residuals(
    targets,
    onsets,
    mu,
    sigma,
    phi1,
    phi2,
    first_stroke,
    tau,
    goal,
    goal_first,
    goal_index,
    grid,
    grid_first,
    contour,
    header,
    start,
    order,
    reach,
    size,
    end_tolerance,
):  # type: ignore[no-untyped-def]
    """The refinement's residuals for the plan and the forward instants ``tau``.

    Rows are evaluation rows: per trace its forward instants and grid instants, sorted by time.
    Returns ``(instant per row — forward index f, or F + grid index —, begin, stop, pairs,
    residual per row (complex, trajectory minus goal), velocity per row (complex), nearest
    contour sample per row (grid rows; −1 for forward rows), the work of those searches
    (:func:`nearest`))``; the goal of a forward row is ``goal[f]`` (contour sample
    ``goal_index[f]``), of a grid row the contour sample nearest to the trajectory there among
    those between the goals of the ``reach`` forward rows before it and after it (``header,
    start, order``: :func:`path_buckets`): a trajectory that strays towards another part of
    its contour (a spiral's next turn, a loop's other side) is pulled back to its own.
    """
    forward = tau.size
    traces = first_stroke.size - 1
    rows = forward + grid.size
    instant = np.empty(rows, np.intp)
    t = np.empty(rows)
    sample_first = np.empty(traces + 1, np.intp)
    sample_first[0] = 0
    for k in range(traces):
        lo = sample_first[k]
        f0, f1, g0, g1 = goal_first[k], goal_first[k + 1], grid_first[k], grid_first[k + 1]
        count = (f1 - f0) + (g1 - g0)
        times = np.empty(count)
        ids = np.empty(count, np.intp)
        times[: f1 - f0], ids[: f1 - f0] = tau[f0:f1], np.arange(f0, f1)
        times[f1 - f0 :], ids[f1 - f0 :] = grid[g0:g1], forward + np.arange(g0, g1)
        sort = np.argsort(times, kind="mergesort")
        t[lo : lo + count], instant[lo : lo + count] = times[sort], ids[sort]
        sample_first[k + 1] = lo + count
    constants, unit_length = shapes_of(phi1, phi2)
    t_on, t_off = windows_of(
        targets, onsets, mu, sigma, unit_length, first_stroke, size, end_tolerance
    )
    xy, v, begin, stop, pairs = evaluate(
        t, sample_first, first_stroke, targets, onsets, mu, sigma, constants, unit_length, t_on,
        t_off,
    )  # fmt: skip
    residual = np.empty(rows, np.complex128)
    velocity = np.empty(rows, np.complex128)
    near = np.full(rows, -1, np.intp)
    work = 0
    for k in range(traces):
        lo, hi = sample_first[k], sample_first[k + 1]
        # The goals' contour samples in time order, and per row how many come before it.
        along = np.empty(goal_first[k + 1] - goal_first[k], np.intp)
        before = np.empty(hi - lo, np.intp)
        count = 0
        for i in range(lo, hi):
            before[i - lo] = count
            if instant[i] < forward:
                along[count] = goal_index[instant[i]]
                count += 1
        for i in range(lo, hi):
            velocity[i] = complex(v[i, 0], v[i, 1])
            if instant[i] < forward:
                gx, gy = goal[instant[i], 0], goal[instant[i], 1]
            else:
                first_goal = max(before[i - lo] - reach, 0)
                last_goal = min(before[i - lo] + reach, count) - 1
                low, high = along[first_goal], along[first_goal]
                for f in range(first_goal + 1, last_goal + 1):
                    low, high = min(low, along[f]), max(high, along[f])
                if high - low < SCAN:
                    near[i] = _nearest_in(contour, low, high, xy[i, 0], xy[i, 1])
                    work += high - low + 1
                else:
                    near[i], effort = nearest(
                        contour, header, start, order, k, xy[i, 0], xy[i, 1], low, high
                    )
                    work += effort
                gx, gy = contour[near[i], 0], contour[near[i], 1]
            residual[i] = complex(xy[i, 0] - gx, xy[i, 1] - gy)
    return instant, begin, stop, pairs, residual, velocity, near, work


@compiled
def cost_of(residual: np.ndarray) -> float:
    total = 0.0
    for r in residual:
        total += r.real * r.real + r.imag * r.imag
    return total


@compiled
def initial_instants(
    targets,
    onsets,
    mu,
    sigma,
    phi1,
    phi2,
    first_stroke,
    goal,
    goal_first,
    goal_stroke,
    dense,
    ends,
    size,
    end_tolerance,
    steps,
) -> tuple[np.ndarray, int]:  # type: ignore[no-untyped-def]
    """Each goal's instant: the nearest of ``dense[k]`` instants spread over its trace's motion
    (``0..ends[k]``) among those from the critical instant (§6.4) of the target before the one
    its stroke ``goal_stroke[f]`` leaves to that of the target after the one it reaches (the
    trace's start and end beyond them); and the work of those searches (instants looked at).

    Kept so near its own stroke, a goal is not matched to where the trajectory passes by it at
    another time (a spiral's next turn): the instants keep the contour's order, and each search
    looks at a few strokes' worth of instants whatever the length of the trace.
    """
    traces = first_stroke.size - 1
    sample_first = np.zeros(traces + 1, np.intp)
    for k in range(traces):
        sample_first[k + 1] = sample_first[k] + dense[k]
    t = np.empty(sample_first[-1])
    for k in range(traces):
        t[sample_first[k] : sample_first[k + 1]] = np.linspace(0.0, ends[k], dense[k])
    constants, unit_length = shapes_of(phi1, phi2)
    t_on, t_off = windows_of(
        targets, onsets, mu, sigma, unit_length, first_stroke, size, end_tolerance
    )
    xy = evaluate(
        t, sample_first, first_stroke, targets, onsets, mu, sigma, constants, unit_length, t_on,
        t_off,
    )[0]  # fmt: skip
    # Per target, its critical instant: where the speed profiles of its two strokes cross.
    lengths = np.empty(onsets.size)
    for k in range(traces):
        for j in range(first_stroke[k], first_stroke[k + 1]):
            chord = math.hypot(
                targets[j + k + 1, 0] - targets[j + k, 0], targets[j + k + 1, 1] - targets[j + k, 1]
            )
            lengths[j] = unit_length[j] * chord
    critical = np.empty(onsets.size + traces)
    for k in range(traces):
        j0, j1 = first_stroke[k], first_stroke[k + 1]
        critical[j0 + k], critical[j1 + k] = 0.0, ends[k]
        for j in range(j0 + 1, j1):
            when = crossing(j - 1, j, onsets, mu, sigma, lengths, steps)
            critical[j + k] = min(max(when, 0.0), ends[k])
    tau = np.empty(goal.shape[0])
    work = 0
    for k in range(traces):
        lo, hi = sample_first[k], sample_first[k + 1]
        j0, j1 = first_stroke[k], first_stroke[k + 1]
        for f in range(goal_first[k], goal_first[k + 1]):
            j = goal_stroke[f]
            early = critical[max(j - 1, j0) + k]
            late = critical[min(j + 2, j1) + k]
            first = lo + np.searchsorted(t[lo:hi], min(early, late), side="left")
            last = lo + np.searchsorted(t[lo:hi], max(early, late), side="right")
            if last <= first:
                first, last = lo, hi
            best, best_d2 = first, np.inf
            for i in range(first, last):
                dx, dy = xy[i, 0] - goal[f, 0], xy[i, 1] - goal[f, 1]
                if dx * dx + dy * dy < best_d2:
                    best, best_d2 = i, dx * dx + dy * dy
            tau[f] = t[best]
            work += last - first
    return tau, work


@compiled
def pack(targets, onsets, phi1, phi2, first_stroke, angle_col, onset_col, target_col,
         arcs_only, params):  # type: ignore[no-untyped-def]  # fmt: skip
    """The refinement's parameter vector (see :class:`tagbot.gesture.refine._Layout`)."""
    x = np.empty(params)
    for k in range(first_stroke.size - 1):
        for j in range(first_stroke[k], first_stroke[k + 1]):
            if arcs_only:
                x[angle_col[j]] = phi2[j]
            else:
                x[angle_col[j]], x[angle_col[j] + 1] = phi1[j], phi2[j]
            if onset_col[j] >= 0:
                x[onset_col[j]] = onsets[j]
                x[target_col[j]], x[target_col[j] + 1] = targets[j + k, 0], targets[j + k, 1]
    return x


@compiled
def unpack(x, targets, onsets, phi1, phi2, first_stroke, angle_col, onset_col, target_col,
           arcs_only):  # type: ignore[no-untyped-def]  # fmt: skip
    """The plan of parameter vector ``x``: ``(targets, onsets, phi1, phi2)``; onsets keep
    their order within a trace (delays that would turn negative become 0)."""
    targets, onsets, phi1, phi2 = targets.copy(), onsets.copy(), phi1.copy(), phi2.copy()
    for k in range(first_stroke.size - 1):
        for j in range(first_stroke[k], first_stroke[k + 1]):
            if arcs_only:
                phi2[j] = x[angle_col[j]]
                phi1[j] = -phi2[j]
            else:
                phi1[j], phi2[j] = x[angle_col[j]], x[angle_col[j] + 1]
            if onset_col[j] >= 0:
                onsets[j] = max(x[onset_col[j]], onsets[j - 1])
                targets[j + k, 0], targets[j + k, 1] = x[target_col[j]], x[target_col[j] + 1]
    return targets, onsets, phi1, phi2


@compiled
def system(
    instant,
    begin,
    stop,
    pairs,
    residual,
    velocity,
    targets,
    phi1,
    phi2,
    first_stroke,
    angle_col,
    onset_col,
    target_col,
    arcs_only,
    angle_step,
    rest,
    forward,
    params,
    tail,
):  # type: ignore[no-untyped-def]
    """The normal equations at the current residuals: ``(A, B, g, indptr, col, u, g_t,
    speed2, forward rows, scale)`` for :func:`damped_step`.

    Where the pen rests (the ends, a stop) an instant is free to slide a long way at no cost in
    the linear model, and far from true in the real one: its scale ``|v|²`` has a floor of
    ``rest`` times the median.
    """
    rows = instant.size
    is_forward = instant < forward
    speed2 = np.ones(rows)
    v = np.zeros(rows, np.complex128)
    moving = np.empty(forward)
    for i in range(rows):
        if is_forward[i]:
            v[i] = velocity[i]
            speed2[i] = velocity[i].real ** 2 + velocity[i].imag ** 2
            moving[instant[i]] = speed2[i]
    floor = rest * max(_median(moving), 1e-300) if forward else 0.0
    for i in range(rows):
        if is_forward[i]:
            speed2[i] = max(speed2[i], floor)
    chords = np.empty((phi1.size, 2))
    for k in range(first_stroke.size - 1):
        for j in range(first_stroke[k], first_stroke[k + 1]):
            chords[j, 0] = targets[j + k + 1, 0] - targets[j + k, 0]
            chords[j, 1] = targets[j + k + 1, 1] - targets[j + k, 1]
    indptr, col, value = jacobian(
        begin, stop, pairs, chords, first_stroke, phi1, phi2, arcs_only, angle_step, angle_col,
        onset_col, target_col, rows, tail,
    )  # fmt: skip
    a, b, g, u = normal_equations(indptr, col, value, residual, v, speed2, is_forward, params)
    g_t = np.empty(rows)
    for i in range(rows):
        g_t[i] = (v[i].conjugate() * residual[i]).real
    top = 1e-300
    for c in range(params):
        top = max(top, a[c, 0])
    scale = np.empty(params)
    for c in range(params):
        scale[c] = max(a[c, 0], 1e-12 * top)
    return a, b, g, indptr, col, u, g_t, speed2, is_forward, scale


@compiled
def _median(values: np.ndarray) -> float:
    ordered = values[np.argsort(values, kind="mergesort")]
    middle = ordered.size // 2
    return ordered[middle] if ordered.size % 2 else 0.5 * (ordered[middle - 1] + ordered[middle])


@compiled
def _valid(targets: np.ndarray, first_stroke: np.ndarray, limit: float) -> bool:
    """No two consecutive targets of a trace within ``limit`` of each other."""
    for k in range(first_stroke.size - 1):
        if collapsed(targets[first_stroke[k] + k : first_stroke[k + 1] + k + 1], limit):
            return False
    return True


@compiled
def refine_loop(
    targets,
    onsets,
    mu,
    sigma,
    phi1,
    phi2,
    first_stroke,
    angle_col,
    onset_col,
    target_col,
    arcs_only,
    lower,
    upper,
    tau,
    tau_end,
    goal,
    goal_first,
    goal_index,
    grid,
    grid_first,
    contour,
    header,
    start,
    order,
    reach,
    size,
    end_tolerance,
    angle_step,
    rest,
    iterations,
    tail,
):  # type: ignore[no-untyped-def]
    """Levenberg-Marquardt with Nielsen's damping update over the plan and the forward
    instants (see :mod:`tagbot.gesture.refine`). Returns the plan ``(targets, onsets, phi1,
    phi2)``, the instants, and per contour sample the largest residual that looked at it."""
    forward = tau.size
    params = lower.size
    x = pack(targets, onsets, phi1, phi2, first_stroke, angle_col, onset_col, target_col,
             arcs_only, params)  # fmt: skip
    current = residuals(
        targets, onsets, mu, sigma, phi1, phi2, first_stroke, tau, goal, goal_first, goal_index,
        grid, grid_first, contour, header, start, order, reach, size, end_tolerance,
    )  # fmt: skip
    cost = cost_of(current[4])
    damping, grow = 1e-3, 2.0
    normal = system(
        current[0], current[1], current[2], current[3], current[4], current[5], targets, phi1,
        phi2, first_stroke, angle_col, onset_col, target_col, arcs_only, angle_step, rest,
        forward, params, tail,
    )  # fmt: skip
    stale = False
    # ``iterations`` counts accepted steps (Jacobians); a rejected step only costs a residual
    # evaluation, and up to three per accepted one are allowed.
    accepted = 0
    for _ in range(4 * iterations):
        if accepted == iterations:
            break
        if stale:
            normal = system(
                current[0], current[1], current[2], current[3], current[4], current[5], targets,
                phi1, phi2, first_stroke, angle_col, onset_col, target_col, arcs_only,
                angle_step, rest, forward, params, tail,
            )  # fmt: skip
            stale = False
        a, b, g, indptr, col, u, g_t, speed2, is_forward, scale = normal
        step, step_t, predicted, ok = damped_step(
            a, b, scale, g, indptr, col, u, g_t, speed2, is_forward, damping
        )
        trial_cost = np.inf
        trial_x = np.empty(params)
        for c in range(params):
            trial_x[c] = min(max(x[c] + step[c], lower[c]), upper[c])
        trial_tau = tau.copy()
        instant = current[0]
        for i in range(instant.size):
            if is_forward[i]:
                f = instant[i]
                trial_tau[f] = min(max(tau[f] + step_t[i], 0.0), tau_end[f])
        trial_plan = unpack(trial_x, targets, onsets, phi1, phi2, first_stroke, angle_col,
                            onset_col, target_col, arcs_only)  # fmt: skip
        trial = current
        if ok and predicted > 0.0 and _valid(trial_plan[0], first_stroke, 1e-6 * size):
            trial = residuals(
                trial_plan[0], trial_plan[1], mu, sigma, trial_plan[2], trial_plan[3],
                first_stroke, trial_tau, goal, goal_first, goal_index, grid, grid_first,
                contour, header, start, order, reach, size, end_tolerance,
            )  # fmt: skip
            trial_cost = cost_of(trial[4])
        gain = (cost - trial_cost) / max(predicted, 1e-300)
        if gain > 0.0:  # Nielsen's damping update, from the gain ratio
            improvement = 1.0 - trial_cost / cost
            x, tau, current, cost = trial_x, trial_tau, trial, trial_cost
            targets, onsets, phi1, phi2 = trial_plan
            accepted += 1
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * min(gain, 1.0) - 1.0) ** 3)
            grow = 2.0
            stale = True
            if improvement < 1e-3:
                break
        else:
            damping *= grow
            grow *= 2.0
            if damping > 1e6:
                break
    misfit = np.zeros(contour.shape[0])
    instant, near, residual = current[0], current[6], current[4]
    for i in range(instant.size):
        sample = goal_index[instant[i]] if instant[i] < forward else near[i]
        misfit[sample] = max(misfit[sample], abs(residual[i]))
    return targets, onsets, phi1, phi2, tau, misfit
