"""Control tables of the DYNAMIXEL X-series servos tagbot drives: XL430-W250, XM430-W350 and
XL330-M288.

A servo is programmed by reading and writing its control table, a byte array whose items have
an address and a size of 1, 2 or 4 bytes (little-endian; signed items in two's complement).
Items below address 64 are in EEPROM, kept across power cycles and writable only while Torque
Enable (64) is 0; the others are in RAM.

Sources (ROBOTIS e-Manual, read in its public source repository ROBOTIS-GIT/emanual):

- ``docs/en/dxl/x/xl430-w250.md`` (model 1060), ``docs/en/dxl/x/xm430-w350.md`` (model 1020) and
  ``docs/en/dxl/x/xl330-m288.md`` (model 1200): address, size, name, access, default ("initial
  value") and range of every item below. The XL330-M288 shares the X430 layout and differs in
  the EEPROM: baud rates 0..6, Drive Mode 0..5, Protocol Type 2..22, a 5 V supply (voltage
  limits 31..70), Current Limit 1750 in 1 mA units (Goal and Present Current too), Velocity
  Limit 445 of 0..2047, Startup Configuration (60), PWM Slope (62), Shutdown 53, and its own
  gains (velocity I/P 1600/180, position D/I/P 0/0/400).
- Where the XM430-W350 table is visibly stale or inconsistent, the description pages it
  includes and the table of its sibling XM430-W210 (``xm430-w210.md``, same firmware family):
  voltage limits 95..160 (the W350 table prints 110..300, outside its own defaults 95 and 160);
  ID range 0..252 (the W350 table prints 0..253; 253 is not a usable ID per the Protocol 2.0
  page).
- ``_includes/en/dxl/x/drive_mode.md``: Drive Mode bits (0x01 reverse, 0x04 time-based profile
  from firmware V42, 0x08 torque on by goal update from firmware V45) for the X430 families;
  the XL430 table's range 0..13 is used for both models (the stale W350 table says 0..1).
- ``_includes/en/dxl/x/profile_velocity.md``, ``profile_acceleration.md``: profile units, 0.229
  rev/min and 214.577 rev/min² per unit; in time-based mode both are in ms (0..32737) and the
  acceleration time may not exceed half the profile velocity (the total time).
- ``_includes/en/dxl/control_table_goal_position_2.md``: 0.088° per unit, 4096 units per turn
  (one turn is 0..4095), ±1,048,575 (±256 turns) in the extended position modes.
- ``_includes/en/dxl/control_table_baudrate_2.md``, ``control_table_opmode_six_2.md``,
  ``x/operating_mode_xl.md``, ``x/shutdown.md``, ``x/status_return_level.md``,
  ``x/shadow_id.md``: baud-rate codes, operating modes, hardware error bits, status return
  levels, and Secondary ID 253..255 meaning "disabled".

Items whose range depends on other items (Goal PWM, Goal Current, Goal Velocity, Goal Position)
name them in ``limited_by``; a simulator applies those limits itself.
"""

from __future__ import annotations

import enum
import itertools
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

EEPROM_END = 64
"""First RAM address; the EEPROM items below it are write-locked while torque is enabled."""

TICKS_PER_REV = 4096
"""Position units per output-shaft turn (one turn is 0..4095)."""

DEGREES_PER_TICK = 360.0 / TICKS_PER_REV
"""0.087890625°, which the e-Manual rounds to 0.088°."""

RPM_PER_VELOCITY_UNIT = 0.229
"""Goal/Present Velocity, Velocity Limit, Profile Velocity (velocity-based): rev/min per unit."""

RPM2_PER_ACCELERATION_UNIT = 214.577
"""Profile Acceleration (velocity-based profile): rev/min² per unit."""

MA_PER_CURRENT_UNIT = 2.69
"""Current Limit, Goal Current, Present Current (XM430-W350): about 2.69 mA per unit (the
XL330-M288's is 1 mA: :attr:`ControlTable.ma_per_current_unit`)."""

PERCENT_PER_PWM_UNIT = 0.113
"""PWM Limit, Goal PWM: percent of full duty per unit (885 is 100 %)."""

VOLTS_PER_VOLTAGE_UNIT = 0.1
"""Voltage limits and Present Input Voltage: 0.1 V per unit."""

