"""Timing-aware reconstruction benchmark: ``fit(timing="match")`` against the geometric fit.

Run from the repository root, with the shared data beside it (``../shared/data``)::

    python benchmarks/bench_timing.py [--data ../shared/data] [--model gamma] [--jobs 2]
                                      [--datasets gml,unipen,mocap] [--csv timing.csv]
    python benchmarks/bench_timing.py --calibrate     # the reference against synthetic truth

Datasets as in ``bench_fit.py``, timed captures only: the GML files ``index.csv`` marks as
``velocity_benchmark`` (dense real timestamps), the UNIPEN words (100 Hz) and the mocap letters
(120 Hz). Per file, for the geometric fit (``timing="ignore"``) and the timed fit
(``timing="match"``): strokes, mean shape error (% of the bounding-box diagonal), velocity SNR
(dB, :func:`tagbot.metrics.fit_report`: per trace after the best uniform time scale and offset)
and fit time (best of 2 runs, after a warm-up fit in each worker). Goals (issue 16): median
velocity SNR ≥ 20 dB, median shape error ≤ 0.5 %, strokes ≤ 1.5× the geometric fit, fit time
≤ 1 s median.

The velocity SNR is measured against two references (:func:`tagbot.metrics.recorded_velocity`):
the recording low-passed at :data:`~tagbot.metrics.VELOCITY_CUTOFF` (15 Hz, the default, "SNR")
and its raw central differences ("raw"). Two checks of the references come with them: "ceiling"
scores the recording's own smoothed velocity (the local-quadratic resampling the timed fit
works on) against the raw differences (no model can do much better on noisy captures), and
"fidelity" scores the timed fit's trajectory, sampled at the recording's own time stamps, through
the low-pass reference against its exact velocity (how much of a writer moving like the fit the
filter and the recording's sampling lose: it should be far above the goal).
"""

from __future__ import annotations

import argparse
import csv
import math
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_fit import case_traces, gml_cases, mocap_cases, unipen_cases

from tagbot.gesture import fit
from tagbot.gesture.timing import TimingOptions, resample
from tagbot.inputs import load_traces
from tagbot.metrics import (
    VELOCITY_CUTOFF,
    clock_velocity_snr,
    fit_report,
    recorded_velocity,
    stroke_report,
    velocity_snr,
)
from tagbot.model.motion import evaluate_plan, sample_plan


@dataclass
class Row:
    dataset: str
    name: str
    points: int = 0
    strokes_geometric: int = 0
    strokes: int = 0
    shape_geometric_pct: float = math.nan
    shape_pct: float = math.nan
    snr_geometric_db: float = math.nan
    snr_db: float = math.nan
    snr_clock_db: float = math.nan
    """The timed fit's velocity SNR on the recording's own clock (scale 1, offset 0)."""
    snr_raw_geometric_db: float = math.nan
    """As ``snr_geometric_db`` and ``snr_db`` against the raw differences."""
    snr_raw_db: float = math.nan
    snr_clock_raw_db: float = math.nan
    ceiling_raw_db: float = math.nan
    """The recording's own smoothed velocity against its raw differences (shared clock)."""
    fidelity_db: float = math.nan
    """The timed fit sampled at the recorded stamps, through the reference, against itself."""
    snr_interior_db: float = math.nan
    """The timed fit's velocity SNR (best mapping) without each trace's first and last
    :data:`EDGE` seconds, where the writer moves at touch-down and lift-off and a plan that
    draws only the recorded ink starts and ends at rest."""
    snr_10hz_db: float = math.nan
    """Sensitivity: the timed fit's velocity SNR against the recording low-passed at 10 Hz..."""
    snr_20hz_db: float = math.nan
    """... and at 20 Hz."""
    stroke_snr_median_db: float = math.nan
    fit_geometric_s: float = math.nan
    fit_s: float = math.nan
    error: str = ""


def _traces(case: tuple[str, str, object]) -> list:
    dataset, _, payload = case
    if dataset == "gml":
        return load_traces(payload[0])
    return case_traces(case)


