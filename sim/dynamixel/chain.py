"""A simulated DYNAMIXEL bus: servos daisy-chained on one half-duplex line, Protocol 2.0.

:class:`SimulatedChain` is a byte-level device like :class:`sim.grbl.device.SimulatedGrbl`:
``write(data)`` puts host bytes on the bus, ``read()`` returns the status bytes that have reached
the host by now, and the clock (:meth:`~SimulatedChain.now`, :meth:`~SimulatedChain.advance_to`)
is simulated unless ``clock="real"`` (wall clock, for :func:`sim.dynamixel.transport.serve_pty`).

Timing: every byte takes 10 bits at the bus speed ``baud`` in each direction. An instruction
packet is executed when its last byte has arrived; each answering servo starts its status packet
Return Delay Time (address 9, 2 µs units) after that, or, in a SYNC_READ, BULK_READ or broadcast
PING, after the previous servo's status packet has ended (the devices answer in turn). Collisions
are not modelled: host and servos never talk at once when the host waits for its replies.

Protocol behaviour (ROBOTIS e-Manual, Protocol 2.0 page, and the X-series control-table pages):

- instruction packets are accepted byte-stuffed and unstuffed (the decoder is
  :class:`firmware_protocols.dynamixel.PacketDecoder`); status packets are sent stuffed, except
  the combined FAST_SYNC_READ / FAST_BULK_READ reply, which the e-Manual says is never stuffed;
- a packet with a bad CRC gets **no reply** by default: the e-Manual's reception order checks
  the CRC before anything else, and ROBOTIS's own device-side library (Dynamixel2Arduino,
  ``Slave::processPacket``) only processes packets that parsed with a correct CRC.
  ``reply_to_bad_crc=True`` answers the packet's ID with error 3 (CRC error) instead;
- broadcast (ID 254) gets replies for PING, SYNC_READ and BULK_READ only; broadcast PING is
  answered by every servo in ascending ID order;
- Status Return Level (68): 0 answers PING only, 1 PING and reads (READ, SYNC/BULK READ), 2 all;
- the status error byte carries 0x80 while Hardware Error Status (70) is non-zero;
- FACTORY_RESET with option 0xFF to the broadcast ID is ignored (e-Manual, firmware ≥ 42);
  Baud Rate changes take effect after the status: a servo whose Baud Rate differs from the bus
  speed hears nothing (as on a real bus);
- unknown instructions → instruction error (2); malformed parameters → data length error (5);
  ACTION without REG_WRITE → instruction error (2); REBOOT answers, then the servo is deaf for
  :attr:`SimulatedServo.boot_time`.

Not simulated: Secondary ID, Protocol 1.0, indirect addresses, Control Table Backup.

Fault hooks: :meth:`~SimulatedChain.silence`, :meth:`~SimulatedChain.corrupt_next`,
:meth:`~SimulatedChain.set_hardware_error`, :meth:`~SimulatedChain.set_model_number`, and
:meth:`~SimulatedChain.set_reply_faults`: status packets that reach the host late (a USB adapter's
latency timer, a loaded host) or never (a lost packet), in order, as through a real adapter.
Recorder: :meth:`~SimulatedChain.trace` (joint ticks) and :meth:`~SimulatedChain.pen_trace`
(planar two-link forward kinematics, see :class:`ArmGeometry`). Physics:
:class:`sim.dynamixel.physics.ArmPhysics` attaches itself as :attr:`~SimulatedChain.plant`; the
clock then steps it up to each instruction packet before executing it (the recorders above stay
the servos' profiles; the physics has its own).
"""

from __future__ import annotations

import math
import random
import threading
import time
from bisect import bisect_right, insort
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from firmware_protocols.dynamixel import (
    BROADCAST_ID,
    HEADER,
    MAX_DEVICE_ID,
    TICKS_PER_REV,
    DecodeError,
    ErrorCode,
    Instruction,
    InstructionPacket,
    PacketDecoder,
    ParameterError,
    StatusPacket,
    crc16,
    encode_status,
    parse_params,
)
from firmware_protocols.dynamixel.control_table import BAUD_RATES
from firmware_protocols.dynamixel.packets import CLEAR_MULTI_TURN, FACTORY_RESET_OPTIONS
from sim.dynamixel.servo import DEFAULT_FIRMWARE_VERSION, DEFAULT_POSITION, SimulatedServo

