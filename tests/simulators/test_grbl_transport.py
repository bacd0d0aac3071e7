"""Transports to the simulated Grbl: the ``grblsim://`` pyserial URL handler and the pty server."""

from __future__ import annotations

import math
import os
import select
import time

import pytest
import serial

from sim.grbl.device import SimulatedGrbl
from sim.grbl.transport import attach_device, serve_pty

WELCOME = b"\r\nGrbl 1.1h ['$' for help]\r\n"
PLOTTER = "$100=80&$101=80&$110=6000&$111=6000&$120=1000&$121=1000"
RX_LIMIT = 127  # Grbl's stream.py keeps at most 127 unacknowledged bytes


def open_url(query: str = "", **kwargs) -> serial.SerialBase:
    port = serial.serial_for_url(f"grblsim://?{query}", timeout=1, **kwargs)
    assert port.read(len(WELCOME)) == WELCOME
    return port


def read_answer(port: serial.SerialBase) -> bytes:
    line = port.readline()
    assert line.endswith(b"\r\n"), line
    return line[:-2]


def stream_counted(port: serial.SerialBase, lines: list[bytes]) -> list[bytes]:
    """Grbl's character-counting streaming: unacknowledged bytes stay within the buffer."""
    pending: list[int] = []
    answers: list[bytes] = []
    sent = 0
    while len(answers) < len(lines):
        while sent < len(lines) and sum(pending) + len(lines[sent]) <= RX_LIMIT:
            port.write(lines[sent])
            pending.append(len(lines[sent]))
            sent += 1
        answers.append(read_answer(port))
        pending.pop(0)
    return answers


def test_url_handler_is_a_serialbase():
    port = open_url()
    try:
        assert isinstance(port, serial.SerialBase)
        assert isinstance(port.device, SimulatedGrbl)
        port.write(b"$$\n")
        listing = port.read_until(b"ok\r\n").decode().split("\r\n")
        assert listing[0] == "$0=10" and listing[-2] == "ok"
    finally:
        port.close()


def test_url_options_and_errors():
    port = open_url("speed=9600&$110=6000&alarm=1")
    try:
        assert port.read_until(b"\r\n") == b"[MSG:'$H'|'$X' to unlock]\r\n"
        port.write(b"$$\n")
        assert b"$110=6000.000\r\n" in port.read_until(b"ok\r\n")
    finally:
        port.close()
    with pytest.raises(serial.SerialException, match="unknown option"):
        serial.serial_for_url("grblsim://?colour=red")
    with pytest.raises(serial.SerialException, match="no device attached"):
        serial.serial_for_url("grblsim://nobody")


def test_baud_rate_limits_delivery():
    slow = open_url("speed=9600")
    fast = open_url("speed=115200")
    try:
        for port, baud in ((slow, 9600), (fast, 115200)):
            port.device.advance(0.1)
            start = port.device.now
            port.write(b"$$\n")
            answer = port.read_until(b"ok\r\n")
            elapsed = port.device.now - start
            # 10 bits a byte, 3 bytes sent then the answer, within one poll step (1 ms).
            expected = (3 + len(answer)) * 10 / baud
            assert expected <= elapsed < expected + 0.0011
        assert len(answer) > 300
    finally:
        slow.close()
        fast.close()


def test_1000_line_stream_acknowledged_in_order_and_executed():
    port = open_url(PLOTTER)
    try:
        targets = [(20 + 10 * math.cos(i / 40), 20 + 10 * math.sin(i / 40)) for i in range(1, 1001)]
        lines = [f"G1X{x:.3f}Y{y:.3f}F3000\n".encode() for x, y in targets]
        assert stream_counted(port, lines) == [b"ok"] * 1000
        assert port.device.lost_bytes == 0
        assert port.device.run_until_idle()
        x, y = (round(v, 3) for v in targets[-1])
        trace = port.device.trace()
        assert trace[-1, 1:3] == pytest.approx((x, y), abs=1 / 80 + 1e-9)
        port.write(b"?")
        status = read_answer(port).decode()
        assert status.startswith("<Idle|MPos:")
    finally:
        port.close()


