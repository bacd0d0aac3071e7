"""benchmarks/bench_axidraw.py's own pieces: the AxiDraw software's planner as rebuilt there
(trapezoids, corners, SM moves), the lower bound's arithmetic, and a classic job on the
simulated board. Hand-computed figures; no shared data."""

from __future__ import annotations

import itertools
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from bench_axidraw import (
    TIME_SLICE,
    Classic,
    classic_job,
    junction_speed,
    lower_bound,
    polyline_moves,
    run_classic,
    run_scale,
    segment_moves,
    segment_slices,
    simplify,
    trapezoid_time,
    vertex_speeds,
)

from tagbot.axidraw.profile import load_profile

RULE = Classic(speed=50.0, accel=800.0, corner=0.05, slow=5.0)


def test_the_default_rule_is_the_axidraw_softwares() -> None:
    # speed_pendown 25 of 110 % of 8.6979 in/s, 30 in/s², cornering 10 / 5000 in.
    down = Classic.pen_down(load_profile())
    assert down.speed == pytest.approx(25 / 110 * 221.0)
    assert down.speed == pytest.approx(50.23, abs=0.01)
    assert down.accel == 762.0
    assert down.corner == pytest.approx(0.0508)
    up = Classic.pen_up(load_profile())
    assert up.speed == pytest.approx(150.7, abs=0.05)
    assert up.accel == 1143.0


def test_a_long_segment_from_rest_to_rest_is_the_trapezoid() -> None:
    # 100 mm at 50 mm/s and 800 mm/s²: 1/16 s up, 1/16 s down (1.5625 mm each), the rest
    # cruising.
    slices = segment_slices(100.0, 0.0, 0.0, RULE)
    durations = np.array([d for d, _ in slices])
    speeds = np.array([v for _, v in slices])
    assert durations.sum() == pytest.approx(100.0 / 50.0 + 50.0 / 800.0, abs=1e-12)
    assert float(durations @ speeds) == pytest.approx(100.0, abs=1e-9)
    assert speeds.max() == pytest.approx(50.0)
    # The ramp: floor(0.0625 / 0.025) = 2 slices of 31.25 ms at 1/3 and 2/3 of the cruise.
    assert speeds[:2] == pytest.approx([50 / 3, 100 / 3])
    assert durations[:2] == pytest.approx([0.03125, 0.03125])
    assert speeds[-2:] == pytest.approx([100 / 3, 50 / 3])
    # The cruise: 96.875 mm, 1.9375 s in pieces of at most 0.5 s.
    cruise = durations[np.isclose(speeds, 50.0)]
    assert cruise == pytest.approx([20 * TIME_SLICE] * 3 + [0.4375])


def test_short_segments_are_triangles_ramps_or_one_slice() -> None:
    # 4.5 mm from rest to rest: too short to cruise (it would need 3.125 + 1.25 mm and 5 mm);
    # over 0.9 of the 3.125 mm the ramps take, so the acceleration eases to
    # 0.9 · 3.125 / 4.5 · 800 = 500 mm/s²: a triangle peaking at √(500 · 4.5) in 3 + 3 slices,
    # the way down stepping from where the way up got to (3/4 of the peak), to rest.
    slices = segment_slices(4.5, 0.0, 0.0, RULE)
    peak = math.sqrt(500.0 * 4.5)
    assert [v for _, v in slices] == pytest.approx([peak * j / 4 for j in (1, 2, 3, 2, 1, 0)])
    assert sum(d for d, _ in slices) == pytest.approx(2 * math.sqrt(4.5 / 500.0))
    # 2 mm: a triangle of only 2 + 2 slices (peak 40 mm/s) becomes a linear ramp from the
    # boosted start (40 + 0) / 2 to rest: 8 slices over (0 - 20) / ((0 - 20²) / (2 · 2)) = 0.2 s.
    slices = segment_slices(2.0, 0.0, 0.0, RULE)
    assert [v for _, v in slices] == pytest.approx([20.0 * (1 - j / 9) for j in range(1, 9)])
    assert sum(d for d, _ in slices) == pytest.approx(0.2)
    # 0.5 mm between two vertices at the cruise speed: one slice at the triangle's peak
    # sqrt(v² + a·L), above the cruise speed (the published planner does so).
    (only,) = segment_slices(0.5, 50.0, 50.0, RULE)
    assert only[1] == pytest.approx(math.sqrt(50.0**2 + 800.0 * 0.5))
    assert only[0] * only[1] == pytest.approx(0.5)


