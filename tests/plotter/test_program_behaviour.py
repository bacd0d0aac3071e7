"""What a user reads off a plotter job, recomputed from the G-code alone (issue 34).

Job time, travel time, drawing time, the buffered motion and the resting share are recomputed
here from the program's lines and the profile's limits, by a reader written for the test: Grbl's
rest-to-rest trapezoid for travel, ``60/F`` for inverse-time lines, ``ceil(20·P)·50 ms`` for
dwells, ``$1`` after every stop that follows motion and, after each stop, Grbl reading the lines
the host sent meanwhile before motion starts again.
"""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest

from tagbot.model import Plan, Tag
from tagbot.plotter import build_program, load_profile, place
from tagbot.plotter.place import PlacementError, Run, Setpoints
from tagbot.plotter.program import resting_share

from .conftest import straight_tag

# Slow axes: the x feed cap binds on mostly-x travel, and an 8 mm hop never reaches full speed.
SLOW = (
    "limits.x_max_feed=900",
    "limits.y_max_feed=3000",
    "limits.x_acceleration=20",
    "limits.y_acceleration=80",
    "limits.step_idle_delay=0.025",
)


def _gap_tag() -> Tag:
    """Two strokes with a gap between them: along +x, then up from 1 unit further right."""
    first = straight_tag().plans[0]
    second = Plan(
        targets=[[11.0, 0.0], [11.0, 5.0]],
        dt=[0.0],
        mu=[math.log(0.2)],
        sigma=[0.3],
        phi1=[0.0],
        phi2=[0.0],
        start=first.end(10.0) + 0.5,
    )
    return Tag(plans=(first, second))


def _words(line: str) -> dict[str, float]:
    return {k: float(v) for k, v in re.findall(r"([A-Z])(-?[0-9.]+)", line)}


def _rest_to_rest(length: float, direction: np.ndarray, feed: float, profile) -> float:
    """Time of a G94 move: cruise speed and acceleration capped per axis, from rest to rest."""
    vmax = [profile["limits.x_max_feed"] / 60.0, profile["limits.y_max_feed"] / 60.0]
    amax = [profile["limits.x_acceleration"], profile["limits.y_acceleration"]]
    speed, accel = feed / 60.0, math.inf
    for axis in range(2):
        share = abs(direction[axis])
        if share > 0:
            speed = min(speed, vmax[axis] / share)
            accel = min(accel, amax[axis] / share)
    peak = min(speed, math.sqrt(accel * length))  # a triangle when it cannot reach cruise
    ramps = peak / accel  # each of the two ramps
    return 2.0 * ramps + (length - peak * ramps) / peak


def _reading(lines, k: int, profile) -> float:
    """After stop line ``k``: Grbl reads on at serial.read_time a byte until it reads the next
    stop line or a move the full planner cannot take, or its 127-byte buffer, refilled at the
    wire's 10 bits a byte, runs dry."""
    read, wire = profile["serial.read_time"], 10.0 / profile["serial.baud"]
    total = moves = 0
    for line in lines[k + 1 :]:
        total += len(line)
        if line.startswith(("G4P", "M3", "M5")):
            break
        moves += line.startswith("G1")
        if moves > profile["limits.planner_blocks"]:
            break
    dry = 127 / (1 / read - 1 / wire) if 0 < read < wire else math.inf
    return min(total * read, dry)


def _replay(lines, profile):
    """Job, travel and per-run drawing times and per-run setpoint durations, from the text."""
    idle = profile["limits.step_idle_delay"]
    here = np.array([profile["motion.park_x"], profile["motion.park_y"]], dtype=float)
    clock = travel = 0.0
    inverse = moved = False
    runs: list[list[float]] = []
    for k, line in enumerate(lines):
        word = _words(line)
        if line.startswith("G93"):
            inverse = True
            runs.append([])
        elif line.startswith("G94"):
            inverse = False
        elif line.startswith("G4P"):
            clock += math.ceil(round(word["P"] * 20, 9)) * 0.05 + (idle if moved else 0.0)
            clock += _reading(lines, k, profile)
            moved = False
        elif line.startswith(("M3", "M5")):
            clock += (idle if moved else 0.0) + _reading(lines, k, profile)
            moved = False
        elif line.startswith("G1") and "Z" not in word:
            target = np.array([word.get("X", here[0]), word.get("Y", here[1])])
            if inverse:
                runs[-1].append(60.0 / word["F"])
                clock += runs[-1][-1]
            else:
                d = target - here
                length = float(np.hypot(*d))
                spent = _rest_to_rest(length, d / length, word["F"], profile)
                travel += spent
                clock += spent
            here, moved = target, True
    return clock, travel, runs


