"""What an arm run reports (issue 34): the placement and figures of a clean run against the
program's own values, the tracking error over the read-backs at its boundaries, the budget's
figures and causes computed independently, and a stop's message naming the resume."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from tagbot.arm import load_profile, prepare
from tagbot.arm.run import Budget, draw_arm, tracking_error
from tagbot.control import RunControl
from tagbot.draw import run_report
from tagbot.errors import ConnectionLost, DeviceError

from .conftest import small_tag, two_plan_tag

TICK_DEG = 360.0 / 4096


@pytest.fixture
def clean(tmp_path) -> tuple[Any, Any, dict[str, Any]]:
    """A clean simulated run of the two-plan tag: the job, the run and its report."""
    job = prepare(two_plan_tag())
    run = job.run(tmp_path)
    return job, run, run_report(run)


@pytest.fixture
def small() -> Any:
    """The one-plan tag's checked job, not run (its goals' rounding has a low speed SNR)."""
    return prepare(small_tag())


def _angles(ticks: np.ndarray, zero: int, sign: int) -> np.ndarray:
    return sign * (np.asarray(ticks, dtype=float) - zero) * (2 * math.pi / 4096)


def test_a_clean_runs_placement_names_each_runs_clock(clean) -> None:
    job, _, report = clean
    sp = job.program.setpoints
    runs = []
    for k in range(2):
        rows = np.flatnonzero(sp.plan == k)
        assert sp.pen[rows[0]] and not sp.pen[rows[0] - 1]  # where the pen has just come down
        runs.append(
            {
                "plan": k,
                "scale": sp.run_scales[k],
                "tag_start": sp.run_clocks[k].tag_start,
                "start": float(sp.t[rows[0]]),
            }
        )
    assert report["placement"] == {
        "runs": runs,
        "mm_per_unit": sp.mm_per_unit,
        "time_scale": max(sp.run_scales),
    }
    assert runs[0]["scale"] != runs[1]["scale"]  # each run at its own scale
    assert all(type(v) is float for r in runs for k, v in r.items() if k != "plan")


def test_a_clean_runs_figures(clean) -> None:
    job, _, report = clean
    d = report["details"]
    n = len(job.program)
    assert report["completed"] and report["sent"] == report["executed"] == report["total"] == n
    assert report["resume_from"] is None and report["error"] is None
    assert d["ticks_sent"] == n and d["readbacks"] == n  # read-back every tick
    # On the simulator's clock every goal leaves exactly one period after the one before.
    assert d["loop_rate_hz"] == pytest.approx(d["rate_hz"], rel=1e-9) and d["rate_hz"] == 100.0
    assert d["period_jitter_p99_ms"] == pytest.approx(0.0, abs=1e-6)
    assert d["late_ticks"] == 0 and d["max_lateness_ms"] == 0.0 and d["resyncs"] == 0
    assert d["simulated"] is True and d["port"] == report["port"] == "simulator"
    assert d["time_scale"] == job.program.setpoints.time_scale
    assert d["mm_per_unit"] == job.program.setpoints.mm_per_unit
    assert report["executed_source"] == "simulator recorder, 1 ms"
    tracking = d["joint_tracking_error"]
    assert 0.0 < tracking["mean"] < tracking["max"] < 1.0


def test_tracking_error_counts_the_reads_at_both_ends_and_none_outside(small) -> None:
    program, profile = small.program, small.profile
    (shoulder, elbow), j = profile.joints, program.joints
    reads = np.column_stack([j[:, 0], j[:, 1], j[:, 2], j[:, 3]]).copy()
    reads[0, 1] += 5  # 5 ticks off at the first tick's time
    reads[-1, 2] -= 7  # 7 ticks off at the last tick's time
    outside = [[j[0, 0] - 1e-6, j[0, 1] + 50, j[0, 2], j[0, 3]]]
    outside += [[j[-1, 0] + 1e-6, j[-1, 1], j[-1, 2] + 50, j[-1, 3]]]
    got = tracking_error(np.concatenate([outside[:1], reads, outside[1:]]), program, profile)
    # Independently: |present − planned| in degrees, at the reads' own ticks.
    e = np.concatenate(
        [
            np.abs(_angles(reads[:, 1], shoulder.zero, shoulder.sign) - program.angles[:, 0]),
            np.abs(_angles(reads[:, 2], elbow.zero, elbow.sign) - program.angles[:, 1]),
        ]
    )
    assert got["max"] == pytest.approx(math.degrees(e.max()), rel=1e-12)
    assert got["mean"] == pytest.approx(math.degrees(e.mean()), rel=1e-12)
    assert 6.5 * TICK_DEG <= got["max"] <= 7.5 * TICK_DEG
    nothing = tracking_error(np.array(outside), program, profile)
    assert math.isnan(nothing["max"]) and math.isnan(nothing["mean"])


def _polyline_distance(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Each point's exact distance to the polyline ``line``."""
    a, b = line[:-1], line[1:]
    ab = b - a
    length2 = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    ap = points[:, None, :] - a[None, :, :]
    u = np.clip(np.sum(ap * ab[None], axis=2) / length2[None], 0.0, 1.0)
    nearest = a[None] + u[..., None] * ab[None]
    return np.min(np.hypot(*(points[:, None, :] - nearest).transpose(2, 0, 1)), axis=1)


