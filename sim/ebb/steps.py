"""The firmware's constant-rate moves (``SM``, ``XM``, ``HM``) as low-level moves, exactly.

Firmware 3.0 (``process_simple_motor_move_fp``, ``process_simple_rate_move_fp``) turns each
into per-axis step rates with the PIC's 32-bit floats (emulated here with IEEE single
precision, truncated to an integer as C casts do) and runs them in the stepper ISR as a
step-limited move without acceleration: per tick ``acc += Rate``, a step when bit 31 is set.
That is an ``LM`` with ``Accel = 0`` and the direction in the sign of ``Steps``, so the
positions come from :func:`firmware_protocols.ebb.motion.execute`; the one rate an ``LM`` cannot
carry, exactly 2**31 (an ``SM`` at 25 kHz), steps on every tick and leaves the accumulator as
it was.
"""

from __future__ import annotations

import numpy as np

from firmware_protocols.ebb.motion import Move, execute

__all__ = ["FULL_RATE", "hm_move", "move_positions", "sm_move"]

FULL_RATE = 2**31
"""An ``SM`` rate that takes a step every tick."""

_F32 = np.float32


def sm_move(
    duration_ms: int, steps: tuple[int, int], clear: int = 0
) -> tuple[Move, tuple[bool, bool]]:
    """The move an ``SM,duration,steps1,steps2[,clear]`` queues (not a delay: some steps are
    nonzero), and which axes run at :data:`FULL_RATE`. Rates outside ``1..2**31`` are clamped,
    as with limit checks off (with them on, ``parse_command`` refuses the line)."""
    per_step = _F32(85899345.92) / _F32(duration_ms)
    rates = []
    full = []
    for count in steps:
        if count == 0:
            rates.append(0)
            full.append(False)
            continue
        rate = int(_F32(abs(count)) * per_step)  # C's (UINT32) cast truncates
        rate = min(max(rate, 1), FULL_RATE)
        full.append(rate == FULL_RATE)
        rates.append(FULL_RATE - 1 if rate == FULL_RATE else rate)
    move = Move("LM", rate=(rates[0], rates[1]), steps=steps, clear=min(clear, 3))
    return move, (full[0], full[1])


def hm_move(frequency: int, steps: tuple[int, int]) -> tuple[Move, tuple[bool, bool]]:
    """The move ``HM`` queues to travel ``steps`` (target minus position) in a straight line,
    the longer axis at ``frequency`` steps/s (25 kHz: :data:`FULL_RATE`), and which axes run at
    the full rate. The accumulators are not cleared."""
    counts = [abs(s) for s in steps]
    major = 0 if counts[0] >= counts[1] else 1
    minor = 1 - major
    per_hz = _F32(85899.34592)
    rates = [0, 0]
    rates[major] = int(_F32(frequency) * per_hz)
    if counts[minor]:
        scaled = _F32(counts[minor]) * _F32(frequency)
        scaled = _F32(scaled / _F32(counts[major])) * per_hz
        rates[minor] = 1 if scaled < 1.0 else min(int(scaled), FULL_RATE - 1)
    full = (rates[0] >= FULL_RATE, rates[1] >= FULL_RATE)
    rates = [min(r, FULL_RATE - 1) for r in rates]
    return Move("LM", rate=(rates[0], rates[1]), steps=steps), full


def move_positions(
    move: Move, accumulators: tuple[int, int], full_rate: tuple[bool, bool] = (False, False)
) -> tuple[np.ndarray, tuple[int, int]]:
    """``(n, 2)`` positions per tick and the final accumulators of ``move`` (as
    :func:`~firmware_protocols.ebb.motion.execute`), with ``full_rate`` axes stepping every
    tick."""
    if not any(full_rate):
        return execute(move, accumulators)
    steps = tuple(0 if f else s for s, f in zip(move.steps, full_rate, strict=True))
    rest = None
    if any(steps):
        rest = execute(Move("LM", move.rate, steps=steps, clear=move.clear), accumulators)
    columns = []
    finals = []
    for i in range(2):
        if full_rate[i]:
            count = move.steps[i]
            columns.append(np.sign(count) * np.arange(1, abs(count) + 1, dtype=np.int64))
            finals.append(0 if move.clear & (1 << i) else accumulators[i])
        elif rest is not None:
            columns.append(rest[0][:, i])
            finals.append(rest[1][i])
        else:
            columns.append(np.zeros(0, dtype=np.int64))
            finals.append(0 if move.clear & (1 << i) else accumulators[i])
    n = max(len(c) for c in columns)
    out = np.zeros((n, 2), dtype=np.int64)
    for i, column in enumerate(columns):
        out[: len(column), i] = column
        if 0 < len(column) < n:
            out[len(column) :, i] = column[-1]
    return out, (finals[0], finals[1])
