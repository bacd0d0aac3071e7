"""The simulated EBB byte for byte: strict parsing, the motion FIFO, step positions against the
firmware arithmetic and an independent implementation (plotink's ebb_calc), QM/QG/QB, ES, EM,
the pen servo's timing, HM, a reset, and the tick-resolution record."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from plotink import ebb_calc

from firmware_protocols.ebb.motion import TICK_HZ, Move, execute
from sim.ebb import SimulatedEBB, servo_travel_time
from sim.ebb.steps import move_positions, sm_move

OK = b"OK\r\n"
RATE_1K = 85899346  # 1000 steps/s


def send(device: SimulatedEBB, *lines: bytes, wait: float = 0.05) -> bytes:
    """Write ``lines`` (each gets its CR), run ``wait`` simulated seconds, return the replies."""
    device.write(b"".join(line + b"\r" for line in lines))
    device.advance(wait)
    return device.read()


def idle(device: SimulatedEBB) -> bytes:
    device.run_until_idle()
    device.advance(0.01)
    return device.read()


@pytest.mark.parametrize(
    ("line", "reply"),
    [
        (b"SM,100", b"!4 Err: Missing parameter(s)\r\n"),
        (b"SM,100A", b"!5 Err: Need comma next, found: 'A'\r\n"),
        (b"SC,300,1", b"!6 Err: Invalid parameter value\r\n"),
        (b"SM,0,10", b"!6 Err: Invalid parameter value\r\n"),
        (b"LT,0,1,0,0,0", b"!6 Err: Invalid parameter value\r\n"),
        (b"B", b"!8 Err: Unknown command 'B:42'\r\n"),
        (b"BB", b"!8 Err: Unknown command 'BB:4242'\r\n"),
        (b"SM,1,100", b"!0 Err: <axis1> step rate too high\n\r\r\n"),
        (b"SM,100,0,-3000", b"!0 Err: <axis2> step rate too high\n\r\r\n"),
        (b"QU,7", b"QU,!6 Err: Invalid parameter value\r\n"),
        (b"LM,1" + b"0" * 300, b"!3 Err: RX Buffer overrun\r\n"),
    ],
)
def test_refused_lines_get_the_firmware_error_and_do_nothing(line, reply):
    device = SimulatedEBB()
    assert send(device, line) == reply
    assert device.recorder.segments == [] and device.fifo_count == 0
    assert send(device, b"QS") == b"0,0\n\rOK\r\n"


def test_characters_after_the_last_parameter_run_the_command_then_say_so():
    device = SimulatedEBB()
    assert send(device, b"SM,10,1,1,0,0") == OK + b"!7 Err: Extra parameter\r\n"
    assert idle(device) == b""
    assert device.steps() == (1, 1)


def test_lines_end_at_cr_or_lf_and_names_are_case_insensitive():
    device = SimulatedEBB()
    device.write(b"qs\r\n\nV\n\x01Q\x02S\r")
    device.advance(0.01)
    assert device.read() == (
        b"0,0\n\rOK\r\n" + b"EBBv13_and_above EB Firmware Version 3.0.3\r\n" + b"0,0\n\rOK\r\n"
    )


def test_firmware_2_lacks_the_3_x_commands():
    device = SimulatedEBB(version="2.8.1")
    assert send(device, b"V") == b"EBBv13_and_above EB Firmware Version 2.8.1\r\n"
    assert send(device, b"T3,10,1,0,0,1,0,0") == b"!8 Err: Unknown command 'T3:5433'\r\n"
    assert send(device, b"QU,2") == b"!8 Err: Unknown command 'QU:5155'\r\n"
    assert send(device, b"LT,10,85899346,0,0,0", wait=0.1) == OK


def test_the_fifo_is_one_deep_at_boot_and_cu_4_deepens_it():
    device = SimulatedEBB()
    lt = b"LT,2500,%d,0,0,0" % RATE_1K  # 0.1 s each
    device.write(b"".join([lt + b"\r"] * 3 + [b"QS\r"]))
    device.advance(0.05)
    # One executing, one in the FIFO; the third waits in the parser, unanswered, and so does QS.
    assert device.read() == OK * 2 and device.fifo_count == 1
    first_end = (100 + 2500) / TICK_HZ  # loaded after the 4 ms LT processing time
    device.advance_to(first_end - 1e-6)
    assert device.read() == b""
    device.advance_to(first_end + 0.001)
    assert device.read() == OK + b"100,0\n\rOK\r\n"
    idle(device)
    # CU,4 waits for the motion to end; then four moves are taken at the parser's pace.
    assert send(device, b"CU,4,99", b"QU,3") == OK + b"QU,32\r\nOK\r\n"
    assert send(device, b"CU,4,3", b"QU,3") == OK + b"QU,3\r\nOK\r\n"
    assert send(device, *[lt] * 4, b"QM", b"QU,6") == OK * 4 + b"QM,1,1,0,1\n\rQU,3\r\nOK\r\n"


def test_moves_follow_each_other_without_a_gap_at_the_tick():
    device = SimulatedEBB()
    send(device, b"CU,4,8")
    # 10 ms moves, longer than the 4 ms the board takes to read each line: no starving.
    send(device, *[b"LT,250,%d,0,0,0" % RATE_1K] * 3, b"LM,%d,3,0,0,0,0,3" % RATE_1K)
    idle(device)
    segments = device.recorder.segments
    assert [s.ticks for s in segments] == [250, 250, 250, 75]
    for before, after in itertools.pairwise(segments):
        assert after.load_tick == before.end_tick
    # The record holds each position from the tick it was stepped to the next step.
    trace = device.recorder.trace()
    for segment in segments:
        assert trace.motor1[segment.load_tick] == segment.origin[0]
        assert trace.motor1[segment.end_tick] == segment.positions()[-1][0]
    assert trace.motor1[: segments[0].load_tick + 1].tolist() == [0] * (segments[0].load_tick + 1)


def test_a_move_loads_on_the_first_tick_after_the_board_has_read_it():
    device = SimulatedEBB()
    device.advance(0.00001)  # the LT is read by 0.00401 s: tick 100.25, so loaded on tick 101
    send(device, b"LT,10,%d,0,0,0" % RATE_1K)
    assert device.recorder.segments[0].load_tick == 101
    assert send(device, b"SM,150000,0,0", wait=0.0) == b""
    device.run_until_idle()
    assert device.recorder.segments[-1].ticks == 100_000 * 25  # SM delays are capped at 100 s


MOVES = st.one_of(
    st.builds(
        lambda n, r, a, r2, a2, c: Move("LT", (r, r2), (a, a2), ticks=n, clear=c),
        st.integers(1, 1500),
        st.integers(-(2**28), 2**28),
        st.integers(-20_000, 20_000),
        st.integers(-(2**28), 2**28),
        st.integers(-20_000, 20_000),
        st.integers(0, 3),
    ),
    st.builds(
        lambda n, r, a, j, c: Move("T3", (r, -r), (a, -a), (j, -j), ticks=n, clear=c),
        st.integers(1, 1500),
        st.integers(-(2**27), 2**27),
        st.integers(-20_000, 20_000),
        st.integers(-30, 30),
        st.integers(0, 3),
    ),
    st.builds(
        lambda s, r, a, s2, c: Move("LM", (r, r), (a, 0), steps=(s, s2), clear=c),
        st.integers(-60, 60).filter(bool),
        st.integers(2**24, 2**28),
        st.integers(0, 5_000),
        st.integers(-60, 60),
        st.integers(0, 3),
    ),
)


def oracle(move: Move, accumulators: list[int]) -> tuple[int, int]:
    """plotink's ebb_calc (the makers' independent implementation): the steps ``move`` takes,
    ``accumulators`` updated in place."""
    out = []
    for i in range(2):
        accum = "clear" if move.clear & (1 << i) else accumulators[i]
        if move.command == "LT":
            steps, accumulators[i] = ebb_calc.move_dist_lt(
                move.rate[i], move.accel[i], move.ticks, accum
            )
        elif move.command == "T3":
            steps, accumulators[i] = ebb_calc.move_dist_t3(
                move.ticks, move.rate[i], move.accel[i], move.jerk[i], accum
            )
        elif move.steps[i] == 0:
            steps = 0
            accumulators[i] = 0 if accum == "clear" else accumulators[i]
        else:
            _, steps, accumulators[i] = ebb_calc.calculate_lm(
                move.steps[i], move.rate[i], move.accel[i], accum
            )
        out.append(steps)
    return out[0], out[1]


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(st.lists(MOVES, min_size=1, max_size=4))
def test_qs_after_random_moves_is_the_firmware_arithmetic_and_plotinks(moves):
    device = SimulatedEBB()
    send(device, b"CU,4,8")
    device.write(b"".join(m.line() for m in moves))
    replies = idle(device)
    assert replies == OK * len(moves)
    mine = np.zeros(2, dtype=np.int64)
    theirs = np.zeros(2, dtype=np.int64)
    accumulators = (0, 0)
    plotink_acc = [0, 0]
    for move in moves:
        positions, accumulators = execute(move, accumulators)
        mine += positions[-1]
        theirs += oracle(move, plotink_acc)
    assert send(device, b"QS") == f"{mine[0]},{mine[1]}\n\rOK\r\n".encode()
    assert tuple(theirs) == tuple(mine)
    assert send(device, b"QU,200") == f"QU,{plotink_acc[0]},{plotink_acc[1]}\r\nOK\r\n".encode()
    # The record at 40 µs ends where QS says, tick for tick as the moves ran.
    trace = device.recorder.trace()
    assert (trace.motor1[-1], trace.motor2[-1]) == tuple(mine)
    assert np.all(np.abs(np.diff(trace.motor1)) <= 1) and np.all(np.abs(np.diff(trace.motor2)) <= 1)


def test_qm_and_qg_while_moving_and_idle():
    device = SimulatedEBB()
    assert send(device, b"QM", b"QG") == b"QM,0,0,0,0\n\r" + b"10\r\n"  # pen up
    # LM example 4: both at 1 ms/step, axis 1 for 500 steps, axis 2 for 250.
    send(device, b"LM,85899346,500,0,85899346,250,0", wait=0.1)
    assert send(device, b"QM", b"QG", wait=0.01) == b"QM,1,1,1,0\n\r" + b"1E\r\n"
    # Written at 0.05 s and read by 0.054 s, the LM was loaded on tick 1350; axis 2 takes its
    # last step on the tick where its column last changes.
    positions, _ = execute(Move("LM", (85899346, 85899346), steps=(500, 250)))
    last_step = (1350 + np.flatnonzero(np.diff(positions[:, 1]))[-1] + 2) / TICK_HZ
    read = device.other_command_time
    device.advance_to(last_step - 1 / TICK_HZ - read)
    assert send(device, b"QM", wait=read) == b"QM,1,1,1,0\n\r"  # read a tick before it
    device.advance_to(last_step - read)
    assert send(device, b"QM", wait=read) == b"QM,1,1,0,0\n\r"  # read on its tick
    assert device.recorder.segments == []  # the LM is still running
    idle(device)
    assert send(device, b"QM", b"QS") == b"QM,0,0,0,0\n\r" + b"500,250\n\rOK\r\n"


def test_the_prg_button_latch_is_read_and_cleared_by_qb_or_qg():
    device = SimulatedEBB()
    device.press_button(0.2)
    assert send(device, b"QB") == b"0\r\nOK\r\n"
    device.advance_to(0.25)
    assert send(device, b"QG") == b"30\r\n"
    assert send(device, b"QB") == b"0\r\nOK\r\n"
    device.press_button(0.5)
    device.advance_to(0.6)
    assert send(device, b"QB", b"QB") == b"1\r\nOK\r\n" + b"0\r\nOK\r\n"


def test_es_stops_mid_move_and_the_rest_is_never_stepped():
    device = SimulatedEBB()
    send(device, b"LM,85899346,1000,0,42949673,500,0", b"SM,500,10,10", wait=0.0)
    device.advance_to(0.3)
    assert device.read() == OK * 2
    assert send(device, b"ES", wait=0.01) == b"1\n\rOK\r\n"
    stop_tick = math.floor((0.3 + device.other_command_time) * TICK_HZ + 1e-9)
    segment = device.recorder.segments[0]
    assert segment.ticks == stop_tick - segment.load_tick
    expected = execute(segment.move, (0, 0))[0][segment.ticks - 1]
    reply = f"{expected[0]},{expected[1]}\n\rOK\r\n".encode()
    assert send(device, b"QS") == reply and 0 < expected[0] < 1000
    device.advance(2.0)
    assert send(device, b"QS", b"QM") == reply + b"QM,0,0,0,0\n\r"
    assert len(device.recorder.segments) == 1  # the queued SM was flushed
    assert send(device, b"ES") == b"0\n\rOK\r\n"
    # The accumulators stay where the ISR left them: k ticks at a constant rate from 0.
    k = segment.ticks
    acc = (k * 85899346 % 2**31, k * 42949673 % 2**31)
    assert send(device, b"QU,200") == f"QU,{acc[0]},{acc[1]}\r\nOK\r\n".encode()


def test_r_reinitialises_and_rb_reboots_off_the_usb():
    device = SimulatedEBB()
    dropped = []
    device.on_close.append(lambda: dropped.append(device.now))
    send(device, b"CU,4,5", b"SC,4,1000", b"SM,100,10,0", b"LT,1000,%d,0,0,0" % RATE_1K)
    assert send(device, b"R", b"QU,3", b"QM") == OK + b"QU,1\r\nOK\r\n" + b"QM,0,0,0,0\n\r"
    assert dropped == [] and device.servo_min == 22565
    assert device.recorder.moves()[0].ticks < 2500  # the SM was cut short
    assert send(device, b"RB", b"QS") == b""  # no answer: the board is gone from the USB
    assert dropped and send(device, b"QS") == b"0,0\n\rOK\r\n"


def test_the_nickname_is_kept_in_flash_and_qr_reads_the_servos_power():
    device = SimulatedEBB()
    assert send(device, b"QT") == b"\r\nOK\r\n"  # none set: an empty line
    assert send(device, b"ST,East EBB", b"QT") == OK + b"East EBB\r\nOK\r\n"
    send(device, b"R")
    send(device, b"RB")
    assert send(device, b"QT") == b"East EBB\r\nOK\r\n"  # flash survives a reboot
    assert send(device, b"CU,10,1", b"QT", b"ST,", b"QT") == b"\nQT,East EBB\nST\nQT,\n"
    send(device, b"CU,10,0")
    assert send(device, b"ST,x") == OK
    assert send(device, b"ST") == b"!8 Err: Unknown command 'ST:5354'\r\n"  # not modelled
    assert device.nickname == b"x"
    assert send(device, b"QR") == b"0\n\rOK\r\n"  # unpowered until the servo is used
    assert send(device, b"SP,1", b"QR") == OK + b"1\n\rOK\r\n"
    assert send(device, b"SR,60000,0", b"QR") == OK + b"0\n\rOK\r\n"


def test_em_sets_the_step_mode_and_clears_the_counters():
    device = SimulatedEBB()
    send(device, b"SM,10,5,-7")
    idle(device)
    assert send(device, b"QS", b"QE") == b"5,-7\n\rOK\r\n" + b"16,16\n\rOK\r\n"
    assert send(device, b"EM,5,0", b"QS", b"QE") == OK + b"0,0\n\rOK\r\n" + b"1,0\n\rOK\r\n"
    assert send(device, b"EM,2") == b""  # one parameter: the firmware answers nothing
    assert device.motor_position() == (5, -7)  # the motors did not move
    send(device, b"SM,10,1,1", b"CS", wait=0.1)
    assert send(device, b"QS") == b"1,1\n\rOK\r\n"  # CS ran before the SM's steps
    assert send(device, b"CS", b"QS") == OK + b"0,0\n\rOK\r\n"


def test_sm_rates_are_the_firmware_32_bit_float_arithmetic():
    # SM,1000,250,-766 (the reference's example): 250 and 766 steps in one second.
    device = SimulatedEBB()
    send(device, b"SM,1000,250,-766")
    idle(device)
    assert send(device, b"QS") == b"250,-766\n\rOK\r\n"
    segment = device.recorder.moves()[0]
    assert abs(segment.ticks - TICK_HZ) <= 1
    # The PIC's 32-bit floats: 85899345.92f / 1000 is 85899.34375, times 766 is 65798897.3,
    # which single precision (steps of 4 there) holds as 65798896; in exact arithmetic 65798898.
    assert segment.move.rate == (21474836, 65798896)
    # 25 kHz exactly: rate 2**31, a step on every tick.
    move, full = sm_move(1, (25, 0))
    assert full == (True, False)
    positions, _ = move_positions(move, (123, 0), full)
    assert positions[:, 0].tolist() == list(range(1, 26))


def test_hm_waits_for_the_motion_then_goes_home_in_a_straight_line():
    device = SimulatedEBB()
    send(device, b"SM,200,300,-100", b"HM,3000", wait=0.1)
    assert device.read() == b""  # HM answers once the move before it has ended
    device.run_until_idle()
    device.advance(0.01)
    assert device.read() == OK
    assert send(device, b"QS") == b"0,0\n\rOK\r\n"
    home = device.recorder.moves()[-1]
    assert home.move.steps == (-300, 100)
    # 3000 * 85899.34375 (85899.34592f) is 257698031.25, held as 257698032 (steps of 16);
    # the minor axis: 100 * 3000 / 300 * 85899.34375 = 85899343.75, held as 85899344.
    assert home.move.rate == (257698032, 85899344)
    # 300 steps at 3000 steps/s; the accumulators are not cleared: within one step period.
    assert abs(home.ticks - 300 * TICK_HZ / 3000) <= TICK_HZ / 3000
    send(device, b"HM,25000,40,-40")
    idle(device)
    assert send(device, b"QS") == b"40,-40\n\rOK\r\n"


def test_the_pen_servo_moves_at_its_rate_and_sp_delays_the_next_move():
    device = SimulatedEBB()
    send(device, b"SC,4,20000", b"SC,5,12000", b"SC,11,500", b"SC,12,250")
    assert send(device, b"SP,1", b"QP") == OK + b"1\n\rOK\r\n"
    idle(device)
    device.advance(6 * 0.024)  # from the boot position 22565, 500 per 24 ms cycle
    assert device.pen_position() == 20000
    start = device.now
    send(device, b"SP,0,300", b"SM,10,1,0", wait=0.0)
    device.run_until_idle()
    assert device.read() == OK * 2
    pen, move = device.recorder.segments[-2:]
    assert pen.kind == "servo" and pen.ticks == 300 * TICK_HZ // 1000
    assert move.load_tick == pen.end_tick  # the move waited for the SP's 300 ms
    down_from = (pen.load_tick + 1) / TICK_HZ
    travel = servo_travel_time(8000, 250)  # 32 cycles of 24 ms
    assert travel == pytest.approx(32 * 0.024)
    trace = device.recorder.trace(until=start + 1.5)
    arrived = trace.t[np.argmax(trace.pen == 12000)]
    assert down_from + travel - 0.024 < arrived <= down_from + travel
    moving = trace.pen[(trace.t > down_from + 0.03) & (trace.t < arrived)]
    assert np.all(np.diff(moving) <= 0) and set(np.diff(moving)) <= {0, -250}
    assert send(device, b"QP", b"QR") == b"0\n\rOK\r\n" + b"1\n\rOK\r\n"  # QR: powered
    assert device.servo_powered()
    device.advance(61.0)
    assert not device.servo_powered()  # the 60 s servo power timeout


def test_a_reset_mid_run_stops_the_motors_where_they_are_and_boots_again():
    device = SimulatedEBB()
    dropped = []
    device.on_close.append(lambda: dropped.append(device.now))
    send(device, b"CU,4,4", b"SC,5,9000", *[b"LT,2500,%d,0,0,0" % RATE_1K] * 3, wait=0.0)
    device.reset_board(0.15)
    device.advance_to(0.2)
    assert dropped == [0.15]
    moves = device.recorder.moves()
    assert [m.ticks for m in moves] == [2500, 0.15 * TICK_HZ - moves[1].load_tick]
    assert device.motor_position()[0] == moves[-1].positions()[-1][0]
    device.read()
    assert send(device, b"QS", b"QU,3") == b"0,0\n\rOK\r\n" + b"QU,1\r\nOK\r\n"
    assert device.servo_max == 15302  # the configuration is back to the boot values


def test_future_syntax_mode():
    device = SimulatedEBB()
    assert send(device, b"CU,10,1") == b"\n"
    assert send(device, b"QS", b"SM,100") == b"QS,0,0\n" + b"SM,!4 Err: Missing parameter(s)\n"
    assert send(device, b"CU,10,0", b"QB") == b"CUOK\r\n" + b"0\r\nOK\r\n"