@pytest.fixture
def slow(tiny_file):
    return load_profile(tiny_file, SLOW)


def test_job_time_is_the_sum_of_what_grbl_does(slow):
    """Travel trapezoids (capped per axis, short hops that never cruise), dwells with the idle
    delay after motion, inverse-time lines: the planned job time is their sum, line by line."""
    program = build_program(place(_gap_tag(), slow), slow)
    clock, travel, runs = _replay(program.lines, slow)
    assert len(runs) == 2
    assert program.duration == pytest.approx(clock, rel=1e-9)
    assert program.notes["travel_time"] == pytest.approx(travel, rel=1e-9)
    assert program.drawing_time == pytest.approx(sum(map(sum, runs)), rel=1e-9)
    assert f"{program.duration:.1f} s (drawing {program.drawing_time:.1f} s)" in program.summary()
    # Line by line: each line ends where the replay's clock says.
    assert program.line_end[-1] == pytest.approx(clock, rel=1e-9)


def _spans(program, prefix: str) -> list[float]:
    return [
        float(program.line_end[i] - program.line_start[i])
        for i, line in enumerate(program.lines)
        if line.startswith(prefix)
    ]


def test_servo_pen_change_waits_for_the_stop(tiny_file):
    """Servo pen: M3 waits for the stop (Grbl's $1 idle delay after motion), then the dwell."""
    profile = load_profile(
        tiny_file, ["limits.step_idle_delay=0.1", "pen.dwell=0.2", "serial.read_time=0"]
    )
    program = build_program(place(straight_tag(), profile), profile)
    assert _spans(program, "M3") == pytest.approx([0.0, 0.1, 0.1])  # nothing moved before #1
    assert _spans(program, "G4P") == pytest.approx([0.2, 0.2, 0.2])
    assert _spans(program, "M5") == pytest.approx([0.1])  # after the travel home
    assert program.notes["pen_time"] == pytest.approx(0.2 * 3 + 0.1 * 2)
    clock, _, _ = _replay(program.lines, profile)
    assert program.duration == pytest.approx(clock, rel=1e-9)


def test_zpen_lines_and_dwells(tiny_file):
    """Z pen: a G1 Z move at pen.feed, then the dwell, which waits for the stop after it."""
    profile = load_profile(
        tiny_file,
        [
            "pen.type=z",
            "pen.up=5",
            "pen.down=0",
            "pen.feed=600",
            "limits.step_idle_delay=0.1",
            "serial.read_time=0",
        ],
    )
    program = build_program(place(straight_tag(), profile), profile)
    assert program.lines[3:5] == ("G1Z5F600\n", "G4P0.2\n")
    assert program.lines.count("G1Z0F600\n") == 1
    assert not any(line.startswith("M3") for line in program.lines)
    assert _spans(program, "G4P") == pytest.approx([0.3, 0.3, 0.3])
    # the pen's time is its Z moves' and its dwells' (0.3 s each, with the stop)
    z_moves = _spans(program, "G1Z")
    assert len(z_moves) == 3 and sum(z_moves) > 0.0
    assert program.notes["pen_time"] == pytest.approx(sum(z_moves) + 0.9, rel=1e-12)


