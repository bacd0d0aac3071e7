"""pyserial's handler for ``dxlsim://`` URLs: a port onto a simulated DYNAMIXEL chain.

pyserial's ``serial_for_url`` imports ``<package>.protocol_<scheme>`` for each package of
``serial.protocol_handler_packages`` and instantiates its ``Serial`` class;
:mod:`sim.dynamixel.transport` adds ``sim.dynamixel`` to that list. See that module for the URL
options and the clock contract (``port.clock.now()``, ``port.clock.sleep_until(t)``).
"""

from __future__ import annotations

import math

from serial.serialutil import PortNotOpenError, SerialException, to_bytes

from sim.dynamixel.chain import SimulatedChain
from sim.dynamixel.transport import POLL_QUANTUM, BusClock, chain_from_url, wait_step
from sim.serial_port import SimulatedSerialBase


class Serial(SimulatedSerialBase):
    """A ``serial.SerialBase`` whose far end is a :class:`SimulatedChain` (``self.chain``)."""

    def __init__(self, *args, **kwargs) -> None:
        self.chain: SimulatedChain | None = None
        self.clock: BusClock | None = None
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        if self.is_open:
            raise SerialException("Port is already open.")
        self.chain = chain_from_url(self.portstr)
        self.clock = BusClock(self.chain)
        self.is_open = True

    def close(self) -> None:
        self.is_open = False

    def _reconfigure_port(self) -> None:
        pass  # the bus runs at the chain's baud, as on a pty

    def _live(self) -> SimulatedChain:
        if not self.is_open or self.chain is None:
            raise PortNotOpenError()
        return self.chain

    @property
    def in_waiting(self) -> int:
        chain = self._live()
        count = chain.in_waiting
        if not count:  # a host polling this must see time move, but never past its deadlines
            wait_step(chain, 1, chain.now() + POLL_QUANTUM)
            count = chain.in_waiting
        return count

    def read(self, size: int = 1) -> bytes:
        chain = self._live()
        out = bytearray(chain.read(size))
        if len(out) >= size:
            return bytes(out)
        timeout = self._timeout
        if timeout == 0:
            if not out:
                wait_step(chain, size)
                out += chain.read(size)
            return bytes(out)
        deadline = math.inf if timeout is None else chain.now() + timeout
        while len(out) < size and chain.now() < deadline:
            if timeout is None and chain.next_event() is None:
                break  # nothing can arrive: do not hang
            wait_step(chain, size - len(out), deadline)
            out += chain.read(size - len(out))
        return bytes(out)

    def write(self, data: bytes) -> int:
        chain = self._live()
        return chain.write(to_bytes(data))  # bytes, or a list of ints as dynamixel-sdk sends

    def flush(self) -> None:
        """Run the clock until every written byte has reached the servos."""
        chain = self._live()
        while chain.out_waiting:
            event = chain.next_input_event()
            chain.advance_to(event if event is not None else chain.now())

    def reset_input_buffer(self) -> None:
        self._live().discard_input()

    def reset_output_buffer(self) -> None:
        self._live()  # bytes already handed over keep going, as with a UART's FIFO

    @property
    def out_waiting(self) -> int:
        return self._live().out_waiting

    def send_break(self, duration: float = 0.25) -> None:
        self._live()


__all__ = ["Serial"]
