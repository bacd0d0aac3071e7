"""Many inputs at once: expand files, folders and globs, map one per-file function over them in
worker processes (or a Dask cluster), and keep one summary row per file.

A per-file function takes a picklable job and returns a dict of figures; it never raises for a
bad file (the row says ``status = error`` with the one-line message), so one bad file never stops
the rest. The same function runs in-process, in a process pool (``jobs`` workers) or over a Dask
bag on a ``dask.distributed`` scheduler (``tagbot[dask]``)::

    rows = list(map_files(fit_file, jobs, workers=4))
"""

from __future__ import annotations

import csv
import glob
import math
import os
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tagbot.errors import InputError, PlanError, TagbotError

if TYPE_CHECKING:
    from tagbot.model.plan import Tag

__all__ = [
    "INPUT_SUFFIXES",
    "MAX_FILES",
    "FileJob",
    "expand_inputs",
    "fit_file",
    "fit_one",
    "is_corpus",
    "map_files",
    "output_paths",
    "render_file",
    "render_one",
    "write_summary",
]

INPUT_SUFFIXES = (".gml", ".xml", ".json", ".js", ".svg", ".csv", ".txt", ".dat")
"""Files taken from a folder given as input (a file named on the command line is read whatever
its name: formats are told from the content)."""

MAX_FILES = 1_000_000
"""Most inputs one command takes (a larger corpus is refused before any work)."""

_GLOB = frozenset("*?[")


@dataclass(frozen=True)
class FileJob:
    """One file's work: the input, where its result goes, and the command's options."""

    source: str
    output: str | None
    options: dict[str, Any] = field(default_factory=dict)


def is_corpus(args: Sequence[str]) -> bool:
    """Whether the command-line inputs name many files: several, a folder or a glob."""
    return len(args) != 1 or Path(args[0]).is_dir() or _is_glob(args[0])


def _is_glob(arg: str) -> bool:
    return not Path(arg).exists() and any(c in _GLOB for c in arg)


def expand_inputs(args: Sequence[str], suffixes: Sequence[str] = INPUT_SUFFIXES) -> list[str]:
    """The files named by ``args``, in order, each once: files as given, folders searched
    recursively for ``suffixes`` (sorted), globs expanded (``**`` included). A name that matches
    nothing raises InputError naming it."""
    found: dict[str, None] = {}
    for arg in args:
        if Path(arg).is_dir():
            hits = sorted(
                str(p) for p in Path(arg).rglob("*") if p.suffix.lower() in suffixes and p.is_file()
            )
            if not hits:
                raise InputError(f"{arg}: no input files in this folder ({', '.join(suffixes)})")
        elif _is_glob(arg):
            hits = sorted(p for p in glob.glob(arg, recursive=True) if Path(p).is_file())
            if not hits:
                raise InputError(f"{arg}: no file matches")
        elif Path(arg).exists():
            hits = [arg]
        else:
            raise InputError(f"{arg}: no such file")
        for hit in hits:
            found.setdefault(hit)
            if len(found) > MAX_FILES:
                raise InputError(f"{arg}: more than {MAX_FILES} input files")
    return list(found)


def output_paths(sources: Sequence[str], folder: str | os.PathLike[str], suffix: str) -> list[str]:
    """One output per source in ``folder``: the source's stem plus ``suffix``, with ``-2``,
    ``-3``… added when two sources share a stem."""
    taken: dict[str, int] = {}
    out = []
    for source in sources:
        stem = Path(source).name
        for ext in (".json", ".plan", ".gml", ".svg", ".csv", ".txt", ".xml", ".js", ".dat"):
            stem = stem.removesuffix(ext)
        n = taken.get(stem.lower(), 0) + 1
        taken[stem.lower()] = n
        out.append(str(Path(folder) / (f"{stem}{suffix}" if n == 1 else f"{stem}-{n}{suffix}")))
    return out


# --------------------------------------------------------------------------- per-file work


def fit_file(job: FileJob) -> dict[str, Any]:
    """Fit one trace file and save its plan; the row of figures (or the error) it ends with.

    Options: ``model``, ``refine``, ``report`` (compute the metrics), plus any
    :func:`tagbot.gesture.fit` option under ``fit``.
    """
    return _guarded(fit_one, job)