def test_the_goals_rounding_figures_are_their_distance_and_speed_snr(clean) -> None:
    job, _, _ = clean
    program, profile = job.program, job.profile
    sp = program.setpoints
    budget = Budget(program, profile, [], np.zeros((0, 2)))
    (shoulder, elbow), (l1, l2) = profile.joints, profile.links
    for k in range(2):
        rows = np.flatnonzero(sp.plan == k)
        g = program.goals[rows]
        a1 = _angles(g[:, 0], shoulder.zero, shoulder.sign)
        a2 = _angles(g[:, 1], elbow.zero, elbow.sign)
        xy = np.column_stack(
            [l1 * np.cos(a1) + l2 * np.cos(a1 + a2), l1 * np.sin(a1) + l2 * np.sin(a1 + a2)]
        )
        t, planned = sp.t[rows], sp.xy[rows]
        v = np.gradient(planned, t, axis=0)
        noise = np.gradient(xy, t, axis=0) - v
        snr = 10 * math.log10(np.sum(v**2) / np.sum(noise**2))
        far = float(_polyline_distance(xy, planned).max())
        got = budget.rounded(k)
        assert got[1] == pytest.approx(snr, rel=1e-9)
        assert got[0] == pytest.approx(far, abs=1e-5)
        assert 0.0 < got[0] < 1.0
    assert budget.rounded(7) == (0.0, math.inf)  # no such plan: nothing rounded


RUN = {"plan": 0, "executed_start": 1.0, "planned_duration": 2.0}
"""A report's run: its window for the causes is 0.95 .. 4.0 s (start - 50 ms .. end + 1 s)."""


def test_a_host_stall_in_the_runs_window_is_the_cause(small) -> None:
    def cause(stalls: list[tuple[float, float]]) -> str:
        return Budget(small.program, small.profile, stalls, np.zeros((0, 2))).cause(RUN, True, True)

    assert cause([(0.95, 0.1)]) == "1 host stall (100 ms) with the pen down"
    assert cause([(4.0, 0.02), (2.0, 0.031), (9.0, 1.0)]) == (
        "2 host stalls (51 ms) with the pen down"
    )
    for outside in (0.9499, 4.0001):
        assert "stall" not in cause([(outside, 0.1)])


def test_late_goals_in_the_runs_window_are_the_cause(small) -> None:
    def cause(late: list[list[float]]) -> str:
        return Budget(small.program, small.profile, [], np.array(late).reshape(-1, 2)).cause(
            RUN, False, True
        )

    assert cause([[1.0, 0.004], [4.0, 0.0123], [0.999, 0.5], [4.001, 0.5]]) == (
        "2 late goals (up to 12.3 ms)"
    )
    assert "late" not in cause([[0.999, 0.5], [4.001, 0.5]])


