"""Placement and retiming: a tag's motion in machine millimetres, slowed to the machine's limits.

:func:`place` maps the tag into the bed with one similarity transform (uniform scale, optional
rotation, alignment inside the margins, y mirrored on machines whose y points down), then, for
each pen-down run (one plan), chooses the part of the motion that is drawn, its time scale and
its setpoints. Every choice follows from what Grbl 1.1 does with the program:

**Trimmed ends** (``motion.trim``, default on). A lognormal stroke starts and ends
asymptotically: on a 12–26× retimed A3 tag up to 30 % of the pen-down time was spent within
one motor step of a run's ends, the pen resting on the paper. A run is drawn only from the
instant its motion first leaves the box of ± one motor step (``1 / limits.x_steps_per_mm``,
``1 / limits.y_steps_per_mm``) around its first point to the instant it last enters the same box
around its last point (both found to 1e-9 of the tag's clock by bisection): what is left out
moves less than one step on every axis, which the machine could not draw anyway.

**Touch-down in motion.** A plan with an ``ink`` window (a writer who touched down or lifted off
while moving) is drawn over its window only: the pen goes down at rest where the ink starts and
the run eases from rest to the plan's own speed over :data:`~tagbot.model.easing.EASE` seconds
of its clock (and back to rest where the ink ends, if it lifts off moving), along the same path,
starting at a constant acceleration as the machine's own moves do (:mod:`tagbot.model.easing`,
``jerk_limited=False``: the pen leaves its touch-down point sooner); a pen command stops
Grbl's motion, so a plotter cannot touch down moving.

**Time scale** ``s ≥ 1``: the retimed motion is ``q(τ) = p(τ / s)``, so speeds divide by ``s``
and accelerations by ``s²`` while the path and the lognormal shape of the speed profile are
kept. With ``motion.time_scale = "run"`` (default) every run has its own ``s_k``, the smallest
meeting the limits below along that run as it is drawn (trimmed, eased: not at the plan's own
speed where the pen touches down moving); with ``"uniform"`` one ``s`` (the largest ``s_k``)
serves the whole tag. Runs are independent on the machine (each starts and ends at rest, with a
pen change between), so a per-run scale changes no run's shape, only the job's length. Limits:

- per-axis speed: ``|vx| / s ≤ x_max_feed / 60`` (same for y), from the analytic velocity;
- per-axis acceleration: ``|ax| / s² ≤ x_acceleration`` (``a`` from differences of the analytic
  velocity at a fine step); both along the profile's ``axes`` (x and y on Grbl; ``x ± y``, the
  motors' axes, on an AxiDraw);
- Grbl's look-ahead: the planner must be able to stop at the end of the blocks it holds
  (``B = limits.planner_blocks``), so a block of speed ``v`` needs ``v ≤ √(2·a·ΣL)`` with ``ΣL``
  the length of it and the next ``B − 1`` blocks (fewer at the run's end) and ``a`` the
  acceleration Grbl allows along its direction ``u``: ``min(a_x / |u_x|, a_y / |u_y|)``. For
  equal steps ``dt`` this is the old ``v ≤ 2·a·B·dt``;
- Grbl's junction speed between consecutive moves (``$11`` junction deviation δ, see
  :func:`junction_speed`) on corners turning less than 45°; sharper ones are the tag's cusps,
  where its own speed is near zero (a reversal is a full stop in Grbl whatever the timing);
- host pauses (adaptive setpoints only): when the host stops sending, the machine still has the
  ``B − 1`` blocks queued behind the executing one and the :data:`RX_LINES` setpoint lines that
  surely fit Grbl's 128-byte receive buffer. ``s`` grows until any that many consecutive lines
  of a longer run (a shorter one is held whole once sent) last at least ``motion.min_buffer``
  seconds (0.6 by
  default: more than the 0.39–0.52 s pauses measured on a loaded host). Longer lines come from
  the tolerance: at a fixed tolerance a line's duration grows in proportion to ``s``. Where
  Grbl's slowest step bounds the lines instead, slowing cannot help and is not done (the job
  then warns, with the figure it holds: :func:`tagbot.plotter.program.host_pause_warnings`).

The limits are checked on the setpoints as sent (3 decimals); ``s`` grows until all hold.
``Setpoints.limits`` / ``Run.limits`` tell which limit set it (``buffer`` for the last one).

**Setpoints** (one ``G93 G1`` line each). ``motion.setpoints = "adaptive"`` (default): each line
is as long as possible, between ``motion.dt`` and ``motion.max_dt`` seconds (in steps of
``motion.dt / 4``), such that the linear interpolation in time between consecutive setpoints
stays within ``motion.tolerance`` mm of the exact retimed trajectory at every instant (checked
on a grid of ``motion.dt / 4``). That bounds the path error and the speed profile's error
(position against time) alike; where the motion is slow or changes slowly the lines are long,
so Grbl's 15 planner blocks hold more time of motion and a host pause starves it less.
Where setpoints are left out because they move no motor step (below), a line spans several of
these and the bound becomes the tolerance plus one motor step (the diagonal of the step box).
``"fixed"``: one setpoint every ``motion.dt`` (the old behaviour).

**Motor steps.** Grbl plans each target as ``lround(target · $100)`` steps and drops a block
that moves no step (``PLAN_EMPTY_BLOCK``), so a setpoint on the same step position as the
previous one is not kept (the next line takes its time). Grbl cannot move slower than its slowest
step (8 × 65535 cycles at 16 MHz: ``limits.slowest_step`` per step of the dominant axis) nor
below ``MINIMUM_FEED_RATE`` (``limits.min_feed``). With ``motion.slow_lines = "clamp"``
(default) a line that should take longer is shortened to what Grbl can execute and the run's
clock moves on without the surplus: the pen never rests (that surplus only exists where the
motion is below 0.4 mm/s at 80 steps/mm). ``"dwell"`` keeps the exact timing and leaves it to
the program to dwell for the surplus (the old behaviour; see :mod:`tagbot.plotter.program`).

Positions outside the bed are refused with a :class:`PlacementError` naming the overflow,
before any program exists.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from tagbot.errors import PlacementError
from tagbot.model import Tag
from tagbot.model.easing import RunClock, run_clock
from tagbot.model.motion import evaluate_plan, sample_ink
from tagbot.plotter.profile import Profile

__all__ = [
    "RX_LINES",
    "PlacementError",
    "Run",
    "Setpoints",
    "buffered",
    "interpolation_error",
    "junction_speed",
    "limit_scale",
    "motor_steps",
    "place",
    "segment_excess",
    "segment_speed_cap",
    "slowest_durations",
    "step_box",
]

Array = NDArray[np.float64]

FINE_STEP = 0.001
"""Seconds (tag clock) between the samples used to measure speed, acceleration and extent."""
SUBSTEPS = 4
"""Adaptive setpoints: line durations are multiples of ``motion.dt / SUBSTEPS`` (the error grid)."""
RX_LINES = 128 // 28
"""Setpoint lines (``G1X…Y…F…``, up to 28 bytes) that surely fit Grbl's 128-byte receive
buffer: what the machine holds beyond its planner when the host stops sending."""
CORNER_MARGIN = 0.9
"""Adaptive setpoints: a corner is entered at no more than this share of Grbl's junction speed
(the targets' 3-decimal rounding and motor steps turn the sent lines a little)."""
_TOLERANCE = 1e-9
_DECIMALS = 3


@dataclass(frozen=True, eq=False)
class Run:
    """One pen-down run as setpoints: the lines the machine is sent, on the run's own clock."""

    plan: int
    t: Array
    """Setpoint times, s, from the run's start (``t[0] = 0``: the run's first point)."""
    xy: Array
    """Setpoint positions, mm (``xy[0]``: where the pen goes down)."""
    v: Array
    """Analytic retimed velocity at each setpoint, mm/s."""
    scale: float = 1.0
    """This run's time scale ``s_k ≥ 1``."""
    tag_t: Array = field(default_factory=lambda: np.zeros(0))
    """The tag-clock instant of each setpoint (``xy[i] = p(tag_t[i])`` exactly)."""
    limits: dict[str, float] = field(default_factory=dict)
    """The ``s`` each limit alone asks of this run."""
    span: tuple[float, float] = (0.0, 0.0)
    """The tag-clock interval drawn (after trimming the ends within one step)."""
    clock: RunClock = field(default_factory=lambda: RunClock(0.0, 0.0))
    """How the run's clock maps to the tag's (easing from and to rest where the plan touches
    down or lifts off moving): setpoint ``i`` is at ``τ = clock.tag_time(t[i] / scale)``."""

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self.t) else 0.0


