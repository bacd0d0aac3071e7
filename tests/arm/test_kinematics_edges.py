"""Kinematics at its edges: the documented ranges at their boundaries, float64 results whatever
the input's float type, and the exact conventions (issue 34: what a mutant of them changes)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tagbot.arm.kinematics import (
    RAD_PER_TICK,
    Arm,
    angles_to_ticks,
    ticks_to_angles,
    unwrap_into,
    wrap_into,
)
from tagbot.arm.profile import Joint, load_profile

ARM = Arm(150.0, 120.0, 3.0, -4.0, 1)
POINTS = np.array([[120.3, 80.7], [-60.25, 190.5], [30.125, -140.75]])
POSES = np.array([[0.3, 1.1], [-2.7, 0.45], [2.9, 2.6]])


def test_results_are_float64_and_those_of_the_float64_input() -> None:
    """A float32 array (a coordinate file read as float32) gives the float64 answer of the same
    values: every function returns float64, computed in float64."""
    pairs = [
        (lambda a: ARM.ik(a), POINTS),
        (lambda a: ARM.fk(a), POSES),
        (lambda a: ARM.tip_resolution(a), POSES),
        (lambda a: ARM.joint_velocity(a, [[30.5, -12.25]] * 3), POSES),
        (lambda a: ARM.joint_velocity(POSES, a), POINTS),
        (lambda a: ARM.tip_velocity(a, [[0.7, -1.3]] * 3), POSES),
        (lambda a: ARM.tip_velocity(POSES, a), POSES),
        (lambda a: unwrap_into(a, -0.5, 3.6), np.array([0.1, 3.1, -3.1, 7.0])),
        (lambda a: wrap_into(a, -0.5, 3.6)[0], np.array([0.1, 3.1, -3.1, 7.0])),
    ]
    for f, values in pairs:
        single = values.astype(np.float32)
        exact = f(single.astype(np.float64))
        got = f(single)
        assert got.dtype == np.float64
        assert np.array_equal(got, exact, equal_nan=True)


def test_ticks_and_angles_of_integer_and_float32_input() -> None:
    joint = Joint("shoulder", 1, "XM430-W350", 1024, -1, -0.5, 3.6, 4.0, 50.0)
    ticks = np.array([0, 1023, 1024, 1025, 4095])
    angles = ticks_to_angles(ticks, joint)
    assert angles.dtype == np.float64
    assert np.array_equal(angles, -(ticks - 1024.0) * (2 * math.pi / 4096))
    assert np.array_equal(ticks_to_angles(ticks.astype(np.float32), joint), angles)
    back = angles_to_ticks(angles.astype(np.float32), joint)
    assert back.dtype == np.int64 and np.array_equal(back, ticks)
    # float32 angles a hair off half a tick round as their float64 values do.
    half = ((np.arange(-1000, 1000) + 0.5) * RAD_PER_TICK).astype(np.float32)
    near = np.concatenate([np.nextafter(half, np.float32(-9)), np.nextafter(half, np.float32(9))])
    expected = np.rint(1024.0 - near.astype(np.float64) / (2 * math.pi / 4096))
    assert np.array_equal(angles_to_ticks(near, joint), expected)


def test_ticks_round_to_the_nearest_whole_tick() -> None:
    joint = load_profile().joints[1]  # zero 2048, sign +1
    # 0.4 tick rounds down, 0.6 up, and −0.6 down: nearest, not truncated toward zero.
    assert angles_to_ticks(0.4 * RAD_PER_TICK, joint) == 2048
    assert angles_to_ticks(0.6 * RAD_PER_TICK, joint) == 2049
    assert angles_to_ticks(-0.6 * RAD_PER_TICK, joint) == 2047
    assert 2 * math.pi / 4096 == RAD_PER_TICK


@pytest.mark.parametrize("y", [0.0, -0.0])
def test_ik_shoulder_angle_is_pi_not_minus_pi_straight_behind(y: float) -> None:
    """``a1`` lies in (−π, π]: the point straight behind the shoulder at full reach (y written
    −0.0 as a computation may leave it) is π, never −π."""
    arm = Arm(150.0, 120.0)
    q = arm.ik([-270.0, y])
    assert q[0] == math.pi and q[1] == 0.0


def test_ik_angles_stay_in_their_range_all_around() -> None:
    arm = Arm(150.0, 120.0, 0.0, 0.0, -1)
    theta = np.linspace(-math.pi, math.pi, 721)
    p = np.column_stack([200.0 * np.cos(theta), 200.0 * np.sin(theta)])
    q = arm.ik(p)
    assert np.all(q[:, 0] > -math.pi) and np.all(q[:, 0] <= math.pi)
    assert np.all(q[:, 1] < 0)
    assert np.allclose(arm.fk(q), p, atol=1e-9)


def test_reach_circles_are_reachable_and_a_hair_beyond_is_not() -> None:
    arm = Arm(150.0, 100.0, 10.0, -5.0)
    inner, outer = arm.reach
    assert (inner, outer) == (50.0, 250.0)
    on = arm.ik([[10.0 + outer, -5.0], [10.0, -5.0 + inner]])
    assert not np.isnan(on).any()
    assert np.allclose(arm.fk(on), [[10.0 + outer, -5.0], [10.0, -5.0 + inner]], atol=1e-6)
    beyond = arm.ik([[10.0 + outer + 1e-9, -5.0], [10.0, -5.0 + inner - 1e-9]])
    assert np.isnan(beyond).all()
    assert Arm(100.0, 150.0).reach == (50.0, 250.0)


def test_wrap_into_a_hair_below_lower_is_lower() -> None:
    """``(a − lower) mod 2π`` rounds to exactly 2π for an angle a hair below ``lower``: that angle
    is ``lower`` itself, inside the range."""
    for lower in (0.0, -0.5, 1.25):
        a = np.nextafter(lower, -math.inf)
        assert np.mod(a - lower, 2 * math.pi) == 2 * math.pi  # the rounding this is about
        wrapped, inside = wrap_into(a, lower, lower + 1.0)
        assert float(wrapped) == lower and bool(inside)


def test_wrap_into_boundaries_and_nan() -> None:
    wrapped, inside = wrap_into([-0.5, 3.5, 3.5 + 1e-9, 3.5 - 2 * math.pi, math.nan], -0.5, 3.5)
    assert inside.tolist() == [True, True, False, True, False]
    assert wrapped[0] == -0.5 and wrapped[1] == 3.5
    assert wrapped[3] == pytest.approx(3.5, abs=1e-12)
    assert math.isnan(wrapped[4])
    # Whole turns only: 3 turns above lower + 0.25 is lower + 0.25.
    assert float(wrap_into(-0.5 + 0.25 + 6 * math.pi, -0.5, 3.6)[0]) == pytest.approx(-0.25)


def test_unwrap_into_moves_the_run_by_whole_turns_as_one() -> None:
    assert unwrap_into([], 0.0, 1.0).shape == (0,)
    run = np.array([3.0, -3.1, -2.9])  # crosses +π: one continuous run
    out = unwrap_into(run, -0.5, 3.6)
    assert np.allclose(out, [3.0, 2 * math.pi - 3.1, 2 * math.pi - 2.9])
    # A first angle inside its range stays put (no turn added), also at the range's ends.
    assert np.array_equal(unwrap_into([3.5, 3.25], -0.5, 3.5), [3.5, 3.25])
    assert np.array_equal(unwrap_into([-0.5, -0.25], -0.5, 3.5), [-0.5, -0.25])
    # One that is in no turn of the range goes to the turn nearest the range's middle.
    near = unwrap_into([5.0 + 4 * math.pi, 5.1 + 4 * math.pi], 0.0, 1.0)
    assert np.allclose(near, [5.0 - 2 * math.pi, 5.1 - 2 * math.pi])
    far = unwrap_into([2.0], 0.0, 1.0)  # 2.0 is nearer 0.5 than 2.0 − 2π is
    assert np.allclose(far, [2.0])
    # Either side of the middle (1.5) of [1, 2], 2.9 away: within π of it, so no turn added.
    for a in (4.4, -1.4):
        assert np.array_equal(unwrap_into([a, a + 0.1], 1.0, 2.0), [a, a + 0.1])
    # In range, the first angle goes where wrap_into puts it, also for a range wider than a turn.
    for a in (-2.9, 3.9, 10.0):
        out = unwrap_into([a], -3.0, 4.0)
        assert out[0] == pytest.approx(float(wrap_into(a, -3.0, 4.0)[0]), abs=1e-12)
    assert unwrap_into([-2.9], -3.0, 4.0)[0] == pytest.approx(-2.9, abs=1e-12)


def test_arm_refuses_bad_geometry_and_takes_the_profile() -> None:
    with pytest.raises(ValueError, match=r"l1, l2: must be > 0, got 0\.0, 1\.0"):
        Arm(0.0, 1.0)
    with pytest.raises(ValueError, match=r"l1, l2: must be > 0, got 1\.0, -1\.0"):
        Arm(1.0, -1.0)
    for l1, l2 in ((1.0, 0.0), (0.0, 1.0)):
        with pytest.raises(ValueError, match=r"l1, l2: must be > 0"):
            Arm(l1, l2)
    with pytest.raises(ValueError, match=r"branch: must be 1 or -1, got 0"):
        Arm(1.0, 1.0, branch=0)
    profile = load_profile(
        None,
        [
            "arm.l1=160",
            "arm.l2=110",
            "arm.elbow=negative",
            "arm.base_x=12.5",
            "arm.base_y=-7",
            "elbow.min_deg=-160",
            "elbow.max_deg=-10",
            "motion.park_elbow=-90",
        ],
    )
    arm = Arm.from_profile(profile)
    l1, l2 = profile.links
    bx, by = profile.base
    assert (arm.l1, arm.l2, arm.base_x, arm.base_y, arm.branch) == (
        l1,
        l2,
        bx,
        by,
        profile.elbow_sign,
    )
    assert (l1, l2, bx, by, arm.branch) == (160.0, 110.0, 12.5, -7.0, -1)


def test_a_straight_elbow_has_no_finite_joint_rates_and_says_nothing():
    """At the singular pose (elbow straight, the Jacobian's determinant 0) a tip velocity has
    no finite joint rates: infinities, quietly (callers test for them), not a numpy warning."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        w = ARM.joint_velocity([[0.3, 0.0]], [[10.0, 5.0]])
    assert np.isinf(w).all()
