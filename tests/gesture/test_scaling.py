"""The geometric fit's cost and shape as the points grow (issue 29): work counted, never timed.

The figures for 1e3..1e5 points are benchmarks/bench_scaling.py's; here the small sizes.
"""

from __future__ import annotations

import importlib
import itertools
import math

import numpy as np
import pytest

from tagbot.gesture import contour, contour_kernels, refine_kernels
from tagbot.gesture.refine import RefineOptions, _Problem
from tagbot.metrics import fit_report

reconstruct = importlib.import_module("tagbot.gesture.reconstruct")


def random_points(n: int) -> np.ndarray:
    """The outside tester's input: ``n`` points uniform in a square, one trace."""
    return np.random.default_rng(0).uniform(0.0, 1000.0, (n, 2))


def spiral(n: int) -> np.ndarray:
    """A dense smooth Archimedean spiral of ten turns (radius 20 to 960) at ``n`` points."""
    theta = np.linspace(0.0, 20.0 * np.pi, n)
    radius = 20.0 + 940.0 * theta / theta[-1]
    return np.column_stack([radius * np.cos(theta), radius * np.sin(theta)])


def refinement_cost(xy: np.ndarray) -> tuple[int, int, int, int]:
    """Contour samples, grid cells, and the nearest-point searches' work (initial instants, one
    evaluation of the residuals) of the refinement of the paper's first estimate of ``xy``."""
    size = float(np.hypot(*np.ptp(xy, axis=0)))
    opts = reconstruct.FitOptions()
    part = reconstruct._analyse(xy, size, "gamma", opts)
    strokes = reconstruct._strokes_of([part], opts)
    problem = _Problem.build(strokes, [part.curve], size, RefineOptions(), [part.dominant])
    header = problem.contour_arrays[1]
    cells = int((header[:, 2] * header[:, 3]).sum())
    initial, residual = problem.search_work(strokes)
    return len(problem.contour), cells, initial, residual


def n_log_n(n: int) -> float:
    return n * math.log(n)


def test_refinement_work_grows_at_most_like_n_log_n():
    """Random points, 1e3 then 4e3: the contour samples, the cells that sort them and the work
    of every nearest-point search grow no faster than n log n (measured: 4.0x each; the fixed
    100 x 100 grid of before held a number of samples per cell growing like n)."""
    small, large = refinement_cost(random_points(1000)), refinement_cost(random_points(4000))
    bound = n_log_n(4000) / n_log_n(1000)  # 4.8
    for name, a, b in zip(("samples", "cells", "initial", "residual"), small, large, strict=True):
        assert b <= bound * a, f"{name}: {a} -> {b}, more than {bound:.2f}x"
    samples, cells = large[:2]
    assert cells <= 3 * samples / refine_kernels.FINEST + 1


@pytest.mark.parametrize(
    "xy",
    [
        random_points(3000),
        spiral(5000),
        np.column_stack([np.linspace(0, 1, 4000), np.zeros(4000)]),  # a line: no area
        np.column_stack([np.linspace(0, 1, 4000), np.linspace(0, 1, 4000)]),  # a diagonal
        np.zeros((50, 2)),  # all at one place
    ],
    ids=["random", "spiral", "line", "diagonal", "point"],
)
def test_path_grid_cells_are_bounded_by_the_points(xy):
    """However the points lie, the per-path grid has at most 3 / FINEST cells per point (one),
    and a query near the points looks at a bounded number of cells and points."""
    first = np.array([0, len(xy)], dtype=np.intp)
    header, start, order = refine_kernels.path_buckets(xy, first)
    assert header[0, 2] * header[0, 3] <= 3 * len(xy) / refine_kernels.FINEST + 1
    assert np.array_equal(np.sort(order), np.arange(len(xy)))
    rng = np.random.default_rng(3)
    queries = xy[rng.integers(0, len(xy), 200)] + rng.normal(scale=1e-3, size=(200, 2))
    work = [refine_kernels.nearest(xy, header, start, order, 0, *q)[1] for q in queries]
    if len(np.unique(xy, axis=0)) > 1:
        assert np.mean(work) < 60


