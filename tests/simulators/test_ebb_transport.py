"""Transports to the simulated EBB: the ``ebbsim://`` URL in simulated time, its fault hooks, the
real-time pseudo-terminal and ``tagbot sim axidraw``."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest
import serial
from click.testing import CliRunner

import tagbot.axidraw.sim_cli as ebb_cli
from firmware_protocols.ebb.motion import TICK_HZ
from sim.ebb import transport
from sim.ebb.device import DEFAULT_COMMAND_TIME, FIFO_MAX, SimulatedEBB
from sim.ebb.transport import attach_device, serve_pty

OK = b"OK\r\n"
V3 = b"EBBv13_and_above EB Firmware Version 3.0.3\r\n"
LT_TICKS = 2500  # 0.1 s
LT_RATE = 85899346  # just above 2**31 / 25: 1000 steps/s, 100 steps per move on motor 1
LT_RATE2 = 42949673  # 500 steps/s on motor 2: 50 steps per move
AFTER_ONE = b"100,50\n\rOK\r\n"  # QS after one move (and within the next one's first ticks)


def open_url(url: str = "ebbsim://") -> serial.SerialBase:
    return serial.serial_for_url(url, timeout=1)


def ask(port: serial.SerialBase, line: bytes, ending: bytes = OK) -> bytes:
    """Send ``line`` and read its reply through ``ending``."""
    port.write(line)
    reply = port.read_until(ending)
    assert reply.endswith(ending), (line, reply)
    return reply


def lt() -> bytes:
    return f"LT,{LT_TICKS},{LT_RATE},0,{LT_RATE2},0\r".encode()


def test_url_port_answers_in_legacy_mode_after_the_command_time():
    port = open_url()
    try:
        assert isinstance(port, serial.SerialBase) and isinstance(port.device, SimulatedEBB)
        assert ask(port, b"V\r", b"\r\n") == V3
        # The reply to a query cannot arrive before the board has processed the line.
        start = port.clock.now()
        assert ask(port, b"QS\r") == b"0,0\n\rOK\r\n"
        assert port.clock.now() - start >= port.device.other_command_time
        assert ask(port, b"QM\r", b"\n\r") == b"QM,0,0,0,0\n\r"
        assert ask(port, b"QU,2\r") == f"QU,{FIFO_MAX}\r\nOK\r\n".encode()
        assert ask(port, b"ZZ\r", b"\r\n").startswith(b"!8 Err: Unknown command 'ZZ:5A5A'")
    finally:
        port.close()


def test_url_options_and_errors():
    port = open_url("ebbsim://?version=2.8.1")
    try:
        assert ask(port, b"V\r", b"\r\n") == b"EBBv13_and_above EB Firmware Version 2.8.1\r\n"
    finally:
        port.close()
    for url, message in [
        ("ebbsim://?speed=9", "unknown option 'speed'"),
        ("ebbsim://?version=three", "version"),
        ("ebbsim://nobody", "no device attached as 'nobody'"),
    ]:
        with pytest.raises(serial.SerialException, match=message):
            open_url(url)
    device = SimulatedEBB()
    attach_device(device, "board")
    with pytest.raises(serial.SerialException, match="options only apply to a new device"):
        open_url("ebbsim://board?version=3.0.3")
    with pytest.raises(ValueError, match="name"):
        attach_device(device, "not a name")


def test_a_motion_line_finding_the_fifo_full_is_answered_when_there_is_room():
    """Depth 1 at boot: one move executing, one in the FIFO, the third line waits in the parser
    (no OK, and no answer to anything after it) until the first move ends."""
    port = open_url()
    try:
        answered = []
        port.write(lt() * 3 + b"QS\r")
        for _ in range(3):
            assert port.read_until(OK) == OK
            answered.append(port.clock.now())
        first_end = port.device.recorder.segments[0].end_tick / TICK_HZ
        assert answered[1] < LT_TICKS / TICK_HZ / 2  # the second went into the FIFO at once
        assert answered[2] >= first_end  # the third waited for the first move to end
        # QS was processed just after the third move went in: the first move is done.
        assert port.read_until(OK) == AFTER_ONE
    finally:
        port.close()


def test_a_deeper_fifo_takes_the_moves_at_the_parsers_pace():
    port = open_url()
    try:
        assert ask(port, b"CU,4,3\r") == OK
        assert ask(port, b"QU,3\r") == b"QU,3\r\nOK\r\n"
        start = port.clock.now()
        port.write(lt() * 4)
        for _ in range(4):
            assert port.read_until(OK) == OK
        # Four lines at the board's documented LT processing time, far less than one move.
        elapsed = port.clock.now() - start
        assert 4 * DEFAULT_COMMAND_TIME["LT"] <= elapsed < LT_TICKS / TICK_HZ
        assert ask(port, b"QM\r", b"\n\r") == b"QM,1,1,1,1\n\r"
        assert ask(port, b"QU,6\r") == b"QU,3\r\nOK\r\n"  # firmware: ebb_print_uint, unpadded
    finally:
        port.close()


def streamed_load_ticks(ticks_per_move: int, count: int = 12) -> list[int]:
    """Stream ``count`` identical LM moves as fast as the board takes them (FIFO at its boot
    depth): the tick each was loaded on, and the tick the last one ended."""
    steps = ticks_per_move // 5
    device = SimulatedEBB()
    with open_url(attach_device(device, "board")) as port:
        port.write(f"LM,{2**31 // 5 + 1},{steps},0,0,0,0\r".encode() * count)
        for _ in range(count):
            assert port.read_until(OK) == OK
        port.clock.sleep_until(port.clock.now() + 2 * count * ticks_per_move / TICK_HZ)
    segments = device.recorder.moves()
    assert [s.ticks for s in segments] == [ticks_per_move] * count
    return [s.load_tick for s in segments] + [segments[-1].end_tick]


def test_streamed_moves_have_no_gaps_only_when_longer_than_the_boards_parse_time():
    """Reference "Performance": LM moves streamed back to back run without gaps only if each
    lasts at least the board's time to parse and queue one (4 ms for LM on firmware 3.0)."""
    parse_ticks = round(DEFAULT_COMMAND_TIME["LM"] * TICK_HZ)
    loads = streamed_load_ticks(parse_ticks + 25)  # 5 ms moves: end to end
    assert set(np.diff(loads)) == {parse_ticks + 25}
    loads = streamed_load_ticks(parse_ticks - 25)  # 3 ms moves: one each 4 ms, idle between
    assert set(np.diff(loads[:-1])) <= {parse_ticks, parse_ticks + 1}