def test_a_small_slow_runs_cause_is_the_goals_rounding(small, clean) -> None:
    budget = Budget(small.program, small.profile, [], np.zeros((0, 2)))
    snr = budget.rounded(0)[1]
    assert snr < 25.0 + 3.0  # the small tag's goals, rounded, fall short of the speed budget
    rounding = (
        f"the goals' rounding to whole ticks ({TICK_DEG:.3f}°): the plan's speed, rounded so,"
        f" has {snr:.1f} dB (a small or slow run)"
    )
    follow = "the servos' follow beyond the retiming's model (motion.max_deviation)"
    assert budget.cause(RUN, False, True) == rounding
    assert budget.cause(RUN, True, True) == f"{rounding}; the path, {follow}"
    assert budget.cause(RUN, True, False) == follow
    # The clean run's second plan rounds to 30 dB: its cause is the servos' follow.
    job = clean[0]
    other = Budget(job.program, job.profile, [], np.zeros((0, 2)))
    assert other.rounded(1)[1] >= 28.0
    assert other.cause({**RUN, "plan": 1}, False, True) == follow


def test_the_budget_names_a_run_below_the_speed_snr_and_keeps_its_bounds(small) -> None:
    budget = Budget(small.program, small.profile, [(1.5, 0.2)], np.zeros((0, 2)))
    rounding = budget.rounded(0)[0]
    limit = small.profile["motion.max_deviation"] + rounding

    def report(deviation: float | None, snr: float | None) -> dict[str, Any]:
        run = {**RUN, "path_deviation_max_mm": deviation, "speed_snr_db": snr}
        return {
            "runs": [{**RUN, "plan": 0, "path_deviation_max_mm": 0.0, "speed_snr_db": 40.0}, run]
        }

    stall = "1 host stall (200 ms) with the pen down"
    assert budget(report(None, None)) == [] and budget({}) == []
    assert budget(report(limit, 25.0)) == []  # at the budget is within it
    assert budget(report(0.0, 24.95)) == [f"run 2 (plan 0): speed SNR 24.9 dB below 25 dB: {stall}"]
    assert budget(report(limit + 0.01, 20.0)) == [
        f"run 2 (plan 0): path deviation {limit + 0.01:.3f} mm over its budget ({limit:.3f} mm:"
        f" motion.max_deviation {small.profile['motion.max_deviation']:g} mm beyond the goals'"
        f" rounding to whole ticks, {rounding:.3f} mm) and speed SNR 20.0 dB below 25 dB:"
        f" {stall}"
    ]
    # A run the stop cut short: its speed ends where the arm stopped, so it is not judged on it.
    cut = report(limit + 0.01, 20.0)
    cut["runs"][1]["cut_short"] = True
    assert budget(cut) == [
        f"run 2 (plan 0): path deviation {limit + 0.01:.3f} mm over its budget ({limit:.3f} mm:"
        f" motion.max_deviation {small.profile['motion.max_deviation']:g} mm beyond the goals'"
        f" rounding to whole ticks, {rounding:.3f} mm): {stall}"
    ]
    cut["runs"][1]["path_deviation_max_mm"] = 0.0
    assert budget(cut) == []


def test_a_slow_run_also_over_its_path_budget_names_both_causes(small) -> None:
    """No stall, no late goal: a run of the small tag below the speed SNR is blamed on the goals'
    rounding, and when its path is also over budget, on the servos' follow as well; a run with
    no path figure is judged on its speed alone."""
    budget = Budget(small.program, small.profile, [], np.zeros((0, 2)))
    rounding, snr = budget.rounded(0)
    limit = small.profile["motion.max_deviation"] + rounding
    because = (
        f"the goals' rounding to whole ticks ({TICK_DEG:.3f}°): the plan's speed, rounded so,"
        f" has {snr:.1f} dB (a small or slow run)"
    )
    follow = "the servos' follow beyond the retiming's model (motion.max_deviation)"

    def warnings(deviation: float | None) -> list[str]:
        run = {**RUN, "path_deviation_max_mm": deviation, "speed_snr_db": 20.0}
        return budget({"runs": [run]})

    assert warnings(None) == [f"run 1 (plan 0): speed SNR 20.0 dB below 25 dB: {because}"]
    assert warnings(limit) == warnings(None)  # at its budget the path is no cause
    assert warnings(limit + 0.01) == [
        f"run 1 (plan 0): path deviation {limit + 0.01:.3f} mm over its budget ({limit:.3f} mm:"
        f" motion.max_deviation {small.profile['motion.max_deviation']:g} mm beyond the goals'"
        f" rounding to whole ticks, {rounding:.3f} mm) and speed SNR 20.0 dB below 25 dB:"
        f" {because}; the path, {follow}"
    ]


