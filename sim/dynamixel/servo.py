"""One simulated DYNAMIXEL X-series servo: control table, write rules, motion profiles.

:class:`SimulatedServo` holds the control-table memory of an XL430-W250 (model 1060),
XM430-W350 (model 1020) or XL330-M288 (model 1200) from
:mod:`firmware_protocols.dynamixel.control_table`, applies the rules the firmware applies to WRITE
and READ, and moves along the profile a Goal Position starts. It is
driven by :class:`~sim.dynamixel.chain.SimulatedChain`, which owns the bus and the clock; every
method that depends on time takes the simulated time ``t`` in seconds.

Write rules (ROBOTIS e-Manual, Protocol 2.0 "Status Packet" error table and the X-series
control-table pages), checked for the whole write before any byte changes:

- a byte beyond the table or outside any item, or an item that is read-only, or an EEPROM item
  (address < 64) while Torque Enable is 1 → **access error** (7);
- a write that covers only part of an item → **data length error** (5);
- a value outside the item's fixed range, or an Operating Mode the model lacks → **data range
  error** (4);
- a Goal Position outside Min/Max Position Limit in Position Control Mode, a Goal Velocity above
  Velocity Limit, a Goal PWM above PWM Limit or a Goal Current above Current Limit → **data
  limit error** (6);
- Torque Enable = 1 while a hardware error selected by Shutdown (63) is present → **result
  fail** (1) (the e-Manual: only REBOOT brings the torque back after a shutdown; the error
  number is this simulator's choice).

READ returns the bytes of any span inside the table (undefined bytes read as 0); a span past the
end is an access error with no data (Protocol 2.0 page, READ note). The table ends after Present
Temperature (146): indirect addresses and Backup Ready are not simulated.

Motion (Position, Extended Position and Current-based Position modes, torque on): a Goal Position
write plans a profile from the present position *and velocity*, so a new goal in mid-move is
continuous in position (and in velocity whenever the acceleration is finite):

- **velocity-based** (Drive Mode bit 2 clear): Profile Velocity caps the speed (0.229 rev/min
  units), Profile Acceleration the acceleration (214.577 rev/min² units); 0 means unlimited.
  The speed never exceeds Velocity Limit (44): Profile Velocity 0 moves at Velocity Limit.
  Trapezoid, or triangle when the move is too short to cruise; an infinite acceleration gives the
  rectangular profile.
- **time-based** (Drive Mode bit 2 set, firmware ≥ 42): Profile Velocity is the total time t3 in
  ms and Profile Acceleration the ramp time t1 in ms, clamped to t3 / 2 as the e-Manual says
  ("What is the Profile"). From a standstill this is the e-Manual's trapezoid; from a moving
  state the ramp starts at the present velocity and the cruise speed is solved so the move still
  ends exactly t3 after the write. If that would exceed Velocity Limit, the move is stretched:
  it runs at Velocity Limit with acceleration Velocity Limit / t1.

Moving (122) is 1 while a profile is in progress or the speed exceeds Moving Threshold; Moving
Status (123) carries In-Position (bit 0), Profile Ongoing (bit 1) and the profile type (bits
4–5: 11 trapezoidal, 10 triangular, 01 rectangular, 00 step), as in the e-Manual's Moving Status
table. Tracking is perfect: Present Position is the profile's position (rounded), Present
Velocity its velocity, and the trajectory registers (136, 140) equal them — unless a
:class:`Plant` is attached (:mod:`sim.dynamixel.physics`): then the profile drives the plant's
motor and Present Position, Velocity, PWM and Current are the plant's. Velocity Control Mode
ramps to Goal Velocity at Profile Acceleration; PWM and Current modes hold still.

Torque on sets Goal Position to the present position and holds there; torque off (also by a
shutdown) stops the horn where it is. REBOOT keeps EEPROM, resets RAM to its defaults, clears the
hardware error and the multi-turn count, and leaves the servo deaf for :attr:`boot_time`.
"""

from __future__ import annotations

