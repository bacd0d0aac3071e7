"""The physics behind the simulated DYNAMIXEL bus (sim.dynamixel.physics): the OpenManipulator-X
driven through real Protocol 2.0 packets (dynamixel-sdk), Present Position from the physics, the
pen's contact with the paper."""

from __future__ import annotations

import math
import time

import dynamixel_sdk as dxl
import mujoco
import numpy as np
import pytest
import serial

import sim.dynamixel  # noqa: F401  (registers dxlsim://)
from firmware_protocols.dynamixel import InstructionPacket, PacketDecoder, encode_instruction
from sim.dynamixel import PtyServer, SimulatedChain, attach_chain, detach_chain
from sim.dynamixel.physics import (
    MOTORS,
    PWM_FULL_SCALE,
    TICKS_PER_RAD,
    ArmPhysics,
    PenSpring,
    Sheet,
)
from sim.dynamixel.servo import TICKS_PER_S_PER_VELOCITY_UNIT
from tagbot.arm.serial import OPEN_MANIPULATOR_X

IDS = (11, 12, 13, 14)
OK = (dxl.COMM_SUCCESS, 0)
XM430 = MOTORS[1020]


class SimTimePortHandler(dxl.PortHandler):
    """The SDK's port handler on a ``dxlsim://`` URL, its packet timeouts on the simulated clock."""

    def setupPort(self, cflag_baud):
        self.ser = serial.serial_for_url(self.port_name, timeout=0)
        self.is_open = True
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True

    def getCurrentTime(self):
        return self.ser.clock.now() * 1000.0


class PatientPortHandler(dxl.PortHandler):
    """The SDK's port handler on a pty, waiting 1 s more for each reply than the SDK's own
    timeout: the pty's pump shares this process (and a busy 2-core host) with the test."""

    def setPacketTimeout(self, packet_length):
        super().setPacketTimeout(packet_length)
        self.packet_timeout += 1000.0


def new_arm(clock: str = "simulated") -> tuple[SimulatedChain, ArmPhysics]:
    chain = SimulatedChain({id: "XM430-W350" for id in IDS}, clock=clock)
    return chain, ArmPhysics(chain, OPEN_MANIPULATOR_X)


@pytest.fixture
def ph() -> dxl.Protocol2PacketHandler:
    return dxl.PacketHandler(2.0)


@pytest.fixture
def arm():
    chain, physics = new_arm()
    attach_chain(chain, "physics_arm")
    yield chain, physics
    detach_chain("physics_arm")


@pytest.fixture
def port(arm):
    port = SimTimePortHandler("dxlsim://physics_arm")
    assert port.openPort()
    yield port
    port.closePort()


def robotis_settings(port, ph, gains=(800, 100, 100)) -> None:
    """ROBOTIS's OpenManipulator-X settings (P/I/D, Profile Velocity 200, Acceleration 50)."""
    p, i, d = gains
    for id in IDS:
        assert ph.write2ByteTxRx(port, id, 84, p) == OK
        assert ph.write2ByteTxRx(port, id, 82, i) == OK
        assert ph.write2ByteTxRx(port, id, 80, d) == OK
        assert ph.write4ByteTxRx(port, id, 112, 200) == OK
        assert ph.write4ByteTxRx(port, id, 108, 50) == OK
        assert ph.write1ByteTxRx(port, id, 64, 1) == OK


def signed16(value: int) -> int:
    return value - 65536 if value >= 32768 else value


def read_present(port, ph, physics: ArmPhysics, id: int) -> tuple[int, set[int]]:
    """Present Position through the SDK, and the physics horn's rounded ticks at every step
    while the READ was on the bus (the step it executed at is one of them)."""
    clock = port.ser.clock
    before = clock.now()
    value, result, error = ph.read4ByteTxRx(port, id, 132)
    after = clock.now()
    assert (result, error) == OK
    t, ticks = physics.joint_trace(id).T
    window = (t >= before - physics.timestep) & (t <= after)
    return value, {round(p) for p in ticks[window]}


