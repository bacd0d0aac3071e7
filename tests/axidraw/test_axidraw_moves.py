"""The job as EBB moves: exact step counts, every tick within the stated error of the plan."""

from __future__ import annotations

import itertools
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocols.ebb.motion import (
    ACCUMULATOR_STEP,
    TICK_HZ,
    AxisStart,
    Move,
    axis_final,
    execute,
)
from tagbot.axidraw.moves import SETTLE, _axis, _check_rates, build_job, run_reference, steps_to_xy
from tagbot.axidraw.profile import MOTOR_AXES, load_profile
from tagbot.errors import PlacementError
from tagbot.model import Plan, Tag
from tagbot.plotter.place import place


def replay(job):
    """Every motion entry re-executed from cleared accumulators at home: ticks per entry."""
    steps, accumulators = np.zeros(2, dtype=np.int64), (0, 0)
    out = []
    for entry in job.entries:
        if entry.move is None:
            out.append(np.zeros((0, 2), dtype=np.int64))
            continue
        relative, accumulators = execute(Move(**vars(entry.move)), accumulators)
        ticks = relative + steps
        steps = ticks[-1]
        out.append(ticks)
    return out


def test_every_move_ends_on_its_target_steps(cae_job):
    _tag, profile, setpoints, job = cae_job
    k = profile.steps_per_mm
    ticks = replay(job)
    for entry, moved in zip(job.entries, ticks, strict=True):
        if len(moved):
            assert tuple(moved[-1]) == entry.steps
    draws = [e for e in job.entries if e.kind == "draw"]
    assert {e.line.split(b",")[0] for e in draws} == {b"T3"}
    for index, run in enumerate(setpoints.runs):
        mine = [e for e in draws if e.run == index]
        # A 2 ms first move (no jerk) from where the pen went down, then one per setpoint,
        # each ending on its setpoint rounded to the nearest motor step.
        assert mine[0].move.ticks == round(SETTLE * TICK_HZ) and mine[0].move.jerk == (0, 0)
        assert mine[0].start == job.run_start[index]
        assert len(mine) == len(run.t)
        ends = [tuple(np.floor(MOTOR_AXES @ xy * k + 0.5).astype(int)) for xy in run.xy[1:]]
        assert [e.steps for e in mine[1:]] == ends
        ticks = [round((b - a) * TICK_HZ) for a, b in zip(run.t[1:-1], run.t[2:], strict=True)]
        assert [e.move.ticks for e in mine[2:]] == ticks


def test_every_tick_within_the_stated_error_of_the_plan(cae_job):
    tag, profile, setpoints, job = cae_job
    k = profile.steps_per_mm
    ticks = replay(job)
    for index, (run, _start) in enumerate(zip(setpoints.runs, job.run_start, strict=True)):
        mine = [i for i, e in enumerate(job.entries) if e.kind == "draw" and e.run == index]
        executed = np.concatenate([ticks[i] for i in mine])
        times = np.arange(1, len(executed) + 1) / TICK_HZ
        plan = run_reference(tag, run, setpoints.matrix, setpoints.offset)(times)
        gap = np.hypot(*(steps_to_xy(executed, k) - plan).T)
        assert gap.max() <= job.run_error[index] + 1e-9  # the times differ by float rounding
        assert job.run_error[index] == pytest.approx(gap.max())
        # Half a step on each motor away from the exact motion (0.00625 mm at 80 steps/mm),
        # more only on a run's first move (where the pen went down, within a step).
        assert np.percentile(gap, 99) <= 0.5 / k + 1e-4
        assert gap.max() < 1.5 / k
        assert job.move_error[mine].max() == pytest.approx(gap.max())
    assert len(job.ticks) == sum(len(t) for t in ticks)


