"""Checks of a serial port named by the user, before anything is planned to be sent to it.

:func:`check_port` looks at the name only (no byte is sent, the port is not opened, so an
Arduino-based controller is not reset by it): a pyserial URL needs a scheme pyserial or tagbot's
simulators know; a device path must exist, be a character device that can be a serial line (not a
directory, a regular file or ``/dev/null``) and be readable and writable by this user. Anything
wrong is a :class:`~tagbot.errors.PortError` (a usage error: exit status 2) in one line.
"""

from __future__ import annotations

import os
import stat
import sys

from tagbot.errors import PortError

__all__ = ["check_port"]

SIMULATED_SCHEMES = {
    "grblsim": "sim.grbl.transport",
    "dxlsim": "sim.dynamixel",
    "ebbsim": "sim.ebb.transport",
}
"""URL schemes of tagbot's in-process simulators, and the module that registers each."""

_PYSERIAL_SCHEMES = ("alt", "cp2110", "hwgrep", "loop", "rfc2217", "socket", "spy")

_MEMORY_DEVICES = 1
"""Linux major number of /dev/null, /dev/zero, /dev/random...: character devices, not lines."""


def check_port(port: str) -> str:
    """``port`` if it can be a serial line; else :class:`PortError` saying why."""
    if not port or port != port.strip():
        raise PortError(f"--port: {port!r} is not a port name")
    if "://" in port:
        scheme = port.split("://", 1)[0]
        if scheme in SIMULATED_SCHEMES:
            __import__(SIMULATED_SCHEMES[scheme])
        elif scheme not in _PYSERIAL_SCHEMES:
            known = ", ".join(sorted([*SIMULATED_SCHEMES, *_PYSERIAL_SCHEMES]))
            raise PortError(f"--port {port}: unknown URL scheme {scheme!r} (known: {known})")
        return port
    if sys.platform == "win32":  # COM3 and friends: only opening tells
        return port
    try:
        info = os.stat(port)
    except FileNotFoundError:
        raise PortError(f"--port {port}: no such device (is the machine plugged in?)") from None
    except OSError as e:
        raise PortError(f"--port {port}: {e.strerror or e}") from None
    if stat.S_ISDIR(info.st_mode):
        raise PortError(f"--port {port}: is a directory, not a serial port")
    if not stat.S_ISCHR(info.st_mode) or os.major(info.st_rdev) == _MEMORY_DEVICES:
        raise PortError(f"--port {port}: not a serial port (a serial line is a character device)")
    if not os.access(port, os.R_OK | os.W_OK):
        raise PortError(
            f"--port {port}: permission denied (on Linux, add yourself to the group that owns "
            "it, often 'dialout', then log in again)"
        )
    return port
