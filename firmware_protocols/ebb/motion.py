"""The EBB firmware 3.x low-level moves (``LM``, ``LT``, ``T3``) to the step and the accumulator.

Reference sections "LM — Low-level Move, Step-limited", "LT — Low-level Move, Time-limited",
"T3 — Low-level Move with Jerk, Time Limited"; the arithmetic is that of firmware 3.0's
``process_low_level_move`` (at parse time) and its 25 kHz stepper ISR:

- at parse time, per axis (32-bit signed, wrapping): ``LM`` with ``Steps < 0`` and ``Rate >= 0``
  negates ``Steps``, ``Rate`` and ``Accel`` (``Rate < 0`` too is ``!6``); then
  ``Rate -= Accel / 2`` and ``Rate += Jerk / 6`` (C division, truncating toward zero), and
  ``Accel -= Jerk``. A clear bit sets the accumulator, when the move is loaded, to ``2**31 - 1``
  if the first tick's rate ``Rate + Accel`` is negative (or zero and ``Accel + Jerk`` negative,
  or both zero and ``Jerk`` negative), else to 0.
- every tick of 40 µs, per active axis: ``Accel += Jerk; Rate += Accel; acc += Rate`` (acc is
  unsigned 32-bit, always below ``2**31`` between ticks); if bit 31 of acc is set it is cleared
  and one step is taken, in the direction of ``Rate``'s sign. ``LM`` counts every step (either
  direction) and the axis stops when it has taken ``|Steps|``; ``LT``/``T3`` run both axes for
  ``Intervals`` ticks. The next move is loaded in the same tick, so moves follow without a gap.

Hence, writing ``C_k = acc_0 + R_1 + ... + R_k`` with ``R_k`` the (wrapped) rate of tick ``k``,
the position after tick ``k`` is ``floor(C_k / 2**31)`` and the accumulator ``C_k mod 2**31``:
a negative rate reverses the motor (firmware 3.x; 2.x behaved differently and is not supported,
see :mod:`.commands`). ``R_k = r + k·a + j·k(k+1)/2`` with ``r, a, j`` the loaded values, so the
final state has a closed form (:func:`axis_final`) and per-tick positions are two cumulative sums
in int64 (:func:`axis_positions`): ``|R_k| <= 2**31`` and a move materialised per tick has at
most :data:`MAX_TICKS` ticks, so ``|C_k| < 2**31 (MAX_TICKS + 1)`` cannot overflow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from .errors import INVALID_PARAMETER, EBBCommandError, MoveTooLong

TICK_HZ = 25_000
"""Stepper ISR rate, Hz (one update every 40 µs)."""
ACCUMULATOR_STEP = 2**31
"""Accumulator units per motor step."""
NEGATIVE_CLEAR = ACCUMULATOR_STEP - 1
"""Accumulator value a clear bit loads when the axis starts in the negative direction."""
MAX_TICKS = 2**24
"""Longest move the per-tick functions materialise (671 s); longer ones raise MoveTooLong."""

_INT32_MIN = -(2**31)
_INT32_MAX = 2**31 - 1
_UINT32_MAX = 2**32 - 1
_ACC_MASK = ACCUMULATOR_STEP - 1


def wrap32(value: int) -> int:
    """``value`` as the firmware's signed 32-bit variable holds it (two's complement wrap)."""
    return ((value + 2**31) & _UINT32_MAX) - 2**31


def _cdiv(value: int, divisor: int) -> int:
    """C integer division (truncates toward zero)."""
    quotient = abs(value) // divisor
    return quotient if value >= 0 else -quotient


@dataclass(frozen=True)
class AxisStart:
    """One axis as the ISR holds it when the move is loaded: rate, accel and jerk per tick."""

    rate: int
    accel: int
    jerk: int

    @classmethod
    def load(cls, rate: int, accel: int, jerk: int = 0) -> AxisStart:
        """The parse-time adjustment of a command's Rate, Accel and Jerk (wrapping int32)."""
        loaded_rate = wrap32(wrap32(rate - _cdiv(accel, 2)) + _cdiv(jerk, 6))
        return cls(loaded_rate, wrap32(accel - jerk), jerk)

    def rate_at(self, tick: int) -> int:
        """The exact (unwrapped) rate of tick ``tick`` (1-based)."""
        return self.rate + tick * self.accel + self.jerk * tick * (tick + 1) // 2

    def stays_in_int32(self, ticks: int) -> bool:
        """Whether no rate of ticks 1..``ticks`` leaves the signed 32-bit range (no wrap)."""
        candidates = {1, ticks}
        if self.jerk:
            vertex = int(np.floor(-self.accel / self.jerk - 0.5))  # where the rate turns
            candidates.update(t for t in range(vertex - 1, vertex + 3) if 1 <= t <= ticks)
        return all(_INT32_MIN <= self.rate_at(t) <= _INT32_MAX for t in candidates)

    def after(self, ticks: int) -> AxisStart:
        """The loaded state that continues this one after ``ticks`` ticks (wrapping int32)."""
        accel = wrap32(self.accel + ticks * self.jerk)
        return AxisStart(wrap32(self.rate_at(ticks)), accel, self.jerk)