@dataclass(frozen=True, eq=False)
class Setpoints:
    """The placed, retimed tag: one :class:`Run` per plan, in machine mm."""

    runs: tuple[Run, ...]
    dt: float
    """``motion.dt``: the fixed step, or the shortest adaptive line."""
    scale: float
    """The largest time scale of the runs (with ``motion.time_scale = "uniform"``: every run's)."""
    size: float
    """mm per tag unit."""
    matrix: Array
    """``machine = matrix @ tag + offset``."""
    offset: Array
    limits: dict[str, float]
    """The ``s`` each limit alone asks for (the largest over the runs): ``speed``,
    ``acceleration``, ``segment`` (look-ahead), ``junction``."""
    mode: str = "run"
    """``motion.time_scale``: ``"run"`` or ``"uniform"``."""

    @property
    def run_scales(self) -> tuple[float, ...]:
        """Each run's time scale ``s_k``, in run order."""
        return tuple(r.scale for r in self.runs)

    @property
    def duration(self) -> float:
        """Pen-down drawing time on the machine, seconds (travel and pen moves excluded)."""
        return float(sum(r.duration for r in self.runs))


def place(tag: Tag, profile: Profile) -> Setpoints:
    """Place ``tag`` on the bed of ``profile`` and retime it; see the module docstring."""
    matrix, offset, size = _transform(tag, profile)
    fine = sample_ink(tag, FINE_STEP)
    _check_bed(profile, [xy @ matrix.T + offset for _, xy, _ in fine])
    spans = [
        _span(tag, k, t, xy @ matrix.T + offset, matrix, offset, profile)
        for k, (t, xy, _) in enumerate(fine)
    ]
    first = [_drawn_limits(tag, k, span, matrix, profile) for k, span in enumerate(spans)]
    uniform = profile["motion.time_scale"] == "uniform"
    if uniform:
        joint = {name: max(f[name] for f in first) for name in first[0]} if first else {}
        runs = _retime(tag, range(len(tag.plans)), spans, joint, matrix, offset, profile)
    else:
        runs = []
        for k in range(len(tag.plans)):
            runs += _retime(tag, [k], spans, first[k], matrix, offset, profile)
    _check_bed(profile, [r.xy for r in runs])
    names = ("speed", "acceleration", "segment", "junction", "buffer")
    limits = {n: max((r.limits.get(n, 1.0) for r in runs), default=1.0) for n in names}
    scale = max((r.scale for r in runs), default=1.0)
    mode = "uniform" if uniform else "run"
    return Setpoints(tuple(runs), profile.dt, scale, size, matrix, offset, limits, mode)


