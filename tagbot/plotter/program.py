"""The Grbl program: header, one inverse-time ``G1`` line per setpoint, pen moves, footer.

Layout (every line built by :mod:`firmware_protocols.grbl.gcode`: no spaces, fixed-point numbers,
at most 80 bytes with the newline)::

    G21  G90  G94            mm, absolute, feed in mm/min (for travel)
    <pen up>                 servo: M3S<up> G4P<dwell>; Z: G1Z<up>F<pen.feed>
    G1X..Y..F<travel_feed>   travel to the first run's start
    <pen down>
    G93                      inverse time: F is 1 / (the move's duration in minutes)
    G1X..Y..F<60/dt>         one per setpoint
    G94                      back to mm/min; Grbl then needs a new F on the next G1
    <pen up>                 ... travel, pen down, G93 ... for each further run
    G1X..Y..F<travel_feed>   park (motion.park)
    M5  M2                   servo signal off, program end

Grbl facts behind it:

- Under G93 every ``G1`` must carry its own ``F`` (error 22 otherwise), and after ``G94`` the
  previous feed is forgotten, so travel lines always carry ``F``.
- Grbl's planner turns each target into motor steps (``lround(target · $100)`` per axis,
  planner.c) and silently drops a block whose step count is zero (``PLAN_EMPTY_BLOCK``): the move
  takes no time, and the next block starts from the old step position. So a setpoint that lands
  on the same step position as the previous line (``limits.x_steps_per_mm``/``y_steps_per_mm``,
  Grbl ``$100``/``$101``) is not sent; its time goes into the next line's duration, which keeps
  the timing of the slow lognormal tails right instead of losing it in dropped blocks.
- Grbl cannot move arbitrarily slowly. The planner never goes below ``MINIMUM_FEED_RATE``
  (1 mm/min, config.h; ``limits.min_feed``), and the AVR stepper's slowest step is 8 × 65535
  CPU cycles at 16 MHz (timer limit 0xFFFF at AMASS level 3, stepper.c), 32.8 ms per step of the
  dominant axis (``limits.slowest_step``): about 23 mm/min at 80 steps/mm. A line that should
  take longer (the slow tails of a lognormal) is preceded by a ``G4`` dwell for the surplus and
  sent at the slowest rate Grbl really executes, so the line still ends at its setpoint time.
  G4 waits for the queue to empty and then for Grbl's step idle delay (``$1``,
  ``limits.step_idle_delay``): the dwell is shortened by that delay, and a surplus shorter than
  it is not dwelt but carried into the next line's duration.
- ``M3``/``M5`` and ``G4`` wait for the queued moves: pen commands are pauses, so they stand only
  between runs. A Z pen (``G1Z..``) stays in the motion stream, moved under G94.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from firmware_protocols.grbl import gcode
from tagbot.plotter.place import Setpoints
from tagbot.plotter.profile import Profile

__all__ = ["Program", "build_program", "pen_down", "pen_up"]

DECIMALS = 3


@dataclass(frozen=True, eq=False)
class Program:
    """G-code lines (each ending in ``"\\n"``) and what they mean in time."""

    lines: tuple[str, ...]
    setpoint_lines: tuple[int, ...]
    """Index in :attr:`lines` of each setpoint line."""
    setpoint_times: tuple[float, ...]
    """The retimed time (s) at which each setpoint line's move should end."""
    scale: float
    """The time scale of the retiming (≥ 1)."""
    drawing_time: float
    """Pen-down time, s: from each run's start to its last line (setpoints after it that Grbl
    would not move for are not sent)."""
    duration: float
    """Estimated total, s: drawing, travel at the travel feed from the park position (no
    acceleration), pen dwells."""
    notes: dict[str, float] = field(default_factory=dict)

    @property
    def text(self) -> str:
        return "".join(self.lines)

    def write(self, path: str | Path) -> None:
        """Write the program to ``path`` (ASCII, ``\\n`` line ends), via a temporary file."""
        target = Path(path)
        temporary = target.with_name(target.name + ".tmp")
        temporary.write_text(self.text, encoding="ascii", newline="\n")
        temporary.replace(target)

    def summary(self) -> str:
        return (
            f"{len(self.lines)} lines, {self.duration:.1f} s "
            f"(drawing {self.drawing_time:.1f} s), time scale {self.scale:.3f}"
        )


def pen_up(profile: Profile) -> list[str]:
    """The lines lifting the pen."""
    return _pen(profile, profile["pen.up"])


def pen_down(profile: Profile) -> list[str]:
    """The lines lowering the pen."""
    return _pen(profile, profile["pen.down"])


