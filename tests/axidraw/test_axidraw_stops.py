"""The AxiDraw's pauses and stops as a user meets them: a keyboard pause costs no fidelity
figure, a stop while paused keeps the pause and stops safely, refusals send no byte (bad
firmware: only ``V``), and SIGTERM to ``tagbot draw`` on a pseudo-terminal stops the board."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from itertools import count

import numpy as np
import pytest

from sim.ebb.device import SimulatedEBB
from sim.ebb.transport import attach_device, serve_pty
from tagbot.axidraw.machine import Budget, prepare
from tagbot.control import RunControl
from tagbot.draw import draw
from tagbot.errors import DeviceError, Interrupted, PlacementError
from tagbot.io.planfile import load_plan

from .conftest import LETTER_B

_names = count()


def _url(device: SimulatedEBB) -> str:
    return attach_device(device, f"a3stop{os.getpid()}_{next(_names)}")


def _spy(device: SimulatedEBB) -> list[bytes]:
    """Every byte string the host writes to ``device``, in order."""
    written: list[bytes] = []
    write = device.write

    def spy(data: bytes) -> int:
        written.append(bytes(data))
        return write(data)

    device.write = spy  # type: ignore[method-assign]
    return written


class ClockedControl(RunControl):
    """Space pressed at the simulated board's second ``at`` and again ``length`` s later; with
    ``stop_after``, Ctrl-C that long into the pause instead of the second press."""

    def __init__(self, at: float, length: float, stop_after: float = -1) -> None:
        super().__init__()
        self.at, self.length, self.stop_after = at, length, stop_after
        self.device: SimulatedEBB | None = None

    @property
    def paused(self) -> bool:
        now = self.device.now if self.device is not None else 0.0
        if self.stop_after >= 0 and now >= self.at + self.stop_after:
            raise KeyboardInterrupt
        return self.at <= now < self.at + self.length


def _simulated(monkeypatch, keys: ClockedControl) -> None:
    """The job's own simulated board (no ``--port``: its 1 ms recorder) seen by ``keys``."""
    import sim.ebb.transport as transport

    attach = transport.attach_device

    def keep(device: SimulatedEBB, name: str) -> str:
        keys.device = device
        return attach(device, name)

    monkeypatch.setattr(transport, "attach_device", keep)


@pytest.fixture
def tag():
    return load_plan(LETTER_B)


@pytest.fixture
def job(tag):
    return prepare(tag)


@pytest.fixture
def plain(job, tag, tmp_path):
    """letter-b drawn through, no pause."""
    return draw(tag, tmp_path / "plain", prepared=job, pictures=False).report


def _on(job, device: SimulatedEBB):
    from dataclasses import replace

    return replace(job, port=_url(device))


def test_a_5_s_keyboard_pause_changes_no_fidelity_figure(job, tag, tmp_path, plain, monkeypatch):
    middle = job.job.run_start[0] + 0.5 * job.setpoints.runs[0].duration
    keys = ClockedControl(middle, 5.0)
    _simulated(monkeypatch, keys)
    held = draw(tag, tmp_path / "held", prepared=job, pictures=False, control=keys).report
    assert held["completed"] and held["executed"] == held["total"]
    # From the motors' stop (the board drains the moves it holds) to the pen's return.
    holds = (held["details"]["fifo"] + 1) * max(e.duration for e in job.job.entries)
    lowering = job.profile.pen_time(True)
    assert held["pauses"] == 1 and 5.0 - holds <= held["paused_s"] <= 5.0 + lowering + 0.06
    assert held["executed_duration_s"] >= plain["executed_duration_s"] + 5.0 - holds
    assert abs(held["speed_snr_db"] - plain["speed_snr_db"]) <= 1.0
    assert abs(held["path_deviation_max_mm"] - plain["path_deviation_max_mm"]) <= 0.01
    assert abs(held["drawing_duration_ratio"] - plain["drawing_duration_ratio"]) <= 0.01
    assert held["warnings"] == []