def _drawn_limits(
    tag: Tag, k: int, span: tuple[float, float], matrix: Array, profile: Profile
) -> dict[str, float]:
    """The scale each limit needs for plan ``k``'s run as it is drawn: its velocity on the run's
    own clock (trimmed to ``span``, eased from and to rest where the plan touches down or lifts
    off moving) every :data:`FINE_STEP`, not the plan's own speed where the pen touches down."""
    plan = tag.plans[k]
    on, off = span
    clock = run_clock(plan, on, off, tag.size, jerk_limited=False)
    u = np.minimum(
        np.arange(math.floor(clock.duration / FINE_STEP) + 2) * FINE_STEP, clock.duration
    )
    _, v = evaluate_plan(plan, clock.tag_time(u), tag.size)
    limits = limit_scale((v @ matrix.T) * clock.rate(u)[:, None], FINE_STEP, profile)
    limits["junction"] = 1.0
    return limits


def step_box(profile: Profile) -> Array:
    """One motor step per axis, mm: ``(1 / $100, 1 / $101)``."""
    return np.array(
        [1.0 / profile["limits.x_steps_per_mm"], 1.0 / profile["limits.y_steps_per_mm"]]
    )


def _span(
    tag: Tag, k: int, t: Array, xy: Array, matrix: Array, offset: Array, profile: Profile
) -> tuple[float, float]:
    """The tag-clock interval of plan ``k``'s ink (``t``, ``xy``: its samples) outside one step
    of its first and last points."""
    plan = tag.plans[k]
    start, end = plan.ink_window(tag.size)
    if not profile["motion.trim"] or len(t) < 2:
        return start, end
    box = step_box(profile)
    p0, p1 = xy[0], xy[-1]
    away = np.any(np.abs(xy - p0) >= box, axis=1)
    near = np.all(np.abs(xy - p1) < box, axis=1)
    if not away.any() or near.all():
        return start, start  # a dot: nothing moves a step
    i = int(np.argmax(away))  # first sample a step away from the start
    j = len(t) - 1 - int(np.argmax(~near[::-1]))  # last sample a step away from the end

    def position(instant: float) -> Array:
        p, _ = evaluate_plan(plan, np.array([instant]), tag.size)
        return p[0] @ matrix.T + offset

    def bisect(lo: float, hi: float, inside_low: bool, centre: Array) -> float:
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            inside = bool(np.all(np.abs(position(mid) - centre) < box))
            if inside == inside_low:
                lo = mid
            else:
                hi = mid
            if hi - lo < 1e-9:
                break
        return hi if inside_low else lo

    on = bisect(float(t[i - 1]), float(t[i]), True, p0) if i > 0 else float(t[0])
    off = bisect(float(t[j]), min(float(t[j + 1]), end), False, p1) if j + 1 < len(t) else end
    # An end where the pen touches down or lifts off moving has no resting tail to trim.
    touches, lifts = plan.moving_ends(tag.size)
    on, off = (start if touches else on), (end if lifts else off)
    off = min(max(off, on), end)
    return on, off


