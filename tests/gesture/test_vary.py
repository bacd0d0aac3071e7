"""Variations (paper §7)."""

import numpy as np
import pytest

from tagbot.errors import PlanError
from tagbot.gesture import Variation, new_seed, vary
from tagbot.metrics import pen_down_paths, shape_error
from tagbot.model.plan import DEFAULT_MU, DEFAULT_SIGMA, PHI_LIMIT, Plan, Tag


def example_tag(model="gamma"):
    a = np.array([[0.0, 0.0], [20.0, 30.0], [40.0, 0.0], [60.0, 25.0]])
    b = np.array([[70.0, 0.0], [90.0, 20.0], [100.0, 0.0]])
    plans = []
    start = 0.0
    for targets in (a, b):
        n = len(targets) - 1
        args = (targets, [0.0] + [0.2] * (n - 1), [DEFAULT_MU] * n, [DEFAULT_SIGMA] * n)
        if model == "sigma":
            plan = Plan.sigma_model(*args, [0.4] * n, start)
        else:
            plan = Plan(*args, [0.4] * n, [0.1] * n, start)
        plans.append(plan)
        start = 3.0
    return Tag(tuple(plans), model)


def test_same_seed_same_instances_other_seed_others():
    tag = example_tag()
    first, again, other = vary(tag, 4, 11), vary(tag, 4, 11), vary(tag, 4, 12)
    for a, b in zip(first, again, strict=True):
        for pa, pb in zip(a.plans, b.plans, strict=True):
            np.testing.assert_array_equal(pa.targets, pb.targets)
            np.testing.assert_array_equal(pa.dt, pb.dt)
            assert pa.start == pb.start
    assert not np.array_equal(first[0].plans[0].targets, other[0].plans[0].targets)
    assert not np.array_equal(first[0].plans[0].targets, first[1].plans[0].targets)


def test_zero_amplitudes_reproduce_the_tag():
    tag = example_tag()
    (same,) = vary(tag, 1, 3, Variation(position=0, scale=0, dt=0, phi=0))
    for a, b in zip(tag.plans, same.plans, strict=True):
        np.testing.assert_allclose(a.targets, b.targets, atol=1e-12)
        np.testing.assert_allclose(a.dt, b.dt)
        np.testing.assert_allclose(a.phi1, b.phi1)
        assert a.start == pytest.approx(b.start)


def test_default_variations_stay_readable_and_keep_lifts():
    tag = example_tag()
    original = pen_down_paths(tag.sample(0.005))
    lift = tag.plans[1].start - tag.plans[0].end(tag.size)
    for instance in vary(tag, 10, 5):
        error = shape_error(original, pen_down_paths(instance.sample(0.005)))
        assert 0.001 < error.mean < 0.05
        gap = instance.plans[1].start - instance.plans[0].end(instance.size)
        assert gap == pytest.approx(lift, rel=1e-9)


def test_strokes_bent_to_the_fits_limit_stay_their_size():
    """A stroke whose tangents deviate as much as the fits allow (±3 rad, a tight spiral) is
    varied like any other: no tangent bent beyond that limit (towards ±π the Euler spiral between
    the same two targets grows without bound), so every variation keeps about the tag's size; a
    tangent already beyond the limit (drawn in the studio) is never bent further out."""
    targets = np.array([[0.0, 0.0], [40.0, 10.0], [80.0, 0.0], [120.0, 20.0]])
    args = (targets, [0.0, 0.2, 0.2], [DEFAULT_MU] * 3, [DEFAULT_SIGMA] * 3)
    tag = Tag((Plan(*args, [0.3, -3.0, PHI_LIMIT], [0.1, 3.0, 0.2]),))
    width = np.ptp(tag.sample(0.005).xy, axis=0)
    for instance in vary(tag, 40, 8):
        plan = instance.plans[0]
        assert np.all(np.abs(plan.phi1) <= PHI_LIMIT) and np.all(np.abs(plan.phi2) <= PHI_LIMIT)
        assert np.all(np.ptp(instance.sample(0.005).xy, axis=0) < 1.5 * width)
    designed = Tag((Plan(*args, [0.3, -3.1, 0.0], [0.1, 3.1, 0.2]),))
    for instance in vary(designed, 20, 9):
        plan = instance.plans[0]
        assert abs(plan.phi1[1]) <= 3.1 + 1e-12 and abs(plan.phi2[1]) <= 3.1 + 1e-12
    assert any(abs(v.plans[0].phi1[1]) < 3.1 for v in vary(designed, 20, 9))  # (still varied)


def test_targets_close_together_move_together():
    """Targets are displaced by a smooth field over the tag: two targets 0.4 mm apart (a tiny
    loop) stay about that close in every variation, while targets across the tag move on their
    own (by about the 1.2 % of its size each)."""
    targets = np.array([[0.0, 0.0], [50.0, 10.0], [50.3, 10.25], [100.0, 0.0]])
    args = (targets, [0.0, 0.2, 0.2], [DEFAULT_MU] * 3, [DEFAULT_SIGMA] * 3)
    tag = Tag((Plan(*args, [0.3, -3.0, 0.2], [0.1, 3.0, 0.2]),))
    near, far = [], []
    for instance in vary(tag, 60, 4, Variation(scale=0.0)):
        moved = instance.plans[0].targets - targets
        near.append(np.hypot(*(moved[2] - moved[1])))
        far.append(np.hypot(*(moved[3] - moved[0])))
    assert max(near) < 0.2  # mm: the loop's chord (0.39 mm) kept within half of itself
    assert 0.01 * tag.size < np.sqrt(np.mean(np.square(far))) < 0.03 * tag.size


def test_sigma_tags_stay_sigma():
    for instance in vary(example_tag("sigma"), 5, 1):
        assert instance.model == "sigma"
        assert all(plan.arcs.all() for plan in instance.plans)


def test_new_seeds_differ():
    assert new_seed() != new_seed()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [({"count": 0}, "count"), ({"count": 2.5}, "count"), ({"seed": -1}, "seed")],
)
def test_bad_arguments(kwargs, message):
    args = {"count": 2, "seed": 1, **kwargs}
    with pytest.raises(PlanError, match=message):
        vary(example_tag(), args["count"], args["seed"])
    with pytest.raises(PlanError, match="position"):
        Variation(position=-1)
