"""Streaming joint goals to the DYNAMIXEL arm with the official dynamixel-sdk.

**Port.** :class:`UrlPortHandler` is the SDK's ``PortHandler`` opening its port with
``serial.serial_for_url`` instead of ``serial.Serial`` (``setupPort``), so a device path
(``/dev/ttyUSB0``, a pseudo-terminal from ``tagbot sim arm``, ``COM3``) and any pyserial URL
(``dxlsim://…`` for the in-process simulator, ``rfc2217://…``) work alike. Details that differ
from the SDK's own: a 1 ms read timeout instead of 0 (see :data:`READ_WAIT`); no output drain
before every packet (``clearPort``: the SDK's ``tcdrain`` made each tick wait for the far end);
the packets' reply allowance is ``bus.silence_timeout`` instead of the SDK's 34 ms; and, on a
port with a simulated clock, ``getCurrentTime`` on that clock so packet timeouts are simulated
time too. Instruction packets and result codes are the unmodified SDK's.

**Connect.** Open at ``bus.baud``; ping every profile ID (a missing one → :class:`DeviceError`
listing what a broadcast ping finds on the bus); check each model number; with torque off set
Return Delay Time, Drive Mode = time-based profile, Operating Mode = position and (optionally)
Min/Max Position Limit from the joint limits (EEPROM, written only when different); Profile
Velocity = ``servo.profile_ms`` and Profile Acceleration a fraction of it (RAM); then torque on.
Each of these transactions waits up to ``bus.silence_timeout`` for its status and is tried
:data:`ATTEMPTS` times (a late reply to a failed try is drained first), so a line that delays or
loses some replies still connects.

**Time-based profile.** Every goal is a move the servo completes in ``servo.profile_ms``
(Profile Velocity in ms), whatever its length, so the joints' speed follows the plan without a
speed computed per goal. With ``profile_ms`` equal to the period the servos interpolate the goals
linearly; with it longer (20 ms by default) each goal restarts the move from the present position
and speed, a moving average of the goals that smooths their 0.088° steps (at 500 Hz and a 2 ms
profile those steps cost 10 dB of speed SNR on the simulator). Goals are sent ``profile_ms``
ahead of when the pen should be there, which cancels the lag for steady motion. (The
velocity-based alternative needs a speed per goal and per joint, recomputed each tick, and lags.)

**Streaming.** One ``GroupSyncWrite`` of the three goal positions per tick, on absolute deadlines
``t_k = t_0 + k·period`` (no accumulated drift); lateness is measured at each tick. Late ticks
catch up on their own deadlines while the servos are still moving to the last goal; a tick later
than the larger of a period and a quarter of the profile time re-anchors the deadlines (counted
as a resync) instead of bursting the backlog, which would overspeed the joints.

**Read-back.** Present positions are read with a ``GroupSyncRead`` every ``readback_every``
ticks (about ``bus.readback_rate``, 100 Hz by default). The read-back only watches (goals are
sync-written and need no reply), so it never holds the loop: :class:`ReadBack` sends the
request and takes the replies whenever they have arrived, at the following ticks, matching each
to its own request by the servo's Realtime Tick (a late reply is not taken for a later read, nor
a reply for an earlier one when a whole read-back was lost). A round trip through a USB
adapter takes 1 to 2 ms with a 1 ms FTDI latency timer and 16+ ms at its default; on a loaded
host replies come tens of ms late. Late and lost replies are counted; only a servo missing more
than ``bus.max_missed`` read-backs in a row, or no reply for ``bus.silence_timeout``, is a fault.

**Pause.** With a :class:`~tagbot.control.RunControl` paused, the loop stops before the next
tick: pen up, the arm holding its last goals, the read-back still watching; on resume the pen
goes back as it was (``pen.move_time``) and the deadlines are re-anchored at that tick.

**Errors.** SDK result codes and status error bytes become tagbot exceptions: a missing reply
while connecting → :class:`DeviceTimeout`, while streaming the faults above; an error byte →
:class:`DeviceFault` (the hardware alert bit reads Hardware Error Status and names overload,
overheating…); ``COMM_TX_FAIL`` and serial exceptions → :class:`ConnectionLost`; corrupt
read-back replies are counted and skipped up to ``bus.max_corrupt`` read-backs in a row, then
:class:`DeviceError`. While streaming ``where`` is ``tick N``: the last tick sent, counting from
1 (the N-th row of ``joints.csv``), which the arm still reaches: nothing is sent after it.

**Safe end and torque policy.** On success the program ends at park, pen up; torque stays on
(holding the arm) unless ``servo.torque_off_at_end``. On an error or KeyboardInterrupt nothing more
of the program is sent: the pen goal is set to up, the arm joints keep their last goal; after
``pen.move_time`` the arm joints' torque is switched off if ``servo.torque_off_after_error`` (a
planar arm does not fall; the pen servo keeps holding the pen up), and the exception is
re-raised. The port is always closed.

**Clock.** ``port.ser.clock`` when the serial object has one (the in-process simulator's simulated
time, so long runs take less than real time), else :class:`MonotonicClock` (``perf_counter`` and
a sleep that finishes with short yields, typically within 0.1 ms).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import dynamixel_sdk as sdk
import numpy as np
import serial
from numpy.typing import NDArray

from firmware_protocols.dynamixel import (
    HardwareError,
    OperatingMode,
    describe_error,
    time_based_profile,
)
from firmware_protocols.dynamixel.control_table import MODELS, DriveMode
from tagbot.arm.kinematics import angles_to_ticks
from tagbot.arm.profile import ArmProfile
from tagbot.clock import Clock, MonotonicClock, RealTime, simulated_clock
from tagbot.control import RunControl
from tagbot.errors import ConnectionLost, DeviceError, DeviceFault, DeviceTimeout

__all__ = [
    "ArmDriver",
    "ReadBack",
    "Scheduler",
    "StreamResult",
    "UrlPortHandler",
]

log = logging.getLogger(__name__)

# Control table addresses (X-series, Protocol 2.0).
RETURN_DELAY_TIME = 9
DRIVE_MODE = 10
OPERATING_MODE = 11
MAX_POSITION_LIMIT = 48
MIN_POSITION_LIMIT = 52
TORQUE_ENABLE = 64
HARDWARE_ERROR_STATUS = 70
POSITION_PID = (84, 82, 80)
"""Position P, I and D Gain addresses (2 bytes each)."""
PROFILE_ACCELERATION = 108
PROFILE_VELOCITY = 112
GOAL_POSITION = 116
REALTIME_TICK = 120
"""The servo's own clock: ms since power-on, modulo 32768 (2 bytes)."""
PRESENT_POSITION = 132
READBACK_LENGTH = PRESENT_POSITION + 4 - REALTIME_TICK
"""Bytes one read-back takes from each servo: Realtime Tick through Present Position (16)."""
TICK_WRAP = 32768

READ_WAIT = 0.001
"""Read timeout of the port, s. The SDK polls ``read`` in a loop until its packet timeout; with
``timeout=0`` (the SDK's choice) that loop spins and, on a pseudo-terminal served by a thread of
the same process, starves it of the GIL (read-backs then take 5 to 20 ms). A read returns as soon as
the bytes asked for have arrived, so this costs no latency."""

ARRIVED = 20
"""Ticks (1.8°) from its goal within which a servo has arrived after the move to park."""

HISTORY = 32
"""Bus operations kept for the debug log when something fails."""

ATTEMPTS = 3
"""Tries of a transaction awaiting its status while connecting (a lost or corrupt reply)."""

DRAIN_QUIET = 0.005
"""Seconds without input that end a drain before a retry."""

BUS_MARGIN = 0.0002
"""Seconds added to a read-back's time on the bus before the next goals may go out."""

SETTLE = 0.001
"""Seconds a USB adapter with a 1 ms latency timer may hold replies (see :class:`ReadBack`)."""

STATUS = 0x55
"""Protocol 2.0 status packet instruction."""


