"""Euler spirals (clothoids): closed-form evaluation and the G1 Hermite fit (the paper's fitEuler).

A clothoid segment starts at ``(x0, y0)`` with tangent angle ``theta0``; its curvature grows
linearly with arc length ``s``: ``kappa(s) = kappa0 + dkappa·s`` for ``0 <= s <= length``, so its
tangent angle is ``theta(s) = theta0 + kappa0·s + dkappa·s²/2``. ``dkappa = 0`` is a circular arc,
and ``kappa0 = dkappa = 0`` a straight line.

Positions are closed form. With the generalised Fresnel integrals ::

    I_k(a, b) = ∫₀¹ τ^k exp(i (a τ²/2 + b τ)) dτ

the point at arc length ``s`` is ``(x0, y0) + s·exp(i theta0)·I_0(dkappa s², kappa0 s)``. For
``|a|`` above :data:`SMALL_A`, ``I_0`` is a difference of two standard Fresnel integrals (scipy);
below it (near-arcs, where that difference would cancel catastrophically) a power series in ``a``
over the moments ``M_n(b) = ∫₀¹ τ^n e^{ibτ} dτ`` is used, each moment computed by whichever
recurrence is stable for it.

**Fit method: Bertolazzi & Frego (2015), "G1 fitting with clothoids".** The problem reduces to one
equation in one unknown ``A = dkappa·L²/2`` whose root is bracketed and unique in the range the
method uses, solved by Newton's method from a polynomial initial guess (the guess's coefficients
are the ones published in the paper). It handles every tangent pair in (−π, π], S-shapes and
near-±π cases included, without the case splits and slow iterations of Walton & Meek, and it is the
method of the C++ Clothoids library that the tests use as an independent oracle (pyclothoids), so
both choose the same spiral.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import fresnel

SMALL_A = 1e-2
"""Below this ``|dkappa|·length²`` a segment is evaluated with the near-arc series."""
_SMALL_A_MOMENTS = 4.0
"""Series threshold when I_1, I_2… are wanted: B&F's recurrence in k divides by ``a`` and
amplifies errors by ``|b|/|a|`` per step, harmless only once ``|a|`` is a few units."""

_NEWTON_TOL = 1e-14
_NEWTON_MAX_ITER = 20
# Initial-guess polynomial of Bertolazzi & Frego (2015), eq. for A(phi0, phi1).
_GUESS = (
    2.989696028701907,
    0.716228953608281,
    -0.458969738821509,
    -0.502821153340377,
    0.261062141752652,
    -0.045854475238709,
)

Array = NDArray[np.float64]


def wrap_angle(angle: ArrayLike) -> Array:
    """Wrap angles into (−π, π]."""
    wrapped = np.pi - np.mod(np.pi - np.asarray(angle, dtype=float), 2.0 * np.pi)
    return wrapped


# --- moments and generalised Fresnel integrals ----------------------------------------------


def _sinc_half(b: Array) -> NDArray[np.complex128]:
    """M_0(b) = (e^{ib} − 1)/(ib), written so that it is exact at and near b = 0."""
    return np.exp(0.5j * b) * np.sinc(b / (2.0 * np.pi))


def moments(n_max: int, b: ArrayLike) -> NDArray[np.complex128]:
    """``M_n(b) = ∫₀¹ τ^n e^{ibτ} dτ`` for ``n = 0..n_max``; shape ``(n_max + 1, *b.shape)``.

    Upward recurrence ``M_n = (e^{ib} − n M_{n−1}) / (ib)`` is stable for ``n < |b|``; downward
    ``M_{n−1} = (e^{ib} − ib M_n) / n`` is stable for ``n > |b|``, started from a short series of
    ``M_N`` about τ = 1. Each moment is taken from its stable direction.
    """
    b = np.asarray(b, dtype=float)
    e = np.exp(1j * b)
    ib = 1j * b
    up = np.empty((n_max + 1, *b.shape), dtype=complex)
    up[0] = _sinc_half(b)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # unused where |b| small
        for n in range(1, n_max + 1):
            up[n] = (e - n * up[n - 1]) / ib
    b_max = float(np.max(np.abs(b), initial=0.0))
    top = n_max + 24 + int(np.ceil(b_max))
    # M_top = e^{ib} Σ_j (−ib)^j top! / (top + j + 1)!  (terms shrink like |b|/top).
    term = e / (top + 1)
    series = term.copy()
    for j in range(1, 40):
        term = term * (-ib) / (top + j + 1)
        series += term
    down = np.empty_like(up)
    m = series
    for n in range(top, 0, -1):
        m = (e - ib * m) / n
        if n - 1 <= n_max:
            down[n - 1] = m
    order = np.arange(n_max + 1).reshape((-1,) + (1,) * b.ndim)
    result = np.where(order < np.abs(b), up, down)
    result[0] = up[0]
    return result


def generalized_fresnel(
    k_max: int, a: ArrayLike, b: ArrayLike, accurate: bool = True
) -> NDArray[np.complex128]:
    """``I_k(a, b) = ∫₀¹ τ^k exp(i(aτ²/2 + bτ)) dτ``, ``k = 0..k_max``; shape ``(k_max+1, …)``.

    ``I_0`` is accurate to ~1e-14 everywhere. ``accurate=False`` computes ``I_k`` for ``k ≥ 1``
    by the fast recurrence down to ``|a| = SMALL_A``, where it may lose up to ~8 digits for large
    ``|b|``: good enough for a derivative in Newton's method, and much cheaper.
    """
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    out = np.empty((k_max + 1, *a.shape), dtype=complex)
    small = np.abs(a) < (SMALL_A if k_max == 0 or not accurate else _SMALL_A_MOMENTS)
    if np.any(small):
        out[:, small] = _generalized_fresnel_series(k_max, a[small], b[small])
    large = ~small
    if np.any(large):
        out[:, large] = _generalized_fresnel_large(k_max, a[large], b[large])
    return out


def _generalized_fresnel_large(k_max: int, a: Array, b: Array) -> NDArray[np.complex128]:
    """I_k for |a| >= SMALL_A: I_0 from standard Fresnel integrals, then B&F's recurrence."""
    sign = np.sign(a)
    a_abs, b_s = np.abs(a), b * sign  # I(a, b) = conj(I(−a, −b)): solve with a > 0
    scale = np.sqrt(np.pi / a_abs)
    u0 = b_s / (scale * a_abs)
    u1 = (a_abs + b_s) / (scale * a_abs)
    s0, c0 = fresnel(u0)
    s1, c1 = fresnel(u1)
    i0 = scale * np.exp(-0.5j * b_s * b_s / a_abs) * ((c1 - c0) + 1j * (s1 - s0))
    i0 = np.where(sign < 0, np.conj(i0), i0)
    out = np.empty((k_max + 1, *a.shape), dtype=complex)
    out[0] = i0
    e1 = np.exp(1j * (0.5 * a + b))
    for k in range(k_max):
        # a I_{k+1} + b I_k = −i (e^{iψ(1)} − [k = 0]) + i k I_{k−1}
        rhs = -1j * (e1 - (1.0 if k == 0 else 0.0)) - b * out[k]
        if k > 0:
            rhs = rhs + 1j * k * out[k - 1]
        out[k + 1] = rhs / a
    return out


