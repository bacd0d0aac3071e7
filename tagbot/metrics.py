"""How well a reconstruction matches its input: shape error, stroke counts, velocity SNR.

Shared by ``tagbot fit``, the benchmarks and the machine reports.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tagbot import metrics_kernels as kernels
from tagbot.inputs.stamps import BLENDS, GAP, REGULAR, SMOOTHING
from tagbot.model.motion import Motion, sampled_plans
from tagbot.model.plan import Plan, Tag

Array = NDArray[np.float64]

DENSITY = 4000
"""The maximum (Hausdorff) distance is found to within 1/(2·DENSITY) of the size..."""

MEAN_DENSITY = 250
"""... and the mean from samples this many per bounding-box diagonal..."""

MAX_SAMPLES = 50_000
"""... at most this many per drawing (long scribbles get a coarser spacing)."""

_CROWDED = 64
"""Samples expected within half a spacing of a point above which a drawing counts as crowded."""
_NEIGHBOURS = 4
"""Nearest samples whose segments a crowded drawing's distances are measured to."""

GRID_PER_POINT = 4
"""A recording is resampled at most this many times per recorded point (velocity SNR)."""

_SCALES = np.geomspace(0.25, 4.0, 41)
"""The velocity SNR's time scales, relative to the ratio of the recording's and model's spans."""
_POLISH_STEPS = np.linspace(-1.0, 1.0, 7)
POLISH_WIDTHS = np.array([0.1, 0.03])
"""The polish's pattern: each pair of ``steps`` (scale relative, offset in recording spans) at each
of the shrinking widths..."""
POLISH_ITERATIONS = 20
"""... then at most this many Levenberg-Marquardt steps on the scale and offset together."""
_SEARCH = (_SCALES, _POLISH_STEPS, POLISH_WIDTHS, POLISH_ITERATIONS)


@dataclass(frozen=True)
class ShapeError:
    """Closest-point distances between two sets of polylines, as fractions of the input's size."""

    mean: float
    """Mean over both directions (input → reconstruction and back), by arc length."""
    max: float
    """The largest distance either way (Hausdorff distance)."""
    size: float
    """The input's bounding-box diagonal the figures are divided by."""


def _tree(points: ArrayLike) -> Any:
    """scipy's KD-tree of ``points``, imported on first use: only crowded drawings and machine
    runs need one, and importing ``scipy.spatial`` costs about 70 ms of a ``tagbot fit``."""
    from scipy.spatial import cKDTree

    return cKDTree(points)


def _kernel_array(a: ArrayLike) -> Array:
    """``a`` as a C-contiguous, writeable float array: one compiled signature for every caller
    (slices and read-only :class:`~tagbot.model.motion.Motion` arrays among them; a copy only
    for those)."""
    a = np.asarray(a, dtype=float)
    return a if a.flags.c_contiguous and a.flags.writeable else np.array(a, order="C")


def densify(polyline: ArrayLike, spacing: float) -> Array:
    """The polyline with points inserted so consecutive points are at most ``spacing`` apart."""
    xy = np.asarray(polyline, dtype=float)
    return kernels.densified(*_joined([xy]), float(spacing))[0] if len(xy) >= 2 else xy


def _joined(polylines: Sequence[ArrayLike]) -> tuple[Array, NDArray[np.intp]]:
    """The non-empty polylines one after the other, ``(N, 2)``, and where each ends."""
    parts = [p for p in (np.asarray(p, dtype=float).reshape(-1, 2) for p in polylines) if len(p)]
    points = _kernel_array(np.concatenate(parts) if parts else np.empty((0, 2)))
    return points, np.cumsum([len(p) for p in parts], dtype=np.intp)


class _Polylines:
    """Polylines cut into segments at most ``spacing`` long (with the segments that lead to and
    from each of their points), and sampled evenly along their arc length at most ``spacing``
    apart (the queries of :func:`shape_error`)."""

    def __init__(self, joined: tuple[Array, NDArray[np.intp]], spacing: float) -> None:
        *samples, self.cell, crowded = kernels.sampled(*joined, float(spacing), _CROWDED)
        self.points, self.before, self.after, self.segments = samples
        self.spacing = spacing
        self.joined, self.lengths = joined, kernels.arc_lengths(*joined)
        self.queries, self.first, self.step = kernels.arc_samples(
            *joined, self.lengths, float(spacing)
        )
        # Where many long segments pass near every point (thousands of strokes over one another,
        # segments long because of MAX_SAMPLES), the exact search would visit all of them: the
        # KD-tree of the samples then gives distances to the segments of the nearest few.
        self.tree = _tree(self.points) if crowded else None
        if self.tree is None:
            self.fine, self.coarse = kernels.grids_of(
                self.segments, self.cell, kernels.COARSE * self.cell
            )

    def distance(self, query: Array) -> Array:
        """Each query point's distance to the polylines (their own segments, cut at the
        samples): exact, through grids of the segments (:mod:`tagbot.metrics_kernels`), or for a
        crowded scribble to the segments next to its :data:`_NEIGHBOURS` nearest samples."""
        query = _kernel_array(query)
        if self.tree is not None:
            return self._near_segments(query)
        distance, _ = kernels.distances(
            query,
            self.segments,
            self.fine,
            self.cell,
            self.coarse,
            kernels.COARSE * self.cell,
            self.spacing,
            kernels.fine_rings(self.spacing, self.cell),
        )
        return distance

    def _near_segments(self, query: Array) -> Array:
        assert self.tree is not None
        k = min(_NEIGHBOURS, len(self.points))
        _, near = self.tree.query(query, k=k)
        best = np.full(len(query), np.inf)
        for i in near.reshape(len(query), k).T:
            for j in (self.before[i], self.after[i]):
                a, ab = self.points[i], self.points[j] - self.points[i]
                length2 = np.einsum("ij,ij->i", ab, ab)
                u = np.einsum("ij,ij->i", query - a, ab) / np.where(length2 > 0, length2, 1.0)
                foot = a + np.clip(u, 0.0, 1.0)[:, None] * ab
                best = np.minimum(best, np.hypot(*(query - foot).T))
        return best

    def farthest(self, other: _Polylines, coarse: Array, fine: float) -> float:
        """The largest distance from these polylines (not only their queries, whose distances
        are ``coarse``) to ``other``, within ``fine``: the intervals between queries that could
        hold it are resampled along the path at ``fine``
        (:func:`tagbot.metrics_kernels.refinement`)."""
        top = float(coarse.max())
        unknown = np.full(len(coarse), -1, dtype=np.intp)  # nearest segments not known here
        query = kernels.refinement(
            *self.joined, self.lengths, self.first, self.step, self.queries, coarse, unknown,
            other.segments, fine, MAX_SAMPLES,
        )  # fmt: skip
        return max(top, float(other.distance(query).max())) if len(query) else top