def test_goal_position_through_the_sdk_follows_the_servo_dynamics(arm, port, ph):
    chain, physics = arm
    robotis_settings(port, ph, gains=(800, 0, 0))  # the XM430-W350's factory gains
    clock = port.ser.clock
    start = clock.now()
    assert ph.write4ByteTxRx(port, 11, 116, 2048 + 512) == OK  # joint1 (vertical axis) 45°
    clock.sleep_until(start + 0.15)  # accelerating: the horn lags the profile
    present, horn = read_present(port, ph, physics, 11)
    assert present in horn
    trajectory, *result = ph.read4ByteTxRx(port, 11, 140)
    assert tuple(result) == OK
    assert 2048 < present < trajectory - 5  # moving, behind the profile by a following error
    clock.sleep_until(start + 0.45)  # the profile has ended (0.41 s); the horn catches up
    assert clock.now() > chain.servo(11).trajectory.end
    moving, *result = ph.read1ByteTxRx(port, 11, 122)
    assert tuple(result) == OK and moving == 1  # faster than Moving Threshold
    status, *result = ph.read1ByteTxRx(port, 11, 123)
    assert tuple(result) == OK and status == 0x20  # triangular profile, done, not in position
    clock.sleep_until(start + 1.5)
    present, horn = read_present(port, ph, physics, 11)
    assert present in horn and present == 2048 + 512  # arrived, to the tick
    status, *result = ph.read1ByteTxRx(port, 11, 123)
    assert tuple(result) == OK and status == 0x21
    t, ticks = physics.joint_trace(11).T
    profile = chain.servo(11).trajectory.sample(t)
    moving = (t > start) & (t < start + 1.5)
    lag = profile[moving] - ticks[moving]
    # at the profile's peak, 2500 ticks/s (3.8 rad/s, near the no-load 4.8 rad/s), the back-EMF
    # takes 0.85 N·m·s/rad × 3.8 rad/s of the torque: P = 800 needs ~100 ticks to drive it
    assert 80.0 < lag.max() < 130.0 and lag.min() > -1.0  # no overshoot
    assert np.all(np.diff(ticks[moving]) > -0.5)  # a monotonic move, as the profile is
    velocity, *result = ph.read4ByteTxRx(port, 11, 128)
    assert tuple(result) == OK and velocity == 0


def test_holding_against_gravity_matches_the_gain_and_motor_model(arm, port, ph):
    chain, physics = arm
    chain.servo(12).input_voltage = 111  # an 11.1 V supply: 11.1/12 of the torque per PWM unit
    robotis_settings(port, ph, gains=(800, 0, 0))  # P only: a steady error carries the load
    clock = port.ser.clock
    goal = 2048 + round(0.6 * TICKS_PER_RAD)  # joint2 leans the arm forwards
    assert ph.write4ByteTxRx(port, 12, 116, goal) == OK
    assert ph.write4ByteTxRx(port, 13, 116, 4096 - goal) == OK  # the forearm level, in the air
    clock.sleep_until(clock.now() + 2.0)
    assert physics.data.ncon == 0
    present, horn = read_present(port, ph, physics, 12)
    assert present in horn
    dof = physics.drives[12].dof
    gravity = float(physics.data.qfrc_bias[dof])  # N·m the joint must hold (at rest)
    # PWM = KPP·e (e-Manual: KPP = P/128), torque = τs·PWM/885·V/12
    error = goal - physics.joint_trace(12)[-1, 1]
    torque = XM430.stall_torque * (800 / 128) * error / PWM_FULL_SCALE * 11.1 / 12.0
    assert abs(gravity) > 0.3 and torque == pytest.approx(gravity, rel=0.01)
    pwm, *result = ph.read2ByteTxRx(port, 12, 124)
    assert tuple(result) == OK and signed16(pwm) == round(800 / 128 * error)
    current, *result = ph.read2ByteTxRx(port, 12, 126)
    assert tuple(result) == OK
    amps = XM430.stall_current * gravity / XM430.stall_torque
    assert signed16(current) == pytest.approx(amps / 2.69e-3, abs=1.5)
    # the I term (KPI = I/65536 per 1 ms period) takes the error away, with a time constant
    # KPP / KPI periods (quasi-static: the loop is fast beside it)
    assert ph.write2ByteTxRx(port, 12, 82, 200) == OK
    clock.sleep_until(clock.now() + 2.0)
    ratio = (goal - physics.joint_trace(12)[-1, 1]) / error
    assert ratio == pytest.approx(math.exp(-2.0 * (200 / 65536) / (800 / 128) / 1e-3), abs=0.03)
    # the torque limit: a PWM Limit of 100 (11.3 %) cannot hold it, and the arm sags
    assert ph.write1ByteTxRx(port, 12, 64, 0) == OK
    assert ph.write2ByteTxRx(port, 12, 36, 100) == OK
    assert ph.write1ByteTxRx(port, 12, 64, 1) == OK
    assert ph.write4ByteTxRx(port, 12, 116, goal) == OK
    clock.sleep_until(clock.now() + 1.0)
    pwm, *result = ph.read2ByteTxRx(port, 12, 124)
    assert tuple(result) == OK and signed16(pwm) == -100
    present, _ = read_present(port, ph, physics, 12)
    assert present > goal + 100  # it sags forwards


