"""Grbl 1.1 numbers and names: status and alarm codes, real-time bytes, buffer sizes, states.

Everything here is a fact about the classic AVR Grbl 1.1h firmware (gnea/grbl): the code tables
follow its ``report.h`` and the error/alarm tables of its documentation, the real-time bytes its
``config.h``, the sizes its ``serial.h``, ``planner.h`` and ``protocol.h``. The descriptions are
short paraphrases for messages, not Grbl's own text (Grbl 1.1 sends only the numbers).
"""

from __future__ import annotations

import enum

VERSION = "1.1h"
"""The firmware version the tables and formats here were checked against."""

BUILD_DATE = "20190830"
"""Grbl 1.1h's build date, as ``$I`` reports it (``[VER:1.1h.20190830:]``)."""

RX_BUFFER_SIZE = 128
"""Bytes Grbl's serial receive ring holds. A status report's ``Bf:`` shows 128 free when empty.

Character-counting streamers keep the bytes of unacknowledged lines (newline included) within it;
Grbl's own ``stream.py`` keeps one byte spare (at most 127 outstanding).
"""

BLOCK_BUFFER_SIZE = 16
"""Planner ring size; one slot always stays empty, so :data:`PLANNER_BLOCKS` are usable."""

PLANNER_BLOCKS = BLOCK_BUFFER_SIZE - 1
"""Motion blocks the planner can queue (15); ``Bf:15,128`` is an empty, idle machine."""

LINE_BUFFER_SIZE = 80
"""Grbl's line buffer, including its terminating NUL: a line keeps at most 79 characters.

Characters are counted after Grbl drops spaces, control characters, comments and ``/``; the 80th
kept character makes the whole line fail with error 11. The line ending is not stored.
"""


MAX_DIGITS = 8
"""Digits Grbl's number reader keeps (its ``MAX_INT_DIGITS``), leading zeros included; it drops
the rest without an error."""


class State(enum.Enum):
    """Machine states, spelled as the first field of a status report spells them."""

    IDLE = "Idle"
    RUN = "Run"
    HOLD = "Hold"
    JOG = "Jog"
    ALARM = "Alarm"
    DOOR = "Door"
    CHECK = "Check"
    HOME = "Home"
    SLEEP = "Sleep"


class Realtime(enum.IntEnum):
    """Real-time command bytes: acted on as they arrive, never part of a line, never answered.

    ``bytes([Realtime.FEED_HOLD])`` is the byte to send. Grbl's serial interrupt picks these out of
    the stream wherever they appear, even inside a comment, and silently drops every other byte
    from 0x80 up (see :func:`is_realtime_byte`).
    """

    STATUS_REPORT = 0x3F  # '?'
    CYCLE_START = 0x7E  # '~' resume after a feed hold
    FEED_HOLD = 0x21  # '!'
    SOFT_RESET = 0x18  # ctrl-x; in motion it raises ALARM:3
    SAFETY_DOOR = 0x84
    JOG_CANCEL = 0x85
    FEED_OVR_RESET = 0x90  # feed override back to 100 %
    FEED_OVR_COARSE_PLUS = 0x91  # +10 %
    FEED_OVR_COARSE_MINUS = 0x92  # -10 %
    FEED_OVR_FINE_PLUS = 0x93  # +1 %
    FEED_OVR_FINE_MINUS = 0x94  # -1 %
    RAPID_OVR_RESET = 0x95  # rapids at 100 %
    RAPID_OVR_MEDIUM = 0x96  # 50 %
    RAPID_OVR_LOW = 0x97  # 25 %
    SPINDLE_OVR_RESET = 0x99
    SPINDLE_OVR_COARSE_PLUS = 0x9A
    SPINDLE_OVR_COARSE_MINUS = 0x9B
    SPINDLE_OVR_FINE_PLUS = 0x9C
    SPINDLE_OVR_FINE_MINUS = 0x9D
    SPINDLE_OVR_STOP = 0x9E  # toggles a spindle stop during a feed hold
    COOLANT_FLOOD_OVR_TOGGLE = 0xA0
    COOLANT_MIST_OVR_TOGGLE = 0xA1  # only in builds with M7


def is_realtime_byte(byte: int) -> bool:
    """Whether Grbl's serial layer takes ``byte`` out of the stream before the line buffer.

    True for ``?``, ``!``, ``~``, ctrl-x and every byte from 0x80 up (the extended real-time
    commands, and unknown ones, which Grbl discards).
    """
    return byte >= 0x80 or byte in (0x3F, 0x7E, 0x21, 0x18)


