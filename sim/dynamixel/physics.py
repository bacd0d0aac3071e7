"""MuJoCo physics behind the simulated DYNAMIXEL bus: the arm moves, the pen touches the paper.

:class:`ArmPhysics` builds a scene from a serial arm's MJCF (the caller's robot description,
e.g. ``tagbot.arm.serial.OPEN_MANIPULATOR_X``: the simulator imports nothing of tagbot),
attaches itself to a :class:`~sim.dynamixel.chain.SimulatedChain` and from then on:

- the chain's clock steps the physics at a fixed timestep (1 ms by default) up to each
  instruction packet before executing it, so what a READ sees is the physics at that step
  (deterministic: the same packets at the same times give the same motion, bit for bit);
- each coupled servo's own profile (what its trajectory generator gives at the step's start,
  :mod:`sim.dynamixel.servo`) is the target of the joint's actuator, with the servo's gains and
  the motor's limits (below);
- Present Position, Velocity, PWM and Current read back from the servo are the physics joint's:
  ``ticks = angle · 4096 / 2π + 2048`` plus the servo's Homing Offset (the servo keeps its own
  zero offset; the physics only knows the horn).

**The servo model** (firmware: ROBOTIS e-Manual, X-series "Position PID Gain" and the position
controller's block diagram: the feedforward and PID controller compute a PWM output, Goal PWM
limits it, the inverter applies it to the motor). In Position and Extended Position modes::

    PWM = KPP·e + KPI·Σe + KPD·Δe        KPP = P(84)/128, KPI = I(82)/65536, KPD = D(80)/16

with ``e`` the trajectory's position minus the present position in ticks, ``Σe`` summed and
``Δe`` differenced per control period (:data:`CONTROL_PERIOD`, 1 ms: the e-Manual does not
publish the period; this is an assumption), the PWM clamped to ±min(PWM Limit, |Goal PWM|) of
:data:`PWM_FULL_SCALE` (885 = 100 %), the sum clamped so its own term stays within that limit
(anti-windup; the firmware's Ka is unpublished). The feedforward gains (88, 90) are not modelled
(0 by default and in ROBOTIS's OpenManipulator-X settings, P/I/D 800/100/100). The motor is a
DC motor through its gearbox, from the e-Manual's stall torque ``τs``, stall current ``Is`` and
no-load speed ``ω0`` at 12 V (5 V for the XL330-M288; :data:`MOTORS`)::

    torque = τs · (PWM/885 · V/Vr − ω/ω0)       current = Is · torque / τs

(``V`` the servo's Present Input Voltage, ``Vr`` the figures' voltage). In MuJoCo this is one
position-servo actuator per joint (a general actuator, ``force = ctrl − kp·q − kv·q̇``, so the
P and D act on the joint state inside the implicit integrator) with ``kp = a·KPP·4096/2π``,
``kv = a·KPD·Δt_c·4096/2π`` (``a`` the torque of one PWM unit),
``ctrl = kp·q_ref + kv·q̇_ref + a·KPI·Σe``, and ``forcerange`` the PWM limit's torque;
the back-EMF term is joint damping ``τs/ω0`` while the torque is on (no
current flows with the bridge off). So ROBOTIS's 800/100/100 on an XM430-W350 is
``kp`` ≈ 18.9 N·m/rad, ``kv`` ≈ 0.019 N·m·s/rad beside a back-EMF damping of 0.85 N·m·s/rad,
and a torque limit of 4.1 N·m at 12 V. Current-based Position mode adds Goal Current's torque as
a second limit; Current mode applies Goal Current's torque, PWM mode Goal PWM's duty; Velocity
mode runs the velocity PI (``KVP = P(78)/128``, ``KVI = I(76)/65536`` on the velocity error in
0.229 rev/min units per control period, the same assumption). Torque off: no actuator force, no
back-EMF (the horn is free under gravity, as on the real arm). Drive Mode's reverse direction
and the multi-turn count are not modelled (the arm's joints stay within a turn).

**The pen** is a compliant tool: the nib is a body on a slide joint along the pen axis with a
preloaded spring (:class:`PenSpring`), not soft contact parameters, so the force on the paper is
a stated spring law (preload + stiffness × compression, like a spring-loaded pen holder) rather
than a consequence of MuJoCo's solver impedance, and it stays right whatever the arm's
effective mass. Contacts: only the nib collides with the paper and the table (collision bits 2);
the arm's own geoms keep the model's self-collision (bits 1) and never touch the table.

**The recorder** (:meth:`ArmPhysics.pen_trace`): at every physics step, the time, where the pen
is on the paper (x, y in mm in the paper's frame: the contact point while the nib touches the
sheet, else the pen tip projected on the paper's plane) and the normal contact force on the
sheet (N). :meth:`ArmPhysics.joint_trace` gives each joint's horn position per step.

Example::

    chain = SimulatedChain({11: "XM430-W350", 12: "XM430-W350", 13: "XM430-W350",
                            14: "XM430-W350"})
    physics = ArmPhysics(chain, OPEN_MANIPULATOR_X)  # the arm's MJCF, paper at DEFAULT_PAPER
    url = attach_chain(chain, "arm")         # drive it with dynamixel-sdk as usual
    ...
    t, x, y, pen, force = physics.pen_trace().T
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from firmware_protocols.dynamixel import (
    TICKS_PER_REV,
    OperatingMode,
)
from sim.dynamixel.chain import SimulatedChain
from sim.dynamixel.servo import (
    DEFAULT_POSITION,
    POSITION_MODES,
    TICKS_PER_S_PER_VELOCITY_UNIT,
    SimulatedServo,
)

TICKS_PER_RAD = TICKS_PER_REV / (2.0 * math.pi)
"""Encoder ticks per radian of the horn (4096 per turn)."""

CENTRE_TICKS = float(DEFAULT_POSITION)
"""Horn ticks at joint angle 0 (2048, ROBOTIS's OpenManipulator-X convention)."""

PWM_FULL_SCALE = 885.0
"""PWM units at 100 % duty (the X-series' PWM Limit maximum; one unit is about 0.113 %)."""

CONTROL_PERIOD = 0.001
"""The firmware's control period in seconds: the time unit of the I and D terms (assumed)."""

RATED_VOLTAGE = 12.0
"""The supply voltage the :data:`MOTORS` figures are given at."""

OPEN_MANIPULATOR_X_JOINTS: Mapping[int, str] = {
    11: "joint1",
    12: "joint2",
    13: "joint3",
    14: "joint4",
}
"""Servo ID → joint name of the OpenManipulator-X (ROBOTIS's IDs; the gripper, 15, is welded)."""


@dataclass(frozen=True)
class Motor:
    """A servo's motor and gearbox at its rated ``voltage`` (V, :data:`RATED_VOLTAGE` unless
    given): stall torque (N·m), stall current (A), no-load speed (rad/s)."""

    stall_torque: float
    stall_current: float
    no_load_speed: float
    voltage: float = RATED_VOLTAGE

    @property
    def back_emf_damping(self) -> float:
        """N·m·s/rad: the torque the motor loses per rad/s of speed (τs / ω0)."""
        return self.stall_torque / self.no_load_speed


_RPM = 2.0 * math.pi / 60.0
MOTORS: Mapping[int, Motor] = {
    1020: Motor(4.1, 2.3, 46.0 * _RPM),  # XM430-W350-T/R at 12.0 V (e-Manual)
    1060: Motor(1.5, 1.4, 61.0 * _RPM),  # XL430-W250-T at 12.0 V (e-Manual)
    1200: Motor(0.52, 1.47, 103.0 * _RPM, 5.0),  # XL330-M288-T at 5.0 V (e-Manual)
}
"""Model number → motor figures from the e-Manual's specifications."""


@dataclass(frozen=True)
class PenSpring:
    """The nib on a spring along the pen axis: ``stiffness`` (N/m), ``preload`` (N, the force
    the nib needs before it moves in), ``travel`` (m, how far it can go in), ``damping``
    (N·s/m), ``mass`` (kg of the sliding nib). The defaults are a light spring-loaded holder:
    0.2 N/mm with 0.2 N of preload, 0.5 N where the arm presses it 1.5 mm (``robot.press``),
    the spring rates such holders are built with (a few tenths of a newton a millimetre), and a
    refill-sized nib sliding in it."""

    stiffness: float = 200.0
    preload: float = 0.2
    travel: float = 0.005
    damping: float = 0.5
    mass: float = 0.003

    def __post_init__(self) -> None:
        for name in ("stiffness", "travel", "damping", "mass"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"pen.{name}: must be a finite number > 0, got {value!r}")
        if not (math.isfinite(self.preload) and self.preload >= 0):
            raise ValueError(f"pen.preload: must be a finite number >= 0, got {self.preload!r}")


STICK_SPEED = 0.005
"""m/s: the nib's slip speed below which :func:`nib_drag` is taken up in proportion."""


def nib_drag(slip: np.ndarray, normal_force: float, friction: float) -> np.ndarray:
    """The paper's drag on a nib slipping at ``slip`` (m/s, along the paper) pressed with
    ``normal_force`` (N): Coulomb's ``friction × normal_force`` against the slip, taken up in
    proportion below :data:`STICK_SPEED` (a regularised Coulomb law: a nib barely moving
    creeps rather than sticks, and the law stays continuous through zero). The simulator
    applies this to its nib and tagbot's feedforward expects the same (one law).

    Figures: a fibre or felt nib on office paper slides with a kinetic coefficient of about 0.2
    to 0.4 (the profiles' 0.3); 5 mm/s is a fortieth of a hand's writing speed and a third of
    the slowest stretches of the benchmark's runs, so the taking-up matters only where a run
    starts, stops or turns."""
    slip = np.asarray(slip, dtype=float)
    speed = float(np.linalg.norm(slip))
    if speed == 0.0 or normal_force <= 0.0:
        return np.zeros_like(slip)
    return -friction * normal_force * min(1.0, speed / STICK_SPEED) * slip / speed


@dataclass(frozen=True)
class Sheet:
    """The paper: ``origin`` (m, arm frame) is its (0, 0) corner, ``x_axis`` and ``y_axis`` its
    edges (orthonormal; the normal ``x × y`` points out of the paper, towards the pen), ``size``
    (m) along them, ``friction`` between nib and paper (:func:`nib_drag`'s coefficient). Any
    object with ``origin``, ``x_axis`` and ``y_axis`` (such as
    :class:`tagbot.arm.serial.reach.Paper`) converts with :meth:`of`. A table (a board 0.1 m
    wider on every side, 2 cm thick) lies under it."""

    origin: tuple[float, float, float] = (0.10, -0.105, 0.0)
    x_axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    y_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)
    size: tuple[float, float] = (0.148, 0.210)
    friction: float = 0.3

    def __post_init__(self) -> None:
        o, u, v = (np.asarray(a, float) for a in (self.origin, self.x_axis, self.y_axis))
        if not (o.shape == u.shape == v.shape == (3,)) or not np.all(np.isfinite([o, u, v])):
            raise ValueError("paper: origin and axes need 3 finite numbers each")
        if abs(u @ u - 1) > 1e-9 or abs(v @ v - 1) > 1e-9 or abs(u @ v) > 1e-9:
            raise ValueError(f"paper: axes must be orthonormal, got {self.x_axis}, {self.y_axis}")
        if len(self.size) != 2 or not all(math.isfinite(s) and s > 0 for s in self.size):
            raise ValueError(f"paper: size must be two lengths > 0, got {self.size!r}")
        if not (math.isfinite(self.friction) and self.friction >= 0):
            raise ValueError(f"paper: friction must be >= 0, got {self.friction!r}")

    @classmethod
    def of(
        cls, paper: Any, size: tuple[float, float] = (0.148, 0.210), friction: float = 0.3
    ) -> Sheet:
        """A sheet placed like ``paper`` (anything with ``origin``, ``x_axis``, ``y_axis``)."""
        if isinstance(paper, Sheet):
            return paper
        return cls(
            tuple(map(float, paper.origin)),
            tuple(map(float, paper.x_axis)),
            tuple(map(float, paper.y_axis)),
            size,
            friction,
        )

    @property
    def rotation(self) -> np.ndarray:
        """3×3: columns x axis, y axis, normal (paper frame → arm frame)."""
        u, v = np.asarray(self.x_axis, float), np.asarray(self.y_axis, float)
        return np.column_stack([u, v, np.cross(u, v)])


