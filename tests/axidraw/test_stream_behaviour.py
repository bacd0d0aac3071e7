"""What a user meets when the EBB answers badly or not at all, and the edges of an AxiDraw run's
report: an error reply, a reply that is not ``OK``, a board gone silent at a stop, a fault
before the first move, Ctrl-C once every move has run, a resumed run's plan, ``--port auto``."""

from __future__ import annotations

import json
import os
from dataclasses import replace
from itertools import count

import numpy as np
import pytest
import serial

from sim.ebb.device import SimulatedEBB
from sim.ebb.transport import attach_device
from tagbot.axidraw.machine import (
    _runs_from,
    find_port,
    prepare,
    resumable,
    resume_point,
    timeline,
)
from tagbot.axidraw.moves import _travel_moves, build_job
from tagbot.axidraw.profile import load_profile
from tagbot.axidraw.stream import (
    RESYNC_TIMEOUT,
    EBBStreamer,
    StreamReport,
    entry_end_ticks,
    parse_version,
)
from tagbot.control import RunControl
from tagbot.draw import draw
from tagbot.errors import (
    ConnectionLost,
    DeviceError,
    DeviceFault,
    DeviceTimeout,
    InputError,
    Interrupted,
    PortError,
)
from tagbot.io.planfile import load_plan
from tagbot.plotter.place import place

from .conftest import LETTER_B

_names = count()


def _url(device: SimulatedEBB) -> str:
    return attach_device(device, f"a3edge{os.getpid()}_{next(_names)}")


@pytest.fixture
def streamer():
    """A streamer on a new simulated board (in-process, simulated time); its port closed after."""
    link = serial.serial_for_url(_url(SimulatedEBB()), timeout=0.01)
    yield EBBStreamer(link, load_profile(), {})
    link.close()


def test_ask_returns_the_data_line_asked_for_and_nothing_else(streamer):
    """``ask`` gives the command's data line when asked for one, else empty bytes (the ``OK``
    is checked, not returned)."""
    assert streamer.ask("QM", data=True, ok=False) == b"QM,0,0,0,0"
    assert streamer.ask("SC,8,8") == b""


def test_an_error_reply_is_a_fault_naming_the_command_and_kept_in_the_report(streamer):
    with pytest.raises(DeviceFault, match=r"^XY: the EBB replied !8 Err: Unknown command 'XY"):
        streamer.ask("XY")
    (error,) = streamer.report.errors
    assert error.startswith("!8 Err: Unknown command 'XY")


def test_a_reply_that_is_not_ok_names_the_command_alone(streamer):
    """``QU,2`` answers a data line before its ``OK``: read as the end, it is not ``OK``."""
    with pytest.raises(DeviceError, match=r"^QU: expected OK from the EBB, got b'QU,32'$"):
        streamer.ask("QU,2")


class _Clock:
    """A simulated clock starting at 100 s (far from 0, where a sum and a difference of two
    instants could agree)."""

    def __init__(self) -> None:
        self.t = 100.0

    def now(self) -> float:
        return self.t

    def sleep_until(self, t: float) -> None:
        self.t = max(self.t, t)


class _SilentLink:
    """A board that never answers again: each read waits out the port's 10 ms timeout."""

    def __init__(self) -> None:
        self.clock = _Clock()
        self.written: list[bytes] = []

    def write(self, data: bytes) -> int:
        self.written.append(bytes(data))
        return len(data)

    def read(self, n: int = 1) -> bytes:
        self.clock.t += 0.01
        return b""


class _WaitingLink:
    """A board whose reply is all waiting on the port once the command is written; it keeps
    the size of every read asked of it."""

    def __init__(self, reply: bytes) -> None:
        self.clock, self.reply, self.held, self.reads = _Clock(), reply, b"", []

    @property
    def in_waiting(self) -> int:
        return len(self.held)

    def write(self, data: bytes) -> int:
        self.held += self.reply
        return len(data)

    def read(self, n: int = 1) -> bytes:
        self.reads.append(n)
        chunk, self.held = self.held[:n], self.held[n:]
        return chunk