def _pen(profile: Profile, value: float) -> list[str]:
    if profile["pen.type"] == "servo":
        lines = [gcode.spindle_on(value, decimals=DECIMALS)]
    else:
        lines = [gcode.move(z=value, feed=profile["pen.feed"], decimals=DECIMALS)]
    if profile["pen.dwell"] > 0:
        lines.append(gcode.dwell(profile["pen.dwell"], decimals=DECIMALS))
    return lines


def build_program(setpoints: Setpoints, profile: Profile) -> Program:
    """The Grbl program drawing ``setpoints`` on the machine of ``profile``."""
    lines: list[str] = ["G21\n", "G90\n", "G94\n"]
    indices: list[int] = []
    times: list[float] = []
    travel_feed = profile["motion.travel_feed"]
    up, down = pen_up(profile), pen_down(profile)
    dwell = profile["pen.dwell"]
    idle_delay = profile["limits.step_idle_delay"]
    lines += up
    pen_time = dwell + idle_delay
    drawing = 0.0
    travel = 0.0
    here: tuple[int, int] | None = None
    steps = (profile["limits.x_steps_per_mm"], profile["limits.y_steps_per_mm"])
    min_feed = profile["limits.min_feed"]
    slowest_step = profile["limits.slowest_step"]

    def step_position(x: float, y: float) -> tuple[int, int]:
        """The motor steps Grbl plans for a line to ``(x, y)`` as sent (3 decimals)."""
        sent = (float(gcode.fixed(x, DECIMALS)), float(gcode.fixed(y, DECIMALS)))
        return tuple(_lround(v * n) for v, n in zip(sent, steps, strict=True))

    # For the time estimate only: the machine is assumed to start at the park position.
    position = np.array([profile["motion.park_x"], profile["motion.park_y"]])

    def travel_to(point: np.ndarray) -> None:
        nonlocal here, travel, position
        key = step_position(point[0], point[1])
        if key == here:
            return
        lines.append(gcode.move(float(point[0]), float(point[1]), feed=travel_feed))
        travel += float(np.hypot(*(point - position))) / (travel_feed / 60.0)
        here, position = key, np.asarray(point, dtype=float)

    for run in setpoints.runs:
        travel_to(run.xy[0])
        lines += down
        lines.append("G93\n")
        last_time = last_sent = float(run.t[0])
        for k in range(1, len(run.t)):
            x, y = run.xy[k]
            key = step_position(x, y)
            if key == here:
                continue  # Grbl would drop this move without spending its time: merge it
            duration = float(run.t[k]) - last_time
            moved = math.hypot(*((key[i] - here[i]) / steps[i] for i in range(2)))
            events = max(abs(key[i] - here[i]) for i in range(2))
            # The longest this move can take in Grbl: its minimum feed rate, its slowest step.
            slowest = min(60.0 * moved / min_feed, events * slowest_step)
            early = 0.0
            if duration > slowest:
                # Grbl would run this move faster than planned: dwell first (near rest, so the
                # stop G4 forces costs little), then move at that rate. The stop also costs
                # Grbl's step idle delay ($1), so the dwell is that much shorter; a surplus too
                # short for a dwell is made up on the next line instead.
                surplus = duration - slowest
                if surplus - idle_delay >= 0.5 * 10**-DECIMALS:
                    lines.append(gcode.dwell(surplus - idle_delay, decimals=DECIMALS))
                else:
                    early = surplus
                duration = slowest
            lines.append(gcode.move(float(x), float(y), feed=60.0 / duration, decimals=DECIMALS))
            indices.append(len(lines) - 1)
            times.append(float(run.t[k]))
            here, position = key, run.xy[k].astype(float)
            last_time = float(run.t[k]) - early
            last_sent = float(run.t[k])
        drawing += last_sent - float(run.t[0])
        lines.append("G94\n")
        lines += up
        pen_time += 2 * (dwell + idle_delay)  # each pen change waits for a full stop
    if profile["motion.park"]:
        travel_to(np.array([profile["motion.park_x"], profile["motion.park_y"]]))
    lines += ["M5\n", "M2\n"]
    for line in lines:  # every line must pass the same checks as gcode.make_line
        gcode.make_line(line[:-1])
    return Program(
        lines=tuple(lines),
        setpoint_lines=tuple(indices),
        setpoint_times=tuple(times),
        scale=setpoints.scale,
        drawing_time=drawing,
        duration=drawing + travel + pen_time,
        notes={"travel_time": travel, "pen_time": pen_time},
    )


def _lround(value: float) -> int:
    """C's ``lround``: halves away from zero (Python's ``round`` goes to even)."""
    return int(math.copysign(math.floor(abs(value) + 0.5), value))