DEFAULT_PAPER = Sheet()
"""An A5 sheet on the table (z = 0, the arm's base plane), 10 to 24.8 cm in front of joint1's
axis, centred left to right: where the OpenManipulator-X reaches with its pen upright."""

_SHEET_THICKNESS = 1e-4
NIB_SOLREF = (0.004, 1.0)
NIB_SOLIMP = (0.9, 0.9, 0.001, 0.5, 2.0)
"""The nib's contact with the paper and the table (MuJoCo's time constant and damping ratio,
constant impedance). A fibre or felt nib is the soft part: about 1 mm² of its point carries the
force through some 3 mm of bonded fibres with a modulus of 10 to 50 MPa, 3 000 to 17 000 N/m
(E·A/L), while the paper on the table is far stiffer; 5 000 N/m, a tenth of a millimetre at
0.5 N, is taken. Measured in the OpenManipulator-X's scene drawing temptTag 7_30 at 0.50 N:
0.094 mm in (5 300 N/m). Damping ratio 1: felt is lossy, a nib does not ring on the paper.
MuJoCo's time constant gives a stiffness in proportion to the mass the contact moves (here the
nib's slider), which is why it is stated as measured. With MuJoCo's own friction in the contact
(not :func:`nib_drag`) the nib chattered on the paper, leaving it for single steps tens of
times a second at speed (BENCHMARKS.md, session 20); with the drag applied as a force and this
contact it does not (session 21)."""
_TABLE_MARGIN, _TABLE_THICKNESS = 0.1, 0.02
_NIB_GROUP = 2  # collision bit shared by the nib, the paper and the table only


