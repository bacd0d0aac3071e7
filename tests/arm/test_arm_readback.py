"""The arm on a line like a real one: late and lost replies, silence, pause, the run's record.

In process (simulated time) unless the test serves a pseudo-terminal (real time).
"""

from __future__ import annotations

import json
import logging
import math
import os
import re
import signal
import time
from pathlib import Path

import dynamixel_sdk as sdk
import numpy as np
import pytest

from sim.dynamixel import SimulatedChain, serve_pty
from tagbot.arm import build_program, latency_timer_warning, load_profile, prepare
from tagbot.arm.driver import ArmDriver
from tagbot.arm.run import simulated_chain
from tagbot.control import RunControl
from tagbot.draw import MachineRun, draw, run_report
from tagbot.errors import (
    ConnectionLost,
    DeviceTimeout,
    InputError,
    Interrupted,
    PlacementError,
    PortError,
    ProfileError,
    SignalInterrupt,
)

from .conftest import FAST, GOAL_POSITION, Recorded, small_tag, two_plan_tag

PEN = 3


def _goals_received(sim: Recorded, id: int) -> list[int]:
    """Goal positions servo ``id`` executed after the approach (the first one)."""
    return sim.values(id, GOAL_POSITION)[1:]


def _stopped_safely(sim: Recorded, profile) -> None:
    assert sim.servo(PEN).get("goal_position") == profile["pen.up"] and sim.servo(PEN).torque
    assert not sim.servo(1).torque and not sim.servo(2).torque


def _deviation(run: MachineRun) -> np.ndarray:
    """mm from each executed pen-down sample to the planned position at its time."""
    motion, ex = run.motion, run.executed
    down = ex[:, 3] > 0.5
    px = np.interp(ex[down, 0], motion.t, motion.xy[:, 0])
    py = np.interp(ex[down, 0], motion.t, motion.xy[:, 1])
    return np.hypot(ex[down, 1] - px, ex[down, 2] - py)


def test_completes_with_replies_50_ms_late_and_2_percent_lost(sim_default, record, tmp_path):
    profile, sim = sim_default
    sim.chain.set_reply_faults(latency=0.05, drop=0.02, seed=3)
    job = prepare(two_plan_tag(), port=sim.url)
    run = job.run(tmp_path)
    assert run.error is None, run.error
    program = job.program
    for column, id in enumerate((1, 2, 3)):
        assert _goals_received(sim, id) == program.goals[:, column].tolist()
    d = run.details
    assert run.executed_steps == run.sent == run.total == len(program)
    assert sim.chain.replies_dropped > 0
    # Every reply came 50 ms (5 ticks) late, none was taken for a later read; the lost ones
    # were counted, never more than a few in a row, and nothing waited for them.
    assert d["readback_requests"] == len(program)
    assert d["readback_missed_replies"] > 0
    assert d["readback_most_missed_in_a_row"] <= profile["bus.max_missed"]
    assert d["readback_late_replies"] == d["readback_replies"]
    assert 50 <= d["reply_delay_p50_ms"] <= 61
    assert d["readbacks"] >= 0.9 * len(program)
    assert d["late_ticks"] == 0 and d["resyncs"] == 0 and d["max_lateness_ms"] == 0.0
    assert d["loop_rate_hz"] == pytest.approx(100.0)
    assert isinstance(d["realtime"], bool)  # whether the loop ran at a real-time priority
    # The read-backs are the positions of their own instants: tracking stays small.
    assert d["joint_tracking_error"]["max"] < 0.5
    assert run.executed_source == "simulator recorder, 1 ms" and not run.sparse
    # What was drawn is what a clean line draws (the recorder, the same goals, the same times).
    clean = _baseline(record, tmp_path / "clean").executed
    ex = run.executed
    for column in (1, 2, 3):
        same = np.interp(ex[:, 0], clean[:, 0], clean[:, column])
        assert np.abs(ex[:, column] - same).max() < (0.01 if column < 3 else 1.0)
    assert abs(ex[:, 3].sum() - clean[:, 3].sum()) <= 2
    report = run_report(run)
    assert report["completed"] and report["pen_down_runs"] == {"planned": 2, "executed": 2}
    assert (tmp_path / "joints.csv").read_text().count("\n") == len(program) + 1


