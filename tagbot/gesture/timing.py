"""Timing-aware reconstruction (beyond the paper): when a capture has real timestamps, make the
plan's velocity follow the recorded one, not only its shape.

The paper (§6) ignores timing, so static and timed traces are fitted alike; a geometric fit of a
timed capture therefore moves at the paper's default rhythm, not the writer's. With
``fit(..., timing="match")`` each trace's geometric plan is refined further:

1. **The recording, resampled by time** (:func:`resample`), at the instants its samples were
   most likely taken at (:func:`~tagbot.inputs.stamps.sample_instants`: stamps that carry a
   steady sampler's delivery noise are regressed on the sample number, exact ones kept):
   positions and velocities on a
   regular grid by Gaussian-weighted local-quadratic regression of the samples, the kernel as wide
   as the median sampling interval (at least :attr:`TimingOptions.min_bandwidth`). No single
   sample decides a value: repeated timestamps (zero dt), jittered clocks and noisy points are
   averaged with their neighbours; where the kernel holds no samples (a stall or dropped
   samples) the value is interpolated linearly between the samples around the gap, and those
   grid points count less in the fit; gaps longer than :attr:`TimingOptions.stall` hold no
   grid points at all. Restarted clocks are chained by the readers.
2. **Initial timing** (:func:`initial_timing`): the geometric plan's clock is mapped onto the
   recording's by arc length (the instant the plan has travelled a fraction of its path goes to
   the instant the recording has); each stroke follows the map's chord between its 10 % and
   90 % instants (``t_q = t0 + exp(mu + sigma·z_q)``): its median instant is mapped, ``mu``
   shifted by the log of the local time scale, ``sigma`` kept.
3. **Levenberg-Marquardt** (:func:`_levenberg_marquardt`, steps projected onto the bounds) over
   each stroke's onset, ``mu``, ``sigma`` and tangents and the interior targets, with residuals
   on the grid: velocity minus recorded velocity (over the recording's RMS speed), position
   minus recorded position (over :attr:`TimingOptions.shape_budget` of the tag's size, times
   ``position_weight``: the shape may move only as much as that budget allows), a weak pull of
   each target back to the geometric fit, and a penalty on tails outlasting the recording. The
   Jacobian is exact for onsets, ``mu`` and ``sigma`` (``∂x/∂t0 = −c·u``, ``∂x/∂mu = −c·u·e``,
   ``∂x/∂sigma = −c·u·e·z`` and their velocity counterparts) and for the targets (the
   trajectory is linear in them), central differences of the G1 fit for the tangents
   (:func:`~tagbot.gesture.timing_kernels.model_terms`); parameters ordered stroke by stroke,
   the normal equations are banded and an iteration costs time linear in the grid and the
   strokes. Stages (:attr:`TimingOptions.stages`): the timing alone, then everything.
4. **Added strokes** (:func:`_split`): where the recorded speed dips between two peaks inside a
   stroke, or the velocity the plan misses peaks (a bump the plan does not explain), and the
   plan misses much of the velocity there, that stroke is split in two and the fit repeated,
   kept only if the cost drops by :attr:`TimingOptions.split_gain` (up to
   :attr:`TimingOptions.max_stroke_ratio` times the geometric stroke count).
5. **Strokes in the air** (:func:`_in_the_air`, beyond the paper): writers touch down and lift
   off while moving. Where the recorded speed at a trace's first (last) sample is at least
   :attr:`TimingOptions.air_speed` of its peak, a stroke in the air is added before (after) the
   ink, to (from) a target :attr:`TimingOptions.air_lead` of the recorded end velocity beyond
   the end point; the pad there is not fitted (nothing was recorded) and the end instant weighs
   :attr:`TimingOptions.air_end_weight`. Refitted from the plan at rest (the last stage), it is
   kept if its cost on the recorded span is lower; across a tag, :func:`match` gives them to the
   traces they help most per stroke added, within the same stroke budget. Such a plan has an
   ``ink`` window (:attr:`~tagbot.model.plan.Plan.ink`) from the first sample to the last.

Bounds (:class:`TimingOptions`): onsets within ``onset_slack`` (0.5 s) of the initial timing,
``exp(mu)`` between 10 ms and 1 s, ``sigma`` between 0.05 and 0.6, tangents within ±3 rad; onsets
stay in order (a plan's delays are >= 0). The first and last targets sit on the recording's
first and last points.

A trace with too few distinct timestamps (:data:`MIN_SAMPLES`) keeps its geometric timing, only
moved and scaled to the recorded start and duration. Each plan starts at its trace's recorded
time (on the file's clock, which is zero at the first point), so pen lifts keep their recorded
durations unless a plan's tail would overlap the next one: plans never overlap, so the next
then starts :attr:`TimingOptions.min_lift` after the previous one has ended (its lognormal
tails within ``END_TOLERANCE`` of the size, typically 0.2-0.5 s after the visible motion). On
captures with short pen lifts (UNIPEN words: ~0.1 s) later plans drift late by that much per
lift; each plan's own rhythm is kept.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import ndtri

from tagbot.errors import PlanError
from tagbot.gesture import timing_kernels
from tagbot.gesture.strokes import Strokes
from tagbot.inputs.stamps import sample_instants
from tagbot.model.plan import (
    MAX_DURATION,
    MU_RANGE,
    PHI_LIMIT,
    Model,
    Plan,
)

Array = NDArray[np.float64]
Timing = Literal["auto", "ignore", "match"]
TIMINGS: tuple[Timing, ...] = ("auto", "ignore", "match")

MIN_SAMPLES = 8
"""A trace needs at least this many distinct timestamps for its speed to be fitted."""

MAX_INTERVAL = 0.1
"""``auto`` matches timing only when the median sampling interval is at most this (10 Hz)."""

_Z90 = timing_kernels.Z90


@dataclass(frozen=True)
class TimingOptions:
    """Constants of the timing fit; times in seconds, lengths fractions of the tag's size."""

    step: float = 0.01
    """Resampling grid step (coarser for sparse recordings: at most 3 grid steps per sample)."""
    min_bandwidth: float = 0.006
    """Smallest Gaussian kernel width of the resampling."""
    bandwidth: float = 1.0
    """Kernel width in median sampling intervals..."""
    jitter_bandwidth: float = 4.0
    """... and at least this many times the timestamps' own noise (estimated from the spread of
    the positive sampling intervals)."""
    shape_budget: float = 0.004
    """Position residuals are position errors over this fraction of the tag's size, times
    ``position_weight``; velocity residuals are velocity errors over the recording's RMS speed."""
    position_weight: float = 3.0
    """See ``shape_budget``."""
    target_pull: float = 0.05
    """Weight of each interior target's pull back to the geometric fit (per budget moved)."""
    onset_slack: float = 0.5
    """How far an onset may move from its initial timing."""
    mu_bounds: tuple[float, float] = (float(np.log(0.01)), float(np.log(1.0)))
    """Bounds of ``mu`` (log seconds): a stroke's median delay between 10 ms and 1 s."""
    sigma_bounds: tuple[float, float] = (0.05, 0.6)
    """Bounds of ``sigma`` (handwriting strokes are found between about 0.1 and 0.5)."""
    tail_weight: float = 1.0
    """Each stroke should be complete (as a plan's end counts it: within ``END_TOLERANCE`` of
    the size) by the recording's end plus ``pad``: beyond, a penalty of this per ``step`` late.
    Long tails would make a plan outlast its recording by far and push the next plan back."""
    min_extent: float = 3.0
    """Each stroke's velocity pulse (its 10-90 % interval, ``2·exp(mu)·sinh(z90·sigma)``) lasts
    at least this many grid steps: a shorter pulse falls between the grid's instants, where the
    velocity residuals do not see it, and draws as a spike the writer never made. Below it, a
    penalty of ``extent_weight`` per e-fold short."""
    extent_weight: float = 10.0
    """See ``min_extent``."""
    phi_limit: float = PHI_LIMIT
    """Tangent deviations stay within ± this, radians."""
    pad: float = 0.15
    """The grid extends this far before the first sample and after the last (pen at rest, or
    free where the pen moves in the air: see ``air_speed``)."""
    air_speed: float | None = 0.1
    """A trace whose recorded speed at its first (last) sample is at least this fraction of its
    peak speed was touched down (lifted off) while moving: its plan gets a stroke in the air
    before (after) the ink and an ``ink`` window, and the pad there is not fitted. None: never."""
    air_end_weight: float = 5.0
    """Where the pen moves in the air, the weight of the first (last) sample's instant: the ink
    starts (ends) on the recorded point, not merely near it (1: as any instant; 5 scored best
    on the development data, BENCHMARKS.md)."""
    air_lead: float = 0.1
    """The air stroke's far target lies this long at the recorded end speed beyond the end
    point, seconds (its onset and median delay are set from it too)."""
    min_lift: float = 0.05
    """Shortest pen lift between plans: a plan whose recorded start comes sooner after the
    previous plan's end (a restarted clock chained at zero lift, a long tail) starts this long
    after it (a sampled tag shows every lift as pen-up samples)."""
    stall: float = 0.5
    """Gaps between samples longer than this (or 4 kernel widths) hold no grid instants: the
    pen rested or the capture dropped out, and nothing there is fitted."""
    iterations: int = 40
    """Levenberg-Marquardt steps per trace and stage at most (20 before: the fits were still
    improving; 40 gain 0.1-0.3 dB median velocity SNR on the development data for 1.3-2 times
    the fit time, 80 little more for twice that again; BENCHMARKS.md, issue 16)."""
    stages: tuple[tuple[bool, float], ...] = ((False, 1.0), (True, 0.2), (True, 1.0))
    """Successive solver stages: (whether targets and tangents move, the velocity residuals'
    weight relative to the positions'). The timing alone first (the geometric fit's shape is
    kept while the strokes find their instants), then everything with positions weighing more
    (a wider basin), then velocities in full."""
    tolerance: float = 1e-4
    """Stop once a step lowers the cost by less than this fraction."""
    work: float = 4e8
    """Floating-point operations a solver stage may spend, about: traces whose strokes overlap
    so much that the normal equations' band is wide get fewer iterations, and none where one
    would cost more than this (thousands of strokes at once, e.g. random points: the trace then
    keeps the timing it has)."""
    starts: tuple[float, ...] = (1.0, 30.0, 1000.0)
    """The timed fit is run from the geometric plan once per start, with the position residuals
    weighing that many times ``position_weight`` (heavier: the shape held while the strokes find
    their instants, which leads to other minima), and the plan that costs least at the nominal
    weights is kept; where it misses the shape, the next cheapest that keeps it (``restrained``).
    The fit is not convex: from the nominal start alone some traces end in a minimum that breaks
    the shape and lose their timing (on the development data: 10 Hz median per-trace velocity
    SNR 2.8 dB below the reference's ceiling on the graffiti tags, 1.8 dB with these starts, for
    about three times the fit time; BENCHMARKS.md, session 22). At least one, each > 0."""
    max_stroke_ratio: float = 1.5
    """Strokes may be added up to this many times the geometric fit's count (rounded down: a
    trace of one stroke is never split), so a whole tag keeps within it too."""
    split_rounds: int = 3
    """Rounds of stroke splitting at most (each followed by a new fit; 0: none)."""
    split_energy: float = 0.01
    """A stroke is split where the recorded speed dips (``dip_depth``) or the missed velocity
    peaks, if the velocity the plan misses within ``dip_reach`` of there is at least this
    fraction of the recording's velocity energy."""
    dip_depth: float = 0.75
    """A dip: the recorded speed's local minimum below this fraction of the lower of its peaks
    within ``dip_reach`` on either side."""
    dip_reach: float = 0.15
    """See ``dip_depth``, seconds."""
    split_gain: float = 0.05
    """A round of splits is kept only if it lowers the cost by at least this fraction."""

    def __post_init__(self) -> None:
        starts = np.asarray(self.starts, dtype=float)
        if starts.ndim != 1 or starts.size == 0 or not np.all(np.isfinite(starts) & (starts > 0)):
            raise PlanError(f"starts: must be one or more finite weights > 0, got {self.starts!r}")