def _quat(rotation: np.ndarray) -> np.ndarray:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rotation).ravel())
    return quat


def build_scene(
    model: str | Path,
    sheet: Sheet = DEFAULT_PAPER,
    pen: PenSpring = PenSpring(),
    *,
    nib: str = "pen_nib",
    tip: str = "pen_tip",
    timestep: float = 0.001,
) -> mujoco.MjSpec:
    """The arm of ``model`` (MJCF) with the table, the paper and the sprung nib, as a spec.

    The model's ``nib`` geom and ``tip`` site move onto a body sliding along the tip site's x
    axis (the pen axis) in the tip's body; the model's actuators become position servos whose
    gains :class:`ArmPhysics` sets from the servos' registers.
    """
    spec = mujoco.MjSpec.from_file(str(model))
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    old_nib, old_tip = spec.geom(nib), spec.site(tip)
    if old_nib is None or old_tip is None:
        raise ValueError(f"{model}: needs a geom {nib!r} and a site {tip!r} (the pen's nib)")
    holder = old_tip.parent
    nib_fromto, nib_size = np.asarray(old_nib.fromto, float), list(old_nib.size)
    tip_pos, tip_quat = np.asarray(old_tip.pos, float), np.asarray(old_tip.quat, float)
    spec.delete(old_nib)
    spec.delete(old_tip)
    body = holder.add_body(name="pen_slider", pos=[0, 0, 0], quat=list(tip_quat))
    body.mass, body.explicitinertial = pen.mass, True
    body.inertia = [1e-7, 1e-7, 1e-7]
    body.add_joint(
        name="pen_slide",
        type=mujoco.mjtJoint.mjJNT_SLIDE,
        axis=[1, 0, 0],
        range=[-pen.travel, 0.0],
        stiffness=pen.stiffness,
        springref=pen.preload / pen.stiffness,
        damping=pen.damping,
        solref_limit=[2.0 * timestep, 1.0],
        solimp_limit=[0.99, 0.999, 0.001, 0.5, 2.0],
    )
    # in the slider's frame (the tip site's orientation at the holder's origin)
    to_slider = _rotation_of(tip_quat).T
    body.add_geom(
        name=nib,
        type=mujoco.mjtGeom.mjGEOM_CAPSULE,
        fromto=np.concatenate([to_slider @ nib_fromto[:3], to_slider @ nib_fromto[3:]]),
        size=nib_size,
        contype=0,
        conaffinity=_NIB_GROUP,
        condim=1,  # no friction in the contact: ArmPhysics applies nib_drag
        solref=NIB_SOLREF,
        solimp=NIB_SOLIMP,
        density=0,
        rgba=[0.1, 0.1, 0.6, 1],
    )
    body.add_site(name=tip, pos=to_slider @ tip_pos, size=[0.002, 0, 0])
    rotation = sheet.rotation
    quat = _quat(rotation)
    w, h = sheet.size
    wide = (w / 2 + _TABLE_MARGIN, h / 2 + _TABLE_MARGIN)
    for name, half, depth, rgba in (
        ("paper", (w / 2, h / 2), _SHEET_THICKNESS, [1, 1, 1, 1]),
        ("table", wide, _TABLE_THICKNESS, [0.6, 0.4, 0.2, 1]),
    ):
        top = _SHEET_THICKNESS if name == "table" else 0.0
        centre = np.asarray(sheet.origin) + rotation @ np.array([w / 2, h / 2, -top - depth / 2])
        spec.worldbody.add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=centre,
            quat=quat,
            size=[half[0], half[1], depth / 2],
            contype=_NIB_GROUP,
            conaffinity=0,
            condim=1,
            solref=NIB_SOLREF,  # the same: a contact takes the mean of its two geoms'
            solimp=NIB_SOLIMP,
            rgba=rgba,
        )
    for actuator in spec.actuators:
        actuator.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        actuator.gainprm = [1.0] + [0.0] * (len(actuator.gainprm) - 1)
        actuator.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        actuator.biasprm = [0.0] * len(actuator.biasprm)
        actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.forcerange = [-1.0, 1.0]  # set per step from the servo's PWM limit
    return spec


