"""Placement and retiming: a tag's motion in machine millimetres, slowed to the machine's limits.

:func:`place` maps the tag into the bed with one similarity transform (uniform scale, optional
rotation, alignment inside the margins, y mirrored on machines whose y points down), then picks
ONE time scale ``s ≥ 1`` for the whole tag: the retimed motion is ``q(τ) = p(τ / s)``, so speeds
divide by ``s`` and accelerations by ``s²`` while the path and the lognormal shape of the speed
profile are kept. ``s`` is the smallest value meeting, along every pen-down motion:

- per-axis speed: ``|vx| / s ≤ x_max_feed / 60`` (same for y);
- per-axis acceleration: ``|ax| / s² ≤ x_acceleration`` (``a`` from differences of the analytic
  velocity at a fine step);
- Grbl's look-ahead cap on short segments, ``v ≤ √(2·a·B·L)`` with ``B`` planner blocks and ``L``
  the segment one setpoint step covers. Resampling the retimed motion at the fixed step ``dt``
  makes ``L ≈ v·dt`` shrink with ``v``, so the cap becomes ``v ≤ 2·a·B·dt``: a plain speed limit
  (150 mm/s for a = 500 mm/s², B = 15, dt = 10 ms). ``a`` is the acceleration Grbl allows along
  the segment's direction ``u``: ``min(a_x / |u_x|, a_y / |u_y|)``.

- Grbl's junction speed between consecutive setpoint moves (``$11`` junction deviation δ):
  on a curve of curvature κ sampled at ``dt`` the direction turns by ``κ·v·dt``, so Grbl caps
  ``v ≤ √(2·√(a·δ) / (κ·dt))`` roughly. Checked exactly (Grbl's formula, see
  :func:`junction_speed`) on corners turning less than 45°; sharper ones are the tag's cusps,
  where its own speed is near zero (a reversal is a full stop in Grbl whatever the timing).

After resampling, the segments between setpoints are checked against the speed limits, the cap
and the junction limit (their exact, 3-decimal lengths and directions); if one exceeds them,
``s`` grows and the tag is resampled. ``Setpoints.limits`` tells which limit set ``s``.
Positions outside the bed are refused with a :class:`PlacementError` naming the overflow,
before any program exists.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tagbot.errors import PlacementError
from tagbot.model import Tag
from tagbot.model.motion import sample_plan
from tagbot.plotter.profile import Profile

__all__ = ["PlacementError", "Run", "Setpoints", "limit_scale", "place"]

Array = NDArray[np.float64]

FINE_STEP = 0.001
"""Seconds (tag clock) between the samples used to measure speed, acceleration and extent."""
_TOLERANCE = 1e-9


@dataclass(frozen=True, eq=False)
class Run:
    """One pen-down movement as setpoints: times (s, retimed clock), positions and velocities."""

    plan: int
    t: Array
    xy: Array
    v: Array


@dataclass(frozen=True, eq=False)
class Setpoints:
    """The placed, retimed tag: one :class:`Run` per plan, in machine mm at step ``dt``."""

    runs: tuple[Run, ...]
    dt: float
    scale: float
    """The time scale ``s ≥ 1``: the machine takes ``s`` times as long as the tag's clock."""
    size: float
    """mm per tag unit."""
    matrix: Array
    """``machine = matrix @ tag + offset``."""
    offset: Array
    limits: dict[str, float]
    """The ``s`` each limit alone asks for: ``speed``, ``acceleration``, ``segment``."""

    @property
    def duration(self) -> float:
        """Pen-down drawing time on the machine, seconds (travel and pen moves excluded)."""
        return float(sum(r.t[-1] - r.t[0] for r in self.runs))


def place(tag: Tag, profile: Profile) -> Setpoints:
    """Place ``tag`` on the bed of ``profile`` and retime it; see the module docstring."""
    matrix, offset, size = _transform(tag, profile)
    fine = [sample_plan(tag, k, FINE_STEP) for k in range(len(tag.plans))]
    _check_bed(profile, [xy @ matrix.T + offset for _, xy, _ in fine])
    limits = {"speed": 1.0, "acceleration": 1.0, "segment": 1.0}
    for _, _, v in fine:
        for name, value in limit_scale(v @ matrix.T, FINE_STEP, profile).items():
            limits[name] = max(limits[name], value)
    limits["junction"] = 1.0
    scale = max(limits.values())
    dt = profile.dt
    for _ in range(100):
        runs = []
        for k in range(len(tag.plans)):
            t, xy, v = sample_plan(tag, k, dt / scale)
            runs.append(
                Run(k, (t - tag.start) * scale, xy @ matrix.T + offset, v @ matrix.T / scale)
            )
        excess = max(_segment_excess(r.xy, dt, profile) for r in runs)
        # The fine grid may miss a speed peak by a hair: check the analytic setpoint velocity.
        vmax = np.asarray(profile.max_speed)
        excess = max(excess, *(float(np.max(np.abs(r.v) / vmax, initial=0.0)) for r in runs))
        corner = max(_junction_excess(r.xy, dt, profile) for r in runs)
        if excess <= 1.0 + 1e-6 and corner <= 1.0 + 1e-6:
            break
        if excess > 1.0 + 1e-6:
            scale *= excess * (1.0 + 1e-3)
            limits["segment"] = max(limits["segment"], scale)
        else:
            # The junction ratio falls as 1/s² on gentle corners, as 1/s on sharp ones.
            scale *= math.sqrt(corner) * (1.0 + 1e-3)
            limits["junction"] = scale
    else:  # pragma: no cover - the segments converge within a few rounds
        raise PlacementError("retiming: did not converge")
    _check_bed(profile, [r.xy for r in runs])
    return Setpoints(tuple(runs), dt, scale, size, matrix, offset, limits)


