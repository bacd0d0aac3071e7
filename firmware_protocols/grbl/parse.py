"""Device side: one received line, read the way Grbl 1.1h reads it, for a faithful simulator.

Grbl handles a line in three stages, and so does this module:

1. **The line buffer** (:func:`parse_line`). Real-time characters never reach it (Grbl's serial
   layer takes ``?``, ``!``, ``~``, ctrl-x and every byte from 0x80 up out of the stream; a
   simulator should act on them before the line, see :func:`~.codes.is_realtime_byte`). Grbl drops
   spaces and control characters, ``/`` (block delete is not supported, the character is simply
   ignored), ``(...)`` comments (to the ``)`` or the end of the line) and ``;`` comments (to the
   end of the line), and upper-cases letters. More than 79 kept characters is error 11; an empty
   line is answered ``ok``; a line starting with ``$`` is a system command; any other line is
   G-code, refused with error 9 while the machine is in the Alarm or Jog state.
2. **Words** (:func:`parse_line` too). A G-code line is a run of words, a letter and a number read
   by :func:`read_float`; this stage finds the errors that depend on the line alone: 1 (not a
   letter), 2 (no number), 4 (negative F, N, P, S or T), 20 (unknown command or letter: ``X1e3``
   is ``X1`` then an ``E`` word, error 20; ``X1e`` is error 2), 21 (two commands of one modal
   group), 23 (``G1.5``), 24 (two commands using axis words), 25 (a repeated word) and 38 (T above
   255). The result is a :class:`Block`.
3. **Checks against the modal state** (:meth:`ParserState.step`): feed rate undefined (22), dwell
   without P (28), G53 without G0/G1 (30), axis words with G80 (31), unused words (36), jog rules
   (16), and the new state and target of the block.

Results are values, not exceptions: a refused line gives :class:`~.messages.Error`, the very
message the device answers with, so a simulator can send what it gets.

The model covers what a 3-axis pen plotter needs: G0, G1, G4, G17-G19, G20/G21, G40, G49, G53,
G54, G61, G80, G90/G91, G91.1, G93/G94, M0-M2, M30, M3-M5, M8/M9, F, N, P, S, T, X, Y, Z, and
jogging. Blocks Grbl accepts but that need machinery a plotter never uses (arcs G2/G3, probing
G38.x, stored positions G28/G30, offsets G10/G92/G43.1, work coordinate systems G55-G59) parse
exactly like Grbl's, and then :meth:`ParserState.step` refuses them with error 20, listed in
:data:`NOT_MODELLED`: a strict simulator rather than a wrong one.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

from .codes import LINE_BUFFER_SIZE, MAX_DIGITS, SETTINGS, State, is_realtime_byte
from .messages import Error, format_float

MM_PER_INCH = 25.4
MAX_LINE_NUMBER = 10_000_000
"""Largest N word Grbl accepts (error 27 above)."""

GROUPS: dict[str, str] = {
    **dict.fromkeys(
        ("G4", "G10", "G28", "G28.1", "G30", "G30.1", "G53", "G92", "G92.1"), "non_modal"
    ),
    **dict.fromkeys(("G0", "G1", "G2", "G3", "G38.2", "G38.3", "G38.4", "G38.5", "G80"), "motion"),
    **dict.fromkeys(("G17", "G18", "G19"), "plane"),
    **dict.fromkeys(("G90", "G91"), "distance"),
    "G91.1": "arc_distance",
    **dict.fromkeys(("G93", "G94"), "feed_mode"),
    **dict.fromkeys(("G20", "G21"), "units"),
    "G40": "cutter_compensation",
    **dict.fromkeys(("G43.1", "G49"), "tool_length"),
    **dict.fromkeys(("G54", "G55", "G56", "G57", "G58", "G59"), "coord_system"),
    "G61": "path_control",
    **dict.fromkeys(("M0", "M1", "M2", "M30"), "program_flow"),
    **dict.fromkeys(("M3", "M4", "M5"), "spindle"),
    **dict.fromkeys(("M8", "M9"), "coolant"),
}
"""Every command Grbl 1.1h (default build) knows, and its modal group (one command per group and
line, else error 21)."""

NOT_MODELLED = frozenset(
    {"G2", "G3", "G38.2", "G38.3", "G38.4", "G38.5", "G10", "G28", "G28.1", "G30", "G30.1"}
    | {"G92", "G92.1", "G43.1", "G55", "G56", "G57", "G58", "G59"}
)
"""Commands Grbl accepts that :meth:`ParserState.step` refuses with error 20 (see module doc)."""

_VALUE_LETTERS = frozenset("FIJKLNPRSTXYZ")
_NON_NEGATIVE = frozenset("FNPST")
_AXES = "XYZ"


def read_float(text: str, pos: int = 0) -> tuple[float, int] | None:
    """Read a number at ``text[pos:]`` the way Grbl does: ``(value, end)`` or None.

    Grbl's reader takes an optional sign, then digits with at most one decimal point, and stops
    at the first other character (so there is no exponent). It keeps the first 8 digits and drops
    the rest, counting leading zeros: ``123456789`` reads 123456780 and ``1.23456789`` reads
    1.2345678. None means no digit was found (Grbl's error 2). The value here is the exact decimal
    as a Python float; the AVR then stores it in 32 bits (about 7 significant digits), which is
    not modelled here (the simulator does it from :func:`scan_number`).
    """
    scanned = scan_number(text, pos)
    if scanned is None:
        return None
    negative, mantissa, exponent, end = scanned
    value = float(f"{mantissa}e{exponent}")
    return (-value if negative else value), end


def scan_number(text: str, pos: int = 0) -> tuple[bool, int, int, int] | None:
    """The digits of a number at ``text[pos:]`` as Grbl's ``read_float`` collects them:
    ``(negative, mantissa, exponent, end)`` with value ``±mantissa·10^exponent`` (the first 8
    digits kept), or None when there is no digit."""
    match = _NUMBER.match(text, pos)
    assert match is not None  # every part of the pattern is optional
    sign, whole, fraction = match.group(1), match.group(2), match.group(3) or ""
    digits = whole + fraction
    if not digits:
        return None
    # Digits past the 8th are dropped: each one before the point scales by ten.
    dropped = max(0, len(whole) - MAX_DIGITS)
    decimals = max(0, min(len(fraction), MAX_DIGITS - len(whole)))
    return sign == "-", int(digits[:MAX_DIGITS]), dropped - decimals, match.end()


_NUMBER = re.compile(r"([+-]?)([0-9]*)(?:\.([0-9]*))?")
"""What Grbl's ``read_float`` takes: an optional sign, digits, at most one decimal point and
its digits (no point: the fraction group is None)."""


@dataclass(frozen=True)
class Block:
    """One G-code line as Grbl's parser reads it, before checks against the modal state.

    ``commands`` are the G and M commands in line order, spelled canonically (``"G1"`` for
    ``g01``, ``"G38.2"``); ``words`` are the value words, e.g. ``(("X", 10.0), ("F", 600.0))``.
    ``text`` is the line as Grbl's buffer holds it (no spaces or comments, upper case), which is
    what a startup line stores. ``jog`` marks a ``$J=`` line (``text`` starts with ``$J=``).
    An empty line is an empty block, which Grbl answers ``ok``.
    """

    text: str = ""
    commands: tuple[str, ...] = ()
    words: tuple[tuple[str, float], ...] = ()
    jog: bool = False

    @property
    def is_empty(self) -> bool:
        return not self.commands and not self.words

    def get(self, letter: str, default: float | None = None) -> float | None:
        """The value of word ``letter`` (``"X"``, ``"F"``...), or ``default``."""
        for name, value in self.words:
            if name == letter:
                return value
        return default

    def command(self, group: str) -> str | None:
        """The command of modal group ``group`` (see :data:`GROUPS`) in this block, or None."""
        for code in self.commands:
            if GROUPS[code] == group:
                return code
        return None


class SystemCommand:
    """Base of the ``$`` commands, which Grbl executes at once rather than queue."""

    __slots__ = ()


@dataclass(frozen=True)
class Help(SystemCommand):
    """``$``: answer with ``[HLP:...]`` (:data:`~.codes.HELP`)."""


@dataclass(frozen=True)
class ViewSettings(SystemCommand):
    """``$$``: list the settings, ``$0=10`` ... (refused with error 8 in Run and Hold)."""


@dataclass(frozen=True)
class ViewParameters(SystemCommand):
    """``$#``: coordinate offsets, ``[G54:...]`` ... ``[PRB:...]``."""


@dataclass(frozen=True)
class ViewParserState(SystemCommand):
    """``$G``: the modal state, ``[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]``."""


@dataclass(frozen=True)
class ViewBuildInfo(SystemCommand):
    """``$I``: ``[VER:1.1h.20190830:<info>]`` and ``[OPT:V,15,128]``."""


@dataclass(frozen=True)
class SetBuildInfo(SystemCommand):
    """``$I=<text>``: store ``text`` to show after the version in ``$I``."""

    text: str


@dataclass(frozen=True)
class ViewStartupLines(SystemCommand):
    """``$N``: list the startup lines, ``$N0=...`` and ``$N1=...``."""


@dataclass(frozen=True)
class SetStartupLine(SystemCommand):
    """``$N<index>=<block>``: store a G-code line to run after each reset.

    Grbl executes the block (checking it against the modal state with :meth:`ParserState.step`)
    and stores ``block.text`` only if that succeeds. Grbl 1.1h does not check ``index``; it has
    startup lines 0 and 1.
    """

    index: int
    block: Block


@dataclass(frozen=True)
class ToggleCheckMode(SystemCommand):
    """``$C``: enter check mode (``[MSG:Enabled]``), or leave it (``[MSG:Disabled]``, a reset)."""


@dataclass(frozen=True)
class Unlock(SystemCommand):
    """``$X``: leave the Alarm state (``[MSG:Caution: Unlocked]``); no effect otherwise."""


@dataclass(frozen=True)
class Home(SystemCommand):
    """``$H``: run the homing cycle.

    The device first answers error 5 when homing is disabled (``$22=0``), then error 3 if
    ``axes`` is not empty: the default build has no single-axis homing (``$HX``).
    """

    axes: str = ""


@dataclass(frozen=True)
class Sleep(SystemCommand):
    """``$SLP``: disable the steppers and enter the Sleep state."""


@dataclass(frozen=True)
class Restore(SystemCommand):
    """``$RST=$`` (settings), ``$RST=#`` (offsets) or ``$RST=*`` (all); ``what`` is ``$#*``."""

    what: str


@dataclass(frozen=True)
class SetSetting(SystemCommand):
    """``$<number>=<value>``: store a setting (``number`` is one of :data:`~.codes.SETTINGS`).

    Checks left to the device: ``$20=1`` needs homing enabled (error 10).
    """

    number: int
    value: float


Parsed = Block | SystemCommand | Error
"""What :func:`parse_line` returns."""


def parse_line(text: str | bytes, state: State = State.IDLE) -> Parsed:
    """Read one received line as Grbl 1.1h does in machine state ``state``.

    ``text`` is one line, with or without its line ending (``"\\n"``, ``"\\r"`` or ``"\\r\\n"``);
    bytes are taken one character each (Latin-1). Returns a :class:`Block` for G-code (and for
    ``$J=`` jogs, with ``jog=True``), a :class:`SystemCommand` for other ``$`` lines, or the
    :class:`~.messages.Error` Grbl would answer with. The state matters only where Grbl refuses a
    line for it: G-code in Alarm or Jog (9), and ``$`` commands outside the states they allow (8).

    Raises ValueError if ``text`` holds a line ending before its end (more than one line).
    """
    if isinstance(text, bytes | bytearray):
        text = bytes(text).decode("latin-1")
    if text.endswith("\r\n"):
        body = text[:-2]
    else:
        body = text[:-1] if text.endswith(("\r", "\n")) else text
    if "\n" in body or "\r" in body:
        raise ValueError(f"text: one line expected, got {text!r}")
    line = _line_buffer(body)
    if line is None:
        return Error(11)
    if not line:
        return Block()
    if line[0] == "$":
        return _system_command(line, state)
    if state in (State.ALARM, State.JOG):
        return Error(9)
    return _parse_words(line)


def _line_buffer(text: str) -> str | None:
    """What Grbl's line buffer keeps of ``text``: None when it overflows (error 11)."""
    if len(text) < LINE_BUFFER_SIZE and _PLAIN.fullmatch(text):
        return text  # nothing to drop or upper-case, and short enough: kept as it is
    kept: list[str] = []
    in_parentheses = in_semicolon = overflow = False
    limit = LINE_BUFFER_SIZE - 1
    for char in text:
        code = ord(char)
        if code > 0xFF or is_realtime_byte(code):
            continue  # taken by the serial layer (a non-Latin-1 character is several such bytes)
        if in_parentheses or in_semicolon or overflow:
            if char == ")":
                in_parentheses = False
        elif code <= 0x20 or char == "/":
            pass
        elif char == "(":
            in_parentheses = True
        elif char == ";":
            in_semicolon = True
        elif len(kept) >= limit:
            overflow = True
        else:
            kept.append(char.upper() if "a" <= char <= "z" else char)
    return None if overflow else "".join(kept)


_PLAIN = re.compile(r"[^\x00-\x21?~/(;a-z\x7f-\U0010ffff]*")
"""Lines the line buffer keeps character for character: no space or control character, no
real-time character, no ``/``, comment or lower-case letter, nothing outside ASCII."""


def _parse_words(line: str) -> Block | Error:
    """Grbl's gc_execute_line, step 2: import the words of a cleaned line (``$`` means a jog)."""
    jog = line.startswith("$")
    pos = 3 if jog else 0
    commands: list[str] = []
    words: list[tuple[str, float]] = []
    groups: set[str] = set()
    axis_command = False
    while pos < len(line):
        letter = line[pos]
        if not "A" <= letter <= "Z":
            return Error(1)
        number = read_float(line, pos + 1)
        if number is None:
            return Error(2)
        value, pos = number
        if letter in "GM":
            if not 0 <= value < 256:
                return Error(20)  # Grbl converts to an 8-bit integer, which C leaves undefined
            integer = int(value)
            hundredths = math.floor(100 * (value - integer) + 0.5)
            if letter == "G" and (
                integer in (0, 1, 2, 3, 38, 43, 49)
                or (integer in (10, 28, 30, 92) and hundredths == 0)
            ):
                if axis_command:
                    return Error(24)
                axis_command = True
            code = _command(letter, integer, hundredths)
            if isinstance(code, Error):
                return code
            group = GROUPS[code]
            if group in groups:
                return Error(21)
            groups.add(group)
            commands.append(code)
        else:
            if letter not in _VALUE_LETTERS:
                return Error(20)
            if letter == "T" and value > 255:
                return Error(38)
            if any(name == letter for name, _ in words):
                return Error(25)
            if letter in _NON_NEGATIVE and value < 0:
                return Error(4)
            words.append((letter, value))
    return Block(line, tuple(commands), tuple(words), jog)


def _command(letter: str, integer: int, hundredths: int) -> str | Error:
    """The canonical name of a command such as ``G38.2`` (integer 38, hundredths 20), or Grbl's
    error for it: 20 for an unknown command, 23 for decimals where the command has none."""
    if letter == "M":
        if hundredths:
            return Error(23)
        code = f"M{integer}"
        return code if code in GROUPS else Error(20)
    if integer in (28, 30, 92):
        if hundredths not in (0, 10):
            return Error(20)
        return f"G{integer}.1" if hundredths else f"G{integer}"
    if integer == 38:
        return f"G38.{hundredths // 10}" if hundredths in (20, 30, 40, 50) else Error(20)
    if integer in (90, 91) and hundredths:
        return "G91.1" if integer == 91 and hundredths == 10 else Error(20)
    if integer == 43:
        return "G43.1" if hundredths == 10 else Error(20)
    if integer == 49:
        return "G49"  # Grbl ignores G49's decimals
    if integer == 61 and hundredths:
        return Error(20)
    code = f"G{integer}"
    if code not in GROUPS:
        return Error(20)
    return Error(23) if hundredths else code


def _system_command(line: str, state: State) -> Parsed:
    """Grbl's system_execute_line: a ``$`` line, with its checks in Grbl's order."""
    if len(line) == 1:
        return Help()
    kind = line[1]
    if kind == "J":
        if state not in (State.IDLE, State.JOG):
            return Error(8)
        if line[2:3] != "=":
            return Error(3)
        return _parse_words(line)
    if kind in "$GCX":
        if len(line) > 2:
            return Error(3)
        if kind == "$":
            return Error(8) if state in (State.RUN, State.HOLD) else ViewSettings()
        if kind == "G":
            return ViewParserState()
        if kind == "C":
            return Error(8) if state not in (State.IDLE, State.CHECK) else ToggleCheckMode()
        return Unlock()
    if state not in (State.IDLE, State.ALARM):
        return Error(8)
    if kind == "#":
        return Error(3) if len(line) > 2 else ViewParameters()
    if kind == "H":
        return Home(line[2:])
    if kind == "S":
        return Sleep() if line == "$SLP" else Error(3)
    if kind == "I":
        if len(line) == 2:
            return ViewBuildInfo()
        return SetBuildInfo(line[3:]) if line[2] == "=" else Error(3)
    if kind == "R":
        ok = len(line) == 6 and line[2:5] == "ST=" and line[5] in "$#*"
        return Restore(line[5]) if ok else Error(3)
    startup = kind == "N"
    if startup:
        if len(line) == 2:
            return ViewStartupLines()
        if state != State.IDLE:
            return Error(8)
    number = read_float(line, 2 if startup else 1)
    if number is None:
        return Error(2)
    parameter, pos = number
    if line[pos : pos + 1] != "=":
        return Error(3)
    if startup:
        block = _parse_words(line[pos + 1 :])
        return block if isinstance(block, Error) else SetStartupLine(int(parameter), block)
    number = read_float(line, pos + 1)
    if number is None:
        return Error(2)
    value, pos = number
    if pos != len(line) or not 0 <= parameter <= 255:
        return Error(3)
    if value < 0:
        return Error(4)
    index = int(parameter)
    if index not in SETTINGS:
        return Error(3)
    if index == 0 and int(value) < 3:
        return Error(6)
    return SetSetting(index, value)


@dataclass(frozen=True)
class ParserState:
    """Grbl's G-code modal state, as far as a plotter uses it; the state after a reset.

    Commands are spelled as in :data:`GROUPS`. ``feed_rate`` is in mm/min under G94 and the
    inverse-time value under G93, where Grbl forgets it after each block. ``position`` is where
    the parser believes the machine is once the queued moves are done, in mm; work and machine
    coordinates coincide here (no offsets are modelled, ``WCO`` is zero). ``tool`` follows Grbl's
    quirk of falling back to 0 on every block without a T word.
    """

    motion: str = "G0"
    plane: str = "G17"
    units: str = "G21"
    distance: str = "G90"
    feed_mode: str = "G94"
    coord_system: str = "G54"
    spindle: str = "M5"
    coolant: str = "M9"
    tool: int = 0
    feed_rate: float = 0.0
    spindle_speed: float = 0.0
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def step(self, block: Block) -> Step | Error:
        """Check ``block`` against this state as Grbl does, and what executing it means.

        Returns the :class:`Step` (new state, target, dwell...) or the :class:`Error` Grbl
        answers; blocks using :data:`NOT_MODELLED` commands give error 20.
        """
        if any(code in NOT_MODELLED for code in block.commands):
            return Error(20)
        words = dict(block.words)
        commands: dict[str, str] = {}  # group -> the block's first command of it
        for code in block.commands:
            commands.setdefault(GROUPS[code], code)
        command = commands.get
        motion = command("motion") or ("G1" if block.jog else self.motion)
        non_modal = command("non_modal")
        units = command("units") or self.units
        distance = command("distance") or self.distance
        feed_mode = "G94" if block.jog else command("feed_mode") or self.feed_mode
        axes = {axis: words[axis] for axis in _AXES if axis in words}
        explicit_motion = command("motion") not in (None, "G80")
        axis_command = command("tool_length") or ("motion" if explicit_motion or axes else None)
        scale = MM_PER_INCH if units == "G20" else 1.0

        if "N" in words and words["N"] > MAX_LINE_NUMBER:
            return Error(27)
        feed = words.get("F", 0.0)
        if block.jog:
            if "F" not in words:
                return Error(22)
            feed *= scale
        elif feed_mode == "G93":
            if axis_command == "motion" and motion not in ("G80", "G0") and "F" not in words:
                return Error(22)
        elif self.feed_mode == "G94":
            feed = feed * scale if "F" in words else self.feed_rate
        speed = words.get("S", self.spindle_speed)
        unused = set(words) - {"N", "F"} - (set() if block.jog else {"S", "T"})
        if non_modal == "G4":
            if "P" not in words:
                return Error(28)
            unused.discard("P")
        if non_modal == "G53" and motion not in ("G0", "G1"):
            return Error(30)

        target = self.position
        if axis_command == "motion" and axes:
            target = tuple(
                self.position[i]
                if axis not in axes
                else axes[axis] * scale
                if non_modal == "G53" or distance == "G90"
                else axes[axis] * scale + self.position[i]
                for i, axis in enumerate(_AXES)
            )
        elif block.jog:
            target = (0.0, 0.0, 0.0)  # Grbl 1.1h jogs to the origin when no axis is given
        moves = bool(axes) and axis_command == "motion" and motion != "G80"
        if motion == "G80":
            if axes:
                return Error(31)
        elif axis_command == "motion" and motion == "G1" and feed == 0:
            return Error(22)
        if axis_command:
            unused -= set(_AXES)
        if unused:
            return Error(36)

        if block.jog:
            allowed = {"distance", "units", "non_modal"}
            if any(GROUPS[code] not in allowed for code in block.commands) or non_modal not in (
                None,
                "G53",
            ):
                return Error(16)
            return Step(replace(self, position=target), target, False, feed, jog=True)

        flow = command("program_flow")
        state = type(self)(  # every field: what dataclasses.replace does, without its checks
            motion=motion,
            plane=command("plane") or self.plane,
            units=units,
            distance=distance,
            feed_mode=feed_mode,
            coord_system=command("coord_system") or self.coord_system,
            spindle=command("spindle") or self.spindle,
            coolant=command("coolant") or self.coolant,
            tool=int(words.get("T", 0)),
            feed_rate=feed,
            spindle_speed=speed,
            position=target if moves else self.position,
        )
        if flow in ("M2", "M30"):
            state = replace(
                state,
                motion="G1",
                plane="G17",
                distance="G90",
                feed_mode="G94",
                coord_system="G54",
                spindle="M5",
                coolant="M9",
            )
        return Step(
            state,
            target if moves else None,
            moves and motion == "G0",
            feed,
            dwell=words["P"] if non_modal == "G4" else None,
            program_flow=flow if flow != "M1" else None,
        )

    def report(self, *, inches: bool = False) -> str:
        """The body of Grbl's ``$G`` answer, e.g. ``"G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0"``.

        ``inches`` (Grbl's ``$13=1``) prints the feed rate in inches per minute, one decimal.
        """
        if inches:
            feed = format_float(self.feed_rate / MM_PER_INCH, 1)
        else:
            feed = format_float(self.feed_rate, 0)
        modes = (self.motion, self.coord_system, self.plane, self.units, self.distance)
        modes += (self.feed_mode, self.spindle, self.coolant)
        speed = format_float(self.spindle_speed, 0)
        return f"{' '.join(modes)} T{self.tool} F{feed} S{speed}"


@dataclass(frozen=True)
class Step:
    """What executing a checked block does, in Grbl's order of execution.

    ``state`` is the parser state afterwards. Spindle and coolant changes (M3/M4/M5, a new S while
    the spindle is on, M8/M9) are the differences between the old and new state; Grbl finishes
    the queued moves before applying them. Then
    ``dwell`` (seconds, G4), then the move to ``target`` (mm; ``rapid`` for G0, else at
    ``feed_rate``: mm/min, or inverse time when ``state.feed_mode`` is G93), then
    ``program_flow``: ``"M0"`` (a feed hold once the queue is done), ``"M2"``/``"M30"`` (program
    end: wait for the queue, spindle off, ``[MSG:Pgm End]``). A jog (``jog``) leaves the modal
    state alone except the position and moves at ``feed_rate`` mm/min.
    """

    state: ParserState
    target: tuple[float, float, float] | None = None
    rapid: bool = False
    feed_rate: float = 0.0
    dwell: float | None = None
    program_flow: str | None = None
    jog: bool = False
