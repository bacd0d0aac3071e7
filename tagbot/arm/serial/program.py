"""A tag on a serial arm: placement on the paper, the timed pen path, IK, retiming, the goals.

:func:`place_on_paper` puts the tag's ink (uniform scale, the profile's rotation, no mirror) in
the profile's ``area`` minus its margin, mm on the paper; ``place.scale = "fit"`` is the largest
that fits, centred. :func:`build_serial_program` then lays out the job at the loop period
``T = 1/motion.rate``::

    park ─► to above run 0 ─► approach ─► run 0 ─► retreat ─► travel ─► approach ─► … ─► park

- each run is its plan's drawn window (trimmed where less than ``motion.trim_mm`` of path is left
  at either end) on its run clock, eased from and to rest wherever it starts or ends with the
  plan moving (a trimmed end, or the plan touching down or lifting off moving:
  :func:`~tagbot.model.easing.run_clock` with ``ease_trimmed``), slowed by its own time scale
  ``s_k ≥ 1``: the lognormal speed along the paper, speeds ÷ ``s_k``;
- the approach and the retreat are minimum-jerk moves along the paper's normal between
  ``robot.pen_up`` above the run's first (last) point and ``robot.press`` below it: the ink
  starts where the plan's starts;
- travel between runs and the moves from and to park are minimum-jerk in joint space (at least
  as long as the straight line at ``motion.travel_speed`` would take), refused if the point
  would come closer to the paper than half the pen-up height.

Each run's samples (approach, ink, retreat) are solved by :meth:`SerialArm.solve_path` in one
pass from where the last run ended (continuous joints: no branch flip); then each move's joints
are checked by differences at the loop period, the move's own shape with the neighbours'
samples it owns (:func:`own_window`: where it starts or ends at rest, or a run's joins), and a
move that exceeds a joint's ``max_speed`` or ``max_acceleration`` is slowed by the excess and
the job solved again (a run keeps its shape: its scale grows; a pen-up move takes longer),
until none does. The goals are whole ticks chosen for the servos' time-based profile
(:func:`profile_goals`). A point out of
reach, beyond a joint limit, tilted beyond ``robot.max_tilt_deg`` or a run that must be slowed
more than ``motion.max_time_scale`` is a :class:`~tagbot.errors.PlacementError` naming the
plan, the stroke and the time, before anything is sent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from sim.dynamixel.physics import nib_drag
from tagbot.arm.kinematics import angles_to_ticks, exact_ticks
from tagbot.arm.place import ArmProgram, Placement, Setpoints
from tagbot.arm.serial.kinematics import PEN_SITE
from tagbot.arm.serial.profile import SerialProfile
from tagbot.arm.serial.reach import Paper
from tagbot.errors import PlacementError, ReachError
from tagbot.model import Tag
from tagbot.model.easing import RunClock, run_clock
from tagbot.model.motion import evaluate_plan, sample_ink

__all__ = ["build_serial_program", "min_jerk", "place_on_paper", "profile_goals"]

Array = NDArray[np.float64]

FINE_STEP = 0.001
"""Seconds (tag clock) between the samples used for the ink's extent and the trimming."""
MIN_JERK_PEAK_RATE = 1.875
MIN_JERK_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)
ROUNDS = 12
"""Most solve-and-retime rounds before giving up. A run is slowed by its excess and a margin
that doubles each round (1e-4 at first): the IK's pull of the pen's axis is one step per
sample, so a small part of a run's joint acceleration does not shrink with its time scale, and
a run found 1e-4 over a limit stayed over it, round after round (ga3 19981, session 22)."""


def min_jerk(n: int) -> Array:
    """``n + 1`` fractions 0..1 of a minimum-jerk move sampled evenly (both ends included)."""
    x = np.linspace(0.0, 1.0, n + 1)
    return x**3 * (10.0 - 15.0 * x + 6.0 * x**2)


