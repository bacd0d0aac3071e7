"""Placement (aspect, margins, y direction), trimmed run ends, per-run and uniform retiming to
the machine's limits, adaptive setpoints within their tolerance."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import tagbot
from tagbot.model import Plan, Tag
from tagbot.model.motion import evaluate_plan
from tagbot.plotter import build_program, load_profile, place
from tagbot.plotter.place import (
    FINE_STEP,
    RX_LINES,
    PlacementError,
    _check_bed,
    _junction_excess,
    buffered,
    limit_scale,
    segment_excess,
    segment_speed_cap,
    slowest_durations,
    step_box,
)
from tagbot.plotter.program import resting_share

from .conftest import straight_tag, two_plan_tag

EXAMPLES = Path(tagbot.__file__).parent / "examples"


def _extent(setpoints):
    xy = np.concatenate([r.xy for r in setpoints.runs])
    return xy.min(axis=0), xy.max(axis=0)


def test_fit_keeps_aspect_and_margins():
    tag = tagbot.load_plan(EXAMPLES / "cae.json")
    profile = load_profile()
    placed = place(tag, profile)
    low, high = _extent(placed)
    margin = profile["bed.margin"]
    x_min, x_max, y_min, y_max = profile.bed
    assert low[0] >= x_min + margin - 1e-6 and high[0] <= x_max - margin + 1e-6
    assert low[1] >= y_min + margin - 1e-6 and high[1] <= y_max - margin + 1e-6
    # One side touches its margins (fit), within the fine sampling's resolution.
    touches_x = np.isclose(high[0] - low[0], x_max - x_min - 2 * margin, atol=0.05)
    touches_y = np.isclose(high[1] - low[1], y_max - y_min - 2 * margin, atol=0.05)
    assert touches_x or touches_y
    # Aspect kept: the tag's own extent times one scale.
    raw = np.concatenate([tag.sample(0.002).xy[tag.sample(0.002).pen == 1]])
    ratio = (high - low) / np.ptp(raw, axis=0)
    assert ratio[0] == pytest.approx(ratio[1], rel=2e-3)
    assert np.allclose(placed.matrix.T @ placed.matrix, placed.size**2 * np.eye(2))


def test_y_down_mirrors(tiny_file):
    exact = ("place.align=top-left", "motion.trim=false")
    up = place(two_plan_tag(), load_profile(tiny_file, exact))
    down = place(two_plan_tag(), load_profile(tiny_file, [*exact, "bed.y_down=true"]))
    for a, b in zip(up.runs, down.runs, strict=True):
        assert np.allclose(b.xy[:, 0], a.xy[:, 0])
        assert np.allclose(b.xy[:, 1], 50.0 - a.xy[:, 1])
        assert np.allclose(b.v[:, 1], -a.v[:, 1])
    # Top-left on a y-down machine is near machine y = margin.
    # (within a motor step: setpoints on the step the last one reached are not sent)
    assert min(r.xy[:, 1].min() for r in down.runs) == pytest.approx(5.0, abs=0.01)


def test_rotation_and_explicit_scale(tiny_file):
    profile = load_profile(tiny_file, ["place.scale=2", "place.rotation=90"])
    placed = place(straight_tag(), profile)
    run = placed.runs[0]
    assert placed.size == 2.0
    assert np.ptp(run.xy[:, 0]) == pytest.approx(0.0, abs=1e-9)
    assert np.ptp(run.xy[:, 1]) == pytest.approx(
        20.0 - 2 * 0.01, abs=1e-3
    )  # trimmed: a step each end
    assert run.xy[-1, 1] > run.xy[0, 1]  # +x of the tag became +y


def test_scale_is_one_when_slow_enough(tiny_file):
    profile = load_profile(tiny_file, ["motion.min_buffer=0", "motion.setpoints=fixed"])
    placed = place(straight_tag(), profile)
    assert placed.scale == 1.0 and placed.run_scales == (1.0,)
    assert placed.runs[0].t[1] - placed.runs[0].t[0] == pytest.approx(profile.dt)


@pytest.mark.parametrize(
    "overrides",
    [
        ["limits.x_max_feed=3000"],  # speed-bound
        ["limits.x_acceleration=200", "limits.y_acceleration=200"],  # acceleration/segment-bound
        ["limits.planner_blocks=1", "motion.dt=0.002"],  # the look-ahead cap dominates
    ],
)
def test_retimed_motion_within_limits(tiny_file, overrides):
    profile = load_profile(tiny_file, ["motion.min_buffer=0", *overrides])
    tag = two_plan_tag()
    placed = place(tag, profile)
    assert placed.scale > 1.0
    if "limits.planner_blocks=1" in overrides:
        assert placed.limits["segment"] == max(placed.limits.values())
    assert placed.scale == pytest.approx(max(placed.limits.values()), rel=0.02)
    vmax = np.array(profile.max_speed)
    amax = np.array(profile.max_acceleration)
    for run in placed.runs:
        # Analytic velocity after retiming, and each line's speed.
        assert np.all(np.abs(run.v) <= vmax * (1 + 1e-9))
        d = np.diff(run.t)
        assert np.all(np.abs(np.diff(run.xy, axis=0)) / d[:, None] <= vmax * (1 + 1e-6))
        # Grbl's look-ahead: each line's speed reachable to a stop within the next 15 lines.
        length = np.hypot(*np.diff(run.xy, axis=0).T)
        ahead = np.array([length[i : i + 15].sum() for i in range(len(length))])
        speed, cap = segment_speed_cap(run.xy, run.t, profile)
        assert np.allclose(speed, length / d)
        a_min = min(profile.max_acceleration)
        assert np.all(speed <= np.sqrt(2 * a_min * np.sqrt(2) * ahead) * (1 + 1e-6))
        assert np.all(speed <= cap * (1 + 1e-6))
    # Acceleration measured independently at a finer step of the retimed clock.
    for k, plan in enumerate(tag.plans):
        t = np.arange(plan.start, plan.end(tag.size), FINE_STEP / 4)
        _, v = tagbot.model.motion.evaluate_plan(plan, t, tag.size)
        scale = placed.runs[k].scale
        v = v @ placed.matrix.T / scale
        acc = np.diff(v, axis=0) / (FINE_STEP / 4 * scale)
        assert np.all(np.abs(acc) <= amax * 1.02), k
    # Retiming keeps the shape: each run still ends where it did (within the motor step on
    # which its last setpoints land), at a scaled clock.
    unscaled = place(tag, load_profile(tiny_file))
    assert np.allclose(placed.runs[0].xy[-1], unscaled.runs[0].xy[-1], atol=0.0101)


def test_limit_scale_formulas(tiny):
    v = np.array([[0.0, 0.0], [2000.0, 0.0], [0.0, 0.0]])  # mm/s, samples 1 ms apart
    limits = limit_scale(v, 0.001, tiny)
    assert limits["speed"] == pytest.approx(2.0)  # 1000 mm/s allowed
    assert limits["acceleration"] == pytest.approx(np.sqrt(2e6 / 1e5))
    # Cap: v ≤ 2·a·B·dt = 2 · 1e5 · 15 · 0.05 = 150000 mm/s.
    assert limits["segment"] == 1.0


def test_limit_scale_of_no_motion_needs_no_slowing(tiny):
    """No samples, or one sample at rest: nothing to slow, every limit's scale is 1."""
    ones = {"speed": 1.0, "acceleration": 1.0, "segment": 1.0}
    assert limit_scale(np.zeros((0, 2)), 0.001, tiny) == ones
    assert limit_scale(np.zeros((1, 2)), 0.001, tiny) == ones


