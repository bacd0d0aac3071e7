"""Trustworthy reconstruction (issue 29): the default fit against the geometric one, timed data.

Run from the repository root, with the shared data beside it (``../shared/data``)::

    python benchmarks/bench_timing.py [--data ../shared/data] [--model gamma] [--jobs 2]
                                      [--datasets gml,unipen,mocap] [--limit N]
                                      [--csv timing.csv] [--quiet] [--rerecord]
    python benchmarks/bench_timing.py --calibrate     # the reference against synthetic truth

Datasets as in ``bench_fit.py``, timed captures only: the GML files ``index.csv`` marks as
``velocity_benchmark`` (dense real timestamps), the UNIPEN words (100 Hz tablet) and the mocap
letters (120 Hz). Per file, the default fit (``timing="auto"``,
:func:`tagbot.gesture.reconstruction`) and the geometric fit (``timing="ignore"``):

- shape error, mean and max (fractions of the input's bounding-box diagonal, as
  :func:`tagbot.metrics.fit_report` gives them), and whether the default fit keeps within the
  shape margin of the geometric one: mean ≤ geometric + :data:`SHAPE_MARGIN_MEAN`, max ≤
  max(1.5 × geometric, geometric + 0.005) (:data:`SHAPE_MARGIN_MAX`);
- the default fit's velocity SNR with no time scaling (:func:`tagbot.metrics.tag_clock_snr`):
  on the tag's own clock (one offset for the capture) and trace by trace (one offset per trace),
  against the reference (:func:`tagbot.metrics.recorded_velocity`: samples at their instants,
  resampled every 10 ms, 4th-order zero-phase Butterworth low-pass, central differences) at
  10 Hz and 15 Hz, and against raw central differences; and the literature's best-mapping
  figure (each trace after its best time scale and offset, 15 Hz, ``velocity_snr_db``);
- the reference's **ceiling** at each cut-off: each fitted plan sampled at its trace's recorded
  stamps (a motion whose velocity is known exactly), put through the same reference, against
  the plan's exact velocity at the reference's instants (energy-weighted over traces, as the
  other figures);
- with ``--rerecord``, the fitter against a motion it can represent: the default fit sampled
  at the capture's own instants (noise-free, :func:`rerecorded`) and fitted again, its
  per-trace SNR and ceiling at 10 Hz (the gap there is the fitter's, not the data's);
- strokes per second of writing (the default fit's strokes over the traces' total pen-down span,
  :func:`tagbot.gesture.timing.pen_down_span`) and strokes default / geometric;
- fit time of each (best of 2 runs, after a warm-up fit in each worker);
- how each trace was timed (matched, restrained, mapped, scaled, geometric) and files whose
  whole clock the default fit refused.

Per dataset the summary gives medians (p10 for SNRs, p90 for times and errors), and the goals:
no file over the shape margin; per-trace SNR within 2 dB of the ceiling and own-clock SNR within
1 dB of per-trace (medians, at each cut-off); strokes ≤ 1.5× the geometric fit's.
"""

from __future__ import annotations

import argparse
import csv
import math
import multiprocessing
import os
import platform
import sys
import time
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_fit import case_traces, gml_cases, mocap_cases, unipen_cases

from tagbot.gesture import reconstruction
from tagbot.gesture.timing import SHAPE_MARGIN_MAX, SHAPE_MARGIN_MEAN, fit_cost, pen_down_span
from tagbot.inputs import Trace
from tagbot.inputs.stamps import sample_instants
from tagbot.metrics import clock_velocity_snr, fit_report, recorded_velocity, tag_clock_snr
from tagbot.model.motion import evaluate_plan, sample_plan
from tagbot.model.plan import Tag

