"""Arm profiles: the keys a DYNAMIXEL drawing arm's TOML profile holds, and their checks.

:func:`load_profile` layers the packaged ``profiles/default.toml``, a packaged profile by name or a
user file by path, then overrides such as ``"arm.l1=160"`` (see :mod:`tagbot.config`); every
problem is one line naming the file and the field, e.g. ``default.toml: elbow.max_deg: must be
> elbow.min_deg``.

Joint convention: ``angle_rad = sign·(ticks − zero)·2π/4096``; the shoulder angle ``a1`` is link
1's direction from +x, the elbow angle ``a2`` link 2's direction relative to link 1, and the pen tip
is ``(bx + l1·cos a1 + l2·cos(a1 + a2), by + l1·sin a1 + l2·sin(a1 + a2))``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from firmware_protocols.dynamixel import MODELS, TICKS_PER_REV
from tagbot.config import (
    BOOL,
    FIT_OR_POSITIVE,
    INT,
    INTEGER,
    NON_NEGATIVE,
    NUMBER,
    POSITIVE,
    LayeredProfile,
    load_layered,
    packaged_names,
)
from tagbot.errors import ProfileError

__all__ = [
    "JOINTS",
    "MAX_RATE",
    "SCHEMA",
    "ArmProfile",
    "Joint",
    "ProfileError",
    "load_profile",
    "packaged_profiles",
]

MODEL_NAMES = tuple(table.model_name for table in MODELS.values())
"""Servo models a profile may name (``XL430-W250``, ``XM430-W350``)."""

MAX_RATE = 500.0
"""Highest loop rate, Hz: 2 ms per tick is about what Python and a USB adapter sustain."""

JOINTS = ("shoulder", "elbow")

_JOINT = {
    "id": INT,
    "model": MODEL_NAMES,
    "zero": INTEGER,
    "sign": INTEGER,
    "min_deg": NUMBER,
    "max_deg": NUMBER,
    "max_speed": POSITIVE,
    "max_acceleration": POSITIVE,
}

AREA_SCHEMA: dict[str, Any] = {
    "x_min": NUMBER,
    "x_max": NUMBER,
    "y_min": NUMBER,
    "y_max": NUMBER,
    "margin": NON_NEGATIVE,
}
"""Where on the paper a tag may go, mm, and the margin kept inside it: every arm's ``[area]``."""

BUS_SCHEMA: dict[str, Any] = {
    "baud": INT,
    "return_delay_us": NON_NEGATIVE,
    "readback_rate": POSITIVE,
    "max_corrupt": INTEGER,
    "max_missed": INT,
    "silence_timeout": POSITIVE,
}
"""The servo bus: every arm's ``[bus]``."""

SCHEMA: dict[str, dict[str, Any]] = {
    "arm": {
        "l1": POSITIVE,
        "l2": POSITIVE,
        "base_x": NUMBER,
        "base_y": NUMBER,
        "elbow": ("positive", "negative"),
        "reach_margin": NON_NEGATIVE,
    },
    "shoulder": dict(_JOINT),
    "elbow": dict(_JOINT),
    "pen": {
        "id": INT,
        "model": MODEL_NAMES,
        "up": INTEGER,
        "down": INTEGER,
        "move_time": POSITIVE,
    },
    "area": AREA_SCHEMA,
    "place": {"scale": FIT_OR_POSITIVE, "rotation": NUMBER},
    "motion": {
        "rate": POSITIVE,
        "travel_speed": POSITIVE,
        "max_time_scale": POSITIVE,
        "time_scale": ("run", "uniform"),
        "trim_ticks": NON_NEGATIVE,
        "max_deviation": NON_NEGATIVE,
        "park_shoulder": NUMBER,
        "park_elbow": NUMBER,
    },
    "servo": {
        "profile_ms": INT,
        "acceleration_fraction": NON_NEGATIVE,
        "write_limits": BOOL,
        "torque_off_at_end": BOOL,
        "torque_off_after_error": BOOL,
    },
    "bus": BUS_SCHEMA,
}
"""Every section and key a profile may hold, with the kind of value it takes."""

BAUDS = (57_600, 115_200, 1_000_000, 2_000_000, 3_000_000, 4_000_000)
"""Bit rates both the X-series servos and dynamixel-sdk's PortHandler accept."""


@dataclass(frozen=True)
class Joint:
    """One arm joint's servo and limits, angles in radians."""

    name: str
    id: int
    model: str
    zero: int
    sign: int
    lower: float
    upper: float
    max_speed: float
    """rad/s"""
    max_acceleration: float
    """rad/s²"""

    @property
    def model_number(self) -> int:
        return next(n for n, t in MODELS.items() if t.model_name == self.model)


