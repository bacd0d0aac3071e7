"""Host side: G-code lines in the dialect Grbl 1.1 reads.

Lines are built without spaces: ``move(x=10.5, y=-3, feed=6000)`` gives ``"G1X10.5Y-3F6000\\n"``.
Grbl throws spaces away before parsing, so they would only cost serial bytes and room in its
128-byte receive buffer, which is what limits a dense stream of short segments.

Rules every line here follows, and why:

- Numbers are fixed-point (:func:`fixed`). Grbl's number reader knows a sign, digits and one
  decimal point, nothing else: ``X1e3`` reads ``X1`` and then an ``E`` word, which Grbl rejects
  with error 20. It also keeps only 8 digits and silently drops the rest, so :func:`fixed` refuses
  numbers that need more rather than send a different value.
- A line is printable ASCII ending in a single ``"\\n"`` (Grbl ends a line at ``\\r`` or ``\\n``
  alike, so ``"\\r\\n"`` would be a second, empty line with an ``ok`` of its own and break
  character counting).
- A line is at most :data:`MAX_LINE` bytes, newline included.
- No real-time characters (``?``, ``!``, ``~``, ctrl-x, bytes from 0x80 up): Grbl picks them out
  of the stream wherever they are, even in a comment, and acts on them.
"""

from __future__ import annotations

import math
import numbers

from .codes import LINE_BUFFER_SIZE, MAX_DIGITS, is_realtime_byte

MAX_LINE = LINE_BUFFER_SIZE
"""Longest line, in bytes including its ``"\\n"``, that this module builds or accepts (80).

Grbl's line buffer holds 79 characters plus a terminating NUL; it counts characters after
dropping spaces and comments, and the newline is not stored. Lines built here have no spaces or
comments, so 79 characters and the newline is exactly what Grbl accepts; a longer line would be
answered with error 11 and not executed.
"""


def fixed(value: float, decimals: int = 3) -> str:
    """``value`` as a fixed-point number Grbl reads back exactly, at most ``decimals`` decimals.

    The number is correctly rounded to ``decimals`` places (ties to even on the exact binary
    value), trailing fractional zeros and a bare decimal point are dropped, and a zero never has a
    sign: ``fixed(2.50) == "2.5"``, ``fixed(-3.0) == "-3"``, ``fixed(-0.0002) == "0"``,
    ``fixed(1e-7) == "0"``. Never exponent notation.

    Raises ValueError for a non-number, a non-finite value, ``decimals`` outside 0..8, or a
    number needing more than :data:`~.codes.MAX_DIGITS` (8) digits, whose rest Grbl would drop
    without a word (e.g. ``123456.789`` at 3 decimals: use fewer decimals or smaller numbers).
    """
    if isinstance(decimals, bool) or not isinstance(decimals, int) or not 0 <= decimals <= 8:
        raise ValueError(f"decimals: must be an integer from 0 to 8, got {decimals!r}")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"not a number: {value!r}")
    try:
        number = float(value)
    except OverflowError:
        raise ValueError(f"needs more than {MAX_DIGITS} digits; Grbl reads {MAX_DIGITS}") from None
    if not math.isfinite(number):
        raise ValueError(f"not a finite number: {value!r}")
    text = f"{number:.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    if text == "-0":
        text = "0"
    digits = sum(c.isdigit() for c in text)
    if digits > MAX_DIGITS:
        raise ValueError(
            f"{value!r} needs {digits} digits at {decimals} decimals; "
            f"Grbl reads {MAX_DIGITS} and drops the rest"
        )
    return text


def word(letter: str, value: float, decimals: int = 3) -> str:
    """One G-code word, ``letter`` and ``fixed(value, decimals)``: ``word("X", 1.5) == "X1.5"``.

    Raises ValueError naming the letter if the value cannot be sent (see :func:`fixed`).
    """
    if not (isinstance(letter, str) and len(letter) == 1 and "A" <= letter <= "Z"):
        raise ValueError(f"letter: must be one of A to Z, got {letter!r}")
    try:
        return letter + fixed(value, decimals)
    except ValueError as error:
        raise ValueError(f"{letter}: {error}") from None


