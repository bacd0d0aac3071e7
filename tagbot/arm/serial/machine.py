"""The serial arm as a machine: ``tagbot draw --device dynamixel --profile openmanipulator-x``.

:func:`prepare` (called by :func:`tagbot.arm.run.prepare` for a serial profile) loads the
profile and its robot description, places, solves, retimes and checks the whole program
(:mod:`tagbot.arm.serial.program`) and checks the port's name before anything is written or
sent. :meth:`SerialJob.run` writes ``joints.csv`` (``t`` and one column per joint), connects with
the same driver as the planar arm (:class:`tagbot.arm.driver.ArmDriver`: sync-written goals on
absolute deadlines, a read-back that never blocks, pauses, faults and Ctrl-C), streams and
returns a :class:`~tagbot.draw.MachineRun` with the same report keys as every machine.

The pen is lifted by the arm (:class:`ArmLift`): a pause, a fault or Ctrl-C lifts it along the
paper's normal to ``robot.pen_up`` once the last goal is reached, and holds (torque off only if
``servo.torque_off_after_error``); a resumed job moves pen up above where it stopped and lowers
the pen there along the normal.

Without a port the servos are a simulated chain with MuJoCo physics behind it
(:class:`sim.dynamixel.physics.ArmPhysics`, in simulated time): the executed trace is where the
nib touched the paper (:meth:`~sim.dynamixel.physics.ArmPhysics.pen_trace`), and the report adds
per run the ink kept (``contact_kept_pct``: of the planned ink length, the share drawn with the
nib on the paper) and the contact force, with a warning when contact is lost or the force leaves
:data:`FORCE_RANGE`. With a port the executed trace is the read-back through forward kinematics
(the pen counted down where the tip is within ``robot.press`` of the paper).
"""

from __future__ import annotations

import itertools
import logging
import math
import re
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from tagbot.arm.driver import ArmDriver
from tagbot.arm.kinematics import angles_to_ticks, ticks_to_angles
from tagbot.arm.place import ArmProgram
from tagbot.arm.run import (
    _drawn_to,
    _executed,
    _Outcome,
    check_bus,
    check_resume,
    finish_run,
    origin,
    planned_motion,
)
from tagbot.arm.serial.kinematics import SerialArm
from tagbot.arm.serial.profile import SerialProfile, load_serial_profile
from tagbot.arm.serial.program import (
    MIN_JERK_PEAK_RATE,
    build_serial_program,
    feedforward,
    min_jerk,
    move_excess,
    own_window,
)
from tagbot.control import RunControl
from tagbot.draw import MachineRun
from tagbot.errors import DeviceError, InputError
from tagbot.io.motionfile import MotionTable
from tagbot.model import Tag
from tagbot.ports import check_port

__all__ = [
    "FORCE_RANGE",
    "ArmLift",
    "SerialJob",
    "contact_figures",
    "move_bounds",
    "prepare",
    "simulated_arm",
    "time_bound",
]

log = logging.getLogger(__name__)

Array = NDArray[np.float64]

_names = itertools.count()

FORCE_RANGE = (0.05, 1.1)
"""N: the nib's force on the paper while a run draws. Below the lower end there is no ink (the
simulator's ink threshold); above the upper the nib's spring (0.2 N preload, 200 N/m, 5 mm) is
nearly all compressed: the pen digs in."""

MAX_DEVIATION_MM = 0.3
"""A run's path deviation on the paper beyond this is a report warning."""
MIN_SPEED_SNR_DB = 25.0
"""A run's speed SNR below this is a report warning."""
SHORT_RUN_MM = 10.0
"""A run shorter than this (mm) is named short when its speed SNR is low."""


LIFT_LONGEST = 5.0
"""s: the longest lift by the arm (a pose the joints leave only slowly is lifted in this)."""