def _rotation_of(quat: Any) -> np.ndarray:
    matrix = np.zeros(9)
    mujoco.mju_quat2Mat(matrix, np.asarray(quat, float))
    return matrix.reshape(3, 3)


class _Drive:
    """One servo driving one joint through one actuator: the firmware's controller per step."""

    def __init__(self, physics: ArmPhysics, servo: SimulatedServo, joint: str) -> None:
        m = physics.model
        self.physics = physics
        self.servo = servo
        self.joint = joint
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint)
        aid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, joint)
        if jid < 0 or aid < 0:
            raise ValueError(f"model: no joint and actuator named {joint!r} for servo {servo.id}")
        self.qadr, self.dof, self.act = m.jnt_qposadr[jid], m.jnt_dofadr[jid], aid
        self.base_damping = float(m.dof_damping[self.dof])
        motor = MOTORS.get(servo.table.model_number)
        if motor is None:
            raise ValueError(f"servo {servo.id}: no motor figures for {servo.table.model_name}")
        self.motor = motor
        self.has_current = "goal_current" in servo.table
        self.integral = 0.0  # Σe (ticks · control periods), or Σ velocity error in velocity mode
        self.force = 0.0
        self.torque_on = False
        self.regime: tuple[bool, int] = (False, -1)  # (torque on, operating mode)
        self.emf_in_damping = False  # the back-EMF acts as joint damping (not in current mode)

    def horn(self) -> tuple[float, float]:
        d = self.physics.data
        return (
            float(d.qpos[self.qadr]) * TICKS_PER_RAD + CENTRE_TICKS,
            float(d.qvel[self.dof]) * TICKS_PER_RAD,
        )

    def output(self) -> tuple[float, float]:
        if not self.torque_on:
            return 0.0, 0.0
        motor = self.motor
        emf = motor.back_emf_damping * float(self.physics.data.qvel[self.dof])
        torque = self.force - emf if self.emf_in_damping else self.force
        pwm = (torque + emf) / self._pwm_torque()
        return pwm, motor.stall_current * torque / motor.stall_torque

    def turn_to(self, ticks: float) -> None:
        d = self.physics.data
        d.qpos[self.qadr] = (ticks - CENTRE_TICKS) / TICKS_PER_RAD
        d.qvel[self.dof] = 0.0
        mujoco.mj_forward(self.physics.model, d)

    def _pwm_torque(self) -> float:
        """N·m of one PWM unit at the servo's present supply voltage."""
        volts = self.servo.input_voltage / 10.0
        return self.motor.stall_torque * volts / self.motor.voltage / PWM_FULL_SCALE

    def control(self, t: float, dt: float) -> None:
        """Set the actuator for the step that starts at ``t`` (``dt`` long)."""
        servo, m, d = self.servo, self.physics.model, self.physics.data
        on, mode = servo.torque, servo.memory[11]
        if (on, mode) != self.regime:
            self.regime, self.torque_on, self.integral = (on, mode), on, 0.0
            self.emf_in_damping = on and mode != OperatingMode.CURRENT
            emf = self.motor.back_emf_damping if self.emf_in_damping else 0.0
            m.dof_damping[self.dof] = self.base_damping + emf
        kp = kv = ctrl = 0.0
        low = high = 0.0
        if on:
            unit = self._pwm_torque()
            pwm_cap = min(servo.get("pwm_limit"), abs(servo.get("goal_pwm")))
            high = unit * pwm_cap
            low = -high
            q, speed = float(d.qpos[self.qadr]), float(d.qvel[self.dof])
            periods = dt / CONTROL_PERIOD
            if mode in POSITION_MODES:
                p_ref, v_ref = servo.trajectory.state(t)
                offset = servo.get("homing_offset") + CENTRE_TICKS
                q_ref, w_ref = (p_ref - offset) / TICKS_PER_RAD, v_ref / TICKS_PER_RAD
                kpp = servo.get("position_p_gain") / 128.0
                kpi = servo.get("position_i_gain") / 65536.0
                kpd = servo.get("position_d_gain") / 16.0
                error = (q_ref - q) * TICKS_PER_RAD
                self.integral = _clamp_sum(self.integral + error * periods, kpi, pwm_cap)
                kp = unit * kpp * TICKS_PER_RAD
                kv = unit * kpd * CONTROL_PERIOD * TICKS_PER_RAD
                ctrl = kp * q_ref + kv * w_ref + unit * kpi * self.integral
                if mode == OperatingMode.CURRENT_BASED_POSITION and self.has_current:
                    high = min(high, abs(self._current_torque(servo.get("goal_current"))))
                    low = -high
            elif mode == OperatingMode.VELOCITY:
                per_unit = TICKS_PER_S_PER_VELOCITY_UNIT / TICKS_PER_RAD  # rad/s per unit
                _, v_ref = servo.trajectory.state(t)
                error = (v_ref / TICKS_PER_RAD - speed) / per_unit
                kvp = servo.get("velocity_p_gain") / 128.0
                kvi = servo.get("velocity_i_gain") / 65536.0
                self.integral = _clamp_sum(self.integral + error * periods, kvi, pwm_cap)
                kv = unit * kvp / per_unit
                ctrl = kv * v_ref / TICKS_PER_RAD + unit * kvi * self.integral
            elif mode == OperatingMode.PWM:
                ctrl = unit * servo.get("goal_pwm")
            elif mode == OperatingMode.CURRENT and self.has_current:
                # the current loop drives the current (so the torque) whatever the speed, as
                # long as its voltage (within the PWM limit) covers the back-EMF
                ctrl = self._current_torque(servo.get("goal_current"))
                emf = self.motor.back_emf_damping * speed
                low, high = low - emf, high - emf
        m.actuator_biasprm[self.act, 1] = -kp
        m.actuator_biasprm[self.act, 2] = -kv
        m.actuator_forcerange[self.act] = (low, high)
        d.ctrl[self.act] = ctrl

    def _current_torque(self, units: int) -> float:
        """N·m the motor gives at ``units`` of current (2.69 mA each, 1 mA on an XL330)."""
        amps = units * self.servo.table.ma_per_current_unit / 1000.0
        return self.motor.stall_torque * amps / self.motor.stall_current

    def after_step(self) -> None:
        self.force = float(self.physics.data.actuator_force[self.act])