def fit_one(job: FileJob, row: dict[str, Any]) -> Tag:
    """:func:`fit_file`'s work, raising on a bad file: the tag, with its figures put in ``row``."""
    from tagbot.inputs import load_traces

    started = time.perf_counter()
    traces = load_traces(job.source)  # first: a bad file is refused before numba/scipy load
    loaded = time.perf_counter()
    from tagbot.gesture import reconstruction
    from tagbot.io.planfile import save_plan
    from tagbot.metrics import timing_summary

    opts = job.options
    try:
        fitted_tag = reconstruction(traces, model=opts.get("model", "gamma"), **opts.get("fit", {}))
    except PlanError as e:  # e.g. a tag longer than a tag may last: which file
        raise PlanError(f"{job.source}: {e}") from e
    tag = fitted_tag.tag
    fitted = time.perf_counter()
    if job.output is not None:
        save_plan(tag, job.output)
    row.update(
        traces=len(traces),
        points=sum(len(t) for t in traces),
        strokes=tag.n_strokes,
        duration_s=round(tag.end - tag.start, 4),
        clock=_clock_of(traces),
        load_s=round(loaded - started, 4),
        fit_s=round(fitted - loaded, 4),
        timing=timing_summary(fitted_tag.timings) or "shape only",
        timing_notes=NOTES_JOINER.join(fitted_tag.notes()),
    )
    if opts.get("report", True):
        from tagbot.metrics import fit_report

        report = fit_report(traces, tag, timings=fitted_tag.timings)
        row.update(
            shape_error_mean=report.shape.mean,
            shape_error_max=report.shape.max,
            velocity_snr_clock_db=report.velocity_snr_clock_db,
            velocity_snr_trace_db=report.velocity_snr_trace_db,
            velocity_snr_db=report.velocity_snr_db,
            summary=report.summary(),
        )
        row["report_s"] = round(time.perf_counter() - fitted, 4)
    return tag


def render_file(job: FileJob) -> dict[str, Any]:
    """Render one plan or trace file (fitted first) into its picture; the row it ends with.

    Options: ``model``, and :func:`tagbot.render.render`'s keywords under ``render``.
    """
    return _guarded(render_one, job)


def render_one(job: FileJob, row: dict[str, Any]) -> None:
    """:func:`render_file`'s work, raising on a bad file."""
    from tagbot.render.api import render
    from tagbot.source import load_source

    started = time.perf_counter()
    tag, traces = load_source(job.source, job.options.get("model"))
    loaded = time.perf_counter()
    assert job.output is not None
    result = render(tag, job.output, **job.options.get("render", {}))
    row.update(
        traces=len(traces) if traces is not None else "",
        strokes=tag.n_strokes,
        duration_s=round(tag.end - tag.start, 4),
        load_s=round(loaded - started, 4),
        render_s=round(time.perf_counter() - loaded, 4),
        picture=result.summary(),
    )


def _clock_of(traces: Sequence[Any]) -> str:
    clocks = {getattr(t, "clock", None) for t in traces if getattr(t, "t", None) is not None}
    clocks.discard(None)
    if not clocks:
        return "untimed" if all(getattr(t, "t", None) is None for t in traces) else "s"
    return "; ".join(sorted(clocks))


def _guarded(work: Callable[[FileJob, dict[str, Any]], object], job: FileJob) -> dict[str, Any]:
    """Run ``work`` on ``job``, turning any failure into the row's error (one line)."""
    row: dict[str, Any] = {"input": job.source, "output": job.output or "", "status": "ok"}
    started = time.perf_counter()
    try:
        work(job, row)
    except TagbotError as e:
        row.update(status="error", error=_one_line(str(e)))
    except (OSError, MemoryError, RecursionError) as e:
        row.update(status="error", error=_one_line(f"{job.source}: {e}"))
    except Exception as e:  # a bug: kept in the row, never stops the rest of the corpus
        where = traceback.extract_tb(e.__traceback__)[-1]
        row.update(
            status="error",
            error=_one_line(
                f"{job.source}: internal error {type(e).__name__}: {e} "
                f"({Path(where.filename).name}:{where.lineno})"
            ),
        )
    row["seconds"] = round(time.perf_counter() - started, 4)
    return row


def _one_line(message: str) -> str:
    return " ".join(message.split())


# --------------------------------------------------------------------------- mapping


def map_files(
    work: Callable[[FileJob], dict[str, Any]],
    jobs: Sequence[FileJob],
    workers: int = 1,
    scheduler: str | None = None,
) -> Iterator[dict[str, Any]]:
    """Rows of ``work`` over ``jobs`` as they finish (not in order): in this process for one
    worker, in ``workers`` processes, or on the Dask scheduler at ``scheduler``."""
    if scheduler is not None:
        yield from _map_dask(work, jobs, scheduler)
    elif workers <= 1 or len(jobs) <= 1:
        for job in jobs:
            yield work(job)
    else:
        yield from _map_processes(work, jobs, workers)


