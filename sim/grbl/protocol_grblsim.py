"""pyserial's handler for ``grblsim://`` URLs: a port to a simulated Grbl in simulated time.

pyserial's ``serial_for_url`` imports ``<package>.protocol_<scheme>`` for each package of
``serial.protocol_handler_packages`` and instantiates its ``Serial`` class;
:mod:`sim.grbl.transport` adds ``sim.grbl`` to that list. See :mod:`sim.grbl.transport` for the
URL options and how the simulated clock moves.
"""

from __future__ import annotations

import math

from serial.serialutil import PortNotOpenError, SerialException

from sim.grbl.device import SimulatedGrbl
from sim.grbl.transport import POLL_QUANTUM, Link, device_from_url
from sim.serial_port import SimulatedSerialBase


class Serial(SimulatedSerialBase):
    """A ``serial.SerialBase`` whose far end is a :class:`SimulatedGrbl` (``self.device``)."""

    def __init__(self, *args, **kwargs) -> None:
        self.device: SimulatedGrbl | None = None
        self._link: Link | None = None
        self._speed: float | None = None
        self._dropped = False
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        if self.is_open:
            raise SerialException("Port is already open.")
        device, self._speed = device_from_url(self.portstr)
        self.device = device
        self._dropped = device.closed
        device.on_close.append(self._on_drop)
        self._link = Link(device, self._speed or self._baudrate)
        self.is_open = True

    @property
    def clock(self) -> _LinkClock:
        """The simulated clock (``now()``, ``sleep_until(t)``): hosts take deadlines from it."""
        return _LinkClock(self._live_link())

    def _on_drop(self) -> None:
        self._dropped = True

    def close(self) -> None:
        if self.device is not None and self._on_drop in self.device.on_close:
            self.device.on_close.remove(self._on_drop)
        self.is_open = False
        self._link = None

    def _reconfigure_port(self) -> None:
        if self._link is not None and self._speed is None:
            self._link.baud = float(self._baudrate)

    def _live_link(self) -> Link:
        if not self.is_open or self._link is None:
            raise PortNotOpenError()
        if self._dropped:
            raise SerialException("grblsim: connection dropped by the device")
        return self._link

    @property
    def in_waiting(self) -> int:
        link = self._live_link()
        count = link.available()
        if not count:
            link.advance_to(link.now + POLL_QUANTUM)
            count = link.available()
        return count

    def read(self, size: int = 1) -> bytes:
        link = self._live_link()
        out = bytearray(link.receive(size))
        timeout = self._timeout
        deadline = math.inf if timeout is None else link.now + timeout
        while len(out) < size and link.now < deadline:
            if timeout is None and link.quiet():
                break  # nothing can ever arrive: do not hang the test
            link.advance_to(min(deadline, link.now + POLL_QUANTUM))
            if self._dropped:
                raise SerialException("grblsim: connection dropped by the device")
            out += link.receive(size - len(out))
        return bytes(out)

    def write(self, data: bytes) -> int:
        link = self._live_link()
        data = bytes(memoryview(data))
        link.send(data)
        return len(data)

    def flush(self) -> None:
        """Wait (in simulated time) until every written byte has reached the device."""
        link = self._live_link()
        while link.sending:
            link.advance_to(link.now + POLL_QUANTUM)

    def reset_input_buffer(self) -> None:
        self._live_link().clear_to_host()

    def reset_output_buffer(self) -> None:
        self._live_link().clear_to_device()

    @property
    def out_waiting(self) -> int:
        return self._live_link().sending

    def send_break(self, duration: float = 0.25) -> None:
        self._live_link()


__all__ = ["Serial"]


class _LinkClock:
    """The simulated time of one open link; waiting moves the line and the device on. It keeps
    telling the time after the port closes or the device drops the connection."""

    def __init__(self, link: Link) -> None:
        self._link = link

    def now(self) -> float:
        return self._link.now

    def sleep_until(self, t: float) -> None:
        if t > self._link.now:
            self._link.advance_to(t)
