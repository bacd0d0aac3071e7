"""The serial arm's job time and fidelity (issue 32's benchmark goals): a move slowed only by its
own joints, the job's bound counting each move by its own shape, whole-tick goals that bring the
servos' profile nearest the plan, the pen holder's preload in the feedforward."""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

import tagbot
from sim.dynamixel.servo import Trajectory, plan_time_based
from tagbot.arm.kinematics import exact_ticks
from tagbot.arm.serial.kinematics import PEN_SITE
from tagbot.arm.serial.machine import move_bounds, time_bound
from tagbot.arm.serial.profile import load_serial_profile
from tagbot.arm.serial.program import (
    MIN_JERK_PEAK_RATE,
    build_serial_program,
    feedforward,
    profile_goals,
)
from tagbot.model import Plan, Tag

EXAMPLES = Path(tagbot.__file__).parent / "examples"


def _stroke(a: list[float], b: list[float], start: float = 0.0) -> Plan:
    return Plan(
        targets=[a, b],
        dt=[0.0],
        mu=[math.log(0.2)],
        sigma=[0.3],
        phi1=[0.0],
        phi2=[0.0],
        start=start,
    )


@pytest.fixture
def profile():
    return load_serial_profile("openmanipulator-x")


def _hop_tag() -> Tag:
    """Two runs, the second starting a hop (about 2 mm on the paper) from where the first
    ends."""
    first = _stroke([0.0, 0.0], [10.0, 0.0])
    second = _stroke([10.3, 0.3], [10.3, 8.0], start=first.end(15.0) + 0.3)
    return Tag(plans=(first, second))


@pytest.fixture
def hop(profile):
    """:func:`_hop_tag`'s program: the travel between the runs is as short as the joints
    allow."""
    return build_serial_program(_hop_tag(), profile)


@pytest.fixture
def letter_b(profile):
    return build_serial_program(tagbot.load_plan(EXAMPLES / "letter-b.json"), profile)


# -- job time ---------------------------------------------------------------------------------


def test_a_short_travel_slows_itself_not_the_lift_and_touch_down_beside_it(hop, profile) -> None:
    """The travel between the two runs starts and ends at rest: its own shape alone is what the
    joints must allow; the lift-off before it and the touch-down after it keep their own pace
    (was: each slowed as much as the travel, 0.22 s -> 0.40 s)."""
    T = profile.period
    nominal = MIN_JERK_PEAK_RATE * (profile["robot.pen_up"] + profile["robot.press"])
    nominal /= profile["motion.approach_speed"]
    kinds = [kind for kind, *_ in hop.segments]
    middle = kinds.index("travel", 1)
    assert kinds[middle - 1 : middle + 2] == ["pen", "travel", "pen"]
    bounds = move_bounds(hop, profile)
    for i in (middle - 1, middle + 1):
        _, _, first, stop = hop.segments[i]
        assert (stop - first) * T == pytest.approx(math.ceil(nominal / T - 1e-9) * T)
        assert bounds[i] < (stop - first) * T  # the joints alone would lift it faster
    _, _, first, stop = hop.segments[middle]
    assert bounds[middle] == pytest.approx((stop - first) * T, rel=0.1)  # the joints bind


def test_a_pen_moves_bound_is_its_own_whatever_the_travel_beside_it() -> None:
    """The two runs drawn small (2 mm per unit: the travel between them takes two ticks), then
    with that travel slowed to a 5 mm/s pace: the lift-off and the touch-down beside it, the
    same moves, keep the same bound (the travel's first step is the travel's)."""
    small = ["place.scale=2"]
    programs = []
    for extra in ([], ["motion.travel_speed=5"]):
        profile = load_serial_profile("openmanipulator-x", small + extra)
        program = build_serial_program(_hop_tag(), profile)
        programs.append((program.segments, move_bounds(program, profile)))
    (fast, fast_bounds), (slow, slow_bounds) = programs
    middle = [kind for kind, *_ in fast].index("travel", 1)
    assert [s[0] for s in slow] == [s[0] for s in fast]
    assert slow[middle][3] - slow[middle][2] > 10 * (fast[middle][3] - fast[middle][2])
    for i in (middle - 1, middle + 1):
        assert slow[i][3] - slow[i][2] == fast[i][3] - fast[i][2]
        assert slow_bounds[i] == pytest.approx(fast_bounds[i], rel=1e-9)