def test_sm_moves_end_on_the_segments_steps_within_the_boards_rate() -> None:
    moves = segment_moves((4000, -1234), 52.9, 0.0, 0.0, RULE)
    assert sum(m[1] for m in moves) == 4000
    assert sum(m[2] for m in moves) == -1234
    assert all(m[0] >= 1 for m in moves)
    assert all(max(abs(m[1]), abs(m[2])) / m[0] < 24.995 for m in moves)
    slices = segment_slices(52.9, 0.0, 0.0, RULE)
    assert sum(m[0] for m in moves) == round(1000 * sum(d for d, _ in slices))


def test_a_fast_move_is_lengthened_to_the_boards_rate() -> None:
    # 60 steps in a 1 ms slice would be 60 steps/ms: lengthened to 3 ms (under 24.995).
    fast = Classic(speed=1000.0, accel=1e9, corner=0.05, slow=5.0)
    (move,) = segment_moves((60, 0), 0.53, 1000.0, 1000.0, fast)
    assert move == (3, 60, 0)


def test_junction_speed_is_the_corner_circles() -> None:
    # A right angle: the circle 0.05 mm from the corner has radius 0.05 / (√2 − 1) mm.
    right = junction_speed(np.array([1.0, 0.0]), np.array([0.0, 1.0]), 800.0, 0.05)
    assert right == pytest.approx(math.sqrt(800.0 * 0.05 / (math.sqrt(2) - 1)))
    assert right == pytest.approx(9.827, abs=0.001)
    assert junction_speed(np.array([1.0, 0.0]), np.array([1.0, 0.0]), 800.0, 0.05) == math.inf
    assert junction_speed(np.array([1.0, 0.0]), np.array([-1.0, 0.0]), 800.0, 0.05) == 0.0


def test_vertex_speeds_stop_at_the_ends_and_can_always_slow_down() -> None:
    t = np.linspace(0, 2 * np.pi, 200)
    points = np.column_stack([20 * np.cos(t), 10 * np.sin(2 * t)])
    path, v = vertex_speeds(points, RULE)
    assert v[0] == 0.0 and v[-1] == 0.0
    assert v.max() == pytest.approx(50.0)
    lengths = np.hypot(*np.diff(path, axis=0).T)
    assert np.all(v[:-1] ** 2 <= v[1:] ** 2 + 2 * 800.0 * lengths + 1e-9)
    assert np.all(v[1:] ** 2 <= v[:-1] ** 2 + 2 * 800.0 * lengths + 1e-9)
    # A right-angle corner holds the speed to its circle's.
    corner = np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 30.0]])
    _, v = vertex_speeds(corner, RULE)
    assert v[1] == pytest.approx(math.sqrt(800.0 * 0.05 / (math.sqrt(2) - 1)))


def test_polyline_moves_reach_every_vertex_step() -> None:
    k = 80.0
    points = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 5.0], [3.0, 7.5]])
    moves, end = polyline_moves(points, k, (0, 0), RULE)
    target = (round(k * (3.0 + 7.5)), round(k * (3.0 - 7.5)))
    assert end == target
    assert (sum(m[1] for m in moves), sum(m[2] for m in moves)) == target


def test_simplify_keeps_the_path_within_the_tolerance() -> None:
    t = np.linspace(0, 1, 1001)
    points = np.column_stack([10 * t, np.sin(6 * t)])
    kept = simplify(points, 0.01)
    assert 5 < len(kept) < 200
    assert (kept[0] == points[0]).all() and (kept[-1] == points[-1]).all()
    # Every point within 0.01 mm of the kept polyline.
    fine = np.vstack([np.linspace(a, b, 200, endpoint=False) for a, b in itertools.pairwise(kept)])
    gaps = np.min(np.hypot(*(points[:, None, :] - fine[None, :, :]).transpose(2, 0, 1)), axis=1)
    assert gaps.max() <= 0.01 + 1e-3


