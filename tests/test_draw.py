"""``tagbot draw`` and its run folder, ``tagbot sim grbl``, ``tagbot demo``, execution metrics."""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import serial

from firmware_protocols.grbl import Status
from firmware_protocols.grbl.codes import State
from sim.grbl import SimulatedGrbl
from sim.grbl.transport import attach_device, serve_pty
from tagbot import load_plan
from tagbot.cli import main
from tagbot.draw import draw
from tagbot.errors import DeviceFault, PlacementError, ProfileError
from tagbot.metrics import SPARSE_SNR_NOTE, compare_execution, compare_reports, executed_runs
from tagbot.model import Plan, Tag
from tagbot.plotter import load_profile
from tagbot.plotter.machine import executed_from_statuses
from tagbot.plotter.profile import device_settings, with_device_settings
from tagbot.plotter.stream import StreamReport

ROOT = Path(__file__).resolve().parents[1]
LETTER_B = ROOT / "tagbot" / "examples" / "letter-b.json"
FAST = [
    "limits.x_acceleration=5000",
    "limits.y_acceleration=5000",
    "place.scale=20",
    "place.align=bottom-left",
    "motion.park=false",
    "pen.dwell=0.05",
]


def short_tag() -> Tag:
    """One quick plan: two strokes, about a second of drawing."""
    plan = Plan(
        targets=[[0.0, 0.0], [2.0, 1.0], [3.0, -1.0]],
        dt=[0.0, 0.25],
        mu=[math.log(0.3)] * 2,
        sigma=[0.3] * 2,
        phi1=[0.3, -0.2],
        phi2=[0.0, 0.0],
    )
    return Tag(plans=(plan,))


def read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    with open(path, encoding="utf-8") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float)


COMMON_KEYS = {
    "device",
    "port",
    "simulated",
    "completed",
    "error",
    "warnings",
    "unit",
    "total",
    "sent",
    "executed",
    "resume_from",
    "planned_duration_s",
    "executed_duration_s",
    "executed_source",
    "placement",
    "path_deviation_mean_mm",
    "path_deviation_max_mm",
    "speed_snr_db",
    "planned_drawing_s",
    "executed_drawing_s",
    "drawing_duration_ratio",
    "pen_down_runs",
    "runs",
    "details",
}


@pytest.mark.parametrize(
    ("device", "program", "deviation"),
    [
        ("grbl", "program.gcode", 0.05),
        ("dynamixel", "joints.csv", 0.3),
        ("axidraw", "moves.txt", 0.02),
    ],
)
def test_both_devices_write_the_same_run_folder(tmp_path, device, program, deviation):
    result = draw(load_plan(LETTER_B), tmp_path / device, device=device)
    folder = result.folder
    names = {p.name for p in folder.iterdir()}
    assert {"plan.json", "motion.csv", program, "executed.csv", "report.json"} <= names
    assert {"tag.png", "speed.png", "plan.png"} <= names
    header, motion = read_csv(folder / "motion.csv")
    assert header == ["t", "x", "y", "vx", "vy", "speed", "pen"]
    # The whole planned timeline: from the job's start, pen-up travel (pen 0) included.
    assert motion[0, 0] == pytest.approx(0.0, abs=1e-9) and np.all(np.diff(motion[:, 0]) > 0)
    assert set(np.unique(motion[:, 6])) == {0.0, 1.0}
    header, executed = read_csv(folder / "executed.csv")
    assert header == ["t", "x", "y", "pen"] and np.all(np.diff(executed[:, 0]) > 0)
    report = json.loads((folder / "report.json").read_text())
    assert report == json.loads(json.dumps(result.report))
    assert set(report) >= COMMON_KEYS
    assert report["device"] == device and report["port"] == "simulator" and report["simulated"]
    assert report["completed"] and report["error"] is None and report["resume_from"] is None
    assert report["total"] == report["sent"] == report["executed"] > 0
    assert report["executed_source"] == "simulator recorder, 1 ms"
    assert report["path_deviation_max_mm"] <= deviation
    assert report["speed_snr_db"] >= 25
    assert 0.98 <= report["drawing_duration_ratio"] <= 1.02
    assert report["pen_down_runs"] == {"planned": 1, "executed": 1}
    assert report["planned_duration_s"] == pytest.approx(motion[-1, 0], abs=0.02)


