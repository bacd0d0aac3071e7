"""The fitter's working form: all traces' strokes evaluated at once, and the refinement's
Jacobian checked against finite differences."""

import numpy as np
import pytest

from tagbot.gesture.reconstruct import correct_targets
from tagbot.gesture.refine import (
    RefineOptions,
    _jacobian,
    _Layout,
    _NormalEquations,
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
    result = strokes.evaluate(trace, np.concatenate(times), size)
    for k, plan in enumerate(plans):
        xy, v = evaluate_plan(plan, times[k], size)
        np.testing.assert_allclose(result.xy[trace == k], xy, atol=1e-9)
        np.testing.assert_allclose(result.v[trace == k], v, atol=1e-9)


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


def dense_jacobian(layout, strokes, current):
    """The complex Jacobian in the plan's parameters, a row per instant."""
    indptr, col, value = _jacobian(layout, strokes, current)
    jac = np.zeros((len(current.order), layout.size), dtype=complex)
    for row in range(len(indptr) - 1):
        entries = slice(indptr[row], indptr[row + 1])
        jac[current.order[row], col[entries]] = value[entries]
    return jac


@pytest.mark.parametrize("sigma_model", [False, True])
def test_jacobian_matches_central_differences(sigma_model):
    """Targets, tangents and onsets: the assembled complex Jacobian equals central differences
    of the residuals whose goals are fixed (the contour samples); instants: the velocity."""
    strokes, problem, layout, tau = jacobian_setup(sigma_model)
    current = problem.evaluate(strokes, tau)
    jac = dense_jacobian(layout, strokes, current)
    x = layout.pack(strokes)
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
        rp = problem.evaluate(layout.unpack(strokes, plus), tau).residual[rows]
        rm = problem.evaluate(layout.unpack(strokes, minus), tau).residual[rows]
        numeric = (rp - rm) / (2 * h)
        scale = max(np.abs(numeric).max(), 1.0)
        worst = max(worst, np.abs(jac[rows, column] - numeric).max() / scale)
    assert worst < 1e-5
    # Instants: d(trajectory)/dτ is the velocity.
    k = rows[::5]
    plus, minus = tau.copy(), tau.copy()
    plus[k] += h
    minus[k] -= h
    rp = problem.evaluate(strokes, plus).residual[k]
    rm = problem.evaluate(strokes, minus).residual[k]
    np.testing.assert_allclose((rp - rm) / (2 * h), current.velocity[k], rtol=1e-4, atol=1e-3)


@pytest.mark.parametrize("sigma_model", [False, True])
@pytest.mark.parametrize("damping", [1e-3, 0.5, 40.0])
def test_banded_schur_step_is_the_dense_damped_step(sigma_model, damping):
    """The step with the instants eliminated and the band factored equals the damped
    Gauss-Newton step of the whole system (parameters and instants) solved densely."""
    strokes, problem, layout, tau = jacobian_setup(sigma_model)
    current = problem.evaluate(strokes, tau)
    system = _NormalEquations(layout, strokes, current)
    step, step_tau, predicted = system.solve(damping)
    # The whole real system: the parameters' columns, then one column per forward instant.
    jac = dense_jacobian(layout, strokes, current)
    forward = len(tau)
    instants = np.zeros((len(jac), forward), dtype=complex)
    instants[np.arange(forward), np.arange(forward)] = current.velocity
    full = np.hstack([jac, instants])
    r = current.residual
    a = (full.conj().T @ full).real
    g = (full.conj().T @ r).real
    scale = np.concatenate([system.scale, system.speed2[system.forward_row]])
    # The floored instants' scale stands in for |v|² in both the damping and the curvature.
    a[layout.size :, layout.size :] = np.diag(scale[layout.size :])
    dense = np.linalg.solve(a + damping * np.diag(scale), -g)
    np.testing.assert_allclose(step, dense[: layout.size], rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(step_tau, dense[layout.size :], rtol=1e-7, atol=1e-9)
    both = np.concatenate([step, step_tau])
    assert predicted == pytest.approx(both @ (damping * scale * both - g), rel=1e-9)


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
        return problem.evaluate(strokes, problem.initial_instants(strokes)).cost

    done, misfit = refine(start, contours, size, options)
    assert misfit.shape == (sum(len(c) for c in contours),) and np.all(misfit >= 0)
    assert cost(done) < 0.5 * cost(start)
    for k, contour in enumerate(contours):
        s = done.target_slice(k)
        np.testing.assert_array_equal(done.targets[s.start], contour[0])
        np.testing.assert_array_equal(done.targets[s.stop - 1], contour[-1])
    np.testing.assert_array_equal(done.onsets[done.first_stroke[:-1]], 0.0)