def run_case(case: tuple[str, str, object], model: str) -> Row:
    dataset, name, _ = case
    row = Row(dataset, name)
    try:
        traces = _traces(case)
        row.points = sum(len(tr) for tr in traces)
        for timing in ("ignore", "match"):
            options = {"model": model, "timing": timing}
            tag = fit(traces, **options)
            seconds = min(_timed(lambda o=options: fit(traces, **o)) for _ in range(2))
            report = fit_report(traces, tag)
            snr = math.nan if report.velocity_snr_db is None else report.velocity_snr_db
            raw = _weighted(traces, tag, _best_raw)
            if timing == "ignore":
                row.strokes_geometric, row.fit_geometric_s = report.strokes, seconds
                row.shape_geometric_pct, row.snr_geometric_db = 100 * report.shape.mean, snr
                row.snr_raw_geometric_db = raw
            else:
                row.strokes, row.fit_s = report.strokes, seconds
                row.shape_pct, row.snr_db = 100 * report.shape.mean, snr
                row.snr_raw_db = raw
                row.snr_clock_db = _weighted(traces, tag, _clock)
                row.snr_clock_raw_db = _weighted(traces, tag, _clock_raw)
                row.ceiling_raw_db = _weighted(traces, tag, _ceiling)
                row.fidelity_db = _weighted(traces, tag, _fidelity)
                row.snr_interior_db = _weighted(traces, tag, _interior)
                row.snr_10hz_db = _weighted(traces, tag, lambda *a: _best_at(10.0, *a))
                row.snr_20hz_db = _weighted(traces, tag, lambda *a: _best_at(20.0, *a))
                per = [s.velocity_snr_db for s in stroke_report(traces, tag)]
                per = [v for v in per if v is not None and np.isfinite(v)]
                row.stroke_snr_median_db = float(np.median(per)) if per else math.nan
    except Exception as e:  # a benchmark reports every failure and goes on
        row.error = f"{type(e).__name__}: {e}"
    return row


def _weighted(traces: list, tag, figure) -> float:
    """``figure(trace, tag, k)`` (dB) per trace, weighted by its recorded velocity energy."""
    signal = noise = 0.0
    for k, trace in enumerate(traces):
        try:
            db = figure(trace, tag, k)
            _, rec = recorded_velocity(trace.t, trace.xy)
        except ValueError:
            continue
        energy = float(np.sum(rec * rec))
        if np.isfinite(db):
            signal, noise = signal + energy, noise + energy / 10 ** (db / 10)
    return 10 * math.log10(signal / noise) if noise > 0 else math.nan


def _best_raw(trace, tag, k: int) -> float:
    """Velocity SNR against the raw differences after the best time mapping (as fit_report)."""
    return _best_at(None, trace, tag, k)


def _best_at(cutoff: float | None, trace, tag, k: int) -> float:
    t, _, v = sample_plan(tag, k, 0.005)
    return velocity_snr(trace.t, trace.xy, t, v, cutoff=cutoff)[0]


EDGE = 0.08
"""Seconds at either end of a trace left out of the "interior" velocity SNR."""


def _interior(trace, tag, k: int) -> float:
    t, _, v = sample_plan(tag, k, 0.005)
    _, scale, offset = velocity_snr(trace.t, trace.xy, t, v)
    grid, rec = recorded_velocity(trace.t, trace.xy, cutoff=VELOCITY_CUTOFF)
    inside = (grid - grid[0] >= EDGE) & (grid[-1] - grid >= EDGE)
    if np.count_nonzero(inside) < 3:
        raise ValueError("too short for an interior")
    tm = t[0] + (grid[inside] - offset) / scale
    model = np.column_stack([np.interp(tm, t, v[:, i], 0.0, 0.0) for i in (0, 1)]) / scale
    rec = rec[inside]
    return 10 * math.log10(float(np.sum(rec * rec)) / float(np.sum((rec - model) ** 2)))


def _clock(trace, tag, k: int) -> float:
    t, _, v = sample_plan(tag, k, 0.005)
    return clock_velocity_snr(trace.t, trace.xy, t, v)


def _clock_raw(trace, tag, k: int) -> float:
    t, _, v = sample_plan(tag, k, 0.005)
    return clock_velocity_snr(trace.t, trace.xy, t, v, cutoff=None)


def _ceiling(trace, tag, k: int) -> float:
    """The recording's local-quadratic velocity (timing.resample) against its raw differences."""
    t = np.asarray(trace.t, dtype=float)
    rec = resample(t - t[0], np.asarray(trace.xy, dtype=float), TimingOptions())
    return clock_velocity_snr(t, trace.xy, rec.t + t[0], rec.v, cutoff=None)


