"""Serial-arm profiles: the keys of a DYNAMIXEL serial arm's TOML profile, and their checks.

:func:`load_serial_profile` layers the packaged ``profiles/default.toml`` (the OpenManipulator-X),
a packaged profile by name (``openmanipulator-x``, ``koch-v1.1``) or a user file by path, then
overrides such as ``"paper.pitch=-60"`` (see :mod:`tagbot.config`); every problem is one line
naming the file and the field. The robot description is loaded with the profile.

**Joints.** A profile has one section per joint of its robot description, named as there, in
the description's order (base first): the OpenManipulator-X's ``[joint1]`` … ``[joint4]``, the
Koch v1.1's ``[shoulder_pan]`` … ``[wrist_roll]``; any number of joints. The joints come with the
description: a layer that names another ``robot.description`` drops the joint sections of the
layers before it (a Koch profile on top of the OpenManipulator-X defaults has no ``joint1``). A
joint section the description lacks, a joint without a section, a park pose outside a joint's
range or a tick range beyond the servo's is refused here.

Joint convention: ``angle_rad = sign·(ticks − zero)·2π/4096``, the angle the description's
joint of the same name takes. Lengths are mm in the profile, m in the description.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from firmware_protocols.dynamixel import TICKS_PER_REV
from tagbot.arm.profile import (
    AREA_SCHEMA,
    BUS_SCHEMA,
    MODEL_NAMES,
    Joint,
    ServoLoopProfile,
    check_area,
    check_servo_loop,
)
from tagbot.arm.serial import MODELS
from tagbot.arm.serial.kinematics import SerialArm
from tagbot.arm.serial.reach import Paper
from tagbot.config import (
    BOOL,
    FIT_OR_POSITIVE,
    INT,
    INTEGER,
    NON_NEGATIVE,
    NUMBER,
    POSITIVE,
    TEXT,
    Layers,
    Schema,
    convert,
    load_layered,
    packaged_names,
)
from tagbot.errors import ProfileError

__all__ = [
    "JOINT_KEYS",
    "SCHEMA",
    "SerialProfile",
    "is_serial_profile",
    "load_serial_profile",
    "schema_for",
    "serial_profiles",
]

PACKAGE = "tagbot.arm.serial"

JOINT_KEYS: dict[str, Any] = {
    "id": INT,
    "model": MODEL_NAMES,
    "zero": INTEGER,
    "sign": INTEGER,
    "max_speed": POSITIVE,
    "max_acceleration": POSITIVE,
    "park_deg": NUMBER,
    "stall_torque": POSITIVE,
    "no_load_speed": POSITIVE,
}
"""The keys of each joint's section (one per joint of the robot description)."""

SCHEMA: dict[str, dict[str, Any]] = {
    "robot": {
        "description": TEXT,
        "tool_offset": POSITIVE,
        "max_tilt_deg": NON_NEGATIVE,
        "pen_up": POSITIVE,
        "press": NON_NEGATIVE,
        "pen_force": NON_NEGATIVE,
        "pen_preload": NON_NEGATIVE,
        "pen_friction": NON_NEGATIVE,
    },
    "paper": {
        "x": NUMBER,
        "y": NUMBER,
        "z": NUMBER,
        "roll": NUMBER,
        "pitch": NUMBER,
        "yaw": NUMBER,
        "width": POSITIVE,
        "height": POSITIVE,
    },
    "area": AREA_SCHEMA,
    "place": {"scale": FIT_OR_POSITIVE, "rotation": NUMBER},
    "motion": {
        "rate": POSITIVE,
        "travel_speed": POSITIVE,
        "approach_speed": POSITIVE,
        "max_time_scale": POSITIVE,
        "trim_mm": NON_NEGATIVE,
    },
    "servo": {
        "profile_ms": INT,
        "acceleration_fraction": NON_NEGATIVE,
        "position_p_gain": INTEGER,
        "position_i_gain": INTEGER,
        "position_d_gain": INTEGER,
        "feedforward": BOOL,
        "write_limits": BOOL,
        "torque_off_at_end": BOOL,
        "torque_off_after_error": BOOL,
    },
    "bus": BUS_SCHEMA,
}
"""Every section and key a serial profile holds besides its joints' (:data:`JOINT_KEYS`), with
the kind of value it takes."""


def _description_path(name: str) -> Path:
    """A shipped robot description by name, or a path."""
    shipped = MODELS / name
    return shipped if shipped.is_file() else Path(name)


