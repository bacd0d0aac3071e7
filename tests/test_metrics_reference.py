"""The compiled metrics against straightforward numpy references: the recorded velocity and its
low-pass, the velocity SNR's grid search, densification and the shape error give the same values
as array code, to rounding (relative 1e-9, far below what a report prints)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from tagbot import metrics_kernels
from tagbot.gesture.timing import simulated_capture
from tagbot.inputs import Trace
from tagbot.inputs.stamps import sample_instants
from tagbot.metrics import (
    DENSITY,
    FILTER_ORDER,
    MAX_SAMPLES,
    MEAN_DENSITY,
    POLISH_ITERATIONS,
    POLISH_WIDTHS,
    VELOCITY_CUTOFF,
    densify,
    fit_report,
    ink_polyline,
    low_pass,
    recorded_velocity,
    shape_error,
    turning_of,
    velocity_snr,
)
from tagbot.metrics_kernels import LM_DAMPING
from tagbot.model.motion import sample_plans
from tagbot.model.plan import Plan, Tag, random_plan, random_timed_plan
from tests.test_metrics import arc_samples

# --- references: the array code the compiled kernels replaced ----------------------------------


def _low_pass(x: np.ndarray, dt: float, cutoff: float) -> np.ndarray:
    n = len(x)
    if not 0.0 < 2.0 * cutoff * dt < 1.0 or n < 4:
        return x
    pad = min(n - 1, max(3, round(3.0 / (cutoff * dt))))
    ext = np.concatenate([2.0 * x[0] - x[pad:0:-1], x, 2.0 * x[-1] - x[-2 : -pad - 2 : -1]])
    m = len(ext)
    line = ext[0] + np.linspace(0.0, 1.0, m)[:, None] * (ext[-1] - ext[0])
    size = 1 << int(np.ceil(np.log2(2 * m)))
    gain = 1.0 / (1.0 + (np.fft.rfftfreq(size, dt) / cutoff) ** (2 * FILTER_ORDER))
    y = np.fft.irfft(np.fft.rfft(ext - line, size, axis=0) * gain[:, None], size, axis=0)[:m]
    return (y + line)[pad : pad + n]


def _recorded_velocity(t, xy, dt=0.01, cutoff=None):
    t, xy = np.asarray(t, dtype=float), np.asarray(xy, dtype=float)
    if cutoff is not None:
        t, _ = sample_instants(t, xy)
    keep = np.concatenate([[True], np.diff(t) > 0])
    t, xy = t[keep], xy[keep]
    dt = max(dt, float(t[-1] - t[0]) / (4 * len(t)))
    grid = t[0] + dt * np.arange(int((t[-1] - t[0]) / dt) + 1)
    grid = grid[grid <= t[-1]]
    rec = np.column_stack([np.interp(grid, t, xy[:, 0]), np.interp(grid, t, xy[:, 1])])
    if cutoff is not None:
        rec = _low_pass(rec, dt, cutoff)
    return grid, np.gradient(rec, dt, axis=0)


def _velocity_snr(t, xy, model_t, model_v, dt=0.01, cutoff=VELOCITY_CUTOFF, polish=True):
    model_t, model_v = np.asarray(model_t, dtype=float), np.asarray(model_v, dtype=float)
    shared = float(model_t[0])
    model_t = model_t - model_t[0]
    grid, v = _recorded_velocity(t, xy, dt, cutoff)
    dt = float(grid[1] - grid[0])
    rec, model = v[:, 0] + 1j * v[:, 1], model_v[:, 0] + 1j * model_v[:, 1]
    energy = float(np.sum(rec.real**2 + rec.imag**2))
    model_span, span = float(model_t[-1]), float(grid[-1] - grid[0])

    def errors(scales, offsets):
        tm = (grid[None, :] - offsets[:, None]) / scales[:, None]
        vm = np.interp(tm.ravel(), model_t, model, 0.0, 0.0)
        err = rec[None, :] - vm.reshape(tm.shape) / scales[:, None]
        return np.sum(err.real**2 + err.imag**2, axis=1)

    n = len(rec)
    ratio = span / model_span if model_span > 0 else 1.0
    scales = np.append(np.geomspace(0.25, 4.0, 41) * ratio, 1.0)
    lengths = (model_span * scales / dt).astype(np.intp) + 1
    k = int(lengths.max())
    times = np.arange(k)[None, :] * dt / scales[:, None]
    inside = np.arange(k)[None, :] < lengths[:, None]
    w = np.where(
        inside, np.interp(times.ravel(), model_t, model).reshape(times.shape) / scales[:, None], 0
    )
    size = 1 << int(np.ceil(np.log2(n + k + 1)))
    cross = np.fft.ifft(np.fft.fft(rec, size)[None, :] * np.conj(np.fft.fft(w, size, axis=1)))
    slack = (span - scales * model_span) / dt
    lo = int(np.floor(min(0.0, float(slack.min()))))
    hi = int(np.ceil(max(0.0, float(slack.max()))))
    m = np.arange(lo, hi + 1)
    cum = np.concatenate([np.zeros((len(scales), 1)), np.cumsum(np.abs(w) ** 2, axis=1)], axis=1)
    first = np.clip(-m[None, :], 0, lengths[:, None])
    last = np.clip(n - m[None, :], 0, lengths[:, None])
    rows = np.arange(len(scales))[:, None]
    overlap = cum[rows, np.maximum(last, first)] - cum[rows, first]
    err = energy - 2.0 * cross[:, m % size].real + overlap
    own = (m[None, :] >= np.floor(np.minimum(0.0, slack))[:, None]) & (
        m[None, :] <= np.ceil(np.maximum(0.0, slack))[:, None]
    )
    i, j = np.unravel_index(int(np.argmin(np.where(own, err, np.inf))), err.shape)
    starts = np.array([float(scales[i]), 1.0]), np.array([float(grid[0] + m[j] * dt), shared])
    e = errors(*starts)
    pick = int(np.argmin(e))
    best, scale, offset = float(e[pick]), float(starts[0][pick]), float(starts[1][pick])
    if not polish:  # the grid's pair, or the shared clock if better
        return 10.0 * np.log10(energy / max(best, 1e-300)), scale, offset
    steps = np.linspace(-1.0, 1.0, 7)
    reach = max(span, dt)
    for width in POLISH_WIDTHS:
        s_try = np.repeat(scale * (1 + width * steps), 7)
        o_try = np.tile(offset + steps * width * reach, 7)
        e = errors(s_try, o_try)
        pick = int(np.argmin(e))
        if e[pick] < best:
            best, scale, offset = float(e[pick]), float(s_try[pick]), float(o_try[pick])
    best, scale, offset = _levenberg_marquardt(
        grid, rec, model_t, model, best, scale, offset, reach
    )
    return 10.0 * np.log10(energy / max(best, 1e-300)), scale, offset


def _levenberg_marquardt(grid, rec, model_t, model, best, scale, offset, reach):
    """The polish's last part: Gauss-Newton steps on (scale, offset) with Marquardt's damping,
    each kept only if the error falls (the kernel's rules, in array code)."""
    slope = np.diff(model) / np.diff(model_t)

    def state(s, o):
        x = (grid - o) / s
        inside = (x >= model_t[0]) & (x <= model_t[-1])
        j = np.clip(np.searchsorted(model_t, x, side="right") - 1, 0, len(slope) - 1)
        m = np.where(inside, model[j] + slope[j] * (x - model_t[j]), 0)
        d = np.where(inside, slope[j], 0) / s**2
        r = rec - m / s
        js, jo = (d * x + m / s**2) * inside, d  # the residuals' derivatives
        dot = lambda a, b: float(np.sum(a.real * b.real + a.imag * b.imag))  # noqa: E731
        return dot(r, r), dot(r, js), dot(r, jo), dot(js, js), dot(js, jo), dot(jo, jo)

    here, damping, moved = state(scale, offset), LM_DAMPING, False
    for _ in range(POLISH_ITERATIONS):
        a, b, c = here[3] * (1 + damping), here[4], here[5] * (1 + damping)
        det = a * c - b * b
        if not det > 0:
            break
        s_try = max(scale - (c * here[1] - b * here[2]) / det, 0.5 * scale)
        o_try = offset - (a * here[2] - b * here[1]) / det
        trial = state(s_try, o_try)
        if trial[0] < here[0]:
            still = abs(s_try - scale) <= 1e-9 * scale and abs(o_try - offset) <= 1e-9 * reach
            gain = here[0] - trial[0]
            scale, offset, here, moved = s_try, o_try, trial, True
            damping = max(0.1 * damping, 1e-9)
            if still or gain < 1e-12 * here[0]:
                break
        else:
            damping *= 10.0
            if damping > 1e8:
                break
    return (here[0] if moved else best), scale, offset


def _densify(polyline: np.ndarray, spacing: float) -> np.ndarray:
    xy = np.asarray(polyline, dtype=float)
    if len(xy) < 2:
        return xy
    seg = np.hypot(*np.diff(xy, axis=0).T)
    pieces = np.maximum(1, np.ceil(seg / spacing).astype(np.intp))
    start = np.repeat(xy[:-1], pieces, axis=0)
    delta = np.repeat(np.diff(xy, axis=0) / pieces[:, None], pieces, axis=0)
    offset = np.arange(int(pieces.sum())) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    return np.vstack([start + delta * offset[:, None], xy[-1:]])


def _distances(query: np.ndarray, polylines: list[np.ndarray]) -> np.ndarray:
    parts = [shapely.LineString(p) if len(p) > 1 else shapely.Point(p[0]) for p in polylines]
    return shapely.distance(shapely.points(query), shapely.GeometryCollection(parts))


def _along(polyline: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The points at arc lengths ``s`` of the polyline."""
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(polyline, axis=0).T))])
    keep = np.concatenate([[True], np.diff(along) > 0])
    return np.column_stack([np.interp(s, along[keep], c) for c in polyline[keep].T])


def _farthest(polylines, spacing, coarse, other, fine):
    """The largest distance from ``polylines`` (their arc samples at ``spacing`` at distances
    ``coarse``) to ``other``, refined along the path within ``fine`` where it could be larger
    than at the samples."""
    top = float(coarse.max())
    chosen, first = [], 0
    for p in polylines:
        count = len(arc_samples(p, spacing))
        if count > 1:
            step = float(np.hypot(*np.diff(p, axis=0).T).sum()) / (count - 1)
            d = coarse[first : first + count]
            j = np.flatnonzero(np.maximum(d[:-1], d[1:]) + 0.5 * step > top + 0.5 * fine)
            chosen.append((p, j * step, step))
        first += count
    total = sum(len(starts) * step for _, starts, step in chosen)
    if not total:
        return top
    fine = max(fine, total / MAX_SAMPLES)
    points = []
    for p, starts, step in chosen:
        pieces = max(1, math.ceil(step / fine))
        s = (starts[:, None] + np.arange(pieces)[None, :] * step / pieces).ravel()
        points.append(_along(p, s))
    return max(top, float(_distances(np.concatenate(points), other).max()))


def _shape_error(reference, candidate) -> tuple[float, float]:
    ref = [np.asarray(p, dtype=float) for p in reference if len(p)]
    cand = [np.asarray(p, dtype=float) for p in candidate if len(p)]
    size = float(np.hypot(*np.ptp(np.concatenate(ref), axis=0))) or 1.0
    spacing = size / MEAN_DENSITY
    for drawing in (ref, cand):
        length = sum(float(np.hypot(*np.diff(p, axis=0).T).sum()) for p in drawing)
        spacing = max(spacing, length / MAX_SAMPLES)
    a = np.concatenate([arc_samples(p, spacing) for p in ref])
    b = np.concatenate([arc_samples(p, spacing) for p in cand])
    a_to_b, b_to_a = _distances(a, cand), _distances(b, ref)
    mean = (a_to_b.sum() + b_to_a.sum()) / (len(a_to_b) + len(b_to_a))
    fine = size / DENSITY
    largest = max(
        _farthest(ref, spacing, a_to_b, cand, fine), _farthest(cand, spacing, b_to_a, ref, fine)
    )
    return float(mean) / size, largest / size


# --- inputs ----------------------------------------------------------------------------------


def _timed_case(seed: int, rate: float = 100.0):
    """A simulated capture of a random timed plan, and a fit-like model of it: the same shape
    on another rhythm (a geometric fit's), sampled every 5 ms."""
    rng = np.random.default_rng(seed)
    plan = random_timed_plan(rng)
    trace = simulated_capture(plan, rng, rate=rate, jitter=0.002, noise=0.05)
    other = random_plan(np.random.default_rng(seed))
    model = Tag((Plan(plan.targets, other.dt, other.mu, other.sigma, plan.phi1, plan.phi2),))
    return trace, model


# --- the comparisons ------------------------------------------------------------------------


@pytest.mark.parametrize("n", [1, 2, 4, 16, 128, 1024])
def test_the_compiled_fft_is_numpys(n):
    x = np.random.default_rng(n).normal(size=(n, 2)) @ [1.0, 1j]
    table = metrics_kernels.twiddles(max(n, 2))
    y = x.copy()
    metrics_kernels.fft(y, table, False)
    np.testing.assert_allclose(y, np.fft.fft(x), rtol=0, atol=1e-12 * n)
    metrics_kernels.fft(y, table, True)
    np.testing.assert_allclose(y / n, x, rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("cutoff", [VELOCITY_CUTOFF, None])
def test_recorded_velocity_is_the_array_codes(seed, cutoff):
    trace, _ = _timed_case(seed, rate=(60.0, 100.0, 240.0)[seed % 3])
    t = np.asarray(trace.t).copy()
    if seed % 2:
        t[1::4] = t[0:-1:4]  # stamps repeated in bursts
    grid, v = recorded_velocity(t, trace.xy, cutoff=cutoff)
    grid_ref, v_ref = _recorded_velocity(t, trace.xy, cutoff=cutoff)
    np.testing.assert_array_equal(grid, grid_ref)
    np.testing.assert_allclose(v, v_ref, rtol=0, atol=1e-9 * np.abs(v_ref).max())


@given(st.integers(1, 400), st.integers(1, 3), st.floats(0.001, 0.05), st.integers(0, 2**32 - 1))
@settings(max_examples=40, deadline=None)
def test_low_pass_is_the_array_codes(n, columns, dt, seed):
    x = np.cumsum(np.random.default_rng(seed).normal(size=(n, columns)), axis=0)
    y = low_pass(x, dt, VELOCITY_CUTOFF)
    np.testing.assert_allclose(y, _low_pass(x, dt, VELOCITY_CUTOFF), rtol=0, atol=1e-9)


@pytest.mark.parametrize("seed", range(10))
def test_velocity_snr_is_the_array_codes(seed):
    """Short and long recordings (scales correlated by direct sums and by FFT), the model on
    its own clock or another, unfiltered too."""
    trace, model = _timed_case(seed, rate=(60.0, 120.0, 200.0)[seed % 3])
    ((model_t, _, model_v),) = sample_plans(model, 0.005)
    if seed % 3 == 1:
        model_t = model_t * 1.3 + 0.2
    cutoff = None if seed % 4 == 3 else VELOCITY_CUTOFF
    db, scale, offset = velocity_snr(trace.t, trace.xy, model_t, model_v, cutoff=cutoff)
    db_ref, scale_ref, offset_ref = _velocity_snr(
        trace.t, trace.xy, model_t, model_v, cutoff=cutoff
    )
    assert db == pytest.approx(db_ref, rel=0, abs=1e-9)
    assert scale == pytest.approx(scale_ref, rel=1e-9)
    assert offset == pytest.approx(offset_ref, rel=0, abs=1e-9)


def test_velocity_snr_of_a_long_recording_is_the_array_codes():
    """A recording long enough that the longest scales are correlated by FFT (the others by
    direct sums) and a model on another clock."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 24.0, 0.008)
    xy = np.cumsum(np.cumsum(rng.normal(size=(len(t), 2)), axis=0), axis=0) * 1e-3
    model_t = 0.3 + 1.2 * t[::2]
    model_v = np.gradient(xy[::2], model_t, axis=0)
    got = velocity_snr(t, xy, model_t, model_v)
    np.testing.assert_allclose(got, _velocity_snr(t, xy, model_t, model_v), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_grid_search_in_single_precision_finds_the_array_codes_pair(seed):
    """A model on a slower clock than the recording (as a geometric fit's is): its longest
    scales have the work for single-precision sums (:data:`~tagbot.metrics_kernels.SINGLE_WORK`),
    and the grid's pair is still the one the double-precision array code finds."""
    trace, model = _timed_case(seed, rate=120.0)
    ((model_t, _, model_v),) = sample_plans(model, 0.005)
    model_t, model_v = 2.5 * model_t, model_v / 2.5
    grid, v = recorded_velocity(trace.t, trace.xy, cutoff=VELOCITY_CUTOFF)
    own = model_t - model_t[0]
    ratio = (grid[-1] - grid[0]) / own[-1]
    scales = np.append(np.geomspace(0.25, 4.0, 41) * ratio, 1.0)
    lengths = (own[-1] * scales / 0.01).astype(int) + 1
    offsets = np.abs((grid[-1] - grid[0] - scales * own[-1]) / 0.01) + 1
    assert np.max(offsets * np.minimum(len(grid), lengths)) >= metrics_kernels.SINGLE_WORK
    energy = float(np.sum(v * v))
    best, scale, offset = metrics_kernels.best_mapping(
        grid, v, own, np.ascontiguousarray(model_v), scales, float(model_t[0]), energy,
        np.linspace(-1.0, 1.0, 7), np.empty(0), 0,
    )  # fmt: skip
    db_ref, scale_ref, offset_ref = _velocity_snr(trace.t, trace.xy, model_t, model_v, polish=False)
    assert (scale, offset) == pytest.approx((scale_ref, offset_ref), rel=1e-12, abs=1e-12)
    assert 10 * np.log10(energy / best) == pytest.approx(db_ref, abs=1e-9)


def test_velocity_snr_on_an_uneven_model_clock_is_the_array_codes():
    """A model sampled at uneven times: its samples are found by bisection."""
    trace, model = _timed_case(3)
    ((t, _, v),) = sample_plans(model, 0.005)
    keep = np.sort(np.random.default_rng(0).choice(len(t), len(t) // 2, replace=False))
    t, v = t[keep], v[keep]
    assert metrics_kernels._uniform_step(t - t[0]) == 0.0
    got = velocity_snr(trace.t, trace.xy, t, v)
    np.testing.assert_allclose(got, _velocity_snr(trace.t, trace.xy, t, v), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("seed", range(8))
def test_densify_is_the_array_codes(seed):
    rng = np.random.default_rng(seed)
    polyline = np.cumsum(rng.normal(size=(int(rng.integers(1, 40)), 2)), axis=0)
    polyline[rng.integers(0, len(polyline))] = polyline[0]  # a repeated point
    spacing = float(rng.uniform(0.05, 2.0))
    np.testing.assert_array_equal(densify(polyline, spacing), _densify(polyline, spacing))


@pytest.mark.parametrize("seed", range(8))
def test_shape_error_is_the_array_codes(seed):
    """A fitted tag against its capture (pens resting at the ends: repeated samples), and
    random polylines with single points among them."""
    trace, model = _timed_case(seed)
    cases = [([trace.xy], [xy for _, xy, _ in sample_plans(model, 0.005)])]
    rng = np.random.default_rng(seed)
    walks = [np.cumsum(rng.normal(size=(n, 2)), axis=0) for n in (25, 1, 9)]
    cases.append((walks, [w + rng.normal(scale=0.1, size=w.shape) for w in walks[::-1]]))
    for reference, candidate in cases:
        error = shape_error(reference, candidate)
        mean, largest = _shape_error(reference, candidate)
        assert error.mean == pytest.approx(mean, rel=1e-9)
        assert error.max == pytest.approx(largest, rel=1e-9)


def test_fit_report_of_a_timed_fit_is_the_array_codes():
    trace, model = _timed_case(4)
    report = fit_report([trace], model)
    ((model_t, _, model_v),) = sample_plans(model, 0.005)
    db, _, _ = _velocity_snr(trace.t, trace.xy, model_t, model_v)
    assert report.velocity_snr_db == pytest.approx(db, rel=0, abs=1e-9)
    # The ink every 5 ms, or finely enough at its fastest that no chord cuts a corner.
    mean, largest = _shape_error([trace.xy], [ink_polyline(model.plans[0], model.size)])
    assert (report.shape.mean, report.shape.max) == pytest.approx((mean, largest), rel=1e-9)
    assert math.isfinite(report.strokes_per_half_turn)


def _turning(polylines) -> float:
    total = 0.0
    for p in polylines:
        d = np.diff(np.asarray(p, dtype=float), axis=0)
        d = d[np.hypot(*d.T) > 0]
        if len(d) >= 2:
            cross = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
            total += float(np.sum(np.abs(np.arctan2(cross, np.sum(d[:-1] * d[1:], axis=1)))))
    return total / np.pi


@pytest.mark.parametrize("seed", range(4))
def test_turning_is_the_array_codes(seed):
    rng = np.random.default_rng(seed)
    walks = [np.cumsum(rng.normal(size=(n, 2)), axis=0) for n in (30, 1, 2, 12)]
    walks[0][5:8] = walks[0][5]  # a pen at rest
    assert turning_of(walks) == pytest.approx(_turning(walks), rel=1e-12)


def test_fit_report_of_untimed_traces_has_no_velocity_figures():
    """Traces without timestamps have no speed to compare with: the report's velocity SNRs are
    None (reported as such), and its shape figures are the array codes'."""
    trace, model = _timed_case(4)
    untimed = Trace(trace.xy)
    report = fit_report([untimed], model)
    assert report.velocity_snr_db is None
    assert report.velocity_snr_clock_db is None and report.velocity_snr_trace_db is None
    mean, largest = _shape_error([trace.xy], [ink_polyline(model.plans[0], model.size)])
    assert (report.shape.mean, report.shape.max) == pytest.approx((mean, largest), rel=1e-9)
