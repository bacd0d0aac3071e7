"""The EiBotBoard (EBB) serial protocol, firmware 3.x, shared by the host and the simulated EBB.

- :mod:`.motion` (both): the firmware's exact step arithmetic for ``LM``, ``LT`` and ``T3``
  (25 kHz ISR, 2**31 accumulator units per step), :class:`Move` and :func:`execute`.
- :mod:`.errors`: the firmware's error replies and :class:`EBBCommandError`.
- :mod:`.commands` (both): the command set in legacy response mode: :func:`parse_command`
  (device, strict, the firmware's error replies), :func:`format_command`, :func:`format_reply`,
  :func:`read_reply` (host), :class:`Firmware` from the ``V`` reply, :class:`LineReader`.

Facts come from the makers' command reference (EBB command set, firmware v3.0+) and the firmware
3.0 source (evil-mad/EggBot ``EBB_firmware/app.X/source``); ``plotink.ebb_calc`` is the
independent oracle in the tests. This package uses only the standard library and numpy.
"""

from .commands import (
    Command,
    Firmware,
    GeneralStatus,
    LineReader,
    Reply,
    ReplyError,
    UnsupportedCommand,
    format_command,
    format_error,
    format_reply,
    parse_command,
    read_reply,
)
from .errors import EBBCommandError, MoveTooLong
from .motion import (
    ACCUMULATOR_STEP,
    MAX_TICKS,
    TICK_HZ,
    Move,
    axis_final,
    axis_positions,
    cleared_accumulator,
    execute,
    lm_axis,
)

__all__ = [
    "ACCUMULATOR_STEP",
    "MAX_TICKS",
    "TICK_HZ",
    "Command",
    "EBBCommandError",
    "Firmware",
    "GeneralStatus",
    "LineReader",
    "Move",
    "MoveTooLong",
    "Reply",
    "ReplyError",
    "UnsupportedCommand",
    "axis_final",
    "axis_positions",
    "cleared_accumulator",
    "execute",
    "format_command",
    "format_error",
    "format_reply",
    "lm_axis",
    "parse_command",
    "read_reply",
]
