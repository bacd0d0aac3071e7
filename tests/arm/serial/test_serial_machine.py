"""The OpenManipulator-X as a machine (issue 32): its profile, its program (IK, touch-down and
lift-off by the arm, retiming), refusals before anything moves, the physics simulator's drawing
and a fault mid-run lifting the pen by the arm."""

from __future__ import annotations

import json
import locale
import logging
import math
import re
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest

import tagbot
from tagbot.arm.driver import ArmDriver
from tagbot.arm.kinematics import angles_to_ticks
from tagbot.arm.serial.machine import (
    FORCE_RANGE,
    ArmLift,
    SerialBudget,
    _approach_time,
    bridge_hops,
    contact_figures,
    executed_from_reads,
    move_bounds,
    prepare,
    simulated_arm,
    time_bound,
)
from tagbot.arm.serial.profile import is_serial_profile, load_serial_profile
from tagbot.arm.serial.program import build_serial_program, check_serial_program
from tagbot.control import RunControl
from tagbot.draw import draw
from tagbot.errors import (
    ConnectionLost,
    DeviceError,
    InputError,
    Interrupted,
    PlacementError,
    ProfileError,
    ReachError,
)

from ..conftest import small_tag

EXAMPLES = Path(tagbot.__file__).parent / "examples"


@pytest.fixture
def letter_b() -> tagbot.Tag:
    return tagbot.load_plan(EXAMPLES / "letter-b.json")


@pytest.fixture
def profile():
    return load_serial_profile("openmanipulator-x")


@pytest.fixture
def program(letter_b, profile):
    return build_serial_program(letter_b, profile)


@pytest.fixture
def drawn(letter_b, tmp_path):
    folder = tmp_path / "b"
    result = draw(letter_b, folder, device="dynamixel", profile="openmanipulator-x", pictures=False)
    return folder, result.report


# -- profile ---------------------------------------------------------------------------------


def test_the_profile_names_the_servos_joints_and_paper(profile) -> None:
    assert profile.bus_ids == [11, 12, 13, 14]
    assert [j.name for j in profile.joints] == ["joint1", "joint2", "joint3", "joint4"]
    np.testing.assert_allclose(profile.paper.normal, (0, 0, 1), atol=1e-12)
    assert profile.paper.origin == pytest.approx((0.1, -0.105, 0.0))
    assert profile.pen_servo is None
    # a P gain of 1600 on an XM430-W350: 4.1/885 N·m a PWM unit, 1600/128 per tick
    assert profile.stiffness == pytest.approx(4.1 / 885 * 1600 / 128 * 4096 / (2 * math.pi))
    assert is_serial_profile("openmanipulator-x") and not is_serial_profile("default")


def test_a_bad_profile_value_is_one_line_naming_the_source_and_field() -> None:
    with pytest.raises(ProfileError, match=r"^--set: joint2\.park_deg: 100° is outside"):
        load_serial_profile("openmanipulator-x", ["joint2.park_deg=100"])
    with pytest.raises(ProfileError, match=r"^--set: joint4\.id: IDs must differ$"):
        load_serial_profile("openmanipulator-x", ["joint3.id=11"])
    with pytest.raises(ProfileError, match=r"^--set: robot\.description: .*no-such-arm\.xml"):
        load_serial_profile("openmanipulator-x", ["robot.description=no-such-arm.xml"])
    with pytest.raises(
        ProfileError,
        match=r"^--set: robot\.max_tilt_deg: must be < 90 \(the pen must point into the paper\)$",
    ):
        load_serial_profile("openmanipulator-x", ["robot.max_tilt_deg=90"])
    # The feedforward needs a position P gain: 0 is refused with it, 1 is enough, and without
    # the feedforward 0 is taken.
    with pytest.raises(
        ProfileError,
        match=r"^--set: servo\.position_p_gain: the feedforward needs a position P gain > 0$",
    ):
        load_serial_profile("openmanipulator-x", ["servo.position_p_gain=0"])
    assert load_serial_profile("openmanipulator-x", ["servo.position_p_gain=1"]).gains[0] == 1
    off = ["servo.position_p_gain=0", "servo.feedforward=false"]
    assert load_serial_profile("openmanipulator-x", off).gains[0] == 0


# -- program ---------------------------------------------------------------------------------


def test_ik_puts_the_pen_on_every_planned_point_within_0_01_mm(program, profile) -> None:
    sp = program.setpoints
    tip, axis = profile.arm.fk(program.angles[sp.pen])
    aim = profile.paper.to_arm(sp.xy[sp.pen] / 1000.0, -profile["robot.press"] / 1000.0)
    assert np.linalg.norm(tip - aim, axis=1).max() <= 1e-5
    tilt = np.degrees(np.arccos(np.clip(-axis @ profile.paper.normal, -1, 1)))
    assert tilt.max() <= profile["robot.max_tilt_deg"] + 1e-6


def _elbow_side(profile, q: np.ndarray) -> np.ndarray:
    """Per pose: the elbow (joint3's axis) above (+) or below (−) the line from the shoulder
    (joint2's) to the wrist (joint4's), in the arm's vertical plane: the IK's branch."""
    model = profile.arm.model
    data = mujoco.MjData(model)
    side = np.empty(len(q))
    for i, qi in enumerate(q):
        data.qpos[:] = qi
        mujoco.mj_kinematics(model, data)
        shoulder, elbow, wrist = (data.xpos[model.body(b).id] for b in ("link3", "link4", "link5"))
        axis = data.xmat[model.body("link3").id].reshape(3, 3)[:, 1]  # joint2's axis (y)
        side[i] = np.cross(wrist - shoulder, elbow - shoulder) @ axis
    return side


def test_no_branch_flip_and_every_joint_within_its_limits(program, profile) -> None:
    q, T = program.angles, profile.period
    side = _elbow_side(profile, q)
    assert np.all(np.sign(side) == np.sign(side[0])) and np.abs(side).min() > 1e-4
    for i, joint in enumerate(profile.joints):
        assert np.abs(np.diff(q[:, i])).max() / T <= joint.max_speed * (1 + 1e-6)
        assert np.abs(np.diff(q[:, i], 2)).max() / T**2 <= joint.max_acceleration * (1 + 1e-6)
    # the retiming slowed the tag only as much as a joint needs: one limit is met (within 2 %)
    draw_rows = np.concatenate(
        [np.arange(a - 1, b + 1) for k, _, a, b in program.segments if k == "draw"]
    )
    worst = 0.0
    for i, joint in enumerate(profile.joints):
        a = q[draw_rows, i]
        worst = max(
            worst,
            np.abs(np.diff(a)).max() / T / joint.max_speed,
            math.sqrt(np.abs(np.diff(a, 2)).max() / T**2 / joint.max_acceleration),
        )
    assert program.setpoints.run_scales[0] > 1.0
    assert worst > 0.98


