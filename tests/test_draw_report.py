"""report.json and the run folder as ``tagbot draw`` writes them, from a back end's result.

The back end here is a recorded :class:`MachineRun` (what a device's ``run`` returns), so each
case states exactly what the machine did and the report is checked against it.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tagbot import load_plan
from tagbot.control import RunControl
from tagbot.draw import DEVICES, MachineRun, draw, prepare, run_report, write_executed_csv
from tagbot.errors import DeviceFault, InputError, PlacementError, PortError, ProfileError
from tagbot.io.motionfile import MotionTable

ROOT = Path(__file__).resolve().parents[1]
LETTER_B = ROOT / "tagbot" / "examples" / "letter-b.json"


def planned_line() -> tuple[np.ndarray, np.ndarray]:
    """One pen-down run: 2 s along x, 0 to 40 mm, eased in and out."""
    t = np.arange(0.0, 2.0 + 1e-9, 0.01)
    return t, np.column_stack([20.0 * (1 - np.cos(np.pi * t / 2)), np.zeros_like(t)])


def executed_line(delay: float = 0.25, offset: float = 0.0) -> np.ndarray:
    """The run drawn ``delay`` s late, ``offset`` mm off in y, sampled every ms, pen up after."""
    fine = np.arange(0.0, 2.0 + 1e-9, 0.001)
    x = 20.0 * (1 - np.cos(np.pi * fine / 2))
    down = np.column_stack([fine + delay, x, np.full_like(fine, offset), np.ones_like(fine)])
    up = [[delay + 2.1, 40.0, offset, 0.0]]
    return np.vstack([down, up])


def machine_run(**changes: object) -> MachineRun:
    """A clean simulated run of :func:`planned_line`; ``changes`` replace its fields."""
    t, xy = planned_line()
    motion = MotionTable(t, xy, np.gradient(xy, t, axis=0), np.zeros_like(t), np.ones(len(t)))
    run = MachineRun(
        device="axidraw",
        motion=motion,
        planned_runs=[(t, xy)],
        plans=[0],
        executed=executed_line(),
        executed_source="simulator recorder, 1 ms",
        sparse=False,
        executed_runs=None,
        unit="move",
        total=12,
        sent=12,
        executed_steps=12,
        resume_from=None,
        planned_duration=2.5,
        executed_duration=2.75,
        placement={"time_scale": 1.5},
        port="simulator",
        details={"moves_acknowledged": 12},
    )
    return replace(run, **changes)


class Recorded:
    """A prepared job whose run returns ``result`` (or raises ``fault``), as a back end does."""

    device = "axidraw"

    def __init__(self, result: MachineRun | None = None, fault: BaseException | None = None):
        self.result, self.fault = result, fault
        self.calls: list[tuple[object, object, object]] = []
        self.planned = machine_run().motion

    def run(self, out, *, progress=None, control=None) -> MachineRun:
        self.calls.append((out, progress, control))
        if self.fault is not None:
            raise self.fault
        assert self.result is not None
        return self.result


def test_a_clean_run_reports_its_counts_times_and_comparison():
    report = run_report(machine_run())
    assert report["device"] == "axidraw" and report["port"] == "simulator"
    assert report["simulated"] is True and report["completed"] is True
    assert report["error"] is None and report["warnings"] == []
    assert (report["unit"], report["total"], report["sent"], report["executed"]) == (
        "move", 12, 12, 12)  # fmt: skip
    assert report["resume_from"] is None
    assert report["planned_duration_s"] == 2.5 and report["executed_duration_s"] == 2.75
    assert (report["paused_s"], report["pauses"], report["longest_pause_s"]) == (0.0, 0, 0.0)
    assert (report["stalled_s"], report["stalls"], report["longest_stall_s"]) == (0.0, 0, 0.0)
    assert report["executed_source"] == "simulator recorder, 1 ms"
    assert report["placement"] == {"time_scale": 1.5}
    assert report["details"] == {"moves_acknowledged": 12}
    # Drawn exactly on the plan, a quarter second late: no deviation, the same duration.
    assert report["path_deviation_max_mm"] < 0.01
    assert report["pen_down_runs"] == {"planned": 1, "executed": 1}
    assert report["drawing_duration_ratio"] == pytest.approx(1.0, abs=0.01)
    assert report["runs"][0]["executed_start"] == pytest.approx(0.25, abs=0.002)
    assert report["runs"][0]["plan"] == 0
    assert run_report(machine_run(plans=[2]))["runs"][0]["plan"] == 2
    assert "comparison_error" not in report and "recorded_speed_snr_db" not in report


def test_pauses_and_stalls_are_totalled_counted_and_the_longest_named():
    pauses = [(0.5, 0.2), (1.0, 0.75), (1.9, 0.05)]
    stalls = [(0.3, 0.01), (1.2, 0.02)]
    report = run_report(machine_run(pauses=pauses, stalls=stalls))
    assert report["pauses"] == 3 and report["paused_s"] == pytest.approx(1.0)
    assert report["longest_pause_s"] == 0.75
    assert report["stalls"] == 2 and report["stalled_s"] == pytest.approx(0.03)
    assert report["longest_stall_s"] == 0.02


def test_a_stopped_run_names_its_error_and_where_it_stopped():
    fault = DeviceFault("board replied !8 Err: Unknown command")
    report = run_report(machine_run(error=fault, executed_steps=5, resume_from=6, until=1.0))
    assert report["completed"] is False
    assert report["error"] == "board replied !8 Err: Unknown command"
    assert (report["executed"], report["resume_from"]) == (5, 6)
    # Compared with the plan up to where the machine had drawn (1 s of the 2 s run).
    line = executed_line()
    drawn = line[line[:, 0] <= 1.25]
    executed = np.vstack([drawn, [[1.3, *drawn[-1, 1:3], 0.0]]])
    report = run_report(machine_run(error=fault, executed=executed, until=1.0))
    assert report["planned_drawing_s"] == pytest.approx(1.0, abs=0.05)  # from 0.02 mm moved
    assert report["drawing_duration_ratio"] == pytest.approx(1.0, abs=0.02)
    assert report["path_deviation_max_mm"] < 0.01
    # A fault with no message is named by its type.
    assert run_report(machine_run(error=KeyboardInterrupt()))["error"] == "KeyboardInterrupt"


def test_a_real_port_is_not_simulated():
    report = run_report(machine_run(port="/dev/ttyACM0"))
    assert report["port"] == "/dev/ttyACM0" and report["simulated"] is False


def test_nothing_executed_or_nothing_drawn_is_said_instead_of_figures():
    empty = run_report(machine_run(executed=np.zeros((0, 4))))
    assert empty["comparison_error"] == "nothing was executed"
    assert "speed_snr_db" not in empty and "path_deviation_max_mm" not in empty
    no_plan = run_report(machine_run(planned_runs=[]))
    assert no_plan["comparison_error"] == "nothing was executed"
    # Executed, but the pen never went down: the comparison's own reason.
    up = executed_line()
    up[:, 3] = 0.0
    report = run_report(machine_run(executed=up))
    assert "no pen-down run" in report["comparison_error"]
    assert "speed_snr_db" not in report


def test_the_device_judges_the_report_with_its_comparison():
    seen = []

    def judge(report):
        seen.append(report["path_deviation_max_mm"])
        return [f"run 1: deviation {report['path_deviation_max_mm']:.1f} mm"]

    report = run_report(machine_run(executed=executed_line(offset=0.5), judge=judge))
    assert seen == [pytest.approx(0.5, abs=0.01)]
    assert report["warnings"] == ["run 1: deviation 0.5 mm"]
    # Warnings the back end had come first, the judge's after them.
    report = run_report(machine_run(warnings=["servo slow"], judge=judge))
    assert report["warnings"][0] == "servo slow" and len(report["warnings"]) == 2
    # No comparison, no judging.
    report = run_report(machine_run(executed=np.zeros((0, 4)), judge=judge))
    assert report["warnings"] == [] and len(seen) == 2


def test_a_sparse_trace_is_compared_like_with_like_and_not_with_the_recording():
    t, xy = planned_line()
    te = np.arange(0.0, 2.0, 0.2) + 0.3
    on = np.column_stack([np.interp(te - 0.3, t, xy[:, i]) for i in (0, 1)])
    executed = np.column_stack([te, on, np.ones(len(te))])
    run = machine_run(
        executed=executed, sparse=True, executed_runs=np.zeros(len(te), int), plans=[3]
    )
    report = run_report(run, recorded=[object()])
    assert report["speed_snr_db"] is None and report["path_deviation_max_mm"] < 0.01
    assert [r["plan"] for r in report["runs"]] == [3]  # the run drew the tag's plan 3
    assert report["recorded_comparison_error"].startswith(
        "the executed trace is the device's status reports (a few a second): too sparse"
    )
    assert "recorded_speed_snr_db" not in report
    # Without recordings nothing is said about them.
    assert "recorded_comparison_error" not in run_report(run)


def test_reports_taken_during_a_pause_are_left_out_of_a_sparse_comparison():
    t, xy = planned_line()
    te = np.arange(0.0, 2.6, 0.1) + 0.3
    # Drawing from 0.3 s, held for 0.5 s at 1.3 s (reports there stand still), then on.
    planned_at = np.where(te < 1.3, te - 0.3, np.where(te < 1.8, 1.0, te - 0.8))
    on = np.column_stack([np.interp(planned_at, t, xy[:, i]) for i in (0, 1)])
    executed = np.column_stack([te, on, np.ones(len(te))])[planned_at <= 2.0]
    run = machine_run(
        executed=executed,
        sparse=True,
        executed_runs=np.zeros(len(executed), int),
        pauses=[(1.3, 0.5)],
    )
    report = run_report(run)
    assert "comparison_error" not in report and report["pauses"] == 1
    assert report["path_deviation_max_mm"] < 0.01
    assert report["drawing_duration_ratio"] == pytest.approx(1.0, abs=0.1)


def test_the_recording_is_compared_only_where_the_pen_went_down():
    # No recorded trace is timed: no figure, no runs, and no error either.
    report = run_report(machine_run(), recorded=[])
    assert report["recorded_speed_snr_db"] is None and report["recorded_runs"] == []
    assert "recorded_comparison_error" not in report
    # Executed with the pen up all along: no run to compare.
    up = executed_line()
    up[:, 3] = 0.0
    report = run_report(machine_run(executed=up), recorded=[])
    assert report["recorded_speed_snr_db"] is None and report["recorded_runs"] == []
    # A trace that is not t, x, y, pen rows: both comparisons say why instead of failing.
    report = run_report(machine_run(executed=np.zeros((5, 3))), recorded=[])
    assert "reshape" in report["comparison_error"]
    assert "reshape" in report["recorded_comparison_error"]
    assert "recorded_speed_snr_db" not in report
    # Nothing executed: nothing said about the recording.
    report = run_report(machine_run(executed=np.zeros((0, 4))), recorded=[])
    assert "recorded_comparison_error" not in report and "recorded_runs" not in report


def test_executed_csv_has_six_decimals_and_the_pen_as_0_or_1(tmp_path):
    rows = np.array([[0.0, 1.0, 2.0, 0.0], [0.0015, -3.1234567, 4.5, 0.5], [1.25, 0, 0, 0.51]])
    write_executed_csv(rows, tmp_path / "executed.csv")
    assert (tmp_path / "executed.csv").read_text(encoding="utf-8") == (
        "t,x,y,pen\n"
        "0.000000,1.000000,2.000000,0\n"
        "0.001500,-3.123457,4.500000,0\n"
        "1.250000,0.000000,0.000000,1\n"
    )
    write_executed_csv(np.zeros(0), tmp_path / "empty.csv")
    assert (tmp_path / "empty.csv").read_text(encoding="utf-8") == "t,x,y,pen\n"


def test_report_json_holds_plain_numbers_and_null_for_non_finite(tmp_path):
    details = {
        "snr": np.float64(31.5),
        "count": np.int64(7),
        "bad": float("nan"),
        "inf": np.float64(np.inf),
        "pair": (np.float32(0.5), -math.inf),
        3: "key",
    }
    tag = load_plan(LETTER_B)
    result = draw(tag, tmp_path / "run", prepared=Recorded(machine_run(details=details)))
    text = (tmp_path / "run" / "report.json").read_text(encoding="utf-8")
    assert text.endswith("}\n") and text.startswith('{\n  "device": "axidraw",\n')
    written = json.loads(text)
    assert written["details"] == {
        "snr": 31.5,
        "count": 7,
        "bad": None,
        "inf": None,
        "pair": [0.5, None],
        "3": "key",
    }
    assert written["completed"] is True and result.folder == tmp_path / "run"
    assert written["pictures"] == result.report["pictures"]
    assert {"tag.png", "speed.png"} <= set(written["pictures"])
    assert all((tmp_path / "run" / name).exists() for name in written["pictures"])


def test_the_run_folder_holds_the_plan_the_timeline_and_the_executed_trace(tmp_path):
    tag = load_plan(LETTER_B)
    folder = tmp_path / "runs" / "today" / "run"  # its parents are made too
    prepared, control = Recorded(machine_run()), RunControl()

    def progress(done: int, total: int) -> None:
        pass

    draw(tag, folder, prepared=prepared, pictures=False, progress=progress, control=control)
    # The machine got the folder, the progress callback and the pause control.
    assert prepared.calls == [(folder, progress, control)]
    assert sorted(p.name for p in folder.iterdir()) == [
        "executed.csv", "motion.csv", "plan.json", "report.json"]  # fmt: skip
    assert json.loads((folder / "plan.json").read_text()) == json.loads(LETTER_B.read_text())
    lines = (folder / "executed.csv").read_text().splitlines()
    assert len(lines) == 1 + len(executed_line())
    assert lines[1] == "0.250000,0.000000,0.000000,1" and lines[-1].endswith(",0")
    motion = (folder / "motion.csv").read_text().splitlines()
    assert motion[0] == "t,x,y,vx,vy,speed,pen" and len(motion) == 1 + len(planned_line()[0])
    assert "pictures" not in json.loads((folder / "report.json").read_text())


def test_a_stopped_run_keeps_its_folder_and_report_then_raises(tmp_path):
    fault = DeviceFault("the board stopped answering")
    prepared = Recorded(machine_run(error=fault, executed_steps=4, resume_from=5))
    with pytest.raises(DeviceFault, match="stopped answering") as caught:
        draw(load_plan(LETTER_B), tmp_path / "run", prepared=prepared)
    assert caught.value is fault
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report["completed"] is False and report["error"] == "the board stopped answering"
    assert report["executed"] == 4 and report["resume_from"] == 5
    assert "pictures" not in report  # nothing drawn to the end: no pictures
    assert not (tmp_path / "run" / "tag.png").exists()
    assert (tmp_path / "run" / "executed.csv").exists()


def test_a_back_end_that_fails_outright_still_leaves_a_report(tmp_path):
    prepared = Recorded(fault=RuntimeError("bus gone"))
    with pytest.raises(RuntimeError, match="bus gone"):
        draw(load_plan(LETTER_B), tmp_path / "run", prepared=prepared)
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report == {"device": "axidraw", "completed": False, "error": "bus gone"}
    with pytest.raises(KeyboardInterrupt):
        draw(load_plan(LETTER_B), tmp_path / "ctrl-c", prepared=Recorded(fault=KeyboardInterrupt()))
    report = json.loads((tmp_path / "ctrl-c" / "report.json").read_text())
    assert report["error"] == "KeyboardInterrupt"
    assert (tmp_path / "ctrl-c" / "plan.json").exists()


def test_a_run_folder_that_cannot_be_made_is_refused_by_name(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(InputError, match=r"^.*file/run: cannot create the run folder \(") as e:
        draw(load_plan(LETTER_B), blocker / "run", prepared=Recorded(machine_run()))
    assert str(e.value).startswith(f"{blocker / 'run'}: cannot create the run folder (")
    assert blocker.read_text() == ""


def test_an_unknown_device_is_refused_naming_the_known_ones():
    tag = load_plan(LETTER_B)
    with pytest.raises(InputError) as caught:
        prepare(tag, device="plotter")
    assert str(caught.value) == "device: unknown 'plotter' (known: axidraw, dynamixel, grbl)"
    assert sorted(DEVICES) == ["axidraw", "dynamixel", "grbl"]


def test_prepare_hands_the_profile_overrides_and_port_to_the_device(tmp_path):
    tag = load_plan(LETTER_B)
    assert prepare(tag, device="axidraw").device == "axidraw"
    assert prepare(tag).device == "grbl"  # the pen plotter unless another device is named
    with pytest.raises(PlacementError, match=r"^placement: the drawing reaches"):
        prepare(tag, device="axidraw", overrides=("place.scale=1000",))
    with pytest.raises(ProfileError, match=r"nowhere\.toml"):
        prepare(tag, device="axidraw", profile=tmp_path / "nowhere.toml")
    with pytest.raises(PortError, match="/dev/nonexistent: no such device"):
        prepare(tag, device="axidraw", port="/dev/nonexistent")