def test_a_reply_waiting_on_the_port_is_read_in_one_call():
    """The reply the port already holds is read at once (all ``in_waiting`` bytes), not a
    byte a call."""
    link = _WaitingLink(b"QM,0,0,0,0\r\n")
    streamer = EBBStreamer(link, load_profile(), {})
    assert streamer.ask("QM", data=True, ok=False) == b"QM,0,0,0,0"
    assert link.reads == [12]


class _SlowBoard(_WaitingLink):
    """A board that answers at once and holds every motion line written to it until its clock
    reaches ``done`` (OK to anything else; idle at home, button not pressed)."""

    def __init__(self, done: float) -> None:
        super().__init__(b"")
        self.done, self.lines, self.written = done, 0, []

    def write(self, data: bytes) -> int:
        self.written.append(bytes(data))
        name = data.split(b",")[0].strip()
        busy = self.lines if self.clock.t < self.done else 0
        replies = {
            b"QM": b"QM,%d,0,0,0\r\n" % min(busy, 1),
            b"QU": b"QU,%d\r\nOK\r\n" % max(busy - 1, 0),
            b"QS": b"0,0\r\nOK\r\n",
            b"QB": b"0\r\nOK\r\n",
        }
        self.lines += name == b"SM"
        self.held += replies.get(name, b"OK\r\n")
        return len(data)


def test_a_board_found_idle_one_recheck_after_its_due_time_has_not_run_dry():
    """Two 1 ms lines sent at 100 s should be done at 100.002 s; the board, still full then,
    has room at the next look 1 ms later (100.003 s) and takes the third line: that is the
    host's own re-check period, not a stall, and the line goes out without another look."""
    board = _SlowBoard(done=100.0025)
    streamer = EBBStreamer(board, load_profile(), {})
    report = streamer.stream([b"SM,1,0,0"] * 3, durations=[0.001] * 3)
    assert report.stalls == [] and report.executed == 3
    # One look (QM, QU,6) a millisecond from the poll at 100 s to the third line, no more.
    second, third = [i for i, line in enumerate(board.written) if line.startswith(b"SM")][1:]
    assert board.written[second + 1 : third].count(b"QM\r") == 4


def test_a_stop_on_a_silent_board_gives_up_after_the_resync_timeout():
    link = _SilentLink()
    streamer = EBBStreamer(link, load_profile(), {})
    assert streamer.stop() is None  # the stopped position is unknown
    assert streamer.report.stopped_at is None
    assert link.written == [b"ES\r", b"V\r"]
    # It waited RESYNC_TIMEOUT s (on the port's clock) for the board, and no longer.
    assert RESYNC_TIMEOUT <= link.clock.t - 100.0 <= RESYNC_TIMEOUT + 0.05


class _SlowSilentLink(_SilentLink):
    """A silent board behind a port whose reads each wait 0.5 s (exact on the clock)."""

    def read(self, n: int = 1) -> bytes:
        self.clock.t += 0.5
        return b""


def test_a_silent_board_is_given_up_on_by_the_first_read_at_the_reply_timeout():
    """A read that starts when the reply timeout (2 s) has run out and brings nothing is the
    last: the host waited 2 s and that read's own 0.5 s, and did not read once more."""
    link = _SlowSilentLink()
    streamer = EBBStreamer(link, load_profile(), {})
    with pytest.raises(DeviceTimeout, match=r"^QM: no reply from the EBB in 2 s$"):
        streamer.ask("QM", data=True)
    assert link.clock.t - 100.0 == 2.5


