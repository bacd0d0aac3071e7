"""The simulated Grbl against facts measured on the real Grbl 1.1h firmware (issue 12).

Figures come from ../shared/reference (README.md, "Measured on the real firmware", and the
grbl-1.1h transcripts): G4 dwells wait ``ceil(20·P)`` × 50 ms (``delay_sec``), standstills
around ``G4 P`` of 88 / 86 / 133 / 184 / 335 ms for P = 0.002 / 0.012 / 0.072 / 0.15 / 0.3 s;
line numbers (``Ln:``), ``Bf:`` fields, and the fault hooks a host watchdog is tested with.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.grbl.device import READ_TIME, SimulatedGrbl, avr_read_float, avr_words
from sim.grbl.planner import Dwell

PLOTTER = {100: 80, 101: 80, 102: 80, 110: 6000, 111: 6000, 112: 3000, 120: 1000, 121: 1000}
PLOTTER |= {122: 1000, 11: 0.01, 10: 3}  # setup-plotter.log
WELCOME = b"\r\nGrbl 1.1h ['$' for help]\r\n"
MEASURED_MS = {0.002: 88, 0.012: 86, 0.072: 133, 0.15: 184, 0.3: 335}
OLD_SIMULATOR_MS = {0.002: 27, 0.012: 37, 0.072: 97, 0.15: 175, 0.3: 325}


def booted(**kwargs) -> SimulatedGrbl:
    """Reading bytes takes no time here unless asked (``read_time``): each test isolates its
    fact; the reading itself is checked in :func:`test_the_next_line_is_read_after_a_dwell` and
    tests/plotter/test_read_wait.py."""
    device = SimulatedGrbl(PLOTTER, **{"read_time": 0.0, **kwargs})
    assert device.read().startswith(WELCOME)
    return device


def lines_of(device: SimulatedGrbl) -> list[tuple[float, bytes]]:
    out = []
    for t, chunk in device.read_timed():
        out += [(t, line + b"\n") for line in chunk.split(b"\n")[:-1]]
    return out


def standstill(p: float, read_time: float = 0.0) -> tuple[float, float, float]:
    """``G1 X10``, ``G4 P<p>``, ``G1 X20`` streamed at once: the time the machine stands at
    X10 from the segments' ends (recorder knots) and from ``MPos`` (the step counter), and when
    the dwell's ``ok`` came after the machine arrived."""
    device = booted(read_time=read_time)
    device.write(f"G1 X10 F3000\nG4 P{p}\nG1 X20\n".encode())
    samples = []
    ok_at = None
    while device.busy:
        device.advance(0.0002)
        samples.append((device.now, device.executor.position_steps[0]))
        for t, line in lines_of(device):
            if line == b"ok\r\n":
                ok_at = t  # the last ok: the dwell's (the moves' oks come at once)
    t = np.array([s[0] for s in samples])
    x = np.array([s[1] for s in samples])
    at = np.flatnonzero(x == 800)
    kt, kp = device.executor.recorder.knots()
    k = np.flatnonzero(np.isclose(kp[:, 0], 10.0))
    assert ok_at is not None
    return kt[k[-1]] - kt[k[0]], t[at[-1] + 1] - t[at[0]], ok_at - kt[k[0]]


@pytest.mark.parametrize("p", sorted(MEASURED_MS))
def test_dwell_waits_in_50_ms_steps_after_the_step_idle_delay(p):
    knots, mpos, ok = standstill(p)
    ticks = math.ceil(20 * p - 1e-9)
    # Motion ends, the step interrupt holds the motors for $1 (25 ms), then delay_sec.
    assert knots == pytest.approx(0.025 + 0.050 * ticks, abs=1e-9)
    assert ok == pytest.approx(0.025 + 0.050 * ticks, abs=1e-9)
    # MPos counts each step when computed: the stop's last step shows one step period earlier.
    assert 0 < mpos - knots < 0.005


