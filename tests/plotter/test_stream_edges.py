"""The streamer between and around jobs (issue 34): what it learns at connect, requests made
outside a job, and stray answers that arrive when no line is in flight."""

from __future__ import annotations

import pytest

from firmware_protocols.grbl import State, parse_message
from sim.grbl import SimulatedGrbl
from tagbot.errors import DeviceFault, DeviceTimeout
from tagbot.plotter.stream import (
    GrblStreamer,
    StreamOptions,
    StreamReport,
    _xy_of,
    executed_where,
    line_effects,
    resume_lines,
    resume_point,
)

from .test_stream import PEN_UP, SETTINGS, Wire, connected, open_device, square_program


def test_a_line_numbered_firmware_gets_numbered_lines():
    """``$I`` names a USE_LINE_NUMBERS build ("N" among its options): with the default
    ``line_numbers="auto"`` every program line goes out with its N word, so the status
    reports' Ln: field says which line runs."""
    numbered = SimulatedGrbl(SETTINGS, pen_servo=(30, 50), line_numbers=True)
    port, streamer, wire = connected(numbered)
    try:
        assert streamer.line_numbers is True
        lines = square_program(40)
        streamer.stream(lines)
    finally:
        port.close()
    sent = wire.lines_sent()[-len(lines) :]
    assert [line.split(b"G", 1)[0].split(b"M", 1)[0] for line in sent[:3]] == [b"N1", b"N2", b"N3"]
    assert sent[-1].startswith(f"N{len(lines)}".encode())
    plain = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, _ = connected(plain)
    port.close()
    assert streamer.line_numbers is False


def test_the_machine_position_at_connect_is_where_the_job_starts():
    """A machine left away from its origin: the streamer starts from where it stands."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50), position_mm=(30.0, 40.0, 0.0))
    port, streamer, _ = connected(device)
    try:
        streamer.query_state()
        assert streamer._machine_xy() == (30.0, 40.0)
    finally:
        port.close()


def test_a_second_job_starts_from_where_the_first_left_the_machine():
    """Two jobs on one connection: the second's first move starts where the first job ended
    (its last status report), so progress names that move from the first report on."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, _ = connected(device)
    seen: list[int] = []
    try:
        streamer.stream(["G21\n", "G90\n", "G94\n", "G1X40Y30F3000\n", "M2\n"])
        second = ["G21\n", "G90\n", "G94\n", "G1X60Y30F300\n", "G1X60Y40F300\n", "M2\n"]
        report = streamer.stream(second, progress=lambda done, total: seen.append(done))
    finally:
        port.close()
    # 20 mm at 5 mm/s: about 4 s of reports on line 4 (3 lines done), then 2 s on line 5.
    assert report.executing[0] == 3 and report.executing.count(3) >= 15
    assert seen == [0, 3, 4, 6]


def test_a_hold_asked_between_jobs_goes_straight_to_the_machine():
    """Outside a job (no stream loop to queue it), hold and resume are written at once."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    try:
        streamer.hold()
        streamer.resume()
        assert wire.tx[-2:] == [b"!", b"~"]
        assert streamer.query_state().state == State.IDLE
    finally:
        port.close()


def test_a_status_query_gives_up_after_one_second_of_silence():
    """A machine that stops answering: query_state waits 1 s (its default) on the port's
    clock, then says what it waited for. (A report already on the wire, answering connect's
    last poll, is still read by the first query.)"""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, _ = connected(device)
    try:
        device.go_silent()
        with pytest.raises(DeviceTimeout, match=r"^no status report within 1 s$"):
            for _ in range(3):
                start = streamer.clock.now()
                streamer.query_state()
        assert streamer.clock.now() - start == pytest.approx(1.0, abs=0.1)
    finally:
        port.close()


def test_a_stray_ok_between_jobs_is_kept_not_counted():
    """An answer to a line sent by someone else, before any job and after one: kept among
    the messages (or logged), never taken for one of the job's lines."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, _ = connected(device)
    try:
        streamer._write(b"G4P0\n")  # no tracker yet: nothing to count it against
        for _ in range(3):  # its ok arrives during one of these waits
            assert streamer.query_state().state == State.IDLE
        lines = square_program(20)
        report = streamer.stream(lines)
        acked = streamer.tracker.acked
        streamer._write(b"G4P0\n")  # after the job: every line already answered
        assert streamer.query_state().state == State.IDLE
    finally:
        port.close()
    assert streamer.tracker.acked == acked == len(lines)
    assert report.lines_acknowledged == len(lines)


