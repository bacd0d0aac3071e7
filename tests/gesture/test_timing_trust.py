"""The timed fit can be trusted: the shape is never traded for timing, clocks no hand can produce
fall back to the geometric timing and say so, and the tag keeps the writer's own clock."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from tagbot.errors import PlanError
from tagbot.gesture import reconstruction
from tagbot.gesture.timing import (
    MAX_STROKE_RATE,
    MAX_TURN_ACCELERATION,
    SHAPE_MARGIN_MAX,
    SHAPE_MARGIN_MEAN,
    TimingOptions,
    TraceTiming,
    Turn,
    fastest_turn,
    fit_cost,
    implausible_clock,
    pen_down_span,
    simulated_capture,
)
from tagbot.inputs import Trace
from tagbot.io.planfile import tag_to_dict
from tagbot.metrics import fit_report, shape_error, tag_clock_snr
from tagbot.model.easing import EASE
from tagbot.model.motion import sample_ink
from tagbot.model.plan import Plan, random_timed_plan


def trace_errors(traces: list[Trace], tag, size: float | None = None) -> list[tuple[float, float]]:
    """Each trace's mean and max shape error against what its plan inks, as fractions of
    ``size`` (default the tag's own; the fit's margins are stated as fractions of one size)."""
    size = tag.size if size is None else size
    out = []
    for k, trace in enumerate(traces):
        down, up = tag.plans[k].ink_window(tag.size)
        ((_, xy, _),) = sample_ink(tag, min(0.005, (up - down) / 1000), [k])
        error = shape_error([trace.xy], [xy])
        out.append((error.mean * error.size / size, error.max * error.size / size))
    return out


def assert_within_margin(traces: list[Trace], timing: str) -> object:
    """Fit ``traces`` with ``timing`` and check every trace's shape against the geometric fit's
    of the same trace; returns the reconstruction."""
    geometric = reconstruction(traces, timing="ignore").tag
    fitted = reconstruction(traces, timing=timing)
    assert fitted.tag.n_strokes <= 1.5 * geometric.n_strokes  # TimingOptions.max_stroke_ratio
    # Both as fractions of one size, the drawing's diagonal, as the fit states its margins (a
    # tag's own size is its targets' span: a timed fit's virtual targets may span 12 % less).
    size = float(np.hypot(*np.ptp(np.concatenate([tr.xy for tr in traces]), axis=0)))
    for k, ((mean, largest), (mean_g, max_g)) in enumerate(
        zip(
            trace_errors(traces, fitted.tag, size),
            trace_errors(traces, geometric, size),
            strict=True,
        )
    ):
        slack = 1.05
        assert mean <= slack * mean_g + SHAPE_MARGIN_MEAN, (k, timing, mean, mean_g)
        assert largest <= slack * max(SHAPE_MARGIN_MAX[0] * max_g, max_g + SHAPE_MARGIN_MAX[1]), (
            k,
            timing,
            largest,
            max_g,
        )
    return fitted


def capture(plan: Plan, rng: np.random.Generator, **digitiser) -> Trace:
    """``plan`` recorded by a simulated digitiser while it visibly moves (from where it has
    travelled 0.5 % of its path to where it has that much left), as a writer's pen is down."""
    trace = simulated_capture(plan, rng, **digitiser)
    xy = np.asarray(trace.xy)
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    keep = (s >= 0.005 * s[-1]) & (s <= 0.995 * s[-1])
    return Trace(xy[keep], np.asarray(trace.t)[keep])


