"""The AxiDraw as a ``tagbot draw`` back end: check, build the moves, stream, record.

:func:`prepare` loads the profile, places and retimes the tag with the plotter's placement
(along the motors' ``x ± y`` axes, :meth:`~tagbot.axidraw.profile.Profile.placement`), builds
every move (:func:`~tagbot.axidraw.moves.build_job`: refused there if off the paper or beyond
the board's step rate) and checks the port's name: nothing is written or sent.
:meth:`AxiDrawJob.run` writes ``moves.txt`` (the commands, one a line), opens the port (a
simulated EBB when none is named), streams (:class:`~tagbot.axidraw.stream.EBBStreamer`) and
returns what was planned and executed. The unit is the *move*: the 1-based line of
``moves.txt``.

**The executed trace.** On the simulator, its tick record every 1 ms (25 ticks). On a board,
the ``QS`` polls (every ``serial.poll`` s): the global step position, with the pen and the
pen-down run of the move executing then.

**Resume** (``resume_from``: a move of ``moves.txt``): the board's ``QS`` says where the
motors are; tagbot lifts the pen, travels to where that move starts (``LM``), lowers the pen if
it was down there, and streams from it. After a stop, ``resume_from`` is the first move that had
not started (none when nothing of the job ran: it is drawn again as it is, as on the other
machines; :func:`resume_point`): a move cut short is not drawn again (what is left of it, at
most ``motion.dt`` s of drawing, is skipped), so nothing is drawn twice. ``EM`` at connect
clears the board's step accumulators, which the job's moves carry from one to the next: the
resumed moves take the same steps from a different fraction of a step, so every position after
the resume is the plan's within one step per motor (0.0125 mm at 16x), not exactly.
"""

from __future__ import annotations

import itertools
import os
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import serial

from firmware_protocols.ebb.motion import TICK_HZ
from tagbot.axidraw.moves import Job, _travel_moves, build_job, run_reference
from tagbot.axidraw.profile import Profile, load_profile
from tagbot.axidraw.stream import EBBStreamer, StreamReport, entry_end_ticks, locate
from tagbot.control import RunControl
from tagbot.draw import MachineRun, Progress
from tagbot.errors import ConnectionLost, DeviceError, InputError, Interrupted, PortError
from tagbot.io.motionfile import MotionTable
from tagbot.model import Tag
from tagbot.plotter.machine import placement_of
from tagbot.plotter.place import Setpoints, place
from tagbot.ports import check_port
from tagbot.signals import label, signal_of

__all__ = ["AxiDrawJob", "find_port", "prepare", "resumable", "resume_point", "timeline"]

_names = itertools.count()

TIMELINE_STEP = 0.01
"""s between the samples of motion.csv's planned timeline."""
PLAN_STEP = 0.001
"""s between the samples of each run's plan in the comparison."""
TRACE_STEP = 25
"""Ticks between the executed trace's samples (1 ms)."""
DEVIATION_BUDGET = 0.02
"""mm: a run's path deviation beyond this carries a warning (issue 31's goal)."""
MIN_SPEED_SNR_DB = 25.0
"""A run's speed SNR below this carries a warning, as on the other machines."""
PAUSE_EDGE = 0.005
"""s either side of a pause the host cannot place exactly: it sees the motors stop at its
polls, and the board starts the next move once it has read it (4 ms for a ``T3``, the
firmware's command time). The comparison leaves that out after each pause and aligns each side
on its own (:attr:`MachineRun.ramp`)."""


def find_port() -> str:
    """The first EiBotBoard on USB (by its name, else its VID:PID 04D8:FD92), with the makers'
    ``plotink.ebb_serial``; PortError when none is plugged in."""
    from plotink import ebb_serial

    found = ebb_serial.findPort()
    if found is None:
        raise PortError("--port auto: no EiBotBoard found on USB (is the AxiDraw plugged in?)")
    return str(found)


def prepare(
    tag: Tag,
    *,
    profile: str | Path | None = None,
    overrides: tuple[str, ...] = (),
    port: str | None = None,
    resume_from: int | None = None,
) -> AxiDrawJob:
    """Everything checked before anything starts: profile, placement, paper, step rates, the
    resume move and the port (``"auto"``: found on USB). Raises; writes and sends nothing."""
    machine = load_profile(profile, overrides)
    if port == "auto":
        port = find_port()
    if port is not None:
        check_port(port)
    setpoints = place(tag, machine.placement())
    job = build_job(tag, setpoints, machine)
    if resume_from is not None and not resumable(job, resume_from):
        raise InputError(
            f"--resume-from: move {resume_from} is not in the job (moves 2 to {len(job.entries)})"
        )
    return AxiDrawJob(tag, machine, setpoints, job, port, resume_from)