def _retime(
    tag: Tag,
    plans: range | list[int],
    spans: list[tuple[float, float]],
    limits: dict[str, float],
    matrix: Array,
    offset: Array,
    profile: Profile,
) -> list[Run]:
    """Runs of ``plans`` sharing one time scale, grown until every limit holds on them."""
    limits = dict(limits)
    scale = max(limits.values(), default=1.0)
    buffer = buffer_goal(profile)
    blocks = profile["limits.planner_blocks"] - 1 + RX_LINES
    held: tuple[float, list[Run], float] | None = None  # scale, runs, buffered before a growth
    for _ in range(100):
        runs = [_setpoints(tag, k, spans[k], scale, matrix, offset, profile) for k in plans]
        excess = max((segment_excess(r.xy, r.t, profile) for r in runs), default=0.0)
        # The fine grid may miss a speed peak by a hair: check the analytic setpoint velocity.
        vmax = np.asarray(profile.max_speed)
        excess = max(
            excess,
            *(float(np.max(np.abs(r.v @ profile.axes.T) / vmax, initial=0.0)) for r in runs),
        )
        corner = max((_junction_excess(r.xy, r.t, profile) for r in runs), default=0.0)
        if excess > 1.0 + 1e-6:
            scale *= excess * (1.0 + 1e-3)
            limits["segment"] = max(limits.get("segment", 1.0), scale)
            continue
        if corner > 1.0 + 1e-6:
            # The junction ratio falls as 1/s² on gentle corners, as 1/s on sharp ones.
            scale *= math.sqrt(corner) * (1.0 + 1e-3)
            limits["junction"] = scale
            continue
        held_s = min((buffered(r.t, blocks) for r in runs if len(r.t) > 1), default=math.inf)
        if held_s >= buffer * (1.0 - 1e-6):
            if held is not None:
                limits["buffer"] = scale
            break
        if held is not None and held_s < held[2] * (1.0 + 0.1 * (scale / held[0] - 1.0)):
            # Slowing down did not lengthen the lines (Grbl's slowest step bounds them there):
            # keep the faster timing.
            scale, runs = held[0], held[1]
            if held[0] > max(v for k, v in limits.items() if k != "buffer"):
                limits["buffer"] = held[0]
            break
        held = (scale, runs, held_s)
        # At least 1 % slower: a step finer than the adaptive lines' own jitter could not tell
        # a window bounded by Grbl's slowest step from one that grows.
        scale *= max(BUFFER_GROWTH, min(4.0, buffer / held_s) * (1.0 + 1e-3))
    else:  # pragma: no cover - the segments converge within a few rounds
        raise PlacementError("retiming: did not converge")
    return [
        Run(r.plan, r.t, r.xy, r.v, scale, r.tag_t, dict(limits), r.span, r.clock) for r in runs
    ]


