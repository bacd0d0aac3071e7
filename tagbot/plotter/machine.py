"""The pen plotter as a ``tagbot draw`` back end: place, program, stream, record.

:func:`run_grbl` places and retimes the tag (refused before any byte if it leaves the bed),
writes ``program.gcode``, opens the port (a simulated Grbl when none is named: the default
never moves hardware), streams the program with :class:`~tagbot.plotter.stream.GrblStreamer`
and returns what was planned and what was executed, for the run folder.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import serial

from tagbot.draw import MachineRun
from tagbot.errors import ConnectionLost, DeviceError
from tagbot.io.motionfile import MotionTable
from tagbot.model import Tag
from tagbot.plotter.place import Setpoints, place
from tagbot.plotter.profile import Profile, device_settings, with_device_settings
from tagbot.plotter.program import Program, build_program, pen_down, pen_up
from tagbot.plotter.stream import GrblStreamer, StreamOptions, StreamReport, resume_lines

__all__ = ["draw_backend", "executed_from_statuses", "run_grbl", "setpoint_motion"]

_names = itertools.count()


def setpoint_motion(setpoints: Setpoints) -> MotionTable:
    """The pen-down setpoints of every run, one table (pen = 1 throughout)."""
    t = np.concatenate([r.t for r in setpoints.runs])
    xy = np.concatenate([r.xy for r in setpoints.runs])
    v = np.concatenate([r.v for r in setpoints.runs])
    return MotionTable(t, xy, v, np.hypot(v[:, 0], v[:, 1]), np.ones(len(t), dtype=np.int8))


def placement_of(setpoints: Setpoints) -> dict[str, Any]:
    return {
        "mm_per_unit": setpoints.size,
        "time_scale": setpoints.scale,
        "matrix": setpoints.matrix.tolist(),
        "offset": setpoints.offset.tolist(),
        "limits": dict(setpoints.limits),
    }


def run_grbl(
    tag: Tag,
    out: Path,
    *,
    profile: Profile,
    port: str | None = None,
    options: StreamOptions | None = None,
    resume_from: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> MachineRun:
    """Draw ``tag`` on a Grbl plotter (simulated unless ``port`` names one).

    ``resume_from`` (1-based line of ``program.gcode``) resumes an interrupted job; the caller
    vouches that the machine's position is known. Device faults are caught, the machine left
    safe, and returned in :attr:`MachineRun.error` with what was executed until then.
    """
    setpoints = place(tag, profile)
    program = build_program(setpoints, profile)
    program.write(out / "program.gcode")
    device = None
    if port is None:
        from sim.grbl import SimulatedGrbl
        from sim.grbl.transport import attach_device

        device = SimulatedGrbl(device_settings(profile), **simulated_pen(profile))
        url = attach_device(device, f"draw{os.getpid()}_{next(_names)}")
    else:
        url = port
        if url.startswith("grblsim://"):
            import sim.grbl.transport  # noqa: F401  (registers the URL scheme)
    streamer: GrblStreamer | None = None
    error: BaseException | None = None
    try:
        link = serial.serial_for_url(url, baudrate=profile["serial.baud"], timeout=0.01)
    except (serial.SerialException, OSError, ValueError) as e:
        raise ConnectionLost(f"cannot open {url}: {e}") from e
    try:
        streamer = GrblStreamer(link, options)
        settings = streamer.connect()
        if profile["limits.from_device"]:
            profile = with_device_settings(profile, settings)
            setpoints = place(tag, profile)
            program = build_program(setpoints, profile)
            program.write(out / "program.gcode")
        first, preamble = 0, []
        if resume_from is not None:
            first = resume_from - 1
            preamble = resume_lines(program.lines, first, pen_up(profile), pen_down(profile))
        streamer.stream(
            program.lines, first=first, preamble=preamble, pen_up=pen_up(profile), progress=progress
        )
    except (DeviceError, KeyboardInterrupt) as e:
        error = e
    finally:
        link.close()
    stream = streamer.last_report if streamer is not None else None
    if device is not None:
        executed = device.trace(0.001)[:, [0, 1, 2, 4]]
    else:
        executed = executed_from_statuses(stream.statuses if stream else [], profile)
    return MachineRun(
        device="grbl",
        motion=setpoint_motion(setpoints),
        planned_runs=[(r.t, r.xy) for r in setpoints.runs],
        plans=[r.plan for r in setpoints.runs],
        executed=executed,
        placement=placement_of(setpoints),
        report=_report(program, profile, stream, device, url, error),
        error=error,
    )


def simulated_pen(profile: Profile) -> dict[str, Any]:
    """The pen arguments of a :class:`~sim.grbl.SimulatedGrbl` matching ``profile``."""
    up, down = profile["pen.up"], profile["pen.down"]
    start = (profile["motion.park_x"], profile["motion.park_y"])
    if profile["pen.type"] == "z":
        return {"pen": "z", "pen_z_below": (up + down) / 2, "position_mm": (*start, up)}
    return {"pen": "spindle", "pen_servo": (down, up), "position_mm": (*start, 0.0)}


def executed_from_statuses(statuses: list[tuple[float, Any]], profile: Profile) -> np.ndarray:
    """``(N, 4)`` t, x, y, pen from status reports (a real machine: ≤ 5 Hz, coarse)."""
    rows = []
    wco = (0.0, 0.0, 0.0)
    up, down = profile["pen.up"], profile["pen.down"]
    for t, status in statuses:
        if status.wco is not None:
            wco = status.wco
        if status.mpos is not None:
            pos = status.mpos
        elif status.wpos is not None:
            pos = tuple(w + o for w, o in zip(status.wpos, wco, strict=False))
        else:
            continue
        if profile["pen.type"] == "z":
            pen = len(pos) > 2 and abs(pos[2] - down) < abs(pos[2] - up)
        else:
            s = status.spindle
            pen = s is not None and s > 0 and abs(s - down) < abs(s - up)
        rows.append((t, pos[0], pos[1], float(pen)))
    return np.array(rows, dtype=float).reshape(-1, 4)


def _report(
    program: Program,
    profile: Profile,
    stream: StreamReport | None,
    device: Any,
    url: str,
    error: BaseException | None,
) -> dict[str, Any]:
    baud = profile["serial.baud"]
    report: dict[str, Any] = {
        "port": "simulator" if device is not None else url,
        "lines_total": len(program.lines),
        "planned_duration_s": program.duration,
        "program_drawing_s": program.drawing_time,
        "time_scale": program.scale,
        "dt": profile.dt,
        "baud": baud,
    }
    if stream is not None:
        duration = max(stream.duration, 1e-9)
        report.update(
            {
                "first_line": stream.first_line + 1,
                "lines_sent": stream.lines_sent,
                "lines_acknowledged": stream.lines_acknowledged,
                "errors": list(stream.errors),
                "stopped_at_line": None if stream.stopped_at is None else stream.stopped_at + 1,
                "executed_duration_s": stream.duration,
                "duration_ratio": stream.duration / program.duration if program.duration else None,
                "bytes_sent": stream.bytes_sent,
                "max_outstanding_bytes": stream.max_outstanding,
                "stream_rate_bytes_per_s": stream.bytes_sent / duration,
                "baud_limit_bytes_per_s": baud / 10,
                "status_reports": len(stream.statuses),
            }
        )
    if error is not None:
        report["error"] = str(error) or type(error).__name__
    report["starvation_events"] = len(device.starvation) if device is not None else None
    return report


def draw_backend(
    tag: Tag,
    out: Path,
    *,
    profile: str | Path | None = None,
    overrides: tuple[str, ...] = (),
    port: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    mode: str = "count",
    unlock: str = "never",
    reset: bool = True,
    resume_from: int | None = None,
) -> MachineRun:
    """:func:`run_grbl` with the profile loaded by name; the ``grbl`` entry of ``tagbot draw``."""
    from tagbot.plotter.profile import load_profile

    machine = load_profile(profile, overrides)
    options = StreamOptions(mode=mode, unlock=unlock, reset=reset)
    return run_grbl(
        tag,
        out,
        profile=machine,
        port=port,
        options=options,
        resume_from=resume_from,
        progress=progress,
    )