def test_a_silent_line_is_a_timeout_that_names_the_tick_and_keeps_the_trace(
    sim_default, tmp_path
) -> None:
    profile, sim = sim_default
    silenced = []

    def progress(done: int, total: int) -> None:
        if done > 300 and not silenced:
            silenced.append(sim.chain.now())
            sim.chain.set_reply_faults(drop=1.0)  # the adapter hears nothing any more

    job = prepare(two_plan_tag(), port=sim.url)
    run = job.run(tmp_path, progress=progress)
    error = run.error
    assert isinstance(error, DeviceTimeout)
    assert str(error).startswith(
        f"{error.where}: servo 1 (shoulder), servo 2 (elbow) and servo 3 (pen) did not answer"
        " SYNC_READ of present positions for 0.25 s"
    )
    tick = int(error.where.split()[1])
    assert 301 + 25 <= tick <= 301 + 27  # 0.25 s at 100 Hz after the last reply
    assert run.sent == run.executed_steps == tick < run.total
    _stopped_safely(sim, profile)
    for column, id in enumerate((1, 2)):
        assert _goals_received(sim, id) == job.program.goals[:tick, column].tolist()
    # The executed trace runs up to the stop, on the program's clock.
    ex = run.executed
    assert len(ex) and ex[-1, 0] >= (tick - 1) * profile.period
    assert ex[-1, 0] < (tick - 1) * profile.period + 0.5
    down = ex[:, 3] > 0.5
    assert down.any() and _deviation(run).mean() < 0.2
    assert run.details["ticks_sent"] == tick


def test_the_run_folder_keeps_the_executed_trace_up_to_a_fault(
    sim_default, record, tmp_path
) -> None:
    profile, sim = sim_default
    done_once = []

    def progress(done: int, total: int) -> None:
        if done > 400 and not done_once:
            done_once.append(True)
            sim.chain.set_hardware_error(2, 0x20)

    folder = tmp_path / "run"
    with pytest.raises(
        Exception,
        match=r"^tick (\d+) \(the last tick executed; resume with --resume-from \d+\): servo 2"
        r" \(elbow\): hardware error: overload",
    ):
        draw(
            two_plan_tag(),
            folder,
            device="dynamixel",
            port=sim.url,
            progress=progress,
            pictures=False,
        )
    report = json.loads((folder / "report.json").read_text())
    assert report["completed"] is False and report["unit"] == "tick"
    assert 401 < report["executed"] == report["sent"] < report["total"]
    assert "hardware error: overload" in report["error"]
    assert report["resume_from"] == report["executed"] + 1
    assert f"--resume-from {report['executed'] + 1})" in report["error"]
    # Stopped in the first run: the drawn part is compared with the part of the plan it stands
    # for, as faithful as a whole clean run (the undrawn rest is no deviation).
    clean = run_report(_baseline(record, tmp_path / "clean"))
    assert report["pen_down_runs"] == {"planned": 1, "executed": 1}
    assert report["path_deviation_max_mm"] <= clean["path_deviation_max_mm"] + 0.01
    rows = (folder / "executed.csv").read_text().splitlines()
    assert rows[0] == "t,x,y,pen" and len(rows) > 3000  # 1 ms samples, 4 s of drawing
    last_t = float(rows[-1].split(",")[0])
    assert last_t >= (report["executed"] - 1) * profile.period
    assert {"plan.json", "motion.csv", "joints.csv"} <= {p.name for p in folder.iterdir()}
    _stopped_safely(sim, profile)


