"""The arm back end: :func:`prepare` plans and checks a job, its ``run`` streams and reports.

:func:`prepare` loads the profile, places, retimes and checks the whole program
(:class:`~tagbot.errors.PlacementError`) and checks the port's name
(:func:`tagbot.ports.check_port`) before anything is written or sent; :meth:`ArmJob.run` then
writes ``joints.csv``, connects, streams and returns a :class:`~tagbot.draw.MachineRun`, also
after a fault or Ctrl-C (in :attr:`~tagbot.draw.MachineRun.error`, once the arm stopped safely:
pen up), with the executed trace up to there. :func:`draw_arm` is the same for the library,
raising instead.

Without a port it builds a simulated servo chain from the profile (IDs, models, baud rate,
geometry for its pen-tip recorder) and streams to it in process, in simulated time; with a port
(a device path, a pseudo-terminal or a pyserial URL) it streams there in real time, and warns when
the port is a USB serial adapter whose latency timer is above 1 ms
(:func:`latency_timer_warning`).

The executed trace is the simulator's 1 ms pen-tip recorder when the port is an in-process
simulator, else the read-back present positions through forward kinematics; either way on the
executed clock: the job's (0 = the pen due at the first setpoint) as it ran, pauses and host
stalls in (the report names both; its comparison leaves pauses out and keeps stalls, see
:func:`tagbot.metrics.compare_execution`). After a stop, the plan is compared up to where the
pen had drawn to; a resumed job (``resume_from``) travels pen up to where the stop left it,
puts the pen as it was and sends the rest.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import serial
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from tagbot.arm.driver import ArmDriver, StreamResult, readback_bus_time
from tagbot.arm.kinematics import RAD_PER_TICK, Arm, angles_to_ticks, ticks_to_angles
from tagbot.arm.place import ArmProgram, Setpoints, approach, build_program
from tagbot.arm.profile import ArmProfile, load_profile
from tagbot.control import RunControl
from tagbot.draw import MachineRun
from tagbot.errors import DeviceError, InputError, Interrupted, ProfileError
from tagbot.io.motionfile import MotionTable
from tagbot.metrics import densify
from tagbot.model import Tag
from tagbot.ports import check_port
from tagbot.signals import label, signal_of

__all__ = [
    "ArmJob",
    "ArmRun",
    "check_bus",
    "draw_arm",
    "executed_from_reads",
    "latency_timer_warning",
    "prepare",
    "simulated_chain",
]

log = logging.getLogger(__name__)

Array = NDArray[np.float64]

_names = itertools.count()

RECORDER_DT = 0.001
"""Seconds between the simulator recorder's samples."""


@dataclass(frozen=True, eq=False)
class ArmRun:
    """What a drawing did.

    - ``setpoints``: the planned pen-tip motion at the loop period (``t``, ``xy``, ``v``,
      ``pen``; with ``mm_per_unit`` and ``time_scale`` of the placement);
    - ``joints``: ``(N, 4)`` planned goals per tick: ``t`` (s), shoulder, elbow, pen (ticks);
    - ``executed``: ``(M, 4)`` ``t, x, y, pen``: the simulator's pen-tip recorder (1 ms) when
      simulated, else the read-back present positions through FK; ``t`` is on the executed
      clock (0 = when the pen should be at the first setpoint), pauses and host stalls in, as
      they happened;
    - ``stats``: the arm's own figures (see :func:`arm_figures`): ``ticks_sent``,
      ``late_ticks``, ``max_lateness_ms``, ``lateness_p50_ms``, ``lateness_p99_ms``,
      ``loop_rate_hz``, ``resyncs``, ``readbacks``, the read-back's misses, late and corrupt
      replies, ``joint_tracking_error`` (``{"max": deg, "mean": deg}``), ``paused_s``...
    """

    setpoints: Setpoints
    joints: Array
    executed: Array
    stats: dict[str, Any] = field(default_factory=dict)
    program: ArmProgram | None = None


