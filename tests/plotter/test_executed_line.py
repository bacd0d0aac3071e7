"""Which line the machine executed: the tracker against the simulator's own record.

Grbl answers ``ok`` when a line is planned; the host must tell what has *run* from the status
reports. Every fault and Ctrl-C names that line, and resuming from the next one redraws nothing
twice and skips nothing.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import serial

from firmware_protocols.grbl import State, Status
from sim.grbl import SimulatedGrbl
from sim.grbl.transport import attach_device
from tagbot.errors import DeviceFault, DeviceTimeout
from tagbot.plotter.stream import (
    ExecutionTracker,
    GrblStreamer,
    StreamOptions,
    _Entry,
    line_effects,
    resume_lines,
    resume_point,
)

SETTINGS = {100: 80, 101: 80, 110: 6000, 111: 6000, 120: 500, 121: 500}
PEN_UP = ["M3S50\n", "G4P0.1\n"]
PEN_DOWN = ["M3S30\n", "G4P0.1\n"]
_names = itertools.count()


def wavy_program(count: int, dt: float = 0.01) -> list[str]:
    """Pen down, ``count`` inverse-time lines along a wave (a path that never repeats), pen up."""
    lines = ["G21\n", "G90\n", "G94\n", "G0X10Y50\n", *PEN_DOWN, "G93\n"]
    for k in range(1, count + 1):
        x = 10 + 0.5 * k * dt * 30
        y = 50 + 10 * math.sin(k / 40)
        lines.append(f"G1X{x:.3f}Y{y:.3f}F{60 / dt:.0f}\n")
    return [*lines, "G94\n", *PEN_UP, "M5\n", "M2\n"]


def connect(device: SimulatedGrbl, **options: object) -> tuple[serial.SerialBase, GrblStreamer]:
    url = attach_device(device, f"executed{next(_names)}")
    port = serial.serial_for_url(url, baudrate=115200)
    streamer = GrblStreamer(port, StreamOptions(**options))
    streamer.connect()
    return port, streamer


def entries(lines: list[str]) -> list[_Entry]:
    moves, targets = line_effects(lines)
    return [
        _Entry(i, t, m, xy) for i, (t, m, xy) in enumerate(zip(lines, moves, targets, strict=True))
    ]


def test_tracker_reads_bf_ln_and_positions():
    lines = ["G93\n", "G1X1Y0F6000\n", "G1X2Y0F6000\n", "G1X3Y0F6000\n", "G1X4Y0F6000\n"]
    tracker = ExecutionTracker(entries(lines), 0, 0, 15, (0.0, 0.0))
    for _ in lines:
        tracker.acknowledge()
    # Bf: 2 blocks still queued -> the last two moving lines (3 and 4, 0-based) have not run;
    # a hold is complete, so that count is exact.
    held = Status(State.HOLD, substate=0, mpos=(2.4, 0.0, 0.0), buffer=(13, 128))
    assert tracker.update(held, (2.4, 0.0)) == 3
    # In motion, the position refines it within the lines Bf allows (never backwards).
    assert tracker.update(Status(State.RUN, buffer=(13, 128)), (2.5, 0.0)) == 3
    assert tracker.update(Status(State.RUN, buffer=(14, 128)), (3.5, 0.0)) == 4
    assert tracker.update(Status(State.IDLE, buffer=(15, 128)), (4.0, 0.0)) == 5
    # Ln: the executing line's number (1-based), preamble and first line accounted for.
    numbered = ExecutionTracker(entries(lines)[2:], 2, 0, 15, (1.0, 0.0), numbered=True)
    for _ in range(3):
        numbered.acknowledge()
    assert numbered.update(Status(State.RUN, line=4), (2.9, 0.0)) == 1  # line 4 = entry 1
    assert numbered.program_done == 1
    # Positions alone: the earliest acknowledged segment holding the point.
    blind = ExecutionTracker(entries(lines), 0, 0, 15, (0.0, 0.0))
    for _ in lines:
        blind.acknowledge()
    assert blind.update(Status(State.RUN), (1.5, 0.0)) == 2
    assert blind.update(Status(State.RUN), (0.5, 0.0)) == 2  # never backwards
    assert blind.update(Status(State.RUN), (3.99, 0.01)) == 4
    assert blind.update(Status(State.IDLE), (4.0, 0.0)) == 5


@pytest.mark.parametrize("mask", [1, 3])  # $10=1: positions only; $10=3: with Bf
def test_ctrl_c_names_the_executed_line_and_resuming_redraws_nothing_twice(mask):
    lines = wavy_program(1200)
    reference = SimulatedGrbl({**SETTINGS, 10: mask}, pen_servo=(30, 50))
    port, streamer = connect(reference)
    try:
        streamer.stream(lines)
    finally:
        port.close()
    whole = reference.trace(0.001)
    device = SimulatedGrbl({**SETTINGS, 10: mask}, pen_servo=(30, 50))
    port, streamer = connect(device)
    received_before = device.lines_received

    def interrupt(done: int, total: int) -> None:
        if done >= 700:
            raise KeyboardInterrupt

    try:
        with pytest.raises(KeyboardInterrupt):
            streamer.stream(lines, pen_up=PEN_UP, progress=interrupt)
    finally:
        port.close()
    report = streamer.last_report
    executed = report.lines_executed
    # The simulator's own record: how many lines had fully taken effect when it stopped.
    truth = device.executed_lines - received_before
    assert executed == truth or (mask == 1 and truth - 1 <= executed <= truth)
    assert report.errors[0] == (
        f"interrupted after line {executed} (the last line the machine executed; resume with "
        f"--resume-from {executed + 1} --position-known)"
    )
    assert report.lines_acknowledged > executed + 5  # 'ok' had run well ahead
    first_part = device.trace(0.001)
    # Resume on the same machine (position kept through the reset), from the next line.
    first = executed
    at = device.position_mm[:2]
    rest = list(lines)
    inside = resume_point(rest, first, at)
    start = None
    if inside is not None:
        rest[first], start = inside
    preamble = resume_lines(rest, first, PEN_UP, PEN_DOWN, start)
    port, streamer = connect(device)
    try:
        streamer.stream(rest, first=first, preamble=preamble, pen_up=PEN_UP)
    finally:
        port.close()
    both = device.trace(0.001)
    second_part = both[len(first_part) :]
    drawn = [p[p[:, 4] > 0.5][:, 1:3] for p in (first_part, second_part)]
    reference_drawn = whole[whole[:, 4] > 0.5][:, 1:3]

    def length(xy: np.ndarray) -> float:
        return float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))

    # Nothing twice, nothing skipped: the two parts add up to the whole drawing's length ...
    total = length(drawn[0]) + length(drawn[1])
    assert total == pytest.approx(length(reference_drawn), abs=0.05)
    # ... and the second starts where the first stopped.
    assert np.hypot(*(drawn[1][0] - drawn[0][-1])) < 0.02


def test_an_error_names_the_executed_line_as_the_simulator_recorded_it():
    lines = wavy_program(800)
    device = SimulatedGrbl({**SETTINGS, 10: 3}, pen_servo=(30, 50))
    port, streamer = connect(device)
    before = device.lines_received
    device.inject_error(before + 400, 22)
    try:
        with pytest.raises(DeviceFault, match=r"^after line (\d+) .*error:22"):
            streamer.stream(lines, pen_up=PEN_UP)
    finally:
        port.close()
    assert streamer.last_report.lines_executed == device.executed_lines - before < 399


def test_a_stalled_machine_is_caught_by_the_watchdog():
    lines = wavy_program(600)
    device = SimulatedGrbl({**SETTINGS, 10: 3}, pen_servo=(30, 50))
    port, streamer = connect(device, stall_timeout=1.0)

    def stall(done: int, total: int) -> None:
        if done >= 200:
            device.freeze_motion()

    try:
        with pytest.raises(
            DeviceTimeout,
            match=r"the machine stopped executing: no motion and no answer for \d+\.\d s with"
            r" lines queued \((Idle|Run), status reports still coming\)",
        ):
            streamer.stream(lines, pen_up=PEN_UP, progress=stall)
    finally:
        device.freeze_motion(False)
        port.close()
    report = streamer.last_report
    assert 200 <= report.lines_executed < 260
    assert report.duration < 20  # not the ~400 s of waiting the issue saw


def test_a_limit_alarm_is_reset_after_grbls_delay():
    lines = wavy_program(600)
    device = SimulatedGrbl({**SETTINGS, 10: 3}, pen_servo=(30, 50))
    port, streamer = connect(device)
    device.schedule_alarm(device.now + 2.0, 1)
    try:
        with pytest.raises(DeviceFault, match=r"ALARM:1"):
            streamer.stream(lines, pen_up=PEN_UP)
    finally:
        port.close()
    report = streamer.last_report
    assert not any("safe stop incomplete" in e for e in report.errors), report.errors
    assert device.state == State.ALARM  # reset taken (banner), left locked for the operator


def test_the_tracker_names_the_evidence_it_went_by():
    """What told which line ran (a report's ``tracking``): the acknowledgements alone until a
    status report comes, then that report's Bf, Ln or position."""
    lines = ["G93\n", "G1X1Y0F6000\n", "G1X2Y0F6000\n"]
    tracker = ExecutionTracker(entries(lines), 0, 0, 15, (0.0, 0.0))
    tracker.acknowledge()
    tracker.finish()
    assert tracker.source == "acknowledgements" and tracker.done == 1
    tracker.update(Status(State.RUN, buffer=(15, 128)), None)
    assert tracker.source == "status Bf"
    tracker.update(Status(State.RUN), (0.5, 0.0))
    assert tracker.source == "status position"
    numbered = ExecutionTracker(entries(lines), 0, 0, 15, (0.0, 0.0), numbered=True)
    numbered.update(Status(State.RUN, line=1), None)
    assert numbered.source == "status Ln"


def test_finishing_empties_the_planner_blocks_the_last_report_counted():
    """Bf said two blocks wait; once the machine is idle with nothing in flight, none do."""
    lines = ["G93\n", "G1X1Y0F6000\n", "G1X2Y0F6000\n", "G1X3Y0F6000\n"]
    tracker = ExecutionTracker(entries(lines), 0, 0, 15, (0.0, 0.0))
    for _ in lines:
        tracker.acknowledge()
    tracker.update(Status(State.RUN, buffer=(13, 128)), None)
    assert tracker.queued_blocks() == 2
    tracker.finish()
    assert tracker.queued_blocks() == 0 and tracker.done == len(lines)
