"""Euler spirals (clothoids): closed-form evaluation and the G1 Hermite fit (the paper's fitEuler).

A clothoid segment starts at ``(x0, y0)`` with tangent angle ``theta0``; its curvature grows
linearly with arc length ``s``: ``kappa(s) = kappa0 + dkappa·s`` for ``0 <= s <= length``, so its
tangent angle is ``theta(s) = theta0 + kappa0·s + dkappa·s²/2``. ``dkappa = 0`` is a circular arc,
and ``kappa0 = dkappa = 0`` a straight line.

Positions are closed form. With the generalised Fresnel integrals ::

    I_k(a, b) = ∫₀¹ τ^k exp(i (a τ²/2 + b τ)) dτ

the point at arc length ``s`` is ``(x0, y0) + s·exp(i theta0)·I_0(dkappa s², kappa0 s)``. For
``|a|`` above :data:`SMALL_A`, ``I_0`` is a difference of two standard Fresnel integrals (scipy);
below it (near-arcs, where that difference would cancel catastrophically) the integrand's Taylor
series in τ where ``|b| ≤ 6``, and beyond that a power series in ``a`` over the moments
``M_n(b) = ∫₀¹ τ^n e^{ibτ} dτ``, each moment computed by whichever recurrence is stable for it.
The scalar maths is compiled (:mod:`tagbot.model.kernels`); this module is its array API.

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

from tagbot.model import kernels
from tagbot.model.kernels import SMALL_A as SMALL_A

Array = NDArray[np.float64]


def wrap_angle(angle: ArrayLike) -> Array:
    """Wrap angles into (−π, π]."""
    wrapped = np.pi - np.mod(np.pi - np.asarray(angle, dtype=float), 2.0 * np.pi)
    return wrapped


# --- moments and generalised Fresnel integrals ----------------------------------------------


def moments(n_max: int, b: ArrayLike) -> NDArray[np.complex128]:
    """``M_n(b) = ∫₀¹ τ^n e^{ibτ} dτ`` for ``n = 0..n_max``; shape ``(n_max + 1, *b.shape)``.

    Upward recurrence ``M_n = (e^{ib} − n M_{n−1}) / (ib)`` is stable for ``n < |b|``; downward
    ``M_{n−1} = (e^{ib} − ib M_n) / n`` is stable for ``n > |b|``, started from a short series of
    ``M_N`` about τ = 1. Each moment is taken from its stable direction.
    """
    b = np.asarray(b, dtype=float)
    out = kernels.moments_array(int(n_max), np.ascontiguousarray(b.ravel()))
    return out.T.reshape((n_max + 1, *b.shape))


def generalized_fresnel(
    k_max: int, a: ArrayLike, b: ArrayLike, accurate: bool = True
) -> NDArray[np.complex128]:
    """``I_k(a, b) = ∫₀¹ τ^k exp(i(aτ²/2 + bτ)) dτ``, ``k = 0..k_max``; shape ``(k_max+1, …)``.

    ``I_0`` is accurate to ~1e-14 everywhere. ``accurate=False`` computes ``I_k`` for ``k ≥ 1``
    by the fast recurrence down to ``|a| = SMALL_A``, where it may lose up to ~8 digits for large
    ``|b|``: good enough for a derivative in Newton's method, and much cheaper.
    """
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    flat_a, flat_b = np.ascontiguousarray(a.ravel()), np.ascontiguousarray(b.ravel())
    out = kernels.generalized_fresnel_array(int(k_max), flat_a, flat_b, bool(accurate))
    return out.T.reshape((k_max + 1, *a.shape))


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
        dx, dy, _, _ = self.evaluate_runs(index, np.ones(len(index), np.intp), flat_s)
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
        return self.constants[:, kernels.KIND].astype(np.int8)

    def evaluate_runs(
        self, segments: NDArray[np.intp], counts: NDArray[np.intp], s: Array
    ) -> tuple[Array, Array, Array, Array]:
        """Displacement ``(dx, dy)`` from the start and unit tangent ``(tx, ty)`` at lengths ``s``.

        ``s`` holds ``counts[i]`` consecutive values for segment ``segments[i]`` (flattened
        index). This is the hot path of sampling: a compiled loop with one sine/cosine pair per
        point, plus one standard Fresnel evaluation on spirals.
        """
        return kernels.evaluate_runs(
            self.constants,
            np.ascontiguousarray(segments, dtype=np.intp),
            np.ascontiguousarray(counts, dtype=np.intp),
            np.ascontiguousarray(s, dtype=float),
        )

    @cached_property
    def constants(self) -> Array:
        """Per segment (flattened), its evaluation constants (:mod:`.kernels`)."""
        theta0, kappa0, dkappa, length = (
            np.ascontiguousarray(np.broadcast_to(v, np.shape(self.length)), dtype=float).ravel()
            for v in (self.theta0, self.kappa0, self.dkappa, self.length)
        )
        return kernels.constants_array(theta0, kappa0, dkappa, length)


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
    """Solve B&F's ``Y_0(2A, φ1 − φ0 − A, φ0) = 0`` for ``A`` (chord-relative angles in (−π, π]):
    Newton's method from the published polynomial guess."""
    phi0, phi1 = np.broadcast_arrays(np.asarray(phi0, dtype=float), np.asarray(phi1, dtype=float))
    flat0, flat1 = np.ascontiguousarray(phi0.ravel()), np.ascontiguousarray(phi1.ravel())
    return kernels.solve_g1_array(flat0, flat1).reshape(phi0.shape)
