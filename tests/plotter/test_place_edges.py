"""Placement at the bed's y edges and Grbl's step rounding (issue 34)."""

from __future__ import annotations

import importlib
import math

import numpy as np
import pytest

from tagbot.model import Plan, Tag
from tagbot.model.motion import evaluate_plan
from tagbot.plotter import load_profile, place
from tagbot.plotter.place import (
    PlacementError,
    interpolation_error,
    junction_speed,
    motor_steps,
    segment_excess,
    step_box,
)

from .conftest import straight_tag, two_plan_tag

place_module = importlib.import_module("tagbot.plotter.place")


def _vertical_tag() -> Tag:
    plan = Plan([[0.0, 0.0], [0.0, 10.0]], [0.0], [math.log(0.2)], [0.3], [0.0], [0.0])
    return Tag((plan,))


def test_a_tag_touching_the_bottom_and_top_edges_is_accepted(tiny_file) -> None:
    """With no margin a vertical line is scaled to the bed's height (50 mm): it touches y_min
    and y_max exactly and is accepted; 1 mm taller (place.scale 5.1 mm per unit) it is refused
    at y_max."""
    edge = load_profile(tiny_file, ["bed.margin=0", "motion.trim=false"])
    setpoints = place(_vertical_tag(), edge)
    ys = np.concatenate([r.xy[:, 1] for r in setpoints.runs])
    assert ys.min() == pytest.approx(0.0, abs=1e-9) and ys.max() == pytest.approx(50.0, abs=0.01)
    tall = load_profile(
        tiny_file,
        ["bed.margin=0", "motion.trim=false", "place.align=bottom-left", "place.scale=5.1"],
    )
    with pytest.raises(
        PlacementError,
        match=r"^placement: the drawing reaches y = 51\.000 mm, beyond bed\.y_max = 50 mm by 1\.0",
    ):
        place(_vertical_tag(), tall)


def test_motor_steps_round_half_away_from_zero(tiny_file) -> None:
    """Grbl's lround of x·$100 (2 steps/mm here): ±0.5 and ±1.5 steps go away from zero."""
    profile = load_profile(tiny_file, ["limits.x_steps_per_mm=2", "limits.y_steps_per_mm=2"])
    xy = np.array([[0.25, -0.25], [0.75, -1.25], [0.2, -0.2], [10.0, 0.0]])
    assert motor_steps(xy, profile).tolist() == [[1, -1], [2, -3], [0, 0], [20, 0]]


def test_trimmed_runs_start_and_end_a_step_away_from_the_plans_ends(tiny_file) -> None:
    """motion.trim: a run is drawn from the first instant its plan is a motor step away from
    its touch-down point to the last instant it is still a step away from its lift-off point,
    so no setpoint of the run lies within a step of either end."""
    profile = load_profile(tiny_file, ["motion.trim=true"])
    box = step_box(profile)
    for tag in (straight_tag(), two_plan_tag()):
        placed = place(tag, profile)
        for run in placed.runs:
            plan = tag.plans[run.plan]
            ends, _ = evaluate_plan(plan, np.array(plan.ink_window(tag.size)), tag.size)
            p0, p1 = ends @ placed.matrix.T + placed.offset
            assert np.any(np.abs(run.xy[0] - p0) >= box)
            assert np.any(np.abs(run.xy[-1] - p1) >= box)
            assert np.all(np.abs(run.xy[-1] - p1) < 2 * box)  # but only just


def test_a_line_between_consecutive_samples_has_no_interpolation_error() -> None:
    """interpolation_error: a line from one sample to the next (or to itself) passes through
    every sample it spans, so its error is 0; over three samples it is the middle one's distance
    from the line between the outer two."""
    xy = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 0.0]])
    assert interpolation_error(xy, 0, 1) == 0.0
    assert interpolation_error(xy, 1, 2) == 0.0
    assert interpolation_error(xy, 1, 1) == 0.0
    assert interpolation_error(xy, 0, 2) == pytest.approx(0.5, abs=1e-12)


