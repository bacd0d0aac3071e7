"""The placed, retimed tag as the EiBotBoard's own moves, each one's every tick known exactly.

**Motors.** Motor 1 turns with ``x + y``, motor 2 with ``x − y``: a machine position ``(x, y)`` mm
is the motor position ``m = k·(x + y, x − y)`` steps (``k`` steps per mm,
:attr:`~tagbot.axidraw.profile.Profile.steps_per_mm`).

**Drawing** (``T3``; ``LT`` with ``motion.jerk = false``). Between consecutive setpoints of a
pen-down run (the plotter's placement and retiming by run, :func:`tagbot.plotter.place.place`)
one move of ``n`` ticks (40 µs; the setpoint times rounded to the tick grid, so no rounding
accumulates). At tick ``k`` the firmware adds ``R_k = r + a·k + j·k(k+1)/2`` to each axis's
accumulator (``r, a, j`` the loaded rate, acceleration and jerk) and steps whenever it passes a
multiple of 2³¹, so an axis holds ``P = p + accumulator / 2³¹`` steps, a cubic in time over the
move (a quadratic for ``LT``). Per axis: the jerk makes the rate start and end at the planned
velocities and the distance exact (the jerk rounded to an integer, what it leaves balanced
between both ends); the acceleration is the planned change of rate; ``r`` is the integer that
makes ``P`` end on ``m + ½`` at the next setpoint (``m`` the setpoint's motor position): the
executed step position ``floor(P)`` is then ``m`` rounded, exactly, the firmware's own arithmetic
(:mod:`firmware_protocols.ebb.motion`) deciding. The accumulators carry from move to move (never
cleared): no fraction of a step is lost, and the rate is continuous from move to move. A run
starts with a 2 ms move (:data:`SETTLE`) that takes up the fraction of a step by which the pen
went down away from the plan's first point, so the next move starts on the plan.

**The error, stated.** Every tick's step position is computed with the firmware's arithmetic
(:func:`~firmware_protocols.ebb.motion.execute`) and compared with the plan's continuous motion
at that tick: :attr:`Job.move_error` (mm, the largest distance over each move's ticks) and
:attr:`Job.run_error` (each run's largest). It is half a step per motor away from ``P`` (at most
``½/k`` mm: 0.00625 mm at 80 steps/mm), plus how far ``P`` strays from the plan within a move,
plus, in a run's first 2 ms, up to a step more. A move that strays more than
:data:`SPLIT_ERROR` (0.012 mm) is split at its middle tick, onto the plan's position and
velocity there, down to 4 ms halves, and the run built again. Measured on ``cae.json``
(AxiDraw V3): at ``motion.dt`` = 10, 30, 50, 100 ms 0.0062, 0.0063, 0.0072, 0.0118 mm with
``T3`` (1467, 511, 313, 191 moves; 100 ms setpoints need 34 splits); 0.011, 0.0115, 0.0116,
0.012 mm with ``LT`` (0.022 and 0.044 mm at 100 ms before splitting); at the default 25 ms
0.0063 mm with ``T3`` (608 moves), 0.0116 mm with ``LT``.

**Each run's move length, as it needs.** The speed a run is judged by is its position's change
over ±10 ms (:data:`SPEED_WINDOW`, the comparison's). Whole motor steps cost a run a speed
error of their own: each motor's rounding is uniform over a step, so its speed over 20 ms
errs with variance ``2 × (1/12) / 0.02²`` steps²/s², and the run's speed SNR can be no better
than its plan's speed energy over that (:attr:`Job.run_step_snr`: 28-51 dB on the development
tags' runs, the slow short ones lowest). The moves' own error is the exact motion's (the
accumulators' fractions kept: ``C_k / 2³¹`` steps) against the plan, taken over the same
±10 ms (:attr:`Job.run_speed_snr`). While a run's moves err by more than the steps'
:data:`SPEED_MARGIN_DB` (15 dB) below, the moves with more than their share are split at their
middle tick (halves of 10 ms at least) and the run built again: then they take at most
0.14 dB from its speed SNR. At the default 25 ms no run of the 49 development tags needs it
(their moves stay 19.2 dB or more under their steps: BENCHMARKS.md, session 21); with
``motion.dt = 0.1`` two of cae's three runs have most of their moves halved, letter-b's run
none. Shorter moves need a deeper FIFO to keep
the board as far ahead: :attr:`Job.fifo` (:func:`fifo_depth`) holds ``serial.fifo`` x
``motion.dt`` s of the job in every stretch of commands the board holds at once (0.275 s by
default: 11 x 25 ms), up to the firmware's 32.

**Travel** (``LM``, pen up): a trapezoid along the longer motor axis at ``limits.travel_speed``
and ``limits.travel_acceleration`` (accelerate, cruise, decelerate: three ``LM``, step-exact per
axis, the other motor's rates in proportion so both finish together), from and to a crawl of
1 ms of acceleration (never a zero rate, where firmware 3 would reverse).

**Pen**: ``SP,0`` / ``SP,1`` with the servo's travel time as the board's own delay
(:meth:`~tagbot.axidraw.profile.Profile.pen_time`), lifted as soon as a run's last move ends.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from firmware_protocols.ebb.motion import ACCUMULATOR_STEP, TICK_HZ, AxisStart, Move, execute
from tagbot.axidraw.profile import MOTOR_AXES, Profile
from tagbot.errors import PlacementError
from tagbot.model import Tag
from tagbot.model.motion import evaluate_plan
from tagbot.plotter.place import Run, Setpoints

__all__ = ["Entry", "Job", "build_job", "run_reference", "steps_to_xy"]

Array = NDArray[np.float64]
Steps = tuple[int, int]

SETTLE = 0.002
"""s: with ``T3``, a run's first move, which takes up the pen-down position's fraction of a step
(module docstring)."""
SPLIT_ERROR = 0.012
"""mm: a drawing move whose ticks stray further from the plan is split in two (half a step per
motor, 0.0088 mm at 80 steps/mm, is the position's own rounding; the rest is the move's cubic
missing the plan, which halving a move divides by about 16)."""
MIN_SPLIT_TICKS = 100
"""Ticks (4 ms): a move is split only into halves this long at least."""
SPEED_WINDOW = 0.01
"""s: the speed a run is judged by is the position's change over ±this (``report.json``'s
comparison: central differences on a 10 ms grid); the moves' own speed error is taken alike."""
SPEED_MARGIN_DB = 15.0
"""dB: each run's moves keep their own speed error this far under what whole motor steps cost
the run (they then take at most 0.14 dB from its speed SNR; module docstring)."""
MIN_SPEED_SPLIT_TICKS = 250
"""Ticks (10 ms): a move is split for its speed only into halves this long at least (with
the FIFO's 33 moves, 0.33 s of drawing: the board is never left short, ``Job.fifo``)."""
CRAWL = 0.001
"""s of travel acceleration a pen-up move starts and ends at (its slowest rate)."""
_MAX_RATE = ACCUMULATOR_STEP - 1
"""The largest per-tick accumulator increment: one step per tick."""