def schema_for(layers: Layers) -> tuple[Schema, Layers]:
    """The schema of a serial profile made of ``layers``: :data:`SCHEMA` and a section per joint
    of the robot description the last layer naming one names; the layers without the joint
    sections of those before that one (their joints were another description's)."""
    owner = max(i for i, (_, data) in enumerate(layers) if "description" in data.get("robot", {}))
    source, data = layers[owner]
    name = convert(source, "robot.description", TEXT, data["robot"]["description"])
    try:
        joints = SerialArm.load(_description_path(name)).joint_names
    except ProfileError as e:
        raise ProfileError(f"{source}: robot.description: {e}") from None
    kept: Layers = []
    for i, (src, table) in enumerate(layers):
        kept.append((src, {k: v for k, v in table.items() if k in SCHEMA or i >= owner}))
        for section in kept[-1][1]:
            if section not in SCHEMA and section not in joints:
                raise ProfileError(
                    f"{src}: {section}: unknown section (the joints of {Path(name).name}:"
                    f" {', '.join(joints)})"
                )
    sections = {"robot": SCHEMA["robot"], **{j: JOINT_KEYS for j in joints}, **SCHEMA}
    return sections, kept


class SerialProfile(ServoLoopProfile):
    """A merged, validated serial-arm profile: ``profile["paper.pitch"]`` and named views.

    It offers the views the servo driver (:class:`tagbot.arm.driver.ArmDriver`) reads from any
    arm: :attr:`bus_ids`, :attr:`names`, :attr:`joints`, :attr:`period`, :attr:`lead`..."""

    pen_servo: int | None = None
    """No pen servo: the arm lifts the pen itself."""

    @cached_property
    def arm(self) -> SerialArm:
        """The robot description with the pen's point at ``robot.tool_offset``."""
        return SerialArm.load(self.description, self["robot.tool_offset"] / 1000.0)

    @property
    def description(self) -> Path:
        """The robot description's file: a shipped model by name, or a path."""
        return _description_path(self["robot.description"])

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The joints the profile drives: its description's, base first."""
        return tuple(self.arm.joint_names)

    def joint(self, name: str) -> Joint:
        """A joint's servo and limits, radians: the description's range within the servo's
        0..4095 ticks of position mode."""
        v = self.values[name]
        arm = self.arm
        j = arm.joint_names.index(name)
        ends = sorted(v["sign"] * (t - v["zero"]) * 2 * math.pi / TICKS_PER_REV for t in (0, 4095))
        return Joint(
            name,
            v["id"],
            v["model"],
            v["zero"],
            v["sign"],
            max(float(arm.lower[j]), ends[0]),
            min(float(arm.upper[j]), ends[1]),
            math.radians(v["max_speed"]),
            math.radians(v["max_acceleration"]),
        )

    @property
    def joints(self) -> tuple[Joint, ...]:
        return tuple(self.joint(name) for name in self.joint_names)

    @property
    def bus_ids(self) -> list[int]:
        """The servo IDs the driver talks to, in joint order."""
        return [self[f"{name}.id"] for name in self.joint_names]

    @property
    def arm_ids(self) -> list[int]:
        """The servos that hold the arm up (all of them)."""
        return self.bus_ids

    @property
    def servos(self) -> dict[int, str]:
        """Servo ID → model name, in bus order."""
        return {self[f"{name}.id"]: self[f"{name}.model"] for name in self.joint_names}

    @property
    def names(self) -> dict[int, str]:
        """Servo ID → joint name."""
        return {self[f"{name}.id"]: name for name in self.joint_names}

    @property
    def paper(self) -> Paper:
        """The sheet's pose in the arm's frame (m)."""
        p = self.values["paper"]
        rpy = [math.radians(p[k]) for k in ("roll", "pitch", "yaw")]
        return Paper.from_pose(np.array([p["x"], p["y"], p["z"]]) / 1000.0, rpy)

    @property
    def park(self) -> np.ndarray:
        """The rest pose, radians per joint."""
        return np.radians([self[f"{name}.park_deg"] for name in self.joint_names])

    @property
    def max_tilt(self) -> float:
        return math.radians(self["robot.max_tilt_deg"])

    @property
    def gains(self) -> tuple[int, int, int]:
        """Position P, I, D gains written to every joint."""
        return (
            int(self["servo.position_p_gain"]),
            int(self["servo.position_i_gain"]),
            int(self["servo.position_d_gain"]),
        )

    def _per_joint(self, key: str) -> np.ndarray:
        return np.array([self[f"{name}.{key}"] for name in self.joint_names], dtype=float)

    @property
    def stiffness(self) -> np.ndarray:
        """N·m/rad of each joint's position loop P term: ``P/128`` PWM units per tick, each
        ``stall_torque/885`` N·m (the joint's servo at its supply)."""
        per_pwm = self._per_joint("stall_torque") / 885.0
        return per_pwm * self["servo.position_p_gain"] / 128.0 * TICKS_PER_REV / (2 * math.pi)

    @property
    def back_emf(self) -> np.ndarray:
        """N·m·s/rad each joint's motor loses per rad/s of speed (stall torque ÷ no-load
        speed)."""
        speed = self._per_joint("no_load_speed") * 2 * math.pi / 60
        return self._per_joint("stall_torque") / speed