def test_a_usb_stall_holds_replies_while_the_motors_run():
    port = open_url()
    try:
        assert ask(port, lt()) == OK
        stall_from = port.clock.now()
        port.device.stall_usb(stall_from, 0.5)
        port.write(b"QS\r")
        port.timeout = 0.4
        assert port.read(4) == b""  # nothing crosses the bus for 0.5 s
        port.timeout = 1
        reply = port.read_until(OK)
        assert reply == AFTER_ONE  # asked after the stall: the move had ended
        assert port.clock.now() >= stall_from + 0.5
    finally:
        port.close()


def test_a_board_reset_drops_the_port_and_boots_again():
    device = SimulatedEBB()
    port = open_url(attach_device(device, "board"))
    try:
        assert ask(port, b"CU,4,8\r") == OK
        for _ in range(4):
            assert ask(port, lt()) == OK
        device.reset_board(port.clock.now() + 0.15)
        with pytest.raises(serial.SerialException, match="off the USB"):
            port.read(1000)  # waits past the reset
    finally:
        port.close()
    moves = device.recorder.moves()
    # The move running at the reset stopped part way, the rest were lost.
    assert [m.ticks for m in moves[:-1]] == [LT_TICKS] and 0 < moves[-1].ticks < LT_TICKS
    assert device.motor_position() == tuple(moves[-1].positions()[-1])
    port = open_url(attach_device(device, "board"))
    try:
        assert ask(port, b"V\r", b"\r\n") == V3
        assert ask(port, b"QS\r") == b"0,0\n\rOK\r\n"
        assert ask(port, b"QU,3\r") == b"QU,1\r\nOK\r\n"
        assert ask(port, b"QM\r", b"\n\r") == b"QM,0,0,0,0\n\r"
    finally:
        port.close()


