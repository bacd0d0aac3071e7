"""Clocks for device loops: the wall clock, or a simulated port's own clock.

A simulated port (``grblsim://``, ``dxlsim://``) runs on simulated time that moves only when the
host reads or waits, so long jobs run faster than real time. Such a port carries a ``clock``
attribute with ``now()`` and ``sleep_until(t)``; :func:`port_clock` returns it, or a
:class:`MonotonicClock` for real ports. Host code takes every deadline from that clock and has
no ``if simulated:`` branches.
"""

from __future__ import annotations

import time
from typing import Protocol

__all__ = ["Clock", "MonotonicClock", "port_clock"]


class Clock(Protocol):
    """Seconds on some monotonic time base, and a way to wait for a moment on it."""

    def now(self) -> float: ...

    def sleep_until(self, t: float) -> None: ...


class MonotonicClock:
    """The wall clock (``time.monotonic``); ``sleep_until`` sleeps, then spins the last 0.5 ms."""

    SPIN = 0.0005

    def now(self) -> float:
        return time.monotonic()

    def sleep_until(self, t: float) -> None:
        remaining = t - time.monotonic()
        if remaining > self.SPIN:
            time.sleep(remaining - self.SPIN)
        while time.monotonic() < t:
            pass


def port_clock(port: object) -> Clock:
    """The clock a port runs on: its own ``clock`` attribute when it has one, else the wall's."""
    clock = getattr(port, "clock", None)
    if clock is not None and callable(getattr(clock, "now", None)):
        return clock
    return MonotonicClock()