def cleared_accumulator(rate: int, accel: int, jerk: int = 0) -> int:
    """The accumulator a clear bit loads for an axis with these command parameters.

    ``2**31 - 1`` when the first tick's rate is negative (or zero and the next one negative, or
    both zero and the jerk negative), else 0. For ``LM`` pass the parameters after the legacy
    sign flip (:func:`lm_direction`).
    """
    loaded = AxisStart.load(rate, accel, jerk)
    first = wrap32(loaded.rate + accel)
    if first < 0:
        return NEGATIVE_CLEAR
    if first == 0:
        second = wrap32(accel + jerk)
        if second < 0 or (second == 0 and jerk < 0):
            return NEGATIVE_CLEAR
    return 0


def lm_direction(steps: int, rate: int, accel: int) -> tuple[int, int, int]:
    """``LM``'s legacy direction rule: ``(|steps|, rate, accel)`` as the firmware keeps them.

    A negative ``steps`` with a non-negative ``rate`` negates all three; with a negative ``rate``
    it is ``!6`` (reference "LM", direction note).
    """
    if steps < 0:
        if rate < 0:
            raise EBBCommandError(INVALID_PARAMETER, "LM: negative Steps with a negative Rate")
        return wrap32(-steps) & _UINT32_MAX, wrap32(-rate), wrap32(-accel)
    return steps, rate, accel


def _accumulated(start: AxisStart, accumulator: int, ticks: int) -> np.ndarray:
    """``C_1..C_ticks`` (int64): the accumulator before carries, summed since the move started."""
    k = np.arange(1, ticks + 1, dtype=np.int64)
    triangle = np.cumsum(k)  # k(k+1)/2, exact modulo 2**64
    with np.errstate(over="ignore"):
        rate = np.int64(start.rate) + k * np.int64(start.accel) + np.int64(start.jerk) * triangle
    # int64 arithmetic is exact modulo 2**64, so the low 32 bits are the firmware's wrapped rate.
    rate = rate.astype(np.int32).astype(np.int64)
    return np.int64(accumulator) + np.cumsum(rate)


def _check_accumulator(accumulator: int) -> None:
    if not 0 <= accumulator < ACCUMULATOR_STEP:
        raise ValueError(f"accumulator: must be in [0, 2**31), got {accumulator}")


def axis_final(
    ticks: int, rate: int, accel: int, jerk: int = 0, accumulator: int = 0
) -> tuple[int, int]:
    """One axis of an ``LT``/``T3`` move: ``(steps, accumulator)`` after ``ticks`` ticks.

    Closed form, exact for any length when no rate leaves the int32 range; otherwise the per-tick
    sum (bounded by :data:`MAX_TICKS`). ``rate``/``accel``/``jerk`` are the command's parameters.
    """
    _check_accumulator(accumulator)
    if ticks <= 0:
        return 0, accumulator
    start = AxisStart.load(rate, accel, jerk)
    if start.stays_in_int32(ticks):
        n = ticks
        total = (
            accumulator
            + n * start.rate
            + start.accel * n * (n + 1) // 2
            + start.jerk * n * (n + 1) * (n + 2) // 6
        )
        return total >> 31, total & _ACC_MASK
    positions, final = axis_positions(ticks, rate, accel, jerk, accumulator)
    return int(positions[-1]), final


