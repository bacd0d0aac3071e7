"""Sampling instants behind recorded stamps (tagbot.inputs.stamps): the compiled kernels
against array implementations kept here, and what the estimate does on known clocks."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import ArrayLike, NDArray

from tagbot.inputs.stamps import (
    BLENDS,
    GAP,
    REGULAR,
    SMOOTHING,
    regular_instants,
    roughness,
    sample_instants,
    spread_stamps,
)
from tagbot.model.plan import Tag, random_timed_plan

Array = NDArray[np.float64]

# --- reference implementations (numpy) ---------------------------------------------------


def _ref_spread_stamps(t: ArrayLike) -> Array:
    """Time stamps with each run of equal (or out-of-order) stamps spread evenly over the
    interval to the next distinct stamp, at most one median sampling interval apart."""
    t = np.asarray(t, dtype=float)
    if t.size < 2 or np.all(np.diff(t) > 0):
        return t
    t = np.maximum.accumulate(t)
    new = np.concatenate([[True], np.diff(t) > 0])
    starts = np.flatnonzero(new)
    steps = np.diff(t[starts])
    interval = float(np.median(steps)) if steps.size else 0.0
    group = np.cumsum(new) - 1
    counts = np.diff(np.append(starts, t.size))
    width = np.append(steps, interval)  # the last run: one median interval
    spacing = np.minimum(width / counts, interval)
    rank = np.arange(t.size) - starts[group]
    return t[starts][group] + spacing[group] * rank


def _ref_regular_instants(t: ArrayLike, width: float = SMOOTHING, gap: float = GAP) -> Array:
    """The instants of a steady sampler behind stamps ``t`` (increasing): per segment between
    intervals longer than ``gap`` median intervals, a Gaussian-weighted (``width`` samples)
    local-linear regression of the stamps on the sample number. Exact on a steady clock."""
    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    steps = dt[dt > 0]
    if steps.size < 2:
        return t.copy()
    cuts = np.flatnonzero(dt > gap * float(np.median(steps))) + 1
    out = t.copy()
    reach = int(np.ceil(3.0 * width))
    k = np.arange(-reach, reach + 1, dtype=float)
    w = np.exp(-0.5 * (k / width) ** 2)
    kernels = (w, w * k, w * k * k)
    for segment in np.split(np.arange(t.size), cuts):
        if segment.size < 3:
            continue
        ts = t[segment]
        ones = np.ones(ts.size)
        # Window sums around each sample i of w(j − i)·(j − i)^p·{1, t_j}.
        s0, s1, s2 = (_ref_window_sum(ones, kern) for kern in kernels)
        t0, t1 = _ref_window_sum(ts, kernels[0]), _ref_window_sum(ts, kernels[1])
        det = s0 * s2 - s1 * s1
        fitted = (t0 * s2 - t1 * s1) / np.where(det > 0, det, 1.0)
        out[segment] = np.where(det > 1e-12, fitted, ts)
    return np.maximum.accumulate(out)


def _ref_window_sum(x: Array, kernel: Array) -> Array:
    """``Σ_k kernel[k]·x[i + k − reach]`` for every ``i``, terms outside ``x`` left out."""
    reach = kernel.size // 2
    padded = np.concatenate([np.zeros(reach), x, np.zeros(reach)])
    return np.convolve(padded, kernel[::-1], mode="valid")


def _ref_roughness(t: ArrayLike, xy: ArrayLike) -> float:
    """How much the velocity by sample differences (under instants ``t``) changes from one
    interval to the next, relative to its energy: ``Σ|Δv|² / Σ|v|²``."""
    t, xy = np.asarray(t, dtype=float), np.asarray(xy, dtype=float)
    dt = np.diff(t)
    keep = dt > 0
    v = np.diff(xy, axis=0)[keep] / dt[keep, None]
    energy = float(np.sum(v * v))
    if v.shape[0] < 3 or not energy > 0:
        return 0.0
    dv = np.diff(v, axis=0)
    return float(np.sum(dv * dv)) / energy


def _ref_sample_instants(t: ArrayLike, xy: ArrayLike) -> tuple[Array, float]:
    """The instants at which samples ``xy`` stamped ``t`` were most likely taken, and the weight
    given to a steady sampler's instants (0: the stamps as recorded; see the module doc)."""
    t = _ref_spread_stamps(t)
    dt = np.diff(t)
    steps = dt[dt > 0]
    if steps.size < 3:
        return t, 0.0
    median = float(np.median(steps))
    if float(np.max(np.abs(steps - median))) <= REGULAR * median:
        return t, 0.0
    regular = _ref_regular_instants(t)
    best, blend, instants = _ref_roughness(t, xy), 0.0, t
    for a in BLENDS[1:]:
        candidate = (1.0 - a) * t + a * regular
        score = _ref_roughness(candidate, xy)
        if score < best * (1.0 - 1e-9):
            best, blend, instants = score, a, candidate
    return instants, blend


# --- the kernels equal the references ----------------------------------------------------