BITS_PER_BYTE = 10
"""A start bit, 8 data bits and a stop bit."""

_EPS = 1e-6  # in byte times: arrival instants computed two ways must agree
_READ_CLASS = frozenset(
    {
        Instruction.READ,
        Instruction.SYNC_READ,
        Instruction.FAST_SYNC_READ,
        Instruction.BULK_READ,
        Instruction.FAST_BULK_READ,
    }
)


@dataclass(frozen=True)
class ArmGeometry:
    """A planar two-link arm with a pen servo, for :meth:`SimulatedChain.pen_trace`.

    Joint angle convention: ``angle_rad = sign * (ticks - zero_ticks) * 2π / 4096`` per joint;
    the shoulder angle ``a1`` is measured from the +x axis, the elbow angle ``a2`` relative to
    link 1, counter-clockwise positive. The pen tip is at
    ``x = bx + l1·cos(a1) + l2·cos(a1 + a2)``, ``y = by + l1·sin(a1) + l2·sin(a1 + a2)`` (mm).
    The pen is down when the pen servo is closer to ``pen_down_ticks`` than to ``pen_up_ticks``.
    ``zero_ticks`` and ``sign`` are ``(shoulder, elbow)``.
    """

    shoulder_id: int
    elbow_id: int
    pen_id: int
    l1_mm: float
    l2_mm: float
    pen_down_ticks: float
    pen_up_ticks: float
    base_xy: tuple[float, float] = (0.0, 0.0)
    zero_ticks: tuple[float, float] = (2048.0, 2048.0)
    sign: tuple[int, int] = (1, 1)

    def __post_init__(self) -> None:
        ids = (self.shoulder_id, self.elbow_id, self.pen_id)
        if len(set(ids)) != 3 or not all(0 <= i <= MAX_DEVICE_ID for i in ids):
            raise ValueError(f"shoulder_id, elbow_id, pen_id: must be 3 distinct IDs, got {ids}")
        for name in ("l1_mm", "l2_mm"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: must be a finite length > 0, got {value!r}")
        if any(s not in (1, -1) for s in self.sign) or len(self.sign) != 2:
            raise ValueError(f"sign: must be two of +1/-1, got {self.sign!r}")
        if len(self.zero_ticks) != 2 or len(self.base_xy) != 2:
            raise ValueError("zero_ticks, base_xy: must be pairs")
        if self.pen_down_ticks == self.pen_up_ticks:
            raise ValueError("pen_down_ticks, pen_up_ticks: must differ")

    def joint_angles(
        self, shoulder_ticks: np.ndarray, elbow_ticks: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Shoulder and elbow angles in radians (see the class docstring)."""
        scale = 2.0 * math.pi / TICKS_PER_REV
        a1 = self.sign[0] * (np.asarray(shoulder_ticks, float) - self.zero_ticks[0]) * scale
        a2 = self.sign[1] * (np.asarray(elbow_ticks, float) - self.zero_ticks[1]) * scale
        return a1, a2

    def forward(
        self, shoulder_ticks: np.ndarray, elbow_ticks: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pen tip ``(x, y)`` in mm for joint positions in ticks (vectorised)."""
        a1, a2 = self.joint_angles(shoulder_ticks, elbow_ticks)
        x = self.base_xy[0] + self.l1_mm * np.cos(a1) + self.l2_mm * np.cos(a1 + a2)
        y = self.base_xy[1] + self.l1_mm * np.sin(a1) + self.l2_mm * np.sin(a1 + a2)
        return x, y

    def pen_down(self, pen_ticks: np.ndarray) -> np.ndarray:
        """1.0 where the pen servo is nearer pen-down than pen-up, else 0.0."""
        pen = np.asarray(pen_ticks, float)
        return (np.abs(pen - self.pen_down_ticks) < np.abs(pen - self.pen_up_ticks)).astype(float)


class Stepped(Protocol):
    """What the chain's clock steps: a simulation run up to each instruction's time."""

    def advance_to(self, t: float) -> None:
        """Run up to simulated time ``t`` (no effect if it is earlier)."""
        ...


class SimulatedChain:
    """Servos on one DYNAMIXEL bus: ``{id: model}`` with model number or name.

    ``baud`` is the bus speed (each servo's Baud Rate is set to match). ``clock="real"`` follows
    the wall clock (for the pty server); the default ``"simulated"`` moves only with
    :meth:`advance_to` (and the transport's reads). ``firmware_version`` and ``position`` (horn
    start, ticks) apply to every servo. Thread-safe: every public method takes :attr:`lock`.
    """

    def __init__(
        self,
        servos: Mapping[int, int | str],
        baud: int = 1_000_000,
        *,
        clock: str = "simulated",
        firmware_version: int = DEFAULT_FIRMWARE_VERSION,
        position: float = DEFAULT_POSITION,
        reply_to_bad_crc: bool = False,
    ) -> None:
        if clock not in ("simulated", "real"):
            raise ValueError(f"clock: expected 'simulated' or 'real', got {clock!r}")
        if baud not in BAUD_RATES.values():
            raise ValueError(f"baud: must be one of {sorted(BAUD_RATES.values())}, got {baud!r}")
        if not servos:
            raise ValueError("servos: must name at least one servo")
        for id in servos:
            if isinstance(id, bool) or not isinstance(id, int) or not 0 <= id <= MAX_DEVICE_ID:
                raise ValueError(f"servos: ID must be 0..{MAX_DEVICE_ID}, got {id!r}")
        self.clock = clock
        self.baud = baud
        self.reply_to_bad_crc = reply_to_bad_crc
        self.lock = threading.RLock()
        self._t = 0.0
        self._wall0 = time.monotonic()
        self.servos: list[SimulatedServo] = [
            SimulatedServo(
                model, id, baud_rate=baud, firmware_version=firmware_version, position=position
            )
            for id, model in sorted(servos.items())
        ]
        self.geometry: ArmGeometry | None = None
        self.plant: Stepped | None = None
        """A physics simulation the clock steps (:class:`sim.dynamixel.physics.ArmPhysics`), or
        None: the servos track their profiles perfectly."""
        self._decoder = PacketDecoder()
        # host -> bus: bytes written but not yet fed to the decoder, with their timing
        self._in = bytearray()
        self._in_base = 0  # absolute index of self._in[0]
        self._in_total = 0  # absolute count of bytes written
        self._fed = 0  # absolute count fed to the decoder
        self._scan = 0  # absolute index from which to look for headers
        self._ends: list[int] = []  # sorted absolute ends of the frames headers announce
        self._in_chunks: deque[list[float]] = deque()  # [first index, start time, count]
        self._in_free = 0.0  # when the last queued host byte has arrived
        # bus -> host: [start time, bytes, taken]
        self._out: deque[list] = deque()
        self._out_free = 0.0  # when the host side of the line is free (delivery, with latency)
        self._bus_free = 0.0  # when the bus itself is free (the servos' own timing)
        self.reply_latency = 0.0
        self.reply_jitter = 0.0
        self.reply_drop = 0.0
        self._fault_rng = random.Random(0)
        self.replies_dropped = 0
        """Status packets :meth:`set_reply_faults` dropped so far."""
        self.packets_received = 0
        """Instruction packets decoded so far (any ID)."""

    # -- clock ---------------------------------------------------------------------------

    @property
    def byte_time(self) -> float:
        """Seconds one byte takes on the bus."""
        return BITS_PER_BYTE / self.baud

    def now(self) -> float:
        """The simulated time in seconds (with ``clock="real"``: the wall clock, caught up)."""
        with self.lock:
            if self.clock == "real":
                self._advance(time.monotonic() - self._wall0)
            return self._t

    def poll(self) -> None:
        """With ``clock="real"``, run the bus and the servos up to the wall clock."""
        self.now()

    def advance(self, seconds: float) -> None:
        """Move the simulated clock on by ``seconds``."""
        if not (math.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"seconds: must be a finite number >= 0, got {seconds!r}")
        with self.lock:
            self.advance_to(self._t + seconds)

    def advance_to(self, t: float) -> None:
        """Run the bus and the servos to simulated time ``t`` (no effect if it is earlier)."""
        if not math.isfinite(t):
            raise ValueError(f"t: must be finite, got {t!r}")
        if self.clock == "real":
            raise RuntimeError("advance_to: this chain follows the wall clock; use poll()")
        with self.lock:
            self._advance(t)

    def _advance(self, t: float) -> None:
        while self._fed < self._in_total:
            arrived = self._arrived_by(t)
            if arrived <= self._fed:
                break
            done = bisect_right(self._ends, self._fed)
            if done:
                del self._ends[:done]
            end = min(self._ends[0], arrived) if self._ends else arrived
            at = self._arrival(end - 1)
            self._t = max(self._t, at)
            chunk = bytes(self._in[self._fed - self._in_base : end - self._in_base])
            self._fed = end
            self._trim_input()
            if self.plant is not None:
                self.plant.advance_to(at)
            for item in self._decoder.feed(chunk):
                self._handle(item, at)
        self._t = max(self._t, t)
        if self.plant is not None:
            self.plant.advance_to(self._t)

    def next_input_event(self) -> float | None:
        """When the next instruction packet (or the last host byte in flight) will have arrived;
        None when no host byte is on its way."""
        with self.lock:
            if self._fed >= self._in_total:
                return None
            k = bisect_right(self._ends, self._fed)
            end = min(self._ends[k], self._in_total) if k < len(self._ends) else self._in_total
            return self._arrival(end - 1)

    def ready_time(self, count: int) -> float | None:
        """When ``count`` more status bytes will have reached the host, or when the last one
        scheduled will have, if fewer are; None when none is scheduled."""
        with self.lock:
            remaining = count
            last = None
            for start, data, taken in self._out:
                unread = len(data) - taken
                if remaining <= unread:
                    return start + (taken + remaining) * self.byte_time
                remaining -= unread
                last = start + len(data) * self.byte_time
            return last

    def next_event(self) -> float | None:
        """The next time something happens without more host input (a packet completes, a
        status byte reaches the host); None when the bus is quiet."""
        with self.lock:
            events = []
            incoming = self.next_input_event()
            if incoming is not None:
                events.append(incoming)
            for start, data, _ in self._out:
                arrived = math.floor((self._t - start) / self.byte_time + _EPS)
                if arrived < len(data):
                    events.append(start + (max(arrived, 0) + 1) * self.byte_time)
                    break
            return min(events) if events else None

    # -- host side -----------------------------------------------------------------------

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Host bytes onto the bus from now (after any still being sent). Returns ``len(data)``."""
        data = bytes(data)
        with self.lock:
            now = self.now()
            if not data:
                return 0
            start = max(now, self._in_free)
            last = self._in_chunks[-1] if self._in_chunks else None
            if last is not None and start == self._in_free and start > now:
                last[2] += len(data)  # back to back with the bytes still going out
            else:
                self._in_chunks.append([float(self._in_total), start, float(len(data))])
            self._in_free = start + len(data) * self.byte_time
            self._in += data
            self._in_total += len(data)
            self._scan_headers()
            return len(data)

    def read(self, size: int | None = None) -> bytes:
        """Up to ``size`` (default: all) status bytes that have reached the host by now."""
        with self.lock:
            now = self.now()
            out = bytearray()
            while self._out and (size is None or len(out) < size):
                entry = self._out[0]
                start, data, taken = entry
                arrived = min(len(data), math.floor((now - start) / self.byte_time + _EPS))
                if arrived <= taken:
                    break
                take = arrived - taken if size is None else min(arrived - taken, size - len(out))
                out += data[taken : taken + take]
                entry[2] = taken + take
                if entry[2] < len(data):
                    break
                self._out.popleft()
            return bytes(out)

    @property
    def in_waiting(self) -> int:
        """Status bytes that have reached the host and wait to be read."""
        with self.lock:
            now = self.now()
            count = 0
            for start, data, taken in self._out:
                arrived = min(len(data), math.floor((now - start) / self.byte_time + _EPS))
                if arrived <= taken:
                    break
                count += arrived - taken
                if arrived < len(data):
                    break
            return count

    @property
    def out_waiting(self) -> int:
        """Host bytes written but not yet arrived at the servos."""
        with self.lock:
            return self._in_total - self._arrived_by(self._t)

    def discard_input(self) -> None:
        """Drop the status bytes that have arrived (a host's ``reset_input_buffer``)."""
        with self.lock:
            self.read()

    # -- servos and fault hooks ----------------------------------------------------------

    @property
    def ids(self) -> tuple[int, ...]:
        """The servos' present IDs, in ascending order."""
        with self.lock:
            return tuple(sorted(servo.id for servo in self.servos))

    def servo(self, id: int) -> SimulatedServo:
        """The servo whose present ID is ``id`` (KeyError if none)."""
        with self.lock:
            for servo in self.servos:
                if servo.id == id:
                    return servo
        raise KeyError(f"no servo with ID {id} on the chain (IDs: {self.ids})")

    def silence(self, id: int, on: bool = True) -> None:
        """Cut servo ``id``'s reply line: it still hears and executes, but sends nothing."""
        with self.lock:
            self.servo(id).silent = on

    def set_reply_faults(
        self, latency: float = 0.0, jitter: float = 0.0, drop: float = 0.0, seed: int = 0
    ) -> None:
        """Deliver every status packet ``latency`` + U(0, ``jitter``) s late, and lose each one
        with probability ``drop`` (``seed`` seeds the draws; all zero: a clean line again).

        The servos keep their own timing on the bus (a SYNC_READ's replies follow one another
        as usual) and execute every instruction; only the host's view is delayed or missing.
        Packets stay in order, as through a USB adapter: one delayed packet delays those behind
        it. ``drop=1`` is a line on which the host hears nothing at all.
        """
        for name, value in (("latency", latency), ("jitter", jitter)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name}: must be a finite number of seconds >= 0, got {value!r}")
        if not (math.isfinite(drop) and 0 <= drop <= 1):
            raise ValueError(f"drop: must be a probability 0..1, got {drop!r}")
        with self.lock:
            self.reply_latency, self.reply_jitter, self.reply_drop = (
                float(latency),
                float(jitter),
                float(drop),
            )
            self._fault_rng = random.Random(seed)

    def corrupt_next(self, id: int, count: int = 1) -> None:
        """Give the next ``count`` status packets of servo ``id`` a wrong CRC."""
        if count < 0:
            raise ValueError(f"count: must be >= 0, got {count!r}")
        with self.lock:
            self.servo(id).corrupt_pending += count

    def set_hardware_error(self, id: int, bits: int) -> None:
        """Raise Hardware Error Status ``bits`` on servo ``id`` now (e.g. 0x20 overload, 0x04
        overheating): those selected by Shutdown (63, default 0x34) turn the torque off; every
        status then carries the alert bit 0x80 until a REBOOT."""
        with self.lock:
            self.servo(id).set_hardware_error(bits, self.now())

    def set_model_number(self, id: int, number: int) -> None:
        """Make servo ``id`` report model ``number`` (PING and address 0): a wrong servo."""
        with self.lock:
            self.servo(id).set_model_number(number)

    def set_position(self, id: int, ticks: float) -> None:
        """Turn servo ``id``'s horn by hand to ``ticks`` (torque off)."""
        with self.lock:
            self.servo(id).set_position(ticks, self.now())

    # -- recorder ------------------------------------------------------------------------

    def sample_times(self, dt: float = 0.001) -> np.ndarray:
        """``0, dt, 2·dt, …`` up to now, plus now itself."""
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt: must be a finite number > 0, got {dt!r}")
        now = self.now()
        times = np.arange(math.floor(now / dt + 1e-9) + 1) * dt
        if times[-1] < now - 1e-12:
            times = np.append(times, now)
        return times

    def trace(self, id: int, dt: float = 0.001) -> np.ndarray:
        """``(N, 2)``: ``t, position`` of servo ``id`` every ``dt`` s from 0 to now.

        Positions are the exact simulated horn position in ticks (Present Position reads its
        rounded value).
        """
        with self.lock:
            times = self.sample_times(dt)
            return np.column_stack([times, self.servo(id).trajectory.sample(times)])

    def set_geometry(self, geometry: ArmGeometry) -> None:
        """Describe the arm the servos form, for :meth:`pen_trace`."""
        if not isinstance(geometry, ArmGeometry):
            raise TypeError(f"geometry: expected ArmGeometry, got {geometry!r}")
        with self.lock:
            for id in (geometry.shoulder_id, geometry.elbow_id, geometry.pen_id):
                self.servo(id)
            self.geometry = geometry

    def pen_trace(self, dt: float = 0.001) -> np.ndarray:
        """``(N, 4)``: ``t, x, y, pen`` every ``dt`` s from 0 to now (mm; pen 1 = down)."""
        with self.lock:
            g = self.geometry
            if g is None:
                raise RuntimeError("pen_trace: call set_geometry() first")
            times = self.sample_times(dt)
            shoulder = self.servo(g.shoulder_id).trajectory.sample(times)
            elbow = self.servo(g.elbow_id).trajectory.sample(times)
            pen = self.servo(g.pen_id).trajectory.sample(times)
            x, y = g.forward(shoulder, elbow)
            return np.column_stack([times, x, y, g.pen_down(pen)])

    # -- input timing --------------------------------------------------------------------

    def _arrived_by(self, t: float) -> int:
        """Absolute count of host bytes that have arrived at the servos by time ``t``."""
        count = self._fed
        for first, start, n in self._in_chunks:
            k = math.floor((t - start) / self.byte_time + _EPS)
            if k <= 0:
                break
            count = max(count, int(first) + int(min(k, n)))
            if k < n:
                break
        return count

    def _arrival(self, index: int) -> float:
        """When host byte ``index`` (absolute) has arrived."""
        for first, start, n in self._in_chunks:
            if first <= index < first + n:
                return start + (index - first + 1) * self.byte_time
        raise AssertionError(f"byte {index} is not queued")  # pragma: no cover

    def _trim_input(self) -> None:
        while self._in_chunks and self._in_chunks[0][0] + self._in_chunks[0][2] <= self._fed:
            self._in_chunks.popleft()
        keep_from = min(self._fed, self._scan)
        if keep_from > self._in_base:
            del self._in[: keep_from - self._in_base]
            self._in_base = keep_from

    def _scan_headers(self) -> None:
        """Note where the frames that headers in the written bytes announce will end, so a packet
        is executed when its own last byte arrives, not when a later one does."""
        buf, base = self._in, self._in_base
        pos = self._scan
        while True:
            hit = buf.find(HEADER, pos - base)
            if hit < 0:
                self._scan = max(pos, base + len(buf) - (len(HEADER) - 1))
                return
            header = base + hit
            if hit + 7 > len(buf):
                self._scan = header  # LEN not written yet: look again later
                return
            length = buf[hit + 5] | (buf[hit + 6] << 8)
            end = header + 7 + length
            if end > self._fed:
                insort(self._ends, end)
            pos = header + 1

    # -- instructions --------------------------------------------------------------------

    def _handle(self, item: InstructionPacket | StatusPacket | DecodeError, t: float) -> None:
        if isinstance(item, DecodeError):
            if item.kind == DecodeError.BAD_CRC and self.reply_to_bad_crc and len(item.data) > 4:
                target = self._listener(item.data[4], t)
                if target is not None and target.status_return_level >= 2:
                    self._reply([(target, ErrorCode.CRC, b"")], t)
            return
        if isinstance(item, StatusPacket):
            return  # another device's reply: the servos ignore it
        self.packets_received += 1
        self._execute(item, t)

    def _listeners(self, t: float) -> list[SimulatedServo]:
        return sorted(
            (s for s in self.servos if s.listening(t, self.baud)), key=lambda servo: servo.id
        )

    def _listener(self, id: int, t: float) -> SimulatedServo | None:
        for servo in self._listeners(t):
            if servo.id == id:
                return servo
        return None

    def _execute(self, packet: InstructionPacket, t: float) -> None:
        inst, pid = packet.instruction, packet.id
        broadcast = pid == BROADCAST_ID
        listeners = self._listeners(t)
        targets = listeners if broadcast else [s for s in listeners if s.id == pid]
        if not targets:
            return
        unicast = None if broadcast else targets[0]
        try:
            params = parse_params(packet)
        except ParameterError:
            if unicast is not None:
                known = inst in Instruction.__members__.values()
                error = ErrorCode.DATA_LENGTH if known else ErrorCode.INSTRUCTION
                self._answer(unicast, inst, error, b"", t)
            return
        if inst == Instruction.PING:
            self._reply([(s, 0, s.ping_reply()) for s in targets], t)
        elif inst == Instruction.READ:
            if unicast is not None:
                error, data = unicast.read(params.address, params.length, t)  # type: ignore[union-attr]
                self._answer(unicast, inst, error, data, t)
        elif inst == Instruction.WRITE:
            for servo in targets:
                error = servo.write(params.address, params.data, t)  # type: ignore[union-attr]
            if unicast is not None:
                self._answer(unicast, inst, error, b"", t)
        elif inst == Instruction.REG_WRITE:
            for servo in targets:
                error = servo.reg_write(params.address, params.data)  # type: ignore[union-attr]
            if unicast is not None:
                self._answer(unicast, inst, error, b"", t)
        elif inst == Instruction.ACTION:
            for servo in targets:
                error = servo.action(t)
            if unicast is not None:
                self._answer(unicast, inst, error, b"", t)
        elif inst == Instruction.REBOOT:
            if unicast is not None:
                self._answer(unicast, inst, 0, b"", t)
            for servo in targets:
                servo.reboot(t)
        elif inst == Instruction.FACTORY_RESET:
            self._factory_reset(targets, unicast, int(params), t)  # type: ignore[arg-type]
        elif inst == Instruction.CLEAR:
            if unicast is not None:
                ok = params == CLEAR_MULTI_TURN
                error = unicast.clear_multi_turn(t) if ok else ErrorCode.DATA_RANGE
                self._answer(unicast, inst, error, b"", t)
        elif inst in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ) and broadcast:
            reads = [(id, params.address, params.length) for id in params.ids]  # type: ignore[union-attr]
            self._bulk_read(reads, t, fast=inst == Instruction.FAST_SYNC_READ)
        elif inst in (Instruction.BULK_READ, Instruction.FAST_BULK_READ) and broadcast:
            reads = [(e.id, e.address, e.length) for e in params]  # type: ignore[union-attr]
            self._bulk_read(reads, t, fast=inst == Instruction.FAST_BULK_READ)
        elif inst == Instruction.SYNC_WRITE and broadcast:
            for id, data in params.data.items():  # type: ignore[union-attr]
                servo = self._find(targets, id)
                if servo is not None:
                    servo.write(params.address, data, t)  # type: ignore[union-attr]
        elif inst == Instruction.BULK_WRITE and broadcast:
            for entry in params:  # type: ignore[union-attr]
                servo = self._find(targets, entry.id)
                if servo is not None:
                    servo.write(entry.address, entry.data, t)
        elif unicast is not None:
            self._answer(unicast, inst, ErrorCode.INSTRUCTION, b"", t)

    @staticmethod
    def _find(servos: Iterable[SimulatedServo], id: int) -> SimulatedServo | None:
        return next((s for s in servos if s.id == id), None)

    def _factory_reset(
        self,
        targets: list[SimulatedServo],
        unicast: SimulatedServo | None,
        option: int,
        t: float,
    ) -> None:
        if option not in FACTORY_RESET_OPTIONS:
            if unicast is not None:
                self._answer(unicast, Instruction.FACTORY_RESET, ErrorCode.DATA_RANGE, b"", t)
            return
        if unicast is None and option == 0xFF:
            return  # broadcast "reset all" is refused by firmware ≥ 42
        if unicast is not None:
            self._answer(unicast, Instruction.FACTORY_RESET, 0, b"", t)
        for servo in targets:
            servo.factory_reset(option, t)

    def _answer(self, servo: SimulatedServo, inst: int, error: int, data: bytes, t: float) -> None:
        level = servo.status_return_level
        needed = 0 if inst == Instruction.PING else 1 if inst in _READ_CLASS else 2
        if level >= needed:
            self._reply([(servo, error, data)], t)

    def _bulk_read(self, reads: list[tuple[int, int, int]], t: float, *, fast: bool) -> None:
        answers = []
        for id, address, length in reads:
            servo = self._listener(id, t)
            if servo is None or servo.status_return_level < 1:
                continue
            error, data = servo.read(address, length, t)
            if fast and error:
                data = bytes(length)
            answers.append((servo, error, data))
        if fast:
            self._fast_reply(answers, [length for _, _, length in reads], t)
        else:
            self._reply(answers, t)

    def _reply(self, answers: list[tuple[SimulatedServo, int, bytes]], t: float) -> None:
        """Schedule status packets, one servo after the other, from instruction end ``t``."""
        base = t
        for servo, error, data in answers:
            if servo.silent:
                continue
            frame = bytearray(encode_status(StatusPacket(servo.id, error | servo.alert, data)))
            if servo.corrupt_pending:
                servo.corrupt_pending -= 1
                frame[-1] ^= 0xFF
            base = self._schedule(bytes(frame), base + servo.return_delay)

    def _fast_reply(
        self, answers: list[tuple[SimulatedServo, int, bytes]], lengths: list[int], t: float
    ) -> None:
        """The combined FAST_SYNC_READ / FAST_BULK_READ status (e-Manual layout, unstuffed):
        each device adds ERR, ID, data and the CRC of the packet so far; the last device's CRC is
        the packet's. LEN counts every device asked, so a missing one leaves a short packet."""
        answers = [a for a in answers if not a[0].silent]
        if not answers:
            return
        length = 1 + sum(4 + n for n in lengths)  # INST + (ERR ID data CRC) per device
        frame = bytearray(HEADER + bytes([BROADCAST_ID]) + length.to_bytes(2, "little"))
        frame.append(Instruction.STATUS)
        corrupt = False
        for servo, error, data in answers:
            frame += bytes([error | servo.alert, servo.id]) + data
            frame += crc16(frame).to_bytes(2, "little")
            if servo.corrupt_pending:
                servo.corrupt_pending -= 1
                corrupt = True
        if corrupt:
            frame[-1] ^= 0xFF
        self._schedule(bytes(frame), t + answers[0][0].return_delay)

    def _schedule(self, frame: bytes, ready: float) -> float:
        """Put ``frame`` on the bus from ``ready`` (or when it is free) and on its way to the host
        (delayed or lost by :meth:`set_reply_faults`); returns its end on the bus."""
        on_bus = max(ready, self._bus_free)
        self._bus_free = on_bus + len(frame) * self.byte_time
        delay = 0.0
        if self.reply_drop or self.reply_latency or self.reply_jitter:
            rng = self._fault_rng
            if self.reply_drop and rng.random() < self.reply_drop:
                self.replies_dropped += 1
                return self._bus_free
            delay = self.reply_latency + self.reply_jitter * rng.random()
        start = max(on_bus + delay, self._out_free)
        self._out.append([start, frame, 0])
        self._out_free = start + len(frame) * self.byte_time
        return self._bus_free


__all__ = ["BITS_PER_BYTE", "ArmGeometry", "SimulatedChain", "Stepped"]