@pytest.mark.parametrize(
    ("error", "message"),
    [
        (ConnectionLost("the studio's link dropped"), "the studio's link dropped"),
        (DeviceError("went away", "studio"), "went away"),
        # With no place of its own, a message is kept whole, whatever its first characters.
        (ConnectionLost("XXXX: the link dropped"), "XXXX: the link dropped"),
    ],
)
def test_a_device_error_from_the_callers_progress_names_the_resume(
    tmp_path, error: DeviceError, message: str
) -> None:
    """A DeviceError raised by the caller's progress callback (with or without a place of its
    own) stops the arm safely; the run's error keeps its message and names the last tick
    executed and the command that resumes."""
    job = prepare(small_tag())

    def progress(done: int, total: int) -> None:
        if done > 200:
            raise error

    run = job.run(tmp_path, progress=progress)
    assert type(run.error) is type(error)
    sent = run.sent
    assert 200 < sent < run.total and run.resume_from == sent + 1
    assert str(run.error) == (
        f"tick {sent} (the last tick executed; resume with --resume-from {sent + 1}): {message}"
    )
    assert run_report(run)["error"] == str(run.error)


def test_a_device_error_after_the_last_tick_names_no_resume(tmp_path) -> None:
    """A DeviceError from the caller's progress once every tick was sent: the run is not
    completed, but nothing is left to resume; the message is kept whole, with no resume."""
    job = prepare(small_tag())

    def progress(done: int, total: int) -> None:
        if done == total:
            raise ConnectionLost("the studio's link dropped")

    run = job.run(tmp_path, progress=progress)
    assert run.sent == run.total == len(job.program)
    assert run.resume_from is None and str(run.error) == "the studio's link dropped"
    report = run_report(run)
    assert report["resume_from"] is None and not report["completed"]


def test_outside_its_limits_at_start_is_a_warning_and_the_arm_goes_back(tmp_path, record) -> None:
    from tagbot.arm.run import simulated_chain

    profile = load_profile()
    sim = record(simulated_chain(profile, at_park=False))  # elbow straight: 0°, below 10°
    run = prepare(small_tag(), port=sim.url).run(tmp_path)
    assert run.error is None
    assert "elbow starts at 0.0° outside elbow.min_deg..max_deg (10..160°): moving it back" in (
        run.warnings
    )
    assert not any(w.startswith("shoulder") for w in run.warnings)


# A float elbow.max_deg whose radians, plus the 1e-9 rad tolerance, is exactly tick 3868's angle.
AT_TICK_3868 = 159.96093744270422


@pytest.mark.parametrize(("tick", "warned"), [(3868, False), (3869, True)])
def test_a_joint_starting_at_its_limit_is_no_warning_one_tick_beyond_is(
    tmp_path, record, tick: int, warned: bool
) -> None:
    from tagbot.arm.run import simulated_chain

    assert math.radians(AT_TICK_3868) + 1e-9 == (3868 - 2048) * 2 * math.pi / 4096
    profile = load_profile(None, [f"elbow.max_deg={AT_TICK_3868!r}"])
    chain = simulated_chain(profile)
    chain.set_position(profile.joints[1].id, float(tick))
    sim = record(chain)
    job = prepare(small_tag(), port=sim.url, overrides=(f"elbow.max_deg={AT_TICK_3868!r}",))

    def progress(done: int, total: int) -> None:  # the warning comes before the first tick
        raise ConnectionLost("enough")

    warnings = job.run(tmp_path, progress=progress).warnings
    message = (
        f"elbow starts at {(tick - 2048) * 360 / 4096:.1f}° outside elbow.min_deg..max_deg"
        f" (10..160°): moving it back"
    )
    assert (message in warnings) is warned
    assert not any("starts at" in w for w in warnings if w != message)


class _PausedFirst(RunControl):
    """Paused for the first ``checks`` times the loop asks (a count, not a clock)."""

    def __init__(self, checks: int) -> None:
        super().__init__()
        self.left = checks

    @property
    def paused(self) -> bool:
        self.left -= 1
        return self.left >= 0


def test_draw_arm_obeys_its_control_and_reports_the_pause() -> None:
    run = draw_arm(small_tag(), load_profile(), control=_PausedFirst(200))
    assert run.stats["pauses"] == 1 and run.stats["paused_s"] > 0.0
    assert run.stats["ticks_sent"] == len(run.joints)