def shape_error(reference: Sequence[ArrayLike], candidate: Sequence[ArrayLike]) -> ShapeError:
    """Mean and max closest-point distance between two drawings, over the reference's size.

    Both are lists of polylines ``(N, 2)``. Each is sampled evenly along its arc length,
    :data:`MEAN_DENSITY` points per diagonal (at most :data:`MAX_SAMPLES` per drawing; both ends
    of each polyline included), and each sample measured exactly against the other drawing's
    segments (a grid search, compiled): the mean is over these samples, so by arc length (a pen
    at rest, hundreds of points in one place, weighs nothing); the max is refined along the
    path where it could be (halving the intervals between samples that a bound does not rule
    out), to within 1/(2·:data:`DENSITY`) of the size. Cost linear in the samples for
    drawings that are close.
    """
    return _shape_error(_joined(reference), _joined(candidate))


def _shape_error(
    reference: tuple[Array, NDArray[np.intp]], candidate: tuple[Array, NDArray[np.intp]]
) -> ShapeError:
    """:func:`shape_error` of two drawings joined (:func:`_joined`)."""
    if not len(reference[1]) or not len(candidate[1]):
        raise ValueError("shape_error: both drawings need at least one point")
    figures = (MEAN_DENSITY, MAX_SAMPLES, DENSITY, _CROWDED)
    mean, largest, size = kernels.shape_error_of(*reference, *candidate, *figures)
    if math.isnan(mean):  # a crowded drawing: its distances through a KD-tree
        _, spacing = kernels.spacing_of(*reference, *candidate, MEAN_DENSITY, MAX_SAMPLES)
        a, b = _Polylines(reference, spacing), _Polylines(candidate, spacing)
        a_to_b = b.distance(a.queries)
        b_to_a = a.distance(b.queries)
        mean = (a_to_b.sum() + b_to_a.sum()) / (len(a_to_b) + len(b_to_a)) / size
        fine = size / DENSITY
        largest = max(a.farthest(b, a_to_b, fine), b.farthest(a, b_to_a, fine)) / size
    return ShapeError(mean=float(mean), max=float(largest), size=size)


def pen_down_paths(motion: Motion) -> list[Array]:
    """The motion's pen-down runs as polylines."""
    return [np.asarray(motion.xy[rows]) for _, rows in motion.runs()]


def turning_of(polylines: Sequence[ArrayLike]) -> float:
    """Total absolute turning of polylines, in half turns (180°)."""
    return kernels.turning(*_joined(polylines)) / np.pi


VELOCITY_CUTOFF = 15.0
"""Cut-off frequency (Hz) of the low-pass filter that gives the recorded velocity the velocity SNR
is measured against (:func:`recorded_velocity`); None there for raw differences. Handwriting's
velocity spectrum peaks near 5 Hz and holds little above 10 Hz (Teulings & Maarse 1984, "Digital
recording and processing of handwriting movements", Human Movement Science 3; 10 Hz is the usual
low-pass of handwriting kinematics, e.g. NeuroScript MovAlyzeR's filtering guide), but graffiti
strokes are faster than pen-on-paper writing and a 20 dB figure counts every percent of the
energy: 15 Hz, the cut-off a public implementation of Martín-Albo et al.'s Sigma-Lognormal
extractor applies to the speed, is the one that recovers the *true* velocity of synthetic
timed plans best over simulated digitisers (30-120 Hz, pixel quantisation, stamp jitter; see
BENCHMARKS.md, issue 16, and ``bench_timing.py --calibrate``): on touch screens within 0.4 dB
of the best cut-off, where 10 Hz scores 1.6-13 dB below the best (it removes real movement).
Above it, what a digitiser adds is mostly noise."""

FILTER_ORDER = 4
"""Order of the Butterworth low-pass whose magnitude :func:`low_pass` applies squared, as if run
forwards and backwards (zero phase): -6 dB at the cut-off, within 0.4 % up to half of it, -48 dB
at twice the cut-off."""


def velocity_snr(
    t: ArrayLike,
    xy: ArrayLike,
    model_t: ArrayLike,
    model_v: ArrayLike,
    dt: float = 0.01,
    cutoff: float | None = VELOCITY_CUTOFF,
) -> tuple[float, float, float]:
    """SNR in dB of a model velocity against a recorded trajectory, after the best time mapping.

    The recording (times ``t``, points ``xy``) is resampled every ``dt`` seconds and its velocity
    estimated by :func:`recorded_velocity` (low-passed at ``cutoff`` Hz, by default
    :data:`VELOCITY_CUTOFF`; None: raw central differences); the model velocity ``model_v`` (at
    ``model_t``) is mapped to the recording's clock by ``t = offset + scale·(t_model −
    model_t[0])`` (velocities divide by ``scale``). Returns ``(snr_db, scale, offset)`` for the
    scale and offset maximising ``10·log10(Σ|v|² / Σ|v − v̂|²)``: for each of 41 scales from ¼
    to 4 times the span ratio, and 1, every offset on the ``dt`` grid (a cross-correlation by
    direct sums or FFT, whichever costs less for the scale; offsets that a Cauchy–Schwarz bound
    shows cannot beat the best so far are skipped), then a local search from the better of the
    best pair and the shared clock (scale 1, offset ``model_t[0]``: a timed fit's own mapping,
    which the grid of offsets can miss by a fraction of a step): a pattern of scale and offset
    steps at :data:`POLISH_WIDTHS`, then Levenberg–Marquardt steps on both (the error is a sum of
    squares of the interpolated model), so the result is never below
    :func:`clock_velocity_snr`'s; compiled (:func:`tagbot.metrics_kernels.best_mapping`). Cost
    O(n log n) in the samples.
    """
    snr_db, scale, offset, _ = _velocity_snr(t, xy, model_t, model_v, dt, cutoff)
    return snr_db, scale, offset


def _velocity_snr(
    t: ArrayLike,
    xy: ArrayLike,
    model_t: ArrayLike,
    model_v: ArrayLike,
    dt: float,
    cutoff: float | None,
) -> tuple[float, float, float, float]:
    """:func:`velocity_snr`, and the recorded velocity's energy ``Σ|v|²`` it is relative to."""
    status, db, scale, offset, energy = kernels.velocity_snr_of(
        _kernel_array(t), _kernel_array(xy), _kernel_array(model_t), _kernel_array(model_v),
        float(dt), float(cutoff or 0.0), cutoff is not None, *_RECORDING, *_SEARCH,
    )  # fmt: skip
    if status != kernels.OK:
        raise ValueError(_NO_SNR[status])
    return db, scale, offset, energy