@pytest.mark.parametrize(
    ("stop_signal", "named"),
    [
        (KeyboardInterrupt, "Ctrl-C"),
        (lambda: SignalInterrupt(signal.SIGTERM, "SIGTERM"), "SIGTERM"),
    ],
)
def test_ctrl_c_is_interrupted_naming_the_last_tick(
    sim_default, record, tmp_path, stop_signal, named
) -> None:
    profile, sim = sim_default
    job = prepare(two_plan_tag(), port=sim.url)
    pen_down = np.flatnonzero(job.program.goals[:, 2] == profile["pen.down"])
    stop = int(pen_down[0]) + 80 - (int(pen_down[0]) + 80) % 10  # mid-stroke, on a progress call

    def progress(done: int, total: int) -> None:
        if done > stop:
            raise stop_signal()

    run = job.run(tmp_path, progress=progress)
    where = f"tick {stop + 1} (the last tick executed; resume with --resume-from {stop + 2})"
    assert isinstance(run.error, Interrupted) and run.error.where == where
    assert str(run.error).startswith(f"{where}: interrupted ({named})")
    assert run.executed_steps == stop + 1 and run.resume_from == stop + 2
    assert _goals_received(sim, 1) == job.program.goals[: stop + 1, 0].tolist()
    _stopped_safely(sim, profile)
    # Stopped mid-stroke: the plan is cut where the pen had drawn to (the stop's tick, less
    # the servos' lead and the pen's lift), and what was drawn is as faithful as a clean run.
    assert run.until is not None
    assert stop * profile.period - 0.05 < run.until <= stop * profile.period
    report = run_report(run)
    clean = run_report(_baseline(record, tmp_path / "clean"))
    assert report["pen_down_runs"] == {"planned": 1, "executed": 1}
    assert report["path_deviation_max_mm"] <= clean["path_deviation_max_mm"] + 0.01
    assert report["path_deviation_mean_mm"] <= clean["path_deviation_mean_mm"] + 0.01


class _PauseFor(RunControl):
    """Paused for ``seconds`` of the chain's clock from when :meth:`start` is called."""

    def __init__(self, chain: SimulatedChain, seconds: float) -> None:
        super().__init__()
        self.chain, self.seconds = chain, seconds
        self.began: float | None = None

    def start(self) -> None:
        self.began = self.chain.now()

    @property
    def paused(self) -> bool:
        return self.began is not None and self.chain.now() < self.began + self.seconds


