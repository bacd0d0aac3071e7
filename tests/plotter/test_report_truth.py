"""The plotter's report tells what happened: pauses and a starved planner are named and cost no
fidelity figure, a stopped run is compared with the part it drew, a lost port names both the
last line known executed and the last line sent, with a resume command the CLI accepts."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import pytest

import sim.grbl.transport as transport
from sim.grbl import SimulatedGrbl
from tagbot import load_plan
from tagbot.cli import draw_command
from tagbot.control import RunControl
from tagbot.draw import run_report
from tagbot.errors import ConnectionLost
from tagbot.metrics import compare_execution
from tagbot.plotter.machine import prepare
from tagbot.plotter.stream import GrblStreamer, StreamOptions

from .test_stream import PEN_UP, SETTINGS, connected, open_device, square_program

ROOT = Path(__file__).resolve().parents[2]
LETTER_B = ROOT / "tagbot" / "examples" / "letter-b.json"
_names = itertools.count()


class ClockedControl(RunControl):
    """Paused from simulated second ``at`` for ``length`` s of the device's own clock."""

    def __init__(self, at: float, length: float) -> None:
        super().__init__()
        self.at, self.length = at, length
        self.device: SimulatedGrbl | None = None

    @property
    def paused(self) -> bool:
        now = self.device.now if self.device is not None else 0.0
        return self.at <= now < self.at + self.length


def run_job(monkeypatch, tmp_path, control=None, overrides=()):
    """letter-b on the simulated plotter; the report and the device."""
    devices: list[SimulatedGrbl] = []
    attach = transport.attach_device

    def keep(device, name):
        devices.append(device)
        if control is not None:
            control.device = device
        return attach(device, name)

    monkeypatch.setattr(transport, "attach_device", keep)
    job = prepare(load_plan(LETTER_B), overrides=("place.scale=2", *overrides))
    run = job.run(tmp_path, control=control)
    return run, run_report(run), devices[0], job


def test_a_5_s_pause_is_named_and_changes_no_fidelity_figure(monkeypatch, tmp_path):
    """The paused run's figures against the same job run through: the velocity comparison
    leaves out the machine's stop and restart around the pause (``ramp``), so the unpaused run
    is scored with the same stretch left out, like with like."""
    plain_run, plain, _, job = run_job(monkeypatch, tmp_path)
    runs = job.program.planned_runs
    middle = 0.5 * (runs[0][0][0] + runs[0][0][-1])  # halfway through the first run
    control = ClockedControl(middle, 5.0)
    held_run, held, _, _ = run_job(monkeypatch, tmp_path, control)
    assert held["pauses"] == 1 and held["stalls"] == 0
    assert held["paused_s"] == pytest.approx(5.0, abs=0.02)
    assert held["executed_duration_s"] > plain["executed_duration_s"] + 4.9
    assert held_run.ramp > 0 and held_run.ramp == plain_run.ramp
    same_stretch = compare_execution(
        plain_run.planned_runs,
        plain_run.executed,
        plans=plain_run.plans,
        pauses=[(start, 0.0) for start, _ in held_run.pauses],  # left out, nothing removed
        ramp=plain_run.ramp,
    )
    assert abs(held["speed_snr_db"] - same_stretch.speed_snr_db) <= 1.0
    assert abs(held["path_deviation_max_mm"] - plain["path_deviation_max_mm"]) <= 0.01
    assert abs(held["path_deviation_mean_mm"] - plain["path_deviation_mean_mm"]) <= 0.01
    assert abs(held["drawing_duration_ratio"] - plain["drawing_duration_ratio"]) <= 0.01
    assert held["warnings"] == []


def test_a_stopped_run_is_compared_with_the_part_it_drew(monkeypatch, tmp_path):
    def stop(done: int, total: int) -> None:
        if done >= total // 3:  # in the first run, well before its end
            raise KeyboardInterrupt

    devices: list[SimulatedGrbl] = []
    attach = transport.attach_device
    monkeypatch.setattr(transport, "attach_device", lambda d, n: devices.append(d) or attach(d, n))
    job = prepare(load_plan(LETTER_B), overrides=("place.scale=2",))
    run = job.run(tmp_path, progress=stop)
    report = run_report(run)
    assert not report["completed"] and "--position-known" in report["error"]
    # The plan is cut where the machine stopped: nothing undrawn counts as deviation or time.
    assert report["path_deviation_max_mm"] < 0.05
    # The executed drawing time counts the machine's deceleration at the stop (the feed hold
    # takes ``ramp`` to stop where the plan, at speed, takes about half that): no more.
    stop = 0.5 * run.ramp / report["planned_drawing_s"]
    assert 0.97 <= report["drawing_duration_ratio"] <= 1.03 + stop
    assert report["planned_drawing_s"] < job.program.drawing_time / 2


def test_a_lost_port_names_the_last_lines_executed_and_sent_and_a_valid_resume():
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    wire.at[wire.lines + 400] = device.drop_connection
    try:
        with pytest.raises(ConnectionLost) as caught:
            streamer.stream(square_program(1000), pen_up=PEN_UP)
    finally:
        port.close()
    report = streamer.last_report
    done, sent = report.lines_executed, report.lines_sent
    assert done < sent
    message = str(caught.value)
    assert f"after line {done} at least (the last line known executed; lines up to {sent} " in (
        message
    )
    assert f"may have gone on to line {sent}" in message
    command = re.search(r"resume with (--resume-from \d+ --position-known)", message)
    assert command is not None and f"--resume-from {done + 1} " in command.group(0)
    # The command the message prints is one the CLI takes.
    args = [str(LETTER_B), "--port", "/dev/ttyUSB0", *command.group(1).split()]
    context = draw_command.make_context("draw", args)
    assert context.params["resume_from"] == done + 1 and context.params["position_known"]