@dataclass(frozen=True)
class Entry:
    """One command of the job, in the order sent."""

    kind: str
    """``"travel"`` (LM), ``"draw"`` (T3 or LT), ``"pen"`` (SP)."""
    line: bytes
    start: float
    """Planned start on the job's clock, s."""
    duration: float
    run: int
    """The pen-down run (index in :attr:`Job.runs`) a draw move or a pen move belongs to; -1."""
    steps: Steps
    """Global motor step position once it has executed."""
    pen: bool
    """Pen down once it has executed."""
    move: Move | None = None

    @property
    def end(self) -> float:
        return self.start + self.duration


@dataclass(eq=False)
class Job:
    """A whole job: commands, their exact ticks, and the stated error against the plan."""

    entries: list[Entry]
    runs: list[Run]
    run_start: list[float]
    """Each run's first draw move's start on the job's clock, s."""
    ticks: NDArray[np.int64]
    """``(T, 2)``: the global step position after every tick of motion (draw and travel)."""
    tick_time: Array
    """``(T,)``: when each of :attr:`ticks` happens on the job's clock, s."""
    move_error: Array
    """Per entry: the largest distance, mm, between its executed and planned positions at every
    tick (draw moves; 0 for the others)."""
    run_error: list[float]
    steps_per_mm: float
    pen_at: list[tuple[float, bool]] = field(default_factory=list)
    """``(time, down)`` at each pen command's start."""
    run_speed_snr: list[float] = field(default_factory=list)
    """Per run: the speed SNR, dB, of its moves' exact motion (the accumulators' fractions
    kept) against the plan, speeds taken as in the comparison (:data:`SPEED_WINDOW`); inf for a
    run too short to have one."""
    run_step_snr: list[float] = field(default_factory=list)
    """Per run: the speed SNR, dB, whole motor steps allow it (the plan's speed against the
    rounding's expected noise, half a step either way on each motor; module docstring)."""
    fifo: int = 1
    """The motion FIFO depth the job asks (``CU,4``): ``serial.fifo`` at least, deeper where its
    moves are short, so that the board always holds ``serial.fifo`` x ``motion.dt`` s of the job
    (:func:`fifo_depth`)."""

    @property
    def duration(self) -> float:
        return self.entries[-1].end if self.entries else 0.0

    def xy(self, steps: NDArray[np.int64] | Sequence[int]) -> Array:
        """Machine mm of global motor step positions ``(…, 2)``."""
        return steps_to_xy(steps, self.steps_per_mm)

    def planned_runs(self) -> list[tuple[Array, Array]]:
        """Per run: the setpoint times on the job's clock and their positions, mm."""
        return [(start + r.t, r.xy) for r, start in zip(self.runs, self.run_start, strict=True)]


