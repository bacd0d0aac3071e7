"""The EBB command set (firmware 3.x, legacy response mode): lines, parsing, replies, features.

Reference sections "Syntax and conventions", each command's own section and "Returned Errors";
where the reference and the firmware 3.0.3 source (``UBW.c``, ``ebb.c``, ``RCServo2.c``) differ,
the source wins, because that is what a board answers:

- an error ends with ``<CR><NL>`` and no ``OK`` follows it (the reference says ``OK<CR><NL>``);
  an ``SM``/``XM`` step-rate error (``!0``) ends ``<NL><CR><CR><NL>``; a ``QU`` error is
  preceded by ``QU,``.
- ``QE`` ends its data with ``<NL><CR>`` (the reference says ``<CR><NL>``).
- ``EM`` with one parameter is obeyed by nobody: the firmware returns before queueing it and
  answers nothing (send both enables).
- characters left after a command's last parameter: the command runs, answers, and then
  ``!7 Err: Extra parameter`` follows (:attr:`Command.extra`); ``R`` ignores them.
- ``XM`` and ``HM`` do not stop on a bad parameter (they queue and answer ``OK``, then the
  error); :func:`parse_command` refuses them like every other command.

Only legacy response mode (the default at boot) is formatted and read; ``CU,10,1`` (future
syntax) parses, and its reply is the documented lone ``<NL>``, after which this module's replies
no longer apply. ``CU,1,0`` (no ``OK``) is the ``ack=False`` of the reply functions.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import Enum

import numpy as np

from .errors import (
    EXTRA_PARAMETER,
    INVALID_PARAMETER,
    MISSING_PARAMETER,
    RX_BUFFER_OVERRUN,
    EBBCommandError,
    unknown_command,
)
from .motion import Move

MAX_LINE = 256
"""Longest command the EBB buffers, bytes, its terminating ``<CR>`` included."""
FIFO_BOOT_DEPTH = 1
"""Motion FIFO depth at boot, commands (``CU,4`` sets it, ``QU,3`` reads it)."""
FIFO_MAX_DEPTH = 32
"""Largest FIFO depth of firmware 3.0.x (``QU,2``); ``CU,4`` clamps larger values to it."""
SM_RATE_FACTOR = 85899345.92
"""``SM``/``XM``: accumulator rate per (step per millisecond), 2**31 * 40 µs * 1000."""
OK = b"OK\r\n"


class Kind(Enum):
    """A parameter's type as the firmware's number reader (``extract_number``) takes it."""

    UCHAR = (0, 255)
    INT = (-32768, 32767)
    UINT = (0, 65535)
    LONG = (-(2**31), 2**31 - 1)
    ULONG = (0, 2**32 - 1)


_REQ, _OPT = True, False
_U8, _I16, _U16, _I32, _U32 = Kind.UCHAR, Kind.INT, Kind.UINT, Kind.LONG, Kind.ULONG

SPECS: dict[str, tuple[tuple[Kind, bool], ...]] = {
    "V": (),
    "QS": (),
    "CS": (),
    "QM": (),
    "QB": (),
    "QG": (),
    "QP": (),
    "QE": (),
    "R": (),
    "RB": (),
    "QU": ((_U8, _REQ),),
    "CU": ((_U16, _REQ), (_I16, _REQ)),
    "ES": ((_U8, _OPT),),
    "EM": ((_U8, _REQ), (_U8, _OPT)),
    "SC": ((_U8, _REQ), (_U16, _REQ)),
    "SP": ((_U8, _REQ), (_U16, _OPT), (_U8, _OPT)),
    "SR": ((_U32, _REQ), (_U8, _OPT)),
    "S2": ((_U16, _OPT), (_U8, _OPT), (_U16, _OPT), (_U16, _OPT)),
    "LM": ((_I32, _REQ),) * 6 + ((_U32, _OPT),),
    "LT": ((_U32, _REQ),) + ((_I32, _REQ),) * 4 + ((_U32, _OPT),),
    "T3": ((_U32, _REQ),) + ((_I32, _REQ),) * 6 + ((_U32, _OPT),),
    "SM": ((_U32, _REQ), (_I32, _REQ), (_I32, _OPT), (_U32, _OPT)),
    "XM": ((_U32, _REQ), (_I32, _REQ), (_I32, _REQ), (_U32, _OPT)),
    "HM": ((_U32, _REQ), (_I32, _OPT), (_I32, _OPT)),
    "QT": (),
    "QR": (),
    "ST": (),  # its one parameter is a string (:data:`NAME_LENGTH`), read by parse_command
}
"""The commands modelled here: each parameter's type and whether it is required."""