import math
from array import array
from bisect import bisect_right
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from firmware_protocols.dynamixel import (
    EEPROM_END,
    MODELS,
    RPM2_PER_ACCELERATION_UNIT,
    RPM_PER_VELOCITY_UNIT,
    TICKS_PER_REV,
    ControlTable,
    ControlTableEntry,
    DriveMode,
    ErrorCode,
    OperatingMode,
    control_table,
)
from firmware_protocols.dynamixel.control_table import (
    BAUD_RATES,
    MAX_TIME_PROFILE_MS,
    US_PER_RETURN_DELAY_UNIT,
)

DEFAULT_FIRMWARE_VERSION = 46
"""Firmware version reported by PING and address 6 (time-based profiles need ≥ 42)."""

SUPPLY = {1060: 111, 1020: 120, 1200: 50}
"""Model number → Present Input Voltage (0.1 V) of a fresh servo: the e-Manual's recommended
supply (XL430 11.1 V, XM430 12 V, XL330 5 V); 12 V for a model not listed."""

DEFAULT_POSITION = 2048.0
"""Where the horn of a new servo sits, in ticks (the middle of a turn)."""

TICKS_PER_S_PER_VELOCITY_UNIT = RPM_PER_VELOCITY_UNIT * TICKS_PER_REV / 60.0
"""One velocity unit (0.229 rev/min) in ticks per second (about 15.63)."""

TICKS_PER_S2_PER_ACCELERATION_UNIT = RPM2_PER_ACCELERATION_UNIT * TICKS_PER_REV / 3600.0
"""One Profile Acceleration unit (214.577 rev/min²) in ticks per second² (about 244.1)."""

POSITION_MODES = frozenset(
    {
        OperatingMode.POSITION,
        OperatingMode.EXTENDED_POSITION,
        OperatingMode.CURRENT_BASED_POSITION,
    }
)
"""Operating modes in which Goal Position starts a profile."""

# Moving Status (123) bits.
IN_POSITION = 0x01
PROFILE_ONGOING = 0x02
PROFILE_STEP = 0x00
PROFILE_RECTANGULAR = 0x10
PROFILE_TRIANGULAR = 0x20
PROFILE_TRAPEZOIDAL = 0x30

_INT32 = (-(2**31), 2**31 - 1)


def resolve_model(model: int | str | ControlTable) -> ControlTable:
    """The control table of a model number (1060), name ("XL430-W250") or table."""
    if isinstance(model, ControlTable):
        return model
    if isinstance(model, str):
        key = model.strip().upper()
        for table in MODELS.values():
            if table.model_name.upper() == key:
                return table
        if key.isdigit():
            return control_table(int(key))
        names = ", ".join(table.model_name for table in MODELS.values())
        raise ValueError(f"model: unknown {model!r} (known: {names})")
    return control_table(model)


# -- trajectories ------------------------------------------------------------------------------

Piece = tuple[float, float, float]
"""A planned piece of motion: ``(duration s, start velocity ticks/s, acceleration ticks/s²)``."""


