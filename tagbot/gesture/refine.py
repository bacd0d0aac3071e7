"""Least-squares refinement of reconstructed plans against their contours (beyond the paper).

The paper's reconstruction (§6) places targets so that the trajectory passes through the
dominant points at the critical instants, with tangents and overlaps estimated once from the
contour. Overlapping strokes then bend the trajectory away from the contour between those points.
This step polishes targets, tangents and onsets together so that the trajectory follows the whole
contour: a Levenberg-Marquardt fit of every trace at once (:mod:`tagbot.gesture.strokes`) whose
residuals are

* contour samples against the trajectory at instants of their own, which are unknowns of the
  fit too (orthogonal distance regression: the trajectory may not skip part of the contour), and
* trajectory instants on a uniform grid against the contour point nearest to them, re-matched at
  every evaluation (the trajectory may not wander off the contour between those instants).

The Jacobian is exact for the targets (the trajectory is linear in them) and the onsets and
instants (minus or plus a velocity), and a forward difference of the unit-chord shapes for the
tangents. Each residual depends only on the strokes active at its instant and the parameters
are ordered stroke by stroke, so the normal equations are banded; the instants are eliminated
(a Schur complement, still banded) and the band is factored in compiled code
(:mod:`tagbot.gesture.kernels`). An iteration costs one evaluation of the active (instant,
stroke) pairs and one of the stepped shapes at them: linear in the number of strokes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from tagbot.gesture import kernels
from tagbot.gesture.strokes import Evaluation, Strokes

Array = NDArray[np.float64]
Index = NDArray[np.intp]

PHI_LIMIT = 3.0
"""Tangent deviations stay within ±3 rad while refining (away from the ±π ambiguity)."""
_ANGLE_STEP = 1e-6
"""Forward-difference step for the tangents' Jacobian columns, radians."""


@dataclass(frozen=True)
class RefineOptions:
    """How hard the refinement works."""

    iterations: int = 4
    """Levenberg-Marquardt iterations at most."""
    contour_samples: int = 16
    """Contour samples per stroke that the trajectory must pass near."""
    path_samples: int = 8
    """Trajectory instants per stroke that must lie near the contour."""
    onset_slack: float = 0.125
    """How far each onset may move from where it started, seconds."""
    arcs_only: bool = False
    """Keep ΣΛ* strokes circular (``phi1 = -phi2``)."""


def refine(
    strokes: Strokes, curves: list[Array], size: float, options: RefineOptions
) -> tuple[Strokes, Array]:
    """``strokes`` (one plan per curve) adjusted to follow ``curves`` (see the module doc), and
    the misfit: per sample of the concatenated curves, the largest distance between it and the
    trajectory that a residual saw there (0 where none looked).

    The first and last target of each trace stay on its contour's ends and its first onset at 0.
    """
    problem = _Problem.build(strokes, curves, size, options)
    layout = _Layout(strokes, options.arcs_only)
    tau = problem.initial_instants(strokes)
    x = layout.pack(strokes)
    lower, upper = layout.bounds(strokes, options.onset_slack)
    end = problem.trace_end[problem.goal_trace]
    current = problem.evaluate(strokes, tau)
    cost = current.cost
    damping, grow = 1e-3, 2.0
    system = None
    for _ in range(options.iterations):
        if system is None:
            system = _NormalEquations(layout, strokes, current)
        step, step_tau, predicted = system.solve(damping)
        trial = None
        if predicted > 0.0:
            trial_x = np.clip(x + step, lower, upper)
            trial_tau = np.clip(tau + step_tau, 0.0, end)
            trial_strokes = layout.unpack(strokes, trial_x)
            if problem.valid(trial_strokes):
                trial = problem.evaluate(trial_strokes, trial_tau)
        trial_cost = np.inf if trial is None else trial.cost
        gain = (cost - trial_cost) / max(predicted, 1e-300)
        if gain > 0:  # Nielsen's damping update, from the gain ratio
            improvement = 1.0 - trial_cost / cost
            x, strokes, tau, current, cost = trial_x, trial_strokes, trial_tau, trial, trial_cost
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * min(gain, 1.0) - 1.0) ** 3)
            grow = 2.0
            system = None
            if improvement < 1e-3:
                break
        else:
            damping *= grow
            grow *= 2.0
            if damping > 1e6:
                break
    return strokes, problem.misfit(current)


@dataclass(frozen=True, eq=False)
class _Residuals:
    evaluation: Evaluation
    order: Index
    """Evaluation row → residual instant (forward instants first, then the grid)."""
    residual: NDArray[np.complex128]
    """Per instant (forward instants first), trajectory minus goal as a complex number."""
    velocity: NDArray[np.complex128]
    """The trajectory's velocity at each forward instant."""
    nearest: Index
    """The contour sample nearest to each grid instant's point."""

    @property
    def cost(self) -> float:
        return float(np.sum(self.residual.real**2 + self.residual.imag**2))


