"""What the fit report costs, part by part, and what coarser settings would save and change.

Run from the repository root, with the shared data beside it (``../shared/data``)::

    python benchmarks/bench_report.py [--data ../shared/data] [--datasets gml,unipen,mocap]

For bench_fit's geometric fits (one process, each time the best of 3 runs), per dataset:

* the report's time over the fit's at the median (bench_fit's ``report / fit``), and the mean
  time of the report's parts: sampling the tag every 5 ms, the shape error, the velocity SNR,
  and the rest (Python glue; each part also runs slower after the others than alone);
* the same ratio with coarser settings that are *not* shipped, each alone and together: the
  velocity SNR's grid of 21 time scales instead of 41, the mean shape error from 125 samples
  per diagonal instead of 250, the model sampled every 10 ms instead of 5; and how far each
  moves the figures (shape error in % of the size, SNR in dB).

The coarser settings are set on :mod:`tagbot.metrics` for the run and restored after it.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import bench_fit
import numpy as np

from tagbot import metrics
from tagbot.gesture import fit
from tagbot.inputs import Trace
from tagbot.model.motion import sampled_plans

VARIANTS = {
    "shipped": (41, 250, 0.005),
    "21 scales": (21, 250, 0.005),
    "125 per diagonal": (41, 125, 0.005),
    "both": (21, 125, 0.005),
    "model every 10 ms": (41, 250, 0.01),
}
"""Label: (SNR time scales, mean shape samples per diagonal, model step in s)."""


@contextlib.contextmanager
def settings(scales: int, density: int) -> Iterator[None]:
    """The report's SNR scales and mean shape density set for a while."""
    saved = metrics._SCALES, metrics._SEARCH, metrics.MEAN_DENSITY
    grid = np.geomspace(saved[0][0], saved[0][-1], scales)
    metrics._SCALES, metrics._SEARCH = grid, (grid, *saved[1][1:])
    metrics.MEAN_DENSITY = density
    try:
        yield
    finally:
        metrics._SCALES, metrics._SEARCH, metrics.MEAN_DENSITY = saved


def best(fn: Callable[..., object], *args: object) -> float:
    """Seconds of ``fn(*args)``, the best of 3 runs (as bench_fit times)."""
    return min(bench_fit._timed(lambda: fn(*args)) for _ in range(3))


def parts(traces: list[Trace], tag: object) -> np.ndarray:
    """Seconds of the report's sampling, shape error and velocity SNR, each alone (the shape of
    each plan's whole motion, as the report has it for plans without an ``ink`` window)."""
    model_t, model_xy, model_v, first = sampled_plans(tag, 0.005)
    reference = metrics._joined([np.asarray(tr.xy, dtype=float) for tr in traces])
    drawn = (model_xy, first[1:])
    snr = 0.0
    if all(tr.t is not None for tr in traces):
        t = metrics._kernel_array(np.concatenate([tr.t for tr in traces]))
        ends = np.concatenate([[0], reference[1]])
        search = (0.01, metrics.VELOCITY_CUTOFF, *metrics._RECORDING, *metrics._SEARCH)
        snr = best(metrics.kernels.velocity_snrs, t, reference[0], ends, model_t, model_v, first,
                   *search)  # fmt: skip
    shape = best(metrics._shape_error, reference, drawn)
    return np.array([best(sampled_plans, tag, 0.005), shape, snr])


def figures(report: metrics.FitReport) -> np.ndarray:
    snr = report.velocity_snr_db
    return np.array(
        [100 * report.shape.mean, 100 * report.shape.max, np.nan if snr is None else snr]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default_data = Path(__file__).resolve().parent.parent.parent / "shared" / "data"
    parser.add_argument("--data", type=Path, default=default_data, help="the shared data folder")
    parser.add_argument("--datasets", default="gml,unipen,mocap,synthetic")
    args = parser.parse_args()
    loaders = {
        "gml": bench_fit.gml_cases,
        "unipen": bench_fit.unipen_cases,
        "mocap": bench_fit.mocap_cases,
        "synthetic": bench_fit.synthetic_cases,
    }
    names = args.datasets.split(",")
    if unknown := sorted(set(names) - set(loaders)):
        sys.exit(f"bench_report: unknown dataset {unknown[0]!r}")
    if not args.data.is_dir() and names != ["synthetic"]:
        sys.exit(f"bench_report: no data folder at {args.data} (use --data)")
    bench_fit._warm_up("gamma", True)
    print("report / fit at the median; mean ms of the report and its parts; largest change of"
          " the figures against the shipped settings")  # fmt: skip
    for dataset in names:
        cases = loaders[dataset](args.data)
        # File by file, the fit, the parts and every variant in turn: a busy moment of the
        # machine slows them all.
        fit_s, split = np.zeros(len(cases)), np.zeros((len(cases), 3))
        report_s = np.zeros((len(VARIANTS), len(cases)))
        found = np.zeros((len(VARIANTS), len(cases), 3))
        for i, case in enumerate(cases):
            traces = bench_fit.case_traces(case)
            tag = fit(traces, timing=bench_fit.TIMING)
            fit_s[i] = best(fit, traces, "gamma", bench_fit.TIMING)
            split[i] = parts(traces, tag)
            for v, (scales, density, step) in enumerate(VARIANTS.values()):
                with settings(scales, density):
                    found[v, i] = figures(metrics.fit_report(traces, tag, step))
                    report_s[v, i] = best(metrics.fit_report, traces, tag, step)
        for v, label in enumerate(VARIANTS):
            ratio = np.median(report_s[v] / fit_s)
            line = f"{dataset:9s} {label:18s} {ratio:.3f}  report {1e3 * report_s[v].mean():.3f} ms"
            if v == 0:
                mean = split.mean(axis=0)
                rest = report_s[0].mean() - mean.sum()
                line += (
                    f" = sampling {1e3 * mean[0]:.3f} + shape {1e3 * mean[1]:.3f}"
                    f" + SNR {1e3 * mean[2]:.3f} + rest {1e3 * rest:.3f}"
                )
            else:
                change = np.abs(found[v] - found[0])
                largest = [np.nanmax(c) if np.isfinite(c).any() else 0.0 for c in change.T]
                line += (
                    f"  | mean {largest[0]:.4f} pp, max {largest[1]:.4f} pp,"
                    f" SNR {largest[2]:.2f} dB"
                )
            print(line, flush=True)


if __name__ == "__main__":
    main()
