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
- **What has run.** ``ok`` means planned, not executed: :class:`ExecutionTracker` follows the
  line the machine is executing from each status report (``Ln:`` when the firmware reports line
  numbers, ``Bf:`` planner blocks when ``$10`` has bit 2, and the reported position against the
  program's segments). Progress counts executed lines, and every fault names the last line the
  machine executed.
- **Watchdog.** Status reports still coming but no motion and no ``ok`` for ``stall_timeout``
  while lines are queued (a machine that stopped executing): a :class:`DeviceTimeout`.
- **Hold / resume** (:meth:`~GrblStreamer.hold`, :meth:`~GrblStreamer.resume`, callable from
  another thread, or a :class:`~tagbot.control.RunControl`): ``!`` and ``~``; the stream keeps
  its place.
- **Faults**: ``error:N`` on line k, ``ALARM:N``, an unexpected reset, bytes that are not Grbl
  messages (a lost ``ok`` would break character counting), silence, a stall, a lost port, or
  Ctrl-C stop the stream at once: no program line is sent after the fault is seen. Then
  :meth:`safe_stop`: feed hold, wait until the hold is complete (the report then says exactly
  which line the machine stopped in), soft reset (which discards the lines still in Grbl's
  buffers without losing position, since nothing moves), pen up. In Alarm the machine is locked
  and already stopped; Grbl waits 500 ms after ``ALARM:N`` and ignores a reset meanwhile on limit
  alarms, so the reset follows ``[MSG:Reset to continue]`` (and is repeated if no banner
  comes); the machine is left locked (unlocking is the operator's decision). The error raised
  names the last line executed (1-based), the line at fault with its text, and Grbl's message.
- **Resuming** from a line (:func:`resume_lines`, :func:`resume_point`) is never automatic: it
  needs the caller to state that the machine's position is known (homed, or checked by hand),
  then re-creates the modal state, travels pen up to where the machine stopped (inside the line
  a feed hold stopped it in, so nothing is drawn twice), and continues.

Every wait has a deadline on the port's clock (:func:`tagbot.clock.port_clock`), so simulated
ports run faster than real time with the same code.
"""

from __future__ import annotations

import bisect
import contextlib
import logging
import math
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
    Feedback,
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
from tagbot.clock import RealTime, port_clock
from tagbot.control import RunControl
from tagbot.errors import ConnectionLost, DeviceError, DeviceFault, DeviceTimeout

__all__ = [
    "ExecutionTracker",
    "GrblStreamer",
    "StreamOptions",
    "StreamReport",
    "executed_where",
    "line_effects",
    "resume_lines",
    "resume_point",
]

log = logging.getLogger(__name__)

UNLOCK_POLICIES = ("never", "unlock", "home")
PLANNER_BLOCKS = 15
"""Usable planner blocks of Grbl 1.1 on an AVR (16 minus one), until ``$I`` says otherwise."""
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
    stall_timeout: float = 2.0
    """Status reports keep coming but nothing moves and nothing is answered for this long while
    lines are queued (longer when the program has long dwells): a stalled machine, a timeout."""
    line_numbers: str = "auto"
    """Send ``N<line>`` words so status reports say the executing line (``Ln:``): ``"auto"``
    (when the firmware's ``$I`` lists the ``N`` option), ``"on"``, ``"off"``."""

    def __post_init__(self) -> None:
        if self.mode not in ("count", "wait"):
            raise ValueError(f"mode: must be 'count' or 'wait', got {self.mode!r}")
        if not 0 < self.poll_rate <= MAX_POLL_RATE:
            raise ValueError(f"poll_rate: must be in (0, {MAX_POLL_RATE}] Hz, got {self.poll_rate}")
        if self.unlock not in UNLOCK_POLICIES:
            raise ValueError(f"unlock: must be one of {', '.join(UNLOCK_POLICIES)}")
        if self.rx_buffer < 2:
            raise ValueError(f"rx_buffer: must be >= 2, got {self.rx_buffer}")
        if self.line_numbers not in ("auto", "on", "off"):
            raise ValueError("line_numbers: must be 'auto', 'on' or 'off'")
        for name in ("silence_timeout", "welcome_timeout", "read_timeout", "stall_timeout"):
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
    lines_executed: int = 0
    """Program lines the machine finished (lines 1..N), by :class:`ExecutionTracker`."""
    tracking: str = ""
    """What told which line was executing: ``status Ln``, ``status Bf``, ``status position``."""
    executing: list[int] = field(default_factory=list)
    """Per status report, the program lines after ``first_line`` finished by then."""
    pause_spans: list[tuple[float, float]] = field(default_factory=list)
    """Feed holds, ``(start, length)`` s on the port's clock: asked for with ``control`` (from
    the ``!`` to the ``~``), or seen in the status reports without tagbot asking (the machine's
    own button, another program: from the first ``Hold`` report to the first report after it,
    so to within one status period)."""
    stall_spans: list[tuple[float, float]] = field(default_factory=list)
    """A starved planner, ``(start, length)`` s on the port's clock: status reports saying
    ``Idle`` with the pen down in the middle of a run (the host did not send the next lines in
    time), from the first such report to the first report after it (to within one status
    period)."""
    outside_holds: int = 0
    """Feed holds tagbot did not ask for."""
    realtime: bool = False
    """Whether the stream ran with real-time scheduling (``SCHED_FIFO``,
    :class:`~tagbot.clock.RealTime`)."""
    warnings: list[str] = field(default_factory=list)
    """What the report must say though the job went on: outside holds, a starved planner."""
    stop_requested: float | None = None
    """When a fault or Ctrl-C started the safe stop, s on the port's clock."""

    @property
    def pauses(self) -> int:
        return len(self.pause_spans)

    @property
    def paused_s(self) -> float:
        """Time spent in feed holds, s."""
        return sum(length for _, length in self.pause_spans)

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
        self.tracker: ExecutionTracker | None = None
        self.blocks = PLANNER_BLOCKS
        """Planner blocks the firmware has (``$I``'s ``[OPT:…,15,128]``)."""
        self.line_numbers = self.options.line_numbers == "on"
        self._progress: Callable[[int, int], None] | None = None
        self._control: RunControl | None = None
        self._held = False
        self._held_since = 0.0
        self._resumed_at = -math.inf
        self._asked_hold = False
        self._outside_since: float | None = None
        self._starved_since: float | None = None
        self._starved_line = 0
        self._stopping = False
        self._drawing: Sequence[bool] = ()
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
            messages = self._messages()
            for k, message in enumerate(messages):
                if accept(message):
                    # What came in the same read after it is the next wait's (an ok read with
                    # a status report must still be counted).
                    self._pending.extendleft(reversed(messages[k + 1 :]))
                    return message
                self._note(message)

    def _note(self, message: Message) -> None:
        """Keep what a wait did not ask for: status, push messages."""
        now = self.clock.now()
        if isinstance(message, Status):
            self.state = message
            if self._report is not None:
                self._report.statuses.append((now, message))
                if self.tracker is not None:
                    self._on_status(message)
        elif isinstance(message, Ok | Error) and self.tracker is not None:
            # Answers to lines still in flight when a fault stopped the stream (the safe stop
            # waits for the hold): they were planned, so the tracker must count them.
            self.tracker.acknowledge(refused=isinstance(message, Error))
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
        self._read_build_options()
        if alarmed or self.query_state().state == State.ALARM:
            self._unlock()
            self.query_state()  # where $X or $H left the machine
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
                    code = message.result.code
                    log.warning(
                        "grbl: startup line %r failed: error:%d (%s)",
                        message.line,
                        code,
                        message.result.description,
                    )
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
                raise DeviceFault(f"ALARM:{message.code} ({message.description})", repr(line))
            before.append(message)
            return False

        result = self._wait_for(answer, f"answer to {line!r}", timeout, poll=True)
        if isinstance(result, Error):
            raise DeviceFault(f"error:{result.code} ({result.description})", repr(line))
        return before

    def _read_build_options(self) -> None:
        """``$I``: the planner's size and whether the firmware reports line numbers."""
        for message in self.command("$I"):
            if isinstance(message, Feedback) and message.kind == "OPT":
                codes, _, rest = message.body.partition(",")
                blocks = rest.split(",")[0]
                if blocks.isdigit() and int(blocks) > 0:
                    self.blocks = int(blocks)
                if self.options.line_numbers == "auto":
                    self.line_numbers = "N" in codes

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
            if self._report is not None:
                self._asked(data == bytes([Realtime.FEED_HOLD]), self._report)

    def _asked(self, hold: bool, report: StreamReport) -> None:
        """Tagbot asked for a feed hold (``hold``) or a resume: its pause spans."""
        now = self.clock.now()
        if hold and not self._asked_hold:
            self._asked_hold, self._held_since = True, now
        elif not hold and self._asked_hold:
            self._asked_hold, self._resumed_at = False, now
            report.pause_spans.append((self._held_since, now - self._held_since))

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
        moves: Sequence[bool] | None = None,
        targets: Sequence[Sequence[float]] | None = None,
        control: RunControl | None = None,
        drawing: Sequence[bool] | None = None,
    ) -> StreamReport:
        """Send ``lines[first:]`` (each ending in ``"\\n"``) after ``preamble``; wait until done.

        ``moves`` and ``targets`` say, per line of ``lines``, whether it creates a planner block
        and where the machine is after it (``Program.line_moves`` and ``line_xy``; worked out
        with Grbl's parser when not given): they let :class:`ExecutionTracker` know which line
        the machine is executing. ``pen_up`` are the lines :meth:`safe_stop` sends after a fault
        or Ctrl-C. ``progress`` gets ``(lines executed, lines in the program)``: first
        ``(first, len(lines))`` before anything is sent (a resumed job's skipped lines were not
        executed now), then as lines execute. ``control``
        pauses (feed hold) and resumes. ``drawing`` says, per line of ``lines``, whether it is a
        pen-down drawing move (``Program.line_run >= 0``): with it, a machine reported ``Idle``
        between two drawing lines is a starved planner (:attr:`StreamReport.stall_spans`, a
        warning); a ``Hold`` tagbot did not ask for is a pause and a warning too. With
        ``wait_idle`` the call returns once the machine has finished moving. Any fault stops the
        stream (see the module docstring) and raises, naming the last line the machine executed;
        the report so far is :attr:`last_report`.
        """
        entries = self._entries(lines, first, preamble, moves, targets)
        for entry in entries:
            text = entry.text
            if not text.endswith("\n") or "\n" in text[:-1]:
                raise ValueError(f"lines: each must be one line ending in a newline: {text!r}")
            if len(text) > self.options.rx_buffer - 1:
                raise ValueError(f"lines: longer than Grbl's receive buffer: {text!r}")
        report = StreamReport(lines_total=len(lines), first_line=first)
        start = self._machine_xy()
        tracker = ExecutionTracker(
            entries, first, len(preamble), self.blocks, start, numbered=self.line_numbers
        )
        self.tracker = tracker
        self._progress = progress
        self._control = control
        self._held = self._asked_hold = False
        self._outside_since = self._starved_since = None
        self._stopping = False
        self._drawing = drawing if drawing is not None else ()
        self._stall_after = max(self.options.stall_timeout, 1.5 * _longest_dwell(lines) + 1.0)
        self._report = report
        self.last_report = report
        report.started = self.clock.now()
        if progress is not None:
            progress(first, len(lines))
        realtime = RealTime(self.clock)
        report.realtime = realtime.fifo
        try:
            self._stream(entries, report)
            if wait_idle:
                self._wait_idle(report)
        except KeyboardInterrupt:
            self._stop_after_fault(pen_up, report)
            report.errors.append(f"interrupted {executed_where(report, tracker.program_done)}")
            raise
        except DeviceError as e:
            alarm = isinstance(e, DeviceFault) and "ALARM:" in str(e)
            self._stop_after_fault(pen_up, report, alarm=alarm)
            lost = isinstance(e, ConnectionLost)
            fault = type(e)(str(e), executed_where(report, tracker.program_done, lost=lost))
            report.errors.insert(0, str(fault))
            raise fault from e
        finally:
            realtime.end()
            report.finished = self.clock.now()
            report.lines_executed = first + tracker.program_done
            report.tracking = tracker.source
            self._report = None
        report.lines_executed = len(lines)
        return report

    def _entries(
        self,
        lines: Sequence[str],
        first: int,
        preamble: Sequence[str],
        moves: Sequence[bool] | None,
        targets: Sequence[Sequence[float]] | None,
    ) -> list[_Entry]:
        """The queue: the preamble, then ``lines[first:]`` (numbered when Grbl reports Ln)."""
        if moves is None or targets is None:
            moves, targets = line_effects(lines)
        if len(moves) != len(lines) or len(targets) != len(lines):
            raise ValueError("moves, targets: one per line")
        here = self._machine_xy()
        pre_moves, pre_targets = line_effects(preamble, here)
        out = [
            _Entry(None, text, bool(m), (float(xy[0]), float(xy[1])))
            for text, m, xy in zip(preamble, pre_moves, pre_targets, strict=True)
        ]
        for index in range(first, len(lines)):
            text = lines[index]
            if self.line_numbers:
                text = f"N{index + 1}{text}"
            xy = targets[index]
            out.append(_Entry(index, text, bool(moves[index]), (float(xy[0]), float(xy[1]))))
        return out

    def _machine_xy(self) -> tuple[float, float]:
        """Where the machine is: the last status report's position, asked for if none came."""
        position = _xy_of(self.state if self.state is not None else self.query_state())
        if position is None:
            raise DeviceFault(
                f"the status report {self.state} gives no machine position (MPos or WPos):"
                " is this a Grbl 1.1 controller?"
            )
        return position

    def _on_status(self, status: Status) -> None:
        """Track the executing line; progress; the watchdog's evidence."""
        tracker = self.tracker
        before = tracker.done
        tracker.update(status, _xy_of(status))
        report = self._report
        if report is not None:
            report.executing.append(tracker.program_done)
        if self._progress is not None and tracker.done != before:
            self._progress(tracker.first + tracker.program_done, tracker.total)
        if report is not None and not self._stopping:
            self._note_holes(status, report, tracker)

    def _inside_run(self, queue: list[_Entry], position: int) -> bool:
        """The next line to send and the one before it are drawing lines of one run."""
        if not 0 < position < len(queue):
            return False
        index, before = queue[position].index, queue[position - 1].index
        drawing = self._drawing
        return (
            index is not None
            and before is not None
            and index < len(drawing)
            and bool(drawing[index])
            and bool(drawing[before])
        )

    def _host_stall(self, report: StreamReport, since: float, length: float, line: int) -> None:
        """The host itself stood still mid-run (descheduled): a stall the status reports cannot
        show (no ``?`` was sent meanwhile), named as one."""
        report.stall_spans.append((since, length))
        report.warnings.append(
            f"host stall: nothing was sent for {length:.2f} s before line {line + 1}, "
            f"{since - report.started:.2f} s into the job, while the pen was down (the machine "
            "starved if its queue held less)"
        )

    def _note_holes(self, status: Status, report: StreamReport, tracker: ExecutionTracker) -> None:
        """Feed holds tagbot did not ask for, and a planner starved mid-run, from one report."""
        now = self.clock.now()
        line = tracker.first + tracker.program_done  # the line executing, or the next to run
        # A report sent before our own resume may still say Hold: one poll period's grace.
        grace = now - self._resumed_at < 1.5 / self.options.poll_rate
        outside = status.state == State.HOLD and not self._asked_hold and not grace
        if outside and self._outside_since is None:
            self._outside_since = now
            report.outside_holds += 1
            report.warnings.append(
                f"feed hold not asked for by tagbot (the machine's button or another program) "
                f"at line {line + 1}, {now - report.started:.2f} s into the job"
            )
        elif not outside and self._outside_since is not None:
            report.pause_spans.append((self._outside_since, now - self._outside_since))
            self._outside_since = None
        # Idle: everything acknowledged has run; starved if the next line is inside a run. A
        # resume's preamble (travel, pen down) is not a run: idle before it is all acknowledged
        # is the machine waiting for its first program line, not a starved planner.
        drawing = self._drawing
        following = tracker.first + max(0, tracker.acked - tracker.preamble)
        starved = (
            status.state == State.IDLE
            and not self._asked_hold
            and tracker.acked > tracker.preamble
            and 0 < following < len(drawing)
            and bool(drawing[following])
            and bool(drawing[following - 1])
        )
        if starved and self._starved_since is None:
            self._starved_since, self._starved_line = now, following
        elif not starved and self._starved_since is not None:
            length, stop = now - self._starved_since, self._starved_line
            report.stall_spans.append((self._starved_since, length))
            report.warnings.append(
                f"starved planner: the machine stood with the pen down before line {stop + 1}"
                f" for about {length:.2f} s, {self._starved_since - report.started:.2f} s into "
                "the job (the host did not send lines in time)"
            )
            self._starved_since = None

    def _check_control(self, report: StreamReport) -> None:
        """Feed hold when ``control`` pauses, resume when it resumes."""
        control = self._control
        if control is None or control.paused == self._held:
            return
        self._held = control.paused
        self._write(bytes([Realtime.FEED_HOLD if self._held else Realtime.CYCLE_START]))
        self._asked(self._held, report)
        self._last_change = self.clock.now()

    def _watchdog(self, status: Status, queued: bool) -> None:
        """A machine that executes nothing while lines wait: a timeout (then the safe stop)."""
        now = self.clock.now()
        key = (_xy_of(status), self.tracker.acked, status.state)
        if key != self._last_key:
            self._last_key, self._last_change = key, now
            return
        waiting = queued or self.tracker.queued_blocks() > 0
        stalled = now - self._last_change > self._stall_after
        if stalled and waiting and not self._held and status.state in (State.IDLE, State.RUN):
            raise DeviceTimeout(
                f"the machine stopped executing: no motion and no answer for "
                f"{now - self._last_change:.1f} s with lines queued ({status.state.value},"
                " status reports still coming)"
            )

    def _stream(self, queue: list[_Entry], report: StreamReport) -> None:
        capacity = 1 if self.options.mode == "wait" else self.options.rx_buffer - 1
        in_flight: deque[tuple[int, int]] = deque()  # (queue position, bytes)
        outstanding = 0
        position = 0
        poll_period = 1.0 / self.options.poll_rate
        next_poll = self.clock.now()
        self._last_rx = self._last_change = self.clock.now()
        self._last_key: object = None
        tracker = self.tracker
        looped = self.clock.now()
        while position < len(queue) or in_flight:
            now = self.clock.now()
            if now - looped > HOST_GAP and self._inside_run(queue, position):
                self._host_stall(report, looped, now - looped, queue[position].index)
            looped = now
            self._send_requests()
            self._check_control(report)
            while position < len(queue):
                entry = queue[position]
                size = len(entry.text)
                if in_flight and (outstanding + size > capacity or (self.options.mode == "wait")):
                    break
                self._write(entry.text.encode("ascii"))
                in_flight.append((position, size))
                outstanding += size
                report.max_outstanding = max(report.max_outstanding, outstanding)
                position += 1
                if entry.index is not None:
                    report.lines_sent += 1
            now = self.clock.now()
            if now >= next_poll:
                self._write(bytes([Realtime.STATUS_REPORT]))
                next_poll = now + poll_period
            for message in self._messages():
                if isinstance(message, Ok | Error):
                    if not in_flight:
                        raise DeviceError(f"unexpected {message!r} with no line outstanding")
                    at, size = in_flight.popleft()
                    outstanding -= size
                    entry = queue[at]
                    if isinstance(message, Error):
                        report.stopped_at = entry.index
                        where = "preamble" if entry.index is None else f"line {entry.index + 1}"
                        raise DeviceFault(
                            f"error:{message.code} ({message.description}) for "
                            f"{entry.text.strip()!r} ({where})"
                        )
                    tracker.acknowledge()
                    if entry.index is not None:
                        report.lines_acknowledged += 1
                elif isinstance(message, Status):
                    self._note(message)
                    self._watchdog(message, bool(in_flight))
                elif isinstance(message, Alarm):
                    raise DeviceFault(
                        f"ALARM:{message.code} ({message.description}); the machine is locked "
                        f"and was left so: check it, then unlock ($X) or home ($H)"
                    )
                elif isinstance(message, Welcome):
                    raise DeviceFault("the controller reset itself (welcome banner) during the job")
                elif isinstance(message, Garbage):
                    raise ConnectionLost(
                        f"unexpected bytes from the device {message.data[:40]!r} (a lost 'ok' "
                        "would break flow control)"
                    )
                else:
                    self._note(message)
            if self._silent_for() > self.options.silence_timeout:
                raise DeviceTimeout(
                    f"no answer from the device for {self.options.silence_timeout:g} s"
                )

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
            self._check_control(report)
            for message in self._messages():
                if isinstance(message, Status):
                    self._note(message)
                    if message.state == State.IDLE and not self._held:
                        self.tracker.finish()
                        return
                    self._watchdog(message, False)
                elif isinstance(message, Alarm):
                    raise DeviceFault(
                        f"ALARM:{message.code} ({message.description}); the machine is locked"
                    )
                elif isinstance(message, Ok | Error | Welcome | Garbage):
                    raise DeviceError(f"unexpected {message!r} after the last line")
                else:
                    self._note(message)
            if self._silent_for() > self.options.silence_timeout:
                raise DeviceTimeout(
                    f"no answer from the device for {self.options.silence_timeout:g} s"
                )

    # -- stopping ---------------------------------------------------------------------------

    def _stop_after_fault(
        self, pen_up: Sequence[str], report: StreamReport, *, alarm: bool = False
    ) -> None:
        self._progress = None  # the caller's callback is not called while stopping
        self._stopping = True
        report.stop_requested = self.clock.now()
        try:
            self.safe_stop(pen_up, alarm=alarm)
        except DeviceError as e:  # the first fault is the one to report
            report.errors.append(f"safe stop incomplete: {e}")
            log.warning("grbl: safe stop incomplete: %s", e)

    def safe_stop(self, pen_up: Sequence[str] = (), *, alarm: bool = False) -> None:
        """Feed hold, wait for the stop, soft reset (flushes Grbl's buffers), pen up.

        The status reports on the way say where the machine stopped (the tracker's last word).
        After an alarm the machine has stopped by itself: Grbl waits 500 ms after printing
        ``ALARM:N`` and, for limit alarms, ignores a reset until it has printed ``[MSG:Reset to
        continue]``; the reset is sent after that (and repeated if no banner follows). It leaves
        the machine locked in Alarm (unlocking is the operator's decision; G-code, pen commands
        included, is refused until then).
        """
        deadline = 5.0

        def stopped(m: Message) -> bool:
            if isinstance(m, Status):
                self._note(m)
                return m.state in (State.IDLE, State.ALARM) or (
                    m.state == State.HOLD and m.substate == 0
                )
            return False

        if alarm:
            # Not a limit alarm: no message, the reset is taken once the delay is over.
            with contextlib.suppress(DeviceTimeout):
                self._wait_for(
                    lambda m: isinstance(m, Msg) and "Reset to continue" in m.text,
                    "[MSG:Reset to continue]",
                    ALARM_DELAY + 0.1,
                )
            # A critical alarm answers no status: the position is the last one reported.
            with contextlib.suppress(DeviceTimeout):
                self._wait_for(stopped, "status in Alarm", 1.0, poll=True)
        else:
            self._write(bytes([Realtime.FEED_HOLD]))
            self._wait_for(stopped, "stop after the feed hold", deadline, poll=True)
        self.tracker = None  # after the reset nothing more runs: the last word is said
        for attempt in range(RESET_ATTEMPTS):
            self._write(bytes([Realtime.SOFT_RESET]))
            try:
                self._wait_for(lambda m: isinstance(m, Welcome), "welcome after the reset", 1.5)
                break
            except DeviceTimeout:
                if attempt == RESET_ATTEMPTS - 1:
                    raise DeviceTimeout(
                        f"no welcome after {RESET_ATTEMPTS} resets: the machine may still hold "
                        "lines; switch it off"
                    ) from None
        if self._after_reset() or alarm:
            return  # locked: leave it to the operator
        for line in pen_up:
            self.command(line.strip(), timeout=deadline)


def executed_where(report: StreamReport, done: int, *, lost: bool = False) -> str:
    """Where the machine stopped, in the program's line numbers, and the command to go on.

    ``done``: program lines after ``report.first_line`` the machine finished. With ``lost`` (the
    port failed: nothing stopped the machine) the last line sent is named too, since the machine
    may have gone on to it.
    """
    done += report.first_line
    sent = report.first_line + report.lines_sent
    resume = f"--resume-from {done + 1} --position-known"
    if lost and sent > done:
        known = f"line {done}" if done else "no line"
        return (
            f"after {known} at least (the last line known executed; lines up to {sent} were "
            f"sent and the machine may have gone on to line {sent}: check where the pen "
            f"stands, then resume with {resume}, or from the line after the one it reached)"
        )
    if done >= report.lines_total:
        return "after the last line"
    if done == 0:
        return "before line 1 (nothing of the program was executed)"
    return f"after line {done} (the last line the machine executed; resume with {resume})"


HOST_GAP = 0.25
"""s: the stream loop standing still this long (a descheduled host) mid-run is a host stall."""
ALARM_DELAY = 0.5
"""s: Grbl 1.1h waits this long after printing ``ALARM:N`` (report_alarm_message)."""
RESET_ATTEMPTS = 3


@dataclass(frozen=True)
class _Entry:
    """One line of the stream: its program index (None in a preamble), text and effect."""

    index: int | None
    text: str
    moves: bool
    xy: tuple[float, float]


class ExecutionTracker:
    """Which line the machine is executing, from its acknowledgements and status reports.

    Grbl answers ``ok`` when a line is planned, not when it has run: up to ``blocks`` planner
    blocks (15 on the AVR) are still to execute. The best evidence the firmware gives is used:

    - ``Ln:`` (firmware built with line numbers; lines sent as ``N<line>…``): the number of
      the executing block;
    - ``Bf:`` (``$10`` with bit 2): free planner blocks, so the blocks still queued are the
      last that many acknowledged moving lines, the first of them executing;
    - otherwise the reported position, matched to the segments of the acknowledged lines that
      may still be in the planner (the earliest segment within :data:`ON_SEGMENT` mm).

    ``done`` counts the stream's entries (preamble included) the machine has finished;
    :attr:`program_done` the program lines among them.
    """

    def __init__(
        self,
        entries: Sequence[_Entry],
        first: int,
        preamble: int,
        blocks: int,
        start: tuple[float, float],
        *,
        numbered: bool = False,
    ) -> None:
        self.entries = entries
        self.first = first
        self.preamble = preamble
        self.total = first + len(entries) - preamble
        self.blocks = blocks
        self.numbered = numbered
        self.acked = 0
        self.moving: list[int] = []
        self.done = 0
        self.source = "acknowledgements"
        self._queued = 0
        self._from: list[tuple[float, float]] = []
        here = start
        for entry in entries:
            self._from.append(here)
            if entry.moves:
                here = entry.xy

    @property
    def program_done(self) -> int:
        """Program lines (after ``first``) the machine has finished."""
        return max(0, self.done - self.preamble)

    def acknowledge(self, *, refused: bool = False) -> None:
        """The oldest line in flight was answered (``ok``, or ``error:N`` when ``refused``)."""
        if self.acked >= len(self.entries):
            return
        if self.entries[self.acked].moves and not refused:
            self.moving.append(self.acked)
        self.acked += 1

    def queued_blocks(self) -> int:
        """Planner blocks the last report said were waiting (0 when unknown)."""
        return self._queued

    def finish(self) -> None:
        """The machine is idle with nothing in flight: everything acknowledged has run."""
        self.done = max(self.done, self.acked)
        self._queued = 0

    def update(self, status: Status, xy: tuple[float, float] | None) -> int:
        """Take one status report (in stream order with the ``ok``s); returns :attr:`done`."""
        bound = self.acked  # no line that was not acknowledged can have run
        settled = status.state == State.IDLE or (
            status.state == State.HOLD and status.substate == 0
        )
        if self.numbered and status.line is not None:
            bound = self.preamble + status.line - 1 - self.first
            self.source = "status Ln"
        elif status.buffer is not None:
            self._queued = max(0, self.blocks - status.buffer[0])
            queued = min(self._queued, len(self.moving))
            bound = self.moving[-queued] if queued else self.acked
            self.source = "status Bf"
        else:
            self.source = "status position"
            settled = False
        done = bound if self.source != "status position" else self.done
        if not settled and xy is not None:
            # In motion the stepper's segment buffer runs a few blocks the planner has already
            # let go: the position says which of them is executing.
            found = self._by_position(xy, bound, status.state == State.IDLE)
            done = done if found is None else found
        self.done = min(self.acked, max(self.done, done))
        return self.done

    def _by_position(self, xy: tuple[float, float], bound: int, idle: bool) -> int | None:
        """The earliest acknowledged moving line from :attr:`done` to ``bound`` whose segment
        holds ``xy`` (all acknowledged lines when idle at the last one's end); None if none."""
        start = bisect.bisect_left(self.moving, self.done)
        for p in self.moving[start:]:
            if p > bound:
                break
            if _to_segment(xy, self._from[p], self.entries[p].xy) <= ON_SEGMENT:
                last = p == self.moving[-1]
                at_end = math.dist(xy, self.entries[p].xy) <= ON_SEGMENT
                return self.acked if (idle and last and at_end) else p
        return None


ON_SEGMENT = 0.02
"""mm: a reported position this close to a line's segment is on it (Grbl reports 3 decimals
of a position quantised to motor steps)."""


def _to_segment(p: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
    ax, ay = b[0] - a[0], b[1] - a[1]
    length2 = ax * ax + ay * ay
    u = 0.0 if length2 == 0 else ((p[0] - a[0]) * ax + (p[1] - a[1]) * ay) / length2
    u = min(1.0, max(0.0, u))
    return math.hypot(p[0] - a[0] - u * ax, p[1] - a[1] - u * ay)


def _xy_of(status: Status | None) -> tuple[float, float] | None:
    """The machine position a status report gives (MPos, or WPos + the last WCO)."""
    if status is None:
        return None
    if status.mpos is not None:
        return (status.mpos[0], status.mpos[1])
    if status.wpos is not None:
        wco = status.wco or (0.0, 0.0)
        return (status.wpos[0] + wco[0], status.wpos[1] + wco[1])
    return None


def _longest_dwell(lines: Sequence[str]) -> float:
    longest = 0.0
    for text in lines:
        if text.startswith("G4P"):
            longest = max(longest, float(text[3:]))
    return longest


def line_effects(
    lines: Sequence[str], start: tuple[float, float] = (0.0, 0.0)
) -> tuple[list[bool], list[tuple[float, float]]]:
    """Per line, whether Grbl plans a moving block for it, and the position after it (parser)."""
    state = ParserState(position=(start[0], start[1], 0.0))
    moves: list[bool] = []
    targets: list[tuple[float, float]] = []
    parsed_as: dict[str, object] = {}  # parse_line is a pure function with frozen results
    for text in lines:
        parsed = parsed_as.get(text)
        if parsed is None:
            parsed = parsed_as[text] = parse_line(text.strip())
        moved = False
        if isinstance(parsed, Block):
            step = state.step(parsed)
            if not isinstance(step, Error):
                if step.target is not None:
                    moved = step.target != state.position
                state = step.state
        moves.append(moved)
        targets.append((state.position[0], state.position[1]))
    return moves, targets


def resume_lines(
    lines: Sequence[str],
    first: int,
    pen_up: Sequence[str],
    pen_down: Sequence[str],
    start: tuple[float, float] | None = None,
) -> list[str]:
    """The preamble that resumes ``lines`` at index ``first`` on a freshly reset machine.

    Runs ``lines[:first]`` through Grbl's own parser (:class:`ParserState`) to find the modal
    state and where line ``first`` starts from, then returns: units and distance modes, the pen
    up, a rapid travel there (or to ``start``, a point inside line ``first``'s move: see
    :func:`resume_point`), the pen down again if it was down (``pen_down`` applied to that
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
    x, y = start if start is not None else state.position[:2]
    out = [f"{state.units}\n", f"{state.distance}\n", "G94\n", *pen_up]
    out.append(gcode.move(x, y, rapid=True))
    if pen_is_down:
        out += pen_down
    if state.feed_mode != "G94":
        out.append(f"{state.feed_mode}\n")
    return out


def resume_point(
    lines: Sequence[str], first: int, at: tuple[float, float] | None
) -> tuple[str, tuple[float, float]] | None:
    """Line ``first`` cut to start at ``at``, when a stop left the machine inside its move.

    A feed hold stops Grbl part of the way along a line. Resuming there, rather than at the
    line's start, draws nothing twice: the line's remaining part, sent with its inverse-time
    feed divided by the remaining fraction (same speed), from ``at``. Returns ``(line,
    start)``, or None when ``at`` is not inside an inverse-time (G93) move of line ``first``.
    """
    if at is None or not 0 < first < len(lines):
        return None
    state = _run_parser(ParserState(), lines[:first], "line")
    parsed = parse_line(lines[first].strip())
    if not isinstance(parsed, Block):
        return None
    step = state.step(parsed)
    if isinstance(step, Error) or step.target is None or step.state.feed_mode != "G93":
        return None
    a, b = state.position[:2], step.target[:2]
    ax, ay = b[0] - a[0], b[1] - a[1]
    length2 = ax * ax + ay * ay
    if length2 == 0 or _to_segment(at, a, b) > ON_SEGMENT:
        return None
    done = ((at[0] - a[0]) * ax + (at[1] - a[1]) * ay) / length2
    if not RESUME_INSIDE < done < 1 - RESUME_INSIDE:
        return None
    feed = step.feed_rate / (1.0 - done)
    return gcode.move(b[0], b[1], feed=feed, decimals=3), (float(at[0]), float(at[1]))


RESUME_INSIDE = 0.02
"""A stop within this fraction of a line's ends resumes at the line's start (or the next)."""


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