def test_buffered_motion_windows(tiny_file):
    """min_buffered: least motion in planner_blocks consecutive setpoint lines of a run;
    min_buffered_rx: in planner_blocks - 1 + 4 lines (what Grbl's 128-byte buffer holds)."""
    profile = load_profile(tiny_file, ["motion.setpoints=fixed", "motion.dt=0.01"])
    program = build_program(place(straight_tag(), profile), profile)
    (durations,) = _replay(program.lines, profile)[2]
    blocks = profile["limits.planner_blocks"]
    assert len(durations) > blocks + 3

    def least(window: int) -> float:
        return min(sum(durations[i : i + window]) for i in range(len(durations) - window + 1))

    assert program.min_buffered == pytest.approx(least(blocks), rel=1e-9)
    assert program.min_buffered_rx == pytest.approx(least(blocks - 1 + 4), rel=1e-9)


def test_short_runs_are_held_whole(tiny_file):
    """A run of no more lines than a window is held whole once sent: nothing to starve."""
    profile = load_profile(tiny_file, ["motion.setpoints=fixed", "motion.dt=0.25"])
    program = build_program(place(straight_tag(), profile), profile)
    (durations,) = _replay(program.lines, profile)[2]
    assert len(durations) <= profile["limits.planner_blocks"]
    assert program.min_buffered == program.min_buffered_rx == math.inf


def _start_reserves(lines) -> list[float]:
    """Per run, from the text: the ``60/F`` of the inverse-time lines after the run's pen-down
    ``G4`` that fit Grbl's 127-byte receive ring while the ``G4`` is still unacknowledged."""
    out = []
    for k, line in enumerate(lines):
        if not line.startswith("G93"):
            continue
        stop = max(i for i in range(k) if lines[i].startswith("G4P"))
        room, held, reserve = 127 - len(lines[stop]), 0.0, math.inf
        for following in lines[stop + 1 :]:
            if following.startswith("G94"):
                break  # the whole run fits: held whole
            room -= len(following)
            if room < 0:
                reserve = held
                break
            if following.startswith("G1") and not following.startswith("G1Z"):
                held += 60.0 / _words(following)["F"]
        out.append(reserve)
    return out


def test_run_start_reserve_is_what_the_receive_buffer_holds_behind_the_pen_down(slow):
    """A pen-down stop empties the planner: a run starts with only the lines that fitted the
    receive buffer behind it, whatever the timing; the report names the least of them."""
    program = build_program(place(_gap_tag(), slow), slow)
    expected = _start_reserves(program.lines)
    assert len(expected) == 2 and all(0 < r < math.inf for r in expected)
    assert program.run_start_reserve == pytest.approx(expected, rel=1e-9)
    assert program.min_buffered_start == pytest.approx(min(expected), rel=1e-9)


def test_run_start_reserve_without_a_pen_stop_or_a_long_run(tiny_file):
    """A Z pen without a dwell flows into each run (no stop); a run that fits the receive buffer
    whole is held whole once sent: nothing is exposed at the start."""
    z_pen = load_profile(tiny_file, ["pen.type=z", "pen.up=5", "pen.down=0", "pen.dwell=0"])
    program = build_program(place(_gap_tag(), z_pen), z_pen)
    assert not any(line.startswith("G4") for line in program.lines)
    assert program.run_start_reserve == (math.inf, math.inf)
    assert program.min_buffered_start == math.inf
    coarse = load_profile(tiny_file, ["motion.setpoints=fixed", "motion.dt=0.25"])
    program = build_program(place(straight_tag(), coarse), coarse)
    assert _start_reserves(program.lines) == [math.inf]
    assert program.run_start_reserve == (math.inf,)