def steps_to_xy(steps: NDArray[np.int64] | Sequence[int], k: float) -> Array:
    """Machine mm of global motor step positions ``(…, 2)`` at ``k`` steps per mm."""
    return np.asarray(steps, dtype=float) @ np.linalg.inv(MOTOR_AXES).T / k


def run_reference(tag: Tag, run: Run, matrix: Array, offset: Array) -> Callable[[Array], Array]:
    """The plan's continuous position, mm, at times ``t`` s of ``run``'s clock."""
    plan = tag.plans[run.plan]

    def at(t: Array) -> Array:
        p, _ = evaluate_plan(plan, run.clock.tag_time(np.asarray(t) / run.scale), tag.size)
        return p @ matrix.T + offset

    return at


def build_job(tag: Tag, setpoints: Setpoints, profile: Profile, start: Steps = (0, 0)) -> Job:
    """Every command of the job from the home position ``start`` (global steps): travel, pen
    down, the run's ``T3`` (or ``LT``) moves, pen up, ... and back to the park position."""
    k = profile.steps_per_mm
    builder = _Builder(profile, start)
    for run in setpoints.runs:  # a dot (one setpoint): pen down and up there
        reference = run_reference(tag, run, setpoints.matrix, setpoints.offset)
        builder.travel(_motor(run.xy[0], k))
        builder.pen(down=True, run=len(builder.runs))
        builder.draw(run, reference)
        builder.pen(down=False, run=len(builder.runs) - 1)
    if profile["motion.park"]:
        builder.travel(_motor(np.array([profile["motion.park_x"], profile["motion.park_y"]]), k))
    job = builder.job()
    base = int(profile["serial.fifo"])
    job.fifo = fifo_depth([e.duration for e in job.entries], base, base * profile["motion.dt"])
    return job


FIFO_MAX = 32
"""The deepest motion FIFO firmware 3.0 has (``QU,2``)."""


def fifo_depth(durations: Sequence[float], least: int, ahead: float) -> int:
    """The FIFO depth (at least ``least``, at most :data:`FIFO_MAX`) with which every run of
    consecutive commands the board holds at once (the FIFO's and the one executing) lasts
    ``ahead`` s at least: the time the host may be late without the board running dry."""
    total = np.concatenate([[0.0], np.cumsum(durations)])
    for depth in range(max(1, least), FIFO_MAX):
        held = depth + 1
        if held >= len(total) - 1 or (total[held:] - total[:-held]).min() >= ahead - 1e-9:
            return depth
    return FIFO_MAX


def _motor(xy: Array, k: float) -> Steps:
    """The nearest global motor step position of machine position ``xy``."""
    m = np.floor(MOTOR_AXES @ xy * k + 0.5).astype(np.int64)
    return int(m[0]), int(m[1])


