"""The Grbl program: exact output against a tiny profile, parsed by independent readers."""

from __future__ import annotations

import math
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
from .test_program_behaviour import _reading

EXAMPLES = Path(tagbot.__file__).parent / "examples"


OLD = ("place.scale=0.2", "motion.dt=0.2", "motion.setpoints=fixed", "motion.trim=false")
"""A slow tag sampled the old way: tails of one motor step per many setpoints."""


def _feed(line):
    return float(re.search(r"F([0-9.]+)", line)[1])


def _inverse_time_lines(lines):
    """Indices of the G1 lines between G93 and G94 (independent of Program's bookkeeping)."""
    out, inside = [], False
    for i, line in enumerate(lines):
        if line == "G93\n":
            inside = True
        elif line == "G94\n":
            inside = False
        elif inside and line.startswith("G1"):
            out.append(i)
    return out


def test_straight_stroke_structure(tiny, tiny_file):
    program = build_program(place(straight_tag(), tiny), tiny)
    lines = program.lines
    assert lines[:9] == (
        "G21\n",
        "G90\n",
        "G94\n",
        "M3S50\n",
        "G4P0.2\n",
        "G1X5.01Y25F1200\n",  # one step (0.01 mm) into the stroke: the trimmed start
        "M3S30\n",
        "G4P0.2\n",
        "G93\n",
    )
    assert lines[-6:] == ("G94\n", "M3S50\n", "G4P0.2\n", "G1X0Y0F1200\n", "M5\n", "M2\n")
    # One short run (18 lines or fewer): held whole by the machine once sent, so the buffer rule
    # leaves it at the machine's own speed.
    assert len(program.setpoint_lines) <= 18
    assert program.min_buffered_rx == math.inf
    free = load_profile(tiny_file, ["motion.min_buffer=0"])
    assert build_program(place(straight_tag(), free), free).drawing_time == pytest.approx(
        program.drawing_time
    )
    # The stroke ends one step (0.01 mm) short of x = 95: nothing is drawn within a step of it.
    setpoints = [lines[i] for i in program.setpoint_lines]
    assert setpoints[-1].startswith("G1X94.99Y25F")
    assert program.setpoint_lines == tuple(_inverse_time_lines(lines))


def test_no_dwell_shorter_than_grbl_executes(tiny_file):
    """Grbl waits ceil(20·P)·50 ms for G4 P: every dwell is a whole number of 50 ms steps, and
    the plan counts what Grbl waits."""
    for mode in ("clamp", "dwell"):
        for dwell in ("0.2", "0.12", "0.01"):
            profile = load_profile(
                tiny_file,
                [*OLD, f"motion.slow_lines={mode}", f"pen.dwell={dwell}", "serial.read_time=0"],
            )
            program = build_program(place(straight_tag(), profile), profile)
            idle = profile["limits.step_idle_delay"]
            for i, line in enumerate(program.lines):
                if not line.startswith("G4P"):
                    continue
                p = float(line[3:])
                steps = round(p / 0.05)
                assert steps >= 1 and p == pytest.approx(0.05 * steps, abs=1e-12), line
                waited = program.line_end[i] - program.line_start[i]
                # A dwell right after a move waits for the stop, then Grbl's $1, then P.
                after_move = program.line_moves[i - 1]
                assert waited == pytest.approx(p + idle if after_move else p), (line, waited)
            dwells = [float(x[3:]) for x in program.lines if x.startswith("G4P")]
            pen = 0.05 * np.ceil(float(dwell) / 0.05 - 1e-9)
            assert dwells.count(pytest.approx(pen)) == 3  # pen up, down, up
            inside, within = [], False
            for line in program.lines:
                within = (within or line == "G93\n") and line != "G94\n"
                if within and line.startswith("G4P"):
                    inside.append(line)
            assert (len(inside) == 0) == (mode == "clamp"), mode


def test_slow_lines_never_slower_than_grbl_steps(tiny_file):
    """Each setpoint line lasts at most what Grbl can take for it: its motor steps at the
    slowest step rate (or the minimum feed); independently parsed from the text."""
    profile = load_profile(tiny_file, ["place.scale=0.5"])
    program = build_program(place(straight_tag(), profile), profile)
    state = ParserState()
    per_mm = 100.0
    for i, line in enumerate(program.lines):
        before = state.position
        step = state.step(parse_line(line))
        state = step.state
        if program.line_run[i] < 0:
            continue
        steps = max(
            abs(round(state.position[a] * per_mm) - round(before[a] * per_mm)) for a in range(2)
        )
        assert steps >= 1, line  # every line moves the motor
        duration = 60.0 / _feed(line)
        assert duration <= steps * profile["limits.slowest_step"] * (1 + 1e-3), line
        assert duration == pytest.approx(program.line_end[i] - program.line_start[i], rel=1e-6)