def test_the_jobs_bound_is_the_sum_of_its_moves_own_bounds(hop, letter_b, profile) -> None:
    for program in (hop, letter_b):
        bounds = move_bounds(program, profile)
        assert len(bounds) == len(program.segments)
        assert time_bound(program, profile) == pytest.approx(sum(bounds))
        for (kind, _, first, stop), bound in zip(program.segments, bounds, strict=True):
            assert 0.0 < bound <= (stop - first) * profile.period * (1 + 1e-6), kind
    # With joints fast enough that the hop's second run is not slowed (time scale 1), that
    # run's bound is the tag's own timing, its whole duration, not what the joints would allow.
    fast = load_serial_profile(
        "openmanipulator-x",
        [f"joint{i}.max_speed=300" for i in range(1, 5)]
        + [f"joint{i}.max_acceleration=3000" for i in range(1, 5)],
    )
    program = build_serial_program(_hop_tag(), fast)
    assert program.setpoints.run_scales[1] == 1.0
    draws = [
        (stop - first, bound)
        for (kind, _, first, stop), bound in zip(
            program.segments, move_bounds(program, fast), strict=True
        )
        if kind == "draw"
    ]
    ticks, bound = draws[1]
    assert bound == pytest.approx(ticks * fast.period, rel=1e-12)


# -- goals --------------------------------------------------------------------------------------


def _profile_after_one_period(goals: np.ndarray, profile) -> np.ndarray:
    """Where each joint's time-based profile (the simulated servo's own) is one period after
    each goal arrives, goals arriving every period from standing at the first."""
    T, move = profile.period, profile.lead
    out = np.empty(goals.shape)
    for j in range(goals.shape[1]):
        trajectory = Trajectory(0.0, float(goals[0, j]))
        for k in range(len(goals)):
            t = k * T
            p, v = trajectory.state(t)
            pieces, _ = plan_time_based(p, v, float(goals[k, j]), move, 0.0, math.inf)
            trajectory.replan(t, p, pieces, final_position=float(goals[k, j]))
            out[k, j] = trajectory.state(t + T)[0]
    return out


def test_the_servos_profile_follows_the_plan_within_half_its_step(letter_b, profile) -> None:
    """Goal k is sent ``profile_ms`` ahead of its time, so one period T after it arrives the
    servo's profile should be where the plan is ``profile_ms − T`` before goal k's time: within
    half of the profile's step T/profile_ms of a tick on every joint (a sixteenth of a tick
    at 80 ms and 100 Hz; each goal rounded alone: up to half a tick, and a lag where the motion
    bends)."""
    q = letter_b.angles
    aimed = q + feedforward(q, letter_b.setpoints.pen, profile)
    exact = np.column_stack([exact_ticks(aimed[:, i], j) for i, j in enumerate(profile.joints)])
    late = round(profile.lead / profile.period) - 1  # rows the profile stands behind
    assert profile.period / profile.lead == 0.125
    reached = _profile_after_one_period(letter_b.goals, profile)
    error = reached[late:] - exact[: len(exact) - late]
    assert np.max(np.abs(error)) <= profile.period / profile.lead / 2 + 1e-9
    rounded = _profile_after_one_period(np.rint(exact), profile)
    assert np.max(np.abs(rounded[late:] - exact[: len(exact) - late])) > 0.5  # rounding alone


