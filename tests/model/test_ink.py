"""Plans whose pen touches down and lifts off while moving: the ``ink`` window, its sampling, and
the run clocks machines draw it with (tagbot.model.easing)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tagbot.errors import PlanError
from tagbot.model.easing import EASE, RunClock, run_clock
from tagbot.model.motion import evaluate_plan, sample_ink, sample_plan
from tagbot.model.plan import Plan, Tag


def lifted(ink: tuple[float, float] | None = (0.15, 0.45), start: float = 0.5) -> Plan:
    """Three strokes along a hook; with ``ink``, the pen is down from 0.15 to 0.45 s in."""
    return Plan(
        [[0.0, 0.0], [20.0, 0.0], [40.0, 10.0], [45.0, 30.0]],
        [0.0, 0.12, 0.12],
        np.log([0.12, 0.12, 0.12]),
        [0.3, 0.3, 0.3],
        [0.2, -0.3, 0.1],
        [-0.1, 0.2, 0.3],
        start,
        ink,
    )


def test_the_ink_window_is_checked() -> None:
    for bad, message in [
        ((0.5, 0.2), r"ink: need 0 <= down < up <= 14400 s after start, got \[0.5, 0.2\]"),
        ((-0.1, 0.2), "ink: need 0 <= down < up"),
        ((0.1, float("nan")), "ink: need 0 <= down < up"),
        ("x", "ink: expected \\[down, up\\] seconds after start, got 'x'"),
    ]:
        with pytest.raises(PlanError, match=message):
            lifted(bad)  # type: ignore[arg-type]
    with pytest.raises(PlanError, match=r"plans\[0\].ink: the pen touches down 100 s after"):
        Tag((lifted((100.0, 200.0)),))


def test_the_pen_is_down_only_within_the_window() -> None:
    plan = lifted()
    tag = Tag((plan,))
    down, up = plan.ink_window(tag.size)
    assert (down, up) == (0.65, 0.95)
    motion = tag.sample(0.01)
    inked = motion.t[motion.pen == 1]
    assert inked[0] == pytest.approx(down) and inked[-1] == pytest.approx(up)
    assert [k for k, _ in motion.runs()] == [0]
    # Outside the window the pen follows the plan in the air: pen up, moving.
    air = (motion.pen == 0) & (motion.t > plan.start) & (motion.t < plan.end(tag.size))
    assert np.all(motion.plan[air] == -1) and motion.speed[air].max() > 50.0
    xy, _ = evaluate_plan(plan, motion.t, tag.size)
    inside = motion.t <= plan.end(tag.size)
    assert np.allclose(
        motion.xy[inside & (motion.t >= plan.start)], xy[inside & (motion.t >= plan.start)]
    )
    # The window moves with the plan; without one the whole motion is drawn.
    assert plan.at(2.0).ink_window(tag.size) == pytest.approx((2.15, 2.45))
    whole = lifted(None)
    assert whole.ink_window(tag.size) == (whole.start, whole.end(tag.size))


def test_sample_ink_covers_the_window_exactly() -> None:
    tag = Tag((lifted(), lifted(None, start=2.0)))
    (t0, xy0, v0), (t1, _, _) = sample_ink(tag, 0.004)
    assert (t0[0], t0[-1]) == pytest.approx((0.65, 0.95)) and np.all(np.diff(t0) > 0)
    assert np.allclose(xy0, evaluate_plan(tag.plans[0], t0, tag.size)[0])
    assert np.hypot(*v0[0]) > 50.0  # touching down moving
    whole = sample_plan(tag, 1, 0.004)[0]
    assert (t1[0], t1[-1]) == pytest.approx((whole[0], tag.plans[1].end(tag.size)))


def test_a_run_clock_eases_from_and_to_rest_on_the_same_path() -> None:
    plan = lifted()
    size = Tag((plan,)).size
    clock = run_clock(plan, 0.65, 0.95, size)
    assert (clock.ease_in, clock.ease_out) == (EASE, EASE)
    assert clock.duration == pytest.approx(0.3 + EASE)
    assert clock.tag_start == pytest.approx(0.65 - EASE / 2)
    u = np.linspace(0.0, clock.duration, 40001)
    tau, rate = clock.tag_time(u), clock.rate(u)
    assert tau[0] == pytest.approx(0.65) and tau[-1] == pytest.approx(0.95)
    assert np.all(np.diff(tau) >= 0) and rate[0] == 0.0 and rate[-1] == 0.0
    assert np.max(np.abs(np.gradient(tau, u) - rate)) < 1e-3  # rate is the clock's derivative
    assert np.max(np.abs(np.diff(rate))) < 1e-3  # no step in speed ...
    slope = np.diff(rate) / np.diff(u)
    assert np.max(np.abs(np.diff(slope))) < 0.1  # ... nor in acceleration
    middle = (u > EASE) & (u < clock.duration - EASE)
    assert np.allclose(tau[middle], clock.tag_start + u[middle]) and np.all(rate[middle] == 1.0)


def test_a_steady_run_clock_starts_at_a_constant_acceleration_and_joins_smoothly() -> None:
    """Not jerk-limited (stepper machines): the speed factor rises as ``2x - x²`` from rest, so
    a run leaves its touch-down point sooner, and still joins the plan's speed with no step in
    speed or acceleration; the path and the middle's rhythm are the same."""
    plan = lifted()
    size = Tag((plan,)).size
    clock = run_clock(plan, 0.65, 0.95, size, jerk_limited=False)
    smooth = run_clock(plan, 0.65, 0.95, size)
    assert (clock.ease_in, clock.ease_out, clock.jerk_limited) == (EASE, EASE, False)
    assert clock.duration == pytest.approx(0.3 + 2 * EASE / 3)
    assert clock.tag_start == pytest.approx(0.65 - EASE / 3)
    u = np.linspace(0.0, clock.duration, 40001)
    tau, rate = clock.tag_time(u), clock.rate(u)
    assert tau[0] == pytest.approx(0.65) and tau[-1] == pytest.approx(0.95)
    assert np.all(np.diff(tau) >= 0) and rate[0] == 0.0 and rate[-1] == 0.0
    assert np.max(np.abs(np.gradient(tau, u) - rate)) < 1e-3
    slope = np.diff(rate) / np.diff(u)
    assert slope[0] == pytest.approx(2 / EASE, rel=1e-3)  # a constant acceleration from rest
    assert np.max(np.abs(np.diff(rate))) < 1e-3 and np.max(np.abs(np.diff(slope))) < 0.1
    middle = (u > EASE) & (u < clock.duration - EASE)
    assert np.allclose(tau[middle], clock.tag_start + u[middle]) and np.all(rate[middle] == 1.0)
    # A hundredth of the ramp's advance is reached after 10 % of the ramp (x² ≈ 0.01), where
    # smoothstep takes 22 % (x³ ≈ 0.01).
    early = 0.65 + 0.01 * EASE
    assert np.interp(early, tau, u) == pytest.approx(0.1 * EASE, rel=0.05)
    u_smooth = np.linspace(0.0, smooth.duration, 40001)
    assert np.interp(early, smooth.tag_time(u_smooth), u_smooth) > 0.2 * EASE
    # Runs at rest keep the identity whatever the ramp.
    rest = run_clock(lifted(None), 0.6, 1.2, size, jerk_limited=False)
    assert rest.tag_start == 0.6 and rest.duration == pytest.approx(0.6)


