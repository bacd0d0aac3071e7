"""The AxiDraw makers' own host library, ``plotink``, drives the simulated EBB over a real
pseudo-terminal without an error: its firmware-3 class (``ebb3_serial``/``ebb3_motion``, future
syntax) and its legacy functions (``ebb_serial``/``ebb_motion``, legacy replies) read every
reply as they read the board's. Only port discovery (by USB identity) is bypassed."""

from __future__ import annotations

import logging

import pytest
from plotink import ebb3_motion, ebb3_serial, ebb_motion, ebb_serial

from sim.ebb.device import SimulatedEBB
from sim.ebb.transport import serve_pty


@pytest.fixture
def board():
    device = SimulatedEBB(clock="real")
    path, stop = serve_pty(device)
    try:
        yield device, path
    finally:
        stop()


@pytest.fixture
def no_usb_scan(monkeypatch):
    """plotink finds the board by its USB identity; here the port is named directly."""
    monkeypatch.setattr(ebb3_serial, "find_named", lambda name=None: name)


def test_plotink_ebb3_connects_and_reads_the_nickname(board, no_usb_scan):
    device, path = board
    device.nickname = b"East EBB"  # as ST stored it in flash
    ebb = ebb3_motion.EBBMotionWrap()
    try:
        assert ebb.connect(path, caller="tests"), ebb.err
        assert ebb.err is None and ebb.name == "East EBB"
        assert ebb.write_nickname("tagbot-1")  # ST in the future syntax
        ebb.query_nickname()
        assert ebb.name == "tagbot-1" and device.nickname == b"tagbot-1"
        assert ebb.query("QR") in ("0", "1")
        assert ebb.err is None
    finally:
        ebb.disconnect()


def test_plotink_ebb3_drives_the_board_in_future_syntax(board, no_usb_scan, monkeypatch):
    device, path = board
    ebb = ebb3_motion.EBBMotionWrap()
    try:
        assert ebb.connect(path, caller="tests"), ebb.err
        assert ebb.version == device.version and ebb.min_version(ebb.MIN_VERSION_STRING)
        assert device.future_syntax
        ebb.motors_enable(1, 1)
        assert ebb.motors_query_enabled() == (1, 1)
        ebb.pen_pos_up(20000)
        ebb.pen_pos_down(14000)
        ebb.pen_rate_down(2000)
        ebb.pen_lower(30)
        ebb.xy_move(24, -10, 40)  # SM,40,-10,24
        ebb.clear_accumulators()  # T3,1,0,0,0,0,0,0,3
        ebb.pen_raise(30)
        ebb.abs_move(2000, 5, 5)  # HM: waits for the motion, then goes to (5, 5)
        for _ in range(100_000):  # QG polls, each waiting on its reply
            status = ebb.query_statusbyte()
            if status is not None and status & 0x0F == 0:
                break
        assert status & 0x10  # bit 4: the pen is up
        assert ebb.query_steps() == (5, 5)
        assert ebb.err is None
    finally:
        ebb.disconnect()
    lines = [segment.line for segment in device.recorder.segments]
    assert lines[-5:] == [
        b"SP,0,30",
        b"SM,40,-10,24",
        b"T3,1,0,0,0,0,0,0,3",
        b"SP,1,30",
        b"HM,2000,5,5",
    ]


def test_plotink_legacy_functions_read_the_legacy_replies(board, caplog):
    device, path = board
    caplog.set_level(logging.INFO)
    port = ebb_serial.testPort(path)
    assert port is not None
    try:
        assert ebb_serial.min_version(port, "2.7.0") is True
        ebb_motion.sendEnableMotors(port, 2)
        ebb_motion.doXYMove(port, 12, -7, 30)  # SM,30,-7,12
        ebb_motion.doLowLevelMove(port, 85899346, 10, 0, 17180814, 2, 0)  # reference LM ex. 3
        assert ebb_motion.QueryPRGButton(port).strip() == "0"
        for _ in range(100_000):  # QM polls, each waiting on its reply
            if ebb_serial.query(port, "QM\r").strip() == "QM,0,0,0,0":
                break
        assert ebb_motion.query_steps(port) == (-7 + 10, 12 + 2)
    finally:
        ebb_serial.closePort(port)
    assert [r.getMessage() for r in caplog.records if r.name.startswith("plotink")] == []
    assert device.step_mode == 2