def pose_for(physics: ArmPhysics, target: np.ndarray, tilt: float = 0.0) -> np.ndarray:
    """Joint angles that put the pen tip at ``target`` (arm frame, m) with the pen upright
    (``tilt`` rad: leaning back towards the arm)."""
    m = physics.model
    d = mujoco.MjData(m)
    tip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "pen_tip")

    def tip_at(q: np.ndarray) -> np.ndarray:
        d.qpos[:4] = [q[0], q[1], q[2], math.pi / 2 - q[1] - q[2] - tilt]
        mujoco.mj_kinematics(m, d)
        return d.site_xpos[tip].copy()

    q = np.array([math.atan2(target[1], target[0]), 0.3, -0.2])
    for _ in range(20):
        r = tip_at(q) - target
        jac = np.column_stack([(tip_at(q + h) - tip_at(q)) / 1e-7 for h in np.eye(3) * 1e-7])
        q -= np.linalg.lstsq(jac, r, rcond=None)[0]
    assert np.linalg.norm(tip_at(q) - target) < 1e-6
    return d.qpos[:4].copy()


def go_to(chain: SimulatedChain, q: np.ndarray) -> None:
    """Goal Position for the four joints now (the servos' own write path)."""
    for id, angle in zip(IDS, q, strict=True):
        goal = round(angle * TICKS_PER_RAD + 2048)
        assert chain.servo(id).write(116, goal.to_bytes(4, "little"), chain.now()) == 0


def torque_on(chain: SimulatedChain, gains=(800, 100, 100)) -> None:
    for id in IDS:
        servo, t = chain.servo(id), chain.now()
        for address, value in zip((84, 82, 80), gains, strict=True):
            assert servo.write(address, value.to_bytes(2, "little"), t) == 0
        assert servo.write(108, (50).to_bytes(4, "little") + (200).to_bytes(4, "little"), t) == 0
        assert servo.write(64, b"\x01", t) == 0


