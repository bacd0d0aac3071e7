"""Planar two-link kinematics, vectorised: closed-form IK on one elbow branch, FK, Jacobian, ticks.

Angles are radians: ``a1`` the shoulder (link 1 from +x), ``a2`` the elbow (link 2 relative to
link 1). The pen tip is ``base + l1·(cos a1, sin a1) + l2·(cos(a1 + a2), sin(a1 + a2))``.

IK uses the half-angle form ``a2 = ±2·atan2(√((l1 + l2)² − d²), √(d² − (l1 − l2)²))`` with both
differences factored (``(L − d)(L + d)``), which stays accurate close to the reach circles where
``acos`` of the law of cosines loses digits; the sign is the branch (profile ``arm.elbow``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from firmware_protocols.dynamixel import TICKS_PER_REV
from tagbot.arm.profile import ArmProfile, Joint

__all__ = [
    "RAD_PER_TICK",
    "Arm",
    "angles_to_ticks",
    "exact_ticks",
    "ticks_to_angles",
    "unwrap_into",
    "wrap_into",
]

Array = NDArray[np.float64]
TAU = 2.0 * math.pi
RAD_PER_TICK = TAU / TICKS_PER_REV
"""One servo tick, radians (360°/4096)."""


@dataclass(frozen=True)
class Arm:
    """The arm's geometry: link lengths (mm), shoulder position (mm) and elbow branch (±1)."""

    l1: float
    l2: float
    base_x: float = 0.0
    base_y: float = 0.0
    branch: int = 1

    def __post_init__(self) -> None:
        if not (self.l1 > 0 and self.l2 > 0):
            raise ValueError(f"l1, l2: must be > 0, got {self.l1!r}, {self.l2!r}")
        if self.branch not in (1, -1):
            raise ValueError(f"branch: must be 1 or -1, got {self.branch!r}")

    @classmethod
    def from_profile(cls, profile: ArmProfile) -> Arm:
        l1, l2 = profile.links
        bx, by = profile.base
        return cls(l1, l2, bx, by, profile.elbow_sign)

    @property
    def reach(self) -> tuple[float, float]:
        """Inner and outer reach radii ``(|l1 − l2|, l1 + l2)``, mm."""
        return abs(self.l1 - self.l2), self.l1 + self.l2

    def fk(self, angles: ArrayLike) -> Array:
        """Pen-tip positions ``(N, 2)`` of joint angles ``(N, 2)`` (or one pose ``(2,)``)."""
        q = np.asarray(angles, dtype=float)
        a1, a12 = q[..., 0], q[..., 0] + q[..., 1]
        x = self.base_x + self.l1 * np.cos(a1) + self.l2 * np.cos(a12)
        y = self.base_y + self.l1 * np.sin(a1) + self.l2 * np.sin(a12)
        return np.stack([x, y], axis=-1)

    def ik(self, xy: ArrayLike) -> Array:
        """Joint angles ``(N, 2)`` on this branch; NaN rows where ``xy`` is out of reach.

        ``a1`` is in (−π, π]; use :func:`unwrap_into` / :func:`wrap_into` for the joint's range.
        """
        p = np.asarray(xy, dtype=float)
        dx, dy = p[..., 0] - self.base_x, p[..., 1] - self.base_y
        d = np.hypot(dx, dy)
        outer, inner = self.l1 + self.l2, abs(self.l1 - self.l2)
        with np.errstate(invalid="ignore"):
            far = (outer - d) * (outer + d)
            near = (d - inner) * (d + inner)
            ok = (far >= 0) & (near >= 0)
            a2 = self.branch * 2.0 * np.arctan2(np.sqrt(far), np.sqrt(near))
            inside = np.arctan2(self.l2 * np.sin(a2), self.l1 + self.l2 * np.cos(a2))
            a1 = np.arctan2(dy, dx) - inside
        a1 = np.where(a1 <= -math.pi, a1 + TAU, np.where(a1 > math.pi, a1 - TAU, a1))
        q = np.stack([a1, a2], axis=-1)
        return np.where(ok[..., None], q, np.nan)

    def joint_velocity(self, angles: ArrayLike, v: ArrayLike) -> Array:
        """Joint rates ``(N, 2)`` rad/s moving the pen tip at ``v`` (mm/s): ``J⁻¹·v``."""
        q, v = np.asarray(angles, dtype=float), np.asarray(v, dtype=float)
        a1, a12 = q[..., 0], q[..., 0] + q[..., 1]
        c1, s1, c12, s12 = np.cos(a1), np.sin(a1), np.cos(a12), np.sin(a12)
        det = self.l1 * self.l2 * np.sin(q[..., 1])
        vx, vy = v[..., 0], v[..., 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            w1 = self.l2 * (c12 * vx + s12 * vy) / det
            w2 = -((self.l1 * c1 + self.l2 * c12) * vx + (self.l1 * s1 + self.l2 * s12) * vy) / det
        return np.stack([w1, w2], axis=-1)

    def tip_velocity(self, angles: ArrayLike, w: ArrayLike) -> Array:
        """Pen-tip velocity ``(N, 2)`` mm/s of joint rates ``w`` (rad/s): ``J·w``."""
        q, w = np.asarray(angles, dtype=float), np.asarray(w, dtype=float)
        a1, a12 = q[..., 0], q[..., 0] + q[..., 1]
        w1, w12 = w[..., 0], w[..., 0] + w[..., 1]
        vx = -self.l1 * np.sin(a1) * w1 - self.l2 * np.sin(a12) * w12
        vy = self.l1 * np.cos(a1) * w1 + self.l2 * np.cos(a12) * w12
        return np.stack([vx, vy], axis=-1)

    def tip_resolution(self, angles: ArrayLike, step: float = RAD_PER_TICK) -> Array:
        """The pen-tip distance (mm) below which every joint moves less than ``step`` (rad).

        A pen move ``d`` needs joint moves ``Δq = J⁻¹·d`` with ``|Δq| ≤ |d| / σ_min(J)``, so
        any move shorter than ``step·σ_min(J)`` is below one tick on both joints: the machine's
        resolution at the pen at that pose. ``σ_min`` depends on the elbow angle only:
        ``σ_min² = 2·det² / (S + √(S² − 4·det²))`` with ``S = l1² + 2·l2² + 2·l1·l2·cos a2``
        (the squared column norms of J) and ``det = l1·l2·sin a2``.
        """
        q = np.asarray(angles, dtype=float)
        a2 = q[..., 1]
        s = self.l1**2 + 2.0 * self.l2**2 + 2.0 * self.l1 * self.l2 * np.cos(a2)
        det2 = (self.l1 * self.l2 * np.sin(a2)) ** 2
        root = np.sqrt(np.maximum(s * s - 4.0 * det2, 0.0))
        return step * np.sqrt(2.0 * det2 / (s + root))


def wrap_into(a: ArrayLike, lower: float, upper: float) -> tuple[Array, NDArray[np.bool_]]:
    """Each angle moved by whole turns to ``lower + ((a − lower) mod 2π)``, and whether it is then
    within ``[lower, upper]`` (NaN stays NaN and is not)."""
    a = np.asarray(a, dtype=float)
    wrapped = lower + np.mod(a - lower, TAU)
    # mod can round up to exactly 2π for a hair below lower: keep that angle at lower.
    wrapped = np.where(wrapped - lower >= TAU, lower, wrapped)
    with np.errstate(invalid="ignore"):
        return wrapped, wrapped <= upper


def unwrap_into(a: ArrayLike, lower: float, upper: float) -> Array:
    """A continuous run of angles: unwrapped (no 2π jumps), then moved by whole turns as one so
    that its first angle lies in ``[lower, upper]`` (or nearest the range's middle)."""
    run = np.unwrap(np.asarray(a, dtype=float))
    if not len(run):
        return run
    first, inside = wrap_into(run[0], lower, upper)
    if not bool(inside):
        middle = 0.5 * (lower + upper)
        first = run[0] + TAU * np.round((middle - run[0]) / TAU)
    return run + (float(first) - run[0])


def exact_ticks(a: ArrayLike, joint: Joint) -> Array:
    """Joint angles in ticks, not rounded: ``zero + sign·a/(2π/4096)``."""
    return joint.zero + joint.sign * np.asarray(a, dtype=float) / RAD_PER_TICK


def angles_to_ticks(a: ArrayLike, joint: Joint) -> NDArray[np.int64]:
    """Goal positions (integer ticks) of joint angles: :func:`exact_ticks`, rounded."""
    return np.rint(exact_ticks(a, joint)).astype(np.int64)


def ticks_to_angles(ticks: ArrayLike, joint: Joint) -> Array:
    """Joint angles (radians) of positions in ticks: ``sign·(ticks − zero)·2π/4096``."""
    return joint.sign * (np.asarray(ticks, dtype=float) - joint.zero) * RAD_PER_TICK