def test_junction_limit_on_curves(tiny_file):
    from tagbot.model import Plan, Tag
    from tagbot.plotter.place import junction_speed

    curve = Plan(
        targets=[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]],
        dt=[0.0, 0.15],
        mu=[np.log(0.2)] * 2,
        sigma=[0.3] * 2,
        phi1=[0.6, 0.5],
        phi2=[-0.6, -0.5],
    )
    tag = Tag(plans=(curve,))
    profile = load_profile(tiny_file, ["limits.junction_deviation=0.0005", "motion.min_buffer=0"])
    placed = place(tag, profile)
    assert placed.limits["junction"] > 1.0
    assert placed.scale == pytest.approx(max(placed.limits.values()))
    run = placed.runs[0]
    entry, limit, deflection = junction_speed(run.xy, profile, run.t)
    gentle = deflection < np.pi / 4
    assert np.all(entry[gentle] <= limit[gentle] * (1 + 1e-6))
    # Entry speeds independently: the slower of each pair of (non-empty) lines.
    sent = np.round(run.xy, 3)
    moving = np.hypot(*np.diff(sent, axis=0).T) > 0
    speeds = (np.hypot(*np.diff(sent, axis=0).T) / np.diff(run.t))[moving]
    assert np.allclose(entry, np.minimum(speeds[:-1], speeds[1:]))
    # A looser machine does not need the junction slow-down.
    loose = load_profile(tiny_file, ["motion.min_buffer=0"])
    assert place(tag, loose).limits["junction"] == 1.0