def test_pen_pressed_on_the_paper_then_lifted():
    chain, physics = new_arm()
    torque_on(chain)
    sheet = physics.sheet
    on_paper = np.array([0.17, 0.0, 0.0])  # 70 mm, 105 mm on the default sheet
    go_to(chain, pose_for(physics, on_paper + np.array([0, 0, 0.01])))  # 1 cm above
    chain.advance(1.5)
    assert np.all(physics.pen_trace()[:, 3:] == 0.0)  # no contact on the way
    go_to(chain, pose_for(physics, on_paper + np.array([0, 0, -0.002])))  # 2 mm into the paper
    chain.advance(1.5)
    t, x, y, pen, force = physics.pen_trace().T
    settled = t > chain.now() - 0.3
    assert np.all(pen[settled] == 1.0)
    # the nib's spring: over its preload, and short of the end of its travel (where the
    # force would jump); 2 mm in, plus the few mm the arm sags under its weight
    spring = PenSpring()
    end = spring.preload + spring.stiffness * spring.travel
    assert np.all((force[settled] > spring.preload) & (force[settled] < end))
    expected = (on_paper - np.asarray(sheet.origin)) * 1000.0
    assert np.all(np.abs(x[settled] - expected[0]) < 3.0)  # mm (the arm sags a little)
    assert np.all(np.abs(y[settled] - expected[1]) < 0.1)
    slide = physics.data.qpos[physics.model.joint("pen_slide").qposadr[0]]
    nib_force = spring.preload - spring.stiffness * slide  # what the spring pushes with
    assert force[-1] == pytest.approx(nib_force, abs=0.05)  # + the nib's weight, 29 mN
    lifted = chain.now()
    go_to(chain, pose_for(physics, on_paper + np.array([0, 0, 0.01])))
    chain.advance(1.5)
    t, x, y, pen, force = physics.pen_trace().T
    up = t > lifted + 0.8
    assert np.all(pen[up] == 0.0) and np.all(force[up] == 0.0)
    touching = physics.pen_trace(threshold=0.0)[:, 3]
    assert np.array_equal(touching, (force > 0.0).astype(float)) and touching.any()
    # on the table beside the sheet: a contact, but no ink
    beside = np.array([0.08, 0.0, -0.002])
    go_to(chain, pose_for(physics, beside))
    chain.advance(1.5)
    nib = physics.model.geom("pen_nib").id
    table = physics.model.geom("table").id
    d = physics.data
    assert any({d.contact[i].geom1, d.contact[i].geom2} == {nib, table} for i in range(d.ncon))
    assert physics.pen_trace()[-1, 3:].tolist() == [0.0, 0.0]
    # the recorder steps with the physics: one row per step, from the attach time
    t = physics.pen_trace()[:, 0]
    assert np.allclose(np.diff(t), physics.timestep) and t[0] == 0.0
    assert t[-1] == pytest.approx(chain.now(), abs=physics.timestep)


def test_the_felt_nib_gives_a_tenth_of_a_millimetre_at_half_a_newton():
    # a fibre or felt nib's point (physics.NIB_SOLREF): about 5 000 N/m on the paper, the
    # paper and the table under it far stiffer; MuJoCo's default contact let it sink 0.6 mm
    chain, physics = new_arm()
    torque_on(chain, gains=(1600, 0, 0))
    on_paper = np.array([0.17, 0.0, 0.0])
    go_to(chain, pose_for(physics, on_paper + np.array([0, 0, 0.005])))
    chain.advance(1.5)
    paper, nib = physics.model.geom("paper").id, physics.model.geom("pen_nib").id
    stiffness = []
    for depth in (0.0005, 0.0015):  # the holder's spring pressed 0.5 and 1.5 mm: 0.3, 0.5 N
        go_to(chain, pose_for(physics, on_paper - np.array([0, 0, depth])))
        chain.advance(1.5)
        d = physics.data
        (sunk,) = [-d.contact[i].dist for i in range(d.ncon)
                   if {d.contact[i].geom1, d.contact[i].geom2} == {paper, nib}]  # fmt: skip
        stiffness.append(physics.pen_trace()[-1, 4] / sunk)
    assert all(3000.0 < k < 8000.0 for k in stiffness)


def run_script() -> tuple[np.ndarray, ...]:
    chain, physics = new_arm()
    torque_on(chain)
    for z in (0.01, -0.002, 0.01):
        go_to(chain, pose_for(physics, np.array([0.16, 0.02, z])))
        chain.advance(0.4)
    return (physics.pen_trace(), *(physics.joint_trace(id) for id in IDS))


def test_same_commands_same_trace():
    first, second = run_script(), run_script()
    assert first[0][:, 3].any()  # it did draw
    for a, b in zip(first, second, strict=True):
        assert np.array_equal(a, b)