def test_grbl_program_matches_the_planned_timeline(tmp_path):
    result = draw(load_plan(LETTER_B), tmp_path / "run", pictures=False)
    folder = result.folder
    _, motion = read_csv(folder / "motion.csv")
    lines = (folder / "program.gcode").read_text().splitlines()
    assert len(lines) == result.report["total"]
    assert result.report["details"]["starvation_events"] == 0
    assert result.report["details"]["realtime"] is False  # simulated time: nothing to schedule
    start = len(lines) - 1 - lines[::-1].index("G93")
    last = [line for line in lines[start : lines.index("G94", start)] if line.startswith("G1X")]
    x, y = last[-1][3:].split("F")[0].split("Y")
    # The run ends on the program's last setpoint (to within a motor step, 1/80 mm).
    down = motion[motion[:, 6] == 1]
    assert down[-1, 1:3] == pytest.approx([float(x), float(y)], abs=0.0125)


def test_outside_the_bed_is_refused_before_the_first_byte(tmp_path):
    device = SimulatedGrbl()
    device.read()
    url = attach_device(device, "draw_outside")
    with pytest.raises(PlacementError, match=r"outside|bed"):
        draw(short_tag(), tmp_path / "run", port=url, overrides=["place.scale=1000"])
    assert device.lines_received == 0 and device.read() == b""
    assert not (tmp_path / "run").exists()


def test_a_fault_leaves_a_run_folder_naming_the_executed_line(tmp_path):
    device = SimulatedGrbl({**device_settings(load_profile()), 10: 3}, pen_servo=(30, 50))
    device.read()
    # The handshake's $$ and $I are lines 1 and 2 of what the device receives.
    device.inject_error(2 + 200, 24)
    url = attach_device(device, "draw_fault")
    with pytest.raises(DeviceFault, match=r"^after line \d+ .*error:24.*\(line 200\)") as caught:
        draw(load_plan(LETTER_B), tmp_path / "run", port=url)
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    done = report["executed"]
    assert caught.value.where.startswith(f"after line {done} ")
    assert done == device.executed_lines - 2 < 199
    assert report["resume_from"] == done + 1 and "error:24" in report["error"]
    assert report["details"]["lines_acknowledged"] == 199
    assert (tmp_path / "run" / "executed.csv").exists()


def test_from_device_takes_the_controllers_limits(tmp_path):
    settings = device_settings(load_profile())
    settings.update({120: 100.0, 121: 100.0})  # a slower machine than the profile says
    device = SimulatedGrbl(settings, pen_servo=(30, 50))
    url = attach_device(device, "draw_from_device")
    slow = draw(
        short_tag(),
        tmp_path / "slow",
        port=url,
        pictures=False,
        overrides=["limits.from_device=true"],
    )
    fast = draw(short_tag(), tmp_path / "fast", pictures=False)
    assert slow.report["placement"]["time_scale"] > 1.5 * fast.report["placement"]["time_scale"]
    profile = with_device_settings(load_profile(), settings)
    assert (
        profile["limits.x_acceleration"] == 100.0
        and profile.sources["limits.x_acceleration"] == "$$"
    )
    with pytest.raises(ProfileError, match=r"^\$\$: limits.x_acceleration: must be > 0"):
        with_device_settings(load_profile(), {120: 0.0})


def test_draw_over_a_pseudo_terminal_reports_what_the_machine_said(tmp_path):
    """The servo-pen profile over a real serial port: the executed trace is the status reports,
    with the pen taken from the program at the executing line, compared like with like."""
    profile = load_profile(None, FAST)
    device = SimulatedGrbl(device_settings(profile), clock="real", pen_servo=(30, 50))
    path, stop = serve_pty(device)
    try:
        result = draw(short_tag(), tmp_path / "pty", port=path, overrides=FAST, pictures=False)
    finally:
        stop()
    report = result.report
    assert report["port"] == path and not report["simulated"]
    assert report["executed"] == report["total"] == report["details"]["lines_acknowledged"]
    assert report["executed_source"].startswith("status reports, 5 Hz")
    assert report["pen_down_runs"] == {"planned": 1, "executed": 1}
    assert report["path_deviation_max_mm"] < 0.5
    _, executed = read_csv(tmp_path / "pty" / "executed.csv")
    # Pen down only while the machine was on the drawing (not while leaving the park position).
    _, motion = read_csv(tmp_path / "pty" / "motion.csv")
    down = motion[motion[:, 6] == 1]
    box_low, box_high = down[:, 1:3].min(axis=0) - 0.05, down[:, 1:3].max(axis=0) + 0.05
    pen_down = executed[executed[:, 3] == 1]
    assert len(pen_down) >= 3
    assert np.all((pen_down[:, 1:3] >= box_low) & (pen_down[:, 1:3] <= box_high))


