"""A byte-level Grbl 1.1h: serial receive buffer, line protocol, real-time bytes, in simulated time.

:class:`SimulatedGrbl` is what a host sees at the far end of a serial line. ``write(data)`` is the
host sending bytes, ``read()`` what Grbl has printed so far, and :meth:`SimulatedGrbl.advance`
moves the simulated clock on: motion executes (:class:`~sim.grbl.executor.GrblExecutor`), the
receive buffer drains as the planner frees slots, and each line's ``ok`` or ``error:N`` is printed
at the simulated time Grbl would print it.

How it follows the firmware (Grbl 1.1h ``serial.c``, ``protocol.c``, ``system.c``, ``report.c``):

- **Receive buffer.** A 128-byte ring (one slot always empty: 127 bytes stored). A byte arriving
  when it is full is lost, as on hardware; :attr:`SimulatedGrbl.lost_bytes` counts them.
  ``Bf:``'s second field is Grbl's ``serial_get_rx_buffer_available()``, which says 128 when empty.
- **Real-time bytes** (``?``, ``!``, ``~``, ctrl-x, and every byte from 0x80 up) never enter the
  buffer and are acted on at once, even when it is full. Unknown bytes from 0x80 up are dropped.
- **Lines.** The main loop moves characters from the ring into its line; each ``\\n`` or ``\\r``
  ends a line (so ``\\r\\n`` is a line and an empty line: two ``ok``, as on the device), read with
  :func:`firmware_protocols.grbl.parse_line`, checked with :class:`~firmware_protocols.grbl.
  ParserState`. Every line gets exactly one ``ok`` or ``error:N``. While a line waits (planner
  full, dwell, a spindle change waiting for the queue to empty) the loop reads nothing more, so
  the ring fills. When the ring runs dry Grbl starts the cycle (auto cycle start).
- **Pen.** ``M3 S..``/``M4``/``M5`` (and a new S while the spindle runs) wait until all queued
  motion has finished, then take effect; ``G4 P..`` dwells. The pen is down while the spindle runs
  with S > 0 (``pen="spindle"``; with ``pen_servo=(down, up)`` S values, while it runs nearer
  the down value: servo pens are M3 S<down> / M3 S<up>) or while Z is below ``pen_z_below``
  (``pen="z"``).
- **Dwell.** ``G4 P`` waits for the queue to empty and the step idle delay ($1, 25 ms), then
  ``delay_sec`` waits ``ceil(20·P)`` × 50 ms (P read in 32-bit floats, :func:`avr_read_float`),
  letting real-time commands through only at the start of each 50 ms step: a ``?`` is answered
  there, one in the last step after the dwell's ``ok``. The standstills measured on the real
  firmware around ``G1 X10 / G4 P / G1 X20`` (88 / 86 / 133 / 184 / 335 ms for P = 0.002 /
  0.012 / 0.072 / 0.15 / 0.3 s) are made of: $1 (25 ms, the step interrupt holding the motors
  after the last step), ``ceil(20·P)`` × 50 ms, the stop's last step period (MPos counts that
  step about 2 ms before its segment ends) and the next line's way to the machine when the host
  sends it after the dwell's ``ok`` (the ``ok``'s transfer, the host's reaction, the line's
  transfer: 6-7 ms for a host 5 ms late). With such a host this simulator stands 83.8 / 83.8 /
  133.8 / 183.8 / 333.8 ms (before the rounding was modelled: 27 / 37 / 97 / 175 / 325).
- **States** Idle, Run, Hold, Jog, Alarm, Check, Sleep; soft reset prints ``ALARM:3`` first if
  it stopped motion (the machine then stays locked, G-code answers ``error:9``, until ``$X``),
  then the welcome banner, then ``[MSG:'$H'|'$X' to unlock]`` in the Alarm state. A machine with
  homing enabled (``$22=1``) starts in Alarm, as a real plotter does.
- **Blocking delays.** After ``ALARM:N`` the firmware waits 500 ms (``report_alarm_message``)
  printing nothing; bytes and real-time flags are still received. For the limit alarms (1, 2) a
  reset received by then is discarded (the critical-event loop clears it), then
  ``[MSG:Reset to continue]``: only a reset after it works, and ``?`` is never answered; for the
  others a reset is acted on after the delay (a ``?`` with it is lost), a ``?`` alone answered.
  A reset in motion holds the motors for $1 (``mc_reset``'s ``st_go_idle``) before ``ALARM:3``,
  and every reboot waits $1 (``st_reset``) before the banner: ``ALARM:3`` 25 ms after the
  reset, the banner 550 ms after it (reset.log: 27 and 559 ms, with the transfer).
- **Line numbers** (``line_numbers=True``, a ``USE_LINE_NUMBERS`` build, URL ``ln=1``): status
  reports carry ``Ln:<N>`` of the planner's tail block (the one being prepared) when there is one
  with N > 0; the planner holds 14 blocks (``Bf:14,128`` idle, ``[OPT:VN,14,128]``). N words are
  read in every build (negative: error 4, above 10000000: error 27, repeated: error 25).
- **Executed lines.** :attr:`SimulatedGrbl.executed_lines` and
  :attr:`SimulatedGrbl.line_finished_at` record when each line received had taken effect,
  :attr:`SimulatedGrbl.line_received_at` when its last byte arrived.
- **Reading.** The main loop takes :data:`READ_TIME` per byte it reads (``read_time``): after a
  stop (a dwell, a pen change) the lines the host sent meanwhile are read one by one and motion
  starts when the planner is full or the buffer runs dry, as on the reference firmware. A ``?``
  is answered between two lines.

Not modelled: soft limits, overrides changing speeds (their values are only reported), homing
motion (``$H`` sets the machine position to 0 at once), work offsets (WCO is always zero), a feed
hold pausing a dwell (the dwell runs on), bytes lost while ``mc_reset`` busy-waits inside the
serial interrupt, the ``Pn:`` field (the host build reports floating pins as ``Pn:PXYZRHS``),
the phase of the first step interrupt after a start (Timer1 runs on while idle).

Fault hooks for tests: :meth:`~SimulatedGrbl.inject_error`, :meth:`~SimulatedGrbl.schedule_alarm`,
:meth:`~SimulatedGrbl.go_silent`, :meth:`~SimulatedGrbl.emit_garbage`,
:meth:`~SimulatedGrbl.drop_connection`, :meth:`~SimulatedGrbl.freeze_motion` (a stalled
machine); host-side timing in :mod:`sim.grbl.transport`
(:meth:`sim.grbl.protocol_grblsim.Serial.freeze_host`, ``Serial.write_latency``,
``serve_pty(write_latency=...)``).
"""

