"""Everything is checked before anything starts; Ctrl-C and faults say where the machine stopped."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from sim.grbl import SimulatedGrbl
from sim.grbl.transport import attach_device
from tagbot.cli import main
from tagbot.errors import PortError
from tagbot.plotter import load_profile
from tagbot.plotter.profile import device_settings
from tagbot.ports import check_port

ROOT = Path(__file__).resolve().parents[1]
LETTER_B = ROOT / "tagbot" / "examples" / "letter-b.json"


def test_port_names_are_checked_without_opening_them(tmp_path):
    master, slave = os.openpty()
    try:
        assert check_port(os.ttyname(slave)) == os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)
    plain = tmp_path / "file"
    plain.write_text("")
    cases = {
        "/dev/nonexistent": "no such device",
        str(tmp_path): "is a directory",
        "/dev/null": "not a serial port",
        str(plain): "not a serial port",
        "ftp://host": "unknown URL scheme 'ftp'",
    }
    for port, message in cases.items():
        with pytest.raises(PortError, match=message):
            check_port(port)
    assert check_port("grblsim://anything") == "grblsim://anything"
    assert check_port("socket://localhost:7777") == "socket://localhost:7777"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--port", "/dev/nonexistent"], "--port /dev/nonexistent: no such device"),
        (["--port", "/dev/null"], "--port /dev/null: not a serial port"),
        (["--set", "place.scale=1000"], "placement: the drawing reaches"),
        (["--set", "bed.margin=-1"], "bed.margin"),
        (["--device", "dynamixel", "--set", "place.scale=1000"], "place"),
    ],
)
def test_refusals_come_before_the_run_folder_and_the_first_byte(tmp_path, capsys, args, message):
    out = tmp_path / "run"
    code = main(["draw", str(LETTER_B), "--out", str(out), *args])
    _, err = capsys.readouterr()
    assert code == 2, err
    assert not out.exists()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tagbot: error: ") and message in lines[0]
    assert f"drawing {LETTER_B}" not in err and "Traceback" not in err


# Early in letter-b's program (under 300 lines), so the interrupt always falls mid-job.
CTRL_C_AT = 120


class _CtrlC(SimulatedGrbl):
    """A simulated Grbl whose host is interrupted (Ctrl-C) while sending line ``at``."""

    def __init__(self, at: int, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)
        self.at = at

    def write(self, data: bytes) -> int:
        if self.at and self.lines_received >= self.at:
            self.at = 0
            raise KeyboardInterrupt
        return super().write(data)


def test_ctrl_c_names_the_last_executed_line_and_keeps_the_run_folder(tmp_path, capsys):
    profile = load_profile()
    device = _CtrlC(CTRL_C_AT, {**device_settings(profile), 10: 3}, pen_servo=(30, 50))
    url = attach_device(device, "checks_ctrl_c")
    out = tmp_path / "run"
    code = main(["draw", str(LETTER_B), "--port", url, "--out", str(out), "--no-pictures"])
    _, err = capsys.readouterr()
    assert code == 130
    last = err.strip().splitlines()[-1]
    report = json.loads((out / "report.json").read_text())
    done = report["executed"]
    assert 0 < done < report["sent"]
    assert last == (
        f"tagbot: error: after line {done} (the last line the machine executed; resume with "
        f"--resume-from {done + 1} --position-known): interrupted (Ctrl-C)"
    )
    assert report["resume_from"] == done + 1 and report["completed"] is False
    for name in ("plan.json", "motion.csv", "program.gcode", "executed.csv"):
        assert (out / name).is_file(), name


def test_a_resumed_job_reports_against_what_was_left_to_draw(tmp_path):
    profile = load_profile()
    device = _CtrlC(CTRL_C_AT, {**device_settings(profile), 10: 3}, pen_servo=(30, 50))
    url = attach_device(device, "checks_resume")
    code = main(["draw", str(LETTER_B), "--port", url, "--out", str(tmp_path / "a"), "-q"])
    assert code == 130
    resume = json.loads((tmp_path / "a" / "report.json").read_text())["resume_from"]
    args = ["--resume-from", str(resume), "--position-known", "--no-pictures", "-q"]
    url = attach_device(device, "checks_resume_again")  # the same machine, opened again
    code = main(["draw", str(LETTER_B), "--port", url, "--out", str(tmp_path / "b"), *args])
    assert code == 0
    report = json.loads((tmp_path / "b" / "report.json").read_text())
    assert report["completed"] and report["executed"] == report["total"]
    assert report["details"]["first_line"] == resume
    # Compared with the part of the run that was left, not with the whole drawing.
    assert report["path_deviation_max_mm"] < 0.05
    # Status reports time the drawing (no speed from 5 Hz); the pen standing at the resume
    # point while it goes down is not drawing late, nor a starved planner.
    assert report["speed_snr_db"] is None and "status reports" in report["speed_snr_note"]
    assert abs(report["drawing_duration_ratio"] - 1) < 0.01
    assert report["stalls"] == 0 and report["warnings"] == []
    assert report["pen_down_runs"] == {"planned": 1, "executed": 1}
