"""Properties over random tags and machines: limits hold, everything stays on the bed and parses."""

from __future__ import annotations

import itertools
import math
import re

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocols.grbl.gcode import MAX_LINE
from firmware_protocols.grbl.messages import Error
from firmware_protocols.grbl.parse import ParserState, parse_line
from tagbot.model import Plan, Tag
from tagbot.plotter import build_program, load_profile, place
from tagbot.plotter.place import segment_speed_cap

coordinate = st.floats(-50, 50, allow_nan=False, allow_subnormal=False)


@st.composite
def tags(draw):
    n = draw(st.integers(2, 4))
    targets = [[draw(coordinate), draw(coordinate)] for _ in range(n)]
    for a, b in itertools.pairwise(targets):
        if math.hypot(b[0] - a[0], b[1] - a[1]) < 1.0:
            b[0] = a[0] + 5.0
    strokes = n - 1
    plan = Plan(
        targets=targets,
        dt=[0.0] + [draw(st.floats(0.05, 0.3)) for _ in range(strokes - 1)],
        mu=[math.log(draw(st.floats(0.1, 0.4))) for _ in range(strokes)],
        sigma=[draw(st.floats(0.2, 0.5)) for _ in range(strokes)],
        phi1=[draw(st.floats(-1.0, 1.0)) for _ in range(strokes)],
        phi2=[draw(st.floats(-1.0, 1.0)) for _ in range(strokes)],
    )
    return Tag(plans=(plan,))


machines = st.fixed_dictionaries(
    {
        "limits.x_max_feed": st.floats(600, 12000),
        "limits.y_max_feed": st.floats(600, 12000),
        "limits.x_acceleration": st.floats(50, 2000),
        "limits.y_acceleration": st.floats(50, 2000),
        "motion.dt": st.sampled_from([0.005, 0.01, 0.02]),
        "motion.time_scale": st.sampled_from(["run", "uniform"]),
        "motion.setpoints": st.sampled_from(["adaptive", "fixed"]),
        "motion.slow_lines": st.sampled_from(["clamp", "dwell"]),
        "motion.tolerance": st.sampled_from([0.005, 0.01, 0.05]),
        "bed.y_down": st.booleans(),
        "place.rotation": st.floats(-180, 180),
    }
)


def _toml(value):
    if isinstance(value, str):
        return f'"{value}"'
    return ("true" if value else "false") if isinstance(value, bool) else repr(value)


@settings(max_examples=25, deadline=None)
@given(tags(), machines)
def test_placed_program_respects_the_machine(tag, machine):
    overrides = [f"{k}={_toml(v)}" for k, v in machine.items()]
    profile = load_profile(None, ["bed.x_max=200", "bed.y_max=150", *overrides])
    placed = place(tag, profile)
    assert placed.scale >= 1.0 and min(placed.run_scales) >= 1.0
    if machine["motion.time_scale"] == "uniform":
        assert set(placed.run_scales) == {placed.scale}
    vmax = np.array(profile.max_speed)
    for run in placed.runs:
        assert np.all(np.abs(run.v) <= vmax * (1 + 1e-6))
        speed, cap = segment_speed_cap(run.xy, run.t, profile)
        assert np.all(speed <= cap * (1 + 1e-6))
        d = np.diff(run.t)
        assert np.all(d > 0)
        assert np.all(np.abs(np.diff(run.xy, axis=0)) / d[:, None] <= vmax * (1 + 1e-6))
    program = build_program(placed, profile)
    n = len(program.lines)
    assert program.line_xy.shape == (n, 2) and len(program.line_end) == n
    assert np.all(program.line_end >= program.line_start)
    assert np.all(program.line_start[1:] == program.line_end[:-1])
    assert program.duration >= program.drawing_time > 0
    assert program.run_scales == placed.run_scales
    within = False
    for line in program.lines:
        if line.startswith("G4P"):
            p = float(line[3:])
            assert p >= 0.05 and abs(p / 0.05 - round(p / 0.05)) < 1e-9, line  # Grbl's 50 ms
            if machine["motion.slow_lines"] == "clamp":
                assert not within, "a dwell inside a run"
        within = (within or line == "G93\n") and line != "G94\n"
    state = ParserState()
    for line in program.lines:
        assert len(line) <= MAX_LINE
        for axis, value in re.findall(r"([XY])(-?[0-9.]+)", line):
            high = 200.0 if axis == "X" else 150.0
            assert 0.0 <= float(value) <= high
        step = state.step(parse_line(line))
        assert not isinstance(step, Error), line
        state = step.state