def simulated_chain(profile: ArmProfile, *, real_time: bool = False, at_park: bool = True) -> Any:
    """A simulated chain with the profile's servos, baud rate and arm geometry (its recorder).

    ``real_time`` makes it follow the wall clock (for a pseudo-terminal); ``at_park`` starts
    the horns at the park pose, pen up (else at the servos' middle position, 2048).
    """
    from sim.dynamixel import SimulatedChain

    clock = "real" if real_time else "simulated"
    chain = SimulatedChain(servos=profile.servos, baud=profile["bus.baud"], clock=clock)
    chain.set_geometry(geometry_of(profile))
    if at_park:
        for joint, angle in zip(profile.joints, profile.park, strict=True):
            chain.set_position(joint.id, float(angles_to_ticks(angle, joint)))
        chain.set_position(profile["pen.id"], float(profile["pen.up"]))
    return chain


def geometry_of(profile: ArmProfile) -> Any:
    """The simulator's ``ArmGeometry`` for this profile (same joint convention)."""
    from sim.dynamixel import ArmGeometry

    shoulder, elbow = profile.joints
    return ArmGeometry(
        shoulder_id=shoulder.id,
        elbow_id=elbow.id,
        pen_id=profile["pen.id"],
        l1_mm=profile["arm.l1"],
        l2_mm=profile["arm.l2"],
        pen_down_ticks=profile["pen.down"],
        pen_up_ticks=profile["pen.up"],
        base_xy=profile.base,
        zero_ticks=(shoulder.zero, elbow.zero),
        sign=(shoulder.sign, elbow.sign),
    )


def executed_from_reads(reads: Array, profile: ArmProfile) -> Array:
    """``(M, 4)`` ``t, x, y, pen`` from read-backs ``(M, 4)`` ``t, shoulder, elbow, pen`` ticks."""
    reads = np.asarray(reads, dtype=float).reshape(-1, 4)
    shoulder, elbow = profile.joints
    q = np.column_stack(
        [ticks_to_angles(reads[:, 1], shoulder), ticks_to_angles(reads[:, 2], elbow)]
    )
    xy = Arm.from_profile(profile).fk(q).reshape(-1, 2)
    up, down = profile["pen.up"], profile["pen.down"]
    pen = np.abs(reads[:, 3] - down) < np.abs(reads[:, 3] - up)
    return np.column_stack([reads[:, 0], xy, pen.astype(float)])


def tracking_error(reads: Array, program: ArmProgram, profile: ArmProfile) -> dict[str, float]:
    """Max and mean |present − planned| joint angle over the read-backs, degrees."""
    reads = np.asarray(reads, dtype=float).reshape(-1, 1 + len(profile.bus_ids))
    t = program.joints[:, 0]
    inside = (reads[:, 0] >= t[0]) & (reads[:, 0] <= t[-1])
    if not inside.any():
        return {"max": math.nan, "mean": math.nan}
    reads = reads[inside]
    errors = []
    for i, joint in enumerate(profile.joints):
        planned = np.interp(reads[:, 0], t, program.angles[:, i])
        errors.append(np.abs(ticks_to_angles(reads[:, 1 + i], joint) - planned))
    e = np.degrees(np.concatenate(errors))
    return {"max": float(e.max()), "mean": float(e.mean())}


def latency_timer_warning(port: str, sysfs: str | os.PathLike[str] = "/sys") -> str | None:
    """A warning, with the fix, when ``port`` is a Linux USB serial adapter (``ttyUSBn``, also
    through a symlink such as ``/dev/serial/by-id/…``, or watched by pyserial's ``spy://``)
    whose latency timer is above 1 ms; else None. ``hwgrep://`` is resolved by pyserial's own
    search, as opening it would. ``sysfs`` is where sysfs is mounted (tests give a fake one)."""
    if port.startswith("spy://"):
        port = port.removeprefix("spy://").split("?", 1)[0]
    if port.startswith("hwgrep://"):
        try:
            port = serial.serial_for_url(port, do_not_open=True).port
        except (serial.SerialException, ValueError):
            return None  # no such adapter: opening it will say so
    if "://" in port:
        return None
    name = os.path.basename(os.path.realpath(port))
    timer = Path(sysfs) / "bus" / "usb-serial" / "devices" / name / "latency_timer"
    try:
        ms = int(timer.read_text(encoding="ascii").strip())
    except (OSError, ValueError):
        return None
    if ms <= 1:
        return None
    return (
        f"{port} is a USB serial adapter ({name}) with a {ms} ms latency timer: every read-back"
        f" reply waits up to {ms} ms in it. Set it to 1 ms: echo 1 | sudo tee {timer} (until it"
        ' is unplugged; for good, a udev rule: ACTION=="add", SUBSYSTEM=="usb-serial",'
        ' DRIVERS=="ftdi_sio", ATTR{latency_timer}="1")'
    )