def simulated_capture(
    plan: Plan,
    rng: np.random.Generator,
    rate: float = 100.0,
    jitter: float = 0.0,
    noise: float = 0.02,
    tick: float = 0.001,
    pixel: float = 0.0,
) -> Any:
    """``plan`` as a digitiser records it, a :class:`~tagbot.inputs.Trace` on the plan's own
    clock: ``rate`` Hz, each time stamp off by ``jitter`` (s, standard deviation) and rounded to
    the clock's ``tick`` (so stamps repeat), positions with ``noise`` (mm) added and rounded to
    ``pixel`` (mm, if any). Synthetic data for tests and benchmarks."""
    from tagbot.inputs.trace import Trace
    from tagbot.model.plan import Tag

    motion = Tag((plan,)).sample(0.001)
    t = np.arange(motion.t[0], motion.t[-1], 1.0 / rate)
    xy = np.column_stack([np.interp(t, motion.t, motion.xy[:, i]) for i in (0, 1)])
    xy += rng.normal(0.0, noise, xy.shape)
    if pixel > 0:
        xy = np.round(xy / pixel) * pixel
    stamps = np.maximum.accumulate(np.round((t + rng.normal(0.0, jitter, t.size)) / tick) * tick)
    return Trace(xy, stamps)


def _distinct(stamps: ArrayLike) -> int:
    """How many distinct instants non-decreasing ``stamps`` hold."""
    return int(np.count_nonzero(np.diff(np.asarray(stamps, dtype=float)) > 0)) + 1


def usable(trace: Any) -> bool:
    """Whether ``trace`` has plausible timestamps for ``timing="auto"``: at least
    :data:`MIN_SAMPLES` distinct times, a median sampling interval of at most
    :data:`MAX_INTERVAL`, and a clock unit its reader found plausible."""
    t = getattr(trace, "t", None)
    if t is None:
        return False
    clock = getattr(trace, "clock", None)
    if clock is not None and "no unit gives a plausible rate" in clock:
        return False
    dt = np.diff(np.asarray(t, dtype=float))
    steps = dt[dt > 0]
    return steps.size + 1 >= MIN_SAMPLES and float(np.median(steps)) <= MAX_INTERVAL


# --------------------------------------------------------------------------- the recording


@dataclass(frozen=True)
class Recording:
    """A recording resampled on a regular grid (:func:`resample`)."""

    t: Array
    """Grid times, seconds on the trace's clock."""
    xy: Array
    """Smoothed positions ``(G, 2)``."""
    v: Array
    """Smoothed velocities ``(G, 2)``."""
    weight: Array
    """Per grid time, 1 where samples surround it closely, less across gaps and in the pads."""
    deadline: float
    """When the plan should have ended (see :attr:`TimingOptions.tail_weight`)."""


def resample(t: Array, xy: Array, options: TimingOptions) -> Recording:
    """The recording on a regular grid by local-quadratic regression (see the module doc)."""
    t, xy = np.asarray(t, dtype=float), np.asarray(xy, dtype=float)
    dt = np.diff(t)
    steps = dt[dt > 0]
    interval = float(np.median(steps)) if steps.size else options.step
    # The clock's own noise: an interval is the difference of two stamps, so the stamps' noise
    # is the intervals' robust spread over √2.
    jitter = 1.4826 * float(np.median(np.abs(steps - interval))) / np.sqrt(2) if steps.size else 0
    width = max(
        options.min_bandwidth, options.bandwidth * interval, options.jitter_bandwidth * jitter
    )
    step = max(options.step, interval / 3.0)
    # The first and last samples' instants are grid instants too: where the ink starts and ends.
    grid = np.union1d(_grid(t, step, max(options.stall, 4.0 * width), options.pad), t[[0, -1]])
    out = timing_kernels.local_quadratic(t, xy[:, 0].copy(), xy[:, 1].copy(), grid, width)
    return Recording(grid, _through(t, xy, grid), out[:, 2:4].copy(), out[:, 4].copy(),
                     float(grid[-1]))  # fmt: skip


def _through(t: Array, xy: Array, grid: Array) -> Array:
    """Positions at the ``grid`` instants on the recorded polyline itself, the samples joined in
    time order (samples sharing an instant averaged): a sharp corner sampled sparsely stays
    sharp, where the smoothing regression would round it by as much as the samples are apart,
    and the shape is what the fit is held to."""
    instants, which = np.unique(t, return_inverse=True)
    count = np.bincount(which, minlength=len(instants))
    x = np.bincount(which, xy[:, 0], len(instants)) / count
    y = np.bincount(which, xy[:, 1], len(instants)) / count
    return np.column_stack([np.interp(grid, instants, x), np.interp(grid, instants, y)])


