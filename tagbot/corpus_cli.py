"""The command-line side of corpus mode: ``--jobs``/``--scheduler``, a progress bar, and the
loop that runs many inputs into one folder with a summary table (see :mod:`tagbot.corpus`)."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import click

__all__ = ["corpus_options", "progress_bar", "run_corpus"]

F = TypeVar("F", bound=Callable[..., Any])

EXIT_OK = 0
EXIT_FAILED = 1


def progress_bar(unit: str, quiet: bool) -> Any:
    """A progress bar on stderr with rate and ETA (quiet when not a terminal or --quiet)."""
    from tqdm import tqdm

    class Bar(tqdm):  # type: ignore[type-arg]
        monitor_interval = 0  # updates come from the machine's loop: no monitor thread

    return Bar(
        total=0,
        unit=unit,
        file=sys.stderr,
        disable=True if quiet else None,
        dynamic_ncols=True,
        leave=False,
    )


def corpus_options(f: F) -> F:
    """``--jobs`` and ``--scheduler`` of commands that take many inputs."""
    f = click.option(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="Run the files on this dask.distributed scheduler (needs tagbot[dask]).",
    )(f)
    return click.option(
        "--jobs",
        "-j",
        type=click.IntRange(min=1),
        default=None,
        help="Worker processes for many inputs [default: the CPU count].",
    )(f)


def run_corpus(
    work: Callable[..., dict[str, Any]],
    sources: Sequence[str],
    output: str | None,
    suffix: str,
    options: dict[str, Any],
    force: bool,
    jobs: int | None,
    scheduler: str | None,
    quiet: bool = False,
) -> int:
    """Run ``work`` over many inputs into the folder ``output``; the exit status."""
    from pathlib import Path

    from tagbot.corpus import FileJob, expand_inputs, map_files, output_paths, write_summary
    from tagbot.errors import OutputError
    from tagbot.io.output import check_output_folder

    if output is None or output == "-":
        raise click.UsageError("many inputs need -o DIR, the folder for the results")
    check_output_folder(output)
    files = expand_inputs(sources)
    outputs = output_paths(files, output, suffix)
    summary = Path(output) / "summary.csv"
    if not force:
        existing = [p for p in [*outputs, str(summary)] if Path(p).exists()]
        if existing:
            more = f" and {len(existing) - 1} more" if len(existing) > 1 else ""
            raise OutputError(f"{existing[0]}: exists{more} (--force replaces them)")
    Path(output).mkdir(parents=True, exist_ok=True)
    workers = jobs or os.cpu_count() or 1
    batch = [FileJob(s, o, options) for s, o in zip(files, outputs, strict=True)]
    rows = []
    bar = progress_bar("file", quiet)
    bar.reset(total=len(batch))
    failed = 0
    try:
        for row in map_files(work, batch, workers=workers, scheduler=scheduler):
            rows.append(row)
            if row["status"] != "ok":
                failed += 1
                bar.write(f"tagbot: error: {row['error']}", file=sys.stderr)
            bar.set_postfix_str(f"{failed} failed" if failed else "", refresh=False)
            bar.update(1)
    finally:
        bar.close()
        if rows:
            write_summary(rows, summary)
    where = f"via {scheduler}" if scheduler else f"{min(workers, len(batch))} worker(s)"
    click.echo(
        f"{len(rows) - failed} of {len(batch)} file(s) done, {failed} failed ({where}); "
        f"summary in {summary}",
        err=True,
    )
    return EXIT_FAILED if failed else EXIT_OK