FIRMWARE_COMMANDS = frozenset(SPECS) | {
    *"COIA",
    *("AC", "BL", "CK", "CM", "L3", "MR", "MW", "ND", "NI", "PD", "PI", "PO"),
    *("QC", "QL", "QN", "QR", "QT", "SE", "SL", "SN", "ST", "TD", "TP", "TR"),
}
"""Every name the 3.0.3 dispatcher knows (``T``, ``PC``, ``PG`` were removed); others: ``!8``."""

CU_SETTINGS = {1: "ack", 2: "limit checks", 3: "empty-FIFO LED", 4: "FIFO depth",
               10: "future syntax", 50: "auto motor enable", 51: "limit switch mask",
               52: "limit switch target", 53: "limit switch reply", 54: "checksums",
               60: "power lost threshold", 61: "stepper disable timeout"}  # fmt: skip
"""``CU`` parameter numbers modelled (250-257 are firmware test modes: not modelled)."""
_CU_BOOLEAN = {1, 2, 3, 10}
QU_VALUES = {1: 2, 2: 0, 3: 0, 4: 3, 5: 3, 6: 0, 60: 0, 61: 0, 200: 0}
"""``QU`` parameter numbers and their reply's hex width (0: decimal)."""
_QUERY_OK = ("QS", "QB", "QP", "QE", "ES", "QU", "QR")
NAME_LENGTH = 16
"""Bytes of the nickname ``ST`` stores in flash (``FLASH_NAME_LENGTH``); more is an extra
parameter."""


class UnsupportedCommand(ValueError):
    """A command the firmware knows that this model does not (the simulator must not guess)."""


class ReplyError(ValueError):
    """Bytes from the board that are not the documented reply to the command sent."""


@dataclass(frozen=True)
class Command:
    """One parsed command: upper-case ``name`` and the parameters present, in wire order.

    ``extra``: characters followed the last parameter; the firmware runs the command and then
    answers ``!7 Err: Extra parameter`` as well (:func:`format_reply` appends it). ``text``:
    ``ST``'s nickname, as sent (up to :data:`NAME_LENGTH` bytes).
    """

    name: str
    params: tuple[int, ...] = ()
    extra: bool = False
    text: bytes = b""

    def move(self) -> Move:
        """The ``LM``/``LT``/``T3`` move this command queues (Clear as sent; absent is 0)."""
        p = self.params
        clear = p[len(SPECS[self.name]) - 1] if len(p) == len(SPECS[self.name]) else 0
        if self.name == "LM":
            return Move("LM", (p[0], p[3]), (p[2], p[5]), steps=(p[1], p[4]), clear=clear)
        if self.name == "LT":
            return Move("LT", (p[1], p[3]), (p[2], p[4]), ticks=p[0], clear=clear)
        if self.name == "T3":
            return Move("T3", (p[1], p[4]), (p[2], p[5]), (p[3], p[6]), ticks=p[0], clear=clear)
        raise ValueError(f"{self.name} is not a low-level move")


def _strip_terminator(line: bytes) -> bytes:
    body = line.rstrip(b"\r\n")
    if b"\r" in body or b"\n" in body:
        raise ValueError(f"{line!r}: more than one line")
    return body


def _number(body: bytes, i: int, kind: Kind) -> tuple[int, int]:
    """The firmware's ``extract_number`` after the comma: ``(value, next index)`` or ``!6``."""
    negative = i < len(body) and body[i] == ord("-")
    if negative:
        if kind in (Kind.UCHAR, Kind.UINT, Kind.ULONG):
            raise EBBCommandError(INVALID_PARAMETER, "a negative unsigned parameter")
        i += 1
    start = i
    while i < len(body) and i - start < 10 and 48 <= body[i] <= 57:
        i += 1
    magnitude = int(body[start:i] or b"0") % 2**32  # 10 digits into a 32-bit unsigned long
    low, high = kind.value
    if kind is not Kind.ULONG and not (-low if negative else high) >= magnitude:
        raise EBBCommandError(INVALID_PARAMETER, f"{magnitude} out of {low}..{high}")
    return (-magnitude if negative else magnitude), i


