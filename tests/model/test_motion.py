"""Sampling: exact end points, arcs and spirals against oracles, analytic velocity, cost."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pyclothoids import Clothoid

from tagbot.errors import PlanError
from tagbot.model import euler
from tagbot.model import motion as motion_module
from tagbot.model.lognormal import lognormal_cdf
from tagbot.model.motion import evaluate_plan, evaluate_plans
from tagbot.model.plan import DEFAULT_MU, DEFAULT_SIGMA, END_TOLERANCE, Plan, Tag

from .strategies import plans, random_plan
from .test_euler import HARD_FAMILIES


def single_stroke(p0, p1, phi1, phi2, mu=DEFAULT_MU, sigma=DEFAULT_SIGMA, dt=0.0):
    return Plan([p0, p1], [dt], [mu], [sigma], [phi1], [phi2])


def chain(rng, plans_count=3, targets=7, sigma_model=False, lift=0.3):
    """A tag of random plans, each starting ``lift`` seconds after the previous one ends."""
    built = []
    for _ in range(plans_count):
        plan = random_plan(rng, targets, 0.0, sigma_model)
        if built:
            # Ends only move earlier as the tag grows (the tolerance scales with its size).
            start = built[-1].end(Tag(tuple(built)).size) + lift
            plan = Plan(plan.targets, plan.dt, plan.mu, plan.sigma, plan.phi1, plan.phi2, start)
        built.append(plan)
    return Tag(tuple(built), "sigma" if sigma_model else "gamma")


@pytest.mark.parametrize("sigma_model", [False, True])
def test_each_plan_ends_on_its_last_target(sigma_model):
    tag = chain(np.random.default_rng(1), sigma_model=sigma_model)
    motion = tag.sample(0.01)
    runs = list(motion.runs())
    assert [k for k, _ in runs] == [0, 1, 2]
    for k, rows in runs:
        plan = tag.plans[k]
        assert np.hypot(*(motion.xy[rows.start] - plan.targets[0])) < 1e-9 * tag.size
        assert np.hypot(*(motion.xy[rows.stop - 1] - plan.targets[-1])) < 1e-9 * tag.size
        assert motion.t[rows.stop - 1] >= plan.end(tag.size)
        assert plan.start - 1e-9 <= motion.t[rows.start] < plan.start + 0.01


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plans(), st.sampled_from([0.001, 0.01, 0.037]))
def test_random_plans_end_exactly_whatever_the_overlap(plan, dt):
    tag = Tag((plan,))
    motion = tag.sample(dt)
    assert np.all(np.isfinite(motion.xy)) and np.all(np.isfinite(motion.v))
    assert np.all(motion.pen == 1) and np.all(motion.plan == 0)
    np.testing.assert_allclose(np.diff(motion.t), dt, rtol=1e-9)
    np.testing.assert_array_equal(motion.xy[0], plan.targets[0])
    assert np.hypot(*(motion.xy[-1] - plan.targets[-1])) < 1e-9 * tag.size
    # Before the end the pen may still be travelling; at the end it is within the tolerance.
    t_end = plan.end(tag.size)
    assert motion.t[-2] < t_end <= motion.t[-1]
    np.testing.assert_allclose(motion.speed, np.hypot(*motion.v.T))


def test_remaining_path_at_the_end_is_below_tolerance():
    """Between the last window's end and the plan's end nothing is lost: the tolerance holds."""
    tag = chain(np.random.default_rng(2), plans_count=1, targets=9)
    plan = tag.plans[0]
    t_end = plan.end(tag.size)
    w = lognormal_cdf(t_end, plan.onsets, plan.mu, plan.sigma)
    remaining = np.sum(plan.geometry.length * (1.0 - w))
    assert remaining <= END_TOLERANCE * tag.size * (1 + 1e-9)


@pytest.mark.parametrize("phi", [0.0, 1e-10, 0.5, -1.2, 2.8])
def test_isolated_sigma_stroke_lies_on_its_arc(phi):
    p0, p1 = np.array([3.0, -1.0]), np.array([13.0, 4.0])
    plan = Plan.sigma_model([p0, p1], [0.1], [DEFAULT_MU], [DEFAULT_SIGMA], [phi])
    motion = Tag((plan,), "sigma").sample(0.002)
    chord = p1 - p0
    c = np.hypot(*chord)
    if abs(phi) < 1e-6:  # a straight stroke: on the segment
        cross = chord[0] * (motion.xy[:, 1] - p0[1]) - chord[1] * (motion.xy[:, 0] - p0[0])
        assert np.max(np.abs(cross)) / c < 1e-9 * c
        return
    # Leaving at alpha − phi, the arc turns left for phi > 0: its centre is left of the chord.
    radius = c / (2 * np.sin(phi))
    normal = np.array([-chord[1], chord[0]]) / c
    centre = p0 + chord / 2 + normal * radius * np.cos(phi)
    distance = np.hypot(*(motion.xy - centre).T)
    assert np.max(np.abs(distance - abs(radius))) < 1e-10 * c
    # It leaves at alpha − phi: the first move is along that tangent.
    alpha = np.arctan2(chord[1], chord[0])
    moving = np.flatnonzero(motion.speed > 1e-3 * motion.speed.max())
    heading = np.arctan2(motion.v[moving[0], 1], motion.v[moving[0], 0])
    assert abs(euler.wrap_angle(heading - (alpha - phi))) < 1e-2


def test_isolated_gamma_strokes_match_pyclothoids():
    """Hundreds of random tangent pairs and the hard families, through the sampler."""
    rng = np.random.default_rng(11)
    pairs = [tuple(p) for p in rng.uniform(-np.pi, np.pi, size=(250, 2))] + HARD_FAMILIES
    for phi1, phi2 in pairs:
        p0 = rng.normal(size=2) * 20
        alpha = rng.uniform(-np.pi, np.pi)
        c = 10 ** rng.uniform(-1, 2)
        p1 = p0 + c * np.array([np.cos(alpha), np.sin(alpha)])
        plan = single_stroke(p0, p1, phi1, phi2)
        motion = Tag((plan,)).sample(0.02)
        length = float(plan.geometry.length[0])
        ref = Clothoid.G1Hermite(*p0, alpha + phi1, *p1, alpha + phi2)
        s = ref.length * lognormal_cdf(motion.t, plan.onsets[0], plan.mu[0], plan.sigma[0])
        expected = np.array([[ref.X(si), ref.Y(si)] for si in s])
        tolerance = 1e-8 * c * max(1.0, 1e-3 * length / c)
        # Within the stroke's window the sampler is exact; outside it may round W to 0 or 1.
        inside = (motion.t > plan.windows(Tag((plan,)).size)[0][0]) & (
            motion.t < plan.windows(Tag((plan,)).size)[1][0]
        )
        error = np.hypot(*(motion.xy - expected).T)
        assert np.max(error[inside]) < tolerance, (phi1, phi2)
        assert np.max(error) < END_TOLERANCE * Tag((plan,)).size + tolerance


@pytest.mark.parametrize("sigma_model", [False, True])
def test_analytic_velocity_matches_finite_differences(sigma_model):
    tag = chain(np.random.default_rng(3), plans_count=2, targets=9, sigma_model=sigma_model)
    dt = 1e-4
    motion = tag.sample(dt)
    for _, rows in motion.runs():
        xy, v = motion.xy[rows], motion.v[rows]
        central = (xy[2:] - xy[:-2]) / (2 * dt)
        error = central - v[1:-1]
        snr = 10 * np.log10(np.sum(v[1:-1] ** 2) / np.sum(error**2))
        assert snr >= 80.0


def test_speed_integrates_to_the_path_length():
    tag = chain(np.random.default_rng(4), plans_count=1, targets=10)
    motion = tag.sample(2e-5)
    integral = np.trapezoid(motion.speed, motion.t)
    polyline = np.sum(np.hypot(*np.diff(motion.xy, axis=0).T))
    assert integral == pytest.approx(polyline, rel=1e-6)


def test_isolated_stroke_travels_its_curve_length():
    plan = single_stroke([0.0, 0.0], [30.0, 10.0], 0.9, 1.3)
    tag = Tag((plan,))
    motion = tag.sample(1e-4)
    integral = np.trapezoid(motion.speed, motion.t)
    # Exact but for the truncated tails, which the end tolerance bounds.
    assert abs(integral - plan.geometry.length[0]) < 2 * END_TOLERANCE * tag.size


def test_gamma_arc_strokes_reproduce_the_sigma_model():
    rng = np.random.default_rng(5)
    sigma_tag = chain(rng, plans_count=2, sigma_model=True)
    gamma_tag = Tag(
        tuple(
            Plan(p.targets, p.dt, p.mu, p.sigma, p.phi1, p.phi2, p.start) for p in sigma_tag.plans
        )
    )
    a, b = sigma_tag.sample(0.005), gamma_tag.sample(0.005)
    np.testing.assert_array_equal(a.xy, b.xy)
    np.testing.assert_array_equal(a.v, b.v)


def test_near_arc_spirals_are_continuous_with_the_arc():
    arc = Tag((single_stroke([0, 0], [10, 3], -0.8, 0.8),)).sample(0.005)
    for eps in (1e-12, 1e-7, 1e-4, 1e-2):
        near = Tag((single_stroke([0, 0], [10, 3], -0.8, 0.8 + eps),)).sample(0.005)
        assert np.max(np.hypot(*(near.xy - arc.xy).T)) < 10.5 * eps


def test_pen_lifts_and_gaps():
    tag = chain(np.random.default_rng(6), plans_count=3, lift=0.25)
    motion = tag.sample(0.01)
    assert motion.pen.dtype == np.int8
    lifts = np.flatnonzero(motion.pen == 0)
    assert lifts.size >= 2 * 20
    np.testing.assert_array_equal(motion.plan[lifts], -1)
    np.testing.assert_array_equal(motion.v[lifts], 0.0)
    for k, rows in list(motion.runs())[1:]:
        # While the pen is up it waits where it goes down next.
        np.testing.assert_array_equal(motion.xy[rows.start - 1], tag.plans[k].targets[0])
        assert motion.pen[rows.start - 1] == 0


def test_too_coarse_dt_for_a_lift_is_refused():
    tag = chain(np.random.default_rng(6), plans_count=2, lift=0.03)
    with pytest.raises(PlanError, match=r"dt: 0\.05 s is too coarse for the .* pen lift"):
        tag.sample(0.05)
    tag.sample(0.01)


@pytest.mark.parametrize("dt", [0.0, -0.01, float("nan"), float("inf"), "fast", None])
def test_bad_dt_is_refused(dt):
    tag = chain(np.random.default_rng(0), plans_count=1)
    with pytest.raises(PlanError, match=r"^dt: "):
        tag.sample(dt)


def test_strokes_are_evaluated_only_inside_their_windows(monkeypatch):
    """A long plan: evaluated (sample, stroke) pairs stay far below samples × strokes."""
    evaluated = []
    kernels = motion_module.kernels  # what the sampler calls (behind the tests' argument checks)
    original = kernels.evaluate_plans_into

    def counting(*args):
        evaluated.append(original(*args))  # the pairs it evaluated
        return evaluated[-1]

    monkeypatch.setattr(kernels, "evaluate_plans_into", counting)
    rng = np.random.default_rng(8)
    m = 200
    targets = np.cumsum(rng.normal(size=(m, 2)) * 20, axis=0)
    n = m - 1
    plan = Plan(
        targets,
        np.full(n, 0.25),
        np.full(n, DEFAULT_MU),
        np.full(n, DEFAULT_SIGMA),
        rng.uniform(-1, 1, n),
        rng.uniform(-1, 1, n),
    )
    motion = Tag((plan,)).sample(0.01)
    pairs = sum(evaluated)
    assert 0 < pairs < 0.05 * len(motion) * n
    # …and about the number of samples times the mean overlap.
    t_on, t_off = plan.windows(Tag((plan,)).size)
    assert pairs == pytest.approx(np.sum(t_off - t_on) / 0.01, rel=0.02)


def test_motion_arrays_are_read_only():
    motion = chain(np.random.default_rng(0), plans_count=1).sample(0.01)
    with pytest.raises(ValueError, match="read-only"):
        motion.xy[0, 0] = 1.0


def test_plans_evaluated_together_match_each_plan_on_its_own():
    rng = np.random.default_rng(3)
    plans = [random_plan(rng, 3 + 2 * k, start=0.3 * k) for k in range(4)]
    times = [np.sort(rng.uniform(-0.2, 2.5, 50 + 30 * k)) for k in range(4)]
    together = evaluate_plans(plans, times, 120.0)
    for plan, t, (xy, v) in zip(plans, times, together, strict=True):
        alone_xy, alone_v = evaluate_plan(plan, t, 120.0)
        # The same sums, possibly split at other chunk boundaries: equal to rounding.
        np.testing.assert_allclose(xy, alone_xy, rtol=0, atol=1e-9)
        np.testing.assert_allclose(v, alone_v, rtol=0, atol=1e-7)
    assert evaluate_plans([], [], 1.0) == []


def _reference_evaluate(plan: Plan, t: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Straightforward arrays: every stroke at every time inside its window, none before it,
    its whole chord after it."""
    from scipy.special import ndtr

    from tagbot.model import kernels

    t_on, t_off = plan.windows(size, END_TOLERANCE)
    xy = np.tile(plan.targets[0], (len(t), 1)).astype(float)
    v = np.zeros((len(t), 2))
    for j in range(plan.n_strokes):
        xy[t > t_off[j]] += plan.chords[j]
        rows = np.flatnonzero((t >= t_on[j]) & (t <= t_off[j]))
        elapsed = np.maximum(t[rows] - plan.onsets[j], np.finfo(float).tiny)
        z = (np.log(elapsed) - plan.mu[j]) / plan.sigma[j]
        length = plan.geometry.length[j]
        dx, dy, tx, ty = kernels.evaluate_runs(
            plan.geometry.constants, np.array([j]), np.array([len(rows)]), length * ndtr(z)
        )
        speed = length * np.exp(-0.5 * z * z) / (plan.sigma[j] * elapsed * np.sqrt(2 * np.pi))
        xy[rows] += np.column_stack([dx, dy])
        v[rows] += speed[:, None] * np.column_stack([tx, ty])
    return xy, v


