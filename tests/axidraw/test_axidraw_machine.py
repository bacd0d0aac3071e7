"""``tagbot draw --device axidraw``: tags through the simulated EBB, refusals, stops, resume."""

from __future__ import annotations

import json
import os
import signal
from collections import Counter
from dataclasses import replace
from itertools import count

import numpy as np
import pytest

from sim.ebb.device import SimulatedEBB
from sim.ebb.transport import attach_device
from tagbot.axidraw.machine import AxiDrawJob, _finite, prepare
from tagbot.axidraw.profile import load_profile
from tagbot.axidraw.stream import entry_end_ticks, locate
from tagbot.control import RunControl
from tagbot.draw import draw
from tagbot.errors import (
    ConnectionLost,
    DeviceError,
    DeviceTimeout,
    Interrupted,
    PlacementError,
    ProfileError,
)
from tagbot.io.planfile import load_plan
from tagbot.signals import SignalInterrupt

from .conftest import LETTER_B

_names = count()


def _url(device: SimulatedEBB) -> str:
    return attach_device(device, f"a3test{os.getpid()}_{next(_names)}")


@pytest.fixture
def tag():
    return load_plan(LETTER_B)


@pytest.fixture
def job(tag):
    return prepare(tag)


class KeyPause(RunControl):
    """Space pressed once a third of the moves have executed, and again ``reads`` asks later
    (the stream asks once a poll, ``serial.poll`` s apart on the board's clock)."""

    def __init__(self, reads: int) -> None:
        super().__init__()
        self.reads, self.third = reads, False

    def progress(self, done: int, total: int) -> None:
        self.third = done >= total // 3

    @property
    def paused(self) -> bool:
        if self.third and self.reads > 0:
            self.reads -= 1
            return True
        return False


@pytest.fixture
def drawn(job, tag, tmp_path):
    out = tmp_path / "axidraw"
    keys = KeyPause(reads=20)
    report = draw(tag, out, prepared=job, pictures=False, control=keys, progress=keys.progress)
    return out, report.report


def test_a_whole_tag_follows_the_plan(drawn, job):
    out, report = drawn
    assert report["device"] == "axidraw" and report["simulated"] and report["completed"]
    assert report["unit"] == "move"
    assert report["executed"] == report["total"] == len(job.job.entries)
    assert report["resume_from"] is None
    # One keyboard pause of 20 polls (0.05 s apart, the lift and lowering of the pen within),
    # left out of the comparison.
    assert report["pauses"] == 1 and 0.9 <= report["paused_s"] <= 1.5
    # The goals: speed SNR >= 35 dB against the plan, path deviation <= 0.02 mm.
    assert report["speed_snr_db"] >= 35.0
    assert report["path_deviation_max_mm"] <= 0.02
    assert report["executed_source"] == "simulator recorder, 1 ms"
    assert report["details"]["fifo"] == 11 and report["details"]["firmware"] == "3.0.3"
    # Streamed ahead by the FIFO's depth and never beyond (one executing, eleven queued).
    assert report["details"]["most_on_board"] == 12
    assert report["stalls"] == 0  # the board never ran dry
    # The moves' own stated error against the plan, per run (letter-b has one), in mm.
    assert report["details"]["run_error_mm"] == job.job.run_error
    # The largest of the moves' own stated errors, as the job states it (well under 1 mm).
    assert report["details"]["move_error_max_mm"] == float(np.max(job.job.move_error)) < 0.02
    # The job's size: every command sent (travel, pen, draw) a move, the draw moves among them.
    assert report["details"]["moves"] == len(job.job.entries)
    assert report["details"]["draw_moves"] == sum(e.kind == "draw" for e in job.job.entries)
    assert len(job.job.run_error) == 1 and 0.0 < job.job.run_error[0] <= 0.02
    # What was sent, one command a line, the job's own.
    sent = (out / "moves.txt").read_text().splitlines()
    assert sent == [e.line.decode().rstrip("\r") for e in job.job.entries]
    assert json.loads((out / "report.json").read_text())["executed"] == len(sent)