def test_executed_trace_from_status_reports_takes_the_pen_from_the_program():
    # Lines: 0 travel (pen up), 1 and 2 drawing (run 0), 3 pen up. The spindle values say
    # nothing here: a servo pen's S value is no evidence of where the pen is.
    program = SimpleNamespace(line_pen=[False, True, True, False], line_run=[-1, 0, 0, -1])
    stream = StreamReport(lines_total=4)
    stream.started = 10.0
    stream.statuses = [
        (10.0, Status(State.IDLE, mpos=(0.0, 0.0, 0.0), spindle=50.0)),
        (10.2, Status(State.RUN, mpos=(1.0, 2.0, 0.0), spindle=50.0)),
        (10.4, Status(State.RUN, wpos=(1.5, 2.5, 0.0), wco=(1.0, 1.0, 0.0), spindle=0.0)),
        (10.6, Status(State.IDLE, wpos=(2.0, 3.0, 0.0), spindle=30.0)),
    ]
    stream.executing = [0, 1, 2, 3]
    executed, runs = executed_from_statuses(stream, program)
    assert executed.tolist() == [
        [0.0, 0.0, 0.0, 0.0],
        [pytest.approx(0.2), 1.0, 2.0, 1.0],
        [pytest.approx(0.4), 2.5, 3.5, 1.0],
        [pytest.approx(0.6), 3.0, 4.0, 0.0],
    ]
    assert runs.tolist() == [-1, 0, 0, -1]


def test_compare_reports_measures_like_with_like():
    t = np.arange(0.0, 4.0, 0.01)
    xy = np.column_stack([30 * (1 - np.cos(np.pi * t / 4)), 5 * np.sin(t)])
    # Reports every 0.2 s, 0.35 s late, exactly on the path: no deviation, a clean SNR.
    te = np.arange(0.0, 4.0, 0.2) + 0.35
    on = np.column_stack([np.interp(te - 0.35, t, xy[:, i]) for i in (0, 1)])
    executed = np.column_stack([te, on, np.ones(len(te))])
    comparison = compare_reports([(t, xy)], executed, np.zeros(len(te), dtype=int))
    assert comparison.deviation_max < 0.005
    assert comparison.runs[0].executed_start == pytest.approx(0.35, abs=0.01)
    assert comparison.speed_snr_db is None and comparison.runs[0].snr_db is None
    assert comparison.speed_snr_note == SPARSE_SNR_NOTE
    assert comparison.duration_ratio == pytest.approx(1.0, abs=0.01)
    # A machine that runs 10 % slow: the drift shows in the duration; the 5 Hz chords never
    # count as deviation.
    slow = np.column_stack([np.interp(te / 1.1, t, xy[:, i]) for i in (0, 1)])
    executed = np.column_stack([te, slow, np.ones(len(te))])
    comparison = compare_reports([(t, xy)], executed, np.zeros(len(te), dtype=int))
    assert comparison.deviation_max < 0.005
    assert comparison.duration_ratio == pytest.approx(1.1, abs=0.03)
    with pytest.raises(ValueError, match="no report while the pen was down"):
        compare_reports([(t, xy)], executed, np.full(len(te), -1))
    # A stop: a run planned past the time drawn to is cut short; one ending there is not.
    assert comparison.runs[0].cut_short is False
    run_of = np.zeros(len(te), dtype=int)
    for until, cut in ((2.0, True), (float(t[-1]), False)):
        stopped = compare_reports([(t, xy)], executed, run_of, until=until)
        assert stopped.runs[0].cut_short is cut


def test_compare_execution_recovers_offsets_and_measures_deviation():
    t = np.arange(0.0, 2.0, 0.01)
    xy = np.column_stack([50 * (1 - np.cos(np.pi * t / 2)), 0 * t])  # straight, lognormal-ish
    runs = [(t, xy), (t + 5.0, xy + np.array([0.0, 20.0]))]
    fine = np.arange(0.0, 2.0, 0.001)
    exact = np.column_stack([np.interp(fine, t, xy[:, 0]), np.interp(fine, t, xy[:, 1])])
    executed = []
    for (tp, shift), delay in zip([(0.0, 0.0), (5.0, 20.0)], (0.3, 1.7), strict=True):
        pen = np.ones((len(fine), 1))
        executed.append(
            np.hstack([fine[:, None] + tp + delay, exact + np.array([0.0, shift + 0.05]), pen])
        )
        executed.append([[tp + delay + 2.1, 0.0, 0.0, 0.0]])
    comparison = compare_execution(runs, np.vstack(executed))
    assert comparison.planned_runs == comparison.executed_runs == 2
    assert comparison.deviation_mean == pytest.approx(0.05, abs=0.01)
    assert comparison.deviation_max == pytest.approx(0.05, abs=0.01)
    assert comparison.speed_snr_db > 30
    starts = [r.executed_start for r in comparison.runs]
    assert starts == pytest.approx([0.3, 6.7], abs=0.002)
    assert comparison.duration_ratio == pytest.approx(1.0, abs=0.01)
    assert len(executed_runs(np.vstack(executed))) == 2
    with pytest.raises(ValueError, match="no pen-down run"):
        compare_execution(runs, np.zeros((3, 4)))