class _Builder:
    """The job so far: where the motors are (steps and accumulators) and when."""

    def __init__(self, profile: Profile, start: Steps) -> None:
        self.profile = profile
        self.k = profile.steps_per_mm
        self.steps = start
        self.accumulators: Steps = (0, 0)
        self.time = 0.0
        self.down = False
        self.entries: list[Entry] = []
        self.errors: list[float] = []
        self.runs: list[Run] = []
        self.run_start: list[float] = []
        self.run_error: list[float] = []
        self.tick_parts: list[NDArray[np.int64]] = []
        self.time_parts: list[Array] = []
        self.pen_at: list[tuple[float, bool]] = []
        self.speed_noise: list[float] = []
        self.run_speed_snr: list[float] = []
        self.run_step_snr: list[float] = []

    def _add(self, kind: str, move: Move | None, line: bytes, duration: float, run: int) -> None:
        self.entries.append(
            Entry(kind, line, self.time, duration, run, self.steps, self.down, move)
        )
        self.errors.append(0.0)
        self.speed_noise.append(0.0)
        self.time += duration

    def _motion(self, kind: str, move: Move, run: int) -> NDArray[np.int64]:
        """Execute ``move`` with the firmware's arithmetic; record its ticks; return them."""
        relative, self.accumulators = execute(move, self.accumulators)
        ticks = relative + np.asarray(self.steps, dtype=np.int64)
        self.tick_parts.append(ticks)
        self.time_parts.append(self.time + np.arange(1, len(ticks) + 1) / TICK_HZ)
        if len(ticks):
            self.steps = int(ticks[-1, 0]), int(ticks[-1, 1])
        self._add(kind, move, move.line(), len(ticks) / TICK_HZ, run)
        return ticks

    def pen(self, *, down: bool, run: int) -> None:
        p = self.profile
        ms = round(1000.0 * p.pen_time(down))
        self.pen_at.append((self.time, down))
        self.down = down
        line = f"SP,{0 if down else 1},{max(ms, 1)},{p['pen.pin']}\r".encode()
        self._add("pen", None, line, max(ms, 1) / 1000.0, run)

    def travel(self, target: Steps) -> None:
        """Pen-up ``LM`` moves from here to ``target`` (none if already there)."""
        delta = (target[0] - self.steps[0], target[1] - self.steps[1])
        for move in _travel_moves(delta, self.profile):
            self._motion("travel", move, -1)
        if self.steps != target:  # pragma: no cover - LM is step-exact
            raise RuntimeError(f"travel ended at {self.steps}, not {target}")

    def draw(self, run: Run, reference: Callable[[Array], Array]) -> None:
        """``T3`` (or ``LT``) moves through the run's setpoints (module docstring); a move whose
        ticks stray more than :data:`SPLIT_ERROR` from the plan is split at its middle tick
        (the plan's position and velocity there) and the run built again."""
        index = len(self.runs)
        self.runs.append(run)
        self.run_start.append(self.time)
        before = (len(self.entries), len(self.errors), len(self.tick_parts), len(self.time_parts))
        state = (self.steps, self.accumulators, self.time)
        splits: list[int] = []
        while True:
            starts, allowed = self._draw(run, reference, index, splits)
            first = before[0]
            errors, noise = self.errors[first:], self.speed_noise[first:]
            lengths = np.diff(starts)
            wide = [
                g + n // 2
                for g, n, e in zip(starts[:-1], lengths, errors, strict=True)
                if e > SPLIT_ERROR and n >= 2 * MIN_SPLIT_TICKS
            ]
            if not wide and sum(noise) > allowed:  # too fast a change for its moves' length
                share = allowed / len(noise)
                wide = [
                    g + n // 2
                    for g, n, e in zip(starts[:-1], lengths, noise, strict=True)
                    if e > share and n >= 2 * MIN_SPEED_SPLIT_TICKS
                ]
            if not wide:
                break
            splits += wide
            del self.entries[before[0] :], self.errors[before[1] :]
            del self.speed_noise[before[1] :]
            del self.tick_parts[before[2] :], self.time_parts[before[3] :]
            self.steps, self.accumulators, self.time = state
        if starts[-1] == starts[0]:  # a dot: no move
            here = steps_to_xy(self.steps, self.k) - reference(np.zeros(1))[0]
            self.run_error.append(float(np.hypot(*here)))
        else:
            self.run_error.append(float(max(self.errors[before[1] :])))
        self.run_speed_snr.append(self._snr)
        self.run_step_snr.append(self._step_snr)

    def _draw(
        self, run: Run, reference: Callable[[Array], Array], index: int, splits: list[int]
    ) -> tuple[list[int], float]:
        """The run's moves through its setpoints and the ``splits`` (ticks of the run's clock);
        each move's largest error in :attr:`errors` and its speed error in
        :attr:`speed_noise` (:func:`_speed_figures`). Returns the moves' start ticks and the
        last one's end, and the speed error the run's moves may have in all."""
        command = "T3" if self.profile["motion.jerk"] else "LT"
        t, xy, v = run.t, run.xy, run.v
        if command == "T3" and len(t) > 1 and t[1] > 2 * SETTLE:
            # A short first move takes up where the pen went down, so that the next one starts
            # on the plan, at the planned rate.
            here, ahead = reference(np.array([SETTLE, SETTLE + 1.0 / TICK_HZ]))
            t = np.insert(t, 1, SETTLE)
            xy = np.insert(xy, 1, here, axis=0)
            v = np.insert(v, 1, (ahead - here) * TICK_HZ, axis=0)
        if splits:
            at = np.asarray(sorted(splits), dtype=float) / TICK_HZ
            step = 1.0 / TICK_HZ
            order = np.argsort(np.concatenate([t, at]), kind="stable")
            t = np.concatenate([t, at])[order]
            xy = np.vstack([xy, reference(at)])[order]
            rates = (reference(at + step) - reference(at - step)) / (2 * step)
            v = np.vstack([v, rates])[order]
        grid = np.round(t * TICK_HZ).astype(np.int64)
        keep = np.concatenate([[True], np.diff(grid) > 0])
        grid, m, v = grid[keep], xy[keep] @ MOTOR_AXES.T * self.k, v[keep] @ MOTOR_AXES.T
        target = np.floor(m + 0.5).astype(np.int64)
        # Accumulator-unit positions (m + 1/2) and per-tick rates (velocity) at the setpoints.
        aim = [[round((float(x) + 0.5) * ACCUMULATOR_STEP) for x in row] for row in m]
        rate = (v * self.k * (ACCUMULATOR_STEP / TICK_HZ)).tolist()
        first, parts = len(self.entries), len(self.tick_parts)
        exact = [_fraction(self.steps, self.accumulators)]  # the exact motion, steps
        for i in range(len(grid) - 1):
            n = int(grid[i + 1] - grid[i])
            goal = (int(target[i + 1, 0]), int(target[i + 1, 1]))
            axes = [
                _axis(
                    n,
                    self.accumulators[j],
                    aim[i + 1][j] - self.steps[j] * ACCUMULATOR_STEP,
                    (rate[i][j], rate[i + 1][j]),
                    goal[j] - self.steps[j],
                    # A run's first move takes up where the pen went down (within a step of
                    # its first point): no end rates to hold it to.
                    command == "T3" and i > 0,
                )
                for j in (0, 1)
            ]
            move = Move(
                command=command,  # type: ignore[arg-type]
                ticks=n,
                rate=(axes[0][0], axes[1][0]),
                accel=(axes[0][1], axes[1][1]),
                jerk=(axes[0][2], axes[1][2]) if command == "T3" else (0, 0),
            )
            _check_rates(move)
            exact.append(_fraction(self.steps, self.accumulators) + _exact(move))
            self._motion("draw", move, index)
            if self.steps != goal:  # pragma: no cover - _axis ends on its target by construction
                raise RuntimeError(f"a {command} move ended at {self.steps}, not {goal}")
        # The error at every tick of the run, and each move's largest.
        ticks = self.tick_parts[parts:]
        self._snr = self._step_snr = math.inf
        allowed = math.inf
        if ticks:
            times = np.concatenate(self.time_parts[parts:]) - self.run_start[index]
            planned = reference(np.concatenate([[0.0], times]))
            gap = np.hypot(*(steps_to_xy(np.concatenate(ticks), self.k) - planned[1:]).T)
            bounds = np.cumsum([0] + [len(t) for t in ticks[:-1]])
            self.errors[first:] = np.maximum.reduceat(gap, bounds).tolist()
            # Motor steps: the rounding (m + 1/2 aimed at, floor executed) taken out.
            motion = np.concatenate(exact) - 0.5
            figures = _speed_figures(motion, planned @ MOTOR_AXES.T * self.k, bounds)
            if figures is not None:
                per_move, signal, steps_noise = figures
                self.speed_noise[first:] = per_move.tolist()
                self._snr = _db(signal, float(per_move.sum()))
                self._step_snr = _db(signal, steps_noise)
                allowed = steps_noise * 10.0 ** (-SPEED_MARGIN_DB / 10.0)
        return [int(g) for g in grid], allowed

    def job(self) -> Job:
        ticks = np.concatenate(self.tick_parts) if self.tick_parts else np.zeros((0, 2), np.int64)
        times = np.concatenate(self.time_parts) if self.time_parts else np.zeros(0)
        return Job(
            self.entries,
            self.runs,
            self.run_start,
            ticks,
            times,
            np.asarray(self.errors),
            self.run_error,
            self.k,
            self.pen_at,
            self.run_speed_snr,
            self.run_step_snr,
        )


