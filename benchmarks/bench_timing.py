"""Timing-aware reconstruction benchmark: ``fit(timing="match")`` against the geometric fit.

Run from the repository root, with the shared data beside it (``../shared/data``)::

    python benchmarks/bench_timing.py [--data ../shared/data] [--model gamma] [--jobs 2]
                                      [--datasets gml,unipen,mocap] [--csv timing.csv]

Datasets as in ``bench_fit.py``, timed captures only: the GML files ``index.csv`` marks as
``velocity_benchmark`` (dense real timestamps), the UNIPEN words (100 Hz) and the mocap letters
(120 Hz). Per file, for the geometric fit (``timing="ignore"``) and the timed fit
(``timing="match"``): strokes, mean shape error (% of the bounding-box diagonal), velocity SNR
(dB, :func:`tagbot.metrics.fit_report`: per trace after the best uniform time scale and offset)
and fit time (best of 2 runs, after a warm-up fit in each worker). Goals (issue 16): median
velocity SNR ≥ 20 dB, median shape error ≤ 0.5 %, strokes ≤ 1.5× the geometric fit, fit time
≤ 1 s median.
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

from bench_fit import _timed_traces, gml_cases, mocap_cases, unipen_cases

from tagbot.gesture import fit
from tagbot.inputs import load_traces
from tagbot.metrics import (
    clock_velocity_snr,
    fit_report,
    recorded_velocity,
    stroke_report,
)
from tagbot.model.motion import sample_plan


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
    stroke_snr_median_db: float = math.nan
    fit_geometric_s: float = math.nan
    fit_s: float = math.nan
    error: str = ""


def _traces(case: tuple[str, str, object]) -> list:
    dataset, _, payload = case
    if dataset == "gml":
        return load_traces(payload[0])
    return _timed_traces(payload, 100.0 if dataset == "unipen" else 120.0)


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
            if timing == "ignore":
                row.strokes_geometric, row.fit_geometric_s = report.strokes, seconds
                row.shape_geometric_pct, row.snr_geometric_db = 100 * report.shape.mean, snr
            else:
                row.strokes, row.fit_s = report.strokes, seconds
                row.shape_pct, row.snr_db = 100 * report.shape.mean, snr
                row.snr_clock_db = _clock_snr(traces, tag)
                per = [s.velocity_snr_db for s in stroke_report(traces, tag)]
                per = [v for v in per if v is not None and np.isfinite(v)]
                row.stroke_snr_median_db = float(np.median(per)) if per else math.nan
    except Exception as e:  # a benchmark reports every failure and goes on
        row.error = f"{type(e).__name__}: {e}"
    return row


def _clock_snr(traces: list, tag) -> float:
    """Energy-weighted velocity SNR of the traces on the fit's own clock (timed fits share it)."""
    signal = noise = 0.0
    for trace, (k, _) in zip(traces, enumerate(tag.plans), strict=True):
        t, _, v = sample_plan(tag, k, 0.005)
        try:
            db = clock_velocity_snr(trace.t, trace.xy, t, v)
            _, rec = recorded_velocity(trace.t, trace.xy)
        except ValueError:
            continue
        energy = float(np.sum(rec * rec))
        signal, noise = signal + energy, noise + energy / 10 ** (db / 10)
    return 10 * math.log10(signal / noise) if noise > 0 else math.nan


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
    args = parser.parse_args()
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
            f"{'file':40s} {'pts':>5s} {'strk':>9s} {'shape %':>13s} {'SNR dB':>11s} {'clock':>5s}"
            f" {'stroke':>6s} {'fit s':>11s}"
        )
        for r in rows:
            label = f"{r.dataset}:{r.name}"[:40]
            if r.error:
                print(f"{label:40s} FAILED {r.error}")
                continue
            print(
                f"{label:40s} {r.points:5d} {r.strokes_geometric:4d}>{r.strokes:<4d}"
                f" {r.shape_geometric_pct:6.2f}>{r.shape_pct:<6.2f} {r.snr_geometric_db:5.1f}>"
                f"{r.snr_db:<5.1f} {r.snr_clock_db:5.1f} {r.stroke_snr_median_db:6.1f}"
                f" {r.fit_geometric_s:5.2f}>"
                f"{r.fit_s:<5.2f}"
            )
    print("\nmedians (geometric > timed)")
    for dataset in [d for d in loaders if any(r.dataset == d for r in rows)]:
        subset = [r for r in rows if r.dataset == dataset]
        failed = sum(bool(r.error) for r in subset)
        ratio = [r.strokes / r.strokes_geometric for r in subset if not r.error]
        print(
            f"[{dataset}] {len(subset)} files, {failed} failed: velocity SNR"
            f" {_median(subset, 'snr_geometric_db'):.1f} > {_median(subset, 'snr_db'):.1f} dB"
            f" (own clock {_median(subset, 'snr_clock_db'):.1f}, per stroke"
            f" {_median(subset, 'stroke_snr_median_db'):.1f}), shape error"
            f" {_median(subset, 'shape_geometric_pct'):.2f} > {_median(subset, 'shape_pct'):.2f} %,"
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