def axis_positions(
    ticks: int, rate: int, accel: int, jerk: int = 0, accumulator: int = 0
) -> tuple[np.ndarray, int]:
    """One axis of an ``LT``/``T3`` move, tick by tick.

    Returns the signed step position relative to the move's start after each tick 1..``ticks``
    (int64, length ``ticks``) and the accumulator after the last tick. ``rate``, ``accel`` and
    ``jerk`` are the command's parameters; ``accumulator`` is the one the move starts with (after
    any clear: :func:`cleared_accumulator`).
    """
    _check_accumulator(accumulator)
    if ticks > MAX_TICKS:
        raise MoveTooLong(f"{ticks} ticks: longer than the {MAX_TICKS}-tick per-tick model")
    if ticks <= 0:
        return np.zeros(0, dtype=np.int64), accumulator
    total = _accumulated(AxisStart.load(rate, accel, jerk), accumulator, ticks)
    return total >> 31, int(total[-1]) & _ACC_MASK


def lm_axis(
    steps: int, rate: int, accel: int, accumulator: int = 0, *, clear: bool = False
) -> tuple[np.ndarray, int]:
    """One axis of an ``LM`` move: positions after each tick until it has taken ``|steps|`` steps.

    Steps in either direction count (a rate that changes sign reverses the motor), so the final
    position is ``±|steps|`` only without a reversal. ``clear`` applies the command's clear bit
    (the accumulator then starts at :func:`cleared_accumulator`). An axis with ``steps == 0`` does
    not run: no ticks, accumulator unchanged (or cleared). Raises :class:`MoveTooLong` for an axis
    that never completes (no rate nor accel) or needs more than :data:`MAX_TICKS` ticks.
    """
    count, rate, accel = lm_direction(steps, rate, accel)
    if clear:
        accumulator = cleared_accumulator(rate, accel)
    _check_accumulator(accumulator)
    if count == 0:
        return np.zeros(0, dtype=np.int64), accumulator
    if rate == 0 and accel == 0:
        raise MoveTooLong(f"LM axis with {count} steps, no rate and no accel: never completes")
    start = AxisStart.load(rate, accel)
    chunks: list[np.ndarray] = []
    done_ticks = 0
    taken = 0
    position = 0
    distance = count * ACCUMULATOR_STEP  # a first guess of the duration; chunks double after it
    guesses = [distance // abs(rate) if rate else MAX_TICKS]
    if accel:
        guesses.append(math.isqrt(2 * distance // abs(accel)))
    chunk = min(65_536, max(64, 5 * min(guesses) // 4 + 16))
    while True:
        total = _accumulated(start, accumulator, chunk)
        positions = (total >> 31) + position
        moved = np.abs(np.diff(positions, prepend=position))
        counts = taken + np.cumsum(moved)
        end = int(np.searchsorted(counts, count))  # first tick with `count` steps taken
        if end < chunk:
            chunks.append(positions[: end + 1])
            return np.concatenate(chunks), int(total[end]) & _ACC_MASK
        chunks.append(positions)
        done_ticks += chunk
        if done_ticks >= MAX_TICKS:
            raise MoveTooLong(f"LM axis with {count} steps: longer than {MAX_TICKS} ticks")
        taken = int(counts[-1])
        position = int(positions[-1])
        accumulator = int(total[-1]) & _ACC_MASK
        start = start.after(chunk)
        chunk = min(2 * chunk, MAX_TICKS - done_ticks)


Command = Literal["LM", "LT", "T3"]


@dataclass(frozen=True)
class Move:
    """One low-level move as sent: per-axis ``(motor 1, motor 2)`` parameters.

    ``steps`` is used by ``LM``, ``ticks`` (Intervals, 40 µs each) by ``LT``/``T3``, ``jerk`` by
    ``T3``; ``clear`` is the optional Clear argument (bit 0 motor 1, bit 1 motor 2, values above 3
    act as 3; omitted from the line when 0).
    """

    command: Command
    rate: tuple[int, int]
    accel: tuple[int, int] = (0, 0)
    jerk: tuple[int, int] = (0, 0)
    steps: tuple[int, int] = (0, 0)
    ticks: int = 0
    clear: int = 0

    def params(self) -> tuple[int, ...]:
        """The command's parameters in wire order (Clear last, only when nonzero)."""
        (r1, r2), (a1, a2), (j1, j2), (s1, s2) = self.rate, self.accel, self.jerk, self.steps
        if self.command == "LM":
            values: tuple[int, ...] = (r1, s1, a1, r2, s2, a2)
        elif self.command == "LT":
            values = (self.ticks, r1, a1, r2, a2)
        else:
            values = (self.ticks, r1, a1, j1, r2, a2, j2)
        return values + ((self.clear,) if self.clear else ())

    def line(self) -> bytes:
        """The exact command text, terminated by ``\\r``."""
        return ",".join([self.command, *map(str, self.params())]).encode("ascii") + b"\r"

    def validate(self, limit_checks: bool = True) -> None:
        """The firmware's parse-time checks: raise its error.

        ``limit_checks`` is the ``CU,2`` setting (on at boot); the legacy ``LM`` sign rule is
        checked either way.
        """
        if self.command not in ("LM", "LT", "T3"):
            raise ValueError(f"command: must be LM, LT or T3, got {self.command!r}")
        signed = [*self.rate, *self.accel, *self.jerk, *self.steps]
        if any(not _INT32_MIN <= v <= _INT32_MAX for v in signed):
            raise EBBCommandError(INVALID_PARAMETER, "a 32-bit signed parameter out of range")
        if not 0 <= self.ticks <= _UINT32_MAX or not 0 <= self.clear <= _UINT32_MAX:
            raise EBBCommandError(INVALID_PARAMETER, "a 32-bit unsigned parameter out of range")
        if self.command == "LM":
            axes = zip(self.rate, self.steps, self.accel, strict=True)
            if limit_checks and all(s == 0 or (r == 0 and a == 0) for r, s, a in axes):
                raise EBBCommandError(INVALID_PARAMETER, "LM: no axis can move")
            for steps, rate, accel in zip(self.steps, self.rate, self.accel, strict=True):
                lm_direction(steps, rate, accel)
        elif limit_checks and self.ticks == 0:
            raise EBBCommandError(INVALID_PARAMETER, f"{self.command}: Intervals must be > 0")


def execute(
    move: Move, accumulators: tuple[int, int] = (0, 0), *, limit_checks: bool = True
) -> tuple[np.ndarray, tuple[int, int]]:
    """Run ``move`` from ``accumulators``: ``(n, 2)`` int64 positions per tick and the new ones.

    Positions are relative to the move's start, motor 1 then motor 2, one row per tick; an
    ``LM`` lasts until both axes are done (a finished axis holds its position). Invalid
    parameters raise :class:`EBBCommandError` with the firmware's reply.
    """
    move.validate(limit_checks)
    bits = min(move.clear, 3)  # the firmware clamps Clear to 3
    clear = [bool(bits & 1), bool(bits & 2)]
    if move.command == "LM":
        axes = [
            lm_axis(move.steps[i], move.rate[i], move.accel[i], accumulators[i], clear=clear[i])
            for i in range(2)
        ]
        n = max(len(p) for p, _ in axes)
        out = np.zeros((n, 2), dtype=np.int64)
        for i, (positions, _) in enumerate(axes):
            out[: len(positions), i] = positions
            if len(positions) and len(positions) < n:
                out[len(positions) :, i] = positions[-1]
        return out, (axes[0][1], axes[1][1])
    columns = []
    finals = []
    for i in range(2):
        jerk = move.jerk[i] if move.command == "T3" else 0
        start = accumulators[i]
        if clear[i]:
            start = cleared_accumulator(move.rate[i], move.accel[i], jerk)
        positions, final = axis_positions(move.ticks, move.rate[i], move.accel[i], jerk, start)
        columns.append(positions)
        finals.append(final)
    return np.stack(columns, axis=1), (finals[0], finals[1])
