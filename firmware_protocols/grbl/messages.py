"""What Grbl 1.1 sends: typed messages, their exact bytes, and an incremental decoder.

Every line the host sends is answered by exactly one :class:`Ok` or :class:`Error` (``ok`` means
queued, not executed); those two are the responses a character-counting streamer counts.
Everything else is pushed: status reports (:class:`Status`, answering ``?``), :class:`Alarm`,
:class:`Welcome` after a reset, ``[MSG:...]`` (:class:`Msg`) and other bracketed feedback
(:class:`Feedback`), settings (:class:`Setting`), startup lines and their results.

Device side, :func:`format_message` gives the bytes Grbl 1.1h prints for a message (every line
ends ``"\\r\\n"``). Host side, :class:`ResponseDecoder` turns received bytes back into messages.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from .codes import State, alarm_description, error_description, setting_decimals


@dataclass(frozen=True)
class Ok:
    """``ok``: the line was accepted (queued, for a motion)."""


@dataclass(frozen=True)
class Error:
    """``error:N``: the line was refused, with status code ``code`` (see :data:`~.codes.ERRORS`)."""

    code: int

    @property
    def description(self) -> str:
        return error_description(self.code)


@dataclass(frozen=True)
class Alarm:
    """``ALARM:N``: the machine is locked in the Alarm state (see :data:`~.codes.ALARMS`)."""

    code: int

    @property
    def description(self) -> str:
        return alarm_description(self.code)


@dataclass(frozen=True)
class Welcome:
    """``Grbl 1.1h ['$' for help]``: Grbl has just started or been reset."""

    version: str = "1.1h"
    hint: str = "'$' for help"


@dataclass(frozen=True)
class Status:
    """A real-time status report, ``<Idle|MPos:0.000,0.000,0.000|FS:0,0>``.

    Only ``state`` and one position are always there; a field Grbl left out is None. Values are
    in the units Grbl reports in (mm, or inches with ``$13=1``).

    - ``substate``: 0 or 1 with Hold (0: hold complete, ready to resume), 0 to 3 with Door.
    - ``mpos`` or ``wpos``: machine or work position (``$10`` chooses); ``WPos = MPos - WCO``.
    - ``buffer``: ``Bf:``, free planner blocks and free serial receive bytes.
    - ``line``: ``Ln:``, the line number being executed (line-number builds only).
    - ``feed``, ``spindle``: ``FS:`` current feed rate and spindle speed; a build without a
      variable spindle sends ``F:`` and ``spindle`` is None.
    - ``pins``: ``Pn:``, the letters of triggered inputs (``XYZPDHRS``).
    - ``wco``: work coordinate offset, sent now and then. ``overrides``: ``Ov:`` feed, rapid and
      spindle override in percent, sent now and then. ``accessories``: ``A:``, ``S``/``C``
      spindle direction, ``F``/``M`` coolant; only with ``Ov:``.
    - ``extra``: fields this decoder does not know, as ``(name, value)`` pairs, in order.
    """

    state: State
    substate: int | None = None
    mpos: tuple[float, ...] | None = None
    wpos: tuple[float, ...] | None = None
    buffer: tuple[int, int] | None = None
    line: int | None = None
    feed: float | None = None
    spindle: float | None = None
    pins: str | None = None
    wco: tuple[float, ...] | None = None
    overrides: tuple[int, int, int] | None = None
    accessories: str | None = None
    extra: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class Msg:
    """``[MSG:text]``: a feedback message, e.g. ``'$H'|'$X' to unlock`` (see ``codes.MSG_*``)."""

    text: str


@dataclass(frozen=True)
class Feedback:
    """Another bracketed line, ``[kind:body]``: ``GC`` ($G), ``HLP`` ($), ``VER`` and ``OPT`` ($I),
    ``G54``...``G30``, ``G92``, ``TLO``, ``PRB`` ($#), ``echo``. ``body`` is kept as sent."""

    kind: str
    body: str


@dataclass(frozen=True)
class Setting:
    """``$11=0.010``: one setting, as ``$$`` lists them."""

    number: int
    value: float


@dataclass(frozen=True)
class StartupLine:
    """``$N0=G21G90``: a stored startup line, as ``$N`` lists them (``line`` may be empty)."""

    index: int
    line: str


@dataclass(frozen=True)
class StartupResult:
    """``>G21G90:ok``: a startup line Grbl ran by itself after a reset, and its result.

    Not a response to anything the host sent, so streamers must not count its ``ok``.
    """

    line: str
    result: Ok | Error


@dataclass(frozen=True)
class Garbage:
    """Bytes that are not a Grbl message: line noise, a baud-rate mismatch, a foreign device."""

    data: bytes


Message = (
    Ok
    | Error
    | Alarm
    | Welcome
    | Status
    | Msg
    | Feedback
    | Setting
    | StartupLine
    | StartupResult
    | Garbage
)


def format_float(value: float, decimals: int) -> str:
    """``value`` printed as Grbl's ``printFloat`` does: fixed ``decimals``, rounding half up.

    The sign is printed for any negative value, so a small negative value prints ``-0.000``, as
    on the device.
    """
    negative = value < 0
    scaled = math.floor(abs(value) * 10**decimals + 0.5)
    digits = str(scaled).rjust(decimals + 1, "0")
    text = f"{digits[:-decimals]}.{digits[-decimals:]}" if decimals else digits
    return "-" + text if negative else text


def format_message(message: Message, *, inches: bool = False) -> bytes:
    """The bytes Grbl 1.1h sends for ``message``, line ending included.

    ``inches`` prints status positions with 4 decimals and rates with 1, as Grbl does with
    ``$13=1`` (the values are taken as already in inches). A :class:`Welcome` is preceded by an
    empty line, as on the device; :class:`Garbage` is its bytes, as they are.
    """
    if isinstance(message, Garbage):
        return message.data
    text = _format_text(message, inches)
    if isinstance(message, Welcome):
        text = "\r\n" + text
    return (text + "\r\n").encode("ascii")


def _format_text(message: Message, inches: bool) -> str:
    if isinstance(message, Ok):
        return "ok"
    if isinstance(message, Error):
        return f"error:{message.code}"
    if isinstance(message, Alarm):
        return f"ALARM:{message.code}"
    if isinstance(message, Welcome):
        return f"Grbl {message.version} [{message.hint}]"
    if isinstance(message, Status):
        return _format_status(message, inches)
    if isinstance(message, Msg):
        return f"[MSG:{message.text}]"
    if isinstance(message, Feedback):
        return f"[{message.kind}:{message.body}]"
    if isinstance(message, Setting):
        return f"${message.number}={format_float(message.value, setting_decimals(message.number))}"
    if isinstance(message, StartupLine):
        return f"$N{message.index}={message.line}"
    if isinstance(message, StartupResult):
        return f">{message.line}:{_format_text(message.result, inches)}"
    raise TypeError(f"message: not a Grbl message: {message!r}")


def _format_status(status: Status, inches: bool) -> str:
    position, rate = (4, 1) if inches else (3, 0)

    def axes(values: tuple[float, ...]) -> str:
        return ",".join(format_float(v, position) for v in values)

    state = status.state.value
    if status.substate is not None:
        state += f":{status.substate}"
    fields = [state]
    if status.mpos is not None:
        fields.append(f"MPos:{axes(status.mpos)}")
    if status.wpos is not None:
        fields.append(f"WPos:{axes(status.wpos)}")
    if status.buffer is not None:
        fields.append(f"Bf:{status.buffer[0]},{status.buffer[1]}")
    if status.line is not None:
        fields.append(f"Ln:{status.line}")
    if status.feed is not None:
        if status.spindle is None:
            fields.append(f"F:{format_float(status.feed, rate)}")
        else:
            fields.append(f"FS:{format_float(status.feed, rate)},{format_float(status.spindle, 0)}")
    if status.pins is not None:
        fields.append(f"Pn:{status.pins}")
    if status.wco is not None:
        fields.append(f"WCO:{axes(status.wco)}")
    if status.overrides is not None:
        fields.append("Ov:" + ",".join(str(v) for v in status.overrides))
    if status.accessories is not None:
        fields.append(f"A:{status.accessories}")
    fields += [f"{name}:{value}" for name, value in status.extra]
    return "<" + "|".join(fields) + ">"


_NUMBER = r"-?\d+(?:\.\d+)?"
_WELCOME = re.compile(r"Grbl (\S+) \[(.*)\]")
_ERROR = re.compile(r"error:(\d{1,3})")
_ALARM = re.compile(r"ALARM:(\d{1,3})")
_BRACKETED = re.compile(r"\[([A-Za-z][A-Za-z0-9]*):(.*)\]")
_SETTING = re.compile(rf"\$(\d{{1,3}})=({_NUMBER})")
_STARTUP_LINE = re.compile(r"\$N(\d{1,3})=(.*)")
_STARTUP_RESULT = re.compile(r">(.*):(ok|error:\d{1,3})")
_STATES = {state.value: state for state in State}
_LINE_END = re.compile(rb"[\r\n]")


def parse_message(line: str) -> Message | None:
    """The message a received line holds (without its line ending), or None if it is not one.

    Strict about the message kinds and their numbers; a status report may have fields in any
    order, and fields it does not know are kept in :attr:`Status.extra`.
    """
    if line == "ok":
        return Ok()
    if match := _ERROR.fullmatch(line):
        return Error(int(match[1]))
    if match := _ALARM.fullmatch(line):
        return Alarm(int(match[1]))
    if line.startswith("<") and line.endswith(">"):
        return _parse_status(line[1:-1])
    if match := _BRACKETED.fullmatch(line):
        kind, body = match[1], match[2]
        return Msg(body) if kind == "MSG" else Feedback(kind, body)
    if match := _WELCOME.fullmatch(line):
        return Welcome(match[1], match[2])
    if match := _SETTING.fullmatch(line):
        return Setting(int(match[1]), float(match[2]))
    if match := _STARTUP_LINE.fullmatch(line):
        return StartupLine(int(match[1]), match[2])
    if match := _STARTUP_RESULT.fullmatch(line):
        result = Ok() if match[2] == "ok" else Error(int(match[2][len("error:") :]))
        return StartupResult(match[1], result)
    return None


def _parse_status(body: str) -> Status | None:
    first, *rest = body.split("|")
    name, _, sub = first.partition(":")
    if name not in _STATES or (sub and not sub.isdigit()):
        return None
    values: dict[str, object] = {"state": _STATES[name], "substate": int(sub) if sub else None}
    extra: list[tuple[str, str]] = []
    for item in rest:
        key, colon, value = item.partition(":")
        if not colon:
            return None
        parsed = _parse_field(key, value)
        if parsed is None:
            return None
        if parsed is _UNKNOWN:
            extra.append((key, value))
        else:
            values.update(parsed)
    return Status(**values, extra=tuple(extra))  # type: ignore[arg-type]


_UNKNOWN = object()
_FLOAT = re.compile(_NUMBER)
_INT = re.compile(r"\d{1,10}")
_LETTERS = re.compile(r"[A-Z]+")


def _numbers(text: str, pattern: re.Pattern[str], convert: type, count: int | None):
    parts = text.split(",")
    if (count is not None and len(parts) != count) or not all(pattern.fullmatch(p) for p in parts):
        return None
    return tuple(convert(p) for p in parts)


def _parse_field(key: str, value: str):
    """``{attribute: value}`` for a known status field, None if malformed, else ``_UNKNOWN``."""
    if key in ("MPos", "WPos", "WCO"):
        numbers = _numbers(value, _FLOAT, float, None)
        return None if numbers is None else {key.lower(): numbers}
    if key == "Bf":
        numbers = _numbers(value, _INT, int, 2)
        return None if numbers is None else {"buffer": numbers}
    if key == "Ln":
        numbers = _numbers(value, _INT, int, 1)
        return None if numbers is None else {"line": numbers[0]}
    if key == "FS":
        numbers = _numbers(value, _FLOAT, float, 2)
        return None if numbers is None else {"feed": numbers[0], "spindle": numbers[1]}
    if key == "F":
        numbers = _numbers(value, _FLOAT, float, 1)
        return None if numbers is None else {"feed": numbers[0]}
    if key == "Ov":
        numbers = _numbers(value, _INT, int, 3)
        return None if numbers is None else {"overrides": numbers}
    if key in ("Pn", "A"):
        attribute = "pins" if key == "Pn" else "accessories"
        return {attribute: value} if _LETTERS.fullmatch(value) else None
    return _UNKNOWN


class ResponseDecoder:
    """Host side: bytes from Grbl in, whole messages out, however the bytes are split.

    ``feed`` keeps an incomplete line until its end arrives, so no message is lost or cut in
    two across reads. A line ends at ``\\n`` or ``\\r``; ``\\r\\n`` (what Grbl sends) and blank
    lines (Grbl sends one before its welcome) give no message. Nothing raises: bytes that are not
    a Grbl message come out as :class:`Garbage`, and the decoder carries on with the next line.
    Within a line, everything up to the last byte that is not printable ASCII is garbage, and
    the rest is still decoded if it is a message (a banner after line noise, say). When a read
    leaves more than ``max_line`` bytes without a line end, they are reported as garbage at once
    rather than kept.
    """

    def __init__(self, max_line: int = 256) -> None:
        if isinstance(max_line, bool) or not isinstance(max_line, int) or max_line < 1:
            raise ValueError(f"max_line: must be a positive integer, got {max_line!r}")
        self.max_line = max_line
        self._pending = bytearray()

    @property
    def pending(self) -> bytes:
        """The bytes of the line received so far, without its end."""
        return bytes(self._pending)

    def reset(self) -> None:
        """Forget an incomplete line, e.g. after a soft reset."""
        self._pending.clear()

    def feed(self, data: bytes) -> list[Message]:
        """Take ``data`` as received and return the messages it completes, in order."""
        messages: list[Message] = []
        buffer = self._pending
        search = len(buffer)  # the pending part holds no line end
        buffer += data
        begin = 0
        while (end := _LINE_END.search(buffer, search)) is not None:
            messages += _decode_line(bytes(buffer[begin : end.start()]))
            begin = search = end.end()
        del buffer[:begin]
        if len(buffer) > self.max_line:
            messages.append(Garbage(bytes(buffer)))
            buffer.clear()
        return messages


def _decode_line(raw: bytes) -> list[Message]:
    if not raw:
        return []
    bad = max((i for i, byte in enumerate(raw) if not 0x20 <= byte <= 0x7E), default=-1)
    message = parse_message(raw[bad + 1 :].decode("ascii")) if bad + 1 < len(raw) else None
    if message is None:
        return [Garbage(raw)]
    if bad < 0:
        return [message]
    return [Garbage(raw[: bad + 1]), message]
