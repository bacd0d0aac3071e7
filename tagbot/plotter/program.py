"""The Grbl program: header, one inverse-time ``G1`` line per setpoint, pen moves, footer, and
what every line means in time (the job's plan, line by line).

Layout (every line built by :mod:`firmware_protocols.grbl.gcode`: no spaces, fixed-point numbers,
at most 80 bytes with the newline)::

    G21  G90  G94            mm, absolute, feed in mm/min (for travel)
    <pen up>                 servo: M3S<up> G4P<dwell>; Z: G1Z<up>F<pen.feed>
    G1X..Y..F<travel_feed>   travel to the first run's start
    <pen down>
    G93                      inverse time: F is 1 / (the move's duration in minutes)
    G1X..Y..F<60/d>          one per setpoint (d: that line's duration, see place.py)
    G94                      back to mm/min; Grbl then needs a new F on the next G1
    <pen up>                 ... travel, pen down, G93 ... for each further run
    G1X..Y..F<travel_feed>   park (motion.park)
    M5  M2                   servo signal off, program end

Grbl facts behind it (Grbl 1.1h, measured on the real firmware where noted):

- Under G93 every ``G1`` must carry its own ``F`` (error 22 otherwise), and after ``G94`` the
  previous feed is forgotten, so travel lines always carry ``F``.
- ``G4 P`` waits for the queue to empty, then ``ceil(20·P) × 50 ms`` (``delay_sec`` in 50 ms
  steps; measured: P = 0.002 s stands still as long as P = 0.05 s). So every dwell this module
  writes is a whole number of 50 ms steps: ``pen.dwell`` is rounded *up* to one
  (:func:`dwell_steps`), and the plan counts what Grbl waits.
- Every full stop costs Grbl's step idle delay (``$1``, ``limits.step_idle_delay``: a blocking
  ``delay_ms`` when the steppers go idle): the line that waits for the stop (``M3``/``M5`` or a
  ``G4`` after motion) is planned that much longer.
- Pen moves and pen-up travel run at machine speed whatever the drawing's time scale: the pen
  dwell as set, the travel at ``motion.travel_feed`` with Grbl's trapezoid (acceleration along
  the move's direction, limited by the axes' feeds), from rest to rest; a Z pen's move at
  ``pen.feed`` capped by ``$112`` (``limits.z_max_feed``), accelerating at ``$122``
  (``limits.z_acceleration``).
- Setpoints that move no motor step were left out by :func:`~tagbot.plotter.place.place`
  (Grbl would drop their block: ``PLAN_EMPTY_BLOCK``). With ``motion.slow_lines = "clamp"``
  no line is slower than Grbl's slowest step, so no run holds a dwell. With ``"dwell"`` (the old
  behaviour) a line that should take longer than Grbl can step (``limits.slowest_step``,
  ``limits.min_feed``) is preceded by a ``G4`` of the surplus less the idle delay, rounded
  *down* to 50 ms steps, and sent at the slowest rate; a surplus under one step is carried into
  the next line (which then lasts longer), so the lines still end at their setpoint times.
- ``M3``/``M5`` and ``G4`` wait for the queued moves: pen commands are pauses, so they stand only
  between runs. A Z pen (``G1Z..``) stays in the motion stream, moved under G94.

The job clock starts (0) when line 1 starts; :class:`Program` gives each line's planned start
and end on it, the position after it, the pen, the run, and whether it moves; Grbl's 15 planner
blocks (``limits.planner_blocks``) then hold at least :attr:`Program.min_buffered` seconds of
motion whenever a run is under way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from firmware_protocols.grbl import gcode
from tagbot.io.motionfile import MotionTable
from tagbot.plotter.place import (
    RX_LINES,
    Setpoints,
    buffer_goal,
    buffered,
    slowest_durations,
    step_box,
)
from tagbot.plotter.profile import Profile

__all__ = [
    "DWELL_STEP",
    "Program",
    "build_program",
    "dwell_steps",
    "grbl_dwell",
    "pen_down",
    "pen_up",
    "resting_share",
    "start_reserves",
    "travel_time",
]

DECIMALS = 3
DWELL_STEP = 0.05
"""s: Grbl 1.1h dwells in steps of 50 ms (``DWELL_TIME_STEP``, ``delay_sec``)."""

_STATIC, _LINEAR, _TRAPEZOID = 0, 1, 2


def grbl_dwell(seconds: float) -> float:
    """What Grbl waits for ``G4 P<seconds>``: ``ceil(20·P) × 50 ms``."""
    return dwell_steps(seconds) * DWELL_STEP


def dwell_steps(seconds: float) -> int:
    """``ceil(20·P)``: Grbl's 50 ms dwell steps for ``P`` (1e-9 slack for decimal inputs)."""
    return max(0, math.ceil(seconds / DWELL_STEP - 1e-9))


