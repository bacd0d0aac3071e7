"""benchmarks/bench_timing.py's own arithmetic, on synthetic captures (never the shared data):
the shape margin, the reference's ceiling, one file's figures and the summary's verdicts."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

from bench_timing import (
    KINDS,
    Row,
    ceiling_db,
    costlier_refits,
    rerecorded,
    run_case,
    shape_excess,
    summarise,
)

from tagbot.gesture import reconstruction
from tagbot.gesture.timing import fit_cost, simulated_capture
from tagbot.inputs import Trace
from tagbot.metrics import clock_velocity_snr, fit_report, recorded_velocity, tag_clock_snr
from tagbot.model.motion import evaluate_plan, sample_plan
from tagbot.model.plan import Tag, random_timed_plan


def test_shape_excess_is_the_fits_margin() -> None:
    # Mean: geometric + 0.0005 of the size.
    assert shape_excess(0.0015, 0.0, 0.001, 0.0) == pytest.approx(0.0)
    assert shape_excess(0.0020, 0.0, 0.001, 0.0) == pytest.approx(0.0005)
    # Max: a small geometric max gets +0.005 of the size (0.002 -> 0.007, not 1.5x = 0.003)...
    assert shape_excess(0.0, 0.0075, 0.0, 0.002) == pytest.approx(0.0005)
    # ... a large one 1.5 times (0.02 -> 0.03, not +0.005 = 0.025).
    assert shape_excess(0.0, 0.029, 0.01, 0.02) == pytest.approx(-0.001)
    # The larger excess of the two counts.
    assert shape_excess(0.0030, 0.0075, 0.001, 0.002) == pytest.approx(0.0015)


def _sampled(plan, stamps: np.ndarray, size: float) -> SimpleNamespace:
    xy, _ = evaluate_plan(plan, stamps, size)
    return SimpleNamespace(t=stamps, xy=xy)


@pytest.mark.parametrize("cutoff", [10.0, 15.0, None])
def test_ceiling_is_the_reference_against_the_exact_velocity(cutoff: float | None) -> None:
    """One plan sampled at 60 Hz stamps: the ceiling is what the reference gives against the
    plan's velocity (here from its own 1 ms sampling, interpolated: to 0.05 dB)."""
    tag = Tag((random_timed_plan(np.random.default_rng(5)),))
    t, _, v = sample_plan(tag, 0, 0.001)
    trace = _sampled(tag.plans[0], np.arange(t[0], t[-1], 1 / 60), tag.size)
    expected = clock_velocity_snr(trace.t, trace.xy, t, v, cutoff)
    assert ceiling_db([trace], tag, cutoff) == pytest.approx(expected, abs=0.05)


def test_ceiling_weighs_traces_by_energy() -> None:
    rng = np.random.default_rng(7)
    first = random_timed_plan(rng)
    tag = Tag((first, random_timed_plan(rng).at(first.end(100.0) + 0.3)))
    span = [(p.start, p.end(tag.size)) for p in tag.plans]
    traces = [
        _sampled(tag.plans[0], np.arange(*span[0], 1 / 100), tag.size),
        _sampled(tag.plans[1], np.arange(*span[1], 1 / 30), tag.size),
    ]
    signal = noise = 0.0
    for plan, trace in zip(tag.plans, traces, strict=True):
        grid, v = recorded_velocity(trace.t, trace.xy, cutoff=15.0)
        _, exact = evaluate_plan(plan, grid, tag.size)
        signal, noise = signal + np.sum(v * v), noise + np.sum((v - exact) ** 2)
    each = [
        ceiling_db([trace], Tag((plan,)), 15.0)
        for plan, trace in zip(tag.plans, traces, strict=True)
    ]
    whole = ceiling_db(traces, tag, 15.0)
    assert whole == pytest.approx(10 * math.log10(signal / noise), abs=1e-9)
    assert abs(each[0] - each[1]) > 1  # so that an average of dB would differ
    assert min(each) < whole < max(each)


