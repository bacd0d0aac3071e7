"""The vectorised contour analysis against the per-section loops it replaced.

The ``_old_*`` functions are the loop versions as they were, kept here as oracles. Integer results
(decimation, salient and turning points, inflections) must be identical; angles and sharpness
equal up to the old functions' own rounding (the old bisection of eq. 19 is noisy below θ ~ 1e-3,
and the old areas are summed in absolute coordinates).
"""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import find_peaks

from tagbot import kernel_check
from tagbot.gesture import contour
from tagbot.model.euler import wrap_angle

EPS = np.finfo(float).eps

# --- the loop versions, as they were ------------------------------------------------------------


def _old_turning(xy, support=1):
    n = len(xy)
    i = np.arange(n)
    before = xy[i] - xy[np.maximum(i - support, 0)]
    after = xy[np.minimum(i + support, n - 1)] - xy[i]
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    dot = np.einsum("ij,ij->i", before, after)
    angle = np.arctan2(cross, dot)
    angle[[0, -1]] = 0.0
    return angle


def _old_heading_changes(xy, support=1):
    n = len(xy)
    half = support // 2
    i = np.arange(n)
    chords = xy[np.minimum(i + support - half, n - 1)] - xy[np.maximum(i - half, 0)]
    heading = np.arctan2(chords[:, 1], chords[:, 0])
    change = np.zeros(n)
    change[1:] = np.angle(np.exp(1j * np.diff(heading)))
    return change


def _old_decimate(xy, radius):
    n = len(xy)
    if n < 3 or radius <= 0:
        return xy
    kept = [0]
    i = 0
    chunk = 64
    while True:
        block = xy[i + 1 : i + 1 + chunk]
        if not len(block):
            break
        far = np.flatnonzero(np.hypot(*(block - xy[i]).T) >= radius)
        if far.size:
            i = i + 1 + int(far[0])
            kept.append(i)
            chunk = 64
        elif i + 1 + chunk >= n:
            break
        else:
            chunk *= 2
    if kept[-1] != n - 1:
        kept.append(n - 1)
    return xy[kept]


def _old_prefilter(xy, step):
    coarse_length = contour.arc_length(_old_decimate(xy, 5.0 * step))[-1]
    if coarse_length <= 0:
        return xy
    per_step = len(xy) * step / coarse_length
    return contour.smooth(xy, 0.5 * per_step) if per_step > 2.0 else xy


def _old_salient_points(xy, support, threshold, prominence, reach=3.0):
    n = len(xy)
    peaks, _ = find_peaks(
        np.abs(_old_turning(xy, support)), prominence=prominence, distance=support
    )
    peaks = peaks[(peaks >= support) & (peaks <= n - 1 - support)]
    points = [0, *peaks.tolist(), n - 1]
    while len(points) > 2:
        idx = np.asarray(points)
        span = int(reach * support)
        here = idx[1:-1]
        near = contour.chord_turn(
            xy, np.maximum(idx[:-2], here - span), here, np.minimum(idx[2:], here + span)
        )
        turns = np.maximum(contour.chord_turn(xy, idx[:-2], here, idx[2:]), near)
        weakest = int(np.argmin(turns))
        if turns[weakest] >= threshold:
            break
        del points[weakest + 1]
    return np.asarray(points, dtype=np.intp)


