"""The arm driver's words and clocks as a user meets them: which servos fell silent, the
SDK's packet timeout on the port's clock, a hardware error's remedy, and a serial arm's safe
stop whose lift cannot be written."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import dynamixel_sdk as sdk
import numpy as np
import pytest

import tagbot
from sim.dynamixel import SimulatedChain
from tagbot.arm import load_profile, prepare
from tagbot.arm.driver import ArmDriver, UrlPortHandler
from tagbot.arm.run import simulated_chain
from tagbot.arm.serial.machine import ArmLift, simulated_arm
from tagbot.arm.serial.machine import prepare as serial_prepare
from tagbot.arm.serial.profile import load_serial_profile
from tagbot.arm.serial.program import build_serial_program
from tagbot.control import RunControl
from tagbot.draw import draw
from tagbot.errors import ConnectionLost, DeviceError, DeviceTimeout, Interrupted
from tagbot.io.planfile import load_plan

from .conftest import GOAL_POSITION, two_plan_tag
from .serial.test_serial_machine import _faulted, _interrupt
from .serial.test_serial_stop import _stopped

LETTER_B = Path(tagbot.__file__).parent / "examples" / "letter-b.json"

PATIENT = ("bus.max_missed=100000",)
"""Misses in a row never count: a silent servo is found by its silence alone."""


@pytest.mark.parametrize(
    ("silent", "named"),
    [((2,), "servo 2 (elbow)"), ((1, 2), "servo 1 (shoulder) and servo 2 (elbow)")],
)
def test_the_servos_that_fell_silent_are_named_and_no_other(record, tmp_path, silent, named):
    profile = load_profile(overrides=PATIENT)
    sim = record(simulated_chain(profile))
    job = prepare(two_plan_tag(), port=sim.url, overrides=PATIENT)

    def progress(done: int, total: int) -> None:
        if done == 301:
            for id in silent:
                sim.chain.silence(id)

    error = job.run(tmp_path, progress=progress).error
    assert isinstance(error, DeviceTimeout)
    assert str(error).startswith(
        f"{error.where}: {named} did not answer SYNC_READ of present positions for 0.2"
    )


class _Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def now(self) -> float:
        return self.t

    def sleep_until(self, t: float) -> None:
        self.t = max(self.t, t)


def test_the_sdks_packet_timeout_runs_on_the_ports_clock():
    """The SDK's 34 ms (twice its 16 ms latency timer, and 2) pass on the simulated clock."""
    port = UrlPortHandler("dxlsim://unused")
    port.clock = _Clock()
    port.tx_time_per_byte = 0.0
    assert port.getCurrentTime() == 100_000.0
    port.setPacketTimeout(10)
    port.clock.t += 0.03398
    assert not port.isPacketTimeout()
    port.clock.t += 0.0001
    assert port.isPacketTimeout()


def test_a_hardware_error_says_how_to_clear_it(tmp_path):
    error, *_ = _faulted(
        load_plan(LETTER_B), tmp_path, lambda chain: chain.set_hardware_error(13, 4)
    )
    assert isinstance(error, DeviceError)
    assert str(error).endswith(
        "hardware error: overheating (Hardware Error Status 0x04); remove the cause, then reboot"
        " the servo (REBOOT or a power cycle) to clear it"
    )


def test_a_hardware_error_whose_status_cannot_be_read_says_so(tmp_path, monkeypatch):
    """A servo flags a hardware error mid-run and its Hardware Error Status read then fails:
    the message says the cause is unknown because that register could not be read."""

    def flag_and_break_the_read(chain) -> None:
        chain.set_hardware_error(13, 4)
        failed = (0, sdk.COMM_RX_TIMEOUT, 0)
        ph = type(sdk.PacketHandler(2.0))
        monkeypatch.setattr(ph, "read1ByteTxRx", lambda self, port, id, address: failed)

    error, *_ = _faulted(load_plan(LETTER_B), tmp_path, flag_and_break_the_read)
    assert isinstance(error, DeviceError)
    assert str(error).endswith(
        "hardware error: unknown (Hardware Error Status could not be read); remove the cause,"
        " then reboot the servo (REBOOT or a power cycle) to clear it"
    )


def test_a_lift_that_cannot_be_written_is_named_in_the_message_and_the_log(
    tmp_path, monkeypatch, caplog
):
    """Ctrl-C mid-run, and from then on the adapter takes no byte: the lift's goals are not
    written, and the message and the log say which packet failed."""

    def interrupt_and_break(chain) -> None:
        monkeypatch.setattr(UrlPortHandler, "writePort", lambda self, packet: 0)
        _interrupt(chain)

    with caplog.at_level(logging.ERROR):
        error, report, *_ = _faulted(load_plan(LETTER_B), tmp_path, interrupt_and_break)
    assert isinstance(error, Interrupted)
    assert report["details"]["lifted_by_arm_at_stop"] is False
    assert "the pen was not lifted by the arm (stop: could not write SYNC_WRITE of goal" in str(
        error
    )
    failed = "safe stop failed: stop: could not write SYNC_WRITE of goal positions to dxlsim"
    assert any(r.getMessage().startswith(failed) for r in caplog.records)