def test_pause_lifts_the_pen_holds_the_pose_and_resume_completes_the_tag(
    sim_default, record, tmp_path
) -> None:
    profile, sim = sim_default
    job = prepare(two_plan_tag(), port=sim.url)
    program = job.program
    pen_down = program.goals[:, 2] == profile["pen.down"]
    at = int(np.flatnonzero(pen_down)[0]) + 60  # mid-stroke
    at -= at % 10  # progress comes every 10 ticks at 100 Hz
    control = _PauseFor(sim.chain, 5.0)

    def progress(done: int, total: int) -> None:
        if done == at + 1:
            control.start()

    run = job.run(tmp_path, progress=progress, control=control)
    assert run.error is None, run.error
    assert control.began is not None
    # The arm joints got every goal once, in order; nothing while paused.
    for column, id in enumerate((1, 2)):
        assert _goals_received(sim, id) == program.goals[:, column].tolist()
    writes = [(t, i, v) for t, i, a, v in sim.writes if a == GOAL_POSITION]
    during = [(t, i, v) for t, i, v in writes if control.began < t < control.began + 5.0]
    # Only the pen moved: lifted in pen.move_time, one goal a tick, as in the program.
    steps = round(profile["pen.move_time"] / profile.period)
    up, down = profile["pen.up"], profile["pen.down"]
    assert {i for _, i, _ in during} == {PEN} and len(during) == steps
    assert [v for _, _, v in during] == sorted(v for _, _, v in during) and during[-1][2] == up
    # After the pause the pen came back down the same way, before the next goal.
    pen = [v for _, i, v in writes if i == PEN]
    first = 1 + at + 1  # the approach, then ticks 0..at
    assert pen[first + steps - 1] == up and pen[first + 2 * steps - 1] == down
    assert pen[first + steps : first + 2 * steps] == sorted(
        pen[first + steps : first + 2 * steps], reverse=True
    )
    trace = sim.chain.pen_trace()
    held = trace[(trace[:, 0] > control.began + 0.2) & (trace[:, 0] < control.began + 4.9)]
    assert held[:, 3].max() == 0.0  # pen up while paused
    assert np.ptp(held[:, 1]) < 0.05 and np.ptp(held[:, 2]) < 0.05  # the pose held
    assert run.details["late_ticks"] == 0 and run.details["resyncs"] == 0
    # The report names the pause; the executed clock keeps it (the job took that much longer)
    # and the comparison leaves it out: no fidelity figure moves by more than 1 dB / 0.01 mm.
    report = run_report(run)
    assert report["pauses"] == 1 and report["stalls"] == 0 and report["stalled_s"] == 0.0
    paused = report["paused_s"]
    assert 5.0 <= paused <= 5.0 + 2 * profile["pen.move_time"] + profile.lead + 0.02
    assert report["longest_pause_s"] == paused
    clean = run_report(_baseline(record, tmp_path / "clean"))
    assert report["executed_duration_s"] == pytest.approx(
        clean["executed_duration_s"] + paused, abs=0.011
    )
    assert report["pen_down_runs"] == clean["pen_down_runs"] == {"planned": 2, "executed": 2}
    for key in ("path_deviation_max_mm", "path_deviation_mean_mm"):
        assert report[key] == pytest.approx(clean[key], abs=0.01)
    assert report["speed_snr_db"] == pytest.approx(clean["speed_snr_db"], abs=1.0)
    for run_, clean_ in zip(report["runs"], clean["runs"], strict=True):
        assert run_["speed_snr_db"] == pytest.approx(clean_["speed_snr_db"], abs=1.0)


def test_prepare_refuses_before_anything_is_sent(sim_default, tmp_path) -> None:
    _, sim = sim_default
    with pytest.raises(PlacementError, match="fits nowhere"):
        prepare(small_tag(), overrides=("place.scale=50",), port=sim.url)
    with pytest.raises(PortError, match="no such device"):
        prepare(small_tag(), port=str(tmp_path / "ttyUSB7"))
    with pytest.raises(PortError, match="is a directory"):
        prepare(small_tag(), port=str(tmp_path))
    with pytest.raises(PortError, match="not a serial port"):
        prepare(small_tag(), port="/dev/null")
    with pytest.raises(
        ProfileError,
        match=r"^bus\.baud: at 57600 bps a tick's goals and read-back take 22\.0 ms on the bus,"
        r" more than the 10 ms period of motion\.rate: raise bus\.baud \(and the servos' Baud"
        r" Rate\) or lower motion\.rate$",
    ):
        prepare(small_tag(), overrides=("bus.baud=57600",), port=sim.url)
    with pytest.raises(InputError, match=r"^mode: not an option of the arm$"):
        prepare(small_tag(), mode="wait")
    with pytest.raises(InputError, match=r"^mode, speed: not an option of the arm$"):
        prepare(small_tag(), mode="wait", speed=2)
    assert sim.chain.packets_received == 0
    folder = tmp_path / "never"
    with pytest.raises(PortError):
        draw(small_tag(), folder, device="dynamixel", port=str(tmp_path / "ttyUSB7"))
    assert not folder.exists()
    job = prepare(small_tag(), port=sim.url)
    assert job.device == "dynamixel" and sim.chain.packets_received == 0
    planned = job.planned
    assert len(planned) == len(job.program) and set(np.unique(planned.pen)) == {0, 1}
    assert np.allclose(np.diff(planned.t), load_profile().period)


def _fake_sysfs(root: Path, name: str, ms: int) -> Path:
    folder = root / "bus" / "usb-serial" / "devices" / name
    folder.mkdir(parents=True)
    (folder / "latency_timer").write_text(f"{ms}\n")
    return root


