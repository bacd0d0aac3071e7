"""The command line: output format, help, and one-line errors with the documented exit codes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import tagbot.io.planfile
from tagbot.cli import main
from tagbot.io.motionfile import HEADER, read_motion_csv

ROOT = Path(__file__).resolve().parents[1]
CAE = ROOT / "tagbot" / "examples" / "cae.json"
LETTER_B = ROOT / "tagbot" / "examples" / "letter-b.json"


def run(capsys: pytest.CaptureFixture[str], *args: str | os.PathLike[str]) -> tuple[int, str, str]:
    code = main([os.fspath(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(err: str, *fragments: str) -> None:
    assert err.startswith("tagbot: error: "), err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in err, (fragment, err)


# --------------------------------------------------------------------------- help and version


@pytest.mark.parametrize("args", [[], ["--help"], ["-h"], ["sample", "--help"], ["sample", "-h"]])
def test_help_exits_zero(capsys: pytest.CaptureFixture[str], args: list[str]) -> None:
    code, out, err = run(capsys, *args)
    assert (code, err) == (0, "")
    assert out.startswith("Usage: tagbot")
    assert "sample" in out


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "--version")
    assert code == 0
    assert out.startswith("tagbot ")


# --------------------------------------------------------------------------- sample


def test_sample_writes_csv_to_stdout(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(capsys, "sample", CAE)
    assert (code, err) == (0, "")
    lines = out.splitlines()
    assert lines[0] == HEADER
    assert len(lines) > 100
    assert {line.rsplit(",", 1)[1] for line in lines[1:]} == {"0", "1"}


def test_sample_dash_means_stdout(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "sample", LETTER_B, "-o", "-")
    assert code == 0
    assert out.splitlines()[0] == HEADER


def test_sample_to_file_prints_summary(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    path = tmp_path / "motion.csv"
    code, out, err = run(capsys, "sample", CAE, "--dt", "0.02", "-o", path)
    assert (code, out) == (0, "")
    motion = read_motion_csv(path)
    assert err == (
        f"wrote {len(motion)} samples ({motion.t[-1] - motion.t[0]:.2f} s, 3 plans) to {path}\n"
    )
    assert np.allclose(np.diff(motion.t), 0.02)
    assert set(np.unique(motion.pen)) == {0, 1}
    assert np.allclose(motion.speed, np.hypot(motion.v[:, 0], motion.v[:, 1]), atol=1e-6)


def test_sample_summary_says_plan_for_one_plan(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code, _, err = run(capsys, "sample", LETTER_B, "--output", tmp_path / "b.csv")
    assert code == 0
    assert ", 1 plan) to " in err


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize("dt", ["0", "-1", "nan", "abc", "inf", "-0", ""])
def test_bad_dt_is_a_usage_error(capsys: pytest.CaptureFixture[str], dt: str) -> None:
    code, out, err = run(capsys, "sample", CAE, "--dt", dt)
    assert (code, out) == (2, "")
    assert_one_line_error(err, "--dt")


@pytest.mark.parametrize(
    "args",
    [
        ["sample"],  # missing argument
        ["sample", str(CAE), "--bogus"],
        ["sample", str(CAE), "--dt"],  # option without value
        ["bogus"],
        ["--bogus"],
        ["sample", str(CAE), str(CAE)],  # extra argument
    ],
)
def test_usage_errors(capsys: pytest.CaptureFixture[str], args: list[str]) -> None:
    code, out, err = run(capsys, *args)
    assert (code, out) == (2, "")
    assert_one_line_error(err, "--help")


def test_missing_plan_file(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    path = tmp_path / "nowhere.json"
    code, out, err = run(capsys, "sample", path)
    assert (code, out) == (2, "")
    assert_one_line_error(err, str(path))


def test_plan_that_is_not_json(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    path = tmp_path / "tag.json"
    path.write_text("{\n  oops\n}\n", encoding="utf-8")
    code, out, err = run(capsys, "sample", path)
    assert (code, out) == (2, "")
    assert_one_line_error(err, str(path), "not JSON (line 2, column 3")


def test_invalid_plan_field(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    doc = json.loads(CAE.read_text(encoding="utf-8"))
    doc["plans"][2]["strokes"][1]["sigma"] = -0.5
    path = tmp_path / "tag.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    code, out, err = run(capsys, "sample", path)
    assert (code, out) == (2, "")
    assert_one_line_error(err, f"{path}: plans[2].strokes[1].sigma: must be > 0")


def test_unwritable_output_names_the_path(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "missing-dir" / "motion.csv"
    code, out, err = run(capsys, "sample", CAE, "-o", path)
    assert (code, out) == (2, "")
    assert_one_line_error(err, str(path))


def test_interrupt_exits_130(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch):
    def interrupted(path: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(tagbot.io.planfile, "load_plan", interrupted)
    code, out, err = run(capsys, "sample", CAE)
    assert (code, out) == (130, "")
    assert_one_line_error(err, "interrupted")


def test_unexpected_errors_propagate(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def broken(path: object) -> None:
        raise RuntimeError("a bug")

    monkeypatch.setattr(tagbot.io.planfile, "load_plan", broken)
    with pytest.raises(RuntimeError, match="a bug"):
        main(["sample", str(CAE)])


# --------------------------------------------------------------------------- a real process


def python_m_tagbot(*args: str | os.PathLike[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "tagbot", *map(os.fspath, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_python_m_tagbot_sample() -> None:
    proc = python_m_tagbot("sample", CAE, "--dt", "0.05")
    assert (proc.returncode, proc.stderr) == (0, "")
    assert proc.stdout.splitlines()[0] == "t,x,y,vx,vy,speed,pen"


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["sample", "no/such/plan.json"], "no/such/plan.json"),
        (["sample", CAE, "--dt", "0"], "--dt"),
        (["sample", CAE, "--dt", "nan"], "--dt"),
    ],
)
def test_python_m_tagbot_errors_are_one_line(args: list[str], fragment: str) -> None:
    proc = python_m_tagbot(*args)
    assert (proc.returncode, proc.stdout) == (2, "")
    assert_one_line_error(proc.stderr, fragment)


def test_fit_times_the_whole_command_from_process_start():
    """The time tagbot fit prints counts the interpreter's start-up and imports, not only the
    fit: in a process that idled 0.3 s before asking, it is at least that."""
    import subprocess
    import sys

    code = (
        "import time; time.sleep(0.3); from tagbot.cli import _since_start;"
        " print(_since_start(0.0))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert float(out.stdout) >= 0.3


def test_every_modules_warnings_are_one_tagbot_line_each(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A machine's, the studio's and the fit's log records print as ``tagbot: warning:`` (or
    ``error:``) lines, once each (not again through the root logger's handlers, e.g. a progress
    bar's), an exception by its message without a traceback; the logging set-up is restored."""
    import logging

    import tagbot.cli

    seen: list[logging.LogRecord] = []

    class Root(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            seen.append(record)

    def command(args: list[str]) -> int:
        logging.getLogger("tagbot.arm.run").warning("run 2 (plan 1): path deviation %s", "0.4 mm")
        logging.getLogger("tagbot.fit").warning("tag.gml: trace 3: scaled\n(the clock)")
        logging.getLogger("tagbot.arm.driver").info("opened the port")  # below a warning
        try:
            raise OSError("the port is gone")
        except OSError:
            logging.getLogger("tagbot.studio.server").exception("studio: draw failed")
        return 0

    root = Root()
    logging.getLogger().addHandler(root)
    monkeypatch.setattr(tagbot.cli, "_main", command)
    try:
        assert main([]) == 0
    finally:
        logging.getLogger().removeHandler(root)
    assert capsys.readouterr().err.splitlines() == [
        "tagbot: warning: run 2 (plan 1): path deviation 0.4 mm",
        "tagbot: warning: tag.gml: trace 3: scaled (the clock)",
        "tagbot: error: studio: draw failed: the port is gone",
    ]
    assert seen == []  # nothing repeated by the root logger's handlers
    package = logging.getLogger("tagbot")
    assert package.propagate and package.handlers == []