def test_the_pen_touches_down_and_lifts_off_along_the_paper_normal(program, profile) -> None:
    sp = program.setpoints
    down = np.flatnonzero(sp.pen)
    first, last = down[0], down[-1]
    tip, _ = profile.arm.fk(program.angles)
    height = (tip - np.asarray(profile.paper.origin)) @ profile.paper.normal
    # before the ink: straight down over its first point from the pen-up height
    approach = next(s for s in program.segments if s[0] == "pen")
    rows = np.arange(approach[2], approach[3])
    assert height[rows[0]] == pytest.approx(profile["robot.pen_up"] / 1000.0, abs=1e-6)
    sideways = np.linalg.norm(
        (tip[rows] - tip[first]) - np.outer(height[rows] - height[first], profile.paper.normal),
        axis=1,
    )
    assert sideways.max() < 1e-5
    assert np.all(np.diff(height[rows]) <= 1e-9)  # down all the way (resting at its ends)
    # the ink starts where the plan's does (its drawn window's first point)
    plan = program.setpoints.run_clocks[0]
    assert sp.t[first] > sp.t[approach[2]]
    assert height[first] == pytest.approx(-profile["robot.press"] / 1000.0, abs=1e-5)
    assert plan.on >= 0
    retreat = [s for s in program.segments if s[0] == "pen"][1]
    rows = np.arange(retreat[2], retreat[3])
    assert np.all(np.diff(height[rows]) >= -1e-9) and rows[0] == last + 1
    assert height[rows[-1]] == pytest.approx(profile["robot.pen_up"] / 1000.0, abs=1e-6)


def test_refusals_name_plan_stroke_and_time_before_anything_moves(letter_b, tmp_path) -> None:
    folder = tmp_path / "never"
    # the paper slid 30 cm away: out of reach from the first point on
    with pytest.raises(ReachError, match=r"plan 0, (stroke \d+, t = [\d.]+ s|approach before it)"):
        draw(
            letter_b,
            folder,
            device="dynamixel",
            profile="openmanipulator-x",
            overrides=("paper.x=300",),
            port="/dev/null-not-a-port",
        )
    assert not folder.exists()
    with pytest.raises(PlacementError, match=r"plan 0: must be slowed down [\d.]+ times"):
        prepare(letter_b, profile="openmanipulator-x", overrides=("motion.max_time_scale=1.5",))


# -- the physics simulator ------------------------------------------------------------------


def test_the_simulated_arm_draws_the_tag_within_its_budgets(drawn) -> None:
    folder, report = drawn
    assert report["completed"] and report["simulated"]
    assert report["warnings"] == []
    assert report["executed_source"].startswith("physics simulator")
    (run,) = report["runs"]
    assert run["path_deviation_max_mm"] <= 0.3
    assert run["speed_snr_db"] >= 25.0
    assert run["contact_kept_pct"] == 100.0
    assert FORCE_RANGE[0] < run["force_max_n"] <= FORCE_RANGE[1]
    header = (folder / "joints.csv").read_text().splitlines()[0]
    assert header == "t,joint1,joint2,joint3,joint4"
    assert json.loads((folder / "report.json").read_text())["device"] == "dynamixel"


def test_contact_lost_and_force_out_of_range_are_warnings() -> None:
    report = {"runs": [{"plan": 0, "path_deviation_max_mm": 0.1, "speed_snr_db": 30.0}] * 2}
    judge = SerialBudget(
        [
            {"contact_kept_pct": 91.5, "force_min_n": 0.0, "force_max_n": 0.5},
            {"contact_kept_pct": 100.0, "force_min_n": 0.3, "force_max_n": 2.4},
        ]
    )
    warnings = judge(json.loads(json.dumps(report)))
    assert warnings[0] == "run 1 (plan 0): contact lost: ink on 91.5 % of the planned ink length"
    assert warnings[1].startswith("run 2 (plan 0): the nib's force reached 2.40 N, above 1.1 N")
    slow = {"runs": [{"plan": 3, "path_deviation_max_mm": 0.1, "speed_snr_db": 12.0}] * 2}
    contacts = [{"contact_kept_pct": 100.0, "force_min_n": 0.3, "force_max_n": 0.5}] * 2
    warnings = SerialBudget(contacts, [1.4, 10.0])(json.loads(json.dumps(slow)))
    assert warnings == [
        "run 1 (plan 3): speed SNR 12.0 dB below 25 dB (a short run, 1.4 mm: the arm's speed"
        " error, set by the servos' whole ticks, is as large as its motion)",
        "run 2 (plan 3): speed SNR 12.0 dB below 25 dB",
    ]


def test_a_run_drawn_short_and_slow_is_warned_of_as_a_short_run_with_its_length(tmp_path) -> None:
    """The hook drawn 0.05 mm per tag unit (under 0.8 mm of ink): the simulated arm's run
    scores below the speed SNR budget, and the warning says it is a short run, naming its
    planned length."""
    report = draw(
        small_tag(),
        tmp_path / "tiny",
        device="dynamixel",
        profile="openmanipulator-x",
        overrides=("place.scale=0.05",),
        pictures=False,
    ).report
    assert report["completed"]
    (warning,) = report["warnings"]
    short = re.fullmatch(
        r"run 1 \(plan 0\): speed SNR [\d.]+ dB below 25 dB \(a short run, ([\d.]+) mm: the"
        r" arm's speed error, set by the servos' whole ticks, is as large as its motion\)",
        warning,
    )
    assert short is not None and 0.0 < float(short[1]) <= 0.8


def test_the_pen_pressed_too_deep_digs_in_and_aimed_at_the_surface_skips(letter_b, tmp_path):
    deep = draw(
        letter_b,
        tmp_path / "deep",
        device="dynamixel",
        profile="openmanipulator-x",
        overrides=("robot.press=5.5", "robot.pen_force=1.3"),
        pictures=False,
    ).report
    assert any("the pen digs in" in w for w in deep["warnings"])
    shallow = draw(
        letter_b,
        tmp_path / "shallow",
        device="dynamixel",
        profile="openmanipulator-x",
        overrides=("robot.press=0", "robot.pen_force=0"),
        pictures=False,
    ).report
    assert any("contact lost" in w for w in shallow["warnings"])


