"""Motion: a tag sampled at a fixed time step, in closed form.

Sample ``i`` is at ``t = tag.start + i·dt``. A plan's samples run from the first one at or after its
``start`` (on its first target) to the first one at or after its end (on its last target, within
``END_TOLERANCE × tag.size``). Between plans the pen is up (``pen = 0``, ``plan = -1``), the speed
is 0 and the position is where the pen will next go down; each pen lift therefore shows as at least
one pen-up sample, and a ``dt`` too coarse for a lift is refused. A plan with an ``ink`` window
moves in the air outside it: those samples follow the plan with the pen up (``pen = 0``,
``plan = -1``), and its pen-down run is the samples within the window.

Position and velocity are exact: each stroke contributes its curve evaluated at arc length
``D·W(t)`` and the velocity ``D·Λ(t)`` along the curve's tangent there (no differencing, no
integration). A stroke is evaluated only inside its active window; before it it contributes
nothing, after it its whole chord. Cost is linear in the number of (sample, active stroke) pairs.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tagbot.errors import PlanError
from tagbot.model import kernels
from tagbot.model.plan import END_TOLERANCE, Plan, Tag

MAX_SAMPLES = 50_000_000
"""Refuse to allocate more samples than this (about 2.4 GB of arrays)."""

Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Motion:
    """Samples at a fixed time step. Arrays share their first dimension ``N``."""

    t: Array
    """Time, seconds on the tag's clock, ``(N,)``."""
    xy: Array
    """Pen position, ``(N, 2)``, in the tag's units."""
    v: Array
    """Velocity, ``(N, 2)``, units per second (analytic)."""
    speed: Array
    """``|v|``, ``(N,)``."""
    pen: NDArray[np.int8]
    """1 while the pen is down, 0 during lifts, ``(N,)``."""
    plan: NDArray[np.intp]
    """Index of the plan being drawn, -1 during lifts, ``(N,)``."""
    dt: float
    """The time step, seconds."""

    def __len__(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        """Time from the first sample to the last, seconds."""
        return float(self.t[-1] - self.t[0]) if len(self.t) else 0.0

    def runs(self) -> Iterator[tuple[int, slice]]:
        """``(plan index, slice)`` for each pen-down run, in drawing order."""
        down = np.flatnonzero(np.diff(np.concatenate([[-1], self.plan, [-1]])) != 0)
        for begin, end in itertools.pairwise(down):
            if self.plan[begin] >= 0:
                yield int(self.plan[begin]), slice(int(begin), int(end))


def sample(tag: Tag, dt: float = 0.01) -> Motion:
    """Sample ``tag`` every ``dt`` seconds. See the module docstring for what each sample holds."""
    dt = _check_dt(dt)
    size, origin = tag.size, tag.start
    starts, ends = owned_spans(tag)
    first = [int(np.ceil((start - origin) / dt - 1e-9)) for start in starts]
    last = [int(np.ceil((end - origin) / dt)) for end in ends]
    for k in range(1, len(tag.plans)):
        if tag.plans[k].start < tag.plans[k - 1].end(size):  # handed over at starts[k]
            cut = (starts[k] - origin) / dt
            whole = ends[k - 1] >= tag.plans[k - 1].end(size)  # the motion ends there anyway
            last[k - 1] = max(int(np.ceil(cut) if whole else np.floor(cut + 1e-9)), first[k - 1])
            first[k] = last[k - 1] + 1
    n = last[-1] + 1
    if n > MAX_SAMPLES:
        raise PlanError(
            f"dt: {dt:g} s over {tag.end - origin:.6g} s needs {n} samples (max {MAX_SAMPLES})"
        )

    t = origin + np.arange(n) * dt
    rows = [slice(first[k], last[k] + 1) for k in range(len(tag.plans))]
    downs = [
        rows[k] if plan.ink is None else _down_rows(plan.ink_window(size), t, dt)
        for k, plan in enumerate(tag.plans)
    ]
    for k in range(1, len(tag.plans)):
        if downs[k].start < downs[k - 1].stop + 1:  # no pen-up sample between the runs
            up = tag.plans[k].ink_window(size)[0] - tag.plans[k - 1].ink_window(size)[1]
            raise PlanError(
                f"dt: {dt:g} s is too coarse for the {up:.3g} s pen lift between"
                f" plans[{k - 1}] and plans[{k}]; use dt < {up / 2:.3g} s"
                f" or delay plans[{k}].start"
            )
    xy = np.empty((n, 2))
    v = np.zeros((n, 2))
    pen = np.zeros(n, dtype=np.int8)
    plan_index = np.full(n, -1, dtype=np.intp)
    drawn = evaluate_plans(tag.plans, [t[r] for r in rows], size)
    lift_start = 0
    for k, (plan, (p, pv)) in enumerate(zip(tag.plans, drawn, strict=True)):
        xy[lift_start : first[k]] = plan.targets[0]  # pen up, waiting where it goes down next
        xy[rows[k]], v[rows[k]] = p, pv
        down = downs[k]  # in the air before touch-down and after lift-off
        pen[down] = 1
        plan_index[down] = k
        lift_start = last[k] + 1
    speed = np.hypot(v[:, 0], v[:, 1])
    for array in (t, xy, v, speed, pen, plan_index):
        array.flags.writeable = False
    return Motion(t=t, xy=xy, v=v, speed=speed, pen=pen, plan=plan_index, dt=dt)


def owned_spans(tag: Tag) -> tuple[list[float], list[float]]:
    """When each plan of ``tag`` holds the pen, ``(starts, ends)`` on the tag's clock: from its
    start to its end, except where the next plan starts before that end (their motions overlap
    in the air, after the one's lift-off and before the other's touch-down). There the pen is
    handed over halfway between the lift-off and the touch-down: the earlier plan's tail after
    it and the later plan's approach before it are not drawn."""
    size = tag.size
    starts = [plan.start for plan in tag.plans]
    ends = [plan.end(size) for plan in tag.plans]
    for k in range(1, len(tag.plans)):
        if starts[k] < ends[k - 1]:
            lift_off = tag.plans[k - 1].ink_window(size)[1]
            touch_down = tag.plans[k].ink_window(size)[0]
            low, high = max(lift_off, starts[k]), min(touch_down, ends[k - 1])
            starts[k] = ends[k - 1] = min(max(0.5 * (lift_off + touch_down), low), high)
    return starts, ends


def _down_rows(window: tuple[float, float], t: Array, dt: float) -> slice:
    """The rows of ``t`` inside an ink window (a sample on the window's edge is down)."""
    eps = 1e-6 * dt
    return slice(
        int(np.searchsorted(t, window[0] - eps)), int(np.searchsorted(t, window[1] + eps, "right"))
    )


def _check_dt(dt: float) -> float:
    try:
        value = float(dt)
    except (TypeError, ValueError):
        raise PlanError(f"dt: must be a number of seconds, got {dt!r}") from None
    if not (np.isfinite(value) and value > 0.0):
        raise PlanError(f"dt: must be a finite number of seconds > 0, got {dt!r}")
    return value


def sample_plan(tag: Tag, k: int, step: float) -> tuple[Array, Array, Array]:
    """Times, positions and velocities of plan ``k`` of ``tag`` every ``step`` seconds of the
    tag's clock, from its start to its end (the last sample at or just past the end)."""
    return sample_plans(tag, step, [k])[0]


def sample_plans(
    tag: Tag, step: float, plans: Sequence[int] | None = None
) -> list[tuple[Array, Array, Array]]:
    """:func:`sample_plan` for each of ``plans`` (by default all), evaluated in one pass: each
    plan on its own grid, so that no pen lift is too short for ``step``."""
    t, xy, v, first = sampled_plans(tag, step, plans)
    return [(t[a:b], xy[a:b], v[a:b]) for a, b in itertools.pairwise(first)]


def sampled_plans(
    tag: Tag, step: float, plans: Sequence[int] | None = None
) -> tuple[Array, Array, Array, NDArray[np.intp]]:
    """:func:`sample_plans` joined: times, positions and velocities of all chosen plans one
    after the other, plan ``k``'s rows ``first[k]:first[k + 1]``."""
    chosen = [tag.plans[k] for k in (range(len(tag.plans)) if plans is None else plans)]
    strokes = _Strokes(chosen, tag.size)
    # Plan.end, from the windows the evaluation needs too.
    starts = np.array([plan.start for plan in chosen], dtype=float)
    t, first = kernels.plan_grids(strokes.t_off, strokes.first, starts, float(step))
    xy, v = strokes.evaluate_joined(t, first)
    return t, xy, v, first


def evaluate_plan(plan: Plan, t: ArrayLike, size: float | None = None) -> tuple[Array, Array]:
    """Position ``(N, 2)`` and velocity ``(N, 2)`` of ``plan`` at the sorted times ``t``.

    ``size`` sets the windows' tolerance (``END_TOLERANCE × size``); by default the extent of the
    plan's own targets. :func:`sample` calls this on its grid with the tag's size.
    """
    if size is None:
        size = float(np.hypot(*np.ptp(plan.targets, axis=0)))
    return evaluate_plans([plan], [t], size)[0]


def evaluate_plans(
    plans: Sequence[Plan], times: Sequence[ArrayLike], size: float
) -> list[tuple[Array, Array]]:
    """:func:`evaluate_plan` of each plan at its own sorted times, all (sample, stroke) pairs of
    all plans in one pass: a tag of many short plans costs what one plan of as many strokes
    does."""
    return _Strokes(plans, size).evaluate(times)


_NONE = np.empty(0)


class _Strokes:
    """The strokes of plans one after the other (plan ``k``'s: ``first[k]:first[k + 1]``),
    with their windows (:meth:`Plan.windows` at ``END_TOLERANCE × size``, all in one call)."""

    def __init__(self, plans: Sequence[Plan], size: float) -> None:
        self.plans = plans
        counts = [plan.n_strokes for plan in plans]
        self.first = np.cumsum([0, *counts])
        fields = [(plan.onsets, plan.mu, plan.sigma, plan.geometry.length) for plan in plans]
        joined = [np.concatenate(a) for a in zip(*fields, strict=True)] if plans else [_NONE] * 4
        self.onsets, self.mu, self.sigma, self.length = joined
        # Plan.windows's budget, stroke by stroke: the same arithmetic.
        budget = END_TOLERANCE * size / (np.repeat(counts, counts) * self.length)
        self.t_on, self.t_off = kernels.windows_array(self.onsets, self.mu, self.sigma, budget)

    def evaluate(self, times: Sequence[ArrayLike]) -> list[tuple[Array, Array]]:
        """Positions and velocities of each plan at its own sorted times."""
        ts = [np.asarray(t, dtype=float) for t in times]
        if any(t.ndim != 1 for t in ts):
            raise ValueError("t: must be a finite, sorted 1-D array of times")
        first = np.cumsum([0, *(len(t) for t in ts)])
        t_all = np.concatenate(ts) if ts else np.empty(0)
        steps = np.diff(t_all)
        joins = first[1:-1]
        steps[joins[(joins > 0) & (joins < len(t_all))] - 1] = 0.0  # each plan sorted on its own
        if np.any(steps < 0) or not np.all(np.isfinite(t_all)):
            raise ValueError("t: must be a finite, sorted 1-D array of times")
        xy, v = self.evaluate_joined(t_all, first)
        return [(xy[first[k] : first[k + 1]], v[first[k] : first[k + 1]]) for k in range(len(ts))]

    def evaluate_joined(self, t: Array, first: NDArray[np.intp]) -> tuple[Array, Array]:
        """Positions and velocities at times ``t`` (finite; plan ``k``'s sorted, rows
        ``first[k]:first[k + 1]``), one after the other."""
        xy, v = np.zeros((len(t), 2)), np.zeros((len(t), 2))
        plans = self.plans
        if plans:
            kernels.evaluate_plans_into(
                t,
                first,
                self.first,
                np.array([plan.targets[0] for plan in plans], dtype=float),
                np.concatenate([plan.chords for plan in plans]),
                self.t_on,
                self.t_off,
                self.onsets,
                self.mu,
                self.sigma,
                self.length,
                np.concatenate([plan.geometry.constants for plan in plans]),
                xy,
                v,
            )
        return xy, v


def sample_ink(
    tag: Tag, step: float, plans: Sequence[int] | None = None
) -> list[tuple[Array, Array, Array]]:
    """Times, positions and velocities of each of ``plans`` (by default all) while its pen is
    down, every ``step`` seconds from its touch-down to its lift-off, both included
    (:meth:`~tagbot.model.plan.Plan.ink_window`; a plan without an ``ink`` window: its whole
    motion). What the plan draws, for shape errors and placement."""
    chosen = range(len(tag.plans)) if plans is None else plans
    times = []
    for k in chosen:
        on, off = tag.plans[k].ink_window(tag.size)
        count = max(math.ceil((off - on) / step - 1e-9), 1)
        times.append(np.minimum(on + np.arange(count + 1) * step, off))
    drawn = evaluate_plans([tag.plans[k] for k in chosen], times, tag.size)
    return [(t, xy, v) for t, (xy, v) in zip(times, drawn, strict=True)]
