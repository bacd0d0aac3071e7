"""pyserial's handler for ``ebbsim://`` URLs: a port to a simulated EBB in simulated time.

pyserial's ``serial_for_url`` imports ``<package>.protocol_<scheme>``; :mod:`sim.ebb.transport`
adds ``sim.ebb`` to ``serial.protocol_handler_packages``. The port is the ``grblsim://`` one
(reads and writes move the simulated clock, ``freeze_host``, ``write_latency``) on a
:class:`~sim.ebb.transport.Link` to a :class:`~sim.ebb.device.SimulatedEBB`.
"""

from __future__ import annotations

from serial.serialutil import SerialException

from sim.ebb.transport import Link, device_from_url
from sim.grbl import protocol_grblsim

__all__ = ["Serial"]


class Serial(protocol_grblsim.Serial):
    """A ``serial.SerialBase`` whose far end is a simulated EBB (``self.device``)."""

    dropped_message = "ebbsim: the board dropped off the USB"

    def open(self) -> None:
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        if self.is_open:
            raise SerialException("Port is already open.")
        device = device_from_url(self.portstr)
        self.device = device  # type: ignore[assignment]
        self._dropped = False
        device.on_close.append(self._on_drop)
        self._link = Link(device)
        self.is_open = True

    def _reconfigure_port(self) -> None:
        """The baud rate of a USB CDC port changes nothing."""