def plan_velocity_based(
    p0: float, v0: float, goal: float, vmax: float, amax: float
) -> tuple[list[Piece], int]:
    """Pieces that take ``(p0, v0)`` to rest at ``goal`` with ``|v| ≤ vmax``, ``|a| ≤ amax``.

    ``amax`` may be ``math.inf`` (velocity jumps: rectangular profile). Returns the pieces and the
    Moving Status profile type. A moving start that would overshoot (or points away) first brakes
    to rest, then plans from there; a start faster than ``vmax`` slows to ``vmax`` first.
    """
    pieces: list[Piece] = []
    distance = goal - p0
    if vmax <= 0.0:
        return pieces, PROFILE_STEP
    if math.isinf(amax):
        if distance != 0.0:
            speed = math.copysign(vmax, distance)
            pieces.append((abs(distance) / vmax, speed, 0.0))
        return pieces, PROFILE_RECTANGULAR
    if v0 != 0.0 and (
        distance == 0.0
        or math.copysign(1.0, v0) != math.copysign(1.0, distance)
        or v0 * v0 / (2.0 * amax) > abs(distance) * (1.0 + 1e-12)
    ):
        brake = abs(v0) / amax
        if brake > 0.0:  # a subnormal v0 brakes in no time
            pieces.append((brake, v0, -math.copysign(amax, v0)))
        p0 += v0 * brake / 2.0
        v0 = 0.0
        distance = goal - p0
    if distance == 0.0:
        return pieces, PROFILE_TRIANGULAR
    direction = math.copysign(1.0, distance)
    length = abs(distance)
    u0 = abs(v0)
    if u0 > vmax:
        slow = (u0 - vmax) / amax
        slow_d = (u0 * u0 - vmax * vmax) / (2.0 * amax)
        stop_d = vmax * vmax / (2.0 * amax)
        cruise = max(0.0, length - slow_d - stop_d) / vmax
        pieces.append((slow, direction * u0, -direction * amax))
        if cruise > 0.0:
            pieces.append((cruise, direction * vmax, 0.0))
        pieces.append((vmax / amax, direction * vmax, -direction * amax))
        return pieces, PROFILE_TRAPEZOIDAL
    accel_d = (vmax * vmax - u0 * u0) / (2.0 * amax)
    stop_d = vmax * vmax / (2.0 * amax)
    if accel_d + stop_d <= length:
        cruise = (length - accel_d - stop_d) / vmax
        if vmax > u0:
            pieces.append(((vmax - u0) / amax, direction * u0, direction * amax))
        if cruise > 0.0:
            pieces.append((cruise, direction * vmax, 0.0))
        pieces.append((vmax / amax, direction * vmax, -direction * amax))
        return pieces, PROFILE_TRAPEZOIDAL
    peak = math.sqrt(amax * length + u0 * u0 / 2.0)
    if peak > u0:
        pieces.append(((peak - u0) / amax, direction * u0, direction * amax))
    pieces.append((peak / amax, direction * peak, -direction * amax))
    return pieces, PROFILE_TRIANGULAR


def plan_time_based(
    p0: float, v0: float, goal: float, total_s: float, ramp_s: float, vmax: float
) -> tuple[list[Piece], int]:
    """Pieces that take ``(p0, v0)`` to rest at ``goal`` exactly ``total_s`` later.

    The velocity ramps linearly from ``v0`` to a cruise speed over ``ramp_s`` (clamped to half the
    total), cruises, and ramps to 0 over ``ramp_s``. ``total_s == 0`` means infinite velocity:
    the move runs at ``vmax``. When the cruise speed would exceed ``vmax`` the move is stretched
    (velocity-based at ``vmax`` with acceleration ``vmax / ramp_s``).
    """
    ramp_s = min(ramp_s, total_s / 2.0)
    if ramp_s < 1e-9:
        ramp_s = 0.0  # below a ns (the firmware counts ms): a jump
    if total_s <= 0.0 or vmax <= 0.0:
        amax = vmax / ramp_s if ramp_s > 0.0 else math.inf
        return plan_velocity_based(p0, v0, goal, vmax, amax)
    distance = goal - p0
    cruise = (distance - v0 * ramp_s / 2.0) / (total_s - ramp_s)
    if abs(cruise) > vmax * (1.0 + 1e-9):
        amax = vmax / ramp_s if ramp_s > 0.0 else math.inf
        return plan_velocity_based(p0, v0, goal, vmax, amax)
    if ramp_s <= 0.0:
        return [(total_s, cruise, 0.0)], PROFILE_RECTANGULAR
    pieces: list[Piece] = [(ramp_s, v0, (cruise - v0) / ramp_s)]
    middle = total_s - 2.0 * ramp_s
    if middle > 0.0:
        pieces.append((middle, cruise, 0.0))
    pieces.append((ramp_s, cruise, -cruise / ramp_s))
    return pieces, PROFILE_TRAPEZOIDAL if middle > 0.0 else PROFILE_TRIANGULAR


class Plant(Protocol):
    """The physical horn a servo drives (:mod:`sim.dynamixel.physics`): without one, tracking is
    perfect (the horn is the profile)."""

    def horn(self) -> tuple[float, float]:
        """Horn position (ticks, without Homing Offset) and velocity (ticks/s) now."""
        ...

    def output(self) -> tuple[float, float]:
        """Present PWM (0.113 % units) and motor current (A) now."""
        ...

    def turn_to(self, ticks: float) -> None:
        """Turn the horn by hand to ``ticks`` (without Homing Offset), at rest."""
        ...