class ServoLoopProfile(LayeredProfile):
    """What every arm's profile says of its servo loop: the setpoint rate, the servos' time-based
    profile and how often present positions are read back (the planar and the serial arms),
    and where on the paper a tag may go."""

    @property
    def area(self) -> tuple[float, float, float, float]:
        """Where the tag may go ``(x_min, x_max, y_min, y_max)``, mm on the paper."""
        a = self.values["area"]
        return a["x_min"], a["x_max"], a["y_min"], a["y_max"]

    @property
    def period(self) -> float:
        """Seconds between setpoints."""
        return 1.0 / self["motion.rate"]

    @property
    def profile_ms(self) -> int:
        """Profile Velocity in the time-based profile: the time each goal move takes, ms."""
        return int(self["servo.profile_ms"])

    @property
    def lead(self) -> float:
        """Seconds between sending a goal and when the servos should be there."""
        return self.profile_ms / 1000.0

    @property
    def readback_every(self) -> int:
        """Present positions are read every this many ticks."""
        return max(1, math.ceil(self["motion.rate"] / self["bus.readback_rate"] - 1e-9))


class ArmProfile(ServoLoopProfile):
    """A merged, validated arm profile: ``profile["arm.l1"]`` and named views."""

    @property
    def links(self) -> tuple[float, float]:
        """``(l1, l2)`` in mm."""
        return self["arm.l1"], self["arm.l2"]

    @property
    def base(self) -> tuple[float, float]:
        """The shoulder axis in the drawing frame, mm."""
        return self["arm.base_x"], self["arm.base_y"]

    @property
    def elbow_sign(self) -> int:
        """+1 or −1: the sign of the elbow angle on the chosen branch."""
        return 1 if self["arm.elbow"] == "positive" else -1

    def joint(self, name: str) -> Joint:
        """``"shoulder"`` or ``"elbow"``."""
        v = self.values[name]
        return Joint(
            name,
            v["id"],
            v["model"],
            v["zero"],
            v["sign"],
            math.radians(v["min_deg"]),
            math.radians(v["max_deg"]),
            math.radians(v["max_speed"]),
            math.radians(v["max_acceleration"]),
        )

    @property
    def joints(self) -> tuple[Joint, Joint]:
        return self.joint("shoulder"), self.joint("elbow")

    @property
    def servos(self) -> dict[int, str]:
        """Servo ID → model name, in bus order (shoulder, elbow, pen)."""
        return {
            self["shoulder.id"]: self["shoulder.model"],
            self["elbow.id"]: self["elbow.model"],
            self["pen.id"]: self["pen.model"],
        }

    @property
    def bus_ids(self) -> list[int]:
        """The servo IDs the driver talks to, in bus order (shoulder, elbow, pen)."""
        return [self[f"{role}.id"] for role in ("shoulder", "elbow", "pen")]

    @property
    def pen_servo(self) -> int | None:
        """The pen-lift servo's ID (a serial arm has none: it lifts the pen itself)."""
        return int(self["pen.id"])

    @property
    def names(self) -> dict[int, str]:
        """Servo ID → role (``shoulder``, ``elbow``, ``pen``)."""
        return {self[f"{role}.id"]: role for role in ("shoulder", "elbow", "pen")}

    @property
    def park(self) -> tuple[float, float]:
        """The rest pose ``(a1, a2)`` in radians."""
        return math.radians(self["motion.park_shoulder"]), math.radians(self["motion.park_elbow"])


def packaged_profiles() -> list[str]:
    """Names of the arm profiles shipped with tagbot (``default``...)."""
    return packaged_names("tagbot.arm")


def load_profile(profile: str | Path | None = None, overrides: Iterable[str] = ()) -> ArmProfile:
    """Packaged defaults, then ``profile`` (a packaged name or a TOML path), then ``overrides``.

    Raises ProfileError naming the file and the field for unreadable files, unknown keys, values
    of the wrong kind and inconsistent values (limits, IDs, branch, rates).
    """
    return load_layered(ArmProfile, "tagbot.arm", SCHEMA, profile, overrides, _check)


def check_area(p: ServoLoopProfile) -> None:
    """The drawing area's checks, any arm's profile (``area.*``)."""
    need = p.need
    x_min, x_max, y_min, y_max = p.area
    need(x_max > x_min, ("area.x_min", "area.x_max"), "must be > area.x_min")
    need(y_max > y_min, ("area.y_min", "area.y_max"), "must be > area.y_min")
    need(
        2 * p["area.margin"] < min(x_max - x_min, y_max - y_min),
        ("area.margin",),
        "leaves no room in the area",
    )


