"""A strict simulated EiBotBoard (firmware 3.x, legacy replies), on a simulated clock.

:class:`SimulatedEBB` takes the host's bytes (:meth:`~SimulatedEBB.write`), splits lines as the
firmware does (CR or LF ends a line, a second one in a row is ignored, other control bytes are
dropped), parses each with :func:`firmware_protocols.ebb.commands.parse_command` (its error
reply for anything the board rejects) and answers in legacy response mode exactly (``CU,10,1``
switches to the future syntax). One line is processed at a time; each takes
:attr:`~SimulatedEBB.command_time` seconds (the reference's Performance table for motion
commands; an assumption for the rest) before it acts and replies.

Motion commands (``LM LT T3 SM XM HM EM SP TP S2``, ``SM`` delays) go through the motion FIFO:
one executing, up to ``fifo_depth`` waiting (1 at boot, ``CU,4,n`` up to ``QU,2`` = 32). A
motion command that finds the FIFO full is not answered until there is room (nor is any
line after it), as on the board. The stepper ISR runs at 25 kHz: an entry is loaded on a tick
and runs from the next one, the following entry is loaded on the tick the previous finishes
(no gap). Steps come from :mod:`firmware_protocols.ebb.motion` (and :mod:`sim.ebb.steps` for
``SM``/``XM``/``HM``); a servo move or ``EM`` takes one tick, plus its delay in ms.

State the host can read: ``QS`` (global step counters, cleared by ``CS``, ``EM`` and boot),
``QM``/``QG`` (command executing, motors moving, FIFO not empty), ``QB`` (the PRG button
latch, cleared by reading it), ``QP``, ``QR`` (the servo's power), ``QU``, ``QT`` (the nickname
``ST`` stored: kept through resets, as in flash), ``V``. ``ES``
stops at the current tick and flushes the FIFO. ``R`` re-initialises, ``RB`` reboots (the USB
connection drops). Fault hooks: :meth:`~SimulatedEBB.stall_usb`,
:meth:`~SimulatedEBB.reset_board`, :meth:`~SimulatedEBB.press_button`. Everything executed is
in :attr:`~SimulatedEBB.recorder` (:class:`~sim.ebb.recorder.Recorder`).

Refusals: the error line (``format_error``) and nothing after it, as the firmware 3.0.3 source
(``CheckForAndPrintErrors``) prints it, not the ``OK`` the reference's prose mentions; commands
the shared parser knows but does not model (``UnsupportedCommand``: ``TP``, ``QL``, ``QN``,
``L3``, ``ST`` without its comma...) are refused as unknown and noted in the recorder's
events, never guessed. A line with characters after its last parameter runs, answers, then
``!7`` (``format_reply``).

RC servo channels (``S2``, ``SP``): up to :data:`SERVO_CHANNELS` (8), the boot's pen-up
holding channel 1 on RP4. A servo move takes the channel its pin has, else the first free one
(at parse time: the firmware takes it when the move runs, which only differs for two new pins
queued at once); on a channel beyond ``SC,8``'s count, or with none free, it is answered ``OK``
and ignored, as ``RCServo2_Move`` does (a recorder event says so). ``S2,0,pin`` frees the pin's
channel at once; ``S2`` without a pin is RP0's. A pen whose channel ``SC,8`` leaves out gets no
pulse until a servo command reaches it again. ``SC,8`` above 8 acts as 8, ``SC,9`` above 6 as
6 and 0 as 1.

Documented simplifications: ``CS`` during a move clears the accumulators from the next move on;
for ``LT``/``T3`` ``QM`` reports a motor moving while the move lasts if it has a nonzero rate,
accel or jerk; limit switches, the engraver, GPIO and analog commands are not simulated
(``parse_command`` decides whether they are accepted; accepted ones answer ``OK``).
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from firmware_protocols.ebb.commands import (
    COMMAND_SINCE,
    Command,
    LineReader,
    UnsupportedCommand,
    format_error,
    format_reply,
    nickname_shown,
    parse_command,
)
from firmware_protocols.ebb.errors import EBBCommandError, unknown_command
from firmware_protocols.ebb.motion import (
    TICK_HZ,
    Move,
    axis_final,
    cleared_accumulator,
    lm_direction,
)
from sim.ebb.recorder import Recorder, Segment
from sim.ebb.servo import ServoSegment
from sim.ebb.steps import hm_move, move_positions, sm_move

__all__ = [
    "DEFAULT_COMMAND_TIME",
    "FIFO_MAX",
    "SimulatedEBB",
]

FIFO_MAX = 32
"""``QU,2``: the largest motion FIFO firmware 3.0 allows (``COMMAND_FIFO_MAX_LENGTH``)."""

DEFAULT_COMMAND_TIME = {
    "SM": 0.002,
    "XM": 0.002,
    "HM": 0.002,
    "LM": 0.004,
    "LT": 0.004,
    "L3": 0.004,
    "T3": 0.004,
    "TD": 0.004,
}
"""Seconds the board spends on one line before acting: the reference's Performance table
(firmware 3.0, the shortest move it sustains without gaps with both motors at 25 kHz)."""

OTHER_COMMAND_TIME = 0.0002
"""Seconds for any other line (an assumption: the reference gives no figure)."""

PEN_PIN = 4
"""RP4 (RB1): the pen servo's output at boot (``g_servo2_RPn``), given channel 1."""
S2_DEFAULT_PIN = 0
"""``S2``'s RPn when none is given: 0, as the firmware's ``Pin = 0`` before its optional
``extract_number`` (``S2,0`` alone turns off RP0, which has no channel: nothing happens)."""
DEFAULT_SP_PIN = 1
"""``SP``'s port B pin when none is given (RB1, RP4): the pen output moves back there."""
SERVO_CHANNELS = 8
"""Software RC servo channels (firmware 3.0: ``SC,8`` takes 1 to 8; larger values act as 8)."""
MAX_SLOT_MS = 6
"""``SC,9``'s largest slot, ms (larger values act as 6; 0 acts as 1: the slot ISR runs every
ms and switches when its counter, just incremented, is at least the slot)."""