class _BlockingLink(_SilentLink):
    """A pyserial port that cannot tell what is waiting (no ``in_waiting``) and whose read of
    ``n`` bytes waits out its 0.5 s timeout when fewer have arrived; ``replies`` have."""

    def __init__(self, replies: bytes) -> None:
        super().__init__()
        self.replies = replies

    def read(self, n: int = 1) -> bytes:
        if len(self.replies) < n:
            self.clock.t += 0.5
        got, self.replies = self.replies[:n], self.replies[n:]
        return got


def test_a_reply_not_ok_to_a_garbled_command_still_names_it():
    """A byte that is not ASCII in a command's name (a corrupted line) answered by a line that
    is not ``OK`` is shown replaced in the error, not a crash."""
    streamer = EBBStreamer(_BlockingLink(b"QU,32\r"), load_profile(), {})
    with pytest.raises(DeviceError, match=r"^\ufffdU: expected OK from the EBB, got b'QU,32'$"):
        streamer.ask(b"\xe9U,2")


def test_a_stop_reads_a_qm_reply_without_its_four_flags_as_nothing_executing():
    """A ``QM`` reply that is not its four flags (a garbled line) counts no command executing:
    the stop's wait for the pen lift ends when ``QU,6`` says nothing is waiting, and the stop
    gives where the motors stopped."""
    version = b"EBBv13_and_above EB Firmware Version 3.0.3\r"
    link = _BlockingLink(b"0\rOK\r" + version + b"120,-40\rOK\rOK\rQM,0\rQU,0\rOK\r")
    up = b"SP,1,200,1\r"
    streamer = EBBStreamer(link, load_profile(), {False: (up, 0.2)})
    assert streamer.stop() == (120, -40)
    assert link.written == [b"ES\r", b"V\r", b"QS\r", up, b"QM\r", b"QU,6\r"]
    assert link.replies == b""


def test_a_line_ended_by_its_first_end_byte_is_taken_without_waiting_for_more():
    """Legacy lines may end with CR or LF alone: a reply whose last byte so far ends its line
    is taken at once, not after the port's timeout waiting for a byte the board never sends."""
    link = _BlockingLink(b"QM,0,1,0,0\n")
    streamer = EBBStreamer(link, load_profile(), {})
    assert streamer.ask("QM", data=True, ok=False) == b"QM,0,1,0,0"
    link.replies = b"OK\r"
    assert streamer.ask("SC,8,8") == b""
    assert link.clock.t == 100.0 and link.replies == b""


def test_a_board_lost_at_connect_says_nothing_of_the_job_was_executed(tmp_path):
    tag = load_plan(LETTER_B)
    device = SimulatedEBB()
    device.reset_board(0.001)  # before the version reply: the USB drops
    job = prepare(tag, port=_url(device))
    expected = r"^before move 1 \(nothing of the job was executed\): the EBB's line failed"
    with pytest.raises(ConnectionLost, match=expected):
        draw(tag, tmp_path / "lost", prepared=job, pictures=False)
    report = json.loads((tmp_path / "lost" / "report.json").read_text())
    assert not report["completed"] and report["executed"] == 0 and report["sent"] == 0
    assert report["error"].startswith("before move 1 (nothing of the job was executed)")
    assert report["comparison_error"] == "nothing was executed"


def test_ctrl_c_once_every_move_has_run_reports_the_whole_drawing(tmp_path):
    """The last progress call comes after the last move: Ctrl-C there stops nothing more, and
    the report holds every move and the comparison of the whole job."""
    tag = load_plan(LETTER_B)
    job = prepare(tag)

    def progress(done: int, total: int) -> None:
        if done == total:
            raise KeyboardInterrupt

    with pytest.raises(Interrupted, match=r"^after move (\d+) of \1 \(moves.txt\): interrupted"):
        draw(tag, tmp_path / "end", prepared=job, pictures=False, progress=progress)
    report = json.loads((tmp_path / "end" / "report.json").read_text())
    assert not report["completed"]
    assert report["executed"] == report["total"] == len(job.job.entries)
    assert report["resume_from"] is None  # nothing is left to resume
    whole = draw(tag, tmp_path / "whole", prepared=job, pictures=False).report
    assert report["planned_drawing_s"] == whole["planned_drawing_s"]
    assert report["speed_snr_db"] >= 35.0 and report["path_deviation_max_mm"] <= 0.02


