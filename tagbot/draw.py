"""``tagbot draw``: a tag on a machine, and a run folder saying what happened.

A back end is chosen by name from :data:`DEVICES` (imported lazily: ``grbl``, the pen plotter;
``dynamixel``, the servo arm; ``axidraw``, the EiBotBoard plotter). Each provides
``prepare(tag, *, profile, overrides, port, **options)``, which loads the profile, places,
retimes and checks the whole job and checks the port's name (:func:`tagbot.ports.check_port`)
*without writing a file or sending a byte*, and returns a :class:`PreparedRun`; its
``run(out, progress=, control=)`` then drives the machine (simulated unless a port is named)
and returns a :class:`MachineRun`, also after a fault or
Ctrl-C (with :attr:`MachineRun.error` set: the machine was stopped safely first).

:func:`draw` prepares first, so every refusal happens before the run folder exists, then writes
the run folder, the same for both devices:

- ``plan.json``: the tag drawn (tag units);
- ``motion.csv``: the whole planned timeline in machine mm on the job's clock (0 = when the job
  starts), pen-up travel and pen moves included, ``t,x,y,vx,vy,speed,pen`` (pen 0 up, 1 down);
- ``program.gcode`` (plotter) or ``joints.csv`` (arm): what is sent;
- ``executed.csv``: ``t,x,y,pen`` on the same clock, as the machine did it: the simulator's
  1 ms recorder, or what the machine reported (Grbl status reports, servo read-backs);
- ``report.json``: what happened (see :func:`run_report`: the same keys for both devices, with
  the device's own figures under ``details``), and the comparison of executed against planned;
- pictures (``tag.png``, the plan's ink; ``executed.png`` and ``execution.png``, what the machine
  drew and both overlaid; ``speed.png``, ``plan.png``) when the rendering extras are installed.

``plan.json`` and ``motion.csv`` are written before the machine starts, ``report.json`` in every
case: a run folder is complete, or its ``report.json`` says what happened.
"""

from __future__ import annotations

import importlib
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from tagbot.control import RunControl
from tagbot.errors import InputError
from tagbot.io.motionfile import MotionTable, write_motion_csv
from tagbot.io.planfile import save_plan
from tagbot.metrics import (
    compare_execution,
    compare_reports,
    compare_with_recording,
    without_pauses,
)
from tagbot.model import Tag

__all__ = [
    "DEVICES",
    "DrawResult",
    "MachineRun",
    "PreparedRun",
    "Progress",
    "draw",
    "prepare",
    "run_report",
    "write_executed_csv",
]

DEVICES: dict[str, str] = {
    "grbl": "tagbot.plotter.machine:prepare",
    "dynamixel": "tagbot.arm.run:prepare",
    "axidraw": "tagbot.axidraw.machine:prepare",
}
"""Back ends by name: ``module:function`` of their ``prepare``."""

Progress = Callable[[int, int], None]
"""``progress(executed, total)``: program lines (plotter), ticks (arm) or moves (AxiDraw) the
machine has executed so far, out of the job's total."""


@dataclass
class MachineRun:
    """What a back end planned and what the machine did, for the run folder and its report."""

    device: str
    motion: MotionTable
    """The whole planned timeline in machine mm (travel and pen moves included, pen 0/1)."""
    planned_runs: list[tuple[np.ndarray, np.ndarray]]
    """Per pen-down run: planned times and positions (the job's clock)."""
    plans: list[int]
    """The plan (index in the tag) of each pen-down run."""
    executed: np.ndarray
    """``(N, 4)``: t, x, y, pen as executed, on the job's clock (empty if nothing ran)."""
    executed_source: str
    """How :attr:`executed` was obtained, e.g. ``"simulator recorder, 1 ms"``, ``"status
    reports, 5 Hz"``, ``"read-back, 100 Hz"``."""
    sparse: bool
    """True when :attr:`executed` holds the machine's own reports (a few per second): the
    report then compares like with like, planned positions at the reported instants."""
    executed_runs: np.ndarray | None
    """With :attr:`sparse`: the pen-down run (index in :attr:`planned_runs`) of each executed
    sample, -1 for none; else None (runs are found from the pen column)."""
    unit: str
    """``"line"`` (1-based line of program.gcode), ``"tick"`` (row of joints.csv) or ``"move"``
    (line of moves.txt)."""
    total: int
    """Lines or ticks in the job."""
    sent: int
    executed_steps: int
    """How many lines or ticks the machine executed: the last executed one, counting from 1."""
    resume_from: int | None
    """The line to resume from after a stop (plotter), or None."""
    planned_duration: float
    """The job's planned duration, s (travel and pen moves included)."""
    executed_duration: float
    """The job as it ran, s: pauses and host stalls included."""
    placement: dict[str, Any]
    port: str
    """The port as named, or ``"simulator"``."""
    details: dict[str, Any] = field(default_factory=dict)
    """The device's own figures (acknowledged lines, buffer levels, read-back misses...)."""
    warnings: list[str] = field(default_factory=list)
    error: BaseException | None = None
    """The fault that stopped the run (re-raised once the run folder is written)."""
    pauses: list[tuple[float, float]] = field(default_factory=list)
    """Pauses asked for, ``(start, length)`` s on the executed clock: named in the report and
    left out of the comparison (see :func:`tagbot.metrics.compare_execution`)."""
    stalls: list[tuple[float, float]] = field(default_factory=list)
    """Host stalls, ``(start, length)`` s on the executed clock: times the host sent nothing
    the machine needed (beyond what the device's own catch-up absorbs). Named in the report
    and kept in the comparison's timeline."""
    until: float | None = None
    """After a stop: the planned time the machine had drawn to (the comparison cuts the plan
    there); None when the job ran to its end."""
    judge: Callable[[dict[str, Any]], list[str]] | None = None
    """The device's own budgets: given the report (with its comparison), the warnings for
    every figure outside them, each naming the run, the figure and the cause."""
    ramp: float = 0.0
    """s the machine takes to regain the planned speed after a pause it holds with the pen down
    (a plotter's feed hold): left out of the velocity comparison after each pause."""