def test_what_arrives_with_the_awaited_report_is_not_lost():
    """A status report and an ``ok`` read in one chunk: the wait takes the report and the
    ``ok`` is still there for whoever reads next (a safe stop counts it as a planned line)."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    try:
        streamer._write(b"G4P0\n")
        streamer.query_state()
        assert wire.rx[-1].endswith(b"ok\r\n") or b"ok\r\n" in b"".join(wire.rx[-2:])
        assert [type(m).__name__ for m in streamer._messages()] == ["Ok"]
    finally:
        port.close()


def test_resuming_after_a_line_grbl_would_refuse_names_it_from_one():
    """The lines before the resume point run through Grbl's parser: one it would refuse is
    named by its line number in the program, counting from 1, as the CLI names lines."""
    lines = ["G21\n", "G1X1Y1\n", "G1X2Y2F100\n", "G1X3Y3\n"]  # line 2: a feed move with no F
    with pytest.raises(ValueError, match=r"^line 2: Grbl would refuse it \(error:22\)$"):
        resume_lines(lines, 3, PEN_UP, [])


def test_work_coordinates_give_the_machine_position():
    """Status reports in work coordinates (``$10=0``): the machine position is WPos plus the
    last work offset, on both axes."""
    status = parse_message("<Idle|WPos:1.000,2.000,0.000|WCO:10.000,-20.000,0.000>")
    assert _xy_of(status) == (11.0, -18.0)
    assert _xy_of(parse_message("<Idle|WPos:1.000,2.000,0.000>")) == (1.0, 2.0)


def test_the_tracker_names_its_evidence_and_the_trace_hook_its_direction():
    """With ``$10=3`` the executing line comes from the free planner blocks (``Bf:``), and the
    report says so; the trace hook is told which way each chunk went."""
    device = SimulatedGrbl({**SETTINGS, 10: 3}, pen_servo=(30, 50))
    port = open_device(device)
    directions: set[str] = set()
    streamer = GrblStreamer(port, StreamOptions(), trace=lambda way, data: directions.add(way))
    try:
        streamer.connect()
        report = streamer.stream(square_program(200))
    finally:
        port.close()
    assert report.tracking == "status Bf"
    assert directions == {"tx", "rx"}


@pytest.mark.parametrize(
    ("first", "done", "lost", "where"),
    [
        (0, 0, False, "before line 1 (nothing of the program was executed)"),
        (0, 3, False, "after line 3 (the last line the machine executed; resume with"
         " --resume-from 4 --position-known)"),
        (4, 2, False, "after line 6 (the last line the machine executed; resume with"
         " --resume-from 7 --position-known)"),
        (0, 10, False, "after the last line"),
        (0, 0, True, "after no line at least (the last line known executed; lines up to 5 were"
         " sent and the machine may have gone on to line 5: check where the pen stands, then"
         " resume with --resume-from 1 --position-known, or from the line after the one it"
         " reached)"),
    ],
)  # fmt: skip
def test_where_the_machine_stopped_is_named_in_the_programs_line_numbers(
    first: int, done: int, lost: bool, where: str
) -> None:
    """A 10-line program (or its resumed rest from line ``first + 1``), 5 lines sent, ``done``
    finished: where it stopped, as the error message says it."""
    report = StreamReport(lines_total=10, first_line=first, lines_sent=5)
    assert executed_where(report, done, lost=lost) == where


def test_a_dwell_longer_than_the_stall_timeout_is_waited_out_not_a_stall():
    """A 12.5 s dwell (G4P12.5) among queued lines: the machine reports no motion for 12.5 s,
    longer than the 2 s stall timeout, and the job still completes (the watchdog allows 1.5
    times the longest dwell plus a second)."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, _ = connected(device)
    lines = square_program(40)
    lines.insert(6, "G4P12.5\n")
    try:
        report = streamer.stream(lines)
    finally:
        port.close()
    assert streamer.options.stall_timeout == 2.0
    assert report.stopped_at is None and report.errors == []
    assert report.lines_executed == len(lines) and report.finished - report.started > 12.5