_NO_SNR = {
    kernels.SHORT_MODEL: "velocity_snr: the model needs at least 2 samples",
    kernels.SHORT_RECORDING: "velocity: the recording needs at least 3 samples over 3·dt",
    kernels.AT_REST: "velocity_snr: the recording does not move",
}


@dataclass(frozen=True)
class FitReport:
    """How a tag reconstructed from traces compares with them."""

    traces: int
    points: int
    strokes: int
    shape: ShapeError
    strokes_per_half_turn: float
    """Strokes per 180° of the input's turning (the paper adds one per 180°)."""
    velocity_snr_db: float | None
    """Velocity SNR against the recorded timing trace by trace, each after its own best time
    scale and offset, as the Sigma-Lognormal literature scores fits (None when the input has
    none)."""
    clock: str | None = None
    """How the input's clock unit was read (``Trace.clock``), None when no reader decided it."""
    velocity_snr_clock_db: float | None = None
    """Velocity SNR on the tag's own clock, the one a machine draws: every plan against its
    trace at the recorded instants, one time offset for the whole capture (within
    ±:data:`CLOCK_REACH`) and no scaling (None when the input has no timing)."""
    timing: str | None = None
    """How the traces were timed (``"3 matched, 1 scaled"``), when the fit said."""
    velocity_snr_trace_db: float | None = None
    """Velocity SNR trace by trace, each with its own time offset but no scaling
    (:func:`tag_clock_snr`; None when the input has no timing)."""

    def summary(self) -> str:
        """One line for people."""
        snr = ""
        if self.velocity_snr_clock_db is not None and self.velocity_snr_trace_db is not None:
            snr = (
                f", velocity SNR {self.velocity_snr_clock_db:.1f} dB on the tag's clock,"
                f" {self.velocity_snr_trace_db:.1f} dB trace by trace"
            )
        elif self.velocity_snr_db is not None:
            snr = f", velocity SNR {self.velocity_snr_db:.1f} dB"
        timing = f"; timing: {self.timing}" if self.timing else ""
        return (
            f"{_count(self.traces, 'trace')} ({_count(self.points, 'point')}) ->"
            f" {_count(self.strokes, 'stroke')}; shape error mean {100 * self.shape.mean:.2f}%"
            f" max {100 * self.shape.max:.2f}% of {self.shape.size:.4g}{snr}{timing}"
        )


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'s' * (n != 1)}"


def fit_report(
    traces: Sequence[object], tag: Tag, dt: float = 0.005, timings: Sequence[Any] | None = None
) -> FitReport:
    """Compare a reconstructed ``tag`` (one plan per trace) with its input ``traces``.

    Traces are objects with ``xy`` and optional ``t`` (as :func:`tagbot.load_traces` returns);
    ``timings`` how the fit timed each (:attr:`tagbot.gesture.Reconstruction.timings`).
    """
    polylines = [np.asarray(getattr(tr, "xy", tr), dtype=float) for tr in traces]
    # Each plan sampled on its own grid: a pen lift shorter than dt cannot make the report fail.
    model_t, _, model_v, first = sampled_plans(tag, dt)
    # The shape is what the plans ink: a plan that touches down moving only within its window,
    # sampled finely enough that its chords cut no corner (ink_polyline).
    drawn = _joined([ink_polyline(plan, tag.size, dt) for plan in tag.plans])
    reference = _joined(polylines)
    shape = _shape_error(reference, drawn)
    turning = kernels.turning(*reference) / np.pi
    snr = clock_snr = None
    timed = [tr for tr in traces if getattr(tr, "t", None) is not None]
    if timed and len(timed) == len(traces) == len(tag.plans):
        status, db, energy = kernels.velocity_snrs(
            _kernel_array(np.concatenate([np.asarray(tr.t, dtype=float) for tr in traces])),
            reference[0], np.concatenate([[0], reference[1]]), model_t, model_v, first,
            0.01, VELOCITY_CUTOFF, *_RECORDING, *_SEARCH,
        )  # fmt: skip
        compared = status == kernels.OK  # the others too short to compare
        signal, noise = energy[compared].sum(), (energy / 10 ** (db / 10))[compared].sum()
        snr = float(10 * np.log10(signal / noise)) if noise > 0 else None
        clock_snr = tag_clock_snr(traces, tag)  # (own clock, trace by trace), no scaling
    return FitReport(
        traces=len(polylines),
        points=sum(len(p) for p in polylines),
        strokes=tag.n_strokes,
        shape=shape,
        strokes_per_half_turn=tag.n_strokes / turning if turning > 0 else float("nan"),
        velocity_snr_db=snr,
        clock=next((c for c in (getattr(tr, "clock", None) for tr in traces) if c), None),
        velocity_snr_clock_db=None if clock_snr is None else clock_snr[0],
        velocity_snr_trace_db=None if clock_snr is None else clock_snr[1],
        timing=timing_summary(timings),
    )


def ink_polyline(plan: Plan, size: float, dt: float = 0.005) -> Array:
    """What ``plan`` inks (:meth:`~tagbot.model.plan.Plan.ink_window`) as a polyline, sampled
    every ``dt`` seconds and, where a chord between samples would cut the path by more than the
    shape error's precision (1/(2·:data:`DENSITY`) of ``size``, judged at its middle instant),
    halved until none does: a fast plan's corners are measured, not cut."""
    from tagbot.model.motion import evaluate_plan

    down, up = plan.ink_window(size)
    t = np.minimum(down + dt * np.arange(max(math.ceil((up - down) / dt - 1e-9), 1) + 1), up)
    xy, _ = evaluate_plan(plan, t, size)
    tolerance = size / (2 * DENSITY)
    check = np.arange(len(t) - 1)
    for _ in range(24):  # each round halves the chords still too far from the path
        middle = 0.5 * (t[check] + t[check + 1])
        at, _ = evaluate_plan(plan, middle, size)
        a, b = xy[check], xy[check + 1]
        ab = b - a
        length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
        u = np.clip(np.einsum("ij,ij->i", at - a, ab) / length2, 0.0, 1.0)
        off = np.hypot(*(at - a - u[:, None] * ab).T)
        bad = np.flatnonzero(off > tolerance)
        if not bad.size:
            break
        where = check[bad] + 1
        t = np.insert(t, where, middle[bad])
        xy = np.insert(xy, where, at[bad], axis=0)
        inserted = where + np.arange(bad.size)
        check = np.concatenate([inserted - 1, inserted])
        check.sort()
    return xy


def timing_summary(timings: Sequence[Any] | None) -> str | None:
    """How many traces got each timing (``"3 matched, 1 scaled"``), None without timings."""
    kinds = [getattr(timing, "kind", str(timing)) for timing in timings or ()]
    return ", ".join(f"{kinds.count(k)} {k}" for k in dict.fromkeys(kinds)) or None


