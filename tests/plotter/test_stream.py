"""Streaming G-code into the simulated Grbl: flow control, handshake, faults, resume, long jobs."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import serial

from firmware_protocols.grbl import Realtime, State
from sim.grbl import SimulatedGrbl
from sim.grbl.device import READ_TIME
from sim.grbl.transport import attach_device, serve_pty
from tagbot.errors import ConnectionLost, DeviceFault, DeviceTimeout
from tagbot.plotter.stream import GrblStreamer, StreamOptions, resume_lines

SETTINGS = {100: 80, 101: 80, 110: 6000, 111: 6000, 120: 500, 121: 500}
PEN_UP = ["M3S50\n", "G4P0.1\n"]
_names = itertools.count()


def open_device(device: SimulatedGrbl, baud: int = 115200) -> serial.SerialBase:
    url = attach_device(device, f"stream{next(_names)}")
    return serial.serial_for_url(url, baudrate=baud)


def square_program(count: int, dt: float = 0.01, size: float = 20.0) -> list[str]:
    """A pen-down job of ``count`` inverse-time setpoint lines going around a circle."""
    lines = ["G21\n", "G90\n", "G94\n", "M3S30\n", "G4P0.1\n", "G93\n"]
    for k in range(1, count + 1):
        angle = 2 * math.pi * k / 400
        x = 50 + size * math.cos(angle) + 0.001 * (k // 400)
        y = 50 + size * math.sin(angle)
        lines.append(f"G1X{x:.3f}Y{y:.3f}F{60 / dt:.0f}\n")
    return [*lines, "G94\n", *PEN_UP, "M5\n", "M2\n"]


class Wire:
    """A trace hook recording the bytes on the wire and firing an action at the n-th line."""

    def __init__(self) -> None:
        self.tx: list[bytes] = []
        self.rx: list[bytes] = []
        self.at: dict[int, object] = {}
        self.lines = 0

    def __call__(self, direction: str, data: bytes) -> None:
        if direction == "rx":
            self.rx.append(data)
            return
        self.tx.append(data)
        if data.endswith(b"\n"):
            self.lines += 1
            action = self.at.pop(self.lines, None)
            if action is not None:
                action()

    def lines_sent(self) -> list[bytes]:
        return [d for d in self.tx if d.endswith(b"\n")]


def connected(device: SimulatedGrbl, **options) -> tuple[serial.SerialBase, GrblStreamer, Wire]:
    port = open_device(device)
    wire = Wire()
    streamer = GrblStreamer(port, StreamOptions(**options), trace=wire)
    streamer.connect()
    return port, streamer, wire


def test_character_counting_streams_a_job_acknowledged_in_order():
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, _ = connected(device)
    lines = square_program(2000)
    try:
        seen = []
        report = streamer.stream(lines, progress=lambda done, total: seen.append((done, total)))
    finally:
        port.close()
    assert report.lines_sent == report.lines_acknowledged == len(lines)
    assert report.errors == [] and report.stopped_at is None
    assert report.max_outstanding <= 127 and device.lost_bytes == 0
    # Progress counts executed lines (from the status reports), never backwards.
    assert seen[-1] == (len(lines), len(lines)) and len(seen) > 10
    assert all(a[0] < b[0] for a, b in itertools.pairwise(seen))
    # 2000 lines of 10 ms: Grbl keeps up, within a few percent.
    assert 20.0 < report.duration < 21.5
    assert device.state == State.IDLE and device.starvation == []
    assert device.position_mm[:2] == pytest.approx((50 + 20 + 0.005, 50), abs=0.02)
    assert 60 < len(report.statuses) <= 5 * report.duration + 2  # polled at <= 5 Hz


def test_send_and_wait_starts_sooner_but_is_slower_with_a_late_host():
    """As on the reference firmware (shortsegs logs: send-and-wait 16 ms sooner than character
    counting with a host that keeps up, 1.1 s later with a host 5 ms late a line of 3 ms):
    counting fills the receive buffer, so the planner fills before motion starts."""
    lines = square_program(300)
    durations = {}
    for mode, latency in (("count", 0.0), ("wait", 0.0), ("wait", 0.015)):
        device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
        port, streamer, _ = connected(device, mode=mode)
        port.write_latency = latency
        try:
            report = streamer.stream(lines)
        finally:
            port.close()
        assert report.lines_acknowledged == len(lines)
        durations[mode, latency] = report.duration
        if mode == "wait":
            assert report.max_outstanding == max(len(line) for line in lines)
        if latency == 0:
            assert device.starvation == []  # at 115200 baud even one line at a time keeps up
    fill = 17 * max(len(line) for line in lines) * READ_TIME  # G93 and 16 moves, read
    assert 0 < durations["count", 0.0] - durations["wait", 0.0] <= fill
    assert durations["wait", 0.015] > durations["count", 0.0] + 0.5  # 15 ms late a 10 ms line


def test_error_mid_job_stops_at_the_exact_line_and_sends_nothing_after():
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    lines = square_program(1000)
    device.inject_error(device.lines_received + 500, 22)
    try:
        with pytest.raises(DeviceFault) as caught:
            streamer.stream(lines, pen_up=PEN_UP)
    finally:
        port.close()
    report = streamer.last_report
    assert report.stopped_at == 499 and report.lines_acknowledged == 499
    # Named: the last line the machine executed (the planner still held the lines before 500,
    # which the reset discarded), and the refused line.
    executed = report.lines_executed
    assert 499 - 15 - 8 <= executed < 499
    assert str(caught.value) == (
        f"after line {executed} (the last line the machine executed; resume with --resume-from "
        f"{executed + 1} --position-known): error:22 (undefined feed rate) for"
        f" {lines[499].strip()!r} (line 500)"
    )
    # Nothing of the program after what was already in flight (<= 127 bytes) when it failed:
    after = wire.lines_sent()[report.lines_sent + 2 :]  # +2: $$ and $I of the handshake
    assert [line.decode() for line in after] == [line for line in PEN_UP]
    assert report.lines_sent - 500 <= 127 // min(len(line) for line in lines[6:])
    # Safe: stopped (hold, then reset), pen up, not in alarm.
    assert device.state == State.IDLE
    pen = device.trace()[-1, 4]
    assert pen == 0.0


@pytest.mark.parametrize(
    ("fault", "error", "message"),
    [
        ("alarm", DeviceFault, r"ALARM:1 \(hard limit triggered"),
        ("silence", DeviceTimeout, r"no answer from the device for 0.5 s"),
        ("garbage", ConnectionLost, r"unexpected bytes from the device"),
        ("drop", ConnectionLost, r"port failed|cannot write"),
    ],
)
def test_device_faults_end_in_a_safe_stop(fault, error, message):
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device, silence_timeout=0.5)
    lines = square_program(1000)
    actions = {
        "alarm": lambda: device.schedule_alarm(device.now + 0.2, 1),
        "silence": lambda: device.go_silent(),
        "garbage": lambda: device.emit_garbage(b"\x00\xff#garbage\r\n"),
        "drop": lambda: device.drop_connection(),
    }
    wire.at[wire.lines + 400] = actions[fault]
    try:
        with pytest.raises(error, match=message) as caught:
            streamer.stream(lines, pen_up=PEN_UP)
    finally:
        port.close()
    report = streamer.last_report
    assert caught.value.where and caught.value.where.startswith(("line ", "after line "))
    sent_lines = report.lines_sent
    assert 390 <= sent_lines < 460  # stopped at once: at most a buffer's worth in flight
    if fault == "alarm":
        assert device.state == State.ALARM  # stopped and locked by the machine itself, left so
        assert wire.lines_sent()[-1].startswith(b"G1")  # no pen command in Alarm (error:9)
    elif fault == "silence":
        assert report.duration > 0.5
    if fault in ("alarm", "garbage"):
        assert device.executor.idle


def test_ctrl_c_holds_lifts_the_pen_and_re_raises():
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)

    def interrupt() -> None:
        raise KeyboardInterrupt

    wire.at[wire.lines + 300] = interrupt
    try:
        with pytest.raises(KeyboardInterrupt):
            streamer.stream(square_program(1000), pen_up=PEN_UP)
    finally:
        port.close()
    assert device.state == State.IDLE  # the hold completed before the reset: no alarm
    assert bytes([Realtime.FEED_HOLD]) in wire.tx and bytes([Realtime.SOFT_RESET]) in wire.tx
    assert device.trace()[-1, 4] == 0.0  # pen up
    assert streamer.last_report.errors[0].startswith("interrupted after line ")


def test_hold_and_resume_keep_the_job_going():
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    connect_rx = b"".join(wire.rx)
    lines = square_program(600)
    events: dict[str, float] = {}

    def progress(done: int, total: int) -> None:
        if done >= 200 and "hold" not in events:
            streamer.hold()
            events["hold"] = streamer.clock.now()

    def resume_later(direction: str, data: bytes) -> None:
        wire(direction, data)
        held = events.get("hold")
        if held is not None and "resume" not in events and streamer.clock.now() > held + 1.5:
            streamer.resume()  # as another thread would: queued, sent by the stream loop
            events["resume"] = streamer.clock.now()

    streamer._trace = resume_later
    try:
        report = streamer.stream(lines, progress=progress)
    finally:
        port.close()
    assert report.lines_acknowledged == len(lines) and report.errors == []
    assert any(s.state == State.HOLD and s.substate == 0 for _, s in report.statuses)
    # The machine stood still while held, then went on: the job took the hold's time longer.
    trace = device.trace()
    still = trace[(trace[:, 0] > events["hold"] + 0.5) & (trace[:, 0] < events["resume"])]
    assert len(still) > 500 and np.ptp(still[:, 1]) == 0 and np.ptp(still[:, 2]) == 0
    assert report.duration > 6.0 + 1.5
    # Asked for: one pause from the "!" sent to the "~" sent, not a hold from outside.
    assert report.pauses == 1 and report.outside_holds == 0 and report.warnings == []
    ((start, length),) = report.pause_spans
    assert events["hold"] <= start < events["resume"] <= start + length
    assert report.paused_s == length < report.duration
    # The trace hook saw every byte received: the banner at connect, an ok per line streamed.
    assert b"Grbl 1.1" in connect_rx
    received = b"".join(wire.rx)[len(connect_rx) :]
    assert received.count(b"ok\r\n") == len(lines)


def test_handshake_policies():
    device = SimulatedGrbl(SETTINGS, start_in_alarm=True)
    port = open_device(device)
    try:
        with pytest.raises(DeviceFault, match="Alarm"):
            GrblStreamer(port).connect()
        streamer = GrblStreamer(port, StreamOptions(unlock="unlock"))
        settings = streamer.connect()
        assert settings[110] == 6000 and settings[120] == 500
        assert streamer.query_state().state == State.IDLE
    finally:
        port.close()
    silent = SimulatedGrbl(SETTINGS)
    silent.read()  # its boot banner is gone; it answers nothing, not even a reset
    silent.go_silent()
    port = open_device(silent)
    try:
        with pytest.raises(DeviceTimeout, match=r"no Grbl (welcome )?banner within 1 s"):
            GrblStreamer(port, StreamOptions(welcome_timeout=1.0)).connect()
    finally:
        port.close()


def test_boot_noise_before_the_banner_is_ignored():
    device = SimulatedGrbl(SETTINGS)
    device.emit_garbage(b"\xf0\x0f noise\r\n")
    port = open_device(device)
    try:
        settings = GrblStreamer(port, StreamOptions(reset=False)).connect()
    finally:
        port.close()
    assert settings[100] == 80


def test_options_are_checked():
    for bad in ({"mode": "fast"}, {"poll_rate": 10}, {"unlock": "always"}, {"rx_buffer": 1}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            StreamOptions(**bad)


def test_a_line_filling_the_receive_buffer_less_one_byte_is_the_longest_sent():
    """At most rx_buffer - 1 unacknowledged bytes go out: a line of exactly that length (its
    newline counted) is streamed; one byte more is refused before anything is sent."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device, rx_buffer=24)
    longest = "G1X1.00000000000Y2F600\n"
    assert len(longest) == 23
    try:
        before = len(wire.lines_sent())
        with pytest.raises(ValueError, match=r"longer than Grbl's receive buffer: 'G1X1\.00000"):
            streamer.stream(["G21\n", "G90\n", longest.replace("X1.0", "X1.00"), "M2\n"])
        assert len(wire.lines_sent()) == before
        report = streamer.stream(["G21\n", "G90\n", longest, "M2\n"])
    finally:
        port.close()
    assert report.lines_acknowledged == 4 and report.errors == []
    assert device.position_mm[:2] == pytest.approx((1.0, 2.0))