def _sm_rate_check(duration_ms: int, steps: tuple[int, int]) -> None:
    """``SM``/``XM`` limit checks (firmware ``process_simple_motor_move_fp``, 32-bit floats).

    An axis without steps has no rate to check (both without steps: a delay).
    """
    if duration_ms == 0:
        raise EBBCommandError(INVALID_PARAMETER, "Duration 0")
    per_step = np.float32(SM_RATE_FACTOR) / np.float32(duration_ms)
    for axis, count in enumerate(steps, start=1):
        if count == 0:
            continue
        rate = float(np.float32(abs(count)) * per_step)
        if rate > 2**31:
            raise EBBCommandError(f"!0 Err: <axis{axis}> step rate too high".encode())
        if rate < 1:
            raise EBBCommandError(f"!0 Err: <axis{axis}> step rate too slow".encode())


def _wrap32(value: int) -> int:
    return ((value + 2**31) % 2**32) - 2**31


def _check(cmd: Command, limit_checks: bool) -> None:
    """The command-specific checks the firmware makes after reading the parameters."""
    name, p = cmd.name, cmd.params
    if name in ("LM", "LT", "T3"):
        cmd.move().validate(limit_checks)
    elif name in ("SM", "XM") and limit_checks:
        clear = p[3] if len(p) > 3 else 0
        if clear > 3:
            raise EBBCommandError(INVALID_PARAMETER, "Clear above 3")
        a, b = p[1], p[2] if len(p) > 2 else 0
        steps = (a, b) if name == "SM" else (_wrap32(a + b), _wrap32(a - b))
        _sm_rate_check(p[0], steps)
    elif name == "CU":
        if 250 <= p[0] <= 257:
            raise UnsupportedCommand(f"CU,{p[0]}: a firmware test mode, not modelled")
        if p[0] not in CU_SETTINGS or (p[0] in _CU_BOOLEAN and p[1] not in (0, 1)):
            raise EBBCommandError(INVALID_PARAMETER, f"CU,{p[0]},{p[1]}")
    elif name == "QU" and p[0] not in QU_VALUES:
        raise EBBCommandError(INVALID_PARAMETER, f"QU,{p[0]}")
    elif name == "S2" and len(p) > 1 and p[1] > 24:
        raise EBBCommandError(INVALID_PARAMETER, "S2 pin above 24")


def parse_command(line: bytes, *, limit_checks: bool = True) -> Command:
    """One command line (its ``<CR>``/``<NL>`` terminator optional) read as the firmware reads it.

    Names are case-insensitive, one or two characters; parameters are decimal, comma-separated,
    read in order until one is refused. Raises :class:`EBBCommandError` with the firmware's error
    line (``!4`` missing, ``!5`` no comma, ``!6`` out of range, ``!8`` unknown command, ``!0``
    step rate) or :class:`UnsupportedCommand`. ``limit_checks`` is ``CU,2`` (on at boot).
    """
    body = _strip_terminator(line)
    if not body:
        raise ValueError("an empty line")
    if len(body) >= MAX_LINE:
        raise EBBCommandError(RX_BUFFER_OVERRUN, f"{len(body) + 1} bytes")
    second = body[1:2] if body[1:2] != b"," else b""
    name = (body[:1] + second).upper()
    text = name.decode("latin-1")
    if text not in FIRMWARE_COMMANDS:
        raise EBBCommandError(unknown_command(name))
    if text not in SPECS:
        raise UnsupportedCommand(f"{text}: not modelled")
    if text == "ST":
        return _parse_st(body, len(name))
    i, params = len(name), []
    for kind, required in SPECS[text]:
        if i == len(body) or body[i] != ord(","):
            if not required:
                break
            if i == len(body):
                raise EBBCommandError(MISSING_PARAMETER)
            found = body[i : i + 1]
            raise EBBCommandError(b"!5 Err: Need comma next, found: '" + found + b"'")
        i += 1
        if i == len(body):
            if required:
                raise EBBCommandError(MISSING_PARAMETER)
            break
        value, i = _number(body, i, kind)
        params.append(value)
    cmd = Command(text, tuple(params), extra=i < len(body) and text != "R")
    _check(cmd, limit_checks)
    return cmd


