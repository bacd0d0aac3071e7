"""Gesture reconstruction (paper §6): a trace becomes a ΓΛ* or ΣΛ* plan that evokes a fast hand.

Per trace:

1. average away jitter on dense captures, resample uniformly along the length and smooth
   (§6.1);
2. salient points: curvature extrema turning more than 25° between their neighbours, plus the
   ends; one extra dominant point per 180° of turning between two of them, equally spaced along
   the contour (§6.1), and again (beyond the paper) in any section that still turns more, where
   the curvature is uneven (a spiral's inner turns); the ΣΛ* model also splits sections at
   their inflections, since its arcs cannot inflect;
3. ``phi`` per section from the area between contour and chord, one circular arc, or two across
   an inflection (eq. 19, §6.2);
4. ``dt`` per stroke from the sharpness of the contour around the target that precedes it
   (eq. 20–21, exponent 3.5);
5. targets start on the dominant points, then move by ``p(z_j) − c_j`` (eq. 22), ``c_j`` the
   trajectory's position where the speed profiles of the strokes meeting at target ``j`` cross,
   until the largest move is below one resampling step or after 10 iterations (§6.4);
6. beyond the paper, unless ``refine=False``: a least-squares polish of targets, tangents and
   onsets so the trajectory follows the whole contour (:mod:`tagbot.gesture.refine`);
7. beyond the paper too: a section the polished trajectory still misses by more than
   ``split_error`` gets one more dominant point where it misses most, and its trace is fitted
   again (at most ``splits`` times, kept only if it got closer).

All traces go through steps 5–7 together (:mod:`tagbot.gesture.strokes`): one call of compiled
code per step for the whole tag (:mod:`tagbot.gesture.kernels`,
:mod:`tagbot.gesture.refine_kernels`, and :mod:`tagbot.gesture.contour_kernels` for steps 1–4).

Lengths in :class:`FitOptions` are fractions of the tag's size (the diagonal of all traces'
bounding box), so a fit does not depend on units; angles are degrees; times seconds.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tagbot.errors import PlanError
from tagbot.gesture import contour, kernels
from tagbot.gesture.refine import RefineOptions, refine
from tagbot.gesture.strokes import Strokes
from tagbot.gesture.timing import (
    MAX_INTERVAL,
    MIN_SAMPLES,
    TIMINGS,
    Timing,
    TimingOptions,
    TraceTiming,
    implausible_clock,
    match,
    pen_down_span,
    plan_turning,
    usable,
)
from tagbot.model.plan import (
    DEFAULT_MU,
    DEFAULT_SIGMA,
    END_TOLERANCE,
    MAX_COORDINATE,
    MAX_DURATION,
    MODELS,
    Model,
    Plan,
    Tag,
    sequence,
)

Array = NDArray[np.float64]


@dataclass(frozen=True)
class FitOptions:
    """Every constant of the reconstruction, with the paper's defaults where it gives one."""

    mu: float = DEFAULT_MU
    """Log-delay shared by all strokes (§5: ln 0.2)."""
    sigma: float = DEFAULT_SIGMA
    """Log-response time shared by all strokes (§5: ln 1.4)."""
    dt_min: float = 0.1
    """Onset delay at the smoothest target, seconds (the paper gives no value)."""
    dt_max: float = 0.35
    """Onset delay at the sharpest corner, seconds (with the default mu and sigma the previous
    stroke is then ~95 % done)."""
    sharpness_exponent: float = 3.5
    """Eq. 21's exponent ``a`` biasing sharpness towards smooth (§6.3: 3.5)."""
    salient_angle: float = 25.0
    """Salient points turn more than this between their neighbours, degrees (§6.1: 25)."""
    max_turn: float = 180.0
    """One extra dominant point per this much turning between salient points, degrees (§6.1)."""
    step: float = 1 / 600
    """Resampling step, fraction of the tag's size (the paper's Δs = 1 pixel)."""
    smoothing: float = 0.003
    """Gaussian smoothing width (standard deviation), fraction of the tag's size."""
    support: float = 0.025
    """Support of the turning angles and half-width of the sharpness region (l_sup)."""
    prominence: float = 8.0
    """How much a curvature peak must stand out to be a salient candidate, degrees."""
    inflection_angle: float = 8.0
    """An inflection needs at least this much turning on each side, degrees."""
    iterations: int = 10
    """Target corrections at most (§6.4: 10)."""
    tolerance: float = 1.0
    """Stop once targets move less than this many resampling steps (§6.4: about 1 unit)."""
    lift: float = 0.3
    """Pen-up time between consecutive plans, seconds."""
    dot: float = 0.003
    """A trace with no length (a dot) becomes a straight stroke this long, fraction of size."""
    split_error: float = 0.015
    """With refinement, a section still farther than this (fraction of the tag's size) from the
    trajectory gets one more dominant point where it is farthest, and its trace is refitted."""
    splits: int = 2
    """Rounds of such splitting at most (0: none)."""
    refine: bool = True
    """Polish targets, tangents and delays by least squares after the paper's steps
    (:mod:`tagbot.gesture.refine`); off, the result is the paper's method alone."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not np.isfinite(value):
                raise PlanError(f"{f.name}: must be finite, got {value!r}")
        positive = ("sigma", "step", "support", "max_turn", "dot", "tolerance")
        for name in positive:
            if getattr(self, name) <= 0:
                raise PlanError(f"{name}: must be > 0, got {getattr(self, name)!r}")
        nonnegative = ("dt_min", "lift", "smoothing", "prominence", "inflection_angle")
        for name in (*nonnegative, "split_error"):
            if getattr(self, name) < 0:
                raise PlanError(f"{name}: must be >= 0, got {getattr(self, name)!r}")
        if self.dt_max < self.dt_min:
            raise PlanError(f"dt_max: must be >= dt_min ({self.dt_min}), got {self.dt_max!r}")
        for name in ("iterations", "splits"):
            value = getattr(self, name)
            if value < 0 or int(value) != value:
                raise PlanError(f"{name}: must be a whole number >= 0, got {value!r}")


@dataclass(frozen=True)
class Reconstruction:
    """A fitted tag and how each of its plans was timed."""

    tag: Tag
    timings: tuple[TraceTiming, ...] | None
    """Per trace (:class:`~tagbot.gesture.timing.TraceTiming`), or None when the tag was fitted
    by its shape alone (``timing="ignore"``, untimed input, or a clock no hand can produce)."""
    note: str = ""
    """Why a timed input was fitted by its shape alone, if it was."""

    def notes(self) -> list[str]:
        """One line per trace not matched to its recording (and for a whole clock refused)."""
        lines = [self.note] if self.note else []
        for k, timing in enumerate(self.timings or ()):
            if timing.kind != "matched":
                lines.append(timing.describe(k))
        return lines


def fit(
    traces: Sequence[Any],
    model: Model = "gamma",
    timing: Timing = "auto",
    timing_options: TimingOptions | None = None,
    **options: Any,
) -> Tag:
    """Reconstruct a tag from traces: one plan per trace, in the given order, pen lifted between.

    ``traces`` holds objects with an ``xy`` array ``(N, 2)`` (such as those of
    :func:`tagbot.load_traces`) or plain ``(N, 2)`` arrays. ``options`` override
    :class:`FitOptions` fields by name.

    ``timing``: ``"ignore"`` fits the shape only (the paper's method: plans move at its default
    rhythm, pen lifts of ``lift`` seconds); ``"match"`` then refits every trace's onsets,
    ``mu``, ``sigma``, tangents and targets so that the velocity follows the recorded one, plans
    inking from their recorded touch-down to their lift-off (:mod:`tagbot.gesture.timing`;
    every trace needs timestamps); ``"auto"`` (the default) is ``"match"`` when every trace has
    timestamps and one has a plausible sampling rate (:func:`tagbot.gesture.timing.usable`),
    trace by trace where the clock is one a hand can produce
    (:func:`tagbot.gesture.timing.implausible_clock`), else ``"ignore"``. Whatever the option,
    a timed plan that would miss the shape by more than the margins keeps the geometric plan on
    the recorded span. :func:`reconstruction` also says how each trace was timed.
    """
    return reconstruction(traces, model, timing, timing_options, **options).tag


def reconstruction(
    traces: Sequence[Any],
    model: Model = "gamma",
    timing: Timing = "auto",
    timing_options: TimingOptions | None = None,
    **options: Any,
) -> Reconstruction:
    """:func:`fit`, with how each trace was timed."""
    if model not in MODELS:
        raise PlanError(f"model: must be 'gamma' or 'sigma', got {model!r}")
    if timing not in TIMINGS:
        raise PlanError(f"timing: must be 'auto', 'ignore' or 'match', got {timing!r}")
    traces = list(traces)
    if timing == "match" and any(getattr(tr, "t", None) is None for tr in traces):
        raise PlanError("timing: 'match' needs timestamps on every trace (use 'auto' or 'ignore')")
    unknown = sorted(set(options) - {f.name for f in fields(FitOptions)})
    if unknown:
        raise PlanError(f"{unknown[0]}: not a fit option (see tagbot.gesture.FitOptions)")
    opts = FitOptions(**options)
    polylines = [_polyline(trace, k) for k, trace in enumerate(traces)]
    if not polylines:
        raise PlanError("traces: empty (nothing to fit)")
    points = np.concatenate(polylines)
    size = float(np.hypot(*np.ptp(points, axis=0)))
    if not size > _NO_SIZE:
        size = 1.0  # only dots, all at one place (or closer than a plan tells apart): any scale
    plans = fit_plans(polylines, size, model, opts, _duration_check(traces, timing, opts))
    note = ""
    timed = match(plans, traces, size, model, timing, timing_options)
    if timed is not None:
        try:
            return Reconstruction(Tag(tuple(timed[0]), model), tuple(timed[1]))
        except PlanError as e:  # e.g. a recorded tag longer than a tag may last
            if timing == "match":
                raise
            note = f"timing ignored: {e}"
    elif timing == "auto" and traces and all(getattr(tr, "t", None) is not None for tr in traces):
        note = _untimed_why(plans, traces, size)
    return Reconstruction(sequence(plans, opts.lift, model), None, note)


def _duration_check(
    traces: list[Any], timing: Timing, opts: FitOptions
) -> Callable[[list[_Sections | Plan]], None]:
    """Refuses, before any target is placed, a tag that will be drawn at the paper's rhythm
    (``ignore``, untimed input, or under ``auto`` a capture with no usable clock or a clock no
    hand can produce by the estimated strokes alone) and would last longer than a tag may
    (:data:`~tagbot.model.plan.MAX_DURATION`): what :func:`~tagbot.model.plan.sequence` would
    refuse after the whole fit (10⁵ random points: 48 s of CPU and 3.7 GB before)."""
    timed = bool(traces) and all(getattr(tr, "t", None) is not None for tr in traces)
    usable_clock = timed and any(usable(tr) for tr in traces)

    def check(analysed: list[_Sections | Plan]) -> None:
        strokes = sum(len(a.dt) if isinstance(a, _Sections) else 1 for a in analysed)
        if timing == "match" or (timing == "auto" and usable_clock):
            span = sum(pen_down_span(tr.t) for tr in traces)
            if timing == "match" or not implausible_clock(strokes, 0.0, span):
                return  # drawn on the recorded clock (refused after the fit if too long)
        least = shortest_duration(analysed, opts)
        if least > MAX_DURATION:
            points = sum(len(_points(tr)) for tr in traces)
            raise PlanError(
                f"{points} points: the tag would last at least {least:.0f} s ({strokes} strokes"
                f" at the paper's rhythm), more than {MAX_DURATION:g} s (a tag's longest);"
                " refused before fitting"
            )

    return check


def _points(trace: Any) -> Array:
    return np.asarray(getattr(trace, "xy", trace))


def _untimed_why(plans: list[Plan], traces: list[Any], size: float) -> str:
    """Why ``auto`` fitted a timed capture by its shape alone."""
    turning = sum(plan_turning(plan, size) for plan in plans)
    span = sum(pen_down_span(tr.t) for tr in traces)
    why = implausible_clock(sum(p.n_strokes for p in plans), turning, span)
    if why:
        return f"timing ignored, the capture's {why}"
    if not any(usable(tr) for tr in traces):
        return (
            f"timing ignored: no trace has {MIN_SAMPLES} distinct time stamps at"
            f" {1 / MAX_INTERVAL:g} Hz or more"
        )
    return ""


_NO_SIZE = 1e-90
"""A tag smaller than this across is a dot: plans cannot hold targets that close (their chords
must exceed 1e-100)."""


def fit_trace(xy: ArrayLike, size: float, model: Model, opts: FitOptions) -> Plan:
    """One trace → one plan (start 0). ``size`` is the whole tag's, which sets every scale."""
    return fit_plans([np.asarray(xy, dtype=float)], size, model, opts)[0]