def test_a_run_of_three_goals_has_its_rounding_figures(clean) -> None:
    """The rounding figures need three goals (a speed by central differences): a run of
    exactly three has them, computed as for any run."""
    job = clean[0]
    sp = job.program.setpoints
    rows = np.flatnonzero(sp.plan == 1)
    plan = np.where(sp.plan == 1, -1, sp.plan)
    plan[rows[10:13]] = 1
    three = replace(job.program, setpoints=replace(sp, plan=plan))
    got = Budget(three, job.profile, [], np.zeros((0, 2))).rounded(1)
    (shoulder, elbow), (l1, l2) = job.profile.joints, job.profile.links
    g = job.program.goals[rows[10:13]]
    a1 = _angles(g[:, 0], shoulder.zero, shoulder.sign)
    a2 = _angles(g[:, 1], elbow.zero, elbow.sign)
    xy = np.column_stack(
        [l1 * np.cos(a1) + l2 * np.cos(a1 + a2), l1 * np.sin(a1) + l2 * np.sin(a1 + a2)]
    )
    t, planned = sp.t[rows[10:13]], sp.xy[rows[10:13]]
    v = np.gradient(planned, t, axis=0)
    noise = np.gradient(xy, t, axis=0) - v
    assert got[1] == pytest.approx(10 * math.log10(np.sum(v**2) / np.sum(noise**2)), rel=1e-9)
    assert got[0] == pytest.approx(float(_polyline_distance(xy, planned).max()), abs=1e-5)
    plan[rows[11]] = -1  # two goals: nothing to measure
    two = replace(job.program, setpoints=replace(sp, plan=plan))
    assert Budget(two, job.profile, [], np.zeros((0, 2))).rounded(1) == (0.0, math.inf)


def test_a_host_stall_leaves_late_goals_on_the_executed_clock(record, tmp_path) -> None:
    """After a 0.12 s host stall the goals due meanwhile go late: the judge holds them (when
    each was due at the pen on the executed clock, and by how much), and names them as the
    cause of a run's budget when no stall is counted."""
    from tagbot.arm.run import simulated_chain

    profile = load_profile()
    sim = record(simulated_chain(profile))
    job = prepare(small_tag(), port=sim.url)
    down = int(np.flatnonzero(job.program.goals[:, 2] == profile["pen.down"])[0]) + 100
    frozen: list[float] = []

    def progress(done: int, total: int) -> None:
        if done >= down and not frozen:
            frozen.append(done)
            sim.chain.advance(0.12)

    run = job.run(tmp_path, progress=progress)
    assert run.error is None and frozen
    late = run.judge.late
    assert len(late) >= 1 and late.shape[1] == 2
    assert 0.1 <= float(late[:, 1].max()) <= 0.12 + 1e-9
    (stall_at, _), *_ = run.stalls
    assert np.all(np.abs(late[:, 0] - stall_at) < 0.2)
    # the first goal due meanwhile, the tick after the last one sent, is on the executed clock
    # at its own program time
    assert late[0, 0] == pytest.approx(float(job.program.joints[frozen[0], 0]), abs=1e-9)
    budget = Budget(job.program, profile, [], late)
    at = float(late[0, 0])
    cause = budget.cause(
        {"plan": 0, "executed_start": at - 0.5, "planned_duration": 1.0}, True, True
    )
    assert cause == f"{len(late)} late goals (up to {1e3 * late[:, 1].max():.1f} ms)"


def test_a_resumed_runs_trace_starts_where_the_arm_stood(record, tmp_path) -> None:
    """A run resumed at tick N keeps the executed trace from tick N − 1's program time (the
    pose it travelled back to), not a tick earlier."""
    from tagbot.arm.run import simulated_chain

    profile = load_profile()
    sim = record(simulated_chain(profile))
    job = prepare(small_tag(), port=sim.url, resume_from=301)
    run = job.run(tmp_path)
    assert run.error is None
    begin = float(job.program.joints[299, 0])
    assert run.executed[0, 0] >= begin - 1e-9
    assert run.executed[0, 0] < begin + 0.002


