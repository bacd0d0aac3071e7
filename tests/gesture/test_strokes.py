"""The fitter's working form: all traces' strokes evaluated at once, and the refinement's
Jacobian checked against finite differences."""

import numpy as np
import pytest

from tagbot.gesture import refine_kernels as kernels
from tagbot.gesture.reconstruct import correct_targets
from tagbot.gesture.refine import (
    ANGLE_STEP,
    JACOBIAN_TAIL,
    REST,
    RefineOptions,
    _Layout,
    _Problem,
    refine,
)
from tagbot.gesture.strokes import Strokes
from tagbot.model.motion import evaluate_plan
from tagbot.model.plan import random_plan


def random_plans(seed, count=4, sigma_model=False):
    rng = np.random.default_rng(seed)
    return [random_plan(rng, sigma_model=sigma_model) for _ in range(count)]


def samples(plans, size, per_plan, rng):
    """Sorted random instants per plan, some before the start and after the end."""
    trace, times = [], []
    for k, plan in enumerate(plans):
        t = np.sort(rng.uniform(-0.2, plan.end(size) + 0.3, per_plan))
        trace.append(np.full(per_plan, k))
        times.append(t)
    return np.concatenate(trace), times


@pytest.mark.parametrize("sigma_model", [False, True])
def test_all_traces_at_once_match_each_plan_alone(sigma_model):
    plans = random_plans(3, sigma_model=sigma_model)
    strokes = Strokes.of(plans)
    size = 150.0
    trace, times = samples(plans, size, 200, np.random.default_rng(0))
    all_xy, all_v = strokes.evaluate(trace, np.concatenate(times), size)
    for k, plan in enumerate(plans):
        xy, v = evaluate_plan(plan, times[k], size)
        np.testing.assert_allclose(all_xy[trace == k], xy, atol=1e-9)
        np.testing.assert_allclose(all_v[trace == k], v, atol=1e-9)