class PreparedRun(Protocol):
    """A job checked and ready to go (nothing written, nothing sent yet)."""

    device: str
    planned: MotionTable
    """The whole planned timeline, as :attr:`MachineRun.motion`."""

    def run(
        self, out: Path, *, progress: Progress | None = None, control: RunControl | None = None
    ) -> MachineRun: ...


@dataclass(frozen=True)
class DrawResult:
    """Where the run folder is and what its report says."""

    folder: Path
    report: dict[str, Any]


def prepare(
    tag: Tag,
    *,
    device: str = "grbl",
    port: str | None = None,
    profile: str | Path | None = None,
    overrides: tuple[str, ...] = (),
    **options: Any,
) -> PreparedRun:
    """Check everything about drawing ``tag`` on ``device`` (profile, placement, limits, port)
    and return the job, ready to :func:`draw`; raises before anything is written or sent."""
    backend = _backend(device)
    return backend(tag, profile=profile, overrides=overrides, port=port, **options)  # type: ignore[no-any-return]


def draw(
    tag: Tag,
    out: str | Path,
    *,
    device: str = "grbl",
    port: str | None = None,
    profile: str | Path | None = None,
    overrides: tuple[str, ...] = (),
    progress: Progress | None = None,
    control: RunControl | None = None,
    pictures: bool = True,
    prepared: PreparedRun | None = None,
    recorded: Sequence[Any] | None = None,
    **options: Any,
) -> DrawResult:
    """Draw ``tag`` on ``device`` (simulated unless ``port`` is given); write the run folder.

    ``prepared`` (from :func:`prepare`) skips the preparation; otherwise it happens here, before
    the folder is created. A fault or Ctrl-C is raised again once the folder is written.
    ``recorded``: the traces ``tag`` was fitted from (one per plan); with timing, the report
    also compares the executed speed with the recorded one (:func:`run_report`).
    """
    job = prepared or prepare(
        tag, device=device, port=port, profile=profile, overrides=overrides, **options
    )
    folder = Path(out)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{folder}: cannot create the run folder ({e.strerror or e})") from e
    save_plan(tag, folder / "plan.json")
    write_motion_csv(job.planned, folder / "motion.csv")
    try:
        run = job.run(folder, progress=progress, control=control)
    except BaseException as e:  # a bug or a fault the back end could not turn into a run
        _write_json(
            folder / "report.json",
            {"device": job.device, "completed": False, "error": str(e) or type(e).__name__},
        )
        raise
    write_motion_csv(run.motion, folder / "motion.csv")
    write_executed_csv(run.executed, folder / "executed.csv")
    report = run_report(run, recorded)
    _write_json(folder / "report.json", report)
    if pictures and run.error is None:
        report["pictures"] = [str(p.name) for p in _pictures(folder)]
        _write_json(folder / "report.json", report)
    if run.error is not None:
        raise run.error
    return DrawResult(folder, report)