def distorted(trace: Trace, how: str, rng: np.random.Generator) -> Trace:
    """``trace`` as a faulty or odd digitiser would have recorded it."""
    t, xy = np.asarray(trace.t), np.asarray(trace.xy)
    if how == "compressed":  # a clock ten times too fast
        return Trace(xy, t * 0.1)
    if how == "burst":  # twenty times: faster than any hand
        return Trace(xy, t * 0.05)
    if how == "stretched":  # ten times too slow: a slow, careful hand
        return Trace(xy, t * 10.0)
    if how == "repeated":  # stamps delivered in bursts of three
        return Trace(xy, t[(np.arange(len(t)) // 3) * 3])
    if how == "dropped":  # a third of the samples lost
        keep = np.sort(rng.choice(len(t), size=2 * len(t) // 3, replace=False))
        keep[0], keep[-1] = 0, len(t) - 1
        return Trace(xy[np.unique(keep)], t[np.unique(keep)])
    if how == "clicks":  # an eye tracker: a few clicks, milliseconds apart
        keep = np.linspace(0, len(t) - 1, 6).astype(int)
        return Trace(xy[keep], np.cumsum(np.r_[0.0, rng.uniform(0.005, 0.02, 5)]))
    raise AssertionError(how)


DISTORTIONS = ("compressed", "stretched", "repeated", "dropped", "clicks")


@pytest.mark.parametrize("how", DISTORTIONS)
def test_every_clock_keeps_the_shape_whatever_the_timing_option(how: str) -> None:
    rng = np.random.default_rng(29)
    for _ in range(2):
        trace = distorted(capture(random_timed_plan(rng), rng), how, rng)
        for timing in ("auto", "match"):
            assert_within_margin([trace], timing)


@pytest.mark.parametrize(
    ("how", "why"),
    [
        ("burst", "timing ignored, the capture's clock implausible: "),
        ("clicks", "timing ignored: no trace has 8 distinct time stamps at 10 Hz or more"),
    ],
)
def test_a_clock_no_hand_can_produce_falls_back_and_says_why(how: str, why: str) -> None:
    rng = np.random.default_rng(3)
    traces = [distorted(capture(random_timed_plan(rng), rng), how, rng) for _ in range(2)]
    traces[1] = Trace(traces[1].xy + 90.0, traces[1].t + traces[0].t[-1] + 0.5)
    fitted = reconstruction(traces)
    geometric = reconstruction(traces, timing="ignore")
    assert fitted.timings is None  # the paper's rhythm
    assert tag_to_dict(fitted.tag) == tag_to_dict(geometric.tag)
    assert len(fitted.notes()) == 1 and fitted.notes()[0].startswith(why)
    if how == "burst":
        assert "per second; a hand draws at most 40" in fitted.notes()[0]
    assert fit_report(traces, fitted.tag, timings=fitted.timings).timing is None


def test_a_plausible_clock_keeps_its_timing() -> None:
    """Ordinary digitisers (100 Hz, 60 Hz with jitter, a slow hand): matched, and the velocity
    on the tag's own clock follows the recording."""
    rng = np.random.default_rng(5)
    for rate, jitter, slow in ((100.0, 0.0005, 1.0), (60.0, 0.004, 1.0), (100.0, 0.0, 3.0)):
        truth = random_timed_plan(rng)
        trace = capture(truth, rng, rate=rate, jitter=jitter)
        trace = Trace(trace.xy, trace.t * slow)
        fitted = reconstruction([trace])
        assert fitted.timings is not None and fitted.timings[0].kind == "matched"
        report = fit_report([trace], fitted.tag, timings=fitted.timings)
        assert report.timing == "1 matched"
        assert report.velocity_snr_clock_db is not None and report.velocity_snr_clock_db > 15.0
        # One offset for the capture scores no better than one offset per trace.
        assert report.velocity_snr_clock_db <= report.velocity_snr_trace_db + 1e-9


def test_one_implausible_trace_falls_back_alone() -> None:
    """Two traces on one clock, the second stamped in a burst no hand makes: the first keeps its
    timing, the second is drawn at the geometric timing, and the fit says which and why."""
    rng = np.random.default_rng(8)
    first = capture(random_timed_plan(rng), rng)
    second = capture(random_timed_plan(rng), rng)
    start = float(first.t[-1]) + 0.4
    burst = Trace(second.xy + 80.0, start + np.linspace(0.0, 0.03, len(second.t)))
    fitted = reconstruction([first, burst])
    assert [t.kind for t in fitted.timings] == ["matched", "geometric"]
    why = fitted.timings[1].reason
    assert why.startswith("clock implausible: ") and "strokes in" in why
    assert fitted.notes() == [f"trace 1: geometric ({why})"]
    report = fit_report([first, burst], fitted.tag, timings=fitted.timings)
    assert report.timing == "1 matched, 1 geometric"
    assert "timing: 1 matched, 1 geometric" in report.summary()
    # The geometric plan touches down where its trace was recorded.
    assert fitted.tag.plans[1].ink_window(fitted.tag.size)[0] >= start - 1e-9


def test_a_timing_without_a_reason_is_described_by_its_kind_alone() -> None:
    """describe names the trace and its kind, and adds the reason in brackets only if there is
    one."""
    assert TraceTiming("matched").describe(0) == "trace 0: matched"
    assert TraceTiming("scaled", "").describe(3) == "trace 3: scaled"
    assert TraceTiming("mapped", "why").describe(2) == "trace 2: mapped (why)"


def test_implausible_clock_bounds() -> None:
    """At and just beyond the limits; a span counts one sampling interval more."""
    assert pen_down_span(np.linspace(0.0, 0.9, 10)) == pytest.approx(1.0)
    assert pen_down_span([0.0, 0.0, 0.0]) == 0.0
    assert implausible_clock(int(MAX_STROKE_RATE), 0.0, 1.0) == ""
    assert implausible_clock(41, 0.0, 1.0) == (
        "clock implausible: 41 strokes in 1 s, 41 per second; a hand draws at most 40"
    )
    assert implausible_clock(1, 0.0, 0.0) == "clock implausible: no time between its stamps"
    assert "45 half turns in 1 s" in implausible_clock(2, 45.0, 1.0)
    assert implausible_clock(2, 40.0, 1.0) == ""


def test_a_timed_plan_that_would_break_the_shape_keeps_the_geometric_plan(monkeypatch) -> None:
    """If the timed fit comes out wrecked (here: its targets scattered), the trace keeps the
    geometric plan on the recorded span, says so with the figures, and keeps its shape."""
    import tagbot.gesture.timing as timing

    real = timing._match_trace

    def wrecked(plan, trace, size, model, options):
        rest, t0, _ = real(plan, trace, size, model, options)
        targets = rest.targets + np.random.default_rng(0).normal(0, 0.05 * size, rest.targets.shape)
        bad = Plan(targets, rest.dt, rest.mu, rest.sigma, rest.phi1, rest.phi2, rest.start)
        return bad, t0, None

    monkeypatch.setattr(timing, "_match_trace", wrecked)
    rng = np.random.default_rng(12)
    trace = capture(random_timed_plan(rng), rng)
    fitted = assert_within_margin([trace], "match")
    assert fitted.timings[0].kind == "scaled"
    assert fitted.timings[0].reason.startswith("the timed fit missed the shape: mean ")
    # On the recorded span: the ink from the first sample to the last (within 1 % of it).
    down, up = fitted.tag.plans[0].ink_window(fitted.tag.size)
    span = trace.t[-1] - trace.t[0]
    assert down == pytest.approx(trace.t[0], abs=0.01 * span)
    assert up == pytest.approx(trace.t[-1], abs=0.01 * span)


@pytest.mark.parametrize("kept", [30.0, 1000.0])
def test_a_broken_shape_keeps_the_cheapest_start_that_holds_it(monkeypatch, kept: float) -> None:
    """Where the cheapest start's fit breaks the shape, the trace keeps the next cheapest start's
    fit that holds it (``restrained``, with its timing, not the geometric plan's); no fit is
    made beyond the starts."""
    import tagbot.gesture.timing as timing

    real, weights, plans = timing._match_trace, [], {}
    base = timing.TimingOptions().position_weight

    def broken_below(plan, trace, size, model, options):
        weight = options.position_weight / base
        weights.append(weight)
        rest, t0, air = real(plan, trace, size, model, options)
        if weight < kept:  # wrecked: its targets scattered
            noise = np.random.default_rng(0).normal(0, 0.05 * size, rest.targets.shape)
            rest = Plan(
                rest.targets + noise, rest.dt, rest.mu, rest.sigma, rest.phi1, rest.phi2,
                rest.start,
            )  # fmt: skip
            air = None
        plans[weight] = rest
        return rest, t0, air

    def broken_first(fitted) -> float:  # (ranked as if the wrecked fits cost least)
        return next(w for w, plan in plans.items() if plan is fitted[0])

    real_starts = timing._match_from_starts
    monkeypatch.setattr(timing, "_match_trace", broken_below)
    monkeypatch.setattr(
        timing, "_match_from_starts", lambda *a: sorted(real_starts(*a), key=broken_first)
    )
    rng = np.random.default_rng(12)
    trace = capture(random_timed_plan(rng), rng)
    fitted = assert_within_margin([trace], "match")
    assert weights == [1.0, 30.0, 1000.0]
    assert fitted.timings[0].kind == "restrained"
    assert fitted.timings[0].reason.startswith("the timed fit missed the shape: mean ")
    np.testing.assert_allclose(fitted.tag.plans[0].targets, plans[kept].targets)


@pytest.mark.parametrize("seed", [1, 16])
def test_a_timing_lost_from_the_nominal_start_is_kept_from_a_heavier_one(seed: int) -> None:
    """The timed fit is not convex. On these captures (60 Hz, 0.3 % noise) the fit started
    from the nominal weights alone breaks the shape at every restraint, and the trace falls back
    to the geometric plan scaled onto the recording (its speed a few dB); started also with the
    positions weighing 30 times more (the default), the fit that costs least keeps the shape
    and the writer's timing."""
    rng = np.random.default_rng(seed)
    trace = capture(random_timed_plan(rng), rng, rate=60.0, noise=0.3)
    alone = reconstruction([trace], timing="match", timing_options=TimingOptions(starts=(1.0,)))
    assert alone.timings[0].kind == "scaled"
    fitted = assert_within_margin([trace], "match")
    assert fitted.timings[0].kind == "matched"
    snr, snr_alone = (tag_clock_snr([trace], r.tag, 10.0)[0] for r in (fitted, alone))
    assert snr >= 12.0 and snr >= snr_alone + 8.0, (snr, snr_alone)
    cost, cost_alone = (fit_cost(r.tag.plans[0], trace, r.tag.size) for r in (fitted, alone))
    assert cost < 0.01 * cost_alone


@pytest.mark.parametrize("starts", [(), (1.0, 0.0), (1.0, float("nan")), (-1.0,)])
def test_starts_must_be_positive_weights(starts) -> None:
    with pytest.raises(PlanError, match=r"starts: must be one or more finite weights > 0"):
        TimingOptions(starts=starts)


def test_the_start_that_costs_least_is_kept(monkeypatch) -> None:
    """Each start is fitted once, in order, and the plan kept is the one the fit's own cost
    (:func:`fit_cost`) ranks first, strokes in the air included where they help."""
    import tagbot.gesture.timing as timing

    real, tried = timing._match_trace, []

    def recorded(plan, trace, size, model, options):
        fitted = real(plan, trace, size, model, options)
        tried.append((options.position_weight, fitted[2][0] if fitted[2] else fitted[0]))
        return fitted

    monkeypatch.setattr(timing, "_match_trace", recorded)
    rng = np.random.default_rng(37)  # (the plan in the air ranks otherwise without its strokes)
    whole = simulated_capture(random_timed_plan(rng), rng, rate=60.0, noise=0.3)
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(whole.xy, axis=0).T))]
    inked = (s >= 0.05 * s[-1]) & (s <= 0.95 * s[-1])  # touched down and lifted off moving
    trace = Trace(whole.xy[inked], whole.t[inked])
    options = TimingOptions(starts=(1.0, 30.0, 1000.0))
    kept = reconstruction([trace], timing="match", timing_options=options)
    assert [w / options.position_weight for w, _ in tried] == [1.0, 30.0, 1000.0]
    t0 = float(trace.t[0])  # (the capture's stamps are the instants: no burst, no noise)
    size = float(np.hypot(*np.ptp(trace.xy, axis=0)))
    costs = [fit_cost(p.at(p.start + t0), trace, size) for _, p in tried]
    assert len(set(np.round(costs, 6))) == 3, costs  # three different minima
    best = tried[int(np.argmin(costs))][1]
    assert any(p.ink is not None for _, p in tried)  # strokes in the air kept
    np.testing.assert_allclose(kept.tag.plans[0].targets, best.targets)


def test_runs_touch_down_and_lift_off_on_the_recorded_clock() -> None:
    """A capture with several pen lifts of 80-300 ms: every plan inks from its trace's first
    sample to its last (within one 10 ms grid step and the machines' easing), and no lift
    drifts."""
    rng = np.random.default_rng(30)
    traces, clock = [], 0.0
    for k in range(4):
        recorded = capture(random_timed_plan(rng), rng)
        t = np.asarray(recorded.t) - recorded.t[0] + clock
        traces.append(Trace(np.asarray(recorded.xy) + 70.0 * k, t))
        clock = float(t[-1]) + rng.uniform(0.08, 0.3)
    fitted = reconstruction(traces)
    assert [t.kind for t in fitted.timings] == ["matched"] * 4
    for plan, trace in zip(fitted.tag.plans, traces, strict=True):
        down, up = plan.ink_window(fitted.tag.size)
        # One 10 ms grid step and the machine's easing from rest (half of EASE of the plan's
        # clock) after the first sample; before it only as far as the plan's lognormal onset
        # already moves the pen (its ink starts with it: the shape first).
        assert trace.t[0] - 0.15 <= down <= trace.t[0] + 0.01 + EASE / 2 + 1e-9
        # The pen lifts at the last sample, or earlier once the writer's pen rests (within
        # 1 % of the tag's size of where it lifted): never later.
        assert up <= trace.t[-1] + 0.01 + 1e-9
        at_lift = [np.interp(up, trace.t, trace.xy[:, i]) for i in (0, 1)]
        assert np.hypot(*(at_lift - trace.xy[-1])) <= 0.01 * fitted.tag.size
    assert fitted.tag.sample(0.01)  # the lifts sample


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    scale=st.sampled_from([0.05, 0.3, 1.0, 4.0]),
    timing=st.sampled_from(["auto", "match"]),
)
@example(seed=2_475_188_494, scale=1.0, timing="auto")  # targets spanning 12 % less
def test_the_shape_margin_holds_over_random_plans_and_clocks(seed, scale, timing) -> None:
    rng = np.random.default_rng(seed)
    recorded = capture(random_timed_plan(rng), rng, jitter=0.002)
    assert_within_margin([Trace(recorded.xy, recorded.t * scale)], timing)


def circle(radius: float, seconds: float, rate: float = 100.0, turns: float = 1.0) -> Trace:
    """A circle of ``radius`` mm drawn at constant speed, ``turns`` turns in ``seconds``."""
    t = np.arange(0.0, seconds, 1.0 / rate)
    angle = 2 * np.pi * turns * t / seconds
    return Trace(np.column_stack([radius * np.cos(angle), radius * np.sin(angle)]), t)


def test_fastest_turn_is_the_acceleration_across_the_path() -> None:
    """At constant speed v on a radius r: v²/r, with that speed and radius; a clock scaled by c
    scales it by 1/c²; a straight line has none."""
    trace = circle(100.0, 2.0)  # 0.314 m/s on 100 mm: 0.987 m/s²
    v = 2 * np.pi * 100.0 / 2.0
    turn = fastest_turn(trace.t, trace.xy)
    assert turn.acceleration == pytest.approx(v * v / 100.0, rel=0.01)
    assert turn.speed == pytest.approx(v, rel=0.01)
    assert turn.radius == pytest.approx(100.0, rel=0.02)
    fast = fastest_turn(trace.t * 0.1, trace.xy)
    assert fast.acceleration == pytest.approx(100 * turn.acceleration, rel=1e-6)
    line = np.column_stack([np.linspace(0, 50, 40), np.zeros(40)])
    assert fastest_turn(np.arange(40) * 0.01, line).acceleration == pytest.approx(0.0, abs=1e-6)
    assert fastest_turn(np.arange(7) * 0.01, line[:7]) == Turn(0.0, 0.0, 0.0)  # too few stamps


def test_fastest_turn_is_judged_at_the_quantile_not_the_peak() -> None:
    """A slow circle with one sample thrown 5 mm off: the stray sample makes a spike of a few
    grid instants that does not decide the figure (it would at the maximum)."""
    trace = circle(100.0, 4.0, turns=1.0)
    xy = np.array(trace.xy)
    xy[200] += 5.0
    turn = fastest_turn(trace.t, xy)
    v = 2 * np.pi * 100.0 / 4.0
    assert turn.acceleration == pytest.approx(v * v / 100.0, rel=0.05)


def test_a_fast_tight_turn_is_a_clock_no_hand_produces() -> None:
    """A 400 mm circle drawn in 1 s (1.26 m/s on a 200 mm radius: 7.9 m/s², plausible) keeps its
    timing; the same capture on a clock ten times too fast (790 m/s², though only a few strokes
    and two half turns in 0.1 s) is drawn at the geometric timing, the reason naming the figure,
    the speed, the radius and the limit."""
    plausible = circle(200.0, 1.0)
    fitted = reconstruction([plausible])
    assert fitted.timings is not None and fitted.timings[0].kind != "geometric"
    fast = Trace(plausible.xy, plausible.t * 0.1)
    fitted = reconstruction([plausible, Trace(fast.xy + 500.0, fast.t + 2.0)])
    assert fitted.timings[0].kind != "geometric"
    assert fitted.timings[1].kind == "geometric"
    why = fitted.timings[1].reason
    v = 2 * np.pi * 200.0 / 0.1
    figure, rest = why.removeprefix("clock implausible: ").split(" m/s² across the path", 1)
    assert float(figure) == pytest.approx(v * v / 200.0 / 1000, rel=0.01)
    assert rest.startswith(" at its fast turns (12.")
    assert rest.endswith(f"mm radius); a hand reaches at most {MAX_TURN_ACCELERATION / 1000:g}")


def test_implausible_clock_turn_bound() -> None:
    """At the limit a turn passes; beyond, it is named with its speed and radius."""
    at = Turn(MAX_TURN_ACCELERATION, 1000.0, 1000.0**2 / MAX_TURN_ACCELERATION)
    assert implausible_clock(2, 1.0, 1.0, at) == ""
    beyond = Turn(2 * MAX_TURN_ACCELERATION, 3000.0, 30.0)
    assert implausible_clock(2, 1.0, 1.0, beyond) == (
        "clock implausible: 300 m/s² across the path at its fast turns (3 m/s on a 30 mm"
        " radius); a hand reaches at most 150"
    )
    # The rates are named first (the older, coarser checks).
    assert implausible_clock(41, 1.0, 1.0, beyond).startswith("clock implausible: 41 strokes")


def test_a_clock_scaled_onto_the_models_longest_delay_is_scaled_and_no_further() -> None:
    """The scaled fallback stretches a plan's clock while its strokes' median delays stay within
    the model's range (MU_RANGE, bound included); a stretch beyond it only moves the plan."""
    from tagbot.gesture.timing import INK_TOLERANCE, _scaled
    from tagbot.model.plan import MU_RANGE

    hi, k = MU_RANGE[1], 2.0
    mu = hi - math.log(k)
    while mu + math.log(k) > hi:  # the largest mu whose stretched delay is the bound exactly
        mu = np.nextafter(mu, -np.inf)
    assert mu + math.log(k) == hi
    for m, stretched in ((mu, True), (np.nextafter(mu, np.inf), False)):
        plan = Plan([[0.0, 0.0], [10.0, 0.0]], [0.0], [m], [0.3], [0.0], [0.0])
        on, off = plan.windows(10.0, INK_TOLERANCE)
        span = k * float(off.max() - on.min())
        out = _scaled(plan, np.array([5.0, 5.0 + span]), 10.0)
        assert out.mu[0] == (hi if stretched else m)
        assert out.windows(10.0, INK_TOLERANCE)[0].min() == pytest.approx(5.0)
