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
tangents. Each residual depends only on the strokes active at its instant, so the normal
equations are sparse; an iteration costs one evaluation of the active (instant, stroke) pairs and
one of the stepped shapes at them, whatever the number of strokes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_factor, cho_solve
from scipy.sparse import csr_matrix, diags
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from tagbot.gesture.strokes import Evaluation, Strokes, evaluate_shapes
from tagbot.model.plan import unit_strokes

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
    layout = _Layout(strokes, options.arcs_only, len(problem.goal))
    tau = problem.initial_instants(strokes)
    x = layout.pack(strokes, tau)
    end = problem.trace_end[problem.goal_trace]
    lower, upper = layout.bounds(strokes, options.onset_slack, end)
    current = problem.evaluate(strokes, tau)
    cost = current.cost
    damping, grow = 1e-3, 2.0
    system = None
    for _ in range(options.iterations):
        if system is None:
            system = _NormalEquations(problem.jacobian(layout, strokes, current), current)
        step, predicted = system.solve(damping)
        trial_x = np.clip(x + step, lower, upper)
        trial_strokes, trial_tau = layout.unpack(strokes, trial_x)
        trial = problem.evaluate(trial_strokes, trial_tau) if problem.valid(trial_strokes) else None
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

    def jacobian(self, layout: _Layout, strokes: Strokes, current: _Residuals) -> csr_matrix:
        """The residuals' Jacobian in the plan's parameters, complex (row per instant, columns as
        in :class:`_Layout` up to the instants)."""
        ev, order = current.evaluation, current.order
        pairs = ev.pairs
        g = pairs.gx + 1j * pairs.gy
        rows, cols, values = [], [], []

        # Targets: x = Σ_i p_i (G_{i-1} − G_i), complex-linear in each interior target p_i.
        inner = layout.inner
        b = strokes.later  # the stroke leaving each interior target
        a = b - 1
        lo = np.minimum(ev.begin[a], ev.begin[b])
        span = np.maximum(ev.stop[a], ev.stop[b]) - lo
        which = np.repeat(np.arange(len(inner)), span)
        row = np.arange(int(span.sum())) - np.repeat(np.cumsum(span) - span - lo, span)
        coefficient = self._shape_at(ev, g, a[which], row) - self._shape_at(ev, g, b[which], row)
        rows += [row, row]
        cols += [2 * which, 2 * which + 1]
        values += [coefficient, 1j * coefficient]

        # Onsets: moving stroke j's onset later moves its contribution back by its velocity.
        free = layout.onset_column[pairs.stroke]
        has = free >= 0
        rows.append(pairs.sample[has])
        cols.append(free[has])
        values.append(-(pairs.chord * pairs.velocity)[has])

        # Tangents: forward differences of the unit shapes at the same CDF values.
        columns, phi1, phi2 = layout.angle_steps(strokes, _ANGLE_STEP)
        copies = len(columns)
        shapes = unit_strokes(phi1, phi2)  # the stepped shapes, ``copies`` blocks of strokes
        n = len(strokes.onsets)
        counts = np.tile(np.diff(pairs.offsets), copies)
        stroke = np.concatenate([pairs.stroke + c * n for c in range(copies)])
        gx, gy, _, _ = evaluate_shapes(shapes, stroke, counts, np.tile(pairs.w, copies))
        change = np.tile(pairs.chord, copies) * ((gx + 1j * gy) - np.tile(g, copies))
        rows.append(np.tile(pairs.sample, copies))
        cols.append(np.concatenate([column[pairs.stroke] for column in columns]))
        values.append(change / _ANGLE_STEP)

        # Rows by instant rather than by evaluation order.
        return csr_matrix(
            (np.concatenate(values), (order[np.concatenate(rows)], np.concatenate(cols))),
            shape=(len(order), layout.instant_column),
        )

    @staticmethod
    def _shape_at(
        ev: Evaluation, g: NDArray[np.complex128], stroke: Index, row: Index
    ) -> NDArray[np.complex128]:
        """Stroke shapes at evaluation rows: 0 before their windows, 1 after, ``g`` inside."""
        begin, stop = ev.begin[stroke], ev.stop[stroke]
        inside = (row >= begin) & (row < stop)
        out = np.where(row >= stop, 1.0 + 0j, 0j)
        out[inside] = g[ev.pairs.offsets[stroke[inside]] + row[inside] - begin[inside]]
        return out


