"""The pen plotter as a ``tagbot draw`` back end: check, program, stream, record.

:func:`prepare` loads the profile, places and retimes the tag (refused before any byte if it
leaves the bed), builds the program and checks the port's name: nothing is written or sent.
:meth:`PlotterJob.run` then writes ``program.gcode``, opens the port (a simulated Grbl when none
is named: the default never moves hardware), streams the program with
:class:`~tagbot.plotter.stream.GrblStreamer` and returns what was planned and what was executed.

**The executed trace.** On the simulator it is the device's own 1 ms recorder. On a real machine
it is the status reports (≤ 5 Hz): the position Grbl reports (``MPos``, or ``WPos`` + ``WCO``),
with the pen and the pen-down run taken from the program at the line the machine was executing
then (:class:`~tagbot.plotter.stream.ExecutionTracker`), not from the spindle value. The report
then compares like with like: reported positions against the planned positions at the reported
instants (:func:`tagbot.metrics.compare_reports`).
"""

from __future__ import annotations

import itertools
import logging
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import serial

from tagbot.control import RunControl
from tagbot.draw import MachineRun, Progress
from tagbot.errors import ConnectionLost, DeviceError, InputError, Interrupted
from tagbot.io.motionfile import MotionTable
from tagbot.model import Tag
from tagbot.plotter.place import RX_LINES, Setpoints, place
from tagbot.plotter.profile import Profile, device_settings, load_profile, with_device_settings
from tagbot.plotter.program import (
    Program,
    build_program,
    host_pause_warnings,
    pen_down,
    pen_up,
)
from tagbot.plotter.stream import (
    GrblStreamer,
    StreamOptions,
    StreamReport,
    executed_where,
    resume_lines,
    resume_point,
)
from tagbot.ports import check_port
from tagbot.signals import label, signal_of

log = logging.getLogger(__name__)

__all__ = ["PlotterJob", "executed_from_statuses", "prepare", "simulated_pen"]

_names = itertools.count()

TIMELINE_STEP = 0.01
"""s between the samples of motion.csv's planned timeline (setpoints are exact in it)."""


def placement_of(setpoints: Setpoints, program: Program) -> dict[str, Any]:
    """Tag to machine: the transform, and each run's clock (``start + scale·(τ − tag_start)``)."""
    runs = [
        {
            "plan": run.plan,
            "scale": float(run.scale),
            "tag_start": float(run.clock.tag_start),
            "start": float(planned[0][0]),
        }
        for run, planned in zip(setpoints.runs, program.planned_runs, strict=True)
    ]
    return {
        "runs": runs,
        "mm_per_unit": setpoints.size,
        "time_scale": setpoints.scale,
        "run_scales": [float(s) for s in getattr(setpoints, "run_scales", ())],
        "matrix": setpoints.matrix.tolist(),
        "offset": setpoints.offset.tolist(),
        "limits": dict(setpoints.limits),
    }


def prepare(
    tag: Tag,
    *,
    profile: str | Path | None = None,
    overrides: tuple[str, ...] = (),
    port: str | None = None,
    mode: str = "count",
    unlock: str = "never",
    reset: bool = True,
    resume_from: int | None = None,
    line_numbers: str = "auto",
) -> PlotterJob:
    """Everything checked before anything starts: profile, placement, bed, limits, the program,
    the stream options, the resume line and the port's name. Raises; writes and sends nothing.

    ``resume_from`` (1-based line of ``program.gcode``) resumes an interrupted job; the caller
    vouches that the machine's position is known.
    """
    machine = load_profile(profile, overrides)
    if port is not None:
        check_port(port)
    try:
        options = StreamOptions(mode=mode, unlock=unlock, reset=reset, line_numbers=line_numbers)
    except ValueError as e:
        raise InputError(f"stream options: {e}") from None
    setpoints = place(tag, machine)
    program = build_program(setpoints, machine)
    for warning in host_pause_warnings(program, machine):
        log.warning("%s", warning)
    if resume_from is not None and not 2 <= resume_from <= len(program.lines):
        raise InputError(
            f"--resume-from: line {resume_from} is not in the program (lines 2 to "
            f"{len(program.lines)})"
        )
    return PlotterJob(tag, machine, setpoints, program, port, options, resume_from)


