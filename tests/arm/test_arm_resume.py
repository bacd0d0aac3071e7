"""Stops the report is honest about, and resuming the arm from the tick a stop names.

In process, on the simulator's clock: a host stall is the clock moving while the host does
nothing (``chain.advance`` from the progress callback).
"""

from __future__ import annotations

import json
import logging
import math
import re

import numpy as np
import pytest

from tagbot.arm import load_profile, prepare
from tagbot.arm.run import check_resume, simulated_chain
from tagbot.cli import main
from tagbot.draw import run_report
from tagbot.errors import InputError, Interrupted
from tagbot.io.planfile import save_plan
from tagbot.metrics import densify, executed_runs

from .conftest import GOAL_POSITION, two_plan_tag


def _pen_down_paths(trace: np.ndarray) -> list[np.ndarray]:
    """The pen-down polylines of a recorder trace ``t, x, y, pen``."""
    return [run[:, 1:3] for run in executed_runs(trace)]


def _farthest(a: list[np.ndarray], b: list[np.ndarray]) -> float:
    """The largest distance from a point of the ``a`` polylines to the ``b`` polylines, mm."""
    from scipy.spatial import cKDTree

    tree = cKDTree(np.concatenate([densify(p, 0.002) for p in b]))
    return float(tree.query(np.concatenate(a))[0].max())


def _length(paths: list[np.ndarray]) -> float:
    return float(sum(np.hypot(*np.diff(p, axis=0).T).sum() for p in paths))


def test_a_resumed_run_draws_the_rest_of_the_plan_exactly(record, tmp_path) -> None:
    for name in ("full", "first", "rest"):
        (tmp_path / name).mkdir()
    profile = load_profile()
    clean = record(simulated_chain(profile))
    full = prepare(two_plan_tag(), port=clean.url).run(tmp_path / "full")
    assert full.error is None
    sim = record(simulated_chain(profile))
    job = prepare(two_plan_tag(), port=sim.url)
    goals = job.program.goals
    down = np.flatnonzero(goals[:, 2] == profile["pen.down"])
    stop = int(down[0]) + 90 - (int(down[0]) + 90) % 10  # mid-stroke, on a progress call

    def progress(done: int, total: int) -> None:
        if done > stop:
            raise KeyboardInterrupt

    first = job.run(tmp_path / "first", progress=progress)
    assert isinstance(first.error, Interrupted) and first.resume_from == stop + 2
    # The message prints the command that resumes; the CLI takes it for the arm.
    command = re.search(r"resume with (--resume-from (\d+))", str(first.error))
    assert command is not None and int(command.group(2)) == first.resume_from
    stopped_at = len(sim.chain.pen_trace())
    resumed = prepare(two_plan_tag(), port=sim.url, resume_from=first.resume_from)
    rest = resumed.run(tmp_path / "rest")
    assert rest.error is None and rest.executed_steps == rest.total == len(goals)
    assert rest.sent == len(goals) and rest.resume_from is None
    # Every arm goal reached the servos once, in order, over the two jobs (each began with
    # its approach: one goal, to park and then to where the stop left the arm).
    for column, id in enumerate((1, 2)):
        received = sim.values(id, GOAL_POSITION)
        assert received[1 : stop + 2] == goals[: stop + 1, column].tolist()
        assert received[stop + 3 :] == goals[stop + 1 :, column].tolist()
    # Drawn: the stroke goes on exactly where it stopped (nothing skipped, nothing twice), and
    # the ink is the whole run's, within what the servos' follow makes of a stop and a start.
    trace = sim.chain.pen_trace()
    before, after = _pen_down_paths(trace[:stopped_at]), _pen_down_paths(trace[stopped_at:])
    assert len(before) == 1 and len(after) == 2
    assert np.hypot(*(before[0][-1] - after[0][0])) < 0.002
    ink, whole = before + after, _pen_down_paths(clean.chain.pen_trace())
    report = run_report(rest)
    clean_report = run_report(full)
    follow = clean_report["path_deviation_max_mm"]
    assert _farthest(whole, ink) <= follow and _farthest(ink, whole) <= follow
    assert _length(ink) == pytest.approx(_length(whole), rel=0.005)
    # The resumed job's report compares what it drew with what was left of the plan.
    assert report["completed"] and report["pen_down_runs"] == {"planned": 2, "executed": 2}
    assert report["runs"][1] == pytest.approx(clean_report["runs"][1], abs=0.05)
    assert report["path_deviation_max_mm"] <= clean_report["path_deviation_max_mm"] + 0.01
    assert report["runs"][0]["planned_duration"] < clean_report["runs"][0]["planned_duration"]


