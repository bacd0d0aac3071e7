"""Report figures as a user reads them: shape error, execution comparison keys, summaries."""

from __future__ import annotations

import numpy as np
import pytest

from tagbot.metrics import FitReport, ShapeError, compare_execution, low_pass, shape_error


def _circle(radius: float) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * np.pi, 2001)
    return radius * np.column_stack([np.cos(a), np.sin(a)])


@pytest.mark.parametrize("crowded_first", [True, False])
def test_shape_error_of_a_crowded_scribble_against_a_plain_line(crowded_first: bool) -> None:
    """A thousand circles over one another (crowded: measured through a KD-tree) against one
    circle 1 mm wider (not crowded): every point is 1 mm from the other drawing (chords of
    0.1 mm: 1e-5 mm of sagitta)."""
    crowded = [_circle(50.0)] * 1000
    plain = [_circle(51.0)]
    reference, candidate = (crowded, plain) if crowded_first else (plain, crowded)
    error = shape_error(reference, candidate)
    diagonal = (100.0 if crowded_first else 102.0) * np.sqrt(2.0)
    assert error.size == pytest.approx(diagonal, rel=1e-3)
    assert error.mean * error.size == pytest.approx(1.0, rel=1e-3)
    assert error.max * error.size == pytest.approx(1.0, rel=1e-3)


def _run(t0: float, length: float = 10.0, n: int = 101):
    t = t0 + np.linspace(0.0, 1.0, n)
    xy = np.column_stack([np.linspace(0.0, length, n), np.zeros(n)])
    return t, xy


def test_execution_report_keys_and_values() -> None:
    """A run executed exactly as planned, late by 0.5 s: no deviation, the planned time."""
    planned = [_run(0.0)]
    t, xy = _run(0.5)
    executed = np.column_stack([t, xy, np.ones(len(t))])
    report = compare_execution(planned, executed).as_dict()
    assert set(report) == {
        "path_deviation_mean_mm",
        "path_deviation_max_mm",
        "speed_snr_db",
        "planned_drawing_s",
        "executed_drawing_s",
        "drawing_duration_ratio",
        "pen_down_runs",
        "runs",
    }
    assert report["path_deviation_max_mm"] == pytest.approx(0.0, abs=1e-9)
    assert report["speed_snr_db"] > 40.0
    # A run counts from 0.02 mm into it to 0.02 mm before its end (a sample either side).
    assert report["planned_drawing_s"] == pytest.approx(1.0, abs=0.03)
    assert report["executed_drawing_s"] == pytest.approx(report["planned_drawing_s"], abs=0.02)
    assert report["pen_down_runs"] == {"planned": 1, "executed": 1}
    (run,) = report["runs"]
    assert set(run) == {
        "plan",
        "planned_start",
        "executed_start",
        "planned_duration",
        "executed_duration",
        "speed_snr_db",
        "path_deviation_max_mm",
        "cut_short",
    }
    assert run["plan"] == 0 and run["speed_snr_db"] > 40.0 and run["cut_short"] is False
    assert run["planned_start"] == pytest.approx(0.0)
    assert run["executed_start"] == pytest.approx(0.5, abs=0.02)


def test_an_off_path_run_costs_deviation_and_snr() -> None:
    planned = [_run(0.0)]
    t, xy = _run(0.0)
    xy = xy + np.array([0.0, 0.3])
    report = compare_execution(planned, np.column_stack([t, xy, np.ones(len(t))])).as_dict()
    assert report["path_deviation_max_mm"] == pytest.approx(0.3, abs=1e-6)
    assert report["path_deviation_mean_mm"] == pytest.approx(0.3, abs=1e-6)


@pytest.mark.parametrize(
    ("traces", "points", "strokes", "words"),
    [(1, 1, 1, "1 trace (1 point) -> 1 stroke;"), (2, 30, 5, "2 traces (30 points) -> 5 strokes;")],
)
def test_fit_summary_counts(traces: int, points: int, strokes: int, words: str) -> None:
    report = FitReport(traces, points, strokes, ShapeError(0.01, 0.02, 50.0), 1.0, 12.345)
    assert report.summary() == (
        f"{words} shape error mean 1.00% max 2.00% of 50, velocity SNR 12.3 dB"
    )