def _grid(t: Array, step: float, stall: float, pad: float) -> Array:
    """Instants every ``step`` from ``pad`` before the first sample to ``pad`` after the last,
    leaving out gaps between samples longer than ``stall`` (nothing was recorded there), so
    the grid's size follows the samples, not the clock's span."""
    cut = np.flatnonzero(np.diff(t) > stall)
    starts = np.r_[t[0] - pad, t[cut + 1]]
    ends = np.r_[t[cut], t[-1] + pad]
    counts = np.floor((ends - starts) / step).astype(np.intp) + 1
    first = np.repeat(starts, counts)
    index = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    return first + step * index


# --------------------------------------------------------------------------- initial timing


def _arc(xy: Array) -> Array:
    step = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(step)])
    return s / s[-1] if s[-1] > 0 else np.linspace(0.0, 1.0, len(s))


def initial_timing(plan: Plan, rec: Recording, size: float, options: TimingOptions) -> Strokes:
    """``plan``'s strokes (one trace) moved onto the recording's clock by arc length: the
    instant the plan has travelled a fraction of its path maps to the instant the recording has,
    and each stroke follows the map's chord between its 10 % and 90 % instants (its median
    instant mapped, its ``mu`` shifted by the log of the local time scale, ``sigma`` kept)."""
    strokes = Strokes.of([plan.at(0.0)])
    end = float(strokes.ends(size)[0])
    tau = np.linspace(0.0, end, max(256, 8 * len(rec.t)))
    xy, _ = strokes.evaluate(np.zeros(len(tau), dtype=np.intp), tau, size)
    s_model = _arc(xy)
    s_rec = _arc(rec.xy)
    keep = np.concatenate([[True], np.diff(s_rec) > 0])  # stalls map to their first instant
    z = ndtri(np.array([0.1, 0.5, 0.9]))
    times = strokes.onsets[:, None] + np.exp(strokes.mu[:, None] + strokes.sigma[:, None] * z)
    mapped = np.interp(np.interp(times, tau, s_model), s_rec[keep], rec.t[keep])
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = (mapped[:, 2] - mapped[:, 0]) / (times[:, 2] - times[:, 0])
    duration = float(rec.t[-1] - rec.t[0]) - 2 * options.pad
    overall = duration / end if end > 0 and duration > 0 else 1.0
    scale = np.where(np.isfinite(scale) & (scale > 0.05 * overall), scale, overall)
    mu = np.clip(strokes.mu + np.log(scale), *options.mu_bounds)
    onsets = np.maximum.accumulate(mapped[:, 1] - np.exp(mu))
    sigma = np.clip(strokes.sigma, *options.sigma_bounds)
    return strokes.replace(onsets=onsets, mu=mu, sigma=sigma)


# --------------------------------------------------------------------------- the fit


class _Fit:
    """One trace's least-squares problem: the parameter vector, residuals and Jacobian."""

    def __init__(
        self,
        strokes: Strokes,
        rec: Recording,
        size: float,
        arcs: bool,
        opts: TimingOptions,
        velocity: float = 1.0,
        anchor: Array | None = None,
    ) -> None:
        self.rec = rec
        self.size = size
        self.arcs = arcs
        self.opts = opts
        self.n = len(strokes.onsets)
        self.angles = 1 if arcs else 2
        self.interior = len(strokes.targets) - 2
        # Stroke by stroke: t0, mu, sigma, its angles, then the target it arrives at (if
        # interior); so ordered, JᵀJ is banded (a residual sees only the strokes active then).
        width = np.full(self.n, 3 + self.angles + 2)
        width[-1] -= 2
        self.column = np.concatenate([[0], np.cumsum(width)[:-1]]).astype(np.intp)
        self.target_column = (self.column[:-1] + 3 + self.angles).astype(np.intp)
        self.params = int(width.sum())
        speed = np.hypot(rec.v[:, 0], rec.v[:, 1])
        rms = float(np.sqrt(np.sum(speed**2 * rec.weight) / max(np.sum(rec.weight), 1e-300)))
        self.v_scale = max(rms, 1e-9 * size)
        self.wv = velocity * np.sqrt(rec.weight) / self.v_scale
        budget = opts.shape_budget * size
        self.wp = np.sqrt(rec.weight) * opts.position_weight / budget
        self.targets0 = np.ascontiguousarray(strokes.targets, dtype=float)
        self.anchor = self.targets0 if anchor is None else anchor
        self.rec_v = (rec.v * self.wv[:, None]).ravel()
        # No deadline (the ink's cost alone) as the largest float: the kernels see finite input.
        self.deadline = rec.deadline if math.isfinite(rec.deadline) else float(np.finfo(float).max)
        step = float(rec.t[1] - rec.t[0]) if len(rec.t) > 1 else opts.step
        self.log_extent = math.log(opts.min_extent * step)
        # Penalties' weights: a target's pull, lateness per second, a pulse's shortfall.
        self.weights = np.array(
            [opts.target_pull / budget, opts.tail_weight / opts.step, opts.extent_weight]
        )
        self.rec_xy = (rec.xy * self.wp[:, None]).ravel()

    def pack(self, s: Strokes) -> Array:
        x = np.empty(self.params)
        x[self.column], x[self.column + 1], x[self.column + 2] = s.onsets, s.mu, s.sigma
        if self.arcs:
            x[self.column + 3] = s.phi2
        else:
            x[self.column + 3], x[self.column + 4] = s.phi1, s.phi2
        x[self.target_column], x[self.target_column + 1] = s.targets[1:-1, 0], s.targets[1:-1, 1]
        return x

    def arrays(self, x: Array) -> tuple[Array, ...]:
        targets = self.targets0.copy()
        targets[1:-1, 0], targets[1:-1, 1] = x[self.target_column], x[self.target_column + 1]
        phi2 = x[self.column + 3 + (self.angles - 1)]
        phi1 = -phi2 if self.arcs else x[self.column + 3]
        return (
            targets,
            x[self.column],
            x[self.column + 1],
            x[self.column + 2],
            np.ascontiguousarray(phi1),
            np.ascontiguousarray(phi2),
        )

    def strokes(self, x: Array, like: Strokes) -> Strokes:
        targets, onsets, mu, sigma, phi1, phi2 = self.arrays(x)
        return like.replace(
            targets=targets, onsets=onsets, mu=mu, sigma=sigma, phi1=phi1, phi2=phi2
        )

    def bounds(self, x: Array) -> tuple[Array, Array]:
        o = self.opts
        lower, upper = np.full(self.params, -np.inf), np.full(self.params, np.inf)
        onsets = x[self.column]
        lower[self.column], upper[self.column] = onsets - o.onset_slack, onsets + o.onset_slack
        lower[self.column + 1], upper[self.column + 1] = o.mu_bounds
        lower[self.column + 2], upper[self.column + 2] = o.sigma_bounds
        for a in range(self.angles):
            lower[self.column + 3 + a], upper[self.column + 3 + a] = -o.phi_limit, o.phi_limit
        return lower, upper

    def project(self, x: Array, lower: Array, upper: Array) -> Array:
        """Within the bounds, onsets in order."""
        x = np.clip(x, lower, upper)
        x[self.column] = np.maximum.accumulate(x[self.column])
        return x

    def evaluate(
        self, x: Array, jacobian: bool
    ) -> tuple[Array, tuple[NDArray[np.intp], NDArray[np.intp], Array, int] | None]:
        """Residuals at ``x`` (an infinite one where ``x`` is not a valid plan) and, if wanted,
        the Jacobian as COO and its leading fours
        (:func:`~tagbot.gesture.timing_kernels.residuals`)."""
        if not np.all(np.isfinite(x)):
            return np.full(1, np.inf), None
        ok, r, rows, cols, vals, groups = timing_kernels.residuals(
            x, self.column, self.target_column, self.targets0, self.arcs, self.rec.t, self.size,
            self.wv, self.wp, self.rec_v, self.rec_xy, self.anchor, self.weights, self.deadline,
            self.log_extent, jacobian, ANGLE_STEP, JACOBIAN_TAIL,
        )  # fmt: skip
        if not ok:
            return np.full(1, np.inf), None
        return r, ((rows, cols, vals, groups) if jacobian else None)


