"""Which request a read-back reply answers, whatever the line does to the replies.

Status packets carry no sequence number: the driver matches each reply to its request by the
servo's own clock (Realtime Tick, read with the position). Replies held back by the adapter, or
read-backs lost whole, must leave every other reply stamped with its own request's instant; a
hold longer than ``bus.silence_timeout`` (0.25 s), counted from the first request a servo has not
answered, is a fault; the servos' clocks drift, jump a little and wrap. Simulated time.
"""

from __future__ import annotations

import re

import pytest

from tagbot.arm import load_profile, prepare
from tagbot.arm.driver import ArmDriver
from tagbot.arm.run import simulated_chain
from tagbot.errors import DeviceFault, DeviceTimeout

from .conftest import two_plan_tag


def _faulty_once(record, tmp_path, *, hold=0.05, drop=0.0, overrides=(), setup=None, fault=None):
    """The two-plan tag, replies 50 ms late; after tick 300, for 10 ticks (the progress
    callback's step), replies are held ``hold`` s (those behind them wait: the adapter keeps
    them in order) or lost with probability ``drop``, or ``fault(chain)`` is done then instead.
    ``setup(chain)`` first, if given; the simulated time the stream started is then in
    ``chain.streamed``. Returns (job, run, that tick)."""
    profile = load_profile(None, overrides)
    sim = record(simulated_chain(profile))
    sim.chain.set_reply_faults(latency=0.05)
    if setup is not None:
        setup(sim.chain)
    phase: list[int] = []

    def progress(done: int, total: int) -> None:
        if not hasattr(sim.chain, "streamed"):
            sim.chain.streamed = sim.chain.now()
        if done > 300 and not phase:
            phase.append(done)
            if fault is not None:
                fault(sim.chain)
            else:
                sim.chain.set_reply_faults(latency=hold, drop=drop)
        elif len(phase) == 1 and done > phase[0]:
            phase.append(done)
            sim.chain.set_reply_faults(latency=0.05)

    job = prepare(two_plan_tag(), port=sim.url, overrides=tuple(overrides))
    return job, job.run(tmp_path, progress=progress), phase[0]


def _every_reply_matched(job, run) -> None:
    """The run completed with every read-back reply matched to its own request (the last few
    requests' replies may come after the stream ended) and each where the arm stood."""
    assert run.error is None, run.error
    d = run.details
    assert d["readback_replies"] == 3 * d["readbacks"] >= 3 * (len(job.program) - 5)
    assert d["readback_missed_replies"] == d["readback_stale_replies"] == 0
    assert d["joint_tracking_error"]["max"] < 0.5


def _held_once(record, tmp_path, hold: float):
    return _faulty_once(record, tmp_path, hold=hold)


@pytest.mark.parametrize("hold", [0.05, 0.2, 0.25])
def test_replies_held_back_are_kept_with_their_own_requests(record, tmp_path, hold) -> None:
    job, run, _ = _held_once(record, tmp_path, hold)
    _every_reply_matched(job, run)
    d = run.details
    assert d["readback_requests"] == len(job.program)
    # No reply is taken sooner than the adapter's 50 ms after the request it answers.
    assert d["reply_delay_p50_ms"] >= 50
    assert 1e3 * hold < d["reply_delay_max_ms"] < 1e3 * hold + 5
    # The held reply is one of more than a hundred: above the 99th percentile, not below it.
    assert d["readback_replies"] > 100
    assert 50 <= d["reply_delay_p99_ms"] < d["reply_delay_max_ms"]


def test_a_hold_past_the_silence_timeout_is_a_fault_not_a_shifted_trace(record, tmp_path):
    _, run, held = _held_once(record, tmp_path, 0.3)
    error = run.error
    assert isinstance(error, DeviceTimeout)
    assert "did not answer SYNC_READ of present positions for 0.25 s" in str(error)
    tick = int(error.where.split()[1])
    # 0.25 s (25 ticks) after the request whose reply was held: not later.
    assert held + 24 <= tick <= held + 26
    d = run.details
    assert d["reply_delay_p50_ms"] >= 50 and d["reply_delay_max_ms"] < 60
    assert d["readback_missed_replies"] == d["readback_stale_replies"] == 0
    assert d["joint_tracking_error"]["max"] < 0.5