@pytest.mark.parametrize(
    ("clock", "trace", "words"),
    [
        (20.04, 15.06, ", velocity SNR 20.0 dB on the tag's clock, 15.1 dB trace by trace"),
        (20.04, None, ", velocity SNR 12.3 dB"),
        (None, 15.06, ", velocity SNR 12.3 dB"),
    ],
)
def test_fit_summary_quotes_the_clock_snrs_only_when_it_has_both(
    clock: float | None, trace: float | None, words: str
) -> None:
    """The tag's-clock and trace-by-trace SNRs are quoted as a pair; with either missing the
    line falls back to the scaled velocity SNR."""
    report = FitReport(
        1,
        2,
        1,
        ShapeError(0.01, 0.02, 50.0),
        1.0,
        12.345,
        velocity_snr_clock_db=clock,
        velocity_snr_trace_db=trace,
    )
    assert (
        report.summary()
        == f"1 trace (2 points) -> 1 stroke; shape error mean 1.00% max 2.00% of 50{words}"
    )


def test_a_run_stopped_before_it_began_is_not_compared() -> None:
    """A stop 2 ms into the second run (a slow one: 0.0002 mm drawn, under the 0.02 mm a run
    needs to start) or on its second sample (0.01 mm): only the first run is compared, and its
    figures are the first run's alone."""
    first, second = _run(0.0), _run(2.0, length=1.0)
    executed = np.vstack(
        [
            np.column_stack([first[0], first[1], np.ones(101)]),
            [[1.5, 10.0, 0.0, 0.0], [1.9, 0.0, 0.0, 0.0]],
            # The pen went down at the second run's start and stayed there 0.1 s.
            np.column_stack([np.linspace(2.0, 2.1, 11), np.zeros((11, 2)), np.ones(11)]),
        ]
    )
    for until in (2.002, 2.01):
        report = compare_execution([first, second], executed, until=until)
        assert report.planned_runs == 1 and len(report.runs) == 1
        assert report.speed_snr_db is not None and report.speed_snr_db > 40.0
    # Cut 0.3 s in (0.3 mm drawn), the second run is compared.
    later = compare_execution([first, second], executed, until=2.3)
    assert later.planned_runs == 2 and len(later.runs) == 2
    # The stop came during the second run, after the first had ended.
    assert [r["cut_short"] for r in later.as_dict()["runs"]] == [False, True]


def test_a_run_the_stop_ends_on_its_last_planned_instant_is_not_cut_short() -> None:
    """A stop exactly when a run's plan ends leaves that run whole; a millisecond earlier, it
    was cut short."""
    run = _run(0.0)
    executed = np.column_stack([run[0], run[1], np.ones(101)])
    (whole,) = compare_execution([run], executed, until=1.0).runs
    (cut,) = compare_execution([run], executed, until=0.999).runs
    assert (whole.cut_short, cut.cut_short) == (False, True)


def test_the_speed_snr_is_a_ratio_free_of_units_and_unbounded_for_an_exact_run() -> None:
    """The speed SNR compares energies: the same runs in metres score what they score in mm,
    and a run executed exactly as planned scores far above any machine's (rounding alone)."""
    t = np.linspace(0.0, 1.0, 201)
    planned = [(t, np.column_stack([10.0 * t**2, 4.0 * np.sin(3.0 * t)]))]
    wobbly = planned[0][1] + np.column_stack([0.05 * np.sin(40.0 * t), np.zeros_like(t)])
    mm = compare_execution(planned, np.column_stack([t, wobbly, np.ones_like(t)]))
    m = compare_execution(
        [(t, planned[0][1] / 1000.0)], np.column_stack([t, wobbly / 1000.0, np.ones_like(t)])
    )
    assert 10.0 < mm.speed_snr_db < 40.0
    assert m.speed_snr_db == pytest.approx(mm.speed_snr_db, abs=1e-6)
    assert m.runs[0].snr_db == pytest.approx(mm.runs[0].snr_db, abs=1e-6)
    line = _run(0.0)
    exact = compare_execution([line], np.column_stack([line[0], line[1], np.ones(101)]))
    assert exact.speed_snr_db > 200.0


@pytest.mark.parametrize("shape", [(4,), (3, 3), (2, 2, 4)])
def test_an_executed_trace_not_n_by_4_is_refused_with_its_shape(shape) -> None:
    from tagbot.metrics import executed_runs

    with pytest.raises(ValueError) as refused:
        executed_runs(np.zeros(shape))
    assert str(refused.value) == f"executed: must be an (N, 4) array t, x, y, pen, got {shape}"