def _generalized_fresnel_series(k_max: int, a: Array, b: Array) -> NDArray[np.complex128]:
    """I_k for small |a|: Σ_n (ia/2)^n / n! · M_{k+2n}(b), truncated below double precision."""
    half = 0.5 * np.abs(a)
    h = float(np.max(half, initial=0.0))
    n_terms = 0
    bound = 1.0
    while h > 0.0 and bound > 1e-18:  # next term ≤ h^{n+1}/(n+1)! (|M| ≤ 1)
        n_terms += 1
        bound *= h / n_terms
    m = moments(k_max + 2 * n_terms, b)
    out = np.empty((k_max + 1, *a.shape), dtype=complex)
    for k in range(k_max + 1):
        total = m[k].copy()
        coeff = np.ones_like(a, dtype=complex)
        for n in range(1, n_terms + 1):
            coeff = coeff * (0.5j * a) / n
            total += coeff * m[k + 2 * n]
        out[k] = total
    return out


# --- clothoid segments -----------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Clothoids:
    """A batch of clothoid segments (arrays of equal shape), see the module docstring."""

    x0: Array
    y0: Array
    theta0: Array
    kappa0: Array
    dkappa: Array
    length: Array

    def __len__(self) -> int:
        return int(np.size(self.length))

    def __getitem__(self, index: object) -> Clothoids:
        return Clothoids(
            *(np.asarray(getattr(self, f))[index] for f in Clothoids.__dataclass_fields__)
        )

    def theta(self, s: ArrayLike) -> Array:
        """Tangent angle at arc length ``s`` (broadcast against the batch)."""
        s = np.asarray(s, dtype=float)
        return self.theta0 + s * (self.kappa0 + 0.5 * self.dkappa * s)

    def point(self, s: ArrayLike) -> Array:
        """Points at arc length ``s`` (broadcast against the batch); shape ``(..., 2)``."""
        s = np.asarray(s, dtype=float)
        shape = np.broadcast_shapes(s.shape, np.shape(self.length))
        index = np.broadcast_to(np.arange(len(self)).reshape(np.shape(self.length)), shape).ravel()
        flat_s = np.broadcast_to(s, shape).ravel()
        order = np.argsort(self._flat.kind[index], kind="stable")
        dx, dy = np.empty(flat_s.shape), np.empty(flat_s.shape)
        ones = np.ones(len(order), np.intp)
        dx[order], dy[order], _, _ = self.evaluate_runs(index[order], ones, flat_s[order])
        x0 = np.broadcast_to(self.x0, shape)
        y0 = np.broadcast_to(self.y0, shape)
        return np.stack([x0 + dx.reshape(shape), y0 + dy.reshape(shape)], axis=-1)

    @property
    def end(self) -> Array:
        """End points, shape ``(..., 2)``."""
        return self.point(self.length)

    @property
    def kind(self) -> NDArray[np.int8]:
        """Per segment (flattened): 0 arc or line, 1 near-arc (series), 2 spiral (Fresnel)."""
        return self._flat.kind

    def evaluate_runs(
        self, segments: NDArray[np.intp], counts: NDArray[np.intp], s: Array
    ) -> tuple[Array, Array, Array, Array]:
        """Displacement ``(dx, dy)`` from the start and unit tangent ``(tx, ty)`` at lengths ``s``.

        ``s`` holds ``counts[i]`` consecutive values for segment ``segments[i]``, and the segments
        are ordered by :attr:`kind`, so that each branch works on one contiguous slice with
        per-segment constants expanded by ``np.repeat``. This is the hot path of sampling: real
        arithmetic, one sine/cosine pair per point, plus one standard Fresnel evaluation on spirals.
        """
        flat = self._flat
        kinds = flat.kind[segments]
        if np.any(np.diff(kinds) < 0):
            raise ValueError("segments: must be ordered by kind")
        dx, dy, tx, ty = (np.empty(s.shape) for _ in range(4))
        bounds = np.concatenate([[0], np.cumsum(counts)])
        for branch in (0, 1, 2):
            group = np.flatnonzero(kinds == branch)
            if not group.size:
                continue
            rows = slice(int(bounds[group[0]]), int(bounds[group[-1] + 1]))
            seg, cnt, sj = segments[group], counts[group], s[rows]

            def per_point(values: np.ndarray, seg=seg, cnt=cnt) -> np.ndarray:
                return np.repeat(values[seg], cnt)

            cos0, sin0 = per_point(flat.cos0), per_point(flat.sin0)
            if branch == 0:
                # Arc or line: the chord to s turns by half the tangent's turn κ0·s, and has
                # length s·sin(x)/x with x = κ0·s/2 (exact at x = 0 and for tiny x).
                x = 0.5 * per_point(flat.kappa0) * sj
                cx, sx = np.cos(x), np.sin(x)
                chord = sj * np.divide(sx, x, out=np.ones_like(x), where=x != 0.0)
                hx, hy = cos0 * cx - sin0 * sx, sin0 * cx + cos0 * sx  # direction θ0 + x
                dx[rows], dy[rows] = chord * hx, chord * hy
                tx[rows], ty[rows] = hx * cx - hy * sx, hy * cx + hx * sx  # direction θ0 + 2x
                continue
            k0, dk = per_point(flat.kappa0), per_point(flat.dkappa)
            turn = sj * (k0 + 0.5 * dk * sj)
            ct, st = np.cos(turn), np.sin(turn)
            tx[rows], ty[rows] = cos0 * ct - sin0 * st, sin0 * ct + cos0 * st
            if branch == 1:  # near-arc: series in dkappa·s²
                off = sj * (cos0 + 1j * sin0) * generalized_fresnel(0, dk * sj * sj, k0 * sj)[0]
                dx[rows], dy[rows] = off.real, off.imag
            else:  # spiral: ρ e^{iθc} [F(u) − F(u0)], u = (s − s_c)/ρ, F = C + iγS
                fs, fc = fresnel((sj - per_point(flat.s_centre)) * per_point(flat.inv_scale))
                fc -= per_point(flat.c0)
                fs -= per_point(flat.s0)
                fs *= per_point(flat.gamma)
                rc, rs = per_point(flat.rotation_cos), per_point(flat.rotation_sin)
                dx[rows], dy[rows] = rc * fc - rs * fs, rs * fc + rc * fs
        return dx, dy, tx, ty

    @cached_property
    def _flat(self) -> _FlatClothoids:
        return _FlatClothoids.of(self)