def test_each_junction_limit_uses_the_acceleration_along_its_own_junction(tiny_file):
    """Two 45-degree turns whose junction vectors lean to different axes: each corner's limit
    uses Grbl's acceleration along its own junction vector, min(a_x/|u_x|, a_y/|u_y|)."""
    from tagbot.plotter.place import junction_speed

    profile = load_profile(
        tiny_file,
        [
            "limits.x_acceleration=100",
            "limits.y_acceleration=400",
            "limits.junction_deviation=0.01",
        ],
    )
    xy = np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 10.0], [20.0, 20.0]])
    entry, limit, deflection = junction_speed(xy, profile, 1.0)
    assert deflection == pytest.approx([math.pi / 4, math.pi / 4])
    assert entry == pytest.approx([10.0, 10.0])  # the shorter side: 10 mm in 1 s
    # Junction vectors point at 112.5 and 157.5 degrees: mostly y, then mostly x.
    eighth = math.radians(22.5)
    a = [100.0 / math.sin(eighth), 100.0 / math.cos(eighth)]
    s = math.sin(math.radians(67.5))  # sin(theta/2), theta = 135 degrees between the moves
    expected = [math.sqrt(a_k * 0.01 * s / (1.0 - s)) for a_k in a]
    assert limit == pytest.approx(expected, rel=1e-9)


def _exact(tag, placed, run, instants):
    p, _ = evaluate_plan(tag.plans[run.plan], instants, tag.size)
    return p @ placed.matrix.T + placed.offset


@pytest.mark.parametrize("name", ["two", "cae"])
def test_runs_start_and_end_one_step_from_their_ends(tiny_file, name):
    tag = two_plan_tag() if name == "two" else tagbot.load_plan(EXAMPLES / "cae.json")
    profile = load_profile(tiny_file if name == "two" else None)
    placed = place(tag, profile)
    box = step_box(profile)
    for run in placed.runs:
        plan = tag.plans[run.plan]
        start, end = plan.start, plan.end(tag.size)
        on, off = run.span
        assert start < on < off < end
        first, last = _exact(tag, placed, run, np.array([start, end]))
        # Drawn from where the motion leaves the ±1-step box around its first point...
        assert np.all(np.abs(run.xy[0] - first) <= box * (1 + 1e-6))
        assert np.max(np.abs(run.xy[0] - first) / box) > 0.999
        before = _exact(tag, placed, run, np.linspace(start, on, 200)[:-1])
        assert np.all(np.all(np.abs(before - first) < box, axis=1))
        # ... to where it last enters the box around its last point; nothing after is drawn.
        at_off = _exact(tag, placed, run, np.array([off]))[0]
        assert np.max(np.abs(at_off - last) / box) == pytest.approx(1.0, abs=0.02)
        after = _exact(tag, placed, run, np.linspace(off, end, 200)[1:])
        assert np.all(np.all(np.abs(after - last) < box, axis=1))
        assert run.tag_t[0] == on and run.tag_t[-1] <= off
    untrimmed = place(
        tag, load_profile(tiny_file if name == "two" else None, ["motion.trim=false"])
    )
    for run in untrimmed.runs:
        assert run.span == (tag.plans[run.plan].start, tag.plans[run.plan].end(tag.size))


