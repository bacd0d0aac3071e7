"""Planned times the program states, computed independently: Grbl reading the lines after a
stop, and the Z pen's moves (issue 34)."""

from __future__ import annotations

import math

import pytest

from tagbot.plotter import build_program, load_profile, place
from tagbot.plotter.program import read_waits

from .conftest import straight_tag

LINES = ["G4P0.15\n", "G93\n", *["G1X1Y1F100\n"] * 20]
MOVES = [False, False, *[True] * 20]
SYNC = [True, *[False] * 21]


@pytest.mark.parametrize(
    ("read_time", "expected"),
    [
        # Slower than the wire brings bytes (86.8 us a byte at 115200 baud): never dry; motion
        # starts when the 16th move (beyond the 15 planner blocks) is read: 4 + 16 x 11 bytes.
        (0.001, (4 + 16 * 11) * 0.001),
        # Much faster: the 127-byte buffer runs dry first, at 127 / (1/read - 1/wire).
        (1e-5, 127 / (1 / 1e-5 - 115200 / 10)),
    ],
)
def test_a_stop_line_waits_while_grbl_reads_what_follows(read_time: float, expected: float):
    profile = load_profile(None, (f"serial.read_time={read_time}", "serial.baud=115200"))
    assert profile["limits.planner_blocks"] == 15
    waits = read_waits(LINES, MOVES, SYNC, profile)
    assert waits[0] == pytest.approx(expected, rel=1e-12)
    assert not waits[1:].any()  # only stop lines wait


def test_z_pen_moves_take_their_trapezoid_and_the_first_takes_none(tiny_file):
    """Z moves at pen.feed capped by $112 (500 mm/min here) accelerating at $122 (10 mm/s²): a
    4.5 mm move never reaches 8.33 mm/s, so it takes 2·√(4.5/10) s; the first Z move, from an
    unknown height, is planned as taking no time."""
    profile = load_profile(
        tiny_file,
        ["pen.type=z", "pen.up=5", "pen.down=0.5", "pen.feed=800", "pen.dwell=0"],
    )
    assert (profile["limits.z_max_feed"], profile["limits.z_acceleration"]) == (500.0, 10.0)
    program = build_program(place(straight_tag(), profile), profile)
    z = [i for i, line in enumerate(program.lines) if line.startswith("G1Z")]
    durations = [float(program.line_end[i] - program.line_start[i]) for i in z]
    assert program.lines[z[0]] == "G1Z5F800\n" and durations[0] == 0.0
    assert durations[1:] == pytest.approx([2 * math.sqrt(4.5 / 10)] * (len(z) - 1), rel=1e-12)


@pytest.mark.parametrize(("park", "travels"), [("0.003", False), ("0.006", True), ("0.02", True)])
def test_a_travel_within_half_a_motor_step_is_not_sent(tiny_file, park: str, travels: bool):
    """The tag's first point is (0, 0); the machine starts parked 0.3, 0.6 or 2 motor steps (of
    0.01 mm) away on each axis: Grbl rounds a target to the nearest step (lround), so at 0.3 it
    is already there and no travel is sent; the others need one."""
    profile = load_profile(
        tiny_file,
        [
            "bed.margin=0",
            "motion.trim=false",
            "place.align=bottom-left",
            f"motion.park_x={park}",
            f"motion.park_y={park}",
        ],
    )
    program = build_program(place(straight_tag(), profile), profile)
    first_down = program.lines.index("M3S30\n")
    travel = [line for line in program.lines[:first_down] if line.startswith("G1X")]
    assert travel == (["G1X0Y0F1200\n"] if travels else [])