def test_trapezoid_time() -> None:
    assert trapezoid_time(100.0, 50.0, 1000.0) == pytest.approx(2.0 + 0.05)
    assert trapezoid_time(1.0, 50.0, 1000.0) == pytest.approx(2 * math.sqrt(0.001))
    edge = 50.0**2 / 1000.0  # cruise reached just as the deceleration starts
    assert trapezoid_time(edge, 50.0, 1000.0) == pytest.approx(0.1)
    assert trapezoid_time(edge * (1 - 1e-9), 50.0, 1000.0) == pytest.approx(0.1)
    assert trapezoid_time(0.0, 50.0, 1000.0) == 0.0


def test_run_scale_holds_speed_and_acceleration_along_the_motors() -> None:
    # A circle of radius 10 mm at 100 mm/s: along x ± y its speed peaks at 100·√2, its
    # acceleration at (100²/10)·√2.
    du = 0.0005
    t = np.arange(0, 2 * np.pi * 10 / 100, du)
    p = 10 * np.column_stack([np.cos(10 * t), np.sin(10 * t)])
    by_speed = run_scale(p, du, 100.0, 1e9)
    assert by_speed == pytest.approx(math.sqrt(2), rel=1e-3)
    by_accel = run_scale(p, du, 1e9, 1000.0)
    assert by_accel == pytest.approx(math.sqrt(1000.0 * math.sqrt(2) / 1000.0), rel=1e-3)
    assert run_scale(p, du, 1e9, 1e9) == 1.0


@pytest.mark.parametrize("name", ["default", "nextdraw8511"])  # the pen on RB1, on RB2
def test_a_classic_job_runs_on_the_simulated_board(name: str) -> None:
    profile = load_profile(name)
    path = np.column_stack([np.linspace(20, 60, 400), 30 + 5 * np.sin(np.linspace(0, 6, 400))])
    job = classic_job([path], profile)
    assert job.lines[0].startswith(b"SM,") and not job.pen_down[0]
    assert any(line.startswith(b"SP,0,") for line in job.lines)
    trace, duration = run_classic(job, profile, "bench_axidraw_test")
    assert duration >= sum(job.durations) - 1e-9
    down = trace[trace[:, 3] > 0.5]
    # Drawn where the path is (within a motor step and the polyline's tolerance) ...
    gaps = np.min(np.hypot(*(down[:, None, 1:3] - path[None, :, :]).transpose(2, 0, 1)), axis=1)
    assert gaps.max() < 0.1
    # ... from its start to its end, and parked home at the end.
    assert np.hypot(*(down[0, 1:3] - path[0])) < 0.05
    assert np.hypot(*(down[-1, 1:3] - path[-1])) < 0.05
    assert np.abs(trace[-1, 1:3]).max() < 1e-9


def test_the_lower_bound_is_below_the_plan_and_agrees_on_each_runs_scale(cae_job) -> None:
    tag, profile, setpoints, job = cae_job
    bound, scales = lower_bound(tag, setpoints, profile)
    assert bound <= job.duration
    pens = len(setpoints.runs) * (profile.pen_time(True) + profile.pen_time(False))
    assert bound > pens + sum(r.duration for r in setpoints.runs) * 0.9
    # The placement retimes each run on its setpoints, the bound on the continuous motion:
    # the same limits, so nearly the same scales (the placement's never the smaller).
    for run, s in zip(setpoints.runs, scales, strict=True):
        assert s <= run.scale * (1 + 1e-3)
        assert s >= run.scale * 0.99


def test_a_run_touching_down_at_its_peak_speed_is_scaled_by_its_drawn_motion() -> None:
    """letter-b with its pen touching down at the plan's fastest instant: the run eases from
    rest there, so its scale is the eased motion's (as the bound computes it independently),
    not the one the plan's own touch-down speed would ask for."""
    from dataclasses import replace

    from tagbot.axidraw.profile import MOTOR_AXES
    from tagbot.io.planfile import load_plan
    from tagbot.model import Tag
    from tagbot.model.motion import evaluate_plan
    from tagbot.plotter.place import place

    letter = load_plan(Path(__file__).resolve().parents[2] / "tagbot/examples/letter-b.json")
    plan = letter.plans[0]
    t = np.linspace(plan.start, plan.end(letter.size), 4001)
    _, v = evaluate_plan(plan, t, letter.size)
    peak = float(t[np.argmax(np.hypot(*v.T))])
    tag = Tag((replace(plan, ink=(peak - plan.start, plan.end(letter.size) - plan.start)),),
              letter.model, letter.units)  # fmt: skip
    profile = load_profile()
    setpoints = place(tag, profile.placement())
    (run,) = setpoints.runs
    _, (bound_scale,) = lower_bound(tag, setpoints, profile)
    assert run.scale == pytest.approx(bound_scale, rel=0.01)
    # The plan's own speed where the pen touches down would have asked for far more.
    touch = np.abs(v[np.argmax(np.hypot(*v.T))] @ setpoints.matrix.T @ MOTOR_AXES.T).max()
    assert touch / profile["limits.draw_speed"] > 1.2 * run.scale