def test_connecting_waits_for_a_reply_as_long_as_bus_silence_timeout(record):
    """While connecting, the SDK's packet timeout allows ``bus.silence_timeout`` (not its own
    34 ms): a servo slow to wake is not taken for a missing one."""
    profile = load_profile(overrides=("bus.silence_timeout=0.4",))
    sim = record(simulated_chain(profile))
    with ArmDriver(sim.url, profile) as driver:
        driver.open()
        assert driver.port.reply_allowance_ms == pytest.approx(400.0, abs=1e-9)
        # A reply of 14 bytes is waited for as long as they take on the wire (10 bits a byte
        # at bus.baud) and that allowance.
        driver.port.setPacketTimeout(14)
        wire_ms = 14 * 10 * 1000.0 / profile["bus.baud"]
        assert driver.port.packet_timeout == pytest.approx(wire_ms + 400.0, abs=1e-9)


def test_a_second_safe_stop_sends_nothing(record, profile):
    sim = record(simulated_chain(profile))
    with ArmDriver(sim.url, profile) as driver:
        driver.connect()
        driver.safe_stop(error=False)
        written = len(sim.writes)
        driver.safe_stop(error=False)
        assert len(sim.writes) == written


@pytest.mark.parametrize("failing", ["read", "in_waiting"])
def test_a_port_failing_while_draining_names_the_port_and_the_drain(record, profile, failing):
    """The adapter fails on a read, or when asked how many bytes are waiting: the error names
    the drain, the port and the adapter's words."""
    sim = record(simulated_chain(profile))
    with ArmDriver(sim.url, profile) as driver:
        driver.connect()

        class Broken:
            @property
            def in_waiting(self) -> int:
                if failing == "in_waiting":
                    raise OSError("the adapter went away")
                return 5

            def read(self, n: int) -> bytes:
                raise OSError("the adapter went away")

        real, driver.port.ser = driver.port.ser, Broken()
        try:
            with pytest.raises(ConnectionLost) as caught:
                driver.drain()
        finally:
            driver.port.ser = real
    assert caught.value.where == "drain"
    assert str(caught.value) == f"drain: {sim.url}: drain: the adapter went away"


def test_a_missing_servo_and_a_failed_broadcast_ping_name_the_connect(record, profile, monkeypatch):
    sim = record(simulated_chain(profile))
    sim.chain.silence(2)

    def gone(self, port):
        raise OSError("the adapter went away")

    monkeypatch.setattr(type(sdk.PacketHandler(2.0)), "broadcastPing", gone)
    with ArmDriver(sim.url, profile) as driver, pytest.raises(ConnectionLost) as caught:
        driver.connect()
    assert str(caught.value) == f"connect: {sim.url}: broadcast ping: the adapter went away"


def test_a_gain_that_cannot_be_written_is_named_at_configure(tmp_path, monkeypatch):
    """The serial arm's position gains (2-byte RAM writes) are written at connect: a failed
    write names the stage, the value and the address."""

    def fails(self, port, id, address, value):
        return sdk.COMM_TX_FAIL, 0

    monkeypatch.setattr(type(sdk.PacketHandler(2.0)), "write2ByteTxRx", fails)
    job = serial_prepare(load_plan(LETTER_B), profile="openmanipulator-x")
    with pytest.raises(
        ConnectionLost, match=r"^configure: could not write WRITE of \d+ to address"
    ):
        draw(load_plan(LETTER_B), tmp_path / "gain", prepared=job, pictures=False)


def test_a_servo_whose_ping_replies_are_all_corrupt_is_named(record, profile):
    sim = record(simulated_chain(profile))
    sim.chain.corrupt_next(2, 10)  # more than the driver's tries
    with ArmDriver(sim.url, profile) as driver, pytest.raises(DeviceError) as caught:
        driver.connect()
    assert str(caught.value).startswith("connect: servo 2 (elbow): PING: ")


def test_a_port_that_fails_to_close_is_logged_not_raised(record, profile, caplog):
    sim = record(simulated_chain(profile))
    driver = ArmDriver(sim.url, profile)
    driver.open()
    real = driver.port.ser

    class Failing:
        def flush(self) -> None:
            raise OSError("the adapter went away")

    driver.port.ser = Failing()
    with caplog.at_level(logging.DEBUG, logger="tagbot.arm.driver"):
        driver.close()
    real.close()
    assert driver.port is None
    closing = f"closing {sim.url}: the adapter went away"
    assert any(r.getMessage() == closing for r in caplog.records)