class ArmLift:
    """The pen lifted by the arm: from a pose, along the paper's normal to ``robot.pen_up``
    above the paper, minimum-jerk, slowed until every joint is within its limits."""

    def __init__(self, profile: SerialProfile, program: ArmProgram | None = None) -> None:
        self.profile = profile
        self.planned: dict[tuple[int, ...], Array] = {}
        """The program's goal rows → their planned angles (a goal is the planned angle plus
        the feedforward: the arm stands at the planned pose)."""
        if program is not None:
            for row, q in zip(program.goals.tolist(), program.angles, strict=True):
                self.planned.setdefault(tuple(row), q)
        self.arm: SerialArm = profile.arm
        self.paper = profile.paper
        self.joints = profile.joints
        self.speed = np.array([j.max_speed for j in self.joints])
        self.acceleration = np.array([j.max_acceleration for j in self.joints])

    def angles(self, row: NDArray[np.int64]) -> Array:
        return np.array([float(ticks_to_angles(row[i], j)) for i, j in enumerate(self.joints)])

    def height(self, q: Array) -> float:
        """The pen's point above the paper, m (negative: pressed in)."""
        tip, _ = self.arm.fk(q)
        return float(self.paper.normal @ (tip - np.asarray(self.paper.origin)))

    def is_up(self, row: NDArray[np.int64]) -> bool:
        """Whether the pose of ``row`` (ticks, e.g. present positions) holds the pen off the
        paper: its point at least half the pen-up height above it."""
        return self.height(self._pose(row)) >= self.profile["robot.pen_up"] / 2000.0

    def stand(self, row: NDArray[np.int64]) -> NDArray[np.int64]:
        """The goal row holding ``row``'s pose still (its feedforward without the motion's)."""
        return self._goals(self._pose(row)[None, :])

    def up(self, row: NDArray[np.int64]) -> NDArray[np.int64]:
        """Goal rows from ``row`` up to the pen-up height (empty when already there)."""
        return self._path(row)[1:]

    def down(self, row: NDArray[np.int64]) -> NDArray[np.int64]:
        """Goal rows from the pen-up height above ``row`` down to its pose, held still (the
        goal of a pose standing, not moving: its feedforward without the motion's)."""
        return self._path(row)[::-1]

    def _path(self, row: NDArray[np.int64]) -> NDArray[np.int64]:
        """Goal rows from ``row``'s planned pose (standing: the first row) to the pen-up height
        above it; just that first row when the pen is up already."""
        p = self.profile
        q = self._pose(row)
        tip, _ = self.arm.fk(q)
        n = self.paper.normal
        rise = p["robot.pen_up"] / 1000.0 - self.height(q)
        if rise <= 1e-4:
            return self._goals(q[None, :])
        T = p.period
        duration = MIN_JERK_PEAK_RATE * rise * 1000.0 / p["motion.approach_speed"]
        for _ in range(8):
            count = max(2, math.ceil(duration / T - 1e-9))
            points = tip + min_jerk(count)[:, None] * rise * n
            path = self.arm.solve_path(points, n, p.max_tilt, q)
            # from the pose itself: a pose the IK would hold otherwise (a present position
            # found by hand or sagged, its wrist at another tilt) keeps its own joints' offset
            # up the lift, not a jump to the IK's in one tick
            path += q - path[0]
            steps = np.concatenate([path[:1], path, path[-1:]])
            rate = np.max(np.abs(np.diff(steps, axis=0)), axis=0) / T / self.speed
            acc = np.max(np.abs(np.diff(steps, 2, axis=0)), axis=0) / T**2 / self.acceleration
            excess = max(float(rate.max()), math.sqrt(float(acc.max())))
            if excess <= 1.0:
                break
            duration = min(duration * excess * 1.01, LIFT_LONGEST)
        return self._goals(path)

    def _pose(self, row: NDArray[np.int64]) -> Array:
        """The angles of ``row``: the planned pose of a program's goal row, else the ticks',
        within the joints' ranges (an arm found with its torque off may lie a hair beyond one,
        where no goal may be sent)."""
        q = self.planned.get(tuple(int(v) for v in np.asarray(row).tolist()))
        if q is not None:
            return q
        return np.clip(self.angles(np.asarray(row)), self.arm.lower, self.arm.upper)

    def _goals(self, path: Array) -> NDArray[np.int64]:
        """Goal rows (ticks) of poses held in turn, pen up: with the torque each pose needs when
        ``servo.feedforward`` (as the program's goals)."""
        p = self.profile
        if p["servo.feedforward"]:
            path = path + feedforward(path, np.zeros(len(path), dtype=bool), p)
        goals = [angles_to_ticks(path[:, i], j) for i, j in enumerate(self.joints)]
        return np.column_stack(goals).astype(np.int64)


