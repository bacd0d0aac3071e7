"""``tagbot draw`` and its run folder, ``tagbot sim grbl``, ``tagbot demo``, execution metrics."""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

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
from tagbot.metrics import compare_execution, executed_runs
from tagbot.model import Plan, Tag
from tagbot.plotter import load_profile
from tagbot.plotter.machine import executed_from_statuses
from tagbot.plotter.profile import device_settings, with_device_settings

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


def test_grbl_run_folder_holds_everything_and_meets_the_plotter_goals(tmp_path):
    result = draw(load_plan(LETTER_B), tmp_path / "run")
    folder = result.folder
    names = {p.name for p in folder.iterdir()}
    assert {"plan.json", "motion.csv", "program.gcode", "executed.csv", "report.json"} <= names
    assert {"tag.png", "speed.png", "plan.png"} <= names
    header, motion = read_csv(folder / "motion.csv")
    assert header == ["t", "x", "y", "vx", "vy", "speed", "pen"]
    header, executed = read_csv(folder / "executed.csv")
    assert header == ["t", "x", "y", "pen"] and np.all(np.diff(executed[:, 0]) > 0)
    report = json.loads((folder / "report.json").read_text())
    assert report == json.loads(json.dumps(result.report))
    assert report["device"] == "grbl" and report["port"] == "simulator"
    assert report["lines_sent"] == report["lines_acknowledged"] == report["lines_total"]
    assert report["errors"] == [] and report["starvation_events"] == 0
    assert report["path_deviation_max_mm"] <= 0.1
    assert report["speed_snr_db"] >= 20
    assert report["drawing_duration_ratio"] <= 1.05
    assert report["pen_down_runs"] == {"planned": 1, "executed": 1}
    lines = (folder / "program.gcode").read_text().splitlines()
    assert len(lines) == report["lines_total"]
    start = len(lines) - 1 - lines[::-1].index("G93")
    last = [line for line in lines[start : lines.index("G94", start)] if line.startswith("G1X")]
    x, y = last[-1][3:].split("F")[0].split("Y")
    # the program ends the run on the last setpoint (to within a motor step, 1/80 mm)
    assert motion[-1, 1:3] == pytest.approx([float(x), float(y)], abs=0.0125)


def test_arm_run_folder(tmp_path):
    result = draw(short_tag(), tmp_path / "arm", device="dynamixel", pictures=False)
    names = {p.name for p in result.folder.iterdir()}
    assert {"plan.json", "motion.csv", "joints.csv", "executed.csv", "report.json"} <= names
    header, joints = read_csv(result.folder / "joints.csv")
    assert header == ["t", "shoulder", "elbow", "pen"]
    report = result.report
    assert report["ticks_sent"] == len(joints) and report["late_ticks"] == 0
    assert report["path_deviation_max_mm"] <= 0.5 and report["speed_snr_db"] >= 20


def test_outside_the_bed_is_refused_before_the_first_byte(tmp_path):
    device = SimulatedGrbl()
    device.read()
    url = attach_device(device, "draw_outside")
    with pytest.raises(PlacementError, match=r"outside|bed"):
        draw(short_tag(), tmp_path / "run", port=url, overrides=["place.scale=1000"])
    assert device.lines_received == 0 and device.read() == b""


def test_a_fault_leaves_a_partial_run_folder_and_is_raised(tmp_path):
    device = SimulatedGrbl(device_settings(load_profile()), pen_servo=(30, 50))
    device.read()
    device.inject_error(40 + 1, 24)  # the handshake's $$ is line 1 of what the device receives
    url = attach_device(device, "draw_fault")
    with pytest.raises(DeviceFault, match=r"^line 40: error:24") as caught:
        draw(load_plan(LETTER_B), tmp_path / "run", port=url)
    assert caught.value.where == "line 40"
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report["stopped_at_line"] == 40 and "error:24" in report["error"]
    assert report["lines_acknowledged"] == 39
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
    assert slow.report["time_scale"] > 1.5 * fast.report["time_scale"]
    profile = with_device_settings(load_profile(), settings)
    assert (
        profile["limits.x_acceleration"] == 100.0
        and profile.sources["limits.x_acceleration"] == "$$"
    )
    with pytest.raises(ProfileError, match=r"^\$\$: limits.x_acceleration: must be > 0"):
        with_device_settings(load_profile(), {120: 0.0})


def test_draw_over_a_pseudo_terminal(tmp_path):
    profile = load_profile(None, FAST)
    device = SimulatedGrbl(device_settings(profile), clock="real", pen_servo=(30, 50))
    path, stop = serve_pty(device)
    try:
        result = draw(short_tag(), tmp_path / "pty", port=path, overrides=FAST, pictures=False)
    finally:
        stop()
    report = result.report
    assert report["port"] == path and report["lines_acknowledged"] == report["lines_total"]
    # On hardware the executed trace is what the status reports said (<= 5 Hz).
    assert len(report["runs"]) == 1 and report["status_reports"] >= 3


def test_executed_trace_from_status_reports():
    profile = load_profile()
    statuses = [
        (0.0, Status(State.IDLE, mpos=(0.0, 0.0, 0.0), spindle=50.0)),
        (0.2, Status(State.RUN, mpos=(1.0, 2.0, 0.0), spindle=30.0)),
        (0.4, Status(State.RUN, wpos=(1.5, 2.5, 0.0), wco=(1.0, 1.0, 0.0), spindle=30.0)),
        (0.6, Status(State.IDLE, wpos=(2.0, 3.0, 0.0), spindle=0.0)),
    ]
    executed = executed_from_statuses(statuses, profile)
    assert executed.tolist() == [
        [0.0, 0.0, 0.0, 0.0],
        [0.2, 1.0, 2.0, 1.0],
        [0.4, 2.5, 3.5, 1.0],
        [0.6, 3.0, 4.0, 0.0],
    ]


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
    assert process.returncode == 130
    assert err.strip().splitlines()[-1] == "tagbot: error: interrupted" and "Traceback" not in err


def test_demo_makes_everything_it_lists(tmp_path, capsys):
    code = main(["demo", "--out", str(tmp_path / "demo")])
    out, err = capsys.readouterr()
    assert code == 0 and "[6/6] arm" in err
    folder = tmp_path / "demo"
    summary = json.loads((folder / "summary.json").read_text())
    for name in summary["files"].values():
        assert (folder / name).exists(), name
    assert len(list((folder / "variations").glob("*.json"))) == 6
    for device in ("plotter", "arm"):
        report = json.loads((folder / device / "report.json").read_text())
        assert "error" not in report and report["speed_snr_db"] > 15
    assert f"demo folder: {folder}" in out
    assert os.path.getsize(folder / "tag.gif") > 10_000