def test_connecting_logs_the_profile_it_configured_and_names_unknown_ids(record, profile, caplog):
    sim = record(simulated_chain(profile))
    with ArmDriver(sim.url, profile) as driver:
        with caplog.at_level(logging.INFO, logger="tagbot.arm.driver"):
            driver.connect()
        assert driver.who(99) == "servo 99 (?)"  # an ID the profile does not name
    assert any(r.getMessage().startswith("configured: time-based profile ") for r in caplog.records)


def test_a_hardware_error_names_every_bit_set(tmp_path):
    error, *_ = _faulted(
        load_plan(LETTER_B), tmp_path, lambda chain: chain.set_hardware_error(13, 0x24)
    )
    assert "hardware error: overheating, overload (Hardware Error Status 0x24)" in str(error)


@pytest.mark.parametrize(("move_time", "goals"), [(0.001, 1), (0.01, 1), (0.035, 4)])
def test_lowering_the_pen_sends_one_goal_a_tick_for_pen_move_time(record, move_time, goals):
    """A resume lowers the pen in pen.move_time at the loop period: one goal a tick, at least
    one (a move quicker than a tick is one goal)."""
    profile = load_profile(overrides=(f"pen.move_time={move_time}",))
    sim = record(simulated_chain(profile))
    pen = profile["pen.id"]
    with ArmDriver(sim.url, profile) as driver:
        driver.connect()
        before = len(sim.values(pen, GOAL_POSITION))
        down = profile["pen.down"]
        driver.lower_pen(down)
        sent = sim.values(pen, GOAL_POSITION)[before:]
    assert len(sent) == goals and sent[-1] == down


class _PauseAtTick(RunControl):
    """Paused when the stream asks before tick ``tick`` (it asks once a tick), for ``looks``
    more looks (the pause asks each time round its loop)."""

    def __init__(self, tick: int, looks: int) -> None:
        super().__init__()
        self.asked, self.tick, self.looks = 0, tick, looks

    @property
    def paused(self) -> bool:
        self.asked += 1
        return self.tick < self.asked <= self.tick + 1 + self.looks


@pytest.mark.parametrize("looks", [5, 6, 7])
def test_no_goal_is_sent_while_a_read_backs_replies_may_be_on_the_bus(
    record, tmp_path, monkeypatch, looks
):
    """The bus is half duplex: after a SYNC_READ, goals (the stream's and a pause's pen lift)
    wait until the request and every servo's reply could have passed, at the bus's bit rate.
    At 57,600 baud a read-back takes 17.0 ms; a pause looks every 10 ms and reads back every
    25 ms, so whichever look ends it, the pen's lowering comes soon after a request."""
    overrides = ("bus.baud=57600", "motion.rate=40", "bus.readback_rate=40", "servo.profile_ms=40")
    profile = load_profile(overrides=overrides)
    sim = record(simulated_chain(profile))
    job = prepare(two_plan_tag(), port=sim.url, overrides=overrides)
    sent: list[tuple[float, int, int]] = []  # clock time, instruction, packet length
    write = UrlPortHandler.writePort

    def spy(port: UrlPortHandler, packet: list[int]) -> int:
        sent.append((port.getCurrentTime() / 1000.0, packet[7], len(packet)))
        return write(port, packet)

    monkeypatch.setattr(UrlPortHandler, "writePort", spy)
    pen_down = np.flatnonzero(job.program.goals[:, 2] == profile["pen.down"])
    tick = int(pen_down[0]) + 20
    run = job.run(tmp_path, control=_PauseAtTick(tick, looks))
    assert run.error is None and len(run.pauses) == 1
    byte = 10.0 / 57600
    free, reads, goals = -1.0, 0, 0
    for t, instruction, length in sent:  # in the order sent
        if instruction == 0x82:  # SYNC_READ: its bytes, one a servo, and 27 from each servo
            free, reads = t + (length + 27 * (length - 14)) * byte, reads + 1
        elif instruction in (0x03, 0x83):  # WRITE, SYNC_WRITE of goals
            assert t >= free - 1e-9
            goals += 1
    assert reads > 10 and goals > len(job.program.goals)


def test_noise_like_a_status_header_of_an_impossible_length_is_skipped(record, tmp_path):
    """A read-back reply is 27 bytes: bytes on the line that look like a status header but
    claim 65,535 are noise, skipped at once; the replies after them are read as usual (not held
    back until that many bytes came, the servos taken for silent)."""
    profile = load_profile()
    sim = record(simulated_chain(profile))
    job = prepare(two_plan_tag(), port=sim.url)

    def progress(done: int, total: int) -> None:
        if done == 301:  # a burst on the line, as if a device had sent it (the simulator's bus)
            with sim.chain.lock:
                sim.chain._schedule(b"\xff\xff\xfd\x00\x01\xff\xff", sim.chain.now())

    run = job.run(tmp_path, progress=progress)
    assert run.error is None
    assert run.details["corrupt_replies"] == 0
    assert run.details["readbacks"] >= 0.9 * len(job.program.goals)