def test_ctrl_c_while_paused_keeps_the_pause_and_stops_safely(
    job, tag, tmp_path, plain, monkeypatch
):
    middle = job.job.run_start[0] + 0.5 * job.setpoints.runs[0].duration
    keys = ClockedControl(middle, 5.0, stop_after=2.0)
    _simulated(monkeypatch, keys)
    with pytest.raises(Interrupted, match=r"^after move \d+ of \d+ \(moves.txt\): interrupted"):
        draw(tag, tmp_path / "s", prepared=job, pictures=False, control=keys)
    device = keys.device
    assert device is not None
    report = json.loads((tmp_path / "s" / "report.json").read_text())
    assert not report["completed"] and 0 < report["executed"] < report["total"]
    # The pause up to the stop is a pause: taken out of the comparison, which holds the drawn
    # half to the plan as well as the whole run was.
    assert report["pauses"] == 1 and report["paused_s"] >= 1.5
    assert report["speed_snr_db"] >= plain["speed_snr_db"] - 3.0
    assert report["path_deviation_max_mm"] <= 0.02
    # Nothing moved after the pause began: the pen up where the drawing stopped.
    assert device.pen_up
    rows = np.loadtxt(tmp_path / "s" / "executed.csv", delimiter=",", skiprows=1)
    assert rows[-1, 3] == 0
    stopped = report["details"]["stopped_at_steps"]
    assert tuple(stopped) == job.job.entries[report["executed"] - 1].steps


def test_refusals_send_no_byte(tag):
    device = SimulatedEBB()
    written = _spy(device)
    url = _url(device)
    with pytest.raises(PlacementError):
        prepare(tag, port=url, overrides=("place.scale=5",))  # off the paper
    with pytest.raises(PlacementError, match="steps/s"):  # a move beyond the EBB's step rate
        prepare(tag, port=url, overrides=("place.scale=fit", "motion.time_scale=uniform",
                                          "limits.draw_speed=312", "limits.draw_acceleration=1e6",
                                          "motion.dt=0.1", "motion.jerk=false"))  # fmt: skip
    assert written == []


def test_bad_firmware_hears_only_v(job, tag, tmp_path):
    device = SimulatedEBB(version="2.8.1")
    written = _spy(device)
    with pytest.raises(DeviceError, match=r"firmware 2\.8\.1 is not supported"):
        draw(tag, tmp_path / "old", prepared=_on(job, device), pictures=False)
    assert b"".join(written) == b"V\r"


def test_sigterm_stops_an_axidraw_draw_safely(tmp_path):
    device = SimulatedEBB(clock="real")
    path, stop = serve_pty(device)
    out = tmp_path / "run"
    try:
        process = subprocess.Popen(
            [sys.executable, "-m", "tagbot", "draw", str(LETTER_B), "--device", "axidraw",
             "--port", path, "--out", str(out), "--no-pictures"],
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        assert process.stderr.readline().startswith("drawing ")
        deadline = time.monotonic() + 30
        while len(device.recorder.moves()) < 30 and time.monotonic() < deadline:
            time.sleep(0.05)  # well into the drawing
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=30)
    finally:
        stop()
    assert process.returncode == 143 and "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("tagbot: error: after move ") and last.endswith("(SIGTERM)")
    report = json.loads((out / "report.json").read_text())
    assert not report["completed"] and report["executed"] >= 1
    assert f"after move {report['executed']} " in report["error"]
    assert device.pen_up and report["details"]["stopped_at_steps"] is not None