def test_a_resumed_runs_plan_starts_at_the_resumed_move(tmp_path):
    """A run resumed in its middle is compared from the resumed move on: its plan starts
    there, not before (the moves before it were drawn by the first run)."""
    tag = load_plan(LETTER_B)
    base = prepare(tag)
    entries = base.job.entries
    device = SimulatedEBB()

    def progress(done: int, total: int) -> None:
        if done >= total // 2:
            raise KeyboardInterrupt

    with pytest.raises(Interrupted):
        draw(tag, tmp_path / "a", prepared=replace(base, port=_url(device)), progress=progress,
             pictures=False)  # fmt: skip
    first = json.loads((tmp_path / "a" / "report.json").read_text())
    resume_from = first["resume_from"]
    start = entries[resume_from - 1].start
    assert start - base.job.run_start[0] > 2.0  # well into the one run
    again = replace(base, port=_url(device), resume_from=resume_from)
    began = device.now
    second = draw(tag, tmp_path / "b", prepared=again, pictures=False).report
    (run,) = second["runs"]
    assert start - 1e-6 <= run["planned_start"] <= start + 0.002
    # Resumed on a pen-down move: the pen goes back down (the board's pen all the way down, as
    # in the first part) for the rest of the run, not only up for the travel there.
    pen = device.recorder.pen_at(np.linspace(began, device.now, 200))
    lowest = device.recorder.pen_at(np.linspace(0.0, began, 200)).min()
    rest = sum(e.duration for e in entries[resume_from - 1 :] if e.kind == "draw" and e.pen)
    assert np.mean(pen == lowest) >= 0.9 * rest / (device.now - began)


def test_port_auto_takes_the_board_the_makers_finder_names(monkeypatch):
    from plotink import ebb_serial

    monkeypatch.setattr(ebb_serial, "findPort", lambda: "/dev/ttyACM7")
    assert find_port() == "/dev/ttyACM7"


@pytest.mark.parametrize(
    ("found", "message"),
    [
        (None, r"--port auto: no EiBotBoard found on USB \(is the AxiDraw plugged in\?\)"),
        ("/dev/ttyACM7", r"--port /dev/ttyACM7: no such device"),
    ],
)
def test_prepare_with_port_auto_checks_the_board_found_or_says_none_is(monkeypatch, found, message):
    """``--port auto`` is looked up on USB before anything is built or sent: none found is
    said as such; the port found is the one checked (here absent)."""
    from plotink import ebb_serial

    monkeypatch.setattr(ebb_serial, "findPort", lambda: found)
    with pytest.raises(PortError, match=rf"^{message}"):
        prepare(load_plan(LETTER_B), port="auto")


def test_a_fault_on_a_garbled_command_still_names_it(streamer):
    """A byte that is not ASCII in a command (a corrupted line) is shown replaced, not a crash."""
    with pytest.raises(DeviceFault, match=r"^\ufffdX: the EBB replied !8 Err"):
        streamer.ask(b"\xe9X")


def test_the_planned_pen_is_down_from_the_instant_it_is_lowered():
    """motion.csv's pen column: 1 at a sample taken the instant the pen command starts."""
    job = prepare(load_plan(LETTER_B)).job
    when = next(t for t, down in job.pen_at if down)
    dt = when / 4  # a power of two: the fourth sample falls on the instant exactly
    table = timeline(job, dt)
    assert table.t[4] == when
    assert list(table.pen[3:6]) == [0, 1, 1]