def test_attach_and_detach():
    chain = SimulatedChain({id: "XM430-W350" for id in (*IDS, 15)})
    sheet = Sheet(origin=(0.1, -0.1, 0.0), size=(0.2, 0.2))
    physics = ArmPhysics(chain, OPEN_MANIPULATOR_X, paper=sheet)
    assert chain.plant is physics and chain.servo(15).plant is None  # the gripper: no joint
    with pytest.raises(ValueError, match="already has a physics"):
        ArmPhysics(chain, OPEN_MANIPULATOR_X)
    torque_on(chain)
    go_to(chain, np.array([0.5, 0.0, 0.0, 0.0]))
    chain.advance(0.2)
    servo = chain.servo(11)
    assert servo.present(chain.now())[0] == physics.joint_trace(11)[-1, 1]
    assert servo.present(chain.now())[0] != servo.state(chain.now())[0]
    physics.detach()
    assert chain.plant is None and all(chain.servo(id).plant is None for id in IDS)
    steps = len(physics.joint_trace(11))
    chain.advance(1.0)  # the physics no longer moves; the servo tracks its profile again
    assert len(physics.joint_trace(11)) == steps
    assert servo.present(chain.now()) == servo.state(chain.now())
    with pytest.raises(ValueError, match="joint9"):
        ArmPhysics(SimulatedChain({1: "XM430-W350"}), OPEN_MANIPULATOR_X, joints={1: "joint9"})
    with pytest.raises(KeyError, match="servo 15"):
        physics.joint_trace(15)


def test_torque_on_holds_where_the_arm_fell_and_reboot_restores_the_goal_limits():
    chain, physics = new_arm()
    chain.advance(1.0)  # torque off: the arm folds under its weight
    servo = chain.servo(12)
    fallen = physics.joint_trace(12)[-1, 1]
    assert abs(fallen - 2048) > 100
    assert servo.write(64, b"\x01", chain.now()) == 0
    assert servo.get("goal_position") == round(fallen)
    chain.advance(0.5)
    assert abs(physics.joint_trace(12)[-1, 1] - fallen) < 30  # held there, not pulled back
    assert (servo.get("goal_pwm"), servo.get("goal_current")) == (885, 1193)
    assert servo.write(100, (100).to_bytes(2, "little"), chain.now()) == 0
    servo.reboot(chain.now())
    assert (servo.get("goal_pwm"), servo.get("torque_enable")) == (885, 0)


def test_homing_offset_and_turning_by_hand_stay_with_the_servo():
    chain, physics = new_arm()
    for id in IDS[1:]:  # the arm held upright; joint1 free
        assert chain.servo(id).write(64, b"\x01", 0.0) == 0
    servo, t = chain.servo(11), chain.now()
    assert servo.write(20, (1000).to_bytes(4, "little"), t) == 0  # Homing Offset
    chain.set_position(11, 3048 + 300)  # by hand, torque off: horn at 2348
    chain.advance(0.01)
    assert physics.data.qpos[physics.drives[11].qadr] == pytest.approx(
        300 / TICKS_PER_RAD, abs=1e-4
    )
    error, data = servo.read(132, 4, chain.now())
    assert error == 0 and int.from_bytes(data, "little") == 3348
    # torque on holds the horn where it is (Goal Position = Present Position, offset included)
    assert servo.write(64, b"\x01", chain.now()) == 0
    assert servo.get("goal_position") == 3348
    chain.advance(0.5)
    assert physics.joint_trace(11)[-1, 1] == pytest.approx(2348, abs=0.01)
    assert servo.write(116, (3448).to_bytes(4, "little"), chain.now()) == 0
    chain.advance(1.0)
    assert physics.joint_trace(11)[-1, 1] == pytest.approx(2448, abs=0.01)


def test_serve_pty_with_physics(ph):
    chain, physics = new_arm(clock="real")
    server = PtyServer(chain)
    port = PatientPortHandler(server.path)
    try:
        assert port.openPort()
        assert ph.ping(port, 11) == (1020, dxl.COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 11, 10, 4) == OK  # time-based profile
        assert ph.write4ByteTxRx(port, 11, 112, 100) == OK  # 100 ms a move
        assert ph.write1ByteTxRx(port, 11, 64, 1) == OK
        assert ph.write4ByteTxRx(port, 11, 116, 2148) == OK
        deadline = time.monotonic() + 10.0  # a generous bound for a loaded host
        while True:
            before = chain.now()
            present, result, error = ph.read4ByteTxRx(port, 11, 132)
            after = chain.now()
            assert (result, error) == OK
            if present == 2148 or time.monotonic() > deadline:
                break
        t, ticks = physics.joint_trace(11).T
        window = (t >= before - physics.timestep) & (t <= after)
        assert present == 2148 and present in {round(p) for p in ticks[window]}
        with chain.lock:  # the clock's reading steps the physics up to it
            now = chain.now()
            assert now - physics.timestep < physics.time <= now
    finally:
        port.closePort()
        server.stop()


