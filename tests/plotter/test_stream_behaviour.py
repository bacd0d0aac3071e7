"""The Grbl streamer's behaviour at the edges the other stream tests do not reach (issue 34):
what a safe stop reports, a watchdog without planner data, a hold still decelerating, a
resumed line's feed."""

from __future__ import annotations

import re

import pytest

from firmware_protocols.grbl import parse_message
from sim.grbl import SimulatedGrbl
from tagbot.control import RunControl
from tagbot.errors import DeviceError, DeviceFault, DeviceTimeout
from tagbot.plotter.stream import (
    ExecutionTracker,
    GrblStreamer,
    StreamOptions,
    _Entry,
    resume_point,
)

from .test_stream import PEN_UP, SETTINGS, Wire, connected, open_device, square_program


def test_a_fault_says_when_the_safe_stop_began_and_its_own_hold_is_no_outside_hold():
    """An ``error:N`` mid-job: the report says when the safe stop was asked for (after the
    start, before the end: the stop takes time), and the feed hold the safe stop sends itself
    is not counted as a hold tagbot did not ask for."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port = open_device(device)
    streamer = GrblStreamer(port, StreamOptions())
    streamer.connect()
    device.inject_error(device.lines_received + 100, 22)
    try:
        with pytest.raises(DeviceFault):
            streamer.stream(square_program(300), pen_up=PEN_UP)
    finally:
        port.close()
    report = streamer.last_report
    assert report.stopped_at == 99
    assert report.started < report.stop_requested < report.finished
    assert report.outside_holds == 0 and report.warnings == [] and report.pause_spans == []


def test_a_frozen_machine_without_planner_reports_is_caught_by_the_watchdog():
    """``$10=1`` (no ``Bf:``: the queued planner blocks are unknown): a machine that stops
    moving with lines still unanswered is a stall all the same, raised after the stall
    timeout (the machine would run on if it were only slow: it is freed 4 s later)."""
    device = SimulatedGrbl({**SETTINGS, 10: 1}, pen_servo=(30, 50))
    port = open_device(device)
    frozen_at: list[float] = []

    def trace(direction: str, data: bytes) -> None:
        if frozen_at and device.now > frozen_at[0] + 4.0:
            device.freeze_motion(False)

    def freeze(done: int, total: int) -> None:
        if done >= 100 and not frozen_at:
            frozen_at.append(device.now)
            device.freeze_motion()

    streamer = GrblStreamer(port, StreamOptions(stall_timeout=1.0), trace=trace)
    streamer.connect()
    try:
        with pytest.raises(DeviceTimeout, match=r"^after line \d+ .*the machine stopped executing"):
            streamer.stream(square_program(400), pen_up=PEN_UP, progress=freeze)
    finally:
        device.freeze_motion(False)
        port.close()
    assert frozen_at
    assert streamer.last_report.stop_requested < frozen_at[0] + 4.0


def _straight_entries(count: int) -> list[_Entry]:
    """``count`` moving lines of 10 mm along x from the origin."""
    return [_Entry(k, f"G1X{10 * (k + 1)}\n", True, (10.0 * (k + 1), 0.0)) for k in range(count)]


def test_a_hold_still_decelerating_is_placed_by_its_position():
    """``Hold:1`` (decelerating, still moving): as in motion, the stepper may still run a
    block the planner already let go, so the position decides: at x = 15 the machine is on
    line 2, only line 1 is done, though ``Bf:`` says just 3 blocks are queued. Once the hold
    is complete (``Hold:0``, standing) the planner's count is taken."""
    tracker = ExecutionTracker(_straight_entries(6), 0, 0, 15, (0.0, 0.0))
    for _ in range(6):
        tracker.acknowledge()
    decelerating = parse_message("<Hold:1|MPos:15.000,0.000,0.000|Bf:12,100>")
    assert tracker.update(decelerating, (15.0, 0.0)) == 1
    assert tracker.program_done == 1
    complete = parse_message("<Hold:0|MPos:35.000,0.000,0.000|Bf:12,100>")
    assert tracker.update(complete, (35.0, 0.0)) == 3