_VERSION_TEXT = "EBBv13_and_above EB Firmware Version {}"
STACK_HIGH_WATER = 0xE00
"""``QU,4``/``QU,5``: the software stack is not simulated; its empty start (0xE00) is reported."""

_MOTION = {"LM", "LT", "T3", "SM", "XM", "HM", "EM", "SP", "S2"}
_EPS = 1e-9


@dataclass
class _Job:
    """One motion-FIFO entry: kind is move, delay, servo or enable."""

    number: int
    line: bytes
    kind: str
    move: Move | None = None
    full_rate: tuple[bool, bool] = (False, False)
    ticks: int = 0  # delay ticks (delay, servo)
    servo: tuple[int, int, int] | None = None  # (pin, position, rate)
    enable: tuple[int, int] | None = None


@dataclass
class _Running:
    job: _Job
    load_tick: int
    origin: tuple[int, int]
    accumulators: tuple[int, int]
    positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    final: tuple[int, int] = (0, 0)
    axis_end: tuple[int, int] = (0, 0)

    @property
    def ticks(self) -> int:
        if self.job.kind == "move":
            return max(len(self.positions), 1)
        return max(self.job.ticks, 1)

    @property
    def end_tick(self) -> int:
        return self.load_tick + self.ticks

    def offset(self, tick: int) -> np.ndarray:
        """Steps moved relative to the origin after absolute tick ``tick``."""
        i = min(tick - self.load_tick, len(self.positions))
        if i <= 0:
            return np.zeros(2, dtype=np.int64)
        return self.positions[i - 1]


@dataclass
class _Line:
    arrival: float
    text: bytes