def test_space_on_the_terminal_pauses_and_resumes_an_axidraw_draw(tmp_path):
    import pty

    device = SimulatedEBB(clock="real")
    path, stop = serve_pty(device)
    out = tmp_path / "keys"
    master, slave = pty.openpty()
    try:
        process = subprocess.Popen(
            [sys.executable, "-m", "tagbot", "draw", str(LETTER_B), "--device", "axidraw",
             "--port", path, "--out", str(out), "--no-pictures"],
            stdin=slave,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        first = process.stderr.readline()
        assert first.startswith("drawing ") and "space pauses" in first
        deadline = time.monotonic() + 30
        while len(device.recorder.moves()) < 30 and time.monotonic() < deadline:
            time.sleep(0.05)  # well into the drawing
        os.write(master, b" ")
        time.sleep(2.0)
        moves = len(device.recorder.moves())
        time.sleep(1.0)
        held = len(device.recorder.moves()) == moves  # nothing ran while paused
        os.write(master, b" ")
        said, err = process.communicate(timeout=60)
    finally:
        os.close(master)
        os.close(slave)
        stop()
    assert process.returncode == 0, err
    assert "paused: space resumes" in said + err and "resumed" in said + err
    assert held
    report = json.loads((out / "report.json").read_text())
    assert report["completed"] and report["executed"] == report["total"]
    # The pause from the motors' stop (after the moves the board held) to the pen's return,
    # left out of the drawing time the board's QS polls give.
    assert report["pauses"] == 1 and report["paused_s"] >= 2.0
    assert report["executed_source"] == "QS polls, 20 Hz"
    assert abs(report["drawing_duration_ratio"] - 1.0) < 0.15  # 1.3 with the pause left in


def test_a_stall_with_the_pen_down_is_a_warning_naming_the_run(job, tag, tmp_path, monkeypatch):
    """The USB carries nothing for 1.5 s in the middle of letter-b's one run: the board runs dry
    with the pen down (the simulator's recorder sees it stand), and the report says which run,
    which figure and why."""
    import sim.ebb.transport as transport

    attach = transport.attach_device
    middle = job.job.run_start[0] + 0.5 * job.setpoints.runs[0].duration

    def stalled(device: SimulatedEBB, name: str) -> str:
        device.stall_usb(middle, 1.5)
        return attach(device, name)

    monkeypatch.setattr(transport, "attach_device", stalled)
    report = draw(tag, tmp_path / "dry", prepared=job, pictures=False).report
    assert report["completed"] and report["stalls"] == 1
    assert report["speed_snr_db"] < 25.0
    (warning,) = report["warnings"]
    assert warning.startswith("run 1 (plan 0): speed SNR ")
    assert "1 host stall (" in warning and "with the pen down" in warning


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep_until(self, t: float) -> None:
        self.t = max(self.t, t)


class _DescheduledLink:
    """A port whose host is descheduled for 3 s during its first read, while the board's
    reply arrives; then the reply is waiting. ``replies``: what each later read finds."""

    def __init__(self, replies: list[bytes]) -> None:
        self.clock = _Clock()
        self.replies = replies
        self.reads = 0

    def write(self, data: bytes) -> int:
        return len(data)

    def read(self, n: int = 1) -> bytes:
        self.reads += 1
        if self.reads == 1:
            self.clock.t += 3.0  # past the 2 s a reply may take
            return b""
        return self.replies.pop(0) if self.replies else b""


def test_a_reply_waiting_when_a_descheduled_host_wakes_is_no_timeout(job):
    from tagbot.axidraw.stream import EBBStreamer
    from tagbot.errors import DeviceTimeout

    link = _DescheduledLink([b"12,-3\n\r", b"OK\r\n"])
    streamer = EBBStreamer(link, job.profile, {})
    assert streamer.position() == (12, -3)
    # Nothing there even after reading past the deadline: a timeout, naming the command.
    with pytest.raises(DeviceTimeout, match=r"^QM: no reply from the EBB in 2 s"):
        EBBStreamer(_DescheduledLink([]), job.profile, {}).ask("QM", data=True, ok=False)


def test_the_budget_judges_a_run_cut_short_by_a_stop_on_its_path_alone(job) -> None:
    """The AxiDraw's budgets: a run under 25 dB is named with its cause; the same run cut short
    by a stop (its speed ends where the board stopped) is named for its path only."""
    from tagbot.axidraw.machine import Budget

    budget = Budget(job.job, [])
    run = {"plan": 0, "executed_start": 0.0, "executed_duration": 1.0}
    slow = {**run, "path_deviation_max_mm": 0.0, "speed_snr_db": 20.0}
    assert budget({"runs": [slow]}) == [
        "run 1 (plan 0): speed SNR 20.0 dB below 25 dB: the executed motion beyond its moves'"
        f" stated {job.job.run_error[0]:.3f} mm"
    ]
    assert budget({"runs": [{**slow, "cut_short": True}]}) == []
    far = {**slow, "path_deviation_max_mm": 0.05, "cut_short": True}
    (warning,) = budget({"runs": [far]})
    assert warning.startswith("run 1 (plan 0): path deviation 0.050 mm over 0.02 mm: ")


def test_the_budget_warns_for_each_run_over_it_naming_its_figures_and_cause(cae_job):
    """The judge of a three-run report: a run within both budgets has no warning (and the runs
    after it are still judged); one over both names both; one with a host stall in it names
    the stall as the cause."""
    job = cae_job[3]
    stated = job.run_error[1]
    assert stated < 0.02

    def run(plan: int, deviation: float, snr: float, start: float) -> dict:
        return {
            "plan": plan,
            "path_deviation_max_mm": deviation,
            "speed_snr_db": snr,
            "executed_start": start,
            "executed_duration": 2.0,
        }

    report = {"runs": [run(0, 0.01, 40.0, 1.0), run(1, 0.03, 20.0, 5.0), run(2, 0.01, 24.0, 9.0)]}
    assert Budget(job, [(10.0, 0.1)])(report) == [
        "run 2 (plan 1): path deviation 0.030 mm over 0.02 mm and speed SNR 20.0 dB below"
        f" 25 dB: the executed motion beyond its moves' stated {stated:.3f} mm",
        "run 3 (plan 2): speed SNR 24.0 dB below 25 dB: 1 host stall (100 ms) with the pen"
        " down: the board ran dry",
    ]


def test_a_resumed_jobs_runs_are_judged_on_their_own_plans_stated_error(cae_job):
    """A resumed job's report starts at a later run (here plan 1): each run's cause names its
    own plan's stated error, not that of the run at its place in the report."""
    job = replace(cae_job[3], run_error=[0.001, 0.030, 0.002])
    run = {
        "plan": 1,
        "path_deviation_max_mm": 0.035,
        "speed_snr_db": 30.0,
        "executed_start": 0.0,
        "executed_duration": 1.0,
    }
    report = {"runs": [run, {**run, "plan": 2, "executed_start": 2.0}]}
    assert Budget(job, [])(report) == [
        "run 1 (plan 1): path deviation 0.035 mm over 0.02 mm: its moves' own error against"
        " the plan (0.030 mm, stated)",
        "run 2 (plan 2): path deviation 0.035 mm over 0.02 mm: the executed motion beyond its"
        " moves' stated 0.002 mm",
    ]


@pytest.mark.parametrize(("stall_at", "named"), [(0.96, True), (3.9, True), (4.1, False)])
def test_a_stall_is_the_cause_of_a_runs_warning_from_just_before_it_to_a_second_after(
    job, stall_at, named
) -> None:
    """A run executed from 1 s for 2 s: a host stall starting from 50 ms before it to 1 s after
    its end (the board's queue still held its moves) is named as the cause; a later one not."""
    from tagbot.axidraw.machine import Budget

    run = {"plan": 0, "executed_start": 1.0, "executed_duration": 2.0}
    slow = {**run, "path_deviation_max_mm": 0.0, "speed_snr_db": 20.0}
    (warning,) = Budget(job.job, [(stall_at, 0.2)])({"runs": [slow]})
    stall = "1 host stall (200 ms) with the pen down: the board ran dry"
    assert warning.endswith(stall) == named