@pytest.mark.parametrize("jerk_limited", [True, False])
def test_a_short_run_eased_at_both_ends_keeps_its_clock_in_order(jerk_limited: bool) -> None:
    """A run of 0.117 s of its plan, touching down and lifting off moving (ga3__katsu-6721 has
    one): both ramps together must not cover more of the plan's clock than the run has, or the
    clock would run backwards where they meet (steady ramps cover 2/3 of their length each)."""
    plan = lifted((0.3, 0.417))
    size = Tag((plan,)).size
    on, off = plan.ink_window(size)
    clock = run_clock(plan, on, off, size, jerk_limited=jerk_limited)
    u = np.linspace(0.0, clock.duration, 20001)
    tau = clock.tag_time(u)
    assert np.all(np.diff(tau) >= 0)
    assert tau[0] == pytest.approx(on) and tau[-1] == pytest.approx(off)
    kept = 0.5 if jerk_limited else 2.0 / 3.0
    assert clock.ease_in == clock.ease_out == pytest.approx(min(EASE, (off - on) / (2 * kept)))
    # The plan's positions along it follow in order too: no step back along the path.
    evaluate_plan(plan, tau, size)


def test_runs_at_rest_keep_the_identity_clock() -> None:
    plan = lifted(None)
    size = Tag((plan,)).size
    clock = run_clock(plan, 0.6, 1.2, size)
    assert clock == RunClock(0.6, 1.2)
    u = np.array([-0.1, 0.0, 0.3, 0.6, 0.7])
    assert np.array_equal(clock.tag_time(u), 0.6 + u) and np.all(clock.rate(u) == 1.0)
    # A window cut inside the ink (a trimmed run) eases only at the ink's moving edges, and a
    # short run's ramps together never exceed it.
    moving = lifted()
    inner = run_clock(moving, 0.7, 0.95, size)
    assert inner.ease_in == 0.0 and inner.ease_out == EASE
    short = run_clock(lifted((0.15, 0.2)), 0.65, 0.7, size)
    assert short.ease_in == short.ease_out == pytest.approx(0.05)
    assert short.duration == pytest.approx(0.1)