def test_a_port_that_fails_in_a_write_names_the_write(record, profile, monkeypatch):
    """An adapter that fails while a servo's control item is written: the error names the
    port, the write (its address) and the adapter's own words."""
    sim = record(simulated_chain(profile))

    def fails(*args, **kwargs):
        raise OSError("the adapter went away")

    monkeypatch.setattr(type(sdk.PacketHandler(2.0)), "write1ByteTxRx", fails)
    with ArmDriver(sim.url, profile) as driver, pytest.raises(ConnectionLost) as caught:
        driver.connect()
    assert re.search(rf"{re.escape(sim.url)}: write \d+: the adapter went away$", str(caught.value))


def test_a_hardware_error_of_no_known_bit_says_none_reported(tmp_path):
    """Hardware Error Status bits the e-Manual names nothing for (here bit 1): the sentence says
    none is reported and gives the byte."""
    error, *_ = _faulted(
        load_plan(LETTER_B), tmp_path, lambda chain: chain.set_hardware_error(13, 0x02)
    )
    assert "hardware error: none reported (Hardware Error Status 0x02)" in str(error)


def test_a_serial_arm_that_fails_while_lowering_its_pen_names_the_resume(record, monkeypatch):
    """A serial arm lowers itself onto the paper to resume; a write failing there names the
    resume, the port and the write."""
    profile = load_serial_profile("openmanipulator-x")
    program = build_serial_program(load_plan(LETTER_B), profile)
    on_paper = program.goals[next(s for s in program.segments if s[0] == "draw")[2] + 5]
    sim = record(simulated_arm(profile)[0])
    with ArmDriver(sim.url, profile) as driver:
        driver.lifter = ArmLift(profile, program)
        driver.connect()

        def fails(*args, **kwargs):
            raise OSError("the adapter went away")

        monkeypatch.setattr(sdk.GroupSyncWrite, "txPacket", fails)
        with pytest.raises(ConnectionLost) as caught:
            driver.lower_pen(on_paper)
    assert caught.value.where == "resume"
    assert str(caught.value) == f"resume: {sim.url}: goal positions: the adapter went away"


@pytest.mark.parametrize(
    ("delay_us", "rate", "fits"),
    [(0, 45.0, True), (0, 46.0, False), (500, 42.0, True), (500, 43.0, False)],
)
def test_the_bus_check_counts_ten_bits_a_byte_and_each_servos_return_delay(delay_us, rate, fits):
    """At 57600 bps a tick of the planar arm's three servos takes 127 bytes on the bus: the sync
    write (14 + 5 per servo), the sync read (14 + 1 per servo) and three 27-byte replies (11 +
    Realtime Tick through Present Position, 16), each byte 10 bits on the UART (start, 8 data,
    stop): 22.0 ms, within 45 Hz's period, over 46 Hz's; with bus.return_delay_us = 500 each
    servo waits 0.5 ms more before its reply: 23.55 ms, within 42 Hz's period, over 43 Hz's."""
    from tagbot.arm.run import check_bus
    from tagbot.errors import ProfileError

    profile = load_profile(
        None,
        [
            "bus.baud=57600",
            f"motion.rate={rate:g}",
            "bus.readback_rate=40",
            "servo.profile_ms=80",
            f"bus.return_delay_us={delay_us}",
        ],
    )
    busy = ((14 + 5 * 3) + (14 + 3) + 3 * 27) * 10 / 57600 + 3 * delay_us * 1e-6
    assert (busy <= 1 / rate) == fits
    if fits:
        check_bus(profile)
    else:
        with pytest.raises(ProfileError) as raised:
            check_bus(profile)
        assert f"take {1e3 * busy:.1f} ms on the bus, more than the {1e3 / rate:g} ms" in str(
            raised.value
        )


@pytest.mark.parametrize(("failing", "what"), [(1, "profile"), (2, "goal positions")])
def test_a_write_failing_in_the_move_to_the_start_names_the_move_and_the_write(
    record, monkeypatch, failing, what
):
    """The move to the start writes the pen's profile, then its goal: the adapter failing at
    either names the approach, the port and that write."""
    profile = load_profile()
    sim = record(simulated_chain(profile))
    with ArmDriver(sim.url, profile) as driver:
        driver.connect()
        written = sdk.GroupSyncWrite.txPacket
        calls = []

        def fails_once_reached(group):
            calls.append(group)
            if len(calls) == failing:
                raise OSError("the adapter went away")
            return written(group)

        monkeypatch.setattr(sdk.GroupSyncWrite, "txPacket", fails_once_reached)
        with pytest.raises(ConnectionLost) as caught:
            driver.move_to(driver.read_present(), 0.5)
    assert caught.value.where == "approach"
    assert str(caught.value) == f"approach: {sim.url}: {what}: the adapter went away"


