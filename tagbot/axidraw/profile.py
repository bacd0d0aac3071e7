"""AxiDraw profiles: the keys an AxiDraw's TOML profile holds, and their checks.

:func:`load_profile` layers the packaged ``profiles/default.toml`` (AxiDraw V3), a packaged
model by name (``v3a3``, ``sea3``, ``minikit``, ``nextdraw8511``, ``nextdraw1117``,
``nextdraw2234``) or a user file by path, then overrides such as
``"motors.microstepping=8"`` (see :mod:`tagbot.config`); every problem is one line naming the
file and the field, e.g. ``minikit.toml: bed.x_max: must be > bed.x_min``.

The machine's geometry: motor 1 turns with ``x + y``, motor 2 with ``x − y`` (mm of belt each),
so a motor's step position is ``steps_per_mm · (x ± y)``; speed and acceleration limits hold
along each motor's axis. :meth:`Profile.placement` is the same machine as a
:class:`tagbot.plotter.profile.Profile` for :func:`tagbot.plotter.place.place` (placement on
the bed, trimming, retiming by run to these limits).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from tagbot.config import (
    BOOL,
    INT,
    NON_NEGATIVE,
    NUMBER,
    POSITIVE,
    TEXT,
    load_layered,
    packaged_names,
)
from tagbot.errors import ProfileError
from tagbot.plotter.profile import SCHEMA as PLOTTER_SCHEMA
from tagbot.plotter.profile import SETPOINT_MODES, TIME_SCALES, BedProfile
from tagbot.plotter.profile import Profile as PlotterProfile

__all__ = [
    "MICROSTEPPING",
    "MOTOR_AXES",
    "SCHEMA",
    "Profile",
    "ProfileError",
    "load_profile",
    "packaged_profiles",
]

MODELS = (
    "AxiDraw V3",
    "AxiDraw V3/A3",
    "AxiDraw SE/A3",
    "AxiDraw MiniKit",
    "NextDraw 8511",
    "NextDraw 1117",
    "NextDraw 2234",
    "other",
)
MICROSTEPPING = {16: 1, 8: 2, 4: 3, 2: 4, 1: 5}
"""Microstepping → the ``EM`` command's mode number."""
MOTOR_AXES = np.array([[1.0, 1.0], [1.0, -1.0]])
"""Machine ``(x, y)`` mm → mm along motor 1's and motor 2's axes (``x + y``, ``x - y``)."""
TICK_S = 40e-6
"""The EBB's motion interrupt period."""
SERVO_SLOT_S = 0.003
"""s of one RC servo channel's slot (the firmware's boot default, ``SC,9,3``): a servo's
pulse repeats every ``channels`` slots (``SC,8``)."""
MAX_SERVO_CHANNELS = 8
"""The most RC servo channels the EBB cycles through (``SC,8``; 8 at boot)."""
MIN_FIRMWARE = (3, 0, 1)
"""The oldest firmware tagbot drives at all (LT/T3, the FIFO set with CU,4, QU,6)."""
_VERSION_TEXT = re.compile(r"(\d+)\.(\d+)\.(\d+)")

SCHEMA: dict[str, dict[str, Any]] = {
    "machine": {"model": MODELS, "min_firmware": TEXT},
    "bed": PLOTTER_SCHEMA["bed"],
    "motors": {"steps_per_mm_16x": POSITIVE, "microstepping": INT, "max_step_rate": POSITIVE},
    "limits": {
        "draw_speed": POSITIVE,
        "draw_acceleration": POSITIVE,
        "travel_speed": POSITIVE,
        "travel_acceleration": POSITIVE,
    },
    "pen": {
        "up": NON_NEGATIVE,
        "down": NON_NEGATIVE,
        "rate_raise": POSITIVE,
        "rate_lower": POSITIVE,
        "delay_up": NON_NEGATIVE,
        "delay_down": NON_NEGATIVE,
        "pin": INT,
        "servo_min": INT,
        "servo_max": INT,
        "period": POSITIVE,
        "sweep_time": POSITIVE,
        "move_min": NON_NEGATIVE,
        "move_slope": NON_NEGATIVE,
    },
    "motion": {
        "setpoints": SETPOINT_MODES,
        "dt": POSITIVE,
        "max_dt": POSITIVE,
        "tolerance": POSITIVE,
        "time_scale": TIME_SCALES,
        "trim": BOOL,
        "park": BOOL,
        "park_x": NUMBER,
        "park_y": NUMBER,
        "jerk": BOOL,
    },
    "place": PLOTTER_SCHEMA["place"],
    "serial": {"fifo": INT, "poll": POSITIVE},
}
"""Every section and key an AxiDraw profile may hold, with the kind of value it takes."""