@dataclass(eq=False)
class PlotterJob:
    """A checked plotter job (see :func:`prepare`); :meth:`run` draws it."""

    tag: Tag
    profile: Profile
    setpoints: Setpoints
    program: Program
    port: str | None
    options: StreamOptions
    resume_from: int | None = None
    device: str = "grbl"
    planned: MotionTable = field(init=False)

    def __post_init__(self) -> None:
        self.planned = self.program.timeline(TIMELINE_STEP)

    def run(
        self, out: Path, *, progress: Progress | None = None, control: RunControl | None = None
    ) -> MachineRun:
        """Stream the program (simulated unless a port was named) and record what ran.

        Device faults and Ctrl-C are caught after the safe stop and returned in
        :attr:`MachineRun.error`, naming the last line the machine executed.
        """
        profile, program, setpoints = self.profile, self.program, self.setpoints
        program.write(out / "program.gcode")
        device = None
        if self.port is None:
            from sim.grbl import SimulatedGrbl
            from sim.grbl.transport import attach_device

            device = SimulatedGrbl(device_settings(profile), **simulated_pen(profile))
            url = attach_device(device, f"draw{os.getpid()}_{next(_names)}")
        else:
            url = self.port
        streamer: GrblStreamer | None = None
        error: BaseException | None = None
        lines = list(program.lines)
        first = 0
        try:
            link = serial.serial_for_url(url, baudrate=profile["serial.baud"], timeout=0.01)
        except (serial.SerialException, OSError, ValueError) as e:
            raise ConnectionLost(f"cannot open {url}: {e}") from e
        try:
            streamer = GrblStreamer(link, self.options)
            settings = streamer.connect()
            if profile["limits.from_device"]:
                profile = with_device_settings(profile, settings)
                setpoints = place(self.tag, profile)
                program = build_program(setpoints, profile)
                program.write(out / "program.gcode")
                lines = list(program.lines)
            preamble: list[str] = []
            if self.resume_from is not None:
                first = self.resume_from - 1
                here = streamer.query_state()
                at = None if here.mpos is None else (here.mpos[0], here.mpos[1])
                inside = resume_point(lines, first, at)
                start = None
                if inside is not None:
                    lines[first], start = inside
                preamble = resume_lines(lines, first, pen_up(profile), pen_down(profile), start)
            streamer.stream(
                lines,
                first=first,
                preamble=preamble,
                pen_up=pen_up(profile),
                progress=progress,
                moves=program.line_moves,
                targets=program.line_xy,
                control=control,
                drawing=program.line_run >= 0,
            )
        except DeviceError as e:
            error = e
        except KeyboardInterrupt as e:
            stream = streamer.last_report if streamer is not None else None
            error = Interrupted(f"interrupted ({label(signal_of(e))})", _where(stream))
        finally:
            link.close()
        stream = streamer.last_report if streamer is not None else None
        pen = simulated_pen(profile)
        executed, runs = _executed(stream, device, program, first, pen.get("pen_z_below"))
        planned_runs, plans, runs = _from_line(program, first, runs)
        done = stream.lines_executed if stream is not None else first
        origin = stream.started if stream is not None else 0.0
        return MachineRun(
            device="grbl",
            motion=program.timeline(TIMELINE_STEP),
            planned_runs=planned_runs,
            plans=plans,
            executed=executed,
            executed_runs=runs,
            executed_source=(
                "simulator recorder, 1 ms"
                if device is not None
                else f"status reports, {self.options.poll_rate:g} Hz"
                + (f" ({stream.tracking})" if stream is not None and stream.tracking else "")
            ),
            sparse=device is None,
            unit="line",
            total=len(lines),
            sent=first + (stream.lines_sent if stream is not None else 0),
            executed_steps=done,
            resume_from=done + 1 if error is not None and 0 < done < len(lines) else None,
            planned_duration=program.duration,
            executed_duration=stream.duration if stream is not None else 0.0,
            placement=placement_of(setpoints, program),
            port="simulator" if device is not None else url,
            details=_details(program, profile, stream, device),
            warnings=[
                *host_pause_warnings(program, profile),
                *(stream.warnings if stream is not None else []),
            ],
            error=error,
            pauses=[(a - origin, n) for a, n in stream.pause_spans] if stream is not None else [],
            stalls=[(a - origin, n) for a, n in stream.stall_spans] if stream is not None else [],
            until=None if error is None else _drawn_until(program, done, executed),
            ramp=_ramp(program, profile),
        )


