"""``tagbot studio``: the design studio's command."""

from __future__ import annotations

from pathlib import Path

import click

__all__ = ["studio_command"]


@click.command(name="studio")
@click.argument(
    "source", metavar="[PLAN|INPUT]", required=False, type=click.Path(dir_okay=False, exists=True)
)
@click.option(
    "--port",
    type=click.IntRange(0, 65535),
    default=0,
    show_default=True,
    help="Port on 127.0.0.1 to serve on (0: any free port).",
)
@click.option("--no-browser", is_flag=True, help="Print the URL without opening a browser.")
@click.option(
    "--machine-port",
    metavar="PORT",
    default=None,
    help="Serial port or pyserial URL the Draw button drives. Without it draws are simulated.",
)
@click.option(
    "--runs",
    metavar="DIR",
    type=click.Path(file_okay=False),
    default="runs",
    show_default=True,
    help="Where draws write their run folders (as tagbot draw does).",
)
@click.option(
    "--autosave",
    metavar="FILE",
    type=click.Path(dir_okay=False),
    default=None,
    help="Where the current design is kept between sessions "
    "(default: ~/.local/state/tagbot/studio.json).",
)
@click.option(
    "--model",
    type=click.Choice(["gamma", "sigma"]),
    default=None,
    help="Model fitted to an INPUT trace (default gamma).",
)
def studio_command(
    source: str | None,
    port: int,
    no_browser: bool,
    machine_port: str | None,
    runs: str,
    autosave: str | None,
    model: str | None,
) -> None:
    """Design tags in the browser: draw a gesture and get its plan at once, or click targets;
    drag targets, φ and Δt handles; see the trajectory, speed, brush and variations; save,
    export and draw on the plotter, arm or AxiDraw (simulated unless --machine-port is given).

    Serves 127.0.0.1 only; the URL printed holds the session's token, which every request needs.
    Without PLAN|INPUT the last design (autosaved) comes back. Ctrl-C stops the studio.
    """
    import webbrowser

    from tagbot.errors import PortError
    from tagbot.ports import check_port
    from tagbot.signals import label, signal_of
    from tagbot.source import load_source
    from tagbot.studio.server import Studio, StudioServer, _decimated, default_autosave

    if machine_port is not None:
        try:
            check_port(machine_port)
        except PortError as e:
            raise PortError(str(e).replace("--port", "--machine-port", 1)) from None
    tag = traces = None
    plan_path = None
    if source is not None:
        tag, traces = load_source(source, model)
        if traces is None:
            plan_path = Path(source)
    studio = Studio(
        tag=tag,
        gestures=[_decimated(t.xy) for t in traces] if traces else None,
        autosave=Path(autosave) if autosave else default_autosave(),
        runs=Path(runs),
        machine_port=machine_port,
        plan_path=plan_path,
        name=Path(source).name.split(".")[0] if source else "studio",
    )
    server = StudioServer(studio, port)
    click.echo(f"tagbot studio: {server.url}", err=True)
    click.echo("Ctrl-C stops it", err=True)
    if not no_browser:
        webbrowser.open(server.url)
    # uvicorn shuts down cleanly on Ctrl-C or SIGTERM, then passes it on: the normal way out.
    how = ""
    try:
        server.run()
    except KeyboardInterrupt as e:
        how = f" ({label(signal_of(e))})"
    click.echo(f"studio stopped{how}", err=True)
