"""A serial arm stopped before its stream sends anything (connecting, the approach, a resume's
touch-down): the report says whether the pen is off the paper as the physics has it.

Ctrl-C is simulated as a KeyboardInterrupt raised while the driver waits on the simulated
chain's clock, at a simulated instant (no wall clock)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

import tagbot
from tagbot.arm.kinematics import angles_to_ticks
from tagbot.arm.serial.machine import prepare
from tagbot.draw import draw
from tagbot.errors import Interrupted

EXAMPLES = Path(tagbot.__file__).parent / "examples"
RESUME = 160
"""A tick of letter-b's run (pen down)."""


@pytest.fixture(scope="module")
def letter_b() -> tagbot.Tag:
    return tagbot.load_plan(EXAMPLES / "letter-b.json")


def _ctrl_c_when(chain, due: Callable[[], bool], after: float) -> None:
    """Raise KeyboardInterrupt in the driver's wait ``after`` s (simulated) past the first
    instant ``due()`` holds, as Ctrl-C during a sleep does."""
    advance = chain.advance_to
    seen: list[float] = []

    def advance_to(t: float) -> None:
        if not seen and due():
            seen.append(chain.now())
        if seen and seen[0] >= 0 and t >= seen[0] + after:
            advance(seen[0] + after)
            seen[0] = -1.0  # once
            raise KeyboardInterrupt
        advance(t)

    chain.advance_to = advance_to


def _stopped(letter_b, tmp_path, *, pen_on_paper: bool, due, after: float):
    """Resume letter-b at :data:`RESUME` (the arm found where that tick puts it, by hand, when
    ``pen_on_paper``, else at park) with Ctrl-C as :func:`_ctrl_c_when` says; the error, the
    report, the physics and the job."""
    job = prepare(letter_b, profile="openmanipulator-x", resume_from=RESUME)
    held = {}

    def fault(chain) -> None:
        held["chain"] = chain
        if pen_on_paper:
            q = job.program.angles[RESUME - 1]
            for joint, angle in zip(job.profile.joints, q, strict=True):
                chain.set_position(joint.id, float(angles_to_ticks(angle, joint)))
        _ctrl_c_when(chain, lambda: due(chain, job.profile), after)

    job.fault = fault
    with pytest.raises(Interrupted) as caught:
        draw(letter_b, tmp_path / "run", prepared=job, pictures=False)
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    return caught.value, report, held["chain"].plant, job


def _height(physics, profile) -> float:
    """The pen's point above the paper in the physics, m."""
    tip = physics.data.site_xpos[physics._tip]
    return float((tip - np.asarray(profile.paper.origin)) @ profile.paper.normal)


def _moving(chain, profile) -> bool:
    """A goal sent that a servo is not at: the approach's move under way."""
    return any(
        abs(chain.servo(id).get("goal_position") - chain.servo(id).get("present_position")) > 20
        for id in profile.bus_ids
    )


def _torque(chain, profile) -> bool:
    return all(chain.servo(id).torque for id in profile.bus_ids)


def test_ctrl_c_in_the_approach_with_the_pen_on_the_paper_lifts_it_and_says_so(
    letter_b, tmp_path
) -> None:
    # the arm found with its pen on the paper (a stop that could not lift it), Ctrl-C 50 ms
    # into the move to above the resumed tick: the report said 'lifted' with no goal of the
    # lift sent and the nib still on the paper
    error, report, physics, job = _stopped(
        letter_b, tmp_path, pen_on_paper=True, due=_moving, after=0.05
    )
    assert str(error).startswith("approach: ") and "pen lifted by the arm" in str(error)
    assert report["details"]["lifted_by_arm_at_stop"] is True
    assert report["warnings"] == []
    trace = physics.pen_trace()
    assert trace[1, 3] == 1.0  # it did start on the paper (the first record: before by hand)
    assert _height(physics, job.profile) == pytest.approx(
        job.profile["robot.pen_up"] / 1000.0, abs=0.002
    )
    assert trace[-50:, 3].max() == 0.0
    # lifted from where it stood, at once: off the paper 0.1 s (simulated) after the Ctrl-C
    # (a lift planned with the IK's own wrist for that point jumped and was slowed to 5 s)
    assert trace[np.flatnonzero(trace[:, 3])[-1], 0] < 0.25