def place_on_paper(tag: Tag, profile: SerialProfile) -> Placement:
    """Tag units to paper mm: the ink's box in ``area`` minus ``area.margin``, centred; with
    ``place.scale = "fit"`` as large as fits, else that many mm per unit (refused if it does
    not fit, naming the largest that does)."""
    theta = math.radians(profile["place.rotation"])
    rotation = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    points = np.concatenate([xy for _, xy, _ in sample_ink(tag, FINE_STEP)])
    turned = points @ rotation.T
    low, high = turned.min(axis=0), turned.max(axis=0)
    extent = high - low
    x_min, x_max, y_min, y_max = profile.area
    m = profile["area.margin"]
    room = np.array([x_max - x_min - 2 * m, y_max - y_min - 2 * m])
    ratios = [room[i] / extent[i] for i in range(2) if extent[i] > 1e-12]
    if not ratios:
        raise PlacementError("place.scale: the tag has no extent to place")
    largest = min(ratios)
    scale = profile["place.scale"]
    size = largest if scale == "fit" else float(scale)
    if size > largest * (1 + 1e-9):
        raise PlacementError(
            f"place.scale: {size:g} mm per unit does not fit in the area (at most {largest:.4g})"
        )
    centre = np.array([(x_min + x_max) / 2, (y_min + y_max) / 2])
    matrix = size * rotation
    offset = centre - size * (low + high) / 2  # the box's centre on the area's
    placed = points @ matrix.T + offset
    box = (*placed.min(axis=0), *placed.max(axis=0))
    return Placement(matrix, offset, size, (box[0], box[2], box[1], box[3]), largest)


def _trimmed_window(tag: Tag, k: int, placement: Placement, trim: float) -> tuple[float, float]:
    """Plan ``k``'s drawn window on the tag's clock: its ink window, less the onset and tail
    where less than ``trim`` mm of path is behind or ahead (a dot is drawn whole)."""
    plan = tag.plans[k]
    down, up = plan.ink_window(tag.size)
    if trim <= 0.0 or up <= down:
        return down, up
    t = np.arange(down, up, FINE_STEP)
    t = np.append(t[t < up], up)  # arange may overshoot ``up`` by a rounding error
    xy, _ = evaluate_plan(plan, t, tag.size)
    xy = xy @ placement.matrix.T
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    if s[-1] <= 2 * trim:
        return down, up
    first = t[max(0, int(np.searchsorted(s, trim, side="right")) - 1)]
    last = t[min(len(t) - 1, int(np.searchsorted(s, s[-1] - trim, side="left")))]
    return float(first), float(max(last, first))


@dataclass
class _Move:
    """One part of the job: ``kind`` (``park``, ``travel``, ``approach``, ``draw``, ``retreat``),
    its plan, and how it is sampled (a run's scale, or a move's duration)."""

    kind: str
    plan: int
    scale: float = 1.0
    duration: float = 0.0
    a: Array | None = None
    b: Array | None = None
    """Ends of a straight move (m, arm frame) or of a joint-space move (rad)."""


def _excess(q: Array, T: float, speed: Array, acceleration: Array) -> float:
    """How much the sampled move must slow down (> 1) to keep every joint within its limits,
    the arm standing still before and after it."""
    q = np.concatenate([q[:1], q, q[-1:]])
    rate = np.max(np.abs(np.diff(q, axis=0)), axis=0) / T / speed
    acc = np.max(np.abs(np.diff(q, 2, axis=0)), axis=0) / T**2 / acceleration
    return float(max(rate.max(), math.sqrt(acc.max())))


PEN_MOVES = ("approach", "retreat", "pen")
"""Kinds of the touch-down and lift-off moves (``pen`` in a program's segments)."""
JOINT_MOVES = ("travel", "park")
"""Kinds of the minimum-jerk moves in joint space."""


def own_window(kind: str, before: str | None, after: str | None) -> tuple[bool, bool]:
    """Whether a move of ``kind`` between moves of kinds ``before`` and ``after`` (None: none)
    owns the neighbour's sample on each side, that is whether that sample is where its own
    shape starts (ends) at rest, or, for a run, where it joins a pen move (a run may start and
    end moving: the joins are its own). A pen move's end beside travel or park is its own last
    sample, at rest: the next step is the joint-space move's, whose shape alone can slow it."""
    if kind not in PEN_MOVES:
        return before is not None, after is not None
    return (
        before is not None and before not in JOINT_MOVES,
        after is not None and after not in JOINT_MOVES,
    )