@dataclass
class _Outcome:
    """What one streaming attempt gave, whatever happened."""

    program: ArmProgram
    result: StreamResult | None = None
    executed: Array = field(default_factory=lambda: np.zeros((0, 4)))
    recorder: bool = False
    approach_s: float = 0.0
    error: BaseException | None = None
    warnings: list[str] = field(default_factory=list)
    where: str = "connect"
    until: float | None = None
    """After a stop: the program time the pen had drawn to (see :func:`_drawn_to`)."""
    lifted: bool = False
    """Whether the safe stop got the pen up (:attr:`ArmDriver.lifted`)."""
    lift_failure: str | None = None
    """Why the safe stop did not get the pen up, when it did not."""

    def stop(self, driver: ArmDriver, error: BaseException) -> None:
        """Stopped by ``error``: the driver's safe stop, and whether it got the pen up (a
        second Ctrl-C cutting it short leaves the pen's state said, not the first error lost)."""
        self.error = error
        with contextlib.suppress(KeyboardInterrupt):  # driver.lift_failure then says so
            driver.safe_stop(error=True)
        self.lifted, self.lift_failure = driver.lifted, driver.lift_failure


def check_resume(resume_from: int | None, program: Any) -> None:
    """An arm job resumes from one of its program's ticks after the first (``--resume-from``)."""
    if resume_from is not None and not 2 <= resume_from <= len(program):
        raise InputError(
            f"--resume-from: tick {resume_from} is not in the program (ticks 2 to {len(program)})"
        )


def finish_run(
    outcome: _Outcome,
    program: Any,
    profile: Any,
    port: str | None,
    first: int,
    device: str,
    planned: MotionTable,
    n_plans: int,
    stopped: tuple[str, str],
    recorder: str,
    judge: Callable[[dict[str, Any], list, list, list], Any],
) -> MachineRun:
    """What an arm's streaming ``outcome`` (from row ``first`` of ``program``) did, as every
    machine reports it: Ctrl-C as :class:`Interrupted` saying what the arm did (``stopped``:
    the words for a stop that got the pen up, and for one that did not, then said with why and
    warned of), the tick a stopped job resumes from, pauses and stalls on the program's clock,
    what was left of each plan to draw, the executed trace's source (``recorder`` when the
    simulator recorded it). ``judge(figures, planned runs, pauses, stalls)`` may add figures and
    gives the report's budget judge. Any other error is a bug and raised
    (:func:`tagbot.draw.draw` reports it)."""
    error = outcome.error
    said, not_up = stopped
    if error is not None and not outcome.lifted:
        said = f"{not_up} ({outcome.lift_failure or 'no connection to the arm'})"
        outcome.warnings.append(f"{said}: it may still be on the paper")
    if isinstance(error, KeyboardInterrupt):
        error = Interrupted(f"interrupted ({label(signal_of(error))}): {said}", outcome.where)
    elif error is not None and not isinstance(error, DeviceError):
        raise error
    sp, result = program.setpoints, outcome.result
    sent = first + (result.ticks_sent if result is not None else 0)
    if error is not None and first < sent < len(program):
        error = _with_resume(error, sent)
    figures = arm_figures(outcome, profile, port)
    executed_duration = 0.0
    pauses: list[tuple[float, float]] = []
    stalls: list[tuple[float, float]] = []
    if result is not None and result.scheduler is not None:
        zero = origin(result, program)
        executed_duration = max(0.0, result.end - result.start - result.lead)
        pauses = [(a - zero, length) for a, length in result.pause_spans]
        stalls = [(a - zero, hole) for a, hole in result.scheduler.stalls]
        outcome.warnings += _stall_warnings(stalls, outcome.executed, program)
    if outcome.recorder:
        source = recorder
    else:
        source = f"read-back, {profile['motion.rate'] / profile.readback_every:g} Hz"
    begin = float(program.joints[first - 1, 0]) if first else -math.inf
    planned_runs, plans = [], []
    for k in range(n_plans):
        rest = (sp.plan == k) & (sp.t >= begin - 1e-9)
        if rest.sum() >= 2:  # what is left of it to draw
            planned_runs.append((sp.t[rest], sp.xy[rest]))
            plans.append(k)
    verdict = judge(figures, planned_runs, pauses, stalls)
    return MachineRun(
        device=device,
        motion=planned,
        planned_runs=planned_runs,
        plans=plans,
        executed=outcome.executed,
        executed_source=source,
        sparse=False,
        executed_runs=None,
        unit="tick",
        total=len(program),
        sent=sent,
        executed_steps=sent,
        resume_from=sent + 1 if error is not None and first < sent < len(program) else None,
        planned_duration=sp.duration,
        executed_duration=executed_duration,
        placement=placement_of(sp),
        port=port or "simulator",
        details=figures,
        warnings=list(outcome.warnings),
        error=error,
        pauses=pauses,
        stalls=stalls,
        until=outcome.until,
        judge=verdict,
    )