def make_line(*parts: str) -> str:
    """Join ``parts`` into one line for Grbl and end it with ``"\\n"``.

    Raises ValueError if the line is empty, is longer than :data:`MAX_LINE` bytes with its
    newline, or holds anything but printable ASCII, or a real-time character (``?``, ``!``, ``~``).
    """
    text = "".join(parts)
    if not text:
        raise ValueError("line: empty")
    for index, char in enumerate(text):
        code = ord(char)
        if not 0x20 <= code <= 0x7E:
            raise ValueError(f"line: character {index} is {char!r}, not printable ASCII: {text!r}")
        if is_realtime_byte(code):
            raise ValueError(
                f"line: character {index} is {char!r}, which Grbl takes as a real-time command: "
                f"{text!r}"
            )
    if len(text) + 1 > MAX_LINE:
        raise ValueError(
            f"line: {len(text) + 1} bytes with its newline, Grbl takes at most {MAX_LINE}: {text!r}"
        )
    return text + "\n"


def move(
    x: float | None = None,
    y: float | None = None,
    z: float | None = None,
    *,
    feed: float | None = None,
    rapid: bool = False,
    decimals: int = 3,
) -> str:
    """A straight move: ``G1`` (or ``G0`` when ``rapid``) with the given axes and feed rate.

    ``move(x=10.5, y=-3, feed=6000) == "G1X10.5Y-3F6000\\n"``. Axes left as None keep their
    position. ``feed`` follows the feed mode: units per minute under ``G94``; under ``G93``
    (inverse time) the move takes ``1/feed`` minutes, and every ``G1`` needs its own.
    Raises ValueError for no axis, a feed rate that is not > 0, or an unsendable number.
    """
    axes = _axes("move", x, y, z)
    parts = ["G0" if rapid else "G1"]
    parts += [word(letter, value, decimals) for letter, value in axes]
    if feed is not None:
        parts.append(_positive("F", feed, decimals))
    return make_line(*parts)


def jog(
    x: float | None = None,
    y: float | None = None,
    z: float | None = None,
    *,
    feed: float,
    incremental: bool = True,
    decimals: int = 3,
) -> str:
    """A jog command, ``$J=G91X1F100``: distances (or with ``incremental=False``, a target).

    ``feed`` is in units per minute (jogs ignore ``G93``); a jog can be stopped at once with
    :attr:`~firmware_protocols.grbl.codes.Realtime.JOG_CANCEL`.
    """
    axes = _axes("jog", x, y, z)
    parts = ["$J=", "G91" if incremental else "G90"]
    parts += [word(letter, value, decimals) for letter, value in axes]
    parts.append(_positive("F", feed, decimals))
    return make_line(*parts)


def dwell(seconds: float, decimals: int = 3) -> str:
    """``G4P<seconds>``: wait until the queued moves are done, then ``seconds`` more."""
    return make_line("G4", _non_negative("P", seconds, decimals))


def spindle_on(speed: float | None = None, decimals: int = 0) -> str:
    """``M3`` with an optional ``S`` speed: on a servo pen plotter, the pen's position.

    Grbl finishes every queued move before it changes the spindle, so a pen command is also a
    pause in the stream; follow it with a :func:`dwell` for the servo to settle.
    """
    if speed is None:
        return make_line("M3")
    return make_line("M3", _non_negative("S", speed, decimals))


def spindle_off() -> str:
    """``M5``: spindle (or servo pen signal) off, after the queued moves."""
    return make_line("M5")


def setting(number: int, value: float, decimals: int = 3) -> str:
    """``$<number>=<value>``, which stores a Grbl setting, e.g. ``setting(110, 6000)``."""
    if isinstance(number, bool) or not isinstance(number, int) or not 0 <= number <= 255:
        raise ValueError(f"number: must be an integer from 0 to 255, got {number!r}")
    text = _non_negative(f"${number}=", value, decimals, name=f"${number}")
    return make_line(text)


def _axes(what: str, x: float | None, y: float | None, z: float | None) -> list[tuple[str, float]]:
    given = (("X", x), ("Y", y), ("Z", z))
    axes = [(letter, value) for letter, value in given if value is not None]
    if not axes:
        raise ValueError(f"{what}: give at least one of x, y, z")
    return axes


def _positive(letter: str, value: float, decimals: int) -> str:
    text = word(letter, value, decimals)
    if float(text[1:]) <= 0:
        raise ValueError(f"{letter}: must be > 0, got {value!r}")
    return text


def _non_negative(prefix: str, value: float, decimals: int, name: str = "") -> str:
    name = name or prefix
    try:
        text = fixed(value, decimals)
    except ValueError as error:
        raise ValueError(f"{name}: {error}") from None
    if text.startswith("-"):
        raise ValueError(f"{name}: must be >= 0, got {value!r}")
    return prefix + text