CLOCK_REACH = 0.25
"""The tag's own clock may be offset from the recording's by up to this, seconds
(:func:`tag_clock_snr`)."""


def tag_clock_snr(
    traces: Sequence[Any], tag: Tag, cutoff: float | None = VELOCITY_CUTOFF
) -> tuple[float, float] | None:
    """Velocity SNR in dB of ``tag`` (one plan per trace) against the timed ``traces``, with no
    time scaling: ``(on the tag's own clock, trace by trace)``. Each trace's velocity
    (:func:`recorded_velocity`, low-passed at ``cutoff``) is compared with its plan's at the
    same instants shifted by an offset within ±:data:`CLOCK_REACH` (every 5 ms, then
    parabolic): on the tag's own clock one offset suits the whole capture (what a machine
    drawing the tag on its clock reproduces), trace by trace each trace has its own. None when
    no trace is long enough to compare."""
    from tagbot.model.motion import evaluate_plan

    step, fine = 0.005, 0.001
    offsets = np.arange(-CLOCK_REACH, CLOCK_REACH + step / 2, step)
    signal, errors, each = 0.0, np.zeros(len(offsets)), 0.0
    for plan, trace in zip(tag.plans, traces, strict=True):
        try:
            grid, v = recorded_velocity(trace.t, trace.xy, cutoff=cutoff)
        except ValueError:
            continue  # too short to compare
        span = grid[-1] - grid[0] + 2 * CLOCK_REACH
        t = grid[0] - CLOCK_REACH + fine * np.arange(int(np.ceil(span / fine)) + 2)
        _, model_v = evaluate_plan(plan, t, tag.size)
        at = (grid[None, :] + offsets[:, None] - t[0]) / fine  # (offsets, grid) in fine steps
        i = np.clip(np.floor(at).astype(np.intp), 0, len(t) - 2)
        w = (at - i)[..., None]
        shifted = model_v[i] * (1 - w) + model_v[i + 1] * w
        signal += float(np.sum(v * v))
        trace_errors = np.sum((shifted - v[None]) ** 2, axis=(1, 2))
        errors += trace_errors
        each += _lowest(trace_errors)
    if signal <= 0:
        return None
    return _db(signal, _lowest(errors)), _db(signal, each)


def _lowest(errors: Array) -> float:
    """The least of ``errors`` (at evenly spaced offsets), refined by the parabola through it
    and its neighbours."""
    b = int(np.argmin(errors))
    best = float(errors[b])
    if 0 < b < len(errors) - 1:
        lo, hi = errors[b - 1], errors[b + 1]
        curvature = lo - 2 * best + hi
        if curvature > 0:
            best = max(best - (hi - lo) ** 2 / (8 * curvature), 0.0)
    return best


def recorded_velocity(
    t: ArrayLike, xy: ArrayLike, dt: float = 0.01, cutoff: float | None = None
) -> tuple[Array, Array]:
    """A recording resampled on a regular grid and its velocity by central differences.

    The grid's step is ``dt`` seconds, or coarser for a sparse recording: at most
    :data:`GRID_PER_POINT` grid samples per recorded point, so the cost follows the points, not
    the clock's span.

    With ``cutoff`` None (raw differences), repeated time stamps are dropped (the first of each
    kept) and the positions interpolated linearly. With a ``cutoff`` (Hz; the velocity SNR uses
    :data:`VELOCITY_CUTOFF`), the velocity is an estimate of the writer's: the samples are
    placed at the instants they were most likely taken at
    (:func:`tagbot.inputs.stamps.sample_instants`: stamps shared by a burst of events spread,
    stamps carrying a steady sampler's delivery noise regressed on the sample number, exact
    stamps kept), the positions interpolated linearly on the grid and low-passed by a
    zero-phase Butterworth filter (:func:`low_pass`; point reflection at the ends, which keeps
    the end velocities), then differentiated. Dropped samples and stalls are bridged by the
    interpolation; no single sample decides a value. O(n log n) in the samples. The
    Sigma-Lognormal extractors likewise fit, and score, a smoothed recording, not raw
    differences: ScriptStudio (O'Reilly & Plamondon 2009, Pattern Recognition 42:3324) smooths
    the signal first, iDeLog (Ferrer, Diaz, Carmona-Duarte & Plamondon, IEEE TPAMI 2020,
    doi:10.1109/TPAMI.2018.2879312) offers that smoothing as its pre-processing, and a public
    implementation of Martín-Albo et al.'s extractor resamples at 200 Hz and low-passes the
    speed by a zero-phase Butterworth at 15 Hz. A grid too coarse for the cut-off (Nyquist at
    or below it) is not filtered.
    """
    if t is None:
        raise ValueError("velocity: the recording has no time stamps")
    t, xy = _kernel_array(t), _kernel_array(xy)
    if t.ndim != 1 or xy.shape != (t.size, 2):
        raise ValueError(
            f"velocity: positions of shape {xy.shape} for time stamps of shape {t.shape}"
            " (expected (N, 2) and (N,))"
        )
    grid, v, ok = kernels.recording_velocity(
        t, xy, float(dt), float(cutoff or 0.0), cutoff is not None,
        *_RECORDING,
    )  # fmt: skip
    if not ok:
        raise ValueError("velocity: the recording needs at least 3 samples over 3·dt")
    return grid, v


_RECORDING = (FILTER_ORDER, float(GRID_PER_POINT), np.array([SMOOTHING, GAP, REGULAR]),
              np.array(BLENDS))  # fmt: skip
"""How :func:`recorded_velocity` treats a recording, for the compiled kernels: the filter's
order, the grid's samples per point, the stamps' treatment
(:func:`tagbot.inputs.stamps.sample_instants`)."""


def low_pass(x: Array, dt: float, cutoff: float) -> Array:
    """``x`` (rows every ``dt`` s) through the zero-phase low-pass of :func:`recorded_velocity`:
    the magnitude of a :data:`FILTER_ORDER` Butterworth filter run forwards and backwards,
    ``1 / (1 + (f / cutoff)^(2·order))``, applied by FFT (O(n log n); scipy.signal would cost
    a second to import). Each end is extended by point reflection over three cut-off periods
    (the end velocities kept) and the straight line through the extended ends taken out before
    the transform, so that nothing wraps around. Unchanged if the rows are too few or the grid
    too coarse for the cut-off (its Nyquist frequency at or below it)."""
    x = np.asarray(x, dtype=float)
    reach = _filter_reach(dt, cutoff)
    if not reach or len(x) < 4:
        return x
    rows = np.array(x.reshape(len(x), -1), dtype=float, order="C")
    kernels.low_pass_into(rows, dt, cutoff, FILTER_ORDER, reach)
    return rows.reshape(x.shape)