def test_a_retried_transaction_is_in_the_debug_log_with_its_result(record, caplog):
    """A corrupt status while connecting is tried again, and the debug log says which
    transaction, where, and the SDK's result code."""
    profile = load_profile()
    sim = record(simulated_chain(profile))
    sim.chain.corrupt_next(2)
    with (
        caplog.at_level(logging.DEBUG, logger="tagbot.arm.driver"),
        ArmDriver(sim.url, profile) as driver,
    ):
        driver.connect()
    retried = [r.getMessage() for r in caplog.records if "trying again" in r.getMessage()]
    assert len(retried) == 1
    assert re.fullmatch(rf"connect: [\w ]+: result {sdk.COMM_RX_CORRUPT}, trying again", retried[0])


@pytest.mark.parametrize(("corrupt", "connects"), [(2, True), (3, False)])
def test_a_ping_is_tried_three_times_before_corrupt_replies_refuse_the_servo(
    record, profile, corrupt, connects
):
    """While connecting, a transaction whose status is corrupt is tried up to three times: two
    corrupt replies in a row still connect, a third refuses the servo."""
    sim = record(simulated_chain(profile))
    sim.chain.corrupt_next(2, corrupt)
    with ArmDriver(sim.url, profile) as driver:
        if connects:
            driver.connect()
            assert driver.torque_on and all(sim.servo(i).torque for i in (1, 2, 3))
        else:
            with pytest.raises(DeviceError, match=r"^connect: servo 2 \(elbow\): PING: "):
                driver.connect()


def test_the_driver_waits_on_the_clock_it_was_given(record, profile):
    """A clock given to the driver is the one it waits on, also on a port with a clock of its
    own (the simulator's): a 5 ms drain passes 5 ms on that clock."""
    sim = record(simulated_chain(profile))
    clock = _Clock()
    with ArmDriver(sim.url, profile, clock=clock) as driver:
        driver.open()
        driver.drain(0.005)
    assert clock.t == pytest.approx(100.005, abs=1e-9)


def _streaming(record, overrides=()):
    """A connected driver on a simulated chain at the start of a slow path, and that path."""
    from .conftest import goals_path

    profile = load_profile(overrides=overrides)
    sim = record(simulated_chain(profile))
    driver = ArmDriver(sim.url, profile)
    driver.connect()
    goals = goals_path(60, profile)
    driver.move_to(goals[0], 0.5)
    return sim, driver, goals


def test_the_end_of_a_stream_is_logged_with_what_it_counted(record, caplog):
    _, driver, goals = _streaming(record)
    with driver, caplog.at_level(logging.INFO, logger="tagbot.arm.driver"):
        result = driver.stream(goals)
    s, r = result.scheduler, result.readback
    assert s is not None and r is not None
    assert (s.late_ticks, s.resyncs, r.missed, r.late, r.corrupt) == (0, 0, 0, 0, 0)
    ended = [m for m in (r.getMessage() for r in caplog.records) if m.startswith("sent ")]
    assert ended == [
        f"sent 60 ticks: 0 late (max {1e3 * s.max_lateness:.2f} ms), 0 resyncs; read-back:"
        " 0 missed, 0 late, 0 corrupt replies"
    ]


@pytest.mark.parametrize("silent_from", [0, 11], ids=["before-any-read-back", "mid-stream"])
def test_a_servo_that_falls_silent_is_named_with_nothing_more(record, monkeypatch, silent_from):
    """A servo that falls silent (no stray replies, no host stall), whether it answered a
    read-back before or never did: the message names it, how long and the timeout, and ends
    there."""
    sim, driver, goals = _streaming(record, PATIENT)
    offsets = driver._clock_offsets

    def offsets_then_silent(where: str) -> dict[int, float]:
        measured = offsets(where)  # the clocks are read: it falls silent as the stream starts
        if silent_from == 0:
            sim.chain.silence(2)
        return measured

    def progress(done: int, total: int) -> None:
        if done == silent_from:
            sim.chain.silence(2)

    monkeypatch.setattr(driver, "_clock_offsets", offsets_then_silent)

    with driver, pytest.raises(DeviceTimeout) as caught:
        driver.stream(goals, progress=progress)
    assert re.fullmatch(
        r"tick \d+: servo 2 \(elbow\) did not answer SYNC_READ of present positions for"
        r" 0\.25 s while requests were flowing \(bus\.silence_timeout: 0\.25 s\)",
        str(caught.value),
    )


def test_a_corrupt_read_back_reply_is_in_the_debug_log_with_its_id(record, caplog):
    sim, driver, goals = _streaming(record)

    def progress(done: int, total: int) -> None:
        if done == 11:
            sim.chain.corrupt_next(2)

    with driver, caplog.at_level(logging.DEBUG, logger="tagbot.arm.driver"):
        result = driver.stream(goals, progress=progress)
    assert result.corrupt_replies == 1
    corrupt = [r.getMessage() for r in caplog.records if "corrupt read-back" in r.getMessage()]
    assert len(corrupt) == 1
    assert re.fullmatch(r"tick \d+: corrupt read-back reply \(ID byte 2\)", corrupt[0])