def test_a_slow_line_starves_the_planner_and_the_simulator_counts_it():
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port = open_device(device, baud=9600)  # ~27 ms per line, for 10 ms of motion each
    try:
        streamer = GrblStreamer(port)
        streamer.connect()
        streamer.stream(square_program(200))
    finally:
        port.close()
    assert len(device.starvation) > 20


def test_a_link_too_slow_for_two_queued_blocks_starves_at_nearly_every_line():
    """At 2400 baud a 10 ms line takes ~90 ms to arrive: the machine comes to rest after each
    one, so the planner never holds two blocks. Every rest counts (only the few lines read
    during the pen's dwell flow on), and the streamer's stall spans, from Idle reports, are
    no more than the simulator saw."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port = open_device(device, baud=2400)
    lines = square_program(30)
    try:
        streamer = GrblStreamer(port)
        streamer.connect()
        report = streamer.stream(lines, drawing=[line.startswith("G1") for line in lines])
    finally:
        port.close()
    assert 20 <= len(device.starvation) <= 29
    assert 1 <= len(report.stall_spans) <= len(device.starvation)


def test_strokes_ending_before_their_pen_up_line_arrives_are_not_starvation():
    """One-line strokes over a slow link: each stroke is at rest before its pen-up line is
    read, but that stop is the one the program asks for."""
    lines = ["G21\n", "G90\n", "G94\n"]
    for k in range(8):
        lines += [f"G0X{10 + 5 * k}Y10\n", "M3S30\n", "G4P0.1\n", f"G1X{10 + 5 * k}Y10.02F6000\n"]
        lines += PEN_UP
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port = open_device(device, baud=2400)
    try:
        streamer = GrblStreamer(port)
        streamer.connect()
        report = streamer.stream([*lines, "M5\n", "M2\n"])
    finally:
        port.close()
    assert report.errors == [] and device.position_mm[:2] == pytest.approx((45, 10.02), abs=0.01)
    assert device.starvation == []


def test_resume_preamble_recreates_modal_state_and_position():
    lines = square_program(50)
    preamble = resume_lines(lines, 20, PEN_UP, ["M3S30\n", "G4P0.1\n"])
    x, y = lines[19][3:].split("F")[0].split("Y")
    assert preamble == [
        "G21\n",
        "G90\n",
        "G94\n",
        *PEN_UP,
        f"G0X{lines[19].split('X')[1].split('Y')[0]}Y{y}\n",
        "M3S30\n",
        "G4P0.1\n",
        "G93\n",
    ]
    assert x  # the X word was there
    start = resume_lines(lines, 2, PEN_UP, ["M3S30\n"])
    assert "M3S30\n" not in start and "G93\n" not in start  # pen still up, still G94
    with pytest.raises(ValueError, match="resume line"):
        resume_lines(lines, 0, PEN_UP, [])


def test_resumed_job_finishes_where_the_interrupted_one_would_have():
    lines = square_program(400)
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    wire.at[wire.lines + 150] = lambda: device.inject_error(device.lines_received + 1, 20)
    try:
        with pytest.raises(DeviceFault):
            streamer.stream(lines, pen_up=PEN_UP)
        stopped = streamer.last_report.stopped_at
        preamble = resume_lines(lines, stopped, PEN_UP, ["M3S30\n", "G4P0.1\n"])
        report = streamer.stream(lines, first=stopped, preamble=preamble, pen_up=PEN_UP)
    finally:
        port.close()
    assert report.first_line == stopped and report.lines_acknowledged == len(lines) - stopped
    assert device.position_mm[:2] == pytest.approx((70.0, 50.0), abs=0.02)


def test_a_100000_line_job_is_acknowledged_and_executed_once_in_order():
    count = 100_000
    lines = ["G21\n", "G90\n", "G91\n", "G93\n"]
    # Relative moves with distinct step counts, so each executed block is identifiable.
    lines += [f"G1X{0.0125 * (1 + k % 3):.4f}Y0.0125F6000\n" for k in range(count)]
    lines += ["G94\n", "G90\n"]
    device = SimulatedGrbl(SETTINGS)
    port, streamer, _ = connected(device)
    try:
        report = streamer.stream(lines)
    finally:
        port.close()
    assert report.lines_sent == report.lines_acknowledged == len(lines)
    assert device.lost_bytes == 0 and device.starvation == []
    steps = sum(1 + k % 3 for k in range(count))
    assert device.position_mm[:2] == pytest.approx((steps / 80, count / 80), abs=1e-9)
    _, positions = device.executor.recorder.knots()
    knots = np.round(positions[:, :2] * 80).astype(int)
    targets = np.column_stack([np.cumsum(1 + np.arange(count) % 3), np.arange(1, count + 1)])
    # Each line's target was reached, in order, once: the path never goes back and passes
    # through every target; the end position rules out a line executed twice.
    assert np.all(np.diff(knots, axis=0) >= 0)
    visited = {tuple(k) for k in knots.tolist()}
    assert all(tuple(t) in visited for t in targets.tolist())
    assert report.duration == pytest.approx(count * 0.01, rel=0.1)  # 1-3 step moves: Grbl lags


def test_streaming_over_a_pseudo_terminal():
    device = SimulatedGrbl(SETTINGS, clock="real", pen_servo=(30, 50))
    path, stop = serve_pty(device)
    try:
        with serial.Serial(path, 115200, timeout=0.01) as port:
            streamer = GrblStreamer(port)
            assert streamer.connect()[110] == 6000
            lines = square_program(100, dt=0.01)
            report = streamer.stream(lines)
    finally:
        stop()
    assert report.lines_acknowledged == len(lines)
    assert 0.9 < report.duration < 3.0
    assert device.position_mm[:2] == pytest.approx((50 + 20 * math.cos(math.pi / 2), 70), abs=0.02)
