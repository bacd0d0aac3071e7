"""The arm back end's entry point: :func:`draw_arm` plans, checks, connects, streams, reports.

Without a port it builds a simulated servo chain from the profile (IDs, models, baud rate,
geometry for its pen-tip recorder) and streams to it in process, in simulated time; with a port
(a device path, a pseudo-terminal or a pyserial URL) it streams there in real time.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tagbot.arm.driver import ArmDriver, StreamResult
from tagbot.arm.kinematics import Arm, angles_to_ticks, ticks_to_angles
from tagbot.arm.place import ArmProgram, Setpoints, approach, build_program
from tagbot.arm.profile import ArmProfile
from tagbot.draw import MachineRun
from tagbot.errors import DeviceError
from tagbot.io.motionfile import MotionTable
from tagbot.model import Tag

__all__ = ["ArmRun", "draw_arm", "draw_backend", "executed_from_reads", "simulated_chain"]

log = logging.getLogger(__name__)

Array = NDArray[np.float64]

_names = itertools.count()


@dataclass(frozen=True, eq=False)
class ArmRun:
    """What a drawing did.

    - ``setpoints``: the planned pen-tip motion at the loop period (``t``, ``xy``, ``v``,
      ``pen``; with ``mm_per_unit`` and ``time_scale`` of the placement);
    - ``joints``: ``(N, 4)`` planned goals per tick: ``t`` (s), shoulder, elbow, pen (ticks);
    - ``executed``: ``(M, 4)`` ``t, x, y, pen``: the simulator's pen-tip recorder (≤ 1 ms) when
      simulated, else the read-back present positions through FK; ``t`` is on the setpoints'
      clock (0 = when the pen should be at the first setpoint);
    - ``stats``: ``ticks_sent``, ``late_ticks``, ``max_lateness_ms``,
      ``joint_tracking_error`` (``{"max": deg, "mean": deg}``, read-backs against the plan),
      and ``rate_hz``, ``readbacks``, ``readback_every``, ``corrupt_replies``, ``resyncs``,
      ``lateness_p50_ms``, ``lateness_p99_ms``, ``time_scale``, ``mm_per_unit``,
      ``approach_s``, ``simulated``, ``port``.
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
    reads = np.asarray(reads, dtype=float).reshape(-1, 4)
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


