"""Streaming G-code to a Grbl 1.1 controller over a serial port, and stopping it safely.

:class:`GrblStreamer` talks to any pyserial port: a real ``/dev/ttyUSB0``, a pseudo-terminal
served by ``tagbot sim grbl``, or an in-process ``grblsim://`` URL. It follows Grbl's protocol:

- **Handshake** (:meth:`~GrblStreamer.connect`): a soft reset (ctrl-x) unless told not to, the
  welcome banner within a deadline (bytes before it are boot noise and are dropped), ``$$`` read
  into :attr:`~GrblStreamer.settings`, then the unlock policy: a machine in Alarm is refused
  (``"never"``, the default: check it, then choose), unlocked with ``$X`` (``"unlock"``) or
  homed with ``$H`` (``"home"``).
- **Flow control**: character counting (the default): lines are sent while the sum of the
  lengths of unacknowledged lines stays within Grbl's 128-byte receive buffer (127 usable);
  each ``ok``/``error:N`` acknowledges the oldest line. ``mode="wait"`` sends one line at a time.
- **Status** ``?`` polled at ≤ 5 Hz; the reports are kept (:attr:`StreamReport.statuses`) and
  prove the device alive: no byte at all for ``silence_timeout`` seconds is a
  :class:`~tagbot.errors.DeviceTimeout`.
- **Hold / resume** (:meth:`~GrblStreamer.hold`, :meth:`~GrblStreamer.resume`, callable from
  another thread): ``!`` and ``~``; the stream keeps its place.
- **Faults**: ``error:N`` on line k, ``ALARM:N``, an unexpected reset, bytes that are not Grbl
  messages (a lost ``ok`` would break character counting), silence, a lost port, or Ctrl-C stop
  the stream at once: no program line is sent after the fault is seen. Then :meth:`safe_stop`:
  feed hold, wait until the hold is complete, soft reset (which discards the lines still in
  Grbl's buffer without losing position, since nothing moves), pen up. In Alarm the machine is
  locked and already stopped; it is left so (unlocking is the operator's decision). The error
  raised names the exact line (1-based, with its text) and Grbl's message.
- **Resuming** from a line (:func:`resume_lines`) is never automatic: it needs the caller to
  state that the machine's position is known (homed, or checked by hand), then re-creates the
  modal state, travels pen up to where the previous line ended, and continues.

Every wait has a deadline on the port's clock (:func:`tagbot.clock.port_clock`), so simulated
ports run faster than real time with the same code.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import serial

from firmware_protocols.grbl import (
    RX_BUFFER_SIZE,
    Alarm,
    Block,
    Error,
    Garbage,
    Message,
    Msg,
    Ok,
    ParserState,
    Realtime,
    ResponseDecoder,
    Setting,
    StartupResult,
    State,
    Status,
    Welcome,
    gcode,
    parse_line,
)
from tagbot.clock import port_clock
from tagbot.errors import ConnectionLost, DeviceError, DeviceFault, DeviceTimeout

__all__ = [
    "GrblStreamer",
    "StreamOptions",
    "StreamReport",
    "resume_lines",
]

log = logging.getLogger(__name__)

UNLOCK_POLICIES = ("never", "unlock", "home")
MAX_POLL_RATE = 5.0
"""Hz: Grbl's documentation asks hosts not to poll status faster."""


