"""Grbl 1.1 planner and stepper in simulated time: physics invariants and reference timings.

The reference timings are facts from transcripts of the real Grbl 1.1h firmware (built as a host
simulator, streamed over a pseudo-terminal at 115200 baud), written here as literal numbers.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.grbl import (
    DT_SEGMENT,
    HOLD,
    IDLE,
    PLANNER_CAPACITY,
    RUN,
    Dwell,
    GrblExecutor,
    GrblSettings,
    MotionBlock,
)

# The pen plotter of the reference logs ($100-$102, $110-$112, $120-$122, $11), without the 25 ms
# step idle delay ($1) where a test wants the bare motion time.
PLOTTER = GrblSettings(
    steps_per_mm=(80.0, 80.0, 80.0),
    max_rate_mm_per_min=(6000.0, 6000.0, 3000.0),
    acceleration_mm_per_s2=(1000.0, 1000.0, 1000.0),
    junction_deviation_mm=0.01,
    stepper_idle_lock_ms=0,
)
A = 1000.0  # mm/s²


def feed(x: float, y: float = 0.0, z: float = 0.0, f: float = 3000.0) -> MotionBlock:
    return MotionBlock((x, y, z), feed_mm_per_min=f)


def stream(
    blocks: list[MotionBlock], config: GrblSettings = PLOTTER, **kwargs: object
) -> GrblExecutor:
    """Queue blocks as fast as the planner takes them (a full serial buffer), run to idle."""
    ex = GrblExecutor(config, auto_start=False, **kwargs)  # type: ignore[arg-type]
    for block in blocks:
        if not ex.submit(block):
            ex.run_until(math.inf, until=lambda block=block: ex.submit(block))
    ex.cycle_start()
    ex.run_until_idle()
    return ex


def segment_kinematics(ex: GrblExecutor) -> tuple[np.ndarray, np.ndarray]:
    """Mid-times and velocities (mm/s) of the executed trace between its knots."""
    t, p = ex.recorder.knots()  # type: ignore[union-attr]
    dt = np.diff(t)
    keep = dt > 0
    v = np.diff(p, axis=0)[keep] / dt[keep, None]
    return ((t[:-1] + t[1:]) / 2)[keep], v


# -- single moves: the trapezoid and triangle formulas --------------------------------------------


def test_long_move_takes_the_trapezoid_time() -> None:
    ex = stream([feed(100.0, f=3000.0)])
    v = 50.0  # mm/s
    assert ex.now == pytest.approx(100.0 / v + v / A, rel=1e-4)  # cruise + accel/decel losses
    assert ex.position_mm == (100.0, 0.0, 0.0)


def test_short_move_takes_the_triangle_time() -> None:
    ex = stream([feed(1.0, f=6000.0)])  # cannot reach 100 mm/s in 0.5 mm
    assert ex.now == pytest.approx(2.0 * math.sqrt(1.0 / A), rel=1e-3)


def test_idle_follows_the_step_idle_delay() -> None:
    ex = stream([feed(10.0, f=3000.0)], dataclasses.replace(PLOTTER, stepper_idle_lock_ms=25))
    assert ex.now == pytest.approx(10.0 / 50.0 + 50.0 / A + 0.025, rel=1e-4)
    # Meanwhile Grbl reports Run at the final position and its main loop reads no line.
    ex = GrblExecutor(dataclasses.replace(PLOTTER, stepper_idle_lock_ms=25))
    assert ex.submit(feed(10.0, f=3000.0))
    ex.run_until(0.25 + 0.010)
    assert ex.locked and ex.state == RUN and ex.position_mm == (10.0, 0.0, 0.0)
    assert not ex.submit(feed(0.0))
    ex.run_until(0.25 + 0.030)
    assert ex.idle and ex.submit(feed(0.0))


def test_motion_waits_for_a_cycle_start_without_auto_start() -> None:
    ex = GrblExecutor(PLOTTER, auto_start=False)
    assert ex.submit(feed(10.0, f=3000.0))
    ex.advance(0.5)
    assert ex.state == IDLE and ex.position_mm == (0.0, 0.0, 0.0)
    ex.cycle_start()  # the serial buffer ran dry
    assert ex.state == RUN
    ex.advance(0.1)
    assert 0.0 < ex.position_mm[0] < 10.0
    assert ex.reported_rate_mm_per_min == pytest.approx(3000.0)  # cruising at F3000
    ex.run_until_idle()
    assert ex.position_mm == (10.0, 0.0, 0.0) and ex.reported_rate_mm_per_min == 0.0


# -- limits ---------------------------------------------------------------------------------------


def test_speed_and_acceleration_stay_within_limits_on_a_diagonal() -> None:
    ex = stream([MotionBlock((60.0, 0.0, 60.0), rapid=True)])
    t, vel = segment_kinematics(ex)
    # Z is limited to 3000 mm/min, so the rapid runs at 3000 mm/min per axis, √2 × along the path.
    assert np.abs(vel[:, 2]).max() * 60 == pytest.approx(3000.0, rel=0.01)
    assert np.abs(vel[:, 0]).max() * 60 <= 3000.0 * 1.01
    acc = np.diff(vel, axis=0) / np.diff(t)[:, None]
    assert np.abs(acc).max() <= A * 1.05  # per axis, estimated from 10 ms segment averages


def test_speed_never_exceeds_feed_and_tangential_acceleration_is_bounded() -> None:
    rng = np.random.default_rng(3)
    heading = np.cumsum(rng.normal(0.0, 0.4, 200))
    step = rng.uniform(0.3, 4.0, 200)
    pts = np.cumsum(np.column_stack([np.cos(heading) * step, np.sin(heading) * step]), axis=0)
    ex = stream([feed(x, y, f=4000.0) for x, y in pts])
    # Differences over 20 ms: the trace's knots sit on whole steps (Bresenham), a step off the
    # ideal line, which over a single short segment would look like a speed error.
    trace = ex.recorder.trace()[::20]  # type: ignore[union-attr]
    t, p = trace[:, 0], trace[:, 1:]
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(t)
    assert speed.max() * 60 <= 4000.0 * 1.02
    # Tangential acceleration: at most the block's limit, a/|u_i| over the axes (≤ √2·a in XY).
    acc = np.diff(speed) / np.diff(t)[1:]
    assert np.abs(acc).max() <= math.sqrt(2.0) * A * 1.05
    assert ex.position_mm == pytest.approx((*pts[-1], 0.0), abs=1 / 80)


# -- junctions and look-ahead ---------------------------------------------------------------------


def test_right_angle_junction_speed_follows_junction_deviation() -> None:
    ex = GrblExecutor(PLOTTER, auto_start=False)
    assert ex.submit(feed(50.0, f=6000.0))
    assert ex.submit(feed(50.0, 50.0, f=6000.0))
    # θ = 90°: v² = a_j·δ·sin(θ/2)/(1 − sin(θ/2)), a_j = √2·a along the junction's bisector.
    half = math.sin(math.pi / 4)
    v_junction = math.sqrt(math.sqrt(2.0) * A * 0.01 * half / (1.0 - half))
    assert math.sqrt(ex.planner.blocks[1].max_junction_speed_sqr) == pytest.approx(v_junction)
    ex.cycle_start()
    ex.run_until_idle()
    t, p = ex.recorder.knots()  # type: ignore[union-attr]
    corner = int(np.nonzero((p[:, 0] == 50.0) & (p[:, 1] == 0.0))[0][0])
    # The segments either side of the corner average between v_j and v_j + a·dt.
    for k in (corner - 1, corner):
        speed = np.linalg.norm(p[k + 1] - p[k]) / (t[k + 1] - t[k])
        assert v_junction <= speed <= v_junction + A * DT_SEGMENT
    assert ex.position_mm == (50.0, 50.0, 0.0)


def test_collinear_blocks_run_through_their_junctions_at_full_speed() -> None:
    one = stream([feed(100.0, f=3000.0)])
    many = stream([feed(float(k), f=3000.0) for k in range(1, 101)])
    assert many.now == pytest.approx(one.now, rel=1e-4)
    _, v = segment_kinematics(many)
    assert np.median(np.abs(v[:, 0])) == pytest.approx(50.0, rel=1e-6)


def test_dense_short_segments_are_capped_by_the_look_ahead() -> None:
    seg = 0.1
    ex = stream([feed(seg * k, f=6000.0) for k in range(1, 1001)])
    _, v = segment_kinematics(ex)
    cap = math.sqrt(2.0 * A * PLANNER_CAPACITY * seg)  # 54.8 mm/s, far below F6000
    cruise = np.abs(v[:, 0])
    assert np.median(cruise) == pytest.approx(cap, rel=0.05)
    assert cruise.max() <= cap * 1.05
    assert 100.0 / cap < ex.now < 1.1 * 100.0 / cap


def test_starved_planner_stops_at_every_block() -> None:
    """Blocks arriving slower than they execute: each is planned to end at rest."""
    ex = GrblExecutor(PLOTTER)
    for k in range(1, 21):
        ex.run_until(0.1 * k)  # one line every 100 ms, e.g. send-and-wait over a slow link
        assert ex.idle  # the previous block has run from rest to rest
        assert ex.submit(feed(0.5 * k, f=6000.0))
    ex.run_until_idle()
    # The last block alone: the triangle time of 0.5 mm, never near F6000.
    assert ex.now - 2.0 == pytest.approx(2.0 * math.sqrt(0.5 / A), rel=1e-3)
    _, v = segment_kinematics(ex)
    assert np.abs(v[:, 0]).max() <= math.sqrt(0.5 * A) + 1e-9  # peak of a 0.5 mm triangle


def test_send_and_wait_with_latency_is_slower_than_streaming() -> None:
    lines = [feed(0.5 * k, f=6000.0) for k in range(1, 201)]
    streamed = stream(lines)
    ex = GrblExecutor(PLOTTER)
    for block in lines:
        ex.run_until(ex.now + 0.010)  # 10 ms per round trip
        ex.run_until(math.inf, until=lambda block=block: ex.submit(block))
        assert ex.queued_blocks <= 5  # the planner never gets to look far ahead
    ex.run_until_idle()
    assert ex.now > 1.5 * streamed.now
    assert ex.position_mm == (100.0, 0.0, 0.0)


# -- inverse time ---------------------------------------------------------------------------------


def test_inverse_time_block_lasts_one_over_f_minutes() -> None:
    ex = stream([MotionBlock((100.0, 0.0, 0.0), inverse_time_per_min=1.0)])  # 100 mm/min
    v = 100.0 / 60.0
    assert ex.now == pytest.approx(60.0 + v / A, rel=1e-5)


def test_inverse_time_stream_runs_each_block_in_its_time() -> None:
    # 1 mm every 20 ms (F3000 = 1/3000 min): 50 mm/s, cruising between accel and decel.
    ex = stream(
        [MotionBlock((float(k), 0.0, 0.0), inverse_time_per_min=3000.0) for k in range(1, 51)]
    )
    t, p = ex.recorder.knots()  # type: ignore[union-attr]
    t20, t30 = np.interp([20.0, 30.0], p[:, 0], t)
    assert t30 - t20 == pytest.approx(10 * 0.020, rel=1e-3)
    assert ex.now == pytest.approx(50 * 0.020 + 0.050 / 1.0, rel=1e-3)


def test_inverse_time_is_capped_by_the_maximum_rate() -> None:
    ex = stream([MotionBlock((50.0, 0.0, 0.0), inverse_time_per_min=6000.0)])  # asks 5000 mm/s
    assert ex.now == pytest.approx(50.0 / 100.0 + 100.0 / A, rel=1e-4)


# -- feed hold, resume, soft reset, dwell ---------------------------------------------------------


def test_feed_hold_decelerates_and_resume_reaches_the_same_end_point() -> None:
    ex = GrblExecutor(PLOTTER)
    assert ex.submit(feed(100.0, f=3000.0))
    ex.run_until(0.5)
    at_hold = ex.position_mm[0]
    ex.feed_hold()
    assert ex.state == HOLD and not ex.hold_complete
    assert not ex.resume()  # ignored while still decelerating
    ex.run_until(1.0)
    assert ex.hold_complete and ex.speed_mm_per_s == 0.0
    stopped = ex.position_mm[0]
    v = 50.0
    # v²/2a of braking, after at most the 5 segments already prepared (≤ 50 ms at v).
    assert v * v / (2 * A) - 1e-9 <= stopped - at_hold <= v * v / (2 * A) + v * 0.05 + 1 / 80
    ex.run_until(2.0)
    assert ex.position_mm[0] == stopped and ex.free_blocks == PLANNER_CAPACITY - 1
    assert ex.resume()
    ex.run_until_idle()
    assert ex.position_mm == (100.0, 0.0, 0.0)
    # Braking never exceeded the acceleration limit.
    t, vel = segment_kinematics(ex)
    acc = np.diff(vel[:, 0]) / np.diff(t)
    assert np.abs(acc).max() <= A * 1.05
    # Time: the move without hold, plus the standstill (stop at 0.55…0.60 s, resume at 2 s),
    # plus v/a for the extra stop and start.
    assert 100.0 / v + v / A + 1.40 + v / A - 1e-3 <= ex.now <= 100.0 / v + v / A + 1.45 + v / A


def test_feed_hold_while_idle_keeps_new_blocks_waiting() -> None:
    ex = GrblExecutor(PLOTTER)
    ex.feed_hold()
    assert ex.state == HOLD and ex.hold_complete
    assert ex.submit(feed(10.0))
    ex.run_until(1.0)
    assert ex.position_mm == (0.0, 0.0, 0.0) and ex.queued_blocks == 1
    assert ex.resume()
    ex.run_until_idle()
    assert ex.position_mm == (10.0, 0.0, 0.0)


def test_soft_reset_in_motion_stops_at_once_and_flushes() -> None:
    ex = GrblExecutor(PLOTTER)
    for k in range(1, 11):
        assert ex.submit(feed(10.0 * k, f=3000.0))
    ex.run_until(0.7)
    assert ex.state == RUN
    where = ex.position_mm
    assert ex.soft_reset() is True  # motion was in progress: Grbl raises ALARM:3
    assert ex.state == IDLE and ex.idle
    assert ex.free_blocks == PLANNER_CAPACITY and ex.queued_blocks == 0
    ex.advance(1.0)
    assert ex.position_mm == where and ex.speed_mm_per_s == 0.0
    # The planner restarts from where the machine stopped.
    assert ex.submit(feed(0.0, f=3000.0))
    ex.run_until_idle()
    assert ex.position_mm == (0.0, 0.0, 0.0)
    assert ex.soft_reset() is False  # idle: no alarm


def test_dwell_waits_for_motion_then_for_its_time() -> None:
    ex = GrblExecutor(PLOTTER)
    assert ex.submit(feed(10.0, f=3000.0))
    pause = Dwell(0.5)
    assert not ex.submit(pause)
    assert not ex.submit(feed(20.0))  # the parser is blocked on the dwell
    ex.run_until(math.inf, until=lambda: ex.submit(pause))
    assert ex.now == pytest.approx(10.0 / 50.0 + 50.0 / A + 0.5, rel=1e-4)
    assert ex.submit(feed(20.0))


# -- buffers and recorder -------------------------------------------------------------------------


def test_planner_takes_at_most_fifteen_blocks() -> None:
    ex = GrblExecutor(PLOTTER, auto_start=False)
    accepted = 0
    while ex.submit(feed(float(accepted + 1))):
        accepted += 1
    assert accepted == PLANNER_CAPACITY == 15
    assert ex.state == RUN  # a full planner starts the cycle (and the first block's prep)
    # Slots free up as blocks are prepared, never beyond 15 queued.
    for k in range(accepted + 1, 60):
        ex.run_until(math.inf, until=lambda k=k: ex.submit(feed(float(k))))
        assert ex.queued_blocks <= PLANNER_CAPACITY
    ex.run_until_idle()
    assert ex.position_mm == (59.0, 0.0, 0.0)


def test_recorder_samples_every_millisecond() -> None:
    ex = stream([feed(10.0), feed(10.0, 10.0)])
    trace = ex.recorder.trace()  # type: ignore[union-attr]
    assert trace.shape[1] == 4
    assert np.all(np.diff(trace[:, 0]) <= 0.001 + 1e-12)
    assert trace[0, 0] == 0.0 and ex.now - trace[-1, 0] < 0.001
    assert trace[-1, 1:] == pytest.approx([10.0, 10.0, 0.0])
    with pytest.raises(ValueError, match="dt"):
        ex.recorder.trace(0.002)  # type: ignore[union-attr]


def test_positions_are_rounded_to_steps() -> None:
    ex = stream([feed(1.0 / 3.0, 0.00624), feed(0.00624)])  # 26.67 → 27 steps, 0.5 → 0 steps
    assert ex.position_steps == (0, 0, 0)
    ex = stream([feed(1.0 / 3.0, 0.00626)])
    assert ex.position_steps == (27, 1, 0)


@settings(max_examples=25, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(-20, 20),
            st.floats(-20, 20),
            st.floats(-2, 2),
            st.sampled_from(["feed", "inverse", "rapid"]),
            st.floats(50, 8000),
            st.floats(0, 0.05),
        ),
        min_size=1,
        max_size=25,
    )
)
def test_any_stream_ends_on_its_last_target_within_the_limits(moves: list) -> None:
    ex = GrblExecutor(PLOTTER)
    for x, y, z, kind, rate, pause in moves:
        if kind == "rapid":
            block = MotionBlock((x, y, z), rapid=True)
        elif kind == "inverse":
            block = MotionBlock((x, y, z), inverse_time_per_min=rate / 20.0)
        else:
            block = MotionBlock((x, y, z), feed_mm_per_min=rate)
        ex.run_until(ex.now + pause)
        ex.run_until(math.inf, until=lambda block=block: ex.submit(block))
        assert ex.queued_blocks <= PLANNER_CAPACITY
    ex.run_until_idle()
    expected = tuple(math.floor(abs(v * 80) + 0.5) * (1 if v >= 0 else -1) for v in moves[-1][:3])
    assert ex.position_steps == expected
    # Axis speeds within their maxima (segments of at least 5 ms: shorter ones are a few steps,
    # whose Bresenham bunching says little about speed).
    t, p = ex.recorder.knots()  # type: ignore[union-attr]
    dt = np.diff(t)
    long = dt >= 0.005
    if long.any():
        vel = np.abs(np.diff(p, axis=0)[long]) / dt[long, None] * 60
        assert np.all(vel.max(axis=0) <= np.array([6000.0, 6000.0, 3000.0]) * 1.03)


_OPS = st.one_of(
    st.tuples(st.just("block"), st.floats(-30, 30), st.floats(-30, 30), st.floats(10, 9000)),
    st.tuples(st.just("dwell"), st.floats(0, 0.05)),
    st.tuples(st.just("advance"), st.floats(0, 0.2)),
    st.tuples(st.sampled_from(["hold", "resume", "reset", "start"])),
)


@settings(max_examples=40, deadline=None)
@given(st.booleans(), st.lists(_OPS, max_size=40))
def test_any_mix_of_commands_settles_idle_on_the_last_target(auto_start: bool, ops: list) -> None:
    """Holds, resumes, resets, dwells and blocks in any order: never stuck, never > 15 queued."""
    ex = GrblExecutor(PLOTTER, auto_start=auto_start)
    pending: MotionBlock | Dwell | None = None
    last: MotionBlock | None = None
    work = 0.0  # an upper bound of the accepted items' nominal durations, seconds

    def offer(item: MotionBlock | Dwell) -> None:
        nonlocal pending, last, work
        if ex.submit(item):
            pending = None
            if isinstance(item, MotionBlock):
                # 85 mm is the longest move in the ±30 mm square; feeds are mm/min.
                work += 85.0 / (item.feed_mm_per_min or 6000.0) * 60.0
                last = item
            else:
                work += item.seconds
        else:
            pending = item  # the parser stays on this line

    for op in ops:
        if op[0] == "block":
            offer(pending or feed(op[1], op[2], f=op[3]))
        elif op[0] == "dwell":
            offer(pending or Dwell(op[1]))
        elif op[0] == "advance":
            ex.advance(op[1])
        elif op[0] == "hold":
            ex.feed_hold()
        elif op[0] == "resume":
            ex.resume()
        elif op[0] == "reset":
            ex.soft_reset()
            pending, last = None, None
        else:
            ex.cycle_start()
        assert ex.queued_blocks <= PLANNER_CAPACITY
    for _ in range(200):
        if ex.state == HOLD:
            ex.advance(0.5)
            ex.resume()
        if pending is not None:
            offer(pending)
        ex.cycle_start()
        ex.advance(max(0.5, work / 100.0))  # slow feeds (10 mm/min) take minutes
        if ex.idle and pending is None:
            break
    assert ex.idle and pending is None
    if last is not None:
        spm = PLOTTER.steps_per_mm[0]
        assert ex.position_mm == pytest.approx(last.target_mm, abs=0.5 / spm + 1e-12)


# -- settings and inputs --------------------------------------------------------------------------


def test_settings_from_dollar_pairs() -> None:
    config = GrblSettings.from_dollar_settings(
        {
            "$100": 80,
            101: 80,
            102: 80,
            110: 6000,
            111: 6000,
            112: 3000,
            120: 1000,
            121: 1000,
            122: 1000,
            11: 0.01,
            1: 255,
            10: 3,
        }
    )
    assert config.steps_per_mm == (80.0, 80.0, 80.0)
    assert config.max_rate_mm_per_min == (6000.0, 6000.0, 3000.0)
    assert config.idle_lock_delay_s == 0.0  # 255 keeps the motors enabled, no delay


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"target_mm": (0, 0, 0)}, "exactly one"),
        ({"target_mm": (0, 0, 0), "feed_mm_per_min": 10, "inverse_time_per_min": 1}, "exactly one"),
        ({"target_mm": (0, 0, 0), "feed_mm_per_min": 0}, "feed_mm_per_min"),
        ({"target_mm": (0, 0, math.nan), "feed_mm_per_min": 1}, "target_mm"),
        ({"target_mm": (0, 0, 0), "rapid": True, "feed_mm_per_min": 1}, "rapid"),
    ],
)
def test_motion_block_rejects_bad_values(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        MotionBlock(**kwargs)


# -- the real firmware's timings ------------------------------------------------------------------


def replay_send_and_wait(blocks: list[MotionBlock | None], round_trip: float) -> list[float]:
    """Send-and-wait: each line is processed `round_trip` after the previous ok; ok times."""
    ex = GrblExecutor(dataclasses.replace(PLOTTER, stepper_idle_lock_ms=25))
    oks = []
    for block in blocks:
        ex.run_until((oks[-1] if oks else 0.0) + round_trip)
        if block is not None:
            ex.run_until(math.inf, until=lambda block=block: ex.submit(block))
        oks.append(ex.now)
    return oks


def circle(n: int) -> list[MotionBlock | None]:
    """`G21 G90 G94`, `G1 X20 Y0 F6000`, then n chords of the r = 20 mm circle, 3 decimals."""
    chords = [
        feed(
            round(20 * math.cos(2 * math.pi * k / n), 3),
            round(20 * math.sin(2 * math.pi * k / n), 3),
            f=6000.0,
        )
        for k in range(1, n + 1)
    ]
    return [None, feed(20.0, f=6000.0), *chords]


@pytest.mark.parametrize(
    ("chords", "real_seconds"),
    [
        # 402 lines (400 chords of 0.314 mm): all acknowledged after 1.559 s on Grbl 1.1h.
        (400, 1.559),
        # 1002 lines (1000 chords of 0.126 mm): 2.271 s; the look-ahead caps them near 3700 mm/min.
        (1000, 2.271),
    ],
)
def test_dense_circle_send_and_wait_matches_the_real_firmware(
    chords: int, real_seconds: float
) -> None:
    # The reference host and firmware took about 1.07 ms per line and round trip.
    oks = replay_send_and_wait(circle(chords), 0.00107)
    assert oks[-1] == pytest.approx(real_seconds, rel=0.05)


def test_square_at_default_settings_matches_the_real_firmware() -> None:
    # Grbl defaults (250 steps/mm, 500 mm/min, 10 mm/s²): G1 X10 F600, X10 Y10, X0 Y10, G0 X0 Y0.
    # Real firmware: idle at the 0.2 s status poll 7.827 s after the first line (last Run poll
    # at 7.613 s).
    ex = GrblExecutor()
    for block in (feed(10.0, f=600.0), feed(10.0, 10.0, f=600.0), feed(0.0, 10.0, f=600.0)):
        assert ex.submit(block)
    assert ex.submit(MotionBlock((0.0, 0.0, 0.0), rapid=True))
    ex.run_until_idle()
    assert ex.now == pytest.approx(7.827, rel=0.05)
    assert 7.613 < ex.now + 0.003 <= 7.827


def test_feed_hold_stops_where_the_real_firmware_stopped() -> None:
    # Defaults, G1 X30 F300 queued at 0.030 s, '!' at 1.530 s: the real firmware came to rest
    # at X7.748 and, resumed at 3.534 s, was at X8.948 half a second later.
    ex = GrblExecutor()
    assert ex.submit(feed(30.0, f=300.0))
    ex.run_until(1.530 - 0.030)
    ex.feed_hold()
    ex.run_until(3.534 - 0.030)
    assert ex.position_mm[0] == pytest.approx(7.748, abs=0.02)
    assert ex.resume()
    ex.run_until(4.034 - 0.030)
    assert ex.position_mm[0] == pytest.approx(8.948, abs=0.02)


def test_a_block_queued_during_a_hold_from_idle_waits_for_the_resume() -> None:
    """A pause while idle (between pen moves) must not swallow the next line's motion."""
    ex = GrblExecutor(PLOTTER, auto_start=False)
    ex.feed_hold()
    assert ex.state == HOLD and ex.hold_complete
    assert ex.submit(feed(0.0, 0.5, f=830.0)) and ex.queued_blocks == 1
    ex.advance(1.0)
    assert ex.position_mm == (0.0, 0.0, 0.0)  # held: nothing moves
    assert ex.resume()
    ex.advance(2.0)
    assert ex.idle and ex.position_mm[:2] == pytest.approx((0.0, 0.5), abs=1 / 160)