def check_servo_loop(p: ServoLoopProfile) -> None:
    """The servo loop's checks, any arm's profile (``motion.*``, ``servo.*``, ``bus.*``)."""
    need = p.need
    rate = p["motion.rate"]
    need(rate <= MAX_RATE, ("motion.rate",), f"must be <= {MAX_RATE:g} Hz, got {rate:g}")
    need(
        p.profile_ms >= 1000.0 / rate - 1e-9,
        ("motion.rate", "servo.profile_ms"),
        f"must be >= the period ({1000.0 / rate:g} ms at {rate:g} Hz), or the servos stop"
        " between goals",
    )
    need(p.profile_ms <= 32737, ("servo.profile_ms",), "must be <= 32737 ms")
    need(
        p["servo.acceleration_fraction"] <= 0.5,
        ("servo.acceleration_fraction",),
        "must be <= 0.5 (the ramps take at most half the move)",
    )
    need(p["motion.max_time_scale"] >= 1.0, ("motion.max_time_scale",), "must be >= 1")
    need(
        p["bus.baud"] in BAUDS,
        ("bus.baud",),
        f"must be one of {', '.join(str(b) for b in BAUDS)}, got {p['bus.baud']}",
    )
    delay = p["bus.return_delay_us"]
    need(
        delay <= 508 and float(delay).is_integer() and int(delay) % 2 == 0,
        ("bus.return_delay_us",),
        f"must be an even number of µs 0..508, got {delay:g}",
    )
    need(
        p["bus.readback_rate"] <= rate,
        ("motion.rate", "bus.readback_rate"),
        "must be <= motion.rate",
    )
    need(p["bus.max_corrupt"] >= 0, ("bus.max_corrupt",), "must be >= 0")


def _check(p: ArmProfile) -> None:
    """Checks across fields; the error names the source that last set one of them."""
    need = p.need
    ids = [p[f"{role}.id"] for role in ("shoulder", "elbow", "pen")]
    for role, id in zip(("shoulder", "elbow", "pen"), ids, strict=True):
        need(id <= 252, (f"{role}.id",), f"must be a DYNAMIXEL ID 0..252, got {id}")
    need(len(set(ids)) == 3, ("shoulder.id", "elbow.id", "pen.id"), "IDs must differ")
    for name in JOINTS:
        sign, low, high = p[f"{name}.sign"], p[f"{name}.min_deg"], p[f"{name}.max_deg"]
        need(sign in (1, -1), (f"{name}.sign",), f"must be 1 or -1, got {sign}")
        need(high > low, (f"{name}.min_deg", f"{name}.max_deg"), f"must be > {name}.min_deg")
        for key, deg in (("min_deg", low), ("max_deg", high)):
            ticks = p[f"{name}.zero"] + sign * deg * TICKS_PER_REV / 360.0
            need(
                0 <= ticks <= TICKS_PER_REV - 1,
                (f"{name}.zero", f"{name}.{key}"),
                f"{deg:g}° is {ticks:.0f} ticks, outside the servo's 0..4095 in position mode",
            )
    need(
        p["shoulder.max_deg"] - p["shoulder.min_deg"] <= 360.0,
        ("shoulder.min_deg", "shoulder.max_deg"),
        "the shoulder range must not exceed 360°",
    )
    branch, low, high = p.elbow_sign, p["elbow.min_deg"], p["elbow.max_deg"]
    ok = (low >= 0.0 and high <= 180.0) if branch > 0 else (low >= -180.0 and high <= 0.0)
    need(
        ok,
        ("arm.elbow", "elbow.min_deg", "elbow.max_deg"),
        f"the elbow range {low:g}..{high:g}° must lie within "
        + ("0..180° on the positive branch" if branch > 0 else "-180..0° on the negative branch"),
    )
    for pose, name in (("park_shoulder", "shoulder"), ("park_elbow", "elbow")):
        need(
            p[f"{name}.min_deg"] <= p[f"motion.{pose}"] <= p[f"{name}.max_deg"],
            (f"{name}.min_deg", f"{name}.max_deg", f"motion.{pose}"),
            f"outside {name}.min_deg..{name}.max_deg",
        )
    for key in ("up", "down"):
        need(0 <= p[f"pen.{key}"] <= 4095, (f"pen.{key}",), "must be 0..4095 ticks")
    need(p["pen.up"] != p["pen.down"], ("pen.down", "pen.up"), "must differ from pen.down")
    check_area(p)
    l1, l2 = p.links
    need(
        2 * p["arm.reach_margin"] < 2 * min(l1, l2),
        ("arm.reach_margin",),
        "leaves no reachable ring",
    )
    check_servo_loop(p)