def test_latency_timer_warning_resolves_symlinks_and_names_the_fix(tmp_path) -> None:
    sysfs = _fake_sysfs(tmp_path / "sys", "ttyUSB0", 16)
    dev = tmp_path / "dev"
    (dev / "serial" / "by-id").mkdir(parents=True)
    (dev / "ttyUSB0").touch()
    link = dev / "serial" / "by-id" / "usb-FTDI_USB__-__Serial_Converter_FT1234-if00-port0"
    link.symlink_to("../../ttyUSB0")
    warning = latency_timer_warning(str(link), sysfs)
    assert warning is not None
    assert warning.startswith(f"{link} is a USB serial adapter (ttyUSB0) with a 16 ms latency")
    timer = sysfs / "bus" / "usb-serial" / "devices" / "ttyUSB0" / "latency_timer"
    assert warning.endswith(
        f"Set it to 1 ms: echo 1 | sudo tee {timer} (until it is unplugged; for good, a udev"
        ' rule: ACTION=="add", SUBSYSTEM=="usb-serial", DRIVERS=="ftdi_sio",'
        ' ATTR{latency_timer}="1")'
    )
    (timer).write_text("1\n")
    assert latency_timer_warning(str(link), sysfs) is None
    assert latency_timer_warning(str(dev / "ttyACM0"), sysfs) is None  # not a usb-serial one
    assert latency_timer_warning("dxlsim://arm", sysfs) is None


def test_an_adapter_watched_by_pyserials_spy_gets_the_latency_timer_warning(tmp_path) -> None:
    """spy://PORT?options: the port is what comes before the first '?', whatever the options
    hold (here a log file name with a '?' of its own)."""
    sysfs = _fake_sysfs(tmp_path / "sys", "ttyUSB0", 16)
    device = tmp_path / "ttyUSB0"
    device.touch()
    warning = latency_timer_warning(f"spy://{device}?file={tmp_path}/spy?.log", sysfs)
    assert warning is not None
    assert warning.startswith(f"{device} is a USB serial adapter (ttyUSB0) with a 16 ms latency")


def test_a_url_port_gets_no_latency_timer_warning_whatever_it_names(tmp_path) -> None:
    """A URL port is no local tty: even a simulated chain named like the slow adapter beside it
    (its last part reads ``ttyUSB0``) gets no latency-timer warning; the adapter itself does."""
    sysfs = _fake_sysfs(tmp_path / "sys", "ttyUSB0", 16)
    (tmp_path / "ttyUSB0").touch()
    assert latency_timer_warning(str(tmp_path / "ttyUSB0"), sysfs) is not None
    assert latency_timer_warning("dxlsim://ttyUSB0", sysfs) is None


def test_over_a_pty_with_late_and_lost_replies_and_a_slow_adapter(record, tmp_path, caplog):
    """Real time: replies 50 ms late, 2 % lost; the pty posing as a 16 ms FTDI adapter.

    The simulated servos are a thread of this process: a busy host may starve them for a
    quarter second, which the default bus.silence_timeout would rightly call a silent bus."""
    overrides = (*FAST, "bus.silence_timeout=1.0")
    profile = load_profile(None, overrides)
    sim: Recorded = record(simulated_chain(profile, real_time=True))
    sim.chain.set_reply_faults(latency=0.05, drop=0.02, seed=5)
    path, stop = serve_pty(sim.chain)
    try:
        sysfs = _fake_sysfs(tmp_path / "sys", os.path.basename(os.path.realpath(path)), 16)
        job = prepare(small_tag(), overrides=overrides, port=path, sysfs=sysfs)
        with caplog.at_level(logging.WARNING, logger="tagbot.arm.run"):
            started = time.monotonic()
            run = job.run(tmp_path)
            wall = time.monotonic() - started
    finally:
        stop()
    assert run.error is None, run.error
    assert len(run.warnings) == 1 and "16 ms latency timer" in run.warnings[0]
    assert "16 ms latency timer" in caplog.text
    program = job.program
    with sim.chain.lock:
        for column, id in enumerate((1, 2, 3)):
            assert _goals_received(sim, id) == program.goals[:, column].tolist()
    d = run.details
    assert run.executed_source == "read-back, 100 Hz" and not d["simulated"]
    assert d["readback_late_replies"] >= 0.9 * d["readback_replies"]
    assert d["reply_delay_p50_ms"] >= 50
    assert d["readbacks"] >= 0.8 * len(program)
    assert d["loop_rate_hz"] > 95  # real time on a shared machine: a few resyncs at most
    ex = run.executed
    assert 0.8 * len(program) <= len(ex) <= d["readbacks"] and ex[:, 3].max() == 1.0
    # Read-back positions belong to their own instants: the trace follows the plan.
    assert d["joint_tracking_error"]["mean"] < 1.0
    assert wall < 30