def test_the_executed_trace_ends_pen_up_at_home_and_pauses_pen_up(drawn, job):
    out, _report = drawn
    rows = np.loadtxt(out / "executed.csv", delimiter=",", skiprows=1)
    assert rows[-1, 3] == 0
    np.testing.assert_allclose(rows[-1, 1:3], [0.0, 0.0], atol=1e-12)
    # letter-b is one pen-down run: the only pen-up stretch inside it is the pause, where the
    # pen lifts and lowers on the same point.
    down = np.flatnonzero(rows[:, 3] == 1)
    inside = rows[down[0] : down[-1] + 1]
    up = np.flatnonzero(inside[:, 3] == 0)
    assert len(up) and np.all(np.diff(up) == 1)
    span = inside[up[0] - 1 : up[-1] + 2]
    assert span[-1, 0] - span[0, 0] >= 0.9
    np.testing.assert_allclose(span[:, 1:3], span[:1, 1:3].repeat(len(span), 0), atol=1e-12)


def test_refusals_happen_before_the_first_byte(tag, tmp_path):
    with pytest.raises(PlacementError):
        prepare(tag, overrides=("place.scale=5",))
    with pytest.raises(ProfileError, match=r"limits\.draw_speed"):
        prepare(tag, overrides=("limits.draw_speed=400",))
    assert not (tmp_path / "never").exists()


@pytest.mark.parametrize("version", ["2.8.1", "3.0.0"])
def test_old_firmware_is_refused_at_connect(job, tag, tmp_path, version):
    base = job
    device = SimulatedEBB(version=version)
    job = on_port(base, _url(device))
    with pytest.raises(DeviceError, match=rf"firmware {version} is not supported.*3\.0\.1"):
        draw(tag, tmp_path / "old", prepared=job, pictures=False)
    report = json.loads((tmp_path / "old" / "report.json").read_text())
    assert not report["completed"] and report["executed"] == 0
    assert not device.recorder.moves()


@pytest.mark.parametrize(
    ("stop", "named"),
    [
        (KeyboardInterrupt, "Ctrl-C"),
        (lambda: SignalInterrupt(signal.SIGTERM, "SIGTERM"), "SIGTERM"),
    ],
)
def test_a_stop_signal_is_named_in_the_error(job, tag, tmp_path, stop, named):
    """Ctrl-C and SIGTERM (raised in the loop as the command's signal handler does) each end
    the run as an interruption naming the signal the user sent."""

    def progress(done: int, total: int) -> None:
        if done >= total // 4:
            raise stop()

    with pytest.raises(Interrupted) as caught:
        draw(tag, tmp_path / "stop", prepared=job, pictures=False, progress=progress)
    assert str(caught.value).endswith(f": interrupted ({named})")


def test_ctrl_c_stops_safely_naming_the_last_move(job, tag, tmp_path):
    def progress(done: int, total: int) -> None:
        if done >= total // 3:
            raise KeyboardInterrupt

    # A FIFO deeper than the firmware's (QU,2: 32) is capped there.
    deep = replace(job, profile=load_profile(overrides=("serial.fifo=40",)))
    with pytest.raises(Interrupted, match=r"after move \d+ of \d+ \(moves.txt\): interrupted"):
        draw(tag, tmp_path / "stop", prepared=deep, pictures=False, progress=progress)
    report = json.loads((tmp_path / "stop" / "report.json").read_text())
    assert report["details"]["fifo"] == 32 and report["details"]["most_on_board"] == 33
    done = report["executed"]
    assert report["total"] // 3 <= done < report["total"]
    assert f"after move {done} " in report["error"]
    assert report["resume_from"] in (done + 1, done + 2)
    rows = np.loadtxt(tmp_path / "stop" / "executed.csv", delimiter=",", skiprows=1)
    assert rows[-1, 3] == 0  # the pen was lifted
    # The motors stopped where the move the report names ends (or inside the next one).
    stopped = report["details"]["stopped_at_steps"]
    entries = job.job.entries
    np.testing.assert_allclose(rows[-1, 1:3], job.job.xy(stopped), atol=1e-9)
    if report["resume_from"] == done + 1:
        assert tuple(stopped) == entries[done - 1].steps