CUTOFFS: dict[str, float | None] = {"10hz": 10.0, "15hz": 15.0, "raw": None}
"""The references every SNR is given against: low-passed at 10 Hz, at 15 Hz (the library's
``VELOCITY_CUTOFF``), and raw central differences."""
KINDS = ("matched", "restrained", "mapped", "scaled", "geometric")
"""How a trace can be timed (:class:`tagbot.gesture.timing.TraceTiming`), the most timing first."""
CEILING_GAP = 2.0
"""Goal: median per-trace SNR at most this far (dB) below the median ceiling..."""
CLOCK_GAP = 1.0
"""... and median own-clock SNR at most this far below the median per-trace SNR."""
STROKE_RATIO = 1.5
"""Goal: the default fit's strokes at most this many times the geometric fit's."""


@dataclass
class Row:
    dataset: str
    name: str
    traces: int = 0
    points: int = 0
    strokes_geometric: int = 0
    strokes: int = 0
    writing_s: float = math.nan
    """Total pen-down span of the traces (:func:`pen_down_span`), seconds."""
    strokes_per_s: float = math.nan
    shape_mean_geometric: float = math.nan
    shape_max_geometric: float = math.nan
    shape_mean: float = math.nan
    shape_max: float = math.nan
    shape_excess: float = math.nan
    """The default fit's largest excess over its shape margin (fraction of the size; > 0: over)."""
    clock_10hz_db: float = math.nan
    trace_10hz_db: float = math.nan
    ceiling_10hz_db: float = math.nan
    clock_15hz_db: float = math.nan
    trace_15hz_db: float = math.nan
    ceiling_15hz_db: float = math.nan
    clock_raw_db: float = math.nan
    trace_raw_db: float = math.nan
    ceiling_raw_db: float = math.nan
    best_mapping_db: float = math.nan
    """The default fit's ``velocity_snr_db`` (best time scale and offset per trace, 15 Hz)."""
    rerecorded_10hz_db: float = math.nan
    """Per-trace SNR (10 Hz) of the default fit of :func:`rerecorded` traces (the default fit
    sampled at the capture's own instants): the fitter against a motion it can represent..."""
    rerecorded_ceiling_10hz_db: float = math.nan
    """... and that fit's ceiling: their gap is the fitter's own, with no noise in the data."""
    rerecorded_traces: int = 0
    """Re-recorded traces the fit times (:func:`tagbot.gesture.timing.fit_cost`)..."""
    rerecorded_costlier: int = 0
    """... and of those, how many the refit ends with a higher cost than the plan they were
    recorded from: the fit stopped in a worse minimum (a search gap, not the objective's)."""
    fit_geometric_s: float = math.nan
    fit_s: float = math.nan
    matched: int = 0
    restrained: int = 0
    mapped: int = 0
    scaled: int = 0
    geometric: int = 0
    refused: str = ""
    """Why the default fit refused the whole clock (fitted the shape alone), if it did."""
    error: str = ""


def shape_excess(mean: float, largest: float, mean_geometric: float, max_geometric: float) -> float:
    """How far (fraction of the size) a fit's shape error goes beyond the margin of the geometric
    fit's: the larger of the mean's and the max's excess; > 0 is over the margin."""
    limit_max = max(SHAPE_MARGIN_MAX[0] * max_geometric, max_geometric + SHAPE_MARGIN_MAX[1])
    return max(mean - (mean_geometric + SHAPE_MARGIN_MEAN), largest - limit_max)


def ceiling_db(traces: Sequence[Any], tag: Tag, cutoff: float | None) -> float:
    """The reference's ceiling: each plan of ``tag`` sampled at its trace's recorded stamps, put
    through :func:`recorded_velocity` at ``cutoff``, against the plan's exact velocity at the
    reference's instants (the same clock); energy-weighted over traces (traces too short for
    the reference left out, as :func:`tag_clock_snr` leaves them)."""
    signal = noise = 0.0
    for plan, trace in zip(tag.plans, traces, strict=True):
        stamps = np.asarray(trace.t, dtype=float)  # non-decreasing (Trace)
        xy, _ = evaluate_plan(plan, stamps, tag.size)
        try:
            grid, v = recorded_velocity(stamps, xy, cutoff=cutoff)
        except ValueError:
            continue
        _, exact = evaluate_plan(plan, grid, tag.size)
        signal += float(np.sum(v * v))
        noise += float(np.sum((v - exact) ** 2))
    if not signal > 0:
        return math.nan
    return 10 * math.log10(signal / noise) if noise > 0 else math.inf