from __future__ import annotations

import functools
import math
import re
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping

import numpy as np

from firmware_protocols.grbl import (
    Alarm,
    Block,
    Error,
    Feedback,
    Help,
    Home,
    Message,
    Msg,
    Ok,
    ParserState,
    Realtime,
    Restore,
    SetBuildInfo,
    SetSetting,
    SetStartupLine,
    Setting,
    Sleep,
    StartupLine,
    StartupResult,
    State,
    Status,
    Step,
    ToggleCheckMode,
    Unlock,
    ViewBuildInfo,
    ViewParameters,
    ViewParserState,
    ViewSettings,
    ViewStartupLines,
    Welcome,
    format_message,
    is_realtime_byte,
    parse_line,
)
from firmware_protocols.grbl.codes import (
    BUILD_DATE,
    HELP,
    INTEGER_SETTINGS,
    MSG_ALARM_LOCK,
    MSG_DISABLED,
    MSG_ENABLED,
    MSG_PROGRAM_END,
    MSG_RESET_TO_CONTINUE,
    MSG_RESTORING_DEFAULTS,
    MSG_SLEEPING,
    MSG_UNLOCKED,
    RX_BUFFER_SIZE,
)
from firmware_protocols.grbl.parse import scan_number
from sim.grbl.executor import HOLD, RUN, GrblExecutor
from sim.grbl.planner import PLANNER_CAPACITY, Dwell, GrblSettings, MotionBlock, PlanBlock

DEFAULT_SETTINGS: dict[int, float] = {
    0: 10,
    1: 25,
    2: 0,
    3: 0,
    4: 0,
    5: 0,
    6: 0,
    10: 1,
    11: 0.010,
    12: 0.002,
    13: 0,
    20: 0,
    21: 0,
    22: 0,
    23: 0,
    24: 25.0,
    25: 500.0,
    26: 250,
    27: 1.0,
    30: 1000,
    31: 0,
    32: 0,
    100: 250.0,
    101: 250.0,
    102: 250.0,
    110: 500.0,
    111: 500.0,
    112: 500.0,
    120: 10.0,
    121: 10.0,
    122: 10.0,
    130: 200.0,
    131: 200.0,
    132: 200.0,
}
"""Grbl 1.1h's generic defaults (``defaults.h``), in ``$$`` order."""

RX_CAPACITY = RX_BUFFER_SIZE - 1
"""Bytes the receive ring can hold (one slot of 128 always stays empty)."""

ALARM_REPORT_DELAY = 0.5
"""``report_alarm_message``'s ``delay_ms(500)`` after printing ``ALARM:N``."""

READ_TIME = 8 / 115200
"""s the main loop takes per received byte, as measured on the reference firmware (Grbl 1.1h's
host build): back-to-back lines are acknowledged 69.4 µs a byte apart (sendresp.log: 57
bytes in 4 ms; the ``g93`` logs: one ``ok`` a millisecond), the serial pacing of grbl-sim
(``baud_ticks = F_CPU·8/BAUD_RATE``). Slightly faster than the 10-bit wire (86.8 µs a byte), so
a receive ring filled during a stop drains slowly and the planner fills before it runs dry."""


def avr_read_float(text: str, pos: int = 0) -> tuple[float, int] | None:
    """Grbl's ``read_float`` as the firmware computes it, in 32-bit floats: ``(value, end)``.

    The digits (at most 8 kept, :func:`~firmware_protocols.grbl.parse.scan_number`) make an
    integer, turned into a float and scaled by ``0.01`` and ``0.1`` steps (or ``10``), each
    product rounded to float32; so ``P0.15`` is 0.15000000596… and ``N9999999.5`` is 9999999.
    None when there is no digit.
    """
    scanned = scan_number(text, pos)
    if scanned is None:
        return None
    negative, intval, exp, end = scanned
    f32 = np.float32
    value = f32(intval)
    if value != 0:
        while exp <= -2:
            value = f32(float(value) * 0.01)
            exp += 2
        if exp < 0:
            value = f32(float(value) * 0.1)
        while exp > 0:
            value = f32(float(value) * 10.0)
            exp -= 1
    return (-float(value) if negative else float(value)), end


def avr_words(text: str) -> dict[str, float]:
    """The value words of a line in Grbl's buffer form (``N10G4P0.15``), read by
    :func:`avr_read_float`; the last of a repeated letter wins (the parser refuses those)."""
    return dict(_avr_words(text))


@functools.lru_cache(maxsize=4096)
def _avr_words(text: str) -> tuple[tuple[str, float], ...]:
    """:func:`avr_words` as pairs, remembered (long jobs repeat lines)."""
    words: dict[str, float] = {}
    i = 3 if text.startswith("$J=") else 0
    while i < len(text):
        letter = text[i]
        read = avr_read_float(text, i + 1)
        if read is None:
            i += 1
            continue
        words[letter], i = read
    return tuple(words.items())


@functools.lru_cache(maxsize=4096)
def _parse_line(text: str, state: State) -> object:
    """:func:`~firmware_protocols.grbl.parse_line`, remembered: a pure function of the line and
    the state, whose results are frozen values (long jobs repeat lines)."""
    return parse_line(text, state)


_REALTIME = re.compile(b"[\\x18!?~\\x80-\\xff]")
"""The bytes :func:`~firmware_protocols.grbl.is_realtime_byte` says are real-time."""

_WCO_REFRESH = (30, 10)  # REPORT_WCO_REFRESH_BUSY_COUNT, _IDLE_COUNT
_OVR_REFRESH = (20, 10)  # REPORT_OVR_REFRESH_BUSY_COUNT, _IDLE_COUNT
_CRITICAL_ALARMS = (1, 2)  # hard and soft limit: "[MSG:Reset to continue]", locked until reset
_OVERRIDE_STEPS = {
    Realtime.FEED_OVR_COARSE_PLUS: (0, 10),
    Realtime.FEED_OVR_COARSE_MINUS: (0, -10),
    Realtime.FEED_OVR_FINE_PLUS: (0, 1),
    Realtime.FEED_OVR_FINE_MINUS: (0, -1),
    Realtime.SPINDLE_OVR_COARSE_PLUS: (2, 10),
    Realtime.SPINDLE_OVR_COARSE_MINUS: (2, -10),
    Realtime.SPINDLE_OVR_FINE_PLUS: (2, 1),
    Realtime.SPINDLE_OVR_FINE_MINUS: (2, -1),
}
_OVERRIDE_SETS = {
    Realtime.FEED_OVR_RESET: (0, 100),
    Realtime.RAPID_OVR_RESET: (1, 100),
    Realtime.RAPID_OVR_MEDIUM: (1, 50),
    Realtime.RAPID_OVR_LOW: (1, 25),
    Realtime.SPINDLE_OVR_RESET: (2, 100),
}
_OVERRIDE_LIMITS = ((10, 200), (25, 100), (10, 200))


