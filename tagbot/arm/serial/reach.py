"""The paper in a serial arm's frame, and a whole job's reach checked before anything moves.

SI units (metres, radians). A :class:`Paper` is a plane placed in the arm's frame: its origin
(the paper's (0, 0)), its x and y axes, and its normal ``x × y`` pointing out of the paper
towards the pen. :func:`check_job` solves every point the pen will visit: each run's points on
the paper, the approach from the pen-up height above its first point and the retreat above its
last, and the pen-up travel between runs, and refuses the first point out with the run, the
kind of move and the point's index in the run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tagbot.arm.serial.kinematics import SerialArm
from tagbot.errors import PlacementError, ReachError

__all__ = ["JobReach", "Paper", "check_job"]

Array = NDArray[np.float64]

INK, APPROACH, RETREAT, TRAVEL = "ink", "approach", "retreat", "travel"


def _rotation_rpy(roll: float, pitch: float, yaw: float) -> Array:
    """``Rz(yaw) · Ry(pitch) · Rx(roll)``, as URDF's ``rpy``."""
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll),
        math.sin(roll),
        math.cos(pitch),
        math.sin(pitch),
        math.cos(yaw),
        math.sin(yaw),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


@dataclass(frozen=True)
class Paper:
    """A plane in the arm's frame: ``origin`` (m) is the paper's (0, 0); ``x_axis`` and
    ``y_axis`` are orthonormal; the normal ``x_axis × y_axis`` points out of the paper."""

    origin: tuple[float, float, float]
    x_axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    y_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)

    def __post_init__(self) -> None:
        u, v = np.asarray(self.x_axis, float), np.asarray(self.y_axis, float)
        o = np.asarray(self.origin, float)
        if not (o.shape == u.shape == v.shape == (3,)) or not np.all(np.isfinite([o, u, v])):
            raise PlacementError("paper: origin and axes need 3 finite numbers each")
        if (
            abs(np.linalg.norm(u) - 1) > 1e-9
            or abs(np.linalg.norm(v) - 1) > 1e-9
            or abs(u @ v) > 1e-9
        ):
            raise PlacementError(
                f"paper: axes must be orthonormal, got {self.x_axis}, {self.y_axis}"
            )

    @classmethod
    def from_pose(cls, origin: ArrayLike, rpy: ArrayLike = (0.0, 0.0, 0.0)) -> Paper:
        """The paper at ``origin`` turned by ``rpy`` (rad, URDF's roll-pitch-yaw) from a table's
        pose (x forward, y left, normal up): ``rpy = (0, 0, 0)`` is a horizontal sheet, a board
        leaning towards the arm by 60° is ``(0, -math.radians(60), 0)`` (its normal tips back)."""
        r = _rotation_rpy(*np.asarray(rpy, dtype=float))
        o = np.asarray(origin, dtype=float)
        return cls(tuple(o), tuple(r[:, 0]), tuple(r[:, 1]))

    @property
    def normal(self) -> Array:
        """Unit normal out of the paper (towards the pen)."""
        return np.cross(self.x_axis, self.y_axis)

    def to_arm(self, xy: ArrayLike, height: float = 0.0) -> Array:
        """Points ``(N, 2)`` on the paper (m) in the arm's frame, ``height`` above the paper."""
        p = np.asarray(xy, dtype=float)
        if p.ndim != 2 or p.shape[1] != 2:
            raise PlacementError(f"paper points: need (N, 2) positions, got shape {p.shape}")
        return (
            np.asarray(self.origin)
            + p[:, :1] * np.asarray(self.x_axis)
            + p[:, 1:] * np.asarray(self.y_axis)
            + height * self.normal
        )


@dataclass(frozen=True)
class JobReach:
    """A job's joint path, one row per point visited: ``q`` (rad), ``points`` (m, arm frame),
    ``run`` (the run each point belongs to; travel belongs to the run it leads to), ``kind``
    (``approach``, ``ink``, ``retreat``, ``travel``), and ``index`` (the point's index in its
    run for ink, in its move otherwise)."""

    q: Array
    points: Array
    run: NDArray[np.int64]
    kind: NDArray[np.str_]
    index: NDArray[np.int64]

    @property
    def ink(self) -> NDArray[np.bool_]:
        return self.kind == INK


def _segment(a: Array, b: Array, spacing: float) -> Array:
    """Points from ``a`` to ``b`` (both included), at most ``spacing`` apart."""
    steps = max(1, math.ceil(float(np.linalg.norm(b - a)) / spacing))
    t = np.linspace(0.0, 1.0, steps + 1)[:, None]
    return a + t * (b - a)


def check_job(
    arm: SerialArm,
    paper: Paper,
    runs: Sequence[ArrayLike],
    pen_up: float,
    max_tilt: float,
    q0: ArrayLike,
    spacing: float = 0.002,
) -> JobReach:
    """Solve every point of a job before anything moves: the runs' points ``(N_i, 2)`` on the
    paper (m), each with its approach from and retreat to ``pen_up`` (m) above the paper, and
    the pen-up travel between runs, sampled every ``spacing`` (m) so the joints stay continuous.

    Raises :class:`~tagbot.errors.ReachError` whose ``where`` names the run, the kind of move
    and the point (``run 3 ink point 41: ...``) and whose ``index`` is the point's index in
    :attr:`JobReach.q`'s rows.
    """
    if not pen_up > 0 or not spacing > 0:
        raise PlacementError(f"pen_up, spacing: must be > 0 m, got {pen_up!r}, {spacing!r}")
    if not runs:
        raise PlacementError("runs: the job has no run")
    parts: list[tuple[Array, int, str]] = []
    above_prev: Array | None = None
    for k, run in enumerate(runs):
        xy = np.asarray(run, dtype=float)
        if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) == 0 or not np.all(np.isfinite(xy)):
            raise PlacementError(f"runs[{k}]: need finite (N, 2) paper positions (m)")
        ink = paper.to_arm(xy)
        lift = pen_up * paper.normal
        if above_prev is not None:
            parts.append((_segment(above_prev, ink[0] + lift, spacing)[1:-1], k, TRAVEL))
        parts.append((_segment(ink[0] + lift, ink[0], spacing)[:-1], k, APPROACH))
        parts.append((ink, k, INK))
        parts.append((_segment(ink[-1], ink[-1] + lift, spacing)[1:], k, RETREAT))
        above_prev = ink[-1] + lift
    points = np.concatenate([p for p, _, _ in parts])
    run = np.concatenate([np.full(len(p), k) for p, k, _ in parts])
    kind = np.concatenate([np.full(len(p), name) for p, _, name in parts])
    index = np.concatenate([np.arange(len(p)) for p, _, _ in parts])
    try:
        q = arm.solve_path(points, paper.normal, max_tilt, q0)
    except ReachError as exc:
        i = exc.index
        where = f"run {run[i]} {kind[i]} point {index[i]}"
        raise ReachError(exc.detail, i, exc.reason, where) from None
    return JobReach(q, points, run, kind, index)