def test_pauses_are_taken_out_of_an_executed_trace_each_at_its_own_time() -> None:
    """Samples every second for 10 s, paused 1 s from 2 s and 2 s from 6 s (executed clock):
    the samples inside each pause go, those after it come back by its length."""
    from tagbot.metrics import without_pauses

    t = np.arange(11.0)
    executed = np.column_stack([t, t * 10, np.zeros(11), np.ones(11)])
    out = without_pauses(executed, [(2.0, 1.0), (6.0, 2.0)])
    kept = [0, 1, 3, 4, 5, 8, 9, 10]
    assert out[:, 1].tolist() == [10.0 * k for k in kept]  # which samples stay
    assert out[:, 0].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]


def _square(half: float) -> np.ndarray:
    return np.array([[-half, -half], [half, -half], [half, half], [-half, half], [-half, -half]])


def test_a_crowded_scribble_is_measured_exactly_against_a_plain_drawing_with_dots() -> None:
    """A thousand squares over one another (crowded: their side of the figures through a
    KD-tree) against a plain drawing, a square 1 mm outside them and dots (single points, four
    at each place) 2 mm inside them every mm along one side. Every scribble point is 1 mm from
    the plain square, however far its nearest plain samples are (the plain drawing is not
    crowded: measured exactly, not near its nearest samples, here dots): the max is the dots'
    2 mm, and the mean is 1 mm but for the plain drawing's few hundred samples (at most 2 mm
    off) among the scribble's 50 000."""
    from tagbot.metrics import DENSITY

    crowded = [_square(49.0)] * 1000
    dots = [np.array([[x, 47.0]]) for x in np.arange(-40.0, 40.5, 1.0) for _ in range(4)]
    error = shape_error(crowded, [_square(50.0), *dots])
    assert error.size == pytest.approx(98.0 * np.sqrt(2.0))
    assert error.max * error.size == pytest.approx(2.0, abs=0.5 / DENSITY * error.size)
    assert 1.0 <= error.mean * error.size < 1.01


def test_a_crowded_scribble_is_measured_near_its_nearest_samples_only() -> None:
    """A thousand squares over one another with corners every 5 mm and dots (four at each
    place) 2 mm inside the bottom side (crowded: measured through a KD-tree of its samples)
    against a square 1 mm outside them with the same dots and dots on the bottom side below
    them, midway between two corners: those dots lie on the scribble but are measured to the
    segments of its nearest samples, its dots 2 mm away, not the side under them (whose
    corners are 2.5 mm away): the max is 2 mm, where all else is at most the corners' √2 mm."""
    from tagbot.metrics import densify

    xs = np.arange(-37.5, 40.0, 10.0)
    inside = [np.array([[x, -48.0]]) for x in xs]
    on_side = [np.array([[x, -50.0]]) for x in xs]
    crowded = [densify(_square(50.0), 5.0)] * 1000 + [dot for dot in inside for _ in range(4)]
    error = shape_error(crowded, [_square(51.0), *inside, *on_side])
    assert error.size == pytest.approx(100.0 * np.sqrt(2.0))
    assert error.max * error.size == pytest.approx(2.0, abs=1e-9)


def test_the_executed_speed_against_the_recorded_one_per_run() -> None:
    """A machine that drew a recording twice as large and twice as slow: time scale 2 (machine
    s per recorded s), the speed followed (the recorded speed scaled by the path lengths' ratio);
    a run whose plan has no timed recording is not compared."""
    from types import SimpleNamespace

    from tagbot.metrics import compare_with_recording

    t = np.linspace(0.0, 1.0, 101)
    along = t - np.sin(2.0 * np.pi * t) / (2.0 * np.pi)  # speed 1 - cos: at rest at both ends
    xy = np.column_stack([30.0 * along, 10.0 * np.sin(np.pi * along)])
    recorded = [SimpleNamespace(xy=xy, t=None), SimpleNamespace(xy=xy, t=t)]
    te = np.linspace(0.0, 2.0, 2001)
    drawn = np.column_stack([np.interp(te / 2.0, t, 2.0 * xy[:, i]) for i in (0, 1)])
    executed = np.vstack(
        [
            np.column_stack([te, drawn, np.ones(len(te))]),  # plan 0: untimed
            [[2.5, 0.0, 0.0, 0.0]],
            np.column_stack([3.0 + te, drawn, np.ones(len(te))]),  # plan 1
        ]
    )
    report = compare_with_recording(executed, recorded, [0, 1])
    (run,) = report["recorded_runs"]
    assert run["plan"] == 1
    assert run["time_scale"] == pytest.approx(2.0, abs=0.005)
    assert run["snr_db"] > 40.0
    assert report["recorded_speed_snr_db"] == pytest.approx(run["snr_db"])


