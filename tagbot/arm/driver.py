"""Streaming joint goals to the DYNAMIXEL arm with the official dynamixel-sdk.

**Port.** :class:`UrlPortHandler` is the SDK's ``PortHandler`` opening its port with
``serial.serial_for_url`` instead of ``serial.Serial`` (``setupPort``), so a device path
(``/dev/ttyUSB0``, a pseudo-terminal from ``tagbot sim arm``, ``COM3``) and any pyserial URL
(``dxlsim://…`` for the in-process simulator, ``rfc2217://…``) work alike. Two details differ
from the SDK's own: a 1 ms read timeout instead of 0 (see :data:`READ_WAIT`), and, on a port
with a simulated clock, ``getCurrentTime`` on that clock so the SDK's packet timeouts are
simulated time too. Packets, timeouts and result codes are the unmodified SDK's.

**Connect.** Open at ``bus.baud``; ping every profile ID (a missing one → :class:`DeviceError`
listing what a broadcast ping finds on the bus); check each model number; with torque off set
Return Delay Time, Drive Mode = time-based profile, Operating Mode = position and (optionally)
Min/Max Position Limit from the joint limits (EEPROM, written only when different); Profile
Velocity = ``servo.profile_ms`` and Profile Acceleration a fraction of it (RAM); then torque on.

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
ticks (about ``bus.readback_rate``, 100 Hz by default). A read is a round trip through the USB
adapter (1 to 2 ms with a 1 ms FTDI latency timer, 16+ ms at its default), so reading at 500 Hz
would eat the whole period on real hardware, while 100 Hz gives the executed trace and stops a
run within 10 ms of a hardware error. The status packets are received with ``readRx`` per ID,
which keeps each status error byte (the SDK's ``GroupSyncRead.rxPacket`` drops them).

**Errors.** SDK result codes and status error bytes become tagbot exceptions: ``COMM_RX_TIMEOUT``
→ :class:`DeviceTimeout`, an error byte → :class:`DeviceFault` (the hardware alert bit reads
Hardware Error Status and names overload, overheating…), ``COMM_TX_FAIL`` and serial exceptions →
:class:`ConnectionLost`, ``COMM_RX_CORRUPT`` → counted and skipped up to ``bus.max_corrupt`` in a
row, then :class:`DeviceError`. ``where`` names the tick.

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
from typing import Any

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
from tagbot.clock import Clock, MonotonicClock, simulated_clock
from tagbot.errors import ConnectionLost, DeviceError, DeviceFault, DeviceTimeout

__all__ = [
    "ArmDriver",
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
PROFILE_ACCELERATION = 108
PROFILE_VELOCITY = 112
GOAL_POSITION = 116
PRESENT_POSITION = 132

READ_WAIT = 0.001
"""Read timeout of the port, s. The SDK polls ``read`` in a loop until its packet timeout; with
``timeout=0`` (the SDK's choice) that loop spins and, on a pseudo-terminal served by a thread of
the same process, starves it of the GIL (read-backs then take 5 to 20 ms). A read returns as soon as
the bytes asked for have arrived, so this costs no latency."""

ARRIVED = 20
"""Ticks (1.8°) from its goal within which a servo has arrived after the move to park."""

HISTORY = 32
"""Bus operations kept for the debug log when something fails."""


class Scheduler:
    """Absolute deadlines ``t_k = t_0 + k·period`` on a clock; lateness measured at each tick.

    :meth:`wait` sleeps until tick ``k``'s deadline and returns how late it woke (s). A tick later
    than ``late_after`` (default a quarter period) counts as late. One later than
    ``resync_after`` (default one period) moves ``t_0`` on so that it is on time (``resyncs``
    counts this): the drawing pauses rather than sending the backlog in a burst, which would
    overspeed the joints. Below that the next ticks catch up on their own deadlines.
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
        self.max_lateness = 0.0
        self.lateness: list[float] = []
        """Per tick, seconds after its deadline that it woke."""
        self.woke: list[float] = []
        """Per tick, the clock time it woke (for period jitter)."""

    def start(self, t0: float | None = None) -> float:
        """Anchor tick 0 at ``t0`` (default: now); returns it."""
        self.t0 = self.clock.now() if t0 is None else float(t0)
        return self.t0

    def deadline(self, k: int) -> float:
        return self.t0 + k * self.period

    def wait(self, k: int) -> float:
        """Sleep until tick ``k``'s deadline; returns the lateness (s) measured on waking."""
        deadline = self.deadline(k)
        self.clock.sleep_until(deadline)
        woke = self.clock.now()
        late = max(0.0, woke - deadline)
        self.woke.append(woke)
        self.ticks += 1
        self.lateness.append(late)
        self.max_lateness = max(self.max_lateness, late)
        if late > self.late_after:
            self.late_ticks += 1
        if late > self.resync_after:
            self.t0 += late
            self.resyncs += 1
        return late


@dataclass
class StreamResult:
    """What :meth:`ArmDriver.stream` measured."""

    ticks_sent: int = 0
    """Goal rows written."""
    reads: list[tuple[float, int, int, int]] = field(default_factory=list)
    """Read-backs: ``(program time s, shoulder, elbow, pen ticks)``."""
    origin: float = 0.0
    """Clock time of program time 0: when the servos should be at the first setpoint (after
    the last resync, if any: each resync delays what follows by its lateness)."""
    end: float = 0.0
    """Clock time when the stream ended."""
    scheduler: Scheduler | None = None
    corrupt_replies: int = 0


class UrlPortHandler(sdk.PortHandler):
    """dynamixel-sdk's ``PortHandler`` opening its port with ``serial.serial_for_url``.

    ``setupPort`` differs from the SDK's only in that call (same settings: 8N1, ``timeout=0``), so
    device paths, pseudo-terminals and pyserial URL handlers (``dxlsim://``) all open. When the
    serial object has a ``clock`` (the in-process simulator's simulated time), ``getCurrentTime``
    reads it, so the SDK's packet timeouts (≈ 34 ms) are measured on the same clock as the bus
    they wait for; otherwise it is the SDK's own wall clock. The rest is the SDK's.
    """

    clock: Clock | None = None

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


class ArmDriver:
    """One connection to the arm's bus. Use as a context manager; see the module docstring.

    ``port`` is a device path or a pyserial URL. ``clock`` overrides the clock choice (tests).
    """

    def __init__(self, port: str, profile: ArmProfile, *, clock: Clock | None = None) -> None:
        self.port_name = port
        self.profile = profile
        self.ids = [profile[f"{role}.id"] for role in ("shoulder", "elbow", "pen")]
        self.roles = profile.names
        self.port: UrlPortHandler | None = None
        self.ph = sdk.PacketHandler(2.0)
        self.clock: Clock = clock or MonotonicClock()
        self._clock_given = clock is not None
        self.history: deque[str] = deque(maxlen=HISTORY)
        self.torque_on = False
        self.models: dict[int, int] = {}
        self.stopped = False

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
            for _attempt in range(2):
                model, result, error = self._guard(
                    lambda id=id: self.ph.ping(port, id), f"ping {id}", where
                )
                if result != sdk.COMM_RX_CORRUPT:
                    break
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

    def _read(self, id: int, address: int, size: int, where: str) -> int:
        call = {1: self.ph.read1ByteTxRx, 2: self.ph.read2ByteTxRx, 4: self.ph.read4ByteTxRx}[size]
        value, result, error = self._guard(
            lambda: call(self.port, id, address), f"read {address}", where
        )
        self._check(result, error, id, f"READ of address {address}", where)
        return int(value)

    def _write(self, id: int, address: int, size: int, value: int, where: str) -> None:
        call = {1: self.ph.write1ByteTxRx, 4: self.ph.write4ByteTxRx}[size]
        result, error = self._guard(
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
        """Present positions of (shoulder, elbow, pen), ticks, one READ each."""
        return np.array([self._read(id, PRESENT_POSITION, 4, where) for id in self.ids])

    def move_to(self, goals: NDArray[np.int64], duration: float, where: str = "approach") -> None:
        """One smooth move of all three servos to ``goals`` in ``duration`` s, using the servos'
        own time-based profile (ramps a quarter of the time each way); the streaming profile is
        restored afterwards. The pen goes first, in ``pen.move_time``."""
        p = self.profile
        pen_ms = max(1, round(1000 * p["pen.move_time"]))
        arm_ms = max(1, math.ceil(1000 * duration))
        if arm_ms > 32737:
            raise DeviceError(f"the move to park would take {duration:.1f} s (> 32.7 s)", where)
        pen = p["pen.id"]
        self._profile_all({pen: (pen_ms, pen_ms // 4)}, where)
        self._goals({pen: int(goals[2])}, where)
        self.clock.sleep_until(self.clock.now() + pen_ms / 1000)
        arm = {p["shoulder.id"]: (arm_ms, arm_ms // 4), p["elbow.id"]: (arm_ms, arm_ms // 4)}
        self._profile_all(arm, where)
        self._goals({p["shoulder.id"]: int(goals[0]), p["elbow.id"]: int(goals[1])}, where)
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
        streaming = time_based_profile(
            p.profile_ms, int(p["servo.acceleration_fraction"] * p.profile_ms)
        )
        self._profile_all({id: streaming for id in self.ids}, where)

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
        self, goals: NDArray[np.int64], progress: Callable[[int, int], None] | None = None
    ) -> StreamResult:
        """Send ``goals`` ``(N, 3)`` (shoulder, elbow, pen ticks), one row per tick. Stops safely
        on any error or KeyboardInterrupt and re-raises it; see the module docstring."""
        goals = np.asarray(goals, dtype=np.int64)
        if goals.ndim != 2 or goals.shape[1] != 3 or not len(goals):
            raise ValueError(f"goals: must be a non-empty (N, 3) array, got shape {goals.shape}")
        p = self.profile
        period, lead, every = p.period, p.lead, p.readback_every
        max_corrupt = int(p["bus.max_corrupt"])
        # Late by up to a quarter of the profile time, the servos are still on their way to the
        # last goal and catching up costs at most 25 % of speed for a moment; later, re-anchor.
        scheduler = Scheduler(self.clock, period, resync_after=max(period, lead / 4))
        out = StreamResult(scheduler=scheduler)
        writer = sdk.GroupSyncWrite(self.port, self.ph, GOAL_POSITION, 4)
        for id, goal in zip(self.ids, goals[0], strict=True):
            writer.addParam(id, _u32(int(goal)))
        reader = sdk.GroupSyncRead(self.port, self.ph, PRESENT_POSITION, 4)
        for id in self.ids:
            reader.addParam(id)
        total = len(goals)
        notify = max(1, round(p["motion.rate"] / 10))
        corrupt_run = 0
        scheduler.start(self.clock.now() + period)
        log.info("streaming %d ticks at %g Hz, read-back every %d", total, p["motion.rate"], every)
        try:
            for k, row in enumerate(goals):
                where = f"tick {k}"
                scheduler.wait(k)
                for id, goal in zip(self.ids, row, strict=True):
                    writer.changeParam(id, _u32(int(goal)))
                result = self._guard(writer.txPacket, "goal positions", where)
                self._check(result, 0, None, "SYNC_WRITE of goal positions", where)
                out.ticks_sent += 1
                if k % every == 0:
                    before = self.clock.now()
                    present = self._sync_read(reader, where)
                    if present is None:
                        out.corrupt_replies += 1
                        corrupt_run += 1
                        if corrupt_run > max_corrupt:
                            raise DeviceError(
                                f"{corrupt_run} corrupt read-backs in a row (more than"
                                f" bus.max_corrupt = {max_corrupt}): noise on the bus?",
                                where,
                            )
                    else:
                        corrupt_run = 0
                        sampled = 0.5 * (before + self.clock.now())
                        out.reads.append((sampled - scheduler.t0 - lead, *present))
                if progress is not None and (k % notify == 0 or k == total - 1):
                    progress(k + 1, total)
            out.origin = scheduler.t0 + lead
            # Let the last move finish before anything else (torque off, the recorder's end).
            self.clock.sleep_until(scheduler.deadline(total - 1) + lead)
            out.end = self.clock.now()
        except BaseException as exc:
            out.origin = scheduler.t0 + lead
            log.warning("stopping: %s", exc if str(exc) else type(exc).__name__)
            for line in self.history:
                log.debug("  %s", line)
            self.safe_stop(error=True)
            raise
        log.info(
            "sent %d ticks: %d late (max %.2f ms), %d resyncs, %d corrupt read-backs",
            out.ticks_sent,
            scheduler.late_ticks,
            1e3 * scheduler.max_lateness,
            scheduler.resyncs,
            out.corrupt_replies,
        )
        self.finish()
        return out

    def _sync_read(self, reader: sdk.GroupSyncRead, where: str) -> list[int] | None:
        """One SYNC_READ of present positions with each status error byte checked; None when a
        reply was corrupt (the rest of the replies are flushed)."""
        result = self._guard(reader.txPacket, "read-back", where)
        self._check(result, 0, None, "SYNC_READ of present positions", where)
        values = []
        for id in self.ids:
            data, result, error = self._guard(
                lambda id=id: self.ph.readRx(self.port, id, 4), "read-back", where
            )
            if result == sdk.COMM_RX_CORRUPT:
                log.debug("%s: corrupt read-back reply from %s", where, self.who(id))
                self.port.is_using = False
                self._guard(self.port.clearPort, "flush", where)
                return None
            self._check(result, error, id, "SYNC_READ of present positions", where)
            values.append(int.from_bytes(bytes(data[:4]), "little", signed=True))
        return values

    def finish(self) -> None:
        """After a successful stream: torque off if ``servo.torque_off_at_end``."""
        if self.profile["servo.torque_off_at_end"]:
            self.set_torque(self.ids, False, "end")

    def safe_stop(self, *, error: bool) -> None:
        """Pen up, arm joints holding their last goal; after an error, arm torque off (policy).

        Best effort: failures are logged, never raised (the original error matters more).
        """
        if self.port is None or self.stopped:
            return
        self.stopped = True
        p = self.profile
        self.port.is_using = False  # an interrupted SDK call may have left it set
        pen = p["pen.id"]
        try:
            group = sdk.GroupSyncWrite(self.port, self.ph, GOAL_POSITION, 4)
            group.addParam(pen, _u32(p["pen.up"]))
            self._guard(group.txPacket, "pen up", "stop")
            self.clock.sleep_until(self.clock.now() + p["pen.move_time"])
            if error and p["servo.torque_off_after_error"]:
                self.set_torque([p["shoulder.id"], p["elbow.id"]], False, "stop")
            log.info("stopped safely: pen up%s", ", arm torque off" if error else "")
        except (DeviceError, OSError, serial.SerialException) as e:
            log.error("safe stop failed: %s", e)
