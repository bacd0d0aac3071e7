"""Motion's public figures against what they are documented to be (issue 34): the default size
of a lone plan, per-plan grids, ink sampling, the handover between overlapping plans."""

from __future__ import annotations

import numpy as np
import pytest

from tagbot.model.motion import (
    Motion,
    evaluate_plan,
    evaluate_plans,
    owned_spans,
    sample,
    sample_ink,
    sample_plan,
    sample_plans,
    sampled_plans,
)
from tagbot.model.plan import Plan, Tag

from .strategies import random_plan


def _two_plans() -> Tag:
    rng = np.random.default_rng(11)
    a = random_plan(rng, 5, 0.0, False)
    b = random_plan(rng, 4, 0.0, False)
    size = float(np.hypot(*np.ptp(np.concatenate([a.targets, b.targets]), axis=0)))
    b = Plan(b.targets + 60, b.dt, b.mu, b.sigma, b.phi1, b.phi2, a.end(size) + 0.4)
    return Tag((a, b))


@pytest.mark.parametrize("targets", [[[0.0, 0.0], [30.0, 40.0]], [[0, 0], [30, 0], [30, 40]]])
def test_a_lone_plans_windows_default_to_its_own_diagonal(targets: list[list[float]]) -> None:
    """evaluate_plan without a size is evaluate_plan at the diagonal of the plan's targets (50)."""
    n = len(targets) - 1
    plan = Plan(targets, [0.0, 0.2][:n], [-1.6] * n, [0.3] * n, [0.4] * n, [-0.2] * n)
    t = np.linspace(-0.1, plan.end(50.0) + 0.1, 301)
    xy, v = evaluate_plan(plan, t)
    xy50, v50 = evaluate_plan(plan, t, 50.0)
    np.testing.assert_array_equal(xy, xy50)
    np.testing.assert_array_equal(v, v50)
    np.testing.assert_allclose(xy[-1], targets[-1], atol=1e-6 * 50)
    # A much larger size widens the tolerance: the ends are cut sooner, visibly.
    xy_big, _ = evaluate_plan(plan, t, 5e4)
    assert np.max(np.abs(xy_big - xy)) > 1e-6


def test_plan_grids_are_each_plans_own() -> None:
    """Each plan on its own grid from its start, every ``step``, to the first sample at or past
    its end; sample_plans of a subset are those plans' grids, in the order asked."""
    tag = _two_plans()
    step = 0.004
    both = sample_plans(tag, step)
    for k, (t, xy, v) in enumerate(both):
        plan = tag.plans[k]
        end = plan.end(tag.size)
        count = int(np.ceil((end - plan.start) / step - 1e-9)) + 1
        np.testing.assert_allclose(t, plan.start + step * np.arange(count), atol=1e-12)
        assert t[-1] >= end - 1e-9 and t[-2] < end
        exy, ev = evaluate_plan(plan, t, tag.size)
        np.testing.assert_array_equal(xy, exy)
        np.testing.assert_array_equal(v, ev)
    (t1, xy1, v1), (t0, _, _) = sample_plans(tag, step, [1, 0])
    np.testing.assert_array_equal(t1, both[1][0])
    np.testing.assert_array_equal(xy1, both[1][1])
    np.testing.assert_array_equal(v1, both[1][2])
    np.testing.assert_array_equal(t0, both[0][0])
    t, xy, _ = sample_plan(tag, 1, step)
    np.testing.assert_array_equal(xy, both[1][1])
    joined_t, joined_xy, _, first = sampled_plans(tag, step)
    assert first.tolist() == [0, len(both[0][0]), len(both[0][0]) + len(both[1][0])]
    np.testing.assert_array_equal(joined_xy[first[1] :], both[1][1])
    np.testing.assert_array_equal(joined_t[: first[1]], both[0][0])


def test_ink_samples_run_from_touch_down_to_lift_off() -> None:
    tag = _two_plans()
    a, b = tag.plans
    off = 0.5 * a.end(tag.size)
    inked = Tag((Plan(a.targets, a.dt, a.mu, a.sigma, a.phi1, a.phi2, 0.0, (0.05, off)), b))
    (t0, xy0, v0), (t1, _, _) = sample_ink(inked, 0.01)
    assert t0[0] == pytest.approx(0.05) and t0[-1] == pytest.approx(off)
    assert np.all(np.diff(t0)[:-1] == pytest.approx(0.01)) and 0 < t0[-1] - t0[-2] <= 0.01 + 1e-12
    exy, ev = evaluate_plan(inked.plans[0], t0, inked.size)
    np.testing.assert_array_equal(xy0, exy)
    np.testing.assert_array_equal(v0, ev)
    assert t1[0] == b.start and t1[-1] == pytest.approx(b.end(inked.size))
    assert sample_ink(inked, 0.01, []) == [] and evaluate_plans([], [], 10.0) == []


def test_overlapping_plans_hand_over_halfway_between_lift_off_and_touch_down() -> None:
    tag = _two_plans()
    a, b = tag.plans
    size = tag.size
    off = 0.6 * a.end(size)
    a = Plan(a.targets, a.dt, a.mu, a.sigma, a.phi1, a.phi2, 0.0, (0.0, off))
    start = off - 0.1
    b = Plan(b.targets, b.dt, b.mu, b.sigma, b.phi1, b.phi2, start, (0.3, 0.6))
    tag = Tag((a, b))
    assert start < a.end(tag.size)
    starts, ends = owned_spans(tag)
    handover = 0.5 * (off + start + 0.3)
    assert starts == [0.0, pytest.approx(handover)] and ends[0] == starts[1]
    assert ends[1] == b.end(tag.size)
    motion = sample(tag, 0.01)
    assert len(motion) == len(motion.t) and motion.duration == motion.t[-1] - motion.t[0]
    assert [k for k, _ in motion.runs()] == [0, 1]


def test_a_run_on_the_first_sample_is_found_whatever_its_plan() -> None:
    """runs() yields a pen-down run that starts on the motion's first sample, even one of
    plans[1] (a motion cut from the middle of a tag)."""
    two = _two_plans()
    a, b = two.plans
    whole = sample(Tag((a, b, b.at(b.end(two.size) + 0.4))), 0.01)
    _, (_, second), (_, third) = whole.runs()
    cut = slice(second.start, None)
    tail = Motion(
        t=whole.t[cut],
        xy=whole.xy[cut],
        v=whole.v[cut],
        speed=whole.speed[cut],
        pen=whole.pen[cut],
        plan=whole.plan[cut],
        dt=whole.dt,
    )
    assert tail.plan[0] == 1
    assert list(tail.runs()) == [
        (1, slice(0, second.stop - second.start)),
        (2, slice(third.start - second.start, third.stop - second.start)),
    ]


def test_a_lift_of_a_single_pen_up_sample_is_sampled() -> None:
    """A pen lift that leaves exactly one pen-up sample between two runs is not too coarse for
    ``dt``: the runs end and start either side of that one sample."""
    a, b = _two_plans().plans
    a = Plan(a.targets, a.dt, a.mu, a.sigma, a.phi1, a.phi2, 0.0, (0.0, 0.5))
    b = Plan(b.targets, b.dt, b.mu, b.sigma, b.phi1, b.phi2, 0.3, (0.22, 0.6))  # down at 0.52
    motion = sample(Tag((a, b)), 0.01)
    (_, first), (_, second) = motion.runs()
    assert (first.stop, second.start) == (51, 52)
    assert motion.t[51] == pytest.approx(0.51) and motion.pen[50:53].tolist() == [1, 0, 1]
    assert motion.plan[51] == -1