_TIME_BASED_PROFILE = int(DriveMode.TIME_BASED_PROFILE)  # a plain int: IntFlag's & is slow

_GOAL_CAPS = {
    "goal_velocity": "velocity_limit",
    "goal_pwm": "pwm_limit",
    "goal_current": "current_limit",
}
"""Goal items and the limit item their magnitude may not exceed (Data Limit Error)."""


class Trajectory:
    """The horn's motion over the whole run: segments of constant acceleration.

    Segment ``k`` starts at time ``t[k]`` at position ``p[k]`` with velocity ``v[k]`` and
    acceleration ``a[k]``, and lasts until the next one starts; the last one lasts forever.
    Re-planning at time ``t`` drops the segments that start at or after ``t`` and appends new
    ones, so the history stays for :meth:`sample`.
    """

    def __init__(self, t0: float, p0: float) -> None:
        self._t = array("d", [t0])
        self._p = array("d", [p0])
        self._v = array("d", [0.0])
        self._a = array("d", [0.0])
        self.end = t0
        """Time the current profile ends (at or before it: in progress)."""

    def __len__(self) -> int:
        return len(self._t)

    def state(self, t: float) -> tuple[float, float]:
        """Position (ticks) and velocity (ticks/s) at time ``t``."""
        k = max(0, bisect_right(self._t, t) - 1)
        dt = t - self._t[k]
        a = self._a[k]
        return self._p[k] + (self._v[k] + 0.5 * a * dt) * dt, self._v[k] + a * dt

    def replan(
        self,
        t: float,
        p: float,
        pieces: Sequence[Piece],
        *,
        final_position: float | None = None,
        final_velocity: float = 0.0,
    ) -> None:
        """From time ``t`` (position ``p``) follow ``pieces``, then hold (or cruise at
        ``final_velocity``) at ``final_position`` (default: where the pieces end)."""
        times = self._t
        kept = len(times)
        while kept > 1 and times[kept - 1] >= t:
            kept -= 1
        if times[kept - 1] >= t:  # only the first segment is left and it starts now
            kept -= 1
        if kept < len(times):
            for column in (times, self._p, self._v, self._a):
                del column[kept:]
        tc, pc = t, p
        for duration, v, a in pieces:
            if duration <= 0.0:
                continue
            self._append(tc, pc, v, a)
            pc += (v + 0.5 * a * duration) * duration
            tc += duration
        self._append(tc, pc if final_position is None else final_position, final_velocity, 0.0)
        self.end = tc

    def hold(self, t: float) -> None:
        """Stop dead at time ``t`` where the horn is."""
        p, _ = self.state(t)
        self.replan(t, p, ())

    def _append(self, t: float, p: float, v: float, a: float) -> None:
        self._t.append(t)
        self._p.append(p)
        self._v.append(v)
        self._a.append(a)

    def sample(self, times: np.ndarray) -> np.ndarray:
        """Positions (ticks, float) at ``times`` (any shape), vectorised."""
        times = np.asarray(times, dtype=float)
        t0 = np.array(self._t)
        k = np.clip(np.searchsorted(t0, times, side="right") - 1, 0, len(t0) - 1)
        dt = times - t0[k]
        p0, v0, a = np.array(self._p)[k], np.array(self._v)[k], np.array(self._a)[k]
        return p0 + (v0 + 0.5 * a * dt) * dt


# -- the servo ---------------------------------------------------------------------------------