def rerecorded(traces: Sequence[Any], tag: Tag) -> list[Trace]:
    """``tag`` (one plan per trace) sampled at the instants each trace's samples were most
    likely taken at (:func:`tagbot.inputs.stamps.sample_instants`, as the fit and the reference
    place them): a recording with the capture's own sampling whose motion a plan can follow
    exactly, with no noise in positions or stamps."""
    out = []
    for plan, trace in zip(tag.plans, traces, strict=True):
        t, _ = sample_instants(np.asarray(trace.t, float), np.asarray(trace.xy, float))
        t = np.maximum.accumulate(t)
        xy, _ = evaluate_plan(plan, t, tag.size)
        out.append(Trace(xy, t))
    return out


def costlier_refits(traces: Sequence[Any], recorded: Tag, refit: Tag) -> tuple[int, int]:
    """Of ``traces`` (re-recorded from ``recorded``, one plan per trace) those the fit times,
    and how many of them ``refit``'s plan costs more on than ``recorded``'s
    (:func:`~tagbot.gesture.timing.fit_cost`, both at ``recorded``'s size)."""
    timed = costlier = 0
    for truth, fitted, trace in zip(recorded.plans, refit.plans, traces, strict=True):
        try:
            cost_truth = fit_cost(truth, trace, recorded.size)
        except ValueError:
            continue
        timed += 1
        costlier += fit_cost(fitted, trace, recorded.size) > cost_truth
    return timed, costlier


def run_case(case: tuple[str, str, object], model: str, rerecord: bool = False) -> Row:
    """Both fits of one file and every figure of :class:`Row` (the re-recorded ones only with
    ``rerecord``)."""
    dataset, name, _ = case
    row = Row(dataset, name)
    try:
        traces = case_traces(case)
        row.traces, row.points = len(traces), sum(len(tr.xy) for tr in traces)
        geometric, row.fit_geometric_s = _best_of_2(lambda: reconstruction(traces, model, "ignore"))
        chosen, row.fit_s = _best_of_2(lambda: reconstruction(traces, model, "auto"))
        report_g = fit_report(traces, geometric.tag)
        report = fit_report(traces, chosen.tag, timings=chosen.timings)
        row.strokes_geometric, row.strokes = report_g.strokes, report.strokes
        row.writing_s = sum(pen_down_span(tr.t) for tr in traces)
        row.strokes_per_s = row.strokes / row.writing_s if row.writing_s > 0 else math.nan
        row.shape_mean_geometric, row.shape_max_geometric = report_g.shape.mean, report_g.shape.max
        row.shape_mean, row.shape_max = report.shape.mean, report.shape.max
        row.shape_excess = shape_excess(
            row.shape_mean, row.shape_max, row.shape_mean_geometric, row.shape_max_geometric
        )
        for label, cutoff in CUTOFFS.items():
            snr = tag_clock_snr(traces, chosen.tag, cutoff)
            if snr is not None:
                setattr(row, f"clock_{label}_db", snr[0])
                setattr(row, f"trace_{label}_db", snr[1])
            setattr(row, f"ceiling_{label}_db", ceiling_db(traces, chosen.tag, cutoff))
        if report.velocity_snr_db is not None:
            row.best_mapping_db = report.velocity_snr_db
        if rerecord and chosen.timings is not None:
            again = rerecorded(traces, chosen.tag)
            refit = reconstruction(again, model, "auto").tag
            snr = tag_clock_snr(again, refit, CUTOFFS["10hz"])
            if snr is not None:
                row.rerecorded_10hz_db = snr[1]
            row.rerecorded_ceiling_10hz_db = ceiling_db(again, refit, CUTOFFS["10hz"])
            row.rerecorded_traces, row.rerecorded_costlier = costlier_refits(
                again, chosen.tag, refit
            )
        kinds = Counter(t.kind for t in chosen.timings or ())
        for kind in KINDS:
            setattr(row, kind, kinds[kind])
        if chosen.timings is None:
            row.refused = chosen.note or "timing ignored"
    except Exception as e:  # a benchmark reports every failure and goes on
        row.error = f"{type(e).__name__}: {e}"
    return row