class Lifter(Protocol):
    """How a serial arm lifts its pen by itself: :meth:`up` gives the goal rows (one a period,
    every servo in bus order) from the pose ``row`` to the pen-up height above it along the
    paper's normal, empty when the pen is up already; :meth:`down` the way back, ending on the
    pose of ``row`` held still; :meth:`stand` the one row holding ``row``'s pose still;
    :meth:`is_up` whether ``row``'s pose holds the pen off the paper."""

    def up(self, row: NDArray[np.int64]) -> NDArray[np.int64]: ...

    def down(self, row: NDArray[np.int64]) -> NDArray[np.int64]: ...

    def stand(self, row: NDArray[np.int64]) -> NDArray[np.int64]: ...

    def is_up(self, row: NDArray[np.int64]) -> bool: ...


class Scheduler:
    """Absolute deadlines ``t_k = t_0 + k·period`` on a clock; lateness measured where goals
    leave the host.

    :meth:`wait` sleeps until tick ``k``'s deadline and returns how late it woke (s). One that
    wakes later than ``resync_after`` (default one period) moves ``t_0`` on so that it is on
    time (``resyncs`` counts this): the drawing waits rather than sending the backlog in a
    burst, which would overspeed the joints. Below that the next ticks catch up on their own
    deadlines. :meth:`sent` is told when the tick's write returned: its lateness is measured
    there, against the deadline the tick had before any resync (so a stall anywhere in the loop
    shows), a tick later than ``late_after`` (default a quarter period) counts as late, and a
    hole between two sends longer than a period plus ``resync_after`` is a host stall.
    """

    def __init__(
        self,
        clock: Clock,
        period: float,
        late_after: float | None = None,
        resync_after: float | None = None,
    ) -> None:
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"period: must be > 0 s, got {period!r}")
        self.clock, self.period = clock, float(period)
        self.late_after = 0.25 * self.period if late_after is None else float(late_after)
        self.resync_after = self.period if resync_after is None else float(resync_after)
        self.t0 = 0.0
        self.ticks = 0
        self.late_ticks = 0
        self.resyncs = 0
        self.resync_delay = 0.0
        """Seconds the deadlines moved on at resyncs, in all."""
        self.max_lateness = 0.0
        self.lateness: list[float] = []
        """Per tick sent, seconds after its deadline that its write returned."""
        self.woke: list[float] = []
        """Per tick, the clock time it woke."""
        self.sends: list[float] = []
        """Per tick sent, the clock time its write returned (period jitter, stalls)."""
        self.stalls: list[tuple[float, float]] = []
        """Host stalls: ``(clock time the next goals were due, seconds beyond one period)``
        for each hole between two sends longer than a period plus ``resync_after``."""
        self._due = 0.0
        self._last_sent: float | None = None
        self.floor = -math.inf
        """No tick is due before this clock time (the end of the last pause)."""
        self.anchors: list[tuple[int, float, float | None]] = []
        """``(k, t0, held)``: from tick ``k`` on, the deadlines were ``t0 + k·period`` (the
        start, then each resync and each resume after a pause); ``held``: the clock time the
        hold before it began (a pause), None for a resync (the late tick's old deadline)."""

    def start(self, t0: float | None = None) -> float:
        """Anchor tick 0 at ``t0`` (default: now); returns it."""
        self.t0 = self.clock.now() if t0 is None else float(t0)
        self.anchors = [(0, self.t0, None)]
        return self.t0

    def reanchor(
        self, k: int, at: float, held: float | None = None, floor: float = -math.inf
    ) -> None:
        """Make tick ``k`` due at clock time ``at``, the ticks after it following (after a pause
        that began at clock time ``held``); ticks due before ``floor`` (the pause's end) are
        due then, sent at once without counting late."""
        self.t0 = float(at) - k * self.period
        self.anchors.append((k, self.t0, held))
        self.floor = float(floor)
        self._due = max(self.deadline(k), self.floor)
        self._last_sent = None  # the hole before the next send is the hold, no stall

    def program_time(self, clock: NDArray[np.float64], lag: float = 0.0) -> NDArray[np.float64]:
        """The program time (tick ``k`` at ``k·period``) of clock instants whose state the goals
        sent ``lag`` s earlier set; NaN inside a hold (a resync's or a pause's gap, when no
        goal was due). Before tick 0 the first anchor extends backwards."""
        c = np.asarray(clock, dtype=float)
        s = c - lag
        out = np.full(s.shape, np.nan)
        anchors = self.anchors or [(0, self.t0, None)]
        for i, (k, t0, _) in enumerate(anchors):
            inside = s >= (-np.inf if i == 0 else t0 + k * self.period)
            if i + 1 < len(anchors):  # until the next hold starts
                k_next, _, held = anchors[i + 1]
                inside &= s < t0 + k_next * self.period
                if held is not None:  # a pause: from the moment the pen began to lift
                    inside &= c < held
            out[inside] = s[inside] - t0
        return out

    def deadline(self, k: int) -> float:
        return self.t0 + k * self.period

    def wait(self, k: int) -> float:
        """Sleep until tick ``k``'s deadline; returns the lateness (s) measured on waking."""
        deadline = max(self.deadline(k), self.floor)
        self._due = deadline
        self.clock.sleep_until(deadline)
        woke = self.clock.now()
        late = max(0.0, woke - deadline)
        self.woke.append(woke)
        self.ticks += 1
        if late > self.resync_after:
            self.t0 += late
            self.resyncs += 1
            self.resync_delay += late
            self.anchors.append((k, self.t0, None))
        return late

    def sent(self, t: float) -> float:
        """The tick last waited for left the host at clock time ``t`` (its write returned);
        returns its lateness (s)."""
        late = max(0.0, t - self._due)
        self.sends.append(t)
        self.lateness.append(late)
        self.max_lateness = max(self.max_lateness, late)
        if late > self.late_after:
            self.late_ticks += 1
        if self._last_sent is not None:
            hole = t - self._last_sent - self.period
            if hole > self.resync_after:
                self.stalls.append((self._last_sent + self.period, hole))
        self._last_sent = t
        return late


@dataclass
class StreamResult:
    """What :meth:`ArmDriver.stream` measured (also after a fault: up to it)."""

    ticks_sent: int = 0
    """Goal rows written: the last tick executed, counting from 1."""
    reads: list[tuple[float, int, int, int]] = field(default_factory=list)
    """Complete read-backs: ``(program time s, shoulder, elbow, pen ticks)``, the time on the
    program's clock (samples inside a pause or a resync gap are left out)."""
    read_clock: list[tuple[float, int, int, int]] = field(default_factory=list)
    """The same read-backs with the clock time the servos sampled them."""
    origin: float = 0.0
    """Clock time of program time 0 under the last anchor (after the last resync or pause)."""
    start: float = 0.0
    """Clock time of tick 0's deadline."""
    end: float = 0.0
    """Clock time when the stream ended (the last goal reached, or the fault)."""
    lead: float = 0.0
    """Seconds between sending a goal and when the servos should be there."""
    scheduler: Scheduler | None = None
    readback: ReadBack | None = None
    corrupt_replies: int = 0
    paused: float = 0.0
    """Seconds spent paused (pen up, pose held), in all."""
    pauses: int = 0
    pause_spans: list[tuple[float, float]] = field(default_factory=list)
    """``(start, length)`` of each pause in clock time: from when the arm stood at the last
    goal before it, as long as the next tick was put off (its lift and drop of the pen
    included)."""
    first: int = 0
    """Index of the program's row sent first (0, or where a resumed job started)."""
    realtime: bool = False
    """Whether the loop ran with real-time scheduling (SCHED_FIFO)."""

    def program_time(self, clock: NDArray[np.float64]) -> NDArray[np.float64]:
        """Program time of clock instants (NaN inside pauses and resync gaps)."""
        assert self.scheduler is not None
        return self.scheduler.program_time(clock, self.lead)


