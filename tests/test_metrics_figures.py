"""Report figures computed independently in the test: pen-down paths, timing summaries, the
velocity SNR on a shared clock and on the tag's clock at the edge of its reach (issue 34)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tagbot.gesture.timing import simulated_capture
from tagbot.inputs import Trace
from tagbot.metrics import (
    CLOCK_REACH,
    VELOCITY_CUTOFF,
    clock_velocity_snr,
    compare_execution,
    densify,
    pen_down_paths,
    recorded_velocity,
    tag_clock_snr,
    timing_summary,
)
from tagbot.model.motion import evaluate_plan, sample
from tagbot.model.plan import Plan, Tag, random_timed_plan


def _line(x0: float, start: float) -> Plan:
    """A straight 40 mm stroke from (x0, 0), starting at ``start``."""
    return Plan([[x0, 0.0], [x0 + 40.0, 0.0]], [0.0], [np.log(0.2)], [0.3], [0.0], [0.0], start)


def test_pen_down_paths_are_the_motions_pen_down_samples_run_by_run() -> None:
    """Each polyline is the positions of one run of consecutive samples of one plan."""
    first = _line(0.0, 0.0)
    tag = Tag([first, _line(100.0, first.end(140.0) + 0.2)])
    motion = sample(tag, 0.01)
    expected: list[list[np.ndarray]] = []
    previous = -1
    for xy, plan in zip(motion.xy, motion.plan, strict=True):
        if plan >= 0:
            if plan != previous:
                expected.append([])
            expected[-1].append(xy)
        previous = plan
    paths = pen_down_paths(motion)
    assert len(paths) == 2
    for path, points in zip(paths, expected, strict=True):
        assert path.dtype == np.float64 and path.shape == (len(points), 2)
        np.testing.assert_array_equal(path, np.array(points))
    assert paths[0][0] == pytest.approx([0.0, 0.0]) and paths[1][-1][0] > 139.0


def test_timing_summary_counts_each_kind_in_first_seen_order() -> None:
    timings = [SimpleNamespace(kind=k) for k in ("matched", "scaled", "matched", "shape")]
    assert timing_summary(timings) == "2 matched, 1 scaled, 1 shape"
    assert timing_summary(["kept", "kept"]) == "2 kept"  # no kind: the value as text
    assert timing_summary([]) is None and timing_summary(None) is None


def test_densify_returns_float_points_even_for_one_integer_point() -> None:
    single = densify([[1, 2]], 0.5)
    assert single.dtype == np.float64 and single.tolist() == [[1.0, 2.0]]
    line = densify([[0, 0], [1, 0]], 0.25)
    np.testing.assert_allclose(line, [[0, 0], [0.25, 0], [0.5, 0], [0.75, 0], [1, 0]])


def _noisy_capture() -> tuple[Plan, Trace]:
    rng = np.random.default_rng(7)
    plan = random_timed_plan(rng)
    return plan, simulated_capture(plan, rng, noise=0.3)


@pytest.mark.parametrize("cutoff", [VELOCITY_CUTOFF, 5.0, None])
def test_clock_velocity_snr_is_the_energy_ratio_at_the_cutoff_asked(cutoff: float | None) -> None:
    """The recording's velocity at ``cutoff`` (None: raw differences) against the model's on the
    same instants: 10·log10(Σ|v|² / Σ|v − v_model|²)."""
    plan, trace = _noisy_capture()
    model_t = plan.start + 0.001 * np.arange(int(plan.end(100.0) / 0.001) + 2)
    _, model_v = evaluate_plan(plan, model_t, 100.0)
    grid, v = recorded_velocity(trace.t, trace.xy, cutoff=cutoff)
    vm = np.column_stack([np.interp(grid, model_t, model_v[:, i], 0.0, 0.0) for i in (0, 1)])
    expected = 10 * np.log10(np.sum(v * v) / np.sum((v - vm) ** 2))
    got = clock_velocity_snr(trace.t, trace.xy, model_t, model_v, cutoff)
    assert got == pytest.approx(expected, rel=1e-12)


def test_clock_velocity_snr_of_raw_differences_is_lower_on_a_noisy_capture() -> None:
    plan, trace = _noisy_capture()
    model_t = plan.start + 0.001 * np.arange(int(plan.end(100.0) / 0.001) + 2)
    _, model_v = evaluate_plan(plan, model_t, 100.0)
    filtered = clock_velocity_snr(trace.t, trace.xy, model_t, model_v)
    raw = clock_velocity_snr(trace.t, trace.xy, model_t, model_v, None)
    assert filtered > raw + 3.0


@pytest.mark.parametrize("early", [0.3, -0.3])
def test_tag_clock_snr_beyond_its_reach_is_the_figure_at_the_reach(early: float) -> None:
    """A trace stamped 0.3 s early (late) is compared at the largest offset searched,
    +CLOCK_REACH (−CLOCK_REACH), 50 ms short of its own: the figure is the energy ratio of the
    recorded velocity against the model's at the recorded instants shifted by that much, both
    figures alike (one trace)."""
    rng = np.random.default_rng(3)
    plan = random_timed_plan(rng)
    capture = simulated_capture(plan, rng, noise=0.0)
    trace = Trace(capture.xy, capture.t - early)
    tag = Tag([plan])
    grid, v = recorded_velocity(trace.t, trace.xy, cutoff=VELOCITY_CUTOFF)
    _, model_v = evaluate_plan(plan, grid + np.sign(early) * CLOCK_REACH, tag.size)
    expected = 10 * np.log10(np.sum(v * v) / np.sum((v - model_v) ** 2))
    clock, each = tag_clock_snr([trace], tag)
    assert expected < 10.0  # 50 ms off: a poor match, but the best within reach
    assert clock == pytest.approx(expected, abs=1e-6)
    assert each == pytest.approx(expected, abs=1e-6)


def _planned_line(t0: float, y: float) -> tuple[np.ndarray, np.ndarray]:
    """10 mm along x at 10 mm/s from ``t0``, standing 0.2 s at x = 4 (1.2 s in all), every 10 ms."""
    tp = t0 + np.linspace(0.0, 1.2, 121)
    x = 10 * np.clip(tp - t0, 0.0, 0.4) + 10 * np.clip(tp - t0 - 0.6, 0.0, None)
    return tp, np.column_stack([x, np.full(len(tp), y)])


def _reports() -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray, np.ndarray]:
    """Reports of a machine 0.3 s late and 10 % slow on run 0 (x → planned instant x/10, or
    x/10 + 0.2 past the standstill at x = 4; executed 0.3 + 1.1·planned), off the path by
    ``y``; on run 1 only reports where it stood at its start; none on run 2."""
    planned = [_planned_line(0.0, 0.0), _planned_line(2.0, 10.0), _planned_line(4.0, 20.0)]
    rows = [  # t, x, y, pen, run
        (0.0, 0.01, 0.0, 1, 0),  # within MOVED of the start: the pen going down
        (0.2, 1.0, 0.01, 1, 0),  # the same position twice: the machine stood
        (0.41, 1.0, 0.01, 1, 0),
        (0.52, 2.0, 0.02, 1, 0),  # planned 0.2
        (0.6, 50.0, 50.0, 0, 0),  # pen up: not part of the run
        (0.63, 3.0, -0.03, 1, 0),  # planned 0.3
        (0.7, 50.0, 50.0, 1, -1),  # no run
        (0.74, 4.0, 0.04, 1, 0),  # planned 0.4: where the standstill begins
        (1.07, 5.0, 0.05, 1, 0),  # planned 0.7
        (1.29, 7.0, 0.06, 1, 0),  # planned 0.9
        (1.51, 9.0, 0.0, 1, 0),  # planned 1.1
        (1.6, 9.995, 0.0, 1, 0),  # within MOVED of the end: the pen going up
        (2.5, 0.0, 10.0, 1, 1),  # run 1: standing at its start only
        (2.6, 0.0, 10.0, 1, 1),
    ]
    table = np.array(rows, dtype=float)
    return planned, table[:, :4], table[:, 4].astype(int)


def test_compare_reports_times_only_reports_that_move_along_the_plan() -> None:
    from tagbot.metrics import SPARSE_SNR_NOTE, compare_reports

    planned, executed, run_of = _reports()
    report = compare_reports(planned, executed, run_of, plans=[3, 7, 9])
    lags = 0.3 + 0.1 * np.array([0.2, 0.3, 0.4, 0.7, 0.9, 1.1])  # the timed reports' offsets
    first, second = report.runs
    assert (first.plan, second.plan) == (3, 7)
    assert (first.planned_start, second.planned_start) == (0.0, 2.0)
    assert first.executed_start == pytest.approx(np.median(lags), abs=1e-9)
    assert first.planned_duration == pytest.approx(1.2 - 0.004, abs=0.002)  # 0.02 mm in, out
    drift = lags[-1] - lags[0]
    assert first.executed_duration - first.planned_duration == pytest.approx(drift, abs=1e-9)
    # Run 1 has no report that times anything: all of its reports time it.
    assert second.executed_start == pytest.approx(2.0 + 0.55, abs=1e-9)
    assert second.executed_duration - second.planned_duration == pytest.approx(0.1, abs=1e-9)
    # Distances to the path densified every 5 µm (``spacing``): within 2.5 µm of the exact ones.
    deviations = [0.0, 0.01, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.0, 0.0, 0.0, 0.0]
    assert report.deviation_mean == pytest.approx(np.mean(deviations), abs=0.0025)
    assert report.deviation_max == pytest.approx(0.06, abs=0.0025)
    assert report.planned_duration == first.planned_duration + second.planned_duration
    assert report.executed_duration == first.executed_duration + second.executed_duration
    assert (report.planned_runs, report.executed_runs) == (3, 2)
    assert report.speed_snr_db is None and report.speed_snr_note == SPARSE_SNR_NOTE
    d = report.as_dict()
    assert d["speed_snr_db"] is None and d["speed_snr_note"] == SPARSE_SNR_NOTE
    assert d["pen_down_runs"] == {"planned": 3, "executed": 2}
    assert d["drawing_duration_ratio"] == pytest.approx(
        report.executed_duration / report.planned_duration, rel=1e-12
    )
    assert [r["plan"] for r in d["runs"]] == [3, 7]
    assert all(
        r["speed_snr_db"] is None and np.isnan(r["path_deviation_max_mm"]) for r in d["runs"]
    )


def test_compare_reports_refuses_what_it_cannot_compare() -> None:
    from tagbot.metrics import compare_reports

    planned, executed, run_of = _reports()
    with pytest.raises(ValueError, match=r"^compare_reports: one run index per executed row$"):
        compare_reports(planned, executed, run_of[:-1])
    with pytest.raises(ValueError, match=r"^compare_reports: no report while the pen was down$"):
        compare_reports(planned, executed, np.full(len(run_of), -1))
    pen_up = executed.copy()
    pen_up[:, 3] = 0.5  # half way is not down
    with pytest.raises(ValueError, match=r"^compare_reports: no report while the pen was down$"):
        compare_reports(planned, pen_up, run_of)


@pytest.mark.parametrize("setpoints", [2, 3, 11])
def test_a_straight_run_has_its_speed_however_few_its_setpoints(setpoints: int) -> None:
    """One straight line at 10 mm/s, planned as two setpoints (one line) or more, drawn exactly
    as planned: the planned velocity is the line's, so the speed SNR is high (two setpoints
    used to count as standing still: -inf dB)."""
    tp = np.linspace(0.0, 1.0, setpoints)
    xyp = np.column_stack([10 * tp, np.zeros(setpoints)])
    te = np.linspace(0.0, 1.0, 1001)
    executed = np.column_stack([te, 10 * te, np.zeros_like(te), np.ones_like(te)])
    report = compare_execution([(tp, xyp)], executed)
    assert report.speed_snr_db > 40.0 and report.runs[0].snr_db == report.speed_snr_db
    assert report.deviation_max <= 0.0025  # to the path densified every 5 µm


def test_a_dot_planned_as_one_setpoint_is_reported() -> None:
    """A dot: one planned setpoint, the pen down and standing there; nothing moves either way."""
    te = np.linspace(0.0, 0.2, 21)
    executed = np.column_stack([te, np.full_like(te, 3.0), np.full_like(te, 4.0), np.ones_like(te)])
    report = compare_execution([(np.array([0.0]), np.array([[3.0, 4.0]]))], executed)
    assert report.deviation_max == 0.0 and report.deviation_mean == 0.0
    # Nothing moves: a run's time is then from its first sample to its last.
    assert report.planned_duration == 0.0
    assert report.executed_duration == pytest.approx(0.2, abs=1e-12)
    assert (report.planned_runs, report.executed_runs) == (1, 1)