def run_report(run: MachineRun, recorded: Sequence[Any] | None = None) -> dict[str, Any]:
    """``report.json``: the same keys for both devices.

    ``device``, ``port``, ``simulated``, ``completed``, ``error``, ``warnings``, ``unit``
    (``line``/``tick``), ``total``, ``sent``, ``executed`` (the last line or tick the machine
    executed, from 1), ``resume_from``, ``planned_duration_s``, ``executed_duration_s`` (pauses
    and stalls included), ``paused_s``, ``pauses``, ``longest_pause_s`` (pauses asked for: their
    total, count and longest, s), ``stalled_s``, ``stalls``, ``longest_stall_s`` (host stalls, the
    same), ``executed_source``, ``placement``, the comparison (``path_deviation_mean_mm``,
    ``path_deviation_max_mm``, ``speed_snr_db``, drawing durations, per-run figures; or
    ``comparison_error`` when nothing was drawn) and ``details`` (the device's own figures).
    With ``recorded`` traces (timed), also ``recorded_speed_snr_db`` and ``recorded_runs``: the
    executed speed against the *recorded* one (:func:`tagbot.metrics.compare_with_recording`);
    for a sparse trace (a real machine's status reports), ``recorded_comparison_error`` says why
    there is none.
    """
    report: dict[str, Any] = {
        "device": run.device,
        "port": run.port,
        "simulated": run.port == "simulator",
        "completed": run.error is None,
        "error": None if run.error is None else (str(run.error) or type(run.error).__name__),
        "warnings": list(run.warnings),
        "unit": run.unit,
        "total": run.total,
        "sent": run.sent,
        "executed": run.executed_steps,
        "resume_from": run.resume_from,
        "planned_duration_s": run.planned_duration,
        "executed_duration_s": run.executed_duration,
        **_holes("paused_s", "pauses", "longest_pause_s", run.pauses),
        **_holes("stalled_s", "stalls", "longest_stall_s", run.stalls),
        "executed_source": run.executed_source,
        "placement": run.placement,
    }
    if run.executed.size and run.planned_runs:
        try:
            if run.sparse and run.executed_runs is not None:
                # Reports taken during a pause left out, later ones moved back (as for a
                # recorder's trace, below): a pause is no drawing time.
                t = run.executed[:, 0] if run.executed.ndim == 2 else np.zeros(0)
                kept = np.ones(len(t), dtype=bool)
                for start, length in run.pauses:
                    kept &= (t < start) | (t >= start + length)
                comparison = compare_reports(
                    run.planned_runs,
                    without_pauses(run.executed, run.pauses),
                    np.asarray(run.executed_runs)[kept],
                    plans=run.plans,
                    until=run.until,
                )
            else:
                comparison = compare_execution(
                    run.planned_runs,
                    run.executed,
                    plans=run.plans,
                    pauses=run.pauses,
                    until=run.until,
                    ramp=run.ramp,
                )
        except ValueError as e:  # nothing was drawn (a fault before the first pen-down)
            report["comparison_error"] = str(e)
        else:
            report.update(comparison.as_dict())
            if run.judge is not None:
                report["warnings"] += run.judge(report)
    else:
        report["comparison_error"] = "nothing was executed"
    if recorded is not None and run.sparse:
        report["recorded_comparison_error"] = (
            "the executed trace is the device's status reports (a few a second): too sparse"
            " for a speed to compare with the recording's"
        )
    elif recorded is not None and run.executed.size:
        try:
            executed = without_pauses(run.executed, run.pauses)
            report.update(compare_with_recording(executed, recorded, run.plans))
        except ValueError as e:
            report["recorded_comparison_error"] = str(e)
    report["details"] = run.details
    return report


def _holes(
    total: str, count: str, longest: str, holes: Sequence[tuple[float, float]]
) -> dict[str, Any]:
    """The total, count and longest of ``(start, length)`` intervals, under those keys."""
    lengths = [float(length) for _, length in holes]
    return {total: sum(lengths), count: len(lengths), longest: max(lengths, default=0.0)}


def _backend(name: str) -> Callable[..., Any]:
    if name not in DEVICES:
        raise InputError(f"device: unknown {name!r} (known: {', '.join(sorted(DEVICES))})")
    module, _, function = DEVICES[name].partition(":")
    return getattr(importlib.import_module(module), function)  # type: ignore[no-any-return]


def _pictures(folder: Path) -> list[Path]:
    try:
        from tagbot.render import pictures_for_run
    except ImportError:  # rendering needs the plotting libraries
        return []
    return list(pictures_for_run(folder))


def write_executed_csv(executed: np.ndarray, path: Path) -> None:
    """``t,x,y,pen`` rows (pen 0 or 1)."""
    data = np.asarray(executed, dtype=float).reshape(-1, 4)
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write("t,x,y,pen\n")
        for row in data.tolist():
            f.write(f"{row[0]:.6f},{row[1]:.6f},{row[2]:.6f},{int(row[3] > 0.5)}\n")


def _write_json(path: Path, data: dict[str, Any]) -> None:
    path.write_text(json.dumps(_plain(data), indent=2) + "\n", encoding="utf-8")


def _plain(value: Any) -> Any:
    """JSON-ready: numpy scalars to Python, non-finite floats to None."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