@dataclass(frozen=True)
class StreamOptions:
    """How to talk to the controller (every time in seconds on the port's clock)."""

    mode: str = "count"
    """``"count"`` (character counting) or ``"wait"`` (send one line, wait for its answer)."""
    rx_buffer: int = RX_BUFFER_SIZE
    """Grbl's serial receive buffer; at most ``rx_buffer - 1`` unacknowledged bytes are sent."""
    poll_rate: float = MAX_POLL_RATE
    """Status polls per second (≤ 5)."""
    silence_timeout: float = 2.0
    """No byte from the device for this long, while something is expected: a timeout."""
    welcome_timeout: float = 5.0
    """How long the banner may take after opening or a reset (an Arduino reboots in ~2 s)."""
    reset: bool = True
    """Soft-reset the controller when connecting (a clean state; never while it moves)."""
    unlock: str = "never"
    """What to do with a machine in Alarm: ``"never"`` (refuse), ``"unlock"`` ($X), ``"home"``
    ($H)."""
    read_timeout: float = 0.01
    """How long one read waits for bytes."""

    def __post_init__(self) -> None:
        if self.mode not in ("count", "wait"):
            raise ValueError(f"mode: must be 'count' or 'wait', got {self.mode!r}")
        if not 0 < self.poll_rate <= MAX_POLL_RATE:
            raise ValueError(f"poll_rate: must be in (0, {MAX_POLL_RATE}] Hz, got {self.poll_rate}")
        if self.unlock not in UNLOCK_POLICIES:
            raise ValueError(f"unlock: must be one of {', '.join(UNLOCK_POLICIES)}")
        if self.rx_buffer < 2:
            raise ValueError(f"rx_buffer: must be >= 2, got {self.rx_buffer}")
        for name in ("silence_timeout", "welcome_timeout", "read_timeout"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: must be > 0")


@dataclass
class StreamReport:
    """What happened during one :meth:`GrblStreamer.stream` call."""

    lines_total: int
    first_line: int = 0
    """Index (0-based) of the first line sent (0, or where a resume started)."""
    lines_sent: int = 0
    lines_acknowledged: int = 0
    errors: list[str] = field(default_factory=list)
    """One entry per fault, in Grbl's words, with the line."""
    started: float = 0.0
    finished: float = 0.0
    statuses: list[tuple[float, Status]] = field(default_factory=list)
    """Status reports with the clock time they arrived."""
    messages: list[tuple[float, Message]] = field(default_factory=list)
    """Push messages (``[MSG:..]``, feedback, startup results) that arrived while streaming."""
    stopped_at: int | None = None
    """Index (0-based) of the line at which the stream stopped, or None if it completed."""
    max_outstanding: int = 0
    """The largest number of unacknowledged bytes the host had in flight."""
    bytes_sent: int = 0

    @property
    def duration(self) -> float:
        return self.finished - self.started


class GrblStreamer:
    """A Grbl 1.1 controller on an open pyserial port (the caller owns and closes the port).

    ``trace`` (optional) is called with ``("tx" | "rx", bytes)`` for every chunk on the wire.
    """

    def __init__(
        self,
        port: serial.SerialBase,
        options: StreamOptions | None = None,
        *,
        trace: Callable[[str, bytes], None] | None = None,
    ) -> None:
        self.port = port
        self.options = options or StreamOptions()
        self.clock = port_clock(port)
        self.settings: dict[int, float] = {}
        self.state: Status | None = None
        self.welcome: Welcome | None = None
        self._trace = trace
        self._decoder = ResponseDecoder()
        self._pending: deque[Message] = deque()
        self._last_rx = self.clock.now()
        self._requests: deque[bytes] = deque()
        self._requests_lock = threading.Lock()
        self._report: StreamReport | None = None
        self.last_report: StreamReport | None = None
        """The report of the latest :meth:`stream` call, also when it raised."""
        self.port.timeout = self.options.read_timeout

    # -- wire -------------------------------------------------------------------------------

    def _write(self, data: bytes) -> None:
        try:
            self.port.write(data)
        except (serial.SerialException, OSError) as e:
            raise ConnectionLost(f"cannot write to the port ({e})") from e
        if self._report is not None:
            self._report.bytes_sent += len(data)
        if self._trace is not None:
            self._trace("tx", data)

    def _read(self) -> list[Message]:
        """Whatever the device has sent (waiting at most ``read_timeout``), decoded."""
        try:
            waiting = self.port.in_waiting
            data = self.port.read(max(1, waiting))
        except (serial.SerialException, OSError) as e:
            raise ConnectionLost(f"the port failed ({e})") from e
        if not data:
            return []
        self._last_rx = self.clock.now()
        if self._trace is not None:
            self._trace("rx", data)
        return self._decoder.feed(data)

    def _messages(self) -> list[Message]:
        if self._pending:
            out = list(self._pending)
            self._pending.clear()
            return out
        return self._read()

    def _silent_for(self) -> float:
        return self.clock.now() - self._last_rx

    def _wait_for(
        self, accept: Callable[[Message], bool], what: str, timeout: float, *, poll: bool = False
    ) -> Message:
        """Read until a message ``accept`` takes; earlier messages are handled or kept."""
        deadline = self.clock.now() + timeout
        next_poll = self.clock.now()
        while True:
            now = self.clock.now()
            if now >= deadline:
                raise DeviceTimeout(f"no {what} within {timeout:g} s")
            if poll and now >= next_poll:
                self._write(bytes([Realtime.STATUS_REPORT]))
                next_poll = now + 1.0 / self.options.poll_rate
            for message in self._messages():
                if accept(message):
                    return message
                self._note(message)

    def _note(self, message: Message) -> None:
        """Keep what a wait did not ask for: status, push messages."""
        now = self.clock.now()
        if isinstance(message, Status):
            self.state = message
            if self._report is not None:
                self._report.statuses.append((now, message))
        elif self._report is not None:
            self._report.messages.append((now, message))
        else:
            log.debug("grbl: %r", message)

    # -- connection -------------------------------------------------------------------------

    def connect(self) -> dict[int, float]:
        """Reset (unless ``options.reset`` is false), banner, ``$$``, unlock policy.

        Returns the settings. Raises DeviceTimeout without a banner, DeviceFault when the
        machine is in Alarm and the policy is ``"never"``.
        """
        if self.options.reset:
            self._write(bytes([Realtime.SOFT_RESET]))
        try:
            message = self._wait_for(
                lambda m: isinstance(m, Welcome),
                "Grbl welcome banner",
                self.options.welcome_timeout,
            )
        except DeviceTimeout as e:
            raise DeviceTimeout(
                f"{e}: is a Grbl 1.1 controller on this port, at this baud rate?"
            ) from None
        assert isinstance(message, Welcome)
        self.welcome = message
        alarmed = self._after_reset()
        self.settings = self.read_settings()
        if alarmed or self.query_state().state == State.ALARM:
            self._unlock()
        return dict(self.settings)

    def _after_reset(self) -> bool:
        """Drain what follows a banner; True if the machine announced it is locked."""
        alarmed = False
        deadline = self.clock.now() + 0.1
        while self.clock.now() < deadline:
            for message in self._messages():
                if (isinstance(message, Msg) and "unlock" in message.text) or isinstance(
                    message, Alarm
                ):
                    alarmed = True
                elif isinstance(message, StartupResult) and isinstance(message.result, Error):
                    log.warning("grbl: startup line %r failed: %s", message.line, message.result)
        return alarmed

    def _unlock(self) -> None:
        policy = self.options.unlock
        if policy == "never":
            raise DeviceFault(
                "the machine is in Alarm (locked); check it, then unlock (--unlock) or home "
                "(--home) before drawing"
            )
        command = "$X" if policy == "unlock" else "$H"
        self.command(command, timeout=60.0 if policy == "home" else 5.0)
        log.info("grbl: %s done", command)

    def command(self, line: str, timeout: float = 5.0) -> list[Message]:
        """Send one line, wait for its ``ok``; returns what came before it. ``error:N`` raises."""
        self._write(line.encode("ascii") + b"\n")
        before: list[Message] = []

        def answer(message: Message) -> bool:
            if isinstance(message, Ok | Error):
                return True
            if isinstance(message, Alarm):
                raise DeviceFault(f"ALARM:{message.code} ({message.description})", line)
            before.append(message)
            return False

        result = self._wait_for(answer, f"answer to {line!r}", timeout, poll=True)
        if isinstance(result, Error):
            raise DeviceFault(f"error:{result.code} ({result.description})", repr(line))
        return before

    def read_settings(self) -> dict[int, float]:
        """``$$``: the controller's settings, ``{110: 6000.0, ...}``."""
        replies = self.command("$$")
        return {m.number: m.value for m in replies if isinstance(m, Setting)}

    def query_state(self, timeout: float = 1.0) -> Status:
        """One status report (``?``)."""
        self._write(bytes([Realtime.STATUS_REPORT]))
        status = self._wait_for(lambda m: isinstance(m, Status), "status report", timeout)
        assert isinstance(status, Status)
        self.state = status
        return status

    # -- hold / resume (any thread) ---------------------------------------------------------

    def hold(self) -> None:
        """Feed hold: Grbl decelerates to a stop and keeps its place (``!``)."""
        self._request(bytes([Realtime.FEED_HOLD]))

    def resume(self) -> None:
        """Resume after a hold (``~``)."""
        self._request(bytes([Realtime.CYCLE_START]))

    def _request(self, data: bytes) -> None:
        if self._report is None:
            self._write(data)
        else:
            with self._requests_lock:
                self._requests.append(data)

    def _send_requests(self) -> None:
        with self._requests_lock:
            requests = list(self._requests)
            self._requests.clear()
        for data in requests:
            self._write(data)

    # -- streaming --------------------------------------------------------------------------

    def stream(
        self,
        lines: Sequence[str],
        *,
        first: int = 0,
        preamble: Sequence[str] = (),
        pen_up: Sequence[str] = (),
        progress: Callable[[int, int], None] | None = None,
        wait_idle: bool = True,
    ) -> StreamReport:
        """Send ``lines[first:]`` (each ending in ``"\\n"``) after ``preamble``; wait until done.

        ``pen_up`` are the lines :meth:`safe_stop` sends after a fault or Ctrl-C. ``progress``
        gets ``(lines acknowledged, lines to send)``. With ``wait_idle`` the call returns once
        the machine has finished moving. Any fault stops the stream (see the module docstring)
        and raises; the report so far is :attr:`last_report`.
        """
        queue = [(None, text) for text in preamble] + [
            (index, lines[index]) for index in range(first, len(lines))
        ]
        for _, text in queue:
            if not text.endswith("\n") or "\n" in text[:-1]:
                raise ValueError(f"lines: each must be one line ending in a newline: {text!r}")
            if len(text) > self.options.rx_buffer - 1:
                raise ValueError(f"lines: longer than Grbl's receive buffer: {text!r}")
        report = StreamReport(lines_total=len(lines), first_line=first)
        self._report = report
        self.last_report = report
        report.started = self.clock.now()
        try:
            self._stream(queue, report, progress)
            if wait_idle:
                self._wait_idle(report)
        except KeyboardInterrupt:
            report.errors.append(f"interrupted {self._acked_where(report)}")
            self._stop_after_fault(pen_up, report)
            raise
        except DeviceError as e:
            fault = e if e.where else type(e)(str(e), self._acked_where(report))
            report.errors.append(str(fault))
            self._stop_after_fault(pen_up, report, alarm="ALARM:" in str(e))
            if fault is e:
                raise
            raise fault from e
        finally:
            report.finished = self.clock.now()
            self._report = None
        return report

    def _stream(
        self,
        queue: list[tuple[int | None, str]],
        report: StreamReport,
        progress: Callable[[int, int], None] | None,
    ) -> None:
        capacity = 1 if self.options.mode == "wait" else self.options.rx_buffer - 1
        in_flight: deque[tuple[int | None, int]] = deque()
        outstanding = 0
        position = 0
        poll_period = 1.0 / self.options.poll_rate
        next_poll = self.clock.now()
        self._last_rx = self.clock.now()
        to_send = sum(1 for index, _ in queue if index is not None)
        done = 0
        while position < len(queue) or in_flight:
            self._send_requests()
            while position < len(queue):
                index, text = queue[position]
                size = len(text)
                if in_flight and (outstanding + size > capacity or (self.options.mode == "wait")):
                    break
                self._write(text.encode("ascii"))
                in_flight.append((index, size))
                outstanding += size
                report.max_outstanding = max(report.max_outstanding, outstanding)
                position += 1
                if index is not None:
                    report.lines_sent += 1
            now = self.clock.now()
            if now >= next_poll:
                self._write(bytes([Realtime.STATUS_REPORT]))
                next_poll = now + poll_period
            for message in self._messages():
                if isinstance(message, Ok | Error):
                    if not in_flight:
                        raise DeviceError(f"unexpected {message!r} with no line outstanding")
                    index, size = in_flight.popleft()
                    outstanding -= size
                    text = queue[position - len(in_flight) - 1][1]
                    if isinstance(message, Error):
                        report.stopped_at = index
                        where = "preamble" if index is None else f"line {index + 1}"
                        raise DeviceFault(
                            f"error:{message.code} ({message.description}) for {text.strip()!r}",
                            where,
                        )
                    if index is not None:
                        report.lines_acknowledged += 1
                        done += 1
                        if progress is not None:
                            progress(done, to_send)
                elif isinstance(message, Alarm):
                    report.stopped_at = in_flight[0][0] if in_flight else None
                    raise DeviceFault(
                        f"ALARM:{message.code} ({message.description}); the machine is locked "
                        f"and was left so: check it, then unlock ($X) or home ($H)",
                        self._acked_where(report),
                    )
                elif isinstance(message, Welcome):
                    report.stopped_at = in_flight[0][0] if in_flight else None
                    raise DeviceFault(
                        "the controller reset itself (welcome banner) during the job",
                        self._acked_where(report),
                    )
                elif isinstance(message, Garbage):
                    report.stopped_at = in_flight[0][0] if in_flight else None
                    raise ConnectionLost(
                        f"unexpected bytes from the device {message.data[:40]!r} (a lost 'ok' "
                        "would break flow control)",
                        self._acked_where(report),
                    )
                else:
                    self._note(message)
            if self._silent_for() > self.options.silence_timeout:
                report.stopped_at = in_flight[0][0] if in_flight else None
                raise DeviceTimeout(
                    f"no answer from the device for {self.options.silence_timeout:g} s",
                    self._acked_where(report),
                )

    def _acked_where(self, report: StreamReport) -> str:
        if report.stopped_at is None:
            return f"after line {report.first_line + report.lines_acknowledged}"
        return f"line {report.stopped_at + 1}"

    def _wait_idle(self, report: StreamReport) -> None:
        """Poll until every queued move has run (state Idle)."""
        poll_period = 1.0 / self.options.poll_rate
        next_poll = self.clock.now()
        while True:
            now = self.clock.now()
            if now >= next_poll:
                self._write(bytes([Realtime.STATUS_REPORT]))
                next_poll = now + poll_period
            self._send_requests()
            for message in self._messages():
                if isinstance(message, Status):
                    self._note(message)
                    if message.state == State.IDLE:
                        return
                elif isinstance(message, Alarm):
                    raise DeviceFault(
                        f"ALARM:{message.code} ({message.description}); the machine is locked",
                        f"after line {report.first_line + report.lines_acknowledged}",
                    )
                elif isinstance(message, Ok | Error | Welcome | Garbage):
                    raise DeviceError(f"unexpected {message!r} after the last line")
                else:
                    self._note(message)
            if self._silent_for() > self.options.silence_timeout:
                raise DeviceTimeout(
                    f"no answer from the device for {self.options.silence_timeout:g} s",
                    "after the last line",
                )

    # -- stopping ---------------------------------------------------------------------------

    def _stop_after_fault(
        self, pen_up: Sequence[str], report: StreamReport, *, alarm: bool = False
    ) -> None:
        try:
            self.safe_stop(pen_up, alarm=alarm)
        except DeviceError as e:  # the first fault is the one to report
            report.errors.append(f"safe stop incomplete: {e}")
            log.warning("grbl: safe stop incomplete: %s", e)

    def safe_stop(self, pen_up: Sequence[str] = (), *, alarm: bool = False) -> None:
        """Feed hold, wait for the stop, soft reset (flushes Grbl's buffers), pen up.

        After an alarm the machine has stopped by itself and may wait in a critical state
        (``[MSG:Reset to continue]``, answering nothing): it gets the soft reset only, which
        leaves it locked in Alarm (unlocking is the operator's decision; G-code, pen commands
        included, is refused until then).
        """
        self._report = None
        deadline = 5.0
        if not alarm:
            self._write(bytes([Realtime.FEED_HOLD]))
            self._wait_for(
                lambda m: (
                    isinstance(m, Status)
                    and (
                        m.state in (State.IDLE, State.ALARM)
                        or (m.state == State.HOLD and m.substate == 0)
                    )
                ),
                "stop after the feed hold",
                deadline,
                poll=True,
            )
        self._write(bytes([Realtime.SOFT_RESET]))
        self._wait_for(lambda m: isinstance(m, Welcome), "welcome after the reset", deadline)
        if self._after_reset() or alarm:
            return  # locked: leave it to the operator
        for line in pen_up:
            self.command(line.strip(), timeout=deadline)


def resume_lines(
    lines: Sequence[str], first: int, pen_up: Sequence[str], pen_down: Sequence[str]
) -> list[str]:
    """The preamble that resumes ``lines`` at index ``first`` on a freshly reset machine.

    Runs ``lines[:first]`` through Grbl's own parser (:class:`ParserState`) to find the modal
    state and where line ``first`` starts from, then returns: units and distance modes, the pen
    up, a rapid travel there, the pen down again if it was down (``pen_down`` applied to that
    state changes nothing), and the feed mode. The caller must know that the machine's position
    is right (homing, or a check by hand): that is why the CLI needs an explicit flag for it.
    """
    if not 0 < first < len(lines):
        raise ValueError(f"resume line: must be between 2 and {len(lines)}, got {first + 1}")
    state = _run_parser(ParserState(), lines[:first], "line")
    down = _run_parser(state, pen_down, "pen down")
    pen_is_down = (down.spindle, down.spindle_speed, down.position[2]) == (
        state.spindle,
        state.spindle_speed,
        state.position[2],
    )
    x, y, _ = state.position
    out = [f"{state.units}\n", f"{state.distance}\n", "G94\n", *pen_up]
    out.append(gcode.move(x, y, rapid=True))
    if pen_is_down:
        out += pen_down
    if state.feed_mode != "G94":
        out.append(f"{state.feed_mode}\n")
    return out


def _run_parser(state: ParserState, lines: Sequence[str], what: str) -> ParserState:
    for number, text in enumerate(lines, start=1):
        parsed = parse_line(text)
        step = parsed if isinstance(parsed, Error) else None
        if isinstance(parsed, Block):
            step = state.step(parsed)
            if not isinstance(step, Error):
                state = step.state
        if isinstance(step, Error):
            raise ValueError(f"{what} {number}: Grbl would refuse it (error:{step.code})")
    return state