class _NormalEquations:
    """Damped Gauss-Newton steps with the instants eliminated (a Schur complement).

    With the complex Jacobian ``C`` (a row per instant) the real normal matrix is
    ``Re(Cᴴ C)``. Each forward instant's own column is the trajectory's velocity ``v`` at it, in
    its row alone, so that block of the normal matrix is diagonal (``|v|²``) and the instants
    drop out: the system left is the size of the plan's parameters, solved densely (or sparse
    when large).
    """

    def __init__(self, jacobian: csr_matrix, current: _Residuals) -> None:
        forward = len(current.velocity)
        r = current.residual
        v = current.velocity
        # Where the pen rests (the ends, a stop) an instant is free to slide a long way at no
        # cost in the linear model, and far from true in the real one: a floor on its scale.
        speed2 = v.real**2 + v.imag**2
        self.speed2 = np.maximum(speed2, _REST * max(float(np.median(speed2)), 1e-300))
        ch = jacobian.conj().T.tocsr()
        # Per forward instant: Re(conj(v)·row), the coupling of its instant to the parameters.
        self.u = (diags(np.conj(v)) @ jacobian[:forward]).real.tocsr()
        self.a = (ch @ jacobian).real
        self.b = self.u.T @ diags(1.0 / self.speed2) @ self.u
        diagonal = self.a.diagonal()
        self.scale = np.maximum(diagonal, 1e-12 * max(float(diagonal.max(initial=0.0)), 1e-300))
        self.g_p = (ch @ r).real
        self.g_t = (np.conj(v) * r[:forward]).real
        if self.a.shape[0] <= _DENSE_LIMIT:
            self.a, self.b = self.a.toarray(), self.b.toarray()

    def solve(self, damping: float) -> tuple[Array, float]:
        """The step for the parameters and the instants at this damping, and the decrease of
        the cost that the linear model predicts for it."""
        d = self.speed2 * (1.0 + damping)
        rhs = -self.g_p + self.u.T @ (self.g_t / d)
        if isinstance(self.a, np.ndarray):
            schur = self.a - self.b / (1.0 + damping)
            schur[np.diag_indices_from(schur)] += damping * self.scale
            step_p = cho_solve(cho_factor(schur, check_finite=False), rhs, check_finite=False)
        else:
            schur = self.a - self.b / (1.0 + damping) + diags(damping * self.scale)
            step_p = spsolve(schur.tocsc(), rhs)
        step_t = (-self.g_t - self.u @ step_p) / d
        # Cost is Σ|r|², so the model's decrease is δᵀ(λDδ − g) (twice the textbook form).
        damped = damping * (self.scale @ step_p**2 + (self.speed2 * step_t) @ step_t)
        predicted = damped - step_p @ self.g_p - step_t @ self.g_t
        return np.concatenate([step_p, step_t]), float(predicted)


_REST = 1e-2
"""Instants' scale floor, a fraction of the median squared speed (see _NormalEquations)."""
_DENSE_LIMIT = 800
"""Plan parameters up to which the reduced normal equations are solved densely."""


class _Layout:
    """How the free parameters sit in the solver's vector.

    ``[interior targets (x, y)…, phi1/phi2 (or phi) per stroke…, onsets of all but each trace's
    first stroke…, forward instants…]``. Onsets rather than delays: a delay moves every later
    stroke, an onset only its own. Delays that would turn negative are clamped to 0.
    """

    def __init__(self, strokes: Strokes, arcs_only: bool, instants: int) -> None:
        n = len(strokes.onsets)
        self.arcs_only = arcs_only
        self.inner = strokes.interior
        self.targets = 2 * len(self.inner)
        self.angles = n if arcs_only else 2 * n
        self.free_onsets = strokes.later
        self.onset_column = np.full(n, -1)
        self.onset_column[self.free_onsets] = (
            self.targets + self.angles + np.arange(len(self.free_onsets))
        )
        self.instant_column = self.targets + self.angles + len(self.free_onsets)
        self.size = self.instant_column + instants

    def pack(self, strokes: Strokes, tau: Array) -> Array:
        if self.arcs_only:
            angles = strokes.phi2
        else:
            angles = np.column_stack([strokes.phi1, strokes.phi2]).ravel()
        return np.concatenate(
            [strokes.targets[self.inner].ravel(), angles, strokes.onsets[self.free_onsets], tau]
        )

    def unpack(self, strokes: Strokes, x: Array) -> tuple[Strokes, Array]:
        targets = strokes.targets.copy()
        targets[self.inner] = x[: self.targets].reshape(-1, 2)
        angles = x[self.targets : self.targets + self.angles]
        if self.arcs_only:
            phi1, phi2 = -angles, angles
        else:
            phi1, phi2 = angles[0::2], angles[1::2]
        onsets = strokes.onsets.copy()
        onsets[self.free_onsets] = x[self.targets + self.angles : self.instant_column]
        # Onsets keep their order within a trace (delays >= 0).
        offset = strokes.trace * (2.0 * float(np.max(np.abs(onsets))) + 1.0)
        onsets = np.maximum.accumulate(onsets + offset) - offset
        changed = strokes.replace(targets=targets, phi1=phi1, phi2=phi2, onsets=onsets)
        return changed, x[self.instant_column :]

    def bounds(self, strokes: Strokes, slack: float, end: Array) -> tuple[Array, Array]:
        """Tangents within ±3 rad, onsets within ``slack`` of where they were, instants within
        their trace's motion (``0..end`` each)."""
        onsets = strokes.onsets[self.free_onsets]
        instants = len(end)
        inf = np.full(self.targets, np.inf)
        lower = np.concatenate(
            [-inf, np.full(self.angles, -PHI_LIMIT), onsets - slack, np.zeros(instants)]
        )
        upper = np.concatenate([inf, np.full(self.angles, PHI_LIMIT), onsets + slack, end])
        return lower, upper

    def angle_steps(self, strokes: Strokes, h: float) -> tuple[list[Index], Array, Array]:
        """Each angle parameter's column per stroke, and ``(phi1, phi2)`` with one parameter
        stepped by ``h`` per block of strokes (one block per column list)."""
        n = len(strokes.onsets)
        base = self.targets + np.arange(n) * (1 if self.arcs_only else 2)
        if self.arcs_only:
            return [base], strokes.phi1 - h, strokes.phi2 + h
        phi1 = np.concatenate([strokes.phi1 + h, strokes.phi1])
        phi2 = np.concatenate([strokes.phi2, strokes.phi2 + h])
        return [base, base + 1], phi1, phi2