def test_a_fit_report_counts_the_traces_their_points_and_the_strokes() -> None:
    """Two untimed traces of 5 and 7 points, fitted by two one-stroke plans: the report counts
    2 traces, 12 points, 2 strokes, and says so first in its line."""
    from tagbot.metrics import fit_report
    from tagbot.model.plan import Plan, Tag

    one = Plan([[0.0, 0.0], [80.0, 0.0]], [0.0], [np.log(0.3)], [0.35], [0.0], [0.0])
    two = Plan([[0.0, 10.0], [80.0, 10.0]], [0.0], [np.log(0.3)], [0.35], [0.0], [0.0], start=5.0)
    traces = [
        np.column_stack([np.linspace(0.0, 80.0, 5), np.zeros(5)]),
        np.column_stack([np.linspace(0.0, 80.0, 7), np.full(7, 10.0)]),
    ]
    report = fit_report(traces, Tag((one, two)))
    assert (report.traces, report.points, report.strokes) == (2, 12, 2)
    assert report.summary().startswith("2 traces (12 points) -> 2 strokes; shape error mean ")


def test_a_run_is_timed_from_moving_away_from_its_start_to_arriving_near_its_end() -> None:
    """8 mm in 1 s at 8 mm/s, sampled every ms, away from the origin: a run counts from its
    first sample more than 0.02 mm into it (3 ms: 0.024 mm) to its last more than 0.02 mm
    before its end (997 ms), planned and executed alike."""
    t = np.linspace(0.0, 1.0, 1001)
    xy = np.column_stack([100.0 + 8.0 * t, np.full_like(t, 50.0)])
    report = compare_execution([(t, xy)], np.column_stack([t, xy, np.ones_like(t)]))
    assert report.planned_duration == pytest.approx(0.994, abs=1e-9)
    assert report.executed_duration == pytest.approx(0.994, abs=1e-9)


def test_reports_of_a_run_the_stop_came_in_are_cut_short() -> None:
    """Status reports of one run planned over 1 s: a stop at 0.5 s (after the run's second
    setpoint) cuts it short; a stop at its last planned instant does not."""
    from tagbot.metrics import compare_reports

    planned = [_run(0.0)]
    t, xy = _run(0.0, n=6)
    executed = np.column_stack([t, xy, np.ones(len(t))])
    run_of = np.zeros(len(t), dtype=int)
    assert compare_reports(planned, executed, run_of).runs[0].cut_short is False
    assert compare_reports(planned, executed, run_of, until=0.5).runs[0].cut_short is True
    assert compare_reports(planned, executed, run_of, until=1.0).runs[0].cut_short is False


def test_one_report_of_a_run_times_its_start_and_keeps_the_planned_duration() -> None:
    """A run planned over 1 s (10 mm) with one status report, 4 mm along 0.3 s late: the run
    started 0.3 s late and, with nothing to measure a drift by, took its planned time (its
    motion 0.02 mm from either end: 3 ms in from each here, sampled at 1 ms)."""
    from tagbot.metrics import compare_reports

    executed = np.array([[0.7, 4.0, 0.0, 1.0]])
    run = compare_reports([_run(0.0)], executed, np.zeros(1, dtype=int)).runs[0]
    assert run.executed_start == pytest.approx(0.3, abs=1e-9)
    assert run.executed_duration == run.planned_duration == pytest.approx(0.994, abs=1e-9)


def test_a_dot_is_reported_executed_when_its_pen_went_down() -> None:
    """A dot planned at 2 s and drawn from 5 s (the pen down 0.2 s, standing): nothing moves
    to align, so it was executed 3 s late, when its pen went down (not 1 s before, at the
    first offset of the search: every offset matches a standstill alike)."""
    te = 5.0 + np.linspace(0.0, 0.2, 21)
    executed = np.column_stack([te, np.full_like(te, 3.0), np.full_like(te, 4.0), np.ones(21)])
    (run,) = compare_execution([(np.array([2.0]), np.array([[3.0, 4.0]]))], executed).runs
    assert (run.planned_start, run.executed_start) == (2.0, 5.0)


