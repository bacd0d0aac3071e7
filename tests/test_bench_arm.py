"""benchmarks/bench_arm.py's own housekeeping: a simulator server it started never outlives it."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

import bench_arm


def _server(ignore_interrupt: bool) -> subprocess.Popen:
    """A stand-in server that says it is ready, then waits: stopped by SIGINT as a Python
    program is, or ignoring it (what a server started from a background job of a
    non-interactive shell inherits)."""
    handler = "SIG_IGN" if ignore_interrupt else "default_int_handler"
    code = (
        "import signal, time\n"
        f"signal.signal(signal.SIGINT, signal.{handler})\n"
        "print('ready', flush=True)\n"
        "while True: time.sleep(0.05)\n"
    )
    server = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE)
    assert server.stdout is not None
    assert server.stdout.readline().strip() == b"ready"
    return server


@pytest.mark.parametrize("ignore_interrupt", [False, True])
def test_a_server_is_stopped_even_when_it_ignores_ctrl_c(monkeypatch, ignore_interrupt) -> None:
    monkeypatch.setattr(bench_arm, "STOP_WAIT", 0.5)
    server = _server(ignore_interrupt)
    try:
        bench_arm.stop_server(server)
        # Ctrl-C ends it when it listens (an uncaught KeyboardInterrupt exits by SIGINT);
        # SIGTERM when it does not
        expected = -signal.SIGTERM if ignore_interrupt else -signal.SIGINT
        assert server.poll() == expected
    finally:
        if server.poll() is None:
            server.kill()
            server.wait()
        assert server.stdout is not None
        server.stdout.close()