def _parse_st(body: bytes, i: int) -> Command:
    """``ST,<name>``: the bytes up to a comma, the end or :data:`NAME_LENGTH` of them (the
    firmware's ``extract_string``); anything after them is an extra parameter."""
    if i == len(body) or body[i] != ord(","):
        # The firmware clears the stored name even then and answers OK and an error line.
        raise UnsupportedCommand("ST without ',<name>': not modelled")
    rest = body[i + 1 :]
    name = rest.split(b",", 1)[0][:NAME_LENGTH]
    return Command("ST", (), extra=len(name) < len(rest), text=name)


def nickname_shown(name: bytes) -> bytes:
    """What ``QT`` prints of a stored nickname: all of it when its first byte is printable
    ASCII other than a space (33-127), else nothing (``parse_QT_packet``)."""
    return name if name[:1] and 32 < name[0] < 128 else b""


def format_command(name: str, *params: int) -> bytes:
    """The exact line for a command, ``<CR>``-terminated, checked as the firmware would."""
    line = ",".join([name.upper(), *(str(int(v)) for v in params)]).encode("ascii") + b"\r"
    cmd = parse_command(line)
    if cmd.extra or len(cmd.params) != len(params):
        raise ValueError(f"{line!r}: {len(params)} parameters, {name} takes {len(SPECS[name])}")
    return line


def format_error(reply: bytes, name: str = "") -> bytes:
    """The bytes a refused command gets in legacy mode (see the module notes)."""
    prefix = b"QU," if name.upper() == "QU" else b""
    return prefix + reply + (b"\n\r\r\n" if reply.startswith(b"!0 ") else b"\r\n")


def _qu_value(param: int, values: tuple[int, ...]) -> bytes:
    width = QU_VALUES[param]
    if width:
        return f"{values[0]:0{width}X}".encode()
    return ",".join(str(v) for v in values).encode()


def format_reply(cmd: Command, *values: int | str, ack: bool = True) -> bytes:
    """The bytes the firmware answers ``cmd`` with in legacy mode, given its query ``values``.

    ``V``: the version text; ``QS``: two positions; ``QM``: four flags; ``QB``, ``QP``, ``ES``,
    ``QR``: one flag; ``QG``: the status byte; ``QE``: two motor states; ``QU``: its value(s);
    ``QT``: the stored nickname (bytes).
    ``ack=False`` is ``CU,1,0`` (no ``OK``, its line ending stays).
    """
    ok = OK if ack else b"\r\n"
    data = ",".join(str(v) for v in values).encode()
    name = cmd.name
    if name == "RB" or (name == "EM" and len(cmd.params) == 1):
        body = b""
    elif name == "V":
        body = data + b"\r\n"
    elif name == "QG":
        body = f"{int(values[0]):02X}".encode() + b"\r\n"
    elif name == "QM":
        body = b"QM," + data + b"\n\r"
    elif name == "QB":
        body = data + b"\r\n" + ok
    elif name == "QU":
        body = b"QU," + _qu_value(cmd.params[0], tuple(map(int, values))) + b"\r\n" + ok
    elif name == "QT":
        stored = values[0] if values else b""
        shown = stored.encode("latin-1") if isinstance(stored, str) else bytes(stored)
        body = nickname_shown(shown) + b"\r\n" + ok
    elif name in _QUERY_OK:
        body = data + b"\n\r" + ok
    elif cmd.params[:2] == (10, 1) and name == "CU":
        body = b"\n"  # the new (future) mode's line ending
    else:
        body = ok
    return body + (EXTRA_PARAMETER + b"\r\n" if cmd.extra else b"")


_INT = rb"(-?[0-9]+)"
_SHAPES: dict[str, tuple[bytes, tuple[bytes, ...]]] = {
    "V": (rb"([ -~]*)\r\n", (b"\r\n",)),
    "QS": (_INT + b"," + _INT + b"\n\r", (b"\n\r",)),
    "QM": (rb"QM,([01]),([01]),([01]),([01])\n\r", (b"\n\r",)),
    "QB": (rb"([01])\r\n", (b"\r\n",)),
    "QP": (rb"([01])\n\r", (b"\n\r",)),
    "ES": (rb"([01])\n\r", (b"\n\r",)),
    "QE": (rb"([0-9]+),([0-9]+)\n\r", (b"\n\r",)),
    "QG": (rb"([0-9A-F]{2})\r\n", (b"\r\n",)),
    "QR": (rb"([01])\n\r", (b"\n\r",)),
    "QT": (rb"((?:[\x21-\x7f][\x20-\xff]*)?)\r\n", (b"\r\n",)),
}
"""Legacy reply data of each query: its pattern and its line endings (``OK`` lines aside)."""
_ERROR = re.compile(rb"(?:QU,)?(![0-9]+ Err: [^\r\n]*)(?:\n\r\r\n|\r\n)")