def _physics_model(profile: SerialProfile, folder: Path) -> Path:
    """The description with the profile's pen (``robot.tool_offset``), as an MJCF file (the
    nib kept as a ``fromto`` capsule, which the physics' scene needs)."""
    spec = mujoco.MjSpec.from_file(str(profile.description))
    SerialArm._place_tool(spec, profile.description, profile["robot.tool_offset"] / 1000.0)
    nib = spec.geom("pen_nib")
    text = spec.to_xml()
    if nib is not None:
        fromto = " ".join(f"{v:.9g}" for v in nib.fromto)
        text = re.sub(
            r'<geom name="pen_nib"[^>]*/>',
            f'<geom name="pen_nib" type="capsule" size="{nib.size[0]:.9g}" fromto="{fromto}"/>',
            text,
        )
    path = folder / "arm.xml"
    path.write_text(text, encoding="utf-8")
    return path


def simulated_arm(profile: SerialProfile, *, real_time: bool = False) -> tuple[Any, Any]:
    """A simulated chain of the profile's servos (at park) with MuJoCo physics behind it:
    ``(chain, physics)``, the paper where the profile puts it; ``real_time`` follows the wall
    clock (for a pseudo-terminal: ``tagbot sim arm --profile openmanipulator-x``)."""
    from sim.dynamixel import SimulatedChain
    from sim.dynamixel.physics import ArmPhysics, Sheet

    clock = "real" if real_time else "simulated"
    chain = SimulatedChain(servos=profile.servos, baud=profile["bus.baud"], clock=clock)
    park = profile.park
    for joint, angle in zip(profile.joints, park, strict=True):
        chain.set_position(joint.id, float(angles_to_ticks(angle, joint)))
    size = (profile["paper.width"] / 1000.0, profile["paper.height"] / 1000.0)
    with tempfile.TemporaryDirectory() as folder:
        model = _physics_model(profile, Path(folder))
        physics = ArmPhysics(
            chain,
            model,
            joints={j.id: j.name for j in profile.joints},
            paper=Sheet.of(profile.paper, size, profile["robot.pen_friction"]),
        )
    return chain, physics


def executed_from_reads(reads: Array, profile: SerialProfile) -> Array:
    """``(M, 4)`` ``t, x, y, pen`` from read-backs ``t`` + ticks per joint: the tip through
    forward kinematics on the paper (mm), pen down where it is within ``robot.press`` of the
    paper or in it."""
    reads = np.asarray(reads, dtype=float).reshape(-1, 1 + len(profile.joints))
    q = np.column_stack([ticks_to_angles(reads[:, 1 + i], j) for i, j in enumerate(profile.joints)])
    tip, _ = profile.arm.fk(q)
    paper = profile.paper
    rel = (tip.reshape(-1, 3) - np.asarray(paper.origin)) * 1000.0
    x, y = rel @ np.asarray(paper.x_axis), rel @ np.asarray(paper.y_axis)
    height = rel @ paper.normal
    pen = height <= profile["robot.press"] / 2
    return np.column_stack([reads[:, 0], x, y, pen.astype(float)])


@dataclass
class _SerialOutcome(_Outcome):
    force: Array = field(default_factory=lambda: np.zeros((0, 2)))
    """``t, N`` on the executed clock (the simulator's nib force), empty on a real arm."""
    contact_steps: float = math.nan


def _connect_and_stream(
    driver: ArmDriver,
    program: ArmProgram,
    profile: SerialProfile,
    outcome: _SerialOutcome,
    progress: Callable[[int, int], None] | None,
    control: RunControl | None,
    first: int,
) -> None:
    driver.lifter = ArmLift(profile, program)
    driver.connect()
    outcome.where = "approach"
    present = driver.read_present()
    if not driver.lifter.is_up(present):  # found on the paper: off it first, not across it
        driver.lift_from(present, "approach")
        present = driver.read_present()
    if first:  # above where the job stopped, then the pen down along the normal
        row = program.goals[first - 1]
        above = driver.lifter.up(row)
        target = above[-1] if len(above) else row
    else:
        target = program.goals[0]
    outcome.approach_s = _approach_time(present, target, profile)
    driver.move_to(target, outcome.approach_s)
    if first:
        driver.lower_pen(program.goals[first - 1])
    outcome.where = f"tick {first}"
    driver.stream(program.goals[first:], progress, control, first)


def _approach_time(present: NDArray[np.int64], goals: NDArray[np.int64], profile: Any) -> float:
    """How long the servos' own time-based move (ramps a quarter each way) from ``present`` to
    ``goals`` takes within every joint's speed and acceleration, at least 0.2 s."""
    duration = 0.2
    for i, joint in enumerate(profile.joints):
        d = abs(float(ticks_to_angles(goals[i], joint) - ticks_to_angles(present[i], joint)))
        duration = max(
            duration,
            4.0 * d / (3.0 * joint.max_speed),
            math.sqrt(16.0 * d / (3.0 * joint.max_acceleration)),
        )
    return duration