@pytest.mark.parametrize("trimmed", ["start", "end"])
def test_a_run_trimmed_at_one_end_eases_there_and_keeps_the_plans_speed_at_the_other(trimmed):
    """With ``ease_trimmed``, a run of an inkless plan cut after the plan's start eases in and
    ends at the plan's own end at the plan's speed (no ramp there), and the other way round."""
    plan = replace(lifted(), ink=None)
    size = Tag((plan,)).size
    end = plan.end(size)
    on, off = (plan.start + 0.2, end) if trimmed == "start" else (plan.start, end - 0.2)
    clock = run_clock(plan, on, off, size, ease_trimmed=True)
    eased = (clock.ease_in, clock.ease_out)
    assert eased == ((EASE, 0.0) if trimmed == "start" else (0.0, EASE))
    assert clock.duration == pytest.approx(off - on + EASE / 2)
    u = np.linspace(0.0, clock.duration, 4001)
    rate = clock.rate(u)
    plain = rate[-1] if trimmed == "start" else rate[0]
    ramped = rate[0] if trimmed == "start" else rate[-1]
    assert (plain, ramped) == (1.0, 0.0)
    assert clock.tag_time(u)[[0, -1]] == pytest.approx([on, off])


def test_a_run_clock_never_steps_back_where_its_ease_in_joins_the_plans_speed() -> None:
    """Sampled at the very instant the ramp ends (u = R₁) and the floats either side of it, the
    tag clock does not run backwards (evaluate_plan takes sorted times): it is already on the
    plan's own line ``tag_start + u`` there."""
    plan = lifted()
    size = Tag((plan,)).size
    clock = run_clock(plan, 0.65, 0.95, size)
    r1 = clock.ease_in
    assert r1 == EASE
    u = np.array([np.nextafter(r1, 0.0), r1, np.nextafter(r1, 1.0)])
    tau = clock.tag_time(u)
    assert np.all(np.diff(tau) >= 0)
    assert tau[1] == clock.tag_start + r1


def test_a_run_clock_at_rest_keeps_the_ramp_kind_it_was_asked_for() -> None:
    """A run with no easing (a plan at rest, or an empty run) still records that its machine is
    not jerk-limited, as every other run clock of that machine does."""
    size = Tag((lifted(None),)).size
    rest = run_clock(lifted(None), 0.6, 1.2, size, jerk_limited=False)
    assert rest == RunClock(0.6, 1.2, jerk_limited=False)
    empty = run_clock(lifted(), 0.8, 0.8, size, jerk_limited=False)
    assert empty == RunClock(0.8, 0.8, jerk_limited=False) and empty.duration == 0.0