def test_a_simulated_run_leaves_no_simulated_bus_behind(tmp_path) -> None:
    """The simulated chain a run attached for itself is detached when the run ends: a studio
    drawing again and again does not keep every past bus (and its recorded trace) alive."""
    from sim.dynamixel import transport

    before = transport._attached.names()
    prepare(small_tag()).run(tmp_path)
    assert transport._attached.names() == before


def test_the_executed_trace_spans_the_first_goals_due_time_to_the_streams_end_both_kept(
    small,
) -> None:
    """``executed.csv`` holds the samples from when the first goal sent was due (0 on the
    executed clock) to when the stream ended, both instants included, no sample outside."""
    from tagbot.arm.driver import StreamResult
    from tagbot.arm.run import _executed

    result = StreamResult(start=10.0, lead=0.05, end=12.0)
    t = np.array([9.9, 10.05 - 1e-6, 10.05, 11.0, 12.0, 12.0 + 1e-6])
    trace = np.column_stack([t, np.zeros((6, 2)), np.ones(6)])
    kept = _executed(trace, result, small.program)
    zero = 10.05 - float(small.program.joints[0, 0])
    np.testing.assert_allclose(kept[:, 0], [10.05 - zero, 11.0 - zero, 12.0 - zero])


def test_a_stopped_runs_pen_drew_to_its_sample_at_the_streams_end_on_a_long_running_clock(
    small,
) -> None:
    """After a stop, the pen drew to the program time of its last pen-down sample up to the
    stream's end, that instant included even on a clock 2**24 s (194 days) on, where 1 ns is
    below its resolution; a sample 1 µs after the end is not counted."""
    from tagbot.arm.driver import Scheduler, StreamResult
    from tagbot.arm.run import _drawn_to
    from tagbot.clock import MonotonicClock

    program = small.program
    period = float(program.joints[1, 0] - program.joints[0, 0])
    scheduler = Scheduler(MonotonicClock(), period)
    t0 = scheduler.start(2.0**24)
    lead, end = 0.05, t0 + 0.05 + 0.5
    assert end + 1e-9 == end  # the clock's resolution here
    result = StreamResult(ticks_sent=100, start=t0, end=end, lead=lead, scheduler=scheduler)
    trace = np.column_stack([[end - 0.25, end, end + 1e-6], np.zeros((3, 2)), np.ones(3)])
    until = _drawn_to(trace, result, program)
    assert until == pytest.approx(float(program.joints[0, 0]) + 0.5, abs=1e-6)


def test_joints_csv_holds_every_ticks_goals_under_its_header(tmp_path) -> None:
    """The run folder's joints.csv, written before anything is sent: the header, then one row
    per tick (row k is tick k), time to the microsecond and whole goal ticks."""
    job = prepare(small_tag())

    def progress(done: int, total: int) -> None:  # the file is written before the first tick
        raise ConnectionLost("enough")

    job.run(tmp_path, progress=progress)
    text = (tmp_path / "joints.csv").read_text(encoding="utf-8")
    lines = text.split("\n")
    assert lines[0] == "t,shoulder,elbow,pen" and lines[-1] == "" and "\r" not in text
    rows = [line.split(",") for line in lines[1:-1]]
    joints = job.program.joints
    assert len(rows) == len(job.program) == len(joints)
    for row, (t, shoulder, elbow, pen) in zip(rows, joints, strict=True):
        assert abs(float(row[0]) - t) <= 5e-7 and len(row[0].split(".")[1]) == 6
        assert [int(v) for v in row[1:]] == [shoulder, elbow, pen]


def test_a_horn_below_tick_0_starts_at_its_negative_angle(tmp_path, record) -> None:
    """A servo whose Present Position reads below 0 (a Homing Offset, a horn turned by hand
    past its zero) is read as the signed number the servo holds, as the read-back reads it:
    the warning names the angle where the elbow is, not one four billion ticks away."""
    from tagbot.arm.run import simulated_chain

    profile = load_profile()
    chain = simulated_chain(profile)
    chain.set_position(profile.joints[1].id, -3.0)
    sim = record(chain)
    job = prepare(small_tag(), port=sim.url)

    def progress(done: int, total: int) -> None:  # the warning comes before the first tick
        raise ConnectionLost("enough")

    warnings = job.run(tmp_path, progress=progress).warnings
    assert "elbow starts at -180.3° outside elbow.min_deg..max_deg (10..160°): moving it back" in (
        warnings
    )