def spin_joint1(mode: int, address: int, size: int, value: int, seconds: float) -> dict:
    """Joint1 (no gravity on its axis) in ``mode`` with ``value`` at ``address``; the present
    values after ``seconds``."""
    chain, physics = new_arm()
    servo = chain.servo(11)
    assert servo.write(11, bytes([mode]), 0.0) == 0
    assert servo.write(64, b"\x01", 0.0) == 0
    assert servo.write(address, value.to_bytes(size, "little", signed=True), 0.0) == 0
    chain.advance(seconds)
    error, data = servo.read(124, 12, chain.now())
    assert error == 0
    pwm, current, velocity, _ = (
        int.from_bytes(data[a:b], "little", signed=True)
        for a, b in ((0, 2), (2, 4), (4, 8), (8, 12))
    )
    damping = physics.drives[11].base_damping  # the model's own (viscous friction)
    return {"pwm": pwm, "current": current, "velocity": velocity, "damping": damping}


def test_pwm_current_and_velocity_modes():
    # PWM: a steady speed where the motor's torque τs·(u − ω/ω0) meets the joint's friction
    got = spin_joint1(16, 100, 2, 300, 1.0)
    u = 300 / PWM_FULL_SCALE
    speed = XM430.stall_torque * u / (XM430.back_emf_damping + got["damping"])
    assert got["pwm"] == 300
    assert got["velocity"] == round(speed * TICKS_PER_RAD / TICKS_PER_S_PER_VELOCITY_UNIT)
    # Current: the current asked for, accelerating (the PWM rises with the back-EMF)
    got = spin_joint1(0, 102, 2, 100, 0.3)
    assert got["current"] == 100 and 0 < got["pwm"] < PWM_FULL_SCALE and got["velocity"] > 50
    # ... until its voltage cannot cover the back-EMF: full PWM, less current
    got = spin_joint1(0, 102, 2, 100, 0.55)
    assert got["pwm"] >= PWM_FULL_SCALE - 1 and 0 < got["current"] < 100
    # Velocity: the PI loop reaches Goal Velocity; its P term drives the first moments
    # (20 ms in: 19.6 units, where the I term alone would have reached 8)
    assert 15 <= spin_joint1(1, 104, 4, 100, 0.02)["velocity"] <= 25
    got = spin_joint1(1, 104, 4, 100, 0.8)
    assert abs(got["velocity"] - 100) <= 2
    # Current-based Position: Goal Current caps the torque; joint2 cannot hold the arm
    chain, physics = new_arm()
    torque_on(chain)
    servo = chain.servo(12)
    assert servo.write(64, b"\x00", 0.0) == 0
    assert servo.write(11, bytes([5]), 0.0) == 0
    assert servo.write(64, b"\x01", 0.0) == 0
    assert servo.write(102, (50).to_bytes(2, "little"), 0.0) == 0
    goal = 2048 + round(0.6 * TICKS_PER_RAD)
    assert servo.write(116, goal.to_bytes(4, "little"), 0.0) == 0
    assert chain.servo(13).write(116, (4096 - goal).to_bytes(4, "little"), 0.0) == 0
    chain.advance(3.0)  # down to joint2's limit (slowly: the back-EMF brakes)
    error, data = servo.read(126, 2, chain.now())
    assert error == 0 and int.from_bytes(data, "little", signed=True) == -50
    assert physics.joint_trace(12)[-1, 1] > goal + 100


def max_lag(gains: tuple[int, int, int]) -> float:
    """Joint1's largest lag behind its profile in a 45° move (ROBOTIS's profile)."""
    chain, physics = new_arm()
    torque_on(chain, gains)
    servo = chain.servo(11)
    assert servo.write(116, (2048 + 512).to_bytes(4, "little"), 0.0) == 0
    chain.advance(1.0)
    t, ticks = physics.joint_trace(11).T
    return float(np.max(servo.trajectory.sample(t) - ticks))