ANGLE_STEP = 1e-6
"""Central-difference step of the tangents' Jacobian columns, radians."""
JACOBIAN_TAIL = 1e-4
"""In the Jacobian (not the residuals), a stroke within this of not started or complete counts
as such (:func:`~tagbot.gesture.timing_kernels.model_terms`)."""


def match_trace(
    plan: Plan, trace: Any, size: float, model: Model, options: TimingOptions
) -> tuple[Plan, float]:
    """``plan`` (a geometric fit of ``trace``, start 0) refitted to ``trace``'s timing. Returns
    the plan on the trace's clock relative to its first timestamp (``start`` = its first onset,
    possibly negative) and that first timestamp. With strokes in the air where the pen touched
    down or lifted off moving, if they help (:func:`match` weighs them across a tag)."""
    fitted, t0, lifted = _match_trace(plan, trace, size, model, options)
    return (lifted[0] if lifted is not None else fitted), t0


def _match_trace(
    plan: Plan, trace: Any, size: float, model: Model, options: TimingOptions
) -> tuple[Plan, float, tuple[Plan, float] | None]:
    """:func:`match_trace`'s plan without strokes in the air, the first timestamp, and the plan
    with them with its relative gain (the ink cost it saves), if they help."""
    xy = np.asarray(trace.xy, dtype=float)
    distinct = _distinct(trace.t)
    t, _ = sample_instants(trace.t, xy)  # the instants behind the stamps
    t0 = float(t[0])
    rec = resample(t - t0, xy, options)
    initial = initial_timing(plan, rec, size, options)
    try:
        fallback = _as_plan(initial)
    except PlanError:  # e.g. a timing beyond a plan's bounds: the geometric plan, at the start
        fallback = plan.at(0.0)
    if distinct < MIN_SAMPLES or len(rec.t) < 8:
        return fallback, t0, None
    last, arcs = float(t[-1] - t0), model == "sigma"
    initial, _ = _in_the_air(initial, rec, last, (False, False), size, options)
    try:
        fitted = _refit(initial, rec, size, arcs, plan.n_strokes, options)
        rest = _as_plan(fitted)
    except PlanError:  # the refit left a plan's bounds (collapsed targets): keep the first timing
        return fallback, t0, None
    air = _moving_ends(rec, last, options)
    if not any(air):
        return rest, t0, None
    # The same plan with strokes in the air, refitted from there; it must follow the recording
    # better where it was recorded.
    lifted, air_rec = _in_the_air(fitted, rec, last, air, size, options)
    if len(lifted.onsets) == len(fitted.onsets):
        return rest, t0, None
    try:
        lifted, _ = _solve(lifted, air_rec, size, arcs, options, options.stages[-1:])
        before = _ink_cost(fitted, rec, last, size, arcs, options)
        gain = 1.0 - _ink_cost(lifted, rec, last, size, arcs, options) / before
        start = float(lifted.onsets[0])
        # Pen down from the first sample to the last, on the trace's clock.
        up = last - start if air[1] else MAX_DURATION  # (until the motion ends)
        in_air = _as_plan(lifted, (max(-start, 0.0) if air[0] else 0.0, up))
    except (PlanError, ZeroDivisionError, FloatingPointError):
        return rest, t0, None
    return rest, t0, ((in_air, gain) if gain > 0.0 else None)


def _ink_cost(
    strokes: Strokes, rec: Recording, last: float, size: float, arcs: bool, options: TimingOptions
) -> float:
    """The fit's cost (velocity and position residuals, full weights) where the trace was
    recorded, ``0 <= t <= last``: what plans with and without strokes in the air compare by."""
    weight = np.where((rec.t >= 0.0) & (rec.t <= last), rec.weight, 0.0)
    inked = Recording(rec.t, rec.xy, rec.v, weight, np.inf)
    problem = _Fit(strokes, inked, size, arcs, options)
    r, _ = problem.evaluate(problem.pack(strokes), False)
    return float(r @ r)


def fit_cost(plan: Plan, trace: Any, size: float, options: TimingOptions | None = None) -> float:
    """What the timing fit minimises, for ``plan`` (on ``trace``'s clock) against ``trace``
    (timed): the velocity and position residuals at full weight where the trace was recorded
    (:func:`_ink_cost`, the figure strokes in the air are judged by). Two plans of one trace
    compare by it: e.g. a refit that costs more than the plan its recording was made from
    stopped in a worse minimum (a search gap, not the data's). Raises ValueError for a trace
    the fit would not time (fewer than :data:`MIN_SAMPLES` distinct stamps)."""
    opts = options or TimingOptions()
    stamps = np.asarray(trace.t, dtype=float)
    if _distinct(stamps) < MIN_SAMPLES:
        raise ValueError(f"fit_cost: the trace has fewer than {MIN_SAMPLES} distinct stamps")
    t0 = float(sample_instants(stamps, np.asarray(trace.xy, dtype=float))[0][0])
    return _relative_cost(plan.at(plan.start - t0), trace, size, False, opts)


def _relative_cost(
    plan: Plan, trace: Any, size: float, arcs: bool, options: TimingOptions
) -> float:
    """:func:`_ink_cost` of ``plan``, on ``trace``'s clock relative to its first instant (as
    :func:`_match_trace` returns it), against ``trace``."""
    xy = np.asarray(trace.xy, dtype=float)
    t, _ = sample_instants(np.asarray(trace.t, dtype=float), xy)
    rec = resample(t - t[0], xy, options)
    strokes = Strokes.of([plan])
    strokes = strokes.replace(onsets=strokes.onsets + plan.start)
    return _ink_cost(strokes, rec, float(t[-1] - t[0]), size, arcs, options)


def _end_velocities(rec: Recording, last: float) -> tuple[NDArray[np.intp], Array, Array] | None:
    """The grid instants of the recorded span ``0 .. last`` and the recorded velocity at its
    first and at its last instant (from the resampled positions over about 40 ms), or None for a
    span too short."""
    inside = np.flatnonzero((rec.t >= 0.0) & (rec.t <= last))
    k = min(4, len(inside) - 1)
    if k < 1:
        return None
    (a, b), (c, d) = inside[[0, k]], inside[[-1 - k, -1]]
    first = (rec.xy[b] - rec.xy[a]) / (rec.t[b] - rec.t[a])
    final = (rec.xy[d] - rec.xy[c]) / (rec.t[d] - rec.t[c])
    return inside, first, final


def _moving_ends(rec: Recording, last: float, options: TimingOptions) -> tuple[bool, bool]:
    """Whether the recorded speed at the first (at 0) and the last (at ``last``) sample is at
    least :attr:`TimingOptions.air_speed` of the trace's peak: the pen touched down (lifted off)
    while moving."""
    ends = _end_velocities(rec, last)
    if options.air_speed is None or ends is None:
        return False, False
    inside, first, final = ends
    threshold = options.air_speed * float(np.max(np.hypot(*rec.v[inside].T)))
    first_moving, last_moving = (
        bool(threshold > 0 and float(np.hypot(*v)) >= threshold) for v in (first, final)
    )
    return first_moving, last_moving


