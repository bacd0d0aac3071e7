"""What every simulated pyserial port shares: a line with no modem signals to drive.

The ``grblsim://`` and ``dxlsim://`` handlers subclass :class:`SimulatedSerialBase` and provide
the data path (``open``, ``read``, ``write``...); the modem lines here read as a cable that is
plugged in, and the controls that would drive them do nothing.
"""

from __future__ import annotations

from serial.serialutil import SerialBase

__all__ = ["SimulatedSerialBase"]


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
