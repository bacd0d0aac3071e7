"""What an arm program states about its motion, checked against its own positions (issue 34):
travel velocities, which tick leaves the area, and the pen-down time of its runs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tagbot.arm import build_program, check_program, load_profile
from tagbot.arm.place import time_at_ends
from tagbot.errors import PlacementError

from .conftest import small_tag


def test_travel_velocity_is_the_derivative_of_the_travel_path(profile) -> None:
    """Travel and park moves start and end at rest, and the tip velocity reported for every
    tick is the rate of change of the tip position (central differences, within 1 % of the
    move's peak speed)."""
    program = build_program(small_tag(), profile)
    sp, T = program.setpoints, program.setpoints.period
    travels = [(a, b) for kind, _, a, b in program.segments if kind in ("travel", "park")]
    assert len(travels) == 2
    for a, b in travels:
        v = sp.v[a:b]
        central = (sp.xy[a + 1 : b] - sp.xy[a - 1 : b - 2]) / (2 * T)
        peak = float(np.max(np.hypot(*v.T)))
        assert peak > 10.0  # it moves
        assert np.abs(v[:-1] - central).max() < 0.01 * peak
        assert v[-1] == pytest.approx([0.0, 0.0], abs=1e-9)


def test_check_program_names_the_tick_that_leaves_the_area() -> None:
    """A pen-down tick inside the arm's reach but right of the area (x_max 148.5 - margin 10)
    is refused, naming that tick, not the run's first."""
    profile = load_profile()
    program = build_program(small_tag(), profile)
    down = np.flatnonzero(program.setpoints.pen)
    k = int(down[len(down) // 2])
    xy = program.setpoints.xy.copy()
    xy[k] = [145.0, 150.0]
    changed = replace(program, setpoints=replace(program.setpoints, xy=xy))
    with pytest.raises(PlacementError) as raised:
        check_program(changed, profile)
    assert str(raised.value) == (
        f"tick {k} (t = {k * profile.period:.3f} s, plan 0): pen at (145.00, 150.00) mm is off the"
        " area (area.* minus area.margin)"
    )


def test_pen_down_time_counts_each_run_from_its_first_sample_to_its_last(profile) -> None:
    program = build_program(small_tag(), profile)
    T = program.setpoints.period
    runs = [b - a for kind, _, a, b in program.segments if kind == "draw"]
    near, total = time_at_ends(program, profile)
    assert total == pytest.approx(sum(n - 1 for n in runs) * T)
    assert 0.0 < near < total


@pytest.mark.parametrize("speed", [7.3, 400.0])  # mm/s: many samples within reach, or one
def test_time_at_the_ends_interpolates_where_the_pen_leaves_and_reaches_them(
    profile, speed
) -> None:
    """Runs redrawn as straight lines at a steady speed leave their start and reach their end
    within one tick's resolution at the pen in exactly resolution ÷ speed each (the crossing
    interpolated between samples), whatever the sampling."""
    from tagbot.arm.kinematics import Arm

    program = build_program(small_tag(), profile)
    T, arm = program.setpoints.period, Arm.from_profile(profile)
    xy, expected = program.setpoints.xy.copy(), 0.0
    for kind, _, a, b in program.segments:
        if kind == "draw":
            xy[a:b] = xy[a] + np.outer(np.arange(b - a) * T * speed, [0.6, 0.8])
            limits = arm.tip_resolution(program.angles[[a, b - 1]])
            expected += min((b - a - 1) * T, float(limits.sum()) / speed)
    lines = replace(program, setpoints=replace(program.setpoints, xy=xy))
    near, _ = time_at_ends(lines, profile)
    assert near == pytest.approx(expected, rel=1e-9)
    assert near < 0.5 * sum((b - a - 1) * T for k, _, a, b in program.segments if k == "draw")


def test_a_tick_after_the_programs_last_segment_is_described_as_the_program(profile) -> None:
    """Errors name the part of the program a tick belongs to; past its segments, "program"."""
    program = build_program(small_tag(), profile)
    assert program.describe(len(program) + 3) == "program"
    last = max(stop for *_, stop in program.segments)
    assert 0 < last <= len(program)
    assert program.describe(last) == "program" and program.describe(last - 1) != "program"


def test_runs_that_start_and_end_off_the_plans_ends_spend_no_time_at_them(profile) -> None:
    """Measured against the plan's own first and last targets, a run drawn a millimetre off
    them (farther than one tick at the pen) never rests there: no time at the ends."""
    tag = small_tag()
    program = build_program(tag, profile)
    resting, drawing = time_at_ends(program, profile, tag)
    assert resting > 0.0
    xy = program.setpoints.xy.copy()
    for kind, _, a, b in program.segments:
        if kind == "draw":
            xy[a:b] += [0.6, 0.8]
    off = replace(program, setpoints=replace(program.setpoints, xy=xy))
    assert time_at_ends(off, profile, tag) == (0.0, pytest.approx(drawing))