def _best_of_2(fit: Callable[[], Any]) -> tuple[Any, float]:
    """``fit()``'s result (a fit is deterministic) and the shorter of two runs' times."""
    times = []
    for _ in range(2):
        started = time.perf_counter()
        result = fit()
        times.append(time.perf_counter() - started)
    return result, min(times)


def _warm_up(model: str) -> None:
    """Load (or compile) the kernels both fits and the figures use before anything is timed."""
    from tagbot.inputs import Trace

    t = np.linspace(0, 1, 101)
    traces = [Trace(np.column_stack([t * 50, np.sin(6 * t) * 20]), t)]
    for timing in ("ignore", "auto"):
        rec = reconstruction(traces, model, timing)
        fit_report(traces, rec.tag, timings=rec.timings)
        for cutoff in CUTOFFS.values():
            tag_clock_snr(traces, rec.tag, cutoff)
            ceiling_db(traces, rec.tag, cutoff)


# --- summary ---------------------------------------------------------------------------------


def _values(rows: list[Row], name: str) -> np.ndarray:
    values = np.array([getattr(r, name) for r in rows], dtype=float)
    return values[np.isfinite(values)]


def _stat(
    rows: list[Row],
    name: str,
    tail: float,
    scale: float = 1.0,
    digits: int = 1,
    worst: bool = False,
) -> str:
    """``median / p{tail}`` of a field over ``rows`` (times ``scale``), ``/ max`` too if
    ``worst``; "-" without values."""
    values = _values(rows, name) * scale
    if not values.size:
        return "-"
    text = f"{np.median(values):.{digits}f} / {np.percentile(values, tail):.{digits}f}"
    return text + (f" / {values.max():.{digits}f}" if worst else "")


def _median(rows: list[Row], name: str) -> float:
    values = _values(rows, name)
    return float(np.median(values)) if values.size else math.nan


def _goal(gap: float, limit: float) -> str:
    if math.isnan(gap):
        return "no figure"
    return "met" if gap <= limit else "NOT met"


