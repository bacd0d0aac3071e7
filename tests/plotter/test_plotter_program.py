"""The Grbl program: exact output against a tiny profile, parsed by independent readers."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import tagbot
from firmware_protocols.grbl.gcode import MAX_LINE
from firmware_protocols.grbl.messages import Error
from firmware_protocols.grbl.parse import ParserState, parse_line
from tagbot.plotter import build_program, load_profile, place
from tagbot.plotter.cli import gcode_command
from tagbot.plotter.place import PlacementError

from .conftest import straight_tag, two_plan_tag

EXAMPLES = Path(tagbot.__file__).parent / "examples"

STRAIGHT = """\
G21
G90
G94
M3S50
G4P0.2
G1X5Y25F1200
M3S30
G4P0.2
G93
G1X5.939Y25F600
G1X20.191Y25F1200
G1X50Y25F1200
G1X74.435Y25F1200
G1X87.057Y25F1200
G1X92.204Y25F1200
G1X94.061Y25F1200
G1X94.691Y25F1200
G1X94.898Y25F1200
G1X94.966Y25F1200
G1X94.989Y25F1200
G1X94.996Y25F1834.862
G94
M3S50
G4P0.2
G1X0Y0F1200
M5
M2
"""


def test_straight_stroke_byte_for_byte(tiny):
    program = build_program(place(straight_tag(), tiny), tiny)
    assert program.text == STRAIGHT
    assert program.scale == 1.0
    # The first setpoint (t = 0.05 s) does not move: it is merged into the next line (F600 =
    # 0.1 s), so each line's end time is still the setpoint time. At 100 steps/mm, 94.996 is one
    # step after 94.989 (9499 → 9500): 0.05 s for one step is slower than Grbl's slowest step
    # (0.0327 s), so the step runs at F = 60/0.0327; the 0.017 s surplus is shorter than Grbl's
    # step idle delay ($1, 25 ms) that a G4 would cost, so no dwell: the line ends early. The
    # last setpoints (94.999, 95) round to the same step and are not sent.
    assert program.setpoint_times[:3] == pytest.approx([0.1, 0.15, 0.2])
    assert [program.lines[i] for i in program.setpoint_lines[:2]] == [
        "G1X5.939Y25F600\n",
        "G1X20.191Y25F1200\n",
    ]
    durations = np.diff(np.concatenate([[0.0], program.setpoint_times]))
    feeds = [float(re.search(r"F([0-9.]+)", program.lines[i])[1]) for i in program.setpoint_lines]
    assert np.allclose(feeds[:-1], 60.0 / durations[:-1])
    assert 0.017 + 60.0 / feeds[-1] == pytest.approx(durations[-1], abs=1e-3)  # early by 17 ms


def test_slow_moves_dwell_less_grbls_step_idle_delay(tiny_file):
    """A G4 costs its P plus Grbl's step idle delay ($1): the dwell is shortened by it."""
    profile = load_profile(tiny_file, ["limits.step_idle_delay=0.005"])
    program = build_program(place(straight_tag(), profile), profile)
    assert "G4P0.012\nG1X94.996Y25F1834.862\n" in program.text
    none = load_profile(tiny_file, ["limits.step_idle_delay=0"])
    assert (
        "G4P0.017\nG1X94.996Y25F1834.862\n" in build_program(place(straight_tag(), none), none).text
    )


def test_z_pen_sequence(tiny_file):
    profile = load_profile(tiny_file, ["pen.type=z", "pen.up=3", "pen.down=-0.5", "pen.dwell=0"])
    lines = build_program(place(straight_tag(), profile), profile).lines
    assert lines[:8] == (
        "G21\n",
        "G90\n",
        "G94\n",
        "G1Z3F1000\n",
        "G1X5Y25F1200\n",
        "G1Z-0.5F1000\n",
        "G93\n",
        "G1X5.939Y25F600\n",
    )
    assert lines[-6:] == (
        "G1X94.996Y25F1834.862\n",
        "G94\n",
        "G1Z3F1000\n",
        "G1X0Y0F1200\n",
        "M5\n",
        "M2\n",
    )


def test_pen_lifts_between_plans(tiny):
    program = build_program(place(two_plan_tag(), tiny), tiny)
    text = program.text
    assert text.count("G93\n") == 2
    assert text.count("G94\n") == 3
    assert text.count("M3S30\nG4P0.2\nG93\n") == 2
    # After each run: back to mm/min, pen up, then a travel with its own F.
    assert re.search(r"G94\nM3S50\nG4P0\.2\nG1X[0-9.]+Y[0-9.]+F1200\nM3S30\n", text)


def _check_with_grbl_reader(lines):
    state = ParserState()
    for line in lines:
        block = parse_line(line)
        assert not isinstance(block, Error), line
        step = state.step(block)
        assert not isinstance(step, Error), (line, step)
        state = step.state
    return state


def test_every_line_parses(tiny):
    pygcode = pytest.importorskip("pygcode")
    lines = build_program(place(two_plan_tag(), tiny), tiny).lines
    for line in lines:
        assert line.endswith("\n") and len(line) <= MAX_LINE
        assert " " not in line
        assert not re.search(r"[eE]", line)
        parsed = pygcode.Line(line.strip())
        assert parsed.block.gcodes, line
    _check_with_grbl_reader(lines)