@dataclass(frozen=True, eq=False)
class _Problem:
    """The contours, the goals and the instants of a refinement."""

    size: float
    contour: Array
    tree: cKDTree
    """Nearest contour point per (x, y, trace·far)."""
    far: float
    goal: Array
    """Contour samples the trajectory must pass near, per forward instant."""
    goal_trace: Index
    goal_index: Index
    """Each goal's index among the contour samples."""
    grid: Array
    """Fixed trajectory instants that must lie near the contour."""
    grid_trace: Index
    trace_end: Array
    counts: Index

    @classmethod
    def build(
        cls, strokes: Strokes, curves: list[Array], size: float, options: RefineOptions
    ) -> _Problem:
        counts = strokes.counts
        contour = np.concatenate(curves)
        trace = np.repeat(np.arange(len(curves)), [len(c) for c in curves])
        far = 4.0 * size
        tree = cKDTree(np.column_stack([contour, trace * far]))
        goal_index, goal_trace = [], []
        first = np.concatenate([[0], np.cumsum([len(c) for c in curves])])
        for k, curve in enumerate(curves):
            count = min(len(curve), max(options.contour_samples * int(counts[k]), 32))
            pick = np.linspace(0, len(curve) - 1, count).round().astype(np.intp)
            goal_index.append(first[k] + pick)
            goal_trace.append(np.full(count, k))
        ends = strokes.ends(size)
        grid, grid_trace = [], []
        for k in range(len(curves)):
            count = max(options.path_samples * int(counts[k]), 16)
            grid.append(np.linspace(0.0, ends[k], count))
            grid_trace.append(np.full(count, k))
        return cls(
            size=size,
            contour=contour,
            tree=tree,
            far=far,
            goal=contour[np.concatenate(goal_index)],
            goal_trace=np.concatenate(goal_trace),
            goal_index=np.concatenate(goal_index),
            grid=np.concatenate(grid),
            grid_trace=np.concatenate(grid_trace),
            trace_end=ends,
            counts=counts,
        )

    def initial_instants(self, strokes: Strokes) -> Array:
        """Each goal's instant: the closest of a dense grid along its trace's trajectory."""
        fine = 4
        per = np.bincount(self.grid_trace, minlength=len(self.counts)) * fine
        trace = np.repeat(np.arange(len(per)), per)
        first = np.concatenate([[0], np.cumsum(per)])
        fraction = (np.arange(first[-1]) - np.repeat(first[:-1], per)) / np.repeat(per - 1, per)
        t = fraction * self.trace_end[trace]
        xy = strokes.evaluate(trace, t, self.size).xy
        tree = cKDTree(np.column_stack([xy, trace * self.far]))
        _, nearest = tree.query(np.column_stack([self.goal, self.goal_trace * self.far]))
        return t[nearest]

    def valid(self, strokes: Strokes) -> bool:
        """No two consecutive targets of a trace (nearly) coincide."""
        return bool(np.all(np.abs(strokes.chords) > 1e-6 * self.size))

    def evaluate(self, strokes: Strokes, tau: Array) -> _Residuals:
        trace = np.concatenate([self.goal_trace, self.grid_trace])
        t = np.concatenate([tau, self.grid])
        order = np.lexsort((t, trace))
        evaluation = strokes.evaluate(trace[order], t[order], self.size)
        xy = np.empty_like(evaluation.xy)
        xy[order] = evaluation.xy
        on_grid = xy[len(tau) :]
        _, nearest = self.tree.query(np.column_stack([on_grid, self.grid_trace * self.far]))
        goal = np.concatenate([self.goal, self.contour[nearest]])
        residual = (xy[:, 0] - goal[:, 0]) + 1j * (xy[:, 1] - goal[:, 1])
        v = np.empty_like(evaluation.v)
        v[order] = evaluation.v
        velocity = v[: len(tau), 0] + 1j * v[: len(tau), 1]
        return _Residuals(evaluation, order, residual, velocity, nearest)

    def misfit(self, current: _Residuals) -> Array:
        """Per contour sample, the largest residual that looked at it."""
        out = np.zeros(len(self.contour))
        distance = np.abs(current.residual)
        forward = len(self.goal)
        np.maximum.at(out, self.goal_index, distance[:forward])
        np.maximum.at(out, current.nearest, distance[forward:])
        return out


def _jacobian(layout: _Layout, strokes: Strokes, current: _Residuals) -> tuple[Index, Index, Any]:
    """The residuals' complex Jacobian in the plan's parameters, as rows ``(indptr, col,
    value)`` in evaluation order (:attr:`_Residuals.order` maps them to instants)."""
    ev = current.evaluation
    return kernels.jacobian(
        ev.begin,
        ev.stop,
        ev.values,
        np.column_stack([strokes.chords.real, strokes.chords.imag]),
        strokes.first_stroke,
        strokes.phi1,
        strokes.phi2,
        layout.arcs_only,
        _ANGLE_STEP,
        layout.angle_col,
        layout.onset_col,
        layout.target_col,
        len(current.order),
    )