def _stream(
    program: ArmProgram,
    profile: ArmProfile,
    port: str | None,
    progress: Callable[[int, int], None] | None,
    control: RunControl | None,
    sysfs: str | os.PathLike[str] = "/sys",
    first: int = 0,
) -> _Outcome:
    """Connect, approach, stream (from row ``first`` of the program: a resumed job travels pen
    up to the pose of the row before it and puts the pen as it was there): the executed trace
    and figures, and the error if one stopped it (the arm already stopped safely)."""
    outcome = _Outcome(program)
    name = None
    if port is None:
        from sim.dynamixel import attach_chain

        name = f"tagbot_arm_{next(_names)}"
        url = attach_chain(simulated_chain(profile), name)
    else:
        url = port
        warning = latency_timer_warning(port, sysfs)
        if warning:
            log.warning("%s", warning)
            outcome.warnings.append(warning)
    try:
        with ArmDriver(url, profile) as driver:
            try:
                driver.connect()
                outcome.where = "approach"
                present = driver.read_present()
                at = program.goals[first - 1] if first else None
                to = None if at is None else at[:2]
                goals, outcome.approach_s = approach(present, profile, to)
                outcome.warnings += _outside_limits(present, profile)
                driver.move_to(goals, outcome.approach_s)
                if at is not None:
                    driver.lower_pen(int(at[2]))
                outcome.where = f"tick {first}"
                driver.stream(program.goals[first:], progress, control, first)
            except BaseException as e:
                outcome.stop(driver, e)
            outcome.result = getattr(driver, "result", None)
            chain = _recorder(driver, profile)
            outcome.recorder = chain is not None
            result = outcome.result
            if result is not None:
                outcome.where = f"tick {result.first + result.ticks_sent}"
                if chain is not None:
                    trace = np.asarray(chain.pen_trace(RECORDER_DT), dtype=float).reshape(-1, 4)
                else:
                    trace = executed_from_reads(result.read_clock, profile)
                outcome.executed = _executed(trace, result, program)
                if outcome.error is not None:
                    outcome.until = _drawn_to(trace, result, program)
    except (DeviceError, KeyboardInterrupt) as e:  # opening or closing the port
        outcome.error = outcome.error or e
    finally:
        if name is not None:
            from sim.dynamixel import detach_chain

            detach_chain(name)
    return outcome


def draw_arm(
    tag: Tag,
    profile: ArmProfile,
    port: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    control: RunControl | None = None,
) -> ArmRun:
    """Draw ``tag`` with the arm of ``profile`` on ``port`` (None: a simulated chain).

    The whole program is placed, retimed and checked before the port is opened
    (PlacementError); then connect (DeviceError listing the IDs found, wrong models), move to
    park, stream one goal row per tick, and return an :class:`ArmRun`. ``progress(done,
    total)`` is called about ten times a second; ``control`` pauses and resumes. Device errors
    and KeyboardInterrupt stop the arm safely (pen up) and are re-raised (for a run folder
    that keeps what was executed, use :func:`prepare`).
    """
    check_bus(profile)
    program = build_program(tag, profile)
    outcome = _stream(program, profile, port, progress, control)
    if outcome.error is not None:
        raise outcome.error
    stats = arm_figures(outcome, profile, port)
    if outcome.result is not None:
        stats["paused_s"], stats["pauses"] = outcome.result.paused, outcome.result.pauses
    return ArmRun(program.setpoints, program.joints, outcome.executed, stats, program)