def test_a_stop_before_the_motors_left_home_cuts_no_move_short():
    """Nothing executed, the first move sent but not one step taken: nothing was cut short
    (there is nothing to resume: the job is drawn again as it is); a step taken cuts move 1
    short (on a profile that parks away from home as well)."""
    tag = load_plan(LETTER_B)
    for overrides in ((), ("motion.park=false",)):
        job = prepare(tag, overrides=overrides)
        assert job.job.entries[0].move is not None  # the first move travels
        report = StreamReport(first=0, sent=1, executed=0, stopped_at=(0, 0))
        assert job._executed_moves(report) == (0, 0)
        report = StreamReport(first=0, sent=1, executed=0, stopped_at=(3, 1))
        assert job._executed_moves(report) == (0, 1)  # under way: cut short


def test_a_stop_waits_for_the_pen_to_be_all_the_way_up(tmp_path):
    """A slow raise and a quick lowering: when the stop returns, the pen servo is at the
    up position (the wait is the raise's, not the lowering's)."""
    tag = load_plan(LETTER_B)
    device = SimulatedEBB()
    slow_raise = ("pen.rate_raise=5", "pen.rate_lower=100")
    job = prepare(tag, port=_url(device), overrides=slow_raise)
    profile = job.profile
    assert profile.pen_time(False) > 2 * profile.pen_time(True)

    def progress(done: int, total: int) -> None:
        if done >= total // 3:
            raise KeyboardInterrupt

    with pytest.raises(Interrupted):
        run = job.run(tmp_path, progress=progress)
        raise run.error
    assert device.pen_position() == profile.servo_position(profile["pen.up"])


def test_the_report_names_the_t3_moves_and_the_placement(tmp_path):
    tag = load_plan(LETTER_B)
    job = prepare(tag)
    report = draw(tag, tmp_path / "r", prepared=job, pictures=False).report
    draws = [e for e in job.job.entries if e.kind == "draw"]
    t3 = sum(e.move.command == "T3" for e in draws)
    assert report["details"]["t3_moves"] == t3 > 0
    placement = report["placement"]
    assert placement["mm_per_unit"] == pytest.approx(job.setpoints.size)
    assert placement["matrix"] == job.setpoints.matrix.tolist()
    (run,) = placement["runs"]
    assert run["start"] == pytest.approx(job.job.run_start[0])


def test_each_run_is_compared_with_its_plan_to_the_runs_very_end():
    """The plan a drawn run is judged against (the report's SNR and deviation) spans the whole
    run on the job's clock, every millisecond: from its start to where the job's own moves end
    it, at the same point, not a setpoint short."""
    job = prepare(load_plan(LETTER_B))
    compared = job._planned_runs()
    planned = job.job.planned_runs()
    assert len(compared) == len(planned) == len(job.job.runs)
    for (t, xy), (moves_t, moves_xy) in zip(compared, planned, strict=True):
        assert t[0] == pytest.approx(moves_t[0]) and t[-1] == pytest.approx(moves_t[-1])
        assert xy[-1] == pytest.approx(moves_xy[-1])
        assert max(t[1:] - t[:-1]) == pytest.approx(0.001)


def test_a_line_given_with_its_cr_goes_out_as_it_is(streamer, monkeypatch):
    """moves.txt's lines end in ``\\r``: each is written once as it is, with no empty line
    after it; a command without one gets it."""
    written = []
    write = streamer.link.write
    monkeypatch.setattr(streamer.link, "write", lambda data: written.append(data) or write(data))
    streamer.ask(b"SM,10,0,0\r")
    streamer.ask("SM,10,0,0")
    assert written == [b"SM,10,0,0\r", b"SM,10,0,0\r"]


