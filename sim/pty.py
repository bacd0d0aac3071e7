"""A raw pseudo-terminal pumped through a simulated device by one thread.

:class:`PtyServer` opens ``os.openpty()`` in raw mode and runs a thread that moves bytes between
the master side and a device; any program (pyserial, a G-code sender, the dynamixel-sdk) opens the
slave ``path`` like a USB adapter. A device's server fills in two hooks: :meth:`wait_time` (how
long to wait for the host's bytes) and :meth:`exchange` (feed them to the device, return what it
printed, or None when the device hung up). ``stop()`` ends the thread and closes the terminal.

A device has a processor of its own, which a busy host cannot take from it: the thread runs with
real-time scheduling (``SCHED_FIFO``, :data:`DEVICE_PRIORITY`) where the system permits it (root,
``CAP_SYS_NICE``, an ``rtprio`` limit), so that other programs do not hold the device back for
milliseconds (a servo's Realtime Tick or a status report stamped late); quietly not elsewhere
(:attr:`PtyServer.realtime` says which).
"""

from __future__ import annotations

import os
import select
import threading
import tty

__all__ = ["DEVICE_PRIORITY", "PtyServer"]

DEVICE_PRIORITY = 20
"""``SCHED_FIFO`` priority of the pump thread (above a host loop's, as a device's own CPU)."""


class PtyServer:
    """The pump thread and its pseudo-terminal; subclasses provide the device hooks."""

    name = "sim-pty"

    def __init__(self) -> None:
        self._master: int | None
        self._slave: int | None
        self._master, self._slave = os.openpty()
        tty.setraw(self._master)
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        self._unsent = b""
        self._stop = threading.Event()
        self.error: BaseException | None = None
        self.realtime = threading.Event()
        """Set once the pump runs with real-time scheduling."""
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()

    def wait_time(self) -> float:
        """Seconds to wait for bytes from the host before exchanging again."""
        raise NotImplementedError

    def exchange(self, data: bytes) -> bytes | None:
        """Give the host's ``data`` to the device; what it printed, or None if it hung up."""
        raise NotImplementedError

    def _run(self) -> None:
        master = self._master
        assert master is not None
        hung_up = False
        try:  # this thread only (Linux: 0 is the calling thread)
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(DEVICE_PRIORITY))
        except (OSError, AttributeError):  # not permitted, or no such call: ordinary scheduling
            pass
        else:
            self.realtime.set()
        try:
            while not self._stop.is_set():
                wait = self.wait_time()
                if self._unsent:
                    wait = min(wait, 0.001)
                ready, _, _ = select.select([master], [], [], wait)
                data = b""
                if ready:
                    try:
                        data = os.read(master, 4096)
                    except OSError:
                        data = b""  # no client has the slave open: nothing to read
                out = self.exchange(data)
                if out is None:
                    hung_up = True
                    break
                self._unsent += out
                if self._unsent:
                    try:
                        written = os.write(master, self._unsent)
                    except BlockingIOError:
                        written = 0  # the client is not reading: keep the bytes
                    self._unsent = self._unsent[written:]
        except BaseException as exc:  # pragma: no cover - reported through stop()
            self.error = exc
        finally:
            if hung_up:
                self._close_fds()  # the cable is pulled: the host sees the port go away

    def _close_fds(self) -> None:
        for name in ("_master", "_slave"):
            fd = getattr(self, name)
            if fd is not None:
                setattr(self, name, None)
                os.close(fd)

    def stop(self) -> None:
        """Stop the thread, wait for it, close the pseudo-terminal (idempotent)."""
        self._stop.set()
        self._thread.join()
        self._close_fds()
        if self.error is not None:
            error, self.error = self.error, None
            raise RuntimeError(f"the {self.name} server thread failed") from error
