"""Stop signals: named, one line, the shell's status, and within a second even inside a long
compiled loop (tagbot.signals)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import click
import pytest

from tagbot import cli
from tagbot.errors import SignalInterrupt
from tagbot.signals import exit_status, label, message

LATENCY_BOUND_SECONDS = 5.0
"""Signal to exit, allowed on a loaded host (the watchdog's grace is 0.5 s; bench_scaling.py
records the real figure)."""

# A command that spends minutes in one call of a compiled kernel (2·n² multiply-adds).
SPIN = textwrap.dedent(
    """
    import contextlib
    import sys
    import numpy as np
    from tagbot import cli
    from tagbot.gesture.contour_kernels import smooth
    from tagbot.signals import machine_run

    @cli.cli.command("spin")
    def spin() -> None:
        smooth(np.zeros((4, 2)), np.ones(2), 0)  # compiled (or loaded) before "ready"
        n = {n}
        guard = machine_run() if {machine} else contextlib.nullcontext()
        try:
            with guard:
                print("ready", flush=True)
                smooth(np.random.rand(n, 2), np.ones(n) / n, 0)
                print("done", flush=True)
        finally:
            print("unwound", flush=True)

    sys.exit(cli.main(["spin"]))
    """
)


def _default_hangup() -> None:
    signal.signal(signal.SIGHUP, signal.SIG_DFL)


def _spin(tmp_path, n: int, machine: bool = False) -> subprocess.Popen[str]:
    script = tmp_path / "spin.py"
    script.write_text(SPIN.format(n=n, machine=machine))
    process = subprocess.Popen(
        [sys.executable, str(script)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # As from a terminal: a suite started under nohup would pass SIGHUP on ignored, and an
        # ignored SIGHUP rightly stays ignored (tagbot takes over no ignored signal).
        preexec_fn=_default_hangup,
    )
    assert process.stdout is not None
    assert process.stdout.readline() == "ready\n", process.communicate(timeout=60)
    return process


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_a_signal_ends_a_long_compiled_loop_at_once_with_one_line(tmp_path, signum) -> None:
    process = _spin(tmp_path, 200_000)
    time.sleep(0.3)  # into the kernel
    sent = time.monotonic()
    process.send_signal(signum)
    out, err = process.communicate(timeout=600)
    latency = time.monotonic() - sent
    assert err == f"tagbot: error: {message(signum)}\n"
    assert process.returncode == 128 + signum
    assert out == ""  # neither finished nor unwound: ended from the watchdog
    assert latency < LATENCY_BOUND_SECONDS, latency


def test_a_machine_run_is_left_to_its_own_safe_stop(tmp_path) -> None:
    process = _spin(tmp_path, 100_000, machine=True)
    time.sleep(0.3)
    process.send_signal(signal.SIGTERM)
    out, err = process.communicate(timeout=600)
    assert out == "unwound\n"  # the main thread ran its handler (and cleanup) after the kernel
    assert err == "tagbot: error: terminated (SIGTERM)\n" and process.returncode == 143


@pytest.fixture
def command():
    """Register a throwaway command on the CLI group for one test."""
    added: list[str] = []

    def add(function):
        cli.cli.command(function.__name__)(function)
        added.append(function.__name__)
        return function

    yield add
    for name in added:
        cli.cli.commands.pop(name)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_in_python_code_is_named_with_the_shells_status(capsys, command, signum):
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}

    @command
    def kill_self() -> None:
        signal.raise_signal(signum)
        click.echo("not reached")

    assert cli.main(["kill_self"]) == 128 + signum
    out, err = capsys.readouterr()
    assert out == "" and err == f"tagbot: error: {message(signum)}\n"
    assert {s: signal.getsignal(s) for s in handlers} == handlers  # restored afterwards


def test_the_raised_interrupt_names_the_signal(command) -> None:
    seen: list[BaseException] = []

    @command
    def catch() -> None:
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(10)
        except KeyboardInterrupt as e:  # as every machine's safe stop catches it
            seen.append(e)

    assert cli.main(["catch"]) == 0
    (error,) = seen
    assert isinstance(error, SignalInterrupt) and error.signum == signal.SIGTERM
    assert str(error) == "SIGTERM"


def test_names_and_statuses() -> None:
    assert [label(s) for s in (signal.SIGINT, signal.SIGTERM)] == ["Ctrl-C", "SIGTERM"]
    assert message(signal.SIGINT) == "interrupted (Ctrl-C)"
    assert message(signal.SIGTERM) == "terminated (SIGTERM)"
    assert message(signal.SIGHUP) == "hung up (SIGHUP)"
    assert [exit_status(s) for s in (signal.SIGINT, signal.SIGTERM)] == [130, 143]