def test_whole_read_backs_lost_do_not_shift_the_later_ones(record, tmp_path) -> None:
    """Ten read-backs lost whole (a noisy line can do this to the request): by order alone,
    every later reply would be taken for the request before its own."""
    job, run, _ = _faulty_once(record, tmp_path, drop=1.0, overrides=["bus.max_missed=20"])
    assert run.error is None, run.error
    d = run.details
    assert d["readback_missed_replies"] == 3 * 10
    assert d["readback_requests"] == len(job.program)
    assert d["readback_replies"] == 3 * d["readbacks"]
    assert d["readback_stale_replies"] == 0
    assert d["reply_delay_p50_ms"] >= 50 and d["reply_delay_max_ms"] < 55
    assert d["joint_tracking_error"]["max"] < 0.5


def test_more_lost_in_a_row_than_allowed_names_every_silent_servo(record, tmp_path) -> None:
    _, run, lost = _faulty_once(record, tmp_path, drop=1.0)
    error = run.error
    assert isinstance(error, DeviceTimeout)
    assert str(error) == (
        f"{error.where}: servo 1 (shoulder), servo 2 (elbow) and servo 3 (pen) did not answer"
        " SYNC_READ of present positions 6 times in a row (more than bus.max_missed = 5)"
    )
    # The read-backs lost (10 ticks of them) are known lost when the next one's replies come,
    # 50 ms (5 ticks) after it was sent: then the run stops, before anything more is sent.
    tick = int(error.where.split()[1])
    assert lost + 15 <= tick <= lost + 17
    assert run.sent == tick


def test_each_servos_clock_is_followed_as_it_drifts(record, tmp_path) -> None:
    """The servos' oscillators are not the host's: one clock 1 % fast, one 1 % slow drift 100 ms
    apart over the tag's 10 s, ten read-back intervals."""

    def drift(chain) -> None:
        chain.servo(2).clock_rate = 1.01
        chain.servo(3).clock_rate = 0.99

    job, run, _ = _faulty_once(record, tmp_path, setup=drift)
    _every_reply_matched(job, run)


def test_a_servos_clock_wrapping_round_mid_stream_changes_nothing(record, tmp_path) -> None:
    """Realtime Tick counts ms modulo 32768: each servo's wraps round at another moment."""
    wraps, chains = [], []

    def near_wrap(chain) -> None:
        chains.append(chain)
        for id, later in ((1, 4.0), (2, 7.0), (3, 10.0)):
            chain.servo(id).booted_at = chain.now() + later - 32.768
            wraps.append(chain.now() + later)

    job, run, _ = _faulty_once(record, tmp_path, setup=near_wrap)
    _every_reply_matched(job, run)
    chain = chains[0]
    assert sum(chain.streamed < w < chain.now() - 0.1 for w in wraps) >= 2


def test_a_servo_whose_clock_restarts_is_named_with_its_unmatched_replies(record, tmp_path):
    def restart(chain) -> None:
        chain.servo(2).booted_at = chain.now()  # its Realtime Tick from 0 again

    _, run, at = _faulty_once(record, tmp_path, fault=restart)
    error = run.error
    assert isinstance(error, DeviceTimeout)
    message = str(error)
    assert message.startswith(
        f"{error.where}: servo 2 (elbow) did not answer SYNC_READ of present positions for 0.25 s"
    )
    n = int(message.split("servo 2 (elbow) replied ")[1].split()[0])
    assert message.endswith(
        f"; servo 2 (elbow) replied {n} times meanwhile, its Realtime Tick matching no request"
        " (its clock restarted?)"
    )
    assert 20 <= n <= 26  # one a tick, for the quarter second
    assert at + 24 <= int(error.where.split()[1]) <= at + 26