US_PER_RETURN_DELAY_UNIT = 2
"""Return Delay Time: 2 µs per unit (default 250 is 500 µs)."""

MAX_PROFILE_VALUE = 32767
"""Largest Profile Velocity / Acceleration in the velocity-based profile."""

MAX_TIME_PROFILE_MS = 32737
"""Largest Profile Velocity / Acceleration in ms in the time-based profile."""

EXTENDED_POSITION_LIMIT = 1_048_575
"""Goal Position bound (±256 turns) in the extended and current-based position modes."""


class DriveMode(enum.IntFlag):
    """Bits of Drive Mode (10)."""

    REVERSE = 0x01
    """Positive direction is clockwise instead of counter-clockwise."""
    TIME_BASED_PROFILE = 0x04
    """Profile Velocity is the move's duration and Profile Acceleration its ramp time, in ms."""
    TORQUE_ON_BY_GOAL_UPDATE = 0x08
    """A new goal turns the torque on instead of being ignored while it is off."""


class OperatingMode(enum.IntEnum):
    """Values of Operating Mode (11)."""

    CURRENT = 0
    VELOCITY = 1
    POSITION = 3
    EXTENDED_POSITION = 4
    CURRENT_BASED_POSITION = 5
    PWM = 16


class HardwareError(enum.IntFlag):
    """Bits of Hardware Error Status (70) and of Shutdown (63), which selects the fatal ones."""

    INPUT_VOLTAGE = 0x01
    OVERHEATING = 0x04
    MOTOR_ENCODER = 0x08
    ELECTRICAL_SHOCK = 0x10
    OVERLOAD = 0x20


class StatusReturnLevel(enum.IntEnum):
    """Values of Status Return Level (68): which instructions get a status packet."""

    PING_ONLY = 0
    PING_AND_READ = 1
    ALL = 2


BAUD_RATES: Mapping[int, int] = {
    0: 9_600,
    1: 57_600,
    2: 115_200,
    3: 1_000_000,
    4: 2_000_000,
    5: 3_000_000,
    6: 4_000_000,
    7: 4_500_000,
}
"""Baud Rate (8) codes and their bit rates; the factory default is 1 (57600 bps)."""


# -- values ---------------------------------------------------------------------------------


def encode_value(value: int, size: int, *, signed: bool = False) -> bytes:
    """``value`` as ``size`` little-endian bytes (two's complement when ``signed``)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"value: must be an integer, got {value!r}")
    if size not in (1, 2, 4):
        raise ValueError(f"size: must be 1, 2 or 4, got {size!r}")
    try:
        return value.to_bytes(size, "little", signed=signed)
    except OverflowError:
        kind = "signed" if signed else "unsigned"
        raise ValueError(f"value: {value} does not fit {size} {kind} bytes") from None


def decode_value(data: bytes | bytearray | memoryview, *, signed: bool = False) -> int:
    """The integer that little-endian ``data`` (1, 2 or 4 bytes) holds."""
    if len(data) not in (1, 2, 4):
        raise ValueError(f"data: must be 1, 2 or 4 bytes, got {len(data)}")
    return int.from_bytes(data, "little", signed=signed)


@dataclass(frozen=True)
class ControlTableEntry:
    """One item of a control table.

    ``key`` is the Python name (``"goal_position"``), ``name`` the e-Manual's. ``minimum`` and
    ``maximum`` are the fixed range the e-Manual gives (None where it gives none or a range that
    depends on other items, listed in ``limited_by``); ``default`` is None where it says "-".
    """

    key: str
    name: str
    address: int
    size: int
    access: str
    default: int | None = None
    minimum: int | None = None
    maximum: int | None = None
    signed: bool = False
    unit: str = ""
    limited_by: tuple[str, ...] = ()

    @property
    def end(self) -> int:
        """The address just past this item."""
        return self.address + self.size

    @property
    def area(self) -> str:
        """``"EEPROM"`` or ``"RAM"``."""
        return "EEPROM" if self.address < EEPROM_END else "RAM"

    @property
    def writable(self) -> bool:
        """Whether WRITE may change it (access RW)."""
        return self.access == "RW"

    def in_range(self, value: int) -> bool:
        """Whether ``value`` is within the item's fixed range (always True without one)."""
        if self.minimum is not None and value < self.minimum:
            return False
        return self.maximum is None or value <= self.maximum

    def encode(self, value: int) -> bytes:
        """``value`` as this item's bytes; ValueError if it does not fit the item's size."""
        try:
            return encode_value(value, self.size, signed=self.signed)
        except ValueError as exc:
            raise ValueError(f"{self.key}: {exc}") from None

    def decode(self, data: bytes | bytearray | memoryview) -> int:
        """The value in ``data``, which must be exactly this item's size."""
        if len(data) != self.size:
            raise ValueError(f"{self.key}: expected {self.size} bytes, got {len(data)}")
        return decode_value(data, signed=self.signed)