def test_rates_follow_the_planned_velocity(cae_job):
    _tag, profile, setpoints, job = cae_job
    k = profile.steps_per_mm
    unit = ACCUMULATOR_STEP / TICK_HZ  # rate units per step/s
    run = setpoints.runs[0]
    draws = [e for e in job.entries if e.kind == "draw" and e.run == 0]
    planned = run.v[1:] @ MOTOR_AXES.T * k  # steps/s at each move's end
    for entry, v in zip(draws[1:], planned, strict=True):  # after the 2 ms first move
        m = entry.move
        n = m.ticks
        for axis in (0, 1):
            r = m.rate[axis] - int(m.accel[axis] / 2) + int(m.jerk[axis] / 6)
            a = m.accel[axis] - m.jerk[axis]
            last = r + a * n + m.jerk[axis] * n * (n + 1) // 2
            # Within 2 steps/s of the plan at the end of every move (speeds up to 10^4 steps/s).
            assert abs(last / unit - v[axis]) < 2.0


def test_pen_moves_with_the_servo_time_and_travel_at_the_machine_speed(cae_job):
    _tag, profile, _setpoints, job = cae_job
    k = profile.steps_per_mm
    kinds = "".join({"travel": "T", "pen": "P", "draw": "D"}[e.kind] for e in job.entries)
    # Travel, pen down, the run, pen up at once (no resting pen), ..., travel home.
    assert re.fullmatch(r"(T+PD+P){3}T+", kinds)
    for entry in job.entries:
        if entry.kind == "pen":
            down = entry.pen
            assert entry.line == (b"SP,0,146,1\r" if down else b"SP,1,130,1\r")
            assert entry.duration == (0.146 if down else 0.130)
    assert job.entries[-1].steps == (0, 0) and not job.entries[-1].pen
    ticks = replay(job)
    window = TICK_HZ // 100  # 10 ms
    for entry, moved in zip(job.entries, ticks, strict=True):
        if entry.kind != "travel" or len(moved) < 10 * window:
            continue
        assert entry.line.startswith(b"LM,")
        speed = np.abs(moved[window:] - moved[:-window]).max() / (window / TICK_HZ) / k
        assert (
            profile["limits.travel_speed"] * 0.95 < speed <= profile["limits.travel_speed"] * 1.01
        )
    duration = sum(e.duration for e in job.entries)
    assert job.duration == pytest.approx(duration)
    assert len(job.ticks) / TICK_HZ == pytest.approx(
        sum(e.duration for e in job.entries if e.kind != "pen")
    )


def test_lt_without_jerk_when_asked(cae_job):
    tag, _, setpoints, _ = cae_job
    profile = load_profile(overrides=["motion.jerk=false"])
    job = build_job(tag, setpoints, profile)
    draws = [e for e in job.entries if e.kind == "draw"]
    assert {e.line.split(b",")[0] for e in draws} == {b"LT"}
    assert max(job.run_error) < 1.5 / profile.steps_per_mm


def test_a_move_faster_than_a_step_per_tick_is_refused(cae_job):
    tag, _, _, _ = cae_job
    setpoints = place(tag, load_profile(overrides=["limits.draw_speed=312"]).placement())
    # The same motion on motors of 5x the steps per mm: past one step per 40 us tick.
    slow = ["motors.steps_per_mm_16x=400", "limits.draw_speed=62", "limits.travel_speed=62"]
    with pytest.raises(PlacementError, match=r"^motion: a drawing move needs \d+ steps/s on a"):
        build_job(tag, setpoints, load_profile(overrides=slow))


