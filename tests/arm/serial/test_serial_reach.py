"""The paper's plane in the arm's frame and a whole job's reach, checked before anything moves."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tagbot.arm.serial.kinematics import SerialArm
from tagbot.arm.serial.reach import Paper, check_job
from tagbot.errors import PlacementError, ReachError

TILT = math.radians(30)


@pytest.fixture(scope="module")
def arm() -> SerialArm:
    return SerialArm.load()


def test_a_paper_pose_places_its_points() -> None:
    table = Paper.from_pose((0.15, -0.05, 0.0))
    np.testing.assert_allclose(table.normal, (0, 0, 1))
    np.testing.assert_allclose(table.to_arm([[0.01, 0.02]], height=0.005), [[0.16, -0.03, 0.005]])
    turned = Paper.from_pose((0.15, 0.0, 0.0), (0.0, 0.0, math.pi / 2))  # x along the arm's y
    np.testing.assert_allclose(turned.to_arm([[0.01, 0.02]]), [[0.13, 0.01, 0.0]], atol=1e-15)
    board = Paper.from_pose((0.2, 0.0, 0.05), (0.0, -math.radians(60), 0.0))
    np.testing.assert_allclose(board.normal, (-math.sin(math.radians(60)), 0, 0.5), atol=1e-15)
    np.testing.assert_allclose(
        board.to_arm([[0.02, 0.0]]), [[0.21, 0.0, 0.05 + 0.02 * 0.866025403784]]
    )


def test_paper_axes_must_be_orthonormal() -> None:
    with pytest.raises(PlacementError, match="paper: axes must be orthonormal"):
        Paper((0, 0, 0), (1, 0, 0), (1, 0, 0))


def test_a_job_is_solved_with_its_approach_retreat_and_travel(arm: SerialArm) -> None:
    paper = Paper.from_pose((0.13, -0.04, 0.0))
    t = np.linspace(0, 2 * math.pi, 120)
    runs = [
        np.stack([0.04 + 0.02 * np.cos(t), 0.04 + 0.02 * np.sin(t)], 1),
        np.stack([np.linspace(0.0, 0.08, 80), np.full(80, 0.01)], 1),
    ]
    job = check_job(arm, paper, runs, pen_up=0.01, max_tilt=TILT, q0=np.zeros(4))
    tip, axis = arm.fk(job.q)
    assert np.linalg.norm(tip - job.points, axis=1).max() < 1e-5
    np.testing.assert_allclose(job.points[job.ink], paper.to_arm(np.concatenate(runs)))
    kinds = [str(k) for k in job.kind]
    # each run: down 10 mm in 2 mm steps (5 points above the paper), the ink, up 10 mm
    assert kinds[:5] == ["approach"] * 5 and kinds[5] == "ink"
    np.testing.assert_allclose(job.points[:5, 2], [0.01, 0.008, 0.006, 0.004, 0.002])
    first_retreat = kinds.index("retreat")
    assert kinds[first_retreat : first_retreat + 5] == ["retreat"] * 5
    travel = job.kind == "travel"
    np.testing.assert_allclose(job.points[travel, 2], 0.01)  # travel at the pen-up height
    assert set(job.run[travel]) == {1}
    assert np.degrees(np.arccos(np.clip(-axis[:, 2], -1, 1))).max() <= 30 + 1e-9
    assert np.abs(np.diff(job.q, axis=0)).max() < 0.05
    assert np.linalg.norm(np.diff(job.points, axis=0), axis=1).min() > 0  # no point twice


def test_a_job_out_of_reach_names_the_run_and_the_move(arm: SerialArm) -> None:
    paper = Paper.from_pose((0.13, -0.04, 0.0))
    near = np.stack([np.linspace(0.0, 0.02, 10), np.zeros(10)], 1)
    far = near + np.array([0.40, 0.0])  # 53 cm from the base, beyond the arm and pen (41 cm)
    with pytest.raises(ReachError) as err:
        check_job(arm, paper, [near, far], 0.01, math.radians(89), np.zeros(4))
    message = str(err.value)
    assert message.startswith("run 1 travel point ") and "out of the arm's reach" in message
    assert err.value.reason == "reach"
    # along the table away from the base the pen leans out: 10° is passed 27.6 cm out
    run = np.stack([np.linspace(0.0, 0.2, 101), np.full(101, 0.04)], 1)  # 2 mm apart
    with pytest.raises(
        ReachError,
        match=r"^run 0 ink point 73: .* \(0\.2760, 0\.0000, 0\.0000\) m would tilt 10\.\d° "
        r".*\(max 10\.0°\)$",
    ):
        check_job(arm, paper, [run], 0.005, math.radians(10), np.zeros(4))


def test_bad_jobs_are_named(arm: SerialArm) -> None:
    paper = Paper.from_pose((0.13, 0.0, 0.0))
    with pytest.raises(PlacementError, match="runs: the job has no run"):
        check_job(arm, paper, [], 0.01, TILT, np.zeros(4))
    with pytest.raises(PlacementError, match=r"runs\[1\]: need finite \(N, 2\)"):
        check_job(arm, paper, [np.zeros((2, 2)), np.zeros((2, 3))], 0.01, TILT, np.zeros(4))
    with pytest.raises(PlacementError, match="pen_up, spacing: must be > 0"):
        check_job(arm, paper, [np.zeros((2, 2))], 0.0, TILT, np.zeros(4))