def fit_plans(
    polylines: list[Array],
    size: float,
    model: Model,
    opts: FitOptions,
    check: Callable[[list[_Sections | Plan]], None] | None = None,
) -> list[Plan]:
    """Each polyline → one plan (start 0), all fitted together (one compiled call per step).

    With refinement on, a section that the refined trajectory still misses by more than
    ``split_error`` of the size gets one more dominant point where it misses most, and its trace
    is fitted again (up to ``splits`` times; kept only if it got closer). ``check`` sees the
    paper's estimates (steps 1-4) before any target is placed, and may raise.
    """
    analysed = [_analyse(xy, size, model, opts) for xy in polylines]
    if check is not None:
        check(analysed)
    plans: list[Plan | None] = [a if isinstance(a, Plan) else None for a in analysed]
    todo = {k: a for k, a in enumerate(analysed) if isinstance(a, _Sections)}
    best: dict[int, float] = {}
    for round_ in range(opts.splits + 1 if opts.refine else 1):
        if not todo:
            break
        keys = list(todo)
        fitted, misfits = _fit_sections([todo[k] for k in keys], size, model, opts)
        retry: dict[int, _Sections] = {}
        for k, plan, misfit in zip(keys, fitted, misfits, strict=True):
            worst = float(misfit.max(initial=0.0))
            if worst < best.get(k, np.inf):
                plans[k], best[k] = plan, worst
            elif round_:
                continue  # splitting did not help this trace: keep its earlier plan
            if worst > opts.split_error * size and round_ < opts.splits:
                split = _split(todo[k], misfit, opts.split_error * size, model, opts)
                if split is not None:
                    retry[k] = split
        todo = retry
    return [p for p in plans if p is not None]