def _stream(
    program: ArmProgram,
    profile: SerialProfile,
    port: str | None,
    progress: Callable[[int, int], None] | None,
    control: RunControl | None,
    first: int = 0,
    fault: Callable[[Any], None] | None = None,
) -> _SerialOutcome:
    """Connect, approach, stream from row ``first``: the executed trace, and the error if one
    stopped it (the arm already stopped safely, pen lifted by the arm). ``fault(chain)`` arms
    a fault on the simulated chain (tests, benchmarks)."""
    from sim.dynamixel import attach_chain, detach_chain

    outcome = _SerialOutcome(program)
    name = physics = None
    if port is None:
        chain, physics = simulated_arm(profile)
        if fault is not None:
            fault(chain)
        name = f"tagbot_serial_arm_{next(_names)}"
        url = attach_chain(chain, name)
    else:
        url = port
    try:
        with ArmDriver(url, profile) as driver:
            try:
                _connect_and_stream(driver, program, profile, outcome, progress, control, first)
            except BaseException as e:
                outcome.stop(driver, e)
            outcome.result = result = getattr(driver, "result", None)
            if result is not None:
                outcome.where = f"tick {result.first + result.ticks_sent}"
                if physics is not None:
                    full = np.asarray(physics.pen_trace(FORCE_RANGE[0]), dtype=float)
                    outcome.contact_steps = float(np.mean(full[:, 3]))
                    trace = bridge_hops(full[:, :4], physics.model.geom_size[physics._nib][0])
                    outcome.recorder = True
                else:
                    full = None
                    trace = executed_from_reads(result.read_clock, profile)
                outcome.executed = _executed(trace, result, program)
                if full is not None:
                    zero = origin(result, program)
                    outcome.force = np.column_stack([full[:, 0] - zero, full[:, 4]])
                if outcome.error is not None:
                    outcome.until = _drawn_to(trace, result, program)
    except (DeviceError, KeyboardInterrupt) as e:  # opening or closing the port
        outcome.error = outcome.error or e
    finally:
        if name is not None:
            detach_chain(name)
    return outcome


HOP = 0.02
"""s: the longest loss of contact :func:`bridge_hops` closes (a pen lift takes far longer)."""


def bridge_hops(trace: Array, nib: float) -> Array:
    """The trace with the nib's hops closed: a gap in contact of at most :data:`HOP` and shorter
    on the paper than the nib's radius ``nib`` (m) leaves no gap in the line (the nib's width
    covers it), so its samples count as ink: what a nib inks is the union of where it touched,
    which such hops do not break. (The simulated nib hopped for single 1 ms steps at speed while
    MuJoCo's friction acted in its contact, BENCHMARKS.md session 20; with
    :func:`sim.dynamixel.physics.nib_drag` it stays on the paper through a run.)"""
    out = np.array(trace, dtype=float)
    pen = out[:, 3] > 0.5
    starts = np.flatnonzero(pen[:-1] & ~pen[1:]) + 1  # first sample off the paper
    ends = np.flatnonzero(~pen[:-1] & pen[1:]) + 1  # first sample back on it
    for s in starts:
        back = ends[ends > s]
        if not len(back):
            break
        e = int(back[0])
        short = out[e, 0] - out[s - 1, 0] <= HOP
        if short and math.hypot(*(out[e, 1:3] - out[s - 1, 1:3])) < nib * 1000.0:
            out[s:e, 3] = 1.0
    return out