def test_a_read_back_request_that_cannot_be_written_names_it(record, monkeypatch):
    """The adapter refuses the SYNC_READ (the SDK's COMM_TX_FAIL): the run stops at that tick
    naming the request and the port."""
    sim, driver, goals = _streaming(record)
    monkeypatch.setattr(sdk.GroupSyncRead, "txPacket", lambda self: sdk.COMM_TX_FAIL)
    with driver, pytest.raises(ConnectionLost) as caught:
        driver.stream(goals)
    assert (
        str(caught.value) == f"tick 1: could not write SYNC_READ of present positions to {sim.url}"
    )


def test_a_host_stall_mid_stream_is_recorded_and_the_run_goes_on(record):
    """The host does not look at the bus for 0.3 s (more than bus.silence_timeout) while
    replies are on their way (50 ms late): the stall is the host's, recorded from the last look
    to the next, and no servo is taken for silent. Later holes between two looks: two periods
    and 4 ms is no stall, two periods and 6 ms is one, from look to look."""
    sim, driver, goals = _streaming(record)
    sim.chain.set_reply_faults(latency=0.05)
    stalled = []
    held = {41: 2 * driver.profile.period + 0.004, 51: 2 * driver.profile.period + 0.006}
    looks = []

    def progress(done: int, total: int) -> None:
        if done == 21:
            stalled.append(driver.clock.now())
            driver.clock.sleep_until(stalled[0] + 0.3)
        elif done in held:
            looks.append(driver.clock.now())
            driver.clock.sleep_until(looks[-1] + held[done])

    with driver:
        result = driver.stream(goals, progress=progress)
    assert result.ticks_sent == 60 and result.readback is not None
    [(start, end), short] = result.readback.host_stalls
    assert start <= stalled[0] and end - start >= 0.3
    assert short == (looks[1], pytest.approx(looks[1] + held[51], abs=1e-9))


def test_a_read_back_is_stamped_when_its_request_has_reached_the_servos(record, monkeypatch):
    """The servos sample their positions once the SYNC_READ has arrived: (14 + 1 per servo)
    bytes of 10 bits after it was sent, at bus.baud (here 57,600 bps: 2.95 ms)."""
    overrides = ("bus.baud=57600", "motion.rate=40", "bus.readback_rate=40", "servo.profile_ms=40")
    _, driver, goals = _streaming(record, overrides)
    requests: list[float] = []
    write = UrlPortHandler.writePort

    def spy(port: UrlPortHandler, packet: list[int]) -> int:
        if packet[7] == 0x82:  # SYNC_READ
            requests.append(port.getCurrentTime() / 1000.0)
        return write(port, packet)

    monkeypatch.setattr(UrlPortHandler, "writePort", spy)
    with driver:
        result = driver.stream(goals)
    sampled = [row[0] for row in result.read_clock]
    assert len(sampled) >= 50
    arrival = (14 + 3) * 10 / 57600
    for t in sampled:
        sent = max(r for r in requests if r <= t)
        assert t - sent == pytest.approx(arrival, abs=1e-9)


