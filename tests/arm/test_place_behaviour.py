"""The arm's refusals at and just beyond their boundaries, and where a tag is put (issue 34)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from tagbot.arm import build_program, check_program, load_profile, place
from tagbot.arm.kinematics import Arm
from tagbot.arm.place import approach, safe
from tagbot.errors import PlacementError
from tagbot.model import Plan, Tag

from .conftest import hook_from_its_end, small_tag, two_plan_tag

# The default arm: links of 150 mm from (0, 0), reach margin 5 mm, so the safe reach ends at
# 295 mm; a tall area lets the reach (not the paper) be the limit straight up the y axis.
TALL = ["area.y_max=400"]


def test_reach_margin_holds_at_the_boundary() -> None:
    profile = load_profile(None, TALL)
    inside = np.array([[0.0, 294.9], [0.0, 200.0], [100.0, 276.0]])
    beyond = np.array([[0.0, 295.1], [0.0, 299.0], [0.0, 301.0]])
    assert safe(inside, profile).all()
    assert not safe(beyond, profile).any()
    wider = load_profile(None, [*TALL, "arm.reach_margin=2"])
    assert safe(np.array([[0.0, 297.9]]), wider).all()
    assert not safe(np.array([[0.0, 298.1]]), wider).any()


def test_area_margin_holds_at_the_boundary() -> None:
    profile = load_profile()  # area x -148.5..148.5, y 40..250, margin 10
    assert safe(np.array([[-100.0, 50.0 + 1e-3], [138.4, 150.0], [0.0, 239.9]]), profile).all()
    assert not safe(np.array([[-100.0, 49.9], [138.6, 150.0], [0.0, 240.1]]), profile).any()


def _pen_down_past_reach(profile):
    program = build_program(small_tag(), profile)
    pen = program.setpoints.pen
    xy = program.setpoints.xy.copy()
    k = int(np.flatnonzero(pen)[3])
    return program, k, xy


def test_check_program_refuses_a_pen_just_beyond_reach() -> None:
    profile = load_profile(None, TALL)
    program, k, xy = _pen_down_past_reach(profile)
    for radius, refused in ((294.9, False), (295.1, True)):
        moved = xy.copy()
        moved[k] = [0.0, radius]
        changed = replace(program, setpoints=replace(program.setpoints, xy=moved))
        if refused:
            with pytest.raises(PlacementError) as raised:
                check_program(changed, profile)
            assert str(raised.value) == (
                f"tick {k} (t = {k / 100:.3f} s, plan 0): pen at (0.00, 295.10) mm, 295.10 mm"
                " from the shoulder, is outside the safe reach 5..295 mm or the joint limits"
            )
        else:
            check_program(changed, profile)


def test_check_program_refuses_goals_outside_the_servo_range(profile) -> None:
    program = build_program(small_tag(), profile)
    check_program(program, profile)
    k = len(program) // 2
    for column, role, value in ((3, "pen", 4096), (3, "pen", -1)):
        joints = program.joints.copy()
        joints[k, column] = value
        with pytest.raises(PlacementError) as raised:
            check_program(replace(program, joints=joints), profile)
        message = str(raised.value)
        assert message.startswith(f"tick {k} (t = {k / 100:.3f} s, ")
        assert message.endswith(f"{role} goal {value} ticks is outside 0..4095")


def test_joint_at_its_limit_is_accepted_beyond_refused(profile) -> None:
    program = build_program(small_tag(), profile)
    k = len(program) // 2
    for degrees, refused in ((160.0, False), (160.01, True)):
        angles = program.angles.copy()
        angles[k:, 1] = math.radians(degrees)
        changed = replace(program, angles=angles)
        if refused:
            with pytest.raises(PlacementError, match=r"elbow at 160.01° beyond elbow.max_deg"):
                check_program(changed, profile)
        else:
            with pytest.raises(PlacementError) as raised:  # the jump is too fast: not the limit
                check_program(changed, profile)
            assert "max_deg" not in str(raised.value)


def _dot_tag() -> Tag:
    plan = Plan(
        targets=[[0.0, 0.0], [1.0, 1.0]],
        dt=[0.0],
        mu=[math.log(0.2)],
        sigma=[0.3],
        phi1=[0.0],
        phi2=[0.0],
    )
    return Tag(plans=(plan,))


def test_an_explicit_scale_is_placed_in_the_middle_of_the_safe_workspace() -> None:
    """The safe workspace of the default arm is symmetric about x = 0 and fills the area but a
    disc of 52 mm round the shoulder: a small tag's centre lands near (0, the area's middle),
    within a cell of the 61 × 61 grid of candidate centres (4.5 mm)."""
    profile = load_profile(None, ["place.scale=10"])
    x0, x1, y0, y1 = place(_dot_tag(), profile).box
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    assert abs(centre[0]) < 4.5
    assert centre[1] == pytest.approx((40.0 + 250.0) / 2, abs=8.0)


def test_the_box_a_placement_checks_is_the_unit_squares_edge_densely_and_its_inside() -> None:
    """A candidate placement is checked at points of the tag's box: every 1/48 of each edge (a
    reach boundary cannot cut a corner between two of them by more than that) and a grid
    inside, each point once."""
    from tagbot.arm.place import _box_template

    points = _box_template()
    assert np.abs(points).max() == 0.5
    assert len(np.unique(points, axis=0)) == len(points)
    for axis in (0, 1):
        for side in (-0.5, 0.5):
            along = np.sort(points[points[:, axis] == side][:, 1 - axis])
            assert along[0] == -0.5 and along[-1] == 0.5
            assert np.diff(along).max() == pytest.approx(1 / 48)
    inside = points[np.abs(points).max(axis=1) < 0.5]
    assert len(inside) == 36 and len(points) == 4 * 48 + 4 * 6 + 36  # the grid meets the edges too
    assert np.diff(np.unique(inside[:, 0])) == pytest.approx(np.full(5, 1 / 7))


@pytest.mark.parametrize("boundary", [1 / 3, 0.5 + 1e-7, 0.9876543])
def test_a_boundary_is_found_to_a_nanosecond_below_it(boundary) -> None:
    """Where a run is trimmed (a predicate true below an instant, false above it) is found from
    below, within 1e-9 of the instant (relative to it above 1 s), never beyond it."""
    from tagbot.arm.place import _bisect

    for scale in (1.0, 40.0):
        b = boundary * scale
        found = _bisect(lambda t, b=b: t < b, 0.0, scale)
        assert found < b and b - found <= 1e-9 * max(1.0, b)


def test_each_part_of_the_program_is_described_by_its_kind() -> None:
    """A refusal names the part of the program a tick is in: the travel and pen moves before
    each plan, the plan itself, and the final travel to park."""
    program = build_program(two_plan_tag(), load_profile())
    described = []
    for _, _, first, stop in program.segments:
        assert program.describe(first) == program.describe(stop - 1)
        described.append(program.describe(first))
    assert described == [
        *("travel at plan 0", "pen move at plan 0", "plan 0", "pen move at plan 0"),
        *("travel at plan 1", "pen move at plan 1", "plan 1", "pen move at plan 1"),
        "travel to park",
    ]


def test_a_tag_that_inks_only_before_it_moves_has_no_extent_to_place() -> None:
    """A plan whose pen is down only for its first 10 ms, while the stroke has not yet moved
    (the lognormal's onset: less than 1e-20 units), leaves a dot: there is nothing to scale."""
    plan = Plan(
        targets=[[0.0, 0.0], [10.0, 0.0]],
        dt=[0.0],
        mu=[math.log(0.2)],
        sigma=[0.3],
        phi1=[0.0],
        phi2=[0.0],
        ink=(0.0, 0.01),
    )
    with pytest.raises(PlacementError) as refused:
        place(Tag(plans=(plan,)), load_profile())
    assert str(refused.value) == "place.scale: the tag has no extent to place"


def test_a_three_tick_program_is_held_to_the_acceleration_limit(profile) -> None:
    """Three ticks are the fewest with an acceleration: an elbow standing, then moving 0.01
    rad in one 10 ms tick (1 rad/s, within its speed) accelerates at 100 rad/s², above its
    3000°/s² (52.4 rad/s²): refused; 0.005 rad (50 rad/s²) is accepted."""
    program = build_program(small_tag(), profile)
    for step, refused in ((0.005, False), (0.01, True)):
        angles = np.repeat(program.angles[:1], 3, axis=0)
        angles[2, 1] += step
        changed = replace(program, angles=angles)
        if refused:
            with pytest.raises(PlacementError) as raised:
                check_program(changed, profile)
            assert str(raised.value).endswith(
                "elbow acceleration 5730°/s² above elbow.max_acceleration = 3000°/s²"
            )
            assert str(raised.value).startswith("tick 1 (t = 0.010 s, ")
        else:
            check_program(changed, profile)


def test_the_pen_lifts_after_a_run_from_down_to_up_in_equal_steps() -> None:
    """After each run the pen goes from its down position to up in pen.move_time, one equal
    step a tick, the arm still: the first goal one step above down, the last at up."""
    profile = load_profile()
    program = build_program(two_plan_tag(), profile)
    up, down = profile["pen.up"], profile["pen.down"]
    n = math.ceil(profile["pen.move_time"] / profile.period - 1e-9)
    kinds = [s[0] for s in program.segments]
    lifts = [s for i, s in enumerate(program.segments) if s[0] == "pen" and kinds[i - 1] == "draw"]
    assert len(lifts) == 2
    for _, _, first, stop in lifts:
        pen = program.joints[first:stop, 3]
        assert stop - first == n
        expected = np.rint(down + (up - down) * np.arange(1, n + 1) / n)
        assert pen.tolist() == expected.tolist()
        assert np.all(program.joints[first:stop, 1:3] == program.joints[first - 1, 1:3])


def test_a_box_of_a_millionth_of_a_millionth_of_the_room_has_no_extent() -> None:
    """A tag whose box is 1e-12 of the room (the area less its margins) on both axes is a dot:
    refused as having no extent, at exactly that fraction; at twice it, a scale is found."""
    from tagbot.arm.place import _largest

    profile = load_profile()  # area x -148.5..148.5, y 40..250, margin 10: room 277 x 190 mm
    arm = Arm.from_profile(profile)
    room = np.array([277.0, 190.0])
    with pytest.raises(PlacementError) as refused:
        _largest(1e-12 * room, profile, arm)
    assert str(refused.value) == "place.scale: the tag has no extent to place"
    largest, centre = _largest(2e-12 * room, profile, arm)
    assert largest > 0.0 and centre is not None


def test_an_approach_to_a_goal_of_the_program_lifts_its_pen(profile) -> None:
    """Approaching one of the program's goals (shoulder, elbow, pen down) gives three goals: that
    goal's shoulder and elbow ticks with the pen up, never its pen-down ticks as a fourth."""
    program = build_program(small_tag(), profile)
    row = program.goals[len(program) // 2]
    goals, _ = approach(np.array([2048, 2048, 2048]), profile, row)
    assert goals.tolist() == [int(row[0]), int(row[1]), profile["pen.up"]]


def test_a_boundary_in_a_long_span_is_found_in_as_few_halvings_as_its_tolerance_needs() -> None:
    """Finding a trim instant in a 40 s span stops once the bracket is within 1e-9 of the
    instant's size: about log2(40 / (1e-9·13.3)) = 32 evaluations of the predicate, not more."""
    from tagbot.arm.place import _bisect

    calls = []
    boundary = 40.0 / 3.0

    def below(t: float) -> bool:
        calls.append(t)
        return t < boundary

    found = _bisect(below, 0.0, 40.0)
    assert found < boundary and boundary - found <= 1e-9 * boundary
    assert len(calls) <= math.ceil(math.log2(40.0 / (1e-9 * boundary))) + 1


def test_a_run_starting_right_of_the_shoulder_keeps_the_shoulders_turn() -> None:
    """With the shoulder's range widened to -30..265° and the elbow's raised to 120..160°, a run
    that starts at a shoulder angle of a few degrees is drawn there (within the shoulder's own
    range, as the inverse kinematics gives it), not a turn round at 366°."""
    profile = load_profile(None, ["elbow.min_deg=120", "shoulder.max_deg=265", "place.scale=5"])
    program = build_program(hook_from_its_end(), profile)
    (first,) = [s[2] for s in program.segments if s[0] == "draw"]
    shoulder = program.angles[first, 0]
    expected = Arm.from_profile(profile).ik(program.setpoints.xy[first : first + 1])[0, 0]
    assert 0.0 < math.degrees(shoulder) < 14.0
    assert shoulder == pytest.approx(expected, abs=1e-9)


def test_a_run_the_sampled_limits_slow_beyond_the_cap_is_refused_naming_it() -> None:
    """A run whose 1 ms estimate is exactly motion.max_time_scale but whose samples at the loop
    period need a little more is refused, naming that plan and the slow-down it needs."""
    tag = two_plan_tag()
    slow = ["shoulder.max_speed=60", "elbow.max_speed=60", "motion.max_deviation=0"]
    uncapped = load_profile(None, [*slow, "motion.max_time_scale=100"])
    placement = place(tag, uncapped)
    free = build_program(tag, uncapped, placement)
    estimate, needed = free.setpoints.limits["speed"], free.setpoints.run_scales[0]
    assert free.setpoints.limits["sampled"] == needed > estimate
    capped = load_profile(None, [*slow, f"motion.max_time_scale={estimate!r}"])
    with pytest.raises(PlacementError) as refused:
        build_program(tag, capped, placement)
    assert str(refused.value) == (
        f"joint limits: plan 0 must be slowed down {needed:.3g} times, more than"
        f" motion.max_time_scale = {estimate:g}"
    )
