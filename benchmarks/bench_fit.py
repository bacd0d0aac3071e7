"""Reconstruction benchmark (paper §6) on real captures: shape error, strokes, time, velocity SNR.

Run from the repository root, with the shared data beside it (``../shared/data``)::

    python benchmarks/bench_fit.py [--data ../shared/data] [--model gamma] [--jobs 2]
                                   [--csv fits.csv] [--no-refine]

Datasets (the development half of the project's data; see its README):

* ``gml``: the graffiti tags in ``gml/dev`` (GML and #000000book JSON), read by
  :func:`tagbot.load_traces`; velocity SNR on the files ``index.csv`` marks as
  ``velocity_benchmark`` (dense real timestamps);
* ``unipen``: the NICI cursive words of writers anton and corrie (100 Hz tablet, words from the
  ``.SEGMENT WORD`` lines, time running through the in-air samples);
* ``mocap``: capital letters A–Z from motion capture (120 Hz, metres → mm);
* ``synthetic``: 50 random ΓΛ* plans (3–8 targets 20–50 mm apart, turning up to ±2.5 rad,
  tangents within ±1.2 rad, delays in the fitter's range) sampled without timing: the round trip
  of the tests, larger. It needs no data folder.

Per file: traces, points, strokes, strokes per 180° of the input's turning, mean and max shape
error (% of the bounding-box diagonal), fit time, fit time over one sampling of the fitted tag at
10 ms, the report's time (shape error and velocity SNR, :func:`tagbot.metrics.fit_report`) over
the fit's (goal ≤ 0.2), the whole command's work (load + fit + report; each timed as the best of
3 runs), velocity SNR (dB, after the best uniform time scaling
and offset). Summaries give median, p90 and worst. A fit that fails is reported as a failure,
never dropped. Each worker process fits one small tag before timing anything, so that loading
the compiled kernels (numba) is not counted as fit time.
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
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from tagbot.gesture import fit
from tagbot.inputs import Trace, load_traces
from tagbot.inputs.unipen import parse_unipen
from tagbot.metrics import fit_report
from tagbot.model.plan import Tag, random_plan


@dataclass
class Row:
    dataset: str
    name: str
    traces: int = 0
    points: int = 0
    strokes: int = 0
    strokes_per_180: float = math.nan
    mean_pct: float = math.nan
    max_pct: float = math.nan
    fit_s: float = math.nan
    fit_over_sampling: float = math.nan
    snr_db: float = math.nan
    report_share: float = math.nan
    command_s: float = math.nan
    error: str = ""


# --- datasets -------------------------------------------------------------------------------


def gml_cases(data: Path) -> list[tuple[str, str, object]]:
    folder = data / "gml" / "dev"
    timed = set()
    with open(folder / "index.csv", newline="") as f:
        for row in csv.DictReader(f):
            if row.get("velocity_benchmark", "").strip().lower() == "true":
                timed.add(row["file"])
    cases = []
    for path in sorted(folder.iterdir()):
        if path.name == "index.csv":
            continue
        cases.append(("gml", path.name, (str(path), path.name in timed)))
    return cases


def unipen_cases(data: Path) -> list[tuple[str, str, object]]:
    """Each ``.SEGMENT WORD`` of the segment files, read by :mod:`tagbot.inputs.unipen` from the
    file they include (the library never follows ``.INCLUDE``: the benchmark does, on its data)."""
    cases = []
    for seg_file in sorted((data / "unipen" / "data").rglob("*.dat")):
        index = parse_unipen(seg_file.read_bytes(), str(seg_file))
        if not index.includes:
            continue
        path = data / "unipen" / "include" / index.includes[0]
        recording = parse_unipen(path.read_bytes(), str(path))
        for seg in index.segments:
            if seg.kind == "WORD" and seg.components is not None:
                name = f"{path.stem}:{seg.components}:{seg.label}"
                cases.append(("unipen", name, recording.traces(seg.components)))
    return cases


def mocap_cases(data: Path) -> list[tuple[str, str, object]]:
    letters = np.load(data / "mocap_letters" / "all_letters_max.npz", allow_pickle=True)
    cases = []
    for name in sorted(letters.files):
        parts = letters[name]
        components = [
            (i % 2 == 1, np.asarray(p, dtype=float) * 1000.0) for i, p in enumerate(parts)
        ]
        cases.append(("mocap", name, components))
    return cases


def synthetic_cases(data: Path, count: int = 50) -> list[tuple[str, str, object]]:
    return [("synthetic", f"seed-{seed}", seed) for seed in range(count)]


def _synthetic_traces(seed: int) -> list[Trace]:
    plan = random_plan(np.random.default_rng(seed))
    return [Trace(Tag((plan,)).sample(0.005).xy)]


def _timed_traces(components: list[tuple[bool, np.ndarray]], rate: float) -> list[Trace]:
    """Pen-down components as traces on one clock running through the pen-up samples."""
    traces, index = [], 0
    for down, points in components:
        if down and len(points):
            traces.append(Trace(points, (index + np.arange(len(points))) / rate))
        index += len(points)
    return traces


def case_traces(case: tuple[str, str, object]) -> list[Trace]:
    """A case's traces, as its dataset reads them."""
    dataset, _, payload = case
    if dataset == "gml":
        path, timed = payload
        traces = load_traces(path)
        # Velocity SNR only where index.csv vouches for the timing.
        return traces if timed else [Trace(tr.xy) for tr in traces]
    if dataset == "synthetic":
        return _synthetic_traces(payload)
    if dataset == "unipen":
        return payload
    return _timed_traces(payload, 120.0)