def test_resume_is_checked_before_anything_is_sent(record) -> None:
    sim = record(simulated_chain(load_profile()))
    job = prepare(two_plan_tag(), port=sim.url)
    with pytest.raises(InputError, match=r"^--resume-from: tick 1 is not in the program"):
        prepare(two_plan_tag(), port=sim.url, resume_from=1)
    with pytest.raises(InputError, match=rf"\(ticks 2 to {len(job.program)}\)$"):
        prepare(two_plan_tag(), port=sim.url, resume_from=len(job.program) + 1)
    assert sim.writes == []


def test_resume_from_the_programs_last_tick_is_accepted_one_past_it_refused() -> None:
    """``--resume-from`` takes ticks 2 to the program's last (resuming its last tick alone);
    one past the last, and tick 1 (a fresh run), are refused with the range."""
    program = prepare(two_plan_tag()).program
    n = len(program)
    assert prepare(two_plan_tag(), resume_from=n).resume_from == n
    for tick in (2, n - 1, n):
        check_resume(tick, program)
    for tick in (1, n + 1):
        with pytest.raises(InputError) as refused:
            check_resume(tick, program)
        assert str(refused.value) == (
            f"--resume-from: tick {tick} is not in the program (ticks 2 to {n})"
        )


def test_the_cli_takes_the_arms_resume_without_position_known(tmp_path) -> None:
    plan = tmp_path / "tag.json"
    save_plan(two_plan_tag(), plan)
    out = tmp_path / "run"
    args = ["draw", str(plan), "--device", "dynamixel", "--resume-from", "150", "--out", str(out)]
    assert main([*args, "--no-pictures", "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["completed"] and report["sent"] == report["total"]
    assert main([*args[:-2], "--out", str(tmp_path / "bad"), "--resume-from", "1"]) == 2


def _stalled_run(record, tmp_path, stall: float):
    """The two-plan tag with the host frozen for ``stall`` s mid-stroke (the simulated clock
    moves on, nothing is sent or read): the run and its report."""
    tmp_path.mkdir(exist_ok=True)
    profile = load_profile()
    sim = record(simulated_chain(profile))
    job = prepare(two_plan_tag(), port=sim.url)
    down = np.flatnonzero(job.program.goals[:, 2] == profile["pen.down"])
    at = int(down[0]) + 100 - (int(down[0]) + 100) % 10
    frozen: list[float] = []

    def progress(done: int, total: int) -> None:
        if done == at + 1 and not frozen:
            frozen.append(sim.chain.now())
            sim.chain.advance(stall)

    run = job.run(tmp_path, progress=progress)
    return run, run_report(run), frozen[0] - (job.program.joints[0, 0])


@pytest.mark.parametrize("stall", [0.12, 0.4])
def test_a_host_stall_mid_ink_is_named_and_blamed_on_the_host(
    record, tmp_path, stall, caplog
) -> None:
    with caplog.at_level(logging.WARNING, logger="tagbot.arm.run"):
        run, report, _ = _stalled_run(record, tmp_path / "stalled", stall)
    # Longer than bus.silence_timeout (0.25 s) or not, the servos that answered every request
    # are not blamed: the run completes and the report names the stall with its length.
    assert run.error is None, run.error
    assert report["stalls"] == 1 and report["stalled_s"] == report["longest_stall_s"]
    # The goals stopped for the stall, less the period until the next was due anyway.
    assert stall - 0.01 <= report["longest_stall_s"] <= stall
    ((start, hole),) = run.stalls
    assert hole == report["longest_stall_s"]
    assert (
        f"the host stalled {1e3 * hole:.0f} ms at {start:.3f} s (executed clock) with the pen"
        " down: no goal left for that long and the pen stood on the paper; a busy host (see"
        " details.realtime)"
    ) in report["warnings"]
    logged = [r.getMessage() for r in caplog.records if "the host stalled" in r.getMessage()]
    assert logged == [w for w in report["warnings"] if w.startswith("the host stalled")]
    d = report["details"]
    assert d["max_lateness_ms"] >= 1e3 * (stall - 0.01) and d["period_jitter_p99_ms"] >= 0.0
    # The stall stays in the executed clock: the job took that much longer, and the figure
    # says what it cost (the pen stood still while the plan moved on).
    (tmp_path / "clean").mkdir()
    clean = run_report(
        prepare(two_plan_tag(), port=record(simulated_chain(load_profile())).url).run(
            tmp_path / "clean"
        )
    )
    assert report["executed_duration_s"] == pytest.approx(
        clean["executed_duration_s"] + report["stalled_s"], abs=0.011
    )
    assert report["speed_snr_db"] < clean["speed_snr_db"] - 3
    assert report["pauses"] == 0 and clean["stalls"] == 0
    assert not any("stall" in w for w in clean["warnings"])
    # The stalled run leaves the speed budget, and its warning says why.
    snr = report["runs"][0]["speed_snr_db"]
    assert (
        snr < 25
        and (
            f"run 1 (plan 0): speed SNR {snr:.1f} dB below 25 dB: 1 host stall"
            f" ({1e3 * report['longest_stall_s']:.0f} ms) with the pen down"
        )
        in report["warnings"]
    )


def test_a_run_over_the_arms_budget_carries_a_warning_naming_the_cause(record, tmp_path):
    """The goals' rounding to whole ticks is a floor no timing removes: half a tick at the pen
    where the second plan is drawn already puts its goals 0.19 mm from the path, beyond
    motion.max_deviation (0.15 mm) alone. The budget is the servos' follow beyond that
    rounding: the clean run keeps it, a run 0.01 mm beyond it carries a warning naming the
    run, the figure, the budget and the cause."""
    sim = record(simulated_chain(load_profile()))
    job = prepare(two_plan_tag(), port=sim.url)
    run = job.run(tmp_path)
    report = run_report(run)
    deviation = report["runs"][1]["path_deviation_max_mm"]
    assert 0.15 < deviation < 0.25 and report["warnings"] == []
    rounding = run.judge.rounded(1)[0]
    assert 0.15 < rounding <= deviation + 1e-5  # the goals themselves lie that far
    over = {**report, "runs": [dict(r) for r in report["runs"]]}
    over["runs"][1]["path_deviation_max_mm"] = 0.15 + rounding + 0.01
    assert run.judge(over) == [
        f"run 2 (plan 1): path deviation {0.16 + rounding:.3f} mm over its budget"
        f" ({0.15 + rounding:.3f} mm: motion.max_deviation 0.15 mm beyond the goals' rounding"
        f" to whole ticks, {rounding:.3f} mm): the servos' follow beyond the retiming's model"
        " (motion.max_deviation)"
    ]
    over["runs"][1]["path_deviation_max_mm"] = 0.15 + rounding - 0.001
    assert run.judge(over) == []


def test_silence_while_requests_flow_is_still_the_servos(record, tmp_path) -> None:
    """A line that goes silent, and a host stall 0.1 s later: the servos are blamed, for the
    time requests were flowing, and the host's stall is named as not counted."""
    profile = load_profile()
    sim = record(simulated_chain(profile))
    job = prepare(two_plan_tag(), port=sim.url)
    state: list[int] = []

    def progress(done: int, total: int) -> None:
        if done == 301:
            for id in (1, 2, 3):
                sim.chain.silence(id)
        if done == 311:
            state.append(done)
            sim.chain.advance(0.2)

    run = job.run(tmp_path, progress=progress)
    message = str(run.error)
    assert (
        "servo 1 (shoulder), servo 2 (elbow) and servo 3 (pen) did not answer SYNC_READ of"
        " present positions for" in message
    )
    quiet = float(re.search(r"for (\d+\.\d+) s while requests were flowing", message).group(1))
    assert 0.25 <= quiet < 0.3
    assert "the host stalled 0.20 s meanwhile, not counted" in message
    assert math.isfinite(quiet)