def contact_figures(
    planned_runs: list[tuple[Array, Array]],
    executed: Array,
    force: Array,
    pauses: list[tuple[float, float]] = (),  # type: ignore[assignment]
) -> list[dict[str, float]]:
    """Per planned run: ``contact_kept_pct`` (of its planned ink length, the share whose
    instant finds the nib on the paper; the executed clock runs on through ``pauses``,
    ``(start, length)``, so planned instants after one are found that much later),
    ``force_min_n`` and ``force_max_n`` while it draws (NaN without a force record)."""
    out = []
    t_exec, pen = executed[:, 0], executed[:, 3] > 0.5
    for t, xy in planned_runs:
        t = _on_executed_clock(t, pauses)
        if len(t) < 2 or not len(t_exec):
            out.append(
                {"contact_kept_pct": math.nan, "force_min_n": math.nan, "force_max_n": math.nan}
            )
            continue
        mid = 0.5 * (t[1:] + t[:-1])
        length = np.hypot(*np.diff(xy, axis=0).T)
        i = np.clip(np.searchsorted(t_exec, mid), 0, len(t_exec) - 1)
        kept = float(np.sum(length[pen[i]]) / np.sum(length)) if np.sum(length) > 0 else 1.0
        figures = {"contact_kept_pct": 100.0 * kept}
        if len(force):
            inside = (force[:, 0] >= t[0]) & (force[:, 0] <= t[-1])
            f = force[inside, 1] if inside.any() else np.zeros(1)
            figures.update(force_min_n=float(f.min()), force_max_n=float(f.max()))
        else:
            figures.update(force_min_n=math.nan, force_max_n=math.nan)
        out.append(figures)
    return out


def _on_executed_clock(t: Array, pauses: list[tuple[float, float]]) -> Array:
    """Planned instants on the executed clock: each pause (``start``, ``length`` on the
    executed clock) puts everything after it that much later."""
    out = np.array(t, dtype=float)
    for start, length in sorted(pauses):
        out[out >= start - 1e-9] += length
    return out


@dataclass(frozen=True, eq=False)
class SerialBudget:
    """The serial arm's budgets for :attr:`~tagbot.draw.MachineRun.judge`: per run, path
    deviation on the paper within :data:`MAX_DEVIATION_MM`, speed SNR at least
    :data:`MIN_SPEED_SNR_DB`, contact kept through the planned ink and the nib's force within
    :data:`FORCE_RANGE`; a warning naming the run and the figure otherwise. A run whose SNR
    is low and whose planned path is shorter than :data:`SHORT_RUN_MM` is named as such: the
    arm's speed error, under 1 mm/s rms on every run whatever its speed (the servos' whole-tick
    goals), is as large as such a run's motion (measured on the simulator: a 1.4 mm run at 6
    mm/s rms scores 19-22 dB; BENCHMARKS.md, sessions 21 and 22)."""

    contacts: list[dict[str, float]]
    lengths: list[float] = field(default_factory=list)
    """Each run's planned path length, mm."""

    def __call__(self, report: dict[str, Any]) -> list[str]:
        out = []
        for i, run in enumerate(report.get("runs", [])):
            over = []
            deviation, snr = run.get("path_deviation_max_mm"), run.get("speed_snr_db")
            if deviation is not None and deviation > MAX_DEVIATION_MM:
                over.append(f"path deviation {deviation:.3f} mm over {MAX_DEVIATION_MM:g} mm")
            if snr is not None and snr < MIN_SPEED_SNR_DB and not run.get("cut_short"):
                why = ""
                if i < len(self.lengths) and self.lengths[i] < SHORT_RUN_MM:
                    why = (
                        f" (a short run, {self.lengths[i]:.1f} mm: the arm's speed error, set by"
                        " the servos' whole ticks, is as large as its motion)"
                    )
                over.append(f"speed SNR {snr:.1f} dB below {MIN_SPEED_SNR_DB:g} dB{why}")
            if i < len(self.contacts):
                c = self.contacts[i]
                run.update(c)
                kept = c["contact_kept_pct"]
                if math.isfinite(kept) and kept < 100.0:
                    over.append(f"contact lost: ink on {kept:.1f} % of the planned ink length")
                high = c["force_max_n"]
                if math.isfinite(high) and high > FORCE_RANGE[1]:
                    over.append(
                        f"the nib's force reached {high:.2f} N, above {FORCE_RANGE[1]:g} N"
                        " (the pen digs in)"
                    )
            if over:
                out.append(f"run {i + 1} (plan {run['plan']}): {' and '.join(over)}")
                log.warning("%s", out[-1])
        return out


