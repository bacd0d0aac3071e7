"""``tagbot render`` and ``tagbot plot``: pictures, animations and plots of a tag or a run."""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from tagbot.corpus_cli import corpus_options, run_corpus

if TYPE_CHECKING:
    from tagbot.inputs import Trace
    from tagbot.model.plan import Tag
    from tagbot.render.api import Rendered

__all__ = ["load_source", "plot_command", "render_command", "render_file"]

_SIZE = re.compile(r"\s*(\d+)\s*(?:[xX]\s*(\d+)\s*)?")


class PixelSize(click.ParamType):
    """``WxH`` in pixels, or one number for the longer side."""

    name = "WxH"

    def convert(
        self, value: Any, param: click.Parameter | None, ctx: click.Context | None
    ) -> int | tuple[int, int]:
        if isinstance(value, int | tuple):
            return value
        match = _SIZE.fullmatch(str(value))
        if not match:
            self.fail(f"{value!r} is not WIDTHxHEIGHT or a number of pixels", param, ctx)
        width, height = int(match[1]), match[2]
        if width < 1 or (height is not None and int(height) < 1):
            self.fail(f"{value!r}: sizes must be at least 1 pixel", param, ctx)
        return width if height is None else (width, int(height))


def load_source(path: str, model: str | None = None) -> tuple[Tag, list[Trace] | None]:
    """:func:`tagbot.source.load_source`, noting when ``--model`` cannot apply (a plan file)."""
    from tagbot.source import load_source as load

    tag, traces = load(path, model)
    if traces is None and model is not None and model != tag.model:
        click.echo(
            f"note: --model applies to traces; {path} is a {tag.model} plan, drawn as is",
            err=True,
        )
    return tag, traces


def _model_option(f: Any) -> Any:
    return click.option(
        "--model",
        type=click.Choice(["gamma", "sigma"]),
        default=None,
        help="Model fitted to an INPUT trace: Euler spirals (gamma, default) or arcs (sigma).",
    )(f)


@click.command(name="render")
@click.argument("sources", metavar="PLAN|INPUT...", nargs=-1, required=True)
@click.option(
    "-o",
    "--output",
    metavar="FILE|DIR",
    required=True,
    help="The picture: .png, .svg, .gif (animated) or .mp4 (needs tagbot[video]); for many "
    "inputs, the folder for the pictures and summary.csv.",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["png", "svg", "gif", "mp4"]),
    default="png",
    show_default=True,
    help="Many inputs: the pictures' format.",
)
@click.option("--force", is_flag=True, help="Many inputs: replace pictures already in the folder.")
@corpus_options
@click.option("--drips", is_flag=True, help="Paint drips where ink pools (the pen lingers).")
@click.option(
    "--seed",
    type=click.IntRange(min=0),
    default=None,
    help="Seed of the drips and texture (printed when not given, to repeat a picture).",
)
@click.option(
    "--texture", is_flag=True, help="A textured brush: felt streaks, dry breaks at speed, grain."
)
@click.option(
    "--brush",
    "brush_name",
    type=click.Choice(["marker", "fineliner", "chisel", "spray"]),
    default="marker",
    show_default=True,
    help="The pen: a felt marker, a fineliner, a chisel marker or a spray can.",
)
@click.option("--size", type=PixelSize(), default=None, help="Pixels: WxH, or the longer side.")
@click.option(
    "--dpi",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Resolution; without --size the tag is drawn at its physical size.",
)
@click.option(
    "--dt",
    type=click.FloatRange(min=0, min_open=True),
    default=0.002,
    show_default=True,
    help="Seconds between the samples the brush is swept over.",
)
@click.option(
    "--fps",
    type=click.FloatRange(min=0, min_open=True),
    default=25.0,
    show_default=True,
    help="Animation frames per second.",
)
@click.option(
    "--speed",
    type=click.FloatRange(min=0, min_open=True),
    default=1.0,
    show_default=True,
    help="Animation speed: 1 is real time, 2 twice as fast.",
)
@click.option(
    "--hold",
    type=click.FloatRange(min=0),
    default=1.0,
    show_default=True,
    help="Seconds the finished tag stays at the end of an animation.",
)
@click.option("--color", default="#111111", show_default=True, help="Ink colour.")
@click.option(
    "--background",
    default="white",
    show_default=True,
    help="Paper colour, or 'none' for transparent (PNG, SVG).",
)
@_model_option
def render_command(
    sources: tuple[str, ...],
    output: str,
    fmt: str,
    force: bool,
    jobs: int | None,
    scheduler: str | None,
    drips: bool,
    seed: int | None,
    texture: bool,
    brush_name: str,
    size: int | tuple[int, int] | None,
    dpi: float | None,
    dt: float,
    fps: float,
    speed: float,
    hold: float,
    color: str,
    background: str,
    model: str | None,
) -> None:
    """Paint a tag with ink that spreads where the pen lingers and drips (paper §5).

    PLAN|INPUT is a plan file, or a trace file (GML, SVG, points) that is fitted first. The
    output's suffix picks the format: PNG (anti-aliased), SVG (one outline per pen-down run),
    GIF or MP4 (the tag drawn progressively, in real time unless --speed says otherwise).
    Many inputs (files, folders, quoted globs) are rendered in worker processes into the folder
    -o DIR as --format pictures, with DIR/summary.csv; the exit status is 1 if any failed.
    """
    from tagbot.corpus import is_corpus
    from tagbot.io.output import check_output_file
    from tagbot.render.api import format_of

    corpus = is_corpus(sources)
    if not corpus:
        fmt = format_of(output)
    if fmt in ("gif", "mp4"):
        from tagbot.render.animate import check_animation

        check_animation(f"x.{fmt}" if corpus else output, fps)
    if not corpus:
        check_output_file(output)
    if seed is None and (drips or texture):
        from tagbot.gesture import new_seed

        seed = new_seed()
        click.echo(f"seed {seed} (pass --seed {seed} to repeat)", err=True)
    options: dict[str, Any] = {
        "size": size,
        "dpi": dpi,
        "dt": dt,
        "drips": drips,
        "seed": seed,
        "texture": texture,
        "brush": brush_name,
        "color": color,
        "background": background,
        "fps": fps,
        "speed": speed,
        "hold": hold,
    }
    if corpus:
        from tagbot.corpus import render_file as render_job

        ctx = click.get_current_context()
        jobs_options = {"model": model, "render": options}
        ctx.exit(
            run_corpus(render_job, sources, output, f".{fmt}", jobs_options, force, jobs, scheduler)
        )
    result = render_file(sources[0], output, model=model, options=options)
    click.echo(f"wrote {output}: {result.summary()}", err=True)