@dataclass(frozen=True, eq=False)
class _FlatClothoids:
    """Per-segment constants for :meth:`Clothoids.evaluate_runs` (flattened batch)."""

    kind: NDArray[np.int8]  # 0 arc/line, 1 near-arc (series), 2 spiral (Fresnel)
    cos0: Array  # cos θ0
    sin0: Array  # sin θ0
    kappa0: Array
    dkappa: Array
    s_centre: Array  # arc length of the zero-curvature point
    inv_scale: Array  # 1/ρ, ρ = sqrt(π/|dkappa|)
    gamma: Array  # sign of dkappa
    rotation_cos: Array  # ρ·cos θc, θc the tangent angle at zero curvature
    rotation_sin: Array  # ρ·sin θc
    c0: Array  # C(u0)
    s0: Array  # S(u0)

    @classmethod
    def of(cls, c: Clothoids) -> _FlatClothoids:
        theta0, kappa0, dkappa, length = (
            np.asarray(v, dtype=float).ravel() for v in (c.theta0, c.kappa0, c.dkappa, c.length)
        )
        a = np.abs(dkappa) * length * length
        kind = np.where(dkappa == 0.0, 0, np.where(a < SMALL_A, 1, 2)).astype(np.int8)
        spiral = kind == 2
        dk = np.where(spiral, dkappa, 1.0)
        scale = np.sqrt(np.pi / np.abs(dk))
        s_centre = -kappa0 / dk
        theta_c = theta0 - 0.5 * kappa0 * kappa0 / dk
        fs0, fc0 = fresnel(-s_centre / scale)
        return cls(
            kind=kind,
            cos0=np.cos(theta0),
            sin0=np.sin(theta0),
            kappa0=kappa0,
            dkappa=dkappa,
            s_centre=s_centre,
            inv_scale=1.0 / scale,
            gamma=np.sign(dk),
            rotation_cos=scale * np.cos(theta_c),
            rotation_sin=scale * np.sin(theta_c),
            c0=fc0,
            s0=fs0,
        )


