"""Placement, retiming and the joint program of a tag on the drawing arm, checked before sending.

:func:`place` finds one similarity transform (uniform scale, the profile's rotation, no mirror)
putting the tag's pen-down bounding box inside the arm's *safe workspace*: the paper
(``area`` minus its margin) ∩ the reach ring (``|l1 − l2| + m ≤ r ≤ l1 + l2 − m``, ``m`` =
``arm.reach_margin``) ∩ the poses whose joint angles, on the profile's elbow branch, are within
the joint limits. With ``place.scale = "fit"`` it is the largest such box (bisection on the scale,
the centre searched on a grid, then refined), placed at the middle of where it fits.

:func:`build_program` then draws each plan over its *drawn window* (:func:`drawn_window`): it
starts where the pen has moved less than ``motion.trim_ticks`` (default 1) ticks at the pen since
the plan's start and ends where less than that is left to draw. One tick at the pen is
:meth:`~tagbot.arm.kinematics.Arm.tip_resolution` (360°/4096 through the Jacobian, its smallest
singular value: any shorter move is under one tick on both joints); the motion is bounded by
``Σ D_j·W_j(t)`` (each lognormal's share of its curve). The lognormal onsets and tails under it
would only rest the pen on the paper. Each run ``k`` gets a time scale ``s_k ≥ 1`` so that every
joint rate ``|ȧ_i| ≤ max_speed_i`` and acceleration ``|ä_i| ≤ max_acceleration_i`` (joint rates
from ``J⁻¹·v`` on a 1 ms grid of the tag's clock, accelerations by differences, then checked on the
samples, the arm standing still before and after the run): the drawn motion is
``p(start_k + τ/s_k)``, same path, same lognormal speed shape, speeds ÷ s_k. ``s_k`` is then
raised, if need be, until the servos' predicted follow of the run strays at most
``motion.max_deviation`` from its path (:func:`_tracking`: each goal is a move over
``servo.profile_ms``, a lag that cuts curves in proportion to the joint accelerations, ∝ 1/s²),
never beyond ``motion.max_time_scale``. With ``motion.time_scale = "run"`` (the default) each
run is slowed only as much as it needs; with ``"uniform"`` every run by the largest ``s_k``
(``"uniform"`` with ``trim_ticks = 0`` and ``max_deviation = 0`` is the behaviour before runs
were trimmed and scaled one by one). Pen moves and travel are at the machine's own speed, whatever
the scales and the tag's pen-lift times. It samples everything at the loop period
``1/motion.rate``:

    park ─► travel ─► pen down ─► plan 0 ─► pen up ─► travel ─► … ─► pen up ─► travel ─► park

Travel is pen up and in joint space (a minimum-jerk move, so it stays within the joint limits
and needs no reach check), as long as its peak pen-tip speed (chord ÷ duration × 1.875)
stays within ``motion.travel_speed`` and its joints within their speed and acceleration limits.
Pen moves take ``pen.move_time`` with the arm still.

:func:`check_program` verifies the sampled program before the first packet: pen-down samples in
the safe workspace, every sample within the joint limits and 0..4095 ticks, joint speeds and
accelerations by differences between ticks (of the planned angles: the goals' ±½-tick rounding
is the servos' resolution, not motion). Anything wrong is a :class:`PlacementError` naming the
tick, its time, what it belongs to and the limit.

:func:`time_at_ends` measures what the trimming saves: the pen-down time within one tick at the
pen of a run's ends.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter
from scipy.spatial import cKDTree
from scipy.special import ndtr

from tagbot.arm.kinematics import Arm, angles_to_ticks, ticks_to_angles, unwrap_into, wrap_into
from tagbot.arm.profile import ArmProfile, Joint
from tagbot.errors import PlacementError
from tagbot.metrics import densify
from tagbot.model import Plan, Tag
from tagbot.model.easing import RunClock, run_clock
from tagbot.model.motion import evaluate_plan, sample_ink

__all__ = [
    "ArmProgram",
    "Placement",
    "PlacementError",
    "Setpoints",
    "approach",
    "build_program",
    "check_program",
    "drawn_window",
    "place",
    "safe",
    "time_at_ends",
]

Array = NDArray[np.float64]

FINE_STEP = 0.001
"""Seconds (tag clock) between the samples used for extent, joint rates and accelerations."""
TRACK_SPACING = 0.01
"""mm between the points of a run's path that the predicted follow is measured against."""
MIN_JERK_PEAK_RATE = 1.875
"""Peak rate of a minimum-jerk move, in units of (distance ÷ duration)."""
MIN_JERK_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)
"""Peak acceleration of a minimum-jerk move, in units of (distance ÷ duration²)."""
_SLACK = 1e-6
"""Relative tolerance of the speed and acceleration checks (rounding of the retimed grid)."""
_EDGE = 1e-6
"""mm of slack on the area and reach checks (floating-point rounding of placed samples)."""


@dataclass(frozen=True, eq=False)
class Placement:
    """Tag units to drawing-frame mm: ``xy_mm = matrix @ xy + offset`` (``matrix`` = size·R)."""

    matrix: Array
    offset: Array
    mm_per_unit: float
    box: tuple[float, float, float, float]
    """The placed pen-down extent ``(x_min, x_max, y_min, y_max)``, mm."""
    largest: float
    """The largest mm per unit that fits (``mm_per_unit`` itself with ``place.scale = "fit"``)."""


