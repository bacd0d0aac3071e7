"""Compiled loops of the timing fit (numba; see :mod:`tagbot.gesture.timing`): the recording's
local-linear resampling, and one trace's trajectory with the exact Jacobian of its timing
residuals. Array conventions as in :mod:`tagbot.gesture.kernels`.
"""

from __future__ import annotations

import math

import numpy as np

from tagbot.gesture.refine_kernels import _band_cholesky, _band_solve
from tagbot.model.kernels import (
    N_CONSTANTS,
    TINY,
    compiled,
    lognormal_at,
    ndtri,
    segment_constants,
    segment_point,
    stroke_window,
    unit_stroke,
)
from tagbot.model.plan import END_TOLERANCE, MAX_COORDINATE

Z90 = 1.2815515655446004
"""The standard normal's 90 % quantile: a stroke's 10-90 % interval lasts
``2·exp(mu)·sinh(Z90·sigma)``."""


@compiled
def local_quadratic(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, grid: np.ndarray, width: float
) -> np.ndarray:
    """Per grid time: position and velocity of a Gaussian-weighted local-quadratic fit of the
    samples (kernel ``width``; its bias on curves and speed peaks is of order ``width⁴``, not
    the ``width²`` of a local-linear fit), a local-linear one where too few samples spread
    around it, or a linear interpolation where the kernel is empty on one side (a gap); and a
    weight: 1, or 0.25 across gaps and outside the samples."""
    n, count = t.size, grid.size
    out = np.empty((count, 5))
    lo = 0
    reach = 3.0 * width
    for g in range(count):
        c = grid[g]
        if c <= t[0] or c >= t[n - 1]:
            k = 0 if c <= t[0] else n - 1
            out[g, 0], out[g, 1], out[g, 2], out[g, 3], out[g, 4] = x[k], y[k], 0.0, 0.0, 0.25
            continue
        while lo < n and t[lo] < c - reach:
            lo += 1
        s0 = s1 = s2 = s3 = s4 = 0.0
        x0 = x1 = x2 = y0 = y1 = y2 = 0.0
        left = right = False
        i = lo
        while i < n and t[i] <= c + reach:
            u = (t[i] - c) / width  # scaled: the moments stay well conditioned
            w = math.exp(-0.5 * u * u)
            wu, wu2 = w * u, w * u * u
            s0 += w
            s1 += wu
            s2 += wu2
            s3 += wu2 * u
            s4 += wu2 * u * u
            x0 += w * x[i]
            x1 += wu * x[i]
            x2 += wu2 * x[i]
            y0 += w * y[i]
            y1 += wu * y[i]
            y2 += wu2 * y[i]
            if -2.0 <= u <= 0.0:
                left = True
            if 0.0 <= u <= 2.0:
                right = True
            i += 1
        if left and right and s0 > 0.0:
            # The symmetric system [[s0, s1, s2], [s1, s2, s3], [s2, s3, s4]] by cofactors.
            c00 = s2 * s4 - s3 * s3
            c01 = s2 * s3 - s1 * s4
            c02 = s1 * s3 - s2 * s2
            c11 = s0 * s4 - s2 * s2
            c12 = s1 * s2 - s0 * s3
            det = s0 * c00 + s1 * c01 + s2 * c02
            if det > 1e-4 * s0 * s0 * s0:
                out[g, 0] = (c00 * x0 + c01 * x1 + c02 * x2) / det
                out[g, 1] = (c00 * y0 + c01 * y1 + c02 * y2) / det
                out[g, 2] = (c01 * x0 + c11 * x1 + c12 * x2) / (det * width)
                out[g, 3] = (c01 * y0 + c11 * y1 + c12 * y2) / (det * width)
                out[g, 4] = 1.0
                continue
            det = s0 * s2 - s1 * s1
            if det > 1e-3 * s0 * s0:
                out[g, 0] = (s2 * x0 - s1 * x1) / det
                out[g, 1] = (s2 * y0 - s1 * y1) / det
                out[g, 2] = (s0 * x1 - s1 * x0) / (det * width)
                out[g, 3] = (s0 * y1 - s1 * y0) / (det * width)
                out[g, 4] = 1.0
                continue
        k = np.searchsorted(t, c, side="right") - 1  # t[k] <= c < t[k + 1]
        while k + 1 < n - 1 and t[k + 1] <= t[k]:
            k += 1
        span = t[k + 1] - t[k]
        f = (c - t[k]) / span if span > 0.0 else 0.0
        out[g, 0] = x[k] + f * (x[k + 1] - x[k])
        out[g, 1] = y[k] + f * (y[k + 1] - y[k])
        out[g, 2] = (x[k + 1] - x[k]) / span if span > 0.0 else 0.0
        out[g, 3] = (y[k + 1] - y[k]) / span if span > 0.0 else 0.0
        out[g, 4] = 0.25
    return out


