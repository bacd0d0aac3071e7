"""The ``tagbot`` command line.

:func:`main` runs the click group and turns every expected failure into one line on stderr,
``tagbot: error: <message>``, with exit status 2 for bad input or usage, 1 for other tagbot errors
and 128 + the signal's number when stopped by one (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP), the
line naming it. Unexpected exceptions propagate: they are bugs.
"""

from __future__ import annotations

import logging
import math
import os
import signal
import sys
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import click

from tagbot.arm.cli import sim_arm_command
from tagbot.axidraw.sim_cli import sim_axidraw_command
from tagbot.corpus_cli import corpus_options, progress_bar, run_corpus
from tagbot.errors import Interrupted, TagbotError
from tagbot.plotter.cli import gcode_command, profile_options, sim_grbl_command
from tagbot.render.cli import plot_command, render_command
from tagbot.studio.cli import studio_command

__all__ = ["cli", "main"]

EXIT_OK = 0
EXIT_ERROR = 1
EXIT_USAGE = 2

PROG = "tagbot"

F = TypeVar("F", bound=Callable[..., Any])


class _Interrupted(Exception):
    """A KeyboardInterrupt inside a command, carried past click's own handling."""


class _Group(click.Group):
    """A click group that lets :func:`main` report Ctrl-C as one line."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as e:
            raise _Interrupted from e
        except SystemError as e:
            # A signal's handler that ran as a compiled kernel returned (numba runs Python to box
            # the result, and turns an exception raised there into "CPUDispatcher(...) returned
            # a result with an exception set"): the interrupt it carries.
            cause: BaseException | None = e
            while cause is not None and not isinstance(cause, KeyboardInterrupt):
                cause = cause.__cause__ or cause.__context__
            if cause is None:
                raise
            raise _Interrupted from cause


class Seconds(click.ParamType):
    """A positive, finite number of seconds."""

    name = "SECONDS"

    def convert(
        self, value: Any, param: click.Parameter | None, ctx: click.Context | None
    ) -> float:
        if isinstance(value, float | int) and not isinstance(value, bool):
            x = float(value)
        else:
            try:
                x = float(str(value).strip())
            except ValueError:
                self.fail(f"{value!r} is not a number of seconds", param, ctx)
        if not (math.isfinite(x) and x > 0):
            self.fail(f"{value!r} is not a positive, finite number of seconds", param, ctx)
        return x


def _print_version(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    if value and not ctx.resilient_parsing:
        from tagbot import __version__

        click.echo(f"{PROG} {__version__}")
        ctx.exit()


def _output_file(metavar: str, what: str) -> Callable[[F], F]:
    """The ``-o/--output`` option of commands that write one file (default: stdout)."""
    return click.option(
        "-o",
        "--output",
        metavar=metavar,
        type=click.Path(dir_okay=False, allow_dash=True),
        default="-",
        show_default="stdout",
        help=f"Where to write {what}; '-' is stdout.",
    )


@click.group(
    name=PROG,
    cls=_Group,
    invoke_without_command=True,
    context_settings={"help_option_names": ["-h", "--help"]},
)
@click.option(
    "--version",
    is_flag=True,
    expose_value=False,
    is_eager=True,
    callback=_print_version,
    help="Show the version and exit.",
)
@click.pass_context
def cli(ctx: click.Context) -> None:
    """Model graffiti tags with Sigma-Lognormal / Gamma-Lognormal strokes.

    Plans are JSON files (see the README, "Plan files"); examples ship in tagbot/examples/.
    """
    if ctx.invoked_subcommand is None:
        click.echo(ctx.get_help())


@cli.command()
@click.argument("plan", metavar="PLAN.json", type=click.Path(dir_okay=False))
@click.option(
    "--dt",
    type=Seconds(),
    default=0.01,
    show_default=True,
    help="Sampling interval in seconds (> 0).",
)
@_output_file("MOTION.csv", "the CSV")
def sample(plan: str, dt: float, output: str) -> None:
    """Sample a plan file's tag at a fixed time step and write it as CSV.

    Columns: t,x,y,vx,vy,speed,pen (seconds, plan units, units/s; pen 1 = down).
    """
    from tagbot.io.motionfile import write_motion_csv
    from tagbot.io.planfile import load_plan

    tag = load_plan(plan)
    motion = tag.sample(dt=dt)
    if output == "-":
        write_motion_csv(motion, sys.stdout)
        sys.stdout.flush()
        return
    write_motion_csv(motion, output)
    n = len(motion.t)
    duration = float(motion.t[-1] - motion.t[0]) if n else 0.0
    plans = len(tag.plans)
    click.echo(
        f"wrote {n} samples ({duration:.2f} s, {plans} plan{'s' if plans != 1 else ''}) "
        f"to {output}",
        err=True,
    )


@cli.command(name="fit")
@click.argument("sources", metavar="INPUT...", nargs=-1, required=True)
@click.option(
    "--model",
    type=click.Choice(["gamma", "sigma"]),
    default="gamma",
    show_default=True,
    help="Euler-spiral strokes (gamma, can inflect) or circular arcs (sigma).",
)
@click.option(
    "--refine/--no-refine",
    default=True,
    show_default=True,
    help="Polish the paper's reconstruction by least squares.",
)
@click.option(
    "--timing",
    type=click.Choice(["auto", "ignore", "match"]),
    default="auto",
    show_default=True,
    help="match: follow the recorded speed (timed inputs); ignore: the shape only, at the paper's "
    "rhythm; auto: match when the input has usable timestamps.",
)
@click.option(
    "--report/--no-report",
    default=True,
    show_default=True,
    help="Measure the fit (shape error, velocity SNR); --no-report skips the metrics.",
)
@click.option(
    "-o",
    "--output",
    metavar="PLAN.json|DIR",
    default=None,
    help="One input: the plan file ('-' or none: stdout). Many inputs: the folder for the plans "
    "and summary.csv (created if needed).",
)
@click.option("--force", is_flag=True, help="Many inputs: replace plans already in the folder.")
@corpus_options
def fit_command(
    sources: tuple[str, ...],
    model: str,
    refine: bool,
    timing: str,
    report: bool,
    output: str | None,
    force: bool,
    jobs: int | None,
    scheduler: str | None,
) -> None:
    """Reconstruct plans from trace files (GML, #000000book JSON, SVG, CSV or JSON points).

    The format is told from the content. One INPUT: prints the traces, strokes, shape error (and
    velocity SNR when the input has timing) and the command's wall time on stderr. Many (several
    files, folders searched for trace files, or quoted globs like 'tags/**/*.gml'): each is fitted
    in a worker process into DIR, with a progress bar, and DIR/summary.csv gets one row per file
    (figures or error); the exit status is 1 when any file failed.
    """
    import time

    from tagbot.corpus import FileJob, fit_file, is_corpus

    started = time.perf_counter()
    options = {"model": model, "report": report, "fit": {"refine": refine, "timing": timing}}
    if is_corpus(sources):
        ctx = click.get_current_context()
        ctx.exit(run_corpus(fit_file, sources, output, ".json", options, force, jobs, scheduler))
    source = sources[0]
    if output is None:
        output = "-"
    from tagbot.io.output import check_output_file

    check_output_file(output)
    from tagbot.corpus import fit_one

    row: dict[str, Any] = {}
    tag = fit_one(FileJob(source, None if output == "-" else output, options), row)
    if output == "-":
        import json

        from tagbot.io.planfile import tag_to_dict

        click.echo(json.dumps(tag_to_dict(tag), indent=1))
    elapsed = _since_start(time.perf_counter() - started)
    from tagbot.corpus import NOTES_JOINER

    for note in filter(None, row["timing_notes"].split(NOTES_JOINER)):
        click.echo(f"{PROG}: warning: {source}: {note}", err=True)
    figures = row.get("summary", f"{row['traces']} traces -> {row['strokes']} strokes")
    clock = f"; clock {row['clock']}" if row["clock"] not in ("untimed", "s") else ""
    click.echo(
        f"{source}: {figures}{clock}; {elapsed:.2f} s since the command started"
        f" (load {row['load_s']:.2f}, fit {row['fit_s']:.2f}"
        + (f", report {row['report_s']:.2f})" if report else ")"),
        err=True,
    )
    if output != "-":
        click.echo(f"wrote {output}", err=True)


@cli.command()
@click.argument("plan", metavar="PLAN.json", type=click.Path(dir_okay=False))
@click.option("--count", "-n", type=click.IntRange(min=1), required=True, help="Instances.")
@click.option(
    "--seed",
    type=click.IntRange(min=0),
    default=None,
    help="Seed of the random variations (printed when not given, to repeat a run).",
)
@click.option(
    "-o",
    "--output",
    metavar="DIR",
    type=click.Path(file_okay=False),
    required=True,
    help="Folder for the varied plans (created if needed).",
)
@click.option("--force", is_flag=True, help="Replace plans of the same names in the folder.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def vary(plan: str, count: int, seed: int | None, output: str, force: bool, quiet: bool) -> None:
    """Write COUNT plausible variations of a plan (paper §7): targets, proportions, rhythm and
    curvature varied at random, reproducibly for a seed.

    The plans are written one by one as they are made (memory stays bounded), named
    PLAN-0001.json and so on; existing plans of these names are kept unless --force.
    """
    import re
    from pathlib import Path

    from tagbot.errors import OutputError
    from tagbot.gesture import iter_vary, new_seed
    from tagbot.io.output import check_output_folder
    from tagbot.io.planfile import load_plan, save_plan

    if count > MAX_VARIATIONS:
        raise click.BadParameter(
            f"{count} is more than {MAX_VARIATIONS} (the most one run writes)", param_hint="--count"
        )
    check_output_folder(output)
    tag = load_plan(plan)
    folder = Path(output)
    stem = Path(plan).name.removesuffix(".json").removesuffix(".plan")
    width = len(str(count))
    if folder.is_dir() and not force:
        mine = re.compile(rf"{re.escape(stem)}-(\d{{{width}}})\.json")
        taken = sorted(
            name
            for name in os.listdir(folder)
            if (m := mine.fullmatch(name)) and 1 <= int(m[1]) <= count
        )
        if taken:
            more = f" and {len(taken) - 1} more" if len(taken) > 1 else ""
            raise OutputError(f"{folder / taken[0]}: exists{more} (--force replaces them)")
    if seed is None:
        seed = new_seed()
        click.echo(f"seed {seed} (pass --seed {seed} to repeat)", err=True)
    folder.mkdir(parents=True, exist_ok=True)
    bar = progress_bar("plan", quiet or count < 100)
    bar.reset(total=count)
    try:
        for i, instance in enumerate(iter_vary(tag, count, seed), start=1):
            save_plan(instance, folder / f"{stem}-{i:0{width}d}.json")
            bar.update(1)
    finally:
        bar.close()
    click.echo(f"wrote {count} plan{'s' * (count != 1)} to {folder}", err=True)


MAX_VARIATIONS = 1_000_000
"""Most plans ``tagbot vary`` writes in one run."""


cli.add_command(gcode_command)
cli.add_command(render_command)
cli.add_command(plot_command)
cli.add_command(studio_command)


@cli.command(name="draw")
@click.argument("source", metavar="INPUT|PLAN", type=click.Path(dir_okay=False, exists=True))
@click.option(
    "--device",
    type=click.Choice(["grbl", "dynamixel", "axidraw"]),
    default="grbl",
    show_default=True,
    help="grbl: a pen plotter; dynamixel: the servo arm; axidraw: an AxiDraw (EiBotBoard).",
)
@click.option(
    "--port",
    metavar="PORT",
    default=None,
    help="Serial port or pyserial URL of the machine (axidraw: 'auto' finds the board on "
    "USB). Without it the run is simulated: nothing moves.",
)
@profile_options
@click.option(
    "--out",
    metavar="DIR",
    type=click.Path(file_okay=False),
    default=None,
    help="The run folder (default: runs/<input>-<device>-<time> under the current directory).",
)
@click.option(
    "--send-and-wait",
    is_flag=True,
    help="Grbl: send one line at a time (slower) instead of character counting.",
)
@click.option(
    "--unlock",
    "unlock",
    flag_value="unlock",
    default=None,
    help="Grbl: unlock ($X) a machine found in Alarm. Check it first.",
)
@click.option(
    "--home",
    "unlock",
    flag_value="home",
    help="Grbl: home ($H) a machine found in Alarm.",
)
@click.option(
    "--resume-from",
    metavar="N",
    type=click.IntRange(min=2),
    default=None,
    help="Resume an interrupted job at this line of program.gcode (Grbl, needs "
    "--position-known), move of moves.txt (AxiDraw, needs --position-known) or tick of "
    "joints.csv (arm: its encoders know where it is).",
)
@click.option(
    "--position-known",
    is_flag=True,
    help="Confirm the machine's position is right (homed or checked) for --resume-from.",
)
@click.option(
    "--recording",
    metavar="FILE",
    type=click.Path(dir_okay=False, exists=True),
    default=None,
    help="The timed capture a PLAN was fitted from (one trace per plan): the report compares "
    "the executed speed with it. A trace file given as INPUT is its own recording.",
)
@click.option("--no-pictures", is_flag=True, help="Do not render pictures into the run folder.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar and no summary.")
def draw_command(
    source: str,
    device: str,
    port: str | None,
    profile: str | None,
    overrides: tuple[str, ...],
    out: str | None,
    send_and_wait: bool,
    unlock: str | None,
    resume_from: int | None,
    position_known: bool,
    recording: str | None,
    no_pictures: bool,
    quiet: bool,
) -> None:
    """Draw a tag on a machine and write a run folder (plan, motion, program, executed trace,
    report, pictures).

    INPUT is a plan file, or a trace file (GML, SVG, points) that is fitted first. Without
    --port the machine is simulated: the default never moves hardware. Everything (profile,
    placement, limits, the port) is checked before anything starts. While drawing, a progress
    bar shows the lines or ticks executed; space or p pauses (feed hold on the plotter, pen up
    on the arm) and resumes; Ctrl-C stops safely. A fault stops the machine safely (pen up) and
    names the last line or tick it executed.
    """
    import time
    from pathlib import Path

    from tqdm.contrib.logging import logging_redirect_tqdm

    from tagbot.control import RunControl
    from tagbot.draw import draw, prepare
    from tagbot.errors import InputError
    from tagbot.signals import machine_run
    from tagbot.source import load_source

    if resume_from is not None and not position_known and device in ("grbl", "axidraw"):
        raise InputError(
            "--resume-from: the machine's position must be known first (home it or check it), "
            "then add --position-known"
        )
    options: dict[str, Any] = {}
    if device == "grbl":
        options = {
            "mode": "wait" if send_and_wait else "count",
            "unlock": unlock or "never",
            "resume_from": resume_from,
        }
    elif send_and_wait or unlock:
        raise InputError("--send-and-wait, --unlock and --home are Grbl options")
    elif resume_from is not None:
        options = {"resume_from": resume_from}
    tag, traces = load_source(source)  # a trace file's traces: the report compares with them
    if recording is not None:
        traces = _recording(recording, len(tag.plans))
    job = prepare(tag, device=device, port=port, profile=profile, overrides=overrides, **options)
    if out is None:
        stem = Path(source).name.split(".")[0]
        out = str(Path("runs") / f"{stem}-{device}-{time.strftime('%Y%m%d-%H%M%S')}")
    where = "the simulator" if port is None else port
    keys = _PauseKeys(RunControl(), enabled=not quiet)
    if not quiet:
        hint = "; space pauses, Ctrl-C stops" if keys.available else "; Ctrl-C stops"
        click.echo(f"drawing {source} on {device} ({where}) into {out}{hint}", err=True)
    unit = {"dynamixel": "tick", "axidraw": "move"}.get(device, "line")
    with progress_bar(unit, quiet) as bar, keys:
        keys.report = bar.write
        progress = bar_progress(bar)
        try:
            # The machine's loop stops it safely on a signal; its log lines go above the bar.
            with machine_run(), logging_redirect_tqdm(tqdm_class=type(bar)):
                result = draw(
                    tag,
                    out,
                    prepared=job,
                    progress=progress,
                    control=keys.control,
                    pictures=not no_pictures,
                    recorded=traces,
                )
        except (TagbotError, KeyboardInterrupt):
            bar.close()
            click.echo(f"run folder (partial): {out}", err=True)
            raise
    if not quiet:
        click.echo(_draw_summary(result.report, out), err=True)


def _recording(path: str, plans: int) -> list[Any]:
    """The timed traces of ``path`` to compare a run of ``plans`` plans with, checked first."""
    from tagbot.errors import InputError
    from tagbot.inputs import load_traces

    traces = load_traces(path)
    if len(traces) != plans:
        raise InputError(
            f"{path}: has {len(traces)} trace{'s' * (len(traces) != 1)} for a tag of {plans} "
            f"plan{'s' * (plans != 1)} (--recording needs the capture the plan was fitted from)"
        )
    if all(getattr(trace, "t", None) is None for trace in traces):
        raise InputError(f"{path}: has no time stamps to compare the executed speed with")
    return traces


class _PauseKeys:
    """Space or p toggles ``control`` (pause / resume) while stdin is a terminal.

    The terminal is put in cbreak mode (keys arrive one by one, Ctrl-C still interrupts) and
    restored on exit; a thread reads the keys. Without a terminal nothing happens.
    """

    KEYS = (b" ", b"p", b"P")

    def __init__(self, control: Any, *, enabled: bool = True) -> None:
        import threading

        self.control = control
        self.report: Callable[[str], None] = lambda text: click.echo(text, err=True)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._saved: Any = None
        try:
            self._fd = sys.stdin.fileno()
            tty = enabled and os.isatty(self._fd)
        except (AttributeError, OSError, ValueError):
            self._fd, tty = -1, False
        try:
            import termios  # noqa: F401
        except ImportError:  # not on Windows
            tty = False
        self.available = tty

    def __enter__(self) -> _PauseKeys:
        if not self.available:
            return self
        import termios
        import threading
        import tty

        self._saved = termios.tcgetattr(self._fd)
        tty.setcbreak(self._fd)
        self._thread = threading.Thread(target=self._read, name="tagbot-keys", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._thread is None:
            return
        import termios

        self._stop.set()
        self._thread.join()
        termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)

    def _read(self) -> None:
        import select

        while not self._stop.is_set():
            ready, _, _ = select.select([self._fd], [], [], 0.1)
            if not ready:
                continue
            key = os.read(self._fd, 1)
            if key in self.KEYS:
                paused = self.control.toggle()
                self.report("paused: space resumes" if paused else "resumed")


def bar_progress(bar: Any) -> Callable[[int, int], None]:
    """A machine's ``progress(done, total)`` on a tqdm ``bar``: the first call (a resumed job's
    first line) sets where the bar starts, not progress, so the rate counts only what runs."""

    def progress(done: int, total: int) -> None:
        if bar.total != total:
            bar.reset(total=total)
            bar.initial = bar.n = bar.last_print_n = done
            bar.refresh()
            return
        bar.update(done - bar.n)

    return progress


def _draw_summary(report: dict[str, Any], out: str) -> str:
    parts = [f"wrote {out}"]
    if "speed_snr_db" in report:
        snr = report["speed_snr_db"]
        parts.append(
            f"path deviation {report['path_deviation_mean_mm']:.3f} mm mean, "
            f"{report['path_deviation_max_mm']:.3f} mm max; speed SNR "
            + ("not measured (status reports)" if snr is None else f"{snr:.1f} dB")
            + f"; drawing time x{report['drawing_duration_ratio']:.3f}"
        )
    if report.get("recorded_speed_snr_db") is not None:
        parts.append(f"speed against the recording {report['recorded_speed_snr_db']:.1f} dB")
    return "; ".join(parts)


@cli.command(name="demo")
@click.option(
    "--out",
    metavar="DIR",
    type=click.Path(file_okay=False),
    default="tagbot-demo",
    show_default=True,
    help="Folder for everything the demo makes.",
)
@click.option(
    "--seed",
    type=click.IntRange(min=0),
    default=7,
    show_default=True,
    help="Seed of the variations, drips and brush texture.",
)
def demo_command(out: str, seed: int) -> None:
    """The whole pipeline on a real tag that ships with tagbot: fit a DustTag capture, plot its
    plan and speed, vary it, paint and animate it, and draw it on the simulated pen plotter and
    the simulated servo arm. Nothing moves: no hardware is used."""
    import time

    from tagbot.demo import run_demo

    started = time.perf_counter()

    def progress(step: str, index: int, count: int) -> None:
        click.echo(f"[{index}/{count}] {step} ...", err=True)

    result = run_demo(out, seed=seed, progress=progress)
    click.echo(result.summary())
    click.echo(f"done in {time.perf_counter() - started:.1f} s", err=True)


@cli.group(name="sim")
def sim_group() -> None:
    """Serve simulated machines on pseudo-terminals (for any sender, or tagbot draw --port)."""


sim_group.add_command(sim_grbl_command)
sim_group.add_command(sim_arm_command, name="arm")
sim_group.add_command(sim_axidraw_command, name="axidraw")


def _one_line(message: str) -> str:
    return " ".join(message.splitlines()).strip()


def _error(message: str) -> None:
    click.echo(f"{PROG}: error: {_one_line(message)}", err=True)


def _os_error_message(e: OSError) -> str:
    if e.filename is not None:
        name = os.fsdecode(e.filename)
        return f"{name}: {e.strerror or e}"
    return str(e)


def _command_path(e: click.UsageError, args: list[str]) -> str:
    """The command a usage error is about, for the ``--help`` hint."""
    if e.ctx is not None:
        return e.ctx.command_path
    command = next((a for a in args if not a.startswith("-")), None)
    return f"{PROG} {command}" if command in cli.commands else PROG


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``tagbot`` command line with ``argv`` (default: ``sys.argv[1:]``); return the exit
    status. Ctrl-C, SIGTERM and SIGHUP stop any command within a second (:mod:`tagbot.signals`):
    a machine is stopped safely and its run folder written, and the last line names the signal.
    """
    from tagbot.signals import stop_signals

    args = list(sys.argv[1:] if argv is None else argv)
    # Every tagbot module's warnings (the fit's, a machine's, the studio's) as one kind of line;
    # not passed on to the root logger, whose handlers (e.g. a progress bar's) would repeat them.
    package_log = logging.getLogger(PROG)
    handler = _Warnings(logging.WARNING)
    package_log.addHandler(handler)
    propagate, package_log.propagate = package_log.propagate, False
    try:
        with stop_signals(PROG):
            return _main(args)
    finally:
        package_log.removeHandler(handler)
        package_log.propagate = propagate