@dataclass(frozen=True)
class ControlTable(Mapping[str, ControlTableEntry]):
    """The control table of one model: a read-only mapping from item key to entry."""

    model_name: str
    model_number: int
    entries: tuple[ControlTableEntry, ...]
    operating_modes: frozenset[int]
    ma_per_current_unit: float = MA_PER_CURRENT_UNIT
    """Current Limit, Goal Current, Present Current: mA per unit (1 on the XL330s)."""
    _by_key: dict[str, ControlTableEntry] = field(init=False, repr=False, compare=False)
    _by_address: dict[int, ControlTableEntry] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        by_key = {entry.key: entry for entry in self.entries}
        by_address = {entry.address: entry for entry in self.entries}
        if len(by_key) != len(self.entries) or len(by_address) != len(self.entries):
            raise ValueError(f"{self.model_name}: duplicate key or address")
        ordered = sorted(self.entries, key=lambda entry: entry.address)
        for before, after in itertools.pairwise(ordered):
            if before.end > after.address:
                raise ValueError(f"{self.model_name}: {before.key} overlaps {after.key}")
        object.__setattr__(self, "_by_key", by_key)
        object.__setattr__(self, "_by_address", by_address)

    def __getitem__(self, key: str) -> ControlTableEntry:
        try:
            return self._by_key[key]
        except KeyError:
            raise KeyError(f"{self.model_name} has no control table item {key!r}") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._by_key)

    def __len__(self) -> int:
        return len(self._by_key)

    def at(self, address: int) -> ControlTableEntry | None:
        """The item starting at ``address``, if any."""
        return self._by_address.get(address)

    @property
    def size(self) -> int:
        """Bytes up to the end of the last item."""
        return max(entry.end for entry in self.entries)

    def default_image(self) -> bytearray:
        """The table's bytes after a factory reset: defaults in place, zeros elsewhere."""
        image = bytearray(self.size)
        for entry in self.entries:
            if entry.default is not None:
                image[entry.address : entry.end] = entry.encode(entry.default)
        return image


# -- the tables -----------------------------------------------------------------------------

_RPM = "0.229 rev/min"
_PULSE = "1 pulse (0.088°)"
_GAIN = (0, 16383)


def _e(
    key: str,
    name: str,
    address: int,
    size: int,
    access: str,
    default: int | None = None,
    span: tuple[int, int] | None = None,
    *,
    signed: bool = False,
    unit: str = "",
    limited_by: tuple[str, ...] = (),
) -> ControlTableEntry:
    low, high = span if span is not None else (None, None)
    return ControlTableEntry(
        key, name, address, size, access, default, low, high, signed, unit, limited_by
    )


