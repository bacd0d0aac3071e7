"""Transports for :class:`~sim.grbl.device.SimulatedGrbl`: a pyserial URL handler and a pty server.

**In-process, simulated time** (fast tests): importing this module (or calling :func:`register`)
adds ``sim.grbl`` to ``serial.protocol_handler_packages``, so that::

    port = serial.serial_for_url("grblsim://?speed=115200&alarm=0&$100=80", timeout=1)

returns a :class:`~sim.grbl.protocol_grblsim.Serial` (a ``serial.SerialBase``) talking to a new
simulated Grbl (``port.device``). ``grblsim://<name>`` opens a device given to
:func:`attach_device` instead, so a test can set it up (fault hooks) before the host opens it.
Query parameters: ``speed`` (line speed in baud; default the port's ``baudrate``), ``alarm``
(1: start in the Alarm state), ``pen`` (``spindle`` or ``z``), ``ln`` (1: a build with
``USE_LINE_NUMBERS``, reporting ``Ln:``) and ``$N`` (a setting).

The simulated clock moves only with the host: bytes written are delivered one by one, 10 bits
each at the line speed; reads advance the clock until enough bytes have arrived or the read
timeout has passed in *simulated* seconds (``in_waiting`` advances it by 1 ms when nothing is
waiting, so a polling loop makes progress). Nothing waits on the wall clock.

Host-side timing fault hooks on the port (:class:`~sim.grbl.protocol_grblsim.Serial`):
``port.freeze_host(at, seconds)`` (a descheduled host: the first call at or after simulated time
``at`` first lets the device run alone for ``seconds``) and ``port.write_latency`` (seconds every
written chunk takes to start reaching the device, default 0).

**Pseudo-terminal, real time** (any program): :func:`serve_pty` opens ``os.openpty()``, puts it in
raw mode and runs a thread that pumps bytes between the master side and a device driven by the
wall clock. ``serial.Serial(path)`` or any G-code sender opens the slave ``path``;
``serve_pty(device, write_latency=s)`` holds the host's bytes ``s`` seconds before the device
gets them.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from urllib.parse import parse_qsl, urlsplit

import serial

from firmware_protocols.grbl import is_realtime_byte
from sim import pty
from sim.grbl.device import SimulatedGrbl
from sim.serial_port import Attached

BITS_PER_BYTE = 10
"""A start bit, 8 data bits and a stop bit."""

POLL_QUANTUM = 0.001
"""Simulated seconds a read moves the clock by per step, and an empty ``in_waiting`` poll."""

_attached: Attached[SimulatedGrbl] = Attached("sim.grbl", "grblsim")


def register() -> None:
    """Make ``serial.serial_for_url`` know the ``grblsim://`` scheme (idempotent)."""
    _attached.register()


def attach_device(device: SimulatedGrbl, name: str) -> str:
    """Make ``device`` the one ``grblsim://<name>`` opens (once); returns that URL."""
    return _attached.attach(device, name)


def take_attached(name: str) -> SimulatedGrbl | None:
    return _attached.take(name)


def device_from_url(url: str) -> tuple[SimulatedGrbl, float | None]:
    """The device a ``grblsim://`` URL names or describes, and its ``speed`` (None: not given)."""
    parts = urlsplit(url)
    if parts.scheme.lower() != "grblsim":
        raise serial.SerialException(f"expected a grblsim:// URL, got {url!r}")
    speed: float | None = None
    settings: dict[int, float] = {}
    options: dict[str, object] = {}
    try:
        for key, value in parse_qsl(parts.query, keep_blank_values=True, strict_parsing=False):
            if key == "speed":
                speed = float(value)
                if not (math.isfinite(speed) and speed > 0):
                    raise ValueError(f"speed: must be > 0, got {value!r}")
            elif key == "alarm":
                options["start_in_alarm"] = value not in ("0", "false", "")
            elif key == "pen":
                options["pen"] = value
            elif key == "ln":
                options["line_numbers"] = value not in ("0", "false", "")
            elif key.startswith("$") and key[1:].isdigit():
                settings[int(key[1:])] = float(value)
            else:
                raise ValueError(f"unknown option {key!r}")
        if parts.netloc:
            device = take_attached(parts.netloc)
            if device is None:
                raise ValueError(f"no device attached as {parts.netloc!r}")
            if settings or options:
                raise ValueError("options and settings only apply to a new device")
        else:
            device = SimulatedGrbl(settings, **options)  # type: ignore[arg-type]
    except ValueError as exc:
        raise serial.SerialException(f"{url}: {exc}") from exc
    return device, speed