@dataclass(eq=False)
class ArmJob:
    """A checked arm job (:func:`prepare`): nothing written, nothing sent yet."""

    tag: Tag
    profile: ArmProfile
    program: ArmProgram
    port: str | None
    planned: MotionTable
    sysfs: str | os.PathLike[str] = "/sys"
    device: str = "dynamixel"
    resume_from: int | None = None
    """The tick (row of ``joints.csv``, from 1) a resumed job starts with, or None."""

    def run(
        self,
        out: Path,
        *,
        progress: Callable[[int, int], None] | None = None,
        control: RunControl | None = None,
    ) -> MachineRun:
        """Write ``joints.csv`` into ``out``, connect, stream; what happened, also after a fault
        or Ctrl-C (:attr:`MachineRun.error`, Ctrl-C as :class:`Interrupted` naming the last tick
        executed)."""
        program, profile = self.program, self.profile
        _write_joints(program.joints, Path(out) / "joints.csv")
        first = 0 if self.resume_from is None else self.resume_from - 1
        outcome = _stream(program, profile, self.port, progress, control, self.sysfs, first)
        return finish_run(
            outcome, program, profile, self.port, first, self.device, self.planned,
            len(self.tag.plans),
            ("the arm stopped, pen up", "the arm stopped, but the pen was not raised"),
            f"simulator recorder, {RECORDER_DT * 1e3:g} ms",
            lambda figures, runs, pauses, stalls: Budget(
                program, profile, stalls, _late(outcome.result, program)
            ),
        )  # fmt: skip


MIN_SPEED_SNR_DB = 25.0
"""Per-run speed SNR below this gets a warning naming its cause."""


def _late(result: StreamResult | None, program: ArmProgram) -> Array:
    """``(n, 2)``: executed-clock time each late tick's goal was due at the pen, and its
    lateness (s)."""
    if result is None or result.scheduler is None or not result.scheduler.sends:
        return np.zeros((0, 2))
    s = result.scheduler
    late = np.array(s.lateness)
    at = np.array(s.sends) - late + result.lead - origin(result, program)
    keep = late > s.late_after
    return np.column_stack([at[keep], late[keep]])