def _resting_exact(program, box) -> float:
    """Pen-down time within ``box`` of a run's first or last point, exactly: position is linear
    in time on each line, so each line's time near an end is an interval per axis."""
    total = 0.0
    for t, xy in program.planned_runs:
        for k in range(1, len(t)):
            p0, p1, span = xy[k - 1], xy[k], t[k] - t[k - 1]
            near = []
            for end in (xy[0], xy[-1]):
                lo, hi = 0.0, 1.0
                for axis in range(2):
                    a, b = p0[axis] - end[axis], p1[axis] - end[axis]
                    if a == b:
                        if abs(a) >= box[axis]:
                            lo, hi = 1.0, 0.0
                        continue
                    u1, u2 = sorted(((-box[axis] - a) / (b - a), (box[axis] - a) / (b - a)))
                    lo, hi = max(lo, u1), min(hi, u2)
                near.append((lo, hi))
            (a0, a1), (b0, b1) = near
            inside = max(0.0, a1 - a0) + max(0.0, b1 - b0)
            inside -= max(0.0, min(a1, b1) - max(a0, b0))
            total += inside * span
    return total


def test_resting_share_is_the_time_near_the_ends(tiny_file):
    """The reported resting share: time within one motor step of a run's ends over drawing."""
    profile = load_profile(tiny_file, ["place.scale=0.2", "motion.trim=false"])
    program = build_program(place(_gap_tag(), profile), profile)
    box = np.array([0.01, 0.01])
    exact = _resting_exact(program, box)
    assert exact > 0.05 * program.drawing_time  # untrimmed slow tails: a real share
    step = 0.0005
    lines = sum(len(t) for t, _ in program.planned_runs)
    share = resting_share(program, profile)
    assert share == pytest.approx(exact / program.drawing_time, abs=2 * lines * step)
    assert program.resting_time(box) == pytest.approx(exact, abs=2 * lines * step)


def test_resting_time_counts_a_run_of_one_line(tiny_file):
    """A run planned as a single line (two setpoints) rests near both its ends too."""
    profile = load_profile(tiny_file, ["motion.setpoints=fixed", "motion.dt=1", "motion.max_dt=1"])
    program = build_program(place(straight_tag(), profile), profile)
    ((t, xy),) = program.planned_runs
    assert len(t) == 2
    box = np.array([1.0, 1.0])
    # 1 mm at each end of a straight line drawn at constant speed
    exact = 2 * 1.0 / abs(xy[1, 0] - xy[0, 0]) * (t[1] - t[0])
    assert exact == pytest.approx(_resting_exact(program, box))
    assert program.resting_time(box) == pytest.approx(exact, abs=2 * 2 * 0.0005)


def test_bed_edges(tiny_file):
    """A tag touching the bed's edges (no margin) is accepted; one 1 mm wider is refused, naming
    the axis, the overflow and the limit."""
    edge = load_profile(tiny_file, ["bed.margin=0", "motion.trim=false"])
    setpoints = place(straight_tag(), edge)
    xs = np.concatenate([r.xy[:, 0] for r in setpoints.runs])
    assert xs.min() == pytest.approx(0.0, abs=0.01) and xs.max() == pytest.approx(100.0, abs=0.01)
    wide = load_profile(tiny_file, ["bed.margin=0", f"place.scale={setpoints.size * 102 / 100}"])
    with pytest.raises(PlacementError) as refused:
        place(straight_tag(), wide)
    assert str(refused.value) == (
        "placement: the drawing reaches x = -1.000 mm, beyond bed.x_min = 0 mm by 1.000 mm "
        "(reduce place.scale or move it)"
    )


def test_a_tag_taller_than_the_bed_is_refused_naming_y(tiny_file):
    """The same refusal along y: a vertical stroke 2 % taller than the 50 mm bed (no margin,
    centred) reaches 0.5 mm below it."""
    (plan,) = straight_tag().plans
    tall = Tag(plans=(replace(plan, targets=plan.targets[:, ::-1]),))
    edge = load_profile(tiny_file, ["bed.margin=0", "motion.trim=false"])
    size = place(tall, edge).size
    over = load_profile(tiny_file, ["bed.margin=0", f"place.scale={size * 51 / 50}"])
    with pytest.raises(PlacementError) as refused:
        place(tall, over)
    assert str(refused.value) == (
        "placement: the drawing reaches y = -0.500 mm, beyond bed.y_min = 0 mm by 0.500 mm "
        "(reduce place.scale or move it)"
    )