def _in_the_air(
    strokes: Strokes,
    rec: Recording,
    last: float,
    air: tuple[bool, bool],
    size: float,
    options: TimingOptions,
) -> tuple[Strokes, Recording]:
    """``strokes`` with their end targets on the recording's first and last points and, on each
    side in ``air``, a stroke in the air to or from a target :attr:`TimingOptions.air_lead`
    ``L`` of the recorded end velocity beyond the end point (straight, σ 0.3, median delay
    ``L``, starting ``1.5 L`` before the first sample or ``0.7 L`` before the last: moving
    through the end point about then); the recording with no weight in the pads on those sides
    (nothing was recorded there, and the pen moved) and the end instant weighing
    :attr:`TimingOptions.air_end_weight`."""
    targets = strokes.targets.copy()
    targets[0], targets[-1] = rec.xy[0], rec.xy[-1]
    ends = _end_velocities(rec, last)
    if not any(air) or ends is None:
        chords = np.hypot(*np.diff(targets, axis=0).T)
        return (strokes.replace(targets=targets) if np.all(chords > 1e-9 * size) else strokes), rec
    inside, v_first, v_last = ends
    lead, mu, sigma = options.air_lead, float(np.log(options.air_lead)), 0.3
    first, final = rec.xy[inside[0]], rec.xy[inside[-1]]
    parts = [strokes.targets[1:-1]]
    onsets, mus, sigmas = [strokes.onsets], [strokes.mu], [strokes.sigma]
    weight = rec.weight.copy()
    if air[0]:
        parts.insert(0, np.array([first - v_first * lead, first]))
        onsets.insert(0, np.array([-1.5 * lead]))
        mus.insert(0, np.array([mu]))
        sigmas.insert(0, np.array([sigma]))
        weight[rec.t < 0.0] = 0.0
        weight[inside[0]] *= options.air_end_weight  # the ink starts on the first point
    else:
        parts.insert(0, rec.xy[:1])
    if air[1]:
        parts.append(np.array([final, final + v_last * lead]))
        onsets.append(np.array([last - 0.7 * lead]))
        mus.append(np.array([mu]))
        sigmas.append(np.array([sigma]))
        weight[rec.t > last] = 0.0
        weight[inside[-1]] *= options.air_end_weight
    else:
        parts.append(rec.xy[-1:])
    targets = np.concatenate(parts)
    if np.any(np.hypot(*np.diff(targets, axis=0).T) <= 1e-9 * size):
        return strokes, rec  # an end at rest after all: keep the plan as it is
    count = len(targets) - 1
    zeros = np.zeros(count - len(strokes.onsets))
    before = int(air[0])
    shaped = Strokes(
        targets=targets,
        onsets=np.maximum.accumulate(np.concatenate(onsets)),
        mu=np.concatenate(mus),
        sigma=np.clip(np.concatenate(sigmas), *options.sigma_bounds),
        phi1=np.concatenate([zeros[:before], strokes.phi1, zeros[before:]]),
        phi2=np.concatenate([zeros[:before], strokes.phi2, zeros[before:]]),
        counts=np.array([count], dtype=np.intp),
    )
    deadline = rec.deadline + (lead if air[1] else 0.0)
    return shaped, Recording(rec.t, rec.xy, rec.v, weight, deadline)


def _refit(
    strokes: Strokes, rec: Recording, size: float, arcs: bool, count: int, options: TimingOptions
) -> Strokes:
    """The least-squares fit of ``strokes`` to ``rec``, with strokes added where the recorded
    speed shows a bump the plan misses (up to ``max_stroke_ratio`` times ``count``)."""
    strokes, cost = _solve(strokes, rec, size, arcs, options)
    room = int(np.floor((options.max_stroke_ratio - 1.0) * count + 1e-9))  # a tag stays within
    for _ in range(options.split_rounds):
        if room <= 0:
            break
        split = _split(strokes, rec, size, options, room)
        if split is None:
            break
        candidate, new_cost = _solve(split, rec, size, arcs, options, options.stages[-1:])
        if not new_cost < (1.0 - options.split_gain) * cost:
            break
        room -= len(candidate.onsets) - len(strokes.onsets)
        strokes, cost = candidate, new_cost
    return strokes


_Z10 = -_Z90


def _split(
    strokes: Strokes, rec: Recording, size: float, options: TimingOptions, room: int
) -> Strokes | None:
    """``strokes`` with strokes split in two (a new target between) where the recorded speed
    dips between two peaks or the velocity the plan misses peaks, and the plan misses much of
    the recorded velocity around there: the stroke split is the fastest there among those
    whose 10-90 % interval holds the instant (at most ``room`` splits, one per stroke), or None
    if there is none."""
    _, v = strokes.evaluate(np.zeros(len(rec.t), dtype=np.intp), rec.t, size)
    speed = np.hypot(rec.v[:, 0], rec.v[:, 1])
    miss = np.sum((rec.v - v) ** 2, axis=1) * rec.weight
    total = float(np.sum(speed**2 * rec.weight))
    if total <= 0:
        return None
    step = float(rec.t[1] - rec.t[0])
    reach = max(2, round(options.dip_reach / step))
    cumulative = np.concatenate([[0.0], np.cumsum(miss)])
    index = np.arange(len(miss))
    missed = cumulative[np.minimum(index + reach + 1, len(miss))]
    missed -= cumulative[np.maximum(index - reach, 0)]
    # Candidate instants: the recorded speed's dips, and the peaks of the velocity the plan
    # misses around each instant (an unexplained bump with no dip of its own).
    bumps = np.flatnonzero((missed[1:-1] > missed[:-2]) & (missed[1:-1] >= missed[2:])) + 1
    dips = np.union1d(_dips(speed, reach, options.dip_depth, 0.1 * float(speed.max())), bumps)
    if dips.size == 0:
        return None
    energy = missed[dips] / total
    lo = strokes.onsets + np.exp(strokes.mu + strokes.sigma * _Z10)
    hi = strokes.onsets + np.exp(strokes.mu + strokes.sigma * _Z90)
    margin = 0.1 * (hi - lo)
    cuts: dict[int, float] = {}
    for d in dips[np.argsort(-energy)]:
        if len(cuts) >= room or energy[np.searchsorted(dips, d)] < options.split_energy:
            break
        t = float(rec.t[d])
        holds = np.flatnonzero((lo + margin < t) & (t < hi - margin))
        holds = holds[[j not in cuts for j in holds]]
        if holds.size == 0:
            continue
        elapsed = np.maximum(t - strokes.onsets[holds], 1e-300)
        z = (np.log(elapsed) - strokes.mu[holds]) / strokes.sigma[holds]
        fastest = strokes.lengths[holds] * np.exp(-0.5 * z * z) / (strokes.sigma[holds] * elapsed)
        cuts[int(holds[np.argmax(fastest)])] = t
    if not cuts:
        return None
    return _insert(strokes, rec, list(cuts.items()))


def _dips(speed: Array, reach: int, depth: float, floor: float) -> NDArray[np.intp]:
    """Grid indices where ``speed`` has a local minimum below ``depth`` times the lower of the
    highest speeds within ``reach`` samples on either side (which must exceed ``floor``)."""
    n = len(speed)
    if n < 3:
        return np.zeros(0, dtype=np.intp)
    i = np.flatnonzero((speed[1:-1] < speed[:-2]) & (speed[1:-1] <= speed[2:])) + 1
    if i.size == 0:
        return i
    padded = np.r_[np.full(reach, -np.inf), speed, np.full(reach, -np.inf)]
    windows = np.lib.stride_tricks.sliding_window_view(padded, reach + 1)
    left = windows[i].max(axis=1)  # speed[i − reach .. i]
    right = windows[i + reach].max(axis=1)  # speed[i .. i + reach]
    low = np.minimum(left, right)
    return i[(speed[i] < depth * low) & (low > floor)]


def _insert(strokes: Strokes, rec: Recording, cuts: list[tuple[int, float]]) -> Strokes:
    """Split stroke ``j`` at recorded time ``t`` for each cut: a new target at the recording's
    position then, each half timed over its share of the stroke's 10-90 % interval (``sigma``
    kept), straight halves."""
    targets = list(strokes.targets)
    onsets, mu, sigma = list(strokes.onsets), list(strokes.mu), list(strokes.sigma)
    phi1, phi2 = list(strokes.phi1), list(strokes.phi2)
    for j, t in sorted(cuts, reverse=True):
        s = sigma[j]
        lo = onsets[j] + np.exp(mu[j] + s * _Z10)
        hi = onsets[j] + np.exp(mu[j] + s * _Z90)
        point = np.array([np.interp(t, rec.t, rec.xy[:, 0]), np.interp(t, rec.t, rec.xy[:, 1])])
        halves = []
        for a, b in ((lo, t), (t, hi)):
            delay = max(b - a, 1e-3) / (2.0 * np.sinh(s * _Z90))
            halves.append((a - delay * np.exp(s * _Z10), float(np.log(delay))))
        targets.insert(j + 1, point)
        onsets[j : j + 1] = [halves[0][0], halves[1][0]]
        mu[j : j + 1] = [halves[0][1], halves[1][1]]
        sigma[j : j + 1] = [s, s]
        phi1[j : j + 1] = [0.0, 0.0]
        phi2[j : j + 1] = [0.0, 0.0]
    return Strokes(
        targets=np.array(targets),
        onsets=np.maximum.accumulate(np.array(onsets)),
        mu=np.array(mu),
        sigma=np.array(sigma),
        phi1=np.array(phi1),
        phi2=np.array(phi2),
        counts=np.array([len(onsets)], dtype=np.intp),
    )