@pytest.mark.parametrize(
    ("rate", "accepted"), [(0.0, False), (1e-9, True), (5.0, True), (5.01, False)]
)
def test_the_poll_rate_is_above_zero_and_at_most_five_hertz(rate: float, accepted: bool) -> None:
    """Status polls: some (a rate of 0 never asks, and the watchdog would never hear), at most
    Grbl's recommended 5 Hz."""
    if accepted:
        assert StreamOptions(poll_rate=rate).poll_rate == rate
    else:
        with pytest.raises(ValueError) as refused:
            StreamOptions(poll_rate=rate)
        assert str(refused.value) == f"poll_rate: must be in (0, 5.0] Hz, got {rate}"


def test_a_z_move_to_where_the_pen_already_stands_plans_no_block() -> None:
    """From the start (z = 0 at the given x, y), ``G1Z0`` and a move to the start itself plan
    no moving block; lowering to z = -2 does, once."""
    lines = ["G21\n", "G90\n", "G1Z0F300\n", "G1X5Y7F600\n", "G1Z-2F300\n", "G1Z-2F300\n"]
    moves, targets = line_effects(lines, start=(5.0, 7.0))
    assert moves == [False, False, False, False, True, False]
    assert targets == [(5.0, 7.0)] * len(lines)


def test_a_startup_line_grbl_refuses_at_connect_is_a_warning_naming_it(caplog):
    """Grbl runs its stored startup lines ($N0) after the reset: one it refuses is logged as a
    warning naming the line and Grbl's error, and the connection goes on."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    device.startup_lines[0] = "G5"  # not a Grbl command
    with caplog.at_level("WARNING", logger="tagbot.plotter.stream"):
        port, streamer, _ = connected(device)
        port.close()
    warnings = [r.getMessage() for r in caplog.records if r.name == "tagbot.plotter.stream"]
    assert warnings == ["grbl: startup line 'G5' failed: error:20 (unsupported G-code command)"]
    assert streamer.settings[100] == SETTINGS[100]


def test_the_settings_are_empty_until_connect_reads_them():
    """``GrblStreamer.settings`` (public): an empty mapping before :meth:`connect`, Grbl's ``$$``
    after it."""
    port = open_device(SimulatedGrbl(SETTINGS, pen_servo=(30, 50)))
    try:
        streamer = GrblStreamer(port, StreamOptions())
        assert streamer.settings == {} and len(streamer.settings) == 0
        streamer.connect()
        assert streamer.settings[100] == SETTINGS[100]
    finally:
        port.close()


def test_an_answer_no_one_waits_for_is_logged_at_debug_with_its_kind(caplog):
    """Before any job, an ``ok`` to a line someone else sent is not counted: the debug log
    shows it as ``grbl: Ok()`` (prefix and the message's kind)."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, _ = connected(device)
    try:
        with caplog.at_level("DEBUG", logger="tagbot.plotter.stream"):
            port.write(b"G4P0\n")  # another program's line
            for _ in range(3):  # its ok arrives during one of these waits
                streamer.query_state()
    finally:
        port.close()
    logged = [r.getMessage() for r in caplog.records if r.name == "tagbot.plotter.stream"]
    assert "grbl: Ok()" in logged


def test_the_planner_size_comes_from_the_build_options():
    """``$I`` says ``[OPT:VN,14,128]`` on the line-numbered build: 14 planner blocks, not the
    stock 15; the stock build says 15."""
    port, streamer, _ = connected(SimulatedGrbl(SETTINGS, pen_servo=(30, 50), line_numbers=True))
    port.close()
    assert streamer.blocks == 14
    port, streamer, _ = connected(SimulatedGrbl(SETTINGS, pen_servo=(30, 50)))
    port.close()
    assert streamer.blocks == 15


def test_a_resume_without_a_hold_is_no_pause():
    """``resume()`` asked during a job that was never held: nothing to end, no pause span."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    lines = square_program(40)
    wire.at[len(wire.lines_sent()) + 10] = streamer.resume
    try:
        report = streamer.stream(lines)
    finally:
        port.close()
    assert b"~" in wire.tx
    assert report.pause_spans == [] and report.pauses == 0 and report.paused_s == 0.0


def _held(holds: tuple[int, ...], resumes: tuple[int, ...], lines: int):
    """Stream a square of ``lines`` lines, calling ``hold()`` as each line of ``holds`` (counted
    from the first of the job) is sent, and ``resume()`` at each count in ``resumes`` of
    status polls sent while held: the report, the wire, and when each ``!`` or ``~`` left."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port = open_device(device)
    wire = Wire()
    asked: list[float] = []
    polls_held = 0

    def trace(direction: str, data: bytes) -> None:
        nonlocal polls_held
        wire(direction, data)
        if direction != "tx":
            return
        if data in (b"!", b"~"):
            asked.append(streamer.clock.now())
        elif data == b"?" and wire.tx.count(b"!") > wire.tx.count(b"~"):
            polls_held += 1
            if polls_held in resumes:
                streamer.resume()

    streamer = GrblStreamer(port, StreamOptions(), trace=trace)
    streamer.connect()
    base = len(wire.lines_sent())
    for line in holds:
        wire.at[base + line] = streamer.hold
    try:
        report = streamer.stream(square_program(lines))
    finally:
        port.close()
    return report, wire, asked


def test_a_second_hold_while_held_does_not_end_the_pause():
    """Two ``hold()`` calls, then one ``resume()``: one pause, from the first hold to the
    resume, and the held machine is never taken for someone else's hold."""
    report, wire, _ = _held((20, 21), (10,), 200)  # resumed about 2 s after
    assert wire.tx.count(b"!") == 2 and wire.tx.count(b"~") == 1
    assert report.outside_holds == 0
    assert not any("not asked for" in w for w in report.warnings)
    assert report.pauses == 1 and 1.5 < report.paused_s < 2.5


def test_a_second_hold_after_a_resume_is_a_pause_of_its_own():
    """Hold, resume, hold again, resume: two pauses, each from its own ``!`` to its own ``~``
    (the second is not measured from the first hold)."""
    report, wire, asked = _held((20, 120), (10, 15), 300)  # held about 2 s, then about 1 s
    assert [d for d in wire.tx if d in (b"!", b"~")] == [b"!", b"~", b"!", b"~"]
    hold1, resume1, hold2, resume2 = asked
    assert report.pause_spans == [
        (hold1, pytest.approx(resume1 - hold1)),
        (hold2, pytest.approx(resume2 - hold2)),
    ]
    assert 0.5 < resume2 - hold2 < 1.5 < hold2 - hold1
    assert report.outside_holds == 0 and report.pauses == 2


def test_a_host_stall_before_the_second_drawing_line_is_named():
    """One line at a time (``mode="wait"``): the host stands still 0.5 s after sending the
    first of two pen-down lines of one run; the report names a host stall before line 2."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device, mode="wait")
    lines = ["G1X10Y0F600\n", "G1X20Y0F600\n", "G1X30Y0F600\n"]
    wire.at[len(wire.lines_sent()) + 1] = lambda: device.advance(0.5)  # descheduled
    try:
        report = streamer.stream(lines, drawing=[True, True, True])
    finally:
        port.close()
    stalls = [w for w in report.warnings if w.startswith("host stall")]
    assert len(stalls) == 1 and "before line 2," in stalls[0]
    assert len(report.stall_spans) == 1 and report.stall_spans[0][1] >= 0.5


def test_a_safe_stop_without_an_alarm_holds_resets_and_lifts_the_pen():
    """``safe_stop(pen_up)`` called by itself (no alarm): feed hold, soft reset, then the
    pen-up lines are sent, after the reset."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    before = len(wire.tx)
    try:
        streamer.safe_stop(PEN_UP)
    finally:
        port.close()
    tx = wire.tx[before:]
    assert tx[0] == b"!"
    reset = tx.index(b"\x18")
    assert [d for d in tx[reset:] if d.endswith(b"\n")] == [b"M3S50\n", b"G4P0.1\n"]


def test_a_streamer_that_saw_no_status_asks_where_the_machine_is_before_the_job():
    """A streamer used without :meth:`connect` (its banner already read by the caller) has no
    status yet: it asks for one before the first line, so the job starts where the machine is
    (here 0,20), not at an assumed origin, and runs to its end."""
    device = SimulatedGrbl(SETTINGS, position_mm=(0.0, 20.0, 0.0))
    device.read()  # the boot banner, taken by whoever opened the port
    port = open_device(device)
    wire = Wire()
    streamer = GrblStreamer(port, StreamOptions(), trace=wire)
    lines = ["G1X20Y20F600\n", "G1X20Y0F600\n"]
    try:
        assert streamer.state is None
        report = streamer.stream(lines)
    finally:
        port.close()
    assert wire.tx[0] == b"?" and wire.tx.index(lines[0].encode()) > 0
    (_, first), *_ = report.statuses
    assert first.mpos[1] == 20.0 and 0.0 <= first.mpos[0] < 1.0  # setting out from (0, 20)
    assert report.lines_executed == 2 and report.errors == []


def test_a_status_with_no_position_is_refused_before_the_job():
    """A controller whose status report carries neither MPos nor WPos (not Grbl 1.1): the job
    is refused before its first line, since no line could be traced to where it ran."""
    device = SimulatedGrbl(SETTINGS)
    device.read()
    port = open_device(device)
    wire = Wire()
    streamer = GrblStreamer(port, StreamOptions(), trace=wire)
    streamer.state = parse_message("<Idle|FS:0,0>")
    try:
        with pytest.raises(DeviceFault, match=r"gives no machine position \(MPos or WPos\)"):
            streamer.stream(["G1X20Y20F600\n"])
    finally:
        port.close()
    assert wire.tx == []


def test_an_alarm_during_a_command_names_the_command():
    """``ALARM:N`` before a command's ``ok`` (here during a one-second dwell) is a fault named
    after that command, as ``error:N`` is: the operator sees which line the machine refused."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, _ = connected(device)
    try:
        device.schedule_alarm(device.now + 0.2, 3)
        with pytest.raises(DeviceFault) as caught:
            streamer.command("G4P1")
    finally:
        port.close()
    assert caught.value.where == "'G4P1'"
    assert str(caught.value).startswith("'G4P1': ALARM:3 (")


def test_a_build_naming_no_planner_blocks_keeps_the_stock_planner():
    """``[OPT:V,0,128]`` (a build that reports no planner) is not believed: the streamer keeps
    Grbl's stock 15 blocks rather than plan for none."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    device.executor.planner.capacity = 0
    port, streamer, wire = connected(device)
    port.close()
    assert b"[OPT:V,0,128]\r\n" in b"".join(wire.rx)
    assert streamer.blocks == 15


def test_resuming_after_a_line_grbl_cannot_parse_names_it():
    """A line before the resume point that Grbl's parser rejects outright (a letter it has no
    word for) is named with Grbl's own error code, as a refused move is."""
    lines = ["G21\n", "G1X1Q2F100\n", "G1X2Y2F100\n", "G1X3Y3\n"]
    with pytest.raises(ValueError, match=r"^line 2: Grbl would refuse it \(error:20\)$"):
        resume_lines(lines, 3, PEN_UP, [])


def test_the_report_counts_every_byte_the_job_wrote():
    """``bytes_sent``: the job's lines and its real-time bytes (status polls), all of them, as
    they went out on the wire."""
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    before = len(wire.tx)
    try:
        report = streamer.stream(square_program(200))
    finally:
        port.close()
    written = wire.tx[before:]
    assert b"?" in written and report.bytes_sent == sum(len(d) for d in written) > 200 * 20


def test_resuming_a_feed_per_minute_program_adds_no_feed_mode_line():
    """A program in G94 throughout: the preamble sets G94 once, up front, and ends with the
    travel to the resume point (no second feed mode line after it)."""
    lines = ["G21\n", "G90\n", "G94\n", "G1X1Y1F100\n", "G1X2Y2F100\n"]
    assert resume_lines(lines, 4, PEN_UP, []) == [
        "G21\n", "G90\n", "G94\n", *PEN_UP, "G0X1Y1\n"
    ]  # fmt: skip


def test_a_stop_inside_a_line_one_mm_long_resumes_inside_it():
    """A 1 mm inverse-time line stopped at its middle resumes there, at the same speed (the
    remaining half in half the time: F doubles)."""
    lines = ["G21\n", "G90\n", "G93\n", "G1X10Y0F60\n", "G1X11Y0F60\n", "G1X20Y0F60\n"]
    assert resume_point(lines, 4, (10.5, 0.0)) == ("G1X11Y0F120\n", (10.5, 0.0))


@pytest.mark.parametrize(("policy", "where"), [("unlock", (30.0, 40.0)), ("home", (0.0, 0.0))])
def test_after_an_unlock_or_homing_at_connect_the_streamer_knows_the_new_state(policy, where):
    """A machine locked at power-up at (30, 40): once ``$X`` or ``$H`` is done, the streamer's
    last status is asked afresh, Idle and where that left the machine (homing moves it to the
    origin), not the Alarm seen before it."""
    device = SimulatedGrbl({**SETTINGS, 22: 1}, start_in_alarm=True, position_mm=(30.0, 40.0, 0.0))
    port = open_device(device)
    streamer = GrblStreamer(port, StreamOptions(unlock=policy))
    try:
        streamer.connect()
    finally:
        port.close()
    assert streamer.state.state == State.IDLE
    assert streamer.state.mpos[:2] == where
