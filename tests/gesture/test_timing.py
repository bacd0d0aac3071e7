"""Timing-aware reconstruction (tagbot.gesture.timing): synthetic timed plans, real clocks."""

from __future__ import annotations

from importlib.resources import files

import numpy as np
import pytest

from tagbot.errors import PlanError
from tagbot.gesture import fit
from tagbot.gesture.timing import (
    MIN_SAMPLES,
    TimingOptions,
    fit_cost,
    match_trace,
    resample,
    simulated_capture,
    usable,
)
from tagbot.inputs import Trace, load_traces, read_gml
from tagbot.metrics import (
    clock_velocity_snr,
    fit_report,
    ink_polyline,
    shape_error,
    stroke_report,
    velocity_snr,
)
from tagbot.model.motion import sample_plan
from tagbot.model.plan import Plan, Tag, random_timed_plan


def gml(*strokes: list[tuple[float, float, float]]) -> bytes:
    """A GML file with one drawing per stroke of ``(x, y, time)`` points."""
    drawings = "".join(
        "<drawing><stroke>"
        + "".join(f"<pt><x>{x!r}</x><y>{y!r}</y><time>{t!r}</time></pt>" for x, y, t in points)
        + "</stroke></drawing>"
        for points in strokes
    )
    return f"<gml><tag>{drawings}</tag></gml>".encode()


def figures(traces: list[Trace], tag: Tag) -> tuple[float, float]:
    """Velocity SNR (dB, against the low-pass reference) after the best uniform time mapping,
    and mean shape error (fraction of the diagonal), as :func:`fit_report` gives them. Per
    trace, the best mapping is never below the shared clock (scale 1, offset 0)."""
    report = fit_report(traces, tag)
    assert report.velocity_snr_db is not None
    for k, trace in enumerate(traces):
        t, _, v = sample_plan(tag, k, 0.005)
        best, _, _ = velocity_snr(trace.t, trace.xy, t, v)
        assert best >= clock_velocity_snr(trace.t, trace.xy, t, v) - 1e-9
    return report.velocity_snr_db, report.shape.mean


def test_synthetic_timed_plans_are_matched() -> None:
    """Random plans, random per-stroke timing, 100 Hz stamped by a 1 ms clock (±0.5 ms of
    timestamp noise) and 0.02 mm of position noise: velocity SNR ≥ 25 dB (median), shape
    error ≤ 0.5 % of the diagonal each; the geometric fit misses the speed by far."""
    rng = np.random.default_rng(16)
    snr, snr_ignored, shape = [], [], []
    for _ in range(8):
        trace = simulated_capture(random_timed_plan(rng), rng)
        matched = fit([trace], timing="match")
        db, error = figures([trace], matched)
        snr.append(db)
        shape.append(error)
        snr_ignored.append(figures([trace], fit([trace], timing="ignore"))[0])
    assert np.median(snr) >= 25.0, snr
    assert max(shape) <= 0.005, shape
    assert np.median(snr) >= np.median(snr_ignored) + 10.0


def test_match_trace_puts_a_geometric_plan_on_the_traces_clock() -> None:
    """One trace of a random timed plan stamped from 5 s: ``match_trace`` refits its geometric
    plan (start 0) to the recorded speed, on the trace's clock counted from that first
    timestamp, which it returns; the geometric plan misses the speed, the ink keeps the shape."""
    rng = np.random.default_rng(2)
    capture = simulated_capture(random_timed_plan(rng), rng)
    trace = Trace(capture.xy, capture.t + 5.0)
    geometric = fit([trace], timing="ignore")
    plan = geometric.plans[0]
    timed, t0 = match_trace(plan, trace, geometric.size, "sigma", TimingOptions())
    assert t0 == pytest.approx(5.0, abs=1e-9)
    db = []
    for p in (plan, timed):
        t, _, v = sample_plan(Tag((p,)), 0, 0.005)
        db.append(clock_velocity_snr(trace.t - t0, trace.xy, t, v))
    assert db[0] < 5.0 and db[1] >= 20.0, db
    assert shape_error([trace.xy], [ink_polyline(timed, geometric.size)]).mean <= 0.005