@dataclass(frozen=True)
class Reply:
    """A complete reply read from the board: its ``values`` or its ``error`` line, and ``size``.

    ``size`` is the number of bytes of the buffer it used.
    """

    values: tuple[int | str, ...]
    size: int
    error: bytes | None = None

    def check(self) -> Reply:
        """This reply, or :class:`EBBCommandError` if the board refused the command."""
        if self.error is not None:
            raise EBBCommandError(self.error)
        return self


def _expected(cmd: Command, ack: bool) -> tuple[bytes, tuple[bytes, ...]]:
    """The pattern of ``cmd``'s legacy reply and the line endings that complete it."""
    ok, ok_end = (rb"OK\r\n" if ack else rb"\r\n"), (b"\r\n",)
    if cmd.name == "QU":
        width = QU_VALUES[cmd.params[0]]
        value = b"([0-9A-F]{%d})" % width if width else rb"([0-9]+(?:,[0-9]+)?)"
        return b"QU," + value + rb"\r\n" + ok, (b"\r\n", b"\r\n")
    if cmd.name in _SHAPES:
        pattern, ends = _SHAPES[cmd.name]
        if cmd.name in _QUERY_OK or cmd.name == "QT":
            return pattern + ok, ends + ok_end
        return pattern, ends
    fixed = format_reply(Command(cmd.name, cmd.params), ack=ack)
    ends = tuple(re.findall(rb"\r\n|\n\r|\n", fixed))
    return re.escape(fixed), ends


def _complete(data: bytes, ends: tuple[bytes, ...]) -> int | None:
    """Where the reply ending with ``ends`` stops in ``data``, None if it has not all arrived.

    Raises :class:`ReplyError` on a line ending that does not belong there.
    """
    pos = 0
    for end in ends:
        found = data.find(end, pos)
        segment = data[pos : len(data) if found < 0 else found]
        stray = re.search(rb"[\r\n]", segment)
        if stray and not (
            found < 0 and segment[stray.start() :] == end[: len(segment) - stray.start()]
        ):
            raise ReplyError(f"{data[:80]!r}: a line ending out of place")
        if found < 0:
            return None
        pos = found + len(end)
    return pos


def read_reply(cmd: Command, data: bytes, *, ack: bool = True) -> Reply | None:
    """The reply to ``cmd`` at the start of ``data`` (legacy mode), or None while incomplete.

    An error line gives a :class:`Reply` with ``error`` set (:meth:`Reply.check` raises it).
    Raises :class:`ReplyError` for bytes that cannot become the documented reply.
    """
    lead = data[3:] if cmd.name == "QU" and data.startswith(b"QU,") else data
    if len(lead) < 2 and (lead[:1] == b"!" or (cmd.name == "QU" and len(data) < 4)):
        return None
    if lead.startswith(b"!"):
        ends = (b"\n\r", b"\r\n") if lead.startswith(b"!0") else (b"\r\n",)
        size = _complete(data, ends)
        if size is None:
            return None
        match = _ERROR.fullmatch(data[:size])
        if match is None:
            raise ReplyError(f"{cmd.name}: {data[:size]!r} is not an EBB error line")
        return Reply((), size, match.group(1))
    pattern, ends = _expected(cmd, ack)
    size = _complete(data, ends)
    if size is None:
        return None
    match = re.fullmatch(pattern, data[:size])
    if match is None:
        raise ReplyError(f"{cmd.name}: reply {data[:size]!r} is not the documented one")
    return Reply(_values(cmd, match), size)


def _values(cmd: Command, match: re.Match[bytes]) -> tuple[int | str, ...]:
    name, groups = cmd.name, match.groups()
    if name == "V":
        return (groups[0].decode("ascii", "replace"),)
    if name == "QT":
        return (groups[0],)
    if name == "QG" or (name == "QU" and QU_VALUES[cmd.params[0]]):
        return (int(groups[0], 16),)
    if name == "QU":
        return tuple(int(v) for v in groups[0].split(b","))
    return tuple(int(g) for g in groups)