def test_the_d_gain_acts_on_the_error():
    # KPD·Δe with e = profile − present: the D term pushes along the profile's velocity (less
    # lag), where a D on the measured speed alone would brake (more lag)
    # (KPD = D/16 per 1 ms period: D = 4000 takes 16.6 ticks off the 109-tick lag)
    assert 12.0 < max_lag((800, 0, 0)) - max_lag((800, 0, 4000)) < 22.0


def test_goal_pwm_limits_and_the_integral_does_not_wind_up():
    chain, physics = new_arm()
    torque_on(chain, (800, 200, 0))
    goal = 2048 + round(0.6 * TICKS_PER_RAD)
    assert chain.servo(13).write(116, (4096 - goal).to_bytes(4, "little"), 0.0) == 0
    servo = chain.servo(12)
    assert servo.write(116, goal.to_bytes(4, "little"), 0.0) == 0
    chain.advance(1.0)
    assert servo.write(100, (100).to_bytes(2, "little"), chain.now()) == 0  # Goal PWM 100
    chain.advance(1.0)
    assert physics.joint_trace(12)[-1, 1] > goal + 100  # too weak: it sags
    error, data = servo.read(124, 2, chain.now())
    assert error == 0 and int.from_bytes(data, "little", signed=True) == -100
    back = chain.now()
    assert servo.write(100, (885).to_bytes(2, "little"), back) == 0
    chain.advance(1.5)
    t, ticks = physics.joint_trace(12).T
    # the I term was held within the PWM limit while saturated: it lifts back, barely past
    assert np.min(ticks[t > back] - goal) > -8.0
    assert abs(ticks[-1] - goal) < 1.0


def test_each_packet_sees_the_physics_at_its_own_arrival():
    # forty READs written at once reach joint1's servo one after the other (14 bytes, 140 µs
    # each at 1 Mbit/s) while it turns: each answers with the horn at its own step
    chain, physics = new_arm()
    torque_on(chain, (800, 0, 0))
    assert chain.servo(11).write(116, (2048 + 512).to_bytes(4, "little"), 0.0) == 0
    chain.advance(0.2)  # mid-move, about 2500 ticks/s
    start = chain.now()
    packet = encode_instruction(InstructionPacket.read(11, 132, 4))
    chain.write(packet * 40)
    chain.advance(0.05)
    decoder = PacketDecoder()
    replies = decoder.feed(chain.read()) + decoder.flush()
    values = [int.from_bytes(r.params, "little", signed=True) for r in replies]
    assert len(values) == 40
    t, ticks = physics.joint_trace(11).T
    for k, value in enumerate(values):
        arrival = start + (k + 1) * len(packet) * chain.byte_time
        step = np.searchsorted(t, arrival + 1e-9) - 1  # the last step at or before it
        assert value in {round(ticks[step - 1]), round(ticks[step])}
    assert values[-1] - values[0] > 5


def test_a_tilted_pen_inks_where_its_nib_touches():
    chain, physics = new_arm()
    torque_on(chain)
    go_to(chain, pose_for(physics, np.array([0.17, 0.0, -0.002]), tilt=0.4))
    chain.advance(1.5)
    m, d = physics.model, physics.data
    nib = m.geom("pen_nib")
    radius = float(nib.size[0])
    axis = d.geom_xmat[nib.id].reshape(3, 3)[:, 2]  # the capsule's axis (towards the point)
    tip = d.site_xpos[m.site("pen_tip").id]
    centre = tip - radius * axis * np.sign(axis @ (tip - d.geom_xpos[nib.id]))
    sheet = physics.sheet
    expected = (centre - np.asarray(sheet.origin)) @ np.array([sheet.x_axis, sheet.y_axis]).T
    row = physics.pen_trace()[-1]
    assert row[3] == 1.0
    # the nib's rounded end touches 2 mm·sin(tilt) behind the tip's own projection
    assert row[1:3] == pytest.approx(expected * 1000.0, abs=0.05)
    tip_x = (tip - np.asarray(sheet.origin)) @ np.asarray(sheet.x_axis) * 1000.0
    assert abs(row[1] - tip_x) > 0.5
