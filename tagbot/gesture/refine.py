"""Least-squares refinement of a reconstructed plan against its contour (beyond the paper).

The paper's reconstruction (§6) places targets so that the trajectory passes through the
dominant points at the critical instants, with tangents and overlaps estimated once from the
contour. Overlapping strokes then bend the trajectory away from the contour between those points.
This step polishes targets, tangents and onset delays together so that the trajectory follows the
whole contour, ICP-style:

1. give each contour sample the time at which the trajectory passes closest to it, and each of
   as many trajectory instants its closest contour point;
2. solve the non-linear least-squares problem ``trajectory(τ_k) ≈ goal_k`` over the plan's
   parameters, with a few evaluations (scipy's trust-region reflective method, ``dt`` kept inside
   ``[dt_min, dt_max]``);
3. repeat from 1 a few times.

Each residual depends only on the strokes active at its time, so the Jacobian is sparse and banded;
scipy's grouped finite differences then cost about (strokes overlapping × parameters per stroke)
evaluations per Jacobian, whatever the number of strokes.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix
from scipy.spatial import cKDTree

from tagbot.errors import PlanError
from tagbot.model.motion import evaluate_plan
from tagbot.model.plan import Plan

Array = NDArray[np.float64]
_PHI_LIMIT = 3.0
"""Tangent deviations stay within ±3 rad while refining (away from the ±π ambiguity)."""
_PATTERN_TOLERANCE = 1e-3
"""Influence below this fraction of the size is left out of the Jacobian's pattern."""


def _onset_slack(dt_range: tuple[float, float]) -> float:
    """How far an onset may move while refining, seconds."""
    return max(0.5 * (dt_range[1] - dt_range[0]), 1e-3)


def refine(
    plan: Plan,
    curve: Array,
    dt_range: tuple[float, float],
    arcs_only: bool = False,
    rounds: int = 2,
    evaluations: int = 6,
    residuals_per_stroke: int = 24,
) -> Plan:
    """``plan`` with targets, tangents and delays adjusted to follow ``curve`` (see module doc).

    The first and last targets stay on the contour's ends and the first stroke's ``dt`` at 0.
    ``arcs_only`` keeps ΣΛ* strokes circular (``phi1 = -phi2``).
    """
    m = len(plan.targets)
    n = m - 1
    count = min(len(curve), max(residuals_per_stroke * n, 32))
    goal_all = curve[np.linspace(0, len(curve) - 1, count).round().astype(np.intp)]
    layout = _Layout(m, arcs_only)
    lower, upper = layout.bounds(plan, dt_range)
    contour_tree = cKDTree(curve)
    for _ in range(rounds):
        size = float(np.hypot(*np.ptp(plan.targets, axis=0)))
        grid = np.linspace(plan.start, plan.end(size), 8 * count)
        points, _ = evaluate_plan(plan, grid)
        # Both ways, like the shape error: each contour sample to the trajectory's closest
        # instant, and the trajectory (every 8th grid instant) to its closest contour point, so
        # that a loop between matched instants is not free.
        _, nearest = cKDTree(points).query(goal_all)
        back = np.arange(0, len(grid), 8)
        _, onto = contour_tree.query(points[back])
        tau = np.concatenate([grid[nearest], grid[back]])
        goal = np.concatenate([goal_all, curve[onto]])
        order = np.argsort(tau, kind="stable")
        tau, goal = tau[order], goal[order]
        sparsity = layout.sparsity(plan, tau, size, _onset_slack(dt_range))
        x0 = np.clip(layout.pack(plan), lower, upper)

        residuals = _residuals(layout, plan, tau, goal, size)

        solution = least_squares(
            residuals,
            x0,
            jac_sparsity=sparsity,
            bounds=(lower, upper),
            max_nfev=evaluations,
            x_scale="jac",
            # scipy's "trf" with bounds cannot take a single parameter (a one-arc plan's phi).
            method="trf" if layout.size > 1 else "dogbox",
        )
        try:
            candidate = layout.unpack(plan, solution.x)
        except PlanError:
            break
        if solution.cost >= 0.5 * float(np.sum(residuals(x0) ** 2)):
            break
        plan = candidate
    return plan


def _residuals(
    layout: _Layout, plan: Plan, tau: Array, goal: Array, size: float
) -> Callable[[Array], Array]:
    """Trajectory minus contour at the times ``tau``, as a function of the solver's vector."""

    def residuals(x: Array) -> Array:
        try:
            trial = layout.unpack(plan, x)
        except PlanError:  # targets collapsed: a large penalty
            return np.full(2 * len(tau), 1e3 * size)
        xy, _ = evaluate_plan(trial, tau, size)
        return (xy - goal).ravel()

    return residuals