def test_a_hop_shorter_than_the_nib_is_no_gap_in_the_line() -> None:
    t = np.arange(8) * 0.001
    x = np.array([0, 0.3, 0.6, 0.9, 1.2, 5.0, 5.3, 5.6])
    pen = np.array([1, 1, 0, 1, 1, 0, 0, 1.0])
    out = bridge_hops(np.column_stack([t, x, np.zeros(8), pen]), nib=0.002)
    np.testing.assert_array_equal(out[:, 3], [1, 1, 1, 1, 1, 0, 0, 1])
    # a pen lift between two runs close together is no hop: it lasts longer
    slow = np.column_stack([t * 30, x, np.zeros(8), pen])
    np.testing.assert_array_equal(bridge_hops(slow, nib=0.002)[:, 3], pen)


# -- faults ---------------------------------------------------------------------------------


def _faulted(letter_b, tmp_path, fire, kind="draw"):
    """Draw letter-b on the simulated arm, calling ``fire(chain)`` once mid-run (the middle of
    the first segment of ``kind``: the pen-down run, or ``travel`` pen up); returns the error,
    the report and the physics."""
    job = prepare(letter_b, profile="openmanipulator-x")
    held = {}
    job.fault = lambda chain: held.setdefault("chain", chain)
    rows = next(s for s in job.program.segments if s[0] == kind)
    middle = (rows[2] + rows[3]) // 2

    def progress(done: int, total: int) -> None:
        if done >= middle and "fired" not in held:
            held["fired"] = done
            fire(held["chain"])

    with pytest.raises(BaseException) as caught:
        draw(letter_b, tmp_path / "run", prepared=job, progress=progress, pictures=False)
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    return caught.value, report, held["chain"].plant, job, held["fired"]


def test_a_fault_mid_run_lifts_the_pen_by_the_arm_and_stops_safely(letter_b, tmp_path) -> None:
    error, report, physics, job, fired = _faulted(
        letter_b, tmp_path, lambda chain: chain.set_hardware_error(13, 0x01)
    )
    assert isinstance(error, DeviceError) and "hardware error" in str(error)
    assert not report["completed"] and report["details"]["lifted_by_arm_at_stop"]
    assert fired <= report["executed"] < len(job.program)
    # the run the fault cut short is marked so, and not judged on its speed
    *whole, cut = report["runs"]
    assert cut["cut_short"] is True and not any(r["cut_short"] for r in whole)
    cut_run = f"run {len(report['runs'])} "
    assert not any(w.startswith(cut_run) and "speed SNR" in w for w in report["warnings"])
    trace = physics.pen_trace()
    profile = job.profile
    # inked up to the fault, then off the paper and up at the pen-up height, arm holding
    inked = np.flatnonzero(trace[:, 3])
    assert len(inked) and inked[-1] < len(trace) - 50  # off the paper well before the end
    tip = physics.data.site_xpos[physics._tip]
    height = float((tip - np.asarray(profile.paper.origin)) @ profile.paper.normal)
    assert height == pytest.approx(profile["robot.pen_up"] / 1000.0, abs=0.002)
    assert all(physics.chain.servo(id).torque for id in profile.bus_ids)


def _interrupt(chain) -> None:
    raise KeyboardInterrupt


def test_ctrl_c_mid_run_lifts_the_pen_by_the_arm(letter_b, tmp_path) -> None:
    error, report, physics, _job, _ = _faulted(letter_b, tmp_path, _interrupt)
    assert isinstance(error, Interrupted) and "pen lifted by the arm" in str(error)
    assert report["resume_from"] == report["executed"] + 1
    assert physics.pen_trace()[-50:, 4].max() == 0.0


def test_ctrl_c_mid_run_takes_the_nib_off_the_paper_within_0_2_s(letter_b, tmp_path) -> None:
    # the servos run servo.profile_ms (80 ms) behind the host: what was sent is drawn, then the
    # arm lifts along the normal; the nib leaves the paper 0.18 s (simulated) after the Ctrl-C
    fired = {}

    def interrupt(chain) -> None:
        fired["sample"] = len(chain.plant.pen_trace()) - 1
        raise KeyboardInterrupt

    _, _, physics, job, _ = _faulted(letter_b, tmp_path, interrupt)
    trace = physics.pen_trace()
    at = fired["sample"]
    assert trace[at, 3] == 1.0  # on the paper when stopped
    off = at + np.flatnonzero(trace[at:, 3] == 0.0)[0]
    assert job.profile.lead <= trace[off, 0] - trace[at, 0] <= 0.2


def _height(physics, profile) -> float:
    """The pen's point above the paper in the physics, m."""
    tip = physics.data.site_xpos[physics._tip]
    return float((tip - np.asarray(profile.paper.origin)) @ profile.paper.normal)


def test_ctrl_c_on_pen_up_travel_is_reported_as_lifted(letter_b, tmp_path) -> None:
    # the pen is up already: the stop holds it there, and the report says it is up (it said
    # False, the safe stop failing on the standing pose's feedforward, on 2 of 7 Ctrl-C)
    error, report, physics, job, fired = _faulted(letter_b, tmp_path, _interrupt, "travel")
    assert isinstance(error, Interrupted) and "pen lifted by the arm" in str(error)
    assert report["details"]["lifted_by_arm_at_stop"] is True
    assert fired <= report["executed"] < job.program.segments[0][3]
    assert _height(physics, job.profile) > job.profile["robot.pen_up"] / 2000.0
    assert physics.pen_trace()[:, 3].max() == 0.0  # no ink: it never went down


def test_a_job_resumed_on_pen_up_travel_goes_on_from_there(letter_b, tmp_path) -> None:
    travel = 40  # a tick of the travel to the first run, the pen up
    job = prepare(letter_b, profile="openmanipulator-x", resume_from=travel)
    report = draw(letter_b, tmp_path / "rest", prepared=job, pictures=False).report
    assert report["completed"] and report["executed"] == len(job.program)
    (run,) = report["runs"]
    assert run["contact_kept_pct"] == 100.0