def test_match_trace_keeps_strokes_in_the_air_where_the_pen_touched_down_moving() -> None:
    """A capture of the middle 80 % of a timed plan's path, stamped from 3 s: ``match_trace``
    returns the plan with strokes in the air, inked exactly over the recorded span on the
    trace's clock from its first timestamp."""
    rng = np.random.default_rng(21)
    full = simulated_capture(random_timed_plan(rng), rng)
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(full.xy, axis=0).T))]
    keep = (s >= 0.1 * s[-1]) & (s <= 0.9 * s[-1])
    trace = Trace(full.xy[keep], full.t[keep] + 3.0)
    geometric = fit([trace], timing="ignore")
    timed, t0 = match_trace(geometric.plans[0], trace, geometric.size, "sigma", TimingOptions())
    assert t0 == trace.t[0]
    assert timed.moving_ends(geometric.size) == (True, True)
    assert timed.ink_window(geometric.size) == pytest.approx((0.0, trace.t[-1] - t0))


def test_ignore_is_the_geometric_fit_exactly() -> None:
    """``ignore`` (and ``auto`` on untimed traces) gives today's result: timestamps unused."""
    rng = np.random.default_rng(3)
    trace = simulated_capture(random_timed_plan(rng), rng)
    today = fit([Trace(trace.xy)])
    for tag in (fit([trace], timing="ignore"), fit([Trace(trace.xy)], timing="auto")):
        assert len(tag.plans) == len(today.plans)
        for a, b in zip(tag.plans, today.plans, strict=True):
            for name in ("targets", "dt", "mu", "sigma", "phi1", "phi2"):
                assert np.array_equal(getattr(a, name), getattr(b, name)), name
            assert a.start == b.start


def test_auto_matches_plausible_timing_only() -> None:
    rng = np.random.default_rng(5)
    trace = simulated_capture(random_timed_plan(rng), rng)
    assert usable(trace)
    auto = fit([trace])
    matched = fit([trace], timing="match")
    assert np.array_equal(auto.plans[0].mu, matched.plans[0].mu)
    sparse = Trace(trace.xy[::40], trace.t[::40])  # 2.5 Hz: not a sampled pen
    assert not usable(sparse)
    assert np.array_equal(fit([sparse]).plans[0].mu, fit([sparse], timing="ignore").plans[0].mu)


def test_match_needs_timestamps_and_a_known_mode() -> None:
    with pytest.raises(PlanError, match="timing: 'match' needs timestamps"):
        fit([np.array([[0.0, 0.0], [10.0, 5.0], [20.0, 0.0]])], timing="match")
    with pytest.raises(PlanError, match="timing: must be"):
        fit([np.array([[0.0, 0.0], [10.0, 5.0]])], timing="fast")  # type: ignore[arg-type]