def _from_line(
    program: Program, first: int, runs: np.ndarray | None
) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[int], np.ndarray | None]:
    """The planned runs (and their plans) of a job resumed at line ``first``: what is left of
    each from that line's start on; ``runs`` (executed samples' run indices) renumbered."""
    planned, plans = list(program.planned_runs), list(program.run_plans)
    if first == 0:
        return planned, plans, runs
    start = float(program.line_start[first])
    kept: list[tuple[np.ndarray, np.ndarray]] = []
    kept_plans: list[int] = []
    index = {}
    for k, (t, xy) in enumerate(planned):
        rest = t >= start - 1e-9
        if rest.sum() >= 2:
            index[k] = len(kept)
            kept.append((t[rest], xy[rest]))
            kept_plans.append(plans[k])
    if runs is not None:
        runs = np.array([index.get(int(r), -1) for r in runs], dtype=int)
    return kept, kept_plans, runs


def _where(stream: StreamReport | None) -> str:
    if stream is None:
        return "before line 1 (nothing of the program was executed)"
    return executed_where(stream, stream.lines_executed - stream.first_line)


def _ramp(program: Program, profile: Profile) -> float:
    """s Grbl takes to stop from, or regain, the fastest drawing speed of ``program`` at the
    lower axis acceleration: what a feed hold costs the motion around it."""
    runs = program.line_run >= 0
    if not runs.any():
        return 0.0
    before = np.vstack([program.notes_start[None, :], program.line_xy[:-1]])
    length = np.hypot(*(program.line_xy - before)[runs].T)
    span = (program.line_end - program.line_start)[runs]
    fastest = float(np.max(np.where(span > 0, length / np.where(span > 0, span, 1.0), 0.0)))
    return fastest / float(min(profile.max_acceleration))


def _drawn_until(program: Program, done: int, executed: np.ndarray) -> float:
    """The planned job time the machine had drawn to when it stopped: at the last executed
    position's place along line ``done`` (0-based, the one executing by the last report), or
    along a later queued line of the same run where that position lies nearer (the report
    that counted the lines may be a line behind the machine)."""
    if done >= len(program.lines):
        return program.duration
    start, end = float(program.line_start[done]), float(program.line_end[done])
    if not len(executed) or not program.line_moves[done] or end <= start:
        return start
    here = executed[-1, 1:3]
    run = program.line_run[done]
    best: tuple[float, float] | None = None
    for k in range(done, len(program.lines)):
        if k > done and (program.line_run[k] != run or run < 0):
            break
        a = program.line_xy[k - 1] if k else program.notes_start
        d = program.line_xy[k] - a
        length2 = float(d @ d)
        along = min(1.0, max(0.0, float((here - a) @ d / length2))) if length2 > 0 else 0.0
        gap = float(np.hypot(*(a + along * d - here)))
        if best is None or gap < best[0] - 1e-9:
            t0, t1 = float(program.line_start[k]), float(program.line_end[k])
            best = (gap, t0 + along * (t1 - t0))
        if k - done >= _QUEUED_LINES:
            break
    assert best is not None
    return best[1]


_QUEUED_LINES = 15 + RX_LINES
"""Lines the machine may hold beyond the one a status report names (Grbl's 15 planner blocks and
the lines in its receive buffer): how far :func:`_drawn_until` looks."""


