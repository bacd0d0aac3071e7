"""What a simulated EBB executed, stored compactly and expanded to 40 µs ticks on demand.

Each motion-queue entry the board ran is a :class:`Segment`: its load tick, how many ticks it
ran (fewer than planned after ``ES`` or a reset), the motors' positions before it and, for a
stepper move, the :class:`~firmware_protocols.ebb.motion.Move` and accumulators it started
from, so its per-tick positions come again from the firmware arithmetic
(:func:`~firmware_protocols.ebb.motion.execute`). The pen servo is a list of
:class:`~sim.ebb.servo.ServoSegment`. Motor positions here are physical steps since the device
was made: ``CS``, ``EM`` and reboots clear the board's global counters, not these.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from firmware_protocols.ebb.motion import TICK_HZ, Move
from sim.ebb.servo import ServoSegment
from sim.ebb.steps import move_positions

__all__ = ["Recorder", "Segment", "Trace"]


@dataclass(frozen=True)
class Segment:
    """One executed motion-queue entry: ``kind`` is move, delay, servo or enable."""

    number: int
    """The entry's number in the order the board accepted motion commands (from 1)."""
    line: bytes
    kind: str
    load_tick: int
    """The tick that loaded it; it runs ticks ``load_tick + 1 .. load_tick + ticks``."""
    ticks: int
    origin: tuple[int, int]
    move: Move | None = None
    accumulators: tuple[int, int] = (0, 0)
    constant_rate_axes: tuple[bool, bool] = (False, False)
    """Axes of an ``SM``/``XM``/``HM`` move at the full rate 2**31 (a step every tick)."""

    def positions(self) -> np.ndarray:
        """``(ticks, 2)`` physical motor positions after each executed tick."""
        origin = np.asarray(self.origin, dtype=np.int64)
        out = np.broadcast_to(origin, (self.ticks, 2)).copy()
        if self.move is not None and self.ticks:
            relative = move_positions(self.move, self.accumulators, self.constant_rate_axes)[0]
            n = min(len(relative), self.ticks)
            out[:n] += relative[:n]
            if n < self.ticks and n:
                out[n:] += relative[n - 1]
        return out

    @property
    def end_tick(self) -> int:
        return self.load_tick + self.ticks


@dataclass
class Trace:
    """Executed motion sampled every tick: ``t`` (s), ``motor1``/``motor2`` (steps), ``pen``
    (servo pulse width, 1/12 MHz units)."""

    t: np.ndarray
    motor1: np.ndarray
    motor2: np.ndarray
    pen: np.ndarray


@dataclass
class Recorder:
    """The executed segments, pen servo segments and events (time, text) of one device."""

    segments: list[Segment] = field(default_factory=list)
    servo: list[ServoSegment] = field(default_factory=list)
    events: list[tuple[float, str]] = field(default_factory=list)

    def moves(self) -> list[Segment]:
        """The stepper moves only."""
        return [s for s in self.segments if s.kind == "move"]

    def last_move(self) -> Segment | None:
        moves = self.moves()
        return moves[-1] if moves else None

    def end_tick(self) -> int:
        return max((s.end_tick for s in self.segments), default=0)

    def pen_at(self, t: np.ndarray) -> np.ndarray:
        """The pen servo's pulse width at times ``t`` (0 before the first servo command)."""
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape, dtype=np.int64)
        starts = np.array([s.start for s in self.servo])
        if not len(starts):
            return out
        which = np.searchsorted(starts, t, side="right") - 1
        for i, segment in enumerate(self.servo):
            mask = which == i
            if mask.any():
                out[mask] = segment.at(t[mask])
        return out

    def trace(self, until: float | None = None) -> Trace:
        """Everything executed, one sample per 40 µs tick from tick 0 to ``until`` seconds
        (default: the end of the last segment)."""
        last = self.end_tick() if until is None else round(until * TICK_HZ)
        ticks = np.arange(last + 1, dtype=np.int64)
        motors = np.zeros((last + 1, 2), dtype=np.int64)
        filled = 0
        position = np.zeros(2, dtype=np.int64)
        for segment in sorted(self.segments, key=lambda s: s.load_tick):
            if segment.load_tick > last:
                break
            motors[filled : segment.load_tick + 1] = position
            positions = segment.positions()[: max(0, last - segment.load_tick)]
            motors[segment.load_tick + 1 : segment.load_tick + 1 + len(positions)] = positions
            filled = segment.load_tick + 1 + len(positions)
            if len(positions):
                position = positions[-1]
            else:
                position = np.asarray(segment.origin, dtype=np.int64)
        motors[filled:] = position
        t = ticks / TICK_HZ
        return Trace(t, motors[:, 0], motors[:, 1], self.pen_at(t))