def test_a_resumed_inverse_time_line_keeps_its_speed():
    """A stop a quarter of the way along a G93 line of 10 mm at F60 (1 s): the rest, 7.5 mm,
    is sent with F80 (0.75 s), the same speed, from where the machine stopped."""
    lines = ["G21\n", "G90\n", "G0X0Y0\n", "G93\n", "G1X10Y0F60\n"]
    assert resume_point(lines, 4, (2.5, 0.0)) == ("G1X10Y0F80\n", (2.5, 0.0))
    assert resume_point(lines, 4, (5.0, 0.0)) == ("G1X10Y0F120\n", (5.0, 0.0))


def test_a_refused_command_is_named_in_the_fault():
    """``error:N`` answering a command sent by itself (``G5``, not a Grbl G-code): the fault
    names that command, as an alarm during one does."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port = open_device(device)
    streamer = GrblStreamer(port, StreamOptions())
    try:
        streamer.connect()
        with pytest.raises(DeviceFault) as caught:
            streamer.command("G5")
    finally:
        port.close()
    assert caught.value.where == "'G5'"
    assert str(caught.value) == "'G5': error:20 (unsupported G-code command)"


def test_idle_exactly_on_segment_distance_from_the_last_end_counts_as_there():
    """From (10, 10) down to (10, 0), then to the origin: idle at (-0.02, 0), exactly
    :data:`ON_SEGMENT` beyond where the last line ends, the machine is at that end and every
    acknowledged line has run."""
    entries = [
        _Entry(0, "G1X10Y0\n", True, (10.0, 0.0)),
        _Entry(1, "G1X0Y0\n", True, (0.0, 0.0)),
    ]
    tracker = ExecutionTracker(entries, 0, 0, 15, (10.0, 10.0))
    tracker.acknowledge()
    tracker.acknowledge()
    idle = parse_message("<Idle|MPos:-0.020,0.000,0.000>")
    assert tracker.update(idle, (-0.02, 0.0)) == 2


@pytest.mark.parametrize("drawing", [None, [True, False, False]])
def test_a_host_stall_not_inside_a_drawing_run_is_no_warning(drawing):
    """The host standing still 0.5 s before line 2 (one line at a time): with no ``drawing``
    given, or line 2 not a drawing line (the pen lifted), the machine waiting is no starved
    stroke, so the job completes with no warning."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port = open_device(device)
    wire = Wire()
    streamer = GrblStreamer(port, StreamOptions(mode="wait"), trace=wire)
    streamer.connect()
    lines = ["G1X10Y0F600\n", "G1X20Y0F600\n", "G1X30Y0F600\n"]
    wire.at[len(wire.lines_sent()) + 1] = lambda: device.advance(0.5)  # descheduled
    try:
        report = streamer.stream(lines, drawing=drawing)
    finally:
        port.close()
    assert report.errors == [] and report.warnings == [] and report.stall_spans == []
    assert report.lines_executed == 3


def test_a_run_control_pause_holds_and_its_resume_starts_the_cycle_again():
    """``control`` paused at line 20, resumed about 2 s later: ``!`` then ``~`` on the wire,
    one pause of about 2 s, and the job runs to its end (a machine still held 5 s after the
    resume fails the test rather than wait for ever)."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port = open_device(device)
    wire = Wire()
    control = RunControl()
    polls = {"held": 0, "after": 0}

    def trace(direction: str, data: bytes) -> None:
        wire(direction, data)
        if direction != "tx" or data != b"?" or b"!" not in wire.tx:
            return
        if control.paused:
            polls["held"] += 1
            if polls["held"] == 10:  # about 2 s held
                control.resume()
        else:
            polls["after"] += 1
            assert polls["after"] < 25, "still held 5 s after the resume"

    streamer = GrblStreamer(port, StreamOptions(), trace=trace)
    streamer.connect()
    wire.at[len(wire.lines_sent()) + 20] = control.pause
    lines = square_program(200)
    try:
        report = streamer.stream(lines, control=control)
    finally:
        port.close()
    assert [d for d in wire.tx if d in (b"!", b"~")] == [b"!", b"~"]
    assert report.pauses == 1 and 1.5 < report.paused_s < 2.5
    assert report.outside_holds == 0 and report.lines_executed == len(lines)


@pytest.mark.parametrize(("option", "firmware_numbers"), [("on", False), ("off", True)])
def test_line_numbers_on_or_off_overrule_what_the_firmware_says(option, firmware_numbers):
    """``line_numbers="on"`` sends N words to a firmware whose ``$I`` does not list them;
    ``"off"`` sends none to one that does (the job runs either way)."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50), line_numbers=firmware_numbers)
    port, streamer, wire = connected(device, line_numbers=option)
    lines = ["G21\n", "G90\n", "G1X10Y0F600\n", "G1X10Y10F600\n", "M2\n"]
    try:
        report = streamer.stream(lines)
    finally:
        port.close()
    sent = [line.decode() for line in wire.lines_sent()[-len(lines) :]]
    if option == "on":
        assert sent == [f"N{k + 1}{line}" for k, line in enumerate(lines)]
    else:
        assert sent == lines
    assert report.lines_executed == len(lines) and report.errors == []