def resumable(job: Job, move: int) -> bool:
    """Whether ``--resume-from move`` can resume ``job``: moves 2 to the last (move 1 is the
    job's start: a job stopped before anything of it ran is drawn again without it)."""
    return 2 <= move <= len(job.entries)


def resume_point(job: Job, done: int, partial: int) -> int | None:
    """The move a stopped job resumes from (the report's ``resume_from``): the first that had
    not started, after ``done`` moves executed in full and ``partial`` (0 or 1) cut short. None
    when ``--resume-from`` has nothing to take: nothing of the job ran (draw it again as it is),
    or everything left was cut short (the last move, a pen-up travel)."""
    move = done + 1 + partial
    return move if resumable(job, move) else None


def timeline(job: Job, dt: float) -> MotionTable:
    """The job's planned motion every ``dt`` s (and at its end): the exact step positions of
    its tick record in mm, velocities from them, the pen from its pen commands."""
    end = job.duration
    t = _grid(end, dt)
    if len(job.ticks):
        i = np.searchsorted(job.tick_time, t + 0.5 / TICK_HZ, side="right") - 1
        steps = np.where((i >= 0)[:, None], job.ticks[np.clip(i, 0, None)], job.entries[0].steps)
    else:
        steps = np.zeros((len(t), 2), dtype=np.int64)
    xy = job.xy(steps)
    v = np.gradient(xy, t, axis=0) if len(t) > 1 else np.zeros_like(xy)
    pen = np.zeros(len(t), dtype=np.int8)
    for when, down in job.pen_at:
        pen[t >= when] = int(down)
    return MotionTable(t, xy, v, np.hypot(v[:, 0], v[:, 1]), pen)