def _filter_reach(dt: float, cutoff: float) -> int:
    """Rows of three cut-off periods every ``dt`` s, how far :func:`low_pass` reflects each end
    (at most the rows less one); 0 where the grid is too coarse for the cut-off."""
    return int(kernels.filter_reach(float(dt), float(cutoff)))


@dataclass(frozen=True)
class RunAlignment:
    """One pen-down run, planned against executed: the time offset that aligns them."""

    plan: int
    planned_start: float
    """Planned time (s) of the run's first setpoint."""
    executed_start: float
    """The executed time matching ``planned_start``: executed t - offset = planned t."""
    planned_duration: float
    """From the first to the last planned movement, s."""
    executed_duration: float
    """From the first to the last executed movement, s."""
    snr_db: float | None
    """None where the executed data cannot support a speed (:data:`SPARSE_SNR_NOTE`)."""
    deviation_max: float = math.nan
    """Largest distance either way between this run's executed and planned paths, mm (NaN
    where it is not measured)."""
    cut_short: bool = False
    """The run was drawing when the machine stopped: its figures cover the part drawn, and its
    speed ends where the machine stopped while the plan's went on, so its SNR is no fidelity
    figure (the budgets do not judge it)."""


@dataclass(frozen=True)
class ExecutionComparison:
    """How faithfully a machine drew the planned motion (machine units, mm, seconds)."""

    deviation_mean: float
    """Mean distance from executed pen-down positions to the planned path."""
    deviation_max: float
    """Largest distance either way between executed and planned pen-down paths."""
    speed_snr_db: float | None
    """``10·log10(Σ|v_planned|² / Σ|v_executed - v_planned|²)`` over all runs, each aligned;
    None where the executed data cannot support a speed (then :attr:`speed_snr_note` says why)."""
    planned_duration: float
    executed_duration: float
    runs: tuple[RunAlignment, ...]
    planned_runs: int
    executed_runs: int
    speed_snr_note: str | None = None

    @property
    def duration_ratio(self) -> float:
        return self.executed_duration / self.planned_duration if self.planned_duration else 1.0

    def as_dict(self) -> dict[str, object]:
        return {
            "path_deviation_mean_mm": self.deviation_mean,
            "path_deviation_max_mm": self.deviation_max,
            "speed_snr_db": self.speed_snr_db,
            **({} if self.speed_snr_note is None else {"speed_snr_note": self.speed_snr_note}),
            "planned_drawing_s": self.planned_duration,
            "executed_drawing_s": self.executed_duration,
            "drawing_duration_ratio": self.duration_ratio,
            "pen_down_runs": {"planned": self.planned_runs, "executed": self.executed_runs},
            "runs": [
                {
                    "plan": r.plan,
                    "planned_start": r.planned_start,
                    "executed_start": r.executed_start,
                    "planned_duration": r.planned_duration,
                    "executed_duration": r.executed_duration,
                    "speed_snr_db": r.snr_db,
                    "path_deviation_max_mm": r.deviation_max,
                    "cut_short": r.cut_short,
                }
                for r in self.runs
            ],
        }


MOVED = 0.02
"""mm: a run starts when the pen has moved this far from its first position, and ends when it
is this close to its last."""


def executed_runs(executed: ArrayLike) -> list[Array]:
    """The pen-down runs of an executed trace ``(N, 4)``: ``t, x, y, pen`` (pen > 0.5 is down)."""
    data = np.asarray(executed, dtype=float)
    if data.ndim != 2 or data.shape[1] != 4:
        raise ValueError(f"executed: must be an (N, 4) array t, x, y, pen, got {data.shape}")
    down = data[:, 3] > 0.5
    edges = np.flatnonzero(np.diff(np.concatenate([[0], down.astype(np.int8), [0]])))
    return [data[a:b, :3] for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= 2]


def compare_execution(
    planned: Sequence[tuple[ArrayLike, ArrayLike]],
    executed: ArrayLike,
    *,
    plans: Sequence[int] | None = None,
    dt: float = 0.01,
    spacing: float = 0.005,
    pauses: Sequence[tuple[float, float]] = (),
    until: float | None = None,
    ramp: float = 0.0,
) -> ExecutionComparison:
    """Executed pen-down runs against the planned ones (``(t, xy)`` per run, in order).

    Like with like, for both machines:

    - ``pauses``: ``(start, length)`` s on the executed clock, the pauses asked for (pen lifted
      or motion held). They are taken out of the executed timeline first (samples inside
      dropped, later ones moved back by the length), so a pause costs no fidelity figure.
      Host stalls are *not* given here: they stay in the timeline as they ran and cost what
      they cost (a stopped pen is a speed error). ``ramp``: s a machine that kept its pen down
      through a pause (a plotter's feed hold) takes to regain the planned speed after it; that
      long after each pause (where the stop's deceleration, taken out with the pause, meets the
      restart's acceleration) is left out of the velocity comparison;
    - ``until``: after a stop, the planned time the machine had drawn to; each planned run is
      cut there (one not begun is left out), so the drawn part is compared with the part of the
      plan it stands for.

    Runs are matched in order. Each executed run is aligned in time to its planned run (the
    offset that best matches their velocities, searched within ±1 s of the offset between their
    movement onsets), then:
    path deviation (closest-point distances, paths densified to ``spacing``), velocity SNR on a
    ``dt`` grid (executed velocity by central differences; none for an executed run too short
    to have a speed, under three samples over 3·``dt``, which is placed by its onset), and the
    time each run takes from its first to its last movement.
    """
    runs_e = executed_runs(without_pauses(executed, pauses))
    gone = np.cumsum([0.0, *(length for _, length in sorted(pauses))])
    starts = [start - gone[k] for k, (start, _) in enumerate(sorted(pauses))]
    skip = [(t - dt, t + ramp + dt) for t in starts] if ramp > 0 else []
    plans = list(range(len(planned))) if plans is None else list(plans)
    cut = [False] * len(planned)
    if until is not None:
        planned, plans, cut = planned_until(planned, plans, until)
    pairs = list(zip(planned, runs_e, plans, cut, strict=False))
    if not pairs:
        raise ValueError("compare_execution: no pen-down run was executed")
    to_path: list[Array] = []
    from_path: list[Array] = []
    signal = noise = 0.0
    alignments: list[RunAlignment] = []
    for (tp, xyp), run, plan, cut_short in pairs:
        tp, xyp = np.asarray(tp, dtype=float), np.asarray(xyp, dtype=float)
        te, xye = run[:, 0], run[:, 1:3]
        path = densify(xyp, spacing)
        d_exec, _ = _tree(path).query(xye)
        d_plan, _ = _tree(densify(xye, spacing)).query(xyp)
        to_path.append(d_exec)
        from_path.append(d_plan)
        p_onset, p_end = _movement(tp, xyp)
        e_onset, e_end = _movement(te, xye)
        aligned = _align(tp, xyp, te, xye, e_onset - p_onset, dt, skip)
        # Too short for a speed (under three samples over 3·dt): placed by its onset, no SNR.
        offset, a, b = aligned if aligned is not None else (e_onset - p_onset, 0.0, 0.0)
        signal, noise = signal + a, noise + b
        alignments.append(
            RunAlignment(
                plan=int(plan),
                planned_start=float(tp[0]),
                executed_start=float(tp[0] + offset),
                planned_duration=float(p_end - p_onset),
                executed_duration=float(e_end - e_onset),
                snr_db=None if aligned is None else _db(a, b),
                deviation_max=float(max(d_exec.max(), d_plan.max())),
                cut_short=cut_short,
            )
        )
    d_exec_all = np.concatenate(to_path)
    return ExecutionComparison(
        deviation_mean=float(d_exec_all.mean()),
        deviation_max=float(max(d_exec_all.max(), max(d.max() for d in from_path))),
        speed_snr_db=_db(signal, noise),
        planned_duration=sum(r.planned_duration for r in alignments),
        executed_duration=sum(r.executed_duration for r in alignments),
        runs=tuple(alignments),
        planned_runs=len(planned),
        executed_runs=len(runs_e),
    )