def test_a_message_after_the_banner_that_is_no_lock_does_not_stop_the_connect():
    """A push message after the banner that does not ask to unlock (``[MSG:Check Door]``):
    the machine is not locked, so the default policy (refuse a locked machine) connects and
    sends neither ``$X`` nor ``$H``."""
    device = SimulatedGrbl(SETTINGS)  # its boot banner is waiting to be read
    device.emit_garbage(b"[MSG:Check Door]\r\n")
    port = open_device(device)
    wire = Wire()
    try:
        settings = GrblStreamer(port, StreamOptions(reset=False), trace=wire).connect()
    finally:
        port.close()
    assert settings[110] == 6000
    assert wire.lines_sent() == [b"$$\n", b"$I\n"]


@pytest.mark.parametrize("policy", ["never", "unlock"])
def test_a_machine_announcing_after_the_banner_that_it_is_locked_is_taken_as_locked(policy):
    """Grbl's ``[MSG:'$H'|'$X' to unlock]`` after the banner says the machine is locked, even
    before a status report shows it: the default policy refuses it, naming what to do;
    ``unlock`` sends ``$X``."""
    device = SimulatedGrbl(SETTINGS)  # its boot banner is waiting to be read
    device.emit_garbage(b"[MSG:'$H'|'$X' to unlock]\r\n")
    port = open_device(device)
    wire = Wire()
    streamer = GrblStreamer(port, StreamOptions(reset=False, unlock=policy), trace=wire)
    try:
        if policy == "never":
            with pytest.raises(DeviceFault) as refused:
                streamer.connect()
            assert str(refused.value) == (
                "the machine is in Alarm (locked); check it, then unlock (--unlock) or home "
                "(--home) before drawing"
            )
        else:
            streamer.connect()
    finally:
        port.close()
    assert wire.lines_sent() == [b"$$\n", b"$I\n", *([b"$X\n"] if policy == "unlock" else [])]


def test_the_watchdog_waits_out_the_longest_dwell_and_no_longer():
    """A program with a 1 s dwell and a stall timeout of 0.3 s: the machine standing still for
    the dwell is no stall (the watchdog allows 1.5 x 1 s + 1 s = 2.5 s); frozen mid-job, the
    same program times out 2.5 s after the machine last changed (to within the acks still
    coming and one status period), not sooner."""
    lines = ["G21\n", "G90\n", "G94\n", "G1X10Y0F600\n", "G4P1\n", "G1X20Y0F600\n", "M2\n"]
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, _ = connected(device, stall_timeout=0.3)
    try:
        report = streamer.stream(lines)
    finally:
        port.close()
    assert report.errors == [] and report.lines_executed == len(lines)
    assert report.duration > 1.0 + 20 / 10  # the dwell, and 20 mm at 10 mm/s

    program = [line.replace("G4P0.1", "G4P1") for line in square_program(400)]
    assert 2.5 < _stall_detected_after(program) < 2.5 + 1.0