def test_a_repeated_last_setpoint_does_not_hide_the_look_ahead_excess(tiny) -> None:
    """segment_excess: 0.01 mm along x in 10 µs (1000 mm/s, the tiny machine's x speed) must
    stop within itself: Grbl's look-ahead cap is √(2·a·L) = √(2·1e5·0.01) mm/s, so the time
    scale must grow by (v / cap)² = 1000² / 2000 = 500. A last setpoint repeating the one before
    (a line that moves nothing, nothing ahead of it) changes nothing."""
    xy = np.array([[0.0, 0.0], [0.01, 0.0]])
    t = np.array([0.0, 1e-5])
    assert segment_excess(xy, t, tiny) == pytest.approx(500.0, rel=1e-9)
    repeated = np.array([[0.0, 0.0], [0.01, 0.0], [0.01, 0.0]])
    assert segment_excess(repeated, np.array([0.0, 1e-5, 2e-5]), tiny) == pytest.approx(
        500.0, rel=1e-9
    )


def test_adaptive_lines_shorten_at_corners_so_the_junction_limit_needs_no_slowing() -> None:
    """With a loose tolerance (0.2 mm) the adaptive lines could be long enough on a curve that
    Grbl's junction speed ($11 = 0.01 mm) would bind at each corner between them; the lines are
    shortened there instead, so every gentle corner is entered at about CORNER_MARGIN (0.9) of
    Grbl's limit at most and the junction limit sets no time scale: the run keeps the scale its
    axis speeds ask for. They are shortened no more than that: the tightest corner is entered
    close to the margin (above 0.875 of the limit), not with room to spare."""
    curve = Plan(
        [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]],
        [0.0, 0.15],
        [math.log(0.2)] * 2,
        [0.3] * 2,
        [0.6, 0.5],
        [-0.6, -0.5],
    )
    profile = load_profile(None, ["motion.min_buffer=0", "motion.tolerance=0.2"])
    placed = place(Tag((curve,)), profile)
    assert placed.limits["junction"] == 1.0
    assert placed.scale == pytest.approx(placed.limits["speed"], rel=1e-9)
    run = placed.runs[0]
    entry, limit, deflection = junction_speed(run.xy, profile, run.t)
    gentle = deflection < math.pi / 4
    assert gentle.sum() > 10
    assert np.all(entry[gentle] <= 0.92 * limit[gentle])
    assert np.max(entry[gentle] / limit[gentle]) > 0.875


def test_a_bed_not_starting_at_y_0_is_filled_between_its_own_edges(tiny_file) -> None:
    """place.scale=fit on a bed from y = 10 to 50 mm (no margin): a vertical line is scaled to
    the bed's height, 40 mm, and drawn from y_min to y_max exactly."""
    bed = load_profile(
        tiny_file, ["bed.margin=0", "bed.y_min=10", "motion.park_y=10", "motion.trim=false"]
    )
    placed = place(_vertical_tag(), bed)
    ys = np.concatenate([r.xy[:, 1] for r in placed.runs])
    assert ys.min() == pytest.approx(10.0, abs=0.01) and ys.max() == pytest.approx(50.0, abs=0.01)
    assert placed.size == pytest.approx(4.0, rel=1e-3)


@pytest.mark.parametrize(("too_fast", "converges"), [(99, True), (100, False)])
def test_retiming_gives_up_after_100_rounds_of_slowing(monkeypatch, too_fast, converges) -> None:
    """Retiming slows a run down for at most 100 rounds: a run still too fast after its 99th
    slowing is drawn (the 100th round finds it within the limits), one still too fast after its
    100th is refused with "retiming: did not converge"."""
    real = place_module.segment_excess
    rounds = []

    def excess(xy, t, profile):
        rounds.append(len(rounds))
        return 1.00001 if len(rounds) <= too_fast else real(xy, t, profile)

    monkeypatch.setattr(place_module, "segment_excess", excess)
    profile = load_profile(None, ["motion.min_buffer=0", "place.scale=0.2"])
    if converges:
        assert len(place(straight_tag(), profile).runs) == 1
        assert len(rounds) == 100
    else:
        with pytest.raises(PlacementError, match=r"^retiming: did not converge$"):
            place(straight_tag(), profile)
        assert len(rounds) == 100


def test_a_plotters_runs_say_they_ease_at_constant_acceleration(tiny_file) -> None:
    """Steppers take a constant acceleration, not a jerk limit: every placed run's clock says
    it is not jerk-limited (the run clock a report or a resume reads back)."""
    placed = place(two_plan_tag(), load_profile(tiny_file))
    assert len(placed.runs) == 2
    assert [run.clock.jerk_limited for run in placed.runs] == [False, False]