class Link:
    """A serial line in simulated time between a host and a :class:`SimulatedGrbl`.

    ``send`` queues host bytes; they reach the device one at a time, ``10 / baud`` seconds apart.
    What the device prints reaches the host as whole chunks, after their bytes' transfer time.
    """

    def __init__(self, device: SimulatedGrbl, baud: float) -> None:
        self.device = device
        self.baud = float(baud)
        self._to_device: deque[tuple[float, int]] = deque()
        self._to_device_free = device.now
        self._to_host: deque[tuple[float, bytes]] = deque()
        self._to_host_free = device.now
        self._collect()

    @property
    def now(self) -> float:
        return self.device.now

    @property
    def byte_time(self) -> float:
        return BITS_PER_BYTE / self.baud

    def send(self, data: bytes, latency: float = 0.0) -> None:
        """Queue ``data``; its first byte starts ``latency`` seconds from now at the earliest."""
        t = max(self.now + latency, self._to_device_free)
        step = self.byte_time
        queue = self._to_device
        for byte in data:
            t += step
            queue.append((t, byte))
        self._to_device_free = t

    @property
    def sending(self) -> int:
        return len(self._to_device)

    def advance_to(self, t: float) -> None:
        """Run the line and the device to simulated time ``t``."""
        device = self.device
        queue = self._to_device
        while queue and queue[0][0] <= t:
            arrival = queue[0][0]
            device.advance_to(arrival)
            self._collect()
            # Bytes arriving at the same instant, or before the device's clock, go together.
            chunk = bytearray()
            while queue and queue[0][0] <= max(arrival, device.now):
                chunk.append(queue.popleft()[1])
            quiet = device.quiet_until()
            if quiet is not None and not any(map(is_realtime_byte, chunk)):
                # The main loop is stalled on a full planner: until its next event, ordinary
                # bytes only fill the receive ring, so those arriving by then go in at once (as
                # one at a time would, at the last one's arrival).
                last = None
                while queue and queue[0][0] <= t and queue[0][0] < quiet:
                    if is_realtime_byte(queue[0][1]):
                        break
                    last, byte = queue.popleft()
                    chunk.append(byte)
                if last is not None and last > device.now:
                    device.advance_to(last)
            device.write(bytes(chunk))
            self._collect()
        device.advance_to(t)
        self._collect()

    def _collect(self) -> None:
        for t, chunk in self.device.read_timed():
            start = max(t, self._to_host_free)
            self._to_host_free = start + len(chunk) * self.byte_time
            self._to_host.append((self._to_host_free, chunk))

    def idle_until(self) -> float:
        """Before this time nothing happens on the line or in the device but the clock moving:
        no byte reaches either end, Grbl's main loop stays stalled on a full planner
        (:meth:`SimulatedGrbl.quiet_until`). ``-inf`` when that cannot be said."""
        device = self.device
        quiet = device.quiet_until()
        if quiet is None or device.out_waiting:
            return -math.inf
        if self._to_device:
            quiet = min(quiet, self._to_device[0][0])
        if self._to_host:
            quiet = min(quiet, self._to_host[0][0])
        return quiet

    def available(self) -> int:
        now = self.now
        return sum(len(c) for t, c in self._to_host if t <= now)

    def receive(self, size: int) -> bytes:
        """Up to ``size`` bytes that have arrived by now."""
        out = bytearray()
        now = self.now
        while self._to_host and self._to_host[0][0] <= now and len(out) < size:
            t, chunk = self._to_host.popleft()
            take = size - len(out)
            out += chunk[:take]
            if take < len(chunk):
                self._to_host.appendleft((t, chunk[take:]))
        return bytes(out)

    def quiet(self) -> bool:
        """Nothing more can arrive unless the host sends something."""
        device = self.device
        return not (self._to_device or self._to_host or device.out_waiting or device.busy) or bool(
            device.silent or device.closed
        )

    def clear_to_host(self) -> None:
        self._collect()
        self._to_host.clear()

    def clear_to_device(self) -> None:
        self._to_device.clear()
        self._to_device_free = self.now


class PtyServer(pty.PtyServer):
    """The pump behind :func:`serve_pty`; ``stop()`` ends it and closes the pseudo-terminal."""

    name = "grblsim-pty"

    def __init__(
        self, device: SimulatedGrbl, poll_interval: float = 0.001, write_latency: float = 0.0
    ) -> None:
        if device.clock != "real":
            raise ValueError("device: serve_pty needs a device with clock='real'")
        if not (math.isfinite(write_latency) and write_latency >= 0):
            raise ValueError(f"write_latency: must be >= 0 s, got {write_latency!r}")
        self.device = device
        self.poll_interval = poll_interval
        self.write_latency = float(write_latency)
        self._delayed: deque[tuple[float, bytes]] = deque()  # (wall time due, bytes)
        super().__init__()

    def wait_time(self) -> float:
        if self._delayed:
            due = self._delayed[0][0] - time.monotonic()
            return min(self.poll_interval, max(due, 0.0))
        return self.poll_interval

    def exchange(self, data: bytes) -> bytes | None:
        if self.write_latency > 0:
            now = time.monotonic()
            if data:
                self._delayed.append((now + self.write_latency, data))
            data = b""
            while self._delayed and self._delayed[0][0] <= now:
                data += self._delayed.popleft()[1]
        with self.device.lock:
            if self.device.closed:
                return None
            self.device.poll()
            if data:
                self.device.write(data)
            return self.device.read()


def serve_pty(device: SimulatedGrbl, write_latency: float = 0.0) -> tuple[str, Callable[[], None]]:
    """Serve ``device`` (``clock="real"``) on a new pseudo-terminal: ``(slave path, stop)``.
    ``write_latency``: wall-clock seconds the host's bytes are held before the device gets them
    (a USB adapter's latency timer), a fault hook."""
    server = PtyServer(device, write_latency=write_latency)
    return server.path, server.stop


register()

__all__ = [
    "BITS_PER_BYTE",
    "POLL_QUANTUM",
    "Link",
    "PtyServer",
    "attach_device",
    "device_from_url",
    "register",
    "serve_pty",
]
