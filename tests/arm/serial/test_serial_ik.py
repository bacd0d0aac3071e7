"""IK by mink against MuJoCo's FK: round trips, continuous paths, limits, tilt and refusals."""

from __future__ import annotations

import math
import re

import mink
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tagbot.arm.serial.kinematics import PEN_SITE, SerialArm, TiltLimit, _PathSolver
from tagbot.errors import PlacementError, ReachError

UP = np.array([0.0, 0.0, 1.0])  # a table's normal
TILT = math.radians(30)
TOL = 1e-5  # 0.01 mm, the bound


@pytest.fixture(scope="module")
def arm() -> SerialArm:
    return SerialArm.load()


def tilts(axes: np.ndarray, normal: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip(-axes @ normal, -1.0, 1.0))


def check_path(arm: SerialArm, q: np.ndarray, points: np.ndarray, normal, max_tilt) -> None:
    """What every solved path must hold: on the points, in the ranges, within the tilt."""
    tip, axis = arm.fk(q)
    assert np.linalg.norm(tip - points, axis=1).max() < TOL
    assert np.all(q >= arm.lower) and np.all(q <= arm.upper)
    assert tilts(axis, np.asarray(normal)).max() <= max_tilt + 1e-9


@settings(
    max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(st.integers(0, 2**32 - 1))
def test_ik_round_trips_fk_on_random_reachable_points(arm: SerialArm, seed: int) -> None:
    """A pose drawn at random gives a point and a normal facing its pen; IK from a start up to
    0.3 rad away puts the pen back on the point within 0.01 mm, the pen within the tilt."""
    rng = np.random.default_rng(seed)
    while True:
        truth = rng.uniform(arm.lower + 0.1, arm.upper - 0.1)
        if not arm.contacts(truth):
            break
    point, axis = arm.fk(truth)
    start = np.clip(truth + rng.uniform(-0.3, 0.3, 4), arm.lower, arm.upper)
    q = arm.solve_path(point[None], -axis, TILT, start)
    check_path(arm, q, point[None], -axis, TILT)


def test_a_straight_line_on_the_table_has_no_branch_flip(arm: SerialArm) -> None:
    # 12 cm across the front of the base, a point every 0.5 mm, the pen within 10° of vertical
    y = np.linspace(-0.06, 0.06, 241)
    line = np.stack([np.full_like(y, 0.17), y, np.zeros_like(y)], 1)
    q = arm.solve_path(line, UP, math.radians(10), np.zeros(4))
    check_path(arm, q, line, UP, math.radians(10))
    steps = np.abs(np.diff(q, axis=0))
    # 0.5 mm at ≥ 0.1 m from joint1 turns it ≤ 5 mrad; the other joints move less: no joint
    # steps more than 10 mrad (a flip of branch is ~1 rad) and the steps change smoothly
    assert steps.max() < 0.01
    assert np.abs(np.diff(q, n=2, axis=0)).max() < 1e-3
    assert q[0, 0] < 0 < q[-1, 0]  # joint1 sweeps from right to left


def test_a_circle_on_a_tilted_board(arm: SerialArm) -> None:
    # a board facing the arm, its normal tipped 60° from vertical towards the base
    normal = np.array([-math.sin(math.radians(60)), 0.0, math.cos(math.radians(60))])
    u = np.array([0.0, 1.0, 0.0])
    v = np.cross(normal, u)
    t = np.linspace(0, 2 * math.pi, 300)
    centre = np.array([0.20, 0.0, 0.12])
    circle = centre + 0.03 * np.cos(t)[:, None] * u + 0.03 * np.sin(t)[:, None] * v
    q = arm.solve_path(circle, normal, math.radians(25), np.zeros(4))
    check_path(arm, q, circle, normal, math.radians(25))
    assert np.abs(np.diff(q, axis=0)).max() < 0.02
    np.testing.assert_allclose(q[-1], q[0], atol=1e-3)  # around and back to the same pose


def test_an_unreachable_point_is_refused_with_its_index(arm: SerialArm) -> None:
    path = np.array([[0.15, 0.0, 0.0]] * 5 + [[0.50, 0.0, 0.0]])
    with pytest.raises(ReachError) as err:
        arm.solve_path(path, UP, math.radians(89), np.zeros(4))
    assert err.value.index == 5 and err.value.reason == "reach"
    # followed 2 mm at a time from point 4, the tip stops where the arm is stretched out
    assert re.fullmatch(
        r"point 5: \(0\.4\d\d0, 0\.0000, 0\.0000\) m is out of the arm's reach \(the pen's "
        r"point gets no closer than \d\.\d\d mm\), on the way from point 4",
        str(err.value),
    )
    assert isinstance(err.value, PlacementError)


def test_a_joint_limit_is_refused(arm: SerialArm) -> None:
    # behind the base at the table's height the elbow (joint3) would have to bend past 1.4 rad
    with pytest.raises(
        ReachError,
        match=r"^point 0: .* needs joint3 = 1\.\d+ rad, outside its range -1\.500…1\.400$",
    ) as err:
        arm.solve_path([[-0.15, 0.0, 0.0]], UP, math.radians(89), np.zeros(4))
    assert (err.value.index, err.value.reason) == (0, "joint limit")


def test_the_tilt_is_refused_and_held(arm: SerialArm) -> None:
    # high and far, the pen cannot point down: 30° refused, 89° accepted (nearly horizontal)
    with pytest.raises(ReachError, match=r"from the paper's normal \(max 30\.0°\)") as err:
        arm.solve_path([[0.1, 0.0, 0.3]], UP, TILT, np.zeros(4))
    assert err.value.reason == "tilt"
    q = arm.solve_path([[0.1, 0.0, 0.3]], UP, math.radians(89), np.zeros(4))
    assert math.degrees(tilts(arm.fk(q)[1], UP)[0]) > 80


def test_self_collision_is_refused(arm: SerialArm) -> None:
    folded = np.array([0.0, 0.0, 1.4, 1.97])
    point, axis = arm.fk(folded)
    with pytest.raises(ReachError, match=r"the arm would touch itself \(.* against .*\)") as err:
        arm.solve_path(point[None], -axis, TILT, folded)
    assert (err.value.index, err.value.reason) == (0, "self-collision")


def test_a_jump_between_points_is_refused(arm: SerialArm) -> None:
    # 1 cm across at 17 cm from the base, followed 2 mm at a time: joint1 turns ~12 mrad a step
    line = np.array([[0.17, 0.0, 0.0], [0.17, 0.01, 0.0]])
    arm.solve_path(line, UP, TILT, np.zeros(4), max_step=0.02)
    with pytest.raises(ReachError) as err:
        arm.solve_path(line, UP, TILT, np.zeros(4), max_step=0.005)
    assert re.fullmatch(
        r"point 1: joint1 would jump by 0\.01\d rad in 2\.00 mm \(max 0\.005 rad per 2 mm\): "
        r"a branch flip or a singularity, on the way from point 0",
        str(err.value),
    )
    assert (err.value.index, err.value.reason) == (1, "jump")
    # the bound is the largest joint step itself: 1 % under it refused, 1 % over it passes
    short = line[:1] + [[0.0, 0.002, 0.0]] * np.arange(2)[:, None]
    step = np.abs(np.diff(arm.solve_path(short, UP, TILT, np.zeros(4)), axis=0)).max()
    arm.solve_path(short, UP, TILT, np.zeros(4), max_step=1.01 * step)
    with pytest.raises(ReachError, match="would jump"):
        arm.solve_path(short, UP, TILT, np.zeros(4), max_step=0.99 * step)


def test_the_first_point_is_held_to_the_tilt(arm: SerialArm) -> None:
    # the first point comes from anywhere and its tilt is checked after: 27.6 cm out on the
    # table the pen leans 10.3°
    with pytest.raises(
        ReachError, match=r"^point 0: the pen axis would be 10\.3° .*\(max 10\.0°\)"
    ):
        arm.solve_path([[0.276, 0.0, 0.0]], UP, math.radians(10), np.zeros(4))
    arm.solve_path([[0.276, 0.0, 0.0]], UP, math.radians(10.5), np.zeros(4))


def test_a_point_the_cone_blocks_is_taken_by_the_position_alone(arm: SerialArm) -> None:
    """The fall-back keeps a pose found without the cone when it is within the tilt."""
    solver = _PathSolver(arm, UP, TILT, 1e-6, 200)
    target = np.array([0.17, 0.0, 0.0])
    solver.fall_back(0, target, np.zeros(4))
    assert np.linalg.norm(solver.tip() - target) < 1e-6
    assert tilts(arm.fk(solver.cfg.q)[1][None], UP)[0] <= TILT


@pytest.mark.parametrize(
    ("kwargs", "problem"),
    [
        ({"points": [[0, 0]]}, r"points: need finite \(N, 3\)"),
        ({"normal": (0, 0, 0)}, "normal: need a non-zero 3-vector"),
        ({"max_tilt": math.pi / 2}, r"max_tilt: must be in \[0, π/2\)"),
        ({"q0": [0, 0, 0]}, "q0: need 4 joint angles"),
        ({"q0": [0, 1.6, 0, 0]}, r"q0: joint2 = 1\.6000 rad is outside its range -1\.5000…1\.5000"),
    ],
)
def test_bad_arguments_are_named(arm: SerialArm, kwargs: dict, problem: str) -> None:
    args = {"points": [[0.15, 0, 0]], "normal": UP, "max_tilt": TILT, "q0": np.zeros(4)}
    with pytest.raises(PlacementError, match=problem):
        arm.solve_path(**(args | kwargs))


def test_the_tilt_row_is_the_cosines_derivative(arm: SerialArm) -> None:
    """``G Δq`` is minus the first-order change of ``−a·n`` (finite differences)."""
    normal = np.array([0.3, -0.2, 0.9])
    normal /= np.linalg.norm(normal)
    site = arm.model.site(PEN_SITE).id
    limit = TiltLimit(arm.model, site, normal, math.radians(60))
    cfg = mink.Configuration(arm.model)
    q = np.array([0.4, 0.3, 0.2, 1.0])
    cfg.update(q)
    row = limit.compute_qp_inequalities(cfg, 0.01)

    def cosine(qq: np.ndarray) -> float:
        return -float(arm.fk(qq)[1] @ normal)

    rng = np.random.default_rng(3)
    for _ in range(3):
        dq = rng.normal(size=4) * 1e-6
        change = cosine(q + dq) - cosine(q)
        assert row.G[0] @ dq == pytest.approx(-change, rel=1e-4, abs=1e-13)
    assert row.h[0] == pytest.approx(0.95 * (cosine(q) - math.cos(math.radians(60))))


def test_outside_the_cone_the_tilt_row_only_forbids_tilting_further(arm: SerialArm) -> None:
    site = arm.model.site(PEN_SITE).id
    limit = TiltLimit(arm.model, site, UP, math.radians(10))
    cfg = mink.Configuration(arm.model)
    cfg.update(np.zeros(4))  # the pen horizontal: 90° from the normal
    row = limit.compute_qp_inequalities(cfg, 0.01)
    assert row.h[0] == 0.0 and np.abs(row.G).max() > 0.1