def test_resume_draws_nothing_twice_and_the_button_pauses(job, tag, tmp_path):
    device = SimulatedEBB()

    def progress(done: int, total: int) -> None:
        if done >= total // 2:
            raise KeyboardInterrupt

    with pytest.raises(Interrupted):
        draw(tag, tmp_path / "a", prepared=on_port(job, _url(device)), progress=progress,
             pictures=False)  # fmt: skip
    first = json.loads((tmp_path / "a" / "report.json").read_text())
    # The PRG button pauses the resumed run for a second (pressed twice).
    device.press_button(device.now + 2.0)
    device.press_button(device.now + 3.0)
    again = on_port(job, _url(device), resume_from=first["resume_from"])
    second = draw(tag, tmp_path / "b", prepared=again, pictures=False).report
    assert second["completed"] and second["executed"] == second["total"]
    assert second["details"]["button_presses"] == 2
    # From the motors' stop (the board drains what it holds first) to the pen's return.
    holds = (second["details"]["fifo"] + 1) * max(e.duration for e in job.job.entries)
    poll = job.profile["serial.poll"]
    lowering = job.profile.pen_time(True)
    assert second["pauses"] == 1
    assert 1.0 - holds - poll <= second["paused_s"] <= 1.0 + poll + lowering + 0.01
    assert second["executed_source"] == "QS polls, 20 Hz" and second["port"].startswith("ebbsim")
    # Every draw move of the job ran exactly once over the two runs (one a stop cut short is
    # not started again: the resume skips what is left of it).
    recorded = [s.line for s in device.recorder.moves() if not s.line.startswith(b"LM")]
    planned = [e.line.rstrip(b"\r") for e in job.job.entries if e.kind == "draw"]
    assert Counter(recorded) == Counter(planned)
    # Parked home at the end, within the one step per motor the cleared accumulators allow.
    assert max(map(abs, device.motor_position())) <= 1


def on_port(job: AxiDrawJob, port: str, resume_from: int | None = None) -> AxiDrawJob:
    """``job`` (already checked) on another port: what prepare(port=...) returns."""
    return replace(job, port=port, resume_from=resume_from)


def test_cli_device_choice_and_one_line_errors(tmp_path, capsys):
    from tagbot.cli import main

    args = ["draw", str(LETTER_B), "--device", "axidraw", "--out", str(tmp_path / "c"), "-q"]
    assert main([*args, "--set", "motors.microstepping=3"]) == 2  # a usage error
    err = capsys.readouterr().err
    assert err.strip().splitlines() == [
        "tagbot: error: --set: motors.microstepping: must be one of 16, 8, 4, 2, 1, got 3"
    ]
    assert main([*args, "--port", "auto"]) == 2  # no board on this host's USB
    err = capsys.readouterr().err
    assert err.strip().splitlines() == [
        "tagbot: error: --port auto: no EiBotBoard found on USB (is the AxiDraw plugged in?)"
    ]
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("fault", ["stall", "reset"])
def test_a_board_fault_ends_in_a_safe_stop_naming_the_last_move(job, tag, tmp_path, fault):
    device = SimulatedEBB()
    if fault == "stall":  # the USB carries nothing for 3 s: a reply is 2 s late
        device.stall_usb(4.0, 3.0)
        expected = DeviceTimeout
    else:  # the board resets: motion stops, the USB connection drops
        device.reset_board(4.0)
        expected = ConnectionLost
    with pytest.raises(expected, match=r"^after move \d+ of \d+ \(moves.txt\): "):
        draw(tag, tmp_path / fault, prepared=on_port(job, _url(device)), pictures=False)
    report = json.loads((tmp_path / fault / "report.json").read_text())
    assert not report["completed"] and 0 < report["executed"] < report["total"]
    assert report["resume_from"] > report["executed"]
    assert f"after move {report['executed']} " in report["error"]
    if fault == "stall":  # ES reached the board once the USB moved again: pen up, stopped
        assert device.pen_up and report["details"]["stopped_at_steps"] is not None
        assert any(text.startswith("ES") for _, text in device.recorder.events)