@dataclass(frozen=True, eq=False)
class _Sections:
    """A trace's contour cut at its dominant points, with each section's stroke estimates."""

    curve: Array
    dominant: NDArray[np.intp]
    phi1: Array
    phi2: Array
    dt: Array
    ds: float
    """The resampling step."""
    support: int
    """The support of turning angles, samples."""


def _fit_sections(
    parts: list[_Sections], size: float, model: Model, opts: FitOptions
) -> tuple[list[Plan], list[Array]]:
    """The plans of ``parts`` (eq. 22, then refinement if on), and per part how far each contour
    sample is from the trajectory where the refinement looked (zeros without refinement)."""
    strokes = _strokes_of(parts, opts)
    tolerance = np.array([p.ds for p in parts]) * opts.tolerance
    strokes = correct_targets(strokes, size, tolerance, opts.iterations)
    curves = [p.curve for p in parts]
    if not opts.refine:
        return strokes.plans(), [np.zeros(len(c)) for c in curves]
    refine_options = RefineOptions(onset_slack=_onset_slack(opts), arcs_only=model == "sigma")
    strokes, misfit = refine(strokes, curves, size, refine_options, [p.dominant for p in parts])
    bounds = np.cumsum([len(c) for c in curves])[:-1]
    return strokes.plans(), np.split(misfit, bounds)