def _fidelity(trace, tag, k: int) -> float:
    """The timed plan sampled at the recorded stamps (through the trace's best time mapping, so
    a plan placed late by an earlier plan's tail is sampled where it moves), then through the
    low-pass reference, against its exact velocity: what the reference and the recording's
    sampling lose of a writer moving exactly like the fit."""
    t, _, v = sample_plan(tag, k, 0.005)
    _, scale, offset = velocity_snr(trace.t, trace.xy, t, v)
    stamps = np.asarray(trace.t, dtype=float)
    xy, _ = evaluate_plan(tag.plans[k], np.sort(t[0] + (stamps - offset) / scale), tag.size)
    return clock_velocity_snr(stamps, xy, offset + scale * (t - t[0]), v / scale)


def _timed(fn) -> float:
    started = time.perf_counter()
    fn()
    return time.perf_counter() - started


def _warm_up(model: str) -> None:
    t = np.linspace(0, 1, 101)
    traces = [type("T", (), {"xy": np.column_stack([t * 50, np.sin(6 * t) * 20]), "t": t})()]
    fit(traces, model=model, timing="match")


def _median(rows: list[Row], field: str) -> float:
    values = np.array([getattr(r, field) for r in rows if not r.error], dtype=float)
    values = values[np.isfinite(values)]
    return float(np.median(values)) if values.size else math.nan


CALIBRATION_CUTOFFS = (None, 8.0, 10.0, 12.0, 15.0, 20.0)
"""Cut-offs (Hz; None: raw differences) the ``--calibrate`` study compares."""
DIGITISERS = {
    "tablet 100 Hz, 0.02 mm noise": {},
    "mocap 120 Hz, 0.05 mm noise": {"rate": 120.0, "noise": 0.05},
    "touch 60 Hz, 0.1 mm pixels": {"rate": 60.0, "jitter": 0.001, "noise": 0.0, "pixel": 0.1},
    "touch 60 Hz, 0.3 mm pixels": {"rate": 60.0, "jitter": 0.002, "noise": 0.0, "pixel": 0.3},
    "touch 30 Hz, 0.3 mm pixels": {"rate": 30.0, "jitter": 0.002, "noise": 0.0, "pixel": 0.3},
}
"""Simulated digitisers of the ``--calibrate`` study (rate Hz, stamp jitter s on a 1 ms clock,
position noise mm, pixel mm), on tags about 100 mm across."""