def test_a_short_usb_stall_is_reported_as_a_stall(job, tag, tmp_path):
    device = SimulatedEBB()
    device.stall_usb(4.0, 1.0)  # shorter than a reply's 2 s: the run goes on
    report = draw(tag, tmp_path / "s", prepared=on_port(job, _url(device)), pictures=False)
    report = report.report
    assert report["completed"] and report["executed"] == report["total"]
    # The board ran dry: 1 s less what it held (at most FIFO + 1 moves) is the stall.
    holds = (report["details"]["fifo"] + 1) * max(e.duration for e in job.job.entries)
    assert report["stalls"] == 1 and 1.0 - holds <= report["stalled_s"] <= 1.0


def test_the_stopped_position_names_the_moves_executed(job):
    """ES flushes what was queued: a stop at a run's last tick has executed that move, not the
    pen lift after it; a stop inside a move has executed the moves before it."""
    entries, ticks = job.job.entries, job.job.ticks
    ends = entry_end_ticks(job.job)
    last = max(i for i, e in enumerate(entries) if e.kind == "draw")
    assert entries[last + 1].kind == "pen"
    # (The board says the last move is under way: the run's slow end reaches its last step
    # position a move earlier, where a stop could not be told from one at its end.)
    assert locate(job.job, entries[last].steps, last, last + 3) == last + 1
    inside = next(i for i, e in enumerate(entries) if e.kind == "draw" and i > 10)
    middle = tuple(ticks[(int(ends[inside - 1]) + int(ends[inside])) // 2])
    assert middle != entries[inside].steps
    assert locate(job.job, middle, inside - 2, inside + 2) == inside
    # Nowhere on the record after the executed moves: as many as the board said.
    assert locate(job.job, (10**6, 10**6), 5, 9) == 5
    # Nothing sent: nothing executed, wherever the motors stand (even on a later move's end).
    assert locate(job.job, entries[inside].steps, 0, 0) == 0


def test_a_stop_on_the_jobs_first_tick_counts_a_one_tick_first_move():
    """The motors stopped where the job's very first tick put them, the end of a one-tick
    first move (the next one leaves that place): that move executed, though the board had
    reported none."""
    from firmware_protocols.ebb.motion import TICK_HZ, Move
    from tagbot.axidraw.moves import Entry, Job

    one = Move("LM", (2**31 - 1, 0), steps=(1, 0))
    two = Move("LM", (2**31 - 1, 0), steps=(2, 0))
    entries = [
        Entry("travel", one.line(), 0.0, 1 / TICK_HZ, -1, (1, 0), False, one),
        Entry("travel", two.line(), 1 / TICK_HZ, 2 / TICK_HZ, -1, (3, 0), False, two),
    ]
    ticks = np.array([[1, 0], [2, 0], [3, 0]], dtype=np.int64)
    job = Job(entries, [], [], ticks, np.arange(1, 4) / TICK_HZ, np.zeros(2), [], 80.0)
    assert list(entry_end_ticks(job)) == [1, 3]
    assert locate(job, (1, 0), 0, 2) == 1
    assert locate(job, (0, 0), 0, 2) == 0  # still home: nothing executed


def test_a_stop_on_a_travels_last_step_has_not_lowered_the_pen(job):
    """The travel to the first run takes its last step on its last tick; motors stopped there
    (first reached then) have executed the travel, not the pen lowering queued after it."""
    entries, ticks = job.job.entries, job.job.ticks
    ends = entry_end_ticks(job.job)
    travel = next(
        i for i, e in enumerate(entries[:-1]) if e.kind == "travel" and entries[i + 1].kind == "pen"
    )
    end = int(ends[travel])
    there = tuple(ticks[end - 1])
    assert there != tuple(ticks[end - 2])  # that last tick steps: the place is its own
    assert locate(job.job, there, travel, travel + 3) == travel + 1


@pytest.mark.parametrize("end", [0.397, 0.3960000000000001, 0.396 + 4e-7, 15.16, 0.0005, 0.001001])
def test_the_plans_samples_never_repeat_an_instant(end):
    """A run's plan every 1 ms and at its end, on the job's clock: never two samples at one
    instant (their velocity would be 0/0), however close the end falls to a sample; a sample
    1 us or less before the end is left out (0.001001: the one at 1 ms, exactly 1 us)."""
    from tagbot.axidraw.machine import PLAN_STEP, _grid

    grid = _grid(end, PLAN_STEP)
    assert len(grid) == 1 or grid[-2] < end - 1e-6
    t = 28.2844 + _grid(end, PLAN_STEP)
    assert np.all(np.diff(t) > 0) and t[-1] == 28.2844 + end and t[0] == 28.2844
    assert np.diff(t).max() <= PLAN_STEP + 1e-6


def test_two_host_stalls_in_a_run_are_named_in_the_plural_with_their_summed_time(cae_job):
    """A run slower than its budget with two host stalls in it: the warning counts them, in the
    plural, and sums their time."""
    from tagbot.axidraw.machine import Budget

    run = {"plan": 0, "executed_start": 1.0, "executed_duration": 2.0}
    slow = {**run, "path_deviation_max_mm": 0.0, "speed_snr_db": 20.0}
    (warning,) = Budget(cae_job[3], [(1.5, 0.1), (2.5, 0.05)])({"runs": [slow]})
    assert warning.endswith("2 host stalls (150 ms) with the pen down: the board ran dry")


def test_a_resume_at_the_last_run_compares_it_with_its_own_plan(tmp_path):
    """The three-run example resumed at its third run's first drawing move: the report's one
    run is that run, named by its own plan (2), not renumbered from 0."""
    from .conftest import CAE

    tag = load_plan(CAE)
    base = prepare(tag)
    plans = [run.plan for run in base.setpoints.runs]
    entries = base.job.entries
    first = next(i for i, e in enumerate(entries) if e.kind == "draw" and e.run == 2)
    job = replace(base, resume_from=first + 1)
    report = draw(tag, tmp_path / "b", prepared=job, pictures=False).report
    assert [run["plan"] for run in report["runs"]] == plans[2:] == [2]


def test_a_run_ctrl_c_stops_halfway_is_reported_cut_short(tmp_path):
    """Ctrl-C halfway through the letter's one run: that run is reported ``cut_short`` (its
    figures cover what was drawn), the stop named after the last move executed."""
    tag = load_plan(LETTER_B)
    job = prepare(tag)

    def progress(done: int, total: int) -> None:
        if done >= total // 2:
            raise KeyboardInterrupt

    with pytest.raises(Interrupted, match=r"^after move \d+ of \d+ \(moves.txt\): interrupted"):
        draw(tag, tmp_path / "a", prepared=job, progress=progress, pictures=False)
    report = json.loads((tmp_path / "a" / "report.json").read_text())
    (run,) = report["runs"]
    assert run["cut_short"] is True and not report["completed"]


def test_a_figure_json_cannot_hold_is_reported_as_none():
    """report.json is strict JSON: a run's speed figure that is infinite or NaN (a run too short
    for it) is written as null, a finite one as the number."""
    assert _finite(float("inf")) is None and _finite(float("nan")) is None
    assert _finite(np.float64(31.25)) == 31.25 and type(_finite(np.float64(31.25))) is float