def test_the_next_line_is_read_after_a_dwell():
    """During the dwell Grbl reads nothing: after it, ``G1 X20`` (7 bytes) is read at 69.4 µs a
    byte before the machine moves on, part of the real standstill's residual."""
    knots, _, ok = standstill(0.15, READ_TIME)
    assert knots == ok == pytest.approx(0.025 + 0.15 + 7 * READ_TIME, abs=1e-9)  # its ok too


def test_standstills_match_the_real_firmware():
    """What the dwell adds is the firmware's: the real standstills minus the simulator's leave
    the same few milliseconds for every P (the slow last and first steps at both ends and the
    next line's transfer, which do not depend on P). The old model (P + $1) did not."""
    residual = {p: MEASURED_MS[p] / 1000 - standstill(p)[1] for p in MEASURED_MS}
    assert max(residual.values()) - min(residual.values()) < 0.006
    assert all(0.0 <= r < 0.013 for r in residual.values())
    old = {p: (MEASURED_MS[p] - OLD_SIMULATOR_MS[p]) / 1000 for p in MEASURED_MS}
    assert max(old.values()) - min(old.values()) > 0.04


@pytest.mark.parametrize(
    ("text", "ticks"),
    [("0", 0), ("0.0001", 1), ("0.05", 1), ("0.051", 2), ("0.15", 3), ("0.3", 6), ("1.15", 23)],
)
def test_dwell_ticks_in_32_bit_floats(text, ticks):
    # 20 × 0.15 is 3.0000000000000004 in doubles (4 ticks); the AVR's floats give 3.
    value, end = avr_read_float(text)
    assert end == len(text)
    assert Dwell(value).ticks == ticks
    assert Dwell(value).duration == pytest.approx(0.05 * ticks)


def test_avr_read_float_is_grbl_read_float():
    assert avr_read_float("0.15")[0] == float(np.float32(0.15))
    assert avr_read_float("9999999.5")[0] == 9999999.0  # 8 digits kept, float32 on the way
    assert avr_read_float("-2.5X", 0) == (-2.5, 4)
    assert avr_read_float("X1", 0) is None
    assert avr_words("N10G4P0.15") == {"N": 10.0, "G": 4.0, "P": float(np.float32(0.15))}
    assert avr_words("$J=X1.5F100") == {"X": 1.5, "F": 100.0}


def test_status_and_reset_during_a_dwell_wait_for_its_50_ms_steps():
    device = booted()
    device.write(b"G4 P0.3\n")
    start = device.now  # nothing to wait for: delay_sec starts now
    device.advance(0.01)
    device.write(b"?")
    device.advance(0.1)
    out = lines_of(device)
    assert len(out) == 1 and out[0][1].startswith(b"<Idle|")
    assert out[0][0] == pytest.approx(start + 0.05)
    device.write(b"\x18")  # at 0.11: seen at the 0.15 step, banner 25 ms later
    device.advance(0.5)
    out = lines_of(device)
    assert [line for _, line in out] == WELCOME.splitlines(keepends=True)
    assert out[0][0] == pytest.approx(start + 0.15 + 0.025)
    assert device.executed_lines == 0  # the dwell was cut short


def test_status_in_the_last_dwell_step_comes_after_its_ok():
    device = booted()
    device.write(b"G4 P0.1\n")
    device.advance(0.07)
    device.write(b"?")
    device.advance(0.1)
    out = lines_of(device)
    assert [line[:5] for _, line in out] == [b"ok\r\n", b"<Idle"]
    assert out[0][0] == out[1][0] == pytest.approx(0.1)


# -- Bf: (planner blocks free, receive bytes free) ---------------------------------------------


def status_of(device: SimulatedGrbl) -> str:
    device.read()
    device.write(b"?")
    out = device.read().decode()
    assert out.startswith("<") and out.endswith(">\r\n"), out
    return out[1:-3]


def fields(status: str) -> dict[str, str]:
    parts = status.split("|")
    return {"state": parts[0]} | dict(p.split(":", 1) for p in parts[1:])


