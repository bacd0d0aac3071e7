"""The serial arm's job as the user's profile sets it: the fitted tag fills the area less its
margin, a tag under one unit long still fits, travel between runs at the profile's speed, short
joint moves at their floor, and the program check's refusals at and just beyond each limit."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import tagbot
import tagbot.arm.serial.program as program_module
from tagbot.arm.kinematics import angles_to_ticks
from tagbot.arm.run import placement_of
from tagbot.arm.serial.profile import load_serial_profile
from tagbot.arm.serial.program import (
    MIN_JERK_PEAK_RATE,
    _check_clearance,
    _excess,
    _joint_move,
    _owned,
    _stroke_at,
    build_serial_program,
    check_serial_program,
    feedforward,
    move_excess,
    place_on_paper,
    profile_goals,
)
from tagbot.errors import PlacementError
from tagbot.io.planfile import load_plan
from tagbot.model import Tag
from tagbot.model.easing import EASE, run_clock
from tagbot.model.motion import evaluate_plan
from tests.model.test_ink import lifted

from ..conftest import small_tag
from .test_serial_fidelity import _stroke

EXAMPLES = Path(tagbot.__file__).parent / "examples"


@pytest.mark.parametrize(("name", "binding"), [("cae", 0), ("letter-b", 1)])
def test_a_fitted_tag_fills_the_area_less_its_margin(name, binding):
    """cae is wide (the paper's width binds), letter-b tall (its height binds); the area starts
    20 mm up the paper, so its height is y_max - y_min."""
    profile = load_serial_profile("openmanipulator-x", ["area.y_min=20"])
    x_min, x_max, y_min, y_max = profile.area
    m = profile["area.margin"]
    box = place_on_paper(load_plan(EXAMPLES / f"{name}.json"), profile).box
    room = [(x_min + m, x_max - m), (y_min + m, y_max - m)]
    for axis in (0, 1):
        low, high = box[2 * axis], box[2 * axis + 1]
        assert room[axis][0] - 1e-9 <= low and high <= room[axis][1] + 1e-9
    assert box[2 * binding] == pytest.approx(room[binding][0], abs=1e-9)
    assert box[2 * binding + 1] == pytest.approx(room[binding][1], abs=1e-9)


def test_a_tag_under_one_unit_long_is_placed_to_fit():
    profile = load_serial_profile("openmanipulator-x")
    placement = place_on_paper(small_tag(0.8), profile)
    x_min, x_max, y_min, y_max = profile.area
    m = profile["area.margin"]
    box = placement.box
    assert box[0] >= x_min + m - 1e-9 and box[1] <= x_max - m + 1e-9
    assert box[2] >= y_min + m - 1e-9 and box[3] <= y_max - m + 1e-9
    # the tag's width binds: it spans the width less the margins
    assert box[1] - box[0] == pytest.approx(x_max - x_min - 2 * m, rel=1e-9)


def test_travel_between_runs_is_no_faster_than_the_profiles_travel_speed():
    """cae's three runs: each travel lasts at least what the straight line between the pen's
    points takes at ``motion.travel_speed`` (a minimum-jerk move peaks at 1.875× its mean)."""
    profile = load_serial_profile("openmanipulator-x", ["motion.travel_speed=40"])
    program = build_serial_program(load_plan(EXAMPLES / "cae.json"), profile)
    travels = [s for s in program.segments if s[0] == "travel" and s[1] > 0]
    assert len(travels) == 2
    for _kind, _plan, first, stop in travels:
        # the pen's point over the paper, mm, where the travel starts and ends
        a, b = program.setpoints.xy[first - 1], program.setpoints.xy[stop]
        distance = float(np.hypot(*(b - a)))
        assert distance > 5.0
        took = (stop - first) * profile.period
        assert took >= MIN_JERK_PEAK_RATE * distance / 40.0 - profile.period


def test_a_travel_takes_the_ticks_its_straight_line_needs_at_the_travel_speed_and_no_more():
    """Two strokes 142 mm apart at 30 mm/s (the joints' limits far off): the travel between
    them lasts the whole ticks the straight line between the runs' ends takes at
    ``motion.travel_speed`` with the minimum-jerk peak at 1.875x its mean, both ends outside
    it."""
    first = _stroke([0.0, 0.0], [10.0, 0.0])
    last = _stroke([90.0, 90.0], [100.0, 90.0], start=first.end(15.0) + 0.3)
    profile = load_serial_profile("openmanipulator-x", ["motion.travel_speed=30"])
    program = build_serial_program(Tag(plans=(first, last)), profile)
    draws = {k: (start, stop) for kind, k, start, stop in program.segments if kind == "draw"}
    ((_kind, _plan, start, stop),) = [s for s in program.segments if s[0] == "travel" and s[1]]
    # where the first run's ink ends and the second one's starts, mm on the paper
    a, b = program.setpoints.xy[draws[0][1] - 1], program.setpoints.xy[draws[1][0]]
    ticks = 1.875 * float(np.hypot(*(b - a))) / 30.0 / profile.period
    assert ticks == pytest.approx(888.47, abs=0.01)  # whole ticks 0.47 and 0.53 away
    assert stop - start == math.ceil(ticks) - 1


def test_a_short_joint_move_takes_its_fifth_of_a_second_and_no_tick_more():
    """0.2 s at 100 Hz is 20 ticks: 21 samples, both ends included."""
    a = np.zeros(4)
    b = np.full(4, 1e-4)
    limits = np.full(4, 10.0)
    q = _joint_move(a, b, 0.01, limits, limits)
    assert len(q) == 21
    np.testing.assert_allclose(q[[0, -1]], [a, b])


def test_a_short_joint_move_at_5_hz_is_one_tick_its_two_ends():
    """At 5 Hz a fifth of a second is one tick: the move is its two ends, nothing between."""
    a = np.zeros(4)
    b = np.full(4, 1e-4)
    limits = np.full(4, 10.0)
    q = _joint_move(a, b, 0.2, limits, limits)
    np.testing.assert_allclose(q, [a, b])


def _standing(profile, ticks: int = 40):
    """A program standing at its first pose for ``ticks``: every rate and acceleration 0."""
    program = build_serial_program(load_plan(EXAMPLES / "letter-b.json"), profile)
    angles = np.repeat(program.angles[:1], ticks, axis=0)
    joints = np.repeat(program.joints[:1], ticks, axis=0)
    return replace(program, angles=angles, joints=joints)


def test_the_check_refuses_a_joint_just_beyond_its_acceleration_and_speed_not_at_them():
    profile = load_serial_profile("openmanipulator-x")
    standing = _standing(profile)
    joint, T, k = profile.joints[1], profile.period, 20
    # a step of d at tick k: the acceleration there is d/T² then -2d/T²... peak 2d/T²
    for factor, refused in ((0.999, False), (1.0, False), (1.001, True)):
        d = factor * joint.max_acceleration * T**2 / 2
        bumped = standing.angles.copy()
        bumped[k, 1] += d
        program = replace(standing, angles=bumped)
        if refused:
            with pytest.raises(PlacementError, match=rf"{joint.name} acceleration .* above"):
                check_serial_program(program, profile)
        else:
            check_serial_program(program, profile)
    # a ramp at the joint's speed: accepted at it, refused just beyond (acceleration allowed)
    fast = load_serial_profile(
        "openmanipulator-x", [f"{j.name}.max_acceleration=1e9" for j in profile.joints]
    )
    for factor, refused in ((0.999, False), (1.0, False), (1.001, True)):
        ramp = standing.angles.copy()
        rate = factor * joint.max_speed * T
        ramp[k:, 1] += rate * np.arange(1, len(ramp) - k + 1)
        ramp[k + 5 :, 1] = ramp[k + 4, 1]
        program = replace(standing, angles=ramp)
        if refused:
            with pytest.raises(PlacementError, match=rf"{joint.name} speed .* above"):
                check_serial_program(program, fast)
        else:
            check_serial_program(program, fast)


@pytest.mark.parametrize("degrees", [90.0, 30.0])
def test_place_rotation_turns_the_tag_counter_clockwise_without_a_mirror(degrees):
    profile = load_serial_profile("openmanipulator-x", [f"place.rotation={degrees}"])
    placement = place_on_paper(load_plan(EXAMPLES / "letter-b.json"), profile)
    theta = np.radians(degrees)
    turn = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    np.testing.assert_allclose(placement.matrix, placement.mm_per_unit * turn, atol=1e-12)
    # the tag's up (+y) points to the paper's left at 90°
    assert np.linalg.det(placement.matrix) > 0


def _drawn_length(program) -> float:
    """mm of path drawn with the pen down."""
    xy = program.setpoints.xy[program.setpoints.pen]
    return float(np.hypot(*np.diff(xy, axis=0).T).sum())


def test_a_run_is_trimmed_at_both_ends_until_its_path_is_twice_the_trim():
    """letter-b's run with motion.trim_mm at 2/5 of its path: 2/5 off at either end, a fifth
    of it drawn (the trim stops only at a path of two trims or less)."""
    tag = load_plan(EXAMPLES / "letter-b.json")
    whole = _drawn_length(
        build_serial_program(tag, load_serial_profile("openmanipulator-x", ["motion.trim_mm=0"]))
    )
    trim = 0.4 * whole
    profile = load_serial_profile("openmanipulator-x", [f"motion.trim_mm={trim}"])
    drawn = _drawn_length(build_serial_program(tag, profile))
    assert drawn == pytest.approx(whole - 2 * trim, rel=0.1)


def test_pen_up_ticks_belong_to_no_plan():
    program = build_serial_program(
        load_plan(EXAMPLES / "cae.json"), load_serial_profile("openmanipulator-x")
    )
    setpoints = program.setpoints
    assert set(setpoints.plan[~setpoints.pen].tolist()) == {-1}
    assert set(setpoints.plan[setpoints.pen].tolist()) == {0, 1, 2}


def test_which_neighbouring_samples_a_move_answers_for():
    """A run or a joint-space move owns the samples beside it; a pen move owns none on a side
    where travel or park meets it (at rest there: the joint-space move's shape decides)."""
    kinds = ["travel", "approach", "draw", "retreat", "park"]
    assert _owned(kinds) == [
        (False, True),  # travel: nothing before it; the approach's first sample is its
        (False, True),
        (True, True),
        (True, False),
        (True, False),  # park: the retreat's last sample, nothing after it
    ]
    assert _owned(["draw"]) == [(False, False)]


def test_a_moves_excess_counts_the_samples_it_owns_and_no_others():
    """A spike in the sample just after a move counts against it only if it owns that side."""
    limits = np.full(2, 1.0)
    q = np.zeros((10, 2))
    q[6, 0] = 1e-4  # just after rows 2:6
    T = 0.01
    alone = move_excess(q, 2, 6, (False, False), T, limits, limits)
    owned = move_excess(q, 2, 6, (False, True), T, limits, limits)
    assert alone == 0.0
    # the step into it, the arm standing still after: 1e-4 / T² = 1 rad/s², at the limit
    assert owned == pytest.approx(1.0)


def test_each_joint_is_held_to_its_own_acceleration():
    """Two joints, one with ten times the other's acceleration limit: the excess is each
    joint's own ratio, the larger of them (not the largest move against the smallest limit);
    the same for their speed limits."""
    speed = np.full(2, 100.0)
    acceleration = np.array([1.0, 10.0])
    T = 0.01
    q = np.zeros((5, 2))
    q[2] = [0.5e-4, 4e-4]  # joint 0: 1 rad/s² peak; joint 1: 8 rad/s² against its 10
    assert _excess(q, T, speed, acceleration) == pytest.approx(1.0)
    # And to its own speed: one step of 0.01 and 0.08 rad in a tick, joint 0 at its 1 rad/s,
    # joint 1 at 8 rad/s against its 10: 1.0 (not 8 from the largest step against 1 rad/s).
    step = np.array([[0.0, 0.0], [0.01, 0.08]])
    assert _excess(step, T, np.array([1.0, 10.0]), np.full(2, 1e9)) == pytest.approx(1.0)


def test_a_way_back_to_park_that_dips_to_the_paper_is_refused_naming_the_park():
    """A job from near the base to the far corner; a park pose the arm leaves cleanly for the
    first run but reaches from the last one by sweeping its pen through the paper."""
    first = _stroke([0.0, 0.0], [10.0, 0.0])
    last = _stroke([90.0, 90.0], [100.0, 90.0], start=first.end(15.0) + 0.3)
    park = [f"joint{i}.park_deg={v}" for i, v in enumerate((0, 40, -30, 30), start=1)]
    profile = load_serial_profile("openmanipulator-x", park)
    with pytest.raises(PlacementError, match=r"^tick \d+ \(park to park\): the pen's point would"):
        build_serial_program(Tag(plans=(first, last)), profile)


@pytest.mark.parametrize(("factor", "refused"), [(1 - 1e-6, False), (1.0, False), (1 + 1e-6, True)])
def test_a_pen_up_move_may_pass_at_half_the_pen_up_height_not_below(factor, refused):
    """A travel whose pen passes exactly half ``robot.pen_up`` above the paper is accepted; a
    pen-up height a hair higher refuses it, naming the tick, the move and the height."""
    profile = load_serial_profile("openmanipulator-x")
    q = profile.park[None, :]
    tip, _ = profile.arm.fk(q)
    paper = profile.paper
    height = float(((tip.reshape(-1, 3) - np.asarray(paper.origin)) @ paper.normal)[0])
    pen_up = 2000.0 * height * factor
    raised = load_serial_profile("openmanipulator-x", [f"robot.pen_up={pen_up!r}"])
    if refused:
        message = (
            f"tick 7 (travel before plan 2): the pen's point would pass {1000 * height:.1f} mm"
            " above the paper, less than half robot.pen_up (raise it, or move the park pose)"
        )
        with pytest.raises(PlacementError) as caught:
            _check_clearance(q, raised, 2, "travel", 7)
        assert str(caught.value) == message
    else:
        _check_clearance(q, raised, 2, "travel", 7)


def _run_rows(program, k: int) -> np.ndarray:
    return np.flatnonzero(program.setpoints.plan == k)


def _plan_speed(tag: Tag, k: int, tau: float, program) -> float:
    """Plan ``k``'s speed on the paper at tag time ``tau``, mm/s, at its run's time scale."""
    sp = program.setpoints
    _, v = evaluate_plan(tag.plans[k], np.array([tau]), tag.size)
    return float(np.hypot(*(v @ sp.placement.matrix.T)[0]) / sp.run_scales[k])


def test_a_trimmed_run_starts_and_ends_at_rest_not_at_the_plans_speed_there():
    """letter-b trimmed by motion.trim_mm: the plan moves where the run starts and ends (a
    lognormal moves everywhere after its onset), so the run eases from and to rest there; its
    first and last ticks move the pen a fraction of what the plan's speed would."""
    tag = load_plan(EXAMPLES / "letter-b.json")
    program = build_serial_program(tag, load_serial_profile("openmanipulator-x"))
    sp = program.setpoints
    clock = sp.run_clocks[0]
    assert clock.on > tag.plans[0].start and clock.off < tag.plans[0].end(tag.size)
    assert (clock.ease_in, clock.ease_out) == (EASE, EASE)
    rows = _run_rows(program, 0)
    assert np.hypot(*sp.v[rows[0]]) == 0.0 and np.hypot(*sp.v[rows[-1]]) < 1e-6
    T = sp.period
    for first, second, tau in ((rows[0], rows[1], clock.on), (rows[-1], rows[-2], clock.off)):
        moving = _plan_speed(tag, 0, tau, program)
        assert moving > 0.1  # mm/s: the plan moves where the trim cut it
        assert np.hypot(*(sp.xy[second] - sp.xy[first])) / T < 0.2 * moving


def test_a_run_drawn_from_the_plans_own_rest_is_not_eased():
    """With motion.trim_mm = 0 the run starts at the lognormal's onset and ends where it has
    stopped: at rest already, on the plan's own clock."""
    tag = load_plan(EXAMPLES / "letter-b.json")
    profile = load_serial_profile("openmanipulator-x", ["motion.trim_mm=0"])
    clock = build_serial_program(tag, profile).setpoints.run_clocks[0]
    assert (clock.on, clock.off) == (tag.plans[0].start, tag.plans[0].end(tag.size))
    assert (clock.ease_in, clock.ease_out) == (0.0, 0.0)
    assert clock.duration == pytest.approx(clock.off - clock.on)


def test_a_run_touching_down_moving_and_trimmed_still_eases_from_rest():
    """A plan whose ink touches down and lifts off moving, trimmed inside its ink window (as
    ga3 19754's hook was: its run started at 12 mm/s): eased at both ends, starting at rest.
    (Its ink window, 0.3 s, a whole number of the trim's 1 ms samples, once failed the trim.)"""
    tag = Tag((lifted(start=0.0),))
    profile = load_serial_profile("openmanipulator-x", ["motion.trim_mm=1"])
    program = build_serial_program(tag, profile)
    clock = program.setpoints.run_clocks[0]
    down, up = tag.plans[0].ink_window(tag.size)
    assert down < clock.on and clock.off < up  # the trim cut inside the ink
    assert (clock.ease_in, clock.ease_out) == (EASE, EASE)
    rows = _run_rows(program, 0)
    assert np.hypot(*program.setpoints.v[rows[0]]) == 0.0


def test_a_run_whose_ink_starts_and_ends_faster_than_the_trim_is_drawn_whole():
    """A plan touching down and lifting off moving, more than motion.trim_mm (0.05 mm) on the
    paper in each first and last millisecond of its ink: the trim cuts nothing, the run spans
    the ink window to its last instant."""
    tag = Tag((lifted(start=0.0),))
    profile = load_serial_profile("openmanipulator-x")
    assert profile["motion.trim_mm"] == 0.05
    clock = build_serial_program(tag, profile).setpoints.run_clocks[0]
    assert (clock.on, clock.off) == tag.plans[0].ink_window(tag.size)


def test_a_run_over_its_limit_by_a_hair_whatever_its_scale_is_still_retimed(monkeypatch):
    """A run whose joint acceleration barely shrinks as it is slowed (as the IK's per-sample
    pull of the pen's axis makes part of it: ga3 19981 stayed 1e-4 over, round after round,
    and was refused 'did not converge') is slowed by a margin that grows each round."""
    moves = []
    solve_job, move_excess_ = program_module._solve_job, program_module.move_excess

    def remember(m, *args):
        moves[:] = m
        return solve_job(m, *args)

    def excess(q, first, stop, owns, *limits):
        real = move_excess_(q, first, stop, owns, *limits)
        if owns != (True, True):
            return real
        draw = next(m for m in moves if m.kind == "draw")
        return max(real, 1.0001 * draw.scale**-0.01)  # 1 % slower clears it

    monkeypatch.setattr(program_module, "_solve_job", remember)
    monkeypatch.setattr(program_module, "move_excess", excess)
    profile = load_serial_profile("openmanipulator-x", ["place.scale=2"])
    program = build_serial_program(small_tag(), profile)
    assert 1.01 <= program.setpoints.run_scales[0] < 1.02


@pytest.mark.parametrize("end", ["lower", "upper"])
def test_a_joint_held_at_its_range_end_passes_and_just_beyond_is_refused(end) -> None:
    profile = load_serial_profile("openmanipulator-x")
    program = build_serial_program(load_plan(EXAMPLES / "letter-b.json"), profile)
    joint = profile.joints[1]
    bound = getattr(joint, end)
    at = program.angles.copy()
    at[:, 1] = bound  # held there the whole job: no speed, no acceleration
    check_serial_program(replace(program, angles=at), profile)
    beyond = at.copy()
    beyond[:, 1] += 1e-6 if end == "upper" else -1e-6
    with pytest.raises(PlacementError, match=r"^tick 0 .*joint2 at -?\d+\.\d\d° beyond its range"):
        check_serial_program(replace(program, angles=beyond), profile)


@pytest.mark.parametrize("end", ["lower", "upper"])
def test_goals_stepping_to_a_range_end_stay_within_the_servos_limits(end) -> None:
    """A step to a joint's range end in one tick: the goals that undo the profile's lag would
    overshoot it, and stop at the end's tick instead (the servo's position limit)."""
    profile = load_serial_profile("openmanipulator-x")
    joint = profile.joints[1]
    angles = np.tile(profile.park, (40, 1))
    angles[10:, 1] = getattr(joint, end)
    goals = profile_goals(angles, profile)
    limit = int(angles_to_ticks(getattr(joint, end), joint))
    ticks = goals[:, 1]
    assert (ticks <= limit).all() if limit >= ticks[0] else (ticks >= limit).all()
    assert ticks[-1] == limit


@pytest.mark.parametrize(
    ("above", "pushed"),
    [(-1.0, False), (0.0, False), (1e-3, True), (1.0, True)],
)
def test_the_papers_push_is_fed_forward_only_where_the_point_is_aimed_into_it(above, pushed):
    """A pose at park with the paper raised to the pen's point, ``above`` mm over it: 1 mm
    under the point, or exactly at it (touching, not aimed in), no push is fed forward; a
    micrometre or 1 mm over it (the point aimed in), the shoulder, elbow and wrist take the
    paper's push (the preload's at least)."""
    profile = load_serial_profile("openmanipulator-x")
    pose = profile.park[None, :]
    tip, _ = profile.arm.fk(pose)
    z = 1000.0 * float(np.asarray(tip).reshape(-1, 3)[0, 2])  # mm above the base plate
    assert z / 1000.0 == float(np.asarray(tip).reshape(-1, 3)[0, 2])  # exactly at the point
    alone = feedforward(pose, np.ones(1, dtype=bool), profile)
    raised = load_serial_profile("openmanipulator-x", [f"paper.z={z + above!r}"])
    push = feedforward(pose, np.ones(1, dtype=bool), raised) - alone
    if pushed:
        assert np.abs(push[0, 1:]).min() > 5e-4  # rad
    else:
        np.testing.assert_array_equal(push, 0.0)


def test_a_point_at_a_strokes_onset_is_named_for_that_stroke() -> None:
    """A refusal names the stroke under way (the last one begun): at its onset exactly, the
    stroke that begins there; just before, the one before it."""
    tag = load_plan(EXAMPLES / "letter-b.json")
    onsets = tag.plans[0].onsets
    assert [_stroke_at(tag, 0, float(t)) for t in onsets] == list(range(len(onsets)))
    assert [_stroke_at(tag, 0, float(t) - 1e-6) for t in onsets[1:]] == list(range(len(onsets) - 1))
    assert _stroke_at(tag, 0, 0.0) == 0  # before the first onset: the first stroke


def test_the_planned_timeline_puts_every_tick_where_the_pens_point_is_over_the_paper() -> None:
    """The planned timeline (report, pictures) in mm on the paper: pen-up ticks too (travel,
    approach, the moves from and to park) are where the planned angles put the pen's point,
    seen along the paper's normal, within 0.01 mm."""
    profile = load_serial_profile("openmanipulator-x")
    program = build_serial_program(load_plan(EXAMPLES / "letter-b.json"), profile)
    tip, _ = profile.arm.fk(program.angles)
    paper = profile.paper
    rel = (np.asarray(tip).reshape(-1, 3) - np.asarray(paper.origin)) * 1000.0
    seen = np.column_stack([rel @ np.asarray(paper.x_axis), rel @ np.asarray(paper.y_axis)])
    sp = program.setpoints
    up = ~np.asarray(sp.pen, dtype=bool)
    assert up.sum() > 100
    assert np.hypot(*(seen - sp.xy).T).max() < 0.01


@pytest.mark.parametrize("off", [0.7, 0.6])
def test_a_run_window_with_no_time_in_it_is_an_empty_clock_at_its_start(off) -> None:
    clock = run_clock(lifted(), 0.7, off, 40.0, ease_trimmed=True)
    assert (clock.on, clock.off, clock.duration) == (0.7, 0.7, 0.0)
    assert (clock.ease_in, clock.ease_out) == (0.0, 0.0)


def test_each_runs_reported_start_is_where_its_ink_starts() -> None:
    """cae's three runs: the report's placement starts each run at its first drawing tick, and
    pen-up ticks (travel, approach, retreat, park) belong to no run."""
    profile = load_serial_profile("openmanipulator-x")
    program = build_serial_program(load_plan(EXAMPLES / "cae.json"), profile)
    draws = [(plan, first) for kind, plan, first, _ in program.segments if kind == "draw"]
    runs = placement_of(program.setpoints)["runs"]
    assert [(r["plan"], r["start"]) for r in runs] == [
        (plan, pytest.approx(first * profile.period)) for plan, first in draws
    ]
    sp = program.setpoints
    assert (sp.plan[~np.asarray(sp.pen, dtype=bool)] == -1).all()


def test_a_runs_lift_off_mirrors_its_touch_down() -> None:
    """Around each of cae's runs: the pen comes down from robot.pen_up (10 mm) above the paper
    to the run's first point and goes back up from its last in as many ticks, at the same
    heights in reverse (within 0.001 mm)."""
    profile = load_serial_profile("openmanipulator-x")
    program = build_serial_program(load_plan(EXAMPLES / "cae.json"), profile)
    tip, _ = profile.arm.fk(program.angles)
    paper = profile.paper
    height = (np.asarray(tip).reshape(-1, 3) - np.asarray(paper.origin)) @ paper.normal * 1000.0
    segments = program.segments
    runs = [i for i, s in enumerate(segments) if s[0] == "draw"]
    assert len(runs) == 3
    for i in runs:
        down, up = segments[i - 1], segments[i + 1]
        assert down[0] == up[0] == "pen"
        lowering, lifting = height[down[2] : down[3]], height[up[2] : up[3]]
        assert len(lowering) == len(lifting)
        assert lowering[0] == pytest.approx(10.0, abs=1e-3)
        np.testing.assert_allclose(lifting[::-1], lowering, atol=1e-3)


@pytest.mark.parametrize(
    ("into", "kind", "side"), [(7, "approach", "before"), (0, "retreat", "after")]
)
def test_a_refusal_in_a_pen_move_names_the_move_and_the_time_into_it(monkeypatch, into, kind, side):
    """Where the arm cannot follow a point of a run's approach or retreat, the refusal names
    the plan, the move and how far into it the point is (seconds at the profile's period)."""
    from tagbot.arm.serial.kinematics import SerialArm
    from tagbot.errors import ReachError

    profile = load_serial_profile("openmanipulator-x")
    real, calls = SerialArm.solve_path, []

    def refuse(self, points, *args, **kwargs):
        calls.append(len(points))
        q = real(self, points, *args, **kwargs)
        if len(calls) == 2:  # the second run's approach, ink and retreat, in one path
            n = len(points) - 1 - into if kind == "retreat" else into
            raise ReachError("out of reach (test)", n, "reach")
        return q

    monkeypatch.setattr(SerialArm, "solve_path", refuse)
    cae = load_plan(Path(tagbot.__file__).parent / "examples" / "cae.json")
    with pytest.raises(ReachError) as raised:
        build_serial_program(cae, profile)
    message = str(raised.value)
    assert message.startswith(f"plan 1, {kind} {side} it, t = ")
    assert message.endswith(" s into the move: out of reach (test)")
    seconds = float(message.split("t = ")[1].split(" s")[0])
    if kind == "approach":
        assert seconds == pytest.approx(into * profile.period)
    else:  # the retreat's last point: its length, under the 5 s cap of any pen move
        assert 0.0 < seconds < 5.0


def test_each_run_is_the_tag_sampled_on_its_run_clock_at_the_tags_size():
    """cae (three plans of different extents) on the OpenManipulator-X: every pen-down sample
    of plan k is the tag's motion at tag time ``run_clocks[k].tag_time(τ / s_k)``, τ the machine
    time since the run's first sample, evaluated with the tag's size (which sets where each
    stroke's window ends), placed on the paper."""
    tag = load_plan(EXAMPLES / "cae.json")
    program = build_serial_program(tag, load_serial_profile("openmanipulator-x"))
    sp = program.setpoints
    placement = sp.placement
    for k, plan in enumerate(tag.plans):
        rows = _run_rows(program, k)
        tau = sp.t[rows] - sp.t[rows[0]]
        u = np.minimum(tau / sp.run_scales[k], sp.run_clocks[k].duration)
        xy, _ = evaluate_plan(plan, sp.run_clocks[k].tag_time(u), tag.size)
        expected = xy @ placement.matrix.T + placement.offset
        np.testing.assert_allclose(sp.xy[rows], expected, rtol=0, atol=1e-9)