@dataclass(frozen=True, eq=False)
class Budget:
    """The arm's budgets for :attr:`tagbot.draw.MachineRun.judge`: each pen-down run's path
    deviation within ``motion.max_deviation`` beyond the goals' own rounding to whole ticks
    (which no timing removes) and speed SNR at least :data:`MIN_SPEED_SNR_DB`,
    or a warning naming the run, the figure and its cause: host stalls with the pen down, late
    goals, the goals' rounding to whole ticks (small slow strokes: the plan itself, rounded,
    falls short), else the servos' follow beyond the retiming's model."""

    program: ArmProgram
    profile: ArmProfile
    stalls: list[tuple[float, float]]
    late: Array

    def __call__(self, report: dict[str, Any]) -> list[str]:
        follow = float(self.profile["motion.max_deviation"])
        out = []
        for i, run in enumerate(report.get("runs", [])):
            deviation, snr = run["path_deviation_max_mm"], run["speed_snr_db"]
            # The goals' own rounding to whole ticks is a floor no timing removes: the budget
            # is the servos' follow (motion.max_deviation) beyond it.
            rounding = self.rounded(int(run["plan"]))[0]
            budget = follow + rounding
            over = []
            if deviation is not None and deviation > budget:
                over.append(
                    f"path deviation {deviation:.3f} mm over its budget ({budget:.3f} mm:"
                    f" motion.max_deviation {follow:g} mm beyond the goals' rounding to whole"
                    f" ticks, {rounding:.3f} mm)"
                )
            slow = snr is not None and snr < MIN_SPEED_SNR_DB and not run.get("cut_short")
            if slow:
                over.append(f"speed SNR {snr:.1f} dB below {MIN_SPEED_SNR_DB:g} dB")
            if over:
                far = deviation is not None and deviation > budget
                cause = self.cause(run, far, slow)
                out.append(f"run {i + 1} (plan {run['plan']}): {' and '.join(over)}: {cause}")
                log.warning("%s", out[-1])
        return out

    def cause(self, run: dict[str, Any], far: bool, slow: bool) -> str:
        """Why ``run`` (a report's entry) left the budget, as far as the run's record tells."""
        start = run["executed_start"]
        end = start + run["planned_duration"] + 1.0
        held = [h for a, h in self.stalls if start - 0.05 <= a <= end]
        if held:
            return (
                f"{len(held)} host stall{'s' * (len(held) > 1)} ({1e3 * sum(held):.0f} ms) with"
                " the pen down"
            )
        late = self.late[(self.late[:, 0] >= start) & (self.late[:, 0] <= end)]
        if len(late):
            return f"{len(late)} late goals (up to {1e3 * late[:, 1].max():.1f} ms)"
        _, snr = self.rounded(int(run["plan"]))
        follow = "the servos' follow beyond the retiming's model (motion.max_deviation)"
        if not (slow and snr < MIN_SPEED_SNR_DB + 3.0):
            return follow
        tick = math.degrees(RAD_PER_TICK)
        rounding = (
            f"the goals' rounding to whole ticks ({tick:.3f}°): the plan's speed, rounded so,"
            f" has {snr:.1f} dB (a small or slow run)"
        )
        return f"{rounding}; the path, {follow}" if far else rounding

    def rounded(self, plan: int) -> tuple[float, float]:
        """The run's goals as sent (whole ticks, through FK) against its plan: their largest
        distance from the planned path (mm) and their speed SNR (dB)."""
        sp, profile = self.program.setpoints, self.profile
        rows = np.flatnonzero(sp.plan == plan)
        if len(rows) < 3:
            return 0.0, math.inf
        goals = self.program.goals[rows]
        shoulder, elbow = profile.joints
        q = np.column_stack(
            [ticks_to_angles(goals[:, 0], shoulder), ticks_to_angles(goals[:, 1], elbow)]
        )
        xy = Arm.from_profile(profile).fk(q).reshape(-1, 2)
        t = sp.t[rows]
        v = np.gradient(sp.xy[rows], t, axis=0)
        error = np.gradient(xy, t, axis=0) - v
        noise = float(np.sum(error * error))
        snr = 10.0 * math.log10(float(np.sum(v * v)) / noise) if noise > 0 else math.inf
        distance, _ = cKDTree(densify(sp.xy[rows], 0.005)).query(xy)
        return float(distance.max()), snr


def _with_resume(error: BaseException, sent: int) -> BaseException:
    """``error`` (a DeviceError naming ``tick N``) naming also the command that resumes it."""
    if not isinstance(error, DeviceError):
        return error
    where = error.where or ""
    message = str(error)[len(where) + 2 :] if where and str(error).startswith(where) else str(error)
    return type(error)(
        message,
        f"tick {sent} (the last tick executed; resume with --resume-from {sent + 1})",
    )


def _stall_warnings(
    stalls: list[tuple[float, float]], executed: Array, program: ArmProgram
) -> list[str]:
    """One warning per host stall that left the pen standing on the paper."""
    out = []
    t, pen = executed[:, 0], executed[:, 3] > 0.5
    for start, hole in stalls:
        inside = (t >= start) & (t <= start + hole)
        if inside.any() and pen[inside].any():
            out.append(
                f"the host stalled {1e3 * hole:.0f} ms at {start:.3f} s (executed clock) with"
                " the pen down: no goal left for that long and the pen stood on the paper; a busy"
                " host (see details.realtime)"
            )
            log.warning("%s", out[-1])
    return out


def placement_of(sp: Setpoints) -> dict[str, Any]:
    """mm per unit, the largest time scale, and each run's clock (``start + scale·(τ −
    tag_start)``), as the plotter reports them."""
    runs = []
    for k, (scale, clock) in enumerate(zip(sp.run_scales, sp.run_clocks, strict=True)):
        drawn = np.flatnonzero(sp.plan == k)
        if len(drawn):
            runs.append(
                {
                    "plan": k,
                    "scale": float(scale),
                    "tag_start": float(clock.tag_start),
                    "start": float(sp.t[drawn[0]]),
                }
            )
    return {"runs": runs, "mm_per_unit": sp.mm_per_unit, "time_scale": sp.time_scale}