def test_ctrl_c_while_connecting_with_the_pen_on_the_paper_says_it_was_not_lifted(
    letter_b, tmp_path
) -> None:
    # nothing powered yet: the stop does not switch the arm on, and says the pen is down
    error, report, physics, job = _stopped(
        letter_b, tmp_path, pen_on_paper=True, due=lambda chain, profile: True, after=0.001
    )
    assert report["details"]["lifted_by_arm_at_stop"] is False
    assert "the pen was not lifted by the arm (stopped before the arm was under torque" in str(
        error
    )
    assert any("not lifted" in w for w in report["warnings"])
    assert not _torque(physics.chain, job.profile)
    assert physics.pen_trace()[-1, 3] == 1.0


def test_ctrl_c_while_connecting_with_the_pen_up_says_it_is_up(letter_b, tmp_path) -> None:
    error, report, physics, job = _stopped(
        letter_b, tmp_path, pen_on_paper=False, due=lambda chain, profile: True, after=0.001
    )
    assert report["details"]["lifted_by_arm_at_stop"] is True
    assert "pen lifted by the arm" in str(error) and report["warnings"] == []
    assert not _torque(physics.chain, job.profile)
    assert physics.pen_trace()[:, 3].max() == 0.0


def test_ctrl_c_in_the_approach_from_park_holds_the_arm_where_it_is(letter_b, tmp_path) -> None:
    # the move from park to above the resumed tick is cut where the arm is: it does not go on
    # to that goal, the pen stays up
    _, report, physics, job = _stopped(
        letter_b, tmp_path, pen_on_paper=False, due=_moving, after=0.1
    )
    assert report["details"]["lifted_by_arm_at_stop"] is True
    ids = job.profile.bus_ids
    before = np.array([physics.joint_trace(id)[-1, 1] for id in ids])
    physics.chain.advance_to(physics.chain.now() + 1.0)
    after = np.array([physics.joint_trace(id)[-1, 1] for id in ids])
    assert np.abs(after - before).max() <= 20  # within 1.8° of where it stopped, 1 s later
    goal = job.program.goals[RESUME - 2]
    assert np.abs(after - goal).max() > 200  # far from the approach's goal
    assert physics.pen_trace()[:, 3].max() == 0.0


def test_a_resumed_job_found_on_the_paper_lifts_off_it_before_moving_across_it(
    letter_b, tmp_path
) -> None:
    # the arm found with its pen on the paper at tick RESUME's pose, the job resumed 80 mm
    # away: the move to above the resumed tick, in joint space, dragged the nib 10 mm across
    # the paper; now the arm lifts it there first (what is left is the arm's fall onto the
    # paper while connecting, its torque off: 1.8 mm)
    job = prepare(letter_b, profile="openmanipulator-x", resume_from=420)
    held = {}

    def fault(chain) -> None:
        held["chain"] = chain
        q = job.program.angles[RESUME - 1]
        for joint, angle in zip(job.profile.joints, q, strict=True):
            chain.set_position(joint.id, float(angles_to_ticks(angle, joint)))

    job.fault = fault
    report = draw(letter_b, tmp_path / "run", prepared=job, pictures=False).report
    assert report["completed"]
    trace = held["chain"].plant.pen_trace()
    on = trace[:, 3] > 0.5
    assert on[1]
    first = trace[1 : int(np.argmax(~on[1:])) + 1]  # the contact it was found in
    assert np.hypot(*(first[:, 1:3] - first[0, 1:3]).T).max() < 2.5


def test_an_arm_whose_port_does_not_open_is_said_not_lifted_for_want_of_a_connection(
    letter_b, tmp_path
) -> None:
    """The port refuses to open (nothing listens there): the run stops before any servo was
    reached, and the report says the pen was not lifted by the arm, having no connection."""
    job = prepare(letter_b, profile="openmanipulator-x", port="socket://127.0.0.1:9")
    with pytest.raises(Exception) as caught:
        draw(letter_b, tmp_path / "run", prepared=job, pictures=False)
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report["details"]["lifted_by_arm_at_stop"] is False and report["executed"] == 0
    expected = (
        "the arm stopped, but the pen was not lifted by the arm (no connection to the arm): it"
        " may still be on the paper"
    )
    assert expected in report["warnings"]
    assert "socket://127.0.0.1:9" in str(caught.value)