@pytest.mark.parametrize(
    ("align", "x", "y"),
    [
        ("bottom-left", "low", "low"),
        ("bottom-right", "high", "low"),
        ("top-left", "low", "high"),
        ("top-right", "high", "high"),
        ("center", "mid", "mid"),
    ],
)
def test_alignment_puts_the_tag_where_asked(tiny_file, align, x, y):
    """place.align: the tag's extent touches the named margins (5 mm), or is centred (within a
    motor step: setpoints are the ink sampled, the extent is measured on a finer grid)."""
    profile = load_profile(
        tiny_file, [f"place.align={align}", "place.scale=2", "motion.trim=false"]
    )
    xy = np.concatenate([r.xy for r in place(_gap_tag(), profile).runs])
    low, high = xy.min(axis=0), xy.max(axis=0)
    for axis, where, limit in ((0, x, 100.0), (1, y, 50.0)):
        if where == "low":
            assert low[axis] == pytest.approx(5.0, abs=0.01)
        elif where == "high":
            assert high[axis] == pytest.approx(limit - 5.0, abs=0.01)
        else:
            assert low[axis] + high[axis] == pytest.approx(limit, abs=0.01)


def test_a_dot_has_no_resting_share(tiny_file):
    """A stroke shorter than a motor step draws nothing that moves: no drawing time, and a
    resting share of 0 (not a division by zero)."""
    profile = load_profile(tiny_file, ["place.scale=0.0005"])
    program = build_program(place(straight_tag(), profile), profile)
    assert program.drawing_time == 0.0
    assert resting_share(program, profile) == 0.0


def _unplaced(runs: tuple[Run, ...]) -> Setpoints:
    """Hand-built runs as setpoints every 50 ms, in machine mm as they are (no placement)."""
    return Setpoints(
        runs=runs,
        dt=0.05,
        scale=1.0,
        size=1.0,
        matrix=np.eye(2),
        offset=np.zeros(2),
        limits={},
    )


def test_dwell_mode_counts_each_surplus_too_short_for_a_dwell(tiny_file):
    """slow_lines = dwell: four one-step runs (slowest 0.0327 s, $1 0.025 s) planned 0.02 s,
    0.0004 s, 0.06 s and 0.0499 s slower than that; the 0.02 s and 0.0499 s surpluses are too
    short for a 50 ms G4 and are counted (0.0004 s is below the 3-decimal resolution, 0.06 s
    becomes one G4 P0.05)."""
    profile = load_profile(
        tiny_file,
        [
            "motion.slow_lines=dwell",
            "limits.slowest_step=0.0327",
            "limits.step_idle_delay=0.025",
            "limits.min_feed=1",
        ],
    )
    runs = tuple(
        Run(
            plan=k,
            t=np.array([0.0, 0.0327 + 0.025 + surplus]),
            xy=np.array([[10.0 + 10 * k, 10.0], [10.01 + 10 * k, 10.0]]),
            v=np.zeros(2),
        )
        for k, surplus in enumerate((0.02, 0.0004, 0.06, 0.0499))
    )
    program = build_program(_unplaced(runs), profile)
    assert program.notes["short_surpluses"] == 2.0
    inside = [
        line
        for k, line in enumerate(program.lines)
        if line.startswith("G4P") and program.lines[k - 1] == "G93\n"
    ]
    assert inside == ["G4P0.05\n"]


