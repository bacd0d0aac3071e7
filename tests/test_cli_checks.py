"""Commands fail before the work, name the user's file, and never leave junk or hang."""

from __future__ import annotations

import json
import os
import threading
import time
from importlib import resources
from pathlib import Path

import pytest

import tagbot
import tagbot.gesture
from tagbot.cli import MAX_VARIATIONS, main

EXAMPLES = resources.files("tagbot") / "examples"
TRACES = str(EXAMPLES / "dusttag-142.json")
PLAN = str(EXAMPLES / "cae.json")


def run(capsys, *args: str) -> tuple[int, str]:
    code = main(list(args))
    return code, capsys.readouterr().err


def one_line(err: str) -> str:
    assert err.startswith("tagbot: error: ") and err.count("\n") == 1, err
    return err


@pytest.mark.parametrize("command", ["fit", "gcode", "render", "plot"])
def test_a_missing_output_folder_fails_before_any_work(command, tmp_path, capsys, monkeypatch):
    def no_fit(*args, **kwargs):
        raise AssertionError("the work started")

    monkeypatch.setattr(tagbot.gesture, "fit", no_fit)
    target = tmp_path / "missing" / ("out.png" if command in ("render", "plot") else "out.json")
    code, err = run(capsys, command, TRACES, "-o", str(target))
    assert code == 2
    assert f"{target}: the folder {target.parent} does not exist" in one_line(err)
    assert not any(tmp_path.rglob("*.tmp"))


def test_plan_errors_name_the_file_in_every_command(tmp_path, capsys):
    document = json.loads(Path(PLAN).read_text())
    document["plans"][0]["strokes"][0]["sigma"] = -0.3
    bad = tmp_path / "negsigma.json"
    bad.write_text(json.dumps(document))
    for args in (["render", str(bad), "-o", str(tmp_path / "x.png")], ["sample", str(bad)]):
        code, err = run(capsys, *args)
        assert code == 2
        assert f"{bad}: plans[0].strokes[0].sigma: must be > 0, got -0.3" in one_line(err)


def test_vary_refuses_to_overwrite_without_force(tmp_path, capsys):
    out = tmp_path / "v"
    assert run(capsys, "vary", PLAN, "-n", "3", "--seed", "1", "-o", str(out))[0] == 0
    first = (out / "cae-1.json").read_bytes()
    code, err = run(capsys, "vary", PLAN, "-n", "3", "--seed", "2", "-o", str(out))
    assert code == 2 and "cae-1.json: exists and 2 more (--force replaces them)" in one_line(err)
    assert (out / "cae-1.json").read_bytes() == first
    assert run(capsys, "vary", PLAN, "-n", "3", "--seed", "2", "-o", str(out), "--force")[0] == 0
    assert (out / "cae-1.json").read_bytes() != first


def test_vary_refuses_a_count_above_its_limit_before_reading(tmp_path, capsys):
    code, err = run(capsys, "vary", PLAN, "-n", str(MAX_VARIATIONS + 1), "-o", str(tmp_path / "v"))
    assert code == 2 and "more than 1000000" in one_line(err)
    assert not (tmp_path / "v").exists()


def test_vary_streams_the_same_plans_as_the_api(tmp_path, capsys):
    out = tmp_path / "v"
    assert run(capsys, "vary", PLAN, "-n", "4", "--seed", "9", "-o", str(out))[0] == 0
    expected = tagbot.vary(tagbot.load_plan(PLAN), 4, seed=9)
    for i, tag in enumerate(expected, start=1):
        saved = tagbot.load_plan(out / f"cae-{i}.json")
        assert [p.targets.tolist() for p in saved.plans] == [p.targets.tolist() for p in tag.plans]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_a_fifo_is_refused_at_once(tmp_path, capsys):
    fifo = tmp_path / "pipe.gml"
    os.mkfifo(fifo)
    outcome: list[tuple[int, str]] = []
    worker = threading.Thread(target=lambda: outcome.append(run(capsys, "fit", str(fifo))))
    started = time.monotonic()
    worker.start()
    worker.join(timeout=20)
    if worker.is_alive():  # unblock the reader so the test ends, then fail
        with open(fifo, "wb"):
            pass
        worker.join()
        pytest.fail("reading a FIFO hung")
    assert time.monotonic() - started < 20
    code, err = outcome[0]
    assert code == 2 and f"{fifo}: not a regular file (a FIFO)" in one_line(err)


def test_fit_prints_the_whole_commands_time_and_can_skip_the_report(tmp_path, capsys):
    code, err = run(capsys, "fit", TRACES, "-o", str(tmp_path / "a.json"))
    assert code == 0 and "shape error mean" in err and "(load " in err and ", report " in err
    code, err = run(capsys, "fit", TRACES, "-o", str(tmp_path / "b.json"), "--no-report")
    assert code == 0 and "shape error" not in err and "report" not in err
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()


def test_drawing_a_timed_capture_compares_with_the_recording(tmp_path, capsys):
    out = tmp_path / "run"
    code, err = run(capsys, "draw", TRACES, "--out", str(out), "--no-pictures")
    assert code == 0 and "speed against the recording" in err
    report = json.loads((out / "report.json").read_text())
    assert report["recorded_speed_snr_db"] > 10  # the writer's rhythm, up to the run's scale


def test_a_plan_drawn_with_its_recording_is_compared_with_it(tmp_path, capsys):
    plan = tmp_path / "plan.json"
    assert run(capsys, "fit", TRACES, "-o", str(plan), "--no-report")[0] == 0
    out = tmp_path / "run"
    code, err = run(
        capsys, "draw", str(plan), "--recording", TRACES, "--out", str(out), "--no-pictures"
    )
    assert code == 0 and "speed against the recording" in err
    assert json.loads((out / "report.json").read_text())["recorded_speed_snr_db"] > 10


def test_a_recording_that_does_not_match_the_plan_is_refused_before_drawing(tmp_path, capsys):
    other = tmp_path / "points.csv"
    other.write_text("0,0\n10,0\n10,10\n")
    out = tmp_path / "run"
    code, err = run(capsys, "draw", TRACES, "--recording", str(other), "--out", str(out))
    assert code == 2 and f"{other}: has 1 trace for a tag of" in one_line(err)
    assert not out.exists()