def test_a_board_that_ran_dry_resumes_from_the_move_after_its_last(tmp_path):
    """A USB stall past the reply timeout: the board runs its FIFO dry and stands at the end of
    the last move it executed. Nothing was cut short, so the report resumes from the very next
    move (none skipped)."""
    tag = load_plan(LETTER_B)
    device = SimulatedEBB()
    device.stall_usb(4.0, 3.0)
    job = prepare(tag, port=_url(device))
    entries = job.job.entries
    with pytest.raises(DeviceTimeout):
        draw(tag, tmp_path / "dry", prepared=job, pictures=False)
    report = json.loads((tmp_path / "dry" / "report.json").read_text())
    executed = report["executed"]
    assert 0 < executed < len(entries) - 1
    assert tuple(report["details"]["stopped_at_steps"]) == entries[executed - 1].steps
    assert entries[executed].move is not None  # the next move would have moved the motors
    assert report["resume_from"] == executed + 1


def test_resume_from_is_taken_from_move_2_to_the_last():
    """``--resume-from``'s edges: ``prepare`` takes move 2 and refuses one past the last
    (before anything is sent), naming the moves it takes; 1 is refused, the last taken."""
    tag = load_plan(LETTER_B)
    job = prepare(tag, resume_from=2)
    assert job.resume_from == 2
    total = len(job.job.entries)
    with pytest.raises(InputError, match=rf"^--resume-from: move {total + 1} is not in the job "
                       rf"\(moves 2 to {total}\)$"):  # fmt: skip
        prepare(tag, resume_from=total + 1)
    assert not resumable(job.job, 1) and resumable(job.job, 2)
    assert resumable(job.job, total) and not resumable(job.job, total + 1)