def test_flooding_without_counting_loses_bytes():
    port = open_url(PLOTTER)
    try:
        lines = [f"G1X{i % 50}Y{i % 7}F300\n".encode() for i in range(200)]
        port.write(b"".join(lines))
        answers = []
        while True:
            line = port.readline()
            if not line:
                break
            answers.append(line)
        assert port.device.lost_bytes > 0
        assert len(answers) < len(lines)
    finally:
        port.close()


def test_realtime_status_with_full_buffer_over_url():
    port = open_url(PLOTTER + "&$10=3")
    try:
        lines = [f"G1X{i}F300\n".encode() for i in range(1, 40)]
        port.write(b"".join(lines))
        port.flush()
        assert port.device.lost_bytes > 0
        port.reset_input_buffer()
        port.write(b"?")
        status = port.read_until(b">\r\n").decode()
        assert status.startswith("<Run|") and "|Bf:0,0|" in status
        port.write(b"!")
        port.read(100)  # 1 s of simulated time: the hold completes
        port.reset_input_buffer()
        port.write(b"?")
        assert port.read_until(b">\r\n").startswith(b"<Hold:0|")
    finally:
        port.close()


def test_attached_device_fault_hooks_over_url():
    device = SimulatedGrbl()
    device.inject_error(1, 20)
    url = attach_device(device, "faulty")
    port = serial.serial_for_url(url, timeout=0.5)
    try:
        assert port.device is device
        assert port.read(len(WELCOME)) == WELCOME
        port.write(b"G21\nG21\n")
        assert [read_answer(port), read_answer(port)] == [b"error:20", b"ok"]
        device.go_silent()
        port.write(b"?")
        assert port.read(10) == b""
        device.go_silent(False)
        device.emit_garbage(b"\x00\xff")
        assert port.read(2) == b"\x00\xff"
        device.drop_connection()
        with pytest.raises(serial.SerialException, match="dropped"):
            port.read(1)
        with pytest.raises(serial.SerialException, match="dropped"):
            port.write(b"?")
    finally:
        port.close()


def test_scheduled_alarm_over_url():
    port = open_url(PLOTTER)
    try:
        port.device.schedule_alarm(port.device.now + 0.05, 2)
        port.write(b"G1 X100 F3000\n")
        assert read_answer(port) == b"ok"
        assert read_answer(port) == b"ALARM:2"
        assert read_answer(port) == b"[MSG:Reset to continue]"
    finally:
        port.close()