@dataclass(frozen=True, eq=False)
class Program:
    """G-code lines (each ending in ``"\\n"``) and what they mean in time, one entry per line.

    Times are on the job clock: 0 when line 1 starts.
    """

    lines: tuple[str, ...]
    line_start: NDArray[np.float64]
    """Planned start of each line, s (job clock)."""
    line_end: NDArray[np.float64]
    """Planned end of each line, s: setpoint lines their inverse-time duration; travel Grbl's
    trapezoid at ``motion.travel_feed``; dwells ``ceil(20·P)·50 ms`` (plus ``$1`` after motion);
    other lines take no time (but a pen change waits for the stop: ``$1``)."""
    line_xy: NDArray[np.float64]
    """(N, 2) machine position after each line, mm (as sent; the park position before any
    move)."""
    line_pen: NDArray[np.bool_]
    """The pen is down while the line executes (the lowering pen line and its dwell included)."""
    line_run: NDArray[np.int64]
    """Index (in :attr:`run_plans`) of the pen-down run a setpoint line belongs to, else -1."""
    line_moves: NDArray[np.bool_]
    """The line creates a planner block that moves at least one motor step."""
    run_plans: tuple[int, ...]
    """The plan (index in the tag) each run draws."""
    run_scales: tuple[float, ...]
    """Each run's time scale ``s_k``."""
    scale: float
    """The largest time scale (with ``motion.time_scale = "uniform"`` every run's)."""
    drawing_time: float
    """Pen-down motion time, s: from each run's first setpoint line to its last."""
    min_buffered: float
    """s: the least motion the planner holds during a run, the minimum over every run of more than
    ``limits.planner_blocks`` setpoint lines of the summed durations of that many consecutive
    ones (``inf`` when no run is that long: each is held whole once sent)."""
    min_buffered_rx: float = 0.0
    """s: the same for what a host pause leaves the machine surely: the ``planner_blocks - 1``
    lines queued behind the executing one plus the :data:`~tagbot.plotter.place.RX_LINES`
    setpoint lines that fit Grbl's 128-byte receive buffer (``motion.min_buffer`` bounds it; the
    report's ``min_buffered_s``). A run's first lines are the exception:
    :attr:`min_buffered_start`."""
    run_start_reserve: tuple[float, ...] = ()
    """s per run: the motion Grbl holds at the run's start, where no timing helps. A pen-down
    stop (``M3``, ``G4``) empties the planner, and while it lasts Grbl reads no line, so when it
    ends the machine holds only the lines that fitted the receive buffer behind it
    (:func:`start_reserves`): a host pause longer than that there starves the planner. ``inf``
    for a run that follows its pen-down without a stop or fits the buffer whole."""
    run_points: tuple[tuple[NDArray[np.float64], NDArray[np.float64]], ...] = ()
    notes: dict[str, float] = field(default_factory=dict)

    @property
    def min_buffered_start(self) -> float:
        """s: the least of :attr:`run_start_reserve` (``inf`` for none)."""
        return min(self.run_start_reserve, default=math.inf)

    @property
    def duration(self) -> float:
        """Planned job time, s: ``line_end[-1]``."""
        return float(self.line_end[-1]) if len(self.line_end) else 0.0

    @property
    def setpoint_lines(self) -> tuple[int, ...]:
        """Index in :attr:`lines` of each setpoint line."""
        return tuple(int(i) for i in np.flatnonzero(self.line_run >= 0))

    @property
    def setpoint_times(self) -> tuple[float, ...]:
        """The job-clock time (s) at which each setpoint line's move should end."""
        return tuple(float(self.line_end[i]) for i in self.setpoint_lines)

    @property
    def planned_runs(self) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Per run, ``(t, xy)`` on the job clock: the run's first point (where the pen went
        down, when its first setpoint line starts), then each setpoint line's end (and the end
        of any dwell inside the run); straight lines between them are the plan."""
        return [(t.copy(), xy.copy()) for t, xy in self.run_points]

    @property
    def text(self) -> str:
        return "".join(self.lines)

    def write(self, path: str | Path) -> None:
        """Write the program to ``path`` (ASCII, ``\\n`` line ends), via a temporary file."""
        from tagbot.io.output import write_atomic

        write_atomic(path, self.text.encode("ascii"))

    def summary(self) -> str:
        return (
            f"{len(self.lines)} lines, {self.duration:.1f} s "
            f"(drawing {self.drawing_time:.1f} s), time scale {self.scale:.3f}"
        )

    def timeline(self, dt: float) -> MotionTable:
        """The whole planned job sampled every ``dt`` s on the job clock (and at its end):
        travel, pen moves and dwells included, pen 0/1, velocities in mm/s, machine mm."""
        if dt <= 0:
            raise ValueError("dt: must be > 0")
        end = self.duration
        t = np.arange(0.0, end, dt)
        t = np.append(t, end) if not len(t) or t[-1] < end else t
        xy, v, pen = self.at(t)
        speed = np.hypot(v[:, 0], v[:, 1])
        return MotionTable(t, xy, v, speed, pen.astype(np.int8))

    def at(self, t: NDArray[np.float64]) -> tuple[NDArray, NDArray, NDArray]:
        """Planned position (N, 2), velocity (N, 2) and pen (N,) at job-clock instants ``t``.

        Setpoint lines move in a straight line at constant speed (inverse time), travel with
        Grbl's trapezoid; the velocity is the derivative of that position.
        """
        t = np.asarray(t, dtype=float)
        n = len(self.lines)
        if not n:  # nothing to run: at rest where the job starts, pen up
            xy = np.tile(self.notes_start, (len(t), 1))
            return xy, np.zeros_like(xy), np.zeros(len(t), dtype=bool)
        before = np.vstack([self.notes_start[None, :], self.line_xy[:-1]])
        i = np.clip(np.searchsorted(self.line_end, t, side="left"), 0, n - 1)
        start, stop = self.line_start[i], self.line_end[i]
        p0, p1 = before[i], self.line_xy[i]
        length = np.hypot(*(p1 - p0).T)
        span = stop - start
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(length[:, None] > 0, (p1 - p0) / length[:, None], 0.0)
            tau = np.clip(np.where(span > 0, (t - start) / span, 1.0), 0.0, 1.0)
        kind = self.notes_kind[i]
        moving = self.line_moves[i] & (span > 0) & (length > 0)
        # Linear (setpoints): constant speed along the line.
        s_lin = tau * length
        v_lin = np.where(span > 0, length / np.where(span > 0, span, 1.0), 0.0)
        # Trapezoid (travel): peak speed vp, acceleration a, from rest to rest.
        a, vp = self.notes_accel[i], self.notes_peak[i]
        ta = np.where(a > 0, vp / np.where(a > 0, a, 1.0), 0.0)
        e = np.clip(t - start, 0.0, span)
        s_acc = 0.5 * a * e**2
        s_cruise = 0.5 * a * ta**2 + vp * (e - ta)
        rest = np.clip(span - e, 0.0, None)
        s_dec = length - 0.5 * a * rest**2
        s_trap = np.where(e < ta, s_acc, np.where(rest < ta, s_dec, s_cruise))
        v_trap = np.where(e < ta, a * e, np.where(rest < ta, a * rest, vp))
        trapezoid = kind == _TRAPEZOID
        s = np.where(trapezoid, np.clip(s_trap, 0.0, length), s_lin)
        speed = np.where(trapezoid, v_trap, v_lin)
        xy = np.where(moving[:, None], p0 + u * s[:, None], p1)
        v = np.where(moving[:, None], u * speed[:, None], 0.0)
        return xy, v, self.line_pen[i]

    # Internal per-line arrays for :meth:`at` (kind, trapezoid parameters, start position).
    notes_kind: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    notes_accel: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    notes_peak: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    notes_start: NDArray[np.float64] = field(default_factory=lambda: np.zeros(2))

    def resting_time(self, box: NDArray[np.float64], step: float = 0.0005) -> float:
        """Planned pen-down time (s, runs' lines) within ``box`` (± mm per axis) of a run's
        first or last point, sampled every ``step`` s."""
        total = 0.0
        for t, xy in self.run_points:
            if len(t) < 2 or t[-1] <= t[0]:
                continue
            count = max(2, math.ceil((t[-1] - t[0]) / step))
            s = np.linspace(t[0], t[-1], count + 1)
            mid = 0.5 * (s[1:] + s[:-1])
            p = np.column_stack([np.interp(mid, t, xy[:, 0]), np.interp(mid, t, xy[:, 1])])
            near = np.all(np.abs(p - xy[0]) < box, axis=1) | np.all(
                np.abs(p - xy[-1]) < box, axis=1
            )
            total += float(np.sum(np.diff(s)[near]))
        return total


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
    steps = dwell_steps(profile["pen.dwell"])
    if steps > 0:
        lines.append(gcode.dwell(steps * DWELL_STEP, decimals=DECIMALS))
    return lines


def travel_time(
    length: float, direction: NDArray, feed: float, profile: Profile
) -> tuple[float, float, float]:
    """Grbl's rest-to-rest trapezoid for a move: ``(duration, peak speed, acceleration)``.

    The nominal speed ``feed/60`` is capped by each axis's maximum feed along the direction
    (planner.c ``limit_value_by_axis_maximum``), and so is the acceleration.
    """
    if length <= 0:
        return 0.0, 0.0, 0.0
    u = np.abs(np.asarray(direction, dtype=float))
    vmax = np.asarray(profile.max_speed)
    amax = np.asarray(profile.max_acceleration)
    with np.errstate(divide="ignore"):
        v = min(feed / 60.0, float(np.min(np.where(u > 0, vmax / u, np.inf))))
        a = float(np.min(np.where(u > 0, amax / u, np.inf)))
    if not math.isfinite(a):
        a = float(np.min(amax))
    duration, peak = _trapezoid(length, v, a)
    return duration, peak, a


def _trapezoid(length: float, v: float, a: float) -> tuple[float, float]:
    """Rest-to-rest move of ``length`` at speed ``v`` and acceleration ``a``: (s, peak)."""
    if length <= 0:
        return 0.0, 0.0
    if length >= v * v / a:
        return length / v + v / a, v
    return 2.0 * math.sqrt(length / a), math.sqrt(a * length)


def build_program(setpoints: Setpoints, profile: Profile) -> Program:
    """The Grbl program drawing ``setpoints`` on the machine of ``profile``."""
    return _Builder(setpoints, profile).build()


class _Builder:
    """Lines and their plan, appended in order (see :class:`Program`)."""

    def __init__(self, setpoints: Setpoints, profile: Profile) -> None:
        self.setpoints, self.profile = setpoints, profile
        self.lines: list[str] = []
        self.start: list[float] = []
        self.end: list[float] = []
        self.xy: list[tuple[float, float]] = []
        self.pen: list[bool] = []
        self.run: list[int] = []
        self.moves: list[bool] = []
        self.kind: list[int] = []
        self.accel: list[float] = []
        self.peak: list[float] = []
        self.sync: list[bool] = []  # the line waits for the motion before it to end
        self.clock = 0.0
        self.origin = (float(profile["motion.park_x"]), float(profile["motion.park_y"]))
        self.here = self.origin
        self.z = None
        self.down = False
        self.moved_since_stop = False
        self.steps = (profile["limits.x_steps_per_mm"], profile["limits.y_steps_per_mm"])
        self.idle = profile["limits.step_idle_delay"]
        self.travel = 0.0
        self.pen_time = 0.0
        self.dwells = 0
        self.short_surplus = 0

    def add(
        self,
        line: str,
        duration: float = 0.0,
        *,
        xy: tuple[float, float] | None = None,
        run: int = -1,
        moves: bool = False,
        kind: int = _STATIC,
        accel: float = 0.0,
        peak: float = 0.0,
        stop: bool = False,
    ) -> float:
        """Append ``line`` lasting ``duration`` (plus ``$1`` when it waits for a stop after
        motion); returns the time it took."""
        if stop and self.moved_since_stop:
            duration += self.idle
            self.moved_since_stop = False
        if moves:
            self.moved_since_stop = True
        self.lines.append(line)
        self.start.append(self.clock)
        self.clock += duration
        self.end.append(self.clock)
        if xy is not None:
            self.here = xy
        self.xy.append(self.here)
        self.pen.append(self.down)
        self.run.append(run)
        self.moves.append(moves)
        self.kind.append(kind)
        self.accel.append(accel)
        self.peak.append(peak)
        self.sync.append(stop)
        return duration

    def key(self, xy: tuple[float, float]) -> tuple[int, int]:
        sent = (float(gcode.fixed(xy[0], DECIMALS)), float(gcode.fixed(xy[1], DECIMALS)))
        return tuple(_lround(v * n) for v, n in zip(sent, self.steps, strict=True))

    def sent(self, xy) -> tuple[float, float]:
        return (
            float(gcode.fixed(float(xy[0]), DECIMALS)),
            float(gcode.fixed(float(xy[1]), DECIMALS)),
        )

    def pen_lines(self, down: bool) -> None:
        p = self.profile
        value = p["pen.down"] if down else p["pen.up"]
        self.down = down
        for line in _pen(p, value):
            if line.startswith("G4P"):
                seconds = grbl_dwell(float(line[3:]))
                self.pen_time += self.add(line, seconds, stop=True)
                self.dwells += 1
            elif line.startswith("M3"):
                self.pen_time += self.add(line, stop=True)
            else:  # a Z move under G94, at pen.feed capped by $112, accelerating at $122
                known = self.z is not None
                distance = abs(value - self.z) if known else 0.0
                speed = min(p["pen.feed"], p["limits.z_max_feed"]) / 60.0
                duration = _trapezoid(distance, speed, p["limits.z_acceleration"])[0]
                self.z = value
                self.pen_time += self.add(line, duration, moves=distance > 0 or not known)

    def travel_to(self, point) -> None:
        p = self.profile
        target = self.sent(point)
        if self.key(target) == self.key(self.here):
            return
        d = np.subtract(target, self.here)
        length = float(np.hypot(*d))
        duration, peak, a = travel_time(length, d / length, p["motion.travel_feed"], p)
        line = gcode.move(float(point[0]), float(point[1]), feed=p["motion.travel_feed"])
        self.travel += self.add(
            line, duration, xy=target, moves=True, kind=_TRAPEZOID, accel=a, peak=peak
        )

    def build(self) -> Program:
        p, setpoints = self.profile, self.setpoints
        for line in ("G21\n", "G90\n", "G94\n"):
            self.add(line)
        self.pen_lines(False)
        dwell_mode = p["motion.slow_lines"] == "dwell"
        run_points = []
        for index, run in enumerate(setpoints.runs):
            self.travel_to(run.xy[0])
            self.pen_lines(True)
            self.add("G93\n")
            begin = self.clock
            times, points = [begin], [self.here]
            slowest = slowest_durations(run.xy, p) if len(run.xy) > 1 else np.zeros(0)
            for k in range(1, len(run.t)):
                target = begin + float(run.t[k])
                duration = target - self.clock
                x, y = run.xy[k]
                if dwell_mode and duration > slowest[k - 1]:
                    # Grbl would run this move faster than planned: dwell first, rounded down
                    # to its 50 ms steps (what is left is carried into the next line), then
                    # move at the slowest rate Grbl steps.
                    surplus = duration - slowest[k - 1] - self.idle
                    steps = math.floor(surplus / DWELL_STEP + 1e-9)
                    if 0.5 * 10**-DECIMALS <= surplus < DWELL_STEP:
                        self.short_surplus += 1  # a G4 Grbl would have stretched to 50 ms
                    if steps >= 1:
                        self.add(
                            gcode.dwell(steps * DWELL_STEP, decimals=DECIMALS),
                            steps * DWELL_STEP,
                            stop=True,
                        )
                        self.dwells += 1
                        times.append(self.clock)
                        points.append(self.here)
                    duration = float(slowest[k - 1])
                # The time Grbl takes is that of F as sent (3 decimals).
                feed = float(gcode.fixed(60.0 / duration, DECIMALS))
                duration = 60.0 / feed
                line = gcode.move(float(x), float(y), feed=feed, decimals=DECIMALS)
                self.add(line, duration, xy=self.sent((x, y)), run=index, moves=True, kind=_LINEAR)
                times.append(self.clock)
                points.append(self.here)
            run_points.append((np.array(times), np.array(points, dtype=float)))
            self.add("G94\n")
            self.pen_lines(False)
        if p["motion.park"]:
            self.travel_to((p["motion.park_x"], p["motion.park_y"]))
        self.add("M5\n", stop=True)
        self.add("M2\n")
        for line in self.lines:  # every line must pass the same checks as gcode.make_line
            gcode.make_line(line[:-1])
        run = np.array(self.run, dtype=np.int64)
        start, end = np.array(self.start), np.array(self.end)
        waits = read_waits(self.lines, self.moves, self.sync, p)
        # Each wait lengthens its stop line; every later line moves by the waits before it.
        later = np.cumsum(waits)
        run_points = [
            (t + later[np.searchsorted(end, t, side="right") - 1], xy) for t, xy in run_points
        ]
        start, end = start + np.concatenate([[0.0], later[:-1]]), end + later
        drawing = sum(float(t[-1] - t[0]) for t, _ in run_points)
        return Program(
            lines=tuple(self.lines),
            line_start=start,
            line_end=end,
            line_xy=np.array(self.xy, dtype=float).reshape(-1, 2),
            line_pen=np.array(self.pen, dtype=bool),
            line_run=run,
            line_moves=np.array(self.moves, dtype=bool),
            run_plans=tuple(r.plan for r in setpoints.runs),
            run_scales=tuple(float(r.scale) for r in setpoints.runs),
            scale=float(setpoints.scale),
            drawing_time=drawing,
            min_buffered=_min_buffered(run, end - start, p["limits.planner_blocks"]),
            min_buffered_rx=_min_buffered(
                run, end - start, p["limits.planner_blocks"] - 1 + RX_LINES
            ),
            run_start_reserve=start_reserves(self.lines, self.moves, self.sync, run, end - start),
            run_points=tuple(run_points),
            notes={
                "travel_time": self.travel,
                "pen_time": self.pen_time,
                "dwells": float(self.dwells),
                # slow_lines = "dwell": surpluses under 50 ms, carried into the next line (the
                # program before issue 12 dwelt for each: Grbl waited 50 ms or more).
                "short_surpluses": float(self.short_surplus),
            },
            notes_kind=np.array(self.kind, dtype=np.int64),
            notes_accel=np.array(self.accel),
            notes_peak=np.array(self.peak),
            notes_start=np.array(self.origin, dtype=float),
        )


def read_waits(
    lines: list[str] | tuple[str, ...],
    moves: list[bool] | NDArray[np.bool_],
    sync: list[bool] | NDArray[np.bool_],
    profile: Profile,
) -> NDArray[np.float64]:
    """s each stop line (``sync``: it waits for the motion before it to end) adds while Grbl
    reads the lines after it before motion starts again.

    During a stop the host fills Grbl's receive buffer; after it the main loop reads on at
    ``serial.read_time`` a byte (as measured on Grbl 1.1h), faster than the wire brings more
    (10 bits a byte), and motion starts only when the next stop line is read, when the planner is
    full (a move beyond ``limits.planner_blocks`` is read) or when the buffer runs dry, whichever
    comes first: ``min(bytes read × read_time, 127 / (1/read_time − 1/byte_time))``.
    """
    read = profile["serial.read_time"]
    waits = np.zeros(len(lines))
    if read <= 0:
        return waits
    wire = 10.0 / profile["serial.baud"]
    dry = RX_BYTES / (1.0 / read - 1.0 / wire) if read < wire else math.inf
    blocks = profile["limits.planner_blocks"]
    for s in np.flatnonzero(np.asarray(sync, dtype=bool)):
        count = queued = 0
        for k in range(s + 1, len(lines)):
            count += len(lines[k])
            if sync[k]:
                break
            if moves[k]:
                queued += 1
                if queued > blocks:
                    break
        waits[s] = min(count * read, dry)
    return waits


RX_BYTES = 127
"""Bytes Grbl's receive ring holds (128, one slot always empty)."""


def start_reserves(
    lines: list[str] | tuple[str, ...],
    moves: list[bool] | NDArray[np.bool_],
    sync: list[bool] | NDArray[np.bool_],
    run: NDArray[np.int64],
    durations: NDArray[np.float64],
) -> tuple[float, ...]:
    """Per run, the motion (s) Grbl holds when the stop line before its first line ends: the
    moves among the lines after that stop that fit the receive buffer while the host still
    counts the stop line as outstanding (:data:`RX_BYTES` in all). ``inf`` for a run with no
    stop of its own before it, or that fits the buffer whole."""
    stops = np.flatnonzero(np.asarray(sync, dtype=bool))
    moving = np.asarray(moves, dtype=bool)
    out = []
    for k in np.unique(run[run >= 0]):
        rows = np.flatnonzero(run == k)
        before = stops[stops < rows[0]]
        held = math.inf
        if len(before) and not np.any(run[before[-1] + 1 : rows[0]] >= 0):
            stop = int(before[-1])
            room, total = RX_BYTES - len(lines[stop]), 0.0
            for i in range(stop + 1, rows[-1] + 1):
                room -= len(lines[i])
                if room < 0:
                    held = total
                    break
                total += float(durations[i]) if moving[i] else 0.0
        out.append(held)
    return tuple(out)


def _min_buffered(run: NDArray[np.int64], durations: NDArray[np.float64], blocks: int) -> float:
    """The least summed duration of ``blocks`` consecutive setpoint lines of one run (``inf``
    when every run has ``blocks`` lines or fewer: see :func:`~tagbot.plotter.place.buffered`)."""
    runs = np.unique(run[run >= 0])
    times = (np.concatenate([[0.0], np.cumsum(durations[run == k])]) for k in runs)
    return min((buffered(t, blocks) for t in times), default=math.inf)


def host_pause_warnings(program: Program, profile: Profile) -> list[str]:
    """A warning when a host pause mid-run can starve the machine sooner than
    ``motion.min_buffer`` asks: slowing did not lengthen the lines (module docstring of
    :mod:`tagbot.plotter.place`), so the placement kept the faster timing."""
    goal = buffer_goal(profile)
    held = program.min_buffered_rx
    if held >= goal * (1.0 - 1e-6):
        return []
    return [
        f"host pauses: the lines hold {held:.3f} s of motion mid-run at least, less than "
        f"motion.min_buffer = {goal:g} s (slowing the tag did not lengthen them: motion.max_dt "
        f"or Grbl's slowest step bounds them); a host pause longer than {held:.3f} s there "
        "starves the planner"
    ]


def resting_share(program: Program, profile: Profile) -> float:
    """Share of the planned pen-down motion time within one motor step of a run's ends."""
    if program.drawing_time <= 0:
        return 0.0
    return program.resting_time(step_box(profile)) / program.drawing_time


def _lround(value: float) -> int:
    """C's ``lround``: halves away from zero (Python's ``round`` goes to even)."""
    return int(math.copysign(math.floor(abs(value) + 0.5), value))