def _onset_slack(opts: FitOptions) -> float:
    """How far the refinement may move an onset, seconds."""
    return max(0.5 * (opts.dt_max - opts.dt_min), 1e-3)


def shortest_duration(analysed: Sequence[_Sections | Plan], opts: FitOptions) -> float:
    """How long the geometric fit's tag lasts at least (seconds at the paper's rhythm), from the
    paper's estimates before refinement: each trace's delays less the most the refinement moves
    an onset (:func:`_onset_slack`), and the pen lifts between traces. Splitting a section only
    adds strokes, each with a delay of at least ``dt_min`` (the neighbours' delays are estimated
    again then, so this bounds the fit of the estimates; measured on random points, the fitted
    tags last 0.05-1 % longer than it)."""
    slack = _onset_slack(opts) if opts.refine else 0.0
    delays = sum(max(float(a.dt.sum()) - slack, 0.0) for a in analysed if isinstance(a, _Sections))
    return delays + opts.lift * max(len(analysed) - 1, 0)


def _strokes_of(parts: list[_Sections], opts: FitOptions) -> Strokes:
    """The strokes the paper's estimates give ``parts``: targets on the dominant points."""
    count = sum(len(p.dt) for p in parts)
    return Strokes(
        targets=np.concatenate([p.curve[p.dominant] for p in parts]),
        onsets=np.concatenate([np.cumsum(p.dt) for p in parts]),
        mu=np.full(count, opts.mu),
        sigma=np.full(count, opts.sigma),
        phi1=np.concatenate([p.phi1 for p in parts]),
        phi2=np.concatenate([p.phi2 for p in parts]),
        counts=np.array([len(p.dt) for p in parts], dtype=np.intp),
    )


