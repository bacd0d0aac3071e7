"""Shape error and velocity SNR against independent oracles (shapely distances, brute force)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from tagbot.metrics import recorded_velocity, shape_error, velocity_snr


def _oracle_distances(query: np.ndarray, polylines: list[np.ndarray]) -> np.ndarray:
    lines = shapely.MultiLineString([p for p in polylines if len(p) > 1])
    return shapely.distance(shapely.points(query), lines)


@pytest.mark.parametrize("seed", range(5))
def test_shape_error_matches_exact_segment_distances(seed: int) -> None:
    rng = np.random.default_rng(seed)
    reference = [np.cumsum(rng.normal(size=(n, 2)), axis=0) for n in (30, 12)]
    candidate = [p + rng.normal(scale=0.05, size=p.shape) for p in reference]
    error = shape_error(reference, candidate)
    # The oracle: every sample of one drawing measured exactly against the other's segments;
    # the mean at the mean's sampling, the max at the fine one.
    from tagbot.metrics import DENSITY, MEAN_DENSITY, densify

    figures = []
    for density in (MEAN_DENSITY, DENSITY):
        spacing = error.size / density
        a = np.concatenate([densify(p, spacing) for p in reference])
        b = np.concatenate([densify(p, spacing) for p in candidate])
        a_to_b, b_to_a = _oracle_distances(a, candidate), _oracle_distances(b, reference)
        mean = (a_to_b.sum() + b_to_a.sum()) / (len(a) + len(b)) / error.size
        figures.append((mean, max(a_to_b.max(), b_to_a.max()) / error.size))
    assert error.mean == pytest.approx(figures[0][0], rel=1e-9)
    assert error.max == pytest.approx(figures[1][1], abs=0.5 / DENSITY)
    assert error.max >= figures[0][1] - 1e-12  # never below what the samples already show


def test_shape_error_of_a_long_scribble_is_bounded_and_still_exact() -> None:
    # 10 000 strokes across the box: densified at the fixed density this was 40 million points.
    zigzag = np.column_stack([np.tile([0.0, 1.0], 5000), np.arange(10_000) * 1e-4])
    error = shape_error([zigzag], [zigzag + np.array([0.0, 0.001])])
    assert error.max == pytest.approx(0.001 / error.size, rel=1e-3)
    assert error.mean <= error.max


def _brute_force_snr(t, xy, model_t, model_v, scales, offsets) -> float:
    grid, v = recorded_velocity(t, xy)
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
    db, s, o = velocity_snr(t, xy, model_t, model_v)
    assert s == pytest.approx(scale, rel=5e-3)
    assert o == pytest.approx(offset, abs=5e-3)
    assert db > 20
    # Never worse than a brute-force search over a grid around the truth.
    oracle = _brute_force_snr(
        t, xy, model_t, model_v, scale * np.linspace(0.9, 1.1, 21), np.linspace(0.25, 0.45, 21)
    )
    assert db >= oracle - 1e-9


def test_velocity_snr_cost_follows_the_points_not_the_clock() -> None:
    # 2 000 points over 2 828 "seconds" (a millisecond clock read as seconds): a coarser grid.
    t = np.linspace(0.0, 2828.0, 2000)
    xy = np.column_stack([np.sin(t / 50), np.cos(t / 37)])
    grid, _ = recorded_velocity(t, xy)
    assert len(grid) <= 4 * len(t) + 1