def test_a_lift_that_fails_is_said_so_in_the_message_and_the_report(
    letter_b, tmp_path, monkeypatch
) -> None:
    def broken(self, row):
        raise ConnectionLost("the adapter went away", "stop")

    monkeypatch.setattr(ArmLift, "up", broken)
    error, report, _, _, _ = _faulted(letter_b, tmp_path, _interrupt)
    assert report["details"]["lifted_by_arm_at_stop"] is False
    assert isinstance(error, Interrupted) and "pen lifted by the arm" not in str(error)
    assert "the pen was not lifted by the arm (stop: the adapter went away)" in str(error)
    assert any("not lifted" in w for w in report["warnings"])


def test_a_second_ctrl_c_during_the_lift_is_still_an_interrupted_job(
    letter_b, tmp_path, monkeypatch
) -> None:
    """A Ctrl-C as the approach ends, then another cutting the stop's lift short: the job ends
    as interrupted, the pen said not to be lifted by the arm because the lift was interrupted
    (the arm was connected: not "no connection to the arm")."""
    approach = ArmDriver.move_to

    def move_to(self, *args, **kwargs):
        approach(self, *args, **kwargs)
        raise KeyboardInterrupt

    def lift_from(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(ArmDriver, "move_to", move_to)
    monkeypatch.setattr(ArmDriver, "lift_from", lift_from)
    job = prepare(letter_b, profile="openmanipulator-x")
    with pytest.raises(Interrupted) as caught:
        draw(letter_b, tmp_path / "run", prepared=job, pictures=False)
    not_lifted = (
        "the arm stopped, but the pen was not lifted by the arm (interrupted before the pen was up)"
    )
    assert f"interrupted (Ctrl-C): {not_lifted}" in str(caught.value)
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert not report["completed"] and report["details"]["lifted_by_arm_at_stop"] is False
    assert report["warnings"] == [f"{not_lifted}: it may still be on the paper"]


def test_a_resumed_job_lowers_the_pen_where_it_stopped_and_draws_the_rest(
    letter_b, tmp_path
) -> None:
    _, stopped, _, _, _ = _faulted(letter_b, tmp_path, _interrupt)
    tick = stopped["resume_from"]
    job = prepare(letter_b, profile="openmanipulator-x", resume_from=tick)
    report = draw(letter_b, tmp_path / "rest", prepared=job, pictures=False).report
    assert report["completed"] and report["executed"] == len(job.program)
    executed = np.loadtxt(tmp_path / "rest" / "executed.csv", delimiter=",", skiprows=1)
    inked = executed[executed[:, 3] > 0.5]
    # the arm stands where the last tick executed left it (row tick - 2), the pen lowered there
    stood = job.program.joints[tick - 2, 0]
    assert inked[0, 0] >= stood - 1e-6  # nothing drawn twice
    planned = job.program.setpoints.xy[tick - 2]
    assert np.hypot(*(inked[0, 1:3] - planned)) < 0.3  # the ink goes on where it stopped
    (run,) = report["runs"]
    assert run["contact_kept_pct"] == 100.0


class _PauseMidRun(RunControl):
    """Paused for ``checks`` of the loop's questions once ``armed`` (a count, not a clock)."""

    def __init__(self, checks: int) -> None:
        super().__init__()
        self.left = checks
        self.armed = False

    @property
    def paused(self) -> bool:
        if not self.armed:
            return False
        self.left -= 1
        return self.left >= 0


def test_a_pause_lifts_the_pen_by_the_arm_and_puts_it_back(letter_b, tmp_path) -> None:
    job = prepare(letter_b, profile="openmanipulator-x")
    held = {}
    job.fault = lambda chain: held.setdefault("chain", chain)
    control = _PauseMidRun(300)
    first, stop = next(s for s in job.program.segments if s[0] == "draw")[2:]

    def progress(done: int, total: int) -> None:
        control.armed = control.armed or done >= (first + stop) // 2

    report = draw(
        letter_b, tmp_path / "p", prepared=job, progress=progress, control=control, pictures=False
    ).report
    assert report["completed"] and report["pauses"] == 1 and report["paused_s"] > 0.5
    (run,) = report["runs"]
    # the pen back on the paper where it lifted (the planned stretch at the pause's edge, one
    # tick of it, falls inside the lift)
    assert run["contact_kept_pct"] >= 99.5 and run["speed_snr_db"] >= 25.0
    trace = held["chain"].plant.pen_trace()
    # the nib left the paper once in the middle of the run (the pause) and came back
    inked = trace[:, 3] > 0.5
    lifts = np.flatnonzero(inked[:-1] & ~inked[1:])
    long_lifts = [i for i in lifts if not inked[i + 1 : i + 200].any()]
    assert len(long_lifts) == 2  # the pause, and the run's end


def test_the_check_names_the_tick_of_a_joint_beyond_its_speed_or_the_servo_range(
    program, profile
) -> None:
    k = next(s for s in program.segments if s[0] == "draw")[2] + 10
    jumped = program.angles.copy()
    jumped[k:, 1] += 0.05  # 0.05 rad in one tick: 5 rad/s
    with pytest.raises(
        PlacementError, match=rf"^tick {k} \(t = {k / 100:.3f} s, plan 0\): joint2 speed"
    ):
        check_serial_program(replace(program, angles=jumped), profile)
    ramp = program.angles.copy()
    ramp[k, 3] += 0.005  # a 0.29° spike: 0.5 rad/s, 50 rad/s² at the tick
    with pytest.raises(PlacementError, match=r"joint4 acceleration \d+°/s² above joint4\.max_"):
        check_serial_program(replace(program, angles=ramp), profile)
    goals = program.joints.copy()
    goals[5, 2] = 4200
    with pytest.raises(PlacementError, match=r"^tick 5 .*joint2 goal 4200 ticks is outside"):
        check_serial_program(replace(program, joints=goals), profile)
    # the servo's range ends, 0 and 4095 ticks, are goals; a tick beyond either is not
    for end, beyond in ((0, -1), (4095, 4096)):
        goals = program.joints.copy()
        goals[5, 2] = end
        check_serial_program(replace(program, joints=goals), profile)
        goals[5, 2] = beyond
        with pytest.raises(
            PlacementError,
            match=rf"^tick 5 \(t = 0\.050 s, travel at plan 0\): joint2 goal {beyond} ticks"
            r" is outside 0\.\.4095$",
        ):
            check_serial_program(replace(program, joints=goals), profile)


def test_a_scale_too_large_and_a_park_pose_near_the_paper_are_refused(letter_b) -> None:
    with pytest.raises(PlacementError, match=r"place\.scale: 10 mm per unit does not fit .* 3\.0"):
        prepare(letter_b, profile="openmanipulator-x", overrides=("place.scale=10",))
    low = ("joint2.park_deg=40", "joint3.park_deg=0", "joint4.park_deg=80")  # the pen under it
    with pytest.raises(PlacementError, match=r"\(travel before plan 0\): the pen's point would"):
        prepare(letter_b, profile="openmanipulator-x", overrides=low)


def test_a_move_of_one_tick_after_a_run_is_bounded_by_its_step(profile) -> None:
    """The move to park one tick long, its shoulder stepping 0.01 rad from the run's last
    pose: its bound is that step at the joint's speed or acceleration limit, whichever binds
    (the arm standing before and after), not nothing."""
    from types import SimpleNamespace

    q = np.zeros((4, len(profile.joints)))
    q[3, 0] = 0.01
    job = SimpleNamespace(
        angles=q,
        segments=(("draw", 0, 0, 3), ("park", 0, 3, 4)),
        setpoints=SimpleNamespace(run_scales=(1.0,)),
    )
    joint = profile.joints[0]
    step = max(0.01 / joint.max_speed, math.sqrt(0.01 / joint.max_acceleration))
    assert move_bounds(job, profile)[1] == pytest.approx(step, rel=1e-12)


def test_the_job_time_bound_is_each_move_at_the_joints_limits(program, profile) -> None:
    bound = time_bound(program, profile)
    # letter-b: one run slowed 3.4 times by its joints (its own bound), pen-up moves near theirs
    assert program.setpoints.duration / 1.1 < bound < program.setpoints.duration
    fast = load_serial_profile(
        "openmanipulator-x",
        [f"joint{i}.max_speed=300" for i in range(1, 5)]
        + [f"joint{i}.max_acceleration=3000" for i in range(1, 5)],
    )
    assert time_bound(program, fast) < 0.75 * bound  # the same moves, faster joints


def test_a_run_is_slowed_by_the_joints_acceleration_where_that_binds(letter_b, program) -> None:
    gentle = load_serial_profile(
        "openmanipulator-x", [f"joint{i}.max_acceleration=200" for i in range(1, 5)]
    )
    slow = build_serial_program(letter_b, gentle)
    assert slow.setpoints.run_scales[0] > 1.2 * program.setpoints.run_scales[0]
    q, T = slow.angles, gentle.period
    first, stop = next(s for s in slow.segments if s[0] == "draw")[2:]
    run = q[first - 1 : stop + 1]
    speed = max(
        np.abs(np.diff(run[:, i])).max() / T / j.max_speed for i, j in enumerate(gentle.joints)
    )
    acc = max(
        np.abs(np.diff(run[:, i], 2)).max() / T**2 / j.max_acceleration
        for i, j in enumerate(gentle.joints)
    )
    assert speed < 0.9 and 0.95 < acc <= 1.0 + 1e-6  # the acceleration, not the speed, binds


# -- the pen's height from the servos' positions, the contact figures, the options -------------


def _park_row(profile) -> np.ndarray:
    """The goal ticks of the profile's rest pose, and the pen's height there, mm."""
    pairs = zip(profile.park, profile.joints, strict=True)
    row = np.array([int(angles_to_ticks(a, j)) for a, j in pairs])
    lift = ArmLift(profile)
    return row, 1000.0 * lift.height(lift.angles(row))


@pytest.mark.parametrize(("factor", "down"), [(1 - 1e-6, False), (1.0, True), (1 + 1e-6, True)])
def test_read_back_pen_is_down_within_half_the_press_of_the_paper(factor, down) -> None:
    row, height = _park_row(load_serial_profile("openmanipulator-x"))
    press = 2.0 * height * factor  # the pen counts as down at up to robot.press / 2 above
    profile = load_serial_profile("openmanipulator-x", [f"robot.press={press!r}"])
    (sample,) = executed_from_reads(np.array([[0.5, *row]]), profile)
    assert sample[0] == 0.5 and sample[3] == float(down)


@pytest.mark.parametrize(("factor", "up"), [(1 - 1e-6, True), (1.0, True), (1 + 1e-6, False)])
def test_the_pen_is_up_from_half_the_pen_up_height(factor, up) -> None:
    row, height = _park_row(load_serial_profile("openmanipulator-x"))
    profile = load_serial_profile("openmanipulator-x", [f"robot.pen_up={2.0 * height * factor!r}"])
    assert ArmLift(profile).is_up(row) is up


def test_the_pens_height_is_measured_from_the_paper_where_it_lies() -> None:
    """A sheet raised 20 mm (on a board) holds the pen at the rest pose 20 mm lower over it."""
    _, on_table = _park_row(load_serial_profile("openmanipulator-x"))
    _, on_board = _park_row(load_serial_profile("openmanipulator-x", ["paper.z=20"]))
    assert on_board == pytest.approx(on_table - 20.0, abs=1e-9)


@pytest.mark.parametrize(("limit", "beyond"), [("lower", -5), ("upper", 5)])
def test_a_pose_found_beyond_a_joints_limit_is_held_at_that_limit(limit, beyond) -> None:
    """An arm found (torque off) with its wrist 5 ticks beyond a limit of its range: the goal
    that holds it there is the limit itself, never a goal beyond it."""
    profile = load_serial_profile("openmanipulator-x", ["servo.feedforward=false"])
    pairs = list(zip(profile.park, profile.joints, strict=True))
    row = np.array([int(angles_to_ticks(a, j)) for a, j in pairs])
    wrist = profile.joints[3]
    at = int(angles_to_ticks(getattr(wrist, limit), wrist))
    row[3] = at + beyond
    (held,) = ArmLift(profile).stand(row)
    assert held.tolist() == [*row[:3].tolist(), at]


def test_a_hop_is_measured_from_the_last_sample_on_the_paper() -> None:
    t = np.arange(5) * 0.001
    x = np.array([-5.0, 0.0, 0.3, 0.6, 0.9])  # far before the last sample on the paper
    pen = np.array([1, 1, 0, 1, 1.0])
    out = bridge_hops(np.column_stack([t, x, np.zeros(5), pen]), nib=0.002)
    np.testing.assert_array_equal(out[:, 3], [1, 1, 1, 1, 1])
    # far from the paper's origin, on both axes: the hop is 0.6 mm along x, none along y
    far = bridge_hops(np.column_stack([t, x + 100.0, np.full(5, 50.0), pen]), nib=0.002)
    np.testing.assert_array_equal(far[:, 3], [1, 1, 1, 1, 1])


def test_a_run_of_two_planned_instants_has_its_contact_figure() -> None:
    executed = np.column_stack([np.linspace(0, 2, 21), np.zeros(21), np.zeros(21), np.ones(21)])
    run = (np.array([0.5, 1.5]), np.array([[0.0, 0.0], [1.0, 0.0]]))
    (figures,) = contact_figures([run], executed, np.zeros((0, 2)))
    assert figures["contact_kept_pct"] == 100.0
    assert math.isnan(figures["force_min_n"]) and math.isnan(figures["force_max_n"])
    force = np.column_stack([[0.2, 0.5, 1.0, 1.5, 1.8], [9.0, 0.3, 0.4, 0.6, 9.0]])
    (figures,) = contact_figures([run], executed, force)  # the force while the run draws
    assert (figures["force_min_n"], figures["force_max_n"]) == (0.3, 0.6)


def test_a_run_planned_as_a_dot_has_no_ink_to_lose() -> None:
    """A run whose planned points all coincide (no ink length) keeps 100 % of its contact."""
    executed = np.column_stack([np.linspace(0, 2, 21), np.zeros(21), np.zeros(21), np.ones(21)])
    run = (np.array([0.5, 1.0, 1.5]), np.zeros((3, 2)))
    (figures,) = contact_figures([run], executed, np.zeros((0, 2)))
    assert figures["contact_kept_pct"] == 100.0


def test_a_run_of_one_planned_instant_or_with_nothing_executed_has_no_figures() -> None:
    """A run of a single planned instant, or a run with no executed sample, has its three
    figures under their report keys, each NaN (nothing to judge)."""
    executed = np.column_stack([np.linspace(0, 2, 21), np.zeros(21), np.zeros(21), np.ones(21)])
    dot = (np.array([0.5]), np.zeros((1, 2)))
    line = (np.array([0.5, 1.5]), np.array([[0.0, 0.0], [1.0, 0.0]]))
    out = contact_figures([dot], executed, np.zeros((0, 2)))
    out += contact_figures([line], executed[:0], np.zeros((0, 2)))
    for figures in out:
        assert sorted(figures) == ["contact_kept_pct", "force_max_n", "force_min_n"]
        assert all(math.isnan(v) for v in figures.values())


def test_planned_instants_in_whole_seconds_move_on_by_a_pause() -> None:
    """A pause of 0.25 s at 0.5 s on the executed clock: the planned instants after it are found
    0.25 s later, given as whole seconds too."""
    executed = np.column_stack([np.linspace(0, 3, 31), np.zeros(31), np.zeros(31), np.ones(31)])
    executed[14:17, 3] = 0.0  # off the paper 1.4..1.6 s: the second step's middle, unpaused
    run = (np.array([0, 1, 2]), np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]))
    (paused,) = contact_figures([run], executed, np.zeros((0, 2)), [(0.5, 0.25)])
    (plain,) = contact_figures([run], executed, np.zeros((0, 2)))
    assert (paused["contact_kept_pct"], plain["contact_kept_pct"]) == (100.0, 50.0)