@dataclass(frozen=True)
class GeneralStatus:
    """The ``QG`` status byte (reference "QG — Query General"), bit 7 down to bit 0."""

    limit_switch: bool
    power_lost: bool
    button: bool
    pen_up: bool
    executing: bool
    motor1: bool
    motor2: bool
    fifo: bool

    @classmethod
    def from_byte(cls, value: int) -> GeneralStatus:
        """Decode the byte (0..255)."""
        if not 0 <= value <= 255:
            raise ReplyError(f"QG status {value}: not a byte")
        return cls(*(bool(value >> bit & 1) for bit in range(7, -1, -1)))

    def byte(self) -> int:
        """Encode back to the byte."""
        bits = (self.limit_switch, self.power_lost, self.button, self.pen_up, self.executing,
                self.motor1, self.motor2, self.fifo)  # fmt: skip
        return sum(int(b) << (7 - i) for i, b in enumerate(bits))


COMMAND_SINCE: dict[str, tuple[int, int, int]] = {
    "V": (1, 0, 0), "R": (1, 0, 0), "CU": (1, 0, 0), "EM": (1, 0, 0), "SC": (1, 0, 0),
    "SP": (1, 0, 0), "SM": (1, 0, 0), "QP": (1, 9, 0), "QB": (1, 9, 2), "S2": (2, 2, 0),
    "ES": (2, 2, 7), "XM": (2, 3, 0), "QS": (2, 4, 3), "CS": (2, 4, 3), "QM": (2, 4, 4),
    "RB": (2, 5, 4), "SR": (2, 6, 0), "QG": (2, 6, 2), "HM": (2, 6, 2), "LM": (2, 7, 0),
    "LT": (2, 7, 0), "QE": (2, 8, 0), "QU": (3, 0, 0), "T3": (3, 0, 0), "QT": (2, 5, 4),
    "ST": (2, 5, 5), "QR": (2, 6, 0),
}  # fmt: skip
"""First firmware version with each modelled command (each command's "Firmware versions")."""
MIN_SUPPORTED = (3, 0, 0)
"""Oldest firmware tagbot drives: ``T3``, the deep FIFO (``CU,4``/``QU,2``) and the 3.x ``LM``
(whose rate may change sign; 2.7-2.8 keep it from going negative) arrived in 3.0.0."""
_VERSION = re.compile(r"^(\S+) EB Firmware Version (\d+)\.(\d+)\.(\d+)\S*$")


@dataclass(frozen=True)
class Firmware:
    """What a board's ``V`` reply says: board, version and the features that follow from it."""

    text: str
    board: str
    version: tuple[int, int, int]

    @classmethod
    def from_version(cls, text: str | bytes) -> Firmware:
        """Read ``EBBv13_and_above EB Firmware Version 3.0.3`` (reference "V — Version query")."""
        if isinstance(text, bytes):
            text = text.decode("ascii", "replace")
        text = text.strip("\r\n")
        match = _VERSION.match(text)
        if match is None:
            raise ReplyError(f"V: {text!r} is not an EBB version string")
        major, minor, patch = (int(g) for g in match.groups()[1:])
        return cls(text, match.group(1), (major, minor, patch))

    @property
    def supported(self) -> bool:
        """Whether tagbot drives this firmware (:data:`MIN_SUPPORTED` or newer)."""
        return self.version >= MIN_SUPPORTED

    def has(self, name: str) -> bool:
        """Whether this firmware has the command ``name``."""
        return self.version >= COMMAND_SINCE[name.upper()]

    @property
    def max_fifo(self) -> int:
        """Deepest FIFO this firmware can be set to (before asking ``QU,2``)."""
        return FIFO_MAX_DEPTH if self.has("QU") else FIFO_BOOT_DEPTH


class LineReader:
    """Bytes from the host cut into command lines as the firmware's receive loop cuts them.

    ``<CR>`` or ``<NL>`` ends a line (a ``<CR><NL>`` pair ends one); other control bytes are
    dropped. A line of 256 bytes or more: :func:`parse_command` refuses it with ``!3 Err: RX
    Buffer overrun``. A terminator first after boot gives an empty line ``b""``, which the
    firmware answers with an ``!8`` error made of stale buffer bytes (not modelled).
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self._after_end = False

    def feed(self, data: bytes) -> list[bytes]:
        """The complete lines (without terminator) that ``data`` finishes."""
        lines = []
        for byte in data:
            if byte in (13, 10):
                if not self._after_end:
                    lines.append(bytes(self._buffer))
                    self._buffer.clear()
                self._after_end = True
            elif byte >= 32:
                self._buffer.append(byte)
                self._after_end = False
        return lines
