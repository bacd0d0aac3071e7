"""``tagbot sim arm``: serve a simulated servo chain for the arm on a pseudo-terminal.

The chain has the profile's servo IDs, models and baud rate, and its geometry (for the
simulator's pen-tip recorder); it runs in real time until Ctrl-C. A serial arm's profile
(``--profile openmanipulator-x``) serves its servos with the MuJoCo physics of the arm behind
them (:class:`sim.dynamixel.physics.ArmPhysics`), the paper where the profile puts it. Any
program opens the printed device path like a USB adapter: ``tagbot draw … --device dynamixel
--port PATH``, the unmodified ``dynamixel_sdk.PortHandler(PATH)``, or DYNAMIXEL Wizard-like
tools that accept a device file.
``--reply-latency``, ``--reply-jitter`` and ``--drop`` make the line behave like a real one
(:meth:`sim.dynamixel.SimulatedChain.set_reply_faults`): replies late, or lost.
"""

from __future__ import annotations

import time
from typing import Any

import click

__all__ = ["sim_arm_command"]


def _wait_for_interrupt() -> None:
    """Sleep until Ctrl-C (KeyboardInterrupt); tests replace it."""
    while True:
        time.sleep(0.5)


@click.command(name="arm")
@click.option(
    "--profile",
    metavar="NAME|PATH",
    default="default",
    show_default=True,
    help="A packaged arm profile or a TOML file layered on the defaults.",
)
@click.option(
    "--set",
    "overrides",
    metavar="KEY=VALUE",
    multiple=True,
    help="Override one profile value, e.g. --set pen.id=4 (repeatable).",
)
@click.option(
    "--reply-latency",
    type=click.FloatRange(min=0),
    default=0.0,
    metavar="SECONDS",
    help="Deliver every status packet this late (e.g. 0.016: an FTDI adapter's latency timer).",
)
@click.option(
    "--reply-jitter",
    type=click.FloatRange(min=0),
    default=0.0,
    metavar="SECONDS",
    help="Plus up to this much more, at random.",
)
@click.option(
    "--drop",
    type=click.FloatRange(min=0, max=1),
    default=0.0,
    metavar="P",
    help="Lose each status packet with this probability (e.g. 0.02).",
)
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the fault draws.")
def sim_arm_command(
    profile: str,
    overrides: tuple[str, ...],
    reply_latency: float,
    reply_jitter: float,
    drop: float,
    seed: int,
) -> None:
    """Serve a simulated DYNAMIXEL chain for the arm on a pseudo-terminal until Ctrl-C.

    Prints the device path (e.g. /dev/pts/3) on stdout; the servos answer Protocol 2.0 at the
    profile's bus.baud in real time, their replies late or lost if asked.
    """
    from sim.dynamixel import serve_pty
    from tagbot.arm.profile import load_profile
    from tagbot.arm.run import simulated_chain
    from tagbot.arm.serial.profile import is_serial_profile
    from tagbot.signals import label, signal_of

    if is_serial_profile(profile):  # a serial arm: its servos with MuJoCo physics behind them
        from tagbot.arm.serial.machine import simulated_arm
        from tagbot.arm.serial.profile import load_serial_profile

        machine: Any = load_serial_profile(profile, overrides)
        chain, _physics = simulated_arm(machine, real_time=True)
    else:
        machine = load_profile(profile, overrides)
        chain = simulated_chain(machine, real_time=True)
    chain.set_reply_faults(reply_latency, reply_jitter, drop, seed)
    path, stop = serve_pty(chain)
    servos = ", ".join(f"{id} {model}" for id, model in machine.servos.items())
    click.echo(path)
    faults = ""
    if reply_latency or reply_jitter or drop:
        faults = (
            f" (replies {1e3 * reply_latency:g}+{1e3 * reply_jitter:g} ms late,"
            f" {100 * drop:g} % lost)"
        )
    click.echo(
        f"serving servos {servos} at {machine['bus.baud']} bps on {path}{faults}; Ctrl-C stops",
        err=True,
    )
    how = ""
    try:
        _wait_for_interrupt()
    except KeyboardInterrupt as e:  # the normal way out
        how = f" ({label(signal_of(e))})"
    finally:
        stop()
    click.echo(f"stopped{how}", err=True)