def _trapezoid(length, v, a):
    if length >= v * v / a:
        return length / v + v / a
    return 2 * np.sqrt(length / a)


def test_line_metadata_against_an_independent_reading(tiny):
    program = build_program(place(two_plan_tag(), tiny), tiny)
    lines = program.lines
    n = len(lines)
    for name in ("line_start", "line_end", "line_xy", "line_pen", "line_run", "line_moves"):
        assert len(getattr(program, name)) == n, name
    assert program.line_start[0] == 0.0
    assert np.all(program.line_start[1:] == program.line_end[:-1])  # one line after another
    assert program.duration == program.line_end[-1]
    state = ParserState(position=(tiny["motion.park_x"], tiny["motion.park_y"], 0.0))
    down = False
    run = -1
    inside = False
    idle = tiny["limits.step_idle_delay"]
    moved_since_stop = False
    for i, line in enumerate(lines):
        before = state.position
        step = state.step(parse_line(line))
        state = step.state
        assert tuple(program.line_xy[i]) == pytest.approx(state.position[:2]), line
        moves = any(round(state.position[a] * 100) != round(before[a] * 100) for a in range(2))
        assert program.line_moves[i] == moves, line
        if line.startswith("M3S"):
            down = line == "M3S30\n"
        assert program.line_pen[i] == down, line
        if line == "G93\n":
            inside, run = True, run + 1
        elif line == "G94\n":
            inside = False
        setpoint = inside and line.startswith("G1")
        assert program.line_run[i] == (run if setpoint else -1), line
        duration = program.line_end[i] - program.line_start[i]
        stop = _reading(lines, i, tiny) if line.startswith(("M3", "M5", "G4")) else 0.0
        if line.startswith(("M3", "M5", "G4")) and moved_since_stop:
            stop, moved_since_stop = stop + idle, False
        if moves:
            moved_since_stop = True
        if setpoint:
            assert duration == pytest.approx(60.0 / _feed(line), rel=1e-6), line
        elif line.startswith("G1") and moves:  # travel: Grbl's trapezoid, rest to rest
            d = np.subtract(state.position[:2], before[:2])
            length = float(np.hypot(*d))
            # Grbl's acceleration along the move: the axes' 1e5 mm/s² over |u_axis|.
            a = min(1e5 / abs(c / length) for c in d if c != 0)
            expected = _trapezoid(length, _feed(line) / 60.0, a)
            assert duration == pytest.approx(expected, rel=1e-9), line
        elif line.startswith("G4P"):
            assert duration == pytest.approx(stop + float(line[3:])), line
        else:
            assert duration == pytest.approx(stop), line


def test_planned_runs_timeline_and_buffer(tiny):
    program = build_program(place(two_plan_tag(), tiny), tiny)
    runs = program.planned_runs
    assert len(runs) == 2 and program.run_plans == (0, 1)
    for k, (t, xy) in enumerate(runs):
        rows = np.flatnonzero(program.line_run == k)
        assert t[0] == program.line_start[rows[0]]
        assert np.allclose(t[1:], program.line_end[rows])
        assert np.allclose(xy[1:], program.line_xy[rows])
        assert np.allclose(xy[0], program.line_xy[rows[0] - 1])  # where the pen went down
    table = program.timeline(0.01)
    assert table.t[0] == 0.0 and table.t[-1] == pytest.approx(program.duration)
    assert np.all(np.diff(table.t) > 0)
    # The speed column is the velocity's magnitude, its x and its y part both counted.
    assert np.max(np.abs(table.v[:, 0])) > 1.0
    assert np.allclose(table.speed, np.sqrt(table.v[:, 0] ** 2 + table.v[:, 1] ** 2))
    xy, _, pen = program.at(program.line_end)
    assert np.allclose(xy, program.line_xy, atol=1e-9)
    assert np.array_equal(pen, program.line_pen)
    # Pen down exactly while a run's lines (and the lowering pen's dwell) execute.
    for t, _ in runs:
        mid = (table.t > t[0] + 1e-6) & (table.t < t[-1] - 1e-6)
        assert np.all(table.pen[mid] == 1)
    assert table.pen[0] == 0 and table.pen[-1] == 0
    # Velocities integrate to the positions (trapezoid rule, 1 ms).
    fine = np.arange(0.0, program.duration, 0.0005)
    p, vel, _ = program.at(fine)
    travel = np.cumsum(vel[:-1] * 0.0005, axis=0) + p[0]
    assert np.max(np.abs(travel[-1] - p[-1])) < 0.2
    # The planner's least buffered motion: 15 (18) consecutive setpoint lines of the runs longer
    # than that, from the parsed feeds (a shorter run is held whole once sent).
    for blocks, value in ((15, program.min_buffered), (18, program.min_buffered_rx)):
        best = np.inf
        for k in range(2):
            rows = np.flatnonzero(program.line_run == k)
            durations = [60.0 / _feed(program.lines[i]) for i in rows]
            windows = [sum(durations[i : i + blocks]) for i in range(len(durations) - blocks + 1)]
            best = min(best, min(windows, default=np.inf) if len(durations) > blocks else np.inf)
        assert value == pytest.approx(best, rel=1e-6), blocks
    # motion.min_buffer (0.6 s) bounds what a host pause may use: 14 queued blocks + 4 in RX.
    assert program.min_buffered_rx >= 0.6 * (1 - 1e-6)