def _opened(path: str) -> serial.Serial:
    """The pty opened as a host opens a Grbl's port, with its banner read. pyserial's open
    discards what is waiting, and the simulator booted before the port was opened (a real Grbl
    reboots as the port opens): wait for the boot banner, open, then soft-reset and read the
    banner that follows, whatever the host's speed."""
    probe = os.open(path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        ready, _, _ = select.select([probe], [], [], 10)
    finally:
        os.close(probe)
    assert ready, "the simulated Grbl printed no banner at boot"
    port = serial.Serial(path, 115200, timeout=10)  # busy hosts: data ends waits
    try:
        port.write(b"\x18")
        assert port.read(len(WELCOME)) == WELCOME
    except BaseException:
        port.close()
        raise
    return port


def _open_fds() -> set[str]:
    return set(os.listdir("/proc/self/fd")) if os.path.isdir("/proc/self/fd") else set()


def test_pty_end_to_end_with_a_real_serial_port():
    before = _open_fds()
    device = SimulatedGrbl(clock="real")
    path, stop = serve_pty(device)
    try:
        with _opened(path) as port:
            port.write(b"$$\n")
            listing = port.read_until(b"ok\r\n").decode().split("\r\n")
            assert listing[0] == "$0=10" and "$11=0.010" in listing and listing[-2] == "ok"
            port.write(b"$110=6000\n$120=1000\n")
            assert [read_answer(port), read_answer(port)] == [b"ok", b"ok"]
            lines = [f"G1X{i}Y{i / 2:.1f}F6000\n".encode() for i in range(1, 6)]
            assert stream_counted(port, lines) == [b"ok"] * 5
            port.write(b"?")
            assert port.read_until(b">\r\n").startswith(b"<")
    finally:
        stop()
        stop()  # idempotent
    with device.lock:
        device.run_until_idle()
        assert device.position_mm[:2] == pytest.approx((5.0, 2.5), abs=0.01)
    assert _open_fds() == before


def test_pty_drop_connection():
    before = _open_fds()
    device = SimulatedGrbl(clock="real")
    path, stop = serve_pty(device)
    try:
        with _opened(path) as port:
            device.drop_connection()
            with pytest.raises(serial.SerialException):
                port.read(1)
    finally:
        stop()
    assert _open_fds() == before


def test_pty_needs_a_real_time_device():
    with pytest.raises(ValueError, match="clock"):
        serve_pty(SimulatedGrbl())


def test_polling_in_waiting_moves_simulated_time():
    port = open_url(baudrate=115200)
    try:
        port.write(b"G4 P0.2\n")
        start = port.device.now
        polls = 0
        while not port.in_waiting:
            polls += 1
        assert port.read(port.in_waiting) == b"ok\r\n"
        assert port.device.now - start == pytest.approx(0.2 + 12 * 10 / 115200, abs=0.0011)
        assert polls >= 150
    finally:
        port.close()


# -- host-side timing fault hooks ------------------------------------------------------------------


def short_segments(n: int) -> list[bytes]:
    return [
        f"G1X{20 * math.cos(k / 40):.3f}Y{20 * math.sin(k / 40):.3f}F6000\n".encode()
        for k in range(n)
    ]


def test_freeze_host_lets_the_device_run_alone():
    port = open_url(PLOTTER)
    try:
        port.write(b"G1 X10 F3000\n")
        start = port.device.now
        port.freeze_host(start + 0.05, 0.5)
        assert port.out_waiting == 13  # before `at`: no freeze yet
        assert port.device.now == start
        port.clock.sleep_until(start + 0.05)
        assert port.in_waiting == 4  # the host comes back after 0.5 s; the ok is there
        assert port.device.now == pytest.approx(start + 0.55)
        assert port.device.position_mm[0] > 5  # the machine ran meanwhile
        assert port.in_waiting == 4 and port.device.now == pytest.approx(start + 0.55)  # once
        with pytest.raises(ValueError):
            port.freeze_host(0.0, -1.0)
    finally:
        port.close()


@pytest.mark.parametrize("pause", [0.0, 0.5])
def test_a_host_pause_starves_the_planner(pause):
    port = open_url(PLOTTER, baudrate=115200)
    try:
        if pause:
            port.freeze_host(port.device.now + 0.5, pause)
        assert stream_counted(port, short_segments(300)) == [b"ok"] * 300
        port.device.run_until_idle()
        assert bool(port.device.starvation) == bool(pause)
    finally:
        port.close()


@pytest.mark.parametrize("latency", [0.0, 0.016])
def test_write_latency_delays_what_the_host_sends(latency):
    port = open_url(baudrate=115200)
    try:
        assert port.write_latency == 0.0
        port.write_latency = latency
        start = port.device.now
        port.write(b"?")
        answer = port.readline()
        assert answer.startswith(b"<Idle|")
        # The byte after the latency, the report's bytes back, read in 1 ms steps.
        expected = latency + (1 + len(answer)) * 10 / 115200
        assert expected <= port.device.now - start < expected + 0.0011
        port.write(b"G4 P0.1\n")
        port.flush()  # waits until the device has the bytes: latency included
        assert port.out_waiting == 0
    finally:
        port.close()


def test_pty_write_latency():
    device = SimulatedGrbl(clock="real")
    path, stop = serve_pty(device, write_latency=0.2)
    try:
        with _opened(path) as port:
            port.write(b"?")
            sent = time.monotonic()
            assert port.read_until(b">\r\n").startswith(b"<Idle|")
            # The latency is a floor at any host speed; a busy host may add any delay on top, so
            # no upper bound is asserted (one of 1.5 s flaked on a loaded 2-core host).
            assert time.monotonic() - sent >= 0.2
    finally:
        stop()
    with pytest.raises(ValueError):
        serve_pty(SimulatedGrbl(clock="real"), write_latency=-1.0)
