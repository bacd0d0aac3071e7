"""The AxiDraw's resume point, as ``tagbot draw`` users meet it: the report's ``resume_from`` is
always a move ``--resume-from`` takes, or none when there is nothing to resume (as on the Grbl
plotter and the arms: a job stopped before any of it ran is drawn again as it is)."""

from __future__ import annotations

import json
import os
from dataclasses import replace
from itertools import count
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import serial

from firmware_protocols.ebb.motion import TICK_HZ, Move, execute
from sim.ebb.device import SimulatedEBB
from sim.ebb.transport import attach_device
from tagbot.axidraw.machine import AxiDrawJob, prepare, resume_point
from tagbot.axidraw.moves import Entry, Job, _travel_moves
from tagbot.axidraw.profile import load_profile
from tagbot.axidraw.stream import EBBStreamer, StreamReport
from tagbot.cli import main
from tagbot.draw import draw
from tagbot.errors import InputError, Interrupted
from tagbot.io.planfile import load_plan

from .conftest import LETTER_B

_names = count()


def _url(device: SimulatedEBB) -> str:
    return attach_device(device, f"a3resume{os.getpid()}_{next(_names)}")


def _draw(url: str, out: Path, *more: str) -> dict:
    """``tagbot draw letter-b --device axidraw --port url``: its exit status and report."""
    args = ["draw", str(LETTER_B), "--device", "axidraw", "--port", url, "--out", str(out)]
    code = main([*args, "--quiet", "--no-pictures", *more])
    report = json.loads((out / "report.json").read_text())
    return {"code": code, **report}


def test_a_fault_before_the_first_move_leaves_nothing_to_resume(tmp_path, capsys):
    """The board resets while the pen lifts before the first move: nothing of the job ran, so
    the report names no resume point, ``--resume-from 1`` is refused before anything is sent,
    and the same command without it draws the whole job."""
    device = SimulatedEBB()
    device.reset_board(0.08)  # after connecting, during the first pen lift (0.011-0.174 s)
    url = _url(device)
    stopped = _draw(url, tmp_path / "a")
    assert stopped["code"] != 0 and not stopped["completed"]
    assert stopped["executed"] == 0 and stopped["sent"] == 0
    assert stopped["resume_from"] is None
    before = len(device.recorder.segments)
    args = ["draw", str(LETTER_B), "--device", "axidraw", "--port", url, "--out", str(tmp_path)]
    code = main([*args, "--quiet", "--resume-from", "1", "--position-known"])
    assert code == 2
    assert "'--resume-from': 1 is not in the range x>=2" in capsys.readouterr().err
    assert len(device.recorder.segments) == before  # refused before the first byte
    again = _draw(_url(device), tmp_path / "c")  # the board's USB is back
    assert again["code"] == 0 and again["completed"]
    assert again["executed"] == again["total"] == stopped["total"]


def test_a_stop_mid_job_names_a_move_the_cli_resumes_from(tmp_path):
    """Ctrl-C's stand-in, a USB stall past the reply timeout in the middle of the job: the
    report's ``resume_from`` is a move ``--resume-from`` takes, and the resumed run ends the
    job."""
    device = SimulatedEBB()
    device.stall_usb(6.0, 3.0)
    stopped = _draw(_url(device), tmp_path / "a")
    assert stopped["code"] != 0 and 0 < stopped["executed"] < stopped["total"]
    resume = stopped["resume_from"]
    assert resume in (stopped["executed"] + 1, stopped["executed"] + 2)
    again = _url(device)  # the same board, its port opened again
    resumed = _draw(again, tmp_path / "b", "--resume-from", str(resume), "--position-known")
    assert resumed["code"] == 0 and resumed["completed"]
    assert resumed["executed"] == resumed["total"]


def test_every_resume_point_is_one_prepare_takes():
    """Over every stop a job can have (moves done, the next one cut short or not), the resume
    point is None or a move ``prepare`` accepts; None only when nothing ran or nothing is left.
    ``prepare`` is asked at the edges: moves 1, 2, the last and one past it."""
    tag = load_plan(LETTER_B)
    job = prepare(tag)
    total = len(job.job.entries)
    accepted = {}
    for move in (1, 2, total, total + 1):
        try:
            accepted[move] = prepare(tag, resume_from=move).resume_from == move
        except InputError:
            accepted[move] = False
    assert accepted == {1: False, 2: True, total: True, total + 1: False}
    for done in range(total + 1):
        for partial in (0, 1) if done < total else (0,):
            move = resume_point(job.job, done, partial)
            if move is None:
                assert done + partial == 0 or done + partial >= total
            else:
                assert move == done + 1 + partial and 2 <= move <= total


def test_a_stop_in_the_last_move_leaves_nothing_to_resume():
    """The park travel cut short: every move that draws ran, and the report names no resume
    point beyond the job's end (``--resume-from`` would refuse it)."""
    job = prepare(load_plan(LETTER_B))
    entries = job.job.entries
    assert entries[-1].kind == "travel"
    total = len(entries)
    middle = job.job.ticks[-20]  # 20 ticks before the park's end
    report = StreamReport(first=0, sent=total, executed=total - 1, stopped_at=tuple(middle))
    assert job._executed_moves(report) == (total - 1, 1)
    assert resume_point(job.job, total - 1, 1) is None