def _split(
    part: _Sections, misfit: Array, limit: float, model: Model, opts: FitOptions
) -> _Sections | None:
    """``part`` with a new dominant point where each section misses by more than ``limit``
    most (kept a quarter of the section away from its ends), or None if none can be added."""
    dominant = part.dominant
    worst = np.maximum.reduceat(misfit, dominant[:-1])
    added = []
    for j in np.flatnonzero(worst > limit):
        a, b = int(dominant[j]), int(dominant[j + 1])
        margin = (b - a) // 4
        if margin < 2:
            continue
        added.append(a + margin + int(np.argmax(misfit[a + margin : b - margin + 1])))
    if not added:
        return None
    dominant = np.union1d(dominant, added).astype(np.intp)
    return _estimate(part.curve, dominant, part.ds, part.support, model, opts)


def _polyline(trace: Any, index: int) -> Array:
    xy = np.asarray(getattr(trace, "xy", trace), dtype=float)
    if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) == 0:
        raise PlanError(f"traces[{index}]: expected (N, 2) points with N >= 1, got {xy.shape}")
    if not np.all(np.isfinite(xy)):
        raise PlanError(f"traces[{index}]: points must be finite")
    if np.abs(xy).max() > MAX_COORDINATE:
        raise PlanError(f"traces[{index}]: points must be within ±{MAX_COORDINATE:g}")
    return xy


SAMPLES = 32768
"""A trace gets the resampling step's samples up to this many (the development data's longest
trace has about 5700), ..."""
SAMPLES_PER_POINT = 64
"""... and beyond that at most this many per point it kept (a sparse capture's longest
stretches between points stay smooth: 64 samples at most per chord)."""


def _analyse(xy: Array, size: float, model: Model, opts: FitOptions) -> _Sections | Plan:
    """§6.1–6.3 for one trace: its sections and their estimates, or a dot's plan."""
    step = opts.step * size
    xy = contour.decimate(contour.prefilter(xy, step), 0.5 * step)
    length = contour.arc_length(xy)[-1]
    if length < 0.5 * opts.dot * size:
        return _dot(xy[0], size, opts)
    # A long trace of sparse points (random points: its length grows with their number, the tag's
    # size does not) is resampled more coarsely: at most SAMPLES_PER_POINT samples per point it
    # kept, beyond SAMPLES. Every length below stays a fraction of the size.
    step = max(step, length / max(SAMPLES, SAMPLES_PER_POINT * len(xy)))
    curve = contour.smooth(contour.resample(xy, step), opts.smoothing * size / step)
    # The resampled step (≤ step): every scale below is in samples of it.
    ds = length / (len(curve) - 1)
    support = max(2, round(opts.support * size / ds))
    dominant = contour.salient_points(
        curve, support, np.radians(opts.salient_angle), np.radians(opts.prominence)
    )
    # §6.1's points, equally spaced along the contour, and again in any section that still turns
    # more than max_turn (where the curvature is uneven: a spiral's inner turns), until none does.
    while True:
        more = contour.add_turning_points(curve, dominant, np.radians(opts.max_turn), support)
        if len(more) == len(dominant):
            break
        dominant = more
    return _estimate(curve, dominant, ds, support, model, opts)


