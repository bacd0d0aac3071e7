"""Shared test fixtures."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Iterator

import pytest

# Compiled kernels check their arguments in the whole suite (see tagbot.kernel_check): a kernel
# reached with a non-finite or absurd value fails the test that reached it.
os.environ.setdefault("TAGBOT_CHECK_KERNELS", "1")
import tagbot.kernel_check

tagbot.kernel_check.install()

THREAD_GRACE_SECONDS = 2.0
"""How long a test's threads get to finish after the test before it fails for leaking them."""


@pytest.fixture(autouse=True, scope="session")
def interruptible_children() -> Iterator[None]:
    """Programs the tests start take Ctrl-C (SIGINT) as from a terminal, even when the suite
    itself runs with SIGINT ignored (a background job of a shell script): an ignored signal is
    inherited through exec, and Python then installs no KeyboardInterrupt handler."""
    ignored = signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    if ignored:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    if ignored:
        signal.signal(signal.SIGINT, signal.SIG_IGN)


@pytest.fixture(autouse=True)
def no_leaked_threads() -> Iterator[None]:
    """Fail a test that leaves threads running (e.g. a serial reader or simulator not stopped)."""
    before = set(threading.enumerate())
    yield
    deadline = time.monotonic() + THREAD_GRACE_SECONDS
    for thread in threading.enumerate():
        if thread not in before and thread is not threading.current_thread():
            thread.join(timeout=max(0.0, deadline - time.monotonic()))
    leaked = [t for t in threading.enumerate() if t not in before and t.is_alive()]
    if leaked:
        names = ", ".join(sorted(f"{t.name} (daemon={t.daemon})" for t in leaked))
        pytest.fail(f"test left {len(leaked)} thread(s) running: {names}", pytrace=False)


def _open_ports() -> set[str]:
    """File descriptors open on serial-like devices: pseudo-terminals and ttys."""
    folder = "/proc/self/fd"
    if not os.path.isdir(folder):  # pragma: no cover - not Linux
        return set()
    found = set()
    for fd in os.listdir(folder):
        try:
            target = os.readlink(os.path.join(folder, fd))
        except OSError:
            continue
        if target.startswith(("/dev/pts/", "/dev/ptmx", "/dev/tty")):
            found.add(f"{fd} -> {target}")
    return found


@pytest.fixture(autouse=True)
def no_leaked_ports() -> Iterator[None]:
    """Fail a test that leaves a serial port or pseudo-terminal open."""
    before = _open_ports()
    yield
    deadline = time.monotonic() + THREAD_GRACE_SECONDS
    leaked = _open_ports() - before
    while leaked and time.monotonic() < deadline:
        time.sleep(0.05)
        leaked = _open_ports() - before
    if leaked:
        pytest.fail(
            f"test left {len(leaked)} port(s) open: {', '.join(sorted(leaked))}", pytrace=False
        )