def _quirky(trace: Trace, rng: np.random.Generator, quirk: str) -> Trace:
    t, xy = trace.t.copy(), trace.xy.copy()
    if quirk == "repeated":  # events delivered in bursts: pairs share a stamp
        t[1::2] = t[0:-1:2]
    elif quirk == "dropped":  # a tenth of the samples lost, and a 60 ms burst
        keep = rng.uniform(size=t.size) > 0.1
        keep[t.size // 2 : t.size // 2 + 6] = False
        keep[[0, -1]] = True
        t, xy = t[keep], xy[keep]
    elif quirk == "stall":  # the pen rests 0.8 s mid-way: no events while it does not move
        i = t.size // 2
        t = np.r_[t[:i], t[i:] + 0.8]
    elif quirk == "jitter":  # 4 ms of timestamp noise
        t = np.maximum.accumulate(t + rng.normal(0.0, 0.004, t.size))
        t -= t[0]
    return Trace(xy, t)


@pytest.mark.parametrize("quirk", ["repeated", "dropped", "stall", "jitter"])
def test_real_clock_quirks(quirk: str) -> None:
    """Repeated stamps, dropped samples, a stall and heavy jitter: the shape stays within 0.5 %
    and the velocity is far closer to the recording than the geometric fit's, at 15 dB or
    within 1 dB of the true plan's own SNR (noisy stamps cap what any model scores)."""
    rng = np.random.default_rng(11)
    plan = random_timed_plan(rng)
    trace = _quirky(simulated_capture(plan, rng), rng, quirk)
    db, error = figures([trace], fit([trace], timing="match"))
    ignored, _ = figures([trace], fit([trace], timing="ignore"))
    truth, _ = figures([trace], Tag((plan,)))
    assert error <= 0.005
    assert db >= min(15.0, truth - 1.0) and db >= ignored + 5.0, (db, ignored, truth)


def test_restarted_clock_in_a_gml_file() -> None:
    """Two strokes, the second's clock restarting at 0 (EyeWriter): chained by the reader, then
    matched; plans start on the recorded clock, one after another."""
    rng = np.random.default_rng(2)
    first, second = (simulated_capture(random_timed_plan(rng), rng) for _ in range(2))
    strokes = []
    for trace in (first, second):
        xy = trace.xy / 400.0 + 0.3
        strokes.append(
            [(float(x), float(1 - y), float(t)) for (x, y), t in zip(xy, trace.t, strict=True)]
        )
    traces = read_gml(gml(*strokes))
    assert traces[1].t[0] == pytest.approx(traces[0].t[-1])  # chained, not overlapping
    tag = fit(traces, timing="match")
    lift = tag.plans[1].ink_window(tag.size)[0] - tag.plans[0].ink_window(tag.size)[1]
    assert lift >= TimingOptions().min_lift - 1e-9  # one after another
    assert tag.plans[0].start == pytest.approx(0.0, abs=0.3)
    db, error = figures(traces, tag)
    assert error <= 0.005 and db >= 20.0


def test_resampling_never_trusts_a_single_sample() -> None:
    """One sample 8 ms late (a clock glitch) moves the resampled velocity much less than it
    moves the velocity of raw differences."""
    t = np.arange(0.0, 1.0, 0.01)
    xy = np.column_stack([100 * t, np.zeros_like(t)])
    glitched = t.copy()
    glitched[50] += 0.008
    options = TimingOptions()
    clean, bad = resample(t, xy, options), resample(glitched, xy, options)
    inside = (clean.t > 0.1) & (clean.t < 0.9)
    smoothed = np.max(np.abs(bad.v[inside, 0] - clean.v[inside, 0]))
    raw = np.max(np.abs(np.diff(xy[:, 0]) / np.diff(glitched) - 100.0))
    assert smoothed < 0.25 * raw


def test_per_stroke_figures_cover_every_stroke() -> None:
    rng = np.random.default_rng(8)
    trace = simulated_capture(random_timed_plan(rng), rng)
    tag = fit([trace], timing="match")
    rows = stroke_report([trace], tag)
    assert [(r.plan, r.stroke) for r in rows] == [(0, j) for j in range(tag.n_strokes)]
    snr = [r.velocity_snr_db for r in rows if r.velocity_snr_db is not None]
    assert len(snr) >= tag.n_strokes - 1 and np.median(snr) >= 20.0
    assert all(r.shape_error is None or r.shape_error < 0.01 for r in rows)


SHIPPED_SNR_FLOOR = 16.0
"""Velocity SNR (dB, against the low-pass reference) the shipped DustTag example must reach
with ``timing="match"`` (20.3 dB; the geometric fit reaches 14.2 dB there; real 180 Hz touch
data with repeated stamps)."""


def test_shipped_timed_example_reaches_its_floor() -> None:
    traces = load_traces(files("tagbot") / "examples" / "dusttag-142.json")
    tag = fit(traces, timing="match")
    db, error = figures(traces, tag)
    assert db >= SHIPPED_SNR_FLOOR
    assert error <= 0.005
    assert tag.n_strokes <= 1.5 * fit(traces, timing="ignore").n_strokes


def test_a_drawn_timed_fit_keeps_the_recorded_rhythm(tmp_path) -> None:
    """On the simulated plotter, the executed speed of a timed fit follows the *recorded* one
    up to each run's time scale (14.9 dB; the geometric fit's 12.7 dB), per run in the report.
    Short runs that touch down moving cost most: a plotter eases from rest there."""
    from tagbot.draw import draw

    traces = load_traces(files("tagbot") / "examples" / "dusttag-142.json")
    report = draw(fit(traces, timing="match"), tmp_path, pictures=False, recorded=traces).report
    runs = report["recorded_runs"]
    assert [r["plan"] for r in runs] == list(range(len(traces)))
    assert all(r["time_scale"] > 1.0 for r in runs)  # the plotter is slower than a hand
    assert report["recorded_speed_snr_db"] >= 14.5
    geometric = draw(fit(traces, timing="ignore"), tmp_path / "geometric", pictures=False,
                     recorded=traces).report  # fmt: skip
    assert report["recorded_speed_snr_db"] >= geometric["recorded_speed_snr_db"] + 2.0


def test_a_timed_fit_keeps_its_rhythm_in_a_plan_file(tmp_path) -> None:
    from tagbot.io.planfile import load_plan, save_plan

    traces = load_traces(files("tagbot") / "examples" / "dusttag-142.json")
    tag = fit(traces, timing="match")
    save_plan(tag, tmp_path / "tag.json")
    again = load_plan(tmp_path / "tag.json")
    for a, b in zip(tag.plans, again.plans, strict=True):
        assert a.start == b.start
        assert np.allclose(a.onsets, b.onsets, rtol=0, atol=1e-12)
        assert np.array_equal(a.mu, b.mu) and np.array_equal(a.sigma, b.sigma)
    # The pen touches down when the trace was recorded (pen lifts kept), give or take the
    # lognormal's lead before visible motion.
    for plan, trace in zip(tag.plans, traces, strict=True):
        assert trace.t[0] - 0.1 <= plan.ink_window(tag.size)[0] <= trace.t[0] + 0.01


def test_per_stroke_figures_without_timing_have_shape_only() -> None:
    rng = np.random.default_rng(9)
    trace = simulated_capture(random_timed_plan(rng), rng)
    untimed = Trace(trace.xy)
    rows = stroke_report([untimed], fit([untimed]))
    assert rows and all(r.velocity_snr_db is None for r in rows)
    assert any(r.shape_error is not None for r in rows)


def test_plans_chained_at_zero_lift_still_sample() -> None:
    """A trace recorded right as the previous one ends (a restarted clock chained at zero lift)
    touches down a short lift after the previous plan lifts off, so the tag samples at 10 ms."""
    rng = np.random.default_rng(4)
    first, second = (simulated_capture(random_timed_plan(rng), rng) for _ in range(2))
    later = Trace(second.xy + 60.0, second.t + first.t[-1])
    tag = fit([first, later], timing="match")
    gap = tag.plans[1].ink_window(tag.size)[0] - tag.plans[0].ink_window(tag.size)[1]
    assert gap >= TimingOptions().min_lift - 1e-9
    motion = tag.sample(0.01)
    assert len(list(motion.runs())) == 2


def _truth_figures(trace: Trace, plan: Plan) -> tuple[float, float]:
    """The true plan's velocity SNR on the shared clock against the low-pass reference and
    against the raw differences of ``trace``."""
    t, _, v = sample_plan(Tag((plan,)), 0, 0.005)
    return (
        clock_velocity_snr(trace.t, trace.xy, t, v),
        clock_velocity_snr(trace.t, trace.xy, t, v, cutoff=None),
    )


def test_touch_screen_captures_are_matched_against_the_writers_velocity() -> None:
    """Random timed plans recorded as a 60 Hz touch screen does (0.3 mm pixels, 2 ms of stamp
    jitter on a 1 ms clock): the low-pass reference gives the true plans >= 21.5 dB (median
    22.5; the raw differences 18.3 dB: digitiser noise, not the writer's movement), and the
    timed fit reaches >= 20 dB against it (23.4), shape error <= 0.5 %."""
    rng = np.random.default_rng(60)
    truth_lp, truth_raw, snr = [], [], []
    for _ in range(6):
        plan = random_timed_plan(rng)
        trace = simulated_capture(plan, rng, rate=60.0, jitter=0.002, noise=0.0, pixel=0.3)
        lp, raw = _truth_figures(trace, plan)
        truth_lp.append(lp)
        truth_raw.append(raw)
        db, error = figures([trace], fit([trace], timing="match"))
        snr.append(db)
        assert error <= 0.005
    assert np.median(truth_lp) >= 21.5, truth_lp
    assert np.median(truth_lp) >= np.median(truth_raw) + 3.0, (truth_lp, truth_raw)
    assert np.median(snr) >= 20.0, snr


def test_a_stroke_is_added_where_the_plan_misses_a_bump_without_a_dip() -> None:
    """Two overlapping strokes along a line make one speed hump with a shoulder, no dip: a plan
    of one stroke misses the shoulder, and the stroke is split there, a new target between."""
    from tagbot.gesture.strokes import Strokes
    from tagbot.gesture.timing import _dips, _split

    mu, sigma = np.log([0.2, 0.15]), np.array([0.3, 0.25])
    true = Plan([[0.0, 0.0], [50.0, 0.0], [80.0, 0.0]], [0.0, 0.1], mu, sigma, [0, 0], [0, 0])
    options = TimingOptions()
    rec = resample(*_stamped(true), options)
    speed = np.hypot(*rec.v.T)
    reach = max(2, round(options.dip_reach / float(rec.t[1] - rec.t[0])))
    assert _dips(speed, reach, options.dip_depth, 0.1 * float(speed.max())).size == 0
    one = Plan([[0.0, 0.0], [80.0, 0.0]], [0.0], [np.log(0.3)], [0.35], [0.0], [0.0])
    split = _split(Strokes.of([one]), rec, 80.0, options, room=2)
    assert split is not None and len(split.onsets) == 2
    assert 30.0 < split.targets[1, 0] < 75.0 and abs(split.targets[1, 1]) < 1.0


def _stamped(plan: Plan) -> tuple[np.ndarray, np.ndarray]:
    """``plan`` sampled every 10 ms: times and positions."""
    t, xy, _ = sample_plan(Tag((plan,)), 0, 0.01)
    return t, xy


def test_a_writer_touching_down_and_lifting_off_moving_is_matched_in_the_air() -> None:
    """Captures of the middle 80 % of random timed plans' paths (the pen touched down and lifted
    off moving): the timed fit adds strokes in the air before and after, whose ink window is
    exactly the recorded span, and follows the recorded speed far better than plans that start
    and end at rest; the ink keeps to the shape."""
    rng = np.random.default_rng(21)
    gains, lifted = [], 0
    for _ in range(6):
        full = simulated_capture(random_timed_plan(rng), rng)
        s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(full.xy, axis=0).T))]
        keep = (s >= 0.1 * s[-1]) & (s <= 0.9 * s[-1])
        trace = Trace(full.xy[keep], full.t[keep])
        air = fit([trace], timing="match")
        rest = fit([trace], timing="match", timing_options=TimingOptions(air_speed=None))
        at_rest = rest.sample(0.002)
        assert at_rest.speed[at_rest.pen == 1][0] < 0.2 * at_rest.speed.max()
        (db_air, shape), (db_rest, _) = figures([trace], air), figures([trace], rest)
        assert shape <= 0.005 and db_air >= db_rest - 1e-9
        gains.append(db_air - db_rest)
        plan = air.plans[0]
        motion = air.sample(0.002)
        if motion.speed[motion.pen == 1][0] > 0.2 * motion.speed.max():  # strokes in the air
            lifted += 1
            assert plan.moving_ends(air.size)[0]
            assert plan.ink_window(air.size) == pytest.approx((trace.t[0], trace.t[-1]))
    assert lifted >= 4 and np.median(gains) >= 3.0, gains