def without_pauses(executed: ArrayLike, pauses: Sequence[tuple[float, float]]) -> Array:
    """``executed`` ``(N, 4)`` with each pause ``(start, length)`` (executed clock) taken out:
    samples inside dropped, later ones moved back by its length (see :func:`compare_execution`)."""
    data = np.array(executed, dtype=float).reshape(-1, 4)
    for start, length in sorted(pauses, reverse=True):  # the latest first: earlier ones unmoved
        t = data[:, 0]
        data = data[(t < start) | (t >= start + length)]
        data[data[:, 0] >= start + length, 0] -= length
    return data


def planned_until(
    planned: Sequence[tuple[ArrayLike, ArrayLike]], plans: Sequence[int], until: float
) -> tuple[list[tuple[Array, Array]], list[int], list[bool]]:
    """The planned runs cut at planned time ``until`` (a segment it falls in ends there, at the
    planned position then; runs with fewer than two samples before it left out, and a run cut
    before it has moved :data:`MOVED` from its first point: not begun), their plans, and
    whether each was cut short (planned to go on after ``until``)."""
    kept: list[tuple[Array, Array]] = []
    kept_plans: list[int] = []
    kept_cut: list[bool] = []
    for (t, xy), plan in zip(planned, plans, strict=True):
        t, xy = np.asarray(t, dtype=float), np.asarray(xy, dtype=float)
        inside = t <= until + 1e-9
        cut_short = until + 1e-9 < t[-1]
        if inside.any() and t[inside][-1] + 1e-9 < until < t[-1]:  # inside a segment: cut
            cut = np.array([np.interp(until, t, xy[:, i]) for i in (0, 1)])
            t, xy = np.append(t[inside], until), np.vstack([xy[inside], cut])
            inside = np.ones(len(t), dtype=bool)
        if cut_short and inside.any() and np.hypot(*(xy[inside] - xy[0]).T).max() <= MOVED:
            continue  # stopped before it began
        if inside.sum() >= 2:
            kept.append((t[inside], xy[inside]))
            kept_plans.append(int(plan))
            kept_cut.append(bool(cut_short))
    return kept, kept_plans, kept_cut


def _db(signal: float, noise: float) -> float:
    return float(10.0 * np.log10(signal / noise)) if noise > 0 else float("inf")


_MOVEMENT_STEP = 0.001
"""s: the step :func:`_movement` looks for a run's start and end at."""


def _movement(t: Array, xy: Array) -> tuple[float, float]:
    """When a run starts moving and when it stops (see :data:`MOVED`), on the path taken
    straight between samples at 1 ms (a plan's setpoints may be a quarter second apart: the
    crossing lies inside a line, not at its end)."""
    if len(t) > 1 and float(np.max(np.diff(t))) > _MOVEMENT_STEP:
        fine = np.union1d(np.arange(t[0], t[-1], _MOVEMENT_STEP), t)
        xy = np.column_stack([np.interp(fine, t, xy[:, i]) for i in (0, 1)])
        t = fine
    away = np.hypot(*(xy - xy[0]).T) > MOVED
    near_end = np.hypot(*(xy - xy[-1]).T) > MOVED
    start = t[np.argmax(away)] if away.any() else t[0]
    end = t[len(t) - 1 - np.argmax(near_end[::-1])] if near_end.any() else t[-1]
    return float(start), float(end)


def _align(
    tp: Array,
    xyp: Array,
    te: Array,
    xye: Array,
    guess: float,
    dt: float,
    skip: Sequence[tuple[float, float]] = (),
) -> tuple[float, float, float] | None:
    """The offset (executed t − planned t) near ``guess`` that best matches the velocities,
    with the planned velocity's energy and the error energy at that offset; None for an
    executed run with no speed to match (under three samples over 3·dt).

    Executed instants inside a ``skip`` window are left out, and each piece between two
    windows is aligned on its own (searched from the previous piece's offset: a machine
    restarting after a pause may come back a little early or late); the first piece's offset
    is returned, with the energies summed over the pieces."""
    try:
        grid, ve = recorded_velocity(te, xye, dt)
    except ValueError:
        return None
    vp_full = np.gradient(xyp, tp, axis=0) if len(tp) >= 2 else np.zeros_like(xyp)
    cuts = sorted(skip)
    piece = np.searchsorted([high for _, high in cuts], grid, side="left")
    inside = np.zeros(len(grid), dtype=bool)
    for low, high in cuts:
        inside |= (grid >= low) & (grid <= high)
    first: float | None = None
    total_a = total_b = 0.0
    for k in np.unique(piece[~inside]) if len(cuts) else [0]:
        chosen = (piece == k) & ~inside if len(cuts) else slice(None)
        offset, a, b = _best_offset(tp, vp_full, grid[chosen], ve[chosen], guess)
        guess, total_a, total_b = offset, total_a + a, total_b + b
        first = offset if first is None else first
    return float(guess if first is None else first), total_a, total_b