def move_excess(
    q: Array,
    first: int,
    stop: int,
    owns: tuple[bool, bool],
    T: float,
    speed: Array,
    acceleration: Array,
) -> float:
    """:func:`_excess` of the move at rows ``first:stop`` of the job's angles ``q``, with the
    neighbours' samples it owns (:func:`own_window`), standing still beyond them."""
    return _excess(q[first - owns[0] : stop + owns[1]], T, speed, acceleration)


def _owned(kinds: list[str]) -> list[tuple[bool, bool]]:
    """:func:`own_window` of each move of a sequence of kinds."""
    return [
        own_window(kind, kinds[i - 1] if i else None, kinds[i + 1] if i + 1 < len(kinds) else None)
        for i, kind in enumerate(kinds)
    ]


def _stroke_at(tag: Tag, k: int, tau: float) -> int:
    """The stroke of plan ``k`` under way at tag time ``tau`` (the last one begun)."""
    onsets = tag.plans[k].onsets
    return max(0, int(np.searchsorted(onsets, tau, side="right")) - 1)


def build_serial_program(
    tag: Tag, profile: SerialProfile, placement: Placement | None = None
) -> ArmProgram:
    """Place, lay out, solve and retime ``tag`` into per-tick joint goals (module docstring).

    Returns an :class:`~tagbot.arm.place.ArmProgram` whose ``angles`` are ``(N, joints)`` and
    ``joints`` ``(N, 1 + joints)`` (``t`` and goal ticks per joint); its setpoints are in mm on
    the paper (``pen`` True while the pen is meant to be on it)."""
    arm, paper = profile.arm, profile.paper
    placement = placement or place_on_paper(tag, profile)
    T = profile.period
    joints = profile.joints
    speed = np.array([j.max_speed for j in joints])
    acceleration = np.array([j.max_acceleration for j in joints])
    normal = paper.normal
    up, press = profile["robot.pen_up"] / 1000.0, profile["robot.press"] / 1000.0
    n = len(tag.plans)
    windows = [_trimmed_window(tag, k, placement, profile["motion.trim_mm"]) for k in range(n)]
    clocks = [run_clock(tag.plans[k], *windows[k], tag.size, ease_trimmed=True) for k in range(n)]
    ends = []
    for k in range(n):
        xy, _ = evaluate_plan(tag.plans[k], clocks[k].tag_time(np.array([0.0, clocks[k].duration])))
        mm = xy @ placement.matrix.T + placement.offset
        ends.append(paper.to_arm(mm / 1000.0, -press))
    lift = (up + press) * normal
    moves: list[_Move] = []
    approach = MIN_JERK_PEAK_RATE * (up + press) * 1000.0 / profile["motion.approach_speed"]
    for k in range(n):
        start, end = ends[k]
        if k:  # in joint space, at least as long as the straight line at travel_speed takes
            d = float(np.linalg.norm(start - ends[k - 1][1]))
            moves.append(
                _Move("travel", k, duration=MIN_JERK_PEAK_RATE * d * 1000.0 / _travel(profile))
            )
        moves.append(_Move("approach", k, duration=approach, a=start + lift, b=start))
        moves.append(_Move("draw", k))
        moves.append(_Move("retreat", k, duration=approach, a=end, b=end + lift))
    cap = profile["motion.max_time_scale"]
    kinds = [m.kind for m in moves]
    for attempt in range(ROUNDS):
        parts, q = _solve_job(moves, tag, clocks, placement, profile)
        starts = np.cumsum([0] + [len(p) for p, _, _ in parts])
        # Each move's own shape, with the samples it owns beside it: pen moves and travel
        # start and end at rest (minimum-jerk), so the steps meeting where two of them join
        # are their smallest; a run's joins are its own. check_serial_program checks the
        # whole job at the end.
        own = [
            move_excess(q, starts[i], starts[i + 1], owns, T, speed, acceleration)
            for i, owns in enumerate(_owned(kinds))
        ]
        slowed = False
        for m, (p, _, _), excess in zip(moves, parts, own, strict=True):
            if excess <= 1.0:
                continue
            slowed = True
            if m.kind == "draw":
                m.scale *= excess * (1.0 + 1e-4 * 2.0**attempt)
                if m.scale > cap:
                    raise PlacementError(
                        f"plan {m.plan}: must be slowed down {m.scale:.3g} times to keep every"
                        f" joint within its max_speed and max_acceleration, more than"
                        f" motion.max_time_scale = {cap:g} (raise it, or the joint limits, or"
                        " draw smaller)"
                    )
            else:  # sampled whole ticks: at least one tick longer, or nothing changes
                ticks = len(p) + (1 if m.kind == "travel" else 0)
                m.duration = max(m.duration * excess * (1.0 + 1e-4), (ticks + 1) * T)
        if not slowed:
            break
    else:  # pragma: no cover - converges in a few rounds
        raise PlacementError("retiming: did not converge")
    park = profile.park
    to_first = _joint_move(park, q[0], T, speed, acceleration)[:-1]
    to_park = _joint_move(q[-1], park, T, speed, acceleration)[1:]
    angles = np.concatenate([to_first, q, to_park])
    rows: list[tuple[Array, Array, NDArray[np.bool_], NDArray[np.intp]]] = []
    segments = [("travel", 0, 0, len(to_first))]
    rows.append(_pen_up_rows(arm.fk(to_first)[0], paper))
    at = len(to_first)
    for m, (p, mm, v) in zip(moves, parts, strict=True):
        kind = "pen" if m.kind in ("approach", "retreat") else m.kind
        segments.append((kind, m.plan, at, at + len(p)))
        if m.kind == "draw":
            rows.append((mm, v, np.ones(len(p), dtype=bool), np.full(len(p), m.plan)))
        else:
            rows.append(_pen_up_rows(p, paper))
        at += len(p)
    segments.append(("park", n - 1, at, at + len(to_park)))
    rows.append(_pen_up_rows(arm.fk(to_park)[0].reshape(-1, 3), paper))
    for kind, k, first, stop in segments:
        if kind in ("travel", "park") and stop > first:
            _check_clearance(angles[first:stop], profile, k, kind, first)
    N = len(angles)
    t = np.arange(N) * T
    pen = np.concatenate([r[2] for r in rows])
    aimed = angles + feedforward(angles, pen, profile) if profile["servo.feedforward"] else angles
    goals = profile_goals(aimed, profile)
    setpoints = Setpoints(
        t=t,
        xy=np.concatenate([r[0] for r in rows]),
        v=np.concatenate([r[1] for r in rows]),
        pen=pen,
        plan=np.concatenate([r[3] for r in rows]).astype(np.intp),
        period=T,
        mm_per_unit=placement.mm_per_unit,
        time_scale=max(m.scale for m in moves if m.kind == "draw"),
        limits={},
        placement=placement,
        run_scales=tuple(m.scale for m in moves if m.kind == "draw"),
        run_windows=tuple(windows),
        run_clocks=tuple(clocks),
    )
    program = ArmProgram(
        setpoints, angles, np.column_stack([t, goals.astype(float)]), tuple(segments)
    )
    check_serial_program(program, profile)
    return program