def test_the_prg_button_latches_until_qb_reads_it():
    device = SimulatedEBB()
    port = open_url(attach_device(device, "board"))
    try:
        device.press_button(0.5)
        assert ask(port, b"QB\r") == b"0\r\nOK\r\n"
        port.clock.sleep_until(0.6)
        assert ask(port, b"QB\r") == b"1\r\nOK\r\n"
        assert ask(port, b"QB\r") == b"0\r\nOK\r\n"
    finally:
        port.close()


def test_a_frozen_host_lets_the_board_run_alone():
    port = open_url()
    try:
        assert ask(port, lt()) == OK
        port.freeze_host(port.clock.now(), 0.3)
        frozen_at = port.clock.now()
        assert ask(port, b"QS\r") == AFTER_ONE
        assert port.clock.now() >= frozen_at + 0.3
    finally:
        port.close()


def talk_real_time(path: str) -> list[bytes]:
    """Over a real pseudo-terminal with pyserial: the version, a short move waited for with QM
    polls (each poll waits on its reply, no sleeps), then QS."""
    replies = []
    with serial.Serial(path, timeout=5) as port:
        port.write(b"V\r")
        replies.append(port.read_until(b"\r\n"))
        port.write(b"LM,85899346,10,0,17180814,2,0\r")  # 10 ms (reference, LM example 3)
        replies.append(port.read_until(OK))
        for _ in range(10_000):
            port.write(b"QM\r")
            status = port.read_until(b"\n\r")
            if status == b"QM,0,0,0,0\n\r":
                break
        replies.append(status)
        port.write(b"QS\r")
        replies.append(port.read_until(OK))
    return replies


def test_pty_serves_pyserial_in_real_time():
    device = SimulatedEBB(clock="real")
    path, stop = serve_pty(device)
    try:
        assert talk_real_time(path) == [V3, OK, b"QM,0,0,0,0\n\r", b"10,2\n\rOK\r\n"]
    finally:
        stop()
    assert [m.line for m in device.recorder.moves()] == [b"LM,85899346,10,0,17180814,2,0"]


def test_serve_pty_needs_a_real_time_device():
    with pytest.raises(ValueError, match="clock='real'"):
        serve_pty(SimulatedEBB())


def test_sim_axidraw_prints_the_path_and_serves_until_interrupted(monkeypatch):
    served: dict[str, object] = {}
    real_serve = transport.serve_pty

    def serve(device):
        path, stop = real_serve(device)
        served["path"] = path
        return path, stop

    def talk_then_interrupt() -> None:
        served["replies"] = talk_real_time(str(served["path"]))
        with serial.Serial(str(served["path"]), timeout=5) as port:
            buttons = []
            for press in (False, True, False):
                if press:
                    os.kill(os.getpid(), signal.SIGUSR1)  # handled before the next line runs
                port.write(b"QB\r")
                buttons.append(port.read_until(OK))
        served["buttons"] = buttons
        raise KeyboardInterrupt

    monkeypatch.setattr(transport, "serve_pty", serve)
    monkeypatch.setattr(ebb_cli, "_wait_for_interrupt", talk_then_interrupt)
    before = signal.getsignal(signal.SIGUSR1)
    result = CliRunner().invoke(ebb_cli.sim_axidraw_command, ["--firmware", "3.0.2"])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines() == [served["path"]]
    replies = served["replies"]
    assert isinstance(replies, list)
    assert replies[0] == b"EBBv13_and_above EB Firmware Version 3.0.2\r\n"
    assert replies[1:] == [OK, b"QM,0,0,0,0\n\r", b"10,2\n\rOK\r\n"]
    assert served["buttons"] == [b"0\r\nOK\r\n", b"1\r\nOK\r\n", b"0\r\nOK\r\n"]
    assert "simulated EBB (firmware 3.0.2) serving" in result.stderr
    assert f"kill -USR1 {os.getpid()} presses its PRG button" in result.stderr
    assert signal.getsignal(signal.SIGUSR1) == before  # restored
    assert result.stderr.splitlines()[-1] == "stopped (Ctrl-C)"


def test_sim_axidraw_refuses_a_bad_firmware_version_in_one_line(capsys):
    from tagbot.cli import main

    assert main(["sim", "axidraw", "--firmware", "three"]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err == (
        "tagbot: error: Invalid value for --firmware: version: expected like '3.0.3', got"
        " 'three' (see 'tagbot sim axidraw --help')\n"
    )