# --- one fit ---------------------------------------------------------------------------------


TIMING = os.environ.get("TAGBOT_BENCH_TIMING", "ignore")
"""``fit(timing=...)`` (``--timing``; workers read it from the environment): ``ignore``, the
geometric fit, by default (see bench_timing.py for the timed fit)."""


def run_case(case: tuple[str, str, object], model: str, refine: bool) -> Row:
    dataset, name, payload = case
    row = Row(dataset, name)
    try:
        load_s = 0.0
        if dataset == "gml":
            load_s = min(_timed(lambda: load_traces(payload[0])) for _ in range(3))
        traces = case_traces(case)
        # Fit and sampling are each timed as the best of 3 runs (a fit is deterministic).
        options = {"model": model, "refine": refine, "timing": TIMING}
        tag = fit(traces, **options)
        row.fit_s = min(_timed(lambda: fit(traces, **options)) for _ in range(3))
        sampling = min(_timed(lambda: tag.sample(0.01)) for _ in range(3))
        report = fit_report(traces, tag)
        report_s = min(_timed(lambda: fit_report(traces, tag)) for _ in range(3))
        row.report_share = report_s / row.fit_s
        row.command_s = load_s + row.fit_s + report_s
        row.traces, row.points, row.strokes = report.traces, report.points, report.strokes
        row.strokes_per_180 = report.strokes_per_half_turn
        row.mean_pct, row.max_pct = 100 * report.shape.mean, 100 * report.shape.max
        row.fit_over_sampling = row.fit_s / sampling
        if report.velocity_snr_db is not None:
            row.snr_db = report.velocity_snr_db
    except Exception as e:  # a benchmark reports every failure and goes on
        row.error = f"{type(e).__name__}: {e}"
    return row


def _warm_up(model: str, refine: bool) -> None:
    tag = fit(_synthetic_traces(0), model=model, refine=refine)
    fit_report(_synthetic_traces(0), tag)


def _timed(fn) -> float:
    started = time.perf_counter()
    fn()
    return time.perf_counter() - started


# --- report ----------------------------------------------------------------------------------


