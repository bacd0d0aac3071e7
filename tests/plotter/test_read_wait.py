"""Grbl reads each byte in 69.4 µs (Grbl 1.1h, measured): after a stop the planner fills
before motion starts, in the simulator as on the firmware, and the program predicts it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.grbl import SimulatedGrbl
from sim.grbl.device import READ_TIME
from tagbot.model import Plan, Tag
from tagbot.plotter import load_profile
from tagbot.plotter.machine import prepare
from tagbot.plotter.program import read_waits


def test_back_to_back_lines_are_acknowledged_as_read():
    """sendresp.log: these 57 bytes, sent at once, acknowledged 1, 2, 3, 4 and 4 ms later."""
    device = SimulatedGrbl()
    device.read()
    lines = [b"G21 G90 G94\n", b"G1 X10 Y0 F600\n", b"G1 X10 Y10\n", b"G1 X0 Y10\n", b"G0 X0 Y0\n"]
    start = device.now
    device.write(b"".join(lines))
    device.advance(0.01)
    oks = [t - start for t, chunk in device.read_timed() if chunk == b"ok\r\n"]
    read = np.cumsum([len(line) for line in lines]) * READ_TIME
    assert oks == pytest.approx(read.tolist(), abs=1e-9)
    assert np.ceil(np.array(oks) * 1000).tolist() == [1, 2, 3, 4, 4]


def _tag() -> Tag:
    plans = [
        Plan(
            targets=[[3.0 * k, 0.0], [3.0 * k + 2.0, 1.0], [3.0 * k + 3.0, -1.0]],
            dt=[0.0, 0.25],
            mu=[math.log(0.3)] * 2,
            sigma=[0.3] * 2,
            phi1=[0.3, -0.2],
            phi2=[0.0, 0.0],
            start=1.5 * k,
        )
        for k in range(3)
    ]
    return Tag(plans=tuple(plans))


def _pen_down_waits(executed: np.ndarray) -> list[float]:
    """s from each pen-down to the first movement after it, in a 1 ms recorder trace."""
    down = np.flatnonzero(np.diff((executed[:, 3] > 0.5).astype(int)) == 1) + 1
    waits = []
    for i in down:
        xy = executed[i:, 1:3]
        first = np.flatnonzero(np.hypot(*(xy - xy[0]).T) > 0)[0]
        waits.append(float(executed[i + first, 0] - executed[i, 0]))
    return waits


def test_pen_down_waits_for_the_planner_to_fill_as_the_program_predicts(tmp_path):
    job = prepare(_tag(), overrides=("place.scale=10",))
    program, profile = job.program, job.profile
    run = job.run(tmp_path)
    assert run.error is None
    # The program: each pen-down's dwell is followed by reading G93 and 16 moves (the planner's
    # 15 blocks full), 30-50 ms on the firmware with lines of this length.
    dwell = math.ceil(20 * profile["pen.dwell"]) * 0.05
    pen_down = [i for i, line in enumerate(program.lines) if line.startswith("M3S30")]
    waits = read_waits(program.lines, program.line_moves, [False] * len(program.lines), profile)
    assert not waits.any()  # no stop line: nothing to wait for
    predicted = []
    for i in pen_down:
        after = program.lines[i + 2 : i + 2 + 17]  # G93 and 16 moves, after M3 and G4
        assert after[0] == "G93\n" and all(line.startswith("G1X") for line in after[1:])
        read = sum(map(len, after)) * profile["serial.read_time"]
        assert 0.03 <= read <= 0.05
        reading_g4 = len(program.lines[i + 1]) * profile["serial.read_time"]
        span = program.line_end[i + 1] - program.line_start[i + 1]
        assert span == pytest.approx(dwell + read, abs=1e-9)
        predicted.append((reading_g4 + dwell, read))
    # The simulator, from the pen-down to the first step: the ring's lines are read before
    # motion starts (at least the 70 bytes of G93 and three moves: 5 ms), and no later than
    # predicted (the planner full), within its 1 ms trace; sooner where the host's lines come
    # too late to keep the receive buffer from running dry.
    measured = _pen_down_waits(run.executed)
    assert len(measured) == len(pen_down) == 3
    for got, (before, read) in zip(measured, predicted, strict=True):
        assert 0.005 <= got - before <= read + 0.003
    assert max(got - before for got, (before, _) in zip(measured, predicted, strict=True)) > 0.02
    # And the job: the simulator's time is the program's within 0.5 %.
    assert run.executed_duration == pytest.approx(program.duration, rel=0.005)


def test_no_read_time_no_wait():
    profile = load_profile(None, ("serial.read_time=0",))
    lines = ["G4P0.15\n", "G93\n", *["G1X1Y1F100\n"] * 20]
    waits = read_waits(lines, [False, False, *[True] * 20], [True, *[False] * 21], profile)
    assert not waits.any()
    profile = load_profile(None)
    waits = read_waits(lines, [False, False, *[True] * 20], [True, *[False] * 21], profile)
    assert waits[0] == pytest.approx((4 + 16 * 11) * profile["serial.read_time"])