def fit_euler(p0: ArrayLike, theta0: ArrayLike, p1: ArrayLike, theta1: ArrayLike) -> Clothoids:
    """The G1 Hermite clothoid from ``p0`` leaving at ``theta0`` to ``p1`` arriving at ``theta1``.

    Vectorised: points have shape ``(..., 2)`` and angles ``(...)``. Angles are absolute (radians,
    counter-clockwise); only their directions matter. Coincident or non-finite points raise
    :class:`ValueError`.
    """
    p0, p1 = np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)
    if p0.shape[-1:] != (2,) or p1.shape[-1:] != (2,):
        raise ValueError("points: expected shape (..., 2)")
    dx, dy = p1[..., 0] - p0[..., 0], p1[..., 1] - p0[..., 1]
    chord = np.hypot(dx, dy)
    theta0, theta1 = np.asarray(theta0, dtype=float), np.asarray(theta1, dtype=float)
    if not (np.all(np.isfinite(chord)) and np.all(np.isfinite(theta0 + theta1))):
        raise ValueError("points and angles: must be finite")
    if np.any(chord == 0.0):
        raise ValueError("points: the two end points coincide (chord length 0)")
    alpha = np.arctan2(dy, dx)
    phi0 = wrap_angle(theta0 - alpha)
    phi1 = wrap_angle(theta1 - alpha)
    a = solve_g1(phi0, phi1)
    delta = phi1 - phi0
    h = (np.exp(1j * phi0) * generalized_fresnel(0, 2.0 * a, delta - a)[0]).real
    length = chord / h
    return Clothoids(
        x0=np.broadcast_to(p0[..., 0], length.shape).copy(),
        y0=np.broadcast_to(p0[..., 1], length.shape).copy(),
        theta0=np.broadcast_to(alpha + phi0, length.shape).copy(),
        kappa0=(delta - a) / length,
        dkappa=2.0 * a / (length * length),
        length=length,
    )


def solve_g1(phi0: ArrayLike, phi1: ArrayLike) -> Array:
    """Solve B&F's ``Y_0(2A, φ1 − φ0 − A, φ0) = 0`` for ``A`` (chord-relative angles in (−π, π])."""
    phi0, phi1 = np.broadcast_arrays(np.asarray(phi0, dtype=float), np.asarray(phi1, dtype=float))
    shape = phi0.shape
    phi0, phi1 = phi0.ravel(), phi1.ravel()
    x, y = phi0 / np.pi, phi1 / np.pi
    xy, x2, y2 = x * y, x * x, y * y
    c = _GUESS
    a = (phi0 + phi1) * (
        c[0] + xy * (c[1] + xy * c[2]) + (c[3] + xy * c[4]) * (x2 + y2) + c[5] * (x2 * x2 + y2 * y2)
    )
    delta = phi1 - phi0
    rot = np.exp(1j * phi0)
    active = np.arange(a.size)
    for _ in range(_NEWTON_MAX_ITER):
        if not active.size:
            break
        ai = a[active]
        moments_ = rot[active] * generalized_fresnel(
            2, 2.0 * ai, delta[active] - ai, accurate=False
        )
        g = moments_[0].imag
        dg = moments_[2].real - moments_[1].real
        a[active] = ai - g / dg
        active = active[np.abs(g) > _NEWTON_TOL]
    return a.reshape(shape)