def _since_start(fallback: float) -> float:
    """Seconds since this process started (Linux: from /proc, so the interpreter's start-up and
    imports count), else ``fallback``."""
    try:
        with open("/proc/self/stat") as f:
            ticks = int(f.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as f:
            uptime = float(f.read().split()[0])
        return max(uptime - ticks / os.sysconf("SC_CLK_TCK"), fallback)
    except (OSError, ValueError, IndexError):
        return fallback


class _Warnings(logging.Handler):
    """tagbot's log records of ``WARNING`` and above as ``tagbot: warning: …`` (``error:``)
    lines on stderr: one line each, an exception by its message, never a traceback; above a
    progress bar when one is shown."""

    def emit(self, record: logging.LogRecord) -> None:
        kind = "error" if record.levelno >= logging.ERROR else "warning"
        line = f"{PROG}: {kind}: {_one_line(record.getMessage())}"
        if record.exc_info and record.exc_info[1] is not None:
            line += f": {_one_line(str(record.exc_info[1]) or type(record.exc_info[1]).__name__)}"
        tqdm = sys.modules.get("tqdm")  # a bar may be showing only if tqdm was imported
        if tqdm is not None:
            tqdm.tqdm.write(line, file=sys.stderr)
        else:
            click.echo(line, err=True)


def _main(args: list[str]) -> int:
    from tagbot.signals import exit_status, last_signal, message, signal_of

    try:
        rv = cli.main(args=args, prog_name=PROG, standalone_mode=False)
    except click.UsageError as e:
        _error(f"{e.format_message()} (see '{_command_path(e, args)} --help')")
        return EXIT_USAGE
    except click.ClickException as e:
        _error(e.format_message())
        return e.exit_code
    except (_Interrupted, click.Abort, KeyboardInterrupt) as e:
        signum = signal_of(e.__cause__ if isinstance(e, _Interrupted) else e)
        _error(message(signum))
        return exit_status(signum)
    except Interrupted as e:
        _error(str(e))
        return exit_status(last_signal() or signal.SIGINT)
    except TagbotError as e:
        _error(str(e))
        return EXIT_USAGE if isinstance(e, ValueError) else EXIT_ERROR
    except OSError as e:
        _error(_os_error_message(e))
        return EXIT_USAGE
    return rv if isinstance(rv, int) else EXIT_OK