def test_bf_idle_and_one_block_as_in_the_transcript():
    """shortsegs-cc_n400: at X20, ``G0 X0``; reports right after its ok, 0.2 s later, 0.4 s."""
    device = SimulatedGrbl(PLOTTER, position_mm=(20.0, 0.0, 0.0))
    device.read()
    reference = [
        "Idle|MPos:20.000,0.000,0.000|Bf:15,128|FS:0,0",
        "Run|MPos:20.000,0.000,0.000|Bf:14,128|FS:3000,0",
        "Run|MPos:5.000,0.000,0.000|Bf:14,128|FS:3000,0",
        "Idle|MPos:0.000,0.000,0.000|Bf:15,128|FS:0,0",
    ]
    seen = [status_of(device)]
    device.write(b"G0X0\n")
    device.advance(5 * device.read_time)  # read at 69.4 µs a byte
    assert device.read() == b"ok\r\n"
    seen.append(status_of(device))
    device.advance(0.2)
    seen.append(status_of(device))
    device.advance(0.2)
    seen.append(status_of(device))
    for ours, theirs in zip(seen, reference, strict=True):
        a, b = fields(ours), fields(theirs)
        assert (a["state"], a["Bf"], a["FS"]) == (b["state"], b["Bf"], b["FS"])
        x = float(a["MPos"].split(",")[0])
        assert abs(x - float(b["MPos"].split(",")[0])) <= 0.0125 + 1e-9  # within one step


def test_bf_while_streaming_counts_the_receive_ring():
    """Character counting keeps the planner full (``Bf:0,n``); n is what the 128-byte ring has
    free (``serial_get_rx_buffer_available``), and once the host has sent everything and the
    ring is empty the report is ``Bf:0,128`` while 15 blocks still run, then ``Bf:15,128``
    (shortsegs-cc transcripts). Lines read at once: each ``?`` is answered as written."""
    device = SimulatedGrbl(PLOTTER, read_time=0.0)
    device.read()
    lines = [
        f"G1X{20 * math.cos(k / 60):.3f}Y{20 * math.sin(k / 60):.3f}F6000\n" for k in range(400)
    ]
    in_flight: list[int] = []
    sent = acked = 0
    reports = []
    while sent < len(lines) or in_flight:
        while sent < len(lines) and sum(in_flight) + len(lines[sent]) <= 127:
            device.write(lines[sent].encode())
            in_flight.append(len(lines[sent]))
            sent += 1
        device.advance(0.001)
        for _ in range(device.read().count(b"ok")):
            in_flight.pop(0)
            acked += 1
        if sent > 50 and sent < len(lines):
            taken = device.lines_received - acked  # read from the ring, waiting for the planner
            unread = sum(in_flight[taken:])
            written = sum(len(line) for line in lines[:sent])
            head, tail = written % 128, (written - unread) % 128
            # Grbl 1.1h's formula, one byte less once the head has wrapped below the tail.
            free = 128 - (head - tail) if head >= tail else tail - head - 1
            reports.append((fields(status_of(device))["Bf"], free))
    assert len(reports) > 100
    for bf, free in reports:
        assert bf in (f"0,{free}", f"1,{free}")
    assert fields(status_of(device))["Bf"] == "0,128"
    device.run_until_idle()
    assert fields(status_of(device))["Bf"] == "15,128"


# -- line numbers (USE_LINE_NUMBERS builds) -------------------------------------------------------