class SimulatedServo:
    """One X-series servo. ``model``: number (1060), name ("XL430-W250") or table.

    ``baud_rate`` (bit/s) sets the EEPROM Baud Rate code so that the servo listens on a bus of
    that speed. ``position`` is where the horn starts, in ticks. ``t`` is the simulated time of
    power-up.
    """

    boot_time: float = 0.1
    """Seconds a rebooting servo stays deaf (an estimate; the e-Manual gives no figure)."""

    def __init__(
        self,
        model: int | str | ControlTable,
        id: int = 1,
        *,
        baud_rate: int = 57_600,
        firmware_version: int = DEFAULT_FIRMWARE_VERSION,
        position: float = DEFAULT_POSITION,
        t: float = 0.0,
    ) -> None:
        self.table = resolve_model(model)
        if not 0 <= firmware_version <= 255:
            raise ValueError(f"firmware_version: must be 0..255, got {firmware_version!r}")
        codes = {rate: code for code, rate in BAUD_RATES.items()}
        if baud_rate not in codes:
            raise ValueError(f"baud_rate: must be one of {sorted(codes)}, got {baud_rate!r}")
        self.firmware_version = firmware_version
        self._factory = bytes(self._image(id=1, baud_code=1))
        self.memory = self._image(id=id, baud_code=codes[baud_rate])
        self._size = self.table.size  # a computed property: keep it
        self._layout = {e.key: (e.address, e.end, e.signed) for e in self.table.values()}
        self._boot_goal_limits()
        self._owner = [None] * self._size  # address -> item covering it
        self._items_at: dict[tuple[int, int], tuple[int, list[ControlTableEntry]]] = {}
        for entry in self.table.values():
            for address in range(entry.address, entry.end):
                self._owner[address] = entry  # type: ignore[call-overload]
        self.trajectory = Trajectory(t, float(position))
        self.profile_type = PROFILE_STEP
        self.registered: tuple[int, bytes] | None = None
        self.booted_at = t
        self.clock_rate = 1.0
        """How fast the servo's own clock (Realtime Tick) runs against true time: an oscillator's
        tolerance (1.01: 1 % fast)."""
        self.deaf_until = -math.inf
        self.input_voltage = SUPPLY.get(self.table.model_number, 120)
        """Present Input Voltage, 0.1 V units (set it to simulate a supply)."""
        self.temperature = 30
        """Present Temperature, °C."""
        self.silent = False
        """Fault hook: hears and executes, but sends nothing."""
        self.corrupt_pending = 0
        """Fault hook: this many coming status packets get a wrong CRC."""
        self.plant: Plant | None = None
        """The physics horn (set by :class:`sim.dynamixel.physics.ArmPhysics`), or None."""

    def _image(self, *, id: int, baud_code: int) -> bytearray:
        image = self.table.default_image()
        image[6] = self.firmware_version
        image[7] = id
        image[8] = baud_code
        return image

    def _boot_goal_limits(self) -> None:
        """Goal PWM and Goal Current start at PWM Limit and Current Limit (what the firmware
        sets at boot: they limit the position controller's output)."""
        for goal, limit in (("goal_pwm", "pwm_limit"), ("goal_current", "current_limit")):
            if goal in self._layout:
                self._put(goal, self.get(limit))

    # -- registers ---------------------------------------------------------------------------

    def get(self, key: str) -> int:
        """The value of control-table item ``key`` as stored (dynamic items: see :meth:`read`)."""
        address, end, signed = self._layout[key]
        return int.from_bytes(self.memory[address:end], "little", signed=signed)

    def _put(self, key: str, value: int) -> None:
        entry = self.table[key]
        low, high = _INT32 if entry.signed else (0, 2 ** (8 * entry.size) - 1)
        value = min(max(int(value), low), high)
        self.memory[entry.address : entry.end] = entry.encode(value)

    @property
    def id(self) -> int:
        return self.memory[7]

    @property
    def baud_rate(self) -> int:
        """The bus speed the servo listens at (from its Baud Rate code)."""
        return BAUD_RATES.get(self.memory[8], 0)

    @property
    def return_delay(self) -> float:
        """Return Delay Time in seconds."""
        return self.memory[9] * US_PER_RETURN_DELAY_UNIT * 1e-6

    @property
    def status_return_level(self) -> int:
        return self.get("status_return_level")

    @property
    def torque(self) -> bool:
        return bool(self.memory[64])

    @property
    def hardware_error(self) -> int:
        return self.get("hardware_error_status")

    @property
    def alert(self) -> int:
        """0x80 when a hardware error is present, else 0 (OR it into every status error)."""
        return 0x80 if self.hardware_error else 0

    def model_number(self) -> int:
        """Model Number as reported (address 0; :meth:`set_model_number` may change it)."""
        return self.get("model_number")

    def set_model_number(self, number: int) -> None:
        """Fault hook: report ``number`` as the model (the control table stays the real one)."""
        self._put("model_number", number)

    def listening(self, t: float, baud: int) -> bool:
        """Whether the servo hears a bus running at ``baud`` at time ``t``."""
        return t >= self.deaf_until and self.baud_rate == baud and self.memory[13] == 2

    # -- motion ------------------------------------------------------------------------------

    def state(self, t: float) -> tuple[float, float]:
        """Exact position (ticks) and velocity (ticks/s) at ``t``."""
        return self.trajectory.state(t)

    def present(self, t: float) -> tuple[float, float]:
        """Present position (ticks) and velocity (ticks/s): the plant's horn plus Homing Offset
        when a plant is attached, else the profile's at ``t``."""
        if self.plant is None:
            return self.trajectory.state(t)
        p, v = self.plant.horn()
        return p + self.get("homing_offset"), v

    def set_position(self, ticks: float, t: float) -> None:
        """Turn the horn by hand to ``ticks`` (only with torque off)."""
        if self.torque:
            raise RuntimeError("set_position: the torque is on; turn it off first")
        self.trajectory.replan(t, float(ticks), ())
        if self.plant is not None:
            self.plant.turn_to(float(ticks) - self.get("homing_offset"))

    @property
    def velocity_limit(self) -> float:
        """Velocity Limit in ticks/s."""
        return self.get("velocity_limit") * TICKS_PER_S_PER_VELOCITY_UNIT

    def _operating_mode(self) -> int:
        return self.memory[11]

    def _start_profile(self, t: float) -> None:
        p, v = self.trajectory.state(t)
        goal = float(self.get("goal_position"))
        vlimit = self.velocity_limit
        pv, pa = self.get("profile_velocity"), self.get("profile_acceleration")
        if self.memory[10] & _TIME_BASED_PROFILE:
            pv, pa = min(pv, MAX_TIME_PROFILE_MS), min(pa, MAX_TIME_PROFILE_MS)
            pieces, kind = plan_time_based(p, v, goal, pv / 1000.0, pa / 1000.0, vlimit)
        else:
            vmax = min(pv * TICKS_PER_S_PER_VELOCITY_UNIT, vlimit) if pv else vlimit
            amax = pa * TICKS_PER_S2_PER_ACCELERATION_UNIT if pa else math.inf
            pieces, kind = plan_velocity_based(p, v, goal, vmax, amax)
        if pv == 0:
            kind = PROFILE_STEP
        elif pa == 0:
            kind = PROFILE_RECTANGULAR
        final = goal if vlimit > 0.0 else None
        self.trajectory.replan(t, p, pieces, final_position=final)
        self.profile_type = kind

    def _start_velocity(self, t: float) -> None:
        p, v = self.trajectory.state(t)
        target = self.get("goal_velocity") * TICKS_PER_S_PER_VELOCITY_UNIT
        pa = self.get("profile_acceleration")
        pieces: list[Piece] = []
        if pa and target != v:
            a = math.copysign(pa * TICKS_PER_S2_PER_ACCELERATION_UNIT, target - v)
            pieces.append(((target - v) / a, v, a))
        self.trajectory.replan(t, p, pieces, final_velocity=target)
        self.profile_type = PROFILE_TRAPEZOIDAL if pa else PROFILE_STEP

    def _torque_on(self, t: float) -> None:
        p, _ = self.present(t)
        self._put("goal_position", round(p))
        self.trajectory.replan(t, p, ())
        if self._operating_mode() == OperatingMode.VELOCITY:
            self._start_velocity(t)

    # -- instructions ------------------------------------------------------------------------

    def read(self, address: int, length: int, t: float) -> tuple[int, bytes]:
        """READ: ``(error, data)``; data is empty on error."""
        if length < 1:
            return ErrorCode.DATA_LENGTH, b""
        if address + length > self._size:
            return ErrorCode.ACCESS, b""
        self._refresh(t)
        return 0, bytes(self.memory[address : address + length])

    def _refresh(self, t: float) -> None:
        """Write the time-dependent items (present values, Moving, Realtime Tick) for ``t``."""
        p, v = self.trajectory.state(t)
        present, speed = self.present(t)
        ongoing = t < self.trajectory.end
        threshold = self.get("moving_threshold") * TICKS_PER_S_PER_VELOCITY_UNIT
        moving = ongoing or abs(speed) > threshold
        status = self.profile_type | (PROFILE_ONGOING if ongoing else 0)
        mode = self._operating_mode()
        if (
            mode in POSITION_MODES
            and not ongoing
            and abs(present - self.get("goal_position")) < 1.0
        ):
            status |= IN_POSITION
        self._put("realtime_tick", int((t - self.booted_at) * 1000.0 * self.clock_rate) % 32768)
        self.memory[122] = int(moving)
        self.memory[123] = status
        pwm, current = (0.0, 0.0) if self.plant is None else self.plant.output()
        self._put("present_pwm", round(pwm))
        if "present_current" in self._layout:
            self._put("present_current", round(current * 1000.0 / self.table.ma_per_current_unit))
        self._put("present_velocity", round(speed / TICKS_PER_S_PER_VELOCITY_UNIT))
        self._put("present_position", round(present))
        self._put("velocity_trajectory", round(v / TICKS_PER_S_PER_VELOCITY_UNIT))
        self._put("position_trajectory", round(p))
        self._put("present_input_voltage", self.input_voltage)
        self._put("present_temperature", self.temperature)

    def _items(self, address: int, length: int) -> tuple[int, list[ControlTableEntry]]:
        """The items a write covers, or an error if it covers anything else (the layout never
        changes: worked out once per address and length)."""
        known = self._items_at.get((address, length))
        if known is None:
            known = self._items_at[(address, length)] = self._find_items(address, length)
        return known

    def _find_items(self, address: int, length: int) -> tuple[int, list[ControlTableEntry]]:
        end = address + length
        if length < 1:
            return ErrorCode.DATA_LENGTH, []
        if end > self._size:
            return ErrorCode.ACCESS, []
        items: list[ControlTableEntry] = []
        position = address
        while position < end:
            entry = self._owner[position]
            if entry is None:
                return ErrorCode.ACCESS, []
            if entry.address != position or entry.end > end:
                return ErrorCode.DATA_LENGTH, []
            items.append(entry)
            position = entry.end
        return 0, items

    def check_write(self, address: int, data: bytes) -> int:
        """The error a WRITE of ``data`` at ``address`` would get now (0: it would succeed)."""
        return self._check_write(address, data)[0]

    def _check_write(self, address: int, data: bytes) -> tuple[int, list[ControlTableEntry]]:
        """:meth:`check_write`'s error, and the items the write covers."""
        error, items = self._items(address, len(data))
        if error:
            return error, items
        if any(not entry.writable for entry in items):
            return ErrorCode.ACCESS, items
        if self.torque and any(entry.address < EEPROM_END for entry in items):
            return ErrorCode.ACCESS, items
        limits = 0
        for entry in items:
            value = entry.decode(data[entry.address - address : entry.end - address])
            if not entry.in_range(value):
                return ErrorCode.DATA_RANGE, items
            if entry.key == "operating_mode" and value not in self.table.operating_modes:
                return ErrorCode.DATA_RANGE, items
            limits = limits or self._limit_error(entry.key, value)
        return limits, items

    def _limit_error(self, key: str, value: int) -> int:
        if key == "goal_position" and self._operating_mode() == OperatingMode.POSITION:
            low, high = self.get("min_position_limit"), self.get("max_position_limit")
            return 0 if low <= value <= high else ErrorCode.DATA_LIMIT
        cap = _GOAL_CAPS.get(key)
        if cap is not None and abs(value) > self.get(cap):
            return ErrorCode.DATA_LIMIT
        if key == "torque_enable" and value and self.hardware_error & self.get("shutdown"):
            return ErrorCode.RESULT_FAIL
        return 0

    def write(self, address: int, data: bytes, t: float) -> int:
        """WRITE: the error (0: done, with its effects at time ``t``)."""
        data = bytes(data)
        error, items = self._check_write(address, data)
        if error:
            return error
        keys = {entry.key for entry in items}
        # Only these two items' old values matter (and the position only for the first).
        homing = "homing_offset" in keys
        if homing:
            offset_before = self.get("homing_offset")
            p, _ = self.trajectory.state(t)
        torque_before = self.get("torque_enable") if "torque_enable" in keys else 0
        self.memory[address : address + len(data)] = data
        if homing:
            shift = self.get("homing_offset") - offset_before
            self.trajectory.replan(t, p + shift, ())
        if "torque_enable" in keys and self.torque != bool(torque_before):
            if self.torque:
                self._torque_on(t)
            else:
                self.trajectory.hold(t)
        mode = self._operating_mode()
        if "goal_position" in keys and mode in POSITION_MODES:
            if not self.torque and self.memory[10] & DriveMode.TORQUE_ON_BY_GOAL_UPDATE:
                shutdown = self.hardware_error & self.get("shutdown")
                self.memory[64] = 0 if shutdown else 1
            if self.torque:
                self._start_profile(t)
        if "goal_velocity" in keys and self.torque and mode == OperatingMode.VELOCITY:
            self._start_velocity(t)
        return 0

    def reg_write(self, address: int, data: bytes) -> int:
        """REG_WRITE: check now, keep for ACTION (Registered Instruction = 1)."""
        error = self.check_write(address, bytes(data))
        if not error:
            self.registered = (address, bytes(data))
            self.memory[69] = 1
        return error

    def action(self, t: float) -> int:
        """ACTION: run the registered write; instruction error (2) if there is none."""
        if self.registered is None:
            return ErrorCode.INSTRUCTION
        address, data = self.registered
        self.registered = None
        self.memory[69] = 0
        return self.write(address, data, t)

    def clear_multi_turn(self, t: float) -> int:
        """CLEAR option 1: Present Position back within one turn; result fail while moving."""
        p, v = self.trajectory.state(t)
        if t < self.trajectory.end or v != 0.0:
            return ErrorCode.RESULT_FAIL
        self.trajectory.replan(t, p % TICKS_PER_REV, ())
        self._put("goal_position", round(p % TICKS_PER_REV))
        return 0

    def set_hardware_error(self, bits: int, t: float) -> None:
        """Raise hardware error ``bits`` (OR-ed in); those in Shutdown (63) turn the torque off."""
        if not 0 <= bits <= 0xFF:
            raise ValueError(f"bits: must be 0..255, got {bits!r}")
        self.memory[70] |= bits
        if self.memory[70] & self.memory[63] and self.torque:
            self.memory[64] = 0
            self.trajectory.hold(t)

    def reboot(self, t: float) -> None:
        """REBOOT at time ``t``: RAM to defaults, hardware error cleared, deaf while booting."""
        p, _ = self.trajectory.state(t)
        self.memory[EEPROM_END:] = self._factory[EEPROM_END:]
        self._boot_goal_limits()
        self.registered = None
        self.trajectory.replan(t, p % TICKS_PER_REV, ())
        self.profile_type = PROFILE_STEP
        self.deaf_until = t + self.boot_time
        self.booted_at = self.deaf_until

    def factory_reset(self, option: int, t: float) -> None:
        """FACTORY_RESET: 0xFF everything, 0x01 all but ID, 0x02 all but ID and baud; reboots."""
        keep = {0xFF: 0, 0x01: 1, 0x02: 2}[option]
        saved = bytes(self.memory[7:9])
        self.memory[:] = self._factory
        self.memory[7 : 7 + keep] = saved[:keep]
        self.reboot(t)

    def ping_reply(self) -> bytes:
        """PING status parameters: model number (2 bytes) and firmware version."""
        return bytes(self.memory[0:2]) + bytes([self.memory[6]])


__all__ = [
    "DEFAULT_FIRMWARE_VERSION",
    "DEFAULT_POSITION",
    "IN_POSITION",
    "POSITION_MODES",
    "PROFILE_ONGOING",
    "PROFILE_RECTANGULAR",
    "PROFILE_STEP",
    "PROFILE_TRAPEZOIDAL",
    "PROFILE_TRIANGULAR",
    "TICKS_PER_S2_PER_ACCELERATION_UNIT",
    "TICKS_PER_S_PER_VELOCITY_UNIT",
    "Plant",
    "SimulatedServo",
    "Trajectory",
    "plan_time_based",
    "plan_velocity_based",
    "resolve_model",
]