def _map_processes(
    work: Callable[[FileJob], dict[str, Any]], jobs: Sequence[FileJob], workers: int
) -> Iterator[dict[str, Any]]:
    """Rows from a pool of ``workers`` processes, at most twice as many jobs in flight. A worker
    that dies (a native crash) breaks the pool: the jobs it held are run again, each in a
    process of its own (``workers`` such processes at a time), so the file that kills a process
    gets an error row and the others their results; a new pool takes the rest."""
    queue = deque(jobs)
    while queue:
        in_flight: dict[Future[dict[str, Any]], FileJob] = {}
        suspects: list[FileJob] = []
        with _pool(min(workers, len(queue))) as pool:
            try:
                while (queue or in_flight) and not suspects:
                    while queue and len(in_flight) < 2 * workers:
                        job = queue.popleft()
                        in_flight[pool.submit(work, job)] = job
                    done, _ = wait(in_flight, return_when=FIRST_COMPLETED)
                    for future in done:
                        job = in_flight.pop(future)
                        try:
                            row = future.result()
                        except BrokenProcessPool:
                            suspects.append(job)
                            continue
                        yield row
            finally:
                for future in in_flight:
                    future.cancel()
        yield from _each_alone(work, [*suspects, *in_flight.values()], workers)


_PRELOAD = ("tagbot.corpus", "tagbot.gesture", "tagbot.inputs", "tagbot.io.planfile")
_PRELOAD += ("tagbot.render.api", "tagbot.source")
"""What a fit or render worker imports first (seconds): the fork server does it once for all."""


def _pool(workers: int) -> ProcessPoolExecutor:
    import multiprocessing

    # Workers share nothing with this process's threads (fork with threads can deadlock): each
    # is forked from a fork server, a single-threaded process that has done the imports (where
    # there is one; else spawned, importing everything again).
    if "forkserver" in multiprocessing.get_all_start_methods():
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(list(_PRELOAD))
    else:
        context = multiprocessing.get_context("spawn")
    return ProcessPoolExecutor(max(1, workers), mp_context=context)


def _each_alone(
    work: Callable[[FileJob], dict[str, Any]], jobs: Sequence[FileJob], workers: int
) -> Iterator[dict[str, Any]]:
    """:func:`_alone` for each of ``jobs``, ``workers`` of them at a time (each job still in a
    process of its own), in order."""
    if workers <= 1 or len(jobs) <= 1:
        for job in jobs:
            yield _alone(work, job)
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(min(workers, len(jobs))) as threads:
        yield from threads.map(lambda job: _alone(work, job), jobs)


def _alone(work: Callable[[FileJob], dict[str, Any]], job: FileJob) -> dict[str, Any]:
    """``work(job)`` in a process of its own; an error row if that process dies."""
    with _pool(1) as pool:
        try:
            return pool.submit(work, job).result()
        except BrokenProcessPool:
            return {
                "input": job.source,
                "output": job.output or "",
                "status": "error",
                "error": f"{job.source}: the worker process died on this file (a native crash)",
            }


def _take(it: Iterator[FileJob], n: int) -> list[FileJob]:
    out = []
    for _ in range(n):
        try:
            out.append(next(it))
        except StopIteration:
            break
    return out


def _map_dask(
    work: Callable[[FileJob], dict[str, Any]], jobs: Sequence[FileJob], scheduler: str
) -> Iterator[dict[str, Any]]:
    try:
        import dask.bag as db
        from distributed import Client, as_completed
    except ImportError as e:
        raise InputError(
            f"--scheduler needs Dask: pip install 'tagbot[dask]' ({e.name} is missing)"
        ) from e
    try:
        client = Client(scheduler, timeout=10)
    except (OSError, TimeoutError) as e:
        raise InputError(f"--scheduler {scheduler}: cannot connect ({e})") from e
    with client:
        parts = max(1, min(len(jobs), 64 * max(1, len(client.nthreads()))))
        bag = db.from_sequence(jobs, npartitions=parts).map(work)
        futures = client.compute(bag.to_delayed())
        for future in as_completed(futures):
            yield from future.result()


# --------------------------------------------------------------------------- summary

NOTES_JOINER = " | "
"""Between a fit's notes in a summary row's ``timing_notes``."""

SUMMARY_FIELDS = (
    "input",
    "status",
    "error",
    "output",
    "traces",
    "points",
    "strokes",
    "duration_s",
    "clock",
    "shape_error_mean",
    "shape_error_max",
    "velocity_snr_clock_db",
    "velocity_snr_trace_db",
    "velocity_snr_db",
    "timing",
    "timing_notes",
    "seconds",
    "load_s",
    "fit_s",
    "report_s",
    "render_s",
    "picture",
)


def write_summary(rows: Iterable[dict[str, Any]], path: str | os.PathLike[str]) -> None:
    """Write rows as CSV (one per file, sorted by input; the fields of :data:`SUMMARY_FIELDS`
    any row has, then the others), atomically."""
    import io

    from tagbot.io.output import write_atomic

    rows = sorted(rows, key=lambda r: str(r.get("input", "")))
    present = {k for r in rows for k in r}
    names = [f for f in SUMMARY_FIELDS if f in present] + sorted(
        present - set(SUMMARY_FIELDS) - {"summary"}
    )
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, names, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _cell(row.get(k)) for k in names})
    write_atomic(path, text.getvalue().encode("utf-8"))


def _cell(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.6g}"
    return value
