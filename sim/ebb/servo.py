"""The EBB's pen-lift servo pulse: a target approached by a fixed rate once per PWM cycle.

The firmware's RC servo output cycles through ``channels`` slots of ``slot_ms`` each (8 x 3 ms
at boot, ``SC,8``/``SC,9``): the pen servo's pulse width (units of 1/12 MHz, 83.3 ns) moves
toward its target by ``rate`` once per cycle (at once when ``rate`` is 0), never past it. The
cycle is counted from boot, so the updates fall at ``boot + k * period`` (k = 1, 2, ...).
:class:`ServoSegment` is one target from its start: its value at any time is exact and
vectorised, which both the device (``QP``/``QG``/``QR``) and the recorder use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["PULSE_HZ", "ServoSegment", "servo_travel_time"]

PULSE_HZ = 12_000_000
"""Servo pulse-width units per second (one unit is 83.3 ns)."""


@dataclass(frozen=True)
class ServoSegment:
    """The pulse width from ``start`` (seconds) on: ``value`` then, moving to ``target``."""

    start: float
    value: int
    target: int
    rate: int
    period: float
    """Seconds per PWM cycle (channels x slot duration)."""
    boot: float = 0.0
    """When the cycle count started (the board's boot)."""

    def updates(self, t: np.ndarray | float) -> np.ndarray:
        """How many PWM cycle updates fall in ``(start, t]``."""
        t = np.asarray(t, dtype=float)
        first = math.floor((self.start - self.boot) / self.period + 1e-9) + 1
        last = np.floor((t - self.boot) / self.period + 1e-9).astype(np.int64)
        return np.maximum(last - first + 1, 0)

    def at(self, t: np.ndarray | float) -> np.ndarray:
        """The pulse width at time(s) ``t >= start`` (int64)."""
        n = self.updates(t)
        distance = self.target - self.value
        if self.rate == 0:
            moved = np.where(n > 0, abs(distance), 0)
        else:
            moved = np.minimum(n * self.rate, abs(distance))
        return self.value + np.sign(distance) * moved

    def arrival(self) -> float:
        """When the pulse width reaches the target (``start`` if it is there already)."""
        distance = abs(self.target - self.value)
        if distance == 0:
            return self.start
        cycles = 1 if self.rate == 0 else -(-distance // self.rate)
        first = math.floor((self.start - self.boot) / self.period + 1e-9) + 1
        return self.boot + (first + cycles - 1) * self.period


def servo_travel_time(distance: int, rate: int, period: float = 0.024) -> float:
    """Seconds a move of ``distance`` pulse units takes at ``rate`` per cycle (reference FAQ)."""
    if distance == 0:
        return 0.0
    return period * (1 if rate == 0 else -(-abs(distance) // rate))