@dataclass(frozen=True, eq=False)
class Setpoints:
    """The planned pen-tip motion at the loop period, mm; ``pen`` True when the pen is down.

    ``plan`` is the plan index of each sample (−1 for travel and pen moves); a run's samples
    are exactly those with ``pen`` True, its first one where the pen has just come down.
    """

    t: Array
    xy: Array
    v: Array
    pen: NDArray[np.bool_]
    plan: NDArray[np.intp]
    period: float
    mm_per_unit: float
    time_scale: float
    """The largest slow-down ``s_k ≥ 1`` of a pen-down run (1: the tag's own timing); with
    ``motion.time_scale = "uniform"`` every run's."""
    limits: dict[str, float]
    """The ``s`` each limit alone asks for, over all runs: ``speed``, ``acceleration`` (1 ms
    grid), ``sampled`` when the samples at the loop period needed a hair more, and ``tracking``
    when the servos' follow needed more (``motion.max_deviation``)."""
    placement: Placement
    run_scales: tuple[float, ...] = ()
    """Each plan's slow-down ``s_k``: its drawn motion is ``p(start_k + τ/s_k)``."""
    run_windows: tuple[tuple[float, float], ...] = ()
    """Each plan's drawn window ``(start_k, end_k)`` on the tag's clock
    (:func:`drawn_window`): its first pen-down sample is the tag at ``start_k``, and machine time
    ``τ`` after it is tag time ``run_clocks[k].tag_time(τ/s_k)`` (``start_k + τ/s_k`` for a
    plan drawn from rest to rest)."""
    run_clocks: tuple[RunClock, ...] = ()
    """Each plan's run clock (:mod:`tagbot.model.easing`): easing from and to rest where the
    plan touches down or lifts off moving."""
    run_tracking: tuple[float, ...] = ()
    """Each plan's predicted path deviation (mm) of the servos' follow (the lag of their
    time-based profile, :func:`_tracking`), which ``motion.max_deviation`` bounds."""

    def __len__(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0


@dataclass(frozen=True, eq=False)
class ArmProgram:
    """What is streamed: one goal per tick for (shoulder, elbow, pen), and what it means."""

    setpoints: Setpoints
    angles: Array
    """Planned joint angles ``(N, 2)``, radians, before rounding to ticks."""
    joints: Array
    """``(N, 4)``: ``t`` (s), shoulder, elbow and pen goals (integer ticks)."""
    segments: tuple[tuple[str, int, int, int], ...] = field(default=())
    """``(kind, plan, first, stop)`` rows: kind ``travel``, ``pen``, ``draw`` or ``park``."""

    @property
    def goals(self) -> NDArray[np.int64]:
        """``(N, 3)`` integer goal positions, shoulder, elbow, pen."""
        return self.joints[:, 1:].astype(np.int64)

    def __len__(self) -> int:
        return len(self.joints)

    def describe(self, k: int) -> str:
        """What tick ``k`` belongs to: ``"plan 2"``, ``"travel at plan 0"``,
        ``"pen move at plan 1"``, ``"travel to park"``, else ``"program"``."""
        for kind, plan, first, stop in self.segments:
            if first <= k < stop:
                if kind == "draw":
                    return f"plan {plan}"
                if kind == "park":
                    return "travel to park"
                return f"{'travel' if kind == 'travel' else 'pen move'} at plan {plan}"
        return "program"


# -- the safe workspace ------------------------------------------------------------------------


def safe(xy: Array, profile: ArmProfile, arm: Arm | None = None) -> NDArray[np.bool_]:
    """Which points (mm) are in the safe workspace: paper, reach ring and joint limits."""
    arm = arm or Arm.from_profile(profile)
    xy = np.asarray(xy, dtype=float)
    x_min, x_max, y_min, y_max = profile.area
    m = profile["area.margin"] - _EDGE
    ok = (xy[..., 0] >= x_min + m) & (xy[..., 0] <= x_max - m)
    ok &= (xy[..., 1] >= y_min + m) & (xy[..., 1] <= y_max - m)
    return ok & _reachable(xy, profile, arm)


def _reachable(xy: Array, profile: ArmProfile, arm: Arm) -> NDArray[np.bool_]:
    inner, outer = arm.reach
    margin = profile["arm.reach_margin"] - _EDGE
    r = np.hypot(xy[..., 0] - arm.base_x, xy[..., 1] - arm.base_y)
    ok = (r >= inner + margin) & (r <= outer - margin)
    q = arm.ik(xy)
    shoulder, elbow = profile.joints
    _, inside = wrap_into(q[..., 0], shoulder.lower, shoulder.upper)
    with np.errstate(invalid="ignore"):
        ok &= inside & (q[..., 1] >= elbow.lower - 1e-9) & (q[..., 1] <= elbow.upper + 1e-9)
    return ok


# -- placement -------------------------------------------------------------------------------


def _box_template(per_side: int = 48, interior: int = 8) -> Array:
    """Points of the unit square centred on 0: its boundary densely, its inside on a grid."""
    u = np.linspace(-0.5, 0.5, per_side + 1)
    edges = [
        np.column_stack([u, np.full_like(u, -0.5)]),
        np.column_stack([u, np.full_like(u, 0.5)]),
        np.column_stack([np.full_like(u, -0.5), u]),
        np.column_stack([np.full_like(u, 0.5), u]),
    ]
    g = np.linspace(-0.5, 0.5, interior)
    inside = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    return np.unique(np.concatenate([*edges, inside]), axis=0)


_TEMPLATE = _box_template()


def _fitting_centres(
    size: Array, centres: Array, profile: ArmProfile, arm: Arm
) -> NDArray[np.bool_]:
    """Which candidate centres (K, 2) hold a box of ``size`` (w, h) mm in the safe workspace."""
    points = centres[:, None, :] + _TEMPLATE[None, :, :] * size
    return safe(points, profile, arm).all(axis=1)


def _centre_grid(size: Array, profile: ArmProfile, count: int) -> Array:
    """Candidate centres keeping a box of ``size`` inside the area's margins."""
    x_min, x_max, y_min, y_max = profile.area
    m = profile["area.margin"]
    low = np.array([x_min + m, y_min + m]) + size / 2
    high = np.array([x_max - m, y_max - m]) - size / 2
    if np.any(high < low - 1e-9):
        return np.zeros((0, 2))
    xs = np.linspace(low[0], max(low[0], high[0]), count)
    ys = np.linspace(low[1], max(low[1], high[1]), count)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


def _best_centre(
    size: Array, profile: ArmProfile, arm: Arm, count: int = 41, near: Array | None = None
) -> Array | None:
    """The middle of where a box of ``size`` fits: the feasible centre nearest their mean, among
    a ``count`` × ``count`` grid over the area (or, with ``near``, over a cell of it around
    ``near``, for refinement). None when none fits."""
    centres = _centre_grid(size, profile, count)
    if not len(centres):
        return None
    if near is not None:
        grid = _centre_grid(size, profile, 25)
        cell = np.ptp(grid, axis=0) / 24 if len(grid) > 1 else np.zeros(2)
        u = np.linspace(-1.0, 1.0, count)
        local = near + np.stack(np.meshgrid(u * cell[0], u * cell[1]), axis=-1).reshape(-1, 2)
        low, high = centres.min(axis=0), centres.max(axis=0)
        centres = local[np.all((local >= low - 1e-9) & (local <= high + 1e-9), axis=1)]
        if not len(centres):
            return None
    ok = _fitting_centres(size, centres, profile, arm)
    if not ok.any():
        return None
    feasible = centres[ok]
    mean = feasible.mean(axis=0)
    return feasible[np.argmin(np.hypot(*(feasible - mean).T))]


def _largest(extent: Array, profile: ArmProfile, arm: Arm) -> tuple[float, Array | None]:
    """The largest mm per tag unit at which the box fits somewhere, and a centre where it fits
    there (0 and None if none fits): bisection with centres on a 25 × 25 grid over the area,
    then refined on a finer grid around the best."""
    x_min, x_max, y_min, y_max = profile.area
    m = profile["area.margin"]
    room = np.array([x_max - x_min - 2 * m, y_max - y_min - 2 * m])
    _, outer = arm.reach
    room = np.minimum(room, 2 * outer)
    ratios = [room[i] / extent[i] for i in range(2) if extent[i] > 1e-12 * room[i]]
    if not ratios:
        raise PlacementError("place.scale: the tag has no extent to place")
    low, high = 0.0, min(ratios)
    best = _best_centre(extent * high, profile, arm, 25)
    if best is not None:
        return high, best
    floor = 1e-4 * high  # below this, nothing usable fits
    while high - low > 1e-3 * high and high > floor:
        mid = 0.5 * (low + high)
        if _best_centre(extent * mid, profile, arm, 25) is not None:
            low = mid
        else:
            high = mid
    best = _best_centre(extent * low, profile, arm, 25) if low > 0 else None
    if best is None:
        return 0.0, None
    # Near the best coarse centre, a finer grid may hold a slightly larger box.
    high = min(min(ratios), low * 1.1)
    while high - low > 1e-4 * high:
        mid = 0.5 * (low + high)
        found = _best_centre(extent * mid, profile, arm, 21, near=best)
        if found is not None:
            low, best = mid, found
        else:
            high = mid
    return low, best


def place(tag: Tag, profile: ArmProfile) -> Placement:
    """The similarity transform putting ``tag`` in the arm's safe workspace (module docstring).

    Raises PlacementError when no placement exists, or when ``place.scale`` is too large to fit
    anywhere (naming the largest that fits).
    """
    arm = Arm.from_profile(profile)
    theta = math.radians(profile["place.rotation"])
    rotation = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    samples = sample_ink(tag, FINE_STEP)
    points = np.concatenate([xy for _, xy, _ in samples])
    turned = points @ rotation.T
    # Between two samples a coordinate with |x''| <= A exceeds both by at most A·step²/8 (A
    # from the velocities' differences, doubled for their peaks): the box holds the motion at
    # any instant, whatever times the program samples it at.
    pad = max(float(np.max(np.hypot(*np.diff(v, axis=0).T), initial=0.0)) for _, _, v in samples)
    pad *= FINE_STEP / 4.0
    low, high = turned.min(axis=0) - pad, turned.max(axis=0) + pad
    extent = high - low
    largest, near = _largest(extent, profile, arm)
    if largest <= 0.0:
        raise PlacementError(
            "placement: no part of the area (area.*) is in the arm's safe reach"
            " (check arm.base_x/base_y, the link lengths and the joint limits)"
        )
    scale = profile["place.scale"]
    # "fit" keeps 0.1 % clear of the limits the box touches: the extent is sampled every 1 ms.
    size = largest * (1.0 - 1e-3) if scale == "fit" else float(scale)
    centre = _best_centre(extent * size, profile, arm, 61)
    if centre is None and near is not None and size <= largest:
        # The area's grid can miss the small region the largest sizes fit in: look around the
        # centre the refinement found (where a box of ``largest`` fits).
        centre = _best_centre(extent * size, profile, arm, 21, near=near)
    if centre is None:
        raise PlacementError(
            f"place.scale: {size:g} mm per unit makes the tag {(extent[0] - 2 * pad) * size:.1f}"
            f" x {(extent[1] - 2 * pad) * size:.1f} mm, which fits nowhere in the arm's safe"
            f" reach inside the area; the largest that fits is {largest:.4g} mm per unit"
            ' (or use "fit")'
        )
    matrix = size * rotation
    offset = centre - size * (low + high) / 2
    placed = points @ matrix.T + offset
    lo, hi = placed.min(axis=0), placed.max(axis=0)
    return Placement(matrix, offset, size, (lo[0], hi[0], lo[1], hi[1]), largest)


# -- retiming and sampling ---------------------------------------------------------------------


def _min_jerk(u: Array) -> tuple[Array, Array]:
    """Position fraction and its derivative (per unit of u) of a minimum-jerk move, u ∈ [0, 1]."""
    return u**3 * (10 - 15 * u + 6 * u**2), 30 * u**2 * (1 - u) ** 2


def _travel_time(
    q0: Array, q1: Array, arm: Arm, joints: tuple[Joint, Joint], speed: float
) -> float:
    """Duration of a minimum-jerk joint move within the travel speed and the joint limits."""
    chord = float(np.hypot(*(arm.fk(q1) - arm.fk(q0))))
    d = np.abs(q1 - q0)
    times = [MIN_JERK_PEAK_RATE * chord / speed]
    for i, joint in enumerate(joints):
        times.append(MIN_JERK_PEAK_RATE * d[i] / joint.max_speed)
        times.append(math.sqrt(MIN_JERK_PEAK_ACCELERATION * d[i] / joint.max_acceleration))
    return max(times)


class _Builder:
    """Collects samples at the loop period: angles, pen ticks, pen-tip position and velocity."""

    def __init__(self, profile: ArmProfile, arm: Arm, q: Array) -> None:
        self.profile, self.arm, self.period = profile, arm, profile.period
        self.joints = profile.joints
        self.up, self.down = profile["pen.up"], profile["pen.down"]
        self.q: list[Array] = [q[None, :]]
        self.pen: list[Array] = [np.array([float(self.up)])]
        self.xy: list[Array] = [arm.fk(q)[None, :]]
        self.v: list[Array] = [np.zeros((1, 2))]
        self.plan: list[Array] = [np.array([-1])]
        self.segments: list[tuple[str, int, int, int]] = []
        self.count = 1

    @property
    def here(self) -> Array:
        return self.q[-1][-1]

    def _add(self, kind: str, plan: int, q: Array, pen: Array, xy: Array, v: Array) -> None:
        n = len(q)
        label = plan if kind == "draw" else -1
        self.q.append(q)
        self.pen.append(pen)
        self.xy.append(xy)
        self.v.append(v)
        self.plan.append(np.full(n, label))
        self.segments.append((kind, plan, self.count, self.count + n))
        self.count += n

    def travel(self, target: Array, plan: int, kind: str = "travel") -> None:
        q0 = self.here
        speed = self.profile["motion.travel_speed"]
        duration = _travel_time(q0, target, self.arm, self.joints, speed)
        n = max(1, math.ceil(duration / self.period - 1e-9))
        u = np.arange(1, n + 1) / n
        f, df = _min_jerk(u)
        q = q0 + f[:, None] * (target - q0)
        w = df[:, None] * (target - q0) / (n * self.period)
        pen = np.full(n, float(self.pen[-1][-1]))
        self._add(kind, plan, q, pen, self.arm.fk(q), self.arm.tip_velocity(q, w))

    def pen_move(self, to: int, plan: int, *, last: bool = True) -> None:
        """The pen to ``to`` in ``pen.move_time``, the arm still; without ``last``, all but the
        final sample (the pen down there is the run's first sample, drawn next)."""
        start = float(self.pen[-1][-1])
        n = max(1, math.ceil(self.profile["pen.move_time"] / self.period - 1e-9))
        pen = (start + (to - start) * np.arange(1, n + 1) / n)[: None if last else -1]
        n = len(pen)
        q = np.repeat(self.here[None, :], n, axis=0)
        self._add("pen", plan, q, pen, self.arm.fk(q), np.zeros((n, 2)))

    def draw(self, plan: int, q: Array, xy: Array, v: Array) -> None:
        self._add("draw", plan, q, np.full(len(q), float(self.down)), xy, v)


def _run_angles(xy: Array, arm: Arm, joints: tuple[Joint, Joint]) -> Array:
    """IK of a continuous run, the shoulder unwrapped into its range (no flips, no jumps)."""
    q = arm.ik(xy)
    if np.isnan(q).any():
        return q
    q[:, 0] = unwrap_into(q[:, 0], joints[0].lower, joints[0].upper)
    return q


# -- the drawn window of each run, its time scale and the samples -------------------------------


def _motion_done(plan: Plan, t: float) -> tuple[float, float]:
    """Path drawn by time ``t`` and path still to draw after it, tag units, as upper bounds:
    ``Σ D_j·W_j(t)`` and ``Σ D_j·(1 − W_j(t))`` (stroke ``j`` of length ``D_j`` has travelled
    ``D_j·W_j`` of its curve; the pen has moved no farther than the sum)."""
    elapsed = t - plan.onsets
    w = np.zeros(len(elapsed))
    on = elapsed > 0.0
    w[on] = ndtr((np.log(elapsed[on]) - plan.mu[on]) / plan.sigma[on])
    length = plan.geometry.length
    return float(np.sum(length * w)), float(np.sum(length * (1.0 - w)))


def _bisect(f: Callable[[float], bool], low: float, high: float) -> float:
    """The boundary in ``[low, high]`` of a predicate true below it and false above it."""
    for _ in range(60):
        mid = 0.5 * (low + high)
        if f(mid):
            low = mid
        else:
            high = mid
        if high - low <= 1e-9 * max(1.0, abs(high)):
            break
    return low


def drawn_window(
    tag: Tag, k: int, placement: Placement, profile: ArmProfile, arm: Arm | None = None
) -> tuple[float, float]:
    """The part of plan ``k`` that is drawn, ``(start, end)`` on the tag's clock.

    The run starts at the last instant where the pen has moved less than ``motion.trim_ticks``
    times the machine's resolution at the pen (:meth:`Arm.tip_resolution` at the plan's first
    target) and ends at the first instant where less than that is left to draw (resolution at
    the last target): the lognormal onset and tail below it would only rest the pen on the
    paper. With ``motion.trim_ticks = 0``, the plan's whole span ``start .. end(size)``. A plan
    shorter than both margins together (a dot) is drawn whole. A plan with an ``ink`` window is
    drawn within it (the pen moves in the air outside it).
    """
    down, up = tag.plans[k].ink_window(tag.size)
    first, last = _trimmed(tag, k, placement, profile, arm)
    first = max(first, down)
    return first, max(min(last, up), first)


def _trimmed(
    tag: Tag, k: int, placement: Placement, profile: ArmProfile, arm: Arm | None
) -> tuple[float, float]:
    """:func:`drawn_window` before the ink window."""
    plan = tag.plans[k]
    start, end = plan.start, plan.end(tag.size)
    ticks = profile["motion.trim_ticks"]
    if ticks <= 0.0:
        return start, end
    arm = arm or Arm.from_profile(profile)
    ends = np.array([plan.targets[0], plan.targets[-1]]) @ placement.matrix.T + placement.offset
    q = _run_angles(ends, arm, profile.joints)
    if np.isnan(q).any():  # out of reach: _run_limits names the sample
        return start, end
    budget = ticks * arm.tip_resolution(q) / placement.mm_per_unit  # tag units
    if float(np.sum(plan.geometry.length)) <= budget.sum():
        return start, end
    first = _bisect(lambda t: _motion_done(plan, t)[0] <= budget[0], start, end)
    last = _bisect(lambda t: _motion_done(plan, t)[1] > budget[1], first, end)
    return first, max(first, last)


def _run_limits(
    tag: Tag,
    k: int,
    window: tuple[float, float],
    placement: Placement,
    profile: ArmProfile,
    arm: Arm,
) -> tuple[dict[str, float], dict[str, str], Array]:
    """The slow-down each limit asks for over the drawn window of plan ``k`` (1 ms grid of the
    tag's clock), which joint's limit that is, and the placed path on that grid (mm)."""
    plan, joints = tag.plans[k], profile.joints
    start, end = window
    t = start + np.arange(math.ceil((end - start) / FINE_STEP - 1e-9) + 1) * FINE_STEP
    xy, v = evaluate_plan(plan, t, tag.size)
    xy = xy @ placement.matrix.T + placement.offset
    v = v @ placement.matrix.T
    q = _run_angles(xy, arm, joints)
    bad = np.flatnonzero(np.isnan(q[:, 0]))
    if len(bad):
        raise PlacementError(
            f"plan {k} at t = {t[bad[0]] - plan.start:.3f} s: ({xy[bad[0], 0]:.2f},"
            f" {xy[bad[0], 1]:.2f}) mm is out of the arm's reach"
        )
    w = arm.joint_velocity(q, v)
    acc = np.diff(w, axis=0) / FINE_STEP
    limits = {"speed": 1.0, "acceleration": 1.0}
    worst = {"speed": "", "acceleration": ""}
    for i, joint in enumerate(joints):
        speed = float(np.max(np.abs(w[:, i])) / joint.max_speed)
        accel = (
            math.sqrt(float(np.max(np.abs(acc[:, i]))) / joint.max_acceleration)
            if len(acc)
            else 0.0
        )
        for name, value in (("speed", speed), ("acceleration", accel)):
            if value > limits[name]:
                limits[name] = value
                worst[name] = f"{joint.name}.max_{name} in plan {k}"
    return limits, worst, xy


def _sample_run(
    tag: Tag,
    k: int,
    clock: RunClock,
    placement: Placement,
    scale: float,
    profile: ArmProfile,
    arm: Arm,
) -> tuple[Array, Array, Array]:
    """Plan ``k``'s drawn window retimed by ``scale`` at the loop period on its run clock:
    angles, positions (mm), velocities (mm/s); the first sample is at the window's start."""
    plan, T = tag.plans[k], profile.period
    n = math.ceil(clock.duration * scale / T - 1e-9)
    u = np.arange(n + 1) * T / scale
    xy, v = evaluate_plan(plan, clock.tag_time(u), tag.size)
    xy = xy @ placement.matrix.T + placement.offset
    v = (v @ placement.matrix.T) * (clock.rate(u) / scale)[:, None]
    return _run_angles(xy, arm, profile.joints), xy, v


def _excess(q: Array, T: float, joints: tuple[Joint, Joint]) -> float:
    """How much the sampled run must slow down (> 1) to keep every joint within its limits,
    the arm standing still before and after it (the pen moves)."""
    q = np.concatenate([q[:1], q, q[-1:]])
    worst = 0.0
    for i, joint in enumerate(joints):
        worst = max(worst, float(np.max(np.abs(np.diff(q[:, i])))) / T / joint.max_speed)
        acc = float(np.max(np.abs(np.diff(q[:, i], 2)))) / T**2 / joint.max_acceleration
        worst = max(worst, math.sqrt(acc))
    return worst * (1.0 + 1e-7)


def _retime(
    tag: Tag, placement: Placement, profile: ArmProfile, arm: Arm
) -> tuple[list[RunClock], list[float], dict[str, float], list[tuple[Array, ...]], list[float]]:
    """Each run's clock (its drawn window, eased where the plan touches down or lifts off moving)
    and time scale, the scale each limit asks for (the largest over the runs) and the sampled
    runs.

    ``motion.time_scale = "run"``: each run gets the smallest ``s_k ≥ 1`` that keeps it within
    the joint limits; ``"uniform"``: every run gets the largest of those.
    """
    n = len(tag.plans)
    windows = [drawn_window(tag, k, placement, profile, arm) for k in range(n)]
    clocks = [run_clock(tag.plans[k], *windows[k], tag.size) for k in range(n)]
    limits = {"speed": 1.0, "acceleration": 1.0}
    scales, worst, paths = [], [], []
    for k in range(n):
        found, names, path = _run_limits(tag, k, windows[k], placement, profile, arm)
        paths.append(cKDTree(densify(path, TRACK_SPACING)))
        for name in limits:
            limits[name] = max(limits[name], found[name])
        key = max(found, key=lambda m: found[m])
        scales.append(found[key])
        worst.append((key, names[key]))
    top = int(np.argmax(scales))
    if scales[top] > profile["motion.max_time_scale"]:
        name, what = worst[top]
        raise PlacementError(
            f"joint {name}: the tag must be slowed down {scales[top]:.3g} times to keep within"
            f" {what}, more than motion.max_time_scale ="
            f" {profile['motion.max_time_scale']:g} (raise it, or the joint limits, or draw"
            " smaller)"
        )
    uniform = profile["motion.time_scale"] == "uniform"
    groups = [list(range(n))] if uniform else [[k] for k in range(n)]
    if uniform:
        scales = [scales[top]] * n
    T, joints = profile.period, profile.joints
    tolerance, cap = profile["motion.max_deviation"], profile["motion.max_time_scale"]
    runs: list[tuple[Array, ...]] = [()] * n
    deviations = [0.0] * n
    for group in groups:
        s = scales[group[0]]
        for _ in range(40):
            sampled = {k: _sample_run(tag, k, clocks[k], placement, s, profile, arm) for k in group}
            # The 1 ms grid may miss a peak by a hair: measure the differences the servos see.
            excess = max(_excess(sampled[k][0], T, joints) for k in group)
            if excess > 1.0:
                s *= excess * (1.0 + 1e-4)
                limits["sampled"] = max(limits.get("sampled", 1.0), s)
                continue
            found = {k: _tracking(sampled[k][0], paths[k], profile, arm) for k in group}
            worst_deviation = max(found.values())
            if tolerance <= 0.0 or worst_deviation <= tolerance or s >= cap:
                break
            # The servos' lag is in proportion to the joint accelerations: ∝ 1/s².
            s = min(cap, s * math.sqrt(worst_deviation / tolerance) * 1.02)
            limits["tracking"] = max(limits.get("tracking", 1.0), s)
        else:  # pragma: no cover - converges in a few rounds
            raise PlacementError("retiming: did not converge")
        if s > cap:
            raise PlacementError(
                f"joint limits: plan {group[0]} must be slowed down {s:.3g} times, more than"
                f" motion.max_time_scale = {cap:g}"
            )
        for k in group:
            scales[k] = s
            runs[k] = sampled[k]
            deviations[k] = found[k]
    return clocks, scales, limits, runs, deviations


def _tracking(q: Array, path: cKDTree, profile: ArmProfile, arm: Arm) -> float:
    """How far (mm) the servos' follow of the run's samples ``q`` strays from its path.

    Each goal is a move the servo completes in ``servo.profile_ms`` from where it is (the
    time-based profile with ``servo.acceleration_fraction = 0``); with a goal every period ``T``
    that is a first-order lag, ``y ← y + (T / profile)·(goal − y)``, whatever the lead the goals
    are sent with (a time shift: the same path). The arm stands still at the run's first pose
    before it and at its last after it (the pen moves); the distance is to the planned path,
    over the run and one period after it.
    """
    T, tau = profile.period, max(profile.lead, profile.period)
    alpha = T / tau
    goals = np.concatenate([q, q[-1:]])
    follow = np.empty_like(goals)
    for i in range(2):
        # follow[n]: where the servo is one period after goal n arrived.
        follow[:, i] = lfilter(
            [alpha], [1.0, alpha - 1.0], goals[:, i], zi=[(1 - alpha) * q[0, i]]
        )[0]
    distance, _ = path.query(arm.fk(follow))
    return float(np.max(distance))


def build_program(tag: Tag, profile: ArmProfile, placement: Placement | None = None) -> ArmProgram:
    """Place, trim, retime and sample ``tag`` into per-tick goals, then :func:`check_program`
    it."""
    arm = Arm.from_profile(profile)
    placement = placement or place(tag, profile)
    clocks, scales, limits, runs, deviations = _retime(tag, placement, profile, arm)
    T = profile.period
    park = np.array(profile.park)
    b = _Builder(profile, arm, park)
    for k, (q, xy, v) in enumerate(runs):
        b.travel(q[0], k)
        b.pen_move(profile["pen.down"], k, last=False)
        b.draw(k, q, xy, v)
        b.pen_move(profile["pen.up"], k)
    b.travel(park, len(tag.plans) - 1, kind="park")

    angles = np.concatenate(b.q)
    pen_ticks = np.concatenate(b.pen)
    n = len(angles)
    t = np.arange(n) * T
    shoulder, elbow = profile.joints
    goals = np.column_stack(
        [
            angles_to_ticks(angles[:, 0], shoulder),
            angles_to_ticks(angles[:, 1], elbow),
            np.rint(pen_ticks).astype(np.int64),
        ]
    )
    setpoints = Setpoints(
        t=t,
        xy=np.concatenate(b.xy),
        v=np.concatenate(b.v),
        pen=np.rint(pen_ticks) == profile["pen.down"],
        plan=np.concatenate(b.plan).astype(np.intp),
        period=T,
        mm_per_unit=placement.mm_per_unit,
        time_scale=max(scales),
        limits=limits,
        placement=placement,
        run_scales=tuple(scales),
        run_windows=tuple((c.on, c.off) for c in clocks),
        run_clocks=tuple(clocks),
        run_tracking=tuple(deviations),
    )
    program = ArmProgram(
        setpoints, angles, np.column_stack([t, goals.astype(float)]), tuple(b.segments)
    )
    check_program(program, profile)
    return program


# -- the checks before the first packet --------------------------------------------------------


def check_program(program: ArmProgram, profile: ArmProfile) -> None:
    """Refuse a program that leaves the safe workspace, the joint limits or their speeds.

    Raises PlacementError naming the first offending tick, its time, what it belongs to
    (plan, travel...) and the limit.
    """
    arm = Arm.from_profile(profile)
    sp, q, T = program.setpoints, program.angles, profile.period
    if not len(q):
        raise PlacementError("program: empty")

    def fail(k: int, message: str) -> PlacementError:
        return PlacementError(f"tick {k} (t = {k * T:.3f} s, {program.describe(k)}): {message}")

    down = np.flatnonzero(sp.pen)
    if len(down):
        xy = sp.xy[down]
        reach = _reachable(xy, profile, arm)
        paper = safe(xy, profile, arm)
        if not reach.all():
            k = int(down[np.argmin(reach)])
            r = math.hypot(sp.xy[k, 0] - arm.base_x, sp.xy[k, 1] - arm.base_y)
            inner, outer = arm.reach
            m = profile["arm.reach_margin"]
            raise fail(
                k,
                f"pen at ({sp.xy[k, 0]:.2f}, {sp.xy[k, 1]:.2f}) mm, {r:.2f} mm from the shoulder,"
                f" is outside the safe reach {inner + m:g}..{outer - m:g} mm or the joint limits",
            )
        if not paper.all():
            k = int(down[np.argmin(paper)])
            raise fail(
                k,
                f"pen at ({sp.xy[k, 0]:.2f}, {sp.xy[k, 1]:.2f}) mm is off the area"
                " (area.* minus area.margin)",
            )
    goals = program.goals
    for i, joint in enumerate(profile.joints):
        a = q[:, i]
        for bad, bound, key in (
            (a < joint.lower - 1e-9, joint.lower, "min_deg"),
            (a > joint.upper + 1e-9, joint.upper, "max_deg"),
        ):
            if bad.any():
                k = int(np.argmax(bad))
                raise fail(
                    k,
                    f"{joint.name} at {math.degrees(a[k]):.2f}° beyond {joint.name}.{key} ="
                    f" {math.degrees(bound):g}° by {abs(math.degrees(a[k] - bound)):.2f}°",
                )
        if len(a) >= 2:
            rate = np.abs(np.diff(a)) / T
            k = int(np.argmax(rate))
            if rate[k] > joint.max_speed * (1 + _SLACK):
                raise fail(
                    k + 1,
                    f"{joint.name} speed {math.degrees(rate[k]):.1f}°/s above"
                    f" {joint.name}.max_speed = {math.degrees(joint.max_speed):g}°/s",
                )
        if len(a) >= 3:
            acc = np.abs(np.diff(a, 2)) / T**2
            k = int(np.argmax(acc))
            if acc[k] > joint.max_acceleration * (1 + _SLACK):
                raise fail(
                    k + 1,
                    f"{joint.name} acceleration {math.degrees(acc[k]):.0f}°/s² above {joint.name}"
                    f".max_acceleration = {math.degrees(joint.max_acceleration):g}°/s²",
                )
    out = (goals < 0) | (goals > 4095)
    if out.any():
        k, i = (int(v) for v in np.argwhere(out)[0])
        role = ("shoulder", "elbow", "pen")[i]
        raise fail(k, f"{role} goal {goals[k, i]} ticks is outside 0..4095")


# -- the move to the first pose, from wherever the arm is --------------------------------------


def approach(
    present: NDArray[np.int64], profile: ArmProfile, to: NDArray[np.int64] | None = None
) -> tuple[NDArray[np.int64], float]:
    """The park goals (shoulder, elbow, pen ticks), or ``to`` (shoulder, elbow ticks) with the
    pen up, and how long the arm may take to get there from ``present`` (ticks), seconds: the
    servos' own time-based move (ramps a quarter of the time each way, peak rate 4/3 of the
    mean) within every joint's speed and acceleration limits, at least 0.2 s. The pen is
    lifted first, in ``pen.move_time``.
    """
    joints = profile.joints
    if to is None:
        park = np.array(profile.park)
    else:
        park = np.array([float(ticks_to_angles(to[i], joints[i])) for i in range(2)])
    duration = 0.2
    for i, joint in enumerate(joints):
        d = abs(float(park[i] - ticks_to_angles(present[i], joint)))
        duration = max(
            duration,
            4.0 * d / (3.0 * joint.max_speed),
            math.sqrt(16.0 * d / (3.0 * joint.max_acceleration)),
        )
    arm = [int(angles_to_ticks(park[i], joints[i])) for i in range(2)] if to is None else to[:2]
    return np.array([*arm, profile["pen.up"]], dtype=np.int64), duration


# -- what the program spends near the ends of its runs -----------------------------------------


def time_at_ends(
    program: ArmProgram, profile: ArmProfile, tag: Tag | None = None
) -> tuple[float, float]:
    """Pen-down time spent within one tick at the pen of a run's ends, and all pen-down time, s.

    For each pen-down run (its first sample, the pen just down, to its last), the time until
    the pen is first :meth:`Arm.tip_resolution` (at the run's first pose) away from the start
    plus the time from when it is last that far (at the last pose) from the end; crossings are
    interpolated between samples and a run that never gets that far counts whole. The start and
    end are the run's own first and last positions, or with ``tag`` the plan's first and last
    targets (where the lognormal motion itself starts and ends): the time the pen rests there.
    The share is the first figure ÷ the second.
    """
    arm = Arm.from_profile(profile)
    sp = program.setpoints
    T = sp.period
    near = total = 0.0
    for kind, k, first, stop in program.segments:
        if kind != "draw":
            continue
        xy, q = sp.xy[first:stop], program.angles[first:stop]
        duration = (len(xy) - 1) * T
        total += duration
        if len(xy) < 2:
            continue
        ends = xy[[0, -1]]
        if tag is not None:
            targets = tag.plans[k].targets[[0, -1]]
            ends = targets @ sp.placement.matrix.T + sp.placement.offset
        limit = arm.tip_resolution(q[[0, -1]])
        head = _inside_for(np.hypot(*(xy - ends[0]).T), float(limit[0]), T)
        tail = _inside_for(np.hypot(*(xy - ends[1]).T)[::-1], float(limit[1]), T)
        near += min(duration, head + tail)
    return near, total


def _inside_for(distance: Array, limit: float, T: float) -> float:
    """How long (s) samples ``T`` apart stay below ``limit`` from the first one on."""
    out = np.flatnonzero(distance >= limit)
    if not len(out):
        return (len(distance) - 1) * T
    i = int(out[0])  # distance[i - 1] < limit <= distance[i]
    if i == 0:
        return 0.0
    a, b = float(distance[i - 1]), float(distance[i])
    return (i - 1 + (limit - a) / (b - a)) * T
