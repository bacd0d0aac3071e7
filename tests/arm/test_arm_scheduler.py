"""Absolute-deadline scheduling on a fake clock: no drift, lateness measured, resync on stalls."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tagbot.arm.driver import Scheduler
from tagbot.clock import MonotonicClock


class FakeClock:
    """Time moves only when the scheduler sleeps or a tick 'works' (``work``)."""

    def __init__(self, t: float = 1000.0) -> None:
        self.t = t
        self.sleeps: list[float] = []

    def now(self) -> float:
        return self.t

    def sleep_until(self, t: float) -> None:
        self.sleeps.append(t)
        self.t = max(self.t, t)

    def work(self, seconds: float) -> None:
        self.t += seconds


def test_no_drift_over_100000_ticks_with_jittery_work() -> None:
    clock = FakeClock()
    period = 0.002
    scheduler = Scheduler(clock, period)
    t0 = scheduler.start()
    rng = np.random.default_rng(7)
    work = rng.uniform(0.0, 0.9 * period, 100_000)
    for k in range(100_000):
        late = scheduler.wait(k)
        assert late == 0.0
        clock.work(work[k])
    # Every deadline is t0 + k·period exactly as computed, never an accumulated sum.
    deadlines = np.array(clock.sleeps)
    assert np.array_equal(deadlines, t0 + np.arange(100_000) * period)
    assert scheduler.ticks == 100_000 and scheduler.late_ticks == 0 and scheduler.resyncs == 0
    assert scheduler.deadline(100_000) - t0 == pytest.approx(200.0, abs=1e-9)


def test_lateness_is_measured_and_late_ticks_catch_up() -> None:
    clock = FakeClock(0.0)
    scheduler = Scheduler(clock, 0.01)  # late after 2.5 ms, resync after 10 ms
    scheduler.start(0.0)
    overrun = {3: 0.014, 10: 0.0141, 20: 0.0259}
    for k in range(30):
        scheduler.wait(k)
        scheduler.sent(clock.now())  # the write returns at once
        clock.work(overrun.get(k, 0.001))
    lateness = np.array(scheduler.lateness)
    assert lateness[4] == pytest.approx(0.004)  # tick 3 ended at 0.044: tick 4 is 4 ms late
    assert lateness[5] == 0.0  # caught up on its own deadline
    assert lateness[11] == pytest.approx(0.0041)
    assert lateness[21] == pytest.approx(0.0159)  # > one period: resync
    assert scheduler.late_ticks == 3 and scheduler.resyncs == 1
    assert scheduler.max_lateness == pytest.approx(0.0159)
    # The hole on the wire before tick 21 (25.9 ms) is a host stall: 15.9 ms beyond a period.
    assert len(scheduler.stalls) == 1
    assert scheduler.stalls[0] == pytest.approx((0.21, 0.0159))
    # After the resync the deadlines moved by the lateness: tick 22 is due 10 ms after tick 21's
    # waking, and nothing is late any more.
    assert scheduler.deadline(22) == pytest.approx(0.22 + 0.0159)
    assert np.all(lateness[22:] == 0.0)


def test_resync_threshold_is_configurable() -> None:
    clock = FakeClock(0.0)
    scheduler = Scheduler(clock, 0.002, late_after=0.001, resync_after=0.005)
    scheduler.start(0.0)
    scheduler.wait(0)
    scheduler.sent(clock.now())
    clock.work(0.006)  # ticks 1 and 2 wake 4 and 2 ms late, then catch up: tick 3 on time
    for k in range(1, 5):
        scheduler.wait(k)
        scheduler.sent(clock.now())
    assert scheduler.late_ticks == 2 and scheduler.resyncs == 0 and not scheduler.stalls
    assert scheduler.lateness[3] == 0.0
    clock.work(0.0075)
    scheduler.wait(5)
    assert scheduler.resyncs == 1


def test_lateness_is_measured_where_the_goals_leave() -> None:
    """A stall between waking and the write (a blocked port, a collection) is lateness."""
    clock = FakeClock(0.0)
    scheduler = Scheduler(clock, 0.01)
    scheduler.start(0.0)
    for k in range(3):
        woke = scheduler.wait(k)  # ticks 0 and 1 wake on time...
        assert woke == (0.0 if k < 2 else pytest.approx(0.02))
        clock.work(0.03 if k == 1 else 0.0)  # ...then the write took 30 ms for tick 1
        scheduler.sent(clock.now())
    assert scheduler.lateness[:2] == [0.0, pytest.approx(0.03)]
    assert scheduler.max_lateness == pytest.approx(0.03) and scheduler.late_ticks >= 1
    assert scheduler.stalls == [pytest.approx((0.01, 0.03))]  # tick 1 left 40 ms after tick 0
    np.testing.assert_allclose(scheduler.sends, [0.0, 0.04, 0.04 + 0.0], atol=1e-12)


def test_a_pause_is_no_stall_and_its_catch_up_is_not_late() -> None:
    clock = FakeClock(0.0)
    scheduler = Scheduler(clock, 0.01)
    scheduler.start(0.0)
    for k in range(3):
        scheduler.wait(k)
        scheduler.sent(clock.now())
    clock.work(5.0)  # paused before tick 3; the ticks due before 5.03 go out at once
    scheduler.reanchor(3, 5.01, held=0.03, floor=5.03)
    for k in range(3, 8):
        scheduler.wait(k)
        scheduler.sent(clock.now())
    assert scheduler.sends[3:] == pytest.approx([5.03, 5.03, 5.03, 5.04, 5.05])
    assert scheduler.late_ticks == 0 and scheduler.resyncs == 0 and scheduler.stalls == []


def test_bad_period_is_refused() -> None:
    with pytest.raises(ValueError, match="period"):
        Scheduler(FakeClock(), 0.0)


def test_monotonic_clock_never_wakes_early() -> None:
    clock = MonotonicClock()
    start = clock.now()
    late = []
    for k in range(1, 101):
        deadline = start + k * 0.001
        clock.sleep_until(deadline)
        late.append(time.perf_counter() - deadline)
    assert min(late) >= 0.0
    assert np.median(late) < 0.002  # generous: shared CI machines


def test_program_time_leaves_out_resync_gaps_and_pauses() -> None:
    clock = FakeClock(0.0)
    scheduler = Scheduler(clock, 0.01)
    scheduler.start(1.0)
    for k in range(5):
        scheduler.wait(k)
    clock.work(0.05)  # tick 5 wakes 40 ms late: a resync
    scheduler.wait(5)
    assert scheduler.resyncs == 1 and scheduler.resync_delay == pytest.approx(0.04)
    # A pause before tick 8, from clock 1.13 until 3.0.
    scheduler.reanchor(8, 3.0, held=1.13)
    assert scheduler.deadline(8) == 3.0 and scheduler.deadline(9) == pytest.approx(3.01)
    clock_times = np.array([0.9, 1.02, 1.045, 1.08, 1.095, 1.12, 1.14, 2.0, 3.0, 3.015])
    t = scheduler.program_time(clock_times, lag=0.005)
    expected = [-0.105, 0.015, 0.04, np.nan, 0.05, 0.075, np.nan, np.nan, np.nan, 0.09]
    assert np.allclose(t, expected, equal_nan=True)


def test_real_time_scheduling_only_on_the_wall_clock_and_put_back() -> None:
    import os

    from tagbot.clock import FIFO_PRIORITY, RealTime

    before = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
    simulated = RealTime(FakeClock())
    assert simulated.fifo is False and os.sched_getscheduler(0) == before[0]
    simulated.end()
    wall = RealTime(MonotonicClock())
    try:
        if wall.fifo:  # permitted here (root, CAP_SYS_NICE or an rtprio limit)
            assert os.sched_getscheduler(0) == os.SCHED_FIFO
            assert os.sched_getparam(0).sched_priority == FIFO_PRIORITY
        else:
            assert os.sched_getscheduler(0) == before[0]
    finally:
        wall.end()
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == before