def test_nearest_keeps_to_the_index_range():
    """A search limited to points ``lo..hi`` (through the grid, or one by one) finds the nearest
    of those, not of all."""
    xy = spiral(2000)
    first = np.array([0, len(xy)], dtype=np.intp)
    grid = refine_kernels.path_buckets(xy, first)
    rng = np.random.default_rng(4)
    for _ in range(50):
        lo = int(rng.integers(0, 1900))
        hi = lo + int(rng.integers(0, 100))
        q = rng.uniform(-900, 900, 2)
        found, _ = refine_kernels.nearest(xy, *grid, 0, q[0], q[1], lo, hi)
        d = np.hypot(*(xy[lo : hi + 1] - q).T)
        assert lo <= found <= hi
        assert np.hypot(*(xy[found] - q)) == d.min()
        scanned = refine_kernels._nearest_in(xy, lo, hi, q[0], q[1])
        assert scanned == lo + int(np.argmin(d))


def shape_max(xy: np.ndarray) -> float:
    """The fit's largest shape error, % of the size (the geometric fit)."""
    tag = reconstruct.fit([xy], timing="ignore")
    return 100 * fit_report([xy], tag).shape.max


def test_dense_spiral_fits_no_worse_with_more_points():
    """A dense spiral (10 turns, radius 20 to 960): 4x the points fit no worse (+0.1 % of the
    size), and within 1 % (the inner turns' strokes once turned over 180°, and goals matched to
    the neighbouring turn: 2.6-3.6 % at some sizes)."""
    errors = [shape_max(spiral(n)) for n in (2500, 10_000, 40_000)]
    for fewer, more in itertools.pairwise(errors):
        assert more <= fewer + 0.1, errors
    assert max(errors) < 1.0, errors


def test_no_section_turns_more_than_max_turn():
    """Dominant points: no section between two of them turns more than ``max_turn`` (measured
    as :func:`tagbot.gesture.contour.add_turning_points` does), on a spiral whose turning is
    all in one stretch between salient points."""
    xy = spiral(10_000)
    size = float(np.hypot(*np.ptp(xy, axis=0)))
    opts = reconstruct.FitOptions()
    part = reconstruct._analyse(xy, size, "gamma", opts)
    again = contour.add_turning_points(part.curve, part.dominant, np.radians(180.0), part.support)
    np.testing.assert_array_equal(again, part.dominant)


def reference_drop(xy, points, threshold, span):
    """The salient points' weakest-first dropping, as a plain loop (``np.argmin`` each time)."""

    def turn(a, b, c):
        def at(p, h, q):
            u, w = xy[h] - xy[p], xy[q] - xy[h]
            return abs(math.atan2(u[0] * w[1] - u[1] * w[0], u[0] * w[0] + u[1] * w[1] + 0.0))

        near = at(max(a, b - span), b, min(c, b + span))
        whole = at(a, b, c)
        return np.nan if np.isnan(whole) or np.isnan(near) else max(whole, near)

    points = list(points)
    while len(points) > 2:
        turns = np.array([turn(*points[k : k + 3]) for k in range(len(points) - 2)])
        weakest = int(np.argmin(turns))
        if turns[weakest] >= threshold:
            break
        del points[weakest + 1]
    return np.array(points)


@pytest.mark.parametrize("seed", range(6))
def test_salient_dropping_matches_the_plain_loop(seed):
    """The heap that drops weak salient candidates (O(m log m)) keeps exactly the points the
    plain weakest-first loop keeps, ties included (a zig-zag on a lattice has many equal
    turns)."""
    rng = np.random.default_rng(seed)
    n = 400
    if seed % 2:
        xy = np.cumsum(rng.integers(-1, 2, size=(n, 2)), axis=0).astype(float)
    else:
        xy = np.cumsum(rng.normal(size=(n, 2)), axis=0)
    points = np.unique(np.r_[0, rng.integers(1, n - 1, 80), n - 1]).astype(np.intp)
    threshold, span = np.radians(25.0 + 20.0 * seed), 6
    got = contour_kernels._drop_weak(xy, points, threshold, span)
    np.testing.assert_array_equal(got, reference_drop(xy, points, threshold, span))


def test_long_sparse_traces_are_resampled_at_most_per_point():
    """Random points (a trace hundreds of sizes long): at most SAMPLES_PER_POINT samples per
    point (220 at the resampling step); a trace within SAMPLES steps keeps the step."""
    xy = random_points(2000)
    size = float(np.hypot(*np.ptp(xy, axis=0)))
    opts = reconstruct.FitOptions()
    part = reconstruct._analyse(xy, size, "gamma", opts)
    assert len(part.curve) <= reconstruct.SAMPLES_PER_POINT * len(xy) + 2  # ends, rounding
    assert len(part.curve) >= reconstruct.SAMPLES_PER_POINT * len(xy) * 0.99
    dense = spiral(10_000)
    size = float(np.hypot(*np.ptp(dense, axis=0)))
    assert reconstruct._analyse(dense, size, "gamma", opts).ds <= opts.step * size