class _NormalEquations:
    """Damped Gauss-Newton steps with the instants eliminated (a Schur complement).

    With the complex Jacobian ``C`` (a row per instant) the real normal matrix is
    ``Re(Cᴴ C)``. Each forward instant's own column is the trajectory's velocity ``v`` at it, in
    its row alone, so that block of the normal matrix is diagonal (``|v|²``) and the instants
    drop out: the system left is the size of the plan's parameters, and banded.
    """

    def __init__(self, layout: _Layout, strokes: Strokes, current: _Residuals) -> None:
        order = current.order
        forward = len(current.velocity)
        self.forward_row = np.argsort(order)[:forward]  # each forward instant's evaluation row
        rows = len(order)
        self.forward = order < forward
        residual = current.residual[order]
        velocity = np.zeros(rows, dtype=complex)
        velocity[self.forward_row] = current.velocity
        # Where the pen rests (the ends, a stop) an instant is free to slide a long way at no
        # cost in the linear model, and far from true in the real one: a floor on its scale.
        speed2 = np.abs(current.velocity) ** 2
        floor = _REST * max(float(np.median(speed2)), 1e-300)
        self.speed2 = np.ones(rows)
        self.speed2[self.forward_row] = np.maximum(speed2, floor)
        self.indptr, self.col, value = _jacobian(layout, strokes, current)
        self.a, self.b, self.g, self.u = kernels.normal_equations(
            self.indptr, self.col, value, residual, velocity, self.speed2, self.forward, layout.size
        )
        self.g_t = (np.conj(velocity) * residual).real
        diagonal = self.a[0]
        self.scale = np.maximum(diagonal, 1e-12 * max(float(diagonal.max(initial=0.0)), 1e-300))

    def solve(self, damping: float) -> tuple[Array, Array, float]:
        """The step for the parameters and the forward instants at this damping, and the
        decrease of the cost that the linear model predicts for it (0 if none)."""
        step, step_t, predicted, ok = kernels.damped_step(
            self.a,
            self.b,
            self.scale,
            self.g,
            self.indptr,
            self.col,
            self.u,
            self.g_t,
            self.speed2,
            self.forward,
            damping,
        )
        return step, step_t[self.forward_row], predicted if ok else 0.0


_REST = 1e-2
"""Instants' scale floor, a fraction of the median squared speed (see _NormalEquations)."""


class _Layout:
    """How the plan's free parameters sit in the solver's vector: stroke by stroke, each
    stroke's ``phi1, phi2`` (or ``phi``), then, but for each trace's first stroke, its onset and
    the target it leaves (x, y). Onsets rather than delays: a delay moves every later stroke, an
    onset only its own. Delays that would turn negative are clamped to 0.
    """

    def __init__(self, strokes: Strokes, arcs_only: bool) -> None:
        self.arcs_only = arcs_only
        angles = 1 if arcs_only else 2
        self.later = strokes.later
        self.inner = strokes.interior
        width = np.full(len(strokes.onsets), angles)
        width[self.later] += 3
        first = np.cumsum(width) - width
        self.angle_col = first
        self.onset_col = np.full(len(width), -1)
        self.onset_col[self.later] = first[self.later] + angles
        self.target_col = np.full(len(width), -1)
        self.target_col[self.later] = first[self.later] + angles + 1
        self.size = int(width.sum())

    def pack(self, strokes: Strokes) -> Array:
        x = np.empty(self.size)
        if self.arcs_only:
            x[self.angle_col] = strokes.phi2
        else:
            x[self.angle_col], x[self.angle_col + 1] = strokes.phi1, strokes.phi2
        x[self.onset_col[self.later]] = strokes.onsets[self.later]
        columns = self.target_col[self.later]
        x[columns], x[columns + 1] = strokes.targets[self.inner].T
        return x

    def unpack(self, strokes: Strokes, x: Array) -> Strokes:
        targets = strokes.targets.copy()
        columns = self.target_col[self.later]
        targets[self.inner, 0], targets[self.inner, 1] = x[columns], x[columns + 1]
        if self.arcs_only:
            phi2 = x[self.angle_col]
            phi1 = -phi2
        else:
            phi1, phi2 = x[self.angle_col], x[self.angle_col + 1]
        onsets = strokes.onsets.copy()
        onsets[self.later] = x[self.onset_col[self.later]]
        # Onsets keep their order within a trace (delays >= 0).
        offset = strokes.trace * (2.0 * float(np.max(np.abs(onsets))) + 1.0)
        onsets = np.maximum.accumulate(onsets + offset) - offset
        return strokes.replace(targets=targets, phi1=phi1, phi2=phi2, onsets=onsets)

    def bounds(self, strokes: Strokes, slack: float) -> tuple[Array, Array]:
        """Tangents within ±3 rad, onsets within ``slack`` of where they were."""
        lower, upper = np.full(self.size, -np.inf), np.full(self.size, np.inf)
        angles = np.concatenate([self.angle_col, self.angle_col + 1])
        angles = self.angle_col if self.arcs_only else angles
        lower[angles], upper[angles] = -PHI_LIMIT, PHI_LIMIT
        onsets = strokes.onsets[self.later]
        lower[self.onset_col[self.later]] = onsets - slack
        upper[self.onset_col[self.later]] = onsets + slack
        return lower, upper
