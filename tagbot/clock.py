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

__all__ = ["Clock", "MonotonicClock", "port_clock", "simulated_clock"]


class Clock(Protocol):
    """Seconds on some monotonic time base, and a way to wait for a moment on it."""

    def now(self) -> float: ...

    def sleep_until(self, t: float) -> None: ...


class MonotonicClock:
    """The wall clock (``time.perf_counter``); ``sleep_until`` sleeps most of the way, then
    yields (``time.sleep(0)``) until the deadline, so other threads (a pty server) still run."""

    SPIN = 0.0003
    """Seconds before a deadline when sleeping turns into yielding."""

    def now(self) -> float:
        return time.perf_counter()

    def sleep_until(self, t: float) -> None:
        while True:
            remaining = t - time.perf_counter()
            if remaining <= 0:
                return
            time.sleep(remaining - self.SPIN if remaining > 2 * self.SPIN else 0)


def simulated_clock(port: object) -> Clock | None:
    """The port's own clock (``now()`` and ``sleep_until(t)``) if it has one, else None."""
    clock = getattr(port, "clock", None)
    if callable(getattr(clock, "now", None)) and callable(getattr(clock, "sleep_until", None)):
        return clock  # type: ignore[return-value]
    return None


def port_clock(port: object) -> Clock:
    """The clock a port runs on: its own when it has one, else the wall clock."""
    return simulated_clock(port) or MonotonicClock()