def _executed(
    stream: StreamReport | None,
    device: Any,
    program: Program,
    first: int,
    pen_z_below: float | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """The executed trace on the job's clock, and the pen-down run of each sample (or None)."""
    if stream is None:
        return np.zeros((0, 4)), None
    if device is not None:
        trace = device.trace(0.001)[:, [0, 1, 2, 4]]
        trace[:, 0] -= stream.started
        return trace[trace[:, 0] >= 0], None
    return executed_from_statuses(stream, program, first, pen_z_below)


def executed_from_statuses(
    stream: StreamReport, program: Program, first: int = 0, pen_z_below: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(N, 4)`` t, x, y, pen from status reports, and each report's pen-down run (-1: none).

    Positions are what Grbl reported (``MPos``, or ``WPos`` plus the last ``WCO``); the pen
    and the run are the program's at the line the machine was executing then. With a Z pen
    (``pen_z_below``: the height between up and down) a report whose Z is at or above it is
    pen up whatever the line: the executing line a report names may be a block behind, and a
    Z move is never drawing.
    """
    rows: list[tuple[float, float, float, float]] = []
    runs: list[int] = []
    wco = (0.0, 0.0, 0.0)
    pen = np.asarray(program.line_pen, dtype=bool)
    run_of = np.asarray(program.line_run, dtype=int)
    for (t, status), done in zip(stream.statuses, stream.executing, strict=False):
        if status.wco is not None:
            wco = status.wco
        if status.mpos is not None:
            pos = status.mpos
        elif status.wpos is not None:
            pos = tuple(w + o for w, o in zip(status.wpos, wco, strict=False))
        else:
            continue
        line = first + done  # the line executing (0-based), or the next one to run
        down = line < len(pen) and bool(pen[line])
        if pen_z_below is not None and len(pos) > 2 and pos[2] >= pen_z_below:
            down = False
        rows.append((t - stream.started, pos[0], pos[1], float(down)))
        runs.append(int(run_of[line]) if down else -1)
    return np.array(rows, dtype=float).reshape(-1, 4), np.array(runs, dtype=int)


def simulated_pen(profile: Profile) -> dict[str, Any]:
    """The pen arguments of a :class:`~sim.grbl.SimulatedGrbl` matching ``profile`` (and the
    time it takes to read a byte, ``serial.read_time``)."""
    up, down = profile["pen.up"], profile["pen.down"]
    start = (profile["motion.park_x"], profile["motion.park_y"])
    read = {"read_time": profile["serial.read_time"]}
    if profile["pen.type"] == "z":
        return {"pen": "z", "pen_z_below": (up + down) / 2, "position_mm": (*start, up), **read}
    return {"pen": "spindle", "pen_servo": (down, up), "position_mm": (*start, 0.0), **read}


def _details(
    program: Program, profile: Profile, stream: StreamReport | None, device: Any
) -> dict[str, Any]:
    baud = profile["serial.baud"]
    details: dict[str, Any] = {
        "program_drawing_s": program.drawing_time,
        "time_scale": program.scale,
        "dt": profile.dt,
        "baud": baud,
        # What a host pause may use mid-run (the planner's queued blocks and the lines surely
        # in the receive buffer): the figure motion.min_buffer was planned for; None when every
        # run fits the machine's buffers whole.
        "min_buffered_s": (
            program.min_buffered_rx if math.isfinite(program.min_buffered_rx) else None
        ),
        # What the machine holds at a run's start, where the pen-down stop left only the receive
        # buffer's lines queued: a longer host pause there starves the planner.
        "min_buffered_start_s": program.min_buffered_start,
    }
    if stream is not None:
        duration = max(stream.duration, 1e-9)
        details.update(
            {
                "first_line": stream.first_line + 1,
                "lines_acknowledged": stream.lines_acknowledged,
                "errors": list(stream.errors),
                "tracking": stream.tracking,
                "bytes_sent": stream.bytes_sent,
                "max_outstanding_bytes": stream.max_outstanding,
                "stream_rate_bytes_per_s": stream.bytes_sent / duration,
                "baud_limit_bytes_per_s": baud / 10,
                "status_reports": len(stream.statuses),
                "outside_holds": stream.outside_holds,
                "realtime": stream.realtime,
            }
        )
    details["starvation_events"] = len(device.starvation) if device is not None else None
    return details