def test_run_case_gives_the_fits_figures() -> None:
    """A synthetic two-trace capture through ``run_case`` (a dataset whose payload is the
    traces): every figure is the library's for the same fits."""
    rng = np.random.default_rng(11)
    plans = [random_timed_plan(rng) for _ in range(2)]
    traces = []
    start = 0.0
    for plan in plans:
        plan = plan.at(start)
        stamps = np.arange(plan.start, plan.end(100.0), 0.01)
        xy, _ = evaluate_plan(plan, stamps, 100.0)
        traces.append(Trace(xy + np.array([150.0 * len(traces), 0.0]), stamps))
        start = stamps[-1] + 0.3
    row = run_case(("unipen", "synthetic", traces), "gamma")
    assert not row.error
    chosen = reconstruction(traces, "gamma", "auto")
    geometric = reconstruction(traces, "gamma", "ignore")
    report = fit_report(traces, chosen.tag, timings=chosen.timings)
    assert (row.strokes, row.strokes_geometric) == (chosen.tag.n_strokes, geometric.tag.n_strokes)
    assert (row.shape_mean, row.shape_max) == (report.shape.mean, report.shape.max)
    assert row.trace_15hz_db == pytest.approx(report.velocity_snr_trace_db)
    assert row.clock_15hz_db == pytest.approx(report.velocity_snr_clock_db)
    assert row.best_mapping_db == pytest.approx(report.velocity_snr_db)
    clock, trace = tag_clock_snr(traces, chosen.tag, 10.0)
    assert (row.clock_10hz_db, row.trace_10hz_db) == (pytest.approx(clock), pytest.approx(trace))
    assert row.ceiling_raw_db == pytest.approx(ceiling_db(traces, chosen.tag, None))
    span = sum(tr.t[-1] - tr.t[0] + 0.01 for tr in traces)
    assert row.strokes_per_s == pytest.approx(row.strokes / span)
    assert sum(getattr(row, kind) for kind in KINDS) == 2
    assert row.refused == ""
    assert row.fit_s > 0 and row.fit_geometric_s > 0


def test_rerecorded_traces_are_the_fit_at_the_captures_instants() -> None:
    """A capture with noisy stamps (a steady 50 Hz sampler, delivery noise): the re-recorded
    trace samples the fit at the instants the reference places the samples at, so a plan
    sampled there is followed exactly; run_case fits it again and scores it against its ceiling."""
    rng = np.random.default_rng(3)
    plan = random_timed_plan(rng)
    instants = np.arange(plan.start, plan.end(100.0), 0.02)
    stamps = np.maximum.accumulate(instants + rng.uniform(0.0, 0.008, len(instants)))
    xy, _ = evaluate_plan(plan, instants, 100.0)
    traces = [Trace(xy, stamps)]
    tag = Tag((plan,))
    (again,) = rerecorded(traces, tag)
    assert len(again.t) == len(stamps) and np.all(np.diff(again.t) >= 0)
    expected, _ = evaluate_plan(plan, again.t, tag.size)
    np.testing.assert_allclose(again.xy, expected)
    # The instants are the regressed ones (a steady sampler's), not the noisy stamps.
    assert np.ptp(np.diff(again.t)) < 0.001 < 0.004 < np.ptp(np.diff(stamps))
    row = run_case(("unipen", "noisy", traces), "gamma", rerecord=True)
    refit = reconstruction(rerecorded(traces, reconstruction(traces, "gamma", "auto").tag),
                           "gamma", "auto").tag  # fmt: skip
    again = rerecorded(traces, reconstruction(traces, "gamma", "auto").tag)
    assert row.rerecorded_10hz_db == pytest.approx(tag_clock_snr(again, refit, 10.0)[1])
    assert row.rerecorded_ceiling_10hz_db == pytest.approx(ceiling_db(again, refit, 10.0))
    assert math.isnan(run_case(("unipen", "noisy", traces), "gamma").rerecorded_10hz_db)
    recorded = reconstruction(traces, "gamma", "auto").tag
    costs = [fit_cost(p, again[0], recorded.size) for p in (refit.plans[0], recorded.plans[0])]
    assert (row.rerecorded_traces, row.rerecorded_costlier) == (1, int(costs[0] > costs[1]))


def test_a_refit_costlier_than_the_recorded_plan_is_counted() -> None:
    rng = np.random.default_rng(8)
    plans = [random_timed_plan(rng) for _ in range(2)]
    tag = Tag((plans[0], plans[1].at(plans[0].end(100.0) + 0.3)))
    traces = [simulated_capture(p, rng, noise=0.0) for p in tag.plans]
    short = Trace(traces[1].xy[:5], traces[1].t[:5])  # too few stamps: not counted
    assert costlier_refits(traces, tag, tag) == (2, 0)
    late = Tag((tag.plans[0].at(tag.plans[0].start + 0.03), tag.plans[1]))
    assert costlier_refits(traces, tag, late) == (2, 1)
    assert costlier_refits([traces[0], short], tag, late) == (1, 1)