def _solve(
    strokes: Strokes,
    rec: Recording,
    size: float,
    arcs: bool,
    options: TimingOptions,
    stages: tuple[tuple[bool, float], ...] | None = None,
) -> tuple[Strokes, float]:
    """Levenberg-Marquardt on :class:`_Fit`'s residuals, steps projected onto the bounds."""
    anchor = strokes.targets
    cost = np.inf
    for free, velocity in options.stages if stages is None else stages:
        problem = _Fit(strokes, rec, size, arcs, options, velocity, anchor)
        x, cost = _levenberg_marquardt(problem, problem.pack(strokes), options, free)
        strokes = problem.strokes(x, strokes)
    return strokes, cost


def _levenberg_marquardt(
    problem: _Fit, x: Array, options: TimingOptions, geometry: bool = True
) -> tuple[Array, float]:
    """Minimise ``problem``'s residuals from ``x``: damped Gauss-Newton steps projected onto the
    bounds, kept only when they lower the cost; with ``geometry`` False, only the onsets, ``mu``
    and ``sigma`` move (targets and tangents held where they are)."""
    lower, upper = problem.bounds(x)
    if not geometry:
        held = np.ones(problem.params, dtype=bool)
        held[problem.column], held[problem.column + 1], held[problem.column + 2] = (
            False,
            False,
            False,
        )
        lower[held], upper[held] = x[held], x[held]
    x = problem.project(x, lower, upper)
    r, jac = problem.evaluate(x, True)
    if jac is None:
        return x, np.inf
    cost = float(r @ r)
    damping = 1e-3
    iterations = options.iterations
    for iteration in range(options.iterations):
        if iteration >= iterations:
            break
        a, grad = timing_kernels.normal_band(*jac, r, problem.params)
        if iteration == 0:  # bound the work: a step costs about params·band² (and the rows')
            band = a.shape[1]
            work = problem.params * band * band + jac[0].size * band
            if work > options.work:  # strokes overlapping so much that one step is too dear:
                return x, cost  # the trace keeps the timing it has (see _shape_first)
            iterations = int(np.clip(options.work / (7 * work), 1, options.iterations))
        diag = np.maximum(a[:, 0], 1e-12 * max(float(np.max(a[:, 0])), 1e-300))
        accepted = False
        for _ in range(6):
            step, ok = timing_kernels.damped_step(a, grad, diag, damping)
            if not ok:
                damping *= 10.0
                continue
            trial = problem.project(x + step, lower, upper)
            r_new, _ = problem.evaluate(trial, False)
            c_new = float(r_new @ r_new)
            if c_new < cost:
                accepted = True
                break
            damping *= 4.0
        if not accepted:
            break
        gain = (cost - c_new) / cost
        x, cost = trial, c_new
        damping = max(damping / 3.0, 1e-9)
        r, jac = problem.evaluate(x, True)
        if jac is None or gain < options.tolerance:
            break
    return x, cost


def _as_plan(strokes: Strokes, ink: tuple[float, float] | None = None) -> Plan:
    onsets = strokes.onsets
    start = float(onsets[0])
    dt = np.diff(onsets, prepend=start)
    return Plan(
        strokes.targets, dt, strokes.mu, strokes.sigma, strokes.phi1, strokes.phi2, start, ink
    )


MAX_STROKE_RATE = 40.0
"""A hand draws at most this many lognormal strokes (of the geometric fit) per second of a
trace, or of a whole capture. The fastest trace of the development data: 25 per second (a
UNIPEN word's 2-stroke trace over 8 samples); graffiti tags 15, motion-captured letters 19
(BENCHMARKS.md, session 16). A faster clock is not a writer's (e.g. a 29-stroke tag stamped
within 0.38 s, eye-tracker clicks 6 ms apart)."""
MAX_TURN_RATE = 40.0
"""... and turns at most this many half turns (180°) per second (development data: at most
25, a UNIPEN word's trace; rapid alternating movements of the hand top out near 10 Hz, 20 half
turns per second)."""
MAX_TURN_ACCELERATION = 150_000.0
"""... and takes its fast turns with at most this acceleration across the path (``v²·κ``, mm/s²:
150 m/s², about 15 g, judged at :data:`TURN_QUANTILE` of the trace, :func:`fastest_turn`). A
hand cannot take a tight turn at speed: drawing movements slow down where the path curves (the
two-thirds power law, speed ∝ curvature^(-1/3): Lacquaniti, Terzuolo & Viviani 1983, Acta
Psychologica 54:115-130), and the fastest arm movements peak near 50 m/s² (a minimum-jerk
reach of distance D in time T peaks at 5.77·D/T²: 0.5 m in 0.25 s, the fast end of the
unrestrained reaches of Atkeson & Hollerbach 1985, J. Neurosci. 5:2318-2330, is 46 m/s²).
Development data (BENCHMARKS.md, issue 29): UNIPEN words at most 2.4 m/s², timed graffiti
tags 15, motion-captured letters a metre tall drawn in 1-2 s 66; the cap leaves 2.3 times the
fastest. A clock compressed ten times multiplies the figure by 100. Lengths are the input's
(mm): a capture whose units are not physical (normalised GML, 100 mm per unit; pixels) is
judged at its stated size."""
TURN_QUANTILE = 0.95
"""See :func:`fastest_turn`."""
_TURN_OPTIONS = TimingOptions(step=0.0, min_bandwidth=0.0, pad=0.0)
""":func:`fastest_turn`'s resampling: the grid and the kernel follow the sampling interval."""
INK_TOLERANCE = 0.002
"""A timed plan's ink runs from the first recorded sample to the last, widened to where its
path left to travel (or travelled) is below this fraction of the tag's size: the lognormal
tails beyond are drawn in the air (or not at all), never as ink that delays the next plan."""
SHAPE_MARGIN_MEAN = 0.0005
"""A timed plan's mean shape error may exceed the geometric fit's of the same trace by this
fraction of the tag's size..."""
SHAPE_MARGIN_MAX = (1.5, 0.005)
"""... and its maximum by ``max(1.5 times, +0.5 %)`` of it; otherwise the trace keeps the geometric
plan, its clock scaled to the recorded span (the shape exactly the geometric fit's)."""

MARGIN_HEADROOM = 0.9
"""The fit holds each trace to this fraction of the margins (see :data:`SHAPE_MARGIN_MAX`)."""

TimingKind = Literal["matched", "restrained", "mapped", "scaled", "geometric"]


@dataclass(frozen=True)
class TraceTiming:
    """How one trace's plan was timed, and why it was not matched to the recording."""

    kind: TimingKind
    """How much of the recorded timing it keeps, the most first: ``matched``: its velocity
    fitted to the recorded one; ``restrained``: the fit from a start with the shape weighing
    more (:attr:`TimingOptions.starts`; the cheapest fit missed the shape); ``mapped``: the
    geometric plan's strokes moved onto the recording's clock by arc length; ``scaled``: the
    geometric plan, its clock scaled to the recorded pen-down span (the geometric fit's shape
    exactly); ``geometric``: the geometric plan at the paper's rhythm (a clock no hand can
    produce)."""
    reason: str = ""
    """Why it is not ``matched`` (empty when it is)."""

    def describe(self, index: int) -> str:
        """One line for people: ``trace 3: scaled (the timed fit ...)``."""
        return f"trace {index}: {self.kind}" + (f" ({self.reason})" if self.reason else "")


def plan_turning(plan: Plan, size: float) -> float:
    """How much ``plan``'s path turns, in half turns (180°): its motion sampled at 512 instants
    (the model's path, smooth where a recording's points carry noise that would add turning)."""
    from tagbot.metrics import turning_of
    from tagbot.model.motion import evaluate_plan

    on, off = plan.windows(size, INK_TOLERANCE)
    xy, _ = evaluate_plan(plan, np.linspace(float(on.min()), float(off.max()), 512), size)
    return turning_of([xy])


def pen_down_span(t: ArrayLike) -> float:
    """How long a trace stamped ``t`` was drawn: its stamps' span and one sampling interval more
    (the pen moved before the first sample and after the last), so that a short trace is not
    judged on a truncated span."""
    t = np.asarray(t, dtype=float)
    steps = np.diff(t)
    steps = steps[steps > 0]
    return float(t[-1] - t[0]) + (float(np.median(steps)) if steps.size else 0.0)