def test_line_number_build_reports_ln_of_the_block_being_prepared():
    device = booted(line_numbers=True)
    device.write(b"$I\n")
    assert device.read() == b"[VER:1.1h.20190830:]\r\n[OPT:VN,14,128]\r\nok\r\n"
    assert status_of(device).startswith("Idle|MPos:0.000,0.000,0.000|Bf:14,128|FS:0,0|WCO:")
    device.write(b"N7 G1 X10 F600\nN8 G1 X20\nG1 X30\nN0 G1 X40\n")
    device.advance(0.5)
    assert status_of(device).startswith("Run|MPos:")
    assert fields(status_of(device))["Ln"] == "7"
    assert "|Bf:10,128|Ln:7|FS:" in "|" + status_of(device)  # Ln: comes after Bf:, before FS:

    def tail_n() -> int | None:
        block = device.executor.planner.current_block()
        return None if block is None else block.source.line_number

    assert device.advance_to(2.0, until=lambda: tail_n() != 7)
    assert fields(status_of(device))["Ln"] == "8"
    assert device.advance_to(4.0, until=lambda: tail_n() == 0)
    assert "Ln" not in fields(status_of(device))  # a line without N (or N0) reports none
    # The last block fully prepared: the planner is empty while its last segments still run.
    device.advance_to(10.0, until=lambda: not device.executor.planner.blocks)
    f = fields(status_of(device))
    assert f["state"] == "Run" and "Ln" not in f and f["Bf"] == "14,128"


def test_stock_build_accepts_n_words_and_reports_no_ln():
    device = booted()
    device.write(b"N5 G1 X10 F600\n")
    assert device.read() == b"ok\r\n"
    device.advance(0.5)
    assert "Ln" not in fields(status_of(device))
    assert device.executor.planner.capacity == 15


@pytest.mark.parametrize(
    ("line", "answer", "ln"),
    [
        (b"N1.9 G1 X1 F600", b"ok", "1"),  # truncated, as Grbl's trunc()
        (b"N10000000 G1 X1 F600", b"ok", "10000000"),
        (b"N10000001 G1 X1 F600", b"error:27", None),  # above MAX_LINE_NUMBER
        (b"N-1 G1 X1 F600", b"error:4", None),  # negative value
        (b"N1 N2 G1 X1 F600", b"error:25", None),  # repeated word
        (b"N G1 X1 F600", b"error:2", None),  # no number
        (b"N12", b"ok", None),  # only a line number: nothing to do
        (b"G1 X1 F600 N3", b"ok", "3"),  # anywhere in the line
    ],
)
def test_n_words_accepted_and_refused_as_by_the_firmware(line, answer, ln):
    device = booted(line_numbers=True)
    device.write(line + b"\n")
    assert device.read() == answer + b"\r\n"
    device.advance(0.05)
    assert fields(status_of(device)).get("Ln") == ln


def test_line_number_build_plans_14_blocks():
    for numbered, capacity in ((False, 15), (True, 14)):
        device = booted(line_numbers=numbered)
        for k in range(20):
            device.write(f"G1 X{10 * (k + 1)} F600\n".encode())
        assert device.read().count(b"ok") == capacity  # the next line waits for a free block
        assert device.lost_bytes == 0
        assert fields(status_of(device))["Bf"].startswith("0,")


def test_url_option_ln():
    import serial

    import sim.grbl.transport  # noqa: F401  (registers grblsim://)

    port = serial.serial_for_url("grblsim://?ln=1&$10=3", timeout=1)
    try:
        assert port.device.line_numbers
        port.reset_input_buffer()
        port.write(b"N4 G1 X10 F600\n")
        assert port.readline() == b"ok\r\n"
        port.read(0)
        port.device.advance(0.3)
        port.write(b"?")
        assert b"|Ln:4|" in port.readline()
    finally:
        port.close()


# -- executed lines ------------------------------------------------------------------------------


def arrival(device: SimulatedGrbl, x: float) -> float:
    """The first time the recorded trace is at X = ``x`` (a block's end)."""
    kt, kp = device.executor.recorder.knots()
    return float(kt[np.flatnonzero(np.isclose(kp[:, 0], x))[0]])