def _fraction(steps: Steps, accumulators: Steps) -> Array:
    """The exact position, steps, of motors at ``steps`` holding ``accumulators``."""
    return (np.asarray(steps, dtype=float) + np.asarray(accumulators) / ACCUMULATOR_STEP)[None]


def _exact(move: Move) -> Array:
    """``(n, 2)``: an ``LT``/``T3`` move's exact motion after each tick, steps from its start
    (the sum of its rates, ``C_k − acc_0``, over 2³¹; :mod:`firmware_protocols.ebb.motion`)."""
    k = np.arange(1, move.ticks + 1, dtype=np.int64)
    columns = []
    for axis in (0, 1):
        jerk = move.jerk[axis] if move.command == "T3" else 0
        start = AxisStart.load(move.rate[axis], move.accel[axis], jerk)
        rates = start.rate + k * start.accel + start.jerk * (k * (k + 1) // 2)
        columns.append(np.cumsum(rates) / ACCUMULATOR_STEP)
    return np.column_stack(columns)


def _speed_figures(
    motion: Array, planned: Array, bounds: NDArray[np.int64]
) -> tuple[Array, float, float] | None:
    """A run's speed figures, motor steps (``motion``, ``planned``: ``(N + 1, 2)`` at its ticks
    0..N; ``bounds``: each move's first tick, 0-based from tick 1), speeds taken over
    ±:data:`SPEED_WINDOW`: each move's squared speed error summed over the instants within it,
    the plan's squared speed summed, and the sum whole steps would cost (each motor's rounding
    uniform over a step, independent at both ends: variance 2 × 1/12 / (2·window)² a motor).
    None for a run shorter than two windows."""
    half = round(SPEED_WINDOW * TICK_HZ)
    if len(planned) <= 2 * half:
        return None
    span = 2 * half / TICK_HZ
    error = motion - planned
    speed_error = (error[2 * half :] - error[: -2 * half]) / span
    speed = (planned[2 * half :] - planned[: -2 * half]) / span
    centre = np.arange(half, len(planned) - half)  # the tick each speed is taken at
    mover = np.clip(np.searchsorted(bounds, centre - 1, side="right") - 1, 0, len(bounds) - 1)
    per_move = np.bincount(mover, (speed_error**2).sum(axis=1), minlength=len(bounds))
    steps_noise = len(centre) * 2 * (2.0 / 12.0) / span**2
    return per_move, float((speed**2).sum()), steps_noise


def _db(signal: float, noise: float) -> float:
    """``10·log10(signal / noise)``; inf without noise."""
    if noise <= 0:
        return math.inf
    return 10.0 * math.log10(signal / noise) if signal > 0 else -math.inf


def _ceil_div(a: int, b: int) -> int:
    return -((-a) // b)


def _axis(
    n: int, accumulator: int, aim: int, rates: tuple[float, float], goal: int, jerk: bool
) -> tuple[int, int, int]:
    """``(Rate, Accel, Jerk)`` of one axis of an ``n``-tick ``T3`` (``LT``: no jerk).

    From ``accumulator`` (the step position is 0 here) to ``aim`` accumulator units, the rate
    per tick going from ``rates[0]`` to ``rates[1]`` as planned, ending on step ``goal`` in the
    firmware's arithmetic (``R_k = r + a·k + j·k(k+1)/2`` at tick ``k``).
    """
    v0, v1 = rates
    half = n * (n + 1) // 2
    sixth = n * (n + 1) * (n + 2) // 6
    if jerk and n > 2:
        # The rate at the move's ends (ticks 1/2 and n + 1/2) as planned, and the distance.
        system = np.array(
            [
                [1.0, 0.5, 0.375],
                [1.0, n + 0.5, (n + 0.5) * (n + 1.5) / 2],
                [n, half, sixth],
            ]
        )
        j = round(float(np.linalg.solve(system, [v0, v1, aim - accumulator])[2]))
        # What the whole jerk leaves to the acceleration and the rate (below, as for LT).
        v0 -= 0.375 * j
        v1 -= j * (n + 0.5) * (n + 1.5) / 2
    else:
        j = 0
    a = round((v1 - v0) / n)
    # r: the nearest integer that makes the ticks add up to `aim`, then into the goal's step.
    base = aim - accumulator - a * half - j * sixth
    r = (2 * base + n) // (2 * n)
    end = accumulator + r * n + a * half + j * sixth
    low, high = goal * ACCUMULATOR_STEP, (goal + 1) * ACCUMULATOR_STEP - 1
    if end < low:
        r += _ceil_div(low - end, n)
    elif end > high:
        r -= _ceil_div(end - high, n)
    # The command's parameters from the loaded ones (rate - accel/2 + jerk/6, accel - jerk).
    accel = a + j
    return r + int(accel / 2) - int(j / 6), accel, j


def _check_rates(move: Move) -> None:
    """Refuse a move any axis of which would have to step more than once per tick."""
    n = move.ticks
    for rate, accel, jerk in zip(move.rate, move.accel, move.jerk, strict=True):
        r, a = rate - int(accel / 2) + int(jerk / 6), accel - jerk
        ticks = [1, n] + ([round(-a / jerk - 0.5)] if jerk and 1 < -a / jerk - 0.5 < n else [])
        fastest = max(abs(r + a * k + jerk * k * (k + 1) // 2) for k in ticks)
        if fastest > _MAX_RATE or max(abs(rate), abs(accel), abs(jerk)) > _MAX_RATE:
            raise PlacementError(
                f"motion: a drawing move needs {fastest / ACCUMULATOR_STEP * TICK_HZ:.0f} steps/s"
                f" on a motor, beyond the EBB's {TICK_HZ} (lower limits.draw_speed)"
            )


def _travel_moves(delta: Steps, profile: Profile) -> list[Move]:
    """``LM`` moves of a pen-up travel by ``delta`` steps (module docstring)."""
    longest = max(abs(delta[0]), abs(delta[1]))
    if longest == 0:
        return []
    k = profile.steps_per_mm
    vmax = profile["limits.travel_speed"] * k  # steps/s along the longer motor axis
    amax = profile["limits.travel_acceleration"] * k
    unit = ACCUMULATOR_STEP / TICK_HZ  # rate units per step/s
    v0 = min(vmax, amax * CRAWL)
    peak = min(vmax, math.sqrt(longest * amax + v0 * v0))
    ramp = min(longest // 2, round((peak * peak - v0 * v0) / (2.0 * amax)))
    if ramp == 0:  # a few steps: one move at the crawl
        phases = [(longest, v0 * unit, 0.0)]
    else:
        # Rates per tick and the constant change that takes v0 to the peak over `ramp` steps.
        r0, r1 = v0 * unit, peak * unit
        accel = (r1 * r1 - r0 * r0) / (2.0 * ramp * ACCUMULATOR_STEP)
        phases = [(ramp, r0, accel), (longest - 2 * ramp, r1, 0.0), (ramp, r1, -accel)]
    moves = []
    done = [0, 0]
    covered = 0
    for steps, rate, accel in phases:
        covered += steps
        share = [round(d * covered / longest) - done[j] for j, d in enumerate(delta)]
        done = [done[j] + share[j] for j in (0, 1)]
        if share == [0, 0]:
            continue
        scale = [abs(s) / steps for s in share]
        moves.append(
            Move(
                command="LM",
                rate=(_lm_rate(rate * scale[0], share[0]), _lm_rate(rate * scale[1], share[1])),
                steps=(share[0], share[1]),
                accel=(round(accel * scale[0]), round(accel * scale[1])),
            )
        )
    return moves


def _lm_rate(rate: float, steps: int) -> int:
    """An ``LM`` axis's rate: at least 1 when it has steps to take, 0 when it has none."""
    return max(1, round(rate)) if steps else 0