def test_a_flick_still_moving_a_step_in_its_last_millisecond_is_trimmed_before_its_end(
    tiny_file,
):
    """A 10 ms flick that still moves more than a motor step in the millisecond before its end
    (its last placement sample): the run still ends where the flick last enters the ±1-step box
    around its end point, before the plan's end, and nothing after that is drawn."""
    plan = Plan(
        targets=[[0.0, 0.0], [10.0, 0.0]],
        dt=[0.0],
        mu=[math.log(0.01)],
        sigma=[0.05],
        phi1=[0.0],
        phi2=[0.0],
        start=0.0,
    )
    tag = Tag(plans=(plan,))
    profile = load_profile(tiny_file)
    placed = place(tag, profile)
    box = step_box(profile)
    (run,) = placed.runs
    end = plan.end(tag.size)
    ms_before, last = _exact(tag, placed, run, np.array([end - 0.001, end]))
    assert np.any(np.abs(ms_before - last) >= box)  # a step moved in the last millisecond
    on, off = run.span
    assert plan.start < on < off < end
    at_off = _exact(tag, placed, run, np.array([off]))[0]
    assert np.max(np.abs(at_off - last) / box) == pytest.approx(1.0, abs=0.02)
    after = _exact(tag, placed, run, np.linspace(off, end, 200)[1:])
    assert np.all(np.all(np.abs(after - last) < box, axis=1))
    assert run.tag_t[-1] <= off


def test_resting_share_is_measured_and_removed():
    tag = tagbot.load_plan(EXAMPLES / "cae.json")
    new = load_profile()
    old = load_profile(
        None,
        [
            "motion.time_scale=uniform",
            "motion.setpoints=fixed",
            "motion.trim=false",
            "motion.slow_lines=dwell",
        ],
    )
    assert resting_share(build_program(place(tag, new), new), new) <= 0.02
    assert resting_share(build_program(place(tag, old), old), old) > 0.05


def _needs(tag, placed, run, profile):
    """The scale the axis speed and acceleration limits ask of the run, measured independently
    (a quarter of the placement's fine step, over the drawn span)."""
    step = FINE_STEP / 4
    t = np.arange(run.span[0], run.span[1], step)
    _, v = evaluate_plan(tag.plans[run.plan], t, tag.size)
    v = v @ placed.matrix.T
    speed = np.max(np.abs(v) / np.asarray(profile.max_speed))
    acc = np.sqrt(np.max(np.abs(np.diff(v, axis=0) / step) / np.asarray(profile.max_acceleration)))
    return float(speed), float(acc)


def test_per_run_scale_each_run_slowed_only_as_it_needs(tiny_file):
    tag = tagbot.load_plan(EXAMPLES / "cae.json")
    run_mode = load_profile(None, ["motion.min_buffer=0"])
    uniform = load_profile(None, ["motion.min_buffer=0", "motion.time_scale=uniform"])
    per_run, joint = place(tag, run_mode), place(tag, uniform)
    assert per_run.mode == "run" and joint.mode == "uniform"
    assert len(set(per_run.run_scales)) == len(per_run.runs) > 1  # each its own
    assert set(joint.run_scales) == {joint.scale}
    assert max(per_run.run_scales) == pytest.approx(joint.scale, rel=0.01)
    assert per_run.duration < joint.duration
    vmax = np.asarray(run_mode.max_speed)
    for a, b in zip(per_run.runs, joint.runs, strict=True):
        assert 1.0 <= a.scale <= b.scale * 1.01
        assert np.all(np.abs(a.v) <= vmax * (1 + 1e-9))
        # The run's own limits hold, and the one that set its scale is reached (within 2 %).
        speed, acc = _needs(tag, per_run, a, run_mode)
        assert a.scale >= max(1.0, speed / (1 + 1e-4), acc / 1.02)
        binding = max(a.limits, key=a.limits.get)
        if binding in ("speed", "acceleration"):
            assert a.scale <= max(speed, acc) * 1.02, binding
        # The shape is kept: the setpoints are the tag's own positions at a scaled clock.
        assert np.allclose(a.xy, _exact(tag, per_run, a, a.tag_t))
        d, dtag = np.diff(a.t), np.diff(a.tag_t) * a.scale
        unclamped = d < slowest_durations(a.xy, run_mode) - 1e-9
        assert np.allclose(d[unclamped], dtag[unclamped])
    # Speed-bound runs: their fastest axis speed is the machine's, within 2 %.
    peaks = [np.max(np.abs(r.v) / vmax) for r in per_run.runs]
    assert max(peaks) > 0.98