def _stall_detected_after(program: list[str]) -> float:
    """Seconds from freezing the machine after 100 lines of ``program`` (stall timeout 0.3 s)
    to the stream's stop for a stall."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, _ = connected(device, stall_timeout=0.3)
    frozen_at: list[float] = []

    def freeze(done: int, total: int) -> None:
        if done >= 100 and not frozen_at:
            frozen_at.append(device.now)
            device.freeze_motion()

    try:
        with pytest.raises(DeviceTimeout, match="the machine stopped executing"):
            streamer.stream(program, pen_up=PEN_UP, progress=freeze)
    finally:
        device.freeze_motion(False)
        port.close()
    return streamer.last_report.stop_requested - frozen_at[0]


def test_a_host_stall_after_the_lines_drawing_covers_is_no_warning():
    """``drawing`` covering only lines 1 and 2: the host standing still 0.5 s before line 3
    (one line at a time) is outside every run it names, so no warning; with line 3 a drawing
    line too, the same stall is a named host stall."""
    lines = ["G1X10Y0F600\n", "G1X20Y0F600\n", "G1X30Y0F600\n"]
    warnings = {}
    for drawing in ([True, True], [True, True, True]):
        device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
        port, streamer, wire = connected(device, mode="wait")
        wire.at[len(wire.lines_sent()) + 2] = lambda device=device: device.advance(0.5)
        try:
            report = streamer.stream(lines, drawing=drawing)
        finally:
            port.close()
        assert report.errors == [] and report.lines_executed == 3
        warnings[len(drawing)] = report.warnings
    assert warnings[2] == []
    assert [w.split(",")[0] for w in warnings[3]] == [
        "host stall: nothing was sent for 0.50 s before line 3"
    ]


@pytest.mark.parametrize("answers", [2, None])
def test_a_reset_the_controller_misses_in_a_safe_stop_is_sent_again(answers, caplog):
    """A fault mid-job; the controller, stopped by the feed hold, misses the safe stop's first
    reset (no banner within 1.5 s): the reset is sent again, and once a banner comes the pen is
    lifted. A controller that answers none of three resets: the safe stop is incomplete, said
    in the report and in the log, and the pen lines are not sent."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port = open_device(device)
    wire = Wire()
    seen = {"hold": False, "resets": 0}

    def trace(direction: str, data: bytes) -> None:
        wire(direction, data)
        if direction == "tx" and data == b"!":
            seen["hold"] = True
        elif direction == "rx" and seen["hold"] and b"Hold:0" in data and not seen["resets"]:
            device.go_silent()  # stopped, then deaf to the reset
        elif direction == "tx" and data == b"\x18" and seen["hold"]:
            seen["resets"] += 1
            if seen["resets"] == answers:
                device.go_silent(False)  # hears this one (it is still on the wire)

    streamer = GrblStreamer(port, StreamOptions(), trace=trace)
    streamer.connect()
    device.inject_error(device.lines_received + 100, 22)
    try:
        with (
            caplog.at_level("WARNING", logger="tagbot.plotter.stream"),
            pytest.raises(DeviceFault, match="error:22"),
        ):
            streamer.stream(square_program(300), pen_up=PEN_UP)
    finally:
        port.close()
    errors = streamer.last_report.errors
    logged = [r.getMessage() for r in caplog.records if r.name == "tagbot.plotter.stream"]
    after_hold = wire.tx[wire.tx.index(b"!") :]
    pen_lines = [d for d in after_hold if d.endswith(b"\n")]
    if answers is None:
        assert seen["resets"] == 3 and pen_lines == []
        assert errors[1:] == [
            "safe stop incomplete: no welcome after 3 resets: the machine may still hold lines;"
            " switch it off"
        ]
        assert (
            "grbl: safe stop incomplete: no welcome after 3 resets: the machine may still hold"
            " lines; switch it off" in logged
        ), logged
    else:
        assert seen["resets"] == 2 and len(errors) == 1
        assert not any("safe stop incomplete" in m for m in logged), logged
        assert pen_lines == [line.encode() for line in PEN_UP]