@dataclass(eq=False)
class AxiDrawJob:
    """A checked AxiDraw job (see :func:`prepare`); :meth:`run` draws it."""

    tag: Tag
    profile: Profile
    setpoints: Setpoints
    job: Job
    port: str | None
    resume_from: int | None = None
    device: str = "axidraw"
    planned: MotionTable = field(init=False)

    def __post_init__(self) -> None:
        self.planned = timeline(self.job, TIMELINE_STEP)

    def run(
        self, out: Path, *, progress: Progress | None = None, control: RunControl | None = None
    ) -> MachineRun:
        """Stream the job (simulated unless a port was named) and record what ran. Faults and
        Ctrl-C end in a safe stop (``ES``, pen up) and are returned in
        :attr:`MachineRun.error`, naming the last move the board executed."""
        job, profile = self.job, self.profile
        (out / "moves.txt").write_bytes(b"".join(e.line.rstrip(b"\r") + b"\n" for e in job.entries))
        device = None
        if self.port is None:
            from sim.ebb.device import SimulatedEBB
            from sim.ebb.transport import attach_device

            device = SimulatedEBB(pen_pin=profile["pen.pin"])  # wired as the profile says
            url = attach_device(device, f"draw{os.getpid()}_{next(_names)}")
        else:
            url = self.port
        try:
            link = serial.serial_for_url(url, timeout=0.01)
        except (serial.SerialException, OSError, ValueError) as e:
            raise ConnectionLost(f"cannot open {url}: {e}") from e
        pens = {e.pen: (e.line, e.duration) for e in job.entries if e.kind == "pen"}
        streamer = EBBStreamer(link, profile, pens)
        first = 0 if self.resume_from is None else self.resume_from - 1
        error: BaseException | None = None
        connected = False
        try:
            streamer.connect(keep_position=first > 0, fifo=job.fifo)
            connected = True
            preamble = self._preamble(streamer, first)
            streamer.stream(
                [e.line for e in job.entries],
                durations=[e.duration for e in job.entries],
                first=first,
                preamble=preamble,
                pen_down=[e.pen for e in job.entries],
                progress=progress,
                control=control,
            )
        except DeviceError as e:
            error = e
        except KeyboardInterrupt as e:
            error = Interrupted(f"interrupted ({label(signal_of(e))})")
        if error is not None and connected:
            try:
                streamer.stop()
            finally:
                link.close()
        else:  # ended, or refused at connect (an old firmware): nothing was sent to stop
            link.close()
        report = streamer.report
        done, partial = self._executed_moves(report)
        if isinstance(error, DeviceError) and error.where is None:
            error = type(error)(str(error), _where(job, done, partial))
        executed, runs = self._trace(report, device)
        planned = _runs_from(self._planned_runs(), job, first)
        total = len(job.entries)
        return MachineRun(
            device="axidraw",
            motion=self.planned,
            planned_runs=[run for run, _ in planned],
            plans=[plan for _, plan in planned],
            executed=executed,
            executed_runs=runs,
            executed_source=(
                "simulator recorder, 1 ms"
                if device is not None
                else f"QS polls, {1.0 / float(profile['serial.poll']):g} Hz"
            ),
            sparse=device is None,
            unit="move",
            total=total,
            sent=first + report.sent,
            executed_steps=done,
            resume_from=resume_point(job, done, partial) if error is not None else None,
            planned_duration=job.duration,
            executed_duration=report.duration,
            placement=placement_of(
                self.setpoints, SimpleNamespace(planned_runs=job.planned_runs())
            ),
            port="simulator" if device is not None else url,
            details=self._details(report),
            error=error,
            pauses=[(a - report.started, n) for a, n in report.pauses],
            stalls=[(a - report.started, n) for a, n in report.stalls],
            until=None if error is None else _until(job, done),
            ramp=PAUSE_EDGE if report.pauses else 0.0,
            judge=Budget(job, [(a - report.started, n) for a, n in report.stalls]),
        )

    def _planned_runs(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per run, the plan's continuous motion every :data:`PLAN_STEP` s on the job's clock
        (what the executed path and speed are compared with, not the setpoints' polyline)."""
        out = []
        for run, start in zip(self.job.runs, self.job.run_start, strict=True):
            at = run_reference(self.tag, run, self.setpoints.matrix, self.setpoints.offset)
            end = float(run.t[-1])
            t = _grid(end, PLAN_STEP)
            out.append((start + t, at(t)))
        return out

    def _preamble(self, streamer: EBBStreamer, first: int) -> list[bytes]:
        """A resume's pen up, travel to where move ``first`` starts, and pen down if needed."""
        if first == 0:  # the motors are home: EM zeroed the counters there
            return [streamer.pen_line(False)] if streamer.pens else []
        here = streamer.position()
        before = self.job.entries[first - 1]
        delta = (before.steps[0] - here[0], before.steps[1] - here[1])
        lines = [streamer.pen_line(False)]
        lines += [m.line() for m in _travel_moves(delta, self.profile)]
        if before.pen:
            lines.append(streamer.pen_line(True))
        return lines

    def _executed_moves(self, report: StreamReport) -> tuple[int, int]:
        """Moves executed in full, and 1 when the next one had started (a stop cut it)."""
        done = report.executed
        if report.stopped_at is None:
            return done, 0
        sent = report.first + report.sent
        done = locate(self.job, report.stopped_at, done, sent)
        start = self.job.entries[done - 1].steps if done else (0, 0)
        ends = entry_end_ticks(self.job)
        moving = done < len(self.job.entries) and self.job.entries[done].move is not None
        started = moving and tuple(report.stopped_at) != tuple(start) and ends[done] > 0
        return done, int(started and done < sent)

    def _trace(self, report: StreamReport, device: Any) -> tuple[np.ndarray, np.ndarray | None]:
        """The executed ``t, x, y, pen`` on the job's clock, and (polls) each sample's run."""
        job, p = self.job, self.profile
        if device is not None:
            trace = device.recorder.trace()
            keep = np.unique(np.append(np.arange(0, len(trace.t), TRACE_STEP), len(trace.t) - 1))
            t = trace.t[keep] - report.started
            xy = job.xy(np.column_stack([trace.motor1[keep], trace.motor2[keep]]))
            up, down = p.servo_position(p["pen.up"]), p.servo_position(p["pen.down"])
            width = trace.pen[keep]
            pen = (np.abs(width - down) < np.abs(width - up)).astype(float)
            rows = np.column_stack([t, xy, pen])
            return rows[t >= 0], None
        if not report.polls:
            return np.zeros((0, 4)), np.zeros(0, dtype=int)
        polls = np.asarray(report.polls, dtype=float)
        executing = np.minimum(polls[:, 1].astype(int), len(job.entries) - 1)
        pen = np.array([job.entries[i].pen or job.entries[i].kind == "draw" for i in executing])
        runs = np.array(
            [job.entries[i].run if d else -1 for i, d in zip(executing, pen, strict=True)]
        )
        xy = job.xy(polls[:, 2:4].astype(np.int64))
        rows = np.column_stack([polls[:, 0] - report.started, xy, pen.astype(float)])
        return rows, runs

    def _details(self, report: StreamReport) -> dict[str, Any]:
        job = self.job
        draws = [e for e in job.entries if e.kind == "draw"]
        return {
            "firmware": ".".join(map(str, report.firmware)),
            "fifo": report.fifo,
            "moves": len(job.entries),
            "draw_moves": len(draws),
            "t3_moves": sum(e.move is not None and e.move.command == "T3" for e in draws),
            "move_error_max_mm": float(np.max(job.move_error, initial=0.0)),
            "run_error_mm": [float(e) for e in job.run_error],
            "run_moves_speed_snr_db": [_finite(v) for v in job.run_speed_snr],
            "run_steps_speed_snr_db": [_finite(v) for v in job.run_step_snr],
            "steps_per_mm": job.steps_per_mm,
            "polls": len(report.polls),
            "button_presses": report.button_presses,
            "most_on_board": report.most_on_board,
            "errors": list(report.errors),
            "stopped_at_steps": list(report.stopped_at) if report.stopped_at else None,
        }


@dataclass(frozen=True, eq=False)
class Budget:
    """The AxiDraw's budgets for :attr:`tagbot.draw.MachineRun.judge`: each pen-down run's path
    deviation within :data:`DEVIATION_BUDGET` and speed SNR at least :data:`MIN_SPEED_SNR_DB`,
    or a warning naming the run, the figure and its cause: host stalls with the pen down (the
    board ran dry), the moves' own stated error, else the executed motion beyond it."""

    job: Job
    stalls: list[tuple[float, float]]
    """``(start, length)`` on the job's clock."""

    def __call__(self, report: dict[str, Any]) -> list[str]:
        out = []
        plans = [run.plan for run in self.job.runs]
        for i, run in enumerate(report.get("runs", [])):
            deviation, snr = run["path_deviation_max_mm"], run["speed_snr_db"]
            over = []
            if deviation is not None and deviation > DEVIATION_BUDGET:
                over.append(f"path deviation {deviation:.3f} mm over {DEVIATION_BUDGET:g} mm")
            if snr is not None and snr < MIN_SPEED_SNR_DB and not run.get("cut_short"):
                over.append(f"speed SNR {snr:.1f} dB below {MIN_SPEED_SNR_DB:g} dB")
            if not over:
                continue
            k = plans.index(run["plan"]) if run["plan"] in plans else i
            start = run["executed_start"]
            end = start + run["executed_duration"] + 1.0
            held = [n for a, n in self.stalls if start - 0.05 <= a <= end]
            stated = self.job.run_error[k] if k < len(self.job.run_error) else 0.0
            if held:
                cause = (
                    f"{len(held)} host stall{'s' * (len(held) > 1)} ({1e3 * sum(held):.0f} ms)"
                    " with the pen down: the board ran dry"
                )
            elif stated > DEVIATION_BUDGET:
                cause = f"its moves' own error against the plan ({stated:.3f} mm, stated)"
            else:
                cause = f"the executed motion beyond its moves' stated {stated:.3f} mm"
            out.append(f"run {i + 1} (plan {run['plan']}): {' and '.join(over)}: {cause}")
        return out


def _runs_from(
    planned: list[tuple[np.ndarray, np.ndarray]], job: Job, first: int
) -> list[tuple[tuple[np.ndarray, np.ndarray], int]]:
    """The ``planned`` runs (and each one's plan) from entry ``first``'s start on (a resumed
    job's: what is left of each)."""
    start = job.entries[first].start if first else 0.0
    kept = []
    for (t, xy), run in zip(planned, job.runs, strict=True):
        rest = t >= start - 1e-9
        if rest.sum() >= 2:
            kept.append(((t[rest], xy[rest]), run.plan))
    return kept


def _grid(end: float, dt: float) -> np.ndarray:
    """``0, dt, 2·dt, ...`` and ``end`` (a sample within 1 µs of the end dropped: two samples
    that close would be one after adding a job time, and their velocity 0/0)."""
    t = np.arange(0.0, end, dt)
    return np.append(t[t < end - 1e-6], end)


def _finite(value: float) -> float | None:
    """``value`` for report.json (JSON has no inf: None, a run too short for the figure)."""
    return float(value) if np.isfinite(value) else None


def _until(job: Job, done: int) -> float:
    return job.entries[done].start if done < len(job.entries) else job.duration


def _where(job: Job, done: int, partial: int) -> str:
    """Where a stop left the job: after the last move executed in full; during move 1 when it
    was cut short (the motors had left home); before it when nothing ran."""
    if done == 0 and partial:
        return f"during move 1 of {len(job.entries)} (moves.txt; cut short)"
    if done == 0:
        return "before move 1 (nothing of the job was executed)"
    return f"after move {done} of {len(job.entries)} (moves.txt)"