def test_adaptive_setpoints_within_the_tolerance(tiny_file):
    """Straight lines in time between setpoints stay within motion.tolerance of the exact motion
    at every instant (1e4 steps/mm: no setpoint merged on a motor step)."""
    tag = tagbot.load_plan(EXAMPLES / "letter-b.json")
    fine_steps = ["limits.x_steps_per_mm=10000", "limits.y_steps_per_mm=10000"]
    lines = {}
    for tolerance in (0.005, 0.02):
        profile = load_profile(None, [*fine_steps, f"motion.tolerance={tolerance}"])
        placed = place(tag, profile)
        run = placed.runs[0]
        d = np.diff(run.t)
        assert np.all(d[:-1] >= profile.dt * (1 - 1e-9))
        assert np.all(d <= profile["motion.max_dt"] * (1 + 1e-9))
        instants = np.linspace(run.tag_t[0], run.tag_t[-1], 200_000)
        exact = _exact(tag, placed, run, instants)
        line = np.column_stack(
            [
                np.interp(instants, run.tag_t, run.xy[:, 0]),
                np.interp(instants, run.tag_t, run.xy[:, 1]),
            ]
        )
        error = np.hypot(*(exact - line).T)
        assert error.max() <= tolerance * 1.02
        assert error.max() > tolerance * 0.8  # the lines are as long as the tolerance allows
        lines[tolerance] = len(run.t)
    assert lines[0.02] < 0.7 * lines[0.005]


def test_buffered_motion_bound(tiny_file):
    """With a fine tolerance the lines are short and the buffer rule slows the runs: any 18
    consecutive lines of a longer run then hold motion.min_buffer."""
    tag = tagbot.load_plan(EXAMPLES / "cae.json")
    blocks = 15 - 1 + RX_LINES
    profile = load_profile(None, ["motion.tolerance=0.01"])
    placed = place(tag, profile)
    for run in placed.runs:
        d = np.diff(run.t)
        assert len(d) > blocks
        sums = np.convolve(d, np.ones(blocks), mode="valid")
        assert sums.min() >= profile["motion.min_buffer"] * (1 - 1e-6)
        assert buffered(run.t, blocks) == pytest.approx(sums.min())
    assert placed.limits["buffer"] == pytest.approx(placed.scale)
    free = place(tag, load_profile(None, ["motion.tolerance=0.01", "motion.min_buffer=0"]))
    assert free.duration < placed.duration
    assert min(buffered(r.t, blocks) for r in free.runs) < profile["motion.min_buffer"]


def test_a_short_run_is_not_slowed_for_the_buffer(tiny_file):
    """A run of 18 lines or fewer is held whole by the machine once sent: no host pause can
    starve it mid-stroke, so the buffer rule leaves its timing alone."""
    blocks = 15 - 1 + RX_LINES
    assert buffered(np.arange(blocks + 1) * 0.01, blocks) == math.inf
    assert buffered(np.arange(blocks + 2) * 0.01, blocks) == pytest.approx(blocks * 0.01)
    profile = load_profile(tiny_file)
    placed = place(straight_tag(), profile)
    free = place(straight_tag(), load_profile(tiny_file, ["motion.min_buffer=0"]))
    assert all(len(r.t) - 1 <= blocks for r in placed.runs)
    assert placed.duration == pytest.approx(free.duration)
    assert placed.limits["buffer"] == 1.0