def draw_arm(
    tag: Tag,
    profile: ArmProfile,
    port: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ArmRun:
    """Draw ``tag`` with the arm of ``profile`` on ``port`` (None: a simulated chain).

    The whole program is placed, retimed and checked before the port is opened
    (PlacementError); then connect (DeviceError listing the IDs found, wrong models), move to
    park, stream one goal row per tick, and return an :class:`ArmRun`. ``progress(done, total)``
    is called about ten times a second. Device errors and KeyboardInterrupt stop the arm safely
    (pen up) and are re-raised.
    """
    program = build_program(tag, profile)
    name = None
    if port is None:
        from sim.dynamixel import attach_chain

        name = f"tagbot_arm_{next(_names)}"
        url = attach_chain(simulated_chain(profile), name)
    else:
        url = port
    try:
        with ArmDriver(url, profile) as driver:
            try:
                driver.connect()
                present = driver.read_present()
                goals, duration = approach(present, profile)
                _warn_outside_limits(present, profile)
                driver.move_to(goals, duration)
                result = driver.stream(program.goals, progress)
            except BaseException:
                driver.safe_stop(error=True)
                raise
            chain = _recorder(driver, profile)
            reads = np.array(result.reads, dtype=float).reshape(-1, 4)
            if chain is not None:
                executed = _recorded(chain, result, program)
            else:
                executed = executed_from_reads(reads, profile)
    finally:
        if name is not None:
            from sim.dynamixel import detach_chain

            detach_chain(name)
    stats = _stats(result, reads, program, profile, duration, url, chain is not None)
    return ArmRun(program.setpoints, program.joints, executed, stats, program)


def _recorder(driver: ArmDriver, profile: ArmProfile) -> Any:
    """The simulated chain behind the port, if any, with this arm's geometry set."""
    ser = driver.port.ser if driver.port is not None else None
    chain = getattr(ser, "chain", None)
    if chain is None or not callable(getattr(chain, "pen_trace", None)):
        return None
    if getattr(chain, "geometry", None) is None:
        chain.set_geometry(geometry_of(profile))
    return chain


def _recorded(chain: Any, result: StreamResult, program: ArmProgram) -> Array:
    """The simulator's pen-tip trace on the setpoints' clock, cropped to the program."""
    trace = np.asarray(chain.pen_trace(), dtype=float).reshape(-1, 4)
    trace = trace.copy()
    trace[:, 0] -= result.origin
    end = program.joints[-1, 0]
    keep = (trace[:, 0] >= -1e-9) & (trace[:, 0] <= end + 1e-9)
    return trace[keep]


def _warn_outside_limits(present: NDArray[np.int64], profile: ArmProfile) -> None:
    for i, joint in enumerate(profile.joints):
        a = float(ticks_to_angles(present[i], joint))
        if not joint.lower - 1e-9 <= a <= joint.upper + 1e-9:
            log.warning(
                "%s starts at %.1f° outside %s.min_deg..max_deg (%.0f..%.0f°): moving it back",
                joint.name,
                math.degrees(a),
                joint.name,
                math.degrees(joint.lower),
                math.degrees(joint.upper),
            )


def _stats(
    result: StreamResult,
    reads: Array,
    program: ArmProgram,
    profile: ArmProfile,
    approach_s: float,
    port: str,
    simulated: bool,
) -> dict[str, Any]:
    s = result.scheduler
    assert s is not None
    lateness = np.array(s.lateness) * 1e3 if s.lateness else np.zeros(1)
    return {
        "ticks_sent": result.ticks_sent,
        "late_ticks": s.late_ticks,
        "max_lateness_ms": 1e3 * s.max_lateness,
        "joint_tracking_error": tracking_error(reads, program, profile),
        "rate_hz": profile["motion.rate"],
        "readbacks": len(reads),
        "readback_every": profile.readback_every,
        "corrupt_replies": result.corrupt_replies,
        "resyncs": s.resyncs,
        "lateness_p50_ms": float(np.percentile(lateness, 50)),
        "lateness_p99_ms": float(np.percentile(lateness, 99)),
        "time_scale": program.setpoints.time_scale,
        "mm_per_unit": program.setpoints.mm_per_unit,
        "approach_s": approach_s,
        "simulated": simulated,
        "port": port,
    }


def draw_backend(
    tag: Tag,
    out: Path,
    *,
    profile: str | Path | None = None,
    overrides: tuple[str, ...] = (),
    port: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> MachineRun:
    """The ``dynamixel`` entry of ``tagbot draw``: :func:`draw_arm`, plus ``joints.csv``.

    A device fault or Ctrl-C (the arm already stopped safely) comes back in
    :attr:`MachineRun.error` with the planned motion, for the run folder.
    """
    from tagbot.arm.profile import load_profile

    arm = load_profile(profile, overrides)
    error: BaseException | None = None
    try:
        run = draw_arm(tag, arm, port, progress)
        program, executed, stats = run.program, run.executed, dict(run.stats)
    except (DeviceError, KeyboardInterrupt) as e:
        error = e
        program, executed = build_program(tag, arm), np.zeros((0, 4))
        stats = {"error": str(e) or type(e).__name__, "port": port or "simulator"}
    assert program is not None
    _write_joints(program.joints, out / "joints.csv")
    sp = program.setpoints
    down = [k for k in range(len(tag.plans)) if np.any(sp.plan == k)]
    return MachineRun(
        device="dynamixel",
        motion=MotionTable(sp.t, sp.xy, sp.v, np.hypot(*sp.v.T), sp.pen.astype(np.int8)),
        planned_runs=[(sp.t[sp.plan == k], sp.xy[sp.plan == k]) for k in down],
        plans=down,
        executed=executed,
        placement={"mm_per_unit": sp.mm_per_unit, "time_scale": sp.time_scale},
        report=stats,
        error=error,
    )


def _write_joints(joints: Array, path: Path) -> None:
    """``t,shoulder,elbow,pen``: the planned goal ticks of every tick."""
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write("t,shoulder,elbow,pen\n")
        for t, a, b, c in np.asarray(joints, dtype=float).tolist():
            f.write(f"{t:.6f},{a:.0f},{b:.0f},{c:.0f}\n")
