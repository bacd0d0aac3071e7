"""X-series control tables (XL430-W250, XM430-W350, XL330-M288), value encoding and units.

Expected addresses, sizes and defaults are the e-Manual's control tables, copied as literals.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_protocols.dynamixel import (
    BAUD_RATES,
    MODELS,
    XL330_M288,
    XL430_W250,
    XM430_W350,
    ControlTable,
    ControlTableEntry,
    DriveMode,
    HardwareError,
    OperatingMode,
    acceleration_to_rpm2,
    control_table,
    decode_value,
    degrees_to_ticks,
    encode_value,
    is_time_based,
    radians_to_ticks,
    rpm2_to_acceleration,
    rpm_to_velocity,
    ticks_to_degrees,
    ticks_to_radians,
    time_based_profile,
    velocity_based_profile,
    velocity_to_rpm,
)

# key: (address, size, access) shared by both models.
LAYOUT = {
    "model_number": (0, 2, "R"),
    "model_information": (2, 4, "R"),
    "firmware_version": (6, 1, "R"),
    "id": (7, 1, "RW"),
    "baud_rate": (8, 1, "RW"),
    "return_delay_time": (9, 1, "RW"),
    "drive_mode": (10, 1, "RW"),
    "operating_mode": (11, 1, "RW"),
    "secondary_id": (12, 1, "RW"),
    "protocol_type": (13, 1, "RW"),
    "homing_offset": (20, 4, "RW"),
    "moving_threshold": (24, 4, "RW"),
    "temperature_limit": (31, 1, "RW"),
    "max_voltage_limit": (32, 2, "RW"),
    "min_voltage_limit": (34, 2, "RW"),
    "pwm_limit": (36, 2, "RW"),
    "velocity_limit": (44, 4, "RW"),
    "max_position_limit": (48, 4, "RW"),
    "min_position_limit": (52, 4, "RW"),
    "shutdown": (63, 1, "RW"),
    "torque_enable": (64, 1, "RW"),
    "led": (65, 1, "RW"),
    "status_return_level": (68, 1, "RW"),
    "registered_instruction": (69, 1, "R"),
    "hardware_error_status": (70, 1, "R"),
    "velocity_i_gain": (76, 2, "RW"),
    "velocity_p_gain": (78, 2, "RW"),
    "position_d_gain": (80, 2, "RW"),
    "position_i_gain": (82, 2, "RW"),
    "position_p_gain": (84, 2, "RW"),
    "goal_pwm": (100, 2, "RW"),
    "goal_velocity": (104, 4, "RW"),
    "profile_acceleration": (108, 4, "RW"),
    "profile_velocity": (112, 4, "RW"),
    "goal_position": (116, 4, "RW"),
    "realtime_tick": (120, 2, "R"),
    "moving": (122, 1, "R"),
    "moving_status": (123, 1, "R"),
    "present_pwm": (124, 2, "R"),
    "present_velocity": (128, 4, "R"),
    "present_position": (132, 4, "R"),
    "velocity_trajectory": (136, 4, "R"),
    "position_trajectory": (140, 4, "R"),
    "present_input_voltage": (144, 2, "R"),
    "present_temperature": (146, 1, "R"),
}

DEFAULTS = {
    XL430_W250: {
        "model_number": 1060,
        "id": 1,
        "baud_rate": 1,
        "return_delay_time": 250,
        "drive_mode": 0,
        "operating_mode": 3,
        "secondary_id": 255,
        "protocol_type": 2,
        "moving_threshold": 10,
        "temperature_limit": 72,
        "max_voltage_limit": 140,
        "min_voltage_limit": 60,
        "pwm_limit": 885,
        "velocity_limit": 265,
        "max_position_limit": 4095,
        "min_position_limit": 0,
        "shutdown": 52,
        "torque_enable": 0,
        "status_return_level": 2,
        "velocity_i_gain": 1000,
        "velocity_p_gain": 100,
        "position_d_gain": 4000,
        "position_i_gain": 0,
        "position_p_gain": 640,
        "profile_acceleration": 0,
        "profile_velocity": 0,
    },
    XM430_W350: {
        "model_number": 1020,
        "temperature_limit": 80,
        "max_voltage_limit": 160,
        "min_voltage_limit": 95,
        "current_limit": 1193,
        "velocity_limit": 200,
        "velocity_i_gain": 1920,
        "position_d_gain": 0,
        "position_p_gain": 800,
        "shutdown": 52,
    },
}


@pytest.mark.parametrize("table", [XL430_W250, XM430_W350, XL330_M288], ids=lambda t: t.model_name)
def test_shared_layout(table: ControlTable) -> None:
    for key, (address, size, access) in LAYOUT.items():
        entry = table[key]
        assert (entry.address, entry.size, entry.access) == (address, size, access), key
        assert entry.area == ("EEPROM" if address < 64 else "RAM")


def test_model_specific_items() -> None:
    assert (XM430_W350["current_limit"].address, XM430_W350["current_limit"].size) == (38, 2)
    assert (XM430_W350["goal_current"].address, XM430_W350["goal_current"].size) == (102, 2)
    assert XM430_W350["present_current"].address == 126
    assert XL430_W250["present_load"].address == 126
    for key in ("current_limit", "goal_current", "present_current"):
        assert key not in XL430_W250
    assert "present_load" not in XM430_W350


@pytest.mark.parametrize("table", [XL430_W250, XM430_W350], ids=lambda t: t.model_name)
def test_defaults(table: ControlTable) -> None:
    for key, value in DEFAULTS[table].items():
        assert table[key].default == value, key
    image = table.default_image()
    assert len(image) == table.size == 147
    for key, value in DEFAULTS[table].items():
        assert table[key].decode(image[table[key].address : table[key].end]) == value, key
    assert image[116:120] == bytes(4)  # no default for Goal Position


def test_signed_items() -> None:
    signed = {key for key, entry in XM430_W350.items() if entry.signed}
    assert signed == {
        "homing_offset",
        "goal_pwm",
        "goal_current",
        "goal_velocity",
        "goal_position",
        "present_pwm",
        "present_current",
        "present_velocity",
        "present_position",
        "velocity_trajectory",
        "position_trajectory",
    }


def test_lookup() -> None:
    assert control_table(1060) is XL430_W250
    assert control_table(1020) is XM430_W350
    assert set(MODELS) == {1060, 1020, 1200}
    assert control_table(1200) is XL330_M288
    with pytest.raises(ValueError, match="model_number: unknown 1030"):
        control_table(1030)
    with pytest.raises(KeyError, match="goal_current"):
        XL430_W250["goal_current"]
    assert XM430_W350.at(116) is XM430_W350["goal_position"]
    assert XM430_W350.at(117) is None
    assert len(XM430_W350) == len(XL430_W250) + 2


def test_the_xl330_m288_table_is_its_e_manual_page() -> None:
    # docs/en/dxl/x/xl330-m288.md: the X430 layout, its own EEPROM items, limits and defaults
    t = XL330_M288
    expected = {
        # key: (address, size, default, minimum, maximum)
        "model_number": (0, 2, 1200, None, None),
        "baud_rate": (8, 1, 1, 0, 6),
        "drive_mode": (10, 1, 0, 0, 5),
        "protocol_type": (13, 1, 2, 2, 22),
        "temperature_limit": (31, 1, 70, 0, 100),
        "max_voltage_limit": (32, 2, 70, 31, 70),
        "min_voltage_limit": (34, 2, 35, 31, 70),
        "current_limit": (38, 2, 1750, 0, 1750),
        "velocity_limit": (44, 4, 445, 0, 2047),
        "startup_configuration": (60, 1, 0, 0, 3),
        "pwm_slope": (62, 1, 140, 1, 255),
        "shutdown": (63, 1, 53, None, None),
        "velocity_i_gain": (76, 2, 1600, 0, 16383),
        "velocity_p_gain": (78, 2, 180, 0, 16383),
        "position_d_gain": (80, 2, 0, 0, 16383),
        "position_p_gain": (84, 2, 400, 0, 16383),
        "goal_current": (102, 2, None, None, None),
        "goal_position": (116, 4, None, -1_048_575, 1_048_575),
        "present_current": (126, 2, None, None, None),
        "present_position": (132, 4, None, None, None),
    }
    for key, (address, size, default, low, high) in expected.items():
        e = t[key]
        assert (e.address, e.size, e.default, e.minimum, e.maximum) == (
            address,
            size,
            default,
            low,
            high,
        ), key
    assert t.ma_per_current_unit == 1.0 and XM430_W350.ma_per_current_unit == 2.69
    assert set(t.operating_modes) == set(OperatingMode)
    assert "present_load" not in t


def test_tables_refuse_overlaps() -> None:
    first = ControlTableEntry("a", "A", 0, 4, "R")
    with pytest.raises(ValueError, match="overlaps"):
        ControlTable("X", 1, (first, ControlTableEntry("b", "B", 2, 1, "R")), frozenset())
    with pytest.raises(ValueError, match="duplicate"):
        ControlTable("X", 1, (first, ControlTableEntry("a", "A", 8, 1, "R")), frozenset())


def test_ranges() -> None:
    goal = XM430_W350["goal_position"]
    assert goal.in_range(-1_048_575) and not goal.in_range(1_048_576)
    assert goal.limited_by == ("min_position_limit", "max_position_limit")
    assert XM430_W350["goal_current"].limited_by == ("current_limit",)
    assert XM430_W350["torque_enable"].in_range(1) and not XM430_W350["torque_enable"].in_range(2)
    assert XM430_W350["present_position"].in_range(10**9)  # no fixed range
    assert XM430_W350["max_voltage_limit"].in_range(160)
    assert not XM430_W350["max_voltage_limit"].in_range(161)


def test_value_encoding() -> None:
    assert XM430_W350["goal_position"].encode(512) == b"\x00\x02\x00\x00"
    assert XM430_W350["goal_position"].encode(-1) == b"\xff\xff\xff\xff"
    assert XM430_W350["present_position"].decode(b"\xff\xff\xff\xff") == -1
    assert XM430_W350["realtime_tick"].decode(b"\xff\xff") == 65535
    with pytest.raises(ValueError, match="torque_enable"):
        XM430_W350["torque_enable"].encode(256)
    with pytest.raises(ValueError, match="max_voltage_limit"):
        XM430_W350["max_voltage_limit"].encode(-1)
    with pytest.raises(ValueError, match="expected 4 bytes"):
        XM430_W350["goal_position"].decode(b"\x00\x00")
    with pytest.raises(ValueError, match="size"):
        encode_value(1, 3)
    with pytest.raises(ValueError, match="integer"):
        encode_value(1.5, 4)  # type: ignore[arg-type]


@given(st.sampled_from([1, 2, 4]), st.booleans(), st.data())
def test_value_round_trip(size: int, signed: bool, data) -> None:
    bits = 8 * size
    low, high = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if signed else (0, 2**bits - 1)
    value = data.draw(st.integers(low, high))
    encoded = encode_value(value, size, signed=signed)
    assert len(encoded) == size
    assert decode_value(encoded, signed=signed) == value


def test_enumerations() -> None:
    assert [int(mode) for mode in OperatingMode] == [0, 1, 3, 4, 5, 16]
    assert XL430_W250.operating_modes == {1, 3, 4, 16}
    assert XM430_W350.operating_modes == {0, 1, 3, 4, 5, 16}
    assert BAUD_RATES[1] == 57_600 and BAUD_RATES[3] == 1_000_000 and BAUD_RATES[7] == 4_500_000
    assert HardwareError(52) == (
        HardwareError.OVERHEATING | HardwareError.ELECTRICAL_SHOCK | HardwareError.OVERLOAD
    )
    assert int(DriveMode.TIME_BASED_PROFILE) == 0x04
    assert is_time_based(0x05) and not is_time_based(0x01)


def test_units() -> None:
    assert ticks_to_degrees(4096) == 360.0
    assert math.isclose(ticks_to_degrees(1), 0.088, abs_tol=1e-3)
    assert degrees_to_ticks(180) == 2048
    assert radians_to_ticks(math.pi) == 2048
    assert math.isclose(ticks_to_radians(1024), math.pi / 2)
    assert math.isclose(velocity_to_rpm(100), 22.9)
    assert rpm_to_velocity(22.9) == 100
    assert math.isclose(acceleration_to_rpm2(2), 429.154)
    assert rpm2_to_acceleration(429.154) == 2


def test_profiles() -> None:
    assert time_based_profile(1000, 250) == (1000, 250)
    assert time_based_profile(1000, 500) == (1000, 500)
    with pytest.raises(ValueError, match="acceleration_ms: must be at most half"):
        time_based_profile(1000, 501)
    with pytest.raises(ValueError, match="duration_ms"):
        time_based_profile(32738, 0)
    with pytest.raises(ValueError, match="duration_ms"):
        time_based_profile(1.5, 0)  # type: ignore[arg-type]
    assert velocity_based_profile(22.9, 429.154) == (100, 2)
    assert velocity_based_profile(0, 0) == (0, 0)  # 0 means unlimited
    with pytest.raises(ValueError, match=r"max_rpm: 0\.1 is below one unit"):
        velocity_based_profile(0.1, 0)
    with pytest.raises(ValueError, match="acceleration_rpm2"):
        velocity_based_profile(1, math.inf)
    with pytest.raises(ValueError, match="max_rpm"):
        velocity_based_profile(10_000, 0)