def limit_scale(v: Array, step: float, profile: Profile) -> dict[str, float]:
    """The time scale each limit needs for velocities ``v`` (mm/s, one run, samples ``step`` apart).

    Returns ``{"speed": s1, "acceleration": s2, "segment": s3}``, each at least 1.
    """
    vmax = np.asarray(profile.max_speed)
    amax = np.asarray(profile.max_acceleration)
    speed_scale = float(np.max(np.abs(v) / vmax, initial=0.0))
    acc = np.diff(v, axis=0) / step
    acc_scale = math.sqrt(float(np.max(np.abs(acc) / amax, initial=0.0)))
    speed = np.hypot(v[:, 0], v[:, 1])
    cap = 2.0 * _direction_acceleration(v, amax) * profile["limits.planner_blocks"] * profile.dt
    segment_scale = float(np.max(speed / cap, initial=0.0))
    return {
        "speed": max(1.0, speed_scale),
        "acceleration": max(1.0, acc_scale),
        "segment": max(1.0, segment_scale),
    }


def segment_speed_cap(xy: Array, dt: float, profile: Profile) -> tuple[Array, Array]:
    """Each segment's speed ``L/dt`` and Grbl's look-ahead cap ``√(2·a·B·L)`` for it, mm/s."""
    d = np.diff(xy, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    a = _direction_acceleration(d, np.asarray(profile.max_acceleration))
    return length / dt, np.sqrt(2.0 * a * profile["limits.planner_blocks"] * length)


def _segment_excess(xy: Array, dt: float, profile: Profile) -> float:
    """How much faster than allowed the fastest segment is (≤ 1: none too fast)."""
    if len(xy) < 2:
        return 0.0
    speed, cap = segment_speed_cap(xy, dt, profile)
    moving = speed > 0
    worst = float(np.max(np.abs(np.diff(xy, axis=0)) / dt / np.asarray(profile.max_speed)))
    if moving.any():
        # speed ∝ 1/s and cap ∝ 1/√s: the ratio falls as 1/√s, so s must grow by ratio².
        worst = max(worst, float(np.max(speed[moving] / cap[moving])) ** 2)
    return worst


def junction_speed(xy: Array, profile: Profile) -> tuple[Array, Array, Array]:
    """Grbl 1.1's junction speed limit between consecutive moves to ``xy`` (3-decimal rounded).

    Returns ``(entry, limit, deflection)`` per junction: ``entry`` the shorter of the two
    segments (mm; divide by dt for the speed Grbl would like to keep), ``limit`` Grbl's cap
    ``√(a·δ·sin(θ/2) / (1 − sin(θ/2)))`` in mm/s (planner.c: ``junction_cos_theta``, the
    acceleration along the junction vector, ``$11`` junction deviation δ; 0 for a reversal) and
    the change of direction in radians. Zero-length moves are left out: Grbl's planner drops them.
    """
    points = np.round(np.asarray(xy, dtype=float), 3)
    d = np.diff(points, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    d, length = d[length > 0], length[length > 0]
    if len(d) < 2:
        return np.zeros(0), np.zeros(0), np.zeros(0)
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
    return np.minimum(length[:-1], length[1:]), np.sqrt(limit_sq), deflection


def _junction_excess(xy: Array, dt: float, profile: Profile) -> float:
    """How much faster than Grbl's junction limit the worst corner is entered (≤ 1: none)."""
    entry, limit, deflection = junction_speed(xy, profile)
    gentle = deflection < math.pi / 4
    if not len(entry):
        return 0.0
    # Only gentle corners (deflection < 45°): a smooth path sampled at dt, whose limit grows as
    # the motion slows. Sharper corners are cusps of the tag, where its speed is near zero anyway
    # and Grbl's full stop there cannot be retimed away (a reversal has a limit of 0).
    entry, limit = entry[gentle], limit[gentle]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(entry > 0, entry / dt / limit, 0.0)
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
    points = np.concatenate([sample_plan(tag, k, FINE_STEP)[1] for k in range(len(tag.plans))])
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
    for bad, axis, value, field, limit in checks:
        if bad:
            raise PlacementError(
                f"placement: the drawing reaches {axis} = {value:.3f} mm, beyond {field} = "
                f"{limit:g} mm by {abs(value - limit):.3f} mm (reduce place.scale or move it)"
            )
