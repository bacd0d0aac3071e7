"""The pen's G-code a resume or a stop sends, and the job's motion at and after its end (issue 34).

The machine lifts the pen on a stop and lifts and lowers it in a resume's preamble with
``pen_up``/``pen_down``: they must be the very lines the job itself uses, carrying the profile's
values. A motion table sampled coarser than the job still has its start and end.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from tagbot.plotter import build_program, load_profile, place
from tagbot.plotter.program import Program, pen_down, pen_up

from .conftest import straight_tag

PENS = {
    "servo": ["pen.type=servo", "pen.up=50", "pen.down=30", "pen.dwell=0.12"],
    "z": ["pen.type=z", "pen.up=5", "pen.down=0.5", "pen.feed=800", "pen.dwell=0"],
}


def _words(line: str) -> dict[str, float]:
    return {k: float(v) for k, v in re.findall(r"([A-Z])(-?[0-9.]+)", line)}


@pytest.mark.parametrize("pen", sorted(PENS))
def test_pen_lines_carry_the_profile_and_are_the_jobs_own(tiny_file, pen):
    profile = load_profile(tiny_file, PENS[pen])
    program = build_program(place(straight_tag(), profile), profile)
    steps = math.ceil(20 * profile["pen.dwell"] - 1e-9)
    for lines, value in ((pen_up(profile), 50.0 if pen == "servo" else 5.0),
                         (pen_down(profile), 30.0 if pen == "servo" else 0.5)):  # fmt: skip
        first = _words(lines[0])
        if pen == "servo":
            assert first == {"M": 3.0, "S": value}
        else:
            assert first == {"G": 1.0, "Z": value, "F": 800.0}
        if steps:
            assert _words(lines[1]) == {"G": 4.0, "P": pytest.approx(steps / 20)}
        assert len(lines) == 1 + (steps > 0)
        text = "".join(lines)
        assert text in "".join(program.lines)  # the job lifts and lowers with the same lines
    assert pen_up(profile) != pen_down(profile)


def test_after_the_job_the_pen_rests_up_where_it_ended(tiny_file):
    profile = load_profile(tiny_file)
    program = build_program(place(straight_tag(), profile), profile)
    xy, v, pen = program.at(np.array([program.duration, program.duration + 1.0]))
    assert xy == pytest.approx(np.tile(program.line_xy[-1], (2, 1)))
    assert np.all(v == 0.0)
    assert not pen.any()


def test_a_timeline_coarser_than_the_job_has_its_start_and_end(tiny_file):
    profile = load_profile(tiny_file)
    program = build_program(place(straight_tag(), profile), profile)
    table = program.timeline(2 * program.duration)
    assert table.t.tolist() == [0.0, program.duration]
    assert table.xy[-1] == pytest.approx(program.line_xy[-1])


@pytest.mark.parametrize("dt", [0.0, -0.01])
def test_a_timeline_step_not_above_zero_is_refused(tiny_file, dt):
    """A sampling step of 0 s or less is refused, naming ``dt``."""
    profile = load_profile(tiny_file)
    program = build_program(place(straight_tag(), profile), profile)
    with pytest.raises(ValueError, match=r"^dt: must be > 0$"):
        program.timeline(dt)


def _empty_program(start: tuple[float, float] = (0.0, 0.0)) -> Program:
    return Program(
        lines=(),
        line_start=np.zeros(0),
        line_end=np.zeros(0),
        line_xy=np.zeros((0, 2)),
        line_pen=np.zeros(0, dtype=bool),
        line_run=np.zeros(0, dtype=np.int64),
        line_moves=np.zeros(0, dtype=bool),
        run_plans=(),
        run_scales=(),
        scale=1.0,
        drawing_time=0.0,
        min_buffered=math.inf,
        notes_start=np.array(start),
    )


def test_a_program_without_lines_has_no_motion_at_no_instants():
    """A hand-built program of no lines, sampled at no instants, gives empty arrays of the
    usual shapes: positions (0, 2), velocities (0, 2), pen (0,)."""
    empty = _empty_program()
    xy, v, pen = empty.at(np.zeros(0))
    assert (xy.shape, v.shape, pen.shape) == ((0, 2), (0, 2), (0,))
    assert empty.duration == 0.0


def test_a_program_without_lines_rests_pen_up_where_it_starts():
    """Its timeline is one instant, 0 s, at the start point, still, pen up."""
    table = _empty_program((3.0, 4.0)).timeline(0.01)
    assert table.t.tolist() == [0.0] and table.xy.tolist() == [[3.0, 4.0]]
    assert table.v.tolist() == [[0.0, 0.0]] and table.speed.tolist() == [0.0]
    assert table.pen.tolist() == [0]
    xy, v, pen = _empty_program((3.0, 4.0)).at(np.array([-1.0, 0.5]))
    assert xy.tolist() == [[3.0, 4.0]] * 2 and not v.any() and pen.tolist() == [False] * 2