@dataclass(eq=False)
class SerialJob:
    """A checked serial-arm job (:func:`prepare`): nothing written, nothing sent yet."""

    tag: Tag
    profile: SerialProfile
    program: ArmProgram
    port: str | None
    planned: MotionTable
    device: str = "dynamixel"
    resume_from: int | None = None
    fault: Callable[[Any], None] | None = None
    """Arms a fault on the simulated chain before the run (tests and benchmarks)."""

    def run(
        self,
        out: Path,
        *,
        progress: Callable[[int, int], None] | None = None,
        control: RunControl | None = None,
    ) -> MachineRun:
        """Write ``joints.csv`` into ``out``, connect, stream; what happened, also after a fault
        or Ctrl-C (the pen lifted by the arm first)."""
        program, profile = self.program, self.profile
        _write_joints(program.joints, profile, Path(out) / "joints.csv")
        first = 0 if self.resume_from is None else self.resume_from - 1
        outcome = _stream(program, profile, self.port, progress, control, first, self.fault)

        stopped = (
            "the arm stopped, pen lifted by the arm",
            "the arm stopped, but the pen was not lifted by the arm",
        )

        def judge(figures: dict[str, Any], runs: list, pauses: list, stalls: list) -> SerialBudget:
            figures["lifted_by_arm_at_stop"] = outcome.lifted
            contacts = contact_figures(runs, outcome.executed, outcome.force, pauses)
            figures["runs_contact"] = contacts
            figures["time_bound_s"] = time_bound(program, profile)
            lengths = [float(np.sum(np.hypot(*np.diff(xy, axis=0).T))) for _, xy in runs]
            return SerialBudget(contacts, lengths)

        return finish_run(
            outcome, program, profile, self.port, first, self.device, self.planned,
            len(self.tag.plans), stopped,
            "physics simulator: the nib's contact with the paper, 1 ms", judge,
        )  # fmt: skip


def time_bound(program: ArmProgram, profile: SerialProfile) -> float:
    """The shortest time the joints allow for this job's moves, s: the sum of
    :func:`move_bounds`. The program's duration over this is what the Cartesian speed caps
    (``motion.travel_speed``, ``motion.approach_speed``) and the sampling cost."""
    return float(sum(move_bounds(program, profile)))


def move_bounds(program: ArmProgram, profile: SerialProfile) -> list[float]:
    """Per segment of the program (a run, an approach, a retreat, travel, the moves from and
    to park), the shortest time the joints allow it, s: the move with its own shape sped up
    until a joint meets its ``max_speed`` or ``max_acceleration`` (its duration ÷ its excess:
    rates scale with 1/duration, accelerations with 1/duration²; with the neighbours' samples
    it owns, :func:`~tagbot.arm.serial.program.own_window`), a run never faster than the tag's
    own timing."""
    T = profile.period
    speed = np.array([j.max_speed for j in profile.joints])
    acceleration = np.array([j.max_acceleration for j in profile.joints])
    scales = iter(program.setpoints.run_scales)
    q, segments = program.angles, program.segments
    out = []
    for i, (kind, _, first, stop) in enumerate(segments):
        duration = (stop - first) * T
        owns = own_window(
            kind,
            segments[i - 1][0] if i else None,
            segments[i + 1][0] if i + 1 < len(segments) else None,
        )
        fastest = 0.0
        if duration > 0 and stop + owns[1] - (first - owns[0]) >= 2:
            fastest = duration * move_excess(q, first, stop, owns, T, speed, acceleration)
        if kind == "draw":
            fastest = max(fastest, duration / next(scales))
        out.append(fastest)
    return out


def _write_joints(joints: Array, profile: SerialProfile, path: Path) -> None:
    """``t`` and one column per joint: the planned goal ticks of every tick."""
    names = [j.name for j in profile.joints]
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write(",".join(["t", *names]) + "\n")
        for row in np.asarray(joints, dtype=float).tolist():
            f.write(f"{row[0]:.6f}," + ",".join(f"{v:.0f}" for v in row[1:]) + "\n")


def prepare(
    tag: Tag,
    *,
    profile: str | Path | None = None,
    overrides: tuple[str, ...] = (),
    port: str | None = None,
    **options: Any,
) -> SerialJob:
    """The serial arm's back end of ``tagbot draw --device dynamixel``: load the profile,
    place, solve, retime and check the program (PlacementError naming plan, stroke and time),
    check the port's name, all before anything is written or sent."""
    resume_from = options.pop("resume_from", None)
    options.pop("sysfs", None)
    if options:
        raise InputError(f"{', '.join(sorted(options))}: not an option of the arm")
    machine = load_serial_profile(profile, overrides)
    check_bus(machine)
    program = build_serial_program(tag, machine)
    check_resume(resume_from, program)
    if port is not None:
        check_port(port)
    job = SerialJob(tag, machine, program, port, planned_motion(program))
    job.resume_from = resume_from
    return job
