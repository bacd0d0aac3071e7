"""Least-squares refinement of reconstructed plans against their contours (beyond the paper).

The paper's reconstruction (§6) places targets so that the trajectory passes through the
dominant points at the critical instants, with tangents and overlaps estimated once from the
contour. Overlapping strokes then bend the trajectory away from the contour between those points.
This step polishes targets, tangents and onsets together so that the trajectory follows the whole
contour: a Levenberg-Marquardt fit of every trace at once (:mod:`tagbot.gesture.strokes`) whose
residuals are

* contour samples against the trajectory at instants of their own, which are unknowns of the
  fit too (orthogonal distance regression: the trajectory may not skip part of the contour),
  each starting where the trajectory passes nearest while the sample's own strokes run, and
* trajectory instants on a uniform grid against the contour point nearest to them among the
  contour between the samples whose instants are near, re-matched at every evaluation (the
  trajectory may not wander off the contour between those instants, nor be held to another
  part of it that it passes by: a spiral's next turn, a loop's other side).

Every search looks at a bounded stretch of instants or contour (a few strokes' worth), or
through a grid of cells holding a bounded number of samples each
(:func:`~tagbot.gesture.refine_kernels.path_buckets`): an evaluation costs time and memory
linear in the contour samples and the strokes.

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

from tagbot.gesture import kernels, refine_kernels
from tagbot.gesture.strokes import Strokes
from tagbot.model.plan import END_TOLERANCE, PHI_LIMIT

Array = NDArray[np.float64]
Index = NDArray[np.intp]

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
    strokes: Strokes,
    curves: list[Array],
    size: float,
    options: RefineOptions,
    sections: list[Index] | None = None,
) -> tuple[Strokes, Array]:
    """``strokes`` (one plan per curve) adjusted to follow ``curves`` (see the module doc), and
    the misfit: per sample of the concatenated curves, the largest distance between it and the
    trajectory that a residual saw there (0 where none looked).

    ``sections``: per curve, the samples its targets were placed on (the dominant points);
    without them, the samples nearest to the targets. The first and last target of each trace
    stay on its contour's ends and its first onset at 0.
    """
    problem = _Problem.build(strokes, curves, size, options, sections)
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
        problem.reach,
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
    goal_stroke: Index
    """The stroke whose section of the contour holds each goal."""
    grid: Array
    """Fixed trajectory instants that must lie near the contour."""
    grid_first: Index
    trace_end: Array
    reach: int
    """A grid instant's nearest contour sample lies between the goals of the ``reach`` forward
    instants before it and after it."""

    @classmethod
    def build(
        cls,
        strokes: Strokes,
        curves: list[Array],
        size: float,
        options: RefineOptions,
        sections: list[Index] | None = None,
    ) -> _Problem:
        counts = strokes.counts
        lengths = np.array([len(c) for c in curves])
        contour_first = np.concatenate([[0], np.cumsum(lengths)])
        goals = np.minimum(lengths, np.maximum(options.contour_samples * counts, 32))
        goal_first = np.concatenate([[0], np.cumsum(goals)])
        trace = np.repeat(np.arange(len(curves)), goals)
        fraction = (np.arange(goal_first[-1]) - goal_first[trace]) / (goals[trace] - 1)
        pick = np.round(fraction * (lengths[trace] - 1)).astype(np.intp)
        if sections is None:
            sections = _nearest_samples(strokes, curves)
        goal_stroke = np.concatenate(
            [
                strokes.first_stroke[k]
                + np.clip(np.searchsorted(sections[k], pick[a:b], "right") - 1, 0, n - 1)
                for k, (n, a, b) in enumerate(
                    zip(counts, goal_first[:-1], goal_first[1:], strict=True)
                )
            ]
        )
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
            goal_stroke=goal_stroke.astype(np.intp),
            grid=fraction * ends[trace],
            grid_first=grid_first,
            trace_end=ends,
            reach=int(options.contour_samples),
        )

    @property
    def goal_trace(self) -> Index:
        return np.repeat(np.arange(len(self.trace_end)), np.diff(self.goal_first))

    @property
    def goal_arrays(self) -> tuple[Array, Index, Array, Index]:
        return self.contour[self.goal_index], self.goal_first, self.grid, self.grid_first

    @property
    def contour_arrays(self) -> tuple[Array, Array, Index, Index]:
        """The contour samples and their grids for nearest-sample queries, trace by trace."""
        header, start, order = refine_kernels.path_buckets(self.contour, self.contour_first)
        return self.contour, header, start, order

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
        return self._initial_instants(strokes)[0]

    def _initial_instants(self, strokes: Strokes) -> tuple[Array, int]:
        dense = np.diff(self.grid_first) * _DENSE
        goal, goal_first, _, _ = self.goal_arrays
        return refine_kernels.initial_instants(  # type: ignore[no-any-return]
            *self.plan_arrays(strokes),
            goal,
            goal_first,
            self.goal_stroke,
            dense,
            self.trace_end,
            self.size,
            END_TOLERANCE,
            kernels.CROSSING_STEPS,
        )

    def search_work(self, strokes: Strokes) -> tuple[int, int]:
        """The nearest-point searches' work (cells and points looked at,
        :func:`~tagbot.gesture.refine_kernels.nearest`) of the initial instants and of one
        evaluation of the residuals there: what bounds the refinement's cost per point."""
        tau, initial = self._initial_instants(strokes)
        return initial, int(self.residuals(strokes, tau)[7])

    def residuals(self, strokes: Strokes, tau: Array) -> tuple[Array, ...]:
        """The residuals (:func:`~tagbot.gesture.refine_kernels.residuals`) at instants ``tau``."""
        goal, goal_first, grid, grid_first = self.goal_arrays
        return refine_kernels.residuals(
            *self.plan_arrays(strokes),
            tau,
            goal,
            goal_first,
            self.goal_index,
            grid,
            grid_first,
            *self.contour_arrays,
            self.reach,
            self.size,
            END_TOLERANCE,
        )


def _nearest_samples(strokes: Strokes, curves: list[Array]) -> list[Index]:
    """Per curve, the samples nearest to its targets, in order along it."""
    out = []
    for k, curve in enumerate(curves):
        first = np.array([0, len(curve)], dtype=np.intp)
        grid = refine_kernels.path_buckets(np.ascontiguousarray(curve, dtype=float), first)
        targets = strokes.targets[strokes.target_slice(k)]
        near = [refine_kernels.nearest(curve, *grid, 0, x, y)[0] for x, y in targets]
        out.append(np.maximum.accumulate(np.array(near, dtype=np.intp)))
    return out


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