def _estimate(
    curve: Array,
    dominant: NDArray[np.intp],
    ds: float,
    support: int,
    model: Model,
    opts: FitOptions,
) -> _Sections:
    """§6.2–6.3: tangents and delays of the strokes between ``dominant`` points (for the ΣΛ*
    model, inflections become dominant points first: arcs cannot inflect)."""
    cuts = contour.inflections(curve, dominant, support, np.radians(opts.inflection_angle))
    if model == "sigma":  # inflections become targets; sections are then single arcs
        dominant = np.union1d(dominant, cuts[cuts >= 0]).astype(np.intp)
        cuts = None
    phi1, phi2 = contour.section_deviations(curve, dominant, cuts)
    # Eq. 21: the first stroke starts at once; each next one after a delay that grows with the
    # sharpness of the contour (eq. 20) around the target it leaves from.
    z = dominant[1:-1]
    sharp = contour.sharpnesses(
        curve, np.maximum(dominant[:-2], z - support), z, np.minimum(dominant[2:], z + support)
    )
    dt = np.zeros(len(dominant) - 1)
    dt[1:] = opts.dt_min + (opts.dt_max - opts.dt_min) * np.minimum(
        sharp**opts.sharpness_exponent, 1.0
    )
    return _Sections(curve, dominant, phi1, phi2, dt, ds, support)


def _dot(point: Array, size: float, opts: FitOptions) -> Plan:
    """A dot: a short straight stroke, so that the pen touches down."""
    end = point + np.array([opts.dot * size, 0.0])
    return Plan([point, end], [0.0], [opts.mu], [opts.sigma], [0.0], [0.0])


def correct_targets(strokes: Strokes, size: float, tolerance: Array, iterations: int) -> Strokes:
    """Eq. 22 for every trace: move each interior target by ``p(z_j) − c_j`` until the largest
    move of its trace is below ``tolerance[trace]``, at most ``iterations`` times.

    The wanted points ``p(z_j)`` are where the targets start. All targets of a trace move at
    once; with strongly overlapping strokes a full move can overshoot, so each iteration takes,
    per trace, the largest step of 1, ½, ¼ or ⅛ of it that lowers the trace's largest error (and
    the trace stops when none does). Compiled: :func:`tagbot.gesture.kernels.correct_targets`.
    """
    targets = kernels.correct_targets(
        *strokes.kernel_arrays,
        strokes.first_stroke,
        float(size),
        END_TOLERANCE,
        np.ascontiguousarray(tolerance, dtype=float),
        int(iterations),
        _CROSSING_STEPS,
    )
    return strokes.replace(targets=targets)


def critical_points(plan: Plan) -> Array:
    """The trajectory's position at each target's critical instant (§6.4), ``(m, 2)``.

    Start and end for the first and last targets; for an interior target ``j``, where the speed
    profiles of strokes ``j − 1`` and ``j`` cross (between their peaks), or the later peak if they
    do not.
    """
    strokes = Strokes.of([plan.at(0.0)])
    points = plan.targets.copy()
    size = float(np.hypot(*np.ptp(plan.targets, axis=0)))
    if plan.n_strokes > 1:
        interior = np.empty((plan.n_strokes - 1, 2))
        kernels.critical_points(
            *strokes.kernel_arrays, size, END_TOLERANCE, _CROSSING_STEPS, interior
        )
        points[1:-1] = interior
    return points


def crossing_times(plan: Plan) -> Array:
    """Critical instants per target: plan start, speed-profile crossings, and the plan's end."""
    m = len(plan.targets)
    peaks = plan.onsets + np.exp(plan.mu - plan.sigma**2)
    times = np.empty(m)
    times[0] = plan.start
    times[-1] = float(np.max(peaks))
    if m > 2:
        strokes = Strokes.of([plan])
        b = np.arange(1, m - 1)
        _, onsets, mu, sigma, _, _ = strokes.kernel_arrays
        times[1:-1] = plan.start + kernels.crossings(
            onsets, mu, sigma, strokes.lengths, b - 1, b, _CROSSING_STEPS
        )
    return times


_CROSSING_STEPS = kernels.CROSSING_STEPS