@dataclass(frozen=True)
class Turn:
    """The fastest turn of a recording (:func:`fastest_turn`): its acceleration across the path
    (``v²·κ``, the centripetal acceleration), the speed and the radius of curvature there."""

    acceleration: float
    """Length units per s² (mm/s² for inputs in mm)."""
    speed: float
    radius: float


def fastest_turn(t: ArrayLike, xy: ArrayLike) -> Turn:
    """The recording's fastest turn, judged robustly: its velocity on a grid of a third of the
    median sampling interval by the local-quadratic regression of :func:`resample` (the kernel
    as wide as that interval, no wider, so the figure scales as 1/c² when the clock is scaled by
    c), the acceleration by central differences of it, and across the path
    ``|v × a| / |v|``; the figure is the :data:`TURN_QUANTILE` quantile over the grid instants
    the samples surround closely (a single stray sample does not decide it). A trace of fewer
    than :data:`MIN_SAMPLES` distinct stamps has no figure (zeros)."""
    t, xy = np.asarray(t, dtype=float), np.asarray(xy, dtype=float)
    if _distinct(t) < MIN_SAMPLES:
        return Turn(0.0, 0.0, 0.0)
    instants, _ = sample_instants(t, xy)
    rec = resample(instants - instants[0], xy, _TURN_OPTIONS)
    step = np.diff(rec.t)
    # Central differences between grid neighbours one step apart on both sides (not across a
    # stall, where the grid leaves a gap).
    regular = np.flatnonzero(
        (np.abs(step[1:] - step[:-1]) <= 1e-9 * np.maximum(step[1:], 1e-300))
        & (rec.weight[1:-1] == 1.0)
        & (rec.weight[:-2] == 1.0)
        & (rec.weight[2:] == 1.0)
    )
    if regular.size == 0:
        return Turn(0.0, 0.0, 0.0)
    k = regular + 1
    v = rec.v[k]
    a = (rec.v[k + 1] - rec.v[k - 1]) / (rec.t[k + 1] - rec.t[k - 1])[:, None]
    speed = np.hypot(v[:, 0], v[:, 1])
    cross = np.abs(v[:, 0] * a[:, 1] - v[:, 1] * a[:, 0])
    normal = np.divide(cross, speed, out=np.zeros_like(speed), where=speed > 0)
    order = np.argsort(normal, kind="stable")
    at = order[min(int(TURN_QUANTILE * len(order)), len(order) - 1)]
    figure = float(normal[at])
    return Turn(figure, float(speed[at]), float(speed[at] ** 2 / figure) if figure > 0 else 0.0)


def implausible_clock(n_strokes: int, turning: float, span: float, turn: Turn | None = None) -> str:
    """Why a drawing of ``n_strokes`` geometric strokes turning ``turning`` half turns in
    ``span`` seconds of pen-down time (:func:`pen_down_span`), its fastest turn ``turn`` (one
    trace's, :func:`fastest_turn`), cannot be a hand's, or "" if it can
    (:data:`MAX_STROKE_RATE`, :data:`MAX_TURN_RATE`, :data:`MAX_TURN_ACCELERATION`)."""
    if span <= 0:
        return "clock implausible: no time between its stamps"
    for count, limit, noun in (
        (n_strokes, MAX_STROKE_RATE, "strokes"),
        (turning, MAX_TURN_RATE, "half turns"),
    ):
        if count > 1 and count / span > limit:
            return (
                f"clock implausible: {count:.3g} {noun} in {span:.3g} s, {count / span:.3g} per"
                f" second; a hand draws at most {limit:g}"
            )
    if turn is not None and turn.acceleration > MAX_TURN_ACCELERATION:
        return (
            f"clock implausible: {turn.acceleration / 1000:.3g} m/s² across the path at its"
            f" fast turns ({turn.speed / 1000:.3g} m/s on a {turn.radius:.3g} mm radius); a"
            f" hand reaches at most {MAX_TURN_ACCELERATION / 1000:g}"
        )
    return ""


def match(
    plans: list[Plan],
    traces: list[Any],
    size: float,
    model: Model,
    timing: Timing,
    options: TimingOptions | None = None,
) -> tuple[list[Plan], list[TraceTiming]] | None:
    """Plans refitted to their traces' timing and placed on the file's clock (see the module
    doc), with how each was timed, or None when ``timing`` says not to (``ignore``, or
    ``auto`` without usable timing on every trace, or a whole capture whose clock no hand can
    produce). Under ``auto`` a trace whose clock is implausible (:func:`implausible_clock`)
    keeps its geometric plan; under either, a timed plan that would miss the shape by more
    than the margins (:data:`SHAPE_MARGIN_MEAN`, :data:`SHAPE_MARGIN_MAX`) is replaced by the
    geometric plan on the recorded span."""
    if timing == "ignore":
        return None
    opts = options or TimingOptions()
    timed = [getattr(tr, "t", None) is not None for tr in traces]
    if not all(timed) or (timing == "auto" and not any(usable(tr) for tr in traces)):
        return None
    turning = [plan_turning(plan, size) for plan in plans]
    spans = [pen_down_span(tr.t) for tr in traces]
    if timing == "auto":
        whole = implausible_clock(sum(p.n_strokes for p in plans), sum(turning), sum(spans))
        if whole:
            return None
    verdicts = [
        implausible_clock(plan.n_strokes, turn, span, fastest_turn(tr.t, tr.xy))
        if timing == "auto"
        else ""
        for plan, turn, span, tr in zip(plans, turning, spans, traces, strict=True)
    ]
    starts = [
        None if verdict else _match_from_starts(plan, trace, size, model, opts)
        for plan, trace, verdict in zip(plans, traces, verdicts, strict=True)
    ]
    candidates = [None if fits is None else fits[0] for fits in starts]
    # Strokes in the air where they help most for the strokes they add, within the tag's budget
    # (max_stroke_ratio times the geometric strokes, less what the splits added).
    chosen = [plan if c is None else c[0] for plan, c in zip(plans, candidates, strict=True)]
    budget = math.floor(opts.max_stroke_ratio * sum(p.n_strokes for p in plans))
    budget -= sum(p.n_strokes for p in chosen)
    offers = [(gain / (air.n_strokes - chosen[k].n_strokes), k, air)
              for k, c in enumerate(candidates) if c is not None and c[2] is not None
              for air, gain in [c[2]]]  # fmt: skip
    for _, k, air in sorted(offers, key=lambda offer: -offer[0]):
        extra = air.n_strokes - chosen[k].n_strokes
        if extra <= budget:
            chosen[k], budget = air, budget - extra
    points = np.concatenate([plan.targets for plan in chosen])
    tag_size = float(np.hypot(*np.ptp(points, axis=0)))  # what Tag measures its plans' ends by
    # The ink may outlast the recorded span (INK_TOLERANCE) only into the recorded lifts, each
    # side into its half of what a lift has beyond min_lift: never pushing the next trace.
    first = np.array([float(tr.t[0]) for tr in traces])
    last = np.array([float(tr.t[-1]) for tr in traces])
    spare = np.maximum(first[1:] - last[:-1] - opts.min_lift, 0.0) / 2
    lows = first - np.r_[np.inf, spare]
    highs = last + np.r_[spare, np.inf]
    out: list[Plan] = []
    timings: list[TraceTiming] = []
    previous_lift = -np.inf
    for k, (geometric, trace) in enumerate(zip(plans, traces, strict=True)):
        t = np.asarray(trace.t, dtype=float)
        if candidates[k] is None:
            plan, timing_k = geometric.at(float(t[0])), TraceTiming("geometric", verdicts[k])
        else:
            limits = (float(lows[k] - t[0]), float(highs[k] - t[0]))
            enough = _distinct(t) >= MIN_SAMPLES
            others = [(fit[0], fit[1]) for fit in starts[k][1:]]
            options = _shape_first(
                chosen[k] if enough else None, candidates[k][1], others, geometric, trace, size,
                opts,
            )  # fmt: skip
            plan, kind, base, reason, window = _kept_to_shape(
                options, geometric, trace, tag_size, limits
            )
            # Inked once, within the limits the shape check accepted (the recorded lifts, or
            # none where the shape needs more ink than they leave).
            bounds = (lows[k], highs[k]) if window[1] < np.inf else (-np.inf, np.inf)
            plan = _with_ink(plan.at(base + plan.start), t, tag_size, bounds)
            if kind == "scaled" and implausible_clock(geometric.n_strokes, turning[k], spans[k]):
                plan, kind = geometric.at(float(t[0])), "geometric"  # (under match)
                reason += "; its recorded span is too short for the geometric plan"
            timing_k = TraceTiming(kind, reason)
        touch_down = plan.ink_window(tag_size)[0]
        if touch_down < previous_lift + opts.min_lift:  # waits for the previous lift-off
            plan = plan.at(plan.start + previous_lift + opts.min_lift - touch_down)
        out.append(plan)
        timings.append(timing_k)
        previous_lift = plan.ink_window(tag_size)[1]
    return out, timings