def _drawing(lines: list[str]) -> list[bool]:
    return [i > 5 and text.startswith("G1X") for i, text in enumerate(lines)]


def test_an_outside_feed_hold_is_a_named_pause():
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    lines = square_program(600)
    held: dict[str, float] = {}

    def button() -> None:  # the machine's own feed-hold button: straight into the firmware
        device.write(b"!")
        held["at"] = device.now

    def release(direction: str, data: bytes) -> None:
        wire(direction, data)
        if "at" in held and "off" not in held and device.now > held["at"] + 1.5:
            device.write(b"~")
            held["off"] = device.now

    wire.at[wire.lines + 200] = button
    streamer._trace = release
    try:
        report = streamer.stream(lines, drawing=_drawing(lines))
    finally:
        port.close()
    assert report.outside_holds == 1 and report.pauses == 1
    assert report.paused_s == pytest.approx(held["off"] - held["at"], abs=0.25)
    assert len(report.warnings) == 1 and "feed hold not asked for by tagbot" in report.warnings[0]
    assert report.stall_spans == []


def test_an_outside_feed_hold_names_the_line_it_stopped():
    """The button pressed 2 s into a 5 s line: the warning names that line (the 7th sent)."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    lines = ["G21\n", "G90\n", "G94\n", "M3S30\n", "G4P0.1\n", "G93\n"]
    lines += ["G1X10Y0F12\n", "G1X10Y10F12\n", "G94\n", *PEN_UP, "M5\n", "M2\n"]
    start, held = device.now, {}

    def button(direction: str, data: bytes) -> None:  # checked at each byte on the wire
        wire(direction, data)
        if "at" not in held and device.now > start + 2.0:
            device.write(b"!")
            held["at"] = device.now
        elif "at" in held and "off" not in held and device.now > held["at"] + 1.0:
            device.write(b"~")
            held["off"] = device.now

    streamer._trace = button
    try:
        report = streamer.stream(lines, drawing=[text.startswith("G1") for text in lines])
    finally:
        port.close()
    assert held["at"] < start + 5.0  # still inside line 7, which ends 0.1 s + 5 s in
    assert report.outside_holds == 1 and len(report.warnings) == 1
    assert " at line 7, " in report.warnings[0]
    assert device.position_mm[:2] == pytest.approx((10.0, 10.0))


def test_a_starved_planner_is_a_named_stall():
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, _ = connected(device)
    lines = square_program(600)
    port.freeze_host(device.now + 2.0, 1.5)  # the host descheduled for 1.5 s mid-stroke
    try:
        report = streamer.stream(lines, drawing=_drawing(lines))
    finally:
        port.close()
    assert report.pauses == 0 and len(report.stall_spans) == 1
    assert report.stall_spans[0][1] == pytest.approx(1.5, abs=0.02)
    assert len(report.warnings) == 1
    assert re.fullmatch(
        r"host stall: nothing was sent for 1\.\d\d s before line \d+, \d+\.\d\d s into the job,"
        r" while the pen was down \(the machine starved if its queue held less\)",
        report.warnings[0],
    )
    assert device.starvation  # the machine did starve


def test_a_link_too_slow_for_the_lines_is_a_named_starved_planner():
    """10 ms lines over 2400 baud (about 90 ms a line on the wire): the machine stands idle
    with the pen down between drawing lines while the host is still sending, and the report
    names each such wait as a starved planner, one stall span per warning."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port = open_device(device, baud=2400)
    streamer = GrblStreamer(port, StreamOptions())
    streamer.connect()
    lines = square_program(30)
    drawing = _drawing(lines)
    try:
        report = streamer.stream(lines, drawing=drawing)
    finally:
        port.close()
    assert report.errors == [] and report.lines_executed == len(lines)
    assert report.warnings and len(report.stall_spans) == len(report.warnings)
    for warning in report.warnings:
        named = re.fullmatch(
            r"starved planner: the machine stood with the pen down before line (\d+) for about"
            r" \d+\.\d\d s, \d+\.\d\d s into the job \(the host did not send lines in time\)",
            warning,
        )
        assert named, warning
        line = int(named[1]) - 1  # inside a run: it and the line before it draw
        assert drawing[line] and drawing[line - 1]


def test_a_buffer_goal_the_program_cannot_hold_is_in_the_report_and_logged_before_the_run(
    monkeypatch, tmp_path, caplog
):
    """motion.min_buffer = 2 s, more than letter-b's lines can hold: the warning is logged when
    the job is checked (before anything is sent) and is the report's first warning."""
    from tagbot.plotter.program import host_pause_warnings

    with caplog.at_level("WARNING", logger="tagbot.plotter.machine"):
        _, report, _, job = run_job(monkeypatch, tmp_path, overrides=("motion.min_buffer=2",))
    expected = host_pause_warnings(job.program, job.profile)
    assert len(expected) == 1 and f"{job.program.min_buffered_rx:.3f} s" in expected[0]
    assert report["warnings"] == expected
    logged = [r.getMessage() for r in caplog.records if r.name == "tagbot.plotter.machine"]
    assert logged == expected