@pytest.fixture
def sim_default(record):
    """The default profile and a recorded chain for it at park: ``(profile, recorded)``."""
    profile = load_profile()
    return profile, record(simulated_chain(profile))


def _baseline(record, tmp_path: Path) -> MachineRun:
    """The two-plan tag on a clean line: what the faulty runs are compared with."""
    profile = load_profile()
    sim = record(simulated_chain(profile))
    tmp_path.mkdir()
    run = prepare(two_plan_tag(), port=sim.url).run(tmp_path)
    assert run.error is None
    return run


def test_the_program_is_what_the_tests_assume(sim_default) -> None:
    profile, _ = sim_default
    program = build_program(two_plan_tag(), profile)
    assert len(program) > 900 and math.isclose(profile.period, 0.01)


def test_an_adapter_found_by_hwgrep_gets_the_latency_timer_warning(tmp_path, monkeypatch) -> None:
    """``hwgrep://FT1234`` is resolved as pyserial resolves it when opening (the first port
    whose name, description or hardware ID matches): that adapter's latency timer is read. No
    match: no warning (opening the port will name the problem)."""
    import serial.tools.list_ports

    sysfs = _fake_sysfs(tmp_path / "sys", "ttyUSB3", 16)
    device = tmp_path / "ttyUSB3"
    device.touch()
    ports = [
        (str(tmp_path / "ttyACM0"), "Arduino", "USB VID:PID=2341:0043"),
        (str(device), "FT232R USB UART", "USB VID:PID=0403:6001 SER=FT1234"),
    ]

    def grep(regexp, include_links=False):
        return iter([p for p in ports if any(re.search(regexp, f, re.I) for f in p)])

    monkeypatch.setattr(serial.tools.list_ports, "grep", grep)
    warning = latency_timer_warning("hwgrep://FT1234", sysfs)
    assert warning is not None
    assert warning.startswith(f"{device} is a USB serial adapter (ttyUSB3) with a 16 ms latency")
    assert latency_timer_warning("hwgrep://nothing-like-it", sysfs) is None


def test_goal_positions_the_adapter_cannot_write_are_named(record, profile, monkeypatch):
    """On the way to the start (the servos' own profile), an adapter that refuses the goals'
    SYNC_WRITE: the error names the approach, that packet and the port."""
    sim = record(simulated_chain(profile))
    sent = sdk.GroupSyncWrite.txPacket

    def refuses_goals(group):
        return sdk.COMM_TX_FAIL if group.start_address == GOAL_POSITION else sent(group)

    with ArmDriver(sim.url, profile) as driver:
        driver.connect()
        monkeypatch.setattr(sdk.GroupSyncWrite, "txPacket", refuses_goals)
        with pytest.raises(ConnectionLost) as caught:
            driver.move_to(driver.read_present(), 0.1)
    assert str(caught.value) == (
        f"approach: could not write SYNC_WRITE of goal positions to {sim.url}"
    )