def test_an_ok_for_no_line_after_the_last_one_is_a_named_device_error():
    """Every line acknowledged, the machine still moving: an ``ok`` nobody asked for then means
    host and controller disagree on what was sent; the stream stops with an error that says
    so."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    lines = ["G21\n", "G90\n", "G1X40Y0F3000\n"]
    port = open_device(device)
    wire = Wire()
    stray = []

    def trace(direction: str, data: bytes) -> None:
        wire(direction, data)
        acked = sum(d.count(b"ok\r\n") for d in wire.rx) - before
        if direction == "tx" and data == b"?" and acked == len(lines) and not stray:
            stray.append(device.now)  # the first status request after the last ok
            device.emit_garbage(b"ok\r\n")

    streamer = GrblStreamer(port, StreamOptions(), trace=trace)
    before = 10**9
    streamer.connect()
    before = sum(d.count(b"ok\r\n") for d in wire.rx)
    try:
        with pytest.raises(DeviceError) as caught:
            streamer.stream(lines)
    finally:
        port.close()
    assert stray
    assert re.fullmatch(
        r"after line [23] \(the last line the machine executed; .*\): unexpected Ok\(\) after"
        r" the last line",
        str(caught.value),
    )


@pytest.mark.parametrize("short", ["moves", "targets"])
def test_moves_or_targets_not_one_per_line_are_refused_before_anything_is_sent(short):
    """A caller's ``moves`` or ``targets`` one short of the lines: refused with a message that
    names both, and not one line goes out."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    lines = ["G21\n", "G90\n", "G1X10Y0F600\n"]
    given = {"moves": [False, False, True], "targets": [(0.0, 0.0), (0.0, 0.0), (10.0, 0.0)]}
    given[short] = given[short][:-1]
    sent = len(wire.lines_sent())
    try:
        with pytest.raises(ValueError) as caught:
            streamer.stream(lines, **given)
    finally:
        port.close()
    assert str(caught.value) == "moves, targets: one per line"
    assert len(wire.lines_sent()) == sent


def test_with_no_dwell_the_watchdog_allows_a_second_beyond_a_shorter_stall_timeout():
    """A program with no dwell and a stall timeout of 0.3 s: the watchdog still allows the
    machine 1 s of standing still (1.5 x 0 s + 1 s) before calling it stalled, and no more."""
    program = [line for line in square_program(400) if not line.startswith("G4P")]
    assert 1.0 < _stall_detected_after(program) < 1.0 + 1.0


def test_a_command_waited_on_polls_the_status_at_the_poll_rate():
    """``G4P1`` sent as a command, with a poll rate of 5 Hz: while waiting for its ``ok`` the
    host asks for a status every 0.2 s, so 5 or 6 times over the second's dwell (4 allows a
    late poll on a busy host; every 0.4 s would be 3)."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device, poll_rate=5.0)
    before = len(wire.tx)
    try:
        streamer.command("G4P1")
    finally:
        port.close()
    assert 4 <= wire.tx[before:].count(b"?") <= 6


def test_a_machine_frozen_on_its_last_move_after_every_ok_is_caught_by_the_watchdog():
    """Every line acknowledged, the one move left frozen mid-way (``Bf:14``: a single planner
    block waits): waiting for the end, the host raises the stall after the stall timeout, naming
    the move as not executed, rather than waiting on (it is freed 4 s later)."""
    device = SimulatedGrbl({**SETTINGS, 10: 3}, pen_servo=(30, 50))
    port = open_device(device)
    lines = ["G21\n", "G90\n", "G94\n", "G1X100Y0F600\n"]  # one 10 s move, all sent at once
    started: list[float] = []
    frozen_at: list[float] = []

    def trace(direction: str, data: bytes) -> None:
        if started and not frozen_at and device.now > started[0] + 1.0:
            frozen_at.append(device.now)
            device.freeze_motion()
        elif frozen_at and device.now > frozen_at[0] + 4.0:
            device.freeze_motion(False)

    streamer = GrblStreamer(port, StreamOptions(stall_timeout=1.0), trace=trace)
    streamer.connect()
    started.append(device.now)
    try:
        with pytest.raises(
            DeviceTimeout,
            match=r"^after line 3 .*resume with --resume-from 4 .*: the machine stopped executing:"
            r" no motion and no answer for 1\.\d s with lines queued \(Run,",
        ):
            streamer.stream(lines)
    finally:
        device.freeze_motion(False)
        port.close()
    report = streamer.last_report
    assert frozen_at and report.lines_acknowledged == 4 and report.lines_executed == 3
    assert frozen_at[0] + 1.0 < report.stop_requested < frozen_at[0] + 4.0
