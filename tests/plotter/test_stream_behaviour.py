"""The Grbl streamer's behaviour at the edges the other stream tests do not reach (issue 34):
what a safe stop reports, a watchdog without planner data, a hold still decelerating, a
resumed line's feed."""

from __future__ import annotations

import pytest

from firmware_protocols.grbl import parse_message
from sim.grbl import SimulatedGrbl
from tagbot.control import RunControl
from tagbot.errors import DeviceFault, DeviceTimeout
from tagbot.plotter.stream import (
    ExecutionTracker,
    GrblStreamer,
    StreamOptions,
    _Entry,
    resume_point,
)

from .test_stream import PEN_UP, SETTINGS, Wire, open_device, square_program


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