def test_cli_draw_and_its_errors(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["draw", str(LETTER_B), "--out", str(out), "--no-pictures"])
    _, err = capsys.readouterr()
    assert code == 0 and "speed SNR" in err and (out / "report.json").exists()
    code = main(["draw", str(LETTER_B), "--resume-from", "10"])
    _, err = capsys.readouterr()
    assert code == 2 and err.strip().endswith("then add --position-known")
    code = main(["draw", str(LETTER_B), "--device", "dynamixel", "--unlock"])
    _, err = capsys.readouterr()
    assert code == 2 and "are Grbl options" in err
    device = SimulatedGrbl(device_settings(load_profile()))
    device.read()  # booted long ago; now it answers nothing
    device.go_silent()
    url = attach_device(device, "cli_silent")
    args = ["draw", str(LETTER_B), "--port", url, "--out", str(tmp_path / "silent")]
    code = main(args)
    _, err = capsys.readouterr()
    last = err.strip().splitlines()[-1]
    assert code == 1 and last.startswith("tagbot: error: no Grbl welcome banner")
    assert "Traceback" not in err


def test_sim_grbl_serves_a_pty_until_interrupted():
    process = subprocess.Popen(
        [sys.executable, "-m", "tagbot", "sim", "grbl"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        path = process.stdout.readline().strip()
        assert path.startswith("/dev/")
        with serial.Serial(path, 115200, timeout=2) as port:
            port.write(b"\x18")
            assert b"Grbl 1.1h" in port.read_until(b"help]\r\n")
            port.write(b"$$\n")
            assert b"$110=6000.000" in port.read_until(b"ok\r\n")
    finally:
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=10)
    assert process.returncode == 0  # Ctrl-C is a server's normal way out
    assert err.strip().splitlines()[-1] == "stopped (Ctrl-C)" and "Traceback" not in err


def test_sigterm_stops_a_draw_safely_and_keeps_the_run_folder(tmp_path):
    device = SimulatedGrbl(device_settings(load_profile()), clock="real")
    path, stop = serve_pty(device)
    out = tmp_path / "run"
    try:
        process = subprocess.Popen(
            [sys.executable, "-m", "tagbot", "draw", str(LETTER_B), "--port", path,
             "--out", str(out), "--no-pictures"],
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        assert process.stderr.readline().startswith("drawing ")
        deadline = time.monotonic() + 30
        while device.executed_lines < 40 and time.monotonic() < deadline:
            time.sleep(0.05)  # until the machine is well into the program (past its preamble)
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=30)
    finally:
        stop()
    assert process.returncode == 143 and "Traceback" not in err
    assert "the last line the machine executed" in err and err.endswith(": interrupted (SIGTERM)\n")
    report = json.loads((out / "report.json").read_text())
    assert not report["completed"] and report["executed"] >= 1


def test_demo_makes_everything_it_lists(tmp_path, capsys):
    code = main(["demo", "--out", str(tmp_path / "demo")])
    out, err = capsys.readouterr()
    assert code == 0 and "[6/7] arm" in err and "[7/7] openmanipulator-x" in err
    folder = tmp_path / "demo"
    summary = json.loads((folder / "summary.json").read_text())
    for name in summary["files"].values():
        assert (folder / name).exists(), name
    assert len(list((folder / "variations").glob("*.json"))) == 6
    for device in ("plotter", "arm", "openmanipulator-x"):
        report = json.loads((folder / device / "report.json").read_text())
        assert report["completed"] and report["error"] is None and report["speed_snr_db"] > 25
    assert f"demo folder: {folder}" in out
    # One line a step, its label padded so that what it made starts in one column.
    lines = out.splitlines()[-7:]
    assert [line.split()[0] for line in lines] == [
        "fit",
        "plots",
        "variations",
        "render",
        "plotter",
        "arm",
        "openmanipulator-x",
    ]
    assert len({len(line) - len(line[2:].split(" ", 1)[1].lstrip()) for line in lines}) == 1
    assert os.path.getsize(folder / "tag.gif") > 10_000
