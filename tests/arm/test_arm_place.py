"""Placement in the safe workspace, uniform retiming to the joint limits, refusals up front."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import tagbot
from tagbot.arm import Arm, build_program, check_program, load_profile, place
from tagbot.arm.place import FINE_STEP, approach, safe
from tagbot.errors import PlacementError
from tagbot.model import evaluate_plan
from tagbot.model.motion import sample_plan

from .conftest import small_tag, two_plan_tag

EXAMPLES = Path(tagbot.__file__).parent / "examples"


def _pen_down_points(tag, placement) -> np.ndarray:
    points = np.concatenate([sample_plan(tag, k, FINE_STEP)[1] for k in range(len(tag.plans))])
    return points @ placement.matrix.T + placement.offset


def test_fit_is_the_largest_safe_box_aspect_kept() -> None:
    profile = load_profile()
    tag = tagbot.load_plan(EXAMPLES / "cae.json")
    placed = place(tag, profile)
    assert np.allclose(placed.matrix, placed.mm_per_unit * np.eye(2))  # no rotation, no mirror
    points = _pen_down_points(tag, placed)
    assert safe(points, profile).all()
    # The box itself (not only the tag) is in the safe workspace, and 1 % larger fits nowhere.
    x0, x1, y0, y1 = placed.box
    corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1], [(x0 + x1) / 2, y0]])
    assert safe(corners, profile).all()
    bigger = load_profile(None, [f"place.scale={placed.largest * 1.01}"])
    with pytest.raises(PlacementError, match="fits nowhere"):
        place(tag, bigger)


def test_explicit_scale_and_rotation() -> None:
    profile = load_profile(None, ["place.scale=3", "place.rotation=90"])
    placed = place(small_tag(), profile)
    assert placed.mm_per_unit == 3.0
    assert np.allclose(placed.matrix, [[0.0, -3.0], [3.0, 0.0]], atol=1e-12)
    x0, x1, y0, y1 = placed.box
    assert x1 - x0 == pytest.approx(3 * 6.0, abs=0.1)  # the 6-unit rise now runs along -x
    assert y1 - y0 == pytest.approx(3 * 10.0, abs=0.1)


def test_too_large_a_scale_is_refused_naming_the_largest() -> None:
    profile = load_profile(None, ["place.scale=100"])
    with pytest.raises(PlacementError) as raised:
        place(small_tag(), profile)
    message = str(raised.value)
    assert message.startswith("place.scale: 100 mm per unit makes the tag 1000.0 x 600.0 mm")
    assert "the largest that fits is" in message


def test_unreachable_area_is_refused() -> None:
    profile = load_profile(None, ["area.x_min=400", "area.x_max=600"])
    with pytest.raises(PlacementError, match="no part of the area"):
        place(small_tag(), profile)


def test_joint_limits_shrink_the_workspace() -> None:
    wide = place(small_tag(), load_profile())
    narrow_profile = load_profile(None, ["shoulder.min_deg=80", "shoulder.max_deg=100"])
    narrow = place(small_tag(), narrow_profile)
    assert narrow.mm_per_unit < 0.5 * wide.mm_per_unit
    arm = Arm.from_profile(narrow_profile)
    q = arm.ik(_pen_down_points(small_tag(), narrow))
    assert np.all(np.degrees(q[:, 0]) >= 80 - 1e-6) and np.all(np.degrees(q[:, 0]) <= 100 + 1e-6)
    with pytest.raises(PlacementError, match="fits nowhere"):
        place(
            small_tag(),
            load_profile(
                None,
                ["shoulder.min_deg=80", "shoulder.max_deg=100", f"place.scale={wide.mm_per_unit}"],
            ),
        )


@pytest.mark.parametrize("rate", [100, 200, 500])
def test_retiming_keeps_joint_limits_with_one_scale(rate: int) -> None:
    profile = load_profile(None, [f"motion.rate={rate}", "shoulder.max_speed=90"])
    program = build_program(tagbot.load_plan(EXAMPLES / "letter-b.json"), profile)
    sp = program.setpoints
    assert sp.time_scale > 1.0 and sp.period == pytest.approx(1 / rate)
    assert np.allclose(np.diff(sp.t), 1 / rate)
    ratios = []
    for i, joint in enumerate(profile.joints):
        rate_of = np.abs(np.diff(program.angles[:, i])) * rate
        assert rate_of.max() <= joint.max_speed * (1 + 1e-6)
        ratios.append(rate_of[sp.plan[1:] >= 0].max() / joint.max_speed)
        acc = np.abs(np.diff(program.angles[:, i], 2)) * rate**2
        assert acc.max() <= joint.max_acceleration * (1 + 1e-6)
    # The scale is no larger than needed: the shoulder's speed limit is (nearly) reached.
    assert max(ratios) > 0.98
    # The pen-down samples are the tag's own motion, slowed down by s (same path, speed / s).
    tag = tagbot.load_plan(EXAMPLES / "letter-b.json")
    plan = tag.plans[0]
    rows = np.flatnonzero(sp.plan == 0)
    tau = np.arange(1, len(rows) + 1) / rate / sp.time_scale  # the draw rows follow the start
    xy, _ = evaluate_plan(plan, plan.start + tau, tag.size)
    placed = xy @ sp.placement.matrix.T + sp.placement.offset
    assert np.allclose(placed, sp.xy[rows], atol=1e-9)


def test_branch_is_kept_and_nothing_flips() -> None:
    for branch in ("positive", "negative"):
        overrides = [f"arm.elbow={branch}"]
        if branch == "negative":
            overrides += ["elbow.min_deg=-160", "elbow.max_deg=-10", "motion.park_elbow=-135"]
            overrides += ["shoulder.min_deg=-20", "shoulder.max_deg=220", "motion.park_shoulder=90"]
        profile = load_profile(None, overrides)
        program = build_program(tagbot.load_plan(EXAMPLES / "cae.json"), profile)
        elbow = program.angles[:, 1]
        assert np.all(np.sign(elbow) == (1 if branch == "positive" else -1))
        # No jumps: at most a joint speed limit's worth per tick.
        assert np.max(np.abs(np.diff(program.angles, axis=0))) < math.radians(180) / 100 * 1.001
        arm = Arm.from_profile(profile)
        down = program.setpoints.pen
        assert np.allclose(arm.fk(program.angles[down]), program.setpoints.xy[down], atol=1e-9)


def test_program_layout_and_pen(profile) -> None:
    program = build_program(two_plan_tag(), profile)
    kinds = [kind for kind, *_ in program.segments]
    assert kinds == ["travel", "pen", "draw", "pen", "travel", "pen", "draw", "pen", "park"]
    goals = program.goals
    assert goals[0, 2] == profile["pen.up"] and goals[-1, 2] == profile["pen.up"]
    sp = program.setpoints
    assert set(np.unique(sp.plan)) == {-1, 0, 1}
    assert np.all(goals[sp.pen, 2] == profile["pen.down"])
    park = np.array(profile.park)
    assert np.allclose(program.angles[0], park) and np.allclose(program.angles[-1], park)
    assert program.joints.shape == (len(sp), 4)
    assert program.describe(program.segments[2][2]) == "plan 0"


def test_joint_speed_refused_before_anything() -> None:
    profile = load_profile(None, ["shoulder.max_speed=5", "motion.max_time_scale=2"])
    with pytest.raises(PlacementError) as raised:
        build_program(small_tag(), profile)
    message = str(raised.value)
    assert "must be slowed down" in message and "shoulder.max_speed" in message
    assert "motion.max_time_scale = 2" in message


def test_check_program_names_tick_and_limit(profile) -> None:
    program = build_program(small_tag(), profile)
    k = next(first for kind, _, first, _ in program.segments if kind == "draw") + 5
    bad = program.angles.copy()
    bad[k:, 1] -= math.radians(5)  # a jump of the elbow: 500°/s for one tick
    with pytest.raises(PlacementError) as raised:
        check_program(replace(program, angles=bad), profile)
    assert str(raised.value).startswith(f"tick {k} (t = {k / 100:.3f} s, plan 0): elbow speed 5")
    assert str(raised.value).endswith("above elbow.max_speed = 180°/s")
    too_far = program.angles.copy()
    too_far[k:, 1] = math.radians(161)
    with pytest.raises(PlacementError, match=r"elbow at 161.00° beyond elbow.max_deg = 160° by 1"):
        check_program(replace(program, angles=too_far), profile)
    off = program.setpoints.xy.copy()
    off[program.setpoints.pen] += [0.0, 500.0]
    with pytest.raises(PlacementError, match="outside the safe reach"):
        check_program(replace(program, setpoints=replace(program.setpoints, xy=off)), profile)


def test_approach_time_respects_the_limits(profile) -> None:
    present = np.array([2048, 2048, 0])
    goals, duration = approach(present, profile)
    elbow = profile.joint("elbow")
    assert goals.tolist() == [2048, 2048 + 1536, profile["pen.up"]]
    move = math.radians(135)  # the elbow from 0° to the park pose's 135°
    assert duration == pytest.approx(
        max(4 * move / (3 * elbow.max_speed), math.sqrt(16 * move / (3 * elbow.max_acceleration)))
    )
