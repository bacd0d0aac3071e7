"""``tagbot sim axidraw``: a simulated EiBotBoard served on a pseudo-terminal until Ctrl-C.

Here rather than in :mod:`sim.ebb` (simulators never import tagbot), and light to import: the
simulator loads when the command runs.
"""

from __future__ import annotations

import os
import signal
import time
from typing import Any

import click

__all__ = ["sim_axidraw_command"]


def _wait_for_interrupt() -> None:
    """Sleep until Ctrl-C (KeyboardInterrupt); tests replace it."""
    while True:
        time.sleep(0.5)


@click.command(name="axidraw")
@click.option(
    "--firmware",
    metavar="VERSION",
    default=None,
    help="The firmware version the board reports to V (default: the simulator's 3.x).",
)
@click.option(
    "--pen-pin",
    type=click.IntRange(0, 7),
    default=1,
    show_default=True,
    help="The port B pin of the pen-lift motor (1: the AxiDraw's servo; 2: the NextDraw's).",
)
def sim_axidraw_command(firmware: str | None, pen_pin: int) -> None:
    """Serve a simulated EiBotBoard (the AxiDraw's controller) on a pseudo-terminal until Ctrl-C.

    Prints the device path (e.g. /dev/pts/3) on stdout: point the AxiDraw software, or
    `tagbot draw --device axidraw --port PATH`, at it. The board answers in real time.
    SIGUSR1 presses its PRG (pause) button: kill -USR1 PID.
    """
    from sim.ebb import transport
    from sim.ebb.device import SimulatedEBB
    from tagbot.signals import label, signal_of

    options: dict[str, Any] = {"pen_pin": pen_pin}
    if firmware is not None:
        options["version"] = firmware
    try:
        device = SimulatedEBB(clock="real", **options)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--firmware") from None

    def press_button(signum: int, frame: Any) -> None:
        with device.lock:
            device.poll()
            device.press_button(device.now)

    path, stop = transport.serve_pty(device)
    before = signal.signal(signal.SIGUSR1, press_button)
    how = ""
    try:
        click.echo(path)
        click.echo(
            f"simulated EBB (firmware {device.version}) serving; kill -USR1 {os.getpid()}"
            " presses its PRG button; Ctrl-C stops it",
            err=True,
        )
        _wait_for_interrupt()
    except KeyboardInterrupt as e:  # the normal way out
        how = f" ({label(signal_of(e))})"
    finally:
        signal.signal(signal.SIGUSR1, before)
        stop()
    click.echo(f"stopped{how}", err=True)
