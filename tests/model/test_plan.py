"""Plans and tags: validation that names the field, conventions, and stroke geometry."""

import numpy as np
import pytest

from tagbot.errors import PlanError
from tagbot.model.euler import wrap_angle
from tagbot.model.plan import (
    DEFAULT_MU,
    DEFAULT_SIGMA,
    MAX_DELAY,
    MAX_DURATION,
    MAX_SIGMA,
    MU_RANGE,
    Plan,
    Tag,
)

TARGETS = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]
GOOD = {
    "dt": [0.0, 0.2],
    "mu": [DEFAULT_MU] * 2,
    "sigma": [DEFAULT_SIGMA] * 2,
    "phi1": [0.2, -0.3],
    "phi2": [0.4, 0.1],
}


def make(targets=TARGETS, start=0.0, **changes):
    fields = {**GOOD, **changes}
    return Plan(targets, **fields, start=start)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"sigma": [DEFAULT_SIGMA, 0.0]}, r"strokes\[1\]\.sigma: must be > 0, got 0\.0"),
        ({"sigma": [-1.0, DEFAULT_SIGMA]}, r"strokes\[0\]\.sigma: must be > 0"),
        ({"dt": [0.0, -0.1]}, r"strokes\[1\]\.dt: must be >= 0"),
        ({"dt": [np.inf, 0.1]}, r"strokes\[0\]\.dt: must be finite"),
        ({"mu": [np.nan, DEFAULT_MU]}, r"strokes\[0\]\.mu: must be finite"),
        ({"phi1": [0.0, np.inf]}, r"strokes\[1\]\.phi1: must be finite"),
        ({"phi2": [0.1]}, r"strokes: expected 2 values of phi2"),
        ({"mu": 0.5}, r"strokes: expected 2 values of mu .*got a scalar"),
    ],
)
def test_bad_stroke_fields_are_named(changes, message):
    with pytest.raises(PlanError, match=message):
        make(**changes)


@pytest.mark.parametrize(
    ("field", "limit", "beyond", "message"),
    [
        ("sigma", MAX_SIGMA, 3.0000001, r"strokes\[1\]\.sigma: must be <= 3, got 3\.0000001"),
        ("dt", MAX_DELAY, 3600.5, r"strokes\[1\]\.dt: must be <= 3600 s, got 3600\.5"),
        ("mu", MU_RANGE[1], 6.0000001, r"strokes\[1\]\.mu: must be in \[-12, 6\], got 6\.0000001"),
        ("mu", MU_RANGE[0], -12.0000001, r"strokes\[1\]\.mu: must be in \[-12, 6\]"),
    ],
)
def test_stroke_fields_at_their_limits_are_kept_just_beyond_refused(field, limit, beyond, message):
    """A stroke's sigma, delay or mu exactly at its bound makes a plan; a hair past it is refused,
    naming the stroke, the bound and the value."""
    values = list(GOOD[field])
    values[1] = limit
    assert getattr(make(**{field: values}), field)[1] == limit
    values[1] = beyond
    with pytest.raises(PlanError, match=message):
        make(**{field: values})


@pytest.mark.parametrize(
    ("targets", "message"),
    [
        ([[0.0, 0.0], [np.nan, 1.0], [2.0, 2.0]], r"targets\[1\]: must be finite"),
        ([[0.0, 0.0], [0.0, np.inf], [2.0, 2.0]], r"targets\[1\]: must be finite"),
        ([[0.0, 0.0], [1.0, 1.0], [1.0, 1.0]], r"targets\[2\]: coincides with targets\[1\]"),
        ([[0.0, 0.0]], r"targets: need at least 2, got 1"),
        ([[0.0, 0.0], [5.0, 0.0], [5.0, 1e-12]], r"targets\[2\]: too close to targets\[1\]"),
        ([[0.0, 0.0], [2.5e-202, 0.0]], r"targets\[1\]: too close to targets\[0\]"),
        ([], r"targets: "),
        ([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], r"targets: expected a list of \[x, y\] pairs"),
    ],
)
def test_bad_targets_are_named(targets, message):
    with pytest.raises(PlanError, match=message):
        Plan(targets, [0.1], [DEFAULT_MU], [DEFAULT_SIGMA], [0.0], [0.0])


def test_bad_start_is_named():
    with pytest.raises(PlanError, match=r"start: must be finite"):
        make(start=np.nan)


def test_plan_errors_are_value_errors():
    assert issubclass(PlanError, ValueError)


def test_plan_is_immutable_copy():
    targets = np.array(TARGETS)
    plan = make(targets=targets)
    targets[0, 0] = 99.0
    assert plan.targets[0, 0] == 0.0
    with pytest.raises(ValueError, match="read-only"):
        plan.dt[0] = 1.0


def test_onsets_follow_the_dt_convention():
    plan = make(start=1.5, dt=[0.1, 0.25])
    np.testing.assert_allclose(plan.onsets, [1.6, 1.85])


