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
instants (minus or plus a velocity); for the tangents it is closed form in the spirals'
parameters, whose dependence on the tangents is a central difference of the G1 fit. Each
residual depends only on the strokes active at its instant and the parameters are ordered
stroke by stroke, so the normal equations are banded; the instants are eliminated (a Schur
complement, still banded) and the band is factored. An iteration costs one evaluation of the
active (instant, stroke) pairs and their derivatives: linear in the number of strokes. The loop
runs in compiled code (:func:`tagbot.gesture.refine_kernels.refine_loop`); this module sets the
problem up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tagbot.gesture import refine_kernels
from tagbot.gesture.strokes import Strokes
from tagbot.model.plan import END_TOLERANCE

Array = NDArray[np.float64]
Index = NDArray[np.intp]

PHI_LIMIT = 3.0
"""Tangent deviations stay within ±3 rad while refining (away from the ±π ambiguity)."""
ANGLE_STEP = 1e-6
"""Central-difference step for the spirals' parameters in the tangents, radians."""
REST = 1e-2
"""Instants' scale floor, a fraction of the median squared speed (see refine_kernels.system)."""
JACOBIAN_TAIL = 1e-4
"""In the Jacobian (not the residuals), a stroke whose CDF is within this of 0 or 1 counts as not
started or complete: its tails' tiny derivatives would double the entries per row."""
_DENSE = 4
"""Initial instants are picked among this many per grid instant."""


@dataclass(frozen=True)
class RefineOptions:
    """How hard the refinement works."""

    iterations: int = 3
    """Levenberg-Marquardt steps taken at most (each with a new Jacobian; rejected trial steps,
    three per step at most, are not counted)."""
    contour_samples: int = 14
    """Contour samples per stroke that the trajectory must pass near."""
    path_samples: int = 7
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
    lower, upper = layout.bounds(strokes, options.onset_slack)
    goal = problem.contour[problem.goal_index]
    targets, onsets, phi1, phi2, _, misfit = refine_kernels.refine_loop(
        *problem.plan_arrays(strokes),
        layout.angle_col,
        layout.onset_col,
        layout.target_col,
        layout.arcs_only,
        lower,
        upper,
        problem.initial_instants(strokes),
        problem.trace_end[problem.goal_trace],
        goal,
        problem.goal_first,
        problem.goal_index,
        problem.grid,
        problem.grid_first,
        *problem.contour_arrays,
        float(size),
        END_TOLERANCE,
        ANGLE_STEP,
        REST,
        int(options.iterations),
        JACOBIAN_TAIL,
    )
    return strokes.replace(targets=targets, onsets=onsets, phi1=phi1, phi2=phi2), misfit