def test_plans_round_trip_through_strokes():
    plans = random_plans(5)
    back = Strokes.of(plans).plans()
    for a, b in zip(plans, back, strict=True):
        for field in ("targets", "mu", "sigma", "phi1", "phi2"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
        np.testing.assert_allclose(a.dt, b.dt, atol=1e-12)


def test_eq22_on_all_traces_at_once_is_eq22_on_each():
    """Batching is an implementation detail: each trace's targets move as they would alone."""
    plans = [p.at(0.0) for p in random_plans(11, count=3)]
    strokes = Strokes.of(plans)
    tolerance = np.full(len(plans), 1e-6)
    both = correct_targets(strokes, 200.0, tolerance, 10)
    assert not np.allclose(both.targets, strokes.targets)  # the targets did move
    for k, plan in enumerate(plans):
        one = correct_targets(Strokes.of([plan]), 200.0, tolerance[:1], 10)
        np.testing.assert_allclose(both.targets[both.target_slice(k)], one.targets, atol=1e-9)


def jacobian_setup(sigma_model, seed=4):
    plans = random_plans(seed, count=2, sigma_model=sigma_model)
    size = 200.0
    # Contours: the plans themselves, shifted a little, so residuals are not zero.
    curves = []
    for plan in plans:
        t = np.linspace(0, plan.end(size), 300)
        xy, _ = evaluate_plan(plan, t, size)
        curves.append(xy + np.column_stack([np.sin(t * 7), np.cos(t * 5)]))
    strokes = Strokes.of(plans)
    options = RefineOptions(arcs_only=sigma_model)
    problem = _Problem.build(strokes, curves, size, options)
    layout = _Layout(strokes, sigma_model)
    tau = problem.initial_instants(strokes)
    return strokes, problem, layout, tau


def pack(layout, strokes):
    arrays = _Problem.plan_arrays(strokes)
    targets, onsets, _, _, phi1, phi2, first_stroke = arrays
    return kernels.pack(targets, onsets, phi1, phi2, first_stroke, *layout.columns, layout.size)


def unpack(layout, strokes, x):
    arrays = _Problem.plan_arrays(strokes)
    targets, onsets, phi1, phi2 = kernels.unpack(
        x, arrays[0], arrays[1], *arrays[4:7], *layout.columns
    )
    return strokes.replace(targets=targets, onsets=onsets, phi1=phi1, phi2=phi2)


def by_instant(problem, strokes, tau):
    """Residuals and velocities per instant (forward instants first, then the grid)."""
    instant, _, _, _, residual, velocity, _, _ = problem.residuals(strokes, tau)
    r, v = np.empty_like(residual), np.empty_like(velocity)
    r[instant], v[instant] = residual, velocity
    return r, v


def normal_system(problem, layout, strokes, tau):
    instant, begin, stop, pairs, residual, velocity, _, _ = problem.residuals(strokes, tau)
    arrays = _Problem.plan_arrays(strokes)
    return instant, kernels.system(
        instant, begin, stop, pairs, residual, velocity, arrays[0], arrays[4], arrays[5],
        arrays[6], *layout.columns, ANGLE_STEP, REST, len(tau), layout.size, 0.0,
    )  # fmt: skip


def dense_jacobian(problem, layout, strokes, tau, tail=0.0):
    """The complex Jacobian in the plan's parameters, a row per instant."""
    instant = problem.residuals(strokes, tau)[0]
    indptr, col, values = kernels.jacobian(
        *_jacobian_arguments(problem, layout, strokes, tau, tail)
    )
    jac = np.zeros((len(instant), layout.size), dtype=complex)
    for row in range(len(indptr) - 1):
        entries = slice(indptr[row], indptr[row + 1])
        jac[instant[row], col[entries]] = values[entries]
    return jac


def _jacobian_arguments(problem, layout, strokes, tau, tail):
    instant, begin, stop, pairs, _, _, _, _ = problem.residuals(strokes, tau)
    chords = np.column_stack([strokes.chords.real, strokes.chords.imag])
    return (
        begin, stop, pairs, chords, strokes.first_stroke, strokes.phi1, strokes.phi2,
        layout.arcs_only, ANGLE_STEP, *layout.columns[:3], len(instant), tail,
    )  # fmt: skip


@pytest.mark.parametrize("sigma_model", [False, True])
def test_jacobian_without_the_strokes_tails_is_close_and_sparser(sigma_model):
    """Treating a stroke within JACOBIAN_TAIL of not started or complete as such (in the
    Jacobian only) changes no entry by more than 0.5 % of its column's largest, and drops many
    entries. (The onsets' columns change most: early in a stroke, when its CDF is 1e-4, its
    speed is still ~0.3 % of its peak.)"""
    strokes, problem, layout, tau = jacobian_setup(sigma_model)
    exact = dense_jacobian(problem, layout, strokes, tau)
    trimmed = dense_jacobian(problem, layout, strokes, tau, JACOBIAN_TAIL)
    scale = np.maximum(np.abs(exact).max(axis=0), 1.0)
    assert np.max(np.abs(trimmed - exact) / scale) < 50 * JACOBIAN_TAIL
    assert np.count_nonzero(trimmed) < 0.8 * np.count_nonzero(exact)


@pytest.mark.parametrize("sigma_model", [False, True])
def test_jacobian_matches_central_differences(sigma_model):
    """Targets, tangents and onsets: the assembled complex Jacobian equals central differences
    of the residuals whose goals are fixed (the contour samples); instants: the velocity."""
    strokes, problem, layout, tau = jacobian_setup(sigma_model)
    _, velocity = by_instant(problem, strokes, tau)
    jac = dense_jacobian(problem, layout, strokes, tau)
    x = pack(layout, strokes)
    forward = len(tau)
    # Outside its window a stroke counts as not started or complete (within 1e-6 of the size):
    # instants at a window's edge see that step, not a derivative. Leave them out.
    t_on, t_off = strokes.windows(problem.size)
    edges = np.concatenate([t_on, t_off])
    same = problem.goal_trace[:, None] == np.concatenate([strokes.trace, strokes.trace])[None]
    near = np.where(same, np.abs(tau[:, None] - edges[None]), np.inf).min(axis=1)
    rows = np.flatnonzero(near > 1e-4)
    assert len(rows) > 0.7 * forward  # many goals near the end map to where the pen stops
    h = 1e-6
    worst = 0.0
    for column in range(layout.size):
        plus, minus = x.copy(), x.copy()
        plus[column] += h
        minus[column] -= h
        rp = by_instant(problem, unpack(layout, strokes, plus), tau)[0][rows]
        rm = by_instant(problem, unpack(layout, strokes, minus), tau)[0][rows]
        numeric = (rp - rm) / (2 * h)
        scale = max(np.abs(numeric).max(), 1.0)
        worst = max(worst, np.abs(jac[rows, column] - numeric).max() / scale)
    assert worst < 1e-5
    # Instants: d(trajectory)/dτ is the velocity.
    k = rows[::5]
    plus, minus = tau.copy(), tau.copy()
    plus[k] += h
    minus[k] -= h
    rp = by_instant(problem, strokes, plus)[0][k]
    rm = by_instant(problem, strokes, minus)[0][k]
    np.testing.assert_allclose((rp - rm) / (2 * h), velocity[k], rtol=1e-4, atol=1e-3)


@pytest.mark.parametrize("sigma_model", [False, True])
@pytest.mark.parametrize("damping", [1e-3, 0.5, 40.0])
def test_banded_schur_step_is_the_dense_damped_step(sigma_model, damping):
    """The step with the instants eliminated and the band factored equals the damped
    Gauss-Newton step of the whole system (parameters and instants) solved densely."""
    strokes, problem, layout, tau = jacobian_setup(sigma_model)
    instant, normal = normal_system(problem, layout, strokes, tau)
    a, b, g, indptr, col, u, g_t, speed2, forward_row, scale = normal
    step, step_t, predicted, ok = kernels.damped_step(
        a, b, scale, g, indptr, col, u, g_t, speed2, forward_row, damping
    )
    assert ok
    forward = len(tau)
    step_tau = np.empty(forward)
    step_tau[instant[forward_row]] = step_t[forward_row]
    floored = np.empty(forward)
    floored[instant[forward_row]] = speed2[forward_row]
    # The whole real system: the parameters' columns, then one column per forward instant.
    jac = dense_jacobian(problem, layout, strokes, tau)
    r, velocity = by_instant(problem, strokes, tau)
    instants = np.zeros((len(jac), forward), dtype=complex)
    instants[np.arange(forward), np.arange(forward)] = velocity[:forward]
    full = np.hstack([jac, instants])
    normal_matrix = (full.conj().T @ full).real
    gradient = (full.conj().T @ r).real
    # The floored instants' scale stands in for |v|² in both the damping and the curvature.
    normal_matrix[layout.size :, layout.size :] = np.diag(floored)
    d = np.concatenate([scale, floored])
    dense = np.linalg.solve(normal_matrix + damping * np.diag(d), -gradient)
    np.testing.assert_allclose(step, dense[: layout.size], rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(step_tau, dense[layout.size :], rtol=1e-7, atol=1e-9)
    both = np.concatenate([step, step_tau])
    assert predicted == pytest.approx(both @ (damping * d * both - gradient), rel=1e-9)


def test_refinement_lowers_the_cost_and_keeps_the_ends():
    plans = random_plans(9, count=2)
    size = 200.0
    contours = []
    for plan in plans:
        t = np.linspace(0, plan.end(size), 300)
        xy, _ = evaluate_plan(plan, t, size)
        contours.append(xy * 1.02 + np.column_stack([np.sin(5 * t), np.cos(3 * t)]))
    targets = np.concatenate([p.targets for p in plans])
    start = Strokes.of(plans)
    for k, contour in enumerate(contours):
        s = start.target_slice(k)
        targets[s.start], targets[s.stop - 1] = contour[0], contour[-1]
    start = start.replace(targets=targets)
    options = RefineOptions()

    def cost(strokes):
        problem = _Problem.build(strokes, contours, size, options)
        residual = problem.residuals(strokes, problem.initial_instants(strokes))[4]
        return float(np.sum(np.abs(residual) ** 2))

    done, misfit = refine(start, contours, size, options)
    assert misfit.shape == (sum(len(c) for c in contours),) and np.all(misfit >= 0)
    assert cost(done) < 0.5 * cost(start)
    for k, contour in enumerate(contours):
        s = done.target_slice(k)
        np.testing.assert_array_equal(done.targets[s.start], contour[0])
        np.testing.assert_array_equal(done.targets[s.stop - 1], contour[-1])
    np.testing.assert_array_equal(done.onsets[done.first_stroke[:-1]], 0.0)


@pytest.mark.parametrize("cell", [0.3, 2.0, 50.0, None])
def test_nearest_contour_sample_is_the_nearest(cell):
    """The bucket grid's nearest point of a group equals a KD-tree's, for queries inside and
    far outside the points, with cells much smaller and larger than their spacing, and with
    each group's own cells (``None``: :func:`path_buckets`)."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(1)
    points = np.concatenate(
        [np.cumsum(rng.normal(size=(500, 2)), 0), np.cumsum(rng.normal(size=(300, 2)), 0) + 5]
    )
    first = np.array([0, 500, 800])
    if cell is None:
        header, start, order = kernels.path_buckets(points, first)
    else:
        header, start, order = kernels.buckets(points, first, cell)
    queries = rng.uniform(-60, 60, size=(400, 2))
    for k in range(2):
        group = points[first[k] : first[k + 1]]
        distance, _ = cKDTree(group).query(queries)
        for q, d in zip(queries, distance, strict=True):
            found = kernels.nearest(points, header, start, order, k, q[0], q[1])[0]
            assert first[k] <= found < first[k + 1]
            assert np.hypot(*(points[found] - q)) == pytest.approx(d, abs=1e-12)