def _solve_job(
    moves: list[_Move],
    tag: Tag,
    clocks: list[RunClock],
    placement: Placement,
    profile: SerialProfile,
) -> tuple[list[tuple[Array, Array, Array]], Array]:
    """Each move's points (m, arm frame; a travel's the tip's through forward kinematics) and
    the job's joint angles: each run (approach, ink, retreat) solved in one pass from where the
    last one ended (park before the first), travel between runs a minimum-jerk move in joint
    space (no branch to flip, no joint motion on the spot where the pen-up points repeat)."""
    T, arm = profile.period, profile.arm
    parts: list[tuple[Array, Array, Array] | None] = [None] * len(moves)
    angles: list[Array | None] = [None] * len(moves)
    q_end = profile.park
    travel: int | None = None
    i = 0
    while i < len(moves):
        if moves[i].kind == "travel":
            travel, i = i, i + 1
            continue
        run = [i, i + 1, i + 2]  # approach, draw, retreat
        sampled = [_sample(moves[j], tag, clocks, placement, profile) for j in run]
        q = _solve(
            np.concatenate([p for p, _, _ in sampled]),
            sampled,
            [moves[j] for j in run],
            tag,
            clocks,
            profile,
            q_end,
        )
        at = 0
        for j, part in zip(run, sampled, strict=True):
            parts[j], angles[j] = part, q[at : at + len(part[0])]
            at += len(part[0])
        if travel is not None:
            count = max(2, math.ceil(moves[travel].duration / T - 1e-9))
            tq = q_end + min_jerk(count)[1:-1, None] * (q[0] - q_end)
            tips = arm.fk(tq)[0].reshape(-1, 3)
            parts[travel] = (tips, np.zeros((len(tq), 2)), np.zeros((len(tq), 2)))
            angles[travel] = tq
            travel = None
        q_end = q[-1]
        i += 3
    return [p for p in parts if p is not None], np.concatenate([a for a in angles if a is not None])