def _nothing() -> None:
    pass


class _Wait:
    """A step of a line that must wait: for motion to end, or for the executor to take an item."""

    __slots__ = ("item",)

    def __init__(self, item: MotionBlock | Dwell | None) -> None:
        self.item = item  # None: wait until all motion has finished (protocol_buffer_synchronize)


class SimulatedGrbl:
    """Grbl 1.1h at the byte level, on a simulated clock (seconds from 0).

    ``settings`` overrides :data:`DEFAULT_SETTINGS` (``{100: 80, 110: 6000, ...}``).
    ``start_in_alarm`` defaults to whether homing is enabled (``$22``). ``clock="real"`` makes
    :meth:`poll` follow the wall clock (for the pseudo-terminal server); ``"simulated"`` (the
    default) moves only with :meth:`advance`. ``pen`` chooses what the recorded pen column follows
    (see the module docstring). ``line_numbers`` builds the firmware with ``USE_LINE_NUMBERS``
    (``Ln:`` in status reports, 14 planner blocks); off by default, as the stock firmware.
    """

    def __init__(
        self,
        settings: Mapping[int, float] | None = None,
        *,
        start_in_alarm: bool | None = None,
        clock: str = "simulated",
        pen: str = "spindle",
        pen_z_below: float = 0.0,
        pen_servo: tuple[float, float] | None = None,
        position_mm: tuple[float, float, float] = (0.0, 0.0, 0.0),
        line_numbers: bool = False,
        read_time: float = READ_TIME,
    ) -> None:
        if clock not in ("simulated", "real"):
            raise ValueError(f"clock: expected 'simulated' or 'real', got {clock!r}")
        if pen not in ("spindle", "z"):
            raise ValueError(f"pen: expected 'spindle' or 'z', got {pen!r}")
        self.settings: dict[int, float] = dict(DEFAULT_SETTINGS)
        for number, value in (settings or {}).items():
            if number not in DEFAULT_SETTINGS:
                raise ValueError(f"settings: unknown setting ${number}")
            self.settings[number] = float(value)
        self.clock = clock
        self.pen_source = pen
        self.pen_z_below = float(pen_z_below)
        self.pen_servo = None if pen_servo is None else (float(pen_servo[0]), float(pen_servo[1]))
        self.line_numbers = bool(line_numbers)
        if not (math.isfinite(read_time) and read_time >= 0):
            raise ValueError(f"read_time: must be a finite number >= 0, got {read_time!r}")
        self.read_time = float(read_time)
        self._read_free_at = 0.0  # when the main loop will have read the bytes paid for
        self._paid_bytes = 0  # bytes at the ring's front the main loop has read (or is reading)
        capacity = PLANNER_CAPACITY - 1 if self.line_numbers else PLANNER_CAPACITY
        self.executor = GrblExecutor(
            self._grbl_settings(), position_mm, auto_start=False, planner_capacity=capacity
        )
        self.executor.on_cycle_stop = self._cycle_stopped
        self.executor.on_block_done = self._block_done
        self.line_finished_at: list[float | None] = []
        """Per line received (index 0 is line 1): the simulated time it had fully taken effect
        and every earlier line too, None until then (forever for lines a reset threw away)."""
        self.line_received_at: list[float] = []
        """Per line received (index 0 is line 1): the simulated time its last byte reached the
        receive buffer (with :attr:`line_finished_at`: what the machine held at any instant)."""
        self._arrivals: deque[float] = deque()  # line ends in the ring, oldest first
        self._line_own: list[float | None] = []  # when each line itself took effect
        self._line_blocks: dict[int, int] = {}  # line -> its planner blocks not yet executed
        self._lines_processed: set[int] = set()
        self._done_prefix = 0
        self._blocked_until: float | None = None
        self._after_block: Callable[[], None] | None = None
        self._restart = False
        self.starvation: list[float] = []
        self._ran_dry: float | None = None
        self._flowing = False
        """Times the planner fell to its last block (so it planned a stop) though no line asked
        for a stop (pen change, dwell, program end), before more motion came: the host did not
        send lines fast enough. Counted when the next move arrives."""
        self._wall_start = time.monotonic()
        self._output: deque[tuple[float, bytes]] = deque()
        self._rx = bytearray()  # the receive ring's bytes, oldest first
        self._rx_head = 0  # ring indices, for Bf:'s exact arithmetic
        self._rx_tail = 0
        self.lost_bytes = 0
        self.lines_received = 0
        self.closed = False
        self.silent = False
        self.on_close: list[Callable[[], None]] = []
        self.lock = threading.RLock()
        """Held by the pty server's thread while it drives the device; the fault hooks take it."""
        self._injected: dict[int, int] = {}
        self._alarms: list[tuple[float, int]] = []
        self.startup_lines = ["", ""]
        self.build_info = ""
        self._pen_events: list[tuple[float, float]] = [(0.0, 0.0)]
        homing = bool(self.settings[22])
        alarm = homing if start_in_alarm is None else start_in_alarm
        self._reset_flags()
        self._boot(alarm)

    # -- host side ---------------------------------------------------------------------------

    @property
    def now(self) -> float:
        """The simulated time in seconds."""
        return self.executor.now

    def write(self, data: bytes) -> int:
        """Bytes from the host, arriving now. Returns ``len(data)`` (lost bytes included)."""
        self._check_open()
        data = bytes(data)
        if _REALTIME.search(data) is None:
            self._store_all(data)  # the common case: as byte by byte, at once
        else:
            for byte in data:
                if not is_realtime_byte(byte):
                    self._store(byte)
                elif not self.silent:  # a hung main loop: real-time bytes are taken, then ignored
                    self._realtime(byte)
        self._pump()
        return len(data)

    def read(self) -> bytes:
        """Everything Grbl has printed and the host has not read yet."""
        data = b"".join(chunk for _, chunk in self._output)
        self._output.clear()
        return data

    def read_timed(self) -> list[tuple[float, bytes]]:
        """Like :meth:`read`, with the simulated time each chunk was printed at."""
        if not self._output:
            return []
        chunks = list(self._output)
        self._output.clear()
        return chunks

    @property
    def out_waiting(self) -> int:
        return sum(len(chunk) for _, chunk in self._output)

    def advance(self, seconds: float) -> None:
        """Move the simulated clock on by ``seconds``, executing whatever happens meanwhile."""
        if not (math.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"seconds: must be a finite number >= 0, got {seconds!r}")
        self.advance_to(self.now + seconds)

    def advance_to(self, t: float, until: Callable[[], bool] | None = None) -> bool:
        """Move the simulated clock on to time ``t`` (no effect if it is already later), or
        only to the first event at which ``until()`` holds (then True)."""
        if until is None:
            quiet = self.quiet_until()
            if quiet is not None and t < quiet:
                self.executor.move_clock(t)  # no event on the way: only the clock moves
                return False
        self._check_open()

        mark = self._blocked_until

        def event() -> bool:
            self._pump()
            changed = self._blocked_until != mark  # a blocking delay began or ended
            return self.closed or changed or (until is not None and until())

        while True:
            self._pump()
            if until is not None and until():
                return True
            due = [a for a in self._alarms if a[0] <= t]
            mark = wake = self._blocked_until
            if wake is not None and (wake > t or self.silent):
                wake = None
            end = min([a[0] for a in due] + ([wake] if wake is not None else []), default=t)
            stopped = self.executor.run_until(end, until=event)
            if self.closed:
                return False
            if due and self.now >= min(due)[0]:
                alarm = min(due)
                self._alarms.remove(alarm)
                self._raise_alarm(alarm[1])
                continue
            if self._blocked_until != mark or (wake is not None and self.now >= wake):
                continue  # a blocking delay began or is over: the loop above carries on
            if stopped:
                return True
            if self.now >= t:
                self._pump()
                return False

    def poll(self) -> None:
        """With ``clock="real"``, catch the simulation up with the wall clock."""
        if self.clock == "real":
            self.advance_to(time.monotonic() - self._wall_start)
        else:
            self._pump()

    def quiet_until(self) -> float | None:
        """While the main loop is stalled on a full planner (and no alarm is scheduled): the
        time of the executor's next event (``inf``: none). Until then bytes that are not
        real-time only go into the receive ring, whenever they arrive. None otherwise."""
        if self._alarms or self.closed or not self._stalled_on_full_planner():
            return None
        event = self.executor.next_event()
        return math.inf if event is None else event

    def run_until_idle(self, limit: float = 3600.0) -> bool:
        """Advance until nothing is left to do (no line waiting, idle, no scheduled alarm), or
        to time ``limit``. True if the device became idle."""
        return self.advance_to(limit, until=lambda: not self.busy)

    def close(self) -> None:
        self.closed = True

    @property
    def busy(self) -> bool:
        """Something will still happen without more input: a line waiting, bytes in the receive
        buffer, motion, a dwell, a scheduled alarm."""
        return self._busy() or bool(self._alarms)

    # -- fault hooks -------------------------------------------------------------------------

    def inject_error(self, line: int, code: int) -> None:
        """Answer the ``line``-th line received (1-based, counting every line) with
        ``error:code`` instead of executing it."""
        with self.lock:
            self._injected[int(line)] = int(code)

    def schedule_alarm(self, at: float, code: int) -> None:
        """Raise ``ALARM:code`` at simulated time ``at``: motion stops at once, Alarm state.
        Codes 1 and 2 (limits) are critical: ``[MSG:Reset to continue]``, deaf until a reset."""
        with self.lock:
            self._alarms.append((float(at), int(code)))

    def go_silent(self, silent: bool = True) -> None:
        """Stop answering anything (bytes still fill the receive buffer), or wake up again."""
        with self.lock:
            self.silent = silent

    def emit_garbage(self, data: bytes) -> None:
        """Print ``data`` as it is, now (line noise, a wrong baud rate)."""
        with self.lock:
            self._emit_raw(bytes(data))

    def freeze_motion(self, frozen: bool = True) -> None:
        """Stall the machine, or let it go on: no step is made, no block or dwell ends, no
        ``ok`` comes for a line waiting on the full planner, while ``?`` is still answered with
        the same position and state (Run stays Run, Idle stays Idle), as a firmware whose stepper
        hangs. Lines keep being taken while the planner has room."""
        with self.lock:
            self.executor.freeze(frozen)
            self._pump()

    @property
    def executed_lines(self) -> int:
        """How many of the lines received (counting every line, in order) have fully taken
        effect, each with all the lines before it: a motion line when its block has finished
        executing, a dwell when it has ended, any other line when processed (answered). A line
        a reset, an alarm or a jog cancel threw away never finishes, so the count stops before
        it (:attr:`line_finished_at` goes on for later lines)."""
        return self._done_prefix

    def drop_connection(self) -> None:
        """The cable is pulled: the device closes and the transport closes with it."""
        with self.lock:
            self.closed = True
            for callback in list(self.on_close):
                callback()

    # -- recording ---------------------------------------------------------------------------

    def trace(self, dt: float = 0.001) -> np.ndarray:
        """``(N, 5)``: ``t, x, y, z, pen`` every ``dt`` (≤ 1 ms) from time 0 to now.

        Positions come from the executor's recorder (exact at segment boundaries); pen is 1 while
        down, 0 while up.
        """
        recorder = self.executor.recorder
        assert recorder is not None
        base = recorder.trace(dt)
        pen = np.zeros(len(base))
        if self.pen_source == "z":
            pen[:] = base[:, 3] < self.pen_z_below
        else:
            times = np.array([t for t, _ in self._pen_events])
            values = np.array([v for _, v in self._pen_events])
            if self.pen_servo is not None:  # on, and nearer the down S value than the up one
                down, up = self.pen_servo
                values = (values > 0) & (np.abs(values - down) < np.abs(values - up))
            else:
                values = values > 0
            pen[:] = values[np.searchsorted(times, base[:, 0], side="right") - 1]
        return np.column_stack([base, pen])

    @property
    def position_mm(self) -> tuple[float, float, float]:
        return self.executor.position_mm

    @property
    def state(self) -> State:
        """The state a status report shows now."""
        if self._state in (State.ALARM, State.CHECK, State.SLEEP):
            return self._state
        ex = self.executor.state
        if ex == HOLD:
            return State.HOLD
        if ex == RUN:
            return State.JOG if self._jogging else State.RUN
        return State.IDLE

    # -- internals: boot and reset -----------------------------------------------------------

    def _reset_flags(self) -> None:
        """``main()``'s re-initialisation: real-time flags and the receive buffer cleared."""
        self._critical = False
        self._jog_cancel = False
        self._status_pending = False
        self._hold_pending = False
        self._reset_pending = False
        self._rx.clear()
        self._rx_head = self._rx_tail = 0
        self._paid_bytes = 0
        self._arrivals.clear()

    def _boot(self, alarm: bool) -> None:
        self._state = State.ALARM if alarm else State.IDLE
        self._critical = False
        self._line = bytearray()
        self._actions: deque[object] = deque()
        self._jogging = False
        self._overrides = [100, 100, 100]
        self._wco_counter = 0
        self._ovr_counter = 0
        self.parser = ParserState(position=self.executor.position_mm)
        self._set_pen(0.0)
        self._emit(Welcome())
        if self._state == State.ALARM:
            self._emit(Msg(MSG_ALARM_LOCK))
        else:
            self._run_startup_lines()

    def _soft_reset(self) -> None:
        """Ctrl-X: ``mc_reset`` stops the steppers at once; in motion its ``st_go_idle`` holds
        them for the step idle delay before ``ALARM:3`` (then the alarm's 500 ms), then the
        reboot (:meth:`_reboot`)."""
        in_motion = self.executor.soft_reset()
        self._abort_main_loop()
        self._set_pen(0.0)  # mc_reset stops the spindle at once
        if self._state == State.CHECK:
            self._state = State.IDLE
        if self._state == State.SLEEP:
            self._state = State.ALARM
        if in_motion:
            self._state = State.ALARM
            self._block(self._idle_delay(alarm=True), lambda: self._report_alarm(3, self._reboot))
        else:
            self._reboot()

    def _reboot(self) -> None:
        """``main()`` after an abort: flags and receive buffer cleared, then ``st_reset``'s
        ``st_go_idle`` waits the step idle delay ($1 ms, none with $1=255), then the banner."""
        self._reset_flags()
        self._actions.clear()
        self._block(self._idle_delay(alarm=False), lambda: self._boot(self._state == State.ALARM))

    def _abort_main_loop(self) -> None:
        self._actions.clear()
        self._line.clear()
        self._restart = True

    def _idle_delay(self, alarm: bool) -> float:
        """``st_go_idle``'s busy wait: $1 ms; with $1=255 only while an alarm is flagged."""
        ms = int(self.settings[1])
        return ms / 1000.0 if (ms != 255 or alarm) else 0.0

    def _block(self, seconds: float, then: Callable[[], None]) -> None:
        """The firmware blocks (a ``delay_ms``) for ``seconds``, then carries on with ``then``.
        Meanwhile nothing is printed; bytes are received and real-time flags set."""
        if seconds <= 0:
            then()
            return
        self._blocked_until = self.now + seconds
        self._after_block = then

    def _report_alarm(self, code: int, then: Callable[[], None] | None = None) -> None:
        """``report_alarm_message``: ``ALARM:N``, then ``delay_ms(500)``; then, for the limit
        alarms, ``[MSG:Reset to continue]`` with any reset received so far discarded."""

        def after() -> None:
            if code in _CRITICAL_ALARMS:
                self._reset_pending = False  # the critical-event loop clears EXEC_RESET
                self._emit(Msg(MSG_RESET_TO_CONTINUE))
            if then is not None:
                then()

        self._emit(Alarm(code))
        self._block(ALARM_REPORT_DELAY, after)

    def _run_startup_lines(self) -> None:
        for text in self.startup_lines:
            if not text:
                continue
            parsed = parse_line(text, self._state)
            result: Ok | Error = Ok()
            if isinstance(parsed, Error):
                result = parsed
            elif isinstance(parsed, Block):
                step = self.parser.step(parsed)
                if isinstance(step, Error):
                    result = step
                else:
                    self._queue_step(step)
            self._emit(StartupResult(text, result))

    # -- internals: receiving ----------------------------------------------------------------

    def _store(self, byte: int) -> None:
        if len(self._rx) >= RX_CAPACITY:
            self.lost_bytes += 1
            return
        self._rx.append(byte)
        self._rx_head = (self._rx_head + 1) % RX_BUFFER_SIZE
        if byte in (0x0A, 0x0D):
            self._arrivals.append(self.now)

    def _store_all(self, data: bytes) -> None:
        """:meth:`_store` each byte of ``data`` (none of them real-time)."""
        room = max(0, RX_CAPACITY - len(self._rx))
        kept = data[:room]
        self.lost_bytes += len(data) - len(kept)
        self._rx += kept
        self._rx_head = (self._rx_head + len(kept)) % RX_BUFFER_SIZE
        ends = kept.count(b"\n") + kept.count(b"\r")
        if ends:
            self._arrivals.extend([self.now] * ends)

    def _rx_available(self) -> int:
        """``serial_get_rx_buffer_available()`` of Grbl 1.1h, quirk included (128 when empty)."""
        head, tail = self._rx_head, self._rx_tail
        if head >= tail:
            return RX_BUFFER_SIZE - (head - tail)
        return tail - head - 1

    def _realtime(self, byte: int) -> None:
        if byte == Realtime.SOFT_RESET:
            self._reset_pending = True
        elif self._critical:
            return
        elif byte == Realtime.STATUS_REPORT:
            self._status_pending = True
        elif byte == Realtime.FEED_HOLD:
            if self._state not in (State.ALARM, State.CHECK, State.SLEEP):
                self._hold_pending = True
        elif byte == Realtime.CYCLE_START:
            stopped = self._state in (State.ALARM, State.CHECK, State.SLEEP)
            if not stopped and not self.executor.resume() and self.executor.idle:
                self.executor.cycle_start()
                self._ovr_counter = 0
        elif byte == Realtime.JOG_CANCEL:
            if self._jogging and self.executor.state == RUN:
                self._jog_cancel = True
                self._hold_pending = True
        elif byte in _OVERRIDE_SETS:
            index, value = _OVERRIDE_SETS[byte]
            self._overrides[index] = value
            self._ovr_counter = 0
        elif byte in _OVERRIDE_STEPS:
            index, step = _OVERRIDE_STEPS[byte]
            low, high = _OVERRIDE_LIMITS[index]
            self._overrides[index] = min(high, max(low, self._overrides[index] + step))
            self._ovr_counter = 0

    # -- internals: the main loop ------------------------------------------------------------

    def _event(self) -> bool:
        """Called by the executor at each of its events: let the main loop run. Never stops it
        early, except when an alarm hook or a closed connection needs the outer loop."""
        self._pump()
        return self.closed

    def _stalled_on_full_planner(self) -> bool:
        """The main loop would only offer its next block to a full planner again and stop: no
        real-time flag to act on, no delay, motion running, no dwell, no step idle delay. Then
        :meth:`_pump` has nothing to do (the long jobs' hot path: called at every byte and
        event while the planner is full)."""
        if (
            self._status_pending
            or self._reset_pending
            or self._hold_pending
            or self._jog_cancel
            or self._critical
            or self._restart
            or self._blocked_until is not None
            or not self._actions
        ):
            return False
        head = self._actions[0]
        if type(head) is not _Wait or type(head.item) is not MotionBlock:
            return False
        ex = self.executor
        return (
            ex.state == RUN
            and ex._lock_until is None
            and ex._dwell is None
            and len(ex.planner.blocks) >= ex.planner.capacity
        )

    def _pump(self) -> None:
        """Grbl at the current time: a blocking delay, or the main loop while it can run."""
        if self._stalled_on_full_planner():
            return
        while not (self.closed or self.silent):
            if self._blocked_until is not None:
                if self.now < self._blocked_until:
                    return
                then = self._after_block
                self._blocked_until = self._after_block = None
                if then is not None:
                    then()
                continue
            self._restart = False
            self._main_loop()
            if not self._restart:
                return

    def _checkpoint(self) -> bool:
        """``protocol_execute_realtime``: act on the real-time flags. False when the main loop
        cannot go on (a reset, a critical alarm, the step interrupt's busy wait). In a dwell,
        flags wait for the next 50 ms step of ``delay_sec``."""
        if self._restart or self._blocked_until is not None:
            return False
        if self.executor.dwell_running and not self.executor.at_dwell_tick:
            return True
        if self._reset_pending:
            self._reset_pending = False
            self._soft_reset()
            return False
        if self._critical or self.executor.locked:
            return False  # the step interrupt busy-waits ($1): the main loop is frozen
        if self._hold_pending:
            self._hold_pending = False
            self.executor.feed_hold()
        if self._jog_cancel and self.executor.state == HOLD and self.executor.hold_complete:
            self._jog_cancel = False
            self._jogging = False
            self.executor.soft_reset()  # flush the jog; the machine has stopped (no alarm)
            self.parser = ParserState(**{**self._parser_fields(), "position": self.position_mm})
        if self._status_pending:
            self._status_pending = False
            self._emit(self._status())
        return True

    def _main_loop(self) -> None:
        """``protocol_main_loop``: real-time flags, then lines while it can."""
        if not self._checkpoint():
            return
        if self._jogging and self.executor.idle and not self.executor.queued_blocks:
            self._jogging = False
        while True:
            if self._actions and not self._run_actions():
                return
            if self._restart or self._blocked_until is not None:
                return
            taken = self._take_line()
            if self._restart or self._blocked_until is not None:
                return
            if not taken:
                break
        if self.executor.state == RUN:
            self._check_starving()
        # The receive buffer ran dry: protocol_auto_cycle_start.
        if self.executor.queued_blocks and self.executor.idle:
            self.executor.cycle_start()
            self._ovr_counter = 0
        self._checkpoint()

    def _cycle_stopped(self) -> None:
        self._check_starving(at_rest=True)

    def _check_starving(self, at_rest: bool = False) -> None:
        """Note when the planner is down to its last block (it must plan a stop), or the machine
        came to rest, with no line asking for that (pen change, dwell, program end): starvation
        if more motion follows before such a line."""
        queued = self.executor.queued_blocks
        if queued > 1:
            self._flowing = True  # a motion sequence is under way (the first block is priming)
            return
        waiting = any(isinstance(a, _Wait) and a.item is None for a in self._actions)
        if waiting or self.executor._dwell is not None:
            self._flowing = False
        elif (self._flowing or at_rest) and self._ran_dry is None:
            self._ran_dry = self.now
            self._flowing = False

    def _busy(self) -> bool:
        ex = self.executor
        frozen = self.silent or self._critical or ex.frozen  # nothing moves until someone acts
        lines = not frozen and (self._actions or 0x0A in self._rx or 0x0D in self._rx)
        motion = not ex.frozen and (not ex.idle or ex.queued_blocks or ex.locked or ex.dwelling)
        blocked = self._blocked_until is not None and not self.silent
        return bool(lines or self._reset_pending or motion or blocked)

    def _take_line(self) -> bool:
        """Move characters from the ring into the line; handle a complete line. False when the
        ring holds no complete line any more."""
        rx = self._rx
        if not rx:
            return False
        ends = [i for i in (rx.find(b"\n"), rx.find(b"\r")) if i >= 0]
        if self._reading(min(ends) + 1 if ends else len(rx)):
            return False
        if not ends:  # no line end yet: every byte moves into the line
            self._line += rx
            self._rx_tail = (self._rx_tail + len(rx)) % RX_BUFFER_SIZE
            self._paid_bytes -= len(rx)
            rx.clear()
            return False
        end = min(ends)
        if end:  # the characters before the line end
            self._line += rx[:end]
            del rx[:end]
            self._paid_bytes -= end
            self._rx_tail = (self._rx_tail + end) % RX_BUFFER_SIZE
        if not self._checkpoint():
            return False  # protocol_execute_realtime at each line's end stopped the loop
        del rx[0]
        self._paid_bytes -= 1
        self._rx_tail = (self._rx_tail + 1) % RX_BUFFER_SIZE
        text = self._line.decode("latin-1")
        self._line.clear()
        self._handle_line(text)
        return True

    def _reading(self, count: int) -> bool:
        """The main loop reads the ring's first ``count`` bytes at :attr:`read_time` each, one
        after another: True (and a wait until then) while it is still reading them, so the ring
        is not dry (no auto cycle start) while bytes wait to be read."""
        extra = count - self._paid_bytes
        if extra > 0 and self.read_time > 0:
            self._read_free_at = max(self.now, self._read_free_at) + extra * self.read_time
            self._paid_bytes = count
        if self.now >= self._read_free_at:
            return False
        self._block(self._read_free_at - self.now, _nothing)
        return True

    def _handle_line(self, text: str) -> None:
        self.lines_received += 1
        index = self.lines_received
        self.line_received_at.append(self._arrivals.popleft() if self._arrivals else self.now)
        self.line_finished_at.append(None)
        self._line_own.append(None)
        injected = self._injected.pop(index, None)
        if injected is not None:
            self._emit(Error(injected))
        else:
            parsed = _parse_line(text, self._state if self._state != State.IDLE else self.state)
            if isinstance(parsed, Error):
                self._emit(parsed)
            elif isinstance(parsed, Block):
                self._handle_block(parsed, index)
            else:
                self._handle_system(parsed)
        self._actions.append(lambda: self._line_processed(index))

    # -- internals: what has been executed -------------------------------------------------------

    def _line_processed(self, index: int) -> None:
        self._lines_processed.add(index)
        if not self._line_blocks.get(index):
            self._line_done(index)

    def _block_done(self, block: PlanBlock) -> None:
        index = block.source.tag
        if not isinstance(index, int) or index not in self._line_blocks:
            return
        self._line_blocks[index] -= 1
        if self._line_blocks[index] <= 0:
            del self._line_blocks[index]
            if index in self._lines_processed:
                self._line_done(index)

    def _line_done(self, index: int) -> None:
        self._lines_processed.discard(index)
        self._line_own[index - 1] = self.now
        while self._done_prefix < len(self._line_own):
            own = self._line_own[self._done_prefix]
            if own is None:
                break
            before = self.line_finished_at[self._done_prefix - 1] if self._done_prefix else 0.0
            self.line_finished_at[self._done_prefix] = max(own, before or 0.0)
            self._done_prefix += 1

    def _run_actions(self) -> bool:
        """Carry out the current line's steps in order; True when all are done."""
        while self._actions:
            action = self._actions[0]
            if isinstance(action, _Wait):
                if action.item is None:
                    if self.executor.queued_blocks or not self.executor.idle:
                        self.executor.cycle_start()
                        return False
                elif not self.executor.submit(action.item):
                    return False
                elif isinstance(action.item, MotionBlock) and self._queued(action.item):
                    tag = action.item.tag
                    if isinstance(tag, int):
                        self._line_blocks[tag] = self._line_blocks.get(tag, 0) + 1
                if action.item is None:
                    self._ran_dry = None  # a line asked for the stop: the pen change, dwell, end
                elif self._ran_dry is not None and isinstance(action.item, MotionBlock):
                    self.starvation.append(self._ran_dry)
                    self._ran_dry = None
            elif callable(action):
                action()
            else:
                self._emit(action)  # type: ignore[arg-type]
            self._actions.popleft()
        return True

    # -- internals: G-code ---------------------------------------------------------------------

    def _queued(self, item: MotionBlock) -> bool:
        """The block just submitted went into the planner (it was not dropped: no step)."""
        planned = self.executor.last_planned
        return planned is not None and planned.source is item

    def _handle_block(self, block: Block, index: int | None = None) -> None:
        step = self.parser.step(block)
        if isinstance(step, Error):
            self._emit(step)
            return
        if block.jog:
            self._jogging = True
        self._queue_step(step, block, index)
        self._actions.append(Ok())

    def _queue_step(self, step: Step, block: Block | None = None, tag: int | None = None) -> None:
        old = self.parser
        self.parser = step.state
        if self._state == State.CHECK:
            return
        new = step.state
        spindle_on = new.spindle in ("M3", "M4")
        if new.spindle != old.spindle or (spindle_on and new.spindle_speed != old.spindle_speed):
            pen = new.spindle_speed if spindle_on else 0.0
            self._actions.append(_Wait(None))
            self._actions.append(lambda: self._set_pen(pen))
            self._actions.append(self._touch_ovr)
        if new.coolant != old.coolant:
            self._actions.append(_Wait(None))
        words = avr_words(block.text) if block is not None else {}
        if step.dwell is not None:
            self._actions.append(_Wait(None))
            self._actions.append(_Wait(Dwell(words.get("P", step.dwell))))
        if step.target is not None:
            n = math.trunc(words.get("N", 0.0)) if self.line_numbers else 0
            extra = {"line_number": n, "tag": tag}
            if step.rapid:
                move = MotionBlock(step.target, rapid=True, **extra)
            elif new.feed_mode == "G93" and not step.jog:
                move = MotionBlock(step.target, inverse_time_per_min=step.feed_rate, **extra)
            else:
                move = MotionBlock(step.target, feed_mm_per_min=step.feed_rate, **extra)
            self._actions.append(_Wait(move))
        if step.program_flow == "M0":
            self._actions.append(_Wait(None))
            self._actions.append(self.executor.feed_hold)
        elif step.program_flow in ("M2", "M30"):
            self._actions.append(_Wait(None))
            self._actions.append(lambda: self._set_pen(0.0))
            self._actions.append(Msg(MSG_PROGRAM_END))

    def _touch_ovr(self) -> None:
        self._ovr_counter = 0

    def _set_pen(self, value: float) -> None:
        t = self.now
        if self._pen_events and self._pen_events[-1][0] == t:
            self._pen_events[-1] = (t, value)
        else:
            self._pen_events.append((t, value))

    def _parser_fields(self) -> dict[str, object]:
        return {name: getattr(self.parser, name) for name in ParserState.__dataclass_fields__}

    # -- internals: $ commands -----------------------------------------------------------------

    def _handle_system(self, command: object) -> None:
        emit = self._emit
        if isinstance(command, Help):
            emit(Feedback("HLP", HELP))
        elif isinstance(command, ViewSettings):
            for number, value in self.settings.items():
                emit(Setting(number, value))
        elif isinstance(command, ViewParserState):
            emit(Feedback("GC", self.parser.report(inches=bool(self.settings[13]))))
        elif isinstance(command, ViewBuildInfo):
            emit(Feedback("VER", f"1.1h.{BUILD_DATE}:{self.build_info}"))
            options = "VN" if self.line_numbers else "V"
            emit(Feedback("OPT", f"{options},{self.executor.planner.capacity},{RX_BUFFER_SIZE}"))
        elif isinstance(command, SetBuildInfo):
            self.build_info = command.text
        elif isinstance(command, ViewParameters):
            zero = "0.000,0.000,0.000"
            for name in ("G54", "G55", "G56", "G57", "G58", "G59", "G28", "G30", "G92"):
                emit(Feedback(name, zero))
            emit(Feedback("TLO", "0.000"))
            emit(Feedback("PRB", zero + ":0"))
        elif isinstance(command, ViewStartupLines):
            for index, text in enumerate(self.startup_lines):
                emit(StartupLine(index, text))
        elif isinstance(command, SetStartupLine):
            step = ParserState(position=self.parser.position).step(command.block)
            if isinstance(step, Error):
                emit(step)
                return
            if 0 <= command.index < len(self.startup_lines):
                self.startup_lines[command.index] = command.block.text
        elif isinstance(command, ToggleCheckMode):
            if self._state == State.CHECK:
                emit(Msg(MSG_DISABLED))
                self._actions.append(Ok())
                self._actions.append(self._request_reset)
                return
            self._state = State.CHECK
            emit(Msg(MSG_ENABLED))
        elif isinstance(command, Unlock):
            if self._state == State.ALARM:
                self._state = State.IDLE
                self._ovr_counter = 0
                emit(Msg(MSG_UNLOCKED))
        elif isinstance(command, Home):
            if not self.settings[22]:
                emit(Error(5))
                return
            if command.axes:
                emit(Error(3))
                return
            self._home()
        elif isinstance(command, Sleep):
            self.executor.soft_reset()
            self._state = State.SLEEP
            emit(Msg(MSG_SLEEPING))
        elif isinstance(command, Restore):
            if command.what in "$*":
                self.settings = dict(DEFAULT_SETTINGS)
            if command.what == "*":
                self.startup_lines = ["", ""]
            emit(Msg(MSG_RESTORING_DEFAULTS))
            self._actions.append(Ok())
            self._actions.append(self._apply_settings)
            self._actions.append(self._request_reset)
            return
        elif isinstance(command, SetSetting):
            error = self._set_setting(command.number, command.value)
            if error is not None:
                emit(error)
                return
            self._actions.append(_Wait(None))
            self._actions.append(self._apply_settings)
        self._actions.append(Ok())

    def _request_reset(self) -> None:
        self._reset_pending = True

    def _set_setting(self, number: int, value: float) -> Error | None:
        if number == 20 and value and not self.settings[22]:
            return Error(10)
        if number in INTEGER_SETTINGS:
            value = float(int(value))
        if 100 <= number <= 122 and value <= 0:
            return Error(3)  # a zero rate would divide by zero; the firmware stores it
        self.settings[number] = value
        return None

    def _apply_settings(self) -> None:
        self.executor.configure(self._grbl_settings())

    def _grbl_settings(self) -> GrblSettings:
        s = self.settings
        lock = int(s[1])
        return GrblSettings(
            steps_per_mm=(s[100], s[101], s[102]),
            max_rate_mm_per_min=(s[110], s[111], s[112]),
            acceleration_mm_per_s2=(s[120], s[121], s[122]),
            junction_deviation_mm=s[11],
            stepper_idle_lock_ms=min(lock, 255),
        )

    def _home(self) -> None:
        """``$H``, without the switch-seeking motion: the machine position becomes 0."""
        ex = self.executor
        ex.soft_reset()
        # The executor keeps its position in steps; set it as homing's plan_sync_position does.
        ex._steps = (0, 0, 0)
        ex.planner.reset((0, 0, 0))
        if ex.recorder is not None:
            ex.recorder.add(ex.now, (0.0, 0.0, 0.0))
        self.parser = ParserState(**{**self._parser_fields(), "position": (0.0, 0.0, 0.0)})
        self._state = State.IDLE

    # -- internals: alarms ---------------------------------------------------------------------

    def _raise_alarm(self, code: int) -> None:
        """A scheduled alarm: motion stops, buffers are flushed, Alarm state. A limit alarm
        (critical) comes through ``mc_reset``, whose ``st_go_idle`` holds the motors for the
        step idle delay first when they were moving; then :meth:`_report_alarm`. One due while
        the firmware is in a blocking delay waits for its end."""
        if self._blocked_until is not None:
            self._alarms.append((self._blocked_until, code))
            return
        in_motion = self.executor.soft_reset()
        self._abort_main_loop()
        self._rx.clear()
        self._rx_head = self._rx_tail = 0
        self._paid_bytes = 0
        self._arrivals.clear()
        self._jogging = False
        self._state = State.ALARM
        self.parser = ParserState(**{**self._parser_fields(), "position": self.position_mm})
        self._set_pen(0.0)
        critical = code in _CRITICAL_ALARMS
        if critical:
            self._critical = True
        delay = self._idle_delay(alarm=True) if critical and in_motion else 0.0
        self._block(delay, lambda: self._report_alarm(code))

    # -- internals: output -----------------------------------------------------------------------

    def _status(self) -> Status:
        state = self.state
        busy = state in (State.RUN, State.HOLD, State.JOG)
        report = int(self.settings[10])
        inches = bool(self.settings[13])
        scale = 1 / 25.4 if inches else 1.0
        position = tuple(v * scale for v in self.executor.position_mm)
        wco = None
        if self._wco_counter > 0:
            self._wco_counter -= 1
        else:
            self._wco_counter = _WCO_REFRESH[0 if busy else 1] - 1
            if self._ovr_counter == 0:
                self._ovr_counter = 1
            wco = (0.0, 0.0, 0.0)
        overrides = accessories = None
        if self._ovr_counter > 0:
            self._ovr_counter -= 1
        else:
            self._ovr_counter = _OVR_REFRESH[0 if busy else 1] - 1
            overrides = tuple(self._overrides)
            spindle = {"M3": "S", "M4": "C"}.get(self.parser.spindle, "")
            coolant = "F" if self.parser.coolant == "M8" else ""
            accessories = (spindle + coolant) or None
        on = self.parser.spindle in ("M3", "M4") and self._pen_events[-1][1] > 0
        return Status(
            state=state,
            substate=(0 if self.executor.hold_complete else 1) if state == State.HOLD else None,
            mpos=position if report & 1 else None,  # type: ignore[arg-type]
            wpos=None if report & 1 else position,  # type: ignore[arg-type]
            buffer=(self.executor.free_blocks, self._rx_available()) if report & 2 else None,
            line=self._line_number(),
            feed=self.executor.reported_rate_mm_per_min * scale,
            spindle=self.parser.spindle_speed if on else 0.0,
            wco=wco,
            overrides=overrides,  # type: ignore[arg-type]
            accessories=accessories,
        )

    def _line_number(self) -> int | None:
        """``Ln:``: the N word of the planner's tail block (the one the stepper is preparing),
        in a line-number build, when there is one and it is above 0."""
        block = self.executor.planner.current_block() if self.line_numbers else None
        if block is None or block.source.line_number <= 0:
            return None
        return block.source.line_number

    def _emit(self, message: Message) -> None:
        inches = bool(self.settings[13])
        self._emit_raw(format_message(message, inches=inches))

    def _emit_raw(self, data: bytes) -> None:
        self._output.append((self.now, data))

    def _check_open(self) -> None:
        if self.closed:
            raise ConnectionError("the simulated Grbl is disconnected")


__all__ = ["DEFAULT_SETTINGS", "RX_CAPACITY", "SimulatedGrbl"]