class Profile(BedProfile):
    """A merged, validated AxiDraw profile: ``profile["bed.margin"]`` and named views."""

    @property
    def steps_per_mm(self) -> float:
        """Motor steps per mm of ``x ± y`` at the profile's microstepping."""
        return self["motors.steps_per_mm_16x"] * self["motors.microstepping"] / 16

    @property
    def step_mode(self) -> int:
        """The ``EM`` mode number of the microstepping (1 = 16x ... 5 = full steps)."""
        return MICROSTEPPING[self["motors.microstepping"]]

    @property
    def min_firmware(self) -> tuple[int, int, int]:
        """The oldest EBB firmware this machine is driven with (``machine.min_firmware``)."""
        found = _VERSION_TEXT.fullmatch(self["machine.min_firmware"].strip())
        if found is None:
            return (0, 0, 0)
        return int(found[1]), int(found[2]), int(found[3])

    @property
    def servo_channels(self) -> int:
        """The RC servo channels (``SC,8``) that give the pen servo its ``pen.period``."""
        return round(self["pen.period"] / SERVO_SLOT_S)

    def servo_position(self, percent: float) -> int:
        """The servo pulse width (1/12 MHz units, ``SC,4``/``SC,5``) at ``percent`` height."""
        low, high = self["pen.servo_min"], self["pen.servo_max"]
        return round(low + (high - low) / 100.0 * percent)

    def servo_rate(self, percent_rate: float) -> int:
        """The ``SC,11``/``SC,12`` rate for a CLI-style rate of ``percent_rate`` (1-100)."""
        span = self["pen.servo_max"] - self["pen.servo_min"]
        return round(span * self["pen.period"] / 100.0 / self["pen.sweep_time"] * percent_rate)

    def pen_time(self, down: bool) -> float:
        """s the servo takes to lower (``down``) or raise the pen, delay included: the blend
        (4th-power mean) of its physical travel and the control signal's sweep at the rate."""
        distance = abs(self["pen.up"] - self["pen.down"])
        rate = self["pen.rate_lower"] if down else self["pen.rate_raise"]
        delay = self["pen.delay_down"] if down else self["pen.delay_up"]
        if distance < 0.9:  # the same height: nothing moves
            return delay
        travel = self["pen.move_slope"] * distance + self["pen.move_min"]
        sweep = self["pen.sweep_time"] * distance / rate
        # Whole milliseconds, as SP's duration takes them.
        return int(1000.0 * (travel**4 + sweep**4) ** 0.25) / 1000.0 + delay

    def placement(self) -> PlotterProfile:
        """This machine as a plotter profile for :func:`tagbot.plotter.place.place`: the bed,
        the placement and motion keys, the drawing limits along the motor axes
        (``PlotterProfile.axes``), one motor step as the trimming box, and none of Grbl's own
        limits (look-ahead, junctions, host-pause buffer, slowest step)."""
        v = self["limits.draw_speed"] * 60.0
        a = self["limits.draw_acceleration"]
        k = self.steps_per_mm
        values = {
            "bed": dict(self.values["bed"]),
            "limits": {
                "from_device": False,
                "x_max_feed": v,
                "y_max_feed": v,
                "x_acceleration": a,
                "y_acceleration": a,
                "z_max_feed": 1.0,
                "z_acceleration": 1.0,
                "junction_deviation": 1e9,
                "x_steps_per_mm": k,
                "y_steps_per_mm": k,
                "min_feed": 1e-9,
                "slowest_step": 1e9,
                "step_idle_delay": 0.0,
                "planner_blocks": 2**31,
            },
            "pen": {"type": "servo", "up": 0.0, "down": 0.0, "dwell": 0.0, "feed": 1.0},
            "motion": {
                **{key: self[f"motion.{key}"] for key in ("dt", "max_dt", "tolerance")},
                **{key: self[f"motion.{key}"] for key in ("setpoints", "time_scale", "trim")},
                **{key: self[f"motion.{key}"] for key in ("park", "park_x", "park_y")},
                "min_buffer": 0.0,
                "slow_lines": "dwell",
                "travel_feed": self["limits.travel_speed"] * 60.0,
            },
            "place": dict(self.values["place"]),
            "serial": {"baud": 115200, "read_time": 0.0},
        }
        sources = {f"{s}.{k}": self.where(f"{s}.{k}") for s in values for k in values[s]}
        return _MotorAxes(values=values, sources=sources, layers=self.layers)