def test_the_jacobian_matches_finite_differences_with_every_penalty_active() -> None:
    """The solver's Jacobian (exact for onsets, mu, sigma and targets; tangents by central
    differences) equals finite differences of its residuals, with a stroke too short for the
    grid (the extent floor active) and one outlasting the recording (the tail penalty). Known
    approximations: entries where a stroke is within ``JACOBIAN_TAIL`` of not started or done
    are left out (under 1 % of a column's largest), and the penalties' rows hold only the
    timing's columns (the tail's budget also moves a little with the geometry)."""
    from tagbot.gesture.strokes import Strokes
    from tagbot.gesture.timing import _Fit

    true = Plan(
        [[0.0, 0.0], [40.0, 10.0], [70.0, -5.0], [90.0, 20.0]],
        [0.0, 0.15, 0.2],
        np.log([0.2, 0.15, 0.25]),
        [0.3, 0.25, 0.3],
        [0.3, -0.2, 0.4],
        [-0.1, 0.5, 0.2],
    )
    rec = resample(*_stamped(true), TimingOptions())
    # Stroke 1 is a 7 ms pulse (below 3 grid steps); stroke 2 ends long after the recording.
    guess = Plan(true.targets, [0.0, 0.2, 0.2], np.log([0.2, 0.02, 0.9]), [0.3, 0.1, 0.5],
                 true.phi1, true.phi2)  # fmt: skip
    problem = _Fit(Strokes.of([guess]), rec, 95.0, False, TimingOptions())
    x = problem.pack(Strokes.of([guess]))
    r, jac = problem.evaluate(x, True)
    assert jac is not None
    rows, cols, vals, _ = jac
    exact = np.zeros((r.size, x.size))
    np.add.at(exact, (rows, cols), vals)
    trajectory = 4 * len(rec.t) + 2 * problem.interior  # velocity, position and pull rows
    tail, short = trajectory + np.arange(problem.n), trajectory + problem.n + np.arange(problem.n)
    assert r[tail[2]] > 0 and r[short[1]] > 0 and r[short[0]] == 0  # both penalties active
    timing = np.concatenate([problem.column + k for k in range(3)])
    for c in range(x.size):
        step = np.zeros(x.size)
        step[c] = 1e-6 * max(1.0, abs(x[c]))
        up, _ = problem.evaluate(x + step, False)
        down, _ = problem.evaluate(x - step, False)
        numeric = (up - down) / (2 * step[c])
        scale = float(np.abs(numeric[:trajectory]).max())
        assert np.allclose(exact[:trajectory, c], numeric[:trajectory], atol=1e-2 * scale), c
        if c in timing:
            assert np.allclose(exact[trajectory:, c], numeric[trajectory:], rtol=1e-5, atol=1e-6)