@st.composite
def stamped(draw: st.DrawFn) -> tuple[Array, Array]:
    """Stamps with repeats, bursts, gaps and jitter, and positions along a wavy path."""
    n = draw(st.integers(3, 120))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    interval = draw(st.sampled_from([0.005, 0.016, 0.033]))
    steps = interval * rng.choice([0.0, 0.3, 1.0, 1.0, 1.0, 2.0, 3.0, 40.0], n - 1)
    steps += rng.normal(0.0, draw(st.sampled_from([0.0, 0.1, 0.5])) * interval, n - 1)
    t = np.concatenate([[0.0], np.cumsum(np.maximum(steps, 0.0))])
    t = np.round(t / 0.001) * 0.001 if draw(st.booleans()) else t
    s = np.linspace(0.0, 3.0, n)
    xy = np.column_stack([10 * np.cos(s) + s, 10 * np.sin(2 * s)]) + rng.normal(0, 0.05, (n, 2))
    return t, xy


@settings(max_examples=150, deadline=None)
@given(stamped())
def test_the_kernels_equal_the_array_references(case: tuple[Array, Array]) -> None:
    t, xy = case
    spread = spread_stamps(t)
    np.testing.assert_allclose(spread, _ref_spread_stamps(t), rtol=0, atol=1e-12)
    assert np.all(np.diff(spread) >= 0)
    np.testing.assert_allclose(
        regular_instants(spread), _ref_regular_instants(spread), rtol=0, atol=1e-9
    )
    assert roughness(spread, xy) == pytest.approx(_ref_roughness(spread, xy), rel=1e-9, abs=1e-12)
    instants, blend = sample_instants(t, xy)
    expected, expected_blend = _ref_sample_instants(t, xy)
    assert blend == expected_blend
    np.testing.assert_allclose(instants, expected, rtol=0, atol=1e-9)
    assert np.all(np.diff(instants) >= 0)


# --- what the estimate does ---------------------------------------------------------------


def _capture(kind: str, rng: np.random.Generator) -> tuple[Array, Array, Array]:
    """True sampling instants, stamps and positions of a random timed plan."""
    motion = Tag((random_timed_plan(rng),)).sample(0.001)
    start, end = motion.t[0], motion.t[-1]
    if kind == "mouse":  # irregular sampling, exact stamps (to the millisecond)
        true = start + np.cumsum(rng.uniform(0.004, 0.03, 2000))
        true = true[true < end]
        stamps = np.round(true, 3)
    elif kind == "frames":  # a steady 30 Hz sampler stamped by the 16 ms frame that read it
        true = np.arange(start, end, 1 / 30)
        stamps = np.maximum.accumulate(np.ceil((true + rng.uniform(0, 0.02, true.size)) / 0.016))
        stamps = stamps * 0.016
    elif kind == "late":  # a steady 60 Hz sampler, each event late by 0-8 ms
        true = np.arange(start, end, 1 / 60)
        stamps = np.maximum.accumulate(true + rng.uniform(0, 0.008, true.size))
    else:  # a steady 100 Hz clock
        true = np.arange(start, end, 0.01)
        stamps = true.copy()
    xy = np.column_stack([np.interp(true, motion.t, motion.xy[:, i]) for i in (0, 1)])
    return true, stamps, xy + rng.normal(0.0, 0.02, xy.shape)


def _error(instants: Array, true: Array) -> float:
    """RMS error of instants against the truth, after their mean offset (a constant delay)."""
    d = instants - true
    return float(np.sqrt(np.mean((d - d.mean()) ** 2)))


@pytest.mark.parametrize("kind", ["frames", "late"])
def test_a_steady_sampler_behind_noisy_stamps_is_found(kind: str) -> None:
    """Stamps off by delivery: the estimate is at least 2.5 times closer to the true instants
    (median over 10 captures), and never farther."""
    rng = np.random.default_rng(3)
    ratios = []
    for _ in range(10):
        true, stamps, xy = _capture(kind, rng)
        instants, blend = sample_instants(stamps, xy)
        assert blend > 0
        ratios.append(_error(stamps, true) / _error(instants, true))
    assert np.median(ratios) >= 2.5 and min(ratios) >= 1.0, ratios


@pytest.mark.parametrize("kind", ["mouse", "steady"])
def test_exact_stamps_are_kept(kind: str) -> None:
    """Exact stamps, whether the sampling is steady or not, come back as they are."""
    rng = np.random.default_rng(4)
    for _ in range(10):
        _, stamps, xy = _capture(kind, rng)
        instants, blend = sample_instants(stamps, xy)
        assert blend == 0.0
        np.testing.assert_array_equal(instants, spread_stamps(stamps))


def test_a_pause_stays_as_recorded() -> None:
    """A 1 s pause between two bursts of noisy stamps keeps its length (to a few ms)."""
    rng = np.random.default_rng(5)
    true = np.concatenate([np.arange(0, 1, 1 / 30), 2.0 + np.arange(0, 1, 1 / 30)])
    stamps = np.maximum.accumulate(np.ceil((true + rng.uniform(0, 0.02, true.size)) / 0.016))
    stamps *= 0.016
    xy = np.column_stack([np.cos(3 * true), np.sin(2 * true)]) * 50
    instants, blend = sample_instants(stamps, xy)
    assert blend > 0
    k = np.searchsorted(true, 2.0)
    assert instants[k] - instants[k - 1] == pytest.approx(true[k] - true[k - 1], abs=0.03)


def test_constants_are_consistent() -> None:
    assert SMOOTHING > 0 and GAP > 1 and 0 <= REGULAR < 0.1 and BLENDS[0] == 0 and BLENDS[-1] == 1