def test_executed_lines_follow_execution_not_acknowledgement():
    device = booted(pen_servo=(1000, 0))
    program = b"G21\nG1 X10 F600\nG1 X10\nG4 P0.1\nM3 S1000\nG1 X20\nbad\nG1 X30\n"
    device.write(program)
    assert device.read().count(b"ok") == 3  # G21, both moves; then the dwell waits
    assert device.executed_lines == 1  # G21 has taken effect; the move is still to run
    assert device.line_finished_at[0] == 0.0
    device.run_until_idle()
    assert device.executed_lines == 8 == device.lines_received
    done = device.line_finished_at
    t10, t20, t30 = arrival(device, 10.0), arrival(device, 20.0), arrival(device, 30.0)
    assert done[1] == pytest.approx(t10)  # the move has finished executing
    assert done[2] == done[1]  # a move of no step: done when processed, after the move before
    assert done[3] == pytest.approx(t10 + 0.025 + 0.1)  # $1, then the dwell
    assert done[4] == done[3]  # M3 waited for nothing more
    assert done[5] == pytest.approx(t20)
    assert done[6] == done[5]  # error:20 answered early, counted in order
    assert done[7] == pytest.approx(t30)
    assert done == sorted(done)


def test_executed_lines_at_a_reset_name_the_last_line_that_ran():
    device = booted()
    for k in range(1, 40):
        device.write(f"G1 X{k} F1200\n".encode())
        device.advance(0.001)
    device.advance(0.6)
    last = device.executed_lines
    acked = device.read().count(b"ok")
    assert 0 < last < acked  # acknowledged is ahead of executed by the planner's blocks
    x = device.position_mm[0]
    assert last <= x < last + 1  # the machine is on the move of line last + 1
    device.write(b"\x18")
    device.advance(1.0)
    assert device.executed_lines == last  # the lines the reset threw away never finish
    assert device.line_finished_at[last] is None
    assert device.read().startswith(b"ALARM:3\r\n")


# -- fault hook: a stalled machine -----------------------------------------------------------------


def long_moves(device: SimulatedGrbl, n: int = 22) -> None:
    for k in range(n):
        device.write(f"G1 X{2 * (k + 1)} F600\n".encode())


def test_freeze_motion_stalls_everything_but_status():
    reference = booted()
    long_moves(reference)
    reference.run_until_idle()
    device = booted()
    long_moves(device)
    device.advance(1.0)
    oks = device.read().count(b"ok")
    before = status_of(device)
    done = device.executed_lines
    device.freeze_motion()
    device.advance(5.0)
    assert device.read() == b""  # no ok for the line waiting on the full planner
    assert status_of(device).split("|")[:4] == before.split("|")[:4]  # Run, MPos, Bf, FS
    assert device.executed_lines == done
    device.freeze_motion(False)
    device.run_until_idle()
    assert oks + device.read().count(b"ok") == 22 and device.lost_bytes == 0
    shifted = [t + 5.0 for t in reference.line_finished_at[done:]]
    assert device.line_finished_at[done:] == pytest.approx(shifted, abs=1e-9)
    assert device.position_mm == reference.position_mm


def test_freeze_motion_while_idle_keeps_idle_and_stops_a_dwell():
    device = booted()
    device.write(b"G4 P0.2\n")
    device.advance(0.07)
    device.freeze_motion()
    device.advance(2.0)
    assert device.read() == b""
    assert status_of(device).startswith("Idle|MPos:0.000,0.000,0.000|")
    assert not device.busy  # nothing happens until the hook lets go
    device.freeze_motion(False)
    device.advance(0.2)
    out = lines_of(device)
    assert out == [(pytest.approx(2.2), b"ok\r\n")]


def test_a_short_move_prepared_at_once_still_counts_when_executed():
    device = booted()
    device.write(b"G1 X10 F600\n")
    ex = device.executor
    assert device.advance_to(5.0, until=lambda: not ex.planner.blocks and not ex._queue)
    assert ex.state == "run"  # its last segment is still running
    device.write(b"G1 X10.1\n")  # 8 steps: prepared and out of the planner at once
    assert not device.executor.planner.blocks
    assert device.executed_lines == 0
    device.run_until_idle()
    assert device.executed_lines == 2
    assert device.line_finished_at[1] == pytest.approx(arrival(device, 10.1))
    assert device.line_finished_at[1] > device.line_finished_at[0] == arrival(device, 10.0)