def test_joints_csv_times_step_by_the_period_from_zero(letter_b, tmp_path) -> None:
    job = prepare(letter_b, profile="openmanipulator-x")
    job.run(tmp_path)
    rows = np.loadtxt(tmp_path / "joints.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(rows[:3, 0], [0.0, 0.01, 0.02])
    assert rows[0, 1:].tolist() == job.program.goals[0].tolist()


def test_the_planar_arms_sysfs_option_is_accepted_and_others_refused(letter_b) -> None:
    assert prepare(letter_b, profile="openmanipulator-x", sysfs="/no/sys").port is None
    with pytest.raises(InputError, match=r"^speed: not an option of the arm$"):
        prepare(letter_b, profile="openmanipulator-x", speed=2)


def test_a_serial_profile_file_is_one_with_a_robot_section(tmp_path) -> None:
    serial = tmp_path / "mine.toml"
    serial.write_text('[robot]\ndescription = "open_manipulator_x.xml"\n', encoding="utf-8")
    planar = tmp_path / "planar.toml"
    planar.write_text("[arm]\nl1 = 100\n", encoding="utf-8")
    text = tmp_path / "robot.txt"
    text.write_text("[robot]\n", encoding="utf-8")
    assert is_serial_profile(serial) and is_serial_profile(str(serial))
    assert not is_serial_profile(planar) and not is_serial_profile(text)
    assert not is_serial_profile(tmp_path / "missing.toml") and not is_serial_profile(None)
    assert not is_serial_profile("default") and is_serial_profile("koch-v1.1")


def test_a_robot_description_by_path_relative_to_the_working_folder(tmp_path, monkeypatch) -> None:
    shipped = load_serial_profile("openmanipulator-x").description
    (tmp_path / "my_arm.xml").write_text(shipped.read_text(encoding="utf-8"), encoding="utf-8")
    default = Path(tagbot.__file__).parent / "arm" / "serial" / "profiles" / "default.toml"
    text = default.read_text(encoding="utf-8")
    mine = text.replace('description = "open_manipulator_x.xml"', 'description = "my_arm.xml"')
    assert mine != text
    (tmp_path / "mine.toml").write_text(mine, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    profile = load_serial_profile("mine.toml")
    assert profile.description == Path("my_arm.xml")
    assert [j.name for j in profile.joints] == ["joint1", "joint2", "joint3", "joint4"]


def _profile_file(folder: Path, description: str, model_text: str | None = None) -> Path:
    """A copy of the shipped default profile naming ``description`` (and that model written)."""
    default = Path(tagbot.__file__).parent / "arm" / "serial" / "profiles" / "default.toml"
    text = default.read_text(encoding="utf-8")
    mine = text.replace('description = "open_manipulator_x.xml"', f"description = {description}")
    assert mine != text
    if model_text is not None:
        (folder / "my_arm.xml").write_text(model_text, encoding="utf-8")
    (folder / "mine.toml").write_text(mine, encoding="utf-8")
    return folder / "mine.toml"


def test_a_robot_description_that_is_no_text_is_named_with_its_file(tmp_path) -> None:
    path = _profile_file(tmp_path, "5")
    with pytest.raises(ProfileError, match=rf"^{path}: robot\.description: must be a non-empty"):
        load_serial_profile(path)


def test_a_description_without_the_pens_mount_is_named_with_the_profile_file(tmp_path) -> None:
    shipped = load_serial_profile("openmanipulator-x").description.read_text(encoding="utf-8")
    model = shipped.replace('<site name="end_effector"', '<site name="wrist"')
    assert model != shipped
    path = _profile_file(tmp_path, f'"{tmp_path / "my_arm.xml"}"', model)
    with pytest.raises(ProfileError, match=rf"^{path}: robot\.description: .*needs sites"):
        load_serial_profile(path)


def test_a_description_with_non_ascii_text_loads_into_the_physics_whatever_the_locale(
    tmp_path,
) -> None:
    """A robot description holding non-ASCII text (a note naming the arm's pen, épaule)
    loads into the physics simulator under an ASCII locale too: its copy with the pen is
    written as UTF-8, as MuJoCo reads it."""
    shipped = load_serial_profile("openmanipulator-x").description.read_text(encoding="utf-8")
    note = '<custom><text name="note" data="the arm\u2019s pen, épaule"/></custom></mujoco>'
    model = shipped.replace("</mujoco>", note)
    assert model != shipped
    profile = load_serial_profile(_profile_file(tmp_path, f'"{tmp_path / "my_arm.xml"}"', model))
    before = locale.setlocale(locale.LC_CTYPE)
    locale.setlocale(locale.LC_CTYPE, "C")
    try:
        assert locale.getencoding() != "UTF-8"
        _chain, physics = simulated_arm(profile)
    finally:
        locale.setlocale(locale.LC_CTYPE, before)
    assert physics.model.ntext == 1
    physics.detach()


def test_the_budgets_warnings_are_logged_as_worded(caplog) -> None:
    report = {"runs": [{"plan": 2, "path_deviation_max_mm": 0.5, "speed_snr_db": 30.0}]}
    contacts = [{"contact_kept_pct": 100.0, "force_min_n": 0.3, "force_max_n": 0.5}]
    with caplog.at_level(logging.WARNING, logger="tagbot.arm.serial.machine"):
        (warning,) = SerialBudget(contacts, [10.0])(report)
    assert warning == "run 1 (plan 2): path deviation 0.500 mm over 0.3 mm"
    assert [r.getMessage() for r in caplog.records] == [warning]


def test_lifting_and_lowering_at_a_pose_retrace_one_path(program, profile) -> None:
    """From a pose on the paper, the lift's goals are the lowering's in reverse, the pose's own
    standing goal ending the lowering (and not in the lift); all are whole ticks, as the
    program's goals."""
    lift = ArmLift(profile, program)
    row = program.goals[next(s for s in program.segments if s[0] == "draw")[2] + 5]
    up, down = lift.up(row), lift.down(row)
    assert up.dtype == down.dtype == lift.stand(row).dtype == program.goals.dtype == np.int64
    assert len(up) >= 2 and len(down) == len(up) + 1
    np.testing.assert_array_equal(down[::-1][1:], up)
    np.testing.assert_array_equal(down[-1], lift.stand(row)[0])
    assert lift.is_up(up[-1]) and not lift.is_up(down[-1])


@pytest.mark.parametrize(("gain", "ok"), [(16383, True), (16384, False)])
def test_a_position_gain_is_a_14_bit_value(gain, ok) -> None:
    overrides = [f"servo.position_p_gain={gain}"]
    if ok:
        assert load_serial_profile("openmanipulator-x", overrides).gains[0] == gain
        return
    with pytest.raises(ProfileError, match=r"^--set: servo\.position_p_gain: must be 0\.\.16383$"):
        load_serial_profile("openmanipulator-x", overrides)


def test_a_servo_range_touching_the_joints_range_at_one_angle_is_refused() -> None:
    """The Koch's shoulder_lift ranges 0..2.5 rad; zero = 4095 puts the servo's 0..4095 ticks
    at -2π..0 rad, meeting that range at 0 alone: no overlap."""
    with pytest.raises(
        ProfileError,
        match=r"^--set: shoulder_lift\.zero: the joint's range and the servo's 0\.\.4095 ticks"
        r" do not overlap$",
    ):
        load_serial_profile("koch-v1.1", ["shoulder_lift.zero=4095"])


def test_a_joint_the_lift_does_not_move_does_not_slow_it(program) -> None:
    """Lifting straight up along the paper's normal leaves the base where it is: a base with
    a slow speed and acceleration limit lifts the pen in as many ticks as a fast one."""
    row = program.goals[next(s for s in program.segments if s[0] == "draw")[2] + 5]
    fast = ArmLift(load_serial_profile("openmanipulator-x"), program).up(row)
    slow_base = ("joint1.max_acceleration=20", "joint1.max_speed=5")
    slow = ArmLift(load_serial_profile("openmanipulator-x", slow_base), program).up(row)
    assert (fast[:, 0] == row[0]).all()
    np.testing.assert_array_equal(slow, fast)


def test_a_lift_is_slowed_where_a_joints_acceleration_binds(program) -> None:
    """The joints the lift moves (shoulder, elbow, wrist) with a lower acceleration limit, their
    speed limit unchanged: the lift takes more ticks than with the default limits."""
    row = program.goals[next(s for s in program.segments if s[0] == "draw")[2] + 5]
    fast = ArmLift(load_serial_profile("openmanipulator-x"), program).up(row)
    slower = tuple(f"joint{i}.max_acceleration=20" for i in (2, 3, 4))
    slow = ArmLift(load_serial_profile("openmanipulator-x", slower), program).up(row)
    assert len(slow) > len(fast)


def test_an_arm_found_a_hair_beyond_a_joints_range_is_lifted_within_it(profile) -> None:
    """Found with its torque off 3 mm above the paper, its elbow 2 mrad past the range's end (as
    the simulator on a pty leaves it after falling): the lift starts from the nearest pose within
    the ranges, no goal leaves them, and the pen ends up."""
    lift, arm = ArmLift(profile), profile.arm
    q = np.array([0.0, -0.3, arm.upper[2] + 2e-3, -0.599])
    row = np.array([angles_to_ticks(q[i], j) for i, j in enumerate(profile.joints)])
    assert lift.angles(row)[2] > arm.upper[2] and not lift.is_up(row)
    goals = np.concatenate([lift.stand(row), lift.up(row)])
    angles = np.array([lift.angles(g) for g in goals])
    tick = 2 * np.pi / 4096
    assert np.all(angles >= arm.lower - tick) and np.all(angles <= arm.upper + tick)
    assert len(goals) > 2 and lift.is_up(goals[-1])


def test_the_budgets_at_their_limits_and_without_figures_warn_of_nothing() -> None:
    """A run at 0.3 mm, 25 dB, contact 100 % and 1.1 N is within every budget; a run without
    figures (NaN contact and force, no deviation or SNR) is judged on nothing; the contact
    figures join the runs of the report."""
    at = {"plan": 0, "path_deviation_max_mm": 0.3, "speed_snr_db": 25.0}
    bare = {"plan": 1}
    contacts = [
        {"contact_kept_pct": 100.0, "force_min_n": 0.05, "force_max_n": 1.1},
        {"contact_kept_pct": math.nan, "force_min_n": math.nan, "force_max_n": math.nan},
    ]
    report = {"runs": [at, bare]}
    assert SerialBudget(contacts, [0.5, 0.5])(report) == []
    assert report["runs"][0]["contact_kept_pct"] == 100.0
    assert report["runs"][0]["force_max_n"] == 1.1
    assert math.isnan(report["runs"][1]["contact_kept_pct"])
    # past each limit, with fewer contact figures and lengths than runs: named, not a crash
    past = {"plan": 0, "path_deviation_max_mm": 0.301, "speed_snr_db": 24.9}
    warnings = SerialBudget([])({"runs": [past]})
    assert warnings == [
        "run 1 (plan 0): path deviation 0.301 mm over 0.3 mm and speed SNR 24.9 dB below 25 dB"
    ]
    # cut short by a stop: its speed is not judged, its path still is
    assert SerialBudget([])({"runs": [{**past, "cut_short": True}]}) == [
        "run 1 (plan 0): path deviation 0.301 mm over 0.3 mm"
    ]


@pytest.mark.parametrize(
    ("ticks", "seconds"),
    [
        (0, 0.2),  # standing still: the servos' move is never shorter than 0.2 s
        (1024, 2.0 * math.pi / (3.0 * math.radians(150.0))),  # a quarter turn: the speed binds
    ],
)
def test_the_approach_takes_what_the_slowest_joint_needs_at_least_0_2_s(ticks, seconds) -> None:
    """The servos' own move with ramps a quarter each way: 4d/3 ÷ max_speed, or
    √(16d/3 ÷ max_acceleration) when that is longer (a short move)."""
    profile = load_serial_profile("openmanipulator-x")
    present = np.array([2148, 2348, 1848, 1948])  # away from every joint's zero
    goals = present.copy()
    goals[0] += ticks // 2
    goals[2] -= ticks  # joint3 moves the farthest and binds
    assert _approach_time(present, goals, profile) == pytest.approx(seconds, rel=1e-9)
    small = present.copy()
    small[1] += 20  # 20 ticks: 0.0307 rad, the acceleration binds (1500°/s²)
    d = 20 * 2 * math.pi / 4096
    bound = max(0.2, math.sqrt(16.0 * d / (3.0 * math.radians(1500.0))))
    slow = load_serial_profile("openmanipulator-x", ["joint2.max_acceleration=20"])
    bound_slow = math.sqrt(16.0 * d / (3.0 * math.radians(20.0)))
    assert _approach_time(present, small, profile) == pytest.approx(bound, rel=1e-9)
    assert _approach_time(present, small, slow) == pytest.approx(bound_slow, rel=1e-9)


def test_a_planned_instant_at_a_pauses_start_is_drawn_after_the_pause() -> None:
    """A pause that starts exactly at a planned instant (1 s, as the pause clock reads it) holds
    that instant too: it is drawn 0.25 s later, with everything after it."""
    executed = np.column_stack([np.linspace(0, 3, 31), np.zeros(31), np.zeros(31), np.ones(31)])
    executed[5, 3] = 0.0  # off the paper at 0.5 s only, before the pause: no planned step there
    run = (np.array([0.0, 1.0, 2.0]), np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]))
    (paused,) = contact_figures([run], executed, np.zeros((0, 2)), [(1.0, 0.25)])
    assert paused["contact_kept_pct"] == 100.0  # steps around 0.625 s and 1.75 s
    (late,) = contact_figures([run], executed, np.zeros((0, 2)), [(1.0 + 1e-6, 0.25)])
    assert late["contact_kept_pct"] == 50.0  # the instant before the pause: a step around 0.5 s