def test_a_stop_before_a_moves_first_step_cuts_nothing_short():
    """Stopped mid-job in a drawing move's first ticks, before it took a step (the motors where
    the move before it left them, later moves sent): that move is not cut short, and the job
    resumes from it; one step later it is cut short, and the job resumes after it."""
    job = prepare(load_plan(LETTER_B))
    entries, ticks, ends = job.job.entries, job.job.ticks, entry_end_ticks(job.job)
    k = next(
        k
        for k in range(len(entries) // 2, len(entries))
        if entries[k].kind == entries[k - 1].kind == "draw"
        and entries[k - 1].steps != entries[k - 2].steps  # move k - 1 moved the motors
        and tuple(ticks[ends[k - 1]]) == entries[k - 1].steps  # move k's first tick: no step
    )
    here = entries[k - 1].steps
    report = StreamReport(first=0, sent=k + 5, executed=k - 1, stopped_at=here)
    assert job._executed_moves(report) == (k, 0)
    assert resume_point(job.job, k, 0) == k + 1  # move k, 1-based
    stepped = next(tuple(p) for p in ticks[ends[k - 1] : ends[k]] if tuple(p) != here)
    report = StreamReport(first=0, sent=k + 5, executed=k - 1, stopped_at=stepped)
    assert job._executed_moves(report) == (k, 1)


def test_a_resumed_run_with_two_planned_samples_left_is_still_compared():
    """A resumed run's plan keeps what is left of it from the resumed move's start: a run
    ending a millisecond after it (two samples left, a segment) is still compared; one ending
    on it (one sample, no segment) is not."""
    job = prepare(load_plan(LETTER_B))
    first = next(i for i, e in enumerate(job.job.entries) if e.kind == "draw" and i > 20)
    start = job.job.entries[first].start
    ((t, xy),) = job._planned_runs()
    j = int(np.searchsorted(t, start - 1e-9))
    assert abs(t[j] - start) < 1e-6 and t[j + 1] - t[j] == pytest.approx(0.001)
    ((kept, plan),) = _runs_from([(t[: j + 2], xy[: j + 2])], job.job, first)
    assert plan == job.job.runs[0].plan
    np.testing.assert_array_equal(kept[0], t[j : j + 2])
    np.testing.assert_array_equal(kept[1], xy[j : j + 2])
    assert _runs_from([(t[: j + 1], xy[: j + 1])], job.job, first) == []


def test_a_job_lifts_a_pen_left_down_before_its_first_step(tmp_path):
    """A board an earlier session left with its pen lowered: a new job (from home, not a
    resume) lifts the pen before the motors take their first step, not across the paper."""
    device = SimulatedEBB()
    link = serial.serial_for_url(_url(device), timeout=0.01)
    link.write(b"SP,0,300\r")
    while b"OK" not in link.read(100):
        pass
    link.close()
    job = prepare(load_plan(LETTER_B), port=_url(device))
    profile = job.profile
    up = profile.servo_position(profile["pen.up"])
    assert device.pen_position() != up

    def progress(done: int, total: int) -> None:
        if done >= 2:  # the first travel under way: enough
            raise KeyboardInterrupt

    assert isinstance(job.run(tmp_path, progress=progress).error, Interrupted)
    trace = device.recorder.trace()
    moved = (trace.motor1 != trace.motor1[0]) | (trace.motor2 != trace.motor2[0])
    first = int(np.flatnonzero(moved)[0])
    assert trace.pen[first] == up


def test_the_timeline_of_an_empty_job_is_one_still_sample_at_home():
    """A job with nothing to do (no runs, no travel, no park): motion.csv holds one sample, at
    0 s, home, still, pen up."""
    tag = load_plan(LETTER_B)
    profile = load_profile(overrides=["motion.park=false"])
    setpoints = replace(place(tag, profile.placement()), runs=())
    table = timeline(build_job(tag, setpoints, profile), 0.01)
    assert table.t.tolist() == [0.0] and table.xy.tolist() == [[0.0, 0.0]]
    assert table.v.tolist() == [[0.0, 0.0]] and table.pen.tolist() == [0]


def test_a_reply_to_v_that_is_not_an_ebbs_is_refused_quoting_it():
    """A port that is not an EiBotBoard (here a Grbl's banner) is named as such, its reply
    quoted; an EBB's reply gives its version."""
    with pytest.raises(DeviceError, match=r"^V: not an EiBotBoard's version reply: b\"Grbl 1.1h"):
        parse_version(b"Grbl 1.1h ['$' for help]")
    assert parse_version(b"EBBv13_and_above EB Firmware Version 3.0.2\r\n") == (3, 0, 2)


def test_waiting_for_the_board_the_host_asks_again_a_millisecond_after_each_answer(streamer):
    """While the board finishes what it holds (a pause, a stop's pen lift, a resume's travel)
    the host asks ``QM``/``QU,6`` every 1 ms after each answer, not back to back: the
    board's USB is not flooded with queries."""
    streamer.connect()
    for move in _travel_moves((8000, 3000), streamer.profile):
        streamer.ask(move.line())
    link, clock, events = streamer.link, streamer.clock, []
    write, read = link.write, link.read

    def logged_write(data: bytes) -> int:
        events.append((clock.now(), bytes(data)))
        return write(data)

    def logged_read(*args: object, **kwargs: object) -> bytes:
        got = read(*args, **kwargs)
        if got:
            events.append((clock.now(), None))
        return got

    link.write, link.read = logged_write, logged_read
    start = clock.now()
    streamer._drain(start)
    assert clock.now() - start > 0.5  # the travel took that long
    answered, gaps = None, []
    for t, data in events:
        if data is None:
            answered = t
        elif data.startswith(b"QM") and answered is not None:
            gaps.append(t - answered)
    assert len(gaps) > 100 and min(gaps) >= 0.001 - 1e-9


class _Recording:
    """A serial link that keeps every line written to it."""

    def __init__(self, link) -> None:
        self.link, self.written = link, []

    def write(self, data: bytes) -> int:
        self.written.append(bytes(data))
        return self.link.write(data)

    def __getattr__(self, name: str):
        return getattr(self.link, name)


def test_a_stop_waits_out_the_pens_rise_before_asking_the_board_again():
    """A stop lifts the pen (the job's own SP line, 0.2 s of servo travel) and waits that long
    before one look (QM, QU) finds the board idle: it does not keep asking while the pen rises."""
    link = serial.serial_for_url(_url(SimulatedEBB()), timeout=0.01)
    try:
        wire = _Recording(link)
        up = b"SP,1,200,1\r"
        streamer = EBBStreamer(
            wire, load_profile(), {False: (up, 0.2), True: (b"SP,0,200,1\r", 0.2)}
        )
        streamer.connect()
        before = streamer.clock.now()
        assert streamer.stop() == (0, 0)
        assert streamer.clock.now() - before >= 0.2
        stop = wire.written[wire.written.index(b"ES\r") :]
        # ES, then V past every reply in flight, QS where the motors stopped, the pen lifted
        # and one look at the board's state (QM, QU): idle.
        assert stop == [b"ES\r", b"V\r", b"QS\r", up, b"QM\r", b"QU,6\r"]
    finally:
        link.close()


def test_connect_ends_by_reading_the_button_to_forget_an_old_press():
    """The set-up's last command is the documented ``QB`` (upper case, as every command sent):
    a press from before the job is read there, not taken for a pause."""
    link = serial.serial_for_url(_url(SimulatedEBB()), timeout=0.01)
    try:
        wire = _Recording(link)
        EBBStreamer(wire, load_profile(), {}).connect()
        assert wire.written[0] == b"V\r" and wire.written[-1] == b"QB\r"
        assert all(line == line.upper() for line in wire.written)
    finally:
        link.close()


def test_a_polled_job_without_park_ends_with_the_pen_reported_up(tmp_path):
    """Without a park travel the job's last move lifts the pen: a report polled once every move
    has run is read against that move, pen up (not against the draw before it)."""
    tag = load_plan(LETTER_B)
    device = SimulatedEBB()
    job = replace(prepare(tag, overrides=("motion.park=false",)), port=_url(device))
    last = job.job.entries[-1]
    assert last.kind == "pen" and not last.pen and job.job.entries[-2].pen
    (tmp_path / "out").mkdir()
    run = job.run(tmp_path / "out")
    assert run.error is None and run.sparse
    assert run.executed[-1, 3] == 0.0 and run.executed_runs[-1] == -1
    assert run.executed[:, 3].max() == 1.0
    # A new job starts from home without a travel: the motors end where its last move ends.
    assert job.job.entries[-1].steps != (0, 0)
    assert device.motor_position() == job.job.entries[-1].steps


class _PauseOnce(RunControl):
    """Paused at the stream's first look, resumed ``reads`` looks later."""

    def __init__(self, reads: int) -> None:
        super().__init__()
        self.reads = reads

    @property
    def paused(self) -> bool:
        self.reads -= 1
        return self.reads >= 0


def test_a_pause_with_the_pen_down_after_the_last_line_lifts_and_lowers_it():
    """Paused once every line is on the board, the last of them leaving the pen down: the pause
    lifts the pen (the job's own SP line) when the motors stop and lowers it before going on."""
    link = serial.serial_for_url(_url(SimulatedEBB()), timeout=0.01)
    try:
        wire = _Recording(link)
        up, down = b"SP,1,200,1\r", b"SP,0,200,1\r"
        streamer = EBBStreamer(wire, load_profile(), {False: (up, 0.2), True: (down, 0.2)})
        streamer.connect()
        moves = [m.line() for m in _travel_moves((2000, 1000), streamer.profile)]
        lines = [down, *moves]
        report = streamer.stream(
            lines,
            durations=[0.2] + [0.5] * len(moves),
            pen_down=[True] * len(lines),
            control=_PauseOnce(reads=3),
        )
        assert report.sent == len(lines) and len(report.pauses) == 1
        pens = [w for w in wire.written if w.startswith(b"SP")]
        assert pens == [down, up, down]
        assert wire.written.index(up) > wire.written.index(moves[-1])
    finally:
        link.close()
