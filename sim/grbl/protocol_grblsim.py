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

    dropped_message = "grblsim: connection dropped by the device"
    """What the port raises once the device has dropped the connection."""

    def __init__(self, *args, **kwargs) -> None:
        self.device: SimulatedGrbl | None = None
        self._link: Link | None = None
        self._speed: float | None = None
        self._dropped = False
        self._host_freezes: list[tuple[float, float]] = []
        self.write_latency: float = 0.0
        """Seconds (simulated) every chunk written takes to start reaching the device, as a
        USB adapter's latency: a fault hook for host-side timing. 0 by default."""
        super().__init__(*args, **kwargs)

    def freeze_host(self, at: float, seconds: float) -> None:
        """A fault hook: the host is descheduled. The first host call (``write``, ``read``,
        ``in_waiting``, ``flush``...) at or after simulated time ``at`` first lets the line and
        the device run alone for ``seconds`` of simulated time: the host neither sends nor
        reads meanwhile (what it wrote before is still delivered)."""
        at, seconds = float(at), float(seconds)
        if not (math.isfinite(at) and math.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"freeze_host: need finite at and seconds >= 0, got {at}, {seconds}")
        self._host_freezes.append((at, seconds))
        self._host_freezes.sort()

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
            raise SerialException(self.dropped_message)
        return self._link

    def _host_call(self) -> Link:
        """The link, once any host freeze due by now has passed (see :meth:`freeze_host`)."""
        link = self._live_link()
        while self._host_freezes and self._host_freezes[0][0] <= link.now:
            _, seconds = self._host_freezes.pop(0)
            link.advance_to(link.now + seconds)
            link = self._live_link()
        return link

    @property
    def in_waiting(self) -> int:
        link = self._host_call()
        count = link.available()
        if not count:
            link.advance_to(link.now + POLL_QUANTUM)
            count = link.available()
        return count

    def read(self, size: int = 1) -> bytes:
        link = self._host_call()
        out = bytearray(link.receive(size))
        timeout = self._timeout
        deadline = math.inf if timeout is None else link.now + timeout
        while len(out) < size and link.now < deadline:
            if timeout is None and link.quiet():
                break  # nothing can ever arrive: do not hang the test
            step = min(deadline, link.now + POLL_QUANTUM)
            idle = link.idle_until() if timeout is not None else -math.inf
            if step < idle:
                # The polls before ``idle`` find nothing and change nothing: take the clock to
                # the last of them at once (the same sums of quanta), then poll on from there.
                while step < deadline:
                    following = min(deadline, step + POLL_QUANTUM)
                    if following >= idle:
                        break
                    step = following
            link.advance_to(step)
            if self._dropped:
                raise SerialException(self.dropped_message)
            out += link.receive(size - len(out))
        return bytes(out)

    def write(self, data: bytes) -> int:
        link = self._host_call()
        data = bytes(memoryview(data))
        link.send(data, latency=self.write_latency)
        return len(data)

    def flush(self) -> None:
        """Wait (in simulated time) until every written byte has reached the device."""
        link = self._host_call()
        while link.sending:
            link.advance_to(link.now + POLL_QUANTUM)

    def reset_input_buffer(self) -> None:
        self._host_call().clear_to_host()

    def reset_output_buffer(self) -> None:
        self._host_call().clear_to_device()

    @property
    def out_waiting(self) -> int:
        return self._host_call().sending

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
