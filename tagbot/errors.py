"""One exception tree for tagbot.

Every error tagbot raises on purpose derives from :class:`TagbotError`, so callers can catch the
whole family at once. Bad arguments and bad input files are also :class:`ValueError` (the Python
convention), and their messages start by naming the offending field, e.g.
``plans[0].strokes[2].sigma: must be > 0, got -1.0``.
"""

from __future__ import annotations


class TagbotError(Exception):
    """Base class of every error tagbot raises on purpose."""


class PlanError(TagbotError, ValueError):
    """A plan, tag or model parameter is invalid; the message names the field."""


class PlanFileError(PlanError):
    """A plan file cannot be read: not JSON, wrong format or version, or invalid content."""


class InputError(TagbotError, ValueError):
    """An input file (trace, motion, profile) is unreadable or invalid."""


class OutputError(TagbotError, ValueError):
    """An output path cannot be written (missing folder, not writable, an existing folder)."""


class ProfileError(TagbotError, ValueError):
    """A machine profile is unreadable or invalid; the message names the file and the field."""


class PlacementError(TagbotError, ValueError):
    """A tag cannot be placed in the machine's workspace (bed, reach, joint limits, speed);
    the message names the overflow. Raised before anything is sent."""


class ReachError(PlacementError):
    """A serial arm cannot put its pen on a point of a path (:mod:`tagbot.arm.serial`).

    ``index`` is the point's index in the path (the caller maps it to plan, stroke and time),
    ``reason`` one of ``reach``, ``joint limit``, ``tilt``, ``self-collision``, ``jump``, and
    ``detail`` the message without its ``point N:`` prefix."""

    def __init__(self, detail: str, index: int, reason: str, where: str | None = None) -> None:
        super().__init__(f"{where or f'point {index}'}: {detail}")
        self.detail = detail
        self.index = index
        self.reason = reason


class PortError(TagbotError, ValueError):
    """The port named cannot be a serial line to the machine (missing, not a device, no access,
    unknown URL scheme). A usage error, found before anything is written or sent."""


class DeviceError(TagbotError):
    """A machine or its connection failed; ``where`` names the line or tick, when known."""

    def __init__(self, message: str, where: str | None = None) -> None:
        super().__init__(f"{where}: {message}" if where else message)
        self.where = where


class DeviceFault(DeviceError):
    """The device reported an error: Grbl ``error:N`` or ``ALARM:N``, a DYNAMIXEL status error
    or hardware-error alert. The run was stopped safely; nothing was sent after it."""


class DeviceTimeout(DeviceError, TimeoutError):
    """The device did not answer before the deadline."""


class ConnectionLost(DeviceError, ConnectionError):
    """The port could not be opened, or closed or failed during the run."""


class Interrupted(DeviceError):
    """The user stopped a running machine (Ctrl-C, SIGTERM); it was stopped safely. ``where``
    names the last line or tick the machine executed."""


class SignalInterrupt(KeyboardInterrupt):
    """A stop signal (Ctrl-C, SIGTERM, SIGHUP) received by the command line
    (:mod:`tagbot.signals`). A KeyboardInterrupt, not a :class:`TagbotError`: everything that
    stops a machine safely on Ctrl-C does so on it; ``str()`` names the signal (``SIGTERM``)."""

    def __init__(self, signum: int, name: str) -> None:
        super().__init__(name)
        self.signum = signum