@pytest.mark.parametrize(
    "te",
    [
        np.array([0.0, 0.01, 0.02]),  # 20 ms: under 3·dt
        np.array([0.0, 1.0]),  # a whole second, but two samples
    ],
)
def test_an_executed_run_too_short_for_a_speed_has_no_snr_and_is_placed_by_its_onset(te):
    """Beside a fully drawn run, a second run of which only two or three samples were taken:
    its speed cannot be measured, so it has no speed SNR (not an infinite one) and adds
    nothing to the overall figure; it is placed where its movement began."""
    tp = np.linspace(0.0, 1.0, 101)
    line = np.column_stack([10.0 * tp, np.zeros_like(tp)])  # 10 mm/s
    first = np.column_stack([tp, line, np.ones_like(tp)])
    moved = 3.0 + te
    second = np.column_stack([moved, 0.5 * (moved - 3.0), np.full_like(te, 5.0), np.ones_like(te)])
    gap = np.array([[2.0, 10.0, 0.0, 0.0]])
    executed = np.vstack([first, gap, second])
    planned = [(tp, line), (3.0 + tp, np.column_stack([10.0 * tp, np.full_like(tp, 5.0)]))]
    comparison = compare_execution(planned, executed)
    alone = compare_execution(planned[:1], first)
    whole, short = comparison.runs
    assert short.snr_db is None and np.isfinite(whole.snr_db)
    assert comparison.speed_snr_db == pytest.approx(alone.speed_snr_db)
    assert short.executed_start == pytest.approx(3.0, abs=0.05)  # not a second away


@pytest.mark.parametrize("crowded_first", [True, False])
def test_a_crowded_scribble_far_inside_a_plain_circle_is_measured_exactly(crowded_first) -> None:
    """A hundred circles of radius 10 over one another (crowded) at the centre of a circle of
    radius 200 (plain: measured through its grids, points this far from it through the coarse
    one): every point of either drawing is 190 mm from the other (less the big circle's
    sagitta, 200·(1 − cos(π/2000)) = 0.00025 mm, between its 2000 chords)."""
    crowded = [_circle(10.0)] * 100
    plain = [_circle(200.0)]
    reference, candidate = (crowded, plain) if crowded_first else (plain, crowded)
    error = shape_error(reference, candidate)
    assert error.size == pytest.approx((20.0 if crowded_first else 400.0) * np.sqrt(2.0))
    assert error.mean * error.size == pytest.approx(190.0, abs=0.0003)
    assert error.max * error.size == pytest.approx(190.0, abs=0.0003)


def test_low_pass_smooths_four_rows_and_leaves_three() -> None:
    """Four rows are enough to filter (a zig-zag at the Nyquist frequency, far above the 5 Hz
    cut-off, straightens out); three rows come back unchanged."""
    zigzag = np.array([0.0, 1.0, 0.0, 1.0])
    smooth = low_pass(zigzag, 0.01, 5.0)
    assert np.abs(np.diff(zigzag, 2)).max() == 2.0
    assert np.abs(np.diff(smooth, 2)).max() < 0.05
    assert smooth.mean() == pytest.approx(0.5, abs=0.05)
    np.testing.assert_array_equal(low_pass(zigzag[:3], 0.01, 5.0), zigzag[:3])


def test_the_shared_clock_speed_snr_counts_the_recording_past_the_model_end_as_noise() -> None:
    """A pen moving at 3 mm/s for 2 s against a model that moves so for only its first second:
    after the model's end it is at rest, so the second half is all noise (201 / 100 in energy)."""
    from tagbot.metrics import clock_velocity_snr

    t = np.linspace(0.0, 2.0, 201)
    xy = np.column_stack([3.0 * t, np.zeros_like(t)])
    model_t = np.linspace(0.0, 1.0, 11)
    model_v = np.column_stack([np.full(11, 3.0), np.zeros(11)])
    snr = clock_velocity_snr(t, xy, model_t, model_v, None)
    assert snr == pytest.approx(10.0 * np.log10(201.0 / 100.0), rel=1e-9)
