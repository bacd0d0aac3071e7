"""Closed-form IK and FK of the planar two-link arm (hypothesis, with FK as the oracle)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from tagbot.arm.kinematics import Arm, angles_to_ticks, ticks_to_angles, unwrap_into, wrap_into
from tagbot.arm.profile import load_profile

lengths = st.floats(20.0, 400.0)
offsets = st.floats(-500.0, 500.0)
unit = arrays(np.float64, st.integers(1, 64), elements=st.floats(0.0, 1.0))

TOLERANCE_MM = 1e-9
AWAY = 1e-4
"""Points stay this fraction of the reach ring's width from its circles (the singular poses)."""


@st.composite
def arms(draw: st.DrawFn) -> Arm:
    return Arm(
        draw(lengths), draw(lengths), draw(offsets), draw(offsets), draw(st.sampled_from([1, -1]))
    )


@settings(max_examples=300, deadline=None)
@given(arm=arms(), radial=unit, angular=unit)
def test_fk_of_ik_is_the_point(arm: Arm, radial: np.ndarray, angular: np.ndarray) -> None:
    n = min(len(radial), len(angular))
    inner, outer = arm.reach
    width = outer - inner
    r = inner + width * (AWAY + (1 - 2 * AWAY) * radial[:n])
    theta = 2 * math.pi * angular[:n]
    p = np.column_stack([arm.base_x + r * np.cos(theta), arm.base_y + r * np.sin(theta)])
    q = arm.ik(p)
    assert not np.isnan(q).any()
    assert np.all(np.sign(q[:, 1]) == arm.branch)
    assert np.max(np.abs(arm.fk(q) - p)) <= TOLERANCE_MM


@settings(max_examples=300, deadline=None)
@given(arm=arms(), a1=unit, a2=unit)
def test_ik_of_fk_is_the_pose_on_its_branch(arm: Arm, a1: np.ndarray, a2: np.ndarray) -> None:
    n = min(len(a1), len(a2))
    q = np.column_stack(
        [
            -math.pi + 2 * math.pi * a1[:n],
            arm.branch * (1e-3 + (math.pi - 2e-3) * a2[:n]),
        ]
    )
    back = arm.ik(arm.fk(q))
    turn = np.angle(np.exp(1j * (back[:, 0] - q[:, 0])))  # a1 compared modulo 2π
    assert np.max(np.abs(turn)) < 1e-9
    assert np.max(np.abs(back[:, 1] - q[:, 1])) < 1e-9


def test_out_of_reach_is_nan_and_the_branch_mirrors() -> None:
    arm = Arm(150.0, 100.0, 10.0, -5.0, 1)
    q = arm.ik([[10.0 + 251.0, -5.0], [10.0 + 49.0, -5.0], [10.0 + 200.0, -5.0]])
    assert np.isnan(q[:2]).all() and not np.isnan(q[2]).any()
    other = Arm(150.0, 100.0, 10.0, -5.0, -1).ik([[210.0, -5.0]])
    assert other[0, 1] == pytest.approx(-q[2, 1])
    assert np.allclose(Arm(150.0, 100.0, 10.0, -5.0, -1).fk(other), [[210.0, -5.0]])


def test_jacobian_matches_differences() -> None:
    arm = Arm(150.0, 120.0, 3.0, 4.0, -1)
    rng = np.random.default_rng(1)
    q = np.column_stack([rng.uniform(-3, 3, 50), -rng.uniform(0.2, 2.9, 50)])
    w = rng.normal(size=(50, 2))
    h = 1e-6
    numeric = (arm.fk(q + h * w) - arm.fk(q - h * w)) / (2 * h)
    assert np.allclose(arm.tip_velocity(q, w), numeric, atol=1e-5)
    assert np.allclose(arm.joint_velocity(q, arm.tip_velocity(q, w)), w, atol=1e-9)


def test_unwrapped_runs_do_not_jump_and_land_in_range() -> None:
    a = np.angle(np.exp(1j * np.linspace(2.5, 4.0, 100)))  # crosses ±π
    run = unwrap_into(a, math.radians(-30), math.radians(250))
    assert np.max(np.abs(np.diff(run))) < 0.1
    assert run[0] == pytest.approx(2.5) and run[-1] == pytest.approx(4.0)
    wrapped, inside = wrap_into(
        [-3.0, 3.0, math.radians(260)], math.radians(-30), math.radians(250)
    )
    assert np.allclose(wrapped[:2], [2 * math.pi - 3.0, 3.0]) and inside.tolist() == [
        True,
        True,
        False,
    ]


def test_ticks_follow_the_convention() -> None:
    profile = load_profile(None, ["shoulder.sign=-1", "shoulder.zero=3072", "shoulder.min_deg=-10"])
    shoulder, elbow = profile.joints
    # angle_rad = sign·(ticks − zero)·2π/4096
    assert angles_to_ticks(math.pi / 2, shoulder) == 3072 - 1024
    assert angles_to_ticks(math.pi / 2, elbow) == 2048 + 1024
    ticks = np.arange(0, 4096, 7)
    assert np.array_equal(angles_to_ticks(ticks_to_angles(ticks, shoulder), shoulder), ticks)
    assert ticks_to_angles(3072, shoulder) == 0.0


def test_tip_resolution_is_one_tick_through_the_jacobian() -> None:
    arm = Arm(150.0, 120.0, 3.0, 4.0, 1)
    rng = np.random.default_rng(2)
    q = np.column_stack([rng.uniform(-3, 3, 40), rng.uniform(0.1, 3.0, 40)])
    tick = 2 * math.pi / 4096
    rho = arm.tip_resolution(q)
    h = 1e-6
    for pose, r in zip(q, rho, strict=True):
        # The Jacobian by differences of FK, its smallest singular value times one tick.
        columns = [(arm.fk(pose + h * e) - arm.fk(pose - h * e)) / (2 * h) for e in np.eye(2)]
        sigma = np.linalg.svd(np.column_stack(columns), compute_uv=False)
        assert r == pytest.approx(tick * sigma[-1], rel=1e-6)
        # A pen move shorter than that, in any direction, is under one tick on both joints.
        angle = rng.uniform(0, 2 * math.pi, 64)
        moves = 0.999 * r * np.column_stack([np.cos(angle), np.sin(angle)])
        back = arm.ik(arm.fk(pose) + moves)
        assert np.max(np.abs(back - pose)) < tick
        # ... and some move a hair longer needs more than a tick (the bound is tight).
        longer = arm.ik(arm.fk(pose) + 1.01 * moves)
        assert np.max(np.hypot(*(longer - pose).T)) > tick
    assert arm.tip_resolution([0.3, 1.0], step=2 * tick) == pytest.approx(
        2 * arm.tip_resolution([0.3, 1.0])
    )
