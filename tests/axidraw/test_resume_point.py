"""The AxiDraw's resume point, as ``tagbot draw`` users meet it: the report's ``resume_from`` is
always a move ``--resume-from`` takes, or none when there is nothing to resume (as on the Grbl
plotter and the arms: a job stopped before any of it ran is drawn again as it is)."""

from __future__ import annotations

import json
import os
from itertools import count
from pathlib import Path

import pytest

from sim.ebb.device import SimulatedEBB
from sim.ebb.transport import attach_device
from tagbot.axidraw.machine import prepare, resume_point
from tagbot.axidraw.stream import StreamReport
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
