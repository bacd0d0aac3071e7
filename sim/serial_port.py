"""What every simulated pyserial port shares: a line with no modem signals to drive.

The ``grblsim://``, ``dxlsim://`` and ``ebbsim://`` handlers subclass :class:`SimulatedSerialBase`
and provide the data path (``open``, ``read``, ``write``...); the modem lines here read as a cable
that is plugged in, and the controls that would drive them do nothing. :class:`Attached` holds the
devices each scheme opens by name.
"""

from __future__ import annotations

import threading
from typing import Generic, TypeVar

import serial
from serial.serialutil import SerialBase

__all__ = ["Attached", "SimulatedSerialBase"]

D = TypeVar("D")


class Attached(Generic[D]):
    """The devices a URL scheme's handler opens by name (``grblsim://<name>``...), set up by a
    test or a back end before the host opens them, and the handler package's registration."""

    def __init__(self, package: str, scheme: str) -> None:
        self.package, self.scheme = package, scheme
        self._devices: dict[str, D] = {}
        self._lock = threading.Lock()

    def register(self) -> None:
        """Make ``serial.serial_for_url`` know the scheme (idempotent)."""
        if self.package not in serial.protocol_handler_packages:
            serial.protocol_handler_packages.append(self.package)

    def attach(self, device: D, name: str) -> str:
        """Attach ``device`` as ``name``; returns its URL."""
        if not isinstance(name, str) or not name.isidentifier():
            raise ValueError(f"name: must be an identifier, got {name!r}")
        with self._lock:
            self._devices[name] = device
        return f"{self.scheme}://{name}"

    def get(self, name: str) -> D | None:
        with self._lock:
            return self._devices.get(name)

    def take(self, name: str) -> D | None:
        """Detach the device attached as ``name`` (returns it, or None)."""
        with self._lock:
            return self._devices.pop(name, None)

    def names(self) -> set[str]:
        with self._lock:
            return set(self._devices)


class SimulatedSerialBase(SerialBase):
    """Modem lines and no-op controls for a simulated port."""

    def cancel_read(self) -> None:
        pass

    def cancel_write(self) -> None:
        pass

    def _update_break_state(self) -> None:
        pass

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        return True

    @property
    def dsr(self) -> bool:
        return True

    @property
    def ri(self) -> bool:
        return False

    @property
    def cd(self) -> bool:
        return True