def _x430(
    *,
    model_number: int,
    temperature_limit: int,
    voltage: tuple[int, int, tuple[int, int]],
    velocity_limit: int,
    gains: tuple[int, int, int, int, int],
    current: bool,
) -> list[ControlTableEntry]:
    """The items the two models share, with their model-specific defaults filled in."""
    max_voltage, min_voltage, voltage_span = voltage
    velocity_i, velocity_p, position_d, position_i, position_p = gains
    # fmt: off
    entries = [
        _e("model_number", "Model Number", 0, 2, "R", model_number),
        _e("model_information", "Model Information", 2, 4, "R"),
        _e("firmware_version", "Firmware Version", 6, 1, "R"),
        _e("id", "ID", 7, 1, "RW", 1, (0, 252)),
        _e("baud_rate", "Baud Rate", 8, 1, "RW", 1, (0, 7)),
        _e("return_delay_time", "Return Delay Time", 9, 1, "RW", 250, (0, 254), unit="2 µs"),
        _e("drive_mode", "Drive Mode", 10, 1, "RW", 0, (0, 13)),
        _e("operating_mode", "Operating Mode", 11, 1, "RW", 3, (0, 16)),
        # 0..252 selects a secondary ID, 253..255 disables it (default 255).
        _e("secondary_id", "Secondary(Shadow) ID", 12, 1, "RW", 255, (0, 255)),
        _e("protocol_type", "Protocol Type", 13, 1, "RW", 2, (1, 2)),
        _e("homing_offset", "Homing Offset", 20, 4, "RW", 0, (-1_044_479, 1_044_479),
           signed=True, unit=_PULSE),
        _e("moving_threshold", "Moving Threshold", 24, 4, "RW", 10, (0, 1023), unit=_RPM),
        _e("temperature_limit", "Temperature Limit", 31, 1, "RW", temperature_limit, (0, 100),
           unit="1 °C"),
        _e("max_voltage_limit", "Max Voltage Limit", 32, 2, "RW", max_voltage, voltage_span,
           unit="0.1 V"),
        _e("min_voltage_limit", "Min Voltage Limit", 34, 2, "RW", min_voltage, voltage_span,
           unit="0.1 V"),
        _e("pwm_limit", "PWM Limit", 36, 2, "RW", 885, (0, 885), unit="0.113 %"),
        _e("velocity_limit", "Velocity Limit", 44, 4, "RW", velocity_limit, (0, 1023), unit=_RPM),
        _e("max_position_limit", "Max Position Limit", 48, 4, "RW", 4095, (0, 4095), unit=_PULSE),
        _e("min_position_limit", "Min Position Limit", 52, 4, "RW", 0, (0, 4095), unit=_PULSE),
        _e("shutdown", "Shutdown", 63, 1, "RW", 52),
        _e("torque_enable", "Torque Enable", 64, 1, "RW", 0, (0, 1)),
        _e("led", "LED", 65, 1, "RW", 0, (0, 1)),
        _e("status_return_level", "Status Return Level", 68, 1, "RW", 2, (0, 2)),
        _e("registered_instruction", "Registered Instruction", 69, 1, "R", 0, (0, 1)),
        _e("hardware_error_status", "Hardware Error Status", 70, 1, "R", 0),
        _e("velocity_i_gain", "Velocity I Gain", 76, 2, "RW", velocity_i, _GAIN),
        _e("velocity_p_gain", "Velocity P Gain", 78, 2, "RW", velocity_p, _GAIN),
        _e("position_d_gain", "Position D Gain", 80, 2, "RW", position_d, _GAIN),
        _e("position_i_gain", "Position I Gain", 82, 2, "RW", position_i, _GAIN),
        _e("position_p_gain", "Position P Gain", 84, 2, "RW", position_p, _GAIN),
        _e("feedforward_2nd_gain", "Feedforward 2nd Gain", 88, 2, "RW", 0, _GAIN),
        _e("feedforward_1st_gain", "Feedforward 1st Gain", 90, 2, "RW", 0, _GAIN),
        _e("goal_pwm", "Goal PWM", 100, 2, "RW", signed=True, unit="0.113 %",
           limited_by=("pwm_limit",)),
        _e("goal_velocity", "Goal Velocity", 104, 4, "RW", signed=True, unit=_RPM,
           limited_by=("velocity_limit",)),
        # Velocity-based profile: 0..32767 in 214.577 rev/min²; time-based: 0..32737 ms.
        _e("profile_acceleration", "Profile Acceleration", 108, 4, "RW", 0, (0, 32767),
           unit="214.577 rev/min² or 1 ms"),
        # Velocity-based profile: 0..32767 in 0.229 rev/min; time-based: 0..32737 ms.
        _e("profile_velocity", "Profile Velocity", 112, 4, "RW", 0, (0, 32767),
           unit="0.229 rev/min or 1 ms"),
        # Position mode: Min..Max Position Limit; extended modes: ±1,048,575.
        _e("goal_position", "Goal Position", 116, 4, "RW",
           span=(-EXTENDED_POSITION_LIMIT, EXTENDED_POSITION_LIMIT), signed=True, unit=_PULSE,
           limited_by=("min_position_limit", "max_position_limit")),
        _e("realtime_tick", "Realtime Tick", 120, 2, "R", span=(0, 32767), unit="1 ms"),
        _e("moving", "Moving", 122, 1, "R", 0, (0, 1)),
        _e("moving_status", "Moving Status", 123, 1, "R", 0),
        _e("present_pwm", "Present PWM", 124, 2, "R", signed=True, unit="0.113 %"),
        _e("present_velocity", "Present Velocity", 128, 4, "R", signed=True, unit=_RPM),
        _e("present_position", "Present Position", 132, 4, "R", signed=True, unit=_PULSE),
        _e("velocity_trajectory", "Velocity Trajectory", 136, 4, "R", signed=True, unit=_RPM),
        _e("position_trajectory", "Position Trajectory", 140, 4, "R", signed=True, unit=_PULSE),
        _e("present_input_voltage", "Present Input Voltage", 144, 2, "R", unit="0.1 V"),
        _e("present_temperature", "Present Temperature", 146, 1, "R", unit="1 °C"),
    ]
    if current:
        entries += [
            _e("current_limit", "Current Limit", 38, 2, "RW", 1193, (0, 1193), unit="2.69 mA"),
            _e("goal_current", "Goal Current", 102, 2, "RW", signed=True, unit="2.69 mA",
               limited_by=("current_limit",)),
            _e("present_current", "Present Current", 126, 2, "R", signed=True, unit="2.69 mA"),
        ]
    else:
        entries.append(
            _e("present_load", "Present Load", 126, 2, "R", span=(-1000, 1000), signed=True,
               unit="0.1 %")
        )
    # fmt: on
    return sorted(entries, key=lambda entry: entry.address)


