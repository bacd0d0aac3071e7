"""Plotter profiles: the keys a Grbl pen plotter's TOML profile holds, and their checks.

:func:`load_profile` layers the packaged ``profiles/default.toml``, a packaged profile by name
(``"zpen"``) or a user file by path, then overrides such as ``"bed.margin=5"`` (see
:mod:`tagbot.config`); every problem is one line naming the file and the field, e.g.
``default.toml: bed.x_max: must be > bed.x_min``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from tagbot.config import (
    BOOL,
    FIT_OR_POSITIVE,
    INT,
    NON_NEGATIVE,
    NUMBER,
    POSITIVE,
    LayeredProfile,
    convert,
    load_layered,
    packaged_names,
)
from tagbot.errors import ProfileError

__all__ = [
    "DEVICE_SETTINGS",
    "SCHEMA",
    "BedProfile",
    "Profile",
    "ProfileError",
    "device_settings",
    "load_profile",
    "packaged_profiles",
    "with_device_settings",
]

ALIGNS = ("center", "bottom-left", "bottom-right", "top-left", "top-right")
PEN_TYPES = ("servo", "z")
TIME_SCALES = ("run", "uniform")
SETPOINT_MODES = ("adaptive", "fixed")
SLOW_LINES = ("clamp", "dwell")

SCHEMA: dict[str, dict[str, Any]] = {
    "bed": {
        "x_min": NUMBER,
        "x_max": NUMBER,
        "y_min": NUMBER,
        "y_max": NUMBER,
        "margin": NON_NEGATIVE,
        "y_down": BOOL,
    },
    "limits": {
        "from_device": BOOL,
        "x_max_feed": POSITIVE,
        "y_max_feed": POSITIVE,
        "x_acceleration": POSITIVE,
        "y_acceleration": POSITIVE,
        "z_max_feed": POSITIVE,
        "z_acceleration": POSITIVE,
        "junction_deviation": POSITIVE,
        "x_steps_per_mm": POSITIVE,
        "min_feed": POSITIVE,
        "slowest_step": POSITIVE,
        "step_idle_delay": NON_NEGATIVE,
        "y_steps_per_mm": POSITIVE,
        "planner_blocks": INT,
    },
    "pen": {
        "type": PEN_TYPES,
        "up": NUMBER,
        "down": NUMBER,
        "dwell": NON_NEGATIVE,
        "feed": POSITIVE,
    },
    "motion": {
        "dt": POSITIVE,
        "max_dt": POSITIVE,
        "tolerance": POSITIVE,
        "min_buffer": NON_NEGATIVE,
        "setpoints": SETPOINT_MODES,
        "time_scale": TIME_SCALES,
        "trim": BOOL,
        "slow_lines": SLOW_LINES,
        "travel_feed": POSITIVE,
        "park": BOOL,
        "park_x": NUMBER,
        "park_y": NUMBER,
    },
    "place": {
        "scale": FIT_OR_POSITIVE,
        "rotation": NUMBER,
        "align": ALIGNS,
    },
    "serial": {"baud": INT, "read_time": NON_NEGATIVE},
}
"""Every section and key a profile may hold, with the kind of value it takes."""


class BedProfile(LayeredProfile):
    """A profile with a rectangular ``bed`` (the plotters': Grbl's and the AxiDraw's)."""

    @property
    def bed(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` in mm."""
        b = self.values["bed"]
        return b["x_min"], b["x_max"], b["y_min"], b["y_max"]

    def check_bed(self) -> None:
        """The bed's extent and margin (ProfileError naming the source and the key)."""
        x_min, x_max, y_min, y_max = self.bed
        self.need(x_max > x_min, ("bed.x_min", "bed.x_max"), "must be > bed.x_min")
        self.need(y_max > y_min, ("bed.y_min", "bed.y_max"), "must be > bed.y_min")
        self.need(
            2 * self["bed.margin"] < min(x_max - x_min, y_max - y_min),
            ("bed.margin",),
            "leaves no room on the bed",
        )

    def check_park(self) -> None:
        """With ``motion.park``, the park position on the bed."""
        if self["motion.park"]:
            x_min, x_max, y_min, y_max = self.bed
            for axis, low, high in (("x", x_min, x_max), ("y", y_min, y_max)):
                self.need(
                    low <= self[f"motion.park_{axis}"] <= high,
                    (f"bed.{axis}_min", f"bed.{axis}_max", f"motion.park_{axis}"),
                    "outside the bed",
                )


class Profile(BedProfile):
    """A merged, validated plotter profile: ``profile["bed.margin"]`` and named views."""

    @property
    def max_speed(self) -> tuple[float, float]:
        """Per-axis speed limits, mm/s."""
        return self["limits.x_max_feed"] / 60.0, self["limits.y_max_feed"] / 60.0

    @property
    def max_acceleration(self) -> tuple[float, float]:
        """Per-axis acceleration limits, mm/s²."""
        return self["limits.x_acceleration"], self["limits.y_acceleration"]

    @property
    def dt(self) -> float:
        return self["motion.dt"]

    @property
    def axes(self) -> np.ndarray:
        """Machine ``(x, y)`` → the two axes the speed and acceleration limits hold along
        (identity: x and y; an AxiDraw's motors turn with ``x ± y``)."""
        return np.eye(2)


def packaged_profiles() -> list[str]:
    """Names of the plotter profiles shipped with tagbot (``default``, ``zpen``...)."""
    return packaged_names("tagbot.plotter")


def load_profile(profile: str | Path | None = None, overrides: Iterable[str] = ()) -> Profile:
    """Packaged defaults, then ``profile`` (a packaged name or a TOML path), then ``overrides``.

    Raises ProfileError naming the file and the field for unreadable files, unknown keys, values
    of the wrong kind and inconsistent values (e.g. ``bed.x_max`` not above ``bed.x_min``).
    """
    return load_layered(Profile, "tagbot.plotter", SCHEMA, profile, overrides, _check)


def _check(p: Profile) -> None:
    """Checks across fields; the error names the source that last set one of them."""

    need = p.need
    p.check_bed()
    need(p.dt <= 1.0, ("motion.dt",), "must be <= 1 s (one G-code line per step)")
    # F = 60/dt must fit Grbl's 8 digits at 3 decimals; Grbl cannot parse lines faster anyway.
    need(
        p["limits.step_idle_delay"] < 0.255,
        ("limits.step_idle_delay",),
        "must be < 0.255 s (Grbl $1 is 0-254 ms; 255 keeps the motors on: use 0)",
    )
    need(p.dt >= 0.001, ("motion.dt",), "must be >= 0.001 s (F = 60/dt needs <= 8 digits)")
    need(p["motion.max_dt"] >= p.dt, ("motion.dt", "motion.max_dt"), "must be >= motion.dt")
    need(p["motion.max_dt"] <= 2.0, ("motion.max_dt",), "must be <= 2 s")
    p.check_park()
    if p["pen.type"] == "servo":
        need(p["pen.up"] >= 0, ("pen.up",), "must be >= 0 (an M3 S value)")
        need(p["pen.down"] >= 0, ("pen.down",), "must be >= 0 (an M3 S value)")
    else:
        need(p["pen.up"] > p["pen.down"], ("pen.down", "pen.up"), "must be > pen.down (Z up)")


DEVICE_SETTINGS = {
    1: "limits.step_idle_delay",
    100: "limits.x_steps_per_mm",
    101: "limits.y_steps_per_mm",
    110: "limits.x_max_feed",
    111: "limits.y_max_feed",
    112: "limits.z_max_feed",
    120: "limits.x_acceleration",
    121: "limits.y_acceleration",
    122: "limits.z_acceleration",
    11: "limits.junction_deviation",
}
"""The Grbl settings (``$$``) that ``limits.from_device`` takes from the machine."""

_MS = 1000.0
"""``$1`` is in milliseconds (255: motors always on, no delay); the profile's key in seconds."""


def _from_device(number: int, value: float) -> float:
    if number == 1:
        return 0.0 if value >= 255 else value / _MS
    return value


def _to_device(number: int, value: float) -> float:
    return round(value * _MS) if number == 1 else value


def with_device_settings(profile: Profile, settings: Mapping[int, float]) -> Profile:
    """``profile`` with its limits replaced by the controller's ``$$`` values (source ``$$``)."""
    values = {section: dict(table) for section, table in profile.values.items()}
    sources = dict(profile.sources)
    for number, key in DEVICE_SETTINGS.items():
        if number in settings:
            section, name = key.split(".")
            value = _from_device(number, settings[number])
            values[section][name] = convert("$$", key, SCHEMA[section][name], value)
            sources[key] = "$$"
    result = Profile(values=values, sources=sources, layers=(*profile.layers, "$$"))
    _check(result)
    return result


def device_settings(profile: Profile) -> dict[int, float]:
    """The ``$$`` values a controller matching ``profile`` has (for a simulated machine)."""
    return {number: _to_device(number, profile[key]) for number, key in DEVICE_SETTINGS.items()}
