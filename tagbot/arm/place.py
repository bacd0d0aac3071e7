"""Placement, retiming and the joint program of a tag on the drawing arm, checked before sending.

:func:`place` finds one similarity transform (uniform scale, the profile's rotation, no mirror)
putting the tag's pen-down bounding box inside the arm's *safe workspace*: the paper
(``area`` minus its margin) ∩ the reach ring (``|l1 − l2| + m ≤ r ≤ l1 + l2 − m``, ``m`` =
``arm.reach_margin``) ∩ the poses whose joint angles, on the profile's elbow branch, are within
the joint limits. With ``place.scale = "fit"`` it is the largest such box (bisection on the scale,
the centre searched on a grid, then refined), placed at the middle of where it fits.

:func:`build_program` then picks ONE time scale ``s ≥ 1`` for the whole tag, so that every joint
rate ``|ȧ_i| ≤ max_speed_i`` and acceleration ``|ä_i| ≤ max_acceleration_i`` along every pen-down
motion (joint rates from ``J⁻¹·v`` on a 1 ms grid of the tag's clock, accelerations by
differences): the drawn motion is ``p(τ/s)``, same path, same lognormal speed shape, speeds ÷ s.
It samples everything at the loop period ``1/motion.rate``:

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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from tagbot.arm.kinematics import Arm, angles_to_ticks, ticks_to_angles, unwrap_into, wrap_into
from tagbot.arm.profile import ArmProfile, Joint
from tagbot.errors import PlacementError
from tagbot.model import Tag
from tagbot.model.motion import evaluate_plan, sample_plan

__all__ = [
    "ArmProgram",
    "Placement",
    "PlacementError",
    "Setpoints",
    "approach",
    "build_program",
    "check_program",
    "place",
    "safe",
]

Array = NDArray[np.float64]

FINE_STEP = 0.001
"""Seconds (tag clock) between the samples used for extent, joint rates and accelerations."""
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

    ``plan`` is the plan index of each sample (−1 for travel and pen moves).
    """

    t: Array
    xy: Array
    v: Array
    pen: NDArray[np.bool_]
    plan: NDArray[np.intp]
    period: float
    mm_per_unit: float
    time_scale: float
    """The uniform slow-down ``s ≥ 1`` of the pen-down motion (1: the tag's own timing)."""
    limits: dict[str, float]
    """The ``s`` each limit alone asks for: ``speed``, ``acceleration`` (1 ms grid), and
    ``sampled`` when the samples at the loop period needed a hair more."""
    placement: Placement

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
        """What tick ``k`` belongs to: ``"plan 2"``, ``"travel before plan 0"``..."""
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


def _largest(extent: Array, profile: ArmProfile, arm: Arm) -> float:
    """The largest mm per tag unit at which the box fits somewhere (0 if none): bisection with
    centres on a 25 × 25 grid over the area, then refined on a finer grid around the best."""
    x_min, x_max, y_min, y_max = profile.area
    m = profile["area.margin"]
    room = np.array([x_max - x_min - 2 * m, y_max - y_min - 2 * m])
    _, outer = arm.reach
    room = np.minimum(room, 2 * outer)
    ratios = [room[i] / extent[i] for i in range(2) if extent[i] > 1e-12 * room[i]]
    if not ratios:
        raise PlacementError("place.scale: the tag has no extent to place")
    low, high = 0.0, min(ratios)
    if _best_centre(extent * high, profile, arm, 25) is not None:
        return high
    floor = 1e-4 * high  # below this, nothing usable fits
    while high - low > 1e-3 * high and high > floor:
        mid = 0.5 * (low + high)
        if _best_centre(extent * mid, profile, arm, 25) is not None:
            low = mid
        else:
            high = mid
    best = _best_centre(extent * low, profile, arm, 25) if low > 0 else None
    if best is None:
        return 0.0
    # Near the best coarse centre, a finer grid may hold a slightly larger box.
    high = min(min(ratios), low * 1.1)
    while high - low > 1e-4 * high:
        mid = 0.5 * (low + high)
        found = _best_centre(extent * mid, profile, arm, 21, near=best)
        if found is not None:
            low, best = mid, found
        else:
            high = mid
    return low