def profile_goals(angles: Array, profile: SerialProfile) -> NDArray[np.int64]:
    """Whole-tick goals for the joint angles ``(N, joints)`` planned one period apart.

    Each goal is a straight move of ``servo.profile_ms`` from where the servo's profile is,
    cut short by the next goal one period ``T`` later (the time-based profile with
    ``servo.acceleration_fraction = 0``; sent ``profile_ms`` ahead of its time): after one
    period the profile is ``p + α·(goal − p)``, ``α = T / profile_ms``. Rounding each goal
    alone puts the profile up to half a tick off the plan and lags it where the motion
    bends (on the OpenManipulator-X half a tick of a joint moves the pen 0.05-0.17 mm along
    the paper); here each goal is the whole tick that brings the profile nearest the plan's angle at
    that instant, from where the earlier goals left it: within ``α/2`` tick (a sixteenth at
    the profiles' 80 ms and 100 Hz, a quarter at 20 ms), its lag undone. Steady motion gets
    the same goals as rounding.
    Goals stay within the joints' ranges (the servos' position limits); with a ramped profile
    (``acceleration_fraction > 0``) each goal is the angle rounded."""
    joints = profile.joints
    exact = np.column_stack([exact_ticks(angles[:, i], j) for i, j in enumerate(joints)])
    if profile["servo.acceleration_fraction"] > 0.0 or not len(exact):
        return np.rint(exact).astype(np.int64)
    ends = np.array([angles_to_ticks([j.lower, j.upper], j) for j in joints])
    low, high = ends.min(axis=1), ends.max(axis=1)
    alpha = min(1.0, profile.period / profile.lead)
    # the plan's angle one period after each goal is sent (fractional rows between samples)
    rows = np.arange(len(exact)) + 1.0 - 1.0 / alpha
    target = np.column_stack(
        [np.interp(rows, np.arange(len(exact)), exact[:, i]) for i in range(len(joints))]
    )
    goals = np.empty(exact.shape, dtype=np.int64)
    where = goals[0] = np.clip(np.rint(exact[0]), low, high)  # the arm stands at the first
    for k in range(1, len(exact)):
        goal = np.clip(np.rint(where + (target[k] - where) / alpha), low, high)
        goals[k] = goal
        where = where + alpha * (goal - where)
    return goals


def _check_clearance(q: Array, profile: SerialProfile, plan: int, kind: str, tick: int) -> None:
    """Refuse a joint-space move that brings the pen's point closer than half the pen-up
    height to the paper's plane."""
    tips, _ = profile.arm.fk(q)
    paper = profile.paper
    height = (tips.reshape(-1, 3) - np.asarray(paper.origin)) @ paper.normal
    low = int(np.argmin(height))
    floor = profile["robot.pen_up"] / 2000.0
    if height[low] < floor:
        where = "to park" if kind == "park" else f"before plan {plan}"
        raise PlacementError(
            f"tick {tick + low} ({kind} {where}): the pen's point would pass"
            f" {1000 * height[low]:.1f} mm above the paper, less than half robot.pen_up"
            " (raise it, or move the park pose)"
        )


def _travel(profile: SerialProfile) -> float:
    return float(profile["motion.travel_speed"])