BUFFER_GROWTH = 1.01
"""The least time-scale step taken towards ``motion.min_buffer``."""


def buffer_goal(profile: Profile) -> float:
    """s of motion a host pause must find queued mid-run: ``motion.min_buffer`` with adaptive
    setpoints, 0 with fixed ones (no rule)."""
    return profile["motion.min_buffer"] if profile["motion.setpoints"] == "adaptive" else 0.0


def _setpoints(
    tag: Tag,
    k: int,
    span: tuple[float, float],
    scale: float,
    matrix: Array,
    offset: Array,
    profile: Profile,
) -> Run:
    """Plan ``k`` between ``span`` at time scale ``scale``: its setpoints (module docstring)."""
    plan = tag.plans[k]
    on, off = span
    dt = profile.dt
    clock = run_clock(plan, on, off, tag.size, jerk_limited=False)  # steppers: see easing
    if off <= on:
        u = np.zeros(1)
    elif profile["motion.setpoints"] == "fixed":
        count = math.ceil(clock.duration * scale / dt - 1e-9) + 1
        u = np.minimum(np.arange(count) * (dt / scale), clock.duration)
    else:
        u = _adaptive_times(plan, tag.size, clock, scale, matrix, offset, profile)
    tag_t = clock.tag_time(u)
    p, v = evaluate_plan(plan, tag_t, tag.size)
    xy = p @ matrix.T + offset
    v = (v @ matrix.T) * (clock.rate(u) / scale)[:, None]
    keep = _moving(xy, profile)
    u, tag_t, xy, v = u[keep], tag_t[keep], xy[keep], v[keep]
    t = (u - u[0]) * scale
    if profile["motion.slow_lines"] == "clamp" and len(t) > 1:
        durations = np.minimum(np.diff(t), slowest_durations(xy, profile))
        t = np.concatenate([[0.0], np.cumsum(durations)])
    return Run(k, t, xy, v, scale, tag_t, {}, span, clock)


def _moving(xy: Array, profile: Profile) -> NDArray[np.bool_]:
    """Setpoints kept: the first, then each on another motor step than the last kept one."""
    steps = motor_steps(xy, profile)
    keep = np.zeros(len(xy), dtype=bool)
    if len(xy):
        keep[0] = True
        last = steps[0]
        for i in range(1, len(xy)):
            if steps[i, 0] != last[0] or steps[i, 1] != last[1]:
                keep[i] = True
                last = steps[i]
    return keep


def buffered(t: Array, blocks: int) -> float:
    """The least time of motion ``blocks`` consecutive lines of a run hold, s, for setpoint times
    ``t``; ``inf`` for a run of ``blocks`` lines or fewer: the machine holds all of it once sent,
    so no host pause can starve it mid-stroke."""
    d = np.diff(t)
    if len(d) <= blocks:
        return math.inf
    total = np.concatenate([[0.0], np.cumsum(d)])
    return float(np.min(total[blocks:] - total[:-blocks]))


def motor_steps(xy: Array, profile: Profile) -> NDArray[np.int64]:
    """Grbl's step position for targets ``xy`` as sent (3 decimals): ``lround(x · $100)``."""
    sent = np.round(np.asarray(xy, dtype=float), _DECIMALS)
    scaled = sent * np.array([profile["limits.x_steps_per_mm"], profile["limits.y_steps_per_mm"]])
    return (np.sign(scaled) * np.floor(np.abs(scaled) + 0.5)).astype(np.int64)


def slowest_durations(xy: Array, profile: Profile) -> Array:
    """The longest each move between consecutive ``xy`` can take in Grbl, s: its slowest step
    (``limits.slowest_step`` per step of the dominant axis) or ``limits.min_feed``."""
    steps = motor_steps(xy, profile)
    delta = np.abs(np.diff(steps, axis=0))
    per_mm = np.array([profile["limits.x_steps_per_mm"], profile["limits.y_steps_per_mm"]])
    moved = np.hypot(*(delta / per_mm).T)
    events = delta.max(axis=1)
    return np.minimum(
        60.0 * moved / profile["limits.min_feed"], events * profile["limits.slowest_step"]
    )