def planned_motion(program: ArmProgram) -> MotionTable:
    """The whole planned timeline (travel and pen moves included, pen 0/1) in mm."""
    sp = program.setpoints
    return MotionTable(sp.t, sp.xy, sp.v, np.hypot(*sp.v.T), sp.pen.astype(np.int8))


def check_bus(profile: ArmProfile) -> None:
    """Refuse (ProfileError) a bus too slow for the loop: a tick that sends its goals and a
    read-back (the request and a reply per servo, half duplex) must fit in one period."""
    byte = 10.0 / profile["bus.baud"]
    n = len(profile.servos)
    write = (14 + 5 * n) * byte
    read = readback_bus_time(n, profile["bus.baud"], profile["bus.return_delay_us"])
    busy = write + read
    if busy > profile.period:
        raise ProfileError(
            f"bus.baud: at {profile['bus.baud']} bps a tick's goals and read-back take"
            f" {1e3 * busy:.1f} ms on the bus, more than the {1e3 * profile.period:g} ms period"
            " of motion.rate: raise bus.baud (and the servos' Baud Rate) or lower motion.rate"
        )


def prepare(
    tag: Tag,
    *,
    profile: str | Path | None = None,
    overrides: tuple[str, ...] = (),
    port: str | None = None,
    sysfs: str | os.PathLike[str] = "/sys",
    **options: Any,
) -> ArmJob:
    """The ``dynamixel`` back end of :func:`tagbot.draw.prepare`: load the profile, place,
    retime and check the program (PlacementError), check the port's name (PortError), all before
    anything is written or sent. ``sysfs`` is where to look for USB adapters' latency timers."""
    from tagbot.arm.serial.profile import is_serial_profile

    if is_serial_profile(profile):  # a serial arm (OpenManipulator-X...): its own program
        from tagbot.arm.serial.machine import prepare as prepare_serial

        return prepare_serial(  # type: ignore[return-value]
            tag, profile=profile, overrides=overrides, port=port, **options
        )
    resume_from = options.pop("resume_from", None)
    if options:
        raise InputError(f"{', '.join(sorted(options))}: not an option of the arm")
    arm = load_profile(profile, overrides)
    check_bus(arm)
    program = build_program(tag, arm)
    check_resume(resume_from, program)
    if port is not None:
        check_port(port)
    job = ArmJob(tag, arm, program, port, planned_motion(program), sysfs)
    job.resume_from = resume_from
    return job


def arm_figures(outcome: _Outcome, profile: ArmProfile, port: str | None) -> dict[str, Any]:
    """The arm's own figures for the report (``details``) and :attr:`ArmRun.stats`."""
    program, result = outcome.program, outcome.result
    figures: dict[str, Any] = {
        "rate_hz": profile["motion.rate"],
        "readback_every": profile.readback_every,
        "time_scale": program.setpoints.time_scale,
        "mm_per_unit": program.setpoints.mm_per_unit,
        "approach_s": outcome.approach_s,
        "simulated": outcome.recorder,
        "port": port or "simulator",
    }
    if result is None or result.scheduler is None:
        figures["ticks_sent"] = 0
        return figures
    s = result.scheduler
    lateness = np.array(s.lateness) * 1e3 if s.lateness else np.zeros(1)
    sends = np.array(s.sends)
    loop_rate = math.nan
    jitter99 = math.nan
    if len(sends) > 1:
        span = sends[-1] - sends[0] - result.paused
        loop_rate = (len(sends) - 1) / span if span > 0 else math.nan
        across = np.zeros(len(sends) - 1, dtype=bool)
        for began, _ in result.pause_spans:  # a pause is no jitter (a stall is)
            across |= (sends[:-1] < began) & (sends[1:] > began)
        gaps = np.diff(sends)[~across]
        if len(gaps):
            jitter99 = float(np.percentile(np.abs(gaps - s.period), 99) * 1e3)
    reads = np.array(result.reads, dtype=float).reshape(-1, 1 + len(profile.bus_ids))
    figures.update(
        {
            "ticks_sent": result.ticks_sent,
            "loop_rate_hz": loop_rate,
            "period_jitter_p99_ms": jitter99,
            "lateness_p50_ms": float(np.percentile(lateness, 50)),
            "lateness_p99_ms": float(np.percentile(lateness, 99)),
            "max_lateness_ms": 1e3 * s.max_lateness,
            "late_ticks": s.late_ticks,
            "resyncs": s.resyncs,
            "resync_delay_s": s.resync_delay,
            "realtime": result.realtime,
            "wall_duration_s": result.end - result.start,
            "readbacks": len(result.read_clock),
            "corrupt_replies": result.corrupt_replies,
            "joint_tracking_error": tracking_error(reads, program, profile),
        }
    )
    if result.readback is not None:
        figures.update(result.readback.figures())
    return figures