@dataclass
class _Request:
    """One SYNC_READ of present positions on its way."""

    sent: float
    sampled: float
    span: float = 0.0
    """Ms the request took to write: it reached the servos from ``sent`` to ``span`` ms later."""
    got: dict[int, int] = field(default_factory=dict)
    late: bool = False
    """Still open when the next request was sent."""
    last: int = -1
    """Index (in the bus order of IDs) of the last servo whose reply came."""
    corrupt: bool = False


def _miss(late: float, span: float) -> float:
    """Ms a servo's tick is outside its request's writing (``late`` ms after it began, modulo
    the tick's wrap; ``span`` ms long): negative before, 0 within, positive after."""
    late = (late + TICK_WRAP / 2) % TICK_WRAP - TICK_WRAP / 2
    return late - min(max(late, 0.0), span)


def readback_bus_time(servos: int, baud: float, return_delay_us: float) -> float:
    """Seconds one read-back takes on the (half-duplex) bus: the SYNC_READ (14 bytes + 1 per
    servo), then each servo's Return Delay Time and its status (11 + :data:`READBACK_LENGTH`
    bytes); a byte is 10 bits on the UART (start, 8 data, stop)."""
    byte = 10.0 / baud
    return (14 + servos) * byte + servos * ((11 + READBACK_LENGTH) * byte + 1e-6 * return_delay_us)


class ReadBack:
    """Present positions, read without ever holding up the goal stream.

    :meth:`request` sends one ``GroupSyncRead`` (the SDK's packet) of Realtime Tick through
    Present Position and returns at once; :meth:`poll` takes whatever status bytes have arrived
    (``in_waiting``, never a blocking read) and matches each reply to its request. Status packets
    carry no sequence number, and order alone cannot tell a late reply from a lost request's
    successor, so each reply is matched by the servo's own clock: its Realtime Tick, less the
    servo's offset from the host's clock (measured when streaming starts, then followed for
    drift), names the open request sent at that instant. Replies come in the order of the
    requests, so the requests before it are over (what they lack was lost). A late reply is
    therefore never taken for a later read, nor a reply for an earlier one after a whole request
    was lost: it keeps its own request's sampling time, and is counted late when it came after
    the next request was sent. A corrupt reply (no clock to trust) goes by order: to the oldest
    open request its servo has not answered. No request is given up on a timer (an adapter may
    hold a burst of replies back): a servo's silence is counted from the first request it has
    not answered. Replies that match no open request, or are no read-back, are stale.

    Faults (``where`` names the tick): a servo that misses more than ``bus.max_missed``
    read-backs in a row (known when a later one's reply comes), or no reply from a servo for
    ``bus.silence_timeout`` (:class:`DeviceTimeout`); a status error (:class:`DeviceFault`,
    naming the hardware error); more than ``bus.max_corrupt`` read-backs in a row with a corrupt
    reply (:class:`DeviceError`).
    """

    def __init__(self, driver: ArmDriver, started: float, offsets: dict[int, float]) -> None:
        p = driver.profile
        self.driver = driver
        self.ids = list(driver.ids)
        self.index = {id: i for i, id in enumerate(self.ids)}
        self.max_missed = int(p["bus.max_missed"])
        self.silence = max(float(p["bus.silence_timeout"]), 2 * p.readback_every * p.period)
        """No reply for this long is a fault: ``bus.silence_timeout``, or two read-back
        intervals when read-backs are rarer than that."""
        self.max_corrupt = int(p["bus.max_corrupt"])
        assert driver.port is not None
        self.port = driver.port
        self.group = sdk.GroupSyncRead(self.port, driver.ph, REALTIME_TICK, READBACK_LENGTH)
        for id in self.ids:
            self.group.addParam(id)
        self.request_time = (14 + len(self.ids)) * 10.0 / p["bus.baud"]
        """Seconds the request takes on the bus: the servos sample when it has arrived."""
        self.busy = readback_bus_time(len(self.ids), p["bus.baud"], p["bus.return_delay_us"])
        """Seconds the bus is taken by a request and its replies (half duplex: the next goals
        wait for the end, see :attr:`bus_free`)."""
        self.bus_free = -math.inf
        """Clock time when the last request's replies are over on the bus."""
        self.window = self.busy + SETTLE
        """Seconds after a request when its replies can be there (bus time, and an adapter's
        1 ms): when the loop looks again, before the next tick."""
        self.open: deque[_Request] = deque()
        self.offset = dict(offsets)
        """Per servo, its Realtime Tick less the host's clock in ms, when it reads a request."""
        self.tolerance = max(500.0 * p.readback_every * p.period, 2.0)
        """Half the interval between requests, ms (at least 2: the ticks are whole ms): how far
        a servo's tick may be from its request's."""
        self.buffer = bytearray()
        self.heard = dict.fromkeys(self.ids, started)
        """Clock time of each servo's last reply (the stream's start before the first)."""
        self.asked: dict[int, float | None] = dict.fromkeys(self.ids)
        """Per servo, when the first request it has not answered yet was sent (None: none)."""
        self.looked = started
        """Clock time of the last :meth:`poll`."""
        self.gap = 2.0 * p.period + 0.005
        """A hole between two polls longer than this is a host stall (:attr:`host_stalls`)."""
        self.host_stalls: list[tuple[float, float]] = []
        """``(from, to)`` clock times the host did not look at the bus (a stall): no servo's
        silence is counted there, the replies waiting in the port's buffer."""
        self.in_a_row = dict.fromkeys(self.ids, 0)
        self.unmatched = dict.fromkeys(self.ids, 0)
        """Per servo, replies since its last read-back whose tick matched no open request."""
        self.samples: list[tuple[float, int, int, int]] = []
        self.requests = 0
        self.replies = 0
        self.late = 0
        self.missed = 0
        self.most_in_a_row = 0
        self.stale = 0
        self.corrupt = 0
        self.corrupt_in_a_row = 0
        self.delays: list[float] = []
        """Per reply, seconds from its request until the loop saw it (to within a tick)."""

    def request(self, where: str) -> None:
        """Send one SYNC_READ (no waiting)."""
        d = self.driver
        now = d.clock.now()
        for old in self.open:
            old.late = True
        self.port.is_using = False
        result = d._guard(self.group.txPacket, "read-back", where)
        self.port.is_using = False  # the SDK keeps it for a reply it is not going to wait for
        d._check(result, 0, None, "SYNC_READ of present positions", where)
        span = 1e3 * (d.clock.now() - now)
        for id in self.ids:
            if self.asked[id] is None:
                self.asked[id] = now
        self.open.append(_Request(now, now + self.request_time, span))
        self.bus_free = now + self.busy + BUS_MARGIN
        self.requests += 1

    def poll(self, where: str) -> None:
        """Take what has arrived, match it, and raise the faults (see the class docstring).

        Silence is counted only while requests were flowing: from a servo's first unanswered
        request, less the host's own stalls in that time (the replies wait in the port's
        buffer); a host stall is the host's, named in the run's report, never a servo's."""
        d = self.driver
        looked, self.looked = self.looked, d.clock.now()
        if self.looked - looked > self.gap:
            self.host_stalls.append((looked, self.looked))
        if not self.open:
            return  # nothing awaited: stale bytes, if any, wait for the next look
        ser = self.port.ser
        waiting = d._guard(lambda: ser.in_waiting, "read-back", where)
        if waiting:
            self.buffer += d._guard(lambda: ser.read(waiting), "read-back", where)
        now = d.clock.now()
        if self.buffer:
            self._parse(now, where)
        quiet = {
            id: now - since - self.host_stalled(since, now)
            for id, since in self.asked.items()
            if since is not None
        }
        silent = [id for id, q in quiet.items() if q > self.silence]
        if silent:
            names = _and([d.who(id) for id in silent])
            first = min(self.asked[id] or now for id in silent)
            stalled = self.host_stalled(first, now)
            host = f"; the host stalled {stalled:.2f} s meanwhile, not counted" if stalled else ""
            strays = "".join(
                f"; {d.who(id)} replied {self.unmatched[id]} times meanwhile, its Realtime Tick"
                " matching no request (its clock restarted?)"
                for id in silent
                if self.unmatched[id]
            )
            raise DeviceTimeout(
                f"{names} did not answer SYNC_READ of present positions for"
                f" {max(quiet[id] for id in silent):.2f} s while requests were flowing"
                f" (bus.silence_timeout: {self.silence:g} s{host}){strays}",
                where,
            )

    def _parse(self, now: float, where: str) -> None:
        buf = self.buffer
        ph = self.driver.ph
        while True:
            at = buf.find(b"\xff\xff\xfd")
            if at < 0:
                del buf[: max(0, len(buf) - 2)]
                return
            if at:
                del buf[:at]
            if len(buf) < 7:
                return
            length = buf[5] | (buf[6] << 8)
            if buf[3] != 0 or length < 4 or length > 64:  # not a status header: resynchronise
                del buf[:1]
                continue
            if len(buf) < 7 + length:
                return
            packet = list(buf[: 7 + length])
            crc = packet[-2] | (packet[-1] << 8)
            if ph.updateCRC(0, packet, len(packet) - 2) != crc or packet[7] != STATUS:
                self.corrupt += 1
                log.debug("%s: corrupt read-back reply (ID byte %d)", where, packet[4])
                del buf[:1]  # its other bytes hold no header: skipped by the scan
                if packet[4] in self.index:
                    self._answer(packet[4], None, None, 0, now, where)
                continue
            del buf[: 7 + length]
            packet = ph.removeStuffing(packet)
            id, error = packet[4], packet[8]
            data = bytes(packet[9 : 9 + (packet[5] | (packet[6] << 8)) - 4])
            if id not in self.index or (len(data) != READBACK_LENGTH and not error):
                self.stale += 1  # not a read-back (a late status from the setup)
                continue
            if len(data) == READBACK_LENGTH:
                tick = int.from_bytes(data[:2], "little")
                value = int.from_bytes(data[-4:], "little", signed=True)
                self._answer(id, value, tick, error, now, where)
            else:  # an error status carries no data: matched by order
                self._answer(id, 0, None, error, now, where)

    def host_stalled(self, start: float, end: float) -> float:
        """Seconds of host stalls between clock times ``start`` and ``end``."""
        return sum(max(0.0, min(b, end) - max(a, start)) for a, b in self.host_stalls)

    def _match(self, i: int, id: int, tick: int | None) -> int | None:
        """Index in :attr:`open` of the request servo ``i`` (``id``) answers with ``tick``
        (None: by order, its oldest open one it has not answered), or None if no open one."""
        if tick is None:
            return next((k for k, r in enumerate(self.open) if i > r.last), None)
        off = self.offset[id]
        misses = [_miss(tick - off - 1e3 * r.sent, r.span) for r in self.open]
        if not misses:
            return None
        k = min(range(len(misses)), key=lambda k: abs(misses[k]))
        if abs(misses[k]) > self.tolerance or i <= self.open[k].last:
            return None
        self.offset[id] = off + 0.1 * misses[k]  # the servo's clock drifts: follow it
        return k

    def _answer(
        self, id: int, value: int | None, tick: int | None, error: int, now: float, where: str
    ) -> None:
        """A reply from ``id`` (``value`` None: corrupt) with its Realtime Tick (None: none to
        trust), seen at ``now``."""
        d = self.driver
        i = self.index[id]
        k = self._match(i, id, tick)
        if k is None:
            self.stale += 1  # no open request for it (a duplicate, or no read-back)
            self.unmatched[id] += tick is not None
            self.heard[id] = now
            self.in_a_row[id] = 0
            return
        self.unmatched[id] = 0
        for _ in range(k):
            self._close(self.open.popleft(), where)  # over: a later request's reply came
        r = self.open[0]
        self._lost(self.ids[r.last + 1 : i], where)
        r.last = i
        # Its next unanswered request is the one after this (replies come in request order).
        self.asked[id] = self.open[1].sent if len(self.open) > 1 else None
        self.heard[id] = now
        self.replies += 1
        self.delays.append(now - r.sent)
        if r.late:
            self.late += 1
        if value is None:
            r.corrupt = True
        else:
            self.in_a_row[id] = 0
            r.got[id] = value
        if error:
            d.history.append(f"{where}: SYNC_READ reply of {d.who(id)}: error {error}")
            if error & 0x80:
                d.drain(DRAIN_QUIET)
                raise DeviceFault(d._hardware_error(id), where)
            raise DeviceFault(
                f"{d.who(id)} answered SYNC_READ of present positions with {describe_error(error)}",
                where,
            )
        if i == len(self.ids) - 1:
            self._close(self.open.popleft(), where)

    def _close(self, r: _Request, where: str) -> None:
        self._lost(self.ids[r.last + 1 :], where)
        if len(r.got) == len(self.ids):
            self.samples.append((r.sampled, *(r.got[id] for id in self.ids)))
        if r.corrupt:
            self.corrupt_in_a_row += 1
            if self.corrupt_in_a_row > self.max_corrupt:
                raise DeviceError(
                    f"{self.corrupt_in_a_row} corrupt read-backs in a row (more than"
                    f" bus.max_corrupt = {self.max_corrupt}): noise on the bus?",
                    where,
                )
        elif len(r.got) == len(self.ids):
            self.corrupt_in_a_row = 0

    def _lost(self, ids: list[int], where: str) -> None:
        """Servos ``ids`` did not answer one read-back."""
        for id in ids:
            self.in_a_row[id] += 1
        self.missed += len(ids)
        self.most_in_a_row = max([self.most_in_a_row, *(self.in_a_row[id] for id in ids)])
        over = [id for id in ids if self.in_a_row[id] > self.max_missed]
        if over:
            others = "" if len(ids) == len(self.ids) else " while the others did"
            raise DeviceTimeout(
                f"{_and([self.driver.who(id) for id in over])} did not answer SYNC_READ of"
                f" present positions {max(self.in_a_row[id] for id in over)} times in a row"
                f" (more than bus.max_missed = {self.max_missed}){others}",
                where,
            )

    def figures(self) -> dict[str, Any]:
        """Counts and reply delays for the report."""
        delays = np.array(self.delays) * 1e3 if self.delays else np.zeros(1)
        return {
            "readback_requests": self.requests,
            "readback_replies": self.replies,
            "readback_late_replies": self.late,
            "readback_missed_replies": self.missed,
            "readback_most_missed_in_a_row": self.most_in_a_row,
            "readback_stale_replies": self.stale,
            "readback_corrupt_replies": self.corrupt,
            "reply_delay_p50_ms": float(np.percentile(delays, 50)),
            "reply_delay_p99_ms": float(np.percentile(delays, 99)),
            "reply_delay_max_ms": float(delays.max()),
        }