def interpolation_error(xy: Array, first: int, last: int) -> float:
    """The largest distance, mm, between samples ``first..last`` of a uniform time grid and the
    straight line in time from sample ``first`` to ``last``."""
    n = last - first
    if n <= 1:
        return 0.0
    frac = np.arange(n + 1)[:, None] / n
    line = xy[first] + frac * (xy[last] - xy[first])
    d = xy[first : last + 1] - line
    return float(np.sqrt(np.max(np.einsum("ij,ij->i", d, d))))


def _adaptive_times(
    plan, size: float, clock: RunClock, scale: float, matrix, offset, profile: Profile
) -> Array:
    """Setpoint instants (the run's clock ``u``): each line as long as the tolerance and max_dt
    allow."""
    dt, longest = profile.dt, profile["motion.max_dt"]
    tolerance = profile["motion.tolerance"]
    duration = clock.duration * scale
    count = max(1, math.ceil(duration / (dt / SUBSTEPS) - 1e-9))
    grid = np.linspace(0.0, clock.duration, count + 1)
    h = duration / count
    p, _ = evaluate_plan(plan, clock.tag_time(grid), size)
    xy = p @ matrix.T + offset
    shortest = max(1, math.ceil(dt / h - 1e-9))
    most = max(shortest, math.floor(longest / h + 1e-9))
    corner = _CornerCheck(profile, h)
    chosen = [0]
    i = 0
    while i < count:
        lo, hi = min(shortest, count - i), min(most, count - i)

        def fits(j: int, i: int = i) -> bool:
            return interpolation_error(xy, i, i + j) <= tolerance and corner.allows(xy, i, j)

        if fits(hi):
            j = hi
        else:
            # Largest j in [lo, hi) whose line stays within the tolerance and whose corner with
            # the previous line Grbl takes at the planned speed (lo at least).
            good, bad = lo, hi
            while bad - good > 1:
                mid = (good + bad) // 2
                if fits(mid):
                    good = mid
                else:
                    bad = mid
            j = good
        corner.take(xy, i, j)
        i += j
        chosen.append(i)
    return grid[chosen]


class _CornerCheck:
    """Adaptive setpoints: a line is only as long as lets Grbl take its corner with the previous
    line at the planned speed (:func:`junction_speed`'s limit, with :data:`CORNER_MARGIN` for the
    targets' rounding): a longer line turns more at its ends. Where even the shortest line
    (``motion.dt``) turns too much (a cusp of the tag, where its own speed is near zero), the
    shortest it is."""

    def __init__(self, profile: Profile, h: float) -> None:
        self.amax = np.asarray(profile.max_acceleration)
        self.delta = profile["limits.junction_deviation"]
        self.h = h
        self.unit: Array | None = None
        self.speed = 0.0

    def _line(self, xy: Array, i: int, j: int) -> tuple[Array | None, float]:
        d = xy[i + j] - xy[i]
        length = float(np.hypot(*d))
        return (d / length if length > 0 else None), length / (j * self.h)

    def allows(self, xy: Array, i: int, j: int) -> bool:
        unit, speed = self._line(xy, i, j)
        if self.unit is None or unit is None:
            return True
        cos_theta = -float(self.unit @ unit)
        if cos_theta < -0.999999:
            return True  # straight on
        junction = unit - self.unit
        a = float(_direction_acceleration(junction[None, :], self.amax)[0])
        sin_half = math.sqrt(max(0.0, 0.5 * (1.0 - cos_theta)))
        limit_sq = a * self.delta * sin_half / (1.0 - sin_half)
        entry = min(speed, self.speed)
        return entry * entry <= CORNER_MARGIN**2 * limit_sq

    def take(self, xy: Array, i: int, j: int) -> None:
        unit, speed = self._line(xy, i, j)
        if unit is not None:
            self.unit, self.speed = unit, speed