@compiled
def _shape_row(phi1: float, phi2: float, out: np.ndarray) -> tuple[float, float, float]:
    """A stroke's unit-chord shape constants into ``out``; returns ``(kappa0, dkappa, L)``."""
    theta0, kappa0, dkappa, length = unit_stroke(phi1, phi2)
    segment_constants(theta0, kappa0, dkappa, length, out)
    return kappa0, dkappa, length


@compiled
def model_terms(
    t: np.ndarray,
    targets: np.ndarray,
    onsets: np.ndarray,
    mu: np.ndarray,
    sigma: np.ndarray,
    phi1: np.ndarray,
    phi2: np.ndarray,
    arcs: bool,
    size: float,
    wv: np.ndarray,
    wp: np.ndarray,
    want_jacobian: bool,
    h: float,
    column: np.ndarray,
    target_column: np.ndarray,
    tail: float,
    unit: np.ndarray,
    extra: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """One trace's positions and velocities at the sorted times ``t``, and (if wanted) the
    Jacobian of the weighted residuals ``wv·v`` (rows ``2g, 2g + 1``) and ``wp·xy`` (rows
    ``2G + 2g, 2G + 2g + 1``) as COO ``(row, col, value)``: its first ``q`` entries (returned
    last), with room for ``extra`` more. Each stroke's unit-chord path length goes to ``unit``.

    Columns: stroke ``j``'s ``t0, mu, sigma`` and its angles (``phi`` for arcs, else ``phi1,
    phi2``) from ``column[j]`` on; interior target ``k + 1``'s ``x, y`` at
    ``target_column[k]`` and the next. With ``x = p_0 + Σ c_j G_j(W_j)`` (complex,
    ``c_j`` the chord, ``G_j`` the unit shape) and ``u_j = G_j'(W_j) Λ_j``, exactly:
    ``∂x/∂t0 = −c u``, ``∂x/∂mu = −c u e``, ``∂x/∂sigma = −c u e z`` (``e = t − t0``,
    ``z = (ln e − mu)/sigma``) and ``∂v/∂θ = c u (∂lnΛ/∂θ + iκL ∂W/∂θ)``; targets enter
    linearly (``G_{j−1} − G_j``); the angles by central differences (step ``h``) of the G1 fit.
    In the Jacobian (not the trajectory) a stroke whose CDF is within ``tail`` of 0 or 1 counts
    as not started or complete: its tails' tiny entries would multiply the work.
    """
    n, count = onsets.size, t.size
    angles = 1 if arcs else 2
    consts = np.empty((n, N_CONSTANTS))
    kappa0, dkappa = np.empty(n), np.empty(n)
    begin, stop = np.empty(n, np.intp), np.empty(n, np.intp)
    cx, cy = np.empty(n), np.empty(n)
    for j in range(n):
        kappa0[j], dkappa[j], unit[j] = _shape_row(phi1[j], phi2[j], consts[j])
        cx[j] = targets[j + 1, 0] - targets[j, 0]
        cy[j] = targets[j + 1, 1] - targets[j, 1]
        length = unit[j] * math.hypot(cx[j], cy[j])
        budget = END_TOLERANCE * size / (n * max(length, TINY))
        t_on, t_off = stroke_window(onsets[j], mu[j], sigma[j], budget)
        begin[j] = np.searchsorted(t, t_on, side="left")
        stop[j] = np.searchsorted(t, t_off, side="right")
    xy, v = np.empty((count, 2)), np.zeros((count, 2))
    done = np.zeros((count + 1, 2))
    for j in range(n):
        done[stop[j], 0] += cx[j]
        done[stop[j], 1] += cy[j]
    x, y = targets[0, 0], targets[0, 1]
    for i in range(count):
        x += done[i, 0]
        y += done[i, 1]
        xy[i, 0], xy[i, 1] = x, y
    first = np.zeros(n + 1, np.intp)  # stroke j's pairs: first[j]..first[j + 1]
    for j in range(n):
        first[j + 1] = first[j] + stop[j] - begin[j]
    pairs = np.empty((first[n], 4))  # gx, gy, ux, uy
    for j in range(n):
        length = unit[j]
        for i in range(begin[j], stop[j]):
            w, density = lognormal_at(t[i], onsets[j], mu[j], sigma[j])
            gx, gy, tx, ty = segment_point(consts[j], length * w)
            ux, uy = tx * length * density, ty * length * density
            xy[i, 0] += cx[j] * gx - cy[j] * gy
            xy[i, 1] += cx[j] * gy + cy[j] * gx
            v[i, 0] += cx[j] * ux - cy[j] * uy
            v[i, 1] += cx[j] * uy + cy[j] * ux
            p = first[j] + i - begin[j]
            pairs[p, 0], pairs[p, 1], pairs[p, 2], pairs[p, 3] = gx, gy, ux, uy
    if not want_jacobian:
        empty = np.empty(0, np.intp)
        return xy, v, empty, empty.copy(), np.empty(0), 0
    jb, js = np.empty(n, np.intp), np.empty(n, np.intp)  # the Jacobian's rows per stroke
    for j in range(n):
        t_on, t_off = stroke_window(onsets[j], mu[j], sigma[j], tail)
        jb[j] = min(max(np.searchsorted(t, t_on, side="left"), begin[j]), stop[j])
        js[j] = max(min(np.searchsorted(t, t_off, side="right"), stop[j]), jb[j])
    m = targets.shape[0]
    span = np.empty(max(m - 2, 0), np.intp)
    lo_t, hi_t = np.empty(max(m - 2, 0), np.intp), np.empty(max(m - 2, 0), np.intp)
    for k in range(m - 2):
        lo_t[k] = min(jb[k], jb[k + 1])
        hi_t[k] = max(js[k], js[k + 1])
        span[k] = max(hi_t[k] - lo_t[k], 0)
    total = 4 * (3 + angles) * int(np.sum(js - jb)) + 8 * int(np.sum(span)) + extra
    rows, cols, vals = np.empty(total, np.intp), np.empty(total, np.intp), np.empty(total)
    q = 0
    shape_p = np.empty(N_CONSTANTS)
    shape_m = np.empty(N_CONSTANTS)
    for j in range(n):
        base = column[j]
        for a in range(angles):
            d1, d2 = (-h, h) if arcs else ((h, 0.0) if a == 0 else (0.0, h))
            _, _, unit_p = _shape_row(phi1[j] + d1, phi2[j] + d2, shape_p)
            _, _, unit_m = _shape_row(phi1[j] - d1, phi2[j] - d2, shape_m)
            for i in range(jb[j], js[j]):
                w, density = lognormal_at(t[i], onsets[j], mu[j], sigma[j])
                gxp, gyp, txp, typ = segment_point(shape_p, unit_p * w)
                gxm, gym, txm, tym = segment_point(shape_m, unit_m * w)
                dgx, dgy = (gxp - gxm) / (2 * h), (gyp - gym) / (2 * h)
                dux = (txp * unit_p - txm * unit_m) * density / (2 * h)
                duy = (typ * unit_p - tym * unit_m) * density / (2 * h)
                q = _put4(rows, cols, vals, q, i, count, base + 3 + a, cx[j], cy[j],
                          dux, duy, dgx, dgy, wv[i], wp[i])  # fmt: skip
        for i in range(jb[j], js[j]):
            p = first[j] + i - begin[j]
            ux, uy = pairs[p, 2], pairs[p, 3]
            e = max(t[i] - onsets[j], TINY)
            z = (math.log(e) - mu[j]) / sigma[j]
            _, density = lognormal_at(t[i], onsets[j], mu[j], sigma[j])
            w = 0.5 * math.erfc(-z / math.sqrt(2.0))
            kl = (kappa0[j] + dkappa[j] * unit[j] * w) * unit[j]  # κ(s)·L at s = L·w
            for c in range(3):
                if c == 0:
                    dw, dlog = -density, (1.0 + z / sigma[j]) / e
                elif c == 1:
                    dw, dlog = -density * e, z / sigma[j]
                else:
                    dw, dlog = -density * e * z, (z * z - 1.0) / sigma[j]
                # dx = u·dW/Λ ... as G'(W)·∂W = u·∂W/Λ; dv = u·(dlog + iκL·∂W)
                ratio = dw / density if density > 0.0 else 0.0
                dgx, dgy = ux * ratio, uy * ratio
                fr, fi = dlog, kl * dw
                dux, duy = ux * fr - uy * fi, ux * fi + uy * fr
                q = _put4(rows, cols, vals, q, i, count, base + c, cx[j], cy[j],
                          dux, duy, dgx, dgy, wv[i], wp[i])  # fmt: skip
    for k in range(m - 2):  # target k + 1, between strokes a = k and b = k + 1
        a, b = k, k + 1
        for i in range(lo_t[k], hi_t[k]):
            ga_x = ga_y = ua_x = ua_y = 0.0
            if i >= stop[a]:
                ga_x = 1.0
            elif i >= begin[a]:
                p = first[a] + i - begin[a]
                ga_x, ga_y, ua_x, ua_y = pairs[p, 0], pairs[p, 1], pairs[p, 2], pairs[p, 3]
            gb_x = gb_y = ub_x = ub_y = 0.0
            if i >= stop[b]:
                gb_x = 1.0
            elif i >= begin[b]:
                p = first[b] + i - begin[b]
                gb_x, gb_y, ub_x, ub_y = pairs[p, 0], pairs[p, 1], pairs[p, 2], pairs[p, 3]
            gx, gy, ux, uy = ga_x - gb_x, ga_y - gb_y, ua_x - ub_x, ua_y - ub_y
            q = _put4(rows, cols, vals, q, i, count, target_column[k], 1.0, 0.0,
                      ux, uy, gx, gy, wv[i], wp[i])  # fmt: skip
            q = _put4(rows, cols, vals, q, i, count, target_column[k] + 1, 0.0, 1.0,
                      ux, uy, gx, gy, wv[i], wp[i])  # fmt: skip
    return xy, v, rows, cols, vals, q


@compiled
def residuals(
    x: np.ndarray,
    column: np.ndarray,
    target_column: np.ndarray,
    targets0: np.ndarray,
    arcs: bool,
    t: np.ndarray,
    size: float,
    wv: np.ndarray,
    wp: np.ndarray,
    rec_v: np.ndarray,
    rec_xy: np.ndarray,
    anchor: np.ndarray,
    weights: np.ndarray,
    deadline: float,
    log_extent: float,
    want_jacobian: bool,
    h: float,
    tail: float,
) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """The timing fit's residuals at parameters ``x`` (laid out by ``column`` and
    ``target_column``, see :class:`tagbot.gesture.timing._Fit`) and, if wanted, their Jacobian
    as COO and how many fours lead it (:func:`normal_band`); False (and nothing) where ``x``
    (finite) is not a valid plan.

    Rows: the weighted velocities and positions less the recording's (``rec_v``, ``rec_xy``:
    :func:`model_terms`' layout), each interior target's pull to ``anchor``, each stroke's
    lateness past ``deadline`` (where its window, as :meth:`~tagbot.model.plan.Plan.windows`
    has it, ends) and its velocity pulse's shortfall below ``exp(log_extent)`` (its 10-90 %
    interval, in e-folds). ``weights``: pull, lateness per second, shortfall.
    """
    n, m, g = column.size, targets0.shape[0], t.size
    angles = 1 if arcs else 2
    targets = targets0.copy()
    onsets, mu, sigma = np.empty(n), np.empty(n), np.empty(n)
    phi1, phi2 = np.empty(n), np.empty(n)
    for j in range(n):
        c = column[j]
        onsets[j], mu[j], sigma[j] = x[c], x[c + 1], x[c + 2]
        phi2[j] = x[c + 2 + angles]
        phi1[j] = -phi2[j] if arcs else x[c + 3]
    for k in range(m - 2):
        targets[k + 1, 0], targets[k + 1, 1] = x[target_column[k]], x[target_column[k] + 1]
    empty = np.empty(0, np.intp)
    for k in range(m):
        if abs(targets[k, 0]) > MAX_COORDINATE or abs(targets[k, 1]) > MAX_COORDINATE:
            return False, np.empty(0), empty, empty.copy(), np.empty(0), 0
        if k > 0:
            dx, dy = targets[k, 0] - targets[k - 1, 0], targets[k, 1] - targets[k - 1, 1]
            if math.hypot(dx, dy) <= 1e-9 * size:
                return False, np.empty(0), empty, empty.copy(), np.empty(0), 0
    unit = np.empty(n)
    xy, v, rows, cols, vals, q = model_terms(
        t, targets, onsets, mu, sigma, phi1, phi2, arcs, size, wv, wp, want_jacobian, h,
        column, target_column, tail, unit, 2 * (m - 2) + 5 * n,
    )  # fmt: skip
    pull, late, short = weights[0], weights[1], weights[2]
    groups = q // 4  # model_terms' entries, in fours (see normal_band)
    interior = 2 * (m - 2)
    r = np.empty(4 * g + interior + 2 * n)
    for i in range(g):
        r[2 * i] = v[i, 0] * wv[i] - rec_v[2 * i]
        r[2 * i + 1] = v[i, 1] * wv[i] - rec_v[2 * i + 1]
        r[2 * g + 2 * i] = xy[i, 0] * wp[i] - rec_xy[2 * i]
        r[2 * g + 2 * i + 1] = xy[i, 1] * wp[i] - rec_xy[2 * i + 1]
    for k in range(m - 2):
        r[4 * g + 2 * k] = (targets[k + 1, 0] - anchor[k + 1, 0]) * pull
        r[4 * g + 2 * k + 1] = (targets[k + 1, 1] - anchor[k + 1, 1]) * pull
        if want_jacobian:
            q = _put1(rows, cols, vals, q, 4 * g + 2 * k, target_column[k], pull)
            q = _put1(rows, cols, vals, q, 4 * g + 2 * k + 1, target_column[k] + 1, pull)
    for j in range(n):
        c, tail_row, short_row = column[j], 4 * g + interior + j, 4 * g + interior + n + j
        chord = math.hypot(targets[j + 1, 0] - targets[j, 0], targets[j + 1, 1] - targets[j, 1])
        budget = min(END_TOLERANCE * size / (n * max(unit[j] * chord, TINY)), 1e-2)
        z_tail = -ndtri(budget)
        delay = math.exp(mu[j] + sigma[j] * z_tail)
        lateness = onsets[j] + delay - deadline
        r[tail_row] = lateness * late if lateness > 0.0 else 0.0
        if lateness > 0.0 and want_jacobian:
            q = _put1(rows, cols, vals, q, tail_row, c, late)
            q = _put1(rows, cols, vals, q, tail_row, c + 1, delay * late)
            q = _put1(rows, cols, vals, q, tail_row, c + 2, delay * late * z_tail)
        spread = Z90 * sigma[j]
        shortfall = log_extent - mu[j] - math.log(2.0 * math.sinh(spread))
        r[short_row] = shortfall * short if shortfall > 0.0 else 0.0
        if shortfall > 0.0 and want_jacobian:
            q = _put1(rows, cols, vals, q, short_row, c + 1, -short)
            q = _put1(rows, cols, vals, q, short_row, c + 2, -short * Z90 / math.tanh(spread))
    for p in range(r.size):
        if not math.isfinite(r[p]):
            return False, np.empty(0), empty, empty.copy(), np.empty(0), 0
    return True, r, rows[:q], cols[:q], vals[:q], groups


@compiled
def _put1(rows, cols, vals, q, row, col, value):  # type: ignore[no-untyped-def]
    """One Jacobian entry at ``q``; returns the next free index."""
    rows[q], cols[q], vals[q] = row, col, value
    return q + 1


@compiled
def _put4(rows, cols, vals, q, i, count, col, cx, cy, dux, duy, dgx, dgy, wv, wp):  # type: ignore[no-untyped-def]
    """The four Jacobian entries of row time ``i`` and column ``col``: chord ``c`` times the
    unit-shape derivatives of velocity ``(dux, duy)`` and position ``(dgx, dgy)``, weighted."""
    rows[q], cols[q], vals[q] = 2 * i, col, wv * (cx * dux - cy * duy)
    rows[q + 1], cols[q + 1], vals[q + 1] = 2 * i + 1, col, wv * (cx * duy + cy * dux)
    rows[q + 2], cols[q + 2], vals[q + 2] = 2 * count + 2 * i, col, wp * (cx * dgx - cy * dgy)
    rows[q + 3], cols[q + 3] = 2 * count + 2 * i + 1, col
    vals[q + 3] = wp * (cx * dgy + cy * dgx)
    return q + 4


@compiled
def _counting_order(keys: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices of ``keys`` (integers in ``[0, n)``) grouped by key, stably, and each key's start
    in them (``start[k]..start[k + 1]``)."""
    start = np.zeros(n + 1, np.intp)
    for e in range(keys.size):
        start[keys[e] + 1] += 1
    for k in range(n):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    order = np.empty(keys.size, np.intp)
    for e in range(keys.size):
        order[fill[keys[e]]] = e
        fill[keys[e]] += 1
    return order, start


@compiled
def _add_product(a: np.ndarray, ce: int, cf: int, product: float) -> None:
    """``product`` into ``(JᵀJ)[ce, cf]`` (and its mirror) in lower band storage."""
    if cf <= ce:
        a[ce, ce - cf] += product
    else:
        a[cf, cf - ce] += product


@compiled
def _widest(
    order: np.ndarray, start: np.ndarray, cols: np.ndarray, stride: int, offset: int
) -> int:
    """The widest span of columns among the groups ``start[k]..start[k + 1]`` of ``order``
    (entry ``offset + stride·order[q]``)."""
    band = 0
    for k in range(start.size - 1):
        lo, hi = start[k], start[k + 1]
        if hi > lo:
            low = high = cols[offset + stride * order[lo]]
            for q in range(lo + 1, hi):
                c = cols[offset + stride * order[q]]
                low, high = min(low, c), max(high, c)
            band = max(band, high - low)
    return band


@compiled
def normal_band(
    rows: np.ndarray,
    cols: np.ndarray,
    vals: np.ndarray,
    groups: int,
    residual: np.ndarray,
    params: int,
) -> tuple[np.ndarray, np.ndarray]:
    """``JᵀJ`` in lower band storage (``a[c, d] = (JᵀJ)[c, c − d]``) and ``Jᵀr``, from the
    Jacobian's COO entries (each ``(row, col)`` once). The first ``4·groups`` entries come in
    fours sharing a column and a grid instant (:func:`_put4`'s rows ``2i, 2i + 1, 2G + 2i,
    2G + 2i + 1``, which hold the same columns): those are gathered by instant, so each pair of
    columns costs one product of four; the rest (the penalties' rows) by row."""
    nrows = residual.size
    instant = rows[: 4 * groups : 4] // 2
    by_instant, first = _counting_order(instant, nrows // 2 + 1)
    singles = rows[4 * groups :]
    by_row, start = _counting_order(singles, nrows)
    band = max(_widest(by_instant, first, cols, 4, 0), _widest(by_row, start, cols, 1, 4 * groups))
    a = np.zeros((params, band + 1))
    g = np.zeros(params)
    for k in range(first.size - 1):
        for q in range(first[k], first[k + 1]):
            e = 4 * by_instant[q]
            ce = cols[e]
            v0, v1, v2, v3 = vals[e], vals[e + 1], vals[e + 2], vals[e + 3]
            g[ce] += (
                v0 * residual[rows[e]]
                + v1 * residual[rows[e + 1]]
                + v2 * residual[rows[e + 2]]
                + v3 * residual[rows[e + 3]]
            )
            for p in range(first[k], q + 1):
                f = 4 * by_instant[p]
                product = v0 * vals[f] + v1 * vals[f + 1] + v2 * vals[f + 2] + v3 * vals[f + 3]
                _add_product(a, ce, cols[f], product)
    offset = 4 * groups
    for k in range(start.size - 1):
        res = residual[k]
        for q in range(start[k], start[k + 1]):
            e = offset + by_row[q]
            ce, ve = cols[e], vals[e]
            g[ce] += ve * res
            for p in range(start[k], q + 1):
                f = offset + by_row[p]
                _add_product(a, ce, cols[f], vals[f] * ve)
    return a, g


@compiled
def damped_step(
    a: np.ndarray, g: np.ndarray, scale: np.ndarray, damping: float
) -> tuple[np.ndarray, bool]:
    """The Levenberg-Marquardt step ``(JᵀJ + λ·diag(scale)) δ = −Jᵀr`` by banded Cholesky, and
    whether the system was positive definite."""
    factor = a.copy()
    for c in range(g.size):
        factor[c, 0] += damping * scale[c]
    if not _band_cholesky(factor, a.shape[1] - 1):
        return np.zeros(g.size), False
    return _band_solve(factor, a.shape[1] - 1, -g), True