XL430_W250 = ControlTable(
    "XL430-W250",
    1060,
    tuple(
        _x430(
            model_number=1060,
            temperature_limit=72,
            voltage=(140, 60, (60, 140)),
            velocity_limit=265,
            gains=(1000, 100, 4000, 0, 640),
            current=False,
        )
    ),
    frozenset(
        {
            OperatingMode.VELOCITY,
            OperatingMode.POSITION,
            OperatingMode.EXTENDED_POSITION,
            OperatingMode.PWM,
        }
    ),
)
"""XL430-W250 (model 1060): no current sensing, so Present Load instead of Present Current."""

XM430_W350 = ControlTable(
    "XM430-W350",
    1020,
    tuple(
        _x430(
            model_number=1020,
            temperature_limit=80,
            voltage=(160, 95, (95, 160)),
            velocity_limit=200,
            gains=(1920, 100, 0, 0, 800),
            current=True,
        )
    ),
    frozenset(OperatingMode),
)
"""XM430-W350 (model 1020): with Current Limit, Goal Current and Present Current."""


def _xl330_m288() -> tuple[ControlTableEntry, ...]:
    """The XL330-M288's table: the X430 layout with its own EEPROM items (see the module
    docstring)."""
    entries = {
        entry.key: entry
        for entry in _x430(
            model_number=1200,
            temperature_limit=70,
            voltage=(70, 35, (31, 70)),
            velocity_limit=445,
            gains=(1600, 180, 0, 0, 400),
            current=True,
        )
    }
    # fmt: off
    for entry in (
        _e("baud_rate", "Baud Rate", 8, 1, "RW", 1, (0, 6)),
        _e("drive_mode", "Drive Mode", 10, 1, "RW", 0, (0, 5)),
        _e("protocol_type", "Protocol Type", 13, 1, "RW", 2, (2, 22)),
        _e("current_limit", "Current Limit", 38, 2, "RW", 1750, (0, 1750), unit="1 mA"),
        _e("velocity_limit", "Velocity Limit", 44, 4, "RW", 445, (0, 2047), unit=_RPM),
        _e("startup_configuration", "Startup Configuration", 60, 1, "RW", 0, (0, 3)),
        _e("pwm_slope", "PWM Slope", 62, 1, "RW", 140, (1, 255), unit="1.977 mV/ms"),
        _e("shutdown", "Shutdown", 63, 1, "RW", 53),
        _e("goal_current", "Goal Current", 102, 2, "RW", signed=True, unit="1 mA",
           limited_by=("current_limit",)),
        _e("present_current", "Present Current", 126, 2, "R", signed=True, unit="1 mA"),
    ):
        entries[entry.key] = entry
    # fmt: on
    return tuple(sorted(entries.values(), key=lambda entry: entry.address))