class _Layout:
    """How a plan's free parameters sit in the solver's vector.

    ``[interior targets (x, y)…, phi1/phi2 (or phi) per stroke…, onsets of strokes 1..n−1]``.
    Onsets rather than delays: a delay moves every later stroke, an onset only its own, which
    keeps the Jacobian banded. Delays that would turn negative are clamped to 0.
    """

    def __init__(self, m: int, arcs_only: bool) -> None:
        self.m, self.n = m, m - 1
        self.arcs_only = arcs_only
        self.targets = 2 * (m - 2)
        self.angles = self.n if arcs_only else 2 * self.n
        self.size = self.targets + self.angles + (self.n - 1)

    def pack(self, plan: Plan) -> Array:
        angles = plan.phi2 if self.arcs_only else np.column_stack([plan.phi1, plan.phi2]).ravel()
        return np.concatenate([plan.targets[1:-1].ravel(), angles, plan.onsets[1:]])

    def unpack(self, plan: Plan, x: Array) -> Plan:
        targets = plan.targets.copy()
        targets[1:-1] = x[: self.targets].reshape(-1, 2)
        angles = x[self.targets : self.targets + self.angles]
        if self.arcs_only:
            phi1, phi2 = -angles, angles
        else:
            phi1, phi2 = angles[0::2], angles[1::2]
        onsets = np.concatenate([plan.onsets[:1], x[self.targets + self.angles :]])
        dt = np.concatenate([plan.dt[:1], np.maximum(np.diff(onsets), 0.0)])
        return Plan(targets, dt, plan.mu, plan.sigma, phi1, phi2, plan.start)

    def bounds(self, plan: Plan, dt_range: tuple[float, float]) -> tuple[Array, Array]:
        """Tangents within ±3 rad; each onset within half the delay range of where it was."""
        slack = _onset_slack(dt_range)
        onsets = plan.onsets[1:]
        lower = np.concatenate(
            [np.full(self.targets, -np.inf), np.full(self.angles, -_PHI_LIMIT), onsets - slack]
        )
        upper = np.concatenate(
            [np.full(self.targets, np.inf), np.full(self.angles, _PHI_LIMIT), onsets + slack]
        )
        return lower, upper

    def sparsity(self, plan: Plan, tau: Array, size: float, slack: float) -> coo_matrix:
        """Which parameters each residual (x and y at each time in ``tau``) can depend on.

        A residual at time τ depends on the strokes active at τ (their end targets, tangents and
        onsets) and on the target the last completed stroke reached. "Active" here means within
        1e-3 of the size of either end (a finer tolerance only widens the band for effects below
        it), padded by ``slack`` since moving an onset moves its window.
        """
        t_on, t_off = plan.windows(size, _PATTERN_TOLERANCE)
        t_on, t_off = t_on - slack, t_off + slack
        rows, cols = [], []
        k = np.arange(len(tau))
        for j in range(self.n):
            active = k[(tau >= t_on[j]) & (tau <= t_off[j])]
            if not active.size:
                continue
            params = self._stroke_params(j) + self._target_params(j) + self._target_params(j + 1)
            params += self._onset_params(j)
            for p in params:
                rows.append(active)
                cols.append(np.full(active.size, p))
        # The last completed stroke's end target.
        done_order = np.argsort(t_off)
        last_done = np.maximum.accumulate(done_order)
        finished = np.searchsorted(t_off[done_order], tau, side="left")
        has = finished > 0
        reached = np.where(has, last_done[np.maximum(finished - 1, 0)] + 1, 0)
        for w in np.unique(reached[has]):
            hit = k[has & (reached == w)]
            for p in self._target_params(int(w)):
                rows.append(hit)
                cols.append(np.full(hit.size, p))
        r = np.concatenate(rows) if rows else np.zeros(0, np.intp)
        c = np.concatenate(cols) if cols else np.zeros(0, np.intp)
        # Each time gives two residuals (x, y) with the same dependencies.
        r2 = np.concatenate([2 * r, 2 * r + 1])
        c2 = np.concatenate([c, c])
        data = np.ones(len(r2), dtype=np.int8)
        matrix = coo_matrix((data, (r2, c2)), shape=(2 * len(tau), self.size)).tocsr()
        matrix.data[:] = 1
        return matrix

    def _target_params(self, w: int) -> list[int]:
        return [2 * (w - 1), 2 * (w - 1) + 1] if 0 < w < self.m - 1 else []

    def _stroke_params(self, j: int) -> list[int]:
        if self.arcs_only:
            return [self.targets + j]
        return [self.targets + 2 * j, self.targets + 2 * j + 1]

    def _onset_params(self, j: int) -> list[int]:
        return [self.targets + self.angles + (j - 1)] if j > 0 else []