def render_file(
    source: str, output: str, *, model: str | None, options: dict[str, Any]
) -> Rendered:
    """One file's work for ``tagbot render``: load (or fit) ``source`` and render it into
    ``output`` with :func:`tagbot.render.render`'s keyword ``options`` (a progress bar for
    animations on a terminal)."""
    from tagbot.render.api import format_of, render
    from tagbot.render.brush import RenderError

    tag, _ = load_source(source, model)
    try:
        if format_of(output) in ("gif", "mp4") and sys.stderr.isatty():
            with click.progressbar(length=1, label="frames", file=sys.stderr) as bar:

                def progress(done: int, total: int) -> None:
                    bar.length = total
                    bar.update(done - bar.pos)

                return render(tag, output, progress=progress, **options)
        return render(tag, output, **options)
    except RenderError as e:  # e.g. a cost over its bound, refused before painting: whose
        if str(e).startswith(output):
            raise
        raise RenderError(f"{source}: {e}") from None


@click.command(name="plot")
@click.argument("source", metavar="PLAN|INPUT|RUNDIR", type=click.Path(exists=True))
@click.option(
    "-o",
    "--output",
    metavar="FILE",
    type=click.Path(dir_okay=False),
    required=True,
    help="The plot: .png, .svg or .pdf.",
)
@click.option(
    "--kind",
    type=click.Choice(["speed", "plan"]),
    default="speed",
    show_default=True,
    help="speed: the speed with each stroke's lognormal; plan: the action plan over the trace.",
)
@_model_option
def plot_command(source: str, output: str, kind: str, model: str | None) -> None:
    """Plot a tag's speed or its action plan (paper Figures 4, 6 and 12).

    PLAN|INPUT|RUNDIR is a plan file, a trace file (fitted first; a timed one adds its recorded
    speed, scaled and aligned), or a run folder of `tagbot draw` (planned and executed speed).
    """
    from tagbot.io.output import check_output_file
    from tagbot.render.plots import plot, plot_format

    plot_format(output)
    check_output_file(output)
    if Path(source).is_dir():
        plot(source, output, kind=kind)
    else:
        tag, traces = load_source(source, model)
        plot(tag, output, kind=kind, traces=traces)
    click.echo(f"wrote {output}", err=True)