class SimulatedEBB:
    """An EiBotBoard running ``version`` (``"3.0.3"``; a ``"2.x"`` string for refusal tests),
    on a simulated clock from 0 (``clock="real"``: :meth:`poll` follows the wall clock).

    ``pen_pin``: the port B pin the pen-lift motor is wired to (1, RB1: the AxiDraw's servo;
    2, RB2: the NextDraw's brushless motor). ``SP``'s pin (RB1 when none is given) routes the
    pen pulses, as the firmware's ``g_servo2_RPn``; the pen moves only with pulses on its pin."""

    def __init__(
        self,
        version: str = "3.0.3",
        clock: str = "simulated",
        command_time: dict[str, float] | None = None,
        other_command_time: float = OTHER_COMMAND_TIME,
        servo_min: int = 22565,
        servo_max: int = 15302,
        servo_rate: int = 400,
        servo_timeout_ms: int = 60_000,
        pen_pin: int = 1,
    ) -> None:
        if clock not in ("simulated", "real"):
            raise ValueError(f"clock: expected 'simulated' or 'real', got {clock!r}")
        parts = version.split(".")
        if len(parts) != 3 or not all(p.isdigit() for p in parts):
            raise ValueError(f"version: expected like '3.0.3', got {version!r}")
        if not 0 <= pen_pin <= 7:
            raise ValueError(f"pen_pin: a port B pin 0-7, got {pen_pin}")
        self.pen_rpn = pen_pin + 3
        """The RPn the pen-lift motor is wired to: the pen moves with the pulses there only."""
        self.version = version
        self.version_tuple = tuple(int(p) for p in parts)
        self.clock = clock
        self.command_time = dict(DEFAULT_COMMAND_TIME if command_time is None else command_time)
        self.other_command_time = float(other_command_time)
        self._boot_servo = (servo_min, servo_max, servo_rate, servo_timeout_ms)
        self.lock = threading.RLock()
        self.recorder = Recorder()
        self.on_close: list[Callable[[], None]] = []
        self.closed = False
        self.silent = False
        self.nickname = b""
        self._now = 0.0
        self._wall_origin = time.monotonic()
        self._physical = np.zeros(2, dtype=np.int64)
        self._out: list[tuple[float, bytes]] = []
        self._stalls: list[tuple[float, float]] = []
        self._scheduled: list[tuple[float, int, Callable[[], None]]] = []
        self._order = 0
        self._number = 0
        self._lines: deque[_Line] = deque()
        self._reader = LineReader()
        self._boot(0.0)

    # -- clock and bytes ------------------------------------------------------------------

    @property
    def now(self) -> float:
        return self._now

    def write(self, data: bytes) -> int:
        """Bytes from the host arriving now (held while the USB is stalled)."""
        self._check_open()
        arrival = self._usb_free(self._now)
        for byte in bytes(data):
            for line in self._reader.feed(bytes((byte,))):
                self._lines.append(_Line(arrival, line))
        return len(data)

    def read(self) -> bytes:
        """Everything printed up to now."""
        return b"".join(chunk for _, chunk in self.read_timed())

    def read_timed(self) -> list[tuple[float, bytes]]:
        """What the board printed up to now, with the time each chunk left it."""
        ready = [(t, c) for t, c in self._out if t <= self._now + _EPS]
        self._out = [(t, c) for t, c in self._out if t > self._now + _EPS]
        return ready

    @property
    def out_waiting(self) -> int:
        return sum(len(c) for t, c in self._out if t <= self._now + _EPS)

    @property
    def busy(self) -> bool:
        """Lines waiting or motion running: time alone changes what the host will see."""
        return bool(self._lines or self._current or self._fifo or self._out or self._scheduled)

    def quiet_until(self) -> float | None:
        """Not known in advance (the link polls)."""
        return None

    def advance(self, seconds: float) -> None:
        self.advance_to(self._now + seconds)

    def advance_to(self, t: float) -> None:
        """Run the board to simulated time ``t`` (no effect if it is already later)."""
        while True:
            when, action = self._next_event()
            if action is None or when > t + _EPS:
                break
            self._now = max(self._now, when)
            action()
        self._now = max(self._now, t)

    def poll(self) -> None:
        """With ``clock="real"``, catch the simulation up with the wall clock."""
        if self.clock == "real":
            self.advance_to(time.monotonic() - self._wall_origin)

    def run_until_idle(self, limit: float = 3600.0) -> None:
        """Advance until no line is waiting and no motion runs (at most ``limit`` s more)."""
        end = self._now + limit
        while self._now < end and (self._lines or self._current or self._fifo):
            when, action = self._next_event()
            if action is None or when > end:
                break
            self.advance_to(when)
        self.advance_to(self._now)

    def close(self) -> None:
        self.closed = True

    def _check_open(self) -> None:
        if self.closed:
            raise ConnectionError("the simulated EBB is closed")

    # -- fault hooks ----------------------------------------------------------------------

    def stall_usb(self, at: float, seconds: float) -> None:
        """From simulated time ``at`` for ``seconds`` the USB moves nothing: the host's bytes
        and the board's replies wait (motion goes on)."""
        if not (math.isfinite(at) and math.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"stall_usb: need finite at and seconds >= 0, got {at}, {seconds}")
        self._stalls.append((float(at), float(at) + float(seconds)))
        self._stalls.sort()

    def reset_board(self, at: float) -> None:
        """At simulated time ``at`` the board resets (power glitch, watchdog): motion stops
        where it is, everything queued or configured is lost, it boots again and its USB
        connection drops (the host must open the port again)."""
        self._schedule(at, lambda: self._reboot(drop_usb=True))

    def press_button(self, at: float) -> None:
        """The PRG button is pressed at simulated time ``at`` (latched until ``QB``/``QG``)."""
        self._schedule(at, self._press)

    def drop_connection(self) -> None:
        """The USB cable is pulled: the host's port fails from now on."""
        for callback in list(self.on_close):
            callback()

    def _press(self) -> None:
        self._button = True
        self.recorder.events.append((self._now, "PRG button pressed"))

    def _schedule(self, at: float, action: Callable[[], None]) -> None:
        self._order += 1
        self._scheduled.append((float(at), self._order, action))
        self._scheduled.sort(key=lambda item: item[:2])

    def _usb_free(self, t: float) -> float:
        for start, end in self._stalls:
            if start <= t < end:
                t = end
        return t

    # -- boot and state -------------------------------------------------------------------

    def _boot(self, t: float) -> None:
        servo_min, servo_max, rate, timeout = self._boot_servo
        self._boot_time = t
        self._cp_free = t
        self._waiting: tuple[_Job, Command] | None = None  # a motion line with no room yet
        self._blocked: Callable[[float], None] | None = None  # HM, CU,4: wait for no motion
        self._fifo: deque[_Job] = deque()
        self._current: _Running | None = None
        self.fifo_depth = 1
        self._global_origin = self._physical.copy()
        self._accumulators = (0, 0)
        self._button = False
        self.ack = True
        self.limit_checks = True
        self.future_syntax = False
        self.auto_enable = True
        self.config: dict[int, int] = {}
        self.motors_enabled = (False, False)
        self.step_mode = 1
        self.servo_min, self.servo_max = servo_min, servo_max
        self.servo_rate_up = self.servo_rate_down = rate
        self.servo_channels, self.servo_slot_ms = SERVO_CHANNELS, 3
        self.servo_timeout_ms = timeout
        self._servo_power_until = -math.inf
        self.pen_up = True
        self.servo_rpn = PEN_PIN  # where SP sends the pen servo's pulses (g_servo2_RPn)
        # Each channel's RPn (0: free); the boot's pen-up took channel 1 for RP4.
        self.channels = [PEN_PIN] + [0] * (SERVO_CHANNELS - 1)
        here = servo_min if self.pen_rpn == PEN_PIN else 0  # the boot's pen-up, on RP4
        self._servo = ServoSegment(t, here, here, 0, self._servo_period(), t)
        self.recorder.servo.append(self._servo)
        self.sl_storage = [0] * 32
        self.node_count = 0

    def _reboot(self, drop_usb: bool) -> None:
        t = self._now
        self._blocked = None
        self._stop_motion(t)
        self.recorder.events.append((t, "reboot" if drop_usb else "reset (R)"))
        self._boot(t)
        if drop_usb:  # what the host sent or was to receive is lost with the USB connection
            self._out = [(when, chunk) for when, chunk in self._out if when <= t]
            self._lines.clear()
            self._reader = LineReader()
            self.drop_connection()

    def _servo_period(self) -> float:
        """Seconds between two pulses of a channel (every slot cycled through, used or not;
        with ``SC,8,0`` no channel pulses: the period is then moot, one slot's)."""
        return max(self.servo_channels, 1) * self.servo_slot_ms / 1000.0

    def _channel(self, rpn: int) -> int | None:
        """The channel (0-based) of ``rpn``: the one it has, else the first free one
        (``RCServo2_get_channel_from_RPn``); None when all are taken. RP0 marks a free
        channel, so ``rpn`` 0 finds one and never keeps it."""
        if rpn in self.channels:
            return self.channels.index(rpn)
        return self.channels.index(0) if 0 in self.channels else None

    def _servo_channel(self, t: float, rpn: int, what: str) -> bool:
        """Whether a servo move on ``rpn`` is queued, its channel taken if new. The firmware
        ignores one whose channel is beyond ``SC,8``'s count or that has none free, and still
        answers ``OK`` (``RCServo2_Move``): noted in the recorder's events."""
        channel = self._channel(rpn)
        if channel is None or channel >= self.servo_channels:
            where = "no channel free" if channel is None else f"channel {channel + 1}"
            self.recorder.events.append(
                (t, f"{what} on RP{rpn} ignored: {where}, SC,8 allows {self.servo_channels}")
            )
            return False
        self.channels[channel] = rpn
        return True

    @property
    def version_line(self) -> str:
        """What ``V`` prints."""
        return _VERSION_TEXT.format(self.version)

    @property
    def tick(self) -> int:
        """The last ISR tick at or before now."""
        return math.floor(self._now * TICK_HZ + _EPS)

    def steps(self) -> tuple[int, int]:
        """The global step counters (what ``QS`` prints) now."""
        position = self._position(self.tick) - self._global_origin
        return int(position[0]), int(position[1])

    def motor_position(self) -> tuple[int, int]:
        """Physical steps since the device was made (not cleared by CS/EM/reboots)."""
        position = self._position(self.tick)
        return int(position[0]), int(position[1])

    def _position(self, tick: int) -> np.ndarray:
        running = self._current
        if running is None:
            return self._physical.copy()
        return self._physical + running.offset(tick)

    @property
    def fifo_count(self) -> int:
        """Motion commands waiting in the FIFO (not counting the executing one)."""
        return len(self._fifo)

    def pen_position(self) -> int:
        """The pen servo's pulse width now (1/12 MHz units)."""
        return int(self._servo.at(self._now))

    def servo_powered(self) -> bool:
        return self._now < self._servo_power_until

    # -- events ---------------------------------------------------------------------------

    def _next_event(self) -> tuple[float, Callable[[], None] | None]:
        best: tuple[float, Callable[[], None] | None] = (math.inf, None)
        if self._current is not None:
            best = (self._current.end_tick / TICK_HZ, self._finish_current)
        if self._scheduled and self._scheduled[0][0] < best[0]:
            best = (self._scheduled[0][0], self._run_scheduled)
        if self._waiting is None and self._blocked is None and self._lines:
            line = self._lines[0]
            start = max(line.arrival, self._cp_free)
            done = start + self._time_for(line.text)
            if done < best[0]:
                best = (done, self._process_line)
        return best

    def _run_scheduled(self) -> None:
        _, _, action = self._scheduled.pop(0)
        action()

    def _time_for(self, text: bytes) -> float:
        name = text.split(b",", 1)[0][:2].upper().decode("ascii", "replace")
        return self.command_time.get(name, self.other_command_time)

    def _emit(self, t: float, data: bytes) -> None:
        if not self.silent:
            self._out.append((self._usb_free(t), data))

    # -- the motion engine ----------------------------------------------------------------

    def _finish_current(self) -> None:
        running = self._current
        assert running is not None
        end = running.end_tick
        self._record(running, running.ticks)
        self._physical = self._physical + running.offset(end)
        if running.job.kind == "move":
            self._accumulators = running.final
        self._current = None
        if self._fifo:
            self._load(self._fifo.popleft(), end)
        self._unblock()

    def _record(self, running: _Running, ticks: int) -> None:
        job = running.job
        origin = (int(self._physical[0]), int(self._physical[1]))
        self.recorder.segments.append(
            Segment(
                job.number,
                job.line,
                job.kind,
                running.load_tick,
                ticks,
                origin,
                job.move,
                running.accumulators,
                job.full_rate,
            )
        )

    def _load(self, job: _Job, tick: int) -> None:
        origin = (int(self._physical[0]), int(self._physical[1]))
        running = _Running(job, tick, origin, self._accumulators)
        t = (tick + 1) / TICK_HZ  # the entry acts on the tick after it is loaded
        if job.kind == "move":
            assert job.move is not None
            positions, final = move_positions(job.move, self._accumulators, job.full_rate)
            running.positions, running.final = positions, final
            ends = []
            for i in range(2):
                changes = np.flatnonzero(np.diff(positions[:, i], prepend=0))
                ends.append(int(changes[-1]) + 1 if len(changes) else 0)
            running.axis_end = (ends[0], ends[1])
            if self.auto_enable:
                self.motors_enabled = (True, True)
        elif job.kind == "servo":
            assert job.servo is not None
            pin, position, rate = job.servo
            if pin == self.pen_rpn:
                self._servo_to(t, position, rate)
            if pin == self.servo_rpn:  # the firmware's pen state follows SP's output
                self.pen_up = position == self.servo_min
        elif job.kind == "enable":
            assert job.enable is not None
            e1, e2 = job.enable
            if e1:
                self.step_mode = e1
            self.motors_enabled = (e1 > 0, e2 > 0)
            self._global_origin = self._physical.copy()
            self._accumulators = (0, 0)
            self.recorder.events.append((t, f"EM,{e1},{e2}: step mode {self.step_mode}"))
        self._current = running

    def _servo_to(self, t: float, position: int, rate: int) -> None:
        value = int(self._servo.at(t))
        if value == 0:
            value = position
        self._servo = ServoSegment(t, value, position, rate, self._servo_period(), self._boot_time)
        self.recorder.servo.append(self._servo)

    def _enqueue(self, job: _Job, t: float) -> None:
        if self._current is None and not self._fifo:
            self._load(job, math.ceil(t * TICK_HZ - _EPS))
        else:
            self._fifo.append(job)

    def _idle(self) -> bool:
        return self._current is None and not self._fifo

    def _stop_motion(self, t: float) -> bool:
        """Stop at the last tick before ``t`` and flush the FIFO; whether anything was
        executing or queued."""
        interrupted = bool(self._fifo)
        self._fifo.clear()
        running = self._current
        if running is not None:
            tick = math.floor(t * TICK_HZ + _EPS)
            done = max(0, min(tick - running.load_tick, running.ticks))
            interrupted = interrupted or running.job.kind == "move"
            self._record(running, done)
            self._physical = self._physical + running.offset(running.load_tick + done)
            if running.job.kind == "move":
                self._accumulators = self._accumulators_after(running, done)
            self._current = None
        self._waiting = None
        self._unblock()
        return interrupted

    def _accumulators_after(self, running: _Running, done: int) -> tuple[int, int]:
        move = running.job.move
        assert move is not None
        if done >= running.ticks:
            return running.final
        out = []
        for i in range(2):
            if running.job.full_rate[i] or done == 0:
                start = running.accumulators[i]
                out.append(0 if (done and move.clear & (1 << i)) else start)
                continue
            if move.command == "LM":
                if done >= running.axis_end[i]:
                    out.append(running.final[i])
                    continue
                _, rate, accel = lm_direction(move.steps[i], move.rate[i], move.accel[i])
                jerk = 0
            else:
                rate, accel = move.rate[i], move.accel[i]
                jerk = move.jerk[i] if move.command == "T3" else 0
            start = running.accumulators[i]
            if move.clear & (1 << i):
                start = cleared_accumulator(rate, accel, jerk)
            out.append(axis_final(done, rate, accel, jerk, start)[1])
        return (out[0], out[1])

    def _qm_bits(self) -> tuple[int, int, int, int]:
        running = self._current
        executing = int(running is not None or bool(self._fifo))
        fifo = int(bool(self._fifo))
        m1 = m2 = 0
        if running is not None and running.job.kind == "move":
            done = self.tick - running.load_tick
            move = running.job.move
            assert move is not None
            if move.command == "LM":
                m1 = int(done < running.axis_end[0])
                m2 = int(done < running.axis_end[1])
            else:
                jerk = move.jerk if move.command == "T3" else (0, 0)
                active = [bool(move.rate[i] or move.accel[i] or jerk[i]) for i in range(2)]
                m1, m2 = (
                    int(active[0] and done < running.ticks),
                    int(active[1] and done < running.ticks),
                )
        return executing, m1, m2, fifo

    # -- the command processor ------------------------------------------------------------

    def _unblock(self) -> None:
        """A waiting motion line goes in when there is room; a line waiting for the motion to
        end (``HM``, ``CU,4``) goes on when it has."""
        t = self._now
        if self._waiting is not None and len(self._fifo) < self.fifo_depth:
            job, command = self._waiting
            self._waiting = None
            self._enqueue(job, t)
            self._answer(t, command)
            self._cp_free = t
        if self._blocked is not None and self._idle():
            resume, self._blocked = self._blocked, None
            resume(t)
            self._cp_free = t

    def _process_line(self) -> None:
        line = self._lines.popleft()
        t = self._now
        self._cp_free = t
        name = line.text.split(b",", 1)[0].upper()
        try:
            command = parse_command(line.text, limit_checks=self.limit_checks)
        except EBBCommandError as error:
            self._refuse(t, name, error.reply, name.decode("latin-1"))
            return
        except UnsupportedCommand as error:
            # A command the board knows and the shared model does not: never guessed.
            self.recorder.events.append((t, f"not simulated, refused as unknown: {error}"))
            self._refuse(t, name[:2], unknown_command(name[:2]))
            return
        if self.version_tuple < COMMAND_SINCE.get(command.name, (0, 0, 0)):
            self._refuse(t, name, unknown_command(command.name.encode()))
            return
        try:
            self._handle(command, line.text, t)
        except EBBCommandError as error:  # a move the firmware arithmetic refuses
            self._refuse(t, name, error.reply, command.name)

    def _refuse(self, t: float, name: bytes, reply: bytes, parser: str = "") -> None:
        """An error line; ``parser``: the command whose parser found it (``QU`` prefixes it)."""
        if self.future_syntax:
            self._emit(t, name + b"," + reply + b"\n")
        else:
            self._emit(t, format_error(reply, parser))

    def _handle(self, command: Command, text: bytes, t: float) -> None:
        name = command.name
        if name in _MOTION:
            job = self._motion_job(command, text, t)
            if job is None:
                return
            if len(self._fifo) < self.fifo_depth:
                self._enqueue(job, t)
                self._answer(t, command)
            else:
                self._waiting = (job, command)
            return
        handler = getattr(self, f"_cmd_{name}", None)
        if handler is None:
            self._answer(t, command)
            return
        handler(command, t)

    def _next_number(self) -> int:
        self._number += 1
        return self._number

    def _motion_job(self, command: Command, text: bytes, t: float) -> _Job | None:
        """The FIFO entry of a motion command, or None when it acts (and answers) at once."""
        name, params = command.name, command.params
        if name in ("LM", "LT", "T3"):
            return _Job(self._next_number(), text, "move", command.move())
        if name in ("SM", "XM"):
            duration, a, b = params[0], params[1], params[2] if len(params) > 2 else 0
            clear = params[3] if len(params) > 3 else 0
            steps = (a, b) if name == "SM" else (_wrap32(a + b), _wrap32(a - b))
            if steps == (0, 0):
                ticks = TICK_HZ // 1000 * min(duration, 100_000)
                return _Job(self._next_number(), text, "delay", ticks=ticks)
            move, full = sm_move(duration, steps, clear)
            return _Job(self._next_number(), text, "move", move, full)
        if name == "HM":
            self._start_hm(command, text, t)
            return None
        if name == "EM":
            if len(params) == 1:
                return None  # the firmware returns before queueing it and answers nothing
            return _Job(self._next_number(), text, "enable", enable=(params[0], params[1]))
        if name == "SP":
            return self._pen_job(command, text, t)
        # S2
        position = params[0] if params else 0
        pin = params[1] if len(params) > 1 else S2_DEFAULT_PIN
        if position == 0:
            self._servo_off(t, pin)
            self._answer(t, command)
            return None
        rate = params[2] if len(params) > 2 else 0
        delay = params[3] if len(params) > 3 else 0
        if not self._servo_channel(t, pin, "S2"):
            self._answer(t, command)
            return None
        if pin == PEN_PIN:
            self._power_servo(t)
        ticks = TICK_HZ // 1000 * delay
        return _Job(self._next_number(), text, "servo", ticks=ticks, servo=(pin, position, rate))

    def _servo_off(self, t: float, rpn: int) -> None:
        """The output on ``rpn`` stops at once (its channel freed): no pulse, the servo limp."""
        if rpn and rpn in self.channels:
            self.channels[self.channels.index(rpn)] = 0
        if rpn == self.pen_rpn:
            self._servo = ServoSegment(t, 0, 0, 0, self._servo_period(), self._boot_time)
            self.recorder.servo.append(self._servo)

    def _pen_job(self, command: Command, text: bytes, t: float) -> _Job | None:
        value = command.params[0]
        duration = command.params[1] if len(command.params) > 1 else 0
        pin = command.params[2] if len(command.params) > 2 else DEFAULT_SP_PIN
        if pin > 7:  # the firmware falls back to its default pin
            pin = DEFAULT_SP_PIN
        if pin + 3 != self.servo_rpn:  # the pen output moves: the old one stops at once
            self._servo_off(t, self.servo_rpn)
            self.servo_rpn = pin + 3
        rpn = self.servo_rpn
        if value in (2, 3):  # at once, bypassing the FIFO
            if value == 3:
                self.servo_max = self.servo_min
                for job in self._fifo:
                    if job.servo is not None and job.servo[0] == rpn:
                        job.servo = (rpn, self.servo_min, job.servo[2])
            self._power_servo(t)
            if rpn == self.pen_rpn:
                self._servo_to(t, self.servo_min, self.servo_rate_up)
            self.pen_up = True
            self._answer(t, command)
            return None
        if not self._servo_channel(t, rpn, "SP"):
            self._answer(t, command)
            return None
        up = value == 1
        position = self.servo_min if up else self.servo_max
        rate = self.servo_rate_up if up else self.servo_rate_down
        self._power_servo(t)
        ticks = TICK_HZ // 1000 * duration
        return _Job(self._next_number(), text, "servo", ticks=ticks, servo=(rpn, position, rate))

    def _power_servo(self, t: float) -> None:
        timeout = self.servo_timeout_ms
        self._servo_power_until = math.inf if timeout == 0 else t + timeout / 1000.0

    def _start_hm(self, command: Command, text: bytes, t: float) -> None:
        params = command.params
        frequency = min(max(params[0], 1), 25_000)
        target = (params[1], params[2]) if len(params) > 2 else (0, 0)

        def resume(when: float) -> None:
            here = self.steps()
            steps = (_wrap32(target[0] - here[0]), _wrap32(target[1] - here[1]))
            if steps != (0, 0):
                move, full = hm_move(frequency, steps)
                job = _Job(self._next_number(), text, "move", move, full)
                self._enqueue(job, when)
            self._answer(when, command)

        if self._idle():
            resume(t)
        else:
            self._blocked = resume

    # -- replies --------------------------------------------------------------------------

    def _answer(self, t: float, command: Command, *values: int | str) -> None:
        """The board's reply to ``command`` with its query ``values``: legacy mode from
        :func:`~firmware_protocols.ebb.commands.format_reply`; in the future syntax (``CU,10,1``)
        the name, the values after a comma, and ``<NL>``."""
        if not self.future_syntax:
            self._emit(t, format_reply(command, *values, ack=self.ack))
            return
        data = b"".join(b"," + (v if isinstance(v, bytes) else str(v).encode()) for v in values)
        if command.name == "QG":
            data = f",{int(values[0]):02X}".encode()
        self._emit(t, command.name.encode() + data + b"\n")

    # -- immediate commands ---------------------------------------------------------------

    def _cmd_V(self, command: Command, t: float) -> None:
        self._answer(t, command, self.version_line)

    def _cmd_QS(self, command: Command, t: float) -> None:
        self._answer(t, command, *self.steps())

    def _cmd_CS(self, command: Command, t: float) -> None:
        self._global_origin = self._position(self.tick)
        self._accumulators = (0, 0)
        self._answer(t, command)

    def _cmd_QM(self, command: Command, t: float) -> None:
        self._answer(t, command, *self._qm_bits())

    def _cmd_QB(self, command: Command, t: float) -> None:
        pressed, self._button = self._button, False
        self._answer(t, command, int(pressed))

    def _cmd_QG(self, command: Command, t: float) -> None:
        executing, m1, m2, fifo = self._qm_bits()
        pressed, self._button = self._button, False
        value = (pressed << 5) | (self.pen_up << 4) | (executing << 3) | (m1 << 2)
        self._answer(t, command, value | (m2 << 1) | fifo)

    def _cmd_QT(self, command: Command, t: float) -> None:
        if self.future_syntax:
            self._answer(t, command, nickname_shown(self.nickname))
        else:
            self._answer(t, command, self.nickname)

    def _cmd_ST(self, command: Command, t: float) -> None:
        self.nickname = command.text  # in flash: kept across resets
        self._answer(t, command)

    def _cmd_QR(self, command: Command, t: float) -> None:
        self._answer(t, command, int(self.servo_powered()))

    def _cmd_QP(self, command: Command, t: float) -> None:
        self._answer(t, command, int(self.pen_up))

    def _cmd_QE(self, command: Command, t: float) -> None:
        resolution = {1: 16, 2: 8, 3: 4, 4: 2, 5: 1}[self.step_mode]
        self._answer(t, command, *(resolution if on else 0 for on in self.motors_enabled))

    def _cmd_ES(self, command: Command, t: float) -> None:
        interrupted = self._stop_motion(t)
        if command.params and command.params[0] == 1:
            self.motors_enabled = (False, False)
        self.recorder.events.append((t, f"ES: interrupted {int(interrupted)}"))
        self._answer(t, command, int(interrupted))

    def _cmd_QU(self, command: Command, t: float) -> None:
        values = {
            1: (0,),  # PortB at the last limit switch trigger: never triggered
            2: (FIFO_MAX,),
            3: (self.fifo_depth,),
            4: (STACK_HIGH_WATER,),
            5: (STACK_HIGH_WATER,),
            6: (len(self._fifo),),
            60: (self.config.get(60, 0),),
            61: (self.config.get(61, 0),),
            200: self._accumulators,
        }[command.params[0]]
        self._answer(t, command, *values)

    def _cmd_CU(self, command: Command, t: float) -> None:
        which, value = command.params
        if which == 4:
            size = min(max(value, 1), FIFO_MAX)

            def resume(when: float) -> None:
                self.fifo_depth = size
                self._answer(when, command)

            if self._idle():
                resume(t)
            else:
                self._blocked = resume
            return
        if which == 10:
            if value and not self.future_syntax:
                self._answer(t, command)  # legacy mode answers the lone <NL>
            elif self.future_syntax and not value:
                self._emit(t, b"CUOK\r\n")
            else:
                self._answer(t, command)
            self.future_syntax = bool(value)
            return
        if which == 1:
            self.ack = bool(value)
        elif which == 2:
            self.limit_checks = bool(value)
        elif which == 50:
            self.auto_enable = bool(value)
        self.config[which] = value
        self._answer(t, command)

    def _cmd_SC(self, command: Command, t: float) -> None:
        which, value = command.params
        if which == 4:
            self.servo_min = value
        elif which == 5:
            self.servo_max = value
        elif which == 8:
            self.servo_channels = min(value, SERVO_CHANNELS)
            self._pen_channel_count(t)
        elif which == 9:
            self.servo_slot_ms = max(1, min(value, MAX_SLOT_MS))
        elif which == 10:
            self.servo_rate_up = self.servo_rate_down = value
        elif which == 11:
            self.servo_rate_up = value
        elif which == 12:
            self.servo_rate_down = value
        self._answer(t, command)

    def _pen_channel_count(self, t: float) -> None:
        """After ``SC,8``: the pulse ISR cycles channels 1..count only, so a pen whose channel
        is beyond the count gets no pulse (limp, its channel kept)."""
        rpn = self.pen_rpn
        if rpn in self.channels and self.channels.index(rpn) >= self.servo_channels:
            self._servo = ServoSegment(t, 0, 0, 0, self._servo_period(), self._boot_time)
            self.recorder.servo.append(self._servo)

    def _cmd_SR(self, command: Command, t: float) -> None:
        self.servo_timeout_ms = command.params[0]
        if len(command.params) > 1:
            if command.params[1]:
                self._power_servo(t)
            else:
                self._servo_power_until = -math.inf
        self._answer(t, command)

    def _cmd_R(self, command: Command, t: float) -> None:
        self._answer(t, command)
        self._reboot(drop_usb=False)

    def _cmd_RB(self, command: Command, t: float) -> None:
        self._reboot(drop_usb=True)


def _wrap32(value: int) -> int:
    """A signed 32-bit variable's value (two's complement wrap), as the firmware sums."""
    return ((value + 2**31) % 2**32) - 2**31
