"""Contour analysis (paper §6.1–6.3) on shapes whose answers are known."""

import numpy as np
import pytest

from tagbot.gesture import contour


def arc(radius, start, stop, count=400):
    a = np.linspace(start, stop, count)
    return np.column_stack([radius * np.cos(a), radius * np.sin(a)])


def test_resample_is_uniform_and_keeps_the_ends():
    xy = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 0.0], [3.0, 4.0]])
    out = contour.resample(xy, 0.1)
    steps = np.hypot(*np.diff(out, axis=0).T)
    np.testing.assert_allclose(steps, steps[0], rtol=1e-9)
    assert steps[0] <= 0.1
    np.testing.assert_array_equal(out[[0, -1]], xy[[0, -1]])


def test_smooth_keeps_lines_and_ends():
    line = np.column_stack([np.linspace(0, 10, 101), np.linspace(0, 5, 101)])
    np.testing.assert_allclose(contour.smooth(line, 4.0), line, atol=1e-12)
    noisy = line + np.random.default_rng(0).normal(0, 0.05, line.shape)
    smoothed = contour.smooth(noisy, 4.0)
    np.testing.assert_array_equal(smoothed[[0, -1]], noisy[[0, -1]])
    assert np.std(smoothed[1:-1] - line[1:-1]) < 0.5 * np.std(noisy - line)


@pytest.mark.parametrize("theta", [1e-3, 0.5, 1.0, np.pi / 2, np.pi, 4.0, 6.0])
def test_segment_angle_inverts_eq_19(theta):
    radius = 2.5
    chord = 2 * radius * np.sin(theta / 2)
    area = 0.5 * radius**2 * (theta - np.sin(theta))
    assert contour.segment_angle(chord, area) == pytest.approx(theta, rel=1e-6)


@pytest.mark.parametrize("phi", [0.3, -0.7, 1.2])
def test_arc_deviation_recovers_the_sigma_convention(phi):
    # The ΣΛ* arc from (0, 0) to (1, 0) leaving at -phi from the chord.
    t = np.linspace(0.0, 1.0, 2001)
    theta = -phi + 2 * phi * t
    length = 1.0 / np.sinc(phi / np.pi)
    dx = np.cos(theta) * length / 2000
    dy = np.sin(theta) * length / 2000
    xy = np.column_stack([np.cumsum(dx) - dx[0], np.cumsum(dy) - dy[0]])
    assert contour.arc_deviation(xy) == pytest.approx(phi, rel=1e-2)


def test_salient_points_of_a_square_are_its_corners():
    corners = np.array([[0, 0], [10, 0], [10, 10], [0, 10], [0, 1]], dtype=float)
    xy = contour.resample(corners, 0.05)
    found = contour.salient_points(xy, 10, np.radians(25), np.radians(8))
    np.testing.assert_allclose(xy[found[1:-1]], corners[1:-1], atol=0.1)


def test_a_smooth_circle_has_no_salient_points_but_one_point_per_half_turn():
    xy = arc(10.0, 0.0, 1.9 * np.pi, 1200)
    salient = contour.salient_points(xy, 10, np.radians(25), np.radians(8))
    assert salient.tolist() == [0, len(xy) - 1]
    dominant = contour.add_turning_points(xy, salient)
    assert len(dominant) == 2 + 1  # 342° of turning: one extra point, half-way
    assert dominant[1] == pytest.approx(len(xy) / 2, abs=2)


def test_inflection_of_an_s_curve_is_in_the_middle():
    t = np.linspace(-1, 1, 801)
    xy = np.column_stack([t, 0.3 * np.sin(np.pi * t)])
    q = contour.inflection(xy, 0, 800, 20, np.radians(8))
    assert q == pytest.approx(400, abs=3)
    assert contour.inflection(arc(1.0, 0, 2), 0, 399, 20, np.radians(8)) is None


def test_sharpness_of_a_corner_and_of_an_arc():
    corner = contour.resample(np.array([[0.0, 0.0], [5.0, 5.0], [10.0, 0.0]]), 0.01)
    middle = len(corner) // 2
    assert contour.sharpness(corner, 0, middle, len(corner) - 1) == pytest.approx(1.0, abs=0.01)
    round_ = arc(5.0, 0.2, 2.5)
    assert contour.sharpness(round_, 0, 200, 399) == pytest.approx(0.0, abs=0.01)


def test_decimate_drops_jitter_and_keeps_the_ends():
    rng = np.random.default_rng(1)
    line = np.column_stack([np.linspace(0, 100, 100_000), np.zeros(100_000)])
    noisy = line + rng.normal(0, 0.05, line.shape)
    kept = contour.decimate(noisy, 0.5)
    assert 150 < len(kept) < 250
    np.testing.assert_array_equal(kept[[0, -1]], noisy[[0, -1]])
    assert np.all(np.hypot(*np.diff(kept[:-1], axis=0).T) >= 0.5)
    assert contour.arc_length(kept)[-1] == pytest.approx(100, rel=0.05)