def test_out_of_bed_refused_before_output(tiny_file, tmp_path):
    profile = load_profile(tiny_file, ["place.scale=20", "place.align=bottom-left"])
    with pytest.raises(PlacementError) as raised:
        place(straight_tag(), profile)
    assert str(raised.value) == (
        "placement: the drawing reaches x = 205.000 mm, beyond bed.x_max = 100 mm by 105.000 mm"
        " (reduce place.scale or move it)"
    )
    centred = load_profile(tiny_file, ["place.scale=20"])
    with pytest.raises(PlacementError, match=r"x = -50\.000 mm, beyond bed\.x_min = 0 mm"):
        place(straight_tag(), centred)
    plan = EXAMPLES / "cae.json"
    out = tmp_path / "out.gcode"
    result = CliRunner().invoke(
        gcode_command,
        [str(plan), "-o", str(out), "--profile", str(tiny_file), "--set", "place.scale=5"],
    )
    assert isinstance(result.exception, PlacementError)
    assert not out.exists()


def test_real_tag_end_to_end(tmp_path):
    out = tmp_path / "cae.gcode"
    result = CliRunner().invoke(gcode_command, [str(EXAMPLES / "cae.json"), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "lines" in result.output and "time scale" in result.output
    lines = out.read_text(encoding="ascii").splitlines(keepends=True)
    assert lines[:3] == ["G21\n", "G90\n", "G94\n"]
    assert lines[-2:] == ["M5\n", "M2\n"]
    state = _check_with_grbl_reader(lines)
    assert state.feed_mode == "G94" and state.position[:2] == (0.0, 0.0)
    profile = load_profile()
    x_min, x_max, y_min, y_max = profile.bed
    tag = tagbot.load_plan(EXAMPLES / "cae.json")
    assert out.read_text() == build_program(place(tag, profile), profile).text
    for line in lines:
        assert len(line) <= MAX_LINE
        for axis, value in re.findall(r"([XY])(-?[0-9.]+)", line):
            low, high = (x_min, x_max) if axis == "X" else (y_min, y_max)
            assert low <= float(value) <= high


def test_trace_input_is_fitted_first(tmp_path):
    points = tmp_path / "stroke.csv"
    rows = [(10 * np.cos(a), 10 * np.sin(a), a / 4) for a in np.linspace(0, 3, 40)]
    points.write_text("x,y,t\n" + "".join(f"{x},{y},{t}\n" for x, y, t in rows))
    out = tmp_path / "stroke.gcode"
    result = CliRunner().invoke(
        gcode_command, [str(points), "-o", str(out), "--profile", "zpen", "--set", "motion.dt=0.02"]
    )
    assert result.exit_code == 0, result.output
    lines = out.read_text().splitlines(keepends=True)
    assert "G93\n" in lines and lines[-1] == "M2\n"
    _check_with_grbl_reader(lines)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--set", "place.scale=100"],
            "tagbot: error: placement: the drawing reaches x = ",
        ),
        (["--set", "bed.margin=-1"], "tagbot: error: --set: bed.margin: must be >= 0, got -1"),
        (["--profile", "nope"], "tagbot: error: nope: no such profile file"),
    ],
)
def test_registered_command_reports_one_line(monkeypatch, capsys, tmp_path, args, message):
    from tagbot.cli import cli, main

    monkeypatch.setitem(cli.commands, "gcode", gcode_command)  # what tagbot/cli.py will register
    out = tmp_path / "x.gcode"
    status = main(["gcode", str(EXAMPLES / "cae.json"), "-o", str(out), *args])
    err = capsys.readouterr().err
    assert status == 2
    assert err.startswith(message) and err.count("\n") == 1
    assert not out.exists()


def test_registered_command_writes(monkeypatch, capsys, tmp_path):
    from tagbot.cli import cli, main

    monkeypatch.setitem(cli.commands, "gcode", gcode_command)
    out = tmp_path / "b.gcode"
    assert (
        main(["gcode", str(EXAMPLES / "letter-b.json"), "-o", str(out), "--profile", "zpen"]) == 0
    )
    err = capsys.readouterr().err
    assert re.fullmatch(
        r"wrote .*b\.gcode: \d+ lines, [0-9.]+ s \(drawing [0-9.]+ s\), time scale [0-9.]+\n", err
    )
    assert "G1Z5F1000\n" in out.read_text()


def test_slow_tails_dwell_then_step_at_grbl_slowest_rate(tiny_file):
    # 100× slower than the tiny tag's natural pace: tails of one step per many setpoints.
    profile = load_profile(tiny_file, ["place.scale=0.5"])
    tag = straight_tag()
    program = build_program(place(tag, profile), profile)
    lines = program.lines
    slowest = profile["limits.slowest_step"]
    for i in program.setpoint_lines:
        feed = float(re.search(r"F([0-9.]+)", lines[i])[1])
        if lines[i - 1].startswith("G4P"):
            # One step in 0.01 mm: run at exactly Grbl's slowest step after the dwell.
            assert 60.0 / feed == pytest.approx(slowest, abs=1e-6)
    assert any(line.startswith("G4P") for line in lines[lines.index("G93\n") :])
    times = np.array(program.setpoint_times)
    assert np.all(np.diff(times) > 0)