@pytest.mark.parametrize(("before", "kept"), [(1e-9, 100.0), (1e-8, 50.0)])
def test_a_planned_instant_a_nanosecond_before_a_pause_counts_as_at_it(before, kept) -> None:
    """A planned instant up to 1 ns before a pause's start (the clocks' rounding) is drawn after
    the pause, with everything after it; 10 ns before, it is drawn before the pause."""
    executed = np.column_stack([np.linspace(0, 3, 31), np.zeros(31), np.zeros(31), np.ones(31)])
    executed[5, 3] = 0.0  # off the paper at 0.5 s only, before the pause
    run = (np.array([0.0, 1.0 - before, 2.0]), np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]))
    (paused,) = contact_figures([run], executed, np.zeros((0, 2)), [(1.0, 0.25)])
    assert paused["contact_kept_pct"] == kept  # steps around 0.625 s and 1.75 s, or 0.5 s


def test_a_step_at_the_first_executed_sample_is_judged_by_that_sample() -> None:
    """The record starts at 0.5 s with the nib off the paper there only: the planned step whose
    middle is that instant counts as not drawn (the first sample's), the next one as drawn."""
    executed = np.column_stack([np.linspace(0.5, 3, 26), np.zeros(26), np.zeros(26), np.ones(26)])
    executed[0, 3] = 0.0
    run = (np.array([0.0, 1.0, 2.0]), np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]))
    (figures,) = contact_figures([run], executed, np.zeros((0, 2)))
    assert figures["contact_kept_pct"] == 50.0  # steps around 0.5 s (off) and 1.5 s (on)


def test_an_arm_on_a_port_is_traced_from_its_read_backs(profile, tmp_path) -> None:
    """A serial arm on a port (a simulated chain attached by URL: no in-process recorder): the
    run ends without error and its executed trace is the read-backs' forward kinematics."""
    from sim.dynamixel import attach_chain, detach_chain

    from ..conftest import small_tag

    chain, _ = simulated_arm(profile)
    url = attach_chain(chain, "tagbot_serial_arm_by_url")
    try:
        run = prepare(small_tag(), profile="openmanipulator-x", port=url).run(tmp_path)
    finally:
        detach_chain("tagbot_serial_arm_by_url")
    assert run.error is None
    assert len(run.executed) > 0 and run.executed[:, 3].max() == 1.0