def test_an_alarm_due_during_a_blocking_delay_comes_after_it():
    device = booted()
    device.write(b"G1 X30 F600\n")
    device.advance(0.5)
    device.read()
    device.write(b"\x18")  # ALARM:3 at +25 ms, banner at +550 ms
    device.schedule_alarm(device.now + 0.1, 1)
    device.advance(2.0)
    out = [line for _, line in lines_of(device)]
    assert out[0] == b"ALARM:3\r\n"
    assert out[-2:] == [b"ALARM:1\r\n", b"[MSG:Reset to continue]\r\n"]
    assert not device.busy


def test_status_requested_with_a_reset_in_motion_is_lost():
    device = booted()
    device.write(b"G1 X30 F600\n")
    device.advance(0.5)
    device.read()
    device.write(b"\x18?G21\n")  # the reset wins; main() clears the other flags and the buffer
    device.advance(1.0)
    out = b"".join(line for _, line in lines_of(device))
    assert out == b"ALARM:3\r\n" + WELCOME + b"[MSG:'$H'|'$X' to unlock]\r\n"
    assert device.lines_received == 1


def test_executor_dwell_is_rounded_up_to_50_ms():
    from sim.grbl.executor import GrblExecutor

    for seconds, expected in ((0.012, 0.05), (0.05, 0.05), (0.0501, 0.1), (0.0, 0.0)):
        ex = GrblExecutor()
        pause = Dwell(seconds)
        accepted = ex.submit(pause)
        assert accepted == (expected == 0.0)  # a zero dwell is over at once
        if not accepted:
            assert ex.run_until(1.0, until=lambda pause=pause, ex=ex: ex.submit(pause))
        assert ex.now == pytest.approx(expected)


def send_and_wait_standstill(p: float, latency: float = 0.005) -> float:
    """A host that sends each line 5 ms after the previous ``ok`` (the reference's ``_lat5ms``
    send-response stream) over the 115200 baud line: how long X stays at 10 (MPos)."""
    import serial

    import sim.grbl.transport  # noqa: F401  (registers grblsim://)

    query = "&".join(f"${k}={v}" for k, v in PLOTTER.items())
    port = serial.serial_for_url(f"grblsim://?{query}", baudrate=115200, timeout=1)
    try:
        assert port.read(len(WELCOME)) == WELCOME
        clock, samples = port.clock, []
        for line in ("G1X10.000Y0.000F3000", f"G4P{p}", "G1X20.000Y0.000"):
            port.write(f"{line}\n".encode())
            while port._link.available() < 4:  # sample MPos every 0.2 ms until the ok is in
                clock.sleep_until(clock.now() + 0.0002)
                samples.append((clock.now(), port.device.executor.position_steps[0]))
            assert port.read(4) == b"ok\r\n"
            clock.sleep_until(clock.now() + latency)
        while port.device.executor.position_steps[0] == 800:
            clock.sleep_until(clock.now() + 0.0002)
            samples.append((clock.now(), port.device.executor.position_steps[0]))
    finally:
        port.close()
    at = [t for t, x in samples if x == 800]
    return at[-1] - at[0] + 0.0002


def test_standstills_with_a_send_and_wait_host_are_the_measured_ones():
    """With the host the 8-13 ms come from (the next line only after the dwell's ok), the
    simulated standstills are the real firmware's to within a few milliseconds (83.8 / 83.8 /
    133.8 / 183.8 / 333.8 ms; the real ones scatter by 2 ms: 88 and 86 for one 50 ms step)."""
    errors = [send_and_wait_standstill(p) - ms / 1000 for p, ms in MEASURED_MS.items()]
    assert max(abs(e) for e in errors) < 0.005
    assert abs(sum(errors) / len(errors)) < 0.002
