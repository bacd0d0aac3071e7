"""Shape error and velocity SNR against independent oracles (shapely distances, brute force)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from tagbot.metrics import (
    VELOCITY_CUTOFF,
    clock_velocity_snr,
    recorded_velocity,
    shape_error,
    velocity_snr,
)


def arc_samples(polyline: np.ndarray, spacing: float) -> np.ndarray:
    """The polyline sampled evenly along its arc length, at most ``spacing`` apart, both ends
    included (its first point if it has no length)."""
    xy = np.asarray(polyline, dtype=float)
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    if not along[-1] > 0:
        return xy[:1]
    keep = np.concatenate([[True], np.diff(along) > 0])  # np.interp needs rising lengths
    s = np.linspace(0.0, along[-1], int(np.ceil(along[-1] / spacing)) + 1)
    return np.column_stack([np.interp(s, along[keep], c) for c in xy[keep].T])


def _oracle_distances(query: np.ndarray, polylines: list[np.ndarray]) -> np.ndarray:
    lines = shapely.MultiLineString([p for p in polylines if len(p) > 1])
    return shapely.distance(shapely.points(query), lines)


def _assert_oracles_figures(reference: list[np.ndarray], candidate: list[np.ndarray]) -> None:
    """The shape error against the oracle: samples evenly along each drawing's arc length, each
    measured exactly against the other's segments; the mean at the mean's sampling, the max at
    the fine one."""
    from tagbot.metrics import DENSITY, MEAN_DENSITY

    error = shape_error(reference, candidate)
    figures = []
    for density in (MEAN_DENSITY, DENSITY):
        spacing = error.size / density
        a = np.concatenate([arc_samples(p, spacing) for p in reference])
        b = np.concatenate([arc_samples(p, spacing) for p in candidate])
        a_to_b, b_to_a = _oracle_distances(a, candidate), _oracle_distances(b, reference)
        mean = (a_to_b.sum() + b_to_a.sum()) / (len(a) + len(b)) / error.size
        figures.append((mean, max(a_to_b.max(), b_to_a.max()) / error.size))
    assert error.mean == pytest.approx(figures[0][0], rel=1e-9)
    assert error.max == pytest.approx(figures[1][1], abs=0.5 / DENSITY)
    assert error.max >= figures[0][1] - 1e-12  # never below what the samples already show


@pytest.mark.parametrize("seed", range(5))
def test_shape_error_matches_exact_segment_distances(seed: int) -> None:
    rng = np.random.default_rng(seed)
    reference = [np.cumsum(rng.normal(size=(n, 2)), axis=0) for n in (30, 12)]
    candidate = [p + rng.normal(scale=0.05, size=p.shape) for p in reference]
    _assert_oracles_figures(reference, candidate)


@pytest.mark.parametrize("seed", range(3))
def test_shape_error_of_a_stray_far_stroke_is_exact(seed: int) -> None:
    """A stroke far outside the other drawing (its samples beyond the fine grid's rings, found
    through the coarse grid, which is built only then), and a lone far point."""
    rng = np.random.default_rng(seed)
    reference = [np.cumsum(rng.normal(size=(40, 2)), axis=0)]
    low, high = reference[0].min(axis=0), reference[0].max(axis=0)
    stray = high + (high - low) * rng.uniform(0.3, 2.0) + np.cumsum(rng.normal(size=(6, 2)), 0)
    candidate = [reference[0] + rng.normal(scale=0.05, size=(40, 2)), stray, low[None] - 50.0]
    _assert_oracles_figures(reference, candidate)
    _assert_oracles_figures(candidate, reference)


@pytest.mark.parametrize("height", [0.0137, 0.05, 0.2, 0.61])
def test_shape_error_max_finds_a_peak_between_samples(height: float) -> None:
    """A tent over its base: the farthest point of either from the other is the apex, at
    ``height``, between the arc samples. It is found (from the samples' nearest segments, by
    halving) within half the stated resolution, and never above the exact figure."""
    from tagbot.metrics import DENSITY

    offset = 0.3 / 250  # the apex off the samples
    tent = np.array([[0.0, 0.0], [0.5 + offset, height], [1.0, 0.0]])
    base = np.array([[0.0, 0.0], [1.0, 0.0]])
    for reference, candidate in (([tent], [base]), ([base], [tent])):
        error = shape_error(reference, candidate)
        assert error.max * error.size <= height + 1e-12
        assert error.max * error.size >= height - 0.5 * error.size / DENSITY


def test_shape_error_of_a_long_scribble_is_bounded_and_still_exact() -> None:
    # 10 000 strokes across the box: densified at the fixed density this was 40 million points.
    zigzag = np.column_stack([np.tile([0.0, 1.0], 5000), np.arange(10_000) * 1e-4])
    error = shape_error([zigzag], [zigzag + np.array([0.0, 0.001])])
    assert error.max == pytest.approx(0.001 / error.size, rel=1e-3)
    assert error.mean <= error.max


def _brute_force_snr(t, xy, model_t, model_v, scales, offsets, cutoff=None) -> float:
    grid, v = recorded_velocity(t, xy, cutoff=cutoff)
    model_t = model_t - model_t[0]
    best = -np.inf
    for s in scales:
        for o in offsets:
            tm = (grid - o) / s
            vm = np.column_stack(
                [np.interp(tm, model_t, model_v[:, i], left=0.0, right=0.0) for i in (0, 1)]
            )
            err = v - vm / s
            best = max(best, 10 * np.log10(np.sum(v * v) / np.sum(err * err)))
    return best


def test_velocity_snr_finds_the_time_mapping_of_a_scaled_shifted_copy() -> None:
    model_t = np.linspace(0.0, 1.0, 201)
    model_xy = np.column_stack([np.sin(2 * np.pi * model_t), np.sin(4 * np.pi * model_t) / 2])
    model_v = np.gradient(model_xy, model_t, axis=0)
    scale, offset = 1.7, 0.35
    t = np.concatenate([[0.0], offset + scale * model_t, [offset + scale + 0.4]])
    xy = np.vstack([model_xy[:1], model_xy, model_xy[-1:]])
    db, s, o = velocity_snr(t, xy, model_t, model_v, cutoff=None)  # as the oracle's
    assert s == pytest.approx(scale, rel=5e-3)
    assert o == pytest.approx(offset, abs=5e-3)
    assert db > 20
    # Never worse than a brute-force search over a grid around the truth.
    oracle = _brute_force_snr(
        t, xy, model_t, model_v, scale * np.linspace(0.9, 1.1, 21), np.linspace(0.25, 0.45, 21)
    )
    assert db >= oracle - 1e-9


@pytest.mark.parametrize("seed", range(8))
def test_velocity_snr_ends_near_the_best_mapping_around_it(seed: int) -> None:
    """No (scale, offset) on a fine grid around the mapping found scores more than 0.06 dB
    better: the polish converged (its pattern alone, stopping at 3 % steps, leaves 0.05-0.4 dB
    on 6 of these 8; the error is piecewise quadratic, so the last few hundredths of a dB are
    small local optima of the interpolation). The model starts and ends at rest, as plans do."""
    rng = np.random.default_rng(seed)
    model_t = np.linspace(0.0, 1.2, 241)
    rest = np.sin(np.pi * model_t / 1.2)[:, None] ** 2
    model_v = rest * np.cumsum(rng.normal(size=(241, 2)), axis=0)
    model_xy = np.cumsum(model_v, axis=0) * (model_t[1] - model_t[0])
    t = 0.2 + 1.1 * model_t + rng.normal(0.0, 0.002, model_t.size)  # another writer's clock
    xy = model_xy + rng.normal(0.0, 2e-4, model_xy.shape)
    db, s, o = velocity_snr(t, xy, model_t, model_v)
    scales, offsets = s * (1 + np.linspace(-1e-3, 1e-3, 11)), o + np.linspace(-2e-3, 2e-3, 11)
    near = _brute_force_snr(t, xy, model_t, model_v, scales, offsets, VELOCITY_CUTOFF)
    assert db >= near - 0.06


def test_velocity_snr_cost_follows_the_points_not_the_clock() -> None:
    # 2 000 points over 2 828 "seconds" (a millisecond clock read as seconds): a coarser grid.
    t = np.linspace(0.0, 2828.0, 2000)
    xy = np.column_stack([np.sin(t / 50), np.cos(t / 37)])
    grid, _ = recorded_velocity(t, xy)
    assert len(grid) <= 4 * len(t) + 1


def _two_strokes(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions (px) and velocities of two overlapping straight lognormal strokes (90 and 70 px,
    median delays 0.18 and 0.2 s): a fast handwritten movement, exactly."""
    from scipy.special import erf

    xy, v = np.zeros((t.size, 2)), np.zeros((t.size, 2))
    for t0, mu, sigma, size, angle in ((0.0, 0.18, 0.28, 90.0, 0.3), (0.17, 0.2, 0.32, 70.0, 2.2)):
        e = np.maximum(t - t0, 1e-12)
        z = (np.log(e) - np.log(mu)) / sigma
        direction = np.array([np.cos(angle), np.sin(angle)])
        xy += (0.5 * (1 + erf(z / np.sqrt(2))) * size)[:, None] * direction
        v += (size * np.exp(-0.5 * z * z) / (sigma * e * np.sqrt(2 * np.pi)))[:, None] * direction
    return xy, v