def feedforward(angles: Array, pen: NDArray[np.bool_], profile: SerialProfile) -> Array:
    """Radians to add to each planned angle so that the position loop's P term gives the
    torque the joint needs there: inverse dynamics of the description (gravity, inertia,
    Coriolis, its joint damping) at the planned angles, rates and accelerations (differences at
    the loop period), plus the motor's back-EMF at the planned rate, less the paper's force on
    the pen's point, all divided by the loop's stiffness (:attr:`SerialProfile.stiffness`).

    The paper's force along its normal, as the pen holder's preloaded spring gives it:
    ``robot.pen_preload`` (at most ``robot.pen_force``) as soon as the point is aimed into the
    paper, growing in proportion to ``robot.pen_force`` where it is aimed ``robot.press`` in
    (none above the paper), and the drag
    ``robot.pen_friction`` times that against the point's motion along the paper, by the law
    the simulator's paper has (:func:`sim.dynamixel.physics.nib_drag`). ``pen`` is
    unused beyond its length: the force follows the planned height. A single row is a pose
    standing still."""
    arm, T = profile.arm, profile.period
    model = arm.model
    data = mujoco.MjData(model)
    rate = _rate(angles, T)
    acc = _rate(rate, T)
    site = model.site(PEN_SITE).id
    jac = np.zeros((3, model.nv))
    paper = profile.paper
    normal, origin = paper.normal, np.asarray(paper.origin)
    press = max(profile["robot.press"], 1e-3) / 1000.0
    force, mu = profile["robot.pen_force"], profile["robot.pen_friction"]
    preload = min(profile["robot.pen_preload"], force)
    tips, _ = arm.fk(angles)
    velocity = _rate(tips, T)
    torque = np.empty_like(angles)
    for i in range(len(angles)):
        data.qpos[:] = angles[i]
        data.qvel[:] = rate[i]
        data.qacc[:] = acc[i]
        mujoco.mj_inverse(model, data)
        torque[i] = data.qfrc_inverse
        depth = -float(normal @ (tips[i] - origin))
        if depth > 0.0 and force > 0.0:
            push = (preload + (force - preload) * min(1.0, depth / press)) * normal
            slide = velocity[i] - (velocity[i] @ normal) * normal
            push = push + nib_drag(slide, float(np.linalg.norm(push)), mu)
            mujoco.mj_jacSite(model, data, jac, None, site)
            torque[i] -= jac.T @ push
    torque += profile.back_emf * rate
    del pen
    return torque / profile.stiffness


def _rate(rows: Array, period: float) -> Array:
    """Rates of change of rows one ``period`` apart (central differences); zero for a single row
    (a pose standing)."""
    if len(rows) < 2:
        return np.zeros_like(rows)
    return np.gradient(rows, period, axis=0)


def _pen_up_rows(
    points: Array, paper: Paper
) -> tuple[Array, Array, NDArray[np.bool_], NDArray[np.intp]]:
    """Setpoint rows of pen-up samples: the tip's points (m, arm frame) seen on the paper (mm),
    no planned velocity, pen up, no plan."""
    rel = (np.asarray(points, dtype=float).reshape(-1, 3) - np.asarray(paper.origin)) * 1000.0
    xy = np.column_stack([rel @ np.asarray(paper.x_axis), rel @ np.asarray(paper.y_axis)])
    count = len(xy)
    return xy, np.zeros((count, 2)), np.zeros(count, dtype=bool), np.full(count, -1, np.intp)


def _sample(
    m: _Move, tag: Tag, clocks: list[RunClock], placement: Placement, profile: SerialProfile
) -> tuple[Array, Array, Array]:
    """A move's points (m, arm frame) at the loop period, with (for a run) its positions (mm on
    the paper) and velocities (mm/s)."""
    T = profile.period
    if m.kind == "draw":
        clock, plan = clocks[m.plan], tag.plans[m.plan]
        count = max(1, math.ceil(clock.duration * m.scale / T - 1e-9))
        u = np.minimum(np.arange(count + 1) * T / m.scale, clock.duration)
        xy, v = evaluate_plan(plan, clock.tag_time(u), tag.size)
        mm = xy @ placement.matrix.T + placement.offset
        v = (v @ placement.matrix.T) * (clock.rate(u) / m.scale)[:, None]
        points = profile.paper.to_arm(mm / 1000.0, -profile["robot.press"] / 1000.0)
        return points, mm, v
    assert m.a is not None and m.b is not None
    count = max(2, math.ceil(m.duration / T - 1e-9))
    f = min_jerk(count)
    # Each point once: the approach ends before the run's first point, the retreat starts after
    # its last.
    f = {"approach": f[:-1], "retreat": f[1:]}[m.kind]
    points = m.a + f[:, None] * (m.b - m.a)
    return points, np.zeros((len(points), 2)), np.zeros((len(points), 2))