def _clamp_sum(total: float, gain: float, cap: float) -> float:
    """The integral, kept so that ``gain · total`` stays within ``±cap`` (anti-windup)."""
    if gain <= 0.0:
        return 0.0
    bound = cap / gain
    return min(max(total, -bound), bound)


class ArmPhysics:
    """A MuJoCo arm behind ``chain``: servo ``id`` drives joint ``joints[id]`` of ``model``.

    ``paper``: a :class:`Sheet` (or anything with ``origin``, ``x_axis``, ``y_axis``; its size
    is then ``paper_size``). ``pen``: the nib's spring. ``timestep``: the physics step (s). The
    joints start where the servos' horns are. Attaching makes the chain's clock step the
    physics; :meth:`detach` gives the chain back its perfect tracking.
    """

    def __init__(
        self,
        chain: SimulatedChain,
        model: str | Path,
        *,
        joints: Mapping[int, str] = OPEN_MANIPULATOR_X_JOINTS,
        paper: Any = DEFAULT_PAPER,
        paper_size: tuple[float, float] = (0.148, 0.210),
        pen: PenSpring = PenSpring(),
        timestep: float = 0.001,
    ) -> None:
        if not (math.isfinite(timestep) and 0 < timestep <= 0.01):
            raise ValueError(f"timestep: must be > 0 and <= 0.01 s, got {timestep!r}")
        if chain.plant is not None:
            raise ValueError("chain: already has a physics simulation attached")
        self.chain = chain
        self.sheet = Sheet.of(paper, paper_size)
        self.spec = build_scene(model, self.sheet, pen, timestep=timestep)
        self.model = self.spec.compile()
        self.data = mujoco.MjData(self.model)
        self.timestep = timestep
        m = self.model
        self._paper = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "paper")
        self._nib = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "pen_nib")
        self._tip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "pen_tip")
        self._slider = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "pen_slider")
        self._normal = self.sheet.rotation[:, 2]
        self._velocity6 = np.zeros(6)
        self._origin = np.asarray(self.sheet.origin, float)
        self._to_paper = self.sheet.rotation.T
        with chain.lock:
            self._t0 = chain.now()
            self._steps = 0
            self.drives = {id: _Drive(self, chain.servo(id), name) for id, name in joints.items()}
            for drive in self.drives.values():
                p, _ = drive.servo.state(self._t0)
                self.data.qpos[drive.qadr] = (
                    p - drive.servo.get("homing_offset") - CENTRE_TICKS
                ) / TICKS_PER_RAD
            mujoco.mj_forward(m, self.data)
            self._columns = {key: array("d") for key in ("t", "x", "y", "force")}
            self._angles = {id: array("d") for id in self.drives}
            self._record()
            for drive in self.drives.values():
                drive.servo.plant = drive
            chain.plant = self
        self._force6 = np.zeros(6)

    # -- clock ---------------------------------------------------------------------------

    @property
    def time(self) -> float:
        """The physics' simulated time (a whole number of steps from the attach time)."""
        return self._t0 + self._steps * self.timestep

    def advance_to(self, t: float) -> None:
        """Step the physics while a whole step fits before ``t`` (the chain calls this)."""
        with self.chain.lock:
            dt = self.timestep
            drives = tuple(self.drives.values())
            m, d = self.model, self.data
            while self._t0 + (self._steps + 1) * dt <= t + 1e-12:
                start = self.time
                for drive in drives:
                    drive.control(start, dt)
                self._drag()
                mujoco.mj_step(m, d)
                for drive in drives:
                    drive.after_step()
                self._steps += 1
                self._record()

    def detach(self) -> None:
        """Give the chain back its perfect tracking (the servos continue from their profiles)."""
        with self.chain.lock:
            if self.chain.plant is self:
                self.chain.plant = None
            for drive in self.drives.values():
                if drive.servo.plant is drive:
                    drive.servo.plant = None

    def _drag(self) -> None:
        """The paper's drag on the nib for the next step (:func:`nib_drag`), from the last
        step's contacts: their normal force, the nib's point's slip along the sheet."""
        m, d = self.model, self.data
        d.qfrc_applied[:] = 0.0
        normal, where = 0.0, None
        for i in range(d.ncon):
            contact = d.contact[i]
            if self._nib in (contact.geom1, contact.geom2):
                mujoco.mj_contactForce(m, d, i, self._force6)
                normal += float(self._force6[0])
                where = contact.pos
        if where is None:
            return
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, self._tip, self._velocity6, 0)
        velocity = self._velocity6[3:]
        slip = velocity - (velocity @ self._normal) * self._normal
        force = nib_drag(slip, normal, self.sheet.friction)
        mujoco.mj_applyFT(m, d, force, np.zeros(3), where, self._slider, d.qfrc_applied)

    # -- recorder ------------------------------------------------------------------------

    def _record(self) -> None:
        """One row of the trace: where the nib touches the paper, and its whole normal force
        there (a nib pressed through the 0.1 mm sheet also bears on the table under it)."""
        d = self.data
        force, where = 0.0, None
        for i in range(d.ncon):
            contact = d.contact[i]
            if self._nib in (contact.geom1, contact.geom2):
                mujoco.mj_contactForce(self.model, d, i, self._force6)
                force += float(self._force6[0])
                if self._paper in (contact.geom1, contact.geom2):
                    where = contact.pos
        if where is None:  # off the paper: no ink, whatever the table bears
            where, force = d.site_xpos[self._tip], 0.0
        x, y, _ = self._to_paper @ (np.asarray(where) - self._origin)
        columns = self._columns
        columns["t"].append(self.time)
        columns["x"].append(x * 1000.0)
        columns["y"].append(y * 1000.0)
        columns["force"].append(force)
        for id, drive in self.drives.items():
            self._angles[id].append(float(d.qpos[drive.qadr]))

    def pen_trace(self, threshold: float = 0.05) -> np.ndarray:
        """``(N, 5)``: ``t, x, y, pen, force`` at every physics step from the attach time.

        ``x, y`` in mm on the paper (its frame), ``force`` the nib's normal force on the
        sheet (N), ``pen`` 1.0 where that force is above ``threshold`` N (ink), else 0.0.
        """
        if not (math.isfinite(threshold) and threshold >= 0):
            raise ValueError(f"threshold: must be a finite force >= 0, got {threshold!r}")
        with self.chain.lock:
            c = self._columns
            force = np.array(c["force"])
            return np.column_stack(
                [c["t"], c["x"], c["y"], (force > threshold).astype(float), force]
            )

    def joint_trace(self, id: int) -> np.ndarray:
        """``(N, 2)``: ``t, ticks`` of servo ``id``'s horn at every physics step (without
        Homing Offset; Present Position reads this rounded, plus the offset)."""
        with self.chain.lock:
            if id not in self._angles:
                raise KeyError(f"servo {id} drives no joint (coupled: {sorted(self.drives)})")
            angles = np.array(self._angles[id])
            return np.column_stack([self._columns["t"], angles * TICKS_PER_RAD + CENTRE_TICKS])


__all__ = [
    "CENTRE_TICKS",
    "CONTROL_PERIOD",
    "DEFAULT_PAPER",
    "MOTORS",
    "OPEN_MANIPULATOR_X_JOINTS",
    "PWM_FULL_SCALE",
    "RATED_VOLTAGE",
    "STICK_SPEED",
    "TICKS_PER_RAD",
    "ArmPhysics",
    "Motor",
    "PenSpring",
    "Sheet",
    "build_scene",
    "nib_drag",
]