def _against_truth(t: np.ndarray, xy: np.ndarray, cutoff: float | None) -> float:
    grid, v = recorded_velocity(t, xy, cutoff=cutoff)
    _, truth = _two_strokes(grid)
    return 10 * np.log10(np.sum(truth**2) / np.sum((v - truth) ** 2))


def _touch_screen(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The strokes as a 60 Hz touch screen records them: positions rounded to pixels, stamps
    with 2 ms of jitter on a 1 ms clock."""
    t = np.arange(0.0, 1.0, 1 / 60)
    xy, _ = _two_strokes(t)
    stamps = np.maximum.accumulate(np.round((t + rng.normal(0.0, 0.002, t.size)) / 1e-3) * 1e-3)
    return stamps, np.round(xy)


def test_reference_velocity_of_a_touch_screen_capture_is_the_writers() -> None:
    """Against the true velocity of the movement, the low-pass reference of a 60 Hz
    pixel-quantised capture scores >= 23 dB (24.4), the raw differences under 21 dB (19.8);
    and of an exact 1 kHz recording the filter keeps all but -38 dB (41.8: it removes noise,
    not movement; at 10 Hz it was 31.8)."""
    stamps, xy = _touch_screen(np.random.default_rng(1))
    assert _against_truth(stamps, xy, VELOCITY_CUTOFF) >= 23.0
    assert _against_truth(stamps, xy, None) <= 21.0
    dense = np.arange(0.0, 1.0, 0.001)
    assert _against_truth(dense, _two_strokes(dense)[0], VELOCITY_CUTOFF) >= 38.0


def test_reference_velocity_spreads_repeated_stamps() -> None:
    """Events delivered in bursts of three sharing one stamp: spread over the interval to the
    next stamp, the reference still scores >= 24 dB against the truth (25.2; keeping the first
    of each burst only, as raw differences do, it scored 19.2 dB)."""
    stamps, xy = _touch_screen(np.random.default_rng(1))
    stamps[1::3] = stamps[0:-1:3]
    stamps[2::3] = stamps[0:-2:3]
    assert _against_truth(stamps, xy, VELOCITY_CUTOFF) >= 24.0
    # A burst followed by a long pause is spread one sampling interval apart, not over the gap.
    t = np.r_[np.arange(0.0, 0.5, 0.01), [0.5, 0.5, 0.5], np.arange(3.0, 3.5, 0.01)]
    xy = np.column_stack([np.arange(t.size, dtype=float), np.zeros(t.size)])
    grid, v = recorded_velocity(t, xy, cutoff=VELOCITY_CUTOFF)
    inside = (grid > 1.0) & (grid < 2.5)  # the pen rests during the pause
    assert np.abs(v[inside, 0]).max() < 2.0  # 1 px per 2.5 s, not 3 px per 10 ms


@pytest.mark.parametrize(
    ("t", "xy", "message"),
    [
        (None, np.zeros((5, 2)), "velocity: the recording has no time stamps"),
        (np.arange(5.0), np.zeros((4, 2)), "shape (4, 2) for time stamps of shape (5,)"),
        (np.arange(5.0), np.zeros((5, 3)), "positions of shape (5, 3) for time stamps"),
        (np.zeros((5, 1)), np.zeros((5, 2)), "of shape (5, 1) (expected (N, 2) and (N,))"),
        (np.array([0.0, 0.01]), np.zeros((2, 2)),
         "velocity: the recording needs at least 3 samples over 3·dt"),
    ],
)  # fmt: skip
def test_reference_velocity_refuses_a_recording_it_cannot_read(t, xy, message) -> None:
    with pytest.raises(ValueError) as refused:
        recorded_velocity(t, xy, cutoff=VELOCITY_CUTOFF)
    assert message in str(refused.value) and str(refused.value).startswith("velocity: ")


def test_reference_velocity_cost_is_linear() -> None:
    """Four times the samples (up to 200 000, about an hour at 60 Hz) cost about four times
    as much (4.5 for n log n, up to about 6 where the larger arrays leave the cache), not
    sixteen: the ratio of the best of five timings each, which holds on a busy host as on an
    idle one (a ratio of 9.5 was seen under mutmut's tracing with three; the absolute time is
    the benchmark's)."""
    import time

    def cost(n: int) -> float:
        t = np.arange(n) / 60.0
        xy = np.column_stack([np.sin(t), np.cos(t / 3)])
        best = math.inf
        for _ in range(5):
            started = time.perf_counter()
            grid, _ = recorded_velocity(t, xy, cutoff=VELOCITY_CUTOFF)
            best = min(best, time.perf_counter() - started)
            assert len(grid) <= 4 * n + 1
        return best

    cost(1_000)  # compiled and warm
    assert cost(200_000) < 10.0 * cost(50_000)


def test_velocity_snr_never_misses_the_shared_clock() -> None:
    """A model on the recording's own clock whose start falls between two grid steps: the best
    mapping is at least the shared clock's figure (the grid of offsets alone can miss it)."""
    rng = np.random.default_rng(7)
    for start in rng.uniform(-0.2, 0.05, 6):
        stamps, xy = _touch_screen(rng)
        model_t = start + np.arange(0.0, 1.2, 0.005)
        _, model_v = _two_strokes(model_t)
        for cutoff in (VELOCITY_CUTOFF, None):
            best, _, _ = velocity_snr(stamps, xy, model_t, model_v, cutoff=cutoff)
            shared = clock_velocity_snr(stamps, xy, model_t, model_v, cutoff)
            assert best >= shared - 1e-9, (start, cutoff, best, shared)


def test_reference_velocity_keeps_uniform_motion_to_its_ends() -> None:
    """A pen moving at constant velocity from the first sample to the last (it touched down and
    lifted off in motion): the low-pass reference keeps that velocity at every instant,
    the ends included (they are extended by point reflection, not held at rest)."""
    t = np.arange(0.0, 0.5, 1 / 60)
    xy = np.column_stack([120.0 * t + 3.0, -40.0 * t])
    _, v = recorded_velocity(t, xy, cutoff=VELOCITY_CUTOFF)
    assert np.allclose(v, [120.0, -40.0], rtol=0, atol=1e-6)


@pytest.mark.parametrize("seed", range(12))
def test_the_fastest_stroke_is_the_dense_argmax_over_all_strokes(seed):
    from tagbot.metrics import _fastest_stroke
    from tagbot.model.motion import sample_plan
    from tagbot.model.plan import Tag, random_plan

    plan = random_plan(np.random.default_rng(seed))
    tag = Tag((plan,))
    t, _, _ = sample_plan(tag, 0, 0.005)
    # The oracle: every stroke's speed D·Λ at every instant (samples × strokes).
    elapsed = np.maximum(t[:, None] - plan.onsets[None, :], np.finfo(float).tiny)
    z = (np.log(elapsed) - plan.mu) / plan.sigma
    speed = plan.geometry.length * np.exp(-0.5 * z * z) / (plan.sigma * elapsed)
    speed[t[:, None] <= plan.onsets[None, :]] = 0.0
    np.testing.assert_array_equal(_fastest_stroke(plan, t, tag.size), np.argmax(speed, axis=1))


def test_a_report_imports_no_kd_tree_it_does_not_use() -> None:
    """Only crowded drawings and machine runs need scipy's KD-tree; ``tagbot fit`` should not
    pay for importing ``scipy.spatial`` (about 70 ms) on every ordinary tag."""
    import subprocess
    import sys

    script = (
        "import sys, numpy as np\n"
        "from tagbot.inputs import Trace\n"
        "from tagbot.metrics import fit_report\n"
        "from tagbot.model.plan import Tag, random_plan\n"
        "tag = Tag((random_plan(np.random.default_rng(3)),))\n"
        "report = fit_report([Trace(tag.sample(0.005).xy)], tag)\n"
        "assert report.shape.mean < 1e-3, report\n"
        "print('scipy.spatial' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"


def test_the_ink_is_measured_without_cutting_corners():
    """A fast plan sampled every 5 ms would cut its corners by its chords: the measured ink's
    chords keep within the shape error's precision of the path (checked at 20 instants inside
    each), from its touch-down to its lift-off; a straight stroke keeps its 5 ms samples."""
    from tagbot.metrics import DENSITY, ink_polyline
    from tagbot.model.motion import evaluate_plan
    from tagbot.model.plan import Plan

    fast = Plan([[0, 0], [100, 0], [100, 100], [0, 100]], [0, 0.01, 0.01], [-4.0] * 3, [0.3] * 3,
                [0.0, 0.5, -0.5], [0.0] * 3, 0.0, (0.005, 0.05))  # fmt: skip
    size = float(np.hypot(100, 100))
    xy = ink_polyline(fast, size)
    down, up = fast.ink_window(size)
    dense = np.linspace(down, up, 200_001)
    path, _ = evaluate_plan(fast, dense, size)
    # Each path point's distance to the polyline (its nearest chord) within the precision.
    from shapely import LineString, Point

    line = LineString(xy)
    worst = max(line.distance(Point(p)) for p in path[::50])
    assert worst <= size / (2 * DENSITY) * 1.05
    every_5ms = evaluate_plan(fast, np.minimum(down + 0.005 * np.arange(11), up), size)[0]
    assert max(LineString(every_5ms).distance(Point(p)) for p in path[::50]) > 10 * worst
    ends, _ = evaluate_plan(fast, [down, up], size)
    np.testing.assert_allclose(xy[[0, -1]], ends, atol=1e-9)
    slow = Plan([[0, 0], [100, 0]], [0.0], [np.log(2.0)], [0.3], [0.0], [0.0])
    assert len(ink_polyline(slow, 100.0)) == math.ceil(slow.end(100.0) / 0.005 - 1e-9) + 1


def test_velocity_snr_on_the_tags_clock_and_trace_by_trace():
    """Two traces recorded from known plans: on their own clock both figures are high; with the
    second trace's stamps 0.1 s late, trace by trace its offset is found (no scaling), while on
    the tag's clock one offset cannot suit both traces."""
    from tagbot.gesture.timing import simulated_capture
    from tagbot.inputs import Trace
    from tagbot.metrics import tag_clock_snr
    from tagbot.model.plan import Plan, Tag, random_timed_plan

    rng = np.random.default_rng(2)
    first = random_timed_plan(rng)
    second = random_timed_plan(rng)
    size = 200.0
    gap = first.end(size) + 0.3
    second = Plan(second.targets + 100, second.dt, second.mu, second.sigma, second.phi1,
                  second.phi2, gap)  # fmt: skip
    tag = Tag((first, second))
    a = simulated_capture(first, rng, noise=0.0)
    b = simulated_capture(second, rng, noise=0.0)
    clock, each = tag_clock_snr([a, b], tag)
    assert clock > 25 and each > 25 and clock <= each + 1e-9
    late = Trace(b.xy, b.t + 0.1)
    clock_late, each_late = tag_clock_snr([a, late], tag)
    assert each_late == pytest.approx(each, abs=1.0)  # its own offset found
    assert clock_late < each_late - 6  # one offset for both: the lateness costs
    far = Trace(b.xy, b.t + 1.0)  # beyond the offsets searched: no scaling, no rescue
    assert tag_clock_snr([a, far], tag)[1] < each - 10
