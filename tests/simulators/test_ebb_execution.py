"""What the simulated EBB executes, over its ``ebbsim://`` port: the global step position
(``QS``) and accumulators (``QU,200``) after random ``LM``/``LT``/``T3`` sequences equal the
firmware arithmetic chained move by move (:func:`firmware_protocols.ebb.motion.execute`) and the
makers' own implementation (``plotink.ebb_calc``), and the recorder's 40 µs trace is those
positions tick by tick."""

from __future__ import annotations

import numpy as np
import pytest
import serial
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from plotink import ebb_calc

from firmware_protocols.ebb.errors import EBBCommandError
from firmware_protocols.ebb.motion import ACCUMULATOR_STEP, TICK_HZ, Move, execute
from sim.ebb.device import SimulatedEBB
from sim.ebb.transport import attach_device

OK = b"OK\r\n"
MAX_TICKS = 1500  # per move: keeps a hypothesis example to a few ms of numpy
RATE = 2**31 // 4  # at most a step every 4 ticks at the start (6250 steps/s)


def _lt_or_t3(draw: st.DrawFn, command: str) -> Move:
    ticks = draw(st.integers(1, MAX_TICKS))
    rate = tuple(draw(st.integers(-RATE, RATE)) for _ in range(2))
    # Accelerations that can reverse the motor within the move (firmware 3.x reverses it).
    accel = tuple(draw(st.integers(-RATE // ticks, RATE // ticks)) for _ in range(2))
    jerk = (0, 0)
    if command == "T3":
        jerk = tuple(draw(st.integers(-RATE // ticks**2, RATE // ticks**2)) for _ in range(2))
    clear = draw(st.integers(0, 3))
    return Move(command, rate, accel, jerk, ticks=ticks, clear=clear)  # type: ignore[arg-type]


def _lm(draw: st.DrawFn) -> Move:
    steps = tuple(draw(st.integers(-40, 40)) for _ in range(2))
    assume(any(steps))
    # A rate that finishes within MAX_TICKS and an acceleration that never slows it to a halt.
    rate = tuple(draw(st.integers(40 * ACCUMULATOR_STEP // MAX_TICKS, RATE)) for _ in range(2))
    accel = tuple(draw(st.integers(0, RATE // MAX_TICKS)) for _ in range(2))
    clear = draw(st.integers(0, 3))
    return Move("LM", rate, accel, steps=steps, clear=clear)  # type: ignore[arg-type]


@st.composite
def moves(draw: st.DrawFn) -> list[Move]:
    out = []
    for _ in range(draw(st.integers(1, 4))):
        command = draw(st.sampled_from(["LM", "LT", "T3"]))
        out.append(_lm(draw) if command == "LM" else _lt_or_t3(draw, command))
    return out


def chained(sequence: list[Move]) -> tuple[list[np.ndarray], tuple[int, int]]:
    """Each move's absolute positions per tick from (0, 0), and the final accumulators."""
    accumulators = (0, 0)
    origin = np.zeros(2, dtype=np.int64)
    out = []
    for move in sequence:
        positions, accumulators = execute(move, accumulators)
        out.append(origin + positions)
        if len(positions):
            origin = origin + positions[-1]
    return out, accumulators


def plotink_final(sequence: list[Move]) -> tuple[list[int], list[int]]:
    """The final step positions and accumulators by ``plotink.ebb_calc``, axis by axis."""
    position = [0, 0]
    accumulator: list[int | str] = [0, 0]
    for move in sequence:
        for i in range(2):
            acc = "clear" if move.clear & (1 << i) else accumulator[i]
            if move.command == "LM":
                if move.steps[i] == 0:
                    accumulator[i] = 0 if acc == "clear" else acc
                    continue
                _, moved, accumulator[i] = ebb_calc.calculate_lm(
                    move.steps[i], move.rate[i], move.accel[i], acc
                )
            elif move.command == "LT":
                moved, accumulator[i] = ebb_calc.move_dist_lt(
                    move.rate[i], move.accel[i], move.ticks, acc
                )
            else:
                moved, accumulator[i] = ebb_calc.move_dist_t3(
                    move.ticks, move.rate[i], move.accel[i], move.jerk[i], acc
                )
            position[i] += moved
    return position, [int(a) for a in accumulator]


def run(sequence: list[Move]) -> tuple[SimulatedEBB, list[tuple[int, int, bytes]], bytes, bytes]:
    """Send the moves (FIFO 8 deep), then poll QS and QM until idle. Returns the board, each
    QS poll as ``(tick sent, tick answered, reply)``, the last QS and QU,200."""
    device = SimulatedEBB()
    polls = []
    with serial.serial_for_url(attach_device(device, "board"), timeout=1) as port:
        port.write(b"CU,4,8\r")
        assert port.read_until(OK) == OK
        for move in sequence:
            port.write(move.line())
            assert port.read_until(OK) == OK, move.line()
        for _ in range(10_000):
            sent = port.clock.now()
            port.write(b"QS\r")
            reply = port.read_until(OK)
            polls.append((int(sent * TICK_HZ), int(port.clock.now() * TICK_HZ) + 1, reply))
            port.write(b"QM\r")
            if port.read_until(b"\n\r") == b"QM,0,0,0,0\n\r":
                break
        port.write(b"QS\r")
        qs = port.read_until(OK)
        port.write(b"QU,200\r")
        qu = port.read_until(OK)
    return device, polls, qs, qu


def timeline(device: SimulatedEBB, positions: list[np.ndarray]) -> np.ndarray:
    """``(ticks, 2)``: the expected global position after every tick from 0, the moves placed
    at the ticks the board loaded them (its timing), their steps from the chained maths."""
    segments = device.recorder.moves()
    end = segments[-1].load_tick + 1 + len(positions[-1])
    out = np.zeros((end + 1, 2), dtype=np.int64)
    for segment, expected in zip(segments, positions, strict=True):
        start = segment.load_tick + 1
        out[start : start + len(expected)] = expected
        out[start + len(expected) :] = expected[-1] if len(expected) else out[start - 1]
    return out


def valid(move: Move) -> bool:
    try:
        move.validate()
    except EBBCommandError:
        return False
    return True


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(moves())
def test_qs_after_random_moves_is_the_firmware_arithmetic(sequence):
    assume(all(valid(m) for m in sequence))
    device, polls, qs, qu = run(sequence)
    positions, accumulators = chained(sequence)
    final = next((p[-1] for p in reversed(positions) if len(p)), np.zeros(2, dtype=np.int64))
    assert qs == f"{final[0]},{final[1]}\n\rOK\r\n".encode()
    assert qu == f"QU,{accumulators[0]},{accumulators[1]}\r\nOK\r\n".encode()
    # The makers' implementation of the same firmware maths agrees.
    theirs, their_accumulators = plotink_final(sequence)
    assert theirs == [int(final[0]), int(final[1])]
    assert their_accumulators == list(accumulators)
    # Every QS while moving reported a position the motors held between asking and answering.
    expected = timeline(device, positions)
    for sent, answered, reply in polls:
        window = expected[min(sent, len(expected) - 1) : answered + 1]
        held = {f"{a},{b}\n\rOK\r\n".encode() for a, b in window}
        assert reply in held, (sent, answered, reply)
    # The recorder has each move at tick resolution.
    trace = device.recorder.trace()
    moves_run = device.recorder.moves()
    assert [m.line + b"\r" for m in moves_run] == [m.line() for m in sequence]
    start = moves_run[0].load_tick + 1
    executed = np.column_stack([trace.motor1, trace.motor2])[start:]
    assert np.array_equal(executed, expected[start : start + len(executed)])
    assert trace.motor1[-1] == final[0] and trace.motor2[-1] == final[1]


def test_queued_moves_follow_without_a_gap_and_the_trace_is_40_us():
    """Moves longer than the board's parse time, queued ahead: each is loaded on the tick the
    previous one ends, so the trace is the moves end to end."""
    sequence = [
        Move("LT", (2**31 // 10, -(2**31) // 20), (1000, 0), ticks=500, clear=3),
        Move("T3", (2**31 // 8, 2**31 // 16), (-2000, 0), (3, 1), ticks=400),
        Move("LM", (2**31 // 5, 2**31 // 7), (0, 500), steps=(-30, 12)),
    ]
    device, _, qs, _ = run(sequence)
    segments = device.recorder.moves()
    assert [s.load_tick for s in segments[1:]] == [s.end_tick for s in segments[:-1]]
    positions, _ = chained(sequence)
    trace = device.recorder.trace()
    assert np.allclose(np.diff(trace.t), 1 / TICK_HZ, rtol=0, atol=1e-12)
    start = segments[0].load_tick + 1
    both = np.concatenate(positions)
    executed = np.column_stack([trace.motor1, trace.motor2])[start : start + len(both)]
    assert np.array_equal(executed, both)
    assert qs == f"{both[-1][0]},{both[-1][1]}\n\rOK\r\n".encode()


@pytest.mark.parametrize(
    ("line", "reply"),
    [
        (b"LM,0,10,0,0,0,0\r", b"!6 Err: Invalid parameter value\r\n"),  # no axis can move
        (b"LM,-5,-10,0,0,0,0\r", b"!6 Err: Invalid parameter value\r\n"),  # both negative
        (b"LT,0,100,0,0,0\r", b"!6 Err: Invalid parameter value\r\n"),  # no interval
    ],
)
def test_invalid_moves_are_refused_and_nothing_moves(line, reply):
    device = SimulatedEBB()
    with serial.serial_for_url(attach_device(device, "board"), timeout=1) as port:
        port.write(line)
        assert port.read_until(b"\r\n") == reply
        port.write(b"QS\r")
        assert port.read_until(OK) == b"0,0\n\rOK\r\n"
    assert device.recorder.moves() == []