def test_sigma_model_constructor_and_checks():
    plan = Plan.sigma_model(TARGETS, [0.0, 0.2], GOOD["mu"], GOOD["sigma"], [0.3, -0.5])
    np.testing.assert_array_equal(plan.phi1, [-0.3, 0.5])
    np.testing.assert_array_equal(plan.phi, [0.3, -0.5])
    assert plan.arcs.all()
    with pytest.raises(PlanError, match=r"strokes\[1\]\.phi: must be finite and in \(-pi, pi\)"):
        Plan.sigma_model(TARGETS, [0.0, 0.2], GOOD["mu"], GOOD["sigma"], [0.3, np.pi])
    with pytest.raises(PlanError, match=r"strokes\[0\]\.phi"):
        Plan.sigma_model(TARGETS, [0.0, 0.2], GOOD["mu"], GOOD["sigma"], [np.nan, 0.1])


def test_tag_validation():
    with pytest.raises(PlanError, match=r"plans: empty"):
        Tag(())
    with pytest.raises(PlanError, match=r"model: must be 'gamma' or 'sigma'"):
        Tag((make(),), model="delta")
    with pytest.raises(PlanError, match=r"plans\[0\]\.strokes\[0\]\.phi: a sigma-model stroke"):
        Tag((make(),), model="sigma")
    first = make()
    end = first.end(Tag((first,)).size)
    message = (
        rf"plans\[1\]: the pen touches down at 0\.5 s, before plans\[0\] lifts it off"
        rf" \({end:.6g} s\)"
    )
    with pytest.raises(PlanError, match=message):
        Tag((first, make(start=0.5)))
    Tag((first, make(start=end)))  # right after (no lift at all): fine


def test_a_tag_longer_than_four_hours_is_refused_with_its_length() -> None:
    """Three plans, the last starting 4 h after the first: the message gives the tag's length,
    from the first plan's start to the last plan's end; one ending just within 4 h is fine."""
    size = Tag((make(),)).size
    end = make().end(size)
    Tag((make(), make(start=2 * end), make(start=MAX_DURATION - 2 * end)))
    late = make(start=MAX_DURATION)
    message = rf"^plans: the tag lasts {late.end(size):.6g} s, more than 14400 s$"
    with pytest.raises(PlanError, match=message):
        Tag((make(), make(start=2 * end), late))


def test_tag_plans_overlap_in_the_air_only():
    """A tail after the lift-off may overlap the next plan; the ink may not."""
    first = make(ink=(0.0, 0.5))
    size = Tag((first,)).size
    assert first.end(size) > 0.6  # the motion goes on in the air after the lift-off
    Tag((first, make(start=0.5)))  # touches down as the first lifts off
    with pytest.raises(PlanError, match=r"plans\[1\]: the pen touches down at 0\.49 s"):
        Tag((first, make(start=0.49)))
    second = make(start=0.3, ink=(0.3, 0.6))  # touches down at 0.6, its approach in the air
    Tag((first, second))


@pytest.mark.parametrize("sigma_model", [False, True])
def test_stroke_geometry_meets_targets_and_tangents(sigma_model):
    rng = np.random.default_rng(7)
    targets = np.cumsum(rng.normal(size=(12, 2)), axis=0)
    n = len(targets) - 1
    phi1, phi2 = rng.uniform(-3.0, 3.0, n), rng.uniform(-3.0, 3.0, n)
    if sigma_model:
        plan = Plan.sigma_model(targets, np.zeros(n), np.zeros(n), np.ones(n), phi2)
        phi1 = -phi2
    else:
        plan = Plan(targets, np.zeros(n), np.zeros(n), np.ones(n), phi1, phi2)
    g = plan.geometry
    chord = np.diff(targets, axis=0)
    alpha = np.arctan2(chord[:, 1], chord[:, 0])
    scale = np.hypot(chord[:, 0], chord[:, 1])
    np.testing.assert_allclose(g.point(np.zeros(n)), targets[:-1], atol=1e-15)
    assert np.all(np.hypot(*(g.end - targets[1:]).T) < 1e-10 * scale)
    assert np.all(np.abs(wrap_angle(g.theta0 - (alpha + phi1))) < 1e-12)
    assert np.all(np.abs(wrap_angle(g.theta(g.length) - (alpha + phi2))) < 1e-9)


def test_sigma_arc_length_is_chord_times_phi_over_sin_phi():
    phi = np.array([1e-9, 0.4, -1.3, 3.0])
    targets = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 9.0], [0.0, 9.0], [0.0, 8.0]])
    plan = Plan.sigma_model(targets, np.zeros(4), np.zeros(4), np.ones(4), phi)
    chord = np.hypot(*np.diff(targets, axis=0).T)
    np.testing.assert_allclose(plan.geometry.length, chord * phi / np.sin(phi), rtol=1e-12)
    np.testing.assert_array_equal(plan.geometry.dkappa, 0.0)


def test_gamma_with_opposite_phis_is_the_sigma_arc():
    gamma = Plan(TARGETS, [0.0, 0.2], GOOD["mu"], GOOD["sigma"], [-0.3, 0.5], [0.3, -0.5])
    sigma = Plan.sigma_model(TARGETS, [0.0, 0.2], GOOD["mu"], GOOD["sigma"], [0.3, -0.5])
    spiral = gamma.geometry
    arc = sigma.geometry
    for name in ("theta0", "kappa0", "dkappa", "length"):
        np.testing.assert_array_equal(getattr(spiral, name), getattr(arc, name))