@given(st.lists(plans(max_targets=6), min_size=1, max_size=3), st.integers(0, 2**32 - 1))
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_the_compiled_pass_is_the_reference_evaluation(drawn, seed):
    """All plans in one compiled pass equal each plan evaluated by straightforward arrays, at
    sorted random times (repeated ones, and before and after the motion, among them)."""
    rng = np.random.default_rng(seed)
    times = []
    for plan in drawn:
        t = np.sort(rng.uniform(plan.start - 0.2, plan.end(200.0) + 0.2, int(rng.integers(0, 80))))
        times.append(np.repeat(t, rng.integers(1, 3, len(t))))
    together = evaluate_plans(drawn, times, 200.0)
    for plan, t, (xy, v) in zip(drawn, times, together, strict=True):
        ref_xy, ref_v = _reference_evaluate(plan, t, 200.0)
        scale = max(1.0, float(np.abs(plan.targets).max()))
        np.testing.assert_allclose(xy, ref_xy, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(v, ref_v, rtol=1e-9, atol=1e-9 * scale)


def test_plans_overlapping_in_the_air_hand_over_between_lift_off_and_touch_down():
    """A tail after a lift-off overlapping the next plan's approach: each sample belongs to one
    plan, the pen-down runs are exactly the ink windows, the pen is up in between, and the
    handover lies halfway between the lift-off and the touch-down."""
    rng = np.random.default_rng(3)
    a = random_plan(rng, 6, 0.0, False)
    b = random_plan(rng, 6, 0.0, False)
    size = float(np.hypot(*np.ptp(np.concatenate([a.targets, b.targets]), axis=0)))
    off = 0.6 * a.end(size)
    a = Plan(a.targets, a.dt, a.mu, a.sigma, a.phi1, a.phi2, 0.0, (0.0, off))
    on = off + 0.2  # the second touches down 0.2 s after the first lifts off
    b = Plan(b.targets, b.dt, b.mu, b.sigma, b.phi1, b.phi2, off - 0.1, (0.3, b.end(size) - off))
    tag = Tag((a, b))
    assert b.start < a.end(tag.size)  # the motions overlap in the air
    motion = tag.sample(0.01)
    runs = list(motion.runs())
    assert [k for k, _ in runs] == [0, 1]
    (_, first), (_, second) = runs
    assert motion.t[first.start] == pytest.approx(0.0)
    assert motion.t[first.stop - 1] <= off + 1e-9 < motion.t[first.stop]
    assert motion.t[second.start - 1] < on - 1e-9 <= motion.t[second.start]
    handover = 0.5 * (off + on)
    before = motion.t < handover - 1e-9
    xy_a, _ = evaluate_plan(a, motion.t[before & (motion.t > 0.0)], tag.size)
    np.testing.assert_allclose(motion.xy[before & (motion.t > 0.0)], xy_a, atol=1e-12)
    after = motion.t > handover + 0.01
    xy_b, _ = evaluate_plan(b, motion.t[after], tag.size)
    np.testing.assert_allclose(motion.xy[after], xy_b, atol=1e-12)
    assert np.all(motion.pen[first.stop : second.start] == 0)
    with pytest.raises(PlanError, match=r"dt: 0\.3 s is too coarse for the 0\.2 s pen lift"):
        tag.sample(0.3)
    # A plan whose approach in the air starts before the previous plan even starts: its
    # motion is cut at the handover all the same.
    delays = b.dt.copy()
    delays[0] += on + 0.5  # starts at -0.5 s, moves once the first has lifted off
    early = Plan(b.targets, delays, b.mu, b.sigma, b.phi1, b.phi2, -0.5, (on + 0.5, on + 0.8))
    motion = Tag((a, early)).sample(0.01)
    assert [k for k, _ in motion.runs()] == [0, 1]
    assert motion.t[0] == pytest.approx(0.0) and motion.plan[0] == 0