def summarise(rows: list[Row], field: str) -> str:
    values = np.array([getattr(r, field) for r in rows if not r.error], dtype=float)
    values = values[np.isfinite(values)]
    if not values.size:
        return "-"
    worst = values.min() if field == "snr_db" else values.max()
    return (
        f"{np.median(values):.3g} / {np.percentile(values, 90 if field != 'snr_db' else 10):.3g}"
        f" / {worst:.3g}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default_data = Path(__file__).resolve().parent.parent.parent / "shared" / "data"
    parser.add_argument("--data", type=Path, default=default_data, help="the shared data folder")
    parser.add_argument("--model", choices=["gamma", "sigma"], default="gamma")
    parser.add_argument("--no-refine", dest="refine", action="store_false")
    parser.add_argument("--timing", choices=["ignore", "auto", "match"], default="ignore")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--datasets", default="gml,unipen,mocap,synthetic")
    parser.add_argument("--csv", type=Path, help="write every row to this CSV file")
    parser.add_argument("--quiet", action="store_true", help="summaries only")
    args = parser.parse_args()
    os.environ["TAGBOT_BENCH_TIMING"] = args.timing  # spawned workers read it at import
    names = args.datasets.split(",")
    unknown = sorted(set(names) - {"gml", "unipen", "mocap", "synthetic"})
    if unknown:
        sys.exit(f"bench_fit: unknown dataset {unknown[0]!r}")
    if not args.data.is_dir() and names != ["synthetic"]:
        sys.exit(f"bench_fit: no data folder at {args.data} (use --data, or --datasets synthetic)")

    loaders = {
        "gml": gml_cases,
        "unipen": unipen_cases,
        "mocap": mocap_cases,
        "synthetic": synthetic_cases,
    }
    cases = [c for d in names for c in loaders[d](args.data)]
    print(
        f"machine: {platform.machine()} python {platform.python_version()} numpy"
        f" {np.__version__}; model {args.model}, refine {args.refine}, {len(cases)} fits,"
        f" {args.jobs} processes"
    )
    started = time.perf_counter()
    # One fit per core, each single-threaded: fresh worker processes started with OpenBLAS's
    # threads off, which would otherwise spin against each other (a 90 ms fit measured 1.4 s).
    for variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(variable, "1")
    spawn = multiprocessing.get_context("spawn")
    # Each worker first fits one small tag: the compiled kernels load from numba's cache (or
    # compile, on a first run) once per process, which is no part of any fit's cost.
    with ProcessPoolExecutor(
        args.jobs, mp_context=spawn, initializer=_warm_up, initargs=(args.model, args.refine)
    ) as pool:
        rows = list(
            pool.map(run_case, cases, [args.model] * len(cases), [args.refine] * len(cases))
        )
    print(f"wall time {time.perf_counter() - started:.1f} s\n")

    if not args.quiet:
        print(
            f"{'file':44s} {'trc':>4s} {'pts':>6s} {'strk':>5s} {'s/180':>6s} {'mean%':>6s}"
            f" {'max%':>6s} {'fit s':>6s} {'ratio':>6s} {'SNR dB':>6s}"
        )
        for r in rows:
            label = f"{r.dataset}:{r.name}"[:44]
            if r.error:
                print(f"{label:44s} FAILED {r.error}")
                continue
            print(
                f"{label:44s} {r.traces:4d} {r.points:6d} {r.strokes:5d} {r.strokes_per_180:6.2f}"
                f" {r.mean_pct:6.2f} {r.max_pct:6.2f} {r.fit_s:6.2f} {r.fit_over_sampling:6.0f}"
                f" {r.snr_db:6.1f}"
            )
    print("\nmedian / p90 / worst (SNR: median / p10 / worst)")
    fields = [
        ("mean_pct", "mean shape error %"),
        ("max_pct", "max shape error %"),
        ("strokes", "strokes"),
        ("strokes_per_180", "strokes per 180°"),
        ("fit_s", "fit time s"),
        ("fit_over_sampling", "fit / one sampling"),
        ("snr_db", "velocity SNR dB"),
        ("report_share", "report time / fit time"),
        ("command_s", "load + fit + report s"),
    ]
    datasets = ("gml", "unipen", "mocap", "synthetic")
    for dataset in [d for d in datasets if any(r.dataset == d for r in rows)]:
        subset = [r for r in rows if r.dataset == dataset]
        failed = [r for r in subset if r.error]
        print(f"[{dataset}] {len(subset)} files, {len(failed)} failed")
        for field, label in fields:
            print(f"  {label:22s} {summarise(subset, field)}")
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(asdict(rows[0])))
            writer.writeheader()
            writer.writerows(asdict(r) for r in rows)


if __name__ == "__main__":
    main()