def test_pen_moves_and_travel_not_stretched_by_the_time_scale(tiny_file):
    # (No reading after stops: its length depends on the setpoint lines' text.)
    fast = load_profile(tiny_file, ["motion.min_buffer=0", "serial.read_time=0"])
    slow = load_profile(
        tiny_file,
        [
            "motion.min_buffer=0",
            "limits.x_max_feed=3000",
            "limits.y_max_feed=3000",
            "serial.read_time=0",
        ],
    )
    a = build_program(place(two_plan_tag(), fast), fast)
    b = build_program(place(two_plan_tag(), slow), slow)
    assert min(b.run_scales) > 1.0 and a.run_scales == (1.0, 1.0)
    pen_or_travel_a = (a.line_run < 0) & (a.line_end > a.line_start)
    pen_or_travel_b = (b.line_run < 0) & (b.line_end > b.line_start)
    da = (a.line_end - a.line_start)[pen_or_travel_a]
    db = (b.line_end - b.line_start)[pen_or_travel_b]
    # Same pauses, same travel (the travel feed is below both limits; the runs end within a
    # step of the same points).
    assert np.allclose(da, db, rtol=0, atol=1e-3)
    assert b.drawing_time > 1.5 * a.drawing_time


def test_z_pen_sequence(tiny_file):
    profile = load_profile(tiny_file, ["pen.type=z", "pen.up=3", "pen.down=-0.5", "pen.dwell=0"])
    program = build_program(place(straight_tag(), profile), profile)
    lines = program.lines
    assert lines[:7] == (
        "G21\n",
        "G90\n",
        "G94\n",
        "G1Z3F1000\n",
        "G1X5.01Y25F1200\n",
        "G1Z-0.5F1000\n",
        "G93\n",
    )
    assert lines[-5:] == ("G94\n", "G1Z3F1000\n", "G1X0Y0F1200\n", "M5\n", "M2\n")
    assert not any(line.startswith(("G4", "M3")) for line in lines)
    lower = lines.index("G1Z-0.5F1000\n")
    assert program.line_pen[lower] and program.line_moves[lower]
    # 3.5 mm at 1000 mm/min capped by $112 = 500 mm/min, at $122 = 10 mm/s², rest to rest:
    # 3.5 mm < v²/a = 6.9 mm, so a triangle of 2·√(L/a).
    assert program.line_end[lower] - program.line_start[lower] == pytest.approx(
        2 * np.sqrt(3.5 / 10)
    )
    faster = load_profile(
        tiny_file,
        ["pen.type=z", "pen.up=3", "pen.down=-0.5", "pen.dwell=0", "limits.z_acceleration=1e4"],
    )
    other = build_program(place(straight_tag(), faster), faster)
    assert other.line_end[lower] - other.line_start[lower] == pytest.approx(
        _trapezoid(3.5, 500 / 60, 1e4)
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


def test_dwell_mode_keeps_the_setpoint_times(tiny_file):
    """slow_lines = dwell: a line slower than Grbl steps waits first (whole 50 ms steps), then
    steps at Grbl's slowest rate; the lines still end near their setpoint times."""
    profile = load_profile(tiny_file, [*OLD, "motion.slow_lines=dwell"])
    placed = place(straight_tag(), profile)
    program = build_program(placed, profile)
    lines = program.lines
    slowest = profile["limits.slowest_step"]
    dwelt = 0
    for i in program.setpoint_lines:
        if lines[i - 1].startswith("G4P"):
            dwelt += 1
            before, after = program.line_xy[i - 2], program.line_xy[i]
            steps = max(abs(round(after[a] * 100) - round(before[a] * 100)) for a in range(2))
            assert 60.0 / _feed(lines[i]) == pytest.approx(steps * slowest, rel=1e-5)
    assert dwelt > 0
    run = placed.runs[0]
    begin = program.line_start[program.setpoint_lines[0]]
    ends = np.array(program.setpoint_times) - begin
    # Each line ends at its setpoint time, or earlier by less than one dwell step and $1.
    late = ends - run.t[1:]
    assert np.all(late <= 1e-6)
    assert np.all(late >= -(0.05 + profile["limits.step_idle_delay"]) - 1e-6)
    assert abs(late[-1]) < 0.05 + profile["limits.step_idle_delay"]


def _stream_with_host_stalls(program, profile, name, pause=0.5, every=2.0):
    """Stream into the simulated Grbl while the host stalls ``pause`` s every ``every`` s."""
    import serial

    from sim.grbl import SimulatedGrbl
    from sim.grbl.transport import attach_device
    from tagbot.plotter.machine import simulated_pen
    from tagbot.plotter.profile import device_settings
    from tagbot.plotter.program import pen_up
    from tagbot.plotter.stream import GrblStreamer, StreamOptions

    device = SimulatedGrbl(device_settings(profile), **simulated_pen(profile))
    link = serial.serial_for_url(attach_device(device, name), baudrate=115200, timeout=0.01)
    try:
        streamer = GrblStreamer(link, StreamOptions())
        streamer.connect()
        start = link.clock.now()
        for k in range(1, int(program.duration / every) + 1):
            link.freeze_host(start + k * every, pause)
        streamer.stream(
            list(program.lines),
            pen_up=pen_up(profile),
            moves=program.line_moves,
            targets=program.line_xy,
        )
        return len(device.starvation), streamer.last_report.duration
    finally:
        link.close()


def test_host_pauses_of_half_a_second_do_not_starve_the_planner():
    tag = tagbot.load_plan(EXAMPLES / "letter-b.json")
    profile = load_profile()
    program = build_program(place(tag, profile), profile)
    assert program.min_buffered_rx > 0.5
    starved, executed = _stream_with_host_stalls(program, profile, "stall_new")
    assert starved == 0
    assert executed == pytest.approx(program.duration, rel=0.01)
    # Lines of 10 ms (15 blocks: 0.15 s of motion) starve under the same stalls.
    old = load_profile(None, ["motion.setpoints=fixed", "motion.min_buffer=0"])
    starved, _ = _stream_with_host_stalls(build_program(place(tag, old), old), old, "stall_old")
    assert starved > 0


def test_a_buffer_goal_the_lines_cannot_hold_is_warned_with_the_figure(
    monkeypatch, capsys, tmp_path
):
    """motion.min_buffer = 2 s on letter-b: slowing the tag shortens its least window (more
    lines clamped to Grbl's slowest step), so the placement keeps the natural timing. The
    command says so, with the figure the program holds; at the default 0.6 s, no warning."""
    from tagbot.cli import cli, main
    from tagbot.plotter.program import host_pause_warnings

    monkeypatch.setitem(cli.commands, "gcode", gcode_command)
    tag = tagbot.load_plan(EXAMPLES / "letter-b.json")
    profile = load_profile(None, ["motion.min_buffer=2"])
    program = build_program(place(tag, profile), profile)
    held = program.min_buffered_rx
    assert 0.5 < held < 2.0
    expected = (
        f"host pauses: the lines hold {held:.3f} s of motion mid-run at least, less than "
        "motion.min_buffer = 2 s (slowing the tag did not lengthen them: motion.max_dt or Grbl's "
        f"slowest step bounds them); a host pause longer than {held:.3f} s there starves the "
        "planner"
    )
    assert host_pause_warnings(program, profile) == [expected]
    out = tmp_path / "b.gcode"
    args = ["gcode", str(EXAMPLES / "letter-b.json"), "-o", str(out)]
    assert main([*args, "--set", "motion.min_buffer=2"]) == 0
    assert capsys.readouterr().err.splitlines()[1:] == [f"tagbot: warning: {expected}"]
    assert main(args) == 0
    assert "warning" not in capsys.readouterr().err


def test_a_buffer_goal_met_exactly_or_with_fixed_lines_is_no_warning():
    """The warning compares the program's own figure with the goal: met at equality, and
    fixed setpoints (no buffer rule) are never warned about."""
    from tagbot.plotter.program import host_pause_warnings

    tag = tagbot.load_plan(EXAMPLES / "letter-b.json")
    free = load_profile(None, ["motion.min_buffer=0"])
    program = build_program(place(tag, free), free)
    held = program.min_buffered_rx
    at = load_profile(None, [f"motion.min_buffer={held!r}"])
    assert host_pause_warnings(program, at) == []
    above = load_profile(None, [f"motion.min_buffer={held * 1.0001!r}"])
    assert len(host_pause_warnings(program, above)) == 1
    fixed = load_profile(None, [f"motion.min_buffer={held * 2!r}", "motion.setpoints=fixed"])
    assert host_pause_warnings(program, fixed) == []