def test_no_fitted_stroke_is_a_pulse_too_short_for_the_grid() -> None:
    """Strokes whose velocity pulse would fall between the grid's instants (a spike the
    recording never shows) are held at the extent floor: none ends up much shorter."""
    rng = np.random.default_rng(7)
    options = TimingOptions()
    for _ in range(3):
        trace = simulated_capture(random_timed_plan(rng), rng)
        step = float(np.diff(resample(trace.t, trace.xy, options).t[:2])[0])
        plan = fit([trace], timing="match").plans[0]
        extent = 2 * np.exp(plan.mu) * np.sinh(1.2815515655446004 * plan.sigma)
        assert extent.min() >= 0.7 * options.min_extent * step, extent.min()


def test_fit_cost_is_least_for_the_plan_a_recording_was_made_from() -> None:
    """The cost the fit minimises, for any plan against a timed trace: lowest for the plan the
    trace was sampled from, higher for it late by a few ms or with its shape moved, and
    independent of which clock the plan and trace share."""
    rng = np.random.default_rng(21)
    plan = random_timed_plan(rng)
    trace = simulated_capture(plan, rng, rate=60.0, noise=0.0)
    own = fit_cost(plan, trace, 100.0)
    assert own >= 0.0
    late = [fit_cost(plan.at(plan.start + d), trace, 100.0) for d in (0.005, 0.02)]
    assert own < late[0] < late[1]
    moved = Plan(plan.targets * 1.01, plan.dt, plan.mu, plan.sigma, plan.phi1, plan.phi2,
                 plan.start)  # fmt: skip
    assert fit_cost(moved, trace, 100.0) > own
    shifted = Trace(trace.xy, trace.t + 7.0)
    assert fit_cost(plan.at(plan.start + 7.0), shifted, 100.0) == pytest.approx(own, rel=1e-6)
    few = Trace(trace.xy[: MIN_SAMPLES - 1], trace.t[: MIN_SAMPLES - 1])
    with pytest.raises(ValueError, match=f"fewer than {MIN_SAMPLES} distinct stamps"):
        fit_cost(plan, few, 100.0)


