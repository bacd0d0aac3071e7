"""``tagbot draw``: a tag on a machine, and a run folder saying what happened.

:func:`draw` runs a back end chosen by name from :data:`DEVICES` (imported lazily: ``grbl``, the
pen plotter; ``dynamixel``, the servo arm), each simulated unless a port is named, and writes
the run folder:

- ``plan.json``: the tag drawn (tag units);
- ``motion.csv``: planned setpoints in machine mm, ``t,x,y,vx,vy,speed,pen``;
- ``program.gcode`` (plotter) or ``joints.csv`` (arm): what was sent;
- ``executed.csv``: ``t,x,y,pen`` as the machine did it (the simulator's recorder at 1 ms, or
  the positions the machine reported);
- ``report.json``: the device's figures (lines or ticks sent and acknowledged, errors,
  durations...) and the comparison of executed against planned: path deviation mean/max (mm),
  speed SNR (dB), drawing durations and the time alignment of each pen-down run;
- pictures (``tag.png``, ``speed.png``, ``plan.png``) when the rendering extras are installed.

The folder is written even when the machine stops on a fault or Ctrl-C; the error is then in
``report.json`` and raised again.
"""

from __future__ import annotations

import importlib
import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tagbot.errors import InputError
from tagbot.io.motionfile import MotionTable, write_motion_csv
from tagbot.io.planfile import save_plan
from tagbot.metrics import compare_execution
from tagbot.model import Tag

__all__ = ["DEVICES", "DrawResult", "MachineRun", "draw", "write_executed_csv"]

DEVICES: dict[str, str] = {
    "grbl": "tagbot.plotter.machine:draw_backend",
    "dynamixel": "tagbot.arm:draw_backend",
}
"""Back ends by name: ``module:function`` taking ``(tag, out, profile=, overrides=, port=,
progress=, **options)`` and returning a :class:`MachineRun`."""


@dataclass
class MachineRun:
    """What a back end planned and what the machine did, for the run folder and its report."""

    device: str
    motion: MotionTable
    """Planned setpoints in machine mm: t, xy, v, speed, pen."""
    planned_runs: list[tuple[np.ndarray, np.ndarray]]
    """Per pen-down run: planned times and positions."""
    plans: list[int]
    executed: np.ndarray
    """``(N, 4)``: t, x, y, pen as executed (empty if nothing ran)."""
    placement: dict[str, Any]
    report: dict[str, Any] = field(default_factory=dict)
    error: BaseException | None = None
    """The fault that stopped the run (re-raised once the run folder is written)."""


@dataclass(frozen=True)
class DrawResult:
    """Where the run folder is and what its report says."""

    folder: Path
    report: dict[str, Any]


def draw(
    tag: Tag,
    out: str | Path,
    *,
    device: str = "grbl",
    port: str | None = None,
    profile: str | Path | None = None,
    overrides: tuple[str, ...] = (),
    progress: Callable[[int, int], None] | None = None,
    pictures: bool = True,
    **options: Any,
) -> DrawResult:
    """Draw ``tag`` on ``device`` (simulated unless ``port`` is given); write the run folder."""
    backend = _backend(device)
    folder = Path(out)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{folder}: cannot create the run folder ({e.strerror or e})") from e
    save_plan(tag, folder / "plan.json")
    run = backend(
        tag, folder, profile=profile, overrides=overrides, port=port, progress=progress, **options
    )
    write_motion_csv(run.motion, folder / "motion.csv")
    write_executed_csv(run.executed, folder / "executed.csv")
    report: dict[str, Any] = {"device": run.device, **run.report, "placement": run.placement}
    if run.executed.size and run.planned_runs:
        try:
            comparison = compare_execution(run.planned_runs, run.executed, plans=run.plans)
        except ValueError as e:  # nothing was drawn (a fault before the first pen-down)
            report["comparison_error"] = str(e)
        else:
            report.update(comparison.as_dict())
    _write_json(folder / "report.json", report)
    if pictures and run.error is None:
        report["pictures"] = [str(p.name) for p in _pictures(folder)]
        _write_json(folder / "report.json", report)
    if run.error is not None:
        raise run.error
    return DrawResult(folder, report)


def _backend(name: str) -> Callable[..., Any]:
    if name not in DEVICES:
        raise InputError(f"device: unknown {name!r} (known: {', '.join(sorted(DEVICES))})")
    module, _, function = DEVICES[name].partition(":")
    return getattr(importlib.import_module(module), function)


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
