"""Transports for :class:`~sim.ebb.device.SimulatedEBB`: a pyserial URL handler and a pty server.

**In-process, simulated time**: importing this module (or calling :func:`register`) lets
``serial.serial_for_url("ebbsim://", timeout=1)`` return a
:class:`~sim.ebb.protocol_ebbsim.Serial` talking to a new simulated EBB (``port.device``);
``ebbsim://<name>`` opens a device given to :func:`attach_device` (set up with fault hooks
first). Query parameters: ``version`` (the firmware, e.g. ``2.8.1`` for refusal tests) and
``fifo`` (1: none; a ``CU,4`` the board has already run).

The line is the Grbl simulator's :class:`~sim.grbl.transport.Link` at USB full speed: bytes
move at :data:`USB_BYTES_PER_S` (12 Mbit/s, 10 bits a byte: the bulk rate of a full-speed CDC
port), the clock moves only with the host's reads and writes, and the board spends its command
processing time on each line (:attr:`SimulatedEBB.command_time`). Host fault hooks on the port:
``port.freeze_host(at, seconds)`` and ``port.write_latency`` (as on ``grblsim://``); board
fault hooks on the device: ``stall_usb``, ``reset_board`` (the port then raises
``SerialException``: open it again after :func:`attach_device`), ``press_button``.

**Pseudo-terminal, real time**: :func:`serve_pty` serves a ``clock="real"`` device on a new
pseudo-terminal (the Grbl simulator's pump, :class:`sim.grbl.transport.PtyServer`).
"""

from __future__ import annotations

from collections.abc import Callable
from urllib.parse import parse_qsl, urlsplit

import serial

from sim.ebb.device import SimulatedEBB
from sim.grbl import transport as grbl_transport
from sim.serial_port import Attached

__all__ = [
    "USB_BYTES_PER_S",
    "Link",
    "PtyServer",
    "attach_device",
    "device_from_url",
    "register",
    "serve_pty",
]

USB_BYTES_PER_S = 1_200_000
"""USB full speed: bulk transfers carry at most 19 packets of 64 bytes a 1 ms frame (1.216 MB/s)."""

_attached: Attached[SimulatedEBB] = Attached("sim.ebb", "ebbsim")


def register() -> None:
    """Make ``serial.serial_for_url`` know the ``ebbsim://`` scheme (idempotent)."""
    _attached.register()


def attach_device(device: SimulatedEBB, name: str) -> str:
    """Make ``device`` the one ``ebbsim://<name>`` opens (once); returns that URL."""
    return _attached.attach(device, name)


def device_from_url(url: str) -> SimulatedEBB:
    """The device an ``ebbsim://`` URL names or describes."""
    parts = urlsplit(url)
    if parts.scheme.lower() != "ebbsim":
        raise serial.SerialException(f"expected an ebbsim:// URL, got {url!r}")
    options = dict(parse_qsl(parts.query, keep_blank_values=True))
    try:
        unknown = sorted(set(options) - {"version", "fifo"})
        if unknown:
            raise ValueError(f"unknown option {unknown[0]!r}")
        if parts.netloc:
            device = _attached.take(parts.netloc)
            if device is None:
                raise ValueError(f"no device attached as {parts.netloc!r}")
            if options:
                raise ValueError("options only apply to a new device")
            return device
        device = SimulatedEBB(version=options.get("version", "3.0.3"))
        if "fifo" in options:
            depth = int(options["fifo"])
            if not 1 <= depth <= 32:
                raise ValueError(f"fifo: must be 1 to 32, got {depth}")
            device.fifo_depth = depth
        return device
    except ValueError as exc:
        raise serial.SerialException(f"{url}: {exc}") from exc


class Link(grbl_transport.Link):
    """The host-board line in simulated time, at USB full speed."""

    def __init__(self, device: SimulatedEBB) -> None:
        super().__init__(device, USB_BYTES_PER_S * grbl_transport.BITS_PER_BYTE)  # type: ignore[arg-type]


class PtyServer(grbl_transport.PtyServer):
    """The pump behind :func:`serve_pty`."""

    name = "ebbsim-pty"


def serve_pty(device: SimulatedEBB, write_latency: float = 0.0) -> tuple[str, Callable[[], None]]:
    """Serve ``device`` (``clock="real"``) on a new pseudo-terminal: ``(slave path, stop)``."""
    server = PtyServer(device, write_latency=write_latency)  # type: ignore[arg-type]
    return server.path, server.stop


register()