def _best_offset(
    tp: Array, vp_full: Array, grid: Array, ve: Array, guess: float
) -> tuple[float, float, float]:
    """:func:`_align`'s search on one piece: the offset, planned and error energies."""

    def energies(offset: float) -> tuple[float, float]:
        t_plan = grid - offset
        vp = np.column_stack(
            [np.interp(t_plan, tp, vp_full[:, i], left=0.0, right=0.0) for i in (0, 1)]
        )
        err = ve - vp
        return float(np.sum(vp * vp)), float(np.sum(err * err))

    # The onsets only guess the offset: a machine lags most in a stroke's slow start, so the
    # search spans ±1 s (10 ms steps) before refining. An offset only displaces the guess by
    # matching better: where nothing moves (a dot), every offset matches alike.
    a, b = energies(guess)
    best = (b, a, b, guess)
    for width, count in ((1.0, 201), (0.01, 21), (0.001, 21)):
        for offset in best[3] + np.linspace(-width, width, count):
            a, b = energies(offset)
            if b < best[0]:
                best = (b, a, b, offset)
    _, a, b, offset = best
    return float(offset), a, b


SPARSE_SNR_NOTE = (
    "no speed SNR from status reports: a few a second, stamped on arrival, cannot follow the"
    " speed (it changes many times between two reports); positions and timing at the reported"
    " instants are compared instead (the simulator's 1 ms recorder supports a speed SNR)"
)
"""Why :func:`compare_reports` gives no speed SNR."""


def compare_reports(
    planned: Sequence[tuple[ArrayLike, ArrayLike]],
    executed: ArrayLike,
    run_of: ArrayLike,
    *,
    plans: Sequence[int] | None = None,
    spacing: float = 0.005,
    until: float | None = None,
) -> ExecutionComparison:
    """Positions a machine reported a few times a second against the plan, like with like.

    ``executed`` is ``(N, 4)`` t, x, y, pen (one row per report) and ``run_of`` the planned run
    each report belongs to (-1: pen up), as the executing line said. Per run:

    - path deviation: each reported position's distance to the planned path;
    - timing: each report's planned instant by position (where along the planned path it is;
      a report within :data:`MOVED` of either end, where the plan stands still while the pen
      goes down or up, or at the same position as its neighbour, where the machine stood,
      times nothing), and the run's offset (executed t − planned t, the
      median over its reports); the executed duration is the planned one plus the drift of
      that offset over the run;
    - no speed SNR (None, and :data:`SPARSE_SNR_NOTE` says why): a few reports a second are
      stamped when the host reads them, not when the machine sampled its position, and a speed
      changes many times between two of them. The figures the reports support are the positions
      and the timing at the reported instants (offset and drift, each within the reports'
      spacing), never a path or a speed densified from the 5 Hz polyline.

    ``until``: after a stop, the planned time the machine had drawn to; a run planned to go on
    after it is ``cut_short``.
    """
    data = np.asarray(executed, dtype=float).reshape(-1, 4)
    run_of = np.asarray(run_of, dtype=int)
    if len(run_of) != len(data):
        raise ValueError("compare_reports: one run index per executed row")
    plans = list(range(len(planned))) if plans is None else list(plans)
    distances: list[Array] = []
    alignments: list[RunAlignment] = []
    for k, ((tp, xyp), plan) in enumerate(zip(planned, plans, strict=False)):
        rows = data[(run_of == k) & (data[:, 3] > 0.5)]
        if not len(rows):
            continue
        tp, xyp = np.asarray(tp, dtype=float), np.asarray(xyp, dtype=float)
        te, xye = rows[:, 0], rows[:, 1:3]
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xyp, axis=0).T))])
        dense_arc = densify(np.column_stack([arc, np.zeros_like(arc)]), spacing)[:, 0]
        dense = np.column_stack([np.interp(dense_arc, arc, xyp[:, i]) for i in (0, 1)])
        d, nearest = _tree(dense).query(xye)
        distances.append(d)
        moving = np.concatenate([[True], np.diff(arc) > 0])  # interp needs rising arc length
        along = dense_arc[nearest]
        # At either end of the path the plan stands still: a report there (the pen going down
        # or up, a Z move) could be at any instant of the rest, so it times nothing.
        timed = (along > MOVED) & (along < arc[-1] - MOVED)
        # Nor does a report where the machine stood (as at a resumed run's first point, the
        # pen going down mid-path): the same position as the report before or after it.
        step = np.hypot(*np.diff(xye, axis=0).T) > MOVED
        timed &= np.concatenate([[True], step]) & np.concatenate([step, [True]])
        if not timed.any():
            timed = np.ones(len(along), dtype=bool)
        lag = (te - np.interp(along, arc[moving], tp[moving]))[timed]
        offset = float(np.median(lag))
        p_onset, p_end = _movement(tp, xyp)
        drift = float(lag[-1] - lag[0]) if len(lag) > 1 else 0.0
        alignments.append(
            RunAlignment(
                plan=int(plan),
                planned_start=float(tp[0]),
                executed_start=float(tp[0] + offset),
                planned_duration=float(p_end - p_onset),
                executed_duration=float(p_end - p_onset + drift),
                snr_db=None,
                cut_short=until is not None and until + 1e-9 < float(tp[-1]),
            )
        )
    if not distances:
        raise ValueError("compare_reports: no report while the pen was down")
    d_all = np.concatenate(distances)
    return ExecutionComparison(
        deviation_mean=float(d_all.mean()),
        deviation_max=float(d_all.max()),
        speed_snr_db=None,
        speed_snr_note=SPARSE_SNR_NOTE,
        planned_duration=sum(r.planned_duration for r in alignments),
        executed_duration=sum(r.executed_duration for r in alignments),
        runs=tuple(alignments),
        planned_runs=len(planned),
        executed_runs=len(alignments),
    )


# --------------------------------------------------------------------------- per stroke


@dataclass(frozen=True)
class StrokeFigures:
    """How one stroke of a fitted tag compares with the recording where it dominates."""

    plan: int
    stroke: int
    shape_error: float | None
    """Mean distance from the recorded points it dominates to the fitted path, as a fraction of
    the tag's size (None if it dominates none)."""
    velocity_snr_db: float | None
    """Velocity SNR over the recorded instants it dominates, under its trace's time mapping
    (None without timing, or if it dominates none)."""


def clock_velocity_snr(
    t: ArrayLike,
    xy: ArrayLike,
    model_t: ArrayLike,
    model_v: ArrayLike,
    cutoff: float | None = VELOCITY_CUTOFF,
) -> float:
    """Velocity SNR in dB of a model sharing the recording's clock (scale 1, offset 0): a lower
    bound of :func:`velocity_snr`'s best mapping, exact for timed fits. ``cutoff`` as there."""
    grid, v = recorded_velocity(t, xy, cutoff=cutoff)
    model_t, model_v = np.asarray(model_t, dtype=float), np.asarray(model_v, dtype=float)
    vm = np.column_stack([np.interp(grid, model_t, model_v[:, i], 0.0, 0.0) for i in (0, 1)])
    return _db(float(np.sum(v * v)), float(np.sum((v - vm) ** 2)))