def test_a_t3_move_too_fast_only_at_its_second_tick_is_refused():
    """A T3 move past one step per tick only at tick 2 (its rate's peak) is refused."""
    # Loaded rate, accel and jerk per tick: the rate turns at tick -accel/jerk - 1/2 = 1.75.
    jerk = -(2**24)
    accel = -jerk * 9 // 4
    rate = ACCUMULATOR_STEP - 1 - (accel + jerk)  # tick 1 at exactly one step per tick
    rates = [rate + accel * k + jerk * k * (k + 1) // 2 for k in (1, 2, 3)]
    assert rates[0] == ACCUMULATOR_STEP - 1 and rates[2] < rates[0] < rates[1]
    # The command's parameters (rate + accel/2 - jerk/6, accel + jerk), each within int32.
    sent = (rate + (accel + jerk) // 2 - int(jerk / 6), accel + jerk, jerk)
    assert AxisStart.load(*sent) == AxisStart(rate, accel, jerk)
    assert not AxisStart.load(*sent).stays_in_int32(3)  # the firmware's tick 2 would wrap
    move = Move("T3", (sent[0], 0), (sent[1], 0), (sent[2], 0), ticks=3)
    needs = round(rates[1] / ACCUMULATOR_STEP * TICK_HZ)
    assert needs == 25049
    with pytest.raises(PlacementError) as info:
        _check_rates(move)
    assert str(info.value) == (
        f"motion: a drawing move needs {needs} steps/s on a motor, beyond the EBB's {TICK_HZ}"
        " (lower limits.draw_speed)"
    )


def test_a_dot_is_drawn_as_pen_down_and_up_where_it_is():
    stroke = dict(dt=[0.0], mu=[math.log(0.2)], sigma=[0.3], phi1=[0.0], phi2=[0.0])
    line = Plan(targets=[[0.0, 0.0], [10.0, 0.0]], start=0.0, **stroke)
    dot = Plan(targets=[[5.0, 5.0], [5.0 + 1e-6, 5.0]], start=line.end(10.0) + 0.5, **stroke)
    tag = Tag(plans=(line, dot))
    profile = load_profile()
    setpoints = place(tag, profile.placement())
    assert [len(r.t) > 1 for r in setpoints.runs] == [True, False]
    job = build_job(tag, setpoints, profile)
    kinds = "".join({"travel": "T", "pen": "P", "draw": "D"}[e.kind] for e in job.entries)
    assert re.fullmatch(r"T+PD+PT+PPT+", kinds)
    down = kinds.index("PP", kinds.index("D"))
    here = steps_to_xy(job.entries[down].steps, profile.steps_per_mm)
    assert np.hypot(*(here - setpoints.runs[1].xy[0])) == pytest.approx(job.run_error[1])
    assert job.run_error[1] < 1.0 / profile.steps_per_mm


def test_runs_are_retimed_to_the_speed_along_each_motor(cae_job):
    _tag, profile, setpoints, _job = cae_job
    along = np.concatenate([np.abs(r.v @ MOTOR_AXES.T) for r in setpoints.runs])
    # cae.json is faster than the machine: the fastest motor runs at the limit, never above.
    assert along.max() <= profile["limits.draw_speed"] * (1 + 1e-6)
    assert along.max() >= profile["limits.draw_speed"] * 0.99
    # Along x alone a motor turns at the speed of the pen: |vx| + |vy| is what is limited.
    speed = np.concatenate([np.abs(r.v).sum(axis=1) for r in setpoints.runs])
    np.testing.assert_allclose(speed.max(), along.max())


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    n=st.integers(3, 2500),
    accumulator=st.integers(0, ACCUMULATOR_STEP - 1),
    speed=st.floats(-0.7, 0.7),
    change=st.tuples(st.floats(-0.1, 0.1), st.floats(-0.1, 0.1)),
    edge=st.sampled_from([None, "low", "high"]),
    jerk=st.booleans(),
)
def test_one_axis_ends_on_its_goal_within_half_a_tick_of_rate(
    n, accumulator, speed, change, edge, jerk
):
    # Steps per tick: under one, as the profile's limits keep them; planned rates near the mean.
    distance = speed * n
    rates = ((speed + change[0]) * ACCUMULATOR_STEP, (speed + change[1]) * ACCUMULATOR_STEP)
    aim = round(distance * ACCUMULATOR_STEP)
    goal = math.floor(distance)
    if edge == "low":  # aimed a hair below its goal's step: the rate brings it in
        aim = goal * ACCUMULATOR_STEP - 1
    elif edge == "high":
        aim = (goal + 1) * ACCUMULATOR_STEP
    rate, accel, j = _axis(n, accumulator, aim, rates, goal, jerk)
    steps, final = axis_final(n, rate, accel, j, accumulator)
    assert steps == goal
    end = steps * ACCUMULATOR_STEP + final
    # The nearest whole rate: within n/2 accumulator units of the aim; within n of the goal's
    # step where the aim is not inside it by n.
    low, high = goal * ACCUMULATOR_STEP, (goal + 1) * ACCUMULATOR_STEP - 1
    if low + n <= aim <= high - n:
        assert abs(end - aim) <= n / 2
    else:
        assert abs(end - min(max(aim, low), high)) < n
    assert j == 0 or jerk


def test_travel_starts_and_ends_at_a_crawl(cae_job):
    _tag, profile, _setpoints, job = cae_job
    unit = ACCUMULATOR_STEP / TICK_HZ
    crawl = profile["limits.travel_acceleration"] * profile.steps_per_mm * 0.001  # steps/s
    travel = [e.move for e in job.entries if e.kind == "travel"]
    for accelerate, _cruise, decelerate in zip(
        travel[::3], travel[1::3], travel[2::3], strict=True
    ):
        dominant = int(np.argmax(np.abs(accelerate.steps)))
        assert accelerate.rate[dominant] == round(crawl * unit)
        # v^2 = v0^2 + 2 a s, per tick, back down to the crawl over the last phase's steps.
        peak = decelerate.rate[dominant]
        slowest = (
            peak**2
            + 2 * decelerate.accel[dominant] * abs(decelerate.steps[dominant]) * ACCUMULATOR_STEP
        )
        assert math.sqrt(slowest) / unit == pytest.approx(crawl, rel=0.01)


@pytest.mark.parametrize("overrides", [("motion.dt=0.2", "motion.max_dt=0.2"),
                                       ("motion.jerk=false", "motion.dt=0.1")])  # fmt: skip
def test_a_move_that_strays_from_the_plan_is_split(overrides):
    """Setpoints far apart (or LT's constant acceleration) leave moves whose cubic misses the
    plan: each is split at its middle tick until every tick is within SPLIT_ERROR (cae: 0.022
    and 0.044 mm before splitting), measured against the plan here from the job's own ticks."""
    from tagbot.axidraw.moves import SPLIT_ERROR
    from tagbot.io.planfile import load_plan

    from .conftest import CAE

    tag = load_plan(CAE)
    profile = load_profile(overrides=overrides)
    setpoints = place(tag, profile.placement())
    job = build_job(tag, setpoints, profile)
    draws = [e for e in job.entries if e.kind == "draw"]
    intervals = sum(len(r.t) - 1 for r in setpoints.runs)
    assert len(draws) > intervals + len(setpoints.runs)  # more than one move per setpoint
    assert max(job.move_error) <= SPLIT_ERROR
    # Every tick of every run against the plan, independently of the job's own figures.
    for k, (run, start) in enumerate(zip(setpoints.runs, job.run_start, strict=True)):
        at = run_reference(tag, run, setpoints.matrix, setpoints.offset)
        mine = [e for e in draws if e.run == k]
        inside = (job.tick_time > mine[0].start + 1e-9) & (job.tick_time <= mine[-1].end + 1e-9)
        gap = np.hypot(*(job.xy(job.ticks[inside]) - at(job.tick_time[inside] - start)).T)
        assert gap.max() <= SPLIT_ERROR + 1e-9, (k, gap.max())
        # Split at the middle tick: each move spans its stretch between setpoints (after a
        # T3 run's settle move) halved some number of times, to the tick.
        ticks = [round((e.start - start) * TICK_HZ) for e in mine]
        ticks.append(round((mine[-1].end - start) * TICK_HZ))
        edges = set(np.round(run.t * TICK_HZ).astype(int).tolist())
        if ticks[1] == round(SETTLE * TICK_HZ):
            edges.add(ticks[1])
        for a, b in itertools.pairwise(ticks):
            m = min(x for x in edges if x >= b) - max(x for x in edges if x <= a)
            assert any(b - a in (m >> j, -(-m >> j)) for j in range(16)), (k, a, b, m)