def _recorder(driver: ArmDriver, profile: ArmProfile) -> Any:
    """The simulated chain behind the port, if any, with this arm's geometry set."""
    ser = driver.port.ser if driver.port is not None else None
    chain = getattr(ser, "chain", None)
    if chain is None or not callable(getattr(chain, "pen_trace", None)):
        return None
    if getattr(chain, "geometry", None) is None:
        try:
            chain.set_geometry(geometry_of(profile))
        except KeyError:  # not this arm's servos (a refused connect)
            return None
    return chain


def origin(result: StreamResult, program: ArmProgram) -> float:
    """Clock time of the executed clock's 0 (the job's: the first row sent is due at its own
    program time, the servos there ``lead`` after it was sent)."""
    return result.start + result.lead - float(program.joints[result.first, 0])


def _executed(trace: Array, result: StreamResult, program: ArmProgram) -> Array:
    """``t, x, y, pen`` samples (clock times) from when the first row sent is due (resumed:
    the row before it, where the arm stood) to the end of the stream (the last move over, or
    the safe stop after a fault), on the executed clock (:func:`origin`): pauses and host
    stalls stay in, as they happened."""
    trace = np.array(trace, dtype=float).reshape(-1, 4)
    zero = origin(result, program)
    t = trace[:, 0] - zero
    begin = float(program.joints[max(0, result.first - 1), 0])  # resumed: where the arm stood
    keep = (t >= begin - 1e-9) & (trace[:, 0] <= result.end + 1e-9)
    trace[:, 0] = t
    return trace[keep]


def _drawn_to(trace: Array, result: StreamResult, program: ArmProgram) -> float | None:
    """After a stop: the program time the pen drew to, or None if it never drew: that of the
    last pen-down sample (clock times in ``trace``) through the deadlines as they were (resyncs
    and pauses), at most the last goal sent's (the arm goes no further)."""
    trace = np.asarray(trace, dtype=float).reshape(-1, 4)
    down = trace[(trace[:, 3] > 0.5) & (trace[:, 0] <= result.end + 1e-9)]
    t = result.program_time(down[:, 0])
    t = t[np.isfinite(t)]
    if not len(t) or not result.ticks_sent:
        return None
    last = float(program.joints[result.first + result.ticks_sent - 1, 0])
    return min(float(t.max()) + float(program.joints[result.first, 0]), last)


def _outside_limits(present: NDArray[np.int64], profile: ArmProfile) -> list[str]:
    warnings = []
    for i, joint in enumerate(profile.joints):
        a = float(ticks_to_angles(present[i], joint))
        if not joint.lower - 1e-9 <= a <= joint.upper + 1e-9:
            warnings.append(
                f"{joint.name} starts at {math.degrees(a):.1f}° outside {joint.name}.min_deg.."
                f"max_deg ({math.degrees(joint.lower):.0f}..{math.degrees(joint.upper):.0f}°):"
                " moving it back"
            )
            log.warning("%s", warnings[-1])
    return warnings


def _write_joints(joints: Array, path: Path) -> None:
    """``t,shoulder,elbow,pen``: the planned goal ticks of every tick."""
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write("t,shoulder,elbow,pen\n")
        for t, a, b, c in np.asarray(joints, dtype=float).tolist():
            f.write(f"{t:.6f},{a:.0f},{b:.0f},{c:.0f}\n")