def calibrate(plans: int = 16, seed: int = 16) -> None:
    """How close each reference comes to the *true* velocity: synthetic timed plans recorded by
    simulated digitisers, the median SNR of :func:`recorded_velocity` at each cut-off against
    the plan's exact velocity (the shared clock: the digitiser's clock is the plan's)."""
    from tagbot.gesture.timing import simulated_capture
    from tagbot.model.plan import Tag, random_timed_plan

    print(f"median SNR (dB) of the reference against the true velocity, {plans} plans each")
    print(f"{'digitiser':32s}" + "".join(f"{'raw' if c is None else f'{c:g} Hz':>8s}"
                                           for c in CALIBRATION_CUTOFFS))  # fmt: skip
    for label, kind in DIGITISERS.items():
        rng = np.random.default_rng(seed)
        scores: dict[float | None, list[float]] = {c: [] for c in CALIBRATION_CUTOFFS}
        for _ in range(plans):
            plan = random_timed_plan(rng)
            trace = simulated_capture(plan, rng, **kind)
            t, _, v = sample_plan(Tag((plan,)), 0, 0.001)
            for cutoff in CALIBRATION_CUTOFFS:
                scores[cutoff].append(clock_velocity_snr(trace.t, trace.xy, t, v, cutoff))
        print(f"{label:32s}" + "".join(f"{np.median(scores[c]):8.1f}" for c in scores))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default_data = Path(__file__).resolve().parent.parent.parent / "shared" / "data"
    parser.add_argument("--data", type=Path, default=default_data, help="the shared data folder")
    parser.add_argument("--model", choices=["gamma", "sigma"], default="gamma")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--datasets", default="gml,unipen,mocap")
    parser.add_argument("--limit", type=int, default=0, help="at most this many files per set")
    parser.add_argument("--csv", type=Path, help="write every row to this CSV file")
    parser.add_argument("--quiet", action="store_true", help="summaries only")
    parser.add_argument(
        "--calibrate",
        action="store_true",
        help="only the reference's calibration on synthetic digitisers (no data needed)",
    )
    args = parser.parse_args()
    if args.calibrate:
        calibrate()
        return
    loaders = {"gml": gml_cases, "unipen": unipen_cases, "mocap": mocap_cases}
    names = args.datasets.split(",")
    unknown = sorted(set(names) - set(loaders))
    if unknown:
        sys.exit(f"bench_timing: unknown dataset {unknown[0]!r}")
    cases = []
    for dataset in names:
        found = loaders[dataset](args.data)
        if dataset == "gml":  # dense real timestamps only
            found = [c for c in found if c[2][1]]
        cases += found[: args.limit] if args.limit else found
    for variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(variable, "1")
    started = time.perf_counter()
    spawn = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(
        args.jobs, mp_context=spawn, initializer=_warm_up, initargs=(args.model,)
    ) as pool:
        rows = list(pool.map(run_case, cases, [args.model] * len(cases)))
    print(
        f"{len(cases)} files, model {args.model}, wall time {time.perf_counter() - started:.1f} s"
    )
    if not args.quiet:
        print(
            f"{'file':40s} {'pts':>5s} {'strk':>9s} {'shape %':>13s} {'SNR dB':>11s}"
            f" {'raw dB':>11s} {'clock':>11s} {'ceil':>5s} {'fidel':>5s} {'stroke':>6s}"
            f" {'fit s':>11s}"
        )
        for r in rows:
            label = f"{r.dataset}:{r.name}"[:40]
            if r.error:
                print(f"{label:40s} FAILED {r.error}")
                continue
            print(
                f"{label:40s} {r.points:5d} {r.strokes_geometric:4d}>{r.strokes:<4d}"
                f" {r.shape_geometric_pct:6.2f}>{r.shape_pct:<6.2f} {r.snr_geometric_db:5.1f}>"
                f"{r.snr_db:<5.1f} {r.snr_raw_geometric_db:5.1f}>{r.snr_raw_db:<5.1f}"
                f" {r.snr_clock_db:5.1f}/{r.snr_clock_raw_db:<5.1f} {r.ceiling_raw_db:5.1f}"
                f" {r.fidelity_db:5.1f} {r.stroke_snr_median_db:6.1f}"
                f" {r.fit_geometric_s:5.2f}>{r.fit_s:<5.2f}"
            )
    print("\nmedians (geometric > timed); velocity SNR against the 15 Hz low-pass reference [raw]")
    for dataset in [d for d in loaders if any(r.dataset == d for r in rows)]:
        subset = [r for r in rows if r.dataset == dataset]
        failed = sum(bool(r.error) for r in subset)
        ratio = [r.strokes / r.strokes_geometric for r in subset if not r.error]
        print(
            f"[{dataset}] {len(subset)} files, {failed} failed: velocity SNR"
            f" {_median(subset, 'snr_geometric_db'):.1f} > {_median(subset, 'snr_db'):.1f} dB"
            f" [raw {_median(subset, 'snr_raw_geometric_db'):.1f} >"
            f" {_median(subset, 'snr_raw_db'):.1f};"
            f" ceiling {_median(subset, 'ceiling_raw_db'):.1f}]"
            f" (own clock {_median(subset, 'snr_clock_db'):.1f}"
            f" [{_median(subset, 'snr_clock_raw_db'):.1f}], reference fidelity"
            f" {_median(subset, 'fidelity_db'):.1f}, interior"
            f" {_median(subset, 'snr_interior_db'):.1f}, 10 / 20 Hz"
            f" {_median(subset, 'snr_10hz_db'):.1f} /"
            f" {_median(subset, 'snr_20hz_db'):.1f}, per stroke"
            f" {_median(subset, 'stroke_snr_median_db'):.1f}), shape error"
            f" {_median(subset, 'shape_geometric_pct'):.3f} >"
            f" {_median(subset, 'shape_pct'):.3f} %,"
            f" strokes x {np.median(ratio) if ratio else math.nan:.2f}, fit time"
            f" {_median(subset, 'fit_geometric_s'):.2f} > {_median(subset, 'fit_s'):.2f} s"
        )
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(asdict(rows[0])))
            writer.writeheader()
            writer.writerows(asdict(r) for r in rows)


if __name__ == "__main__":
    main()