def test_a_stop_during_the_first_travel_says_the_motors_had_left_home(tmp_path):
    """Ctrl-C at the first progress call, while move 1 (the travel from home) runs: the error
    names move 1 as cut short, not "nothing executed", and the resume point skips it."""
    tag = load_plan(LETTER_B)
    job = prepare(tag)

    def progress(done: int, total: int) -> None:
        raise KeyboardInterrupt

    with pytest.raises(Interrupted, match=r"^during move 1 of \d+ \(moves.txt; cut short\)"):
        draw(tag, tmp_path / "r", prepared=job, pictures=False, progress=progress)
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["executed"] == 0 and report["resume_from"] == 2
    assert report["details"]["stopped_at_steps"] != [0, 0]


def test_a_resume_lifts_the_pen_travels_pen_up_and_lowers_it_where_the_move_starts(tmp_path):
    """``--resume-from`` the last drawing move of letter-b's run, on a board at home: before
    any motor turns the board gets the job's own pen lift (its servo time as the command's
    delay, so the travel waits for it), the travel (``LM`` only) ends where the move before
    it ended, the pen goes down there, then the job's lines from that move on."""
    job = prepare(load_plan(LETTER_B))
    entries = job.job.entries
    last = max(i for i, e in enumerate(entries) if e.kind == "draw")
    assert entries[last - 1].kind == "draw" and entries[last - 1].pen
    up, down = (next(e.line.rstrip(b"\r") for e in entries if e.kind == "pen" and e.pen == d)
                for d in (False, True))  # fmt: skip
    device = SimulatedEBB()
    run = replace(job, port=_url(device), resume_from=last + 1).run(tmp_path)
    assert run.error is None and run.executed_steps == len(entries)
    done = [s for s in device.recorder.segments if s.kind != "enable"]
    assert done[0].kind == "servo" and done[0].line == up
    lowered = next(i for i, s in enumerate(done) if s.line == down)
    travel = done[1:lowered]
    assert travel and all(s.line.startswith(b"LM,") for s in travel)
    assert tuple(travel[-1].positions()[-1]) == entries[last - 1].steps
    assert [s.line for s in done[lowered + 1 :]] == [e.line.rstrip(b"\r") for e in entries[last:]]
    # The travel ran with the pen all the way up (it starts once the lift has ended).
    assert travel[0].load_tick >= done[0].load_tick + done[0].ticks
    during = np.arange(travel[0].load_tick, travel[-1].end_tick) / 25_000
    assert np.all(device.recorder.pen_at(during) == device.recorder.pen_at(during[:1]))


def test_a_stop_off_the_plan_during_a_one_tick_first_move_counts_it_cut_short():
    """A job whose first motion (move 2, after the pen goes down where the motors are) lasts a
    single tick, resumed from it: the board, its accumulators left by the resume's travel,
    took a step in that tick where the plan took none, and stopped there, off the plan's tick
    record. The move counts as cut short, as any started move does, and the resume point
    skips it (move 3); motors where the plan's tick left them (no step: the same place) count
    it executed, and the resume point is move 3 again."""
    half = 2**30  # motor 2: half a step a tick (motor 1: just under one)
    specs = [("pen", None), ("draw", 1), ("draw", 4), ("draw", 4)]
    entries, parts, here, accumulators, time = [], [], (0, 0), (0, 0), 0.0
    for kind, ticks in specs:
        move = None
        if ticks is not None:
            move = Move(command="LT", rate=(2**31 - 1, half), ticks=ticks)
            relative, accumulators = execute(move, accumulators)
            parts.append(relative + np.asarray(here))
            here = tuple(int(v) for v in parts[-1][-1])
        duration = ticks / TICK_HZ if ticks else 0.1
        line = move.line() if move else b"SP,0,100,1\r"
        entries.append(Entry(kind, line, time, duration, 0, here, True, move))
        time += duration
    ticks = np.concatenate(parts)
    job = Job(entries, [], [], ticks, np.arange(1, len(ticks) + 1) / TICK_HZ,
              np.zeros(len(entries)), [], 80.0)  # fmt: skip
    machine = SimpleNamespace(job=job)
    off = (1, 0)  # a step from where move 2 ends on the plan (its one tick takes none)
    assert not (ticks == np.asarray(off)).all(axis=1).any()
    report = StreamReport(first=1, sent=3, executed=1, stopped_at=off)
    assert AxiDrawJob._executed_moves(machine, report) == (1, 1)
    assert entries[1].steps == (0, 0) and resume_point(job, 1, 1) == 3
    report = StreamReport(first=1, sent=3, executed=1, stopped_at=(0, 0))
    assert AxiDrawJob._executed_moves(machine, report) == (2, 0)
    assert resume_point(job, 2, 0) == 3


def test_a_new_job_counts_steps_from_where_the_motors_stand_and_a_resume_keeps_the_count():
    """A board whose motors a stopped job left away from home (its counters at 1500, -700): a
    new job (no ``--resume-from``) counts its steps from where they stand (``EM`` zeroes the
    counters there); a resume (``keep_position``) goes on counting from the old job's home."""
    profile = load_profile()
    for keep, expected in ((False, (0, 0)), (True, (1500, -700))):
        device = SimulatedEBB()
        link = serial.serial_for_url(_url(device), timeout=0.01)
        first = EBBStreamer(link, profile, {})
        first.connect()
        for move in _travel_moves((1500, -700), profile):
            first.ask(move.line())
        first._drain(first.clock.now())
        assert first.position() == (1500, -700)
        link.close()
        link = serial.serial_for_url(_url(device), timeout=0.01)
        streamer = EBBStreamer(link, profile, {})
        streamer.connect(keep_position=keep)
        assert streamer.position() == expected
        link.close()
        assert device.motor_position() == (1500, -700)  # the motors never moved