def serial_profiles() -> list[str]:
    """Names of the serial-arm profiles shipped with tagbot (``default``, ``koch-v1.1``,
    ``openmanipulator-x``)."""
    return packaged_names(PACKAGE)


def is_serial_profile(profile: str | Path | None) -> bool:
    """Whether ``profile`` names a shipped serial profile or a TOML file with a ``[robot]``
    section (a planar arm's profile has none)."""
    if profile is None:
        return False
    text = str(profile)
    if text in serial_profiles() and text != "default" and not Path(text).exists():
        return True
    path = Path(text)
    if path.suffix != ".toml" or not path.is_file():
        return False
    try:
        head = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return False
    return any(line.strip() == "[robot]" for line in head.splitlines())


def load_serial_profile(
    profile: str | Path | None = None, overrides: Iterable[str] = ()
) -> SerialProfile:
    """Packaged defaults (the OpenManipulator-X), then ``profile`` (a packaged name or a TOML
    path), then ``overrides``; the robot description loaded. Raises ProfileError naming the
    file and the field."""
    return load_layered(SerialProfile, PACKAGE, schema_for, profile, overrides, _check)


def _check(p: SerialProfile) -> None:
    """Checks across fields; the error names the source that last set one of them."""
    need = p.need
    try:
        names = p.joint_names  # the description with the pen's point
    except ProfileError as e:
        raise ProfileError(f"{p.where('robot.description')}: robot.description: {e}") from None
    ids = p.bus_ids
    for name, id in zip(names, ids, strict=True):
        need(id <= 252, (f"{name}.id",), f"must be a DYNAMIXEL ID 0..252, got {id}")
    need(len(set(ids)) == len(ids), tuple(f"{n}.id" for n in names), "IDs must differ")
    for joint in p.joints:
        name = joint.name
        need(joint.sign in (1, -1), (f"{name}.sign",), f"must be 1 or -1, got {joint.sign}")
        need(
            joint.upper > joint.lower,
            (f"{name}.zero",),
            "the joint's range and the servo's 0..4095 ticks do not overlap",
        )
        park = math.radians(p[f"{name}.park_deg"])
        need(
            joint.lower <= park <= joint.upper,
            (f"{name}.park_deg",),
            f"{p[f'{name}.park_deg']:g}° is outside the joint's range"
            f" {math.degrees(joint.lower):.1f}..{math.degrees(joint.upper):.1f}°",
        )
    need(
        p["robot.max_tilt_deg"] < 90.0,
        ("robot.max_tilt_deg",),
        "must be < 90 (the pen must point into the paper)",
    )
    check_area(p)
    x_min, x_max, y_min, y_max = p.area
    off = [  # the edges beyond the paper, named in the message
        key
        for key, on in (
            ("area.x_min", x_min >= 0),
            ("area.x_max", x_max <= p["paper.width"]),
            ("area.y_min", y_min >= 0),
            ("area.y_max", y_max <= p["paper.height"]),
        )
        if not on
    ]
    need(
        not off,
        tuple(off),
        f"the area must lie on the paper (0..{p['paper.width']:g} by 0..{p['paper.height']:g} mm)",
    )
    check_servo_loop(p)
    for key in ("position_p_gain", "position_i_gain", "position_d_gain"):
        need(0 <= p[f"servo.{key}"] <= 16383, (f"servo.{key}",), "must be 0..16383")
    need(
        not p["servo.feedforward"] or p["servo.position_p_gain"] > 0,
        ("servo.feedforward", "servo.position_p_gain"),
        "the feedforward needs a position P gain > 0",
    )