def test_a_small_jump_of_a_servos_clock_is_within_the_match_and_followed(record, tmp_path):
    """A tick 3 ms off (less than half the 10 ms between requests) still names its request."""

    def jump(chain) -> None:
        chain.servo(2).booted_at -= 0.003

    job, run, _ = _faulty_once(record, tmp_path, fault=jump)
    _every_reply_matched(job, run)


@pytest.mark.parametrize(
    ("late", "span", "miss"),
    [
        (0.0, 0.0, 0.0),
        (0.4, 0.5, 0.0),  # within the request's writing
        (0.5, 0.5, 0.0),
        (1.5, 0.5, 1.0),  # after it
        (-2.0, 0.5, -2.0),  # before it began
        (32767.0, 0.0, -1.0),  # the tick wrapped round below the request's
        (-32767.5, 0.5, 0.0),  # the request's ms wrapped round below the tick
        (20000.0, 0.0, -12768.0),  # nearer the tick after a wrap than before it
        (-20000.0, 0.0, 12768.0),
    ],
)
def test_a_ticks_miss_is_its_distance_outside_the_requests_writing(late, span, miss) -> None:
    from tagbot.arm.driver import _miss

    assert _miss(late, span) == pytest.approx(miss)


def test_a_servo_silent_when_its_clock_is_read_stops_the_run_before_the_first_tick(
    record, tmp_path, monkeypatch
):
    profile = load_profile()
    sim = record(simulated_chain(profile))
    read = ArmDriver._clock_offsets

    def silenced_then_read(driver, where):
        sim.chain.silence(2)
        return read(driver, where)

    monkeypatch.setattr(ArmDriver, "_clock_offsets", silenced_then_read)
    run = prepare(two_plan_tag(), port=sim.url).run(tmp_path)
    error = run.error
    assert isinstance(error, DeviceTimeout)
    assert str(error) == (
        "tick 0: servo 2 (elbow) did not answer READ of address 120 (no status packet before"
        " the SDK's timeout)"
    )
    assert run.sent == 0
    assert sim.chain.servo(3).get("goal_position") == profile["pen.up"]


def test_a_read_back_answered_with_an_error_and_no_data_is_a_fault_naming_it(record, tmp_path):
    """A status carrying an error byte and no data (the servo refused the read) has no clock to
    match by: it answers the oldest open request by order, and the run stops naming the error."""
    from firmware_protocols.dynamixel.packets import StatusPacket, encode_status

    def refused(chain) -> None:
        with chain.lock:  # on the simulator's bus, as if servo 2 had sent it
            chain._schedule(encode_status(StatusPacket(2, 7, b"")), chain.now())

    _, run, at = _faulty_once(record, tmp_path, fault=refused)
    error = run.error
    assert isinstance(error, DeviceFault)
    assert str(error).endswith(
        ": servo 2 (elbow) answered SYNC_READ of present positions with access error (7)"
    )
    assert at + 5 <= int(error.where.split()[1]) <= at + 7  # delivered 50 ms late, as all


def test_two_servos_whose_clocks_restart_are_each_named_with_their_unmatched_replies(
    record, tmp_path
):
    """Two clocks restarted at once: each servo's stray replies are said in turn, one clause
    each, nothing between them."""

    def restart(chain) -> None:
        for id in (1, 2):
            chain.servo(id).booted_at = chain.now()

    _, run, _ = _faulty_once(record, tmp_path, fault=restart)
    message = str(run.error)
    assert "servo 1 (shoulder) and servo 2 (elbow) did not answer SYNC_READ" in message
    stray = (
        r" replied \d+ times meanwhile, its Realtime Tick matching no request"
        r" \(its clock restarted\?\)"
    )
    timeout = r"\(bus\.silence_timeout: 0\.25 s\)"
    assert re.search(rf"{timeout}; servo 1 \(shoulder\){stray}; servo 2 \(elbow\){stray}$", message)
