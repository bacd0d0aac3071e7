"""The shipped OpenManipulator-X description against ROBOTIS's published numbers, by hand."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from tagbot.arm.serial import OPEN_MANIPULATOR_X
from tagbot.arm.serial.kinematics import SerialArm
from tagbot.arm.serial.profile import load_serial_profile
from tagbot.errors import ProfileError

# open_manipulator_x.urdf (ROBOTIS, Apache-2.0): joint origins in the parent frame, axes, limits
ORIGINS = [(0.012, 0, 0), (0, 0, 0.0595), (0.024, 0, 0.128), (0.124, 0, 0)]
AXES = [(0, 0, 1), (0, 1, 0), (0, 1, 0), (0, 1, 0)]
RANGES = [(-math.pi, math.pi), (-1.5, 1.5), (-1.5, 1.4), (-1.7, 1.97)]
MASSES = {"link1": 0.079119962, "link2": 0.098406837, "link3": 0.13850917}
MASSES |= {"link4": 0.13274562, "link5": 0.14327573}
EE = 0.126  # end effector from link5 along x
PEN = 0.03  # the shipped pen's point beyond the end effector


@pytest.fixture(scope="module")
def arm() -> SerialArm:
    return SerialArm.load()


def test_the_chain_at_zero_is_the_reference_offsets_summed(arm: SerialArm) -> None:
    data = mujoco.MjData(arm.model)
    mujoco.mj_kinematics(arm.model, data)
    # At q = 0 every frame is parallel to the base: the joints sit at the running sums.
    expected = np.cumsum(ORIGINS, axis=0)
    np.testing.assert_allclose(data.xanchor, expected, atol=1e-12)
    np.testing.assert_allclose(expected[-1], (0.160, 0, 0.1875))
    np.testing.assert_allclose(data.xaxis, AXES, atol=1e-12)
    np.testing.assert_allclose(data.site("end_effector").xpos, (0.286, 0, 0.1875), atol=1e-12)
    tip, axis = arm.fk(np.zeros(4))
    np.testing.assert_allclose(tip, (0.286 + PEN, 0, 0.1875), atol=1e-12)
    np.testing.assert_allclose(axis, (1, 0, 0), atol=1e-12)


def test_a_bent_pose_by_hand(arm: SerialArm) -> None:
    # joint1 a quarter turn, joint4 pointing the pen straight down: the tip is 0.156 m below
    # joint4, which is 0.148 m from joint1's axis along +y.
    tip, axis = arm.fk([math.pi / 2, 0, 0, math.pi / 2])
    np.testing.assert_allclose(tip, (0.012, 0.148, 0.1875 - EE - PEN), atol=1e-12)
    np.testing.assert_allclose(axis, (0, 0, -1), atol=1e-12)
    # joint2 forward by a: the arm's rest turns about the shoulder (0.012, 0, 0.0595)
    a = 0.7
    rest = np.array([0.024 + 0.124 + EE + PEN, 0.128])  # (x, z) from the shoulder at q = 0
    x = rest[0] * math.cos(a) + rest[1] * math.sin(a)
    z = -rest[0] * math.sin(a) + rest[1] * math.cos(a)
    tip, axis = arm.fk([0, a, 0, 0])
    np.testing.assert_allclose(tip, (0.012 + x, 0, 0.0595 + z), atol=1e-12)
    np.testing.assert_allclose(axis, (math.cos(a), 0, -math.sin(a)), atol=1e-12)


def test_limits_masses_velocities_and_actuators(arm: SerialArm) -> None:
    assert arm.joint_names == ("joint1", "joint2", "joint3", "joint4")
    np.testing.assert_allclose(np.stack([arm.lower, arm.upper], 1), RANGES)
    np.testing.assert_array_equal(arm.velocity, [4.8] * 4)
    for name, mass in MASSES.items():
        assert arm.model.body(name).mass[0] == pytest.approx(mass, rel=1e-7)
    for j, name in enumerate(arm.joint_names):
        act = arm.model.actuator(name)
        assert arm.model.joint(act.trnid[0]).name == name
        np.testing.assert_allclose(act.ctrlrange, RANGES[j])
    assert arm.model.nu == 4


def test_a_longer_pen_moves_the_tip_and_the_nib(arm: SerialArm) -> None:
    longer = SerialArm.load(tool_offset=0.05)
    tip, _ = longer.fk(np.zeros(4))
    np.testing.assert_allclose(tip, (0.286 + 0.05, 0, 0.1875), atol=1e-12)
    nib = longer.model.geom("pen_nib")
    data = mujoco.MjData(longer.model)
    mujoco.mj_kinematics(longer.model, data)
    # the capsule's far cap ends at the point: centre + (half length + radius) along x
    end = data.geom("pen_nib").xpos[0] + nib.size[1] + nib.size[0]
    assert end == pytest.approx(0.336, abs=1e-12)
    off = SerialArm.load(tool_offset=(0.02, 0.0, -0.01))
    np.testing.assert_allclose(off.fk(np.zeros(4))[0], (0.306, 0, 0.1775), atol=1e-12)


def test_self_contacts_exclude_adjacent_links_and_the_scene(arm: SerialArm, tmp_path) -> None:
    assert arm.contacts(np.zeros(4)) == []
    # a block in the scene where the pen is at q = 0: a contact, but not the arm's own
    text = OPEN_MANIPULATOR_X.read_text().replace(
        "<worldbody>",
        '<worldbody><geom name="block" type="box" pos="0.30 0 0.1875" size="0.02 0.02 0.02"/>',
    )
    (tmp_path / "scene.xml").write_text(text)
    scene = SerialArm.load(tmp_path / "scene.xml")
    data = mujoco.MjData(scene.model)
    mujoco.mj_forward(scene.model, data)
    assert data.ncon > 0 and scene.contacts(np.zeros(4)) == []
    assert scene.contacts([0, 0, 1.4, 1.97]) == arm.contacts([0, 0, 1.4, 1.97])
    folded = arm.contacts([0, 0, 1.4, 1.97])  # the gripper folded back onto the arm
    assert ("link3_arm", "link5_body") in folded
    assert all("link1" not in a or "link2" not in b for a, b in folded)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        (None, "cannot load the robot description"),
        (
            "<mujoco><worldbody><body><joint range='0 1'/><geom size='0.1'/></body>"
            "</worldbody></mujoco>",
            "no site 'pen_tip'",
        ),
        (
            "<mujoco><worldbody><body><joint range='0 1'/><geom size='0.1'/>"
            "<site name='pen_tip'/></body></worldbody></mujoco>",
            "no custom numeric",
        ),
        (
            "<mujoco><worldbody><body><joint/><geom size='0.1'/><site name='pen_tip'/></body>"
            "</worldbody></mujoco>",
            "every joint needs a range",
        ),
        (
            "<mujoco><custom><numeric name='joint_velocity_limit' data='0'/></custom><worldbody>"
            "<body><joint range='0 1'/><geom size='0.1'/><site name='pen_tip'/></body>"
            "</worldbody></mujoco>",
            "need 1 positive values",
        ),
    ],
)
def test_bad_descriptions_are_named(tmp_path, text: str | None, problem: str) -> None:
    path = tmp_path / "arm.xml"
    if text is not None:
        path.write_text(text)
    with pytest.raises(ProfileError, match=problem) as err:
        SerialArm.load(path)
    assert str(err.value).startswith(f"{path}: ")
    assert "\n" not in str(err.value)


def test_a_bad_tool_offset_is_named() -> None:
    with pytest.raises(ProfileError, match="tool_offset: need a number or 3 numbers"):
        SerialArm.load(tool_offset=(0.1, 0.2))
    with pytest.raises(ProfileError, match="inside the holder"):
        SerialArm.load(tool_offset=-0.006)


def test_the_model_ships_with_the_package() -> None:
    assert OPEN_MANIPULATOR_X.is_file()
    text = OPEN_MANIPULATOR_X.read_text()
    assert "Apache-2.0" in text and "open_manipulator_x.urdf" in text


def test_a_servo_id_of_252_is_taken_and_253_refused() -> None:
    """The highest DYNAMIXEL ID, 252, is a joint's servo; 253 is refused naming the joint."""
    assert load_serial_profile(None, ["joint4.id=252"]).bus_ids == [11, 12, 13, 252]
    with pytest.raises(ProfileError) as err:
        load_serial_profile(None, ["joint4.id=253"])
    assert str(err.value) == "--set: joint4.id: must be a DYNAMIXEL ID 0..252, got 253"


def test_an_area_off_the_paper_names_the_file_that_widened_it(tmp_path) -> None:
    """An area edge beyond the sheet is named, with the file (or --set) that put it there."""
    path = tmp_path / "wide.toml"
    path.write_text("[area]\nx_max = 200.0\n")
    with pytest.raises(ProfileError) as err:
        load_serial_profile(path)
    assert str(err.value) == (
        f"{path}: area.x_max: the area must lie on the paper (0..148 by 0..210 mm)"
    )
    with pytest.raises(ProfileError) as err:  # the edge that is off, whichever it is
        load_serial_profile(None, ["area.y_min=-5"])
    assert (
        str(err.value) == "--set: area.y_min: the area must lie on the paper (0..148 by 0..210 mm)"
    )
