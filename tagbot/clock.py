"""Clocks for device loops: the wall clock, or a simulated port's own clock.

A simulated port (``grblsim://``, ``dxlsim://``) runs on simulated time that moves only when the
host reads or waits, so long jobs run faster than real time. Such a port carries a ``clock``
attribute with ``now()`` and ``sleep_until(t)``; :func:`port_clock` returns it, or a
:class:`MonotonicClock` for real ports. Host code takes every deadline from that clock and has
no ``if simulated:`` branches.
"""

from __future__ import annotations

import gc
import logging
import os
import time
from typing import Protocol

__all__ = ["FIFO_PRIORITY", "Clock", "MonotonicClock", "RealTime", "port_clock", "simulated_clock"]

log = logging.getLogger(__name__)

FIFO_PRIORITY = 10
"""``SCHED_FIFO`` priority of a device loop when permitted (1..99): below the kernel's threaded
interrupt handlers (50), which the serial port itself needs."""


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


class RealTime:
    """What a device loop (the arm's ticks, the plotter's stream) changes while it runs on the
    wall clock, and puts back (:meth:`end`):

    - ``gc.freeze()``, so that everything allocated before the loop (the program's rows, the
      profile, the caller's objects) leaves the collector's view and a full collection during
      the loop looks at its few new objects only, not for milliseconds at the whole heap;
    - real-time scheduling for the loop's thread (``SCHED_FIFO``, priority
      :data:`FIFO_PRIORITY`) where the system permits it (root or ``CAP_SYS_NICE``, an
      ``rtprio`` limit), so that other programs on a busy host cannot hold it off the CPU;
      quietly not where it does not (:attr:`fifo` says which), nor on a simulated clock.
    """

    def __init__(self, clock: Clock) -> None:
        gc.freeze()
        self.fifo = False
        self._before: tuple[int, os.sched_param] | None = None
        if isinstance(clock, MonotonicClock) and hasattr(os, "sched_setscheduler"):
            try:
                before = (os.sched_getscheduler(0), os.sched_getparam(0))
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(FIFO_PRIORITY))
            except OSError:  # not permitted: the ordinary scheduler
                log.debug("real-time scheduling not permitted: running without it")
            else:
                self._before, self.fifo = before, True

    def end(self) -> None:
        gc.unfreeze()
        if self._before is not None:
            try:
                os.sched_setscheduler(0, *self._before)
            except OSError as e:  # pragma: no cover - lowering is always permitted
                log.debug("restoring the scheduler: %s", e)