def test_lines_never_slower_than_grbl_steps(tiny_file):
    profile = load_profile(tiny_file, ["place.scale=0.2"])
    placed = place(straight_tag(), profile)
    run = placed.runs[0]
    steps = np.round(np.round(run.xy, 3) * 100).astype(int)
    per_line = np.max(np.abs(np.diff(steps, axis=0)), axis=1)
    assert np.all(per_line >= 1)  # every setpoint moves the motor
    assert np.all(np.diff(run.t) <= per_line * profile["limits.slowest_step"] * (1 + 1e-9))
    fixed = place(
        straight_tag(), load_profile(tiny_file, ["place.scale=0.2", "motion.setpoints=fixed"])
    )
    d = np.diff(fixed.runs[0].t)
    assert np.all(d <= profile.dt * (1 + 1e-9))


def test_the_slowest_a_move_can_take_is_its_slowest_steps_or_the_minimum_feed() -> None:
    """At 100 steps/mm and 0.0327 s a step, 1 mm takes at most 3.27 s and a 3-4-5 move
    (400 steps on y) 13.08 s; a minimum feed of 100 mm/min caps them at 0.6 s and 3 s."""
    steps = ["limits.x_steps_per_mm=100", "limits.y_steps_per_mm=100", "limits.slowest_step=0.0327"]
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [4.0, 4.0]])
    by_steps = slowest_durations(xy, load_profile(None, [*steps, "limits.min_feed=1"]))
    assert by_steps == pytest.approx([3.27, 13.08])
    by_feed = slowest_durations(xy, load_profile(None, [*steps, "limits.min_feed=100"]))
    assert by_feed == pytest.approx([0.6, 3.0])


def test_a_segment_of_no_duration_has_speed_zero_and_every_speed_is_a_number() -> None:
    """Speeds per segment in mm/s: 10 mm in 0.5 s is 20; a repeated instant (no time) has no
    speed, 0, rather than an infinity or a missing value."""
    profile = load_profile(None, ["motion.min_buffer=0"])
    xy = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 0.0], [10.0, 5.0]])
    speed, cap = segment_speed_cap(xy, np.array([0.0, 0.5, 0.5, 1.0]), profile)
    assert speed.dtype == np.float64 and speed.tolist() == [20.0, 0.0, 10.0]
    assert len(cap) == 3 and np.all(np.isfinite(cap))


def test_a_single_too_fast_segment_is_slowed_and_a_run_without_corner_has_no_excess(tiny) -> None:
    """One move of 100 mm in 0.01 s (10 m/s) is far above the axis speeds: the time scale must
    grow by its speed over the axis limit; a lone point needs nothing. A run with no gentle
    corner (two points: no junction; a right angle: a cusp, where Grbl stops anyway) needs no
    slowing for its junctions: its junction excess is 0."""
    xy = np.array([[0.0, 0.0], [100.0, 0.0]])
    t = np.array([0.0, 0.01])
    vx = float(np.max(np.abs(tiny.axes @ np.array([1.0, 0.0])) / np.asarray(tiny.max_speed)))
    assert segment_excess(xy, t, tiny) >= 10_000.0 * vx > 1.0
    assert segment_excess(xy[:1], t[:1], tiny) == 0.0
    assert _junction_excess(xy, t, tiny) == 0.0
    corner = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    assert _junction_excess(corner, np.array([0.0, 0.01, 0.02]), tiny) == 0.0


def test_the_buffer_rule_is_met_at_equality_and_slows_just_beyond() -> None:
    """motion.min_buffer set to exactly the least time any 18 consecutive lines hold at the
    tag's natural timing is met: nothing is slowed. Set 0.1 % above it, the run holding that
    least time is slowed (and the buffer becomes a limit), the others are left alone."""
    tag = tagbot.load_plan(EXAMPLES / "cae.json")
    base = ["motion.tolerance=0.05"]
    blocks = 15 - 1 + RX_LINES
    free = place(tag, load_profile(None, [*base, "motion.min_buffer=0"]))
    held = [buffered(r.t, blocks) for r in free.runs]
    least = min(held)
    assert math.isfinite(least)
    at = place(tag, load_profile(None, [*base, f"motion.min_buffer={least!r}"]))
    assert [r.scale for r in at.runs] == [r.scale for r in free.runs]
    assert at.duration == free.duration and at.limits["buffer"] == 1.0
    above = place(tag, load_profile(None, [*base, f"motion.min_buffer={least * 1.001!r}"]))
    k = held.index(least)
    for i, (a, f) in enumerate(zip(above.runs, free.runs, strict=True)):
        if i == k:
            assert a.scale > f.scale and buffered(a.t, blocks) >= least * 1.001 * (1 - 1e-6)
            assert a.limits["buffer"] == a.scale
        else:
            assert a.scale == f.scale
    assert above.duration > free.duration