def limit_scale(v: Array, step: float, profile: Profile) -> dict[str, float]:
    """The time scale each limit needs for velocities ``v`` (mm/s, one run, samples ``step`` apart).

    Returns ``{"speed": s1, "acceleration": s2, "segment": s3}``, each at least 1 (``segment``
    for lines of ``motion.dt``, the shortest; the exact check is on the setpoints).
    """
    vmax = np.asarray(profile.max_speed)
    amax = np.asarray(profile.max_acceleration)
    along = v @ profile.axes.T
    speed_scale = float(np.max(np.abs(along) / vmax, initial=0.0))
    acc = np.diff(along, axis=0) / step
    acc_scale = math.sqrt(float(np.max(np.abs(acc) / amax, initial=0.0)))
    speed = np.hypot(v[:, 0], v[:, 1])
    cap = 2.0 * _direction_acceleration(v, amax) * profile["limits.planner_blocks"] * profile.dt
    segment_scale = float(np.max(speed / cap, initial=0.0))
    return {
        "speed": max(1.0, speed_scale),
        "acceleration": max(1.0, acc_scale),
        "segment": max(1.0, segment_scale),
    }


def segment_speed_cap(xy: Array, t: Array, profile: Profile) -> tuple[Array, Array]:
    """Each segment's speed ``L/d`` and Grbl's look-ahead cap ``√(2·a·ΣL)`` for it, mm/s.

    ``ΣL`` sums the segment and the next ``limits.planner_blocks − 1`` (fewer at the end);
    ``t`` the setpoint times (s), or a number: a fixed step.
    """
    d = np.diff(xy, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    durations = np.diff(t) if np.ndim(t) else np.full(len(length), float(t))
    a = _direction_acceleration(d, np.asarray(profile.max_acceleration))
    blocks = profile["limits.planner_blocks"]
    total = np.concatenate([[0.0], np.cumsum(length)])
    ahead = total[np.minimum(np.arange(len(length)) + blocks, len(length))] - total[:-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.where(durations > 0, length / durations, 0.0)
    return speed, np.sqrt(2.0 * a * ahead)


def segment_excess(xy: Array, t: Array, profile: Profile) -> float:
    """How much the time scale must grow for every segment to respect the axis speeds and the
    look-ahead cap (≤ 1: none too fast)."""
    if len(xy) < 2:
        return 0.0
    speed, cap = segment_speed_cap(xy, t, profile)
    durations = np.diff(t)
    moves = np.diff(xy, axis=0) @ profile.axes.T
    worst = float(np.max(np.abs(moves) / durations[:, None] / np.asarray(profile.max_speed)))
    moving = speed > 0
    if moving.any():
        # speed ∝ 1/s and cap ∝ 1/√s: the ratio falls as 1/√s, so s must grow by ratio².
        worst = max(worst, float(np.max(speed[moving] / cap[moving])) ** 2)
    return worst


def junction_speed(
    xy: Array, profile: Profile, t: Array | float = 1.0
) -> tuple[Array, Array, Array]:
    """Grbl 1.1's junction speed limit between consecutive moves to ``xy`` (3-decimal rounded).

    Returns ``(entry, limit, deflection)`` per junction: ``entry`` the slower of the two moves'
    speeds (mm/s, for moves lasting ``t``'s differences, or ``t`` each when a number), ``limit``
    Grbl's cap ``√(a·δ·sin(θ/2) / (1 − sin(θ/2)))`` in mm/s (planner.c: ``junction_cos_theta``,
    the acceleration along the junction vector, ``$11`` junction deviation δ; 0 for a reversal)
    and the change of direction in radians. Zero-length moves are left out: Grbl's planner drops
    them (their time goes to the next move).
    """
    points = np.round(np.asarray(xy, dtype=float), _DECIMALS)
    times = np.asarray(t, dtype=float) if np.ndim(t) else np.arange(len(points)) * float(t)
    d = np.diff(points, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    ends = np.concatenate([[0], np.flatnonzero(length > 0) + 1])
    durations = np.diff(times[ends])
    d, length = d[length > 0], length[length > 0]
    if len(d) < 2:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    speed = length / durations
    unit = d / length[:, None]
    previous, current = unit[:-1], unit[1:]
    cos_theta = -np.sum(previous * current, axis=1)
    junction = current - previous
    a = _direction_acceleration(junction, np.asarray(profile.max_acceleration))
    sin_half = np.sqrt(np.clip(0.5 * (1.0 - cos_theta), 0.0, 1.0))
    with np.errstate(divide="ignore"):
        limit_sq = a * profile["limits.junction_deviation"] * sin_half / (1.0 - sin_half)
    limit_sq = np.where(cos_theta < -0.999999, np.inf, limit_sq)
    limit_sq = np.where(cos_theta > 0.999999, 0.0, limit_sq)
    deflection = np.arccos(np.clip(-cos_theta, -1.0, 1.0))
    return np.minimum(speed[:-1], speed[1:]), np.sqrt(limit_sq), deflection


def _junction_excess(xy: Array, t: Array, profile: Profile) -> float:
    """How much faster than Grbl's junction limit the worst corner is entered (≤ 1: none)."""
    entry, limit, deflection = junction_speed(xy, profile, t)
    if not len(entry):
        return 0.0
    # Only gentle corners (deflection < 45°): a smooth path sampled finely, whose limit grows as
    # the motion slows. Sharper corners are cusps of the tag, where its speed is near zero anyway
    # and Grbl's full stop there cannot be retimed away (a reversal has a limit of 0).
    gentle = deflection < math.pi / 4
    entry, limit = entry[gentle], limit[gentle]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(entry > 0, entry / limit, 0.0)
    return float(np.max(ratio, initial=0.0))


def _direction_acceleration(d: Array, amax: Array) -> Array:
    """Grbl's acceleration along each direction ``d``: ``min_i a_i / |u_i|`` (mm/s²)."""
    norm = np.hypot(d[:, 0], d[:, 1])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        u = np.abs(d) / norm[:, None]
        per_axis = np.where(u > 0, amax / u, np.inf)
    a = np.min(per_axis, axis=1)
    return np.where(norm > 0, a, float(np.min(amax)))


def _transform(tag: Tag, profile: Profile) -> tuple[Array, Array, float]:
    """``(matrix, offset, mm per unit)`` placing the tag's pen-down extent on the bed."""
    x_min, x_max, y_min, y_max = profile.bed
    margin = profile["bed.margin"]
    theta = math.radians(profile["place.rotation"])
    rotation = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    points = np.concatenate([xy for _, xy, _ in sample_ink(tag, FINE_STEP)])
    turned = points @ rotation.T
    low, high = turned.min(axis=0), turned.max(axis=0)
    extent = high - low
    room = np.array([x_max - x_min - 2 * margin, y_max - y_min - 2 * margin])
    scale = profile["place.scale"]
    if scale == "fit":
        ratios = [room[i] / extent[i] for i in range(2) if extent[i] > _TOLERANCE * room[i]]
        if not ratios:
            raise PlacementError("place.scale: the tag has no extent to fit")
        scale = min(ratios)
    size = float(scale)
    placed = extent * size
    align = profile["place.align"]
    horizontal = "left" if align.endswith("left") else "right" if align.endswith("right") else ""
    vertical = "bottom" if align.startswith("bottom") else "top" if align.startswith("top") else ""
    corner = np.array([x_min + margin, y_min + margin])
    free = room - placed
    corner[0] += {"left": 0.0, "right": free[0]}.get(horizontal, free[0] / 2)
    corner[1] += {"bottom": 0.0, "top": free[1]}.get(vertical, free[1] / 2)
    matrix = size * rotation
    offset = corner - size * low
    if profile["bed.y_down"]:
        # The paper's "up" is the machine's -y: mirror about the bed's centre line.
        flip = np.diag([1.0, -1.0])
        matrix = flip @ matrix
        offset = flip @ offset + np.array([0.0, y_min + y_max])
    return matrix, offset, size


def _check_bed(profile: Profile, parts: list[Array]) -> None:
    """Refuse positions outside the bed, naming the axis, the overflow and the limit."""
    x_min, x_max, y_min, y_max = profile.bed
    points = np.concatenate(parts)
    low, high = points.min(axis=0), points.max(axis=0)
    slack = 1e-6
    checks = (
        (low[0] < x_min - slack, "x", low[0], "bed.x_min", x_min),
        (high[0] > x_max + slack, "x", high[0], "bed.x_max", x_max),
        (low[1] < y_min - slack, "y", low[1], "bed.y_min", y_min),
        (high[1] > y_max + slack, "y", high[1], "bed.y_max", y_max),
    )
    for bad, axis, value, key, limit in checks:
        if bad:
            raise PlacementError(
                f"placement: the drawing reaches {axis} = {value:.3f} mm, beyond {key} = "
                f"{limit:g} mm by {abs(value - limit):.3f} mm (reduce place.scale or move it)"
            )