def test_the_step_ceiling_is_the_rounding_to_motor_steps() -> None:
    """A run along x whose speed varies (v + 0.9·cos 3t mm/s) for 1 s, rounded to motor steps
    (1/80 mm on each motor): the slower it is, the fewer steps per 10 ms of the comparison and
    the lower its ceiling (about 6 dB per doubling); a run on whole steps has no rounding."""
    from bench_axidraw import step_ceiling

    t = np.arange(0.0, 1.0005, 0.001)

    def ceiling(v: float) -> float:
        return step_ceiling(t, np.column_stack([v * t + 0.3 * np.sin(3 * t), 0 * t]), 80.0)

    slow, fast = ceiling(1.0), ceiling(10.0)
    assert 10.0 < slow < 20.0 and 27.0 < fast < 37.0 and fast - slow > 15.0
    on_steps = np.column_stack([np.round(t * 1000) / 80.0, np.zeros_like(t)])
    assert step_ceiling(t, on_steps, 80.0) > 200.0  # float rounding only


def test_where_a_slow_run_sits_on_the_step_grid_moves_an_exact_followers_score() -> None:
    """The same slow run (1 mm/s along x, varying) moved by fractions of a step: an exact
    follower's score spans a band of dB; the band holds the unmoved run's, and on a fast run
    (more steps per 10 ms) it is narrower."""
    from bench_axidraw import step_band, step_ceiling

    t = np.arange(0.0, 1.0005, 0.001)

    def run(v: float) -> np.ndarray:
        return np.column_stack([v * t + 0.3 * np.sin(3 * t), 0 * t])

    low, high = step_band(t, run(1.0), 80.0)
    assert low <= step_ceiling(t, run(1.0), 80.0) <= high
    assert high - low > 0.5
    fast_low, fast_high = step_band(t, run(10.0), 80.0)
    assert fast_low > high and fast_high - fast_low < high - low


def test_the_band_is_judged_over_the_span_that_was_drawn() -> None:
    """A run that starts and ends at rest: over its middle alone (a pen-down span that left its
    slow ends out) an exact follower's steps lose less of its speed than over all of it."""
    from bench_axidraw import step_band

    t = np.arange(0.0, 0.6005, 0.001)
    xy = np.column_stack([2.0 * (1 - np.cos(np.pi * t / 0.6)), 0.5 * (1 - np.cos(np.pi * t / 0.6))])
    whole = step_band(t, xy, 80.0)
    middle = step_band(t, xy, 80.0, t[(t > 0.15) & (t < 0.45)])
    assert middle[0] > whole[0] and middle[1] > whole[1]


def test_the_worst_runs_band_is_over_its_pen_down_span_on_the_plans_clock() -> None:
    """The pen went down 50 ms before a (trimmed, already moving) run's plan starts and lifted
    50 ms after it ends, on an executed clock 2 s later: the band takes those instants too,
    on the plan's clock, as the run's own comparison does."""
    from bench_axidraw import drawn_band, step_band

    t = np.arange(0.0, 0.3005, 0.001)
    xy = np.column_stack([1.0 + 3.0 * t + 0.2 * np.sin(9 * t), 0.5 * t])
    te = np.arange(-0.05, 0.3505, 0.001)
    held = np.column_stack([np.interp(te, t, xy[:, 0]), np.interp(te, t, xy[:, 1])])
    executed = np.column_stack([te + 2.0, np.round(held * 80) / 80, np.ones(len(te))])
    run = {"planned_start": 0.0, "executed_start": 2.0}
    band = drawn_band({"runs": [run]}, run, (t, xy), executed, 80.0)
    np.testing.assert_allclose(band, step_band(t, xy, 80.0, (te + 2.0) - 2.0), atol=1e-9)
    assert band != step_band(t, xy, 80.0)