def summarise(dataset: str, rows: list[Row]) -> list[str]:
    """The summary lines of one dataset."""
    done = [r for r in rows if not r.error]
    lines = [f"[{dataset}] {len(rows)} files, {len(rows) - len(done)} failed"]
    if not done:
        return lines
    pct = 100.0
    worst = max(done, key=lambda r: r.shape_excess)
    over = [r for r in done if r.shape_excess > 0]
    lines += [
        "  shape error % of the size, median / p90 / worst: default fit mean"
        f" {_stat(done, 'shape_mean', 90, pct, 3, True)}, max"
        f" {_stat(done, 'shape_max', 90, pct, 3, True)}; geometric mean"
        f" {_stat(done, 'shape_mean_geometric', 90, pct, 3, True)}, max"
        f" {_stat(done, 'shape_max_geometric', 90, pct, 3, True)}",
        f"  shape margin: {len(over)} files over (goal: none, {_goal(len(over), 0)}); worst"
        f" {worst.name}: {pct * worst.shape_excess:+.4f} % of the size beyond its margin (mean"
        f" {pct * worst.shape_mean:.3f} against {pct * worst.shape_mean_geometric:.3f}, max"
        f" {pct * worst.shape_max:.3f} against {pct * worst.shape_max_geometric:.3f})",
        "  velocity SNR dB of the default fit, no time scaling, median / p10:",
    ]
    for label in CUTOFFS:
        clock, trace, ceiling = (
            _median(done, f"{kind}_{label}_db") for kind in ("clock", "trace", "ceiling")
        )
        name = "raw differences" if CUTOFFS[label] is None else f"{CUTOFFS[label]:g} Hz low-pass"
        lines.append(
            f"    {name:16s} own clock {_stat(done, f'clock_{label}_db', 10)}, per trace"
            f" {_stat(done, f'trace_{label}_db', 10)}, ceiling"
            f" {_stat(done, f'ceiling_{label}_db', 10)};"
            f" per trace - ceiling {trace - ceiling:+.1f} ({_goal(ceiling - trace, CEILING_GAP)}),"
            f" own clock - per trace {clock - trace:+.1f} ({_goal(trace - clock, CLOCK_GAP)})"
        )
    ratio = np.array([r.strokes / r.strokes_geometric for r in done if r.strokes_geometric])
    kinds = {kind: sum(getattr(r, kind) for r in done) for kind in KINDS}
    falling = sum(any(getattr(r, k) for k in KINDS[1:]) for r in done)
    refused = [r for r in done if r.refused]
    lines += [
        "    best mapping (each trace's time scale and offset, 15 Hz)"
        f" {_stat(done, 'best_mapping_db', 10)}",
        f"  strokes per second of writing {_stat(done, 'strokes_per_s', 90)} (median / p90);"
        f" strokes default / geometric median {np.median(ratio):.2f}, max {ratio.max():.2f}"
        f" (goal <= {STROKE_RATIO:g}: {_goal(float(ratio.max()) - STROKE_RATIO, 0.0)})",
        f"  fit time s, median / p90: default {_stat(done, 'fit_s', 90, digits=2)},"
        f" geometric {_stat(done, 'fit_geometric_s', 90, digits=2)}",
        f"  traces timed: {', '.join(f'{n} {k}' for k, n in kinds.items())};"
        f" {falling} files with a trace not matched; {len(refused)} files' whole clock refused",
    ]
    lines += [f"    refused {r.name}: {r.refused}" for r in refused]
    again = [r for r in done if not math.isnan(r.rerecorded_10hz_db)]
    if again:
        trace, ceiling = (_median(again, f"rerecorded{k}_10hz_db") for k in ("", "_ceiling"))
        lines.append(
            f"  re-recorded (the default fit sampled at the capture's instants, fitted again),"
            f" 10 Hz, {len(again)} files: per trace {_stat(again, 'rerecorded_10hz_db', 10)},"
            f" ceiling {_stat(again, 'rerecorded_ceiling_10hz_db', 10)}; per trace - ceiling"
            f" {trace - ceiling:+.1f} (the fitter's own gap); the refit costs more than the plan"
            f" it was recorded from on {sum(r.rerecorded_costlier for r in again)} of"
            f" {sum(r.rerecorded_traces for r in again)} traces (where it does, the fit stopped"
            " in a worse minimum: a search gap)"
        )
    return lines


def _row_line(r: Row) -> str:
    label = f"{r.dataset}:{r.name}"[:40]
    if r.error:
        return f"{label:40s} FAILED {r.error}"
    kinds = "".join(f"{getattr(r, k)}{k[0]}" if getattr(r, k) else "" for k in KINDS)
    return (
        f"{label:40s} {r.strokes_geometric:4d}>{r.strokes:<4d} {r.strokes_per_s:5.1f}"
        f" {100 * r.shape_mean:6.3f} {100 * r.shape_max:6.3f} {100 * r.shape_excess:+7.3f}"
        f" {r.clock_10hz_db:5.1f} {r.trace_10hz_db:5.1f} {r.ceiling_10hz_db:5.1f}"
        f" {r.clock_15hz_db:5.1f} {r.trace_15hz_db:5.1f} {r.ceiling_15hz_db:5.1f}"
        f" {r.clock_raw_db:5.1f} {r.trace_raw_db:5.1f} {r.ceiling_raw_db:5.1f}"
        f" {r.best_mapping_db:5.1f} {r.fit_geometric_s:5.2f}>{r.fit_s:<5.2f} {kinds or 'refused'}"
    )