class _MotorAxes(PlotterProfile):
    """A plotter profile whose speed and acceleration limits hold along ``x ± y``."""

    @property
    def axes(self) -> np.ndarray:
        return MOTOR_AXES


def packaged_profiles() -> list[str]:
    """Names of the AxiDraw profiles shipped with tagbot (``default``, ``v3a3``...)."""
    return packaged_names("tagbot.axidraw")


def load_profile(profile: str | Path | None = None, overrides: Iterable[str] = ()) -> Profile:
    """Packaged defaults (AxiDraw V3), then ``profile`` (a packaged name or a TOML path), then
    ``overrides``; ProfileError naming the file and the field for any problem."""
    return load_layered(Profile, "tagbot.axidraw", SCHEMA, profile, overrides, _check)


def _check(p: Profile) -> None:
    """Checks across fields; the error names the source that last set one of them."""
    need = p.need
    p.check_bed()
    need(
        p["motors.microstepping"] in MICROSTEPPING,
        ("motors.microstepping",),
        f"must be one of 16, 8, 4, 2, 1, got {p['motors.microstepping']}",
    )
    need(
        p["motors.max_step_rate"] <= 25000,
        ("motors.max_step_rate",),
        "must be <= 25000 (the EBB steps at most once per 40 us tick)",
    )
    fastest = p["motors.max_step_rate"] / p.steps_per_mm
    for key in ("limits.draw_speed", "limits.travel_speed"):
        need(
            p[key] <= fastest,
            ("motors.microstepping", "motors.max_step_rate", key),
            f"must be <= {fastest:g} mm/s (motors.max_step_rate / steps per mm)",
        )
    for key in ("pen.up", "pen.down"):
        need(p[key] <= 100, (key,), "must be <= 100 (% of the servo's range)")
    need(
        p["pen.servo_max"] > p["pen.servo_min"],
        ("pen.servo_min", "pen.servo_max"),
        "must be > pen.servo_min",
    )
    need(p["pen.servo_max"] <= 65535, ("pen.servo_max",), "must be <= 65535 (SC,4/SC,5)")
    need(p["pen.pin"] <= 7, ("pen.pin",), "must be <= 7 (a port B pin)")
    need(
        1 <= p.servo_channels <= MAX_SERVO_CHANNELS
        and abs(p.servo_channels * SERVO_SLOT_S - p["pen.period"]) < 1e-9,
        ("pen.period",),
        "must be 1 to 8 servo slots of 0.003 s (SC,8): 0.003, 0.006 ... 0.024",
    )
    need(
        p.min_firmware >= MIN_FIRMWARE,
        ("machine.min_firmware",),
        'must be a version like "3.0.2", at least 3.0.1 (the oldest tagbot drives)',
    )
    for key in ("pen.rate_raise", "pen.rate_lower"):
        need(0 < p.servo_rate(p[key]) <= 65535, (key,), "gives an SC,11/12 rate outside 1-65535")
    for down in (True, False):
        key = "pen.delay_down" if down else "pen.delay_up"
        need(p.pen_time(down) <= 65.535, (key,), "the pen's move must last <= 65.535 s (SP)")
    need(p["motion.dt"] >= TICK_S, ("motion.dt",), "must be >= 0.00004 s (one EBB tick)")
    need(
        p["motion.max_dt"] >= p["motion.dt"], ("motion.dt", "motion.max_dt"), "must be >= motion.dt"
    )
    need(p["motion.max_dt"] <= 2.0, ("motion.max_dt",), "must be <= 2 s")
    need(p["serial.fifo"] <= 64, ("serial.fifo",), "must be <= 64")
    p.check_park()