def _and(names: list[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


class UrlPortHandler(sdk.PortHandler):
    """dynamixel-sdk's ``PortHandler`` opening its port with ``serial.serial_for_url``.

    ``setupPort`` differs from the SDK's only in that call (same settings: 8N1, ``timeout=0``), so
    device paths, pseudo-terminals and pyserial URL handlers (``dxlsim://``) all open. When the
    serial object has a ``clock`` (the in-process simulator's simulated time), ``getCurrentTime``
    reads it, so the SDK's packet timeouts (≈ 34 ms) are measured on the same clock as the bus
    they wait for; otherwise it is the SDK's own wall clock. The rest is the SDK's.
    """

    clock: Clock | None = None
    reply_allowance_ms: float = 2.0 * sdk.port_handler.LATENCY_TIMER + 2.0
    """What the SDK's packet timeout allows beyond the bytes' own time, ms (the SDK's 34 ms
    unless the driver sets it: ``bus.silence_timeout`` while connecting)."""

    def clearPort(self) -> None:
        """Nothing. The SDK calls this before every packet it sends, and pyserial's ``flush``
        behind it drains the output (``tcdrain``): the loop would wait, at every tick, until the
        far end has taken the bytes (on a pseudo-terminal, until its server is scheduled).
        Stale input is the read-back's business (:class:`ReadBack`)."""

    def setPacketTimeout(self, packet_length: int) -> None:
        self.packet_start_time = self.getCurrentTime()
        self.packet_timeout = self.tx_time_per_byte * packet_length + self.reply_allowance_ms

    def setupPort(self, cflag_baud: int) -> bool:
        if self.is_open:
            self.closePort()
        self.ser = serial.serial_for_url(
            self.port_name, baudrate=self.baudrate, bytesize=serial.EIGHTBITS, timeout=READ_WAIT
        )
        self.is_open = True
        self.clock = simulated_clock(self.ser)
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True

    def getCurrentTime(self) -> float:
        """Milliseconds, on the serial object's clock when it has one."""
        if self.clock is not None:
            return self.clock.now() * 1000.0
        return super().getCurrentTime()  # type: ignore[no-any-return]


def _u32(value: int) -> list[int]:
    return list(int(value).to_bytes(4, "little", signed=True))


def _signed32(value: int) -> int:
    """A 4-byte item the SDK read as unsigned, as the signed number the servo holds."""
    return value - (1 << 32) if value >= 1 << 31 else value


class ArmDriver:
    """One connection to the arm's bus. Use as a context manager; see the module docstring.

    ``port`` is a device path or a pyserial URL. ``clock`` overrides the clock choice (tests).
    """

    def __init__(self, port: str, profile: ArmProfile, *, clock: Clock | None = None) -> None:
        self.port_name = port
        self.profile = profile
        self.ids = list(profile.bus_ids)
        self.lifter: Lifter | None = None
        """A serial arm's pen lift by the arm itself (None: the profile's pen servo lifts it)."""
        self.last_row: list[int] | None = None
        """The last goal row sent (ticks per servo in bus order)."""
        self.roles = profile.names
        self.port: UrlPortHandler | None = None
        self.ph = sdk.PacketHandler(2.0)
        self.clock: Clock = clock or MonotonicClock()
        self._clock_given = clock is not None
        self.history: deque[str] = deque(maxlen=HISTORY)
        self.torque_on = False
        self.models: dict[int, int] = {}
        self.stopped = False
        self.lifted = False
        """Whether the safe stop got the pen up: the pen servo's pen-up goal sent and its
        ``pen.move_time`` waited, or a serial arm's lift by the arm done (or the pen found up)."""
        self.lift_failure: str | None = None
        """Why the safe stop did not get the pen up, when it failed."""

    # -- context -----------------------------------------------------------------------------

    def __enter__(self) -> ArmDriver:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the port (idempotent)."""
        port, self.port = self.port, None
        if port is not None and port.ser is not None:
            try:
                port.ser.flush()  # the last packets (pen up, torque) reach the bus first
                port.closePort()
            except (OSError, serial.SerialException) as e:  # pragma: no cover - best effort
                log.debug("closing %s: %s", self.port_name, e)

    # -- naming and errors -------------------------------------------------------------------

    def who(self, id: int) -> str:
        return f"servo {id} ({self.roles.get(id, '?')})"

    def _check(self, result: int, error: int, id: int | None, what: str, where: str) -> None:
        """Turn an SDK result code and a status error byte into a tagbot exception."""
        self.history.append(f"{where}: {what} -> result {result}, error {error}")
        who = self.who(id) if id is not None else "the bus"
        if result == sdk.COMM_SUCCESS:
            if error & 0x80 and id is not None:
                raise DeviceFault(self._hardware_error(id), where)
            if error:
                raise DeviceFault(f"{who} answered {what} with {describe_error(error)}", where)
            return
        if result == sdk.COMM_RX_TIMEOUT:
            raise DeviceTimeout(
                f"{who} did not answer {what} (no status packet before the SDK's timeout)", where
            )
        if result == sdk.COMM_TX_FAIL:
            raise ConnectionLost(f"could not write {what} to {self.port_name}", where)
        text = self.ph.getTxRxResult(result) or f"result code {result}"
        raise DeviceError(f"{who}: {what}: {text}", where)

    def _hardware_error(self, id: int) -> str:
        """A sentence naming the bits of ``id``'s Hardware Error Status (read now, if possible)."""
        try:
            bits, result, _ = self.ph.read1ByteTxRx(self.port, id, HARDWARE_ERROR_STATUS)
        except (OSError, serial.SerialException):
            result, bits = sdk.COMM_TX_FAIL, 0
        if result != sdk.COMM_SUCCESS:
            names = "unknown (Hardware Error Status could not be read)"
        else:
            flags = [str(f.name).lower().replace("_", " ") for f in HardwareError if bits & f]
            names = ", ".join(flags) or "none reported"
            names += f" (Hardware Error Status 0x{bits:02x})"
        return (
            f"{self.who(id)}: hardware error: {names}; remove the cause, then reboot the servo"
            " (REBOOT or a power cycle) to clear it"
        )

    def _guard(self, action: Callable[[], Any], what: str, where: str) -> Any:
        """Run an SDK call, turning serial exceptions into ConnectionLost."""
        try:
            return action()
        except (OSError, serial.SerialException) as e:
            raise ConnectionLost(f"{self.port_name}: {what}: {e}", where) from e

    # -- connect -----------------------------------------------------------------------------

    def open(self) -> None:
        """Open the port at ``bus.baud``."""
        baud = self.profile["bus.baud"]
        port = UrlPortHandler(self.port_name)
        port.baudrate = baud
        try:
            opened = port.openPort()
        except (OSError, ValueError, serial.SerialException) as e:
            raise ConnectionLost(f"cannot open {self.port_name}: {e}", "connect") from e
        if not opened:
            raise ConnectionLost(f"cannot open {self.port_name} at {baud} bps", "connect")
        self.port = port
        port.reply_allowance_ms = 1000.0 * self.profile["bus.silence_timeout"]
        if not self._clock_given and port.clock is not None:
            self.clock = port.clock
        log.info("opened %s at %d bps", self.port_name, baud)

    def connect(self) -> None:
        """Open, find the servos, check their models, configure them and switch torque on."""
        if self.port is None:
            self.open()
        self.scan()
        self.configure()

    def scan(self) -> dict[int, int]:
        """Ping every profile ID; returns ID → model number. Refuses missing or wrong servos."""
        port, where = self.port, "connect"
        missing = []
        for id in self.ids:
            model, result, error = self._transact(
                lambda id=id: self.ph.ping(port, id), f"ping {id}", where
            )
            if result == sdk.COMM_RX_TIMEOUT:
                missing.append(id)
                continue
            self._check(result, error & 0x7F, id, "PING", where)
            self.models[id] = model
            if error & 0x80:
                raise DeviceFault(self._hardware_error(id), where)
        if missing:
            raise DeviceError(self._missing_message(missing), where)
        for id in self.ids:
            role = self.roles[id]
            wanted = self.profile[f"{role}.model"]
            number = self.models[id]
            have = MODELS[number].model_name if number in MODELS else "an unknown model"
            if have != wanted:
                raise DeviceError(
                    f"{self.who(id)} is {have} (model number {number}), the profile says"
                    f" {wanted}: fix {role}.model or {role}.id",
                    where,
                )
        log.info("found %s", ", ".join(f"{self.who(i)} model {self.models[i]}" for i in self.ids))
        return dict(self.models)

    def _missing_message(self, missing: list[int]) -> str:
        found, result = self._guard(
            lambda: self.ph.broadcastPing(self.port), "broadcast ping", "connect"
        )
        baud = self.profile["bus.baud"]
        names = ", ".join(self.who(i) for i in missing)
        if result == sdk.COMM_SUCCESS and found:
            listed = ", ".join(
                f"{i} ({MODELS[m[0]].model_name if m[0] in MODELS else f'model {m[0]}'})"
                for i, m in sorted(found.items())
            )
            seen = f"IDs found on the bus: {listed}"
        else:
            seen = "no servo answered a broadcast ping (check power, wiring and bus.baud)"
        return f"{names} did not answer a ping at {baud} bps on {self.port_name}; {seen}"

    def configure(self) -> None:
        """Torque off, EEPROM settings (only if different), profile, torque on."""
        p, where = self.profile, "configure"
        self.set_torque(self.ids, False, where, reply=True)
        delay = int(p["bus.return_delay_us"]) // 2
        fraction = p["servo.acceleration_fraction"]
        velocity, acceleration = time_based_profile(p.profile_ms, int(fraction * p.profile_ms))
        limits = self._position_limits()
        for id in self.ids:
            self._ensure(id, RETURN_DELAY_TIME, 1, delay, where)
            self._ensure(id, DRIVE_MODE, 1, int(DriveMode.TIME_BASED_PROFILE), where)
            self._ensure(id, OPERATING_MODE, 1, int(OperatingMode.POSITION), where)
            if id in limits:
                low, high = limits[id]
                self._ensure(id, MIN_POSITION_LIMIT, 4, low, where)
                self._ensure(id, MAX_POSITION_LIMIT, 4, high, where)
            self._write(id, PROFILE_ACCELERATION, 4, acceleration, where)
            self._write(id, PROFILE_VELOCITY, 4, velocity, where)
            gains = getattr(p, "gains", None)  # a serial arm's position PID (RAM)
            if gains is not None:
                for address, value in zip(POSITION_PID, gains, strict=True):
                    self._write(id, address, 2, value, where)
        self.set_torque(self.ids, True, where, reply=True)
        log.info(
            "configured: time-based profile %d ms (ramps %d ms), torque on", velocity, acceleration
        )

    def _position_limits(self) -> dict[int, tuple[int, int]]:
        if not self.profile["servo.write_limits"]:
            return {}
        out = {}
        for joint in self.profile.joints:
            ends = angles_to_ticks([joint.lower, joint.upper], joint)
            out[joint.id] = (int(ends.min()), int(ends.max()))
        return out

    def _transact(self, action: Callable[[], tuple[Any, ...]], what: str, where: str) -> Any:
        """One SDK transaction awaiting its status, tried :data:`ATTEMPTS` times while the reply
        is missing or corrupt; before a retry the late reply to the last try, if it comes, is
        drained so that it is not taken for the next one's."""
        for attempt in range(ATTEMPTS):
            answer = self._guard(action, what, where)
            result = answer[-2]
            if result not in (sdk.COMM_RX_TIMEOUT, sdk.COMM_RX_CORRUPT) or attempt == ATTEMPTS - 1:
                return answer
            log.debug("%s: %s: result %d, trying again", where, what, result)
            self.history.append(f"{where}: {what} -> result {result}, retried")
            self.drain(DRAIN_QUIET)
        return answer  # pragma: no cover - the loop returns

    def drain(self, quiet: float = 0.0) -> int:
        """Discard input until none has come for ``quiet`` s (0: what is there now); returns the
        bytes discarded."""
        assert self.port is not None
        port = self.port
        port.is_using = False
        dropped = 0
        end = self.clock.now() + quiet
        while True:
            waiting = self._guard(lambda: port.ser.in_waiting, "drain", "drain")
            if waiting:
                data = self._guard(lambda n=waiting: port.ser.read(n), "drain", "drain")
                dropped += len(data)
                end = self.clock.now() + quiet
            elif self.clock.now() >= end:
                return dropped
            else:
                self.clock.sleep_until(min(end, self.clock.now() + 0.001))

    def _clock_offsets(self, where: str) -> dict[int, float]:
        """Per servo, its Realtime Tick less the host's clock (ms) when a request reaches it:
        one READ each, awaited (a single request open, so the reply is its own)."""
        offsets = {}
        for id in self.ids:
            sent = self.clock.now()
            offsets[id] = self._read(id, REALTIME_TICK, 2, where) - 1e3 * sent
        return offsets

    def _read(self, id: int, address: int, size: int, where: str) -> int:
        call = {1: self.ph.read1ByteTxRx, 2: self.ph.read2ByteTxRx, 4: self.ph.read4ByteTxRx}[size]
        value, result, error = self._transact(
            lambda: call(self.port, id, address), f"read {address}", where
        )
        self._check(result, error, id, f"READ of address {address}", where)
        return int(value)

    def _write(self, id: int, address: int, size: int, value: int, where: str) -> None:
        call = {
            1: self.ph.write1ByteTxRx,
            2: self.ph.write2ByteTxRx,
            4: self.ph.write4ByteTxRx,
        }[size]
        result, error = self._transact(
            lambda: call(self.port, id, address, value & 0xFFFFFFFF), f"write {address}", where
        )
        self._check(result, error, id, f"WRITE of {value} to address {address}", where)

    def _ensure(self, id: int, address: int, size: int, value: int, where: str) -> None:
        """Write an EEPROM item only when it differs (EEPROM wears; unchanged is untouched)."""
        if self._read(id, address, size, where) != value:
            self._write(id, address, size, value, where)

    def set_torque(self, ids: list[int], on: bool, where: str, *, reply: bool = False) -> None:
        """Torque Enable for ``ids``: one WRITE each with its status (``reply``) or one
        SYNC_WRITE (no status: works even with a silent servo on the bus)."""
        if reply:
            for id in ids:
                self._write(id, TORQUE_ENABLE, 1, int(on), where)
        else:
            group = sdk.GroupSyncWrite(self.port, self.ph, TORQUE_ENABLE, 1)
            for id in ids:
                group.addParam(id, [int(on)])
            self._check(
                self._guard(group.txPacket, "torque", where), 0, None, "SYNC_WRITE torque", where
            )
        self.torque_on = on if set(ids) == set(self.ids) else self.torque_on

    # -- streaming ---------------------------------------------------------------------------

    def read_present(self, where: str = "connect") -> NDArray[np.int64]:
        """Present positions of (shoulder, elbow, pen), ticks, one READ each (signed, as the
        read-back's: a Homing Offset can put a horn below 0)."""
        return np.array([_signed32(self._read(id, PRESENT_POSITION, 4, where)) for id in self.ids])

    def move_to(self, goals: NDArray[np.int64], duration: float, where: str = "approach") -> None:
        """One smooth move of all three servos to ``goals`` in ``duration`` s, using the servos'
        own time-based profile (ramps a quarter of the time each way); the streaming profile is
        restored afterwards. The pen goes first, in ``pen.move_time``."""
        p = self.profile
        arm_ms = max(1, math.ceil(1000 * duration))
        if arm_ms > 32737:
            raise DeviceError(f"the move to park would take {duration:.1f} s (> 32.7 s)", where)
        pen = self.pen_id
        if pen is not None:
            pen_ms = max(1, round(1000 * p["pen.move_time"]))
            self._profile_all({pen: (pen_ms, pen_ms // 4)}, where)
            self._goals({pen: int(goals[self.ids.index(pen)])}, where)
            self.clock.sleep_until(self.clock.now() + pen_ms / 1000)
        moving = [id for id in self.ids if id != pen]
        self._profile_all({id: (arm_ms, arm_ms // 4) for id in moving}, where)
        self._goals({id: int(goals[self.ids.index(id)]) for id in moving}, where)
        arrive = self.clock.now() + arm_ms / 1000
        self.clock.sleep_until(arrive)
        # Servos slower than asked (Velocity Limit) or a busy host: wait a little longer.
        deadline = arrive + max(0.5, arm_ms / 1000)
        while True:
            present = self.read_present(where)
            off = np.abs(present - np.asarray(goals))
            if off.max() <= ARRIVED or self.clock.now() > deadline:
                break
            self.clock.sleep_until(self.clock.now() + 0.02)
        if off.max() > ARRIVED:
            i = int(np.argmax(off))
            raise DeviceError(
                f"{self.who(self.ids[i])} stopped at {present[i]} ticks, {off[i]} from its goal"
                f" {goals[i]} (blocked, or torque off?)",
                where,
            )
        self._streaming_profile(where)
        self.last_row = [int(g) for g in goals]

    def _streaming_profile(self, where: str) -> None:
        """Every servo back on the streaming profile (``profile_ms``) after a move of its own."""
        p = self.profile
        streaming = time_based_profile(
            p.profile_ms, int(p["servo.acceleration_fraction"] * p.profile_ms)
        )
        self._profile_all({id: streaming for id in self.ids}, where)

    @property
    def pen_id(self) -> int | None:
        """The pen servo's ID, or None when the arm lifts the pen itself."""
        return self.profile.pen_servo

    def _rows(self, rows: NDArray[np.int64], readback: ReadBack | None, where: str) -> None:
        """Stream goal rows (every servo) one a period, the read-back (if any) watching, then
        wait for the last one's own move."""
        clock, period = self.clock, self.profile.period
        writer = sdk.GroupSyncWrite(self.port, self.ph, GOAL_POSITION, 4)
        for id in self.ids:
            writer.addParam(id, _u32(0))
        t0 = clock.now()
        for i, row in enumerate(np.asarray(rows, dtype=np.int64).tolist()):
            free = readback.bus_free if readback is not None else -math.inf
            clock.sleep_until(max(t0 + i * period, free))
            for id, goal in zip(self.ids, row, strict=True):
                writer.changeParam(id, _u32(goal))
            result = self._guard(writer.txPacket, "goal positions", where)
            self._check(result, 0, None, "SYNC_WRITE of goal positions", where)
            self.last_row = row
            if readback is not None:
                readback.poll(where)
        settled = clock.now() + self.profile.lead
        while clock.now() < settled:
            if readback is not None:
                readback.poll(where)
            clock.sleep_until(min(settled, clock.now() + period))

    def _profile_all(self, values: dict[int, tuple[int, int]], where: str) -> None:
        """Profile Velocity and Acceleration (ms) per servo, one SYNC_WRITE of 108..115."""
        group = sdk.GroupSyncWrite(self.port, self.ph, PROFILE_ACCELERATION, 8)
        for id, (velocity, acceleration) in values.items():
            group.addParam(id, _u32(acceleration) + _u32(velocity))
        result = self._guard(group.txPacket, "profile", where)
        self._check(result, 0, None, "SYNC_WRITE of the profile", where)

    def _goals(self, goals: dict[int, int], where: str) -> None:
        group = sdk.GroupSyncWrite(self.port, self.ph, GOAL_POSITION, 4)
        for id, goal in goals.items():
            group.addParam(id, _u32(goal))
        result = self._guard(group.txPacket, "goal positions", where)
        self._check(result, 0, None, "SYNC_WRITE of goal positions", where)

    def stream(
        self,
        goals: NDArray[np.int64],
        progress: Callable[[int, int], None] | None = None,
        control: RunControl | None = None,
        first: int = 0,
    ) -> StreamResult:
        """Send ``goals`` ``(N, 3)`` (shoulder, elbow, pen ticks), one row per tick, reading
        present positions back on the side; obey ``control`` (pause: pen up, pose held). Stops
        safely on any error or KeyboardInterrupt and re-raises it, ``where`` naming the last tick
        sent (from 1, counting ``first`` rows of the program before ``goals``); :attr:`result`
        holds what was measured up to then. See the module docstring."""
        goals = np.asarray(goals, dtype=np.int64)
        if goals.ndim != 2 or goals.shape[1] != len(self.ids) or not len(goals):
            raise ValueError(
                f"goals: must be a non-empty (N, {len(self.ids)}) array, got shape {goals.shape}"
            )
        assert self.port is not None
        p = self.profile
        period, lead, every = p.period, p.lead, p.readback_every
        # Late by up to a quarter of the profile time, the servos are still on their way to the
        # last goal and catching up costs at most 25 % of speed for a moment; later, re-anchor.
        scheduler = Scheduler(self.clock, period, resync_after=max(period, lead / 4))
        out = StreamResult(scheduler=scheduler, lead=lead, first=first)
        self.result = out
        writer = sdk.GroupSyncWrite(self.port, self.ph, GOAL_POSITION, 4)
        for id, goal in zip(self.ids, goals[0], strict=True):
            writer.addParam(id, _u32(int(goal)))
        total = len(goals)
        notify = max(1, round(p["motion.rate"] / 10))
        ticks = first + total
        dropped = self.drain()  # late replies from the setup
        if dropped:
            log.debug("dropped %d stale bytes before streaming", dropped)
        offsets = self._clock_offsets(f"tick {first}")
        now = self.clock.now()
        if first:  # resumed where the arm stands: the row before is due now, as after a pause
            out.start = scheduler.start(now - lead + period)
            scheduler.floor = now
        else:
            out.start = scheduler.start(now + period)
        readback = ReadBack(self, now, offsets)
        out.readback = readback
        ids = self.ids
        log.info("streaming %d ticks at %g Hz, read-back every %d", total, p["motion.rate"], every)
        rows = goals.tolist()
        k = 0
        realtime = RealTime(self.clock)  # after the rows: frozen, out of the collector's way
        out.realtime = realtime.fifo
        try:
            while k < total:
                scheduler.wait(k)
                if control is not None and control.paused:
                    self._pause(k, goals, readback, control, out)  # then tick k is due
                where = f"tick {first + k + 1}"
                if readback.bus_free > self.clock.now():  # slow bus: replies still on the line
                    self.clock.sleep_until(readback.bus_free)
                for id, goal in zip(ids, rows[k], strict=True):
                    writer.changeParam(id, _u32(goal))
                result = self._guard(writer.txPacket, "goal positions", where)
                self._check(result, 0, None, "SYNC_WRITE of goal positions", where)
                self.last_row = rows[k]
                scheduler.sent(self.clock.now())
                out.ticks_sent = k + 1
                readback.poll(where)
                if k % every == 0:
                    readback.request(where)
                    # Look again once the replies could be here, if that leaves half the
                    # period before the next deadline (else at the next tick).
                    settle = readback.open[-1].sent + readback.window
                    if settle < scheduler.deadline(k) + 0.5 * period:
                        self.clock.sleep_until(settle)
                        readback.poll(where)
                if progress is not None and (k % notify == 0 or k == total - 1):
                    progress(first + k + 1, ticks)
                k += 1
            # Let the last move finish before anything else (torque off, the recorder's end),
            # still watching the replies.
            where = f"tick {ticks}"
            last = scheduler.deadline(total - 1) + lead
            while self.clock.now() < last:
                self.clock.sleep_until(min(last, self.clock.now() + period))
                readback.poll(where)
        except BaseException as exc:
            log.warning("stopping: %s", exc if str(exc) else type(exc).__name__)
            for line in self.history:
                log.debug("  %s", line)
            self.safe_stop(error=True)
            raise
        finally:
            realtime.end()
            out.end = self.clock.now()
            out.origin = scheduler.t0 + lead
            out.corrupt_replies = readback.corrupt
            out.read_clock = list(readback.samples)
            if readback.samples:
                reads = np.array(readback.samples, dtype=float)
                t = out.program_time(reads[:, 0])
                keep = np.isfinite(t)
                out.reads = [
                    (float(t[i]), *(int(v) for v in reads[i, 1:])) for i in np.flatnonzero(keep)
                ]
        log.info(
            "sent %d ticks: %d late (max %.2f ms), %d resyncs; read-back: %d missed, %d late,"
            " %d corrupt replies",
            out.ticks_sent,
            scheduler.late_ticks,
            1e3 * scheduler.max_lateness,
            scheduler.resyncs,
            readback.missed,
            readback.late,
            readback.corrupt,
        )
        self.finish()
        return out

    def _pause(
        self,
        k: int,
        goals: NDArray[np.int64],
        readback: ReadBack,
        control: RunControl,
        out: StreamResult,
    ) -> None:
        """Before tick ``k``: lift the pen, hold the pose (the last goals), keep watching the
        read-back until ``control`` resumes; then put the pen back as it was, and make tick ``k``
        due now."""
        p, clock, scheduler = self.profile, self.clock, out.scheduler
        assert scheduler is not None
        where = f"tick {out.first + k}"
        began = clock.now()
        out.pauses += 1
        held = goals[k - 1] if k else None
        log.info("paused at %s: pen up, holding the pose", where)
        if self.lifter is not None:
            pose = held if held is not None else np.array(self.last_row)
            up = self.lifter.up(pose)
            lifted = len(up) > 0
            if lifted:
                self._rows(up, readback, where)
        else:
            lifted = held is not None and int(held[2]) != p["pen.up"]
            if lifted:
                assert held is not None
                self._pen_ramp(int(held[2]), p["pen.up"], readback, where)
        interval = p.readback_every * p.period
        next_read = clock.now()
        while control.paused:
            now = clock.now()
            if now >= next_read:
                readback.request(where)
                next_read = now + interval
            readback.poll(where)
            clock.sleep_until(min(next_read, clock.now() + 0.01))
        if lifted and self.lifter is not None:
            self._rows(self.lifter.down(pose)[1:], readback, where)
        elif lifted:
            assert held is not None
            self._pen_ramp(p["pen.up"], int(held[2]), readback, where)
            settled = clock.now() + p.lead  # the last pen goal's own move
            while clock.now() < settled:
                readback.poll(where)
                clock.sleep_until(min(settled, clock.now() + p.period))
        resumed = clock.now()
        due = scheduler.deadline(k)  # before the pause
        # The arm goes on as if it had never stopped: tick k - 1's pose, where it stands, is due
        # now, so the goals after it go out at once up to the one due now, which the servos
        # reach a profile time later, as in the steady stream (the first move from rest, then
        # on time). In the executed timeline the pause is as long as the ticks were put off,
        # from the arm's arrival at tick k - 1.
        shift = resumed - p.lead - (due - p.period)
        scheduler.reanchor(k, due + shift, began, floor=resumed)
        out.pause_spans.append((due - p.period + p.lead, shift))
        out.paused += resumed - began
        log.info("resumed at %s after %.1f s", where, resumed - began)

    def _pen_ramp(
        self, start: int, end: int, readback: ReadBack | None, where: str, *, settle: bool = False
    ) -> None:
        """Move the pen alone from ``start`` to ``end`` ticks in ``pen.move_time``, one goal a
        tick (as the program's pen moves), the read-back (if any) still watching; with
        ``settle``, until the last goal's own move is over."""
        p, clock = self.profile, self.clock
        steps = max(1, math.ceil(p["pen.move_time"] / p.period - 1e-9))
        t0 = clock.now()
        for i in range(1, steps + 1):
            free = readback.bus_free if readback is not None else -math.inf
            clock.sleep_until(max(t0 + (i - 1) * p.period, free))
            self._goals({p["pen.id"]: round(start + (end - start) * i / steps)}, where)
            if readback is not None:
                readback.poll(where)
        if settle:
            clock.sleep_until(clock.now() + p.lead)

    def lift_from(self, pose: NDArray[np.int64], where: str) -> None:
        """A serial arm standing at ``pose`` (ticks: its present positions), held there and
        lifted along the paper's normal to the pen-up height (held only when the pen is up
        already), on the streaming profile (a move of the servos' own is cut where it is)."""
        assert self.lifter is not None
        self._streaming_profile(where)
        self._rows(np.concatenate([self.lifter.stand(pose), self.lifter.up(pose)]), None, where)

    def lower_pen(self, pen: int | NDArray[np.int64], where: str = "resume") -> None:
        """From up, put the pen to ``pen`` ticks as a pause's resume does (before streaming);
        a serial arm lowers itself to the row ``pen`` along the paper's normal."""
        if self.lifter is not None:
            self._rows(self.lifter.down(np.asarray(pen, dtype=np.int64))[1:], None, where)
            return
        if pen != self.profile["pen.up"]:
            self._pen_ramp(self.profile["pen.up"], pen, None, where, settle=True)

    def finish(self) -> None:
        """After a successful stream: torque off if ``servo.torque_off_at_end``."""
        if self.profile["servo.torque_off_at_end"]:
            self.set_torque(self.ids, False, "end")

    def safe_stop(self, *, error: bool) -> None:
        """Pen up once the arm has reached its last goal (``lead`` after it was sent: what was
        sent is drawn, so a resume from the next tick skips nothing), arm joints holding it;
        after an error, arm torque off (policy).

        Best effort: failures are logged, never raised (the original error matters more);
        :attr:`lifted` says whether the pen is up, :attr:`lift_failure` why not (also when a
        second interrupt cut the stop short, which is re-raised).
        """
        if self.port is None or self.stopped:
            return
        self.stopped = True
        p = self.profile
        self.port.is_using = False  # an interrupted SDK call may have left it set
        result = getattr(self, "result", None)
        if self.lifter is not None:
            self._lift_by_arm(error, result)
            return
        pen = p["pen.id"]
        self.lift_failure = "interrupted before the pen was up"  # until the pen is up
        try:
            if result is not None and result.scheduler is not None and result.scheduler.sends:
                self.clock.sleep_until(result.scheduler.sends[-1] + p.lead)
            group = sdk.GroupSyncWrite(self.port, self.ph, GOAL_POSITION, 4)
            group.addParam(pen, _u32(p["pen.up"]))
            written = self._guard(group.txPacket, "pen up", "stop")
            self._check(written, 0, None, "SYNC_WRITE of pen up", "stop")
            self.clock.sleep_until(self.clock.now() + p["pen.move_time"])
            self.lifted, self.lift_failure = True, None
            if error and p["servo.torque_off_after_error"]:
                self.set_torque([p["shoulder.id"], p["elbow.id"]], False, "stop")
            log.info("stopped safely: pen up%s", ", arm torque off" if error else "")
        except (DeviceError, OSError, serial.SerialException) as e:
            if not self.lifted:
                self.lift_failure = str(e) or type(e).__name__
            log.error("safe stop failed: %s", e)

    def _lift_by_arm(self, error: bool, result: StreamResult | None) -> None:
        """A serial arm's safe stop: once the last goal is reached, the arm itself lifts the pen
        along the paper's normal to the pen-up height and holds; after an error, torque off only
        if ``servo.torque_off_after_error`` (the arm then falls). Stopped before the stream
        sent anything (connecting, the approach, a resume's touch-down) the arm is where its
        present positions say, not at a goal: it is held there and lifted from there, or, with
        its torque not on yet, left as it is. Best effort, as :meth:`safe_stop`: :attr:`lifted`
        says whether the pen is up, :attr:`lift_failure` why not (also when a second interrupt
        cut the lift short, which is re-raised)."""
        p = self.profile
        lifter = self.lifter
        assert lifter is not None
        self.lift_failure = "interrupted before the pen was up"  # until the lift is done
        try:
            if result is not None and result.scheduler is not None and result.scheduler.sends:
                self.clock.sleep_until(result.scheduler.sends[-1] + p.lead)
                pose = np.asarray(self.last_row, dtype=np.int64)
                rows = lifter.up(pose)
            else:
                self.drain(DRAIN_QUIET)  # a reply to an interrupted request is no pose
                pose = self.read_present("stop")
                if not self.torque_on:
                    if not lifter.is_up(pose):
                        self.lift_failure = (
                            "stopped before the arm was under torque, with the pen on the paper"
                        )
                        log.error("safe stop: %s", self.lift_failure)
                        return
                    rows = pose[:0]
                else:  # the approach's own move cut where the arm is, then the lift
                    self.lift_from(pose, "stop")
                    rows = pose[:0]
            if len(rows):
                self._rows(rows, None, "stop")
            self.lifted, self.lift_failure = True, None
            if error and p["servo.torque_off_after_error"]:
                self.set_torque(list(self.ids), False, "stop")
            log.info(
                "stopped safely: pen lifted by the arm%s",
                ", torque off" if error and p["servo.torque_off_after_error"] else "",
            )
        except (DeviceError, OSError, serial.SerialException, ValueError) as e:
            if not self.lifted:
                self.lift_failure = str(e) or type(e).__name__
            log.error("safe stop failed: %s", e)