def test_run_case_reports_a_refused_clock_and_a_failure() -> None:
    t = np.linspace(0.0, 0.05, 40)  # 40 stamps in 50 ms: a scribble no hand draws that fast
    angle = 2 * np.pi * 60 * t  # three turns, six half turns: 120 per second
    xy = np.column_stack([np.cos(angle), np.sin(angle)]) * (30 + 200 * t[:, None])
    row = run_case(("unipen", "fast", [Trace(xy, t)]), "gamma")
    assert "clock implausible" in row.refused and not any(getattr(row, k) for k in KINDS)
    failed = run_case(("unipen", "empty", []), "gamma")
    assert failed.error.startswith("PlanError: traces: empty")


def _row(name: str, **figures: float) -> Row:
    base = dict(
        strokes=10, strokes_geometric=8, shape_mean=0.001, shape_max=0.01,
        shape_mean_geometric=0.001, shape_max_geometric=0.01, shape_excess=-0.001,
        strokes_per_s=5.0, fit_s=0.3, fit_geometric_s=0.05, matched=2,
    )  # fmt: skip
    for label in ("10hz", "15hz", "raw"):
        base |= {f"clock_{label}_db": 17.0, f"trace_{label}_db": 18.0, f"ceiling_{label}_db": 19.5}
    return Row("gml", name, **(base | figures))


def test_summary_gives_the_fitters_own_gap_when_rerecorded() -> None:
    plain = summarise("gml", [_row("a.gml")])
    assert not any("re-recorded" in line for line in plain)
    rows = [
        _row("a.gml", rerecorded_10hz_db=20.0, rerecorded_ceiling_10hz_db=23.0),
        _row("b.gml", rerecorded_10hz_db=22.0, rerecorded_ceiling_10hz_db=23.5),
        _row("c.gml"),  # not re-recorded (e.g. its clock refused): left out
    ]
    (line,) = [x for x in summarise("gml", rows) if "re-recorded" in x]
    assert "2 files" in line and "per trace 21.0 / " in line and "ceiling 23.2 / " in line
    assert "per trace - ceiling -2.2 (the fitter's own gap)" in line
    assert "costs more than the plan it was recorded from on 0 of 0 traces" in line
    counted = [_row("a.gml", rerecorded_10hz_db=20.0, rerecorded_ceiling_10hz_db=23.0,
                    rerecorded_traces=4, rerecorded_costlier=3),
               _row("b.gml", rerecorded_10hz_db=20.0, rerecorded_ceiling_10hz_db=23.0,
                    rerecorded_traces=2, rerecorded_costlier=1)]  # fmt: skip
    (line,) = [x for x in summarise("gml", counted) if "re-recorded" in x]
    assert "from on 4 of 6 traces" in line


def test_summary_names_the_worst_file_and_marks_the_goals() -> None:
    rows = [
        _row("a.gml", shape_excess=0.0002, restrained=1),
        _row("b.gml", ceiling_15hz_db=23.0, strokes=13, scaled=1, mapped=1),
        _row("c.gml", clock_raw_db=17.5, refused="timing ignored, the capture's clock ..."),
        Row("gml", "d.gml", error="PlanError: bad"),
    ]
    text = "\n".join(summarise("gml", rows))
    assert "[gml] 4 files, 1 failed" in text
    assert "1 files over (goal: none, NOT met); worst a.gml: +0.0200 % of the size beyond" in text
    # Medians: per trace 18.0, ceiling 19.5 (10 Hz, raw) and 19.5 (15 Hz: 19.5, 23, 19.5).
    assert "per trace - ceiling -1.5 (met), own clock - per trace -1.0 (met)" in text
    assert "raw differences  own clock 17.0 / 17.0" in text
    # Strokes: 10/8 = 1.25 twice, 13/8 = 1.625 -> over 1.5.
    assert "median 1.25, max 1.62 (goal <= 1.5: NOT met)" in text
    assert "6 matched, 1 restrained, 1 mapped, 1 scaled, 0 geometric; 2 files with a trace" in text
    assert "1 files' whole clock refused" in text and "refused c.gml: timing ignored" in text
    gap = "\n".join(summarise("gml", [_row("e.gml", trace_10hz_db=17.4, ceiling_10hz_db=19.5)]))
    assert "per trace - ceiling -2.1 (NOT met), own clock - per trace -0.4 (met)" in gap