def _solve(
    points: Array,
    parts: list[tuple[Array, Array, Array]],
    moves: list[_Move],
    tag: Tag,
    clocks: list[RunClock],
    profile: SerialProfile,
    q0: Array,
) -> Array:
    """Joint angles of every point, one pass from ``q0``; a ReachError named by plan, stroke
    and time (the tag's clock for a run's point, the move's own otherwise)."""
    try:
        return profile.arm.solve_path(points, profile.paper.normal, profile.max_tilt, q0)
    except ReachError as exc:
        i = exc.index
        m = moves[-1]
        for move, (p, _, _) in zip(moves, parts, strict=True):
            m = move
            if i < len(p):
                break
            i -= len(p)
        T = profile.period
        if m.kind == "draw":
            u = min(i * T / m.scale, clocks[m.plan].duration)
            tau = float(clocks[m.plan].tag_time(np.array([u]))[0])
            stroke = _stroke_at(tag, m.plan, tau)
            where = f"plan {m.plan}, stroke {stroke}, t = {tau:.3f} s (tag clock)"
        else:
            side = "after" if m.kind == "retreat" else "before"
            where = f"plan {m.plan}, {m.kind} {side} it, t = {i * T:.3f} s into the move"
        raise ReachError(exc.detail, exc.index, exc.reason, where) from None


def _joint_move(a: Array, b: Array, T: float, speed: Array, acceleration: Array) -> Array:
    """A minimum-jerk move in joint space from ``a`` to ``b`` within the joints' limits,
    sampled at ``T`` (both ends included)."""
    d = np.abs(b - a)
    duration = max(
        0.2,
        float(np.max(MIN_JERK_PEAK_RATE * d / speed)),
        float(np.max(np.sqrt(MIN_JERK_PEAK_ACCELERATION * d / acceleration))),
    )
    count = max(1, math.ceil(duration / T - 1e-9))
    return a + min_jerk(count)[:, None] * (b - a)


def check_serial_program(program: ArmProgram, profile: SerialProfile) -> None:
    """Refuse a program whose joints leave their ranges, speeds or accelerations, or whose
    goals leave 0..4095 ticks; PlacementError naming the tick, its time and what it belongs
    to."""
    q, T = program.angles, profile.period

    def fail(k: int, message: str) -> PlacementError:
        return PlacementError(f"tick {k} (t = {k * T:.3f} s, {program.describe(k)}): {message}")

    for i, joint in enumerate(profile.joints):
        a = q[:, i]
        for bad, bound in (
            (a < joint.lower - 1e-9, joint.lower),
            (a > joint.upper + 1e-9, joint.upper),
        ):
            if bad.any():
                k = int(np.argmax(bad))
                raise fail(
                    k,
                    f"{joint.name} at {math.degrees(a[k]):.2f}° beyond its range end"
                    f" {math.degrees(bound):.2f}°",
                )
        rate = np.abs(np.diff(a)) / T
        if len(rate) and rate.max() > joint.max_speed * (1 + 1e-6):
            k = int(np.argmax(rate))
            raise fail(
                k + 1,
                f"{joint.name} speed {math.degrees(rate[k]):.1f}°/s above"
                f" {joint.name}.max_speed = {math.degrees(joint.max_speed):g}°/s",
            )
        acc = np.abs(np.diff(a, 2)) / T**2
        if len(acc) and acc.max() > joint.max_acceleration * (1 + 1e-6):
            k = int(np.argmax(acc))
            raise fail(
                k + 1,
                f"{joint.name} acceleration {math.degrees(acc[k]):.0f}°/s² above"
                f" {joint.name}.max_acceleration = {math.degrees(joint.max_acceleration):g}°/s²",
            )
    goals = program.goals
    out = (goals < 0) | (goals > 4095)
    if out.any():
        k, i = (int(v) for v in np.argwhere(out)[0])
        raise fail(k, f"{profile.joints[i].name} goal {goals[k, i]} ticks is outside 0..4095")
