"""benchmarks/bench_arm.py's own housekeeping: a simulator server it started never outlives it."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
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


def test_the_speed_error_floor_is_the_median_runs_error_and_names_what_it_rules_out() -> None:
    # a run's error rms is its planned speed rms × 10^(−SNR/20): 40 mm/s at 32 dB is 1.0 mm/s
    rows = [
        {"run_speeds": [(0, 50.0, 40.0, 20 * math.log10(40.0), 60.0)]},  # 1 mm/s
        {
            "run_speeds": [
                (0, 9.0, 10.0, 20 * math.log10(10.0 / 2.0), 60.0),
                (1, 80.0, 60.0, 40.0, 60.0),
            ]
        },
    ]
    assert bench_arm.speed_error_floor(rows) == pytest.approx(1.0)  # of 1, 2 and 0.6 mm/s
    assert bench_arm.speed_rms(np.array([0.0, 1.0, 2.0]), np.array([[0, 0], [3, 4], [6, 8.0]])) == (
        pytest.approx(5.0)
    )
    assert bench_arm.path_length(np.array([[0, 0], [3, 4], [6, 8.0]])) == pytest.approx(10.0)


def test_a_plan_followed_exactly_scores_high_unless_it_starts_and_ends_moving() -> None:
    t = np.arange(0.0, 1.0 + 1e-9, 0.01)
    smooth = 50.0 * (t - np.sin(2 * np.pi * t) / (2 * np.pi))  # from rest to rest
    steady = 10.0 * t[:21]  # 10 mm/s from its first sample to its last, 0.2 s
    runs = [
        (t, np.column_stack([smooth, np.zeros_like(t)])),
        (t[:21] + 2.0, np.column_stack([steady, np.full(21, 20.0)])),
    ]
    smooth_db, steady_db = bench_arm.plan_ceilings(runs)
    assert smooth_db > 40.0
    assert steady_db < 25.0
