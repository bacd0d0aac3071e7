"""The plotter's commands: `tagbot gcode` (a Grbl program for any sender) and `tagbot sim grbl`."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

import click

if TYPE_CHECKING:
    pass

__all__ = ["gcode_command", "profile_options", "sim_grbl_command"]


def profile_options(f: Any) -> Any:
    """``--profile`` and ``--set``, shared by the machine commands."""
    f = click.option(
        "--set",
        "overrides",
        metavar="KEY=VALUE",
        multiple=True,
        help="Override one profile value, e.g. --set bed.margin=5 (repeatable).",
    )(f)
    return click.option(
        "--profile",
        metavar="NAME|PATH",
        default=None,
        help="A packaged machine profile or a TOML file layered on the defaults.",
    )(f)


@click.command(name="gcode")
@click.argument("source", metavar="INPUT|PLAN", type=click.Path(dir_okay=False, exists=True))
@click.option(
    "-o",
    "--output",
    metavar="FILE",
    type=click.Path(dir_okay=False),
    required=True,
    help="Where to write the G-code program.",
)
@profile_options
def gcode_command(
    source: str, output: str, profile: str | None, overrides: tuple[str, ...]
) -> None:
    """Place and retime a tag on a Grbl pen plotter and write the G-code program.

    INPUT is a plan file, or a trace file (GML, SVG, points) that is fitted first. The tag is
    fitted into the bed, each pen-down run slowed down to the machine's limits (never sped up;
    motion.time_scale=uniform slows the whole tag by one factor), and written as inverse-time
    (G93) moves whose durations adapt to the motion (motion.dt to motion.max_dt, within
    motion.tolerance mm). Nothing is written when the tag would leave the bed.
    """
    from tagbot.io.output import check_output_file
    from tagbot.plotter.place import place
    from tagbot.plotter.profile import load_profile
    from tagbot.plotter.program import build_program, host_pause_warnings
    from tagbot.source import load_tag

    machine = load_profile(profile, overrides)
    check_output_file(output)
    tag = load_tag(source)
    program = build_program(place(tag, machine), machine)
    program.write(output)
    click.echo(f"wrote {output}: {program.summary()}", err=True)
    for warning in host_pause_warnings(program, machine):
        logging.getLogger(__name__).warning("%s", warning)


@click.command(name="grbl")
@profile_options
def sim_grbl_command(profile: str | None, overrides: tuple[str, ...]) -> None:
    """Serve a simulated Grbl 1.1h on a pseudo-terminal until Ctrl-C.

    The machine's settings ($100/$101, $110/$111, $120/$121, $11) and pen come from the
    profile. Prints the device path: point any G-code sender, or `tagbot draw --port PATH`,
    at it.
    """
    import threading

    from sim.grbl import SimulatedGrbl
    from sim.grbl.transport import serve_pty
    from tagbot.plotter.machine import simulated_pen
    from tagbot.plotter.profile import device_settings, load_profile
    from tagbot.signals import label, signal_of

    machine = load_profile(profile, overrides)
    device = SimulatedGrbl(device_settings(machine), clock="real", **simulated_pen(machine))
    path, stop = serve_pty(device)
    how = ""
    try:
        click.echo(path)
        click.echo("simulated Grbl 1.1h serving; Ctrl-C stops it", err=True)
        threading.Event().wait()
    except KeyboardInterrupt as e:  # the normal way out
        how = f" ({label(signal_of(e))})"
    finally:
        stop()
    click.echo(f"stopped{how}", err=True)