ERRORS: dict[int, str] = {
    1: "expected a command letter",
    2: "bad number format",
    3: "invalid '$' statement",
    4: "negative value",
    5: "homing not enabled",
    6: "step pulse shorter than 3 µs",
    7: "EEPROM read failed, defaults restored",
    8: "'$' command needs the Idle state",
    9: "G-code locked out in Alarm or Jog state",
    10: "soft limits need homing enabled",
    11: "line too long",
    12: "step rate above 30 kHz",
    13: "safety door open",
    14: "line too long for EEPROM",
    15: "jog target beyond machine travel",
    16: "invalid jog command",
    17: "laser mode needs PWM output",
    20: "unsupported G-code command",
    21: "two commands from one modal group",
    22: "undefined feed rate",
    23: "command value must be an integer",
    24: "two commands that use axis words",
    25: "repeated word",
    26: "no axis words for a command that needs them",
    27: "invalid line number",
    28: "missing a required value word",
    29: "G59.x work coordinate systems not supported",
    30: "G53 needs G0 or G1",
    31: "axis words that no command uses",
    32: "arc without axis words in its plane",
    33: "invalid motion target",
    34: "invalid arc radius",
    35: "arc without offsets in its plane",
    36: "unused value words",
    37: "G43.1 not on the tool length axis",
    38: "tool number above 255",
}
"""Grbl 1.1 status codes (``error:N``) and what they mean. 18 and 19 are unused."""

ALARMS: dict[int, str] = {
    1: "hard limit triggered, position likely lost",
    2: "soft limit: target beyond machine travel, position kept",
    3: "reset while in motion, position likely lost",
    4: "probe fail: probe not in its expected initial state",
    5: "probe fail: no contact within the programmed travel",
    6: "homing fail: reset during homing",
    7: "homing fail: safety door opened during homing",
    8: "homing fail: pull-off did not clear the limit switch",
    9: "homing fail: limit switch not found within search distance",
    10: "homing fail: second switch of a dual axis not found",
}
"""Grbl 1.1 alarm codes (``ALARM:N``). 10 exists only in dual-axis builds."""


def error_description(code: int) -> str:
    """A short description of status code ``code``, or ``"unknown error"``."""
    return ERRORS.get(code, "unknown error")


def alarm_description(code: int) -> str:
    """A short description of alarm code ``code``, or ``"unknown alarm"``."""
    return ALARMS.get(code, "unknown alarm")


# Texts of Grbl's ``[MSG:...]`` feedback lines (report.c, report_feedback_message).
MSG_RESET_TO_CONTINUE = "Reset to continue"
MSG_ALARM_LOCK = "'$H'|'$X' to unlock"
MSG_UNLOCKED = "Caution: Unlocked"
MSG_ENABLED = "Enabled"  # check mode on ($C)
MSG_DISABLED = "Disabled"  # check mode off ($C again)
MSG_CHECK_DOOR = "Check Door"
MSG_CHECK_LIMITS = "Check Limits"
MSG_PROGRAM_END = "Pgm End"  # after M2 or M30
MSG_RESTORING_DEFAULTS = "Restoring defaults"
MSG_RESTORING_SPINDLE = "Restoring spindle"
MSG_SLEEPING = "Sleeping"

HELP = "$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x"
"""The body of the ``[HLP:...]`` line Grbl 1.1h prints for ``$``."""

SETTINGS: dict[int, str] = {
    0: "step pulse time, µs",
    1: "step idle delay, ms",
    2: "step pulse invert, mask",
    3: "step direction invert, mask",
    4: "invert step enable pin, boolean",
    5: "invert limit pins, boolean",
    6: "invert probe pin, boolean",
    10: "status report options, mask",
    11: "junction deviation, mm",
    12: "arc tolerance, mm",
    13: "report in inches, boolean",
    20: "soft limits enable, boolean",
    21: "hard limits enable, boolean",
    22: "homing cycle enable, boolean",
    23: "homing direction invert, mask",
    24: "homing locate feed rate, mm/min",
    25: "homing search seek rate, mm/min",
    26: "homing switch debounce delay, ms",
    27: "homing switch pull-off distance, mm",
    30: "maximum spindle speed, RPM",
    31: "minimum spindle speed, RPM",
    32: "laser mode enable, boolean",
    100: "X steps per mm",
    101: "Y steps per mm",
    102: "Z steps per mm",
    110: "X maximum rate, mm/min",
    111: "Y maximum rate, mm/min",
    112: "Z maximum rate, mm/min",
    120: "X acceleration, mm/s²",
    121: "Y acceleration, mm/s²",
    122: "Z acceleration, mm/s²",
    130: "X maximum travel, mm",
    131: "Y maximum travel, mm",
    132: "Z maximum travel, mm",
}
"""The settings Grbl 1.1h lists for ``$$``, in its order."""

INTEGER_SETTINGS = frozenset({0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 32})
"""Settings Grbl stores as integers: ``$10=3.7`` stores 3 (the value is truncated)."""


def setting_decimals(number: int) -> int:
    """Decimals Grbl prints setting ``number`` with in ``$$``: 0 for integers and RPM, else 3."""
    return 0 if number in INTEGER_SETTINGS or number in (30, 31) else 3