@dataclass(frozen=True, eq=False)
class _Problem:
    """The contours, the goals and the instants of a refinement."""

    size: float
    contour: Array
    contour_first: Index
    """Trace ``k``'s contour samples are ``contour_first[k]:contour_first[k + 1]``."""
    goal_index: Index
    """The contour samples the trajectory must pass near (one forward instant each)."""
    goal_first: Index
    grid: Array
    """Fixed trajectory instants that must lie near the contour."""
    grid_first: Index
    trace_end: Array

    @classmethod
    def build(
        cls, strokes: Strokes, curves: list[Array], size: float, options: RefineOptions
    ) -> _Problem:
        counts = strokes.counts
        lengths = np.array([len(c) for c in curves])
        contour_first = np.concatenate([[0], np.cumsum(lengths)])
        goals = np.minimum(lengths, np.maximum(options.contour_samples * counts, 32))
        goal_first = np.concatenate([[0], np.cumsum(goals)])
        trace = np.repeat(np.arange(len(curves)), goals)
        fraction = (np.arange(goal_first[-1]) - goal_first[trace]) / (goals[trace] - 1)
        pick = np.round(fraction * (lengths[trace] - 1)).astype(np.intp)
        ends = strokes.ends(size)
        grids = np.maximum(options.path_samples * counts, 16)
        grid_first = np.concatenate([[0], np.cumsum(grids)])
        trace = np.repeat(np.arange(len(curves)), grids)
        fraction = (np.arange(grid_first[-1]) - grid_first[trace]) / (grids[trace] - 1)
        return cls(
            size=size,
            contour=np.ascontiguousarray(np.concatenate(curves), dtype=float),
            contour_first=contour_first,
            goal_index=contour_first[:-1][np.repeat(np.arange(len(curves)), goals)] + pick,
            goal_first=goal_first,
            grid=fraction * ends[trace],
            grid_first=grid_first,
            trace_end=ends,
        )

    @property
    def goal_trace(self) -> Index:
        return np.repeat(np.arange(len(self.trace_end)), np.diff(self.goal_first))

    @property
    def cell(self) -> float:
        """Width of the cells that sort contour samples for nearest-point queries."""
        return self.size / 100.0

    @property
    def goal_arrays(self) -> tuple[Array, Index, Array, Index]:
        return self.contour[self.goal_index], self.goal_first, self.grid, self.grid_first

    @property
    def contour_arrays(self) -> tuple[Array, Array, Index, Index, float]:
        header, start, order = refine_kernels.buckets(self.contour, self.contour_first, self.cell)
        return self.contour, header, start, order, self.cell

    @staticmethod
    def plan_arrays(strokes: Strokes) -> tuple[Array, ...]:
        """``targets, onsets, mu, sigma, phi1, phi2, first_stroke`` for the compiled loops."""
        return (
            *(
                np.ascontiguousarray(a, dtype=float)
                for a in (strokes.targets, strokes.onsets, strokes.mu, strokes.sigma)
            ),
            np.ascontiguousarray(strokes.phi1, dtype=float),
            np.ascontiguousarray(strokes.phi2, dtype=float),
            strokes.first_stroke,
        )

    def initial_instants(self, strokes: Strokes) -> Array:
        """Each goal's instant: the closest of a dense grid along its trace's trajectory."""
        dense = np.diff(self.grid_first) * _DENSE
        goal, goal_first, _, _ = self.goal_arrays
        return refine_kernels.initial_instants(
            *self.plan_arrays(strokes),
            goal,
            goal_first,
            dense,
            self.trace_end,
            self.size,
            END_TOLERANCE,
            self.cell,
        )

    def residuals(self, strokes: Strokes, tau: Array) -> tuple[Array, ...]:
        """The residuals (:func:`~tagbot.gesture.refine_kernels.residuals`) at instants ``tau``."""
        return refine_kernels.residuals(
            *self.plan_arrays(strokes),
            tau,
            *self.goal_arrays,
            *self.contour_arrays,
            self.size,
            END_TOLERANCE,
        )


class _Layout:
    """How the plan's free parameters sit in the solver's vector: stroke by stroke, each
    stroke's ``phi1, phi2`` (or ``phi``), then, but for each trace's first stroke, its onset and
    the target it leaves (x, y). Onsets rather than delays: a delay moves every later stroke, an
    onset only its own. Ordered so, the normal equations are banded.
    """

    def __init__(self, strokes: Strokes, arcs_only: bool) -> None:
        self.arcs_only = arcs_only
        angles = 1 if arcs_only else 2
        self.later = strokes.later
        width = np.full(len(strokes.onsets), angles)
        width[self.later] += 3
        first = np.cumsum(width) - width
        self.angle_col = first
        self.onset_col = np.full(len(width), -1)
        self.onset_col[self.later] = first[self.later] + angles
        self.target_col = np.full(len(width), -1)
        self.target_col[self.later] = first[self.later] + angles + 1
        self.size = int(width.sum())

    def bounds(self, strokes: Strokes, slack: float) -> tuple[Array, Array]:
        """Tangents within ±3 rad, onsets within ``slack`` of where they were."""
        lower, upper = np.full(self.size, -np.inf), np.full(self.size, np.inf)
        angles = self.angle_col if self.arcs_only else np.r_[self.angle_col, self.angle_col + 1]
        lower[angles], upper[angles] = -PHI_LIMIT, PHI_LIMIT
        onsets = strokes.onsets[self.later]
        lower[self.onset_col[self.later]] = onsets - slack
        upper[self.onset_col[self.later]] = onsets + slack
        return lower, upper

    @property
    def columns(self) -> tuple[Index, Index, Index, bool]:
        return self.angle_col, self.onset_col, self.target_col, self.arcs_only