def test_goals_stay_whole_ticks_within_the_joints_ranges(profile) -> None:
    joint = profile.joints[1]
    top = float(exact_ticks(joint.upper, joint))
    # towards the range's end fast: the profile's catch-up would ask beyond it; then held there
    # as long as a goal is sent ahead of its angle (servo.profile_ms), so the last goal is the end
    ahead = round(profile.lead / profile.period)
    angles = np.zeros((6 + ahead, len(profile.joints)))
    angles[:, 1] = joint.upper
    angles[:6, 1] = np.linspace(joint.upper - 0.05, joint.upper, 6)
    goals = profile_goals(angles, profile)
    assert goals.dtype == np.int64
    assert goals[:, 1].max() <= round(top)
    assert goals[-1, 1] == round(top)


def test_a_ramped_profile_gets_each_goal_rounded(letter_b) -> None:
    ramped = load_serial_profile("openmanipulator-x", ["servo.acceleration_fraction=0.25"])
    q = letter_b.angles
    goals = profile_goals(q, ramped)
    exact = np.column_stack([exact_ticks(q[:, i], j) for i, j in enumerate(ramped.joints)])
    assert np.array_equal(goals, np.rint(exact))


# -- the feedforward ----------------------------------------------------------------------------


def test_the_feedforward_pushes_back_with_the_springs_preload_as_the_nib_touches(
    letter_b, profile
) -> None:
    """Just into the paper, the holder's spring already pushes with ``robot.pen_preload``;
    ``press`` in, with ``robot.pen_force``: the feedforward's paper force follows that law."""
    k = next(first for kind, _, first, _ in letter_b.segments if kind == "draw")
    standing = letter_b.angles[k : k + 1]  # the run's first pose, aimed `press` in
    arm, paper = profile.arm, profile.paper
    tip, _ = arm.fk(standing[0])
    normal = paper.normal
    free = load_serial_profile("openmanipulator-x", ["robot.pen_force=0", "robot.pen_preload=0"])
    pen = np.zeros(1, dtype=bool)

    def paper_torque(depth_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """N·m the feedforward gives each joint for the paper's push, the point aimed
        ``depth_mm`` into the paper (standing)."""
        point = tip + (profile["robot.press"] - depth_mm) / 1000.0 * normal
        q = arm.solve_path(point[None, :], normal, profile.max_tilt, standing[0])
        ff = feedforward(q, pen, profile) - feedforward(q, pen, free)
        return ff[0] * profile.stiffness, q[0]

    for depth in (1e-3, 0.75, 1.5):
        torque, q = paper_torque(depth)
        force = 0.2 + (0.5 - 0.2) * depth / 1.5  # the preload, then the spring's rate
        expected = -(_jacobian(profile, q).T @ (force * normal))
        assert torque == pytest.approx(expected, rel=1e-3, abs=1e-6)
    torque, _ = paper_torque(-0.5)  # above the paper: no force
    assert np.allclose(torque, 0.0)


def test_two_rows_are_fed_forward_as_a_move_not_a_pose_standing(letter_b, profile) -> None:
    """Two rows one period apart are a move at the rate between them (its back-EMF and damping
    fed forward), as the first row of the same steady move three rows long; one row stands."""
    k = next(first for kind, _, first, _ in letter_b.segments if kind == "draw") + 50
    a, b = letter_b.angles[k], letter_b.angles[k + 1]  # mid-run: moving, the pen on the paper
    pen = np.ones(3, dtype=bool)
    two = feedforward(np.array([a, b]), pen[:2], profile)
    steady = feedforward(np.array([a, b, 2 * b - a]), pen, profile)
    standing = feedforward(a[None, :], pen[:1], profile)
    assert two[0] == pytest.approx(steady[0], rel=1e-6, abs=1e-9)
    assert np.abs(two[0] - standing[0]).max() > 1e-4  # the rate is felt


def _jacobian(profile, q: np.ndarray) -> np.ndarray:
    """The pen point's position Jacobian at ``q`` (3 × joints)."""
    model = profile.arm.model
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)
    jac = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jac, None, model.site(PEN_SITE).id)
    return jac