def _old_add_turning_points(xy, points, max_turn=np.pi, support=1):
    step_turn = np.abs(_old_heading_changes(xy, support))
    margin = support // 2
    s = contour.arc_length(xy)
    last = len(xy) - 1
    out = [int(points[0])]
    for a, b in itertools.pairwise(points):
        lo = a + 1 + (margin if a > 0 else 0)
        hi = b - (margin if b < last else 0)
        total = float(np.sum(step_turn[lo:hi]))
        extra = int(total // max_turn)
        if extra:
            targets = np.linspace(s[a], s[b], extra + 2)[1:-1]
            inner = np.clip(np.searchsorted(s, targets), a + 1, b - 1)
            out.extend(sorted(set(inner.tolist())))
        out.append(int(b))
    return np.asarray(sorted(set(out)), dtype=np.intp)


def _old_inflection(xy, a, b, support, min_turn):
    if b - a < 4:
        return None
    # Measured within the section (chords stop at its ends).
    theta = _old_turning(xy[a : b + 1], max(1, min(support, (b - a) // 4)))[1:-1]
    left = np.cumsum(theta)
    right = left[-1] - left
    nonzero = np.flatnonzero(theta != 0)
    flips = np.flatnonzero(np.sign(theta[nonzero[:-1]]) != np.sign(theta[nonzero[1:]]))
    change = (nonzero[flips] + nonzero[flips + 1]) // 2
    if not change.size:
        return None
    score = np.minimum(np.abs(left[change]), np.abs(right[change]))
    opposite = np.sign(left[change]) * np.sign(right[change]) < 0
    score = np.where(opposite, score, 0.0)
    best = int(np.argmax(score))
    if score[best] < min_turn:
        return None
    return a + 1 + int(change[best]) + 1


def _old_signed_area(xy):
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _old_segment_angle(chord, area):
    if chord <= 0 or area <= 0:
        return 0.0
    ratio = area / (chord * chord)
    lo, hi = 0.0, 2.0 * np.pi - 1e-9
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        value = (mid - np.sin(mid)) / (8.0 * np.sin(0.5 * mid) ** 2)
        if value < ratio:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _bisection_noise(theta):
    """How far the old bisection can be from the root: ``θ − sin θ`` cancels for small θ (and is
    0 below θ ~ 3e-8, where the bisection stalls)."""
    return 1e-15 / np.maximum(theta, 2e-8)


def _old_arc_deviation(xy):
    """The old ΣΛ* deviation, and how far off the old bisection can have left it."""
    area = _old_signed_area(xy)
    chord = float(np.hypot(*(xy[-1] - xy[0])))
    theta = _old_segment_angle(chord, abs(area))
    return float(np.sign(area)) * 0.5 * theta, 0.5 * _bisection_noise(theta)


def _old_section_tangents(section, cut):
    """reconstruct.section_tangents as it was (with its noise bound)."""
    if cut is None or not 0 < cut < len(section) - 1:
        phi, noise = _old_arc_deviation(section)
        return -phi, phi, noise

    def direction(v):
        return float(np.arctan2(v[1], v[0]))

    alpha = direction(section[-1] - section[0])
    first, noise1 = _old_arc_deviation(section[: cut + 1])
    second, noise2 = _old_arc_deviation(section[cut:])
    start = direction(section[cut] - section[0]) - first
    end = direction(section[-1] - section[cut]) + second
    return float(wrap_angle(start - alpha)), float(wrap_angle(end - alpha)), noise1 + noise2


def _old_sharpness(xy, a, z, b):
    pa, pz, pb = xy[a], xy[z], xy[b]
    u, w = pa - pz, pb - pz
    lengths = float(np.hypot(*u) * np.hypot(*w))
    if lengths <= 0:
        return 0.0
    gamma = float(np.arccos(np.clip(np.dot(u, w) / lengths, -1.0, 1.0)))
    if gamma < 1e-6:
        return 1.0
    chord = float(np.hypot(*(pb - pa)))
    triangle = 0.5 * abs(float(u[0] * w[1] - u[1] * w[0]))
    if chord <= 0 or triangle <= 0 or np.pi - gamma < 1e-9:
        return 0.0
    radius = chord / (2.0 * np.sin(gamma))
    theta = 2.0 * np.pi - 2.0 * gamma
    circle = 0.5 * radius * radius * (theta - np.sin(theta))
    contour_area = abs(_old_signed_area(xy[a : b + 1]))
    if not circle > max(contour_area, triangle):
        return 0.0
    return (circle - contour_area) / (circle - triangle)


def _near_straight_cutoff(xy, a, z, b):
    """Whether ``a, z, b`` turn within rounding of the 1e-9 rad below which eq. 20 is cut to 0
    (straight through): there the value jumps between 0 and its formula, and which side a triple
    falls on depends on rounding that varies with the arrays' memory alignment."""
    u, w = xy[a] - xy[z], xy[b] - xy[z]
    lengths = np.hypot(*u) * np.hypot(*w)
    if lengths <= 0:
        return False
    gamma = np.arccos(np.clip(np.dot(u, w) / lengths, -1.0, 1.0))
    return abs((np.pi - gamma) - 1e-9) < 1e-7


def _old_area_noise(xy, a, z, b):
    """How far rounding can move the old sharpness: its area's rounding (summed in absolute
    coordinates) over ``A_s − A_t`` (infinite where these are equal: a straight line)."""
    pa, pz, pb = xy[a], xy[z], xy[b]
    u, w = pa - pz, pb - pz
    with np.errstate(divide="ignore", invalid="ignore"):
        gamma = np.arccos(np.clip(np.dot(u, w) / (np.hypot(*u) * np.hypot(*w)), -1.0, 1.0))
        radius = np.hypot(*(pb - pa)) / (2.0 * np.sin(gamma))
        theta = 2.0 * np.pi - 2.0 * gamma
        circle = 0.5 * radius * radius * (theta - np.sin(theta))
        triangle = 0.5 * abs(u[0] * w[1] - u[1] * w[0])
        part = xy[a : b + 1]
        x, y = part[:, 0], part[:, 1]
        scale = np.sum(np.abs(x * np.roll(y, -1)) + np.abs(np.roll(x, -1) * y))
        noise = len(part) * EPS * scale / abs(circle - triangle)
    return noise if np.isfinite(noise) else np.inf


# --- curves --------------------------------------------------------------------------------------


def _curves():
    """Smooth random walks, zig-zags, a circle, an S-curve, polylines with repeated points, noisy
    and straight lines. The polylines on a dyadic grid (``exact``) have exact areas."""
    rng = np.random.default_rng(20260)
    out = {}
    for scale in (0.05, 1.0, 30.0):
        walk = np.cumsum(rng.normal(size=(120, 2)), axis=0) * scale
        out[f"walk {scale}"] = contour.smooth(contour.resample(walk, 0.4 * scale), 3.0)
    zigzag = np.array([[i, 3 * (i % 2)] for i in range(12)], dtype=float)
    out["zig-zag resampled"] = contour.resample(zigzag, 0.25)
    out["zig-zag exact"] = zigzag
    t = np.linspace(0.0, 1.9 * np.pi, 500)
    out["circle"] = np.column_stack([4 * np.cos(t), 4 * np.sin(t)])
    t = np.linspace(-1.0, 1.0, 301)
    out["s-curve"] = np.column_stack([t, 0.3 * np.sin(np.pi * t)])
    grid = rng.integers(-40, 40, size=(80, 2)) / 8.0
    out["repeats exact"] = np.repeat(grid, rng.integers(1, 4, size=80), axis=0)
    out["lattice walk exact"] = np.cumsum(rng.integers(-2, 3, size=(150, 2)), axis=0) / 4.0
    line = np.column_stack([np.linspace(0, 5, 400), np.zeros(400)])
    out["noisy line"] = line + rng.normal(0, 0.02, line.shape)
    out["line"] = line
    return out


CURVES = _curves()


def _dominant(rng, n):
    """Sorted dominant points from 0 to n - 1, with many short sections (1 to 6 samples)."""
    gaps = np.where(rng.random(n) < 0.5, rng.integers(1, 7, n), rng.integers(7, 80, n))
    inner = np.cumsum(gaps)
    return np.concatenate([[0], inner[inner < n - 1], [n - 1]]).astype(np.intp)


# --- tests ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", CURVES)
def test_turning_and_heading_changes_are_unchanged(name):
    xy = CURVES[name]
    for support in (0, 1, 2, 3, 7, 15, len(xy) + 3):
        np.testing.assert_array_equal(contour.turning(xy, support), _old_turning(xy, support))
        np.testing.assert_array_equal(
            contour.heading_changes(xy, support), _old_heading_changes(xy, support)
        )


def test_segment_angles_match_the_bisection():
    rng = np.random.default_rng(1)
    ratio = np.concatenate([10 ** rng.uniform(-20, 20, 3000), [1e-300, 1e300, 1 / 12, 3e18]])
    chord = 10 ** rng.uniform(-3, 3, len(ratio))
    area = ratio * chord * chord
    new = contour.segment_angles(chord, area)
    old = np.array([_old_segment_angle(c, a) for c, a in zip(chord, area, strict=True)])
    assert np.all(np.abs(new - old) <= 1e-12 + _bisection_noise(old))
    assert np.max(np.abs(new - old)[old > 1e-3]) <= 1e-12
    # The scalar version is the vectorised one.
    for c, a, theta in zip(chord[:50], area[:50], new[:50], strict=True):
        assert contour.segment_angle(c, a) == theta
    # No segment where the chord or the area is not positive; the whole circle at most.
    edges = contour.segment_angles(
        np.array([0.0, 1.0, -1.0, 1.0, 1.0]), [1.0, 0.0, 1.0, -1, np.inf]
    )
    np.testing.assert_array_equal(edges, [0.0, 0.0, 0.0, 0.0, 2 * np.pi - 1e-9])


def test_segment_angles_invert_eq_19():
    theta = np.linspace(1e-3, 2 * np.pi - 1e-3, 2001)
    radius = 1.7
    chord = 2 * radius * np.sin(theta / 2)
    area = 0.5 * radius**2 * (theta - np.sin(theta))
    np.testing.assert_allclose(contour.segment_angles(chord, area), theta, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", CURVES)
def test_section_deviations_match_the_loop(name):
    xy = CURVES[name]
    k = list(CURVES).index(name)
    rng = np.random.default_rng(k)
    for _ in range(4):
        dominant = _dominant(rng, len(xy))
        cuts = []
        for a, b in itertools.pairwise(dominant.tolist()):
            # inside, on an end, outside, or none
            choice = rng.integers(4)
            cuts.append([None, int(rng.integers(a, b + 1)), a, b + 3][choice] if b > a else None)
        old = [
            _old_section_tangents(xy[a : b + 1], None if q is None else q - a)
            for a, b, q in zip(dominant[:-1], dominant[1:], cuts, strict=True)
        ]
        old1, old2, noise = (np.array(v) for v in zip(*old, strict=True))
        for given_cuts in (cuts, np.array([-1 if q is None else q for q in cuts])):
            phi1, phi2 = contour.section_deviations(xy, dominant, given_cuts)
            assert np.all(np.abs(wrap_angle(phi1 - old1)) <= 1e-9 + noise)
            assert np.all(np.abs(wrap_angle(phi2 - old2)) <= 1e-9 + noise)
    phi1, phi2 = contour.section_deviations(xy, dominant)
    old = [_old_section_tangents(xy[a : b + 1], None) for a, b in itertools.pairwise(dominant)]
    assert np.all(np.abs(phi2 - [p[1] for p in old]) <= 1e-9 + np.array([p[2] for p in old]))
    np.testing.assert_array_equal(phi1, -phi2)


@pytest.mark.parametrize("name", CURVES)
def test_sharpnesses_match_sharpness(name):
    xy = CURVES[name]
    k = list(CURVES).index(name)
    rng = np.random.default_rng(100 + k)
    n = len(xy)
    z = rng.integers(0, n, 300)
    a = np.maximum(z - rng.integers(0, 20, 300), 0)
    b = np.minimum(z + rng.integers(0, 20, 300), n - 1)
    new = contour.sharpnesses(xy, a, z, b)
    for i, j, m, value in zip(a, z, b, new, strict=True):
        if _near_straight_cutoff(xy, i, j, m):
            continue  # either side of the documented cut to 0 is right
        old = _old_sharpness(xy, i, j, m)
        if name.endswith("exact"):  # every area exact: the same arithmetic throughout
            assert value == old
        else:
            assert abs(value - old) <= 1e-12 + _old_area_noise(xy, i, j, m)
        assert contour.sharpness(xy, int(i), int(j), int(m)) == value


def test_sharpnesses_special_cases():
    spike = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    line = np.column_stack([np.linspace(0, 1, 5), np.zeros(5)])
    corner = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    assert contour.sharpnesses(spike, [0], [2], [4]).tolist() == [1.0]  # cusp
    assert contour.sharpnesses(line, [0, 0, 2], [2, 0, 2], [4, 4, 2]).tolist() == [0.0] * 3
    assert contour.sharpnesses(corner, [0], [1], [2])[0] == pytest.approx(1.0)
    assert contour.sharpnesses(corner, [], [], []).shape == (0,)


@pytest.mark.parametrize("name", CURVES)
def test_inflections_match_the_loop(name):
    xy = CURVES[name]
    k = list(CURVES).index(name)
    rng = np.random.default_rng(200 + k)
    for support, min_turn in ((1, 0.0), (2, 0.01), (3, np.radians(8)), (15, np.radians(8))):
        dominant = _dominant(rng, len(xy))
        new = contour.inflections(xy, dominant, support, min_turn)
        old = [
            _old_inflection(xy, a, b, support, min_turn)
            for a, b in itertools.pairwise(dominant.tolist())
        ]
        assert new.tolist() == [-1 if q is None else q for q in old]
        assert contour.inflection(xy, 0, len(xy) - 1, support, min_turn) == _old_inflection(
            xy, 0, len(xy) - 1, support, min_turn
        )


def test_inflections_of_no_section():
    xy = CURVES["circle"]
    assert contour.inflections(xy, np.array([0]), 5, 0.1).shape == (0,)
    assert contour.inflections(xy, np.array([0, 3, 5]), 5, 0.1).tolist() == [-1, -1]


@pytest.mark.parametrize("name", CURVES)
def test_salient_and_turning_points_match_the_loops(name):
    xy = CURVES[name]
    k = list(CURVES).index(name)
    for support, threshold, prominence in ((2, 0.4, 0.05), (5, 1.2, 0.0), (15, 0.44, 0.14)):
        salient = contour.salient_points(xy, support, threshold, prominence)
        np.testing.assert_array_equal(
            salient, _old_salient_points(xy, support, threshold, prominence)
        )
        for max_turn in (np.pi, np.pi / 2, 0.05):
            np.testing.assert_array_equal(
                contour.add_turning_points(xy, salient, max_turn, support),
                _old_add_turning_points(xy, salient, max_turn, support),
            )
    # Short sections, some ending within half a support of the start.
    rng = np.random.default_rng(300 + k)
    for support in (1, 4, 12):
        points = _dominant(rng, len(xy))
        np.testing.assert_array_equal(
            contour.add_turning_points(xy, points, np.pi / 3, support),
            _old_add_turning_points(xy, points, np.pi / 3, support),
        )


def test_turning_points_on_exact_right_angles():
    """Sections turning exactly a multiple of max_turn (the floor is decided by the last bit)."""
    square = np.array([[0, 0], [4, 0], [4, 4], [0, 4], [0, 0], [4, 0], [4, 4]], dtype=float)
    xy = contour.resample(square, 0.5)
    for support in (1, 2, 3):
        for points in ([0, len(xy) - 1], [0, 9, len(xy) - 1], [0, 16, 25, 33, len(xy) - 1]):
            for max_turn in (np.pi / 2, np.pi, 3 * np.pi / 2, np.pi / 4):
                np.testing.assert_array_equal(
                    contour.add_turning_points(xy, np.array(points), max_turn, support),
                    _old_add_turning_points(xy, np.array(points), max_turn, support),
                )


@pytest.mark.parametrize("name", CURVES)
def test_decimate_and_prefilter_match_the_loop(name):
    xy = CURVES[name]
    step = float(np.median(np.hypot(*np.diff(xy, axis=0).T))) or 0.1
    for radius in (0.0, 0.3 * step, step, 2.5 * step, 40 * step, 1e9):
        np.testing.assert_array_equal(contour.decimate(xy, radius), _old_decimate(xy, radius))
    for factor in (0.2, 1.0, 5.0):
        np.testing.assert_array_equal(
            contour.prefilter(xy, factor * step), _old_prefilter(xy, factor * step)
        )


def test_decimate_of_dense_jitter_and_exact_distances():
    rng = np.random.default_rng(5)
    line = np.column_stack([np.linspace(0, 20, 20_000), np.zeros(20_000)])
    noisy = line + rng.normal(0, 0.05, line.shape)
    np.testing.assert_array_equal(contour.decimate(noisy, 0.5), _old_decimate(noisy, 0.5))
    # Collinear points exactly one radius apart now and then (the path-length bound is tight).
    ticks = np.column_stack([np.cumsum(np.tile([0.1, 0.2, 0.2], 50)), np.zeros(150)])
    for radius in (0.5, 0.3, 0.1, 0.7):
        np.testing.assert_array_equal(contour.decimate(ticks, radius), _old_decimate(ticks, radius))
    # A point that is not finite: validated inputs never have one, and in the suite's checked
    # mode (tagbot.kernel_check) the kernel refuses it; unchecked, the plain search handles it.
    broken = noisy[:300].copy()
    broken[100] = np.nan
    if kernel_check.installed():
        with pytest.raises(kernel_check.KernelInputError, match="decimate: argument xy"):
            contour.decimate(broken, 0.5)
    else:
        np.testing.assert_array_equal(contour.decimate(broken, 0.5), _old_decimate(broken, 0.5))


coordinate = st.integers(-6, 6).map(lambda v: v / 4)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(coordinate, coordinate), min_size=1, max_size=30),
    st.sampled_from([0.25, 0.5, 1.0, 1.3]),
    st.integers(1, 4),
)
def test_decimate_and_inflections_of_any_polyline(points, radius, support):
    """Repeats, back-and-forth and lattices: exactly the loops' answers."""
    xy = np.asarray(points, dtype=float)
    np.testing.assert_array_equal(contour.decimate(xy, radius), _old_decimate(xy, radius))
    if len(xy) >= 2:
        dominant = np.arange(0, len(xy), 5)
        dominant = np.unique(np.append(dominant, len(xy) - 1))
        old = [_old_inflection(xy, a, b, support, 0.0) for a, b in itertools.pairwise(dominant)]
        assert contour.inflections(xy, dominant, support, 0.0).tolist() == [
            -1 if q is None else q for q in old
        ]