XL330_M288 = ControlTable("XL330-M288", 1200, _xl330_m288(), frozenset(OperatingMode), 1.0)
"""XL330-M288 (model 1200): the X430 layout on a 5 V supply, current in 1 mA units."""

MODELS: Mapping[int, ControlTable] = {
    table.model_number: table for table in (XL430_W250, XM430_W350, XL330_M288)
}
"""The known control tables by model number (what PING and address 0 report)."""


def control_table(model_number: int) -> ControlTable:
    """The control table of a model number; ValueError for a model this module does not know."""
    try:
        return MODELS[model_number]
    except (KeyError, TypeError):
        known = ", ".join(f"{number} ({table.model_name})" for number, table in MODELS.items())
        raise ValueError(f"model_number: unknown {model_number!r} (known: {known})") from None


# -- units ----------------------------------------------------------------------------------


def ticks_to_degrees(ticks: float) -> float:
    """Position units to degrees (4096 per turn)."""
    return ticks * DEGREES_PER_TICK


def degrees_to_ticks(degrees: float) -> int:
    """Degrees to the nearest position unit."""
    return round(degrees / DEGREES_PER_TICK)


def ticks_to_radians(ticks: float) -> float:
    """Position units to radians."""
    return ticks * (2.0 * math.pi / TICKS_PER_REV)


def radians_to_ticks(radians: float) -> int:
    """Radians to the nearest position unit."""
    return round(radians * TICKS_PER_REV / (2.0 * math.pi))


def velocity_to_rpm(units: float) -> float:
    """Velocity units (0.229 rev/min) to rev/min."""
    return units * RPM_PER_VELOCITY_UNIT


def rpm_to_velocity(rpm: float) -> int:
    """rev/min to the nearest velocity unit."""
    return round(rpm / RPM_PER_VELOCITY_UNIT)


def acceleration_to_rpm2(units: float) -> float:
    """Profile Acceleration units (214.577 rev/min²) to rev/min²."""
    return units * RPM2_PER_ACCELERATION_UNIT


def rpm2_to_acceleration(rpm2: float) -> int:
    """rev/min² to the nearest Profile Acceleration unit."""
    return round(rpm2 / RPM2_PER_ACCELERATION_UNIT)


def is_time_based(drive_mode: int) -> bool:
    """Whether Drive Mode selects the time-based profile (bit 2)."""
    return bool(drive_mode & DriveMode.TIME_BASED_PROFILE)


def time_based_profile(duration_ms: int, acceleration_ms: int) -> tuple[int, int]:
    """Profile Velocity and Profile Acceleration for a time-based move.

    The move takes ``duration_ms`` in all and ramps up (and down) over ``acceleration_ms``,
    which may not exceed half the duration; both are in 0..32737.
    """
    for name, value in (("duration_ms", duration_ms), ("acceleration_ms", acceleration_ms)):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{name}: must be an integer number of ms, got {value!r}")
        if not 0 <= value <= MAX_TIME_PROFILE_MS:
            raise ValueError(f"{name}: must be 0..{MAX_TIME_PROFILE_MS} ms, got {value}")
    if 2 * acceleration_ms > duration_ms:
        raise ValueError(
            f"acceleration_ms: must be at most half of duration_ms ({duration_ms}), "
            f"got {acceleration_ms}"
        )
    return duration_ms, acceleration_ms


def velocity_based_profile(max_rpm: float, acceleration_rpm2: float) -> tuple[int, int]:
    """Profile Velocity and Profile Acceleration units for a velocity-based move.

    0 means "no limit" on the servo; a positive value that rounds to 0 units is refused, as
    it would silently lift the limit.
    """
    values = []
    for name, value, unit in (
        ("max_rpm", max_rpm, RPM_PER_VELOCITY_UNIT),
        ("acceleration_rpm2", acceleration_rpm2, RPM2_PER_ACCELERATION_UNIT),
    ):
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"{name}: must be a finite number >= 0, got {value!r}")
        units = round(value / unit)
        if value > 0 and units == 0:
            raise ValueError(f"{name}: {value} is below one unit ({unit}) and would mean no limit")
        if units > MAX_PROFILE_VALUE:
            raise ValueError(f"{name}: {value} exceeds {MAX_PROFILE_VALUE} units of {unit}")
        values.append(units)
    return values[0], values[1]