def test_fit_cost_times_a_trace_of_exactly_min_samples_stamps() -> None:
    """A trace of exactly MIN_SAMPLES distinct stamps is one the fit times: it has a cost."""
    rng = np.random.default_rng(21)
    plan = random_timed_plan(rng)
    trace = simulated_capture(plan, rng, rate=60.0, noise=0.0)
    just = Trace(trace.xy[:MIN_SAMPLES], trace.t[:MIN_SAMPLES])
    assert len(np.unique(just.t)) == MIN_SAMPLES
    cost = fit_cost(plan, just, 100.0)
    assert np.isfinite(cost) and cost >= 0.0


def _missed_bump_at(at: float) -> tuple[object, object]:
    """One straight stroke, and a recording of it plus a sideways velocity bump centred at
    ``at`` seconds that the stroke misses (so the only candidate cut is there)."""
    from tagbot.gesture.strokes import Strokes
    from tagbot.gesture.timing import Recording

    one = Plan([[0.0, 0.0], [80.0, 0.0]], [0.0], [np.log(0.3)], [0.3], [0.0], [0.0])
    strokes = Strokes.of([one])
    t = np.arange(-0.1, 1.6, 0.005)
    _, v = strokes.evaluate(np.zeros(len(t), dtype=np.intp), t, 80.0)
    v = v.copy()
    v[:, 1] += 100.0 * np.exp(-0.5 * ((t - at) / 0.08) ** 2)  # wider than the dip reach
    xy = np.cumsum(v, axis=0) * 0.005
    return strokes, Recording(t, xy, v, np.ones(len(t)), float(t[-1]))


