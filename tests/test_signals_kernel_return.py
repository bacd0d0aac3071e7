"""A stop signal handled as a compiled kernel returns: one line and the signal's status.

numba runs Python code (``numba.core.serialize._numba_unpickle``) to box a kernel's result; a
signal pending then has its handler raise there, and numba reports "SystemError:
CPUDispatcher(...) returned a result with an exception set" (the outside tester's traceback,
Ctrl-C during ``tagbot fit`` of 3000 random points, whose many short kernels make it likely).
The kernel here sends the signal itself, so the handler runs exactly there, every time.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent(
    """
    import ctypes, sys
    import numpy as np
    from numba import njit
    from tagbot import cli

    send = ctypes.CDLL(None)["raise"]
    send.argtypes, send.restype = [ctypes.c_int], ctypes.c_int

    @njit(nogil=True)
    def signal_then_return(signum):
        send(signum)
        return np.zeros(2), 1.0  # boxing a tuple: numba's Python callback runs the handler

    @cli.cli.command("spin")
    def spin() -> None:
        signal_then_return(int(SIGNUM))

    SIGNUM = sys.argv[1]
    sys.exit(cli.main(["spin"]))
    """
)


@pytest.mark.parametrize(
    ("signum", "line"),
    [
        (signal.SIGINT, "tagbot: error: interrupted (Ctrl-C)"),
        (signal.SIGTERM, "tagbot: error: terminated (SIGTERM)"),
    ],
)
def test_signal_as_a_kernel_returns_is_one_line(signum, line):
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(int(signum))],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.stderr.strip().splitlines() == [line]
    assert done.returncode == 128 + int(signum)