def stroke_report(
    traces: Sequence[object],
    tag: Tag,
    dt: float = 0.005,
    cutoff: float | None = VELOCITY_CUTOFF,
) -> list[StrokeFigures]:
    """Per stroke of ``tag`` (one plan per trace), its shape error and velocity SNR (against the
    recording low-passed at ``cutoff`` Hz, as :func:`velocity_snr`).

    Each recorded point and each instant of the recording's velocity grid
    (:func:`recorded_velocity`) belongs to the stroke whose speed ``D·Λ`` is largest at the
    model time it maps to: a point's nearest sample of the fitted path; an instant through the
    trace's time mapping, the better of the shared clock and :func:`velocity_snr`'s best one.
    """
    from tagbot.model.motion import sample_plan

    out: list[StrokeFigures] = []
    size = tag.size if tag.size > 0 else 1.0
    for k, (trace, plan) in enumerate(zip(traces, tag.plans, strict=True)):
        mt, mxy, mv = sample_plan(tag, k, dt)
        owner = _fastest_stroke(plan, mt, size)
        xy = np.asarray(getattr(trace, "xy", trace), dtype=float)
        _, nearest = _tree(mxy).query(xy)
        n = plan.n_strokes
        dist = np.linalg.norm(xy - mxy[nearest], axis=1)
        count = np.bincount(owner[nearest], minlength=n)
        total = np.bincount(owner[nearest], weights=dist, minlength=n)
        signal = noise = None
        t = getattr(trace, "t", None)
        if t is not None and len(mt) >= 2:
            try:
                grid, v = recorded_velocity(t, xy, cutoff=cutoff)
                shared = clock_velocity_snr(t, xy, mt, mv, cutoff)
                best, scale, offset = velocity_snr(t, xy, mt, mv, cutoff=cutoff)
            except ValueError:  # too short to compare
                grid = None
            if grid is not None:
                if shared >= best:
                    scale, offset = 1.0, float(mt[0])
                tm = (grid - offset) / scale + mt[0]
                vm = np.column_stack([np.interp(tm, mt, mv[:, i], 0.0, 0.0) for i in (0, 1)])
                vm /= scale
                mine = owner[np.clip(np.searchsorted(mt, tm), 0, len(mt) - 1)]
                signal = np.bincount(mine, weights=np.sum(v * v, axis=1), minlength=n)
                noise = np.bincount(mine, weights=np.sum((v - vm) ** 2, axis=1), minlength=n)
        for j in range(n):
            snr = None
            if signal is not None and noise is not None and signal[j] > 0:
                snr = _db(float(signal[j]), float(noise[j]))
            error = float(total[j] / count[j]) / size if count[j] else None
            out.append(StrokeFigures(k, j, error, snr))
    return out


def _fastest_stroke(plan: Plan, t: Array, size: float) -> NDArray[np.intp]:
    """At each (sorted) time ``t``, the stroke of ``plan`` whose speed ``D·Λ`` is largest, among
    the strokes active then (their windows, :meth:`Plan.windows`: outside, a stroke moves the pen
    by a negligible part of the size); where none is, the last stroke begun. Cost linear in the
    (time, active stroke) pairs."""
    t_on, t_off = plan.windows(size)
    begin = np.searchsorted(t, t_on, side="left")
    counts = np.searchsorted(t, t_off, side="right") - begin
    strokes = np.repeat(np.arange(plan.n_strokes), counts)
    rows = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts - begin, counts)
    elapsed = np.maximum(t[rows] - plan.onsets[strokes], np.finfo(float).tiny)
    z = (np.log(elapsed) - plan.mu[strokes]) / plan.sigma[strokes]
    speed = plan.geometry.length[strokes] * np.exp(-0.5 * z * z)
    speed /= plan.sigma[strokes] * elapsed
    speed[t[rows] <= plan.onsets[strokes]] = 0.0
    owner = np.maximum(np.searchsorted(plan.onsets, t, side="right") - 1, 0)
    # Per row, the fastest pair: sorted by row, then speed (ties: the earlier stroke), the last
    # pair of each row.
    order = np.lexsort((-strokes, speed, rows))
    last = order[np.flatnonzero(np.diff(np.append(rows[order], -1)) != 0)]
    owner[rows[last]] = strokes[last]
    return owner


def compare_with_recording(
    executed: ArrayLike, traces: Sequence[object], plans: Sequence[int]
) -> dict[str, object]:
    """How the executed speed follows the *recorded* one: per pen-down run (the ``k``-th run
    drew plan ``plans[k]``, fitted from ``traces[plans[k]]``), the speed SNR in dB after the
    best uniform time scale and offset (:func:`velocity_snr` on the arc-length speed), the
    recording's speed (low-passed at :data:`VELOCITY_CUTOFF`, the writer's speed as the velocity
    SNR takes it) scaled by the ratio of path lengths (machine mm per input mm); the executed
    run's speed by raw differences (a machine's samples carry no digitiser noise).

    Returns ``recorded_speed_snr_db`` (energy-weighted over runs, None if no run has a timed
    recording) and ``recorded_runs`` (per run: plan, SNR, time scale: machine s per recorded s).
    """
    runs = executed_runs(executed)
    signal = noise = 0.0
    per_run: list[dict[str, float | int]] = []
    for run, plan in zip(runs, plans, strict=False):
        trace = traces[plan] if 0 <= plan < len(traces) else None
        t = getattr(trace, "t", None)
        if t is None:
            continue
        xy = np.asarray(getattr(trace, "xy", trace), dtype=float)
        length_e = float(np.sum(np.hypot(*np.diff(run[:, 1:3], axis=0).T)))
        length_r = float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))
        if not (length_e > 0 and length_r > 0):
            continue
        try:
            grid, v = recorded_velocity(t, xy, cutoff=VELOCITY_CUTOFF)
            arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(run[:, 1:3], axis=0).T))])
            speed = np.hypot(v[:, 0], v[:, 1]) * (length_e / length_r)
            # The executed run is the "recording" here and the recording the "model": time
            # maps as t_exec = offset + scale·(t_rec − t_rec[0]).
            db, scale, _ = velocity_snr(
                run[:, 0], np.column_stack([arc, np.zeros_like(arc)]), grid,
                np.column_stack([speed, np.zeros_like(speed)]), cutoff=None,
            )  # fmt: skip
            _, mine = recorded_velocity(run[:, 0], np.column_stack([arc, np.zeros_like(arc)]))
        except ValueError:  # too short to compare
            continue
        energy = float(np.sum(mine * mine))
        signal, noise = signal + energy, noise + energy / 10 ** (db / 10)
        per_run.append({"plan": int(plan), "snr_db": float(db), "time_scale": float(scale)})
    return {
        "recorded_speed_snr_db": _db(signal, noise) if per_run else None,
        "recorded_runs": per_run,
    }