def _match_from_starts(
    plan: Plan, trace: Any, size: float, model: Model, options: TimingOptions
) -> list[tuple[Plan, float, tuple[Plan, float] | None]]:
    """:func:`_match_trace` from each of :attr:`TimingOptions.starts`, the one whose plan (with
    strokes in the air, where they help) costs least at the nominal weights first."""

    def cost(fitted: tuple[Plan, float, tuple[Plan, float] | None]) -> float:
        drawn = fitted[2][0] if fitted[2] is not None else fitted[0]
        try:
            return _relative_cost(drawn, trace, size, model == "sigma", options)
        except (PlanError, FloatingPointError, ZeroDivisionError):
            return np.inf

    weights = [options.position_weight * start for start in options.starts]
    fits = [
        _match_trace(plan, trace, size, model, replace(options, position_weight=w)) for w in weights
    ]
    return sorted(fits, key=cost)


def _with_ink(
    plan: Plan, t: Array, size: float, limits: tuple[float, float] = (-np.inf, np.inf)
) -> Plan:
    """``plan`` (on the trace's clock) inking from the first recorded instant ``t[0]`` to the
    last ``t[-1]``, widened to where the path left to travel (or travelled) is below
    :data:`INK_TOLERANCE` of ``size`` but not beyond ``limits``; where the pen touches down
    or lifts off moving (strokes in the air, :meth:`~tagbot.model.plan.Plan.moving_ends`) the
    window it has is kept."""
    on, off = plan.windows(size, INK_TOLERANCE)
    start, end = plan.start, plan.end(size)
    moving = plan.moving_ends(size)
    down = min(max(min(float(t[0]), float(on.min())), limits[0], start), end)
    up = max(min(max(float(t[-1]), float(off.max())), limits[1], end), down)
    if any(moving):
        window = plan.ink_window(size)
        down = window[0] if moving[0] else min(down, window[1])
        up = window[1] if moving[1] else max(up, down)
    if not up > down:
        return plan
    return Plan(
        plan.targets, plan.dt, plan.mu, plan.sigma, plan.phi1, plan.phi2, plan.start,
        (down - start, up - start),
    )  # fmt: skip


def _drawn_error(plan: Plan, xy: Array, size: float) -> tuple[float, float]:
    """Mean and max shape error of what ``plan`` inks against the polyline ``xy``, as fractions
    of ``size``, as :func:`tagbot.metrics.fit_report` measures them."""
    from tagbot.metrics import ink_polyline, shape_error

    error = shape_error([xy], [ink_polyline(plan, size)])
    return error.mean * error.size / size, error.max * error.size / size


def _kept_to_shape(
    candidates: Iterator[tuple[Plan, TimingKind, float]],
    geometric: Plan,
    trace: Any,
    size: float,
    limits: tuple[float, float],
) -> tuple[Plan, TimingKind, float, str, tuple[float, float]]:
    """The first of ``candidates`` (plans relative to the instant ``t0`` each comes with, their
    kind) whose ink, within ``limits`` (relative to the trace's first stamp) or else without
    them, keeps within the shape margins of ``geometric``'s, else ``geometric`` scaled to the
    recorded span; with its ``t0``, why the first candidate was not kept, and the limits its
    ink keeps to (relative to its ``t0``)."""
    xy = np.asarray(trace.xy, dtype=float)
    t = np.asarray(trace.t, dtype=float)
    reference = _drawn_error(geometric, xy, size)
    # Each trace keeps MARGIN_HEADROOM of the margins in hand, so that a whole file's mean (an
    # average by arc length over its traces, both ways) keeps within them too.
    limit_mean = reference[0] + MARGIN_HEADROOM * SHAPE_MARGIN_MEAN
    limit_max = MARGIN_HEADROOM * max(
        SHAPE_MARGIN_MAX[0] * reference[1], reference[1] + SHAPE_MARGIN_MAX[1]
    )
    distinct = _distinct(t)
    reason = f"{distinct} distinct time stamps, too few to fit a speed"
    for k, (plan, kind, t0) in enumerate(candidates):
        # Inking within the recorded lifts, else as long as the shape needs (which may delay
        # the next plan a little: the shape comes first).
        for window in ((limits[0] + t[0] - t0, limits[1] + t[0] - t0), (-np.inf, np.inf)):
            mean, largest = _drawn_error(_with_ink(plan, t - t0, size, window), xy, size)
            if mean <= limit_mean and largest <= limit_max:
                return plan, kind, t0, ("" if k == 0 and kind == "matched" else reason), window
        if k == 0 and kind == "matched":
            reason = (
                f"the timed fit missed the shape: mean {100 * mean:.2f} %, max"
                f" {100 * largest:.2f} % of the size, against {100 * reference[0]:.2f} % and"
                f" {100 * reference[1]:.2f} % geometric"
            )
    return _scaled(geometric, t - t[0], size), "scaled", float(t[0]), reason, limits


def _shape_first(
    timed: Plan | None,
    t0: float,
    others: list[tuple[Plan, float]],
    geometric: Plan,
    trace: Any,
    size: float,
    options: TimingOptions,
) -> Iterator[tuple[Plan, TimingKind, float]]:
    """The plans a trace may be drawn with, the most timing first: the timed fit (if it has
    one), the fits from the other starts (``others``, cheapest first; the positions weighed
    more there) within its strokes, then the geometric plan moved onto the recording's clock by
    arc length (:func:`initial_timing`)."""
    if timed is not None:
        yield timed, "matched", t0
        for restrained, t0_restrained in others:
            if restrained.n_strokes <= timed.n_strokes:  # within the tag's stroke budget
                yield restrained, "restrained", t0_restrained
    xy = np.asarray(trace.xy, dtype=float)
    t, _ = sample_instants(trace.t, xy)
    rec = resample(t - t[0], xy, options)
    try:
        yield _as_plan(initial_timing(geometric, rec, size, options)), "mapped", float(t[0])
    except PlanError:
        return


def _scaled(plan: Plan, t: Array, size: float) -> Plan:
    """``plan`` with its clock scaled uniformly (the shape unchanged) so that its motion, from
    where it has travelled :data:`INK_TOLERANCE` of ``size`` to where it has that much left,
    spans the recorded instants ``t`` (unchanged for a span of no time)."""
    on, off = plan.windows(size, INK_TOLERANCE)
    begin, finish = float(on.min()), float(off.max())
    span = float(t[-1] - t[0])
    if not (span > 0 and finish > begin):
        return plan.at(float(t[0]) - begin)
    k = span / (finish - begin)
    lo, hi = MU_RANGE
    if not (lo <= float(plan.mu.min()) + math.log(k) and float(plan.mu.max()) + math.log(k) <= hi):
        return plan.at(float(t[0]) - begin)
    scaled = Plan(
        plan.targets, plan.dt * k, plan.mu + math.log(k), plan.sigma, plan.phi1, plan.phi2,
        plan.start * k,
    )  # fmt: skip
    return scaled.at(float(t[0]) - (begin - plan.start) * k)


__all__ = [
    "INK_TOLERANCE",
    "MAX_INTERVAL",
    "MAX_STROKE_RATE",
    "MAX_TURN_ACCELERATION",
    "MAX_TURN_RATE",
    "MIN_SAMPLES",
    "TIMINGS",
    "Recording",
    "Timing",
    "TimingOptions",
    "TraceTiming",
    "Turn",
    "fastest_turn",
    "fit_cost",
    "implausible_clock",
    "initial_timing",
    "match",
    "match_trace",
    "pen_down_span",
    "plan_turning",
    "resample",
    "simulated_capture",
    "usable",
]