def place(tag: Tag, profile: ArmProfile) -> Placement:
    """The similarity transform putting ``tag`` in the arm's safe workspace (module docstring).

    Raises PlacementError when no placement exists, or when ``place.scale`` is too large to fit
    anywhere (naming the largest that fits).
    """
    arm = Arm.from_profile(profile)
    theta = math.radians(profile["place.rotation"])
    rotation = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    points = np.concatenate([sample_plan(tag, k, FINE_STEP)[1] for k in range(len(tag.plans))])
    turned = points @ rotation.T
    low, high = turned.min(axis=0), turned.max(axis=0)
    extent = high - low
    largest = _largest(extent, profile, arm)
    if largest <= 0.0:
        raise PlacementError(
            "placement: no part of the area (area.*) is in the arm's safe reach"
            " (check arm.base_x/base_y, the link lengths and the joint limits)"
        )
    scale = profile["place.scale"]
    # "fit" keeps 0.1 % clear of the limits the box touches: the extent is sampled every 1 ms.
    size = largest * (1.0 - 1e-3) if scale == "fit" else float(scale)
    centre = _best_centre(extent * size, profile, arm, 61)
    if centre is None:
        raise PlacementError(
            f"place.scale: {size:g} mm per unit makes the tag {extent[0] * size:.1f} x"
            f" {extent[1] * size:.1f} mm, which fits nowhere in the arm's safe reach inside the"
            f' area; the largest that fits is {largest:.4g} mm per unit (or use "fit")'
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

    def pen_move(self, to: int, plan: int) -> None:
        start = float(self.pen[-1][-1])
        n = max(1, math.ceil(self.profile["pen.move_time"] / self.period - 1e-9))
        pen = start + (to - start) * np.arange(1, n + 1) / n
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


def _time_scale(
    tag: Tag, placement: Placement, profile: ArmProfile, arm: Arm
) -> tuple[float, dict[str, float]]:
    """The slow-down each limit asks for over every pen-down motion; refuses s > max."""
    joints = profile.joints
    limits = {"speed": 1.0, "acceleration": 1.0}
    worst: dict[str, str] = {}
    for k in range(len(tag.plans)):
        t, xy, v = sample_plan(tag, k, FINE_STEP)
        xy = xy @ placement.matrix.T + placement.offset
        v = v @ placement.matrix.T
        q = _run_angles(xy, arm, joints)
        bad = np.flatnonzero(np.isnan(q[:, 0]))
        if len(bad):
            raise PlacementError(
                f"plan {k} at t = {t[bad[0]] - tag.plans[k].start:.3f} s: ({xy[bad[0], 0]:.2f},"
                f" {xy[bad[0], 1]:.2f}) mm is out of the arm's reach"
            )
        w = arm.joint_velocity(q, v)
        acc = np.diff(w, axis=0) / FINE_STEP
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
    scale = max(limits.values())
    cap = profile["motion.max_time_scale"]
    if scale > cap:
        name = max(limits, key=lambda n: limits[n])
        raise PlacementError(
            f"joint {name}: the tag must be slowed down {scale:.3g} times to keep within"
            f" {worst[name]}, more than motion.max_time_scale = {cap:g} (raise it, or the"
            " joint limits, or draw smaller)"
        )
    return scale, limits


def _sample_run(
    tag: Tag, k: int, placement: Placement, scale: float, profile: ArmProfile, arm: Arm
) -> tuple[Array, Array, Array]:
    """Plan ``k`` retimed by ``scale`` at the loop period: angles, positions (mm), velocities."""
    plan, T = tag.plans[k], profile.period
    n = math.ceil((plan.end(tag.size) - plan.start) * scale / T - 1e-9)
    xy, v = evaluate_plan(plan, plan.start + np.arange(n + 1) * T / scale, tag.size)
    xy = xy @ placement.matrix.T + placement.offset
    v = v @ placement.matrix.T / scale
    return _run_angles(xy, arm, profile.joints), xy, v


def _excess(q: Array, T: float, joints: tuple[Joint, Joint]) -> float:
    """How much the sampled run must slow down (> 1) to keep every joint within its limits."""
    worst = 0.0
    for i, joint in enumerate(joints):
        if len(q) >= 2:
            worst = max(worst, float(np.max(np.abs(np.diff(q[:, i])))) / T / joint.max_speed)
        if len(q) >= 3:
            acc = float(np.max(np.abs(np.diff(q[:, i], 2)))) / T**2 / joint.max_acceleration
            worst = max(worst, math.sqrt(acc))
    return worst * (1.0 + 1e-7)


def build_program(tag: Tag, profile: ArmProfile, placement: Placement | None = None) -> ArmProgram:
    """Place, retime and sample ``tag`` into per-tick goals, then :func:`check_program` it."""
    arm = Arm.from_profile(profile)
    placement = placement or place(tag, profile)
    scale, limits = _time_scale(tag, placement, profile, arm)
    joints = profile.joints
    T = profile.period
    for _ in range(20):
        runs = [_sample_run(tag, k, placement, scale, profile, arm) for k in range(len(tag.plans))]
        # The 1 ms grid may miss a peak by a hair: measure the differences the servos will see.
        excess = max(_excess(q, T, joints) for q, _, _ in runs)
        if excess <= 1.0:
            break
        scale *= excess * (1.0 + 1e-4)
        limits["sampled"] = scale
    else:  # pragma: no cover - converges in a round or two
        raise PlacementError("retiming: did not converge")
    if scale > profile["motion.max_time_scale"]:
        raise PlacementError(
            f"joint limits: the tag must be slowed down {scale:.3g} times, more than"
            f" motion.max_time_scale = {profile['motion.max_time_scale']:g}"
        )
    park = np.array(profile.park)
    b = _Builder(profile, arm, park)
    for k, (q, xy, v) in enumerate(runs):
        b.travel(q[0], k)
        b.pen_move(profile["pen.down"], k)
        b.draw(k, q[1:], xy[1:], v[1:])
        b.pen_move(profile["pen.up"], k)
    b.travel(park, len(tag.plans) - 1, kind="park")

    angles = np.concatenate(b.q)
    pen_ticks = np.concatenate(b.pen)
    n = len(angles)
    t = np.arange(n) * T
    shoulder, elbow = joints
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
        time_scale=scale,
        limits=limits,
        placement=placement,
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


def approach(present: NDArray[np.int64], profile: ArmProfile) -> tuple[NDArray[np.int64], float]:
    """The park goals (shoulder, elbow, pen ticks) and how long the arm may take to get there from
    ``present`` (ticks), seconds: the servos' own time-based move (ramps a quarter of the time
    each way, peak rate 4/3 of the mean) within every joint's speed and acceleration limits,
    at least 0.2 s. The pen is lifted first, in ``pen.move_time``.
    """
    joints = profile.joints
    park = np.array(profile.park)
    duration = 0.2
    for i, joint in enumerate(joints):
        d = abs(float(park[i] - ticks_to_angles(present[i], joint)))
        duration = max(
            duration,
            4.0 * d / (3.0 * joint.max_speed),
            math.sqrt(16.0 * d / (3.0 * joint.max_acceleration)),
        )
    goals = np.array(
        [*(int(angles_to_ticks(park[i], joints[i])) for i in range(2)), profile["pen.up"]],
        dtype=np.int64,
    )
    return goals, duration