def test_a_pause_lifts_the_pen_alone_holds_and_puts_it_back(record):
    """Paused before tick 20 with the pen down: the pen alone goes up in pen.move_time (one
    goal a tick), the arm holds its last goals while the pause lasts, the pen comes back down
    the same way, and the stream goes on from tick 20: nothing of it skipped or repeated."""
    sim, driver, goals = _streaming(record)
    p = driver.profile
    up, down, pen = p["pen.up"], p["pen.down"], p["pen.id"]
    goals[:, 2] = down
    before = len(sim.values(pen, GOAL_POSITION))
    with driver:
        result = driver.stream(goals, control=_PauseAtTick(20, 5))
    assert result.ticks_sent == 60 and result.pauses == 1 and result.paused > 0.04
    steps = max(1, -(-round(1e3 * p["pen.move_time"]) // round(1e3 * p.period)))
    lift = [round(down + (up - down) * i / steps) for i in range(1, steps + 1)]
    lower = [round(up + (down - up) * i / steps) for i in range(1, steps + 1)]
    assert sim.values(pen, GOAL_POSITION)[before:] == [down] * 20 + lift + lower + [down] * 40
    for column, id in enumerate((1, 2)):
        assert sim.values(id, GOAL_POSITION)[-60:] == goals[:, column].tolist()
    # The program's clock has no time for the pause: from the pen's first lift goal until the
    # stream went on, every instant maps to NaN; tick 19's own send still has its time.
    sent = [t for t, i, a, _ in sim.writes if i == pen and a == GOAL_POSITION][before:]
    start, length = result.pause_spans[0]
    assert np.isnan(result.program_time(np.linspace(sent[20], start + length, 50))).all()
    assert np.isfinite(result.program_time(np.array([sent[19]]))).all()


def test_every_missing_servo_is_named_once_in_a_list(record, profile):
    """Two servos of the profile silent at connect: both are named, in ID order, separated by
    a comma, before what the broadcast ping found."""
    sim = record(SimulatedChain({1: "XM430-W350"}))
    with ArmDriver(sim.url, profile) as driver, pytest.raises(DeviceError) as caught:
        driver.connect()
    assert str(caught.value) == (
        f"connect: servo 2 (elbow), servo 3 (pen) did not answer a ping at 1000000 bps on"
        f" {sim.url}; IDs found on the bus: 1 (XM430-W350)"
    )
    # A servo of a model the driver does not know is listed by its model number.
    sim.chain.set_model_number(1, 9999)
    with ArmDriver(sim.url, profile) as driver, pytest.raises(DeviceError) as caught:
        driver.connect()
    assert str(caught.value).endswith("; IDs found on the bus: 1 (model 9999)")


def test_a_resumes_pen_goals_leave_at_once_and_a_tick_apart(record):
    """Lowering the pen for a resume: the first goal leaves at once, each next one a period
    later (it reaches the pen after its packet's time on the wire, well under a period), and
    the call returns ``lead`` after the last goal."""
    profile = load_profile(overrides=("pen.move_time=0.035",))
    sim = record(simulated_chain(profile))
    pen, period, lead = profile["pen.id"], profile.period, profile.lead
    with ArmDriver(sim.url, profile) as driver:
        driver.connect()
        before = len(sim.writes)
        t0 = driver.clock.now()
        driver.lower_pen(profile["pen.down"])
        end = driver.clock.now()
    sent = [
        t for t, id, address, _ in sim.writes[before:] if id == pen and address == GOAL_POSITION
    ]
    assert len(sent) == 4
    for k, t in enumerate(sent):
        assert 0.0 < t - (t0 + k * period) < 0.1 * period
    assert end - t0 == pytest.approx(3 * period + lead, abs=0.1 * period)


@pytest.mark.parametrize(
    ("pen_on_paper", "logged"),
    [
        (True, "safe stop: stopped before the arm was under torque, with the pen on the paper"),
        (False, "stopped safely: pen lifted by the arm"),
    ],
)
def test_a_stop_while_connecting_logs_what_became_of_the_pen(
    tmp_path, caplog, pen_on_paper, logged
):
    """Ctrl-C while a serial arm is connecting: with its pen on the paper the log says why the
    stop did not lift it; with the pen off the paper, that the arm stopped safely with it
    lifted, in those words."""
    with caplog.at_level(logging.INFO, logger="tagbot.arm.driver"):
        _stopped(
            load_plan(LETTER_B),
            tmp_path,
            pen_on_paper=pen_on_paper,
            due=lambda chain, profile: True,
            after=0.001,
        )
    assert logged in [r.getMessage() for r in caplog.records]


def test_a_failed_stream_logs_its_last_bus_operations_with_their_results(
    record, monkeypatch, caplog
):
    """The read-back request refused at tick 1: the debug log lists the bus operations before
    the stop, the goals written with result 0 and the refused SYNC_READ with the SDK's code."""
    _, driver, goals = _streaming(record)
    monkeypatch.setattr(sdk.GroupSyncRead, "txPacket", lambda self: sdk.COMM_TX_FAIL)
    with (
        driver,
        caplog.at_level(logging.DEBUG, logger="tagbot.arm.driver"),
        pytest.raises(ConnectionLost),
    ):
        driver.stream(goals)
    logged = [r.getMessage() for r in caplog.records]
    stop = next(i for i, m in enumerate(logged) if m.startswith("stopping: "))
    listed = [m for m in logged[stop + 1 :] if m.startswith("  ")]
    assert listed[-2:] == [
        "  tick 1: SYNC_WRITE of goal positions -> result 0, error 0",
        f"  tick 1: SYNC_READ of present positions -> result {sdk.COMM_TX_FAIL}, error 0",
    ]


@pytest.mark.parametrize("off", [20, 21])
def test_a_servo_stopping_up_to_20_ticks_from_its_goal_has_arrived(record, profile, off):
    """After the move to the start a servo 20 ticks (1.8°) from its goal has arrived; 21 ticks
    away it is named as stopped short, with where it stands."""
    sim = record(simulated_chain(profile))
    with ArmDriver(sim.url, profile) as driver:
        driver.connect()
        goals = driver.read_present()
        stands = goals + np.array([0, off, 0])
        driver.read_present = lambda where="connect": stands.copy()
        if off == 20:
            driver.move_to(goals, 0.5)
            assert driver.last_row == goals.tolist()
        else:
            with pytest.raises(DeviceError) as caught:
                driver.move_to(goals, 0.5)
            assert str(caught.value) == (
                f"approach: servo 2 (elbow) stopped at {stands[1]} ticks, 21 from its goal"
                f" {goals[1]} (blocked, or torque off?)"
            )


def _ctrl_c_with_a_stop_that(breaks: str, monkeypatch):
    """Ctrl-C mid-run of the planar arm, its safe stop's pen-up goal then ``written``, not
    written (the adapter takes no byte from then on), or ``interrupted`` by a second Ctrl-C."""
    guard = ArmDriver._guard

    def second_ctrl_c(self, action, what, where):
        if what == "pen up":
            raise KeyboardInterrupt
        return guard(self, action, what, where)

    def progress(done: int, total: int) -> None:
        if done == 301:
            if breaks == "not written":
                monkeypatch.setattr(UrlPortHandler, "writePort", lambda self, packet: 0)
            if breaks == "interrupted":
                monkeypatch.setattr(ArmDriver, "_guard", second_ctrl_c)
            raise KeyboardInterrupt

    return progress


@pytest.mark.parametrize(
    ("breaks", "said"),
    [
        ("written", None),
        ("not written", "stop: could not write SYNC_WRITE of pen up to dxlsim://"),
        ("interrupted", "interrupted before the pen was up"),
    ],
)
def test_a_planar_arm_stopped_says_whether_its_pen_went_up(
    record, tmp_path, monkeypatch, breaks, said
):
    """The stop's pen-up goal is said done only when it was written: a failed write or a
    second Ctrl-C is named, and warned of, with the pen perhaps still on the paper."""
    profile = load_profile()
    sim = record(simulated_chain(profile))
    job = prepare(two_plan_tag(), port=sim.url)
    run = job.run(tmp_path, progress=_ctrl_c_with_a_stop_that(breaks, monkeypatch))
    assert isinstance(run.error, Interrupted)
    message = str(run.error)
    pen_goals = sim.values(profile["pen.id"], GOAL_POSITION)
    if said is None:
        assert "interrupted (Ctrl-C): the arm stopped, pen up" in message
        assert not any("still be on the paper" in w for w in run.warnings)
        assert pen_goals[-1] == profile["pen.up"]
        return
    assert pen_goals[-1] == profile["pen.down"]  # the stop's goal never reached the servo
    not_raised = "the arm stopped, but the pen was not raised ("
    assert f"interrupted (Ctrl-C): {not_raised}{said}" in message
    warned = [w for w in run.warnings if w.startswith(not_raised)]
    assert len(warned) == 1 and warned[0].endswith("): it may still be on the paper")
    assert said in warned[0]


def test_a_serial_arm_told_to_go_limp_after_an_error_lifts_its_pen_then_drops_torque(
    record, caplog
):
    """With ``servo.torque_off_after_error`` a serial arm's stop after an error lifts the pen,
    then switches every joint's torque off and logs that it did."""
    profile = load_serial_profile("openmanipulator-x", ("servo.torque_off_after_error=true",))
    sim = record(simulated_arm(profile)[0])
    with (
        ArmDriver(sim.url, profile) as driver,
        caplog.at_level(logging.INFO, logger="tagbot.arm.driver"),
    ):
        driver.lifter = ArmLift(profile)
        driver.connect()
        assert all(sim.servo(id).torque for id in profile.bus_ids)
        driver.safe_stop(error=True)
        assert driver.lifted and driver.lift_failure is None
    assert not any(sim.servo(id).torque for id in profile.bus_ids)
    logged = [r.getMessage() for r in caplog.records]
    assert "stopped safely: pen lifted by the arm, torque off" in logged


def test_a_hole_between_looks_at_the_bus_is_a_host_stall_only_beyond_two_periods_and_5_ms(
    record, profile
):
    """The read-back loop away from the bus for exactly two periods and 5 ms is no host stall
    (no servo's silence is excused for it); a microsecond longer is one, from look to look."""
    from tagbot.arm.driver import ReadBack

    sim = record(simulated_chain(profile))
    with ArmDriver(sim.url, profile) as driver:
        driver.open()  # the simulated clock at 0: early instants, where the hole is exact
        clock = driver.clock
        readback = ReadBack(driver, clock.now(), dict.fromkeys(driver.ids, 0.0))
        gap = 2 * profile.period + 0.005
        assert readback.gap == gap
        clock.sleep_until(0.05)
        readback.looked = 0.05 - gap
        assert clock.now() - readback.looked == gap  # the hole, to the bit
        readback.poll("test")
        assert readback.host_stalls == []
        clock.sleep_until(0.06)
        readback.looked = 0.06 - gap - 1e-6
        readback.poll("test")
        assert readback.host_stalls == [(0.06 - gap - 1e-6, 0.06)]
