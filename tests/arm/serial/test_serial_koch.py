"""Arms with any number of joints (issue 32): a profile's joints are its robot description's;
the Koch v1.1 (five joints, XL430-W250 and XL330-M288) draws a shipped tag through the physics
simulator, and is refused before the first byte where it cannot."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import tagbot
from tagbot.arm.serial.kinematics import SerialArm
from tagbot.arm.serial.machine import prepare
from tagbot.arm.serial.profile import is_serial_profile, load_serial_profile
from tagbot.draw import draw
from tagbot.errors import PlacementError, ProfileError, ReachError

EXAMPLES = Path(tagbot.__file__).parent / "examples"
KOCH_JOINTS = ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll"]


@pytest.fixture
def letter_b() -> tagbot.Tag:
    return tagbot.load_plan(EXAMPLES / "letter-b.json")


@pytest.fixture
def koch():
    return load_serial_profile("koch-v1.1")


@pytest.fixture
def drawn(letter_b, tmp_path):
    folder = tmp_path / "b"
    result = draw(letter_b, folder, device="dynamixel", profile="koch-v1.1", pictures=False)
    return folder, result.report


def test_the_profile_drives_the_joints_its_description_names(koch) -> None:
    assert is_serial_profile("koch-v1.1")
    assert [j.name for j in koch.joints] == KOCH_JOINTS  # the description's order
    assert koch.bus_ids == [1, 2, 3, 4, 5]  # LeRobot's IDs; the gripper (6) holds the pen
    assert list(koch.servos.values()) == ["XL430-W250"] * 2 + ["XL330-M288"] * 3
    assert "joint1" not in koch.values  # the OpenManipulator-X defaults' joints are dropped
    # each joint's feedforward by its own servo: an XL430 at 12 V, an XL330 at 5 V
    stiffness = koch.stiffness
    assert stiffness[0] == pytest.approx(stiffness[4] * 1.5 / 0.52)
    assert koch.back_emf[2] == pytest.approx(0.52 / (103 * 2 * np.pi / 60))


def test_a_joint_section_the_description_lacks_or_a_missing_one_is_one_line(tmp_path) -> None:
    with pytest.raises(ProfileError, match=r"^--set: joint1: unknown section \(the joints of "):
        load_serial_profile("koch-v1.1", ["joint1.id=7"])
    partial = tmp_path / "koch.toml"
    text = (Path(tagbot.__file__).parent / "arm/serial/profiles/koch-v1.1.toml").read_text()
    partial.write_text(text.split("[wrist_roll]")[0] + "[paper]" + text.split("[paper]")[1])
    with pytest.raises(ProfileError, match=r"^.*koch\.toml: wrist_roll\.\w+: missing$"):
        load_serial_profile(partial)
    with pytest.raises(ProfileError, match=r"^--set: wrist_roll\.id: IDs must differ$"):
        load_serial_profile("koch-v1.1", ["wrist_roll.id=1"])


def test_the_description_is_the_published_chain(koch) -> None:
    arm = SerialArm.load(koch.description)  # the pen's point where the file puts it
    tip, axis = arm.fk(np.zeros(5))
    # stretched out: 109.4 + 100.5 mm of arm (less their drops), 44.8 + 65 mm to the TCP, the
    # pen 30 mm beyond; 1.7 mm to the left of the pan axis and 33 mm up (the offsets summed)
    z = 0.0386 + 0.015368 - 0.014951 + 0.002641 - 0.00037 - 0.008
    assert tip == pytest.approx([0.108424 + 0.100502 + 0.044779 + 0.065 + 0.03, 0.00167, z])
    assert axis == pytest.approx([1.0, 0.0, 0.0])
    assert np.degrees(arm.upper[1:4]) == pytest.approx(np.degrees([2.5, 3.05, 2.14159]))


def test_the_koch_arm_draws_a_shipped_tag_through_the_physics(drawn) -> None:
    folder, report = drawn
    assert report["completed"] and report["simulated"]
    assert report["executed_source"].startswith("physics simulator")
    (run,) = report["runs"]
    # measured: 0.88 mm, 25.5 dB (the XL330s' 0.52 N·m against the feedforward's model; the
    # 0.3 mm budget warns); the ink kept all along, the nib's force within range
    assert run["path_deviation_max_mm"] <= 1.0
    assert run["speed_snr_db"] >= 24.0
    assert run["contact_kept_pct"] == 100.0
    assert run["force_max_n"] <= 1.1
    header = (folder / "joints.csv").read_text().splitlines()[0]
    assert header == "t," + ",".join(KOCH_JOINTS)
    executed = np.loadtxt(folder / "executed.csv", delimiter=",", skiprows=1)
    inked = executed[executed[:, 3] > 0.5]
    assert inked[:, 1].min() >= 0 and inked[:, 1].max() <= 105  # on the A6 sheet
    assert json.loads((folder / "report.json").read_text())["details"]["time_bound_s"] > 0


def test_the_koch_arm_refuses_before_the_first_byte(letter_b, tmp_path) -> None:
    folder = tmp_path / "never"
    with pytest.raises(ReachError, match=r"plan 0, (stroke \d+, t = [\d.]+ s|approach before it)"):
        draw(
            letter_b,
            folder,
            device="dynamixel",
            profile="koch-v1.1",
            overrides=("paper.x=200",),  # beyond the short arm's reach
            port="/dev/null-not-a-port",
        )
    assert not folder.exists()
    with pytest.raises(PlacementError, match=r"^plan 0: must be slowed down [\d.]+ times"):
        prepare(letter_b, profile="koch-v1.1", overrides=("shoulder_lift.max_speed=5",))