@pytest.mark.parametrize("above", [1.0001, 1.001, 1.003])
def test_a_buffer_goal_a_hair_above_the_natural_least_is_met(above: float) -> None:
    """letter-b's one run at its natural timing holds 0.80 s in its least 18 lines. A goal
    0.01-0.3 % above that is met, by slowing at least 1 % (a finer step changes the adaptive
    lines less than their own jitter, and was taken for lines that cannot lengthen), and no
    more than 1 % beyond the step the goal asks for."""
    tag = tagbot.load_plan(EXAMPLES / "letter-b.json")
    blocks = 15 - 1 + RX_LINES
    free = place(tag, load_profile(None, ["motion.min_buffer=0"]))
    least = buffered(free.runs[0].t, blocks)
    goal = least * above
    placed = place(tag, load_profile(None, [f"motion.min_buffer={goal!r}"]))
    assert buffered(placed.runs[0].t, blocks) >= goal
    assert placed.limits["buffer"] == placed.scale
    assert 1.01 <= placed.scale / free.scale <= 1.01 * 1.001 + 1e-9


def test_a_buffer_goal_half_again_the_least_is_met_by_every_run_of_cae() -> None:
    """cae's three runs hold 0.49, 0.61 and 0.55 s in their least 18 lines at their natural
    timing. A goal 1.5 times the least is met by each, also by the one whose lines lengthen
    less than in proportion at the first slowing (it is slowed again, not kept at the faster
    timing)."""
    tag = tagbot.load_plan(EXAMPLES / "cae.json")
    blocks = 15 - 1 + RX_LINES
    free = place(tag, load_profile(None, ["motion.min_buffer=0"]))
    goal = 1.5 * min(buffered(r.t, blocks) for r in free.runs)
    placed = place(tag, load_profile(None, [f"motion.min_buffer={goal!r}"]))
    for run, before in zip(placed.runs, free.runs, strict=True):
        assert buffered(run.t, blocks) >= goal * (1 - 1e-6)
        assert run.scale > before.scale and run.limits["buffer"] == run.scale


def test_the_bed_check_allows_a_micrometre_on_every_edge_and_not_more() -> None:
    """Setpoints exactly 1e-6 mm past an edge (rounding of a tag fitted edge to edge) are
    accepted on each of the four edges; 2e-6 mm past it is refused, naming that edge."""
    profile = load_profile(None, [])
    x_min, x_max, y_min, y_max = profile.bed
    inside = np.array([[0.5 * (x_min + x_max), 0.5 * (y_min + y_max)]])
    for axis, edge, key, out in (
        (0, x_min, "bed.x_min", -1.0),
        (0, x_max, "bed.x_max", 1.0),
        (1, y_min, "bed.y_min", -1.0),
        (1, y_max, "bed.y_max", 1.0),
    ):
        point = inside.copy()
        point[0, axis] = edge + out * 1e-6
        _check_bed(profile, [inside, point])
        point[0, axis] = edge + out * 2e-6
        with pytest.raises(PlacementError, match=rf"beyond {re.escape(key)} = "):
            _check_bed(profile, [inside, point])


def test_the_look_ahead_cap_counts_only_the_segment_and_the_ones_after_it() -> None:
    """With two look-ahead blocks, a segment's cap √(2·a·ΣL) sums its own length and the next
    one's (just its own at the end), never the path already drawn before it."""
    profile = load_profile(None, ["limits.planner_blocks=2"])
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [4.0, 0.0]])
    _, cap = segment_speed_cap(xy, 0.1, profile)
    # One direction, one acceleration: cap² is proportional to ΣL = 2, 2, 2 and 1 mm.
    assert (cap**2 / cap[-1] ** 2).tolist() == pytest.approx([2.0, 2.0, 2.0, 1.0])