def test_a_run_flowing_on_from_the_previous_runs_dwell_has_no_start_reserve(tiny_file):
    """slow_lines = dwell with a Z pen and no pen dwell: the last stop before run 1 is a G4 inside
    run 0, so run 1 starts with motion already queued behind it (no stop of its own): nothing is
    exposed at its start, even though the lines after that G4 overflow the receive buffer."""
    profile = load_profile(
        tiny_file,
        [
            "place.scale=0.2",
            "motion.dt=0.2",
            "motion.setpoints=fixed",
            "motion.trim=false",
            "motion.slow_lines=dwell",
            "pen.type=z",
            "pen.up=5",
            "pen.down=0",
            "pen.dwell=0",
        ],
    )
    first = straight_tag().plans[0]
    second = Plan(
        targets=[[10.0, 0.0], [10.0, 40.0]],
        dt=[0.0],
        mu=[math.log(0.4)],
        sigma=[0.3],
        phi1=[0.0],
        phi2=[0.0],
        start=first.end(10.0) + 0.5,
    )
    program = build_program(place(Tag(plans=(first, second)), profile), profile)
    lines = program.lines
    g93 = [k for k, line in enumerate(lines) if line.startswith("G93")]
    assert len(g93) == 2
    stop = max(k for k in range(g93[1]) if lines[k].startswith(("G4P", "M3")))
    assert g93[0] < stop < g93[1]  # a G4 inside run 0, none between the runs
    assert any(lines[k].startswith("G1X") for k in range(stop + 1, g93[1]))  # run 0 goes on
    # The lines after that G4 up to run 1's end would overflow the 127-byte ring.
    run1_end = next(k for k in range(g93[1], len(lines)) if lines[k].startswith("G94"))
    assert sum(map(len, lines[stop : run1_end + 1])) > 127
    assert program.run_start_reserve == (math.inf, math.inf)
    assert program.min_buffered_start == math.inf


def test_a_run_starting_two_motor_steps_from_the_park_position_is_travelled_to(tiny_file):
    """Travel is left out only when it moves no motor step: a run starting 0.02 mm (2 steps at
    100 steps/mm) from the park corner in x and y still gets its travel line, so the pen comes down
    at the run's start, not at the park position."""
    profile = load_profile(
        tiny_file, ["bed.margin=0.02", "place.align=bottom-left", "motion.trim=false"]
    )
    setpoints = place(straight_tag(), profile)
    assert setpoints.runs[0].xy[0].tolist() == pytest.approx([0.02, 0.02])
    program = build_program(setpoints, profile)
    pen_down = program.lines.index("M3S30\n")
    assert program.lines[pen_down - 1] == "G1X0.02Y0.02F1200\n"
    assert program.line_xy[pen_down].tolist() == pytest.approx([0.02, 0.02])
    assert program.notes["travel_time"] > 0.0


def test_a_travel_that_cruises_is_halfway_along_at_half_its_time(slow):
    """Grbl's trapezoid is symmetric: halfway through the long hop home (slow axes, so it
    cruises), the planned pen is at the hop's midpoint, moving at the cruise speed toward park."""
    program = build_program(place(_gap_tag(), slow), slow)
    k = max(i for i, line in enumerate(program.lines) if line.startswith("G1X0Y0"))
    here = program.line_xy[k - 1]
    start, stop = program.line_start[k], program.line_end[k]
    d = -here
    length = float(np.hypot(*d))
    assert stop - start == pytest.approx(_rest_to_rest(length, d / length, 1200.0, slow))
    xy, v, _ = program.at(np.array([0.5 * (start + stop)]))
    assert xy[0] == pytest.approx(0.5 * here, abs=1e-9)
    speed = min(20.0, slow["limits.x_max_feed"] / 60.0 / abs(d[0] / length))
    assert v[0] == pytest.approx(speed * d / length, rel=1e-9)


def test_a_run_starting_beside_the_last_ones_end_on_the_same_y_is_travelled_to(tiny_file):
    """Two runs on one horizontal line, the second starting 5 mm right of where the first ends:
    the pen lifts, travels along x alone to the second run's start and comes down there, not
    where the first run ended."""
    profile = load_profile(tiny_file)
    runs = tuple(
        Run(
            plan=k,
            t=np.array([0.0, 1.0]),
            xy=np.array([[x, 10.0], [x + 10.0, 10.0]]),
            v=np.zeros(2),
        )
        for k, x in enumerate((10.0, 25.0))
    )
    program = build_program(_unplaced(runs), profile)
    second_down = [k for k, line in enumerate(program.lines) if line == "M3S30\n"][1]
    assert program.lines[second_down - 1] == "G1X25Y10F1200\n"
    assert program.line_xy[second_down].tolist() == pytest.approx([25.0, 10.0])
