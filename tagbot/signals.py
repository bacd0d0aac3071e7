"""Ctrl-C, SIGTERM and SIGHUP for the command line: named, and effective within a second anywhere.

Python runs a signal handler only between bytecodes of the main thread, so a long compiled loop
(a numba kernel) would hold off Ctrl-C and SIGTERM until it returns. :func:`stop_signals`
installs handlers that raise :class:`~tagbot.errors.SignalInterrupt` (a KeyboardInterrupt that
names its signal, so every path that stops a machine safely on Ctrl-C does so on SIGTERM too),
and a watchdog thread woken through :func:`signal.set_wakeup_fd`. When the main thread has not
run the handler :data:`GRACE_SECONDS` after a signal (it is inside compiled code, which releases
the GIL: the kernels are ``nogil``), the watchdog prints the command's one line and ends the
process at once with ``128 + signal number``. Nothing is half written then: outputs are renamed
into place whole (:func:`tagbot.io.output.write_atomic`) and printed only when complete.

A machine run is never ended that way: inside :func:`machine_run` the watchdog waits, and the
run's Python loop handles the signal and stops the machine safely.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Iterator
from types import FrameType

from tagbot.errors import SignalInterrupt

__all__ = [
    "GRACE_SECONDS",
    "STOP_SIGNALS",
    "exit_status",
    "label",
    "last_signal",
    "machine_run",
    "message",
    "stop_signals",
]

GRACE_SECONDS = 0.5
"""How long the main thread has to run a signal's handler before the watchdog ends the process."""

STOP_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)
"""The signals that stop a command (SIGHUP: its terminal closed)."""

_LABELS = {"SIGINT": "Ctrl-C"}

_received: list[int] = []  # the signals the handler ran for, in order
_machine_runs = 0  # machine runs in progress: the watchdog never ends the process during one


def label(signum: int) -> str:
    """How the user knows the signal: ``Ctrl-C`` for SIGINT, else its name (``SIGTERM``)."""
    name = signal.Signals(signum).name
    return _LABELS.get(name, name)


def signal_of(error: BaseException) -> int:
    """The signal behind a KeyboardInterrupt (SIGINT for a plain one, as Python raises it)."""
    return error.signum if isinstance(error, SignalInterrupt) else int(signal.SIGINT)


def message(signum: int) -> str:
    """The command's last line after a stop signal: ``interrupted (Ctrl-C)``,
    ``terminated (SIGTERM)``, ``hung up (SIGHUP)``."""
    verb = {"SIGINT": "interrupted", "SIGHUP": "hung up"}.get(signal.Signals(signum).name)
    return f"{verb or 'terminated'} ({label(signum)})"


def exit_status(signum: int) -> int:
    """The shell's status for a command ended by ``signum``: 128 + its number (130, 143, 129)."""
    return 128 + int(signum)


def last_signal() -> int | None:
    """The last stop signal the command's handler ran for, if any."""
    return _received[-1] if _received else None


@contextlib.contextmanager
def machine_run() -> Iterator[None]:
    """While a machine runs: a stop signal is left to the run's own safe stop, never a hard exit."""
    global _machine_runs
    _machine_runs += 1
    try:
        yield
    finally:
        _machine_runs -= 1


@contextlib.contextmanager
def stop_signals(prog: str) -> Iterator[None]:
    """Handle :data:`STOP_SIGNALS` in the main thread while the block runs, as the module says;
    ``prog`` starts the watchdog's line. Signals set to be ignored (``nohup``) stay ignored.
    Elsewhere than in the main thread nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    watchdog = _Watchdog(prog)
    previous = {}
    for signum in STOP_SIGNALS:
        if signal.getsignal(signum) is not signal.SIG_IGN:
            previous[signum] = signal.signal(signum, watchdog.handler)
    del _received[:]
    watchdog.start()
    try:
        yield
    finally:
        watchdog.stop()
        for signum, handler in previous.items():
            signal.signal(signum, handler)


class _Watchdog:
    """The thread that ends the process when the main thread cannot run a signal's handler."""

    def __init__(self, prog: str) -> None:
        self.prog = prog
        self._handled = threading.Semaphore(0)
        self._read, self._write = os.pipe()
        os.set_blocking(self._write, False)
        self._previous_fd = -1
        self._thread = threading.Thread(target=self._watch, name="tagbot-signals", daemon=True)

    def handler(self, signum: int, frame: FrameType | None) -> None:
        """The main thread's handler: raise the signal as a KeyboardInterrupt that names it."""
        _received.append(signum)
        self._handled.release()
        raise SignalInterrupt(signum, label(signum))

    def start(self) -> None:
        self._previous_fd = signal.set_wakeup_fd(self._write, warn_on_full_buffer=False)
        self._thread.start()

    def stop(self) -> None:
        signal.set_wakeup_fd(self._previous_fd)
        with contextlib.suppress(OSError):
            os.write(self._write, b"\0")  # no signal has number 0: the thread's cue to end
        self._thread.join()
        os.close(self._read)
        os.close(self._write)

    def _watch(self) -> None:
        while True:
            try:
                woken = os.read(self._read, 64)
            except InterruptedError:  # pragma: no cover - PEP 475 retries; belt and braces
                continue
            for signum in woken:
                if signum == 0:
                    return
                if signal.getsignal(signum) != self.handler:
                    continue  # another handler (the studio's server) owns the signal now
                if self._handled.acquire(timeout=GRACE_SECONDS) or _machine_runs:
                    continue
                self._hard_exit(signum)

    def _hard_exit(self, signum: int) -> None:
        """Print the line on a fresh line of the terminal and end the process now."""
        fresh = "\r\x1b[K" if _isatty(2) else ""  # over a progress bar's line
        line = f"{fresh}{self.prog}: error: {message(signum)}\n"
        with contextlib.suppress(OSError):  # a hung-up terminal
            os.write(2, line.encode())
        os._exit(exit_status(signum))


def _isatty(fd: int) -> bool:
    try:
        return os.isatty(fd)
    except OSError:
        return False