# --- calibration -----------------------------------------------------------------------------


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
    from tagbot.model.plan import random_timed_plan

    print(
        f"median SNR (dB) of the reference against the true velocity / the ceiling (the true"
        f" plan sampled at the stamps without noise, as bench_timing's ceiling), {plans} plans"
    )
    print(f"{'digitiser':32s}" + "".join(f"{'raw' if c is None else f'{c:g} Hz':>13s}"
                                           for c in CALIBRATION_CUTOFFS))  # fmt: skip
    for label, kind in DIGITISERS.items():
        rng = np.random.default_rng(seed)
        scores: dict[float | None, list[float]] = {c: [] for c in CALIBRATION_CUTOFFS}
        ceilings: dict[float | None, list[float]] = {c: [] for c in CALIBRATION_CUTOFFS}
        for _ in range(plans):
            plan = random_timed_plan(rng)
            trace = simulated_capture(plan, rng, **kind)
            t, _, v = sample_plan(Tag((plan,)), 0, 0.001)
            for cutoff in CALIBRATION_CUTOFFS:
                scores[cutoff].append(clock_velocity_snr(trace.t, trace.xy, t, v, cutoff))
                ceilings[cutoff].append(ceiling_db([trace], Tag((plan,)), cutoff))
        print(
            f"{label:32s}"
            + "".join(f"{np.median(scores[c]):6.1f} /{np.median(ceilings[c]):5.1f}" for c in scores)
        )


# --- command ---------------------------------------------------------------------------------


def _arguments() -> argparse.Namespace:
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
        "--rerecord",
        action="store_true",
        help="also fit each default fit again, sampled at the capture's instants (noise-free)",
    )
    parser.add_argument(
        "--calibrate",
        action="store_true",
        help="only the reference's calibration on synthetic digitisers (no data needed)",
    )
    return parser.parse_args()


def main() -> None:
    args = _arguments()
    if args.calibrate:
        calibrate()
        return
    loaders = {"gml": gml_cases, "unipen": unipen_cases, "mocap": mocap_cases}
    names = args.datasets.split(",")
    unknown = sorted(set(names) - set(loaders))
    if unknown:
        sys.exit(f"bench_timing: unknown dataset {unknown[0]!r} (gml, unipen, mocap)")
    if args.jobs < 1:
        sys.exit(f"bench_timing: --jobs must be at least 1, got {args.jobs}")
    if not args.data.is_dir():
        sys.exit(f"bench_timing: no data folder at {args.data} (use --data)")
    cases = []
    for dataset in names:
        try:
            found = loaders[dataset](args.data)
        except (OSError, ValueError, KeyError) as e:
            sys.exit(f"bench_timing: {dataset} data under {args.data}: {e}")
        if dataset == "gml":  # dense real timestamps only
            found = [c for c in found if c[2][1]]
        cases += found[: args.limit] if args.limit else found
    for variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(variable, "1")
    print(
        f"machine: {platform.machine()} python {platform.python_version()} numpy"
        f" {np.__version__}; model {args.model}, {len(cases)} files, {args.jobs} processes"
    )
    started = time.perf_counter()
    spawn = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(
        args.jobs, mp_context=spawn, initializer=_warm_up, initargs=(args.model,)
    ) as pool:
        rows = list(
            pool.map(run_case, cases, [args.model] * len(cases), [args.rerecord] * len(cases))
        )
    print(f"wall time {time.perf_counter() - started:.1f} s")
    if not args.quiet:
        print(
            f"\n{'file':40s} {'strokes':>9s} {'str/s':>5s} {'mean%':>6s} {'max%':>6s}"
            f" {'excess':>7s} {'clock/trace/ceiling 10 Hz':>17s} {'15 Hz':>17s} {'raw':>17s}"
            f" {'best':>5s} {'fit s':>11s} timing"
        )
        for r in rows:
            print(_row_line(r))
    print("\nsummary: the default fit (timing='auto') against the geometric fit ('ignore')")
    for dataset in [d for d in loaders if any(r.dataset == d for r in rows)]:
        print("\n".join(summarise(dataset, [r for r in rows if r.dataset == dataset])))
    if args.csv and rows:
        with open(args.csv, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(asdict(rows[0])))
            writer.writeheader()
            writer.writerows(asdict(r) for r in rows)


if __name__ == "__main__":
    main()