def test_a_stroke_is_split_only_inside_its_10_90_interval_less_a_tenth_at_each_end() -> None:
    """A missed bump inside a stroke's 10-90 % interval splits it there; one within the interval's
    outer tenths, or beyond, splits nothing (the halves would be too short to fit)."""
    from tagbot.gesture.timing import _Z10, _Z90, _split

    onset, mu, sigma = 0.0, np.log(0.3), 0.3
    lo, hi = onset + np.exp(mu + sigma * _Z10), onset + np.exp(mu + sigma * _Z90)
    margin = 0.1 * (hi - lo)
    for at, splits in [
        (lo + 1.5 * margin, True),
        (0.5 * (lo + hi), True),
        (hi - 1.5 * margin, True),
        (lo + 0.5 * margin, False),
        (hi - 0.5 * margin, False),
        (hi + 0.5 * margin, False),
    ]:
        strokes, rec = _missed_bump_at(at)
        split = _split(strokes, rec, 80.0, TimingOptions(), room=1)
        assert (split is not None) == splits, (at - lo) / margin
        if splits:
            assert len(split.onsets) == 2
            near = np.abs(rec.t - at) <= 0.011  # the new target: where the recording was then
            assert np.min(np.hypot(*(rec.xy[near] - split.targets[1]).T)) < 1e-9


def test_per_stroke_snr_without_low_pass_maps_a_late_clock_at_that_cutoff() -> None:
    """A one-stroke recording 13 ms late with 0.2 mm of noise, compared unfiltered (cutoff None):
    its stroke's velocity SNR is the best mapping's unfiltered figure (velocity_snr), well above
    the 13 ms-off shared clock's, not the shared clock picked because it looks better
    low-passed."""
    one = Plan([[0.0, 0.0], [80.0, 0.0]], [0.0], [np.log(0.3)], [0.35], [0.0], [0.0])
    tag = Tag((one,))
    t, xy = _stamped(one)
    xy = xy + np.random.default_rng(0).normal(0.0, 0.2, xy.shape)
    t = t + 0.013
    mt, _, mv = sample_plan(tag, 0, 0.005)
    best, _, offset = velocity_snr(t, xy, mt, mv, cutoff=None)
    shared = clock_velocity_snr(t, xy, mt, mv, None)
    assert offset == pytest.approx(0.013, abs=0.003) and best > shared + 0.5
    assert clock_velocity_snr(t, xy, mt, mv) > best  # low-passed, the shared clock looks better
    [row] = stroke_report([Trace(xy, t)], tag, cutoff=None)
    assert row.velocity_snr_db == pytest.approx(best, abs=1e-6)
