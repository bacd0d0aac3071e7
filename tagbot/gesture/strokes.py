"""Every trace's strokes side by side (the fitter's working form), as the compiled loops of
:mod:`tagbot.gesture.kernels` take them.

Reconstruction works on all the traces of a tag at once: each trace's plan keeps its own clock
(starting at 0), and a sample belongs to one trace. Per stroke, the curve is its unit-chord shape
(:func:`~tagbot.model.plan.unit_strokes`, set by ``phi1, phi2`` alone) times its chord, so in
complex numbers the pen of one trace is

    x(t) = p_0 + Σ_j (p_{j+1} − p_j) · G_j(W_j(t))

with ``G_j`` the shape (``G_j(0) = 0``, ``G_j(1) = 1``) and ``W_j`` the stroke's lognormal CDF.
That is linear in the targets, which gives the refinement an exact Jacobian for them; the onsets'
columns are minus each stroke's velocity.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from tagbot.gesture import kernels
from tagbot.model.euler import Clothoids
from tagbot.model.plan import END_TOLERANCE, Plan, stroke_windows, unit_strokes

Array = NDArray[np.float64]
Index = NDArray[np.intp]
_INV_SQRT_2PI = 1.0 / float(np.sqrt(2.0 * np.pi))


@dataclass(frozen=True, eq=False)
class Strokes:
    """The strokes of several plans (one per trace), flattened.

    Trace ``k`` has targets ``targets[first_target[k] : first_target[k + 1]]`` and strokes
    ``first_stroke[k] : first_stroke[k + 1]``; stroke ``j`` runs from target ``j + trace[j]``.
    ``onsets`` are on each trace's own clock.
    """

    targets: Array
    onsets: Array
    mu: Array
    sigma: Array
    phi1: Array
    phi2: Array
    counts: Index
    """Strokes per trace."""

    @classmethod
    def of(cls, plans: list[Plan]) -> Strokes:
        """The strokes of ``plans``, each on its own clock (its start moved to 0)."""
        return cls(
            targets=np.concatenate([p.targets for p in plans]),
            onsets=np.concatenate([p.onsets - p.start for p in plans]),
            mu=np.concatenate([p.mu for p in plans]),
            sigma=np.concatenate([p.sigma for p in plans]),
            phi1=np.concatenate([p.phi1 for p in plans]),
            phi2=np.concatenate([p.phi2 for p in plans]),
            counts=np.array([p.n_strokes for p in plans], dtype=np.intp),
        )

    def replace(self, **changes: Array) -> Strokes:
        """A copy with some arrays replaced; the unit shapes are reused unless a tangent changed."""
        fields = {f: getattr(self, f) for f in self.__dataclass_fields__}
        out = Strokes(**(fields | changes))
        if "phi1" not in changes and "phi2" not in changes and "shapes" in self.__dict__:
            out.__dict__["shapes"] = self.shapes
        return out

    def plans(self) -> list[Plan]:
        """One plan per trace (start 0); raises PlanError for collapsed targets."""
        out = []
        for k in range(len(self.counts)):
            t, s = self.target_slice(k), self.stroke_slice(k)
            onsets = self.onsets[s]
            dt = np.diff(onsets, prepend=0.0)
            out.append(
                Plan(self.targets[t], dt, self.mu[s], self.sigma[s], self.phi1[s], self.phi2[s])
            )
        return out

    # --- indexing ------------------------------------------------------------------------------

    @cached_property
    def first_stroke(self) -> Index:
        return np.concatenate([[0], np.cumsum(self.counts)])

    @cached_property
    def first_target(self) -> Index:
        return self.first_stroke + np.arange(len(self.counts) + 1)

    @cached_property
    def trace(self) -> Index:
        """Per stroke, its trace."""
        return np.repeat(np.arange(len(self.counts)), self.counts)

    @cached_property
    def start_target(self) -> Index:
        """Per stroke, the index of the target it leaves from."""
        return np.arange(len(self.onsets)) + self.trace

    def target_slice(self, k: int) -> slice:
        return slice(int(self.first_target[k]), int(self.first_target[k + 1]))

    def stroke_slice(self, k: int) -> slice:
        return slice(int(self.first_stroke[k]), int(self.first_stroke[k + 1]))

    @cached_property
    def later(self) -> Index:
        """Strokes other than the first of their trace: in order, the stroke leaving each
        :attr:`interior` target."""
        first = np.zeros(len(self.onsets), dtype=bool)
        first[self.first_stroke[:-1]] = True
        return np.flatnonzero(~first)

    @cached_property
    def interior(self) -> Index:
        """Targets that are neither the first nor the last of their trace."""
        return self.start_target[self.later]

    # --- geometry ------------------------------------------------------------------------------

    @cached_property
    def shapes(self) -> Clothoids:
        """Unit-chord shapes of the strokes."""
        return unit_strokes(self.phi1, self.phi2)

    @cached_property
    def chords(self) -> NDArray[np.complex128]:
        """Chord of each stroke as a complex number."""
        start = self.targets[self.start_target]
        end = self.targets[self.start_target + 1]
        return (end[:, 0] - start[:, 0]) + 1j * (end[:, 1] - start[:, 1])

    @cached_property
    def lengths(self) -> Array:
        """Arc length of each stroke."""
        return self.shapes.length * np.abs(self.chords)

    def windows(self, size: float) -> tuple[Array, Array]:
        """Active windows per stroke, as :meth:`Plan.windows` with the tag's ``size``."""
        budget = END_TOLERANCE * size / (self.counts[self.trace] * self.lengths)
        return stroke_windows(self.onsets, self.mu, self.sigma, budget)

    def ends(self, size: float) -> Array:
        """When each trace's motion ends (on its own clock)."""
        return np.maximum.reduceat(self.windows(size)[1], self.first_stroke[:-1])

    # --- evaluation ----------------------------------------------------------------------------

    def evaluate(self, trace: Index, t: Array, size: float) -> tuple[Array, Array]:
        """Positions and velocities ``(N, 2)`` at times ``t`` of traces ``trace`` (sorted by
        trace, then time)."""
        t = np.ascontiguousarray(t, dtype=float)
        sample_first = np.searchsorted(trace, np.arange(len(self.counts) + 1))
        xy, v, _, _, _ = kernels.evaluate(
            t, sample_first, self.first_stroke, *self.kernel_arrays, *self.windows(size)
        )
        return xy, v

    @property
    def kernel_arrays(self) -> tuple[Array, ...]:
        """``targets, onsets, mu, sigma``, the shapes' constants and unit lengths, as the
        compiled loops (:mod:`tagbot.gesture.kernels`) take them."""
        shapes = self.shapes
        return (
            *(np.ascontiguousarray(a, dtype=float) for a in (self.targets, self.onsets, self.mu)),
            np.ascontiguousarray(self.sigma, dtype=float),
            shapes.constants,
            np.ascontiguousarray(shapes.length, dtype=float),
        )
